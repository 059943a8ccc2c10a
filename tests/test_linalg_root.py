"""Solves through K's square root (linalg.root, models.linear.rest_solve): a long clamped chain's compliance to round-off."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp

from band_rows import dense_rows
from cosserat_chain import ChainParams
from cosserat_chain.analysis.timoshenko import clamped_central_compliance
from cosserat_chain.linalg import BorderedFactor, RootFactor
from cosserat_chain.linalg.root import ROW_WIDTH
from cosserat_chain.models.base import get_model
from cosserat_chain.models.linear import rest_solve, stiffness_matrix, stiffness_root
from cosserat_chain.numerics.continuation import compliance
from cosserat_chain.numerics.newton import moment_dof
from cosserat_chain.state import n_free, zeros


def test_the_root_factor_is_the_cholesky_factor_of_a_t_a_and_solves_with_it():
    rng = np.random.default_rng(3)
    n = 40
    starts = np.sort(np.concatenate([np.arange(n), rng.integers(0, n, size=50)]))
    values = rng.standard_normal((starts.size, ROW_WIDTH))
    values[np.r_[0, np.flatnonzero(np.diff(starts)) + 1], 0] += 4.0  # a leading entry in every column: A^T A regular
    values[starts[:, None] + np.arange(ROW_WIDTH) >= n] = 0.0
    a = dense_rows(values, starts, n)
    factor = RootFactor(values, starts, n)
    r = np.zeros((n, n))
    for j in range(n):
        width = min(ROW_WIDTH, n - j)
        r[j, j : j + width] = factor.r[j, :width]
    np.testing.assert_allclose(r.T @ r, a.T @ a, rtol=0, atol=1e-12 * np.abs(a.T @ a).max())
    b = rng.standard_normal(n)
    np.testing.assert_allclose(factor.solve(b), np.linalg.solve(a.T @ a, b), rtol=1e-10)


def test_the_root_factor_refuses_rows_out_of_order_or_beyond_the_last_column():
    values = np.ones((2, ROW_WIDTH))
    with pytest.raises(ValueError, match="ordered by their first column"):
        RootFactor(values, np.array([3, 1]), 10)
    with pytest.raises(ValueError, match="beyond its last column 9"):
        RootFactor(values, np.array([0, 5]), 10)
    with pytest.raises(ValueError, match=r"values must be \(rows, 6\)"):
        RootFactor(np.ones((2, 4)), np.array([0, 1]), 10)


@pytest.mark.parametrize(
    "params",
    [
        ChainParams(N=7),
        ChainParams(N=7, right_end="free"),
        ChainParams(N=7, left_end="pinned", right_end="pinned"),
        ChainParams(N=7, right_end="pinned", a=0.35, b=0.15, E1=2.0, E2=0.4),
    ],
)
def test_the_square_root_of_k_is_the_linear_stiffness(params):
    values, starts = stiffness_root(params)
    n = n_free(params)
    a = dense_rows(values, starts, n)
    k = stiffness_matrix(params).toarray()
    np.testing.assert_allclose(a.T @ a, k, rtol=0, atol=4 * np.finfo(float).eps * np.abs(k).max())
    b = np.random.default_rng(1).standard_normal(n)
    np.testing.assert_allclose(rest_solve(params, b), np.linalg.solve(k, b), rtol=1e-9)


def test_a_ring_has_no_banded_square_root():
    with pytest.raises(ValueError, match="ring"):
        stiffness_root(ChainParams(N=5, periodic=True))


def test_the_compliance_at_n_3e4_is_the_closed_form_where_a_factor_of_k_loses_the_bending_mode():
    """Before: 46874.485 (the refined SuperLU solve, 1.1e-5 off); the band LU the trace factors gives 31191 (33 % off)."""
    params = ChainParams(N=30_000)
    exact = clamped_central_compliance(params, nodal=True)
    for model in ("nonlinear", "sine", "linear"):
        assert compliance(params, model) == pytest.approx(exact, rel=1e-11)
    seed = np.zeros(n_free(params) + 1)
    seed[-1] = 1.0
    lost = BorderedFactor(get_model("nonlinear").stiffness_band(params, zeros(params)), moment_dof(params, 0)).solve(seed, seed)
    assert abs(lost[moment_dof(params, 0)] / exact - 1) > 0.1  # the mechanism: K's rounded entries lose its softest modes


def test_the_compliance_at_n_1e5_is_the_closed_form():
    """Before: 69602.2 (the refined solve, 55 % off the exact 156250.0000066)."""
    params = ChainParams(N=100_000)
    e = np.zeros(n_free(params))
    e[moment_dof(params, 0)] = 1.0
    value = rest_solve(params, e)[moment_dof(params, 0)]
    assert value == pytest.approx(clamped_central_compliance(params, nodal=True), rel=1e-11)
    assert sp.issparse(stiffness_matrix(ChainParams(N=3)))
