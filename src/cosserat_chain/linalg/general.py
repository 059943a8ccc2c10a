"""Dense-or-sparse matrices of any structure: solves, a row appended, the sign of the determinant.

The continuation kit (:mod:`cosserat_chain.numerics.kit`) takes a problem's Jacobian as it
comes, a dense array for a small system or a SciPy sparse matrix for a lattice of 10^4 sites;
these functions give both the same answers, sparse ones in O(nnz) memory.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla


def solve(matrix, rhs: np.ndarray) -> np.ndarray:
    """``matrix^-1 rhs`` for a dense array (LAPACK) or a sparse matrix (SuperLU).

    Raises
    ------
    numpy.linalg.LinAlgError
        For a singular dense matrix (a singular sparse one gives non-finite entries or raises RuntimeError).
    """
    if sp.issparse(matrix):
        return spla.spsolve(sp.csc_matrix(matrix), rhs)
    return np.linalg.solve(matrix, rhs)


def append_row(matrix, row: np.ndarray):
    """``matrix`` (m, n) with ``row`` (n,) below it, in the matrix's own kind (dense, or sparse CSC)."""
    if sp.issparse(matrix):
        return sp.vstack([matrix, sp.csr_matrix(row[None, :])], format="csc")
    return np.vstack([matrix, row])


def determinant_sign(matrix) -> float:
    """Sign of det(matrix): +1, -1, or 0 for a singular one; sparse matrices by SuperLU with its
    row and column permutations' parities."""
    if sp.issparse(matrix):
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
