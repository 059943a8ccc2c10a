"""The mixed form of K by its rows (linalg.mixed, Model.stiffness_rows): the band LU's solves where K's entries hold,
and a long clamped chain's soft modes where they do not."""

from __future__ import annotations

import numpy as np
import pytest

from band_rows import dense_rows
from cosserat_chain import ChainParams
from cosserat_chain.analysis.timoshenko import clamped_central_compliance
from cosserat_chain.linalg import BandMatrix, BorderedFactor, MixedBorderedFactor, MixedFactor
from cosserat_chain.linalg.root import ROW_WIDTH
from cosserat_chain.models.base import get_model
from cosserat_chain.numerics.continuation import continue_in_moment
from cosserat_chain.numerics.newton import moment_dof
from cosserat_chain.state import n_free, unpack, zeros

GEOMETRIES = [
    ChainParams(N=7),
    ChainParams(N=7, right_end="free"),
    ChainParams(N=7, left_end="pinned", right_end="pinned"),
    ChainParams(N=7, right_end="pinned", a=0.35, b=0.15, E1=2.0, E2=0.4),
]


def _state(params: ChainParams, scale: float, seed: int) -> np.ndarray:
    return unpack(params, scale * np.random.default_rng(seed).standard_normal(n_free(params)))


def test_the_mixed_factor_solves_with_l_t_r_plus_g():
    rng = np.random.default_rng(5)
    n = 30
    starts = np.sort(np.concatenate([np.arange(n), rng.integers(0, n, size=20)]))
    left = rng.standard_normal((starts.size, ROW_WIDTH))
    left[starts[:, None] + np.arange(ROW_WIDTH) >= n] = 0.0
    right = left + 0.1 * rng.standard_normal(left.shape) * (left != 0.0)
    g = np.diag(rng.standard_normal(n)) + np.diag(rng.standard_normal(n - 5), 5) + np.diag(rng.standard_normal(n - 5), -5)
    k = dense_rows(left, starts, n).T @ dense_rows(right, starts, n) + g
    factor = MixedFactor(left, right, starts, n, BandMatrix.from_sparse(g))
    q = rng.standard_normal(n)
    np.testing.assert_allclose(factor.apply(q), k @ q, rtol=0, atol=1e-12 * np.abs(k).max() * np.abs(q).max())
    np.testing.assert_allclose(factor.solve(q), np.linalg.solve(k, q), rtol=1e-9)


def test_the_mixed_factor_refuses_rows_out_of_order_or_of_the_wrong_width():
    with pytest.raises(ValueError, match="ordered by their first column"):
        MixedFactor(np.ones((2, ROW_WIDTH)), np.ones((2, ROW_WIDTH)), np.array([3, 1]), 10)
    with pytest.raises(ValueError, match=r"must be \(rows, 6\)"):
        MixedFactor(np.ones((2, 4)), np.ones((2, 4)), np.array([0, 1]), 10)


@pytest.mark.parametrize("model", ["nonlinear", "sine"])
@pytest.mark.parametrize("params", GEOMETRIES)
def test_the_rows_sum_to_the_stiffness(model, params):
    """L^T R + G is the model's K at a state far from rest (large angles: tensions, cos phi of either sign)."""
    x = _state(params, 0.8, 2)
    rows = get_model(model).stiffness_rows(params, x)
    n = n_free(params)
    k = get_model(model).stiffness(params, x).toarray()
    total = dense_rows(rows.left, rows.starts, n).T @ dense_rows(rows.right, rows.starts, n)
    if rows.g is not None:
        total += rows.g.toarray()
    np.testing.assert_allclose(total, k, rtol=0, atol=1e-13 * np.abs(k).max())


def test_the_tension_part_vanishes_at_rest():
    """At rest every link has its rest length (to the rounding of L - L0): G is round-off, K is J^T J."""
    params = ChainParams(N=5)
    assert np.abs(get_model("nonlinear").stiffness_rows(params, zeros(params)).g.data).max() <= 1e-14
    assert get_model("linear").stiffness_rows(params, zeros(params)) is None


@pytest.mark.parametrize("model", ["nonlinear", "sine"])
@pytest.mark.parametrize(
    "n_chain, params_kw, seed", [(100, {}, 1), (300, {"a": 0.35, "b": 0.15, "E1": 2.0, "E2": 0.4}, 2), (1000, {"right_end": "pinned"}, 3)]
)
def test_the_mixed_bordered_solve_is_the_band_one(model, n_chain, params_kw, seed):
    """Where K's entries hold (N <= 1000), both factors solve the pseudo-arclength system to round-off (eps cond K)."""
    params = ChainParams(N=n_chain, **params_kw)
    x = _state(params, 0.3 / n_chain, seed)
    m = get_model(model)
    band, dof = m.stiffness_band(params, x), moment_dof(params, 0)
    rng = np.random.default_rng(seed)
    row, rhs = rng.standard_normal(n_free(params) + 1), rng.standard_normal(n_free(params) + 1)
    expected = BorderedFactor(band, dof).solve(row, rhs)
    found = MixedBorderedFactor(MixedFactor.from_rows(m.stiffness_rows(params, x), n_free(params)), band, dof).solve(row, rhs)
    condition = float(n_chain) ** 4  # K's: its softest eigenvalue falls like N^-4
    np.testing.assert_allclose(found, expected, rtol=0, atol=1e-16 * condition * np.abs(expected).max())


@pytest.mark.parametrize("model, fold", [("nonlinear", 0.16625561012940132), ("sine", 0.006399731215050738)])
def test_a_trace_in_the_mixed_form_finds_the_band_traces_fold(model, fold):
    """The first fold of N = 100 (`benchmarks/results/critical_scaling_models.json`), the trace's every solve mixed."""
    branch = continue_in_moment(ChainParams(N=100), model, max_folds=1, mixed=True)
    assert branch.folds[0].moment == pytest.approx(fold, rel=1e-10)


def test_the_mixed_form_keeps_the_bending_mode_that_the_band_lu_loses():
    """N = 3 10^4 at rest: the band LU's compliance is 33 % off the closed form; the mixed form's is the sine model's
    to round-off and the nonlinear model's to 1.5e-7, what the tensions of one ulp of L - L0 at rest make of the
    bending mode (a prestress of eps E moves its eigenvalue by about eps N^2 of itself)."""
    params = ChainParams(N=30_000)
    exact = clamped_central_compliance(params, nodal=True)
    dof = moment_dof(params, 0)
    seed = np.zeros(n_free(params) + 1)
    seed[-1] = 1.0
    for model, rel in (("nonlinear", 1e-6), ("sine", 1e-13)):
        m = get_model(model)
        band = m.stiffness_band(params, zeros(params))
        mixed = MixedBorderedFactor(MixedFactor.from_rows(m.stiffness_rows(params, zeros(params)), n_free(params)), band, dof)
        assert mixed.solve(seed, seed)[dof] == pytest.approx(exact, rel=rel)
        assert abs(BorderedFactor(band, dof).solve(seed, seed)[dof] / exact - 1) > 0.1


@pytest.mark.slow
def test_the_first_fold_of_n_3e4_in_the_mixed_form_is_the_band_traces_confirmed_one():
    """From the approach, every solve mixed: the fold the band trace from rest found and the
    re-solve confirmed, 0.04689566864700 (docs/statics.md)."""
    branch = continue_in_moment(ChainParams(N=30_000), "nonlinear", max_folds=1, from_approach=True, mixed=True)
    assert branch.folds[0].moment == pytest.approx(0.04689566864700, rel=1e-11)
