"""The damped dynamics' verdict from the stiffness in band storage (issue 44, item 3: ``critical``'s start-up).

:func:`~cosserat_chain.numerics.stability.dynamic_stability` and
:func:`~cosserat_chain.numerics.stability.sine_theorem_stability` read K~ = M^(-1/2) K M^(-1/2) from the model's
band (:meth:`BandMatrix.scaled`, dense through :meth:`BandMatrix.toarray`), not through SciPy's sparse products.
Checked: the band's dense form and scaling against NumPy's arithmetic entry by entry, and the verdict (unstable
eigenvalues, real ones and pairs, the stiffness index, stability) against LAPACK's eigenvalues of the unscaled
Jacobian [[0, M^-1], [-K, -Gamma M^-1]] built here from the model's sparse stiffness, on random chains (every kind
of end, N = 1 .. 8, all three models, states with angles beyond pi/2) and at every point of traced branches through
their folds.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
import scipy.linalg as la

from cosserat_chain.linalg import BANDWIDTH, BandMatrix
from cosserat_chain.models.base import get_model
from cosserat_chain.numerics.continuation import continue_in_moment
from cosserat_chain.numerics.stability import DynamicStability, dynamic_stability, sine_theorem_stability
from cosserat_chain.params import ChainParams
from cosserat_chain.state import pack, per_dof, zero_held

ENDS = [("clamped", "clamped"), ("clamped", "free"), ("pinned", "pinned"), ("clamped", "pinned"), ("free", "free")]


def _random_band(rng: np.random.Generator, n: int) -> np.ndarray:
    """Band storage of a random n x n matrix of half-bandwidth BANDWIDTH, some entries -0.0, the padding zero."""
    data = np.zeros((n + 2 * BANDWIDTH, 2 * BANDWIDTH + 1))
    for i in range(n):
        for t in range(2 * BANDWIDTH + 1):
            if 0 <= i + t - BANDWIDTH < n:
                data[BANDWIDTH + i, t] = rng.choice([rng.normal(), 0.0, -0.0])
    return data


@pytest.mark.parametrize("n", [1, 4, 11, 30])
def test_band_toarray_and_scaled_are_numpys_arithmetic_entry_by_entry(n):
    rng = np.random.default_rng(n)
    band = BandMatrix(_random_band(rng, n))
    dense = band.toarray()
    assert np.array_equal(dense, band.tocsr().toarray())
    assert not np.any(np.signbit(dense[dense == 0.0]))  # every zero +0.0, as CSR's dense form has it
    d = rng.uniform(0.1, 3.0, n)
    scaled = band.scaled(d)
    assert isinstance(scaled, BandMatrix) and scaled.shape == (n, n)
    assert np.array_equal(scaled.toarray(), d[:, None] * dense * d[None, :])  # (M_ij d_i) d_j, the same bits
    assert not np.any(scaled.data[:BANDWIDTH]) and not np.any(scaled.data[n + BANDWIDTH :])  # the padding stays zero


def test_band_scaled_names_a_diagonal_of_the_wrong_length():
    band = BandMatrix(np.zeros((3 + 2 * BANDWIDTH, 2 * BANDWIDTH + 1)))
    with pytest.raises(ValueError, match=r"diagonal must have length 3 .*got shape \(4,\)"):
        band.scaled(np.ones(4))


def _reference(params: ChainParams, model: str, x: np.ndarray, tolerance: float) -> tuple[int, int, int, int]:
    """(unstable eigenvalues, real ones, complex pairs, K's negative real parts) from LAPACK, unscaled and dense."""
    stiffness = get_model(model).stiffness(params, x).toarray()
    mass = pack(params, params.particle_inertia)
    n = mass.size
    a = np.zeros((2 * n, 2 * n))
    a[:n, n:] = np.diag(1.0 / mass)
    a[n:, :n] = -stiffness
    a[n:, n:] = -np.diag(per_dof(params, params.damping) / mass)
    values = la.eigvals(a)
    unstable = values[values.real > tolerance]
    real = int(np.sum(np.abs(unstable.imag) <= 1e-8 * max(1.0, float(np.max(np.abs(unstable), initial=0.0)))))
    k = la.eigvals(stiffness).real
    return unstable.size, real, (unstable.size - real) // 2, int(np.sum(k < -1e-9 * max(1.0, float(np.max(np.abs(k))))))


def _agrees(params: ChainParams, model: str, x: np.ndarray, verdict: DynamicStability) -> None:
    unstable, real, pairs, index = _reference(params, model, x, verdict.tolerance)
    assert (verdict.unstable_eigenvalues, verdict.unstable_real, verdict.unstable_pairs) == (unstable, real, pairs)
    assert verdict.stiffness_index == index and verdict.stable == (unstable == 0)


@pytest.mark.parametrize("case", range(40))
def test_the_banded_verdict_is_lapacks_on_random_chains_and_states(case):
    rng = np.random.default_rng(4400 + case)
    left, right = ENDS[case % len(ENDS)]
    params = ChainParams(
        N=int(rng.integers(1, 9)), a=float(rng.uniform(0.05, 0.45)), b=float(rng.uniform(0.05, 0.45)),
        E1=float(rng.uniform(0.3, 3.0)), E2=float(rng.uniform(0.3, 3.0)), left_end=left, right_end=right,
        gamma_u=float(rng.choice([0.02, 0.1, 0.4])), gamma_v=0.1, gamma_phi=float(rng.choice([0.01, 0.1, 0.3])),
    )  # fmt: skip
    x = rng.normal(0.0, 0.05, (3, params.n_particles))
    x[2] = rng.normal(0.0, 1.2, params.n_particles)  # a third of the angles beyond pi/2: K indefinite
    x = zero_held(params, x)
    for model in ("sine", "nonlinear", "linear"):
        verdict = dynamic_stability(params, model, x, method="dense")
        _agrees(params, model, x, verdict)
        theorem = sine_theorem_stability(params, model, x)
        if theorem is not None:  # eq. (2) with every free angle within pi/2: stable, and as the eigenvalues say
            assert theorem.stable and verdict.stable and theorem.stiffness_index == verdict.stiffness_index == 0
            assert theorem.tolerance == verdict.tolerance


@pytest.mark.parametrize(
    ("model", "geometry"),
    [("sine", {"N": 2}), ("sine", {"N": 3, "a": 0.3, "b": 0.1, "E1": 2.0, "E2": 0.3}), ("nonlinear", {"N": 3})],
)
def test_the_banded_verdict_is_lapacks_along_a_branch_through_its_folds(model, geometry):
    params = ChainParams(**geometry)
    branch = continue_in_moment(params, model, phi0_stop=2 * math.pi)
    assert len(branch.folds) >= 2  # the trace passes its folds: K turns indefinite and definite again
    indices = set()
    for x in branch.x:
        verdict = dynamic_stability(params, model, x)
        _agrees(params, model, x, verdict)
        indices.add(verdict.stiffness_index)
    assert {0, 1} <= indices
