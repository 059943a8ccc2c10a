"""Dense-or-sparse matrices of any structure: solves, a row appended, the sign of the determinant.

The continuation kit (:mod:`cosserat_chain.numerics.kit`) takes a problem's Jacobian as it
comes, a dense array for a small system or a SciPy sparse matrix for a lattice of 10^4 sites;
these functions give both the same answers, sparse ones in O(nnz) memory.

A large sparse Jacobian with the continued parameter's column, n x (n + 1), is best given as
:class:`CoreAndColumn`: the pseudo-arclength system appends a dense row (the tangent) to it,
and SuperLU's partial pivoting then takes pivots from that row and fills the factor (four
times the core's alone for the extended system of a fold at N = 1000: benchmarks/TIMINGS.md).
Block elimination solves it with the core's factor and two of its solves.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp


def solve(matrix, rhs: np.ndarray) -> np.ndarray:
    """``matrix^-1 rhs`` for a dense array (LAPACK) or a sparse matrix (SuperLU).

    Raises
    ------
    numpy.linalg.LinAlgError
        For a singular dense matrix (a singular sparse one gives non-finite entries or raises RuntimeError).
    """
    if sp.issparse(matrix):
        import scipy.sparse.linalg as spla  # here, not at import: small chains' statics never use it

        return spla.spsolve(sp.csc_matrix(matrix), rhs)
    return np.linalg.solve(matrix, rhs)


class CoreAndColumn:
    """The n x (n + 1) matrix [A c]: a square sparse core A and one dense column c (a Jacobian with
    its continued parameter's column), solved with one LU of A.

    :meth:`solve` takes the system with a row appended, [[A, c], [r^T]] x = b, by block
    elimination (x_A = A^-1 b_A - xi A^-1 c) and one step of iterative refinement on the whole
    system; :meth:`solve_core` solves A x = b (the parameter held), refined the same way. Where A
    is singular to working precision (a point where the parameter turns), the whole system goes
    to SuperLU.

    ``pivoting`` is SuperLU's threshold for keeping a diagonal pivot (1: partial pivoting; a
    band with its borders ordered last fills far less with 0.01, the refinement step making up
    for the weaker pivots).
    """

    def __init__(self, core, column: np.ndarray, *, pivoting: float = 1.0):
        self.core = sp.csc_matrix(core)
        self.pivoting = pivoting
        self.column = np.asarray(column, dtype=float)
        if self.core.shape[0] != self.core.shape[1] or self.column.shape != (self.core.shape[0],):
            raise ValueError(f"CoreAndColumn needs a square core and one column of its size, got {self.core.shape} and {self.column.shape}")
        self.shape = (self.core.shape[0], self.core.shape[1] + 1)
        self._lu = None
        self._along = None  # A^-1 c

    def tocsc(self) -> sp.csc_matrix:
        """The matrix [A c] itself."""
        return sp.hstack([self.core, sp.csc_matrix(self.column[:, None])], format="csc")

    def _factor(self):
        if self._lu is None:
            import scipy.sparse.linalg as spla  # here, not at import: small chains' statics never use it

            self._lu = spla.splu(self.core, diag_pivot_thresh=self.pivoting)
            self._along = self._lu.solve(self.column)
        return self._lu

    def solve_core(self, rhs: np.ndarray) -> np.ndarray:
        """A^-1 rhs (RuntimeError where A is singular)."""
        rhs = np.asarray(rhs, dtype=float)
        x = self._factor().solve(rhs)
        return x + self._lu.solve(rhs - self.core @ x)

    def solve(self, row: np.ndarray, rhs: np.ndarray) -> np.ndarray:
        """x with [[A, c], [row^T]] x = rhs (row and rhs of length n + 1)."""
        row, rhs = np.asarray(row, dtype=float), np.asarray(rhs, dtype=float)
        import scipy.sparse.linalg as spla  # here, not at import: small chains' statics never use it

        try:
            self._factor()
        except RuntimeError:
            return spla.spsolve(append_row(self.tocsc(), row), rhs)
        x = self._eliminate(row, rhs)
        residual = rhs - np.append(self.core @ x[:-1] + self.column * x[-1], row @ x)
        x += self._eliminate(row, residual)
        if not np.all(np.isfinite(x)):
            return spla.spsolve(append_row(self.tocsc(), row), rhs)
        return x

    def _eliminate(self, row: np.ndarray, rhs: np.ndarray) -> np.ndarray:
        head = self._lu.solve(rhs[:-1])
        xi = (rhs[-1] - row[:-1] @ head) / (row[-1] - row[:-1] @ self._along)
        return np.append(head - xi * self._along, xi)


def append_row(matrix, row: np.ndarray):
    """``matrix`` (m, n) with ``row`` (n,) below it, in the matrix's own kind (dense, or sparse CSC)."""
    if sp.issparse(matrix):
        return sp.vstack([matrix, sp.csr_matrix(row[None, :])], format="csc")
    return np.vstack([matrix, row])


def determinant_sign(matrix) -> float:
    """Sign of det(matrix): +1, -1, or 0 for a singular one; sparse matrices by SuperLU with its
    row and column permutations' parities."""
    if sp.issparse(matrix):
        import scipy.sparse.linalg as spla  # here, not at import: small chains' statics never use it

        try:
            lu = spla.splu(sp.csc_matrix(matrix))
        except RuntimeError:
            return 0.0
        sign = np.prod(np.sign(lu.U.diagonal()))
        return float(sign * _parity(lu.perm_r) * _parity(lu.perm_c))
    sign, _ = np.linalg.slogdet(matrix)
    return float(np.real(sign))


def _parity(perm: np.ndarray) -> int:
    """+1 for an even permutation, -1 for an odd one (from its cycles' lengths)."""
    seen = np.zeros(len(perm), dtype=bool)
    parity = 1
    for i in range(len(perm)):
        if not seen[i]:
            j, length = i, 0
            while not seen[j]:
                seen[j] = True
                j = perm[j]
                length += 1
            if length % 2 == 0:
                parity = -parity
    return parity
