"""The sine model's dynamic verdict by the theorem where every free angle is within pi/2 of rest (issue 44, item 5).

:func:`~cosserat_chain.numerics.stability.sine_theorem_stability` gives the verdict without
eigenvalues there; ``critical_point`` takes it at those points of its branch and LAPACK's dense
eigenvalues elsewhere. Both are checked against the dense eigenvalues of the damped dynamics at
every state: random states of random chains (damped, undamped, graded), and every point of the
branch of the paper's chain and of random geometries, with the Hopf points the dense search finds.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from conftest import random_geometries
from cosserat_chain.experiments.critical import critical_point
from cosserat_chain.numerics.hopf import hopf_points
from cosserat_chain.numerics.stability import THEOREM, dynamic_stability, sine_theorem_stability
from cosserat_chain.params import ChainParams
from cosserat_chain.state import free_columns, free_rows, zeros


def _verdict(s):
    return s.stable, s.unstable_eigenvalues, s.unstable_real, s.unstable_pairs, s.stiffness_index


def _state(params: ChainParams, rng: np.random.Generator, angle: float) -> np.ndarray:
    """A random state, its free angles uniform in (-angle, angle)."""
    x = zeros(params)
    rows, cols = free_rows(params), free_columns(params)
    x[rows, cols] = np.where(rows == 2, rng.uniform(-angle, angle, rows.size), rng.normal(0.0, 0.3, rows.size))
    return x


def _chains() -> list[ChainParams]:
    rng = np.random.default_rng(5)
    graded = ChainParams(
        N=3,
        E1_factors=tuple(rng.uniform(0.5, 2.0, 6)),
        E2_factors=tuple(rng.uniform(0.0, 2.0, 6)),
        m_factors=tuple(rng.uniform(0.5, 2.0, 7)),
    )
    return [
        *random_geometries(4, seed=21),
        ChainParams(N=4, gamma_u=0.0, gamma_v=0.0, gamma_phi=0.0),
        ChainParams(N=3, gamma_u=0.3, gamma_v=0.0, gamma_phi=0.002),
        ChainParams(N=2, left_end="pinned", right_end="pinned"),
        ChainParams(N=2, right_end="free"),
        graded,
    ]


@pytest.mark.parametrize("params", _chains(), ids=lambda p: f"N{p.N}_a{p.a:.2f}_g{p.gamma_u:g}_{p.left_end}_{p.right_end}")
def test_the_theorem_verdict_is_the_dense_eigenvalues_verdict_within_pi_over_2(params):
    rng = np.random.default_rng(params.N)
    for _ in range(6):
        x = _state(params, rng, 0.999 * math.pi / 2)
        theorem, dense = sine_theorem_stability(params, "sine", x), dynamic_stability(params, "sine", x, method="dense")
        assert theorem is not None and theorem.method == THEOREM
        assert _verdict(theorem) == _verdict(dense) == (True, 0, 0, 0, 0)
        assert theorem.tolerance == dense.tolerance and theorem.rightmost == () and math.isnan(theorem.spectral_abscissa)
        assert dense.spectral_abscissa <= dense.tolerance


def test_the_theorem_says_nothing_beyond_pi_over_2_nor_for_other_models_or_a_ring():
    params = ChainParams(N=3)
    x = _state(params, np.random.default_rng(1), 1.0)
    assert sine_theorem_stability(params, "sine", x) is not None
    for model in ("nonlinear", "linear"):
        assert sine_theorem_stability(params, model, x) is None
    beyond = x.copy()
    beyond[2, 4] = 2.0  # one free angle past pi/2: K has a negative eigenvalue, the dynamics a growing mode
    assert sine_theorem_stability(params, "sine", beyond) is None
    assert not dynamic_stability(params, "sine", beyond, method="dense").stable
    for other in (ChainParams(N=3, periodic=True), ChainParams(N=2, left_end="pinned", right_end="free")):
        # A ring and a chain with a rigid mode: left to the eigenvalues.
        assert sine_theorem_stability(other, "sine", _state(other, np.random.default_rng(2), 0.5)) is None


def _same_as_dense(params: ChainParams):
    """critical_point's result, its verdict at every point checked against the dense eigenvalues and its Hopf points
    against the dense search's."""
    result = critical_point(params, "sine")
    assert result.dynamics_from == "eigenvalues" and len(result.dynamics) == len(result.branch.x)
    dense = [dynamic_stability(params, "sine", x, method="dense") for x in result.branch.x]
    assert [_verdict(d) for d in result.dynamics] == [_verdict(d) for d in dense]
    for mine, reference in zip(result.dynamics, dense):
        if mine.method != THEOREM:
            assert mine == reference  # the same eigenvalues, bit for bit
    reference_hopf = hopf_points(params, "sine", result.branch, checks=dense)
    assert [h.as_dict() for h in result.hopf] == [h.as_dict() for h in reference_hopf]
    return result


# The paper's chain at N = 2 (its Hopf points) and 3 quick; random geometries and the longer chains slow.
@pytest.mark.parametrize(
    "params",
    [ChainParams(N=2), ChainParams(N=3), *(pytest.param(p, marks=pytest.mark.slow) for p in random_geometries(3, seed=8))],
    ids=lambda p: f"N{p.N}_a{p.a:.2f}",
)
def test_critical_point_verdicts_are_the_dense_eigenvalues_verdicts(params):
    # Both kinds of point are met: the theorem's (from rest and after the turn) and the eigenvalues' (beyond pi/2).
    result = _same_as_dense(params)
    assert sum(d.method == THEOREM for d in result.dynamics) > 0
    if params == ChainParams(N=2):
        # The paper's geometry at N = 2: four Hopf points on the unstable branch, between points the eigenvalues decide.
        assert len(result.hopf) == 4 and all(h.located for h in result.hopf)
        assert all(result.dynamics[i].method != THEOREM for h in result.hopf for i in (h.after_point, h.after_point + 1))


@pytest.mark.slow
@pytest.mark.parametrize("n", [10, 20, 30])
def test_critical_point_verdicts_are_the_dense_eigenvalues_verdicts_on_longer_chains(n):
    result = _same_as_dense(ChainParams(N=n))
    assert sum(d.method == THEOREM for d in result.dynamics) > len(result.dynamics) // 3
