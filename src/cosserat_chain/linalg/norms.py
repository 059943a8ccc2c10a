"""Norms and dot products of the statics' vectors and matrices, compiled and on the calling thread.

Contract
--------
:func:`infinity_norm` of a sparse, dense or :class:`~.band.BandMatrix` matrix in O(nnz);
:func:`dot` and :func:`euclidean_norm` of vectors in a fixed order of additions (the same
bits on every machine and thread count), never through a threaded BLAS.
"""

from __future__ import annotations

import math

import numpy as np
import scipy.sparse as sp
from numba import njit

from .band import BandMatrix


def infinity_norm(matrix: sp.spmatrix | BandMatrix) -> float:
    """max_i sum_j |A_ij| of a sparse or banded matrix (0 for an empty one), O(nnz).

    A compiled loop over a CSR matrix's data (:func:`_csr_infinity_norm`): scipy's
    ``abs(A).sum(axis=1).max()`` builds two temporaries (benchmarks/TIMINGS.md), and the continuation
    asks it at every corrector iteration. A
    :class:`~.band.BandMatrix` keeps its norm once computed.
    """
    if isinstance(matrix, BandMatrix):
        return matrix.infinity_norm
    if not matrix.shape[0]:
        return 0.0
    if sp.issparse(matrix) and matrix.format == "csr":
        return float(_csr_infinity_norm(matrix.indptr, np.asarray(matrix.data, dtype=float)))
    return float(abs(matrix).sum(axis=1).max())


@njit(cache=True, nogil=True)
def _csr_infinity_norm(indptr, data):  # pragma: no cover - compiled
    """The largest absolute row sum of a CSR matrix given by its ``indptr`` and ``data``."""
    largest = 0.0
    for i in range(indptr.size - 1):
        total = 0.0
        for p in range(indptr[i], indptr[i + 1]):
            total += abs(data[p])
        largest = max(largest, total)
    return largest


@njit(cache=True, nogil=True)
def dot(a: np.ndarray, b: np.ndarray) -> float:  # pragma: no cover - compiled
    """a^T b of two vectors, compiled, on this thread, in eight partial sums.

    OpenBLAS's ddot (NumPy's ``a @ b`` and ``np.linalg.norm``) runs on several threads
    from about 10^4 entries on: the continuation's few dot products a corrector iteration
    then woke a second thread that spun between them, doubling the CPU time of the
    statics of N = 10^4 and slowing its wall time by 15 %. Eight partial sums keep the
    additions off one chain of dependences (and the order fixed on every machine).
    """
    partial = np.zeros(8)
    n = a.size
    head = n - n % 8
    for i in range(0, head, 8):
        for j in range(8):
            partial[j] += a[i + j] * b[i + j]
    total = ((partial[0] + partial[1]) + (partial[2] + partial[3])) + ((partial[4] + partial[5]) + (partial[6] + partial[7]))
    for i in range(head, n):
        total += a[i] * b[i]
    return total


def euclidean_norm(a: np.ndarray) -> float:
    """The Euclidean norm of a vector with :func:`dot` (on this thread)."""
    return math.sqrt(dot(a, a))
