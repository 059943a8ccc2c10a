"""Solves of a band matrix bordered by one column e_dof and one dense row: the statics' pseudo-arclength systems.

Contract
--------
For K within the band (:mod:`.band`), a degree of freedom ``dof`` and a row r of length n + 1,

    B = [[-K, e_dof], [r^T]]

is the Jacobian of (F(q) + M e_dof, r . (q, M)) in the unknowns (q, M): a continuation's
corrector and tangent (r its tangent), and with r = e_dof the rotation-controlled Newton
(:func:`rotation_controlled_jacobian`: -K with column ``dof`` replaced by e_dof). B stays
regular at a fold of the load-controlled problem, where K is singular.

:class:`BorderedFactor` factors -K once (:func:`~.band.negated_lu`, O(n w^2)) and solves
with any border row in O(n w) each; :func:`bordered_solve` is one such solve;
:func:`sparse_solve` is SuperLU's solve of any banded or bordered matrix in the same
elimination order, the fallback where the band factor meets a zero pivot, and the
reference it is tested against. Every solve takes one step of iterative refinement.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
from numba import njit

from .band import BANDWIDTH, BandMatrix, negated_lu


def rotation_controlled_jacobian(stiffness: sp.spmatrix, dof: int) -> sp.csc_matrix:
    """d/d(q without q[dof], M) of F(q) + M e_dof: -K with column ``dof`` replaced by e_dof (O(nnz))."""
    jac = (-stiffness).tocsc()
    first, last = jac.indptr[dof], jac.indptr[dof + 1]
    data = np.concatenate([jac.data[:first], [1.0], jac.data[last:]])
    indices = np.concatenate([jac.indices[:first], [dof], jac.indices[last:]]).astype(jac.indices.dtype)
    indptr = jac.indptr.copy()
    indptr[dof + 1 :] -= last - first - 1
    return sp.csc_matrix((data, indices, indptr), shape=jac.shape)


def bordered_jacobian(stiffness: sp.spmatrix, dof: int, row: np.ndarray) -> sp.csc_matrix:
    """The pseudo-arclength matrix [[-K, e_dof], [row^T]] of the unknowns (q, M), square, O(nnz).

    Every column of -K gains its entry of the dense last row at its end (row index
    n, the largest), and the last column holds e_dof and row[n].
    """
    jac = (-stiffness).tocsc()
    jac.sort_indices()
    n = jac.shape[0]
    data = np.insert(jac.data, jac.indptr[1:], row[:n])
    indices = np.insert(jac.indices, jac.indptr[1:], n)
    indptr = np.concatenate([jac.indptr + np.arange(n + 1), [jac.indptr[-1] + n + 2]])
    data = np.concatenate([data, [1.0, row[n]]])
    indices = np.concatenate([indices, [dof, n]])
    return sp.csc_matrix((data, indices.astype(np.int32), indptr.astype(np.int32)), shape=(n + 1, n + 1))


@njit(cache=True, nogil=True)
def _band_column(band, dof):  # pragma: no cover - compiled
    """L^-1 e_dof with -K's band LU (:func:`~.band.negated_lu`): the eliminated last column of the bordered matrix."""
    n = band.shape[0] - BANDWIDTH
    last_column = np.zeros(n + BANDWIDTH)
    last_column[dof] = 1.0
    for j in range(dof, n):  # zero above dof
        for i in range(1, BANDWIDTH + 1):
            last_column[j + i] -= band[j + i, BANDWIDTH - i] * last_column[j]
    return last_column


@njit(cache=True, nogil=True)
def _band_row(band, inverse, last_column, row):  # pragma: no cover - compiled
    """The eliminated last row (U^T l = row) and corner (row[n] - l . L^-1 e_dof) of the bordered matrix."""
    n = band.shape[0] - BANDWIDTH
    last_row = np.zeros(n + BANDWIDTH)
    for j in range(n):  # a loop: a slice assignment compiles numba's shape-mismatch message
        last_row[j] = row[j]
    corner = row[n]
    for j in range(n):
        factor = last_row[j] * inverse[j]
        last_row[j] = factor
        for t in range(1, BANDWIDTH + 1):
            last_row[j + t] -= factor * band[j, BANDWIDTH + t]
        corner -= factor * last_column[j]
    return last_row, corner


@njit(cache=True, nogil=True)
def _band_border_solve(band, inverse, stiffness, last_column, last_row, corner, dof, row, rhs, refine):  # pragma: no cover - compiled
    """Solve [[-K, e_dof], [row^T]] x = rhs with -K's band LU (:func:`~.band.negated_lu`) and its border.

    The border (:func:`_band_column`, :func:`_band_row`) costs O(n w) on top of the
    factor; together they are the elimination of the whole bordered matrix without
    pivoting. ``refine`` steps of iterative refinement with the same factor follow. Both
    substitutions go row by row and carry the last B unknowns solved in registers
    (B = :data:`~.band.BANDWIDTH` = 5), subtracting the term of the one
    solved last at the end: only one multiply-add a row waits for it, and none waits on a
    store and its reload (timings: benchmarks/TIMINGS.md). The forward one adds its terms
    in the order of the column sweep it replaced, so the solution is the same bit for bit.
    """
    n = band.shape[0] - BANDWIDTH
    solution = np.zeros(n + 1)
    residual = rhs.copy()
    y = np.zeros(n)
    padded = np.zeros(n + 2 * BANDWIDTH if refine else 0)  # the solution with BANDWIDTH zeros either side
    for sweep in range(refine + 1):
        border = residual[n]
        y1 = y2 = y3 = y4 = y5 = 0.0
        for i in range(n):  # L y = b
            total = residual[i] - band[i, 0] * y5
            total -= band[i, 1] * y4
            total -= band[i, 2] * y3
            total -= band[i, 3] * y2
            total -= band[i, 4] * y1
            y[i] = total
            border -= last_row[i] * total
            y5, y4, y3, y2, y1 = y4, y3, y2, y1, total
        border /= corner
        x1 = x2 = x3 = x4 = x5 = 0.0
        for j in range(n - 1, -1, -1):  # U x = y
            total = y[j] - last_column[j] * border - band[j, 10] * x5
            total -= band[j, 9] * x4
            total -= band[j, 8] * x3
            total -= band[j, 7] * x2
            value = (total - band[j, 6] * x1) * inverse[j]
            solution[j] += value
            x5, x4, x3, x2, x1 = x4, x3, x2, x1, value
        solution[n] += border
        if sweep == refine:
            break
        # residual = rhs - B solution, with the matrix as given (``stiffness``: K's storage)
        for i in range(n):  # a loop: a slice assignment compiles numba's shape-mismatch message
            padded[BANDWIDTH + i] = solution[i]
        for i in range(n):
            total = rhs[i] - (solution[n] if i == dof else 0.0)
            for t in range(2 * BANDWIDTH + 1):
                total += stiffness[i + BANDWIDTH, t] * padded[i + t]
            residual[i] = total
        total = rhs[n] - row[n] * solution[n]
        for k in range(n):
            total -= row[k] * solution[k]
        residual[n] = total
    return solution


class BorderedFactor:
    """The factor of -K for solving [[-K, e_dof], [row^T]] x = rhs with any border row, O(N) a solve.

    The O(n w^2) elimination of the band is done once (:func:`~.band.negated_lu`); each
    :meth:`solve` adds its row's border in O(n w) (:func:`_band_border_solve`), one step
    of refinement, and falls back to :func:`sparse_solve` of :func:`bordered_jacobian`
    at a zero pivot or a non-finite result. The continuation's tangent at a point and
    the chord corrector of the next step share one factor this way.
    """

    def __init__(self, stiffness: sp.spmatrix | BandMatrix, dof: int):
        if not isinstance(stiffness, BandMatrix) and not (sp.issparse(stiffness) and stiffness.format == "csr"):
            stiffness = sp.csr_matrix(stiffness)
        self.stiffness, self.dof = stiffness, dof
        try:
            band = stiffness if isinstance(stiffness, BandMatrix) else BandMatrix.from_sparse(stiffness)
        except ValueError:  # wider than the band (a ring's corner blocks): the sparse solver
            self._ok = False
        else:
            self._stiffness_data = band.data
            self._band, self._inverse, self._ok = negated_lu(band.data)
        self._column = _band_column(self._band, dof) if self._ok else None
        self._row: tuple[np.ndarray, np.ndarray, float] | None = None  # the last border row and its elimination

    @property
    def negative_eigenvalues(self) -> int | None:
        """The number of negative eigenvalues of a symmetric K, from the inertia of its factor; None without one.

        The LU of -K without pivoting is -K = L U with U = -D L^T for K = L D L^T, so
        (Sylvester's law of inertia) K has as many negative eigenvalues as U has positive
        pivots: free where the factor is made anyway (a continuation's tangent). Meaningless
        for a non-symmetric K.
        """
        return int(np.count_nonzero(self._inverse > 0.0)) if self._ok else None

    def solve(self, row: np.ndarray, rhs: np.ndarray, *, refine: int = 1) -> np.ndarray:
        """x with [[-K, e_dof], [row^T]] x = rhs; ``row`` and ``rhs`` of length n_free + 1.

        ``refine``: steps of iterative refinement (a chord corrector's inexact steps need none).
        The last row's elimination is kept for the next solve with the same row.
        """
        out = None
        row = np.asarray(row, float)
        if self._ok:
            if self._row is None or not (self._row[0] is row or np.array_equal(self._row[0], row)):
                self._row = (row.copy(), *_band_row(self._band, self._inverse, self._column, row))
            _, last_row, corner = self._row
            if corner != 0.0:
                out = _band_border_solve(
                    self._band,
                    self._inverse,
                    self._stiffness_data,
                    self._column,
                    last_row,
                    corner,
                    self.dof,
                    row,
                    np.asarray(rhs, float),
                    refine,
                )
        if out is None or not np.all(np.isfinite(out)):
            k = self.stiffness.tocsr() if isinstance(self.stiffness, BandMatrix) else self.stiffness
            return sparse_solve(bordered_jacobian(k, self.dof, row), rhs)
        return out


def bordered_solve(stiffness: sp.spmatrix, dof: int, row: np.ndarray, rhs: np.ndarray) -> np.ndarray:
    """Solve the pseudo-arclength system [[-K, e_dof], [row^T]] x = rhs in O(N).

    Compiled banded elimination with one step of refinement (:class:`BorderedFactor`, quicker
    than SuperLU on the same elimination: benchmarks/TIMINGS.md); a zero pivot or
    a non-finite result falls back to :func:`sparse_solve` of :func:`bordered_jacobian`.
    """
    return BorderedFactor(stiffness, dof).solve(row, rhs)


def sparse_solve(matrix: sp.spmatrix, rhs: np.ndarray) -> np.ndarray:
    """Solve a banded system, or one bordered by a dense last row and column, in O(N).

    In the natural order and with diagonal pivots the fill stays in the band and the
    dense last row; SuperLU's default pivoting moved it up and filled the factor (benchmarks/TIMINGS.md). One step of refinement with the same
    factor recovers what the diagonal pivots lose; a factorisation that fails (a zero
    pivot) or gives a non-finite result falls back to the default pivoting.
    """
    import scipy.sparse.linalg as spla  # here, not at import: small chains' statics never use it

    matrix = sp.csc_matrix(matrix)
    try:
        lu = spla.splu(matrix, permc_spec="NATURAL", diag_pivot_thresh=0.0)
        out = lu.solve(rhs)
        out = out + lu.solve(rhs - matrix @ out)
    except RuntimeError:
        return spla.spsolve(matrix, rhs)
    return out if np.all(np.isfinite(out)) else spla.spsolve(matrix, rhs)
