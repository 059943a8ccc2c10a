"""The damped pencil K~ + z R + z^2 I of a banded K~ and a diagonal R >= 0: its eigenvalues near the axis, its count right of it.

Contract
--------
The first-order system d/dt (y, w) = A (y, w), A = [[0, I], [-K~, -R]], has the eigenvalues z
with det(K~ + z R + z^2 I) = 0 (its Schur complement). With K~ banded both questions of
:func:`~cosserat_chain.numerics.stability.dynamic_stability` take O(n) a point:

* :func:`unstable_count`: the eigenvalues right of the line Re z = tolerance, by the
  argument principle (the phase of det(A - z I), one banded LU a point, followed round a
  curve enclosing that part of the spectrum);
* :func:`nearest_axis` with :func:`shifted_solver`: the eigenvalues nearest a shift just
  right of the axis, by shift-invert (ARPACK, each product one banded solve of n x n).

Cayley transforms with ARPACK's largest |mu| were tried first and did not converge at
N = 100: the slow overdamped modes crowd the unit circle.
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np
import scipy.sparse as sp
from numba import njit

#: Most eigenvalues nearest the axis :func:`nearest_axis` asks ARPACK for.
NEAREST_LIMIT = 64


def shifted_solver(scaled: sp.spmatrix, rate: np.ndarray, shift: float) -> Callable[[np.ndarray], np.ndarray]:
    """x -> (A - s I)^-1 x for A = [[0, I], [-K~, -R]] (``scaled`` K~, ``rate`` R's diagonal), by one banded LU of n x n.

    From -s y + w = a and -K~ y - (R + s) w = b: w = a + s y and
    (K~ + s (R + s)) y = -b - (R + s) a.
    """
    n = scaled.shape[0]
    import scipy.sparse.linalg as sla  # here, not at import: small chains' statics never use it

    lu = sla.splu(sp.csc_matrix(scaled + sp.diags(shift * (rate + shift))), permc_spec="NATURAL")
    damped = rate + shift

    def solve(vector: np.ndarray) -> np.ndarray:
        a, b = vector[:n], vector[n:]
        y = lu.solve(-b - damped * a)
        return np.concatenate([y, a + shift * y])

    return solve


def _pencil_band(scaled: sp.spmatrix) -> tuple[np.ndarray, int]:
    """K~ in LAPACK's general band storage by columns (band[j, 2w + i - j] = K~[i, j]; w rows of fill first), and w."""
    coo = sp.coo_matrix(scaled)
    width = int(np.max(np.abs(coo.row - coo.col), initial=0))
    band = np.zeros((scaled.shape[0], 3 * width + 1), dtype=complex)
    np.add.at(band, (coo.col, 2 * width + coo.row - coo.col), coo.data)
    return band, width


def _phase(band: np.ndarray, width: int, rate: np.ndarray, z: complex) -> float:
    """arg det(K~ + z R + z^2 I) = arg det(A - z I) (not reduced mod 2 pi), from one banded LU (O(n w^2))."""
    value = _band_phase(band, width, rate, complex(z), np.empty_like(band))
    if math.isnan(value):  # z is an eigenvalue: the phase next to it (the caller's steps resolve the jump)
        return _phase(band, width, rate, z + 1e-12 * max(abs(z), 1e-300) * 1j)
    return value


@njit(cache=True, nogil=True)
def _band_phase(band, width, rate, z, work):  # pragma: no cover - compiled
    """arg det(B + diag(z rate + z^2)) for B in band storage by columns ``band`` (:func:`_pencil_band`).

    LAPACK's unblocked banded LU with partial pivoting (xGBTF2, its pivot chosen by
    |Re| + |Im| as izamax does) in ``work``: the sum of the pivots' arguments, plus pi a row
    interchange; NaN at a zero pivot. Compiled, each column's band contiguous: the blocking of zgbtrf through
    SciPy does not pay at this width (benchmarks/TIMINGS.md), and the argument principle takes
    thousands of them.
    """
    n = band.shape[0]
    kl = ku = width
    kv = kl + ku
    work[:, :] = band
    for c in range(n):
        work[c, kv] += z * rate[c] + z * z
    total = 0.0
    last = 0
    for j in range(n):
        km = min(kl, n - 1 - j)
        jp = 0
        best = abs(work[j, kv].real) + abs(work[j, kv].imag)
        for i in range(1, km + 1):
            size = abs(work[j, kv + i].real) + abs(work[j, kv + i].imag)
            if size > best:
                best, jp = size, i
        if best == 0.0:
            return math.nan
        last = max(last, min(j + ku + jp, n - 1))
        if jp != 0:
            total += math.pi
            for c in range(j, last + 1):
                upper, lower = kv + j - c, kv + j + jp - c
                work[c, upper], work[c, lower] = work[c, lower], work[c, upper]
        pivot = work[j, kv]
        total += math.atan2(pivot.imag, pivot.real)
        inverse = 1.0 / pivot
        for i in range(1, km + 1):
            work[j, kv + i] *= inverse
        for c in range(j + 1, last + 1):
            above = work[c, kv + j - c]
            for i in range(1, km + 1):
                work[c, kv + j + i - c] -= work[j, kv + i] * above
    return total


def _wrap_angle(angle: float) -> float:
    """``angle`` reduced to (-pi, pi]."""
    return angle - 2.0 * math.pi * math.ceil((angle - math.pi) / (2.0 * math.pi))


def unstable_count(scaled: sp.spmatrix, rate: np.ndarray, tolerance: float, reference: sp.spmatrix | None = None) -> int:
    """Eigenvalues of A with a real part above ``tolerance``, by the argument principle, O(n) a point.

    det(A - z I) = det(K~ + z R + z^2 I) winds round zero once for each eigenvalue inside
    a closed curve. The curve: the line Re z = tolerance and a half circle right of it of
    radius 4 rho, rho = (r + sqrt(r^2 + 4 |K~|)) / 2 bounding every |lambda| (from
    lambda^2 + lambda y*Ry + y*K~y = 0, |y| = 1). A is real, so the upper half of the curve
    turns the phase by pi per eigenvalue.

    ``reference``: a symmetric positive semi-definite K~_0 (the chain at rest), whose damped
    dynamics has no eigenvalue right of the line (K~_0 symmetric and R >= 0: no growing mode);
    the phase followed is then that of det(K~ + z R + z^2 I) / det(K~_0 + z R + z^2 I), which
    winds once per eigenvalue of A inside the curve less one per eigenvalue of the reference:
    the eigenvalues the state shares with rest (those of the chain far from where it is
    deformed) cancel, and the phase turns slowly.

    The phase is followed in steps that turn it by less than :data:`PHASE_STEP` (halved on a
    larger turn, grown by half otherwise). Eigenvalues within one step and nearer the line than
    its length could hide each other's turns: the steps are at most a quarter of the least
    damping rate r_min, since a complex eigenvalue of a conservative damped chain lies at least
    r_min / 2 left of the axis (Re lambda = -y*Ry / 2 for its eigenvector y), and they shrink
    geometrically towards the real axis, where the slow overdamped modes lie (within 1e-7 of
    zero at N = 100). The cost is two banded LUs a point, O(rho / r_min) points.
    """
    band, width = _pencil_band(scaled)
    base = None if reference is None else _pencil_band(reference)[0]
    if base is not None and base.shape != band.shape:
        base = None
    n = scaled.shape[0]
    r = float(rate.max(initial=0.0))
    size = abs(scaled)
    norm = math.sqrt(float(size.sum(axis=0).max()) * float(size.sum(axis=1).max())) if n else 0.0
    radius = 4.0 * (r + math.sqrt(r * r + 4.0 * norm)) / 2.0 + tolerance

    def phase(z: complex) -> float:
        if base is None:
            return _phase(band, width, rate, z)
        return _phase(band, width, rate, z) - _phase(base, width, rate, z)

    # Without a reference the phase of z^(2n) is taken out on the circle, where it dominates.
    power = 0 if base is not None else 2 * n

    def arc(theta: float) -> float:
        z = tolerance + radius * complex(math.cos(theta), math.sin(theta))
        return phase(z) - power * math.atan2(z.imag, z.real)

    def line(y: float) -> float:
        return phase(complex(tolerance, y))

    start = complex(tolerance + radius, 0.0)
    corner = complex(tolerance, radius)
    # The arc from the real axis to the line, then the line down to the real axis.
    total = _follow_phase(arc, 0.0, 0.5 * math.pi, 0.5 * math.pi / 64)
    total += power * (math.atan2(corner.imag, corner.real) - math.atan2(start.imag, start.real))
    damped = rate[rate > 0]
    largest = min(0.25 * float(damped.min()) if damped.size else radius / 4096, radius / 64)
    total += _follow_phase(line, radius, 0.0, largest, floor=tolerance * 1e-3, largest=largest)
    return int(round(total / math.pi))


#: Largest turn of the phase of det(A - z I) over one step of :func:`unstable_count`.
PHASE_STEP = 0.25 * math.pi


def _follow_phase(phase, begin: float, end: float, step: float, floor: float = 0.0, largest: float = math.inf) -> float:
    """The phase's total turn from ``begin`` to ``end`` (a real parameter), in steps that turn it by less than PHASE_STEP.

    Steps grow by half after each accepted one, up to ``largest``, and halve on a larger
    turn; near ``end`` they are kept below half the distance left (geometric towards it,
    down to ``floor``). Growing by half, a step turns the phase by at most about 1.5 times
    the last one's unless its rate jumps sevenfold, so a turn of 2 pi is never taken for none.
    """
    here, value, total = begin, phase(begin), 0.0
    direction = 1.0 if end > begin else -1.0
    while direction * (end - here) > 0.0:
        left = abs(end - here)
        length = min(abs(step), left if left <= floor else max(0.5 * left, floor))
        there = end if length >= left else here + direction * length
        after = phase(there)
        turn = _wrap_angle(after - value)
        if abs(turn) > PHASE_STEP and length > 4.0 * np.finfo(float).eps * max(abs(here), 1.0):
            step = 0.5 * length
            continue
        total += turn
        here, value, step = there, after, min(1.5 * length, largest)
    return total


def nearest_axis(solve, size: int, count: int, rightmost: int) -> np.ndarray:
    """Eigenvalues nearest the shift of ``solve`` (just right of the axis), enough to hold ``count`` unstable ones if they are near.

    Shift-invert: ARPACK's largest 1 / (lambda - s) converge fast, clusters of slow modes
    included. The number asked for doubles while fewer than ``count`` of those found are
    unstable, up to :data:`NEAREST_LIMIT` (unstable eigenvalues far from the axis among
    many stable ones nearer it are then not all listed; their number is still exact).
    """
    import scipy.sparse.linalg as sla  # here, not at import: small chains' statics never use it

    inverse = sla.LinearOperator((size, size), matvec=solve, dtype=float)
    start = np.random.default_rng(0).standard_normal(size)
    wanted = min(count + rightmost + 2, size - 2)
    while True:
        try:
            nu = sla.eigs(inverse, k=wanted, which="LM", v0=start, tol=1e-12, return_eigenvectors=False, maxiter=100 * size)
        except sla.ArpackNoConvergence as err:  # the converged ones (the count does not depend on them)
            nu = err.eigenvalues
        eigenvalues = 1.0 / nu
        if int(np.sum(eigenvalues.real > 0.0)) >= count or wanted >= min(NEAREST_LIMIT, size - 2):
            return eigenvalues
        wanted = min(2 * wanted, NEAREST_LIMIT, size - 2)
