"""Neutral modes: the rigid motions a chain's ends leave free get omega = 0 exactly, never NaN (issue 45, item 5)."""

import numpy as np
import pytest

from cosserat_chain.analysis.dispersion import finite_modes, rigid_motions
from cosserat_chain.models.base import get_model
from cosserat_chain.params import ChainParams
from cosserat_chain.state import zeros

MODELS = ("linear", "sine", "nonlinear")
#: (left end, right end) and the rigid motions they leave free.
ENDS = [(("free", "free"), 3), (("pinned", "free"), 1), (("free", "pinned"), 1), (("clamped", "free"), 0), (("pinned", "pinned"), 0)]


@pytest.mark.parametrize("model", MODELS)
@pytest.mark.parametrize("n", [3, 4])
@pytest.mark.parametrize(("ends", "expected"), ENDS)
def test_free_and_pinned_chains_at_rest_are_stable_with_their_rigid_modes_at_zero(model, n, ends, expected):
    params = ChainParams(N=n, left_end=ends[0], right_end=ends[1])
    modes = finite_modes(params, model)
    assert modes.rigid == expected == params.rigid_modes
    assert np.all(np.isfinite(modes.frequencies))
    assert modes.stable
    assert np.all(modes.omega2[:expected] == 0.0)
    assert np.all(modes.frequencies[:expected] == 0.0)
    # The elastic modes stay clear of zero: a free chain at rest has no other neutral mode.
    assert np.all(modes.omega2[expected:].real > 1e-4)


def test_ring_has_two_rigid_translations():
    modes = finite_modes(ChainParams(N=3, periodic=True), "linear")
    assert modes.rigid == 2
    assert modes.stable and np.all(modes.frequencies[:2] == 0.0)


@pytest.mark.parametrize("model", MODELS)
def test_rigid_motions_are_exact_zero_modes_of_every_model_at_rest(model):
    params = ChainParams(N=4, left_end="free", right_end="free", a=0.3, b=0.15)
    stiffness = get_model(model).stiffness(params, zeros(params))
    motions = rigid_motions(params)
    assert motions.shape == (3, stiffness.shape[0])
    assert np.linalg.matrix_rank(motions) == 3
    assert np.max(np.abs(stiffness @ motions.T)) <= 1e-13 * abs(stiffness).max()


@pytest.mark.parametrize("model", MODELS)
def test_elastic_frequencies_match_the_full_eigenproblem(model):
    # Splitting the rigid modes off changes nothing else: the nonzero omega^2 are the
    # eigenvalues of M^-1 K computed without it.
    params = ChainParams(N=3, left_end="free", right_end="free")
    modes = finite_modes(params, model)
    stiffness = get_model(model).stiffness(params, zeros(params)).toarray()
    from cosserat_chain.state import pack

    full = np.sort(np.linalg.eigvals(stiffness / pack(params, params.particle_inertia)[:, None]).real)
    np.testing.assert_allclose(np.sort(modes.omega2.real)[3:], full[3:], rtol=1e-9)
    assert np.max(np.abs(full[:3])) < 1e-12


def test_mode_shapes_are_mass_normalised_and_the_rigid_ones_orthogonal_to_the_rest():
    params = ChainParams(N=3, left_end="pinned", right_end="free")
    modes = finite_modes(params, "linear")
    mass = params.particle_inertia
    gram = np.einsum("ari,ri,bri->ab", modes.shapes, mass, modes.shapes)
    np.testing.assert_allclose(gram, np.eye(gram.shape[0]), atol=1e-10)
