"""Model (i): nonlinear springs on the exact corner geometry, potential (1).

Every bond has four links (:mod:`cosserat_chain.geometry`); a link of stiffness E
and rest length L0 between corner P0 of particle k and corner P1 of particle k+1
stores P = E (L - L0)^2 / 2 with L = |P1 - P0| (eq. 1). The forces are the exact
gradient: with the link vector D = P1 - P0 and tension T = E (1 - L0/L) D,
particle k receives the force +T and the moment r0 x T, particle k+1 the force
-T and the moment -r1 x T, where r0, r1 are the rotated corner vectors.

The model is conservative and invariant under rigid motions of the whole chain
(when the ends are not clamped). Its Hessian at rest equals the stiffness
matrix K of the linear model (iii), which is how eqs. (2)-(3) are derived.
"""

from __future__ import annotations

import math
from functools import lru_cache

import numpy as np
import scipy.sparse as sp
from numba import carray, njit

from ..geometry import bond_links, rotate
from ..linalg import BandMatrix, StiffnessRows
from ..params import ChainParams
from ..state import bonded, check_state, scatter_bonds, zero_held
from .base import (
    BOND_BLOCK,
    BOND_SUMS,
    END_SIGNATURE,
    FORCE_SIGNATURE,
    KERNEL_OPTIONS,
    LANES,
    Model,
    assemble_bond_sums,
    put_six,
    stack_floats,
)
from .linear import free_bond_rows, max_frequency
from .trig import sincos

#: Length of a uniform chain's coefficients (a, b, h, E1, E2, h - 2a, d); a graded chain's
#: append E1 of every bond, then E2 of every bond.
GRADED_OFFSET = 7


@njit(inline="always", **KERNEL_OPTIONS)
def _bond(a, b, h, E1, E2, rest1, rest2, c0, s0, c1, s1, du, dv):  # pragma: no cover - compiled
    """Force (fx, fy) and moment m0 on the left particle of a bond, moment m1 on the right one.

    The right particle receives (-fx, -fy). ``a, b, h, E1, E2, rest1, rest2``: the
    coefficients; ``c0, s0, c1, s1``: cos and sin of the two angles; ``du, dv``:
    differences of the displacements (right minus left). IEEE square roots and divisions:
    reciprocal square roots by estimate and Newton steps measured no faster in numba
    (``benchmarks/bench_engine_rsqrt.py``).
    """
    # Right-hand corners of the left particle: A = R(a, b), B = R(a, -b).
    ax = a * c0 - b * s0
    ay = a * s0 + b * c0
    bx = a * c0 + b * s0
    by = a * s0 - b * c0
    # Left-hand corners of the right particle: C = R(-a, b), D = R(-a, -b).
    cx = -a * c1 - b * s1
    cy = -a * s1 + b * c1
    dx = -a * c1 + b * s1
    dy = -a * s1 - b * c1
    ex = h + du
    ey = dv
    # Tensions T = E (1 - L0/L) (P1 - P0): top A-C, bottom B-D (E1); diagonals A-D, B-C (E2).
    lx = ex + cx - ax
    ly = ey + cy - ay
    t = E1 * (1.0 - rest1 / math.sqrt(lx * lx + ly * ly))
    top_x = t * lx
    top_y = t * ly
    lx = ex + dx - bx
    ly = ey + dy - by
    t = E1 * (1.0 - rest1 / math.sqrt(lx * lx + ly * ly))
    bot_x = t * lx
    bot_y = t * ly
    lx = ex + dx - ax
    ly = ey + dy - ay
    t = E2 * (1.0 - rest2 / math.sqrt(lx * lx + ly * ly))
    ad_x = t * lx
    ad_y = t * ly
    lx = ex + cx - bx
    ly = ey + cy - by
    t = E2 * (1.0 - rest2 / math.sqrt(lx * lx + ly * ly))
    bc_x = t * lx
    bc_y = t * ly
    fx = top_x + bot_x + ad_x + bc_x
    fy = top_y + bot_y + ad_y + bc_y
    m0 = ax * (top_y + ad_y) - ay * (top_x + ad_x) + bx * (bot_y + bc_y) - by * (bot_x + bc_x)
    m1 = -(cx * (top_y + bc_y) - cy * (top_x + bc_x) + dx * (bot_y + ad_y) - dy * (bot_x + ad_x))
    return fx, fy, m0, m1


# The chain kernels compute a block of columns c0..c1-1 in three passes over scratch on
# the stack: the sines and cosines of columns c0-1..c1, the bonds c0-1..c1-1 (four values
# each), then each column as the difference of its two bonds. One loop carrying a bond to
# the next did all three, and each of its turns waited on its own sines before its four
# square roots and divisions; apart, the bond pass keeps the divider busy: a column of a
# long chain takes a fifth less time, as in the vectorised C reference. The sines and the
# bonds are two allocations: in one, the compiler could not tell the rows it reads from
# those it writes and left the bond pass scalar. Each pass runs whole turns of LANES values,
# then its last few values, fewer than LANES, in a loop of their own, which the vectoriser
# makes one masked turn: a remainder loop takes them one at a time, and a bond alone costs
# about what a whole turn does. The 101-particle chain's 99 columns: 280 ns instead of 430
# (12 turns and four bonds alone: the remainder and bond start-1, peeled off to start the
# carried values); the 7-particle chain's five: 50 ns instead of 155.
#: Columns per block: BLOCK + 1 bonds, a multiple of LANES; more than the engine's segment
#: (``numerics.engine.SWEEP_BLOCK``), which then is one block; six rows of scratch (25 KB)
#: that stay in the L1 cache.
BLOCK = 519
_WIDTH = BLOCK + 2
#: Members per block of the batch kernel: seven rows of scratch on the stack (14 KB).
_MEMBERS = 256
_MEMBER_TRIG = 4 * _MEMBERS
_MEMBER_CARRIED = 3 * _MEMBERS
#: Values of the scratch for the sines and cosines (2, _WIDTH) and for the bonds (4, _WIDTH).
_TRIG_SIZE = 2 * _WIDTH
_BOND_SIZE = 4 * _WIDTH


@njit(inline="always", **KERNEL_OPTIONS)
def _whole_turns(count):  # pragma: no cover - compiled
    """The first ``count - count % LANES`` of ``count`` values, the rest (fewer than LANES) being one masked turn."""
    return count - count % np.uint64(LANES)


@njit(inline="always", **KERNEL_OPTIONS)
def _sines(trig, phi, first, last):  # pragma: no cover - compiled
    """sin and cos of phi[first:last] into rows 0 and 1 of ``trig``."""
    for i in range(first, last):
        s, c = sincos(phi[i])
        trig[0, i] = s
        trig[1, i] = c


@njit(inline="always", **KERNEL_OPTIONS)
def _bonds(a, b, h, E1, E2, rest1, rest2, trig, bonds, u, v, first, last):  # pragma: no cover - compiled
    """Bonds first..last-1 of a block (bond i joins its columns i and i+1) into the rows fx, fy, m0, m1 of ``bonds``."""
    for i in range(first, last):
        j = i + np.uint64(1)
        fx, fy, m0, m1 = _bond(a, b, h, E1, E2, rest1, rest2, trig[1, i], trig[0, i], trig[1, j], trig[0, j], u[j] - u[i], v[j] - v[i])
        bonds[0, i] = fx
        bonds[1, i] = fy
        bonds[2, i] = m0
        bonds[3, i] = m1


@njit(inline="always", **KERNEL_OPTIONS)
def _graded_bonds(a, b, h, rest1, rest2, E1, E2, trig, bonds, u, v, first, last):  # pragma: no cover - compiled
    """:func:`_bonds` with bond i's E1 and E2 read from E1[i], E2[i]."""
    for i in range(first, last):
        j = i + np.uint64(1)
        fx, fy, m0, m1 = _bond(
            a, b, h, E1[i], E2[i], rest1, rest2, trig[1, i], trig[0, i], trig[1, j], trig[0, j], u[j] - u[i], v[j] - v[i]
        )
        bonds[0, i] = fx
        bonds[1, i] = fy
        bonds[2, i] = m0
        bonds[3, i] = m1


@njit(inline="always", **KERNEL_OPTIONS)
def _differences(bonds, out_u, out_v, out_phi, first, last):  # pragma: no cover - compiled
    """Columns first..last-1 of a block: the right half of bond i (-fx, -fy, m1) and the left half of bond i+1 (fx, fy, m0)."""
    one = np.uint64(1)
    for i in range(first, last):
        out_u[i] = bonds[0, i + one] - bonds[0, i]
        out_v[i] = bonds[1, i + one] - bonds[1, i]
        out_phi[i] = bonds[2, i + one] + bonds[3, i]


@njit(FORCE_SIGNATURE, **KERNEL_OPTIONS)
def nonlinear_forces_kernel(x, coef, out, start, stop):  # pragma: no cover - compiled
    a, b, h, E1, E2, rest1, rest2 = coef[0], coef[1], coef[2], coef[3], coef[4], coef[5], coef[6]
    trig = carray(stack_floats(_TRIG_SIZE), (2, _WIDTH))
    bonds = carray(stack_floats(_BOND_SIZE), (4, _WIDTH))
    # Block windows from column c0-1 and unsigned indices: numba then adds no wrap-around
    # for negative indices, which (with a run-time offset) would keep the loops scalar.
    for c0 in range(start, stop, BLOCK):
        c1 = min(c0 + BLOCK, stop)
        u, v, phi = x[0, c0 - 1 :], x[1, c0 - 1 :], x[2, c0 - 1 :]
        count = np.uint64(c1 - c0)
        _sines(trig, phi, np.uint64(0), _whole_turns(count + np.uint64(2)))
        _sines(trig, phi, _whole_turns(count + np.uint64(2)), count + np.uint64(2))
        _bonds(a, b, h, E1, E2, rest1, rest2, trig, bonds, u, v, np.uint64(0), _whole_turns(count + np.uint64(1)))
        _bonds(a, b, h, E1, E2, rest1, rest2, trig, bonds, u, v, _whole_turns(count + np.uint64(1)), count + np.uint64(1))
        out_u, out_v, out_phi = out[0, c0:c1], out[1, c0:c1], out[2, c0:c1]
        _differences(bonds, out_u, out_v, out_phi, np.uint64(0), _whole_turns(count))
        _differences(bonds, out_u, out_v, out_phi, _whole_turns(count), count)


# Compiled at its first use (for FORCE_SIGNATURE, by the engine), not at import: most runs, the report's among
# them, have no graded chain, and with an empty cache it cost them its compilation (benchmarks/TIMINGS.md).
@njit(**KERNEL_OPTIONS)
def nonlinear_graded_kernel(x, coef, out, start, stop):  # pragma: no cover - compiled
    a, b, h, rest1, rest2 = coef[0], coef[1], coef[2], coef[5], coef[6]
    # nonlinear_forces_kernel with bond k's E1 and E2 read from the coefficients' tail
    # (GRADED_OFFSET: E1 of every bond, then E2), sliced from the block's first bond so
    # that every index stays 0-based.
    n_bonds = (coef.size - GRADED_OFFSET) // 2
    trig = carray(stack_floats(_TRIG_SIZE), (2, _WIDTH))
    bonds = carray(stack_floats(_BOND_SIZE), (4, _WIDTH))
    for c0 in range(start, stop, BLOCK):
        c1 = min(c0 + BLOCK, stop)
        u, v, phi = x[0, c0 - 1 :], x[1, c0 - 1 :], x[2, c0 - 1 :]
        E1, E2 = coef[GRADED_OFFSET + c0 - 1 :], coef[GRADED_OFFSET + n_bonds + c0 - 1 :]
        count = np.uint64(c1 - c0)
        _sines(trig, phi, np.uint64(0), _whole_turns(count + np.uint64(2)))
        _sines(trig, phi, _whole_turns(count + np.uint64(2)), count + np.uint64(2))
        _graded_bonds(a, b, h, rest1, rest2, E1, E2, trig, bonds, u, v, np.uint64(0), _whole_turns(count + np.uint64(1)))
        _graded_bonds(a, b, h, rest1, rest2, E1, E2, trig, bonds, u, v, _whole_turns(count + np.uint64(1)), count + np.uint64(1))
        out_u, out_v, out_phi = out[0, c0:c1], out[1, c0:c1], out[2, c0:c1]
        _differences(bonds, out_u, out_v, out_phi, np.uint64(0), _whole_turns(count))
        _differences(bonds, out_u, out_v, out_phi, _whole_turns(count), count)


@njit(inline="always", **KERNEL_OPTIONS)
def _link_stiffness(coef, bond):  # pragma: no cover - compiled
    """(E1, E2) of a bond: the scalars of a uniform chain's coefficients, or the bond's own of a graded chain's."""
    if coef.size == GRADED_OFFSET:
        return coef[3], coef[4]
    n_bonds = (coef.size - GRADED_OFFSET) // 2
    return coef[GRADED_OFFSET + bond], coef[GRADED_OFFSET + n_bonds + bond]


@njit(END_SIGNATURE, **KERNEL_OPTIONS)
def nonlinear_end_kernel(x, coef, out, first, last, ring):  # pragma: no cover - compiled
    a, b, h, rest1, rest2 = coef[0], coef[1], coef[2], coef[5], coef[6]
    n = x.shape[1]
    # Column 0 has bond 0 on its right, column n-1 bond n-2 on its left; a ring's closing
    # bond n-1 joins column n-1 (left) to column 0 (right), a neighbour h further on.
    closing_x = closing_y = closing_m0 = closing_m1 = 0.0
    if ring:
        E1, E2 = _link_stiffness(coef, n - 1)
        s0, c0 = sincos(x[2, n - 1])
        s1, c1 = sincos(x[2, 0])
        closing_x, closing_y, closing_m0, closing_m1 = _bond(
            a, b, h, E1, E2, rest1, rest2, c0, s0, c1, s1, x[0, 0] - x[0, n - 1], x[1, 0] - x[1, n - 1]
        )
    if first:
        E1, E2 = _link_stiffness(coef, 0)
        s0, c0 = sincos(x[2, 0])
        s1, c1 = sincos(x[2, 1])
        fx, fy, m0, _ = _bond(a, b, h, E1, E2, rest1, rest2, c0, s0, c1, s1, x[0, 1] - x[0, 0], x[1, 1] - x[1, 0])
        out[0, 0] = fx - closing_x
        out[1, 0] = fy - closing_y
        out[2, 0] = m0 + closing_m1
    if last:
        E1, E2 = _link_stiffness(coef, n - 2)
        s0, c0 = sincos(x[2, n - 2])
        s1, c1 = sincos(x[2, n - 1])
        fx, fy, _, m1 = _bond(a, b, h, E1, E2, rest1, rest2, c0, s0, c1, s1, x[0, n - 1] - x[0, n - 2], x[1, n - 1] - x[1, n - 2])
        out[0, n - 1] = closing_x - fx
        out[1, n - 1] = closing_y - fy
        out[2, n - 1] = closing_m0 + m1


@njit(inline="always", **KERNEL_OPTIONS)
def _batch_sines(x, k, at, trig, row, first, last):  # pragma: no cover - compiled
    """sin and cos of column k's angle, members at+first..at+last-1, into rows ``row`` and ``row + 1`` of ``trig``."""
    one = np.uint64(1)
    for i in range(first, last):
        s, c = sincos(x[2, k, at + i])
        trig[row, i] = s
        trig[row + one, i] = c


@njit(inline="always", **KERNEL_OPTIONS)
def _batch_start(coef, x, at, trig, carried, first, last):  # pragma: no cover - compiled
    """Bond 0 (columns 0, 1; their sines in rows 0-1 and 2-3 of ``trig``) of members at+first..at+last-1: it starts the carried half bond."""
    one = np.uint64(1)
    zero = np.uint64(0)
    for i in range(first, last):
        j = at + i
        fx, fy, _, m1 = _bond(
            coef[0, j], coef[1, j], coef[2, j], coef[3, j], coef[4, j], coef[5, j], coef[6, j],
            trig[1, i], trig[0, i], trig[3, i], trig[2, i], x[0, one, j] - x[0, zero, j], x[1, one, j] - x[1, zero, j],
        )  # fmt: skip
        carried[0, i], carried[1, i], carried[2, i] = fx, fy, m1


@njit(inline="always", **KERNEL_OPTIONS)
def _batch_column(coef, x, out, k, at, trig, here, right, carried, first, last):  # pragma: no cover - compiled
    """Column k's forces for members at+first..at+last-1: bond k (columns k, k+1, their sines from rows ``here``
    and ``right`` of ``trig``) less the carried bond k-1."""
    k1 = k + np.uint64(1)
    one = np.uint64(1)
    for i in range(first, last):
        j = at + i
        fx, fy, m0, m1 = _bond(
            coef[0, j], coef[1, j], coef[2, j], coef[3, j], coef[4, j], coef[5, j], coef[6, j],
            trig[here + one, i], trig[here, i], trig[right + one, i], trig[right, i], x[0, k1, j] - x[0, k, j], x[1, k1, j] - x[1, k, j],
        )  # fmt: skip
        out[0, k, j] = fx - carried[0, i]
        out[1, k, j] = fy - carried[1, i]
        out[2, k, j] = m0 + carried[2, i]
        carried[0, i], carried[1, i], carried[2, i] = fx, fy, m1


@njit(**KERNEL_OPTIONS)
def nonlinear_batch_kernel(x, coef, out):  # pragma: no cover - compiled
    n, size = np.uint64(x.shape[1]), np.uint64(x.shape[2])
    zero, one, two = np.uint64(0), np.uint64(1), np.uint64(2)
    # Per member: the sines of two columns (rows 0-1 and 2-3 of trig, taking turns as the
    # bond's left and right column) and the carried half bond, the same arithmetic as
    # nonlinear_forces_kernel member by member, in scratch on the stack (blocks of
    # _MEMBERS). Each column's sines in a loop of their own before the bonds that read them
    # (in the bond's loop they cost a fifth more time: 1000 members of 7 particles 5.1 ->
    # 4.2 ns a particle, of 101 particles 6.2 -> 4.8, as the reference's sines pass does).
    # The members in whole turns of LANES and then one masked turn (as the chain kernel's
    # columns, where a remainder loop took its values one at a time); bond 0 in a loop of
    # its own (a branch in the loop kept it scalar); indexed in three dimensions, unsigned,
    # without row slices (each an atomic reference count).
    trig = carray(stack_floats(_MEMBER_TRIG), (4, _MEMBERS))
    carried = carray(stack_floats(_MEMBER_CARRIED), (3, _MEMBERS))
    for at in range(zero, size, np.uint64(_MEMBERS)):
        count = min(at + np.uint64(_MEMBERS), size) - at
        whole = _whole_turns(count)
        for k in range(two):
            _batch_sines(x, k, at, trig, two * k, zero, whole)
            _batch_sines(x, k, at, trig, two * k, whole, count)
        _batch_start(coef, x, at, trig, carried, zero, whole)
        _batch_start(coef, x, at, trig, carried, whole, count)
        here = two
        for k in range(one, n - one):
            right = two - here
            _batch_sines(x, k + one, at, trig, right, zero, whole)
            _batch_sines(x, k + one, at, trig, right, whole, count)
            _batch_column(coef, x, out, k, at, trig, here, right, carried, zero, whole)
            _batch_column(coef, x, out, k, at, trig, here, right, carried, whole, count)
            here = right


#: Bonds per block of the Hessian kernel: the block's sums and angles stay in the L1 cache (31 KB).
_HESSIAN_BLOCK = 256


@njit(inline="always", cache=True, nogil=True, error_model="numpy")
def _link_hessian(px, py, qx, qy, stiff, rest, h, c0, s0, c1, s1, u0, u1, dv):  # pragma: no cover - compiled
    """One link's terms of its bond's Hessian sums (:data:`~.base.BOND_SUMS`), corners (px, py) left and (qx, qy) right,
    then its force (fx, fy) on the left particle and its moments on the left and the right one (as :func:`_bond`'s).

    With D the link vector, e = D / L and B = dD/d(u0, v0, phi0, u1, v1, phi1), the block
    gains B^T G B with G = d^2 P / dD^2 = E [(L0/L) e e^T + (1 - L0/L) I], and the corner
    paths' curvature (d^2 D/dphi0^2 = r0, d^2 D/dphi1^2 = -r1) adds T.r0 and -T.r1 with
    T = E (1 - L0/L) D. B's translation columns are -I (left) and I (right), so B^T G B is
    made of G itself, G p0 and G p1 for the rotation columns p0 = (r0y, -r0x),
    p1 = (-r1y, r1x), and their products.
    """
    r0x = px * c0 - py * s0
    r0y = px * s0 + py * c0
    r1x = qx * c1 - qy * s1
    r1y = qx * s1 + qy * c1
    dx = h + u1 - u0 + r1x - r0x
    dy = dv + r1y - r0y
    length = math.sqrt(dx * dx + dy * dy)
    ratio = rest / length
    ex, ey = dx / length, dy / length
    gxx = stiff * (ratio * ex * ex + 1.0 - ratio)
    gxy = stiff * ratio * ex * ey
    gyy = stiff * (ratio * ey * ey + 1.0 - ratio)
    g0x, g0y = gxx * r0y - gxy * r0x, gxy * r0y - gyy * r0x
    g1x, g1y = -gxx * r1y + gxy * r1x, -gxy * r1y + gyy * r1x
    tension = stiff * (1.0 - ratio)
    # The link's tension T = tension D on the left particle and its moments r0 x T and -r1 x T
    # after the ten sums (read by the bond kernel; dead code where only the sums are used).
    tx, ty = tension * dx, tension * dy
    return (
        gxx,
        gxy,
        gyy,
        g0x,
        g0y,
        g1x,
        g1y,
        r0y * g0x - r0x * g0y + tension * (dx * r0x + dy * r0y),
        -r1y * g1x + r1x * g1y - tension * (dx * r1x + dy * r1y),
        r0y * g1x - r0x * g1y,
        tx,
        ty,
        r0x * ty - r0y * tx,
        r1y * tx - r1x * ty,
    )


@njit(cache=True, nogil=True, error_model="numpy")
def _hessian_sums(x, h, corners, rests, stiffness, sums):  # pragma: no cover - compiled
    """Every bond's Hessian sums of P = E (L - L0)^2 / 2 over its four links into ``sums`` (10, n_bonds).

    ``corners[l]``: body-frame corners of link l on the left and the right particle;
    ``rests[l]``: its L0; ``stiffness[l, k]``: its E in bond k (:func:`_link_tables`). The
    sums (:data:`~.base.BOND_SUMS`) determine the bond's 6x6 block
    (:func:`~.base.assemble_bond_sums`), so the 36 entries are never written.

    Written for SIMD across bonds (8 bonds a turn; timings: benchmarks/TIMINGS.md): the four
    links are spelled out, the block's sines, cosines and sums share one scratch array at
    offsets fixed at compile time and the indices are unsigned (each alone kept the loop
    scalar: the vectoriser could not bound the pointers of ten output rows, or of numba's
    wrap-around for a block's run-time start), and the stiffness is one row per link (a
    stride-4 read across bonds made the vector loop as slow as the scalar one). No
    fastmath: the sums are the scalar loop's bit for bit.
    """
    n_bonds = x.shape[1] - 1
    width = _HESSIAN_BLOCK
    sines, cosines = 10 * width, 11 * width + 1  # offsets in the scratch of the block's angles (width + 1 each)
    work = np.empty(12 * width + 2)
    px0, py0, qx0, qy0 = corners[0, 0, 0], corners[0, 0, 1], corners[0, 1, 0], corners[0, 1, 1]
    px1, py1, qx1, qy1 = corners[1, 0, 0], corners[1, 0, 1], corners[1, 1, 0], corners[1, 1, 1]
    px2, py2, qx2, qy2 = corners[2, 0, 0], corners[2, 0, 1], corners[2, 1, 0], corners[2, 1, 1]
    px3, py3, qx3, qy3 = corners[3, 0, 0], corners[3, 0, 1], corners[3, 1, 0], corners[3, 1, 1]
    rest0, rest1, rest2, rest3 = rests[0], rests[1], rests[2], rests[3]
    one = np.uint64(1)
    for block in range((n_bonds + width - 1) // width):
        start = np.uint64(block * width)
        m = np.uint64(min(width, n_bonds - block * width))
        for i in range(m + one):
            s, c = sincos(x[2, start + i])
            work[sines + i] = s
            work[cosines + i] = c
        for i in range(m):
            k = start + i
            s0, s1 = work[sines + i], work[sines + i + one]
            c0, c1 = work[cosines + i], work[cosines + i + one]
            u0, u1 = x[0, k], x[0, k + one]
            dv = x[1, k + one] - x[1, k]
            t0 = _link_hessian(px0, py0, qx0, qy0, stiffness[0, k], rest0, h, c0, s0, c1, s1, u0, u1, dv)
            t1 = _link_hessian(px1, py1, qx1, qy1, stiffness[1, k], rest1, h, c0, s0, c1, s1, u0, u1, dv)
            t2 = _link_hessian(px2, py2, qx2, qy2, stiffness[2, k], rest2, h, c0, s0, c1, s1, u0, u1, dv)
            t3 = _link_hessian(px3, py3, qx3, qy3, stiffness[3, k], rest3, h, c0, s0, c1, s1, u0, u1, dv)
            work[i] = (((0.0 + t0[0]) + t1[0]) + t2[0]) + t3[0]
            work[width + i] = (((0.0 + t0[1]) + t1[1]) + t2[1]) + t3[1]
            work[2 * width + i] = (((0.0 + t0[2]) + t1[2]) + t2[2]) + t3[2]
            work[3 * width + i] = (((0.0 + t0[3]) + t1[3]) + t2[3]) + t3[3]
            work[4 * width + i] = (((0.0 + t0[4]) + t1[4]) + t2[4]) + t3[4]
            work[5 * width + i] = (((0.0 + t0[5]) + t1[5]) + t2[5]) + t3[5]
            work[6 * width + i] = (((0.0 + t0[6]) + t1[6]) + t2[6]) + t3[6]
            work[7 * width + i] = (((0.0 + t0[7]) + t1[7]) + t2[7]) + t3[7]
            work[8 * width + i] = (((0.0 + t0[8]) + t1[8]) + t2[8]) + t3[8]
            work[9 * width + i] = (((0.0 + t0[9]) + t1[9]) + t2[9]) + t3[9]
        for row in range(10):
            for i in range(m):
                sums[row, start + i] = work[row * width + i]


@njit(inline="always", **KERNEL_OPTIONS)
def _bond_rows(a, b, h, rest1, rest2, e1, e2, x, work, start, i):  # pragma: no cover - compiled
    """Bond start + i's 40 rows (the bond kernel's layout) into column i of the block's scratch ``work``."""
    width = BOND_BLOCK
    one = np.uint64(1)
    k = start + i
    s0, s1 = work[40 * width + i], work[40 * width + i + one]
    c0, c1 = work[41 * width + 1 + i], work[41 * width + 1 + i + one]
    u0, u1, dv = x[0, k], x[0, k + one], x[1, k + one] - x[1, k]
    t0 = _link_hessian(a, b, -a, b, e1, rest1, h, c0, s0, c1, s1, u0, u1, dv)
    t1 = _link_hessian(a, -b, -a, -b, e1, rest1, h, c0, s0, c1, s1, u0, u1, dv)
    t2 = _link_hessian(a, b, -a, -b, e2, rest2, h, c0, s0, c1, s1, u0, u1, dv)
    t3 = _link_hessian(a, -b, -a, b, e2, rest2, h, c0, s0, c1, s1, u0, u1, dv)
    work[i] = t0[10] + t1[10] + t2[10] + t3[10]
    work[width + i] = t0[11] + t1[11] + t2[11] + t3[11]
    work[2 * width + i] = t0[12] + t1[12] + t2[12] + t3[12]
    work[3 * width + i] = t0[13] + t1[13] + t2[13] + t3[13]
    uu, uv, vv = t0[0] + t1[0] + t2[0] + t3[0], t0[1] + t1[1] + t2[1] + t3[1], t0[2] + t1[2] + t2[2] + t3[2]
    u_p0, v_p0 = t0[3] + t1[3] + t2[3] + t3[3], t0[4] + t1[4] + t2[4] + t3[4]
    u_p1, v_p1 = t0[5] + t1[5] + t2[5] + t3[5], t0[6] + t1[6] + t2[6] + t3[6]
    p0p0, p1p1, p0p1 = t0[7] + t1[7] + t2[7] + t3[7], t0[8] + t1[8] + t2[8] + t3[8], t0[9] + t1[9] + t2[9] + t3[9]
    # Minus the Hessian (BOND_SUMS' signs: the left particle's translations enter with -1), row by row.
    put_six(work, width, 4, i, -uu, -uv, u_p0, uu, uv, u_p1)
    put_six(work, width, 10, i, -uv, -vv, v_p0, uv, vv, v_p1)
    put_six(work, width, 16, i, u_p0, v_p0, -p0p0, -u_p0, -v_p0, -p0p1)
    put_six(work, width, 22, i, uu, uv, -u_p0, -uu, -uv, -u_p1)
    put_six(work, width, 28, i, uv, vv, -v_p0, -uv, -vv, -v_p1)
    put_six(work, width, 34, i, u_p1, v_p1, -p0p1, -u_p1, -v_p1, -p1p1)


@njit(FORCE_SIGNATURE, **KERNEL_OPTIONS)
def nonlinear_bond_kernel(x, coef, out, first, last):  # pragma: no cover - compiled
    """Bonds first..last-1: the forces and their Jacobian, minus the Hessian, summed over the four
    links (:func:`_link_hessian`; top A-C and bottom B-D with E1, diagonals A-D and B-C with E2),
    for either layout of ``coef``.

    Written for SIMD across bonds, as :func:`_hessian_sums`: blocks of :data:`~.base.BOND_BLOCK` bonds in
    one scratch array at offsets fixed at compile time (40 rows, then the sines and cosines of the
    block's columns), unsigned indices, the bonds' stiffnesses read from an array (a uniform chain's
    from a block of equal values, no branch in the loop), and the rows copied out at the end of each block.
    """
    a, b, h, rest1, rest2 = coef[0], coef[1], coef[2], coef[5], coef[6]
    graded = coef.size > GRADED_OFFSET
    n_bonds = (coef.size - GRADED_OFFSET) // 2
    width = BOND_BLOCK
    work = np.empty(42 * width + 2)
    # A uniform chain's stiffnesses as a block of equal values: one loop for both layouts (its
    # body inlines four links' Hessians; a second copy for the uniform chain doubled the compile).
    uniform = np.empty((2, width))
    for i in range(width):
        uniform[0, i] = coef[3]
        uniform[1, i] = coef[4]
    one = np.uint64(1)
    for begin in range(first, last, width):
        start = np.uint64(begin)
        m = np.uint64(min(width, last - begin))
        for i in range(m + one):
            s, c = sincos(x[2, start + i])
            work[40 * width + i] = s
            work[41 * width + 1 + i] = c
        E1 = coef[GRADED_OFFSET + begin :] if graded else uniform[0]
        E2 = coef[GRADED_OFFSET + n_bonds + begin :] if graded else uniform[1]
        for i in range(m):
            _bond_rows(a, b, h, rest1, rest2, E1[i], E2[i], x, work, start, i)
        for row in range(40):
            for i in range(m):
                out[row, start + i] = work[row * width + i]


def _links(params: ChainParams, x: np.ndarray):
    """Per link of every bond (a ring's closing bond last): the link, rotated corners r0 (left) and r1 (right), link vector D."""
    u, v, phi = bonded(params, x)
    centre = np.stack([params.h * np.arange(-params.N, -params.N + u.size, dtype=float) + u, v])
    for link in bond_links(params):
        r0 = np.stack(rotate(link.left_corner, phi[:-1]))
        r1 = np.stack(rotate(link.right_corner, phi[1:]))
        yield link, r0, r1, centre[:, 1:] + r1 - centre[:, :-1] - r0


def chain_energy(params: ChainParams, x: np.ndarray) -> float:
    """Potential (1) summed over all links for any (3, 2N+1) state, whatever its ends hold.

    Unlike :meth:`NonlinearModel.energy` it does not check the state against the ends,
    so that invariance under rigid motions of the whole chain can be checked.
    """
    total = 0.0
    for link, _, _, D in _links(params, np.asarray(x, dtype=float)):
        total += np.sum(0.5 * link.stiffness * (np.hypot(D[0], D[1]) - link.rest_length) ** 2)
    return float(total)


def _cross(r: np.ndarray, t: np.ndarray) -> np.ndarray:
    return r[0] * t[1] - r[1] * t[0]


@lru_cache(maxsize=16)
def _link_tables(params: ChainParams) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The links' body-frame corners (4, 2, 2), rest lengths (4,) and stiffness per link and bond (4, n_bonds).

    Constant for a chain (the bonds of a graded chain differ in their stiffness only).
    """
    links = bond_links(params)
    corners = np.array([[link.left_corner, link.right_corner] for link in links])
    rests = np.array([link.rest_length for link in links])
    stiffness = np.empty((len(links), params.n_bonds))
    for index, link in enumerate(links):
        stiffness[index] = link.stiffness
    for array in (corners, rests, stiffness):
        array.flags.writeable = False
    return corners, rests, stiffness


@njit(cache=True, nogil=True, error_model="numpy")
def _split_hessian(x, h, corners, rests, stiffness, rows, sums):  # pragma: no cover - compiled
    """The Hessian of P = E (L - L0)^2 / 2 split as K = J^T J + G: every link's row sqrt(E) dL/dq over its bond's six
    degrees of freedom into ``rows`` (4 n_bonds, 6), and the bonds' sums (:data:`~.base.BOND_SUMS`) of G into ``sums``.

    With e = D / L, the link's d^2 P / dD^2 = E e e^T + tension (I - e e^T), tension = E (1 - L0/L)
    (:func:`_link_hessian`): its first term is the row's outer product, the second and the corner
    paths' curvature (tension D.r0 and -tension D.r1) are G's, which vanishes at rest.
    """
    n_bonds = x.shape[1] - 1
    for k in range(n_bonds):
        s0, c0 = sincos(x[2, k])
        s1, c1 = sincos(x[2, k + 1])
        u0, u1 = x[0, k], x[0, k + 1]
        dv = x[1, k + 1] - x[1, k]
        for row in range(10):
            sums[row, k] = 0.0
        for link in range(4):
            px, py, qx, qy = corners[link, 0, 0], corners[link, 0, 1], corners[link, 1, 0], corners[link, 1, 1]
            stiff = stiffness[link, k]
            r0x = px * c0 - py * s0
            r0y = px * s0 + py * c0
            r1x = qx * c1 - qy * s1
            r1y = qx * s1 + qy * c1
            dx = h + u1 - u0 + r1x - r0x
            dy = dv + r1y - r0y
            length = math.sqrt(dx * dx + dy * dy)
            ex, ey = dx / length, dy / length
            root = math.sqrt(stiff)
            i = 4 * k + link
            rows[i, 0] = -root * ex
            rows[i, 1] = -root * ey
            rows[i, 2] = root * (ex * r0y - ey * r0x)
            rows[i, 3] = root * ex
            rows[i, 4] = root * ey
            rows[i, 5] = root * (ey * r1x - ex * r1y)
            tension = stiff * (1.0 - rests[link] / length)
            gxx, gxy, gyy = tension * ey * ey, -tension * ex * ey, tension * ex * ex
            g0x, g0y = gxx * r0y - gxy * r0x, gxy * r0y - gyy * r0x
            g1x, g1y = -gxx * r1y + gxy * r1x, -gxy * r1y + gyy * r1x
            sums[0, k] += gxx
            sums[1, k] += gxy
            sums[2, k] += gyy
            sums[3, k] += g0x
            sums[4, k] += g0y
            sums[5, k] += g1x
            sums[6, k] += g1y
            sums[7, k] += r0y * g0x - r0x * g0y + tension * (dx * r0x + dy * r0y)
            sums[8, k] += -r1y * g1x + r1x * g1y - tension * (dx * r1x + dy * r1y)
            sums[9, k] += r0y * g1x - r0x * g1y


def _hessian(params: ChainParams, x: np.ndarray) -> np.ndarray:
    """Every bond's Hessian sums (:data:`~.base.BOND_SUMS`) at ``x`` (:func:`_hessian_sums`), shape (10, n_bonds)."""
    x = check_state(params, x)
    sums = np.empty((len(BOND_SUMS), params.n_bonds))
    _hessian_sums(np.ascontiguousarray(bonded(params, x)), params.h, *_link_tables(params), sums)
    return sums


class NonlinearModel(Model):
    """Nonlinear springs model (i), potential (1) on the exact corner geometry; conservative."""

    name = "nonlinear"
    conservative = True
    equation = "eq. (1)"
    rotates = True
    force_kernel = nonlinear_forces_kernel
    end_kernel = nonlinear_end_kernel
    batch_kernel = nonlinear_batch_kernel
    graded_kernel = nonlinear_graded_kernel
    bond_kernel = nonlinear_bond_kernel

    @staticmethod
    def coefficients(params: ChainParams) -> np.ndarray:
        uniform = np.array([params.a, params.b, params.h, params.E1, params.E2, params.gap, params.d])
        return np.concatenate([uniform, *params.bond_stiffness]) if params.graded_stiffness else uniform

    def energy(self, params: ChainParams, x: np.ndarray) -> float:
        return chain_energy(params, check_state(params, x))

    def bond_energy(self, params: ChainParams, x: np.ndarray) -> np.ndarray:
        """Potential (1) of the four links of every bond, shape (..., n_bonds) for x (..., 3, 2N+1)."""
        x = bonded(params, x)
        du, dv, phi = np.diff(x[..., 0, :], axis=-1), np.diff(x[..., 1, :], axis=-1), x[..., 2, :]
        # The corners rotated as geometry.rotate does, from one cosine and sine of each angle for all four links.
        c, s = np.cos(phi), np.sin(phi)
        c0, s0, c1, s1 = c[..., :-1], s[..., :-1], c[..., 1:], s[..., 1:]
        total = np.zeros(du.shape)
        for link in bond_links(params):
            (ax, ay), (bx, by) = link.left_corner, link.right_corner
            r0x, r0y = ax * c0 - ay * s0, ax * s0 + ay * c0
            r1x, r1y = bx * c1 - by * s1, bx * s1 + by * c1
            length = np.hypot(params.h + du + r1x - r0x, dv + r1y - r0y)
            total += 0.5 * link.stiffness * (length - link.rest_length) ** 2
        return total

    def max_frequency(self, params: ChainParams) -> float:
        """The infinite linear chain's bound (:func:`.linear.max_frequency`): the Hessian at rest is eq. (3)'s K.

        A graded chain has no such closed form: the generic bound from the stiffness at rest."""
        return super().max_frequency(params) if params.graded else max_frequency(params)

    def forces(self, params: ChainParams, x: np.ndarray) -> np.ndarray:
        x = check_state(params, x)
        left = np.zeros((3, params.n_bonds))
        right = np.zeros((3, params.n_bonds))
        for link, r0, r1, D in _links(params, x):
            T = link.stiffness * (1.0 - link.rest_length / np.hypot(D[0], D[1])) * D
            left[:2] += T
            left[2] += _cross(r0, T)
            right[:2] -= T
            right[2] -= _cross(r1, T)
        out = scatter_bonds(params, left, right)
        return zero_held(params, out)

    def stiffness(self, params: ChainParams, x: np.ndarray) -> sp.csr_matrix:
        """Exact Hessian of the energy over the free degrees of freedom (symmetric, banded; O(N), compiled)."""
        return assemble_bond_sums(_hessian(params, x), params)

    def stiffness_band(self, params: ChainParams, x: np.ndarray) -> BandMatrix:
        """:meth:`stiffness` assembled straight into band storage (the same values, bit for bit)."""
        return assemble_bond_sums(_hessian(params, x), params, band=True)

    def stiffness_rows(self, params: ChainParams, x: np.ndarray) -> StiffnessRows:
        """K = J^T J + G (:func:`_split_hessian`): the links' rows sqrt(E) dL/dq over the free degrees of freedom
        (left = right = J's rows) and G's band.

        Raises
        ------
        ValueError
            For a ring (its matrices are not banded).
        """
        x = check_state(params, x)
        rows = np.empty((4 * params.n_bonds, 6))
        sums = np.empty((len(BOND_SUMS), params.n_bonds))
        _split_hessian(np.ascontiguousarray(bonded(params, x)), params.h, *_link_tables(params), rows, sums)
        values, starts, before = free_bond_rows(params, rows)
        return StiffnessRows(values, values, starts, before, assemble_bond_sums(sums, params, band=True))
