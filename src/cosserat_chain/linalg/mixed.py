"""Solves with K = L^T R + G given by its rows, in the mixed (saddle-point) form that never forms K.

Contract
--------
A model whose stiffness is a sum of rank-one terms, K = sum_i l_i r_i^T + G (the nonlinear
springs: l_i = r_i = sqrt(E) times a link's length gradient, G the tension term; the sine
model: l_i the linear model's square-root rows, r_i = C l_i, G = 0), gives its rows
(each at most ``BANDWIDTH + 1`` consecutive entries from its first column on, the rows ordered
by that column, as :class:`~.root.RootFactor` takes them) and G in band storage.
:class:`MixedFactor` solves K q = b through the mixed system

    [[-I, R], [L^T, G]] [lambda; q] = [0; b]      (lambda = R q),

whose unknowns are ordered by column (each multiplier beside its row's middle column), so that
the matrix is banded (half-bandwidth about 9), and factored by LAPACK's band LU with partial
pivoting (``dgbtrf``). Why: a clamped chain's K has its softest eigenvalue near N^-4 of its
largest; a factor of K's rounded entries is exact only for K perturbed by eps ||K|| in every
direction, which moves that eigenvalue by more than its size at N = 10^5
(:mod:`.root`). The mixed form is backward stable for perturbations of the rows and of G, which
move the soft eigenvalue lambda by about eps sqrt(lambda ||K||) only.

:class:`MixedBorderedFactor` is :class:`~.bordered.BorderedFactor`'s interface (the bordered
pseudo-arclength systems [[-K, e_dof], [row^T]]) on such a factor: the border by block
elimination, with K^-1 e_dof kept per factor, and every solve refined with the residual of the
bordered system evaluated in the row form (L^T (R q) + G q), never with K's rounded entries.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numba import njit
from scipy.linalg.lapack import dgbtrf, dgbtrs

from .band import BANDWIDTH, BandMatrix
from .root import ROW_WIDTH


@njit(cache=True, nogil=True)
def _row_product(values, starts, q, out):  # pragma: no cover - compiled
    """out[i] = sum_d values[i, d] q[starts[i] + d] (the entries past q's end are zero)."""
    n = q.shape[0]
    for i in range(values.shape[0]):
        total = 0.0
        for d in range(ROW_WIDTH):
            j = starts[i] + d
            if j < n:
                total += values[i, d] * q[j]
        out[i] = total
    return out


@njit(cache=True, nogil=True)
def _row_transpose_product(values, starts, y, out):  # pragma: no cover - compiled
    """out += sum_i y[i] values[i] placed from column starts[i] on."""
    n = out.shape[0]
    for i in range(values.shape[0]):
        for d in range(ROW_WIDTH):
            j = starts[i] + d
            if j < n:
                out[j] += values[i, d] * y[i]
    return out


@njit(cache=True, nogil=True)
def _band_product(data, q, out):  # pragma: no cover - compiled
    """out += M q for M in :class:`~.band.BandMatrix` storage."""
    n = q.shape[0]
    for i in range(n):
        total = 0.0
        for t in range(2 * BANDWIDTH + 1):
            j = i + t - BANDWIDTH
            if 0 <= j < n:
                total += data[BANDWIDTH + i, t] * q[j]
        out[i] += total
    return out


@njit(cache=True, nogil=True)
def _mixed_width(left, right, starts, g, q_at, lambda_at):  # pragma: no cover - compiled
    """The half-bandwidth of the mixed matrix: the largest distance of a nonzero entry from its diagonal."""
    n = q_at.shape[0]
    width = 0
    for i in range(starts.shape[0]):
        for d in range(ROW_WIDTH):
            j = starts[i] + d
            if j < n and (left[i, d] != 0.0 or right[i, d] != 0.0):
                width = max(width, abs(lambda_at[i] - q_at[j]))
    for i in range(n):
        for t in range(2 * BANDWIDTH + 1):
            j = i + t - BANDWIDTH
            if 0 <= j < n and g[BANDWIDTH + i, t] != 0.0:
                width = max(width, abs(q_at[i] - q_at[j]))
    return width


@njit(cache=True, nogil=True)
def _mixed_fill(left, right, starts, g, q_at, lambda_at, width, ab):  # pragma: no cover - compiled
    """The mixed matrix [[-I, R], [L^T, G]] in the order of ``q_at`` and ``lambda_at`` into ``ab``, the transpose of
    LAPACK's band storage with kl = ku = ``width`` (entry (r, c) at ab[c, 2 width + r - c])."""
    n = q_at.shape[0]
    for i in range(starts.shape[0]):
        at = lambda_at[i]
        ab[at, 2 * width] = -1.0
        for d in range(ROW_WIDTH):
            j = starts[i] + d
            if j < n:
                column = q_at[j]
                if right[i, d] != 0.0:
                    ab[column, 2 * width + at - column] = right[i, d]
                if left[i, d] != 0.0:
                    ab[at, 2 * width + column - at] = left[i, d]
    for i in range(n):
        for t in range(2 * BANDWIDTH + 1):
            j = i + t - BANDWIDTH
            if 0 <= j < n and g[BANDWIDTH + i, t] != 0.0:
                ab[q_at[j], 2 * width + q_at[i] - q_at[j]] = g[BANDWIDTH + i, t]


def _positions(before: np.ndarray, n: int) -> tuple[np.ndarray, np.ndarray]:
    """Positions of the unknowns q_j and of the multipliers lambda_i in the mixed system's order: multiplier i after
    the first ``before[i]`` unknowns, the multipliers of one place in their order."""
    keys = np.concatenate([np.arange(n, dtype=float), before - 0.5])
    order = np.argsort(keys, kind="stable")
    position = np.empty(keys.size, dtype=np.int64)
    position[order] = np.arange(keys.size)
    return position[:n], position[n:]


class StiffnessRows(NamedTuple):
    """K = L^T R + G by rows (:class:`MixedFactor`'s parameters of the same names)."""

    left: np.ndarray
    right: np.ndarray
    starts: np.ndarray
    before: np.ndarray
    g: BandMatrix | None


class MixedFactor:
    """The band LU of the mixed form of K = L^T R + G (module docstring).

    Parameters
    ----------
    left, right : ndarray, shape (rows, BANDWIDTH + 1)
        The rows l_i and r_i: row i holds ``left[i, d]`` in column ``starts[i] + d``.
    starts : ndarray of int, shape (rows,)
        Each row's first column, non-decreasing.
    n : int
        Columns (K is n x n).
    g : BandMatrix or None
        The rest of K, G, in band storage (None: zero).
    before : ndarray of int, shape (rows,), optional
        How many unknowns precede each row's multiplier in the mixed system's order (default: those up to
        the middle of its row). A chain's rows give the columns of their bond's left particle: the band is
        then as narrow as the bonds make it, also where a held particle shortens the rows.

    Raises
    ------
    ValueError
        If the shapes disagree or the rows are not ordered by their first column.
    """

    def __init__(
        self, left: np.ndarray, right: np.ndarray, starts: np.ndarray, n: int, g: BandMatrix | None = None, before: np.ndarray | None = None
    ):
        left = np.ascontiguousarray(left, dtype=float)
        right = np.ascontiguousarray(right, dtype=float)
        starts = np.ascontiguousarray(starts, dtype=np.int64)
        rows = starts.shape[0]
        if left.shape != (rows, ROW_WIDTH) or right.shape != (rows, ROW_WIDTH):
            raise ValueError(
                f"left and right must be (rows, {ROW_WIDTH}) with starts (rows,), got {left.shape}, {right.shape} and {starts.shape}"
            )
        if rows and (np.any(np.diff(starts) < 0) or starts[0] < 0):
            raise ValueError("the rows must be ordered by their first column, from column 0 on")
        if g is not None and g.shape != (n, n):
            raise ValueError(f"g must be {n} x {n}, got {g.shape}")
        self.left, self.right, self.starts, self.n, self.g = left, right, starts, n, g
        self.q_at, self.lambda_at = _positions(starts + ROW_WIDTH // 2 if before is None else np.asarray(before), n)
        size = n + rows
        g_data = np.zeros((n + 2 * BANDWIDTH, 2 * BANDWIDTH + 1)) if g is None else g.data
        self.kl = self.ku = width = _mixed_width(left, right, starts, g_data, self.q_at, self.lambda_at)
        ab = np.zeros((size, 3 * width + 1))  # the transpose of LAPACK's band storage, filled by rows
        _mixed_fill(left, right, starts, g_data, self.q_at, self.lambda_at, width, ab)
        ab = ab.T  # Fortran order, as dgbtrf takes it
        self.size = size
        self.lu, self.pivots, info = dgbtrf(ab, width, width, overwrite_ab=1)
        self.singular = info != 0

    @classmethod
    def from_rows(cls, rows: StiffnessRows, n: int) -> MixedFactor:
        """The factor of a model's :class:`StiffnessRows` (``Model.stiffness_rows``) over n unknowns."""
        return cls(rows.left, rows.right, rows.starts, n, rows.g, rows.before)

    def apply(self, q: np.ndarray) -> np.ndarray:
        """K q in the row form, L^T (R q) + G q."""
        q = np.ascontiguousarray(q, dtype=float)
        out = _row_transpose_product(
            self.left, self.starts, _row_product(self.right, self.starts, q, np.empty(self.starts.size)), np.zeros(self.n)
        )
        return out if self.g is None else _band_product(self.g.data, q, out)

    def solve(self, rhs: np.ndarray) -> np.ndarray:
        """q with K q = ``rhs`` (not finite where the factor met a zero pivot: K singular)."""
        if self.singular:
            return np.full(self.n, np.nan)
        full = np.zeros(self.size)
        full[self.q_at] = rhs
        x, _ = dgbtrs(self.lu, self.kl, self.ku, full, self.pivots)
        return x[self.q_at]


class MixedBorderedFactor:
    """:class:`~.bordered.BorderedFactor`'s solves of [[-K, e_dof], [row^T]] x = rhs on a :class:`MixedFactor` of K.

    Parameters
    ----------
    factor : MixedFactor
        K in the mixed form.
    stiffness : BandMatrix
        K's band (its norm: the round-off floors of the corrector; not factored).
    dof : int
        The bordered column's degree of freedom.
    """

    #: No inertia from a pivoted LU: the stability checks count K's negative eigenvalues themselves.
    negative_eigenvalues = None

    def __init__(self, factor: MixedFactor, stiffness: BandMatrix, dof: int):
        self.factor, self.stiffness, self.dof = factor, stiffness, dof
        e = np.zeros(factor.n)
        e[dof] = 1.0
        self._column = self._refined(e)

    def _refined(self, b: np.ndarray) -> np.ndarray:
        """K^-1 b with one step of refinement on the row form's residual."""
        x = self.factor.solve(b)
        return x + self.factor.solve(b - self.factor.apply(x))

    def solve(self, row: np.ndarray, rhs: np.ndarray, *, refine: int = 1) -> np.ndarray:
        """x with [[-K, e_dof], [row^T]] x = rhs; ``row`` and ``rhs`` of length n + 1; ``refine`` steps of refinement."""
        row = np.asarray(row, dtype=float)
        rhs = np.asarray(rhs, dtype=float)
        n, y = self.factor.n, self._column
        corner = float(row[:n] @ y) + row[n]
        solution = np.zeros(n + 1)
        residual = rhs.copy()
        for sweep in range(refine + 1):
            # -K q + e M = b, row . (q, M) = c: q = M y - K^-1 b with y = K^-1 e.
            z = self.factor.solve(residual[:n])
            moment = (residual[n] + float(row[:n] @ z)) / corner
            solution[:n] += moment * y - z
            solution[n] += moment
            if sweep == refine:
                break
            residual[:n] = rhs[:n] + self.factor.apply(solution[:n])
            residual[self.dof] -= solution[n]
            residual[n] = rhs[n] - float(row @ solution)
        return solution
