"""Floquet multipliers from the product of segment matrices, by the periodic Schur form.

Contract
--------
A periodic orbit's monodromy is a product M = G_m ... G_1 of the transfer matrices of its
segments (the variational flow over each piece of the period, or a collocation interval's
condensed equations). Its eigenvalues, the Floquet multipliers, span many orders of magnitude
on a long, strongly damped orbit: a mode damped at rate gamma / (2 m) has the multiplier
exp(-gamma T / (2 m)), 1e-100 and below for T in the hundreds, next to the trivial multiplier 1.
Formed in floating point, M carries an absolute error of about eps |M| in every entry, so its
eigenvalues below eps |mu_max| ~ 1e-16 are round-off: the small multipliers are lost, whatever
the accuracy of the factors.

:func:`periodic_schur_multipliers` never forms the product. Orthogonal Q_1 ... Q_m bring the
factors to the periodic real Schur form

    G_k Q_k = Q_{k+1} T_k,    k = 1..m,    Q_{m+1} = Q_1,

with every T_k upper triangular (Q_1^T M Q_1 = T_m ... T_1 upper triangular up to 2 x 2 blocks,
Bojanczyk, Golub and Van Dooren 1992), and each multiplier is the product of the factors'
diagonal entries, summed as logarithms; a complex pair (or multipliers of equal modulus, which
the iteration below does not separate) comes from the product of the matching small diagonal
blocks. The form is reached by the periodic orthogonal iteration G_k Q_k = Q_{k+1} R_k (a QR
factorisation per segment) repeated around the period, started from the eigenvectors of the
formed product, which already span the subspaces of the multipliers it resolves: the coupling
of two multipliers falls by their moduli's ratio every period, so the strongly damped ones,
far apart, separate in a few periods. Each step is orthogonal and touches one factor, so the
result is exact for factors perturbed by round-off relative to each factor's own norm: a
multiplier is accurate when every segment's part of it is, however small the product. On a
flow, where each segment keeps its modes apart (an exponential dichotomy), this gives the
small multipliers to nearly full relative precision, where the formed product gives round-off
and the pencils of AUTO's FLOWKM lose them below about 1e-20 (Lust 2001). Moduli beyond the
floating-point range (below 1e-308) keep their value in :attr:`Multipliers.log_moduli`.

SLICOT's periodic QR (MB03VD/MB03WD, Hench and Laub 1994) computes the same form with shifts,
but MB03WD returns transformations that do not reduce the factors (residuals of order 1) on
products with small multipliers (SLICOT-Reference issue 3, open), so it is not used.

References
----------
A. Bojanczyk, G. Golub and P. Van Dooren, "The periodic Schur decomposition: algorithms and
applications", Proc. SPIE 1770 (1992) 31-42. J. J. Hench and A. J. Laub, "Numerical solution
of the discrete-time periodic Riccati equation", IEEE Trans. Automat. Control 39 (1994)
1197-1210 (SLICOT MB03VD, MB03WD). L. Dieci and E. S. Van Vleck, "Lyapunov spectral intervals:
theory and computation", SIAM J. Numer. Anal. 40 (2002) 516-542 (the discrete QR method). K. Lust, "Improved numerical Floquet multipliers",
Int. J. Bifurcation and Chaos 11 (2001) 2389-2410.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numba import njit

from ..linalg.threads import one_blas_thread

__all__ = ["DEFLATION", "MAX_SWEEPS", "STALL", "Multipliers", "OrbitMultipliers", "periodic_schur_multipliers"]

#: An entry of the iteration's lower part below this (relative to the unit-norm factors) is round-off: it deflates.
DEFLATION = 1e-13
#: The iteration stops once the multipliers that remain coupled (one block) lie within this ratio of moduli of each
#: other: a complex pair, equal moduli, or close ones, whose coupling would fall by less than this ratio a sweep.
STALL = 0.5
#: Periods of the orthogonal iteration at most (the formed product's eigenvectors start it close to the answer).
MAX_SWEEPS = 100


@dataclass(frozen=True)
class Multipliers:
    """Floquet multipliers by decreasing modulus.

    Attributes
    ----------
    values : ndarray (n,) complex
        The multipliers; those beyond the floating-point range are 0 or infinite there, with their
        modulus in ``log_moduli``. A complex pair comes with the positive imaginary part first.
    log_moduli : ndarray (n,)
        ln |mu| of each (-inf for an exactly zero multiplier).
    angles : ndarray (n,)
        arg mu in (-pi, pi] of each (0 or pi for the real ones).
    separated : bool
        Whether the iteration separated the multipliers down to blocks of moduli within 1 / :data:`STALL`
        of each other; False where ``max_sweeps`` ran out first (many close moduli spanning decades):
        the smaller members of a wide block then carry its formed product's round-off.
    errors : ndarray (n,) or None
        Error estimates of the values, where they come from an iteration that gives them (the leading
        multipliers of a long chain's collocation by Arnoldi's method); None from the periodic Schur form.
    """

    values: np.ndarray
    log_moduli: np.ndarray
    angles: np.ndarray
    separated: bool = True
    errors: np.ndarray | None = None

    @property
    def log10_moduli(self) -> np.ndarray:
        """log10 |mu| of each."""
        return self.log_moduli / math.log(10.0)


class OrbitMultipliers:
    """What a periodic orbit derives from its Floquet multipliers, once for the shooting's
    :class:`~cosserat_chain.numerics.periodic.PeriodicOrbit` and the collocation's orbits
    (:class:`~cosserat_chain.numerics.collocation_core.ProfileOrbit`): dataclasses with the fields
    ``multipliers`` and ``multiplier_log_moduli``. Each gives its own ``trivial_multiplier_error``
    (the shooting's from the integration's error estimates, the collocation's from the distance to 1)."""

    multipliers: np.ndarray
    multiplier_log_moduli: np.ndarray | None

    @property
    def log_moduli(self) -> np.ndarray:
        """ln |mu| of :attr:`multipliers` (``multiplier_log_moduli`` where known, from the periodic Schur form, so that
        multipliers below the floating-point range keep their modulus; else ln |multipliers|)."""
        if self.multiplier_log_moduli is not None:
            return self.multiplier_log_moduli
        with np.errstate(divide="ignore"):
            return np.log(np.abs(self.multipliers))

    @property
    def trivial_index(self) -> int:
        """The index in :attr:`multipliers` of the multiplier along the flow (the one closest to 1)."""
        return int(np.argmin(np.abs(self.multipliers - 1.0)))

    @property
    def trivial_multiplier(self) -> complex:
        """The multiplier along the flow (closest to 1); it equals 1 up to the discretisation's error."""
        return complex(self.multipliers[self.trivial_index])

    @property
    def nontrivial_multipliers(self) -> np.ndarray:
        """All multipliers but the trivial one."""
        return np.delete(self.multipliers, self.trivial_index)

    @property
    def max_multiplier(self) -> float:
        """Largest modulus of the nontrivial multipliers."""
        return float(np.max(np.abs(self.nontrivial_multipliers)))

    @property
    def stable(self) -> bool:
        """Orbitally stable: every nontrivial multiplier strictly inside the unit circle."""
        return self.max_multiplier < 1.0


def _check_segments(segments) -> np.ndarray:
    """The segments as a real (m, n, n) array, or a ValueError naming what is wrong."""
    try:
        stack = np.asarray(segments)
    except ValueError as err:  # ragged sequences
        raise ValueError(f"segments must be a sequence of m >= 1 square n x n matrices of one size: {err}") from None
    if stack.dtype == object or stack.ndim != 3 or stack.shape[0] < 1 or stack.shape[1] != stack.shape[2] or stack.shape[1] < 1:
        raise ValueError(
            f"segments must be a sequence of m >= 1 square n x n matrices of one size (an (m, n, n) array), got shape {stack.shape}"
        )
    if np.iscomplexobj(stack):
        raise ValueError("segments must be real matrices (the variational flow of a real system), got complex ones")
    try:
        stack = stack.astype(float)
    except (TypeError, ValueError) as err:
        raise ValueError(f"segments must be real numbers: {err}") from None
    bad = ~np.isfinite(stack)
    if bad.any():
        k, i, j = np.argwhere(bad)[0]
        raise ValueError(f"segments must be finite, got {float(stack[k, i, j])!r} at segment {k}, entry ({i}, {j})")
    return stack


@one_blas_thread
def periodic_schur_multipliers(segments: Sequence[np.ndarray] | np.ndarray, *, max_sweeps: int = MAX_SWEEPS) -> Multipliers:
    """The eigenvalues of M = G_m ... G_1 from its factors, without forming the product (module docstring).

    Parameters
    ----------
    segments : sequence of m ndarrays (n, n), or ndarray (m, n, n)
        G_1, ..., G_m in the order of time: G_1 maps the perturbation at the start of the first
        segment to the end of it, so the monodromy is G_m ... G_1 (the last factor on the left).
    max_sweeps : int
        The most periods of the orthogonal iteration; multipliers still coupled after them (equal or
        nearly equal moduli) are taken together from the product of their diagonal blocks.

    Returns
    -------
    Multipliers
        The n multipliers by decreasing modulus, with ln |mu|, arg mu and whether they were separated.

    Raises
    ------
    ValueError
        For segments that are not m >= 1 real square matrices of one size, not finite, or max_sweeps < 1.
    """
    stack = _check_segments(segments)
    if not (isinstance(max_sweeps, (int, np.integer)) and max_sweeps >= 1):
        raise ValueError(f"max_sweeps must be an integer >= 1, got {max_sweeps!r}")
    m, n = stack.shape[0], stack.shape[1]
    # Each factor scaled by a power of two (exact), so that no product over- or underflows.
    peak = np.max(np.abs(stack), axis=(1, 2))
    exponents = np.frexp(np.where(peak > 0, peak, 1.0))[1]
    stack = np.ldexp(stack, -exponents[:, None, None])
    shift = float(np.sum(exponents)) * math.log(2.0)
    # Orthogonal (periodic QR) iteration: G_k Q_k = Q_{k+1} R_k around the period, Q_1 <- Q_{m+1}. The
    # transformations are applied to each factor alone, so that every R_k is exact for a G_k perturbed by
    # round-off of its own norm; the coupling of two multipliers in Q_1^T Q_{m+1} falls by their moduli's
    # ratio a sweep, and the couplings that do not fall (a complex pair, equal or close moduli) are kept as blocks.
    basis, triangles = _start(stack), np.empty_like(stack)
    converged = False
    for _ in range(max_sweeps):
        q = _sweep(stack, basis, triangles)
        turn = basis.T @ q  # Q_1^T M Q_1 = turn R_m ... R_1
        basis = q
        logs, angles = np.empty(n), np.empty(n)
        converged = True
        for lo, hi in _blocks(turn):
            if hi - lo <= 2:
                _small_block(turn, triangles, lo, hi - lo, logs, angles)
            else:
                factors = [turn[lo:hi, lo:hi], *(triangles[k, lo:hi, lo:hi] for k in range(m - 1, -1, -1))]
                logs[lo:hi], angles[lo:hi] = _block(factors)
            # A block whose multipliers' moduli differ by more than 1 / STALL is still separating: sweep on.
            finite = logs[lo:hi][np.isfinite(logs[lo:hi])]
            if finite.size > 1 and np.ptp(finite) > -math.log(STALL):
                converged = False
        if converged:
            break
    logs = logs + shift
    order = np.lexsort((-angles, -logs))
    logs, angles = logs[order], angles[order]
    with np.errstate(over="ignore", under="ignore", invalid="ignore"):
        moduli = np.exp(logs)
        # Real multipliers exactly real (exp(i pi) has an imaginary part of round-off).
        values = np.where(angles == 0.0, moduli + 0j, np.where(angles == math.pi, -moduli + 0j, moduli * np.exp(1j * angles)))
    return Multipliers(values=values, log_moduli=logs, angles=angles, separated=converged)


def _start(stack: np.ndarray) -> np.ndarray:
    """An orthogonal start of the iteration: the formed product's eigenvectors by decreasing modulus, orthonormalised.

    Their leading columns already span the invariant subspaces of the multipliers that the formed
    product resolves, so that the sweeps only have to separate the small ones.
    """
    product = np.eye(stack.shape[1])
    for factor in stack:
        product = factor @ product
        product = product / max(float(np.max(np.abs(product))), np.finfo(float).tiny)
    values, vectors = np.linalg.eig(product)
    order = np.lexsort((-values.imag, -np.abs(values)))
    vectors = vectors[:, order]
    # A complex pair's real and imaginary parts span its real invariant plane.
    return np.linalg.qr(np.where(values[order].imag[None, :] < 0.0, vectors.imag, vectors.real))[0]


def _blocks(turn: np.ndarray) -> list[tuple[int, int]]:
    """The diagonal blocks [lo, hi) of ``turn`` that its lower part above :data:`DEFLATION` couples (contiguous)."""
    n = turn.shape[0]
    reach = np.arange(n)
    for i, j in np.argwhere(np.abs(np.tril(turn, -1)) > DEFLATION):
        reach[j] = max(reach[j], i)
    blocks, lo = [], 0
    while lo < n:
        hi, k = lo + 1, lo
        while k < hi:
            hi = max(hi, reach[k] + 1)
            k += 1
        blocks.append((lo, hi))
        lo = hi
    return blocks


@njit(cache=True, nogil=True)
def _sweep(stack: np.ndarray, basis: np.ndarray, triangles: np.ndarray) -> np.ndarray:
    """One period of the orthogonal iteration: G_k Q_k = Q_{k+1} R_k for k = 1..m from Q_1 = ``basis``.

    Writes R_k into ``triangles[k - 1]`` and returns Q_{m+1}.
    """
    q = np.ascontiguousarray(basis)
    for k in range(stack.shape[0]):
        q, triangles[k] = np.linalg.qr(stack[k] @ np.ascontiguousarray(q))
    return q


def _block(factors: list[np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
    """ln |mu| and arg mu of the eigenvalues of the product of ``factors`` (first on the left; all but the first upper triangular).

    For blocks of three and more multipliers (equal or close moduli); those of one and two are :func:`_small_block`'s.
    """
    size = factors[0].shape[0]
    product, scale = np.eye(size), 0.0
    for factor in factors:
        product = product @ factor
        peak = float(np.max(np.abs(product)))
        if peak == 0.0:
            return np.full(size, -math.inf), np.zeros(size)
        product, scale = product / peak, scale + math.log(peak)
    values = np.linalg.eigvals(product)
    with np.errstate(divide="ignore"):
        logs = np.log(np.abs(values)) + scale
    angles = np.angle(values)
    angles = np.where(np.abs(values.imag) == 0.0, np.where(values.real < 0, math.pi, 0.0), angles)
    return logs, angles


@njit(cache=True, nogil=True, error_model="numpy")
def _small_block(turn: np.ndarray, triangles: np.ndarray, lo: int, size: int, logs: np.ndarray, angles: np.ndarray) -> None:
    """ln |mu| and arg mu of the one or two multipliers of the diagonal block at ``lo`` into ``logs``, ``angles``.

    The block's product is turn R_m ... R_1 restricted to rows and columns lo .. lo + size - 1. One
    multiplier is the product of the diagonal entries (as a sum of logarithms). Of two, the
    determinant is the product of the factors' determinants (as a sum of logarithms: exact in
    range); the product itself is kept at unit norm, its scale in a logarithm, and gives the
    larger eigenvalue (or a complex pair's angle); the smaller real one is the determinant over
    the larger, so that it keeps its digits however far apart the two are.
    """
    m = triangles.shape[0]
    if size == 1:
        log, negative, zero = np.log(abs(turn[lo, lo])), turn[lo, lo] < 0.0, turn[lo, lo] == 0.0
        for k in range(m):
            entry = triangles[k, lo, lo]
            log += np.log(abs(entry))
            negative ^= entry < 0.0
            zero |= entry == 0.0
        logs[lo], angles[lo] = log, math.pi if negative and not zero else 0.0
        return
    hi = lo + 1
    det_first = turn[lo, lo] * turn[hi, hi] - turn[lo, hi] * turn[hi, lo]
    log_det, det_sign = np.log(abs(det_first)), math.copysign(1.0, det_first)
    for k in range(m):
        entry = triangles[k, lo, lo] * triangles[k, hi, hi]
        log_det += np.log(abs(entry))
        det_sign *= np.sign(entry)
    if det_first == 0.0:
        log_det = -math.inf
    # The product turn R_m ... R_1 of the 2 x 2 blocks from the left, at unit norm, its scale in a logarithm.
    p00, p01, p10, p11 = turn[lo, lo], turn[lo, hi], turn[hi, lo], turn[hi, hi]
    scale = 0.0
    for k in range(m, -1, -1):  # k = m: the turn's block alone; then R_m ... R_1
        if k < m:
            f00, f01, f10, f11 = triangles[k, lo, lo], triangles[k, lo, hi], triangles[k, hi, lo], triangles[k, hi, hi]
            p00, p01, p10, p11 = p00 * f00 + p01 * f10, p00 * f01 + p01 * f11, p10 * f00 + p11 * f10, p10 * f01 + p11 * f11
        peak = max(abs(p00), abs(p01), abs(p10), abs(p11))
        if peak == 0.0:
            logs[lo], logs[hi], angles[lo], angles[hi] = -math.inf, -math.inf, 0.0, 0.0
            return
        p00, p01, p10, p11, scale = p00 / peak, p01 / peak, p10 / peak, p11 / peak, scale + math.log(peak)
    trace = p00 + p11
    det = p00 * p11 - p01 * p10
    disc = trace * trace - 4.0 * det
    if disc < 0.0:
        angle = math.atan2(math.sqrt(-disc), trace)
        logs[lo], logs[hi], angles[lo], angles[hi] = 0.5 * log_det, 0.5 * log_det, angle, -angle
        return
    big = 0.5 * (trace + math.copysign(math.sqrt(disc), trace))
    log_big = scale + math.log(abs(big))
    sign_big = math.copysign(1.0, big)
    logs[lo], logs[hi] = log_big, log_det - log_big
    angles[lo] = 0.0 if sign_big > 0 else math.pi
    angles[hi] = 0.0 if sign_big * det_sign > 0 else math.pi
