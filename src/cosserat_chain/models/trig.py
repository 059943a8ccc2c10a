"""sin and cos of one angle together, branch-free, inline in compiled kernels.

The nonlinear and sine kernels need sin and cos of every particle's angle at every
force evaluation; two scalar libm calls took about half their time, and a call or
a branch in a loop body keeps the loop from being vectorised. :func:`sincos`
reduces the angle to [-pi/4, pi/4] with a three-part pi/2 (Cody-Waite; exact for
|phi| < :data:`REDUCTION_LIMIT`, some 160 000 turns) and evaluates the Cephes
minimax polynomials, accurate to about 1 ulp. The quadrant is applied by selects
and a sign factor, not by branches, so a loop over particles (or over the members
of a batch) compiles to packed SIMD instructions.

Beyond :data:`REDUCTION_LIMIT` the reduction loses bits gradually (about
|phi| 2^-53 absolute error); non-finite angles give NaN. Neither reaches the
kernels: the engine keeps every angle of a rotating model as whole turns plus an
angle near :data:`WRAP_ANGLE` or below (``numerics.engine``), reducing it by whole turns
with :data:`TWO_PI_1` + :data:`TWO_PI_2` + :data:`TWO_PI_3` outside the hot loop,
and :func:`split_turns` does so for a start state at any angle up to
:data:`MAX_START_ANGLE`, exactly.

Numba's cache keys a compiled function on its own source file only: after an edit
here, the cached kernels that inline :func:`sincos` (nonlinear, sine) keep the old
code until their own files change.
"""

from __future__ import annotations

import math
from fractions import Fraction

import numpy as np
from numba import njit

from .base import KERNEL_OPTIONS

_TWO_OVER_PI = 0.636619772367581343076
# pi/2 = _PIO2_1 + _PIO2_2 + _PIO2_3 (fdlibm): the first two have trailing zero
# bits, so n * _PIO2_1 and n * _PIO2_2 are exact for |n| < 2^20.
_PIO2_1 = 1.57079632673412561417e00
_PIO2_2 = 6.07710050630396597660e-11
_PIO2_3 = 2.02226624879595063154e-21
#: Largest |angle| for which the reduction is exact (2^20 quarter turns, rounded down).
REDUCTION_LIMIT = 1.0e6
# 2 pi = TWO_PI_1 + TWO_PI_2 + TWO_PI_3: four times the parts of pi/2, with the same trailing
# zero bits, so that k TWO_PI_1 and k TWO_PI_2 are exact for |k| < 2^20 turns.
#: First part of 2 pi (33 bits).
TWO_PI_1 = 4.0 * _PIO2_1
#: Second part of 2 pi (33 bits).
TWO_PI_2 = 4.0 * _PIO2_2
#: Third part of 2 pi.
TWO_PI_3 = 4.0 * _PIO2_3
#: A rotating model's angles beyond this (rad) lose their whole turns (``numerics.engine``),
#: so that a double resolves them as finely at every winding as in a run of ten turns.
WRAP_ANGLE = 64.0
#: Largest |angle| of a start state (rad): beyond 2^53 doubles are more than a radian apart,
#: and an angle says nothing about where in its turn a particle is.
MAX_START_ANGLE = 2.0**53
#: 2 pi is carried to this many bits by :func:`split_turns` (a double's 53 bits, the 53 of the
#: largest start angle, and a wide margin).
_SCALE = 2**256


#: 2 pi * _SCALE rounded down to an integer (mpmath's ``floor(2 * pi * 2**256)`` at 320 bits, written out so that a
#: run reducing a start angle does not import mpmath; tests/test_cli_startup.py recomputes it).
TWO_PI_SCALED = 727543153783532648560469885555459725306786754656784859917544302235877788932370

_S1, _S2, _S3 = 1.58962301576546568060e-10, -2.50507477628578072866e-8, 2.75573136213857245213e-6
_S4, _S5, _S6 = -1.98412698295895385996e-4, 8.33333333332211858878e-3, -1.66666666666666307295e-1
_C1, _C2, _C3 = -1.13585365213876817300e-11, 2.08757008419747316778e-9, -2.75573141792967388112e-7
_C4, _C5, _C6 = 2.48015872888517045348e-5, -1.38888888888730564116e-3, 4.16666666666665929218e-2


@njit(inline="always", **KERNEL_OPTIONS)
def sincos(angle: float) -> tuple[float, float]:
    """(sin(angle), cos(angle)) to about 1 ulp for |angle| < REDUCTION_LIMIT, without a branch."""
    n = math.floor(angle * _TWO_OVER_PI + 0.5)
    r = ((angle - n * _PIO2_1) - n * _PIO2_2) - n * _PIO2_3
    z = r * r
    s = r + r * z * (((((_S1 * z + _S2) * z + _S3) * z + _S4) * z + _S5) * z + _S6)
    c = 1.0 - 0.5 * z + z * z * (((((_C1 * z + _C2) * z + _C3) * z + _C4) * z + _C5) * z + _C6)
    # Quadrant q = n mod 4: (s, c), (c, -s), (-s, -c), (-c, s). Odd quadrants swap
    # the pair (a select), quadrants 2 and 3 flip both signs (an exact product).
    quadrant = int(n)
    odd = (quadrant & 1) != 0
    sign = 1.0 - (quadrant & 2)
    return (c if odd else s) * sign, (-s if odd else c) * sign


def split_turns(angles, name: str = "phi") -> tuple[np.ndarray, np.ndarray]:
    """Angles as (reduced, turns): angle = reduced + 2 pi turns, |reduced| <= pi, for |angle| > WRAP_ANGLE.

    Angles up to :data:`WRAP_ANGLE` are kept as they are, with 0 turns. The others are
    reduced exactly (2 pi to 256 bits in rational arithmetic, then one rounding), so that
    a start at 2 pi 10^7 + a continues as a start at a would.

    Parameters
    ----------
    angles : array_like of float
    name : str
        What the angles are, for the error message.

    Returns
    -------
    reduced : ndarray of float, turns : ndarray of int64
        Both of the shape of ``angles``.

    Raises
    ------
    ValueError
        For an angle that is not finite or beyond :data:`MAX_START_ANGLE`, naming it.
    """
    reduced = np.array(angles, dtype=float)
    turns = np.zeros(reduced.shape, dtype=np.int64)
    flat, flat_turns = reduced.reshape(-1), turns.reshape(-1)
    for i in np.flatnonzero(~(np.abs(flat) <= WRAP_ANGLE)):
        angle = float(flat[i])
        if not abs(angle) <= MAX_START_ANGLE:
            where = np.unravel_index(i, reduced.shape) if reduced.ndim else ()
            raise ValueError(
                f"{name}{list(map(int, where)) if where else ''} is {angle!r}: angles must be finite and within "
                f"+-{MAX_START_ANGLE:.4g} rad (2^53; beyond it doubles are more than a radian apart)"
            )
        exact = Fraction(angle)
        k = round(exact * _SCALE / TWO_PI_SCALED)
        flat[i] = float(exact - Fraction(k * TWO_PI_SCALED, _SCALE))
        flat_turns[i] = k
    return reduced, turns


def join_turns(reduced, turns) -> np.ndarray:
    """reduced + 2 pi turns as doubles (rounded once, but for 2^-86 |turns|): the unwrapped angle."""
    turns = np.asarray(turns)
    return (np.asarray(reduced, dtype=float) + turns * TWO_PI_2) + turns * TWO_PI_1
