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
|phi| 2^-53 absolute error); non-finite angles give NaN. Neither is tested here:
the engine checks the angles against the limit with its runaway test, outside the
hot loop (``numerics.engine``).

Numba's cache keys a compiled function on its own source file only: after an edit
here, the cached kernels that inline :func:`sincos` (nonlinear, sine) keep the old
code until their own files change.
"""

from __future__ import annotations

import math

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
