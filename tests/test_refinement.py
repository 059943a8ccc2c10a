"""Solves refined with residuals in extended precision (``linalg.refinement``)."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from cosserat_chain.linalg import refined_solve


def biharmonic(n: int) -> sp.csr_matrix:
    """T^2 with T = tridiag(-1, 2, -1): integer entries, condition number about (2 n / pi)^4 (a clamped beam's)."""
    t = sp.diags([-np.ones(n - 1), 2 * np.ones(n), -np.ones(n - 1)], [-1, 0, 1], format="csr", dtype=np.int64)
    return (t @ t).tocsr()


@pytest.mark.skipif(np.finfo(np.longdouble).eps >= np.finfo(float).eps, reason="no extended precision on this platform")
def test_refinement_recovers_an_exact_integer_solution_far_better_than_a_double_solve():
    # Condition number about 1.6e15: a double-precision solve keeps about four digits; the
    # refined one's error is about cond times the extended type's eps (1e-19) at worst.
    n = 10_000
    matrix = biharmonic(n).astype(float)
    exact = np.random.default_rng(4).integers(-1000, 1000, n)
    rhs = (biharmonic(n) @ exact).astype(float)  # exact: integers
    plain = spla.spsolve(matrix.tocsc(), rhs)
    refined = refined_solve(matrix, rhs)
    scale = np.abs(exact).max()
    error = np.abs(refined.x - exact)
    assert error.max() < np.abs(plain - exact).max() / 100
    assert error.max() / scale < 1e-5
    # The refinement's own estimate bounds what it did not reach.
    assert np.all(error <= 10 * refined.uncertainty + 1e-12 * scale)
    assert refined.error == pytest.approx(refined.uncertainty.max() / np.abs(refined.x).max())
    # Another factor's solve (no fill-reducing order) refines to the same, within their estimates.
    other = refined_solve(matrix, rhs, spla.splu(matrix.tocsc(), permc_spec="NATURAL").solve)
    assert np.all(np.abs(other.x - refined.x) <= 10 * (other.uncertainty + refined.uncertainty) + 1e-12 * scale)


def test_a_well_conditioned_system_is_solved_to_round_off_and_a_singular_one_is_refused():
    matrix = biharmonic(50)
    exact = np.arange(-25, 25)
    refined = refined_solve(matrix.astype(float), (matrix @ exact).astype(float))
    assert np.abs(refined.x - exact).max() < 1e-12 and refined.steps <= 12
    assert refined.relative_error(10) < 1e-12
    singular = sp.csr_matrix(np.array([[1.0, 1.0], [1.0, 1.0]]))
    with pytest.raises(ValueError, match="singular"):
        refined_solve(singular, np.ones(2))
