"""Banded matrices over a chain's free degrees of freedom, in the storage the compiled solvers share.

An open chain's stiffness couples degrees of freedom at most
:data:`~cosserat_chain.state.BANDWIDTH` (B) apart. :class:`BandMatrix` holds such a matrix
M (n x n) as ``data[B + i, B + j - i] = M[i, j]``, shape (n + 2B, 2B + 1), with B zero rows
before the first row and after the last: every compiled loop over it then has the band's
constant length (no bound tests: the loops unroll). The statics' band LU
(:class:`~cosserat_chain.numerics.newton.BorderedFactor`) and LDL^T
(:mod:`~cosserat_chain.numerics.stability`) read it directly; a model assembles its
stiffness into it from the bond sums (:func:`~cosserat_chain.models.base.assemble_bond_sums`
with ``band=True``), without the CSR matrix between (its scatter and the conversion to bands were a quarter
of the cost of a point of a continuation at N = 1000).
"""

from __future__ import annotations

from functools import cached_property

import numpy as np
import scipy.sparse as sp
from numba import njit

from .state import BANDWIDTH


class BandMatrix:
    """A square matrix of half-bandwidth at most :data:`~cosserat_chain.state.BANDWIDTH` in padded band storage.

    Parameters
    ----------
    data : ndarray, shape (n + 2B, 2B + 1)
        ``data[B + i, B + j - i] = M[i, j]``; the B rows before and after the matrix's are zero.

    Attributes
    ----------
    shape : tuple of int
        (n, n).
    """

    def __init__(self, data: np.ndarray):
        data = np.asarray(data, dtype=float)
        if data.ndim != 2 or data.shape[1] != 2 * BANDWIDTH + 1 or data.shape[0] < 2 * BANDWIDTH:
            raise ValueError(f"band data must have shape (n + {2 * BANDWIDTH}, {2 * BANDWIDTH + 1}), got {data.shape}")
        self.data = data
        n = data.shape[0] - 2 * BANDWIDTH
        self.shape = (n, n)

    @classmethod
    def from_sparse(cls, matrix) -> BandMatrix:
        """The band of a sparse (or dense) matrix, O(nnz).

        Raises
        ------
        ValueError
            If an entry lies further than :data:`~cosserat_chain.state.BANDWIDTH` from the
            diagonal (a ring's corner blocks).
        """
        csr = matrix if sp.issparse(matrix) and matrix.format == "csr" else sp.csr_matrix(matrix)
        data, width = _csr_band(csr.indptr, csr.indices, np.asarray(csr.data, dtype=float))
        if width > BANDWIDTH:
            raise ValueError(f"the matrix has half-bandwidth {width}, more than the chain's {BANDWIDTH}")
        return cls(data)

    @cached_property
    def infinity_norm(self) -> float:
        """max_i sum_j |M_ij| (the rows' entries summed in the order of their columns, as over CSR)."""
        return float(_band_infinity_norm(self.data)) if self.shape[0] else 0.0

    def tocsr(self) -> sp.csr_matrix:
        """The matrix as CSR, its explicit zeros dropped."""
        n, b = self.shape[0], BANDWIDTH
        offsets = np.arange(-b, b + 1)
        # dia_matrix's column j of diagonal k is M[j - k, j]: row B + j - k of the storage.
        diagonals = np.stack([self.data[b - k : n + b - k, b + k] for k in offsets])
        out = sp.dia_matrix((diagonals, offsets), shape=self.shape).tocsr()
        out.eliminate_zeros()
        return out

    def toarray(self) -> np.ndarray:
        """The matrix as a dense array (tests and small chains)."""
        return self.tocsr().toarray()

    def __repr__(self) -> str:
        return f"<BandMatrix {self.shape[0]}x{self.shape[1]}, half-bandwidth {BANDWIDTH}>"


@njit(cache=True, nogil=True)
def _csr_band(indptr, indices, data):  # pragma: no cover - compiled
    """:class:`BandMatrix` storage of a CSR matrix and its half-bandwidth (entries beyond the band left out)."""
    n = indptr.size - 1
    out = np.zeros((n + 2 * BANDWIDTH, 2 * BANDWIDTH + 1))
    width = 0
    for i in range(n):
        for p in range(indptr[i], indptr[i + 1]):
            offset = indices[p] - i
            if offset > BANDWIDTH or offset < -BANDWIDTH:
                width = max(width, abs(offset))
            else:
                out[BANDWIDTH + i, BANDWIDTH + offset] += data[p]
    return out, width


@njit(cache=True, nogil=True)
def _band_infinity_norm(data):  # pragma: no cover - compiled
    """The largest absolute row sum of band storage (the padding's rows are zero)."""
    largest = 0.0
    for i in range(data.shape[0]):
        total = 0.0
        for t in range(2 * BANDWIDTH + 1):
            total += abs(data[i, t])
        largest = max(largest, total)
    return largest
