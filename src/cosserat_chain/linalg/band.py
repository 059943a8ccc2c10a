"""Band storage of half-bandwidth :data:`BANDWIDTH`, and the band LU and LDL^T that read it in place.

Contract
--------
:class:`BandMatrix` holds a square matrix M (n x n) whose entries lie at most
:data:`BANDWIDTH` (B) from the diagonal as ``data[B + i, B + j - i] = M[i, j]``, shape
(n + 2B, 2B + 1), with B zero rows before the first row and after the last: every
compiled loop over it then has the band's constant length (no bound tests: the loops
unroll). A chain's matrices in the free-dof order of :mod:`cosserat_chain.state` lie
in this band; a model assembles its stiffness straight into it (:func:`scatter_signed`
of the bonds' sums, :func:`~cosserat_chain.models.base.assemble_bond_sums` with
``band=True``), without a CSR matrix between (its scatter and the conversion to bands
were a quarter of the cost of a point of a continuation at N = 1000).

* :func:`negated_lu`: LU without pivoting of -M (the bordered solves of
  :mod:`.bordered`); :func:`ldlt` and :func:`negative_count`: LDL^T of M - shift I and
  its inertia (the eigenvalue searches of :mod:`.eigen`). Both read the storage in place.
* :func:`upper_bands` and :func:`from_upper_bands`: LAPACK's upper banded storage of a
  symmetric matrix of any bandwidth (``scipy.linalg.cholesky_banded``).
"""

from __future__ import annotations

from functools import cached_property

import numpy as np
import scipy.sparse as sp
from numba import njit

#: Half-bandwidth of the band storage. An open chain's matrices lie in it (a bond couples two
#: neighbours' six degrees of freedom, at most five apart in :mod:`cosserat_chain.state`'s order).
#: The compiled kernels take it as a constant; their substitutions carry the last five unknowns
#: in five registers, so they are written for this value.
BANDWIDTH = 5


class BandMatrix:
    """A square matrix of half-bandwidth at most :data:`BANDWIDTH` in padded band storage.

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
            If an entry lies further than :data:`BANDWIDTH` from the
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
        """The matrix as a dense array (tests and small chains), without a sparse matrix between.

        Every zero is +0.0, as in :meth:`tocsr`'s dense form: a band entry -0.0 (a structural zero of K
        times a negative factor) would otherwise flip a sign a dense eigensolver's reflections read.
        """
        n, b = self.shape[0], BANDWIDTH
        padded = np.zeros((n, n + 2 * b))
        rows = np.arange(n)[:, None]
        padded[rows, rows + np.arange(2 * b + 1)] = self.data[b : n + b] + 0.0  # x + 0.0: -0.0 becomes +0.0
        return padded[:, b : n + b].copy()

    def scaled(self, diagonal: np.ndarray) -> BandMatrix:
        """diag(d) M diag(d) for the vector ``diagonal`` d (length n), each entry (M_ij d_i) d_j.

        Raises
        ------
        ValueError
            If ``diagonal`` is not of length n.
        """
        n, b = self.shape[0], BANDWIDTH
        diagonal = np.asarray(diagonal, dtype=float)
        if diagonal.shape != (n,):
            raise ValueError(f"diagonal must have length {n} (the matrix's order), got shape {diagonal.shape}")
        padded = np.zeros(n + 4 * b)
        padded[2 * b : 2 * b + n] = diagonal
        # Storage row r holds row i = r - B, its entry t column j = r + t - 2B: d_i at padded[r + B], d_j at padded[r + t].
        columns = padded[np.arange(n + 2 * b)[:, None] + np.arange(2 * b + 1)]
        return BandMatrix(self.data * padded[b : n + 3 * b, None] * columns)

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


def band_storage(matrix: sp.spmatrix | BandMatrix) -> np.ndarray:
    """The padded band storage (:class:`BandMatrix`) the compiled LDL^T reads.

    Its upper triangle is read (a Hessian summed link by link is symmetric only to round-off:
    one triangle is read, as LAPACK's upper storage reads it, and either gives the same
    inertia), in place: no copy by rows of the lower band once a point of a branch
    (benchmarks/TIMINGS.md). A sparse matrix goes through its band.

    Raises
    ------
    ValueError
        If the matrix is wider than the band (a ring's corner blocks).
    """
    return (matrix if isinstance(matrix, BandMatrix) else BandMatrix.from_sparse(matrix)).data


@njit(cache=True, nogil=True)
def negated_lu(stiffness):  # pragma: no cover - compiled
    """LU without pivoting of -K for K in band storage (:class:`BandMatrix`); (band, inverse, ok).

    ``band[i, j - i + BANDWIDTH]`` holds U on and above the diagonal and L's multipliers
    below it, ``inverse`` the reciprocals of U's diagonal (the solves multiply: a division
    on the substitutions' chain of dependences took half their time); ``ok`` is False on
    a zero pivot. Gaussian elimination in the natural order with diagonal pivots, like
    SuperLU with ``diag_pivot_thresh=0`` (:func:`.bordered.sparse_solve`): the fill stays in the
    band, O(n w^2). The storage has :data:`BANDWIDTH` zero rows after the last (as K's
    storage has), read by the bordered solves (:mod:`.bordered`).

    Row by row (Doolittle): entry (r, c) is -K[r, c] minus L[r, j] U[j, c] over the pivots
    j before both, in increasing j, as the right-looking elimination subtracted them (the
    same factor bit for bit), each row's terms read from rows already final. The sums have
    the band's constant lengths outside the first B rows (the loops unroll), and -K is
    read from K's storage as it goes: the copy of -K and the second copy to eliminate in
    were half the factor's time (benchmarks/TIMINGS.md).
    """
    n = stiffness.shape[0] - 2 * BANDWIDTH
    band = np.empty((n + BANDWIDTH, 2 * BANDWIDTH + 1))
    band[n:, :] = 0.0
    inverse = np.zeros(n)
    for r in range(n):
        k = r + BANDWIDTH  # K's row in its storage
        if r >= BANDWIDTH:
            for o in range(-BANDWIDTH, 0):  # L[r, r + o], from the B + o pivots before column r + o
                total = -stiffness[k, BANDWIDTH + o]
                for m in range(BANDWIDTH + o):
                    total -= band[r, m] * band[r - BANDWIDTH + m, 2 * BANDWIDTH + o - m]
                band[r, BANDWIDTH + o] = total * inverse[r + o]
            for o in range(BANDWIDTH + 1):  # U[r, r + o], from the B - o pivots before row r
                total = -stiffness[k, BANDWIDTH + o]
                for m in range(BANDWIDTH - o):
                    total -= band[r, o + m] * band[r + o - BANDWIDTH + m, 2 * BANDWIDTH - m]
                band[r, BANDWIDTH + o] = total
        else:  # the first rows: the pivots before are fewer than the band
            for o in range(-BANDWIDTH, BANDWIDTH + 1):
                c = r + o
                if c < 0:
                    band[r, BANDWIDTH + o] = 0.0
                    continue
                total = -stiffness[k, BANDWIDTH + o]
                for j in range(max(max(r, c) - BANDWIDTH, 0), min(r, c)):
                    total -= band[r, BANDWIDTH + j - r] * band[j, BANDWIDTH + c - j]
                band[r, BANDWIDTH + o] = total * inverse[c] if o < 0 else total
        pivot = band[r, BANDWIDTH]
        if pivot == 0.0:
            return band, inverse, False
        inverse[r] = 1.0 / pivot
    return band, inverse, True


@njit(cache=True, nogil=True)
def ldlt(band, shift, factor, inverse):  # pragma: no cover - compiled
    """LDL^T of M - shift I without pivoting into ``factor`` (factor[r, d] = L[i, i - d], r = B + i) and ``inverse`` (1 / D).

    Returns the number of negative pivots: by Sylvester's law of inertia the number
    of eigenvalues below ``shift``, in O(n w^2) (a zero pivot is nudged by the round-off).
    ``band`` is the padded storage (:func:`band_storage`) and M[i, i - d] is read from its
    upper triangle, M[i - d, i] = band[r - d, B + d]; the padding's rows factor as the identity.

    A row's entries are formed as w_d = L[i, i - d] D[i - d] first, each from the ones
    before it, and L's entry is w_d times the reciprocal pivot: the chain of dependences
    along a row holds multiply-adds only, where it held a division per entry (benchmarks/TIMINGS.md);
    the one division a row is off that chain.
    """
    rows = band.shape[0]
    tiny = 1e-300
    count = 0
    w = np.zeros(BANDWIDTH + 1)
    for r in range(BANDWIDTH):
        inverse[r] = 1.0
        inverse[rows - 1 - r] = 1.0
    for i in range(BANDWIDTH, rows - BANDWIDTH):
        for d in range(BANDWIDTH, 0, -1):
            j = i - d
            total = band[j, BANDWIDTH + d]
            for e in range(BANDWIDTH, d, -1):  # k = i - e < j: w_e L[j, k]
                total -= w[e] * factor[j, e - d]
            w[d] = total
            factor[i, d] = total * inverse[j]
        total = band[i, BANDWIDTH] - shift
        for d in range(BANDWIDTH, 0, -1):
            total -= w[d] * factor[i, d]
        if total < 0.0:
            count += 1
        inverse[i] = 1.0 / (total if total != 0.0 else tiny)
    return count


@njit(cache=True, nogil=True)
def negative_count(band: np.ndarray, shift: float) -> int:  # pragma: no cover - compiled
    """Number of eigenvalues below ``shift`` of the symmetric matrix in padded band storage ``band`` (:func:`band_storage`)."""
    return ldlt(band, shift, np.zeros((band.shape[0], BANDWIDTH + 1)), np.zeros(band.shape[0]))


def upper_bands(matrix: sp.spmatrix) -> np.ndarray:
    """LAPACK's upper banded storage of a symmetric sparse matrix: entry [w + i - j, j] holds M[i, j], i <= j.

    w, the bandwidth, is the number of rows less one.
    """
    upper = sp.triu(matrix, format="coo")
    width = int(np.max(upper.col - upper.row, initial=0))
    bands = np.zeros((width + 1, matrix.shape[0]))
    bands[width + upper.row - upper.col, upper.col] = upper.data
    return bands


def from_upper_bands(bands: np.ndarray) -> sp.csr_matrix:
    """The upper triangle stored by :func:`upper_bands` (or a banded Cholesky factor U) as a sparse matrix."""
    width, n = bands.shape[0] - 1, bands.shape[1]
    offsets = list(range(width + 1))
    return sp.diags([bands[width - d, d:] for d in offsets], offsets, shape=(n, n), format="csr")


@njit(cache=True, nogil=True)
def scatter_add(values, keep, position, out):  # pragma: no cover - compiled
    """out[position[t]] += values[keep[t]] in the order of t.

    The sums of ``np.bincount(position, values[keep])``, added in the same order (the
    same bits), without its gathered copy and its weights' conversion: the assembly of
    the stiffness took half its time in them, and a continuation assembles some 13000
    stiffnesses over a turn (benchmarks/TIMINGS.md).
    """
    for t in range(keep.size):
        out[position[t]] += values[keep[t]]


@njit(cache=True, nogil=True)
def scatter_signed(values, source, sign, position, out):  # pragma: no cover - compiled
    """out[position[t]] += sign[t] values[source[t]] in the order of t (:func:`scatter_add` of signed sums)."""
    for t in range(source.size):
        out[position[t]] += sign[t] * values[source[t]]
