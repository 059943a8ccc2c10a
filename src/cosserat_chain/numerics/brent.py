"""Brent's root finder on a bracket, step for step SciPy's ``brentq``, without importing ``scipy.optimize``.

``scipy.optimize``'s package ``__init__`` loads its whole toolbox (linear programming, global
optimisers, ``scipy.spatial``, ``scipy.fft``): more CPU than the statics of a short chain take,
for the one bracketed root finder the continuation's fold location needs
(benchmarks/README.md, "Start-up"). :func:`brentq` is the same algorithm in the same floating
point operations (SciPy's ``Zeros/brentq.c``, C doubles without fused multiply-adds): the same
iterates, the same root to the last bit, and the same errors (tests/test_brent.py checks it
against SciPy's on many brackets).
"""

from __future__ import annotations

import math
from collections.abc import Callable

#: SciPy's smallest allowed relative tolerance, four machine epsilons.
RTOL_FLOOR = 4 * 2.220446049250313e-16


def brentq(f: Callable[[float], float], a: float, b: float, *, xtol: float = 2e-12, rtol: float = RTOL_FLOOR, maxiter: int = 100) -> float:
    """A root of ``f`` in the bracket [a, b], to ``xtol + rtol |x|``, as ``scipy.optimize.brentq`` finds it.

    Parameters
    ----------
    f : callable
        f(x) -> float, continuous, with f(a) and f(b) of opposite signs (or one of them zero).
    a, b : float
        The bracket's ends.
    xtol, rtol : float
        The root is known to within ``xtol + rtol * |x|`` (SciPy's defaults).
    maxiter : int
        Most iterations.

    Returns
    -------
    float
        The root, bit for bit SciPy's.

    Raises
    ------
    ValueError
        For ``xtol <= 0``, ``rtol`` below four machine epsilons, f(a) and f(b) of one sign, or f
        returning NaN.
    RuntimeError
        When ``maxiter`` iterations did not converge.
    """
    if xtol <= 0:
        raise ValueError(f"xtol too small ({xtol:g} <= 0)")
    if rtol < RTOL_FLOOR:
        raise ValueError(f"rtol too small ({rtol:g} < {RTOL_FLOOR:g})")

    def value(x: float) -> float:
        fx = f(x)
        if math.isnan(fx):
            raise ValueError(f"The function value at x={x} is NaN; solver cannot continue.")
        return float(fx)

    xpre, xcur = float(a), float(b)
    xblk = fblk = spre = scur = 0.0
    fpre, fcur = value(xpre), value(xcur)
    if fpre * fcur > 0:
        raise ValueError("f(a) and f(b) must have different signs")
    if fpre == 0:
        return xpre
    if fcur == 0:
        return xcur
    for _ in range(maxiter):
        if fpre * fcur < 0:
            xblk, fblk = xpre, fpre
            spre = scur = xcur - xpre
        if abs(fblk) < abs(fcur):
            xpre, xcur, xblk = xcur, xblk, xcur
            fpre, fcur, fblk = fcur, fblk, fcur
        delta = (xtol + rtol * abs(xcur)) / 2
        sbis = (xblk - xcur) / 2
        if fcur == 0 or abs(sbis) < delta:
            return xcur
        if abs(spre) > delta and abs(fcur) < abs(fpre):
            if xpre == xblk:  # interpolate
                stry = -fcur * (xcur - xpre) / (fcur - fpre)
            else:  # extrapolate
                dpre = (fpre - fcur) / (xpre - xcur)
                dblk = (fblk - fcur) / (xblk - xcur)
                stry = -fcur * (fblk * dblk - fpre * dpre) / (dblk * dpre * (fblk - fpre))
            bound = 3 * abs(sbis) - delta
            if 2 * abs(stry) < (abs(spre) if abs(spre) < bound else bound):  # a good short step (C's MIN)
                spre, scur = scur, stry
            else:
                spre = scur = sbis
        else:
            spre = scur = sbis
        xpre, fpre = xcur, fcur
        xcur += scur if abs(scur) > delta else (delta if sbis > 0 else -delta)
        fcur = value(xcur)
    raise RuntimeError(f"Failed to converge after {maxiter} iterations.")
