"""The linear-algebra floor against dense NumPy/SciPy references on random band matrices, tiny ones included.

Each claim is checked on matrices of half-bandwidth up to :data:`~cosserat_chain.linalg.BANDWIDTH`
and sizes from 1 (where every loop runs its short first rows only) to 40, with no chain or
model in sight: the floor knows neither.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
import scipy.linalg as la
import scipy.sparse as sp

from cosserat_chain.linalg import (
    BANDWIDTH,
    BandMatrix,
    BorderedFactor,
    band_storage,
    bordered_jacobian,
    bordered_solve,
    dot,
    eigen,
    euclidean_norm,
    infinity_norm,
    largest_eigenvalue_bound,
    ldlt,
    lowest_real_eigenvalue,
    negated_lu,
    negative_count,
    rotation_controlled_jacobian,
    smallest_eigenvalue,
    sparse_solve,
)
from cosserat_chain.linalg.eigen import smallest_band_eigenvalue
from cosserat_chain.linalg.pencil import nearest_axis, shifted_solver, unstable_count
from test_layering import import_graph

SIZES = [1, 2, 3, 6, 11, 40]
#: Relative agreement asked of a solve of a well-conditioned (diagonally dominant) system with a dense one.
SOLVE_RTOL = 1e-12


def random_band(n: int, seed: int, *, symmetric: bool = False, dominant: bool = True, width: int = BANDWIDTH) -> np.ndarray:
    """A dense n x n matrix with entries at most ``width`` from the diagonal; diagonally dominant unless asked not to be."""
    rng = np.random.default_rng(seed)
    a = np.zeros((n, n))
    for k in range(-min(width, n - 1), min(width, n - 1) + 1):
        a += np.diag(rng.standard_normal(n - abs(k)), k)
    if symmetric:
        a = 0.5 * (a + a.T)
    if dominant:
        a += np.diag(np.sign(np.diag(a) + 0.1) * (np.abs(a).sum(axis=1) + 1.0))
    return a


def indefinite_band(n: int, seed: int) -> np.ndarray:
    """A symmetric band matrix with eigenvalues of both signs, well separated from zero."""
    a = random_band(n, seed, symmetric=True, dominant=False)
    return a + np.diag(np.where(np.arange(n) % 3 == 0, -4.0, 4.0))


@pytest.mark.parametrize("n", SIZES)
def test_the_band_lu_of_minus_m_multiplies_back_to_minus_m_and_solves_as_the_dense_solve(n):
    m = random_band(n, seed=n)
    band, inverse, ok = negated_lu(BandMatrix.from_sparse(m).data)
    assert ok
    lower, upper = np.eye(n), np.zeros((n, n))
    for i in range(n):
        for j in range(max(0, i - BANDWIDTH), min(n, i + BANDWIDTH + 1)):
            (lower if j < i else upper)[i, j] = band[i, BANDWIDTH + j - i]
    np.testing.assert_allclose(inverse, 1.0 / np.diag(upper), rtol=1e-15)
    np.testing.assert_allclose(lower @ upper, -m, rtol=0, atol=SOLVE_RTOL * np.abs(m).max())
    rhs = np.random.default_rng(n + 100).standard_normal(n)
    x = la.solve_triangular(upper, la.solve_triangular(lower, rhs, lower=True, unit_diagonal=True))
    np.testing.assert_allclose(x, np.linalg.solve(-m, rhs), rtol=SOLVE_RTOL, atol=SOLVE_RTOL * np.abs(x).max())


def test_the_band_lu_reports_a_zero_pivot():
    m = random_band(8, seed=1)
    m[0, 0] = 0.0
    assert not negated_lu(BandMatrix.from_sparse(m).data)[2]


@pytest.mark.parametrize("n", SIZES)
def test_the_ldlt_inertia_counts_the_eigenvalues_below_every_shift(n):
    m = indefinite_band(n, seed=2 * n)
    eigenvalues = np.linalg.eigvalsh(m)
    storage = band_storage(sp.csr_matrix(m))
    # Shifts between consecutive eigenvalues and beyond both ends: the count is exact there.
    shifts = np.concatenate([[eigenvalues[0] - 1.0], 0.5 * (eigenvalues[1:] + eigenvalues[:-1]), [eigenvalues[-1] + 1.0]])
    for shift in shifts:
        assert negative_count(storage, shift) == int(np.sum(eigenvalues < shift))
    assert negative_count(storage, 0.0) == int(np.sum(eigenvalues < 0.0))
    # The factor itself: L D L^T = M - s I.
    shift = shifts[len(shifts) // 2]
    factor, inverse = np.zeros((storage.shape[0], BANDWIDTH + 1)), np.zeros(storage.shape[0])
    ldlt(storage, shift, factor, inverse)
    lower = np.eye(n)
    for i in range(n):
        for d in range(1, min(i, BANDWIDTH) + 1):
            lower[i, i - d] = factor[BANDWIDTH + i, d]
    d = 1.0 / inverse[BANDWIDTH : n + BANDWIDTH]
    np.testing.assert_allclose(lower @ np.diag(d) @ lower.T, m - shift * np.eye(n), atol=1e-11 * np.abs(m).max())


@pytest.mark.parametrize("n", SIZES)
def test_the_bordered_solve_equals_the_dense_solve_of_the_bordered_matrix(n):
    rng = np.random.default_rng(3 * n)
    for symmetric in (False, True):
        k = random_band(n, seed=3 * n + symmetric, symmetric=symmetric)
        dof = int(rng.integers(n))
        row, rhs = rng.standard_normal(n + 1), rng.standard_normal(n + 1)
        bordered = np.zeros((n + 1, n + 1))
        bordered[:n, :n], bordered[dof, n], bordered[n] = -k, 1.0, row
        exact = np.linalg.solve(bordered, rhs)
        csr = sp.csr_matrix(k)
        assert np.array_equal(bordered_jacobian(csr, dof, row).toarray(), bordered)
        replaced = -k.copy()
        replaced[:, dof] = np.eye(n)[dof]
        assert np.array_equal(rotation_controlled_jacobian(csr, dof).toarray(), replaced)
        bound = SOLVE_RTOL * np.linalg.cond(bordered) * max(1.0, np.abs(exact).max())
        factor = BorderedFactor(BandMatrix.from_sparse(csr), dof)
        for solution in (bordered_solve(csr, dof, row, rhs), factor.solve(row, rhs), factor.solve(row, rhs, refine=0)):
            assert np.max(np.abs(solution - exact)) <= bound
        assert np.max(np.abs(sparse_solve(sp.csc_matrix(bordered), rhs) - exact)) <= bound
        if symmetric:
            # Sylvester: the LU of -K without pivoting has as many positive pivots as K negative eigenvalues.
            assert factor.negative_eigenvalues == int(np.sum(np.linalg.eigvalsh(k) < 0))


def test_the_bordered_solve_falls_back_at_a_zero_pivot_and_beyond_the_band():
    n = 12
    rng = np.random.default_rng(5)
    row, rhs = rng.standard_normal(n + 1), rng.standard_normal(n + 1)
    zero_pivot = random_band(n, seed=6)
    zero_pivot[0, 0] = 0.0
    for k in (zero_pivot, random_band(n, seed=7, width=BANDWIDTH + 2)):
        bordered = np.zeros((n + 1, n + 1))
        bordered[:n, :n], bordered[0, n], bordered[n] = -k, 1.0, row
        assert np.linalg.cond(bordered) < 1e6
        factor = BorderedFactor(sp.csr_matrix(k), 0)
        assert not factor._ok  # the band factor cannot: the solve is SuperLU's
        np.testing.assert_allclose(factor.solve(row, rhs), np.linalg.solve(bordered, rhs), rtol=1e-10, atol=1e-10)


@pytest.mark.parametrize("n", SIZES)
def test_inverse_iteration_finds_the_smallest_eigenvalue_from_any_guess_and_leaves_its_eigenvector(n):
    m = indefinite_band(n, seed=4 * n)
    eigenvalues, vectors = np.linalg.eigh(m)
    value, resolution = smallest_eigenvalue(sp.csr_matrix(m))
    assert abs(value - eigenvalues[0]) <= max(resolution, 1e-12 * np.abs(eigenvalues).max())
    storage = band_storage(sp.csr_matrix(m))
    radius = float(np.abs(m).sum(axis=1).max())
    for guess in (None, eigenvalues[0], eigenvalues[0] - 3.0, eigenvalues[-1] + 2.0, 0.0):
        start = np.ones(n)
        found, bound = smallest_band_eigenvalue(storage, radius, guess, start)
        assert abs(found - eigenvalues[0]) <= 1e-12 * radius and bound <= found
        if n > 1 and eigenvalues[1] - eigenvalues[0] > 1e-3 * radius:
            # The start vector is left holding the lowest eigenvector (up to sign).
            assert abs(abs(start @ vectors[:, 0]) - 1.0) < 1e-8


@pytest.mark.parametrize("n", SIZES)
def test_the_largest_eigenvalue_bound_lies_just_above_the_largest_eigenvalue(n):
    m = random_band(n, seed=5 * n, symmetric=True, dominant=False)
    largest = np.linalg.eigvalsh(m)[-1]
    bound = largest_eigenvalue_bound(sp.csr_matrix(m), 1e-10)
    gershgorin = np.abs(m).sum(axis=1).max()
    assert largest - 1e-13 * gershgorin <= bound <= largest + 1e-10 * gershgorin


def test_the_leftmost_eigenvalue_of_a_diagonally_symmetrisable_matrix_equals_the_dense_one(monkeypatch):
    n = 30
    d = np.random.default_rng(7).uniform(0.5, 2.0, n)
    symmetric = indefinite_band(n, seed=8)
    matrix = sp.csr_matrix(np.diag(d) @ symmetric @ np.diag(1.0 / d))
    dense = float(np.linalg.eigvalsh(symmetric)[0])
    monkeypatch.setattr(eigen, "DENSE_SPECTRUM_LIMIT", 0)  # the banded path, not the dense one
    assert lowest_real_eigenvalue(matrix).real == pytest.approx(dense, abs=1e-10)
    similar = eigen.diagonal_similar_symmetric(matrix)
    np.testing.assert_allclose(np.linalg.eigvalsh(similar.toarray()), np.linalg.eigvalsh(symmetric), atol=1e-10)


def _damped(k: np.ndarray, rate: np.ndarray) -> np.ndarray:
    n = k.shape[0]
    return np.block([[np.zeros((n, n)), np.eye(n)], [-k, -np.diag(rate)]])


@pytest.mark.parametrize("n", [1, 3, 11, 40])
def test_the_argument_principle_counts_the_damped_pencils_eigenvalues_right_of_the_axis(n):
    rng = np.random.default_rng(9 * n)
    rate = rng.uniform(0.2, 1.0, n)
    for k in (indefinite_band(n, seed=9 * n), random_band(n, seed=9 * n + 1, dominant=False) + 3.0 * np.eye(n)):
        tolerance = 1e-10 * max(math.sqrt(np.abs(k).sum(axis=1).max()), 1.0)
        dense = int(np.sum(np.linalg.eigvals(_damped(k, rate)).real > tolerance))
        assert unstable_count(sp.csr_matrix(k), rate, tolerance) == dense


@pytest.mark.parametrize("n", [6, 11, 40])
def test_shift_invert_finds_the_eigenvalues_nearest_the_shift(n):
    rng = np.random.default_rng(10 * n)
    rate = rng.uniform(0.2, 1.0, n)
    k = indefinite_band(n, seed=10 * n)
    eigenvalues = np.linalg.eigvals(_damped(k, rate))
    shift = 0.05
    found = shift + nearest_axis(shifted_solver(sp.csr_matrix(k), rate, shift), 2 * n, 0, 3)
    nearest = eigenvalues[np.argsort(np.abs(eigenvalues - shift))][: found.size]
    assert found.size >= 3
    for z in found:
        assert np.min(np.abs(nearest - z)) <= 1e-8 * max(1.0, abs(z))


@pytest.mark.parametrize("n", [0, 1, 7, 8, 9, 1000])
def test_norms_and_dots_equal_numpys_in_every_storage(n):
    rng = np.random.default_rng(n)
    a, b = rng.standard_normal(n), rng.standard_normal(n)
    assert abs(dot(a, b) - math.fsum(a * b)) <= 4 * max(n, 1) * np.finfo(float).eps * np.sum(np.abs(a * b))
    assert euclidean_norm(a) == pytest.approx(math.sqrt(math.fsum(a * a)), rel=1e-14, abs=0.0)
    if 0 < n <= 40:
        m = random_band(n, seed=n, dominant=False)
        expected = np.abs(m).sum(axis=1).max()
        for matrix in (sp.csr_matrix(m), sp.csc_matrix(m), BandMatrix.from_sparse(m), m):
            assert infinity_norm(matrix) == pytest.approx(expected, rel=1e-15)


def test_the_floor_imports_nothing_of_the_package_above_it():
    graph = import_graph(deferred=True)
    floor = {name for name in graph if name.startswith("cosserat_chain.linalg")}
    assert len(floor) >= 6
    allowed = floor | {"cosserat_chain.memory", "cosserat_chain.status", "cosserat_chain.errors"}
    above = {name: sorted(graph[name] - allowed) for name in floor if graph[name] - allowed}
    assert not above, f"the linear-algebra floor imports modules above it: {above}"


@pytest.mark.parametrize("size", [1, 2, 5, 17])
def test_general_solve_append_row_and_determinant_sign_agree_dense_and_sparse(size):
    """The continuation kit's dense-or-sparse helpers: the same answers in both kinds, the determinant's
    sign against NumPy's (random permuted matrices, so SuperLU pivots and the parities count)."""
    import scipy.sparse as sparse

    from cosserat_chain.linalg.general import append_row, determinant_sign, solve

    rng = np.random.default_rng(size)
    for _ in range(5):
        dense = rng.normal(size=(size, size)) * (rng.random((size, size)) < 0.5) + np.diag(rng.normal(size=size))
        dense = dense[rng.permutation(size)]
        if abs(np.linalg.det(dense)) < 1e-8:
            continue
        rhs = rng.normal(size=size)
        np.testing.assert_allclose(solve(sparse.csr_matrix(dense), rhs), np.linalg.solve(dense, rhs), rtol=1e-10, atol=1e-12)
        assert determinant_sign(sparse.csr_matrix(dense)) == determinant_sign(dense) == np.sign(np.linalg.det(dense))
        row = rng.normal(size=size)
        np.testing.assert_array_equal(append_row(sparse.csr_matrix(dense[:-1]), row).toarray(), append_row(dense[:-1], row))
    assert determinant_sign(sparse.csr_matrix((size, size))) == 0.0


@pytest.mark.parametrize("n", [1, 5, 40])
@pytest.mark.parametrize("pivoting", [1.0, 0.01])
def test_a_core_with_its_column_solves_as_the_dense_bordered_matrix(n, pivoting):
    from cosserat_chain.linalg.general import CoreAndColumn

    rng = np.random.default_rng(n)
    core = sp.random(n, n, density=0.3, random_state=rng) + sp.identity(n) * (2.0 + n / 10)
    column, row, rhs = rng.standard_normal(n), rng.standard_normal(n + 1), rng.standard_normal(n + 1)
    matrix = CoreAndColumn(core, column, pivoting=pivoting)
    dense = np.vstack([np.column_stack([core.toarray(), column]), row])
    np.testing.assert_allclose(matrix.solve(row, rhs), np.linalg.solve(dense, rhs), rtol=1e-10, atol=1e-12)
    np.testing.assert_allclose(matrix.solve_core(rhs[:-1]), np.linalg.solve(core.toarray(), rhs[:-1]), rtol=1e-10, atol=1e-12)
    np.testing.assert_array_equal(matrix.tocsc().toarray(), dense[:-1])


def test_a_singular_core_with_a_regular_border_is_solved_whole():
    from cosserat_chain.linalg.general import CoreAndColumn

    # A fold of x^2 + lambda = 0 at x = 0 (2 x is singular there): [[0, 1], [t]] is regular.
    matrix = CoreAndColumn(sp.csc_matrix([[0.0]]), np.array([1.0]))
    np.testing.assert_allclose(matrix.solve(np.array([1.0, 0.0]), np.array([0.0, 1.0])), [1.0, 0.0])


def test_arpacks_eigenvalues_are_the_same_bits_at_every_call():
    """ARPACK's own start vector is random: the lowest real eigenvalue of a large non-symmetric matrix (the
    sparse path) and the merged largest/nearest sets changed in their last digits from call to call; the package
    starts it from a fixed vector. The value is also checked against LAPACK on the dense matrix."""
    from cosserat_chain.linalg.eigen import DENSE_SPECTRUM_LIMIT, largest_and_nearest, lowest_real_eigenvalue

    rng = np.random.default_rng(5)
    n = DENSE_SPECTRUM_LIMIT + 40
    matrix = (sp.diags(np.linspace(1.0, 50.0, n)) + sp.random(n, n, density=4 / n, random_state=rng) * 0.3).tocsr()
    first = lowest_real_eigenvalue(matrix)
    dense = np.linalg.eigvals(matrix.toarray())
    assert first == pytest.approx(dense[np.argmin(dense.real)], abs=1e-9)
    for _ in range(3):
        assert lowest_real_eigenvalue(matrix) == first

    dense_matrix = matrix.toarray()
    lu = la.lu_factor(dense_matrix - 20.0 * np.eye(n))

    def product(z):
        return dense_matrix @ z

    def inverse(z):
        return la.lu_solve(lu, z)

    values = largest_and_nearest(product, inverse, n, 20.0, 4, tol=1e-12, restarts=200)[0]
    for _ in range(2):
        assert np.array_equal(largest_and_nearest(product, inverse, n, 20.0, 4, tol=1e-12, restarts=200)[0], values)
