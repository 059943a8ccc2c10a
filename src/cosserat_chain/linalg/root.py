"""Solves with a symmetric matrix given by its square root: K = A^T A, A banded, factored by Givens rotations.

Contract
--------
:class:`RootFactor` takes the rows of A (each at most ``BANDWIDTH + 1`` consecutive entries
from its first column on, the rows ordered by that column) and reduces them to the upper
triangular R of A = Q R by Givens rotations, one row at a time, in O(rows w^2); R has K's
half-bandwidth, and R^T R = K. :meth:`RootFactor.solve` solves K x = b by the two triangular
solves R^T y = b, R x = y.

Why: a clamped chain's K has its softest eigenvalue (bending) near N^-4 of its largest, a
condition number beyond 1/eps from N of a few thousand. A factor of K's rounded entries (band
LU, LDL^T, SuperLU) is then exact for a K perturbed by eps ||K|| in every direction, which
moves that eigenvalue by more than its size: at N = 10^5 the band LU's compliance was 80 %
off. Rotations of A's rows perturb A itself (by eps ||A||), so K = A^T A only by
A^T dA + dA^T A, which moves the soft eigenvalue lambda by about eps sqrt(lambda ||K||): R
carries K's soft modes to eps cond(A) = eps sqrt(cond(K)) (4e-6 at N = 10^5), and iterative
refinement (:func:`~cosserat_chain.linalg.refinement.refined_solve` with this factor's solve)
converges from there.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from .band import BANDWIDTH

#: Entries of a row of A: its first column and the BANDWIDTH after it.
ROW_WIDTH = BANDWIDTH + 1


@njit(cache=True, nogil=True)
def _rotate_rows(values, starts, r):  # pragma: no cover - compiled
    """Reduce the rows of A (``values[i]`` from column ``starts[i]`` on) into R (r[j, d] = R[j, j + d]) by Givens rotations."""
    n = r.shape[0]
    row = np.zeros(2 * ROW_WIDTH)
    for i in range(values.shape[0]):
        first = starts[i]
        for d in range(ROW_WIDTH):
            row[d] = values[i, d]
        for d in range(ROW_WIDTH, 2 * ROW_WIDTH):
            row[d] = 0.0
        for p in range(ROW_WIDTH):
            x = row[p]
            j = first + p
            if x == 0.0 or j >= n:
                continue
            diagonal = r[j, 0]
            radius = math.hypot(diagonal, x)
            c, s = diagonal / radius, x / radius
            r[j, 0] = radius
            row[p] = 0.0
            for q in range(1, ROW_WIDTH):
                above, below = r[j, q], row[p + q]
                r[j, q] = c * above + s * below
                row[p + q] = c * below - s * above
    return r


@njit(cache=True, nogil=True)
def _root_solve(r, rhs):  # pragma: no cover - compiled
    """x with R^T R x = rhs: R^T y = rhs forward, then R x = y backward."""
    n = r.shape[0]
    x = np.empty(n)
    for j in range(n):
        total = rhs[j]
        for d in range(1, min(ROW_WIDTH, j + 1)):
            total -= r[j - d, d] * x[j - d]
        x[j] = total / r[j, 0]
    for j in range(n - 1, -1, -1):
        total = x[j]
        for d in range(1, min(ROW_WIDTH, n - j)):
            total -= r[j, d] * x[j + d]
        x[j] = total / r[j, 0]
    return x


class RootFactor:
    """The triangular factor R of K = A^T A from A's rows (module docstring).

    Parameters
    ----------
    values : ndarray, shape (rows, BANDWIDTH + 1)
        Row i of A holds ``values[i, d]`` in column ``starts[i] + d`` (zeros past its last entry).
    starts : ndarray of int, shape (rows,)
        Each row's first column, non-decreasing.
    n : int
        Columns of A (K is n x n).

    Raises
    ------
    ValueError
        If the shapes disagree, the rows are not ordered by their first column, or an entry lies
        beyond column n.
    """

    def __init__(self, values: np.ndarray, starts: np.ndarray, n: int):
        values = np.ascontiguousarray(values, dtype=float)
        starts = np.ascontiguousarray(starts, dtype=np.int64)
        if values.ndim != 2 or values.shape[1] != ROW_WIDTH or starts.shape != (values.shape[0],):
            raise ValueError(f"values must be (rows, {ROW_WIDTH}) and starts (rows,), got {values.shape} and {starts.shape}")
        if starts.size and (np.any(np.diff(starts) < 0) or starts[0] < 0):
            raise ValueError("the rows of A must be ordered by their first column, from column 0 on")
        last = starts[:, None] + np.arange(ROW_WIDTH)
        if np.any((values != 0.0) & (last >= n)):
            raise ValueError(f"an entry of A lies beyond its last column {n - 1}")
        self.n = n
        self.r = _rotate_rows(values, starts, np.zeros((n, ROW_WIDTH)))

    def solve(self, rhs: np.ndarray) -> np.ndarray:
        """x with A^T A x = ``rhs`` (not finite where R has a zero pivot: A's columns dependent, K singular)."""
        with np.errstate(divide="ignore", invalid="ignore"):
            return _root_solve(self.r, np.ascontiguousarray(rhs, dtype=float))
