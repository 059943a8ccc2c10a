"""The linear modes by the band solver (linalg.band_eigenpairs, used by finite_modes and so by classify_modes) equal
the dense solver's: a random graded chain's eigenvalues and participation ratios against scipy.linalg.eigh of the
dense M^-1/2 K M^-1/2, clamped, with free ends (rigid motions deflated) and as a ring (rows reordered into a band)."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.linalg as sla
import scipy.sparse as sp

from cosserat_chain.analysis.dispersion import finite_modes
from cosserat_chain.analysis.localized_modes import classify_modes
from cosserat_chain.linalg import band_eigenpairs, upper_bands
from cosserat_chain.models import get_model
from cosserat_chain.params import ChainParams, disordered
from cosserat_chain.state import free_index, pack

#: Tolerances of the comparison with the dense solver (the task's): eigenvalues relative, participation ratios relative.
EIGENVALUE_RTOL = 1e-10
PARTICIPATION_RTOL = 1e-8

CHAINS = {
    "clamped": {},
    "free": {"left_end": "free", "right_end": "free"},
    "pinned_free": {"left_end": "pinned", "right_end": "free"},
    "ring": {"periodic": True},
}


def random_graded(n: int, seed: int, **ends) -> ChainParams:
    return disordered(ChainParams(N=n, **ends), seed, 0.5, ("E1", "E2", "m", "j"))


def dense_modes(params: ChainParams) -> tuple[np.ndarray, np.ndarray]:
    """omega^2 and each mode's participation ratio from scipy.linalg.eigh of the dense M^-1/2 K M^-1/2, rigid modes left out."""
    stiffness = get_model("linear").stiffness(params, np.zeros((3, params.n_particles)))
    root = sp.diags(1.0 / np.sqrt(pack(params, params.particle_inertia)))
    values, vectors = sla.eigh((root @ stiffness @ root).toarray())
    elastic = np.sort(np.argsort(np.abs(values))[params.rigid_modes :])
    # z^2 summed over each particle's free rows is its share of the mode's energy (z = M^1/2 a, z^T z = 1).
    particle = free_index(params) // 3
    shares = np.array([np.bincount(particle, vectors[:, i] ** 2, minlength=params.n_particles) for i in elastic])
    return values[elastic], 1.0 / np.sum(shares**2, axis=1)


def banded_modes(params: ChainParams) -> tuple[np.ndarray, np.ndarray]:
    modes = finite_modes(params, "linear")
    energy = np.sum(params.particle_inertia[None] * modes.shapes**2, axis=1)[modes.rigid :]
    shares = energy / np.sum(energy, axis=1, keepdims=True)
    return modes.omega2.real[modes.rigid :], 1.0 / np.sum(shares**2, axis=1)


@pytest.mark.parametrize("ends", list(CHAINS))
@pytest.mark.parametrize("seed", [1, 2])
def test_a_random_graded_chains_modes_by_the_band_solver_equal_the_dense_ones(ends, seed):
    params = random_graded(6, seed, **CHAINS[ends])
    dense_values, dense_participation = dense_modes(params)
    values, participation = banded_modes(params)
    # Distinct eigenvalues: each mode, and so its participation, is determined.
    assert np.min(np.diff(dense_values)) > 1e-6 * dense_values[-1]
    assert values == pytest.approx(dense_values, rel=EIGENVALUE_RTOL, abs=0.0)
    assert participation == pytest.approx(dense_participation, rel=PARTICIPATION_RTOL, abs=0.0)


def test_the_rigid_motions_stay_out_of_the_elastic_modes():
    """Free ends: three zero frequencies, exactly, and every elastic mode M-orthogonal to them and to each other."""
    params = random_graded(5, 3, left_end="free", right_end="free")
    modes = finite_modes(params, "linear")
    assert modes.rigid == 3 and np.all(modes.omega2[:3] == 0.0)
    flat = modes.shapes.transpose(0, 2, 1).reshape(modes.shapes.shape[0], -1)[:, free_index(params)]
    gram = flat @ (pack(params, params.particle_inertia)[:, None] * flat.T)
    assert np.max(np.abs(gram - np.eye(gram.shape[0]))) < 1e-12


def test_an_exactly_repeated_spectrum_gives_orthonormal_eigenvectors():
    """Two uncoupled copies of one band matrix: every eigenvalue twice. Inverse iteration alone would find the same
    vector for both; the cluster's orthogonalisation gives an orthonormal basis of each pair's plane."""
    params = random_graded(8, 4)
    stiffness = get_model("linear").stiffness(params, np.zeros((3, params.n_particles)))
    twice = sp.block_diag([stiffness, stiffness], format="csr")
    values, vectors = band_eigenpairs(upper_bands(twice))
    once = sla.eigvalsh(stiffness.toarray())
    assert values == pytest.approx(np.repeat(once, 2), rel=EIGENVALUE_RTOL)
    assert np.max(np.abs(vectors.T @ vectors - np.eye(values.size))) < 1e-12
    assert np.max(np.abs(twice @ vectors - vectors * values)) < 1e-12 * np.max(np.abs(once))


def test_band_eigenpairs_deflates_a_given_null_space():
    """A chain with free ends: its rigid motions (three zero eigenvalues) given, the rest of the spectrum is left."""
    params = random_graded(4, 5, left_end="free", right_end="free")
    stiffness = get_model("linear").stiffness(params, np.zeros((3, params.n_particles)))
    dense, basis = sla.eigh(stiffness.toarray())
    null = basis[:, :3]
    values, vectors = band_eigenpairs(upper_bands(stiffness), null)
    assert values == pytest.approx(dense[3:], rel=EIGENVALUE_RTOL)
    assert np.max(np.abs(null.T @ vectors)) < 1e-13


def test_a_uniform_ring_has_no_localized_mode():
    """Its modes are waves round the whole ring, in degenerate pairs (+q and -q) that the clusters keep apart."""
    assert classify_modes(ChainParams(N=12, periodic=True)).localized == ()
