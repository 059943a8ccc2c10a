"""Vectorised Numba references for the benchmarks: the package's damped Verlet scheme, written for SIMD.

Benchmark code only, not part of the package. The scheme is the one of
``cosserat_chain.numerics.integrators`` with method "verlet" on the nonlinear springs
model (``models/nonlinear.py::_bond``): per step, for every free column and row r,

    damp(h/2) kick(h/2) drift(h) | forces at the new x, + the moment | kick(h/2) damp(h/2)

with the exact damping flow v <- v exp(-gamma_r h / (2 m_r)), the kinetic energy removed
by every damping sub-step summed into ``dissipated`` and the work of the moment into
``work`` (the same sums as the package). What differs is only how the arithmetic is
laid out, so that the compiler can put four or eight particles into one SIMD register:

* ``error_model="numpy"`` (no zero-division checks) and fastmath;
* a branch-free sin/cos (Cody-Waite reduction by pi/2 in three parts, the Cephes minimax
  polynomials the package uses, the quadrant applied by arithmetic on 0/1 and +-1
  factors, no ``if``); it is accurate for |angle| < 2^20 pi/2, which
  :func:`run_single` checks once per 1024 steps, outside the hot loops;
* the force in passes over blocks of :data:`BLOCK` columns (sin/cos of the block, the
  bonds of the block, then the columns as differences of neighbouring bonds), each
  pass a loop without branches over 0-based slices;
* the dissipation sums in a loop of their own with reassociation allowed (``reassoc``),
  so that they vectorise as partial sums; the force passes keep the order of their
  sums (no ``reassoc``: the Cody-Waite reduction must not be re-associated).

:func:`run_single` runs one chain, x[3, n] (rows u, v, phi) as the package;
:func:`run_batch` runs B chains stored batch-innermost, x[3, n, B], so that the SIMD
lanes run over the members (at 7 particles the chain is too short to fill them); its
coefficients, inertia, damping and moments are per member.
``energy=False`` drops the two energy sums (they never feed back into the state).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

#: Columns per block of the force passes (the block's buffers stay in the L1 cache).
BLOCK = 256
#: Columns per block and steps per super-step of :func:`run_single_blocked` (x, v, f of a
#: block, 2.4 MB, stay in the cache for its steps).
CACHE_WIDTH = 2**15
SUPER_STEPS = 64
#: Test for a runaway or out-of-range state every so many steps, as the package does.
CHECK_EVERY = 1024
#: Angles must stay below this for the three-part reduction to be exact.
ANGLE_LIMIT = 1.0e6

# Force passes: fastmath without reassociation. Sums: everything, reassociation included.
FORCE_OPTIONS = {
    "cache": True,
    "nogil": True,
    "error_model": "numpy",
    "fastmath": {"nnan", "ninf", "nsz", "arcp", "contract", "afn"},
}
SUM_OPTIONS = {"cache": True, "nogil": True, "error_model": "numpy", "fastmath": True}
# The range test: no fastmath, which would let the compiler assume that every value is finite.
CHECK_OPTIONS = {"cache": True, "nogil": True, "error_model": "numpy"}

_TWO_OVER_PI = 0.636619772367581343076
_PIO2_1 = 1.57079632673412561417e00
_PIO2_2 = 6.07710050630396597660e-11
_PIO2_3 = 2.02226624879595063154e-21
_S1, _S2, _S3 = 1.58962301576546568060e-10, -2.50507477628578072866e-8, 2.75573136213857245213e-6
_S4, _S5, _S6 = -1.98412698295895385996e-4, 8.33333333332211858878e-3, -1.66666666666666307295e-1
_C1, _C2, _C3 = -1.13585365213876817300e-11, 2.08757008419747316778e-9, -2.75573141792967388112e-7
_C4, _C5, _C6 = 2.48015872888517045348e-5, -1.38888888888730564116e-3, 4.16666666666665929218e-2


@njit(inline="always", **FORCE_OPTIONS)
def sincos(angle):  # pragma: no cover - compiled
    """(sin, cos) of ``angle`` without a branch (|angle| < 2^20 pi/2)."""
    n = math.floor(angle * _TWO_OVER_PI + 0.5)
    r = ((angle - n * _PIO2_1) - n * _PIO2_2) - n * _PIO2_3
    z = r * r
    s = r + r * z * (((((_S1 * z + _S2) * z + _S3) * z + _S4) * z + _S5) * z + _S6)
    c = 1.0 - 0.5 * z + z * z * (((((_C1 * z + _C2) * z + _C3) * z + _C4) * z + _C5) * z + _C6)
    q = np.int64(n)
    # Quadrant q & 3: 0 (s, c), 1 (c, -s), 2 (-s, -c), 3 (-c, s). swap is 0 or 1, so
    # one of swap * c and keep * s is an exact zero and the sum is exact.
    swap = np.float64(q & 1)
    keep = 1.0 - swap
    sign_s = 1.0 - np.float64(q & 2)
    sign_c = 1.0 - np.float64((q + 1) & 2)
    return sign_s * (keep * s + swap * c), sign_c * (keep * c + swap * s)


@njit(inline="always", **FORCE_OPTIONS)
def bond(a, b, h, E1, E2, rest1, rest2, c0, s0, c1, s1, du, dv):  # pragma: no cover - compiled
    """``models/nonlinear.py::_bond`` line by line: (fx, fy) and m0 on the left particle, m1 on the right."""
    ax = a * c0 - b * s0
    ay = a * s0 + b * c0
    bx = a * c0 + b * s0
    by = a * s0 - b * c0
    cx = -a * c1 - b * s1
    cy = -a * s1 + b * c1
    dx = -a * c1 + b * s1
    dy = -a * s1 - b * c1
    ex = h + du
    ey = dv
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


# ----------------------------------------------------------------------------- one chain, x[3, n]
# Arrays are indexed in two dimensions, never sliced: every slice is a new array
# whose reference count is updated atomically, which cost about 250 ns per step.
@njit(**FORCE_OPTIONS)
def forces_columns(x, coef, f, work, c0, c1):  # pragma: no cover - compiled
    """Forces on columns c0..c1-1 (c1 - c0 <= BLOCK) into f, reading columns c0-1..c1 of x (3, n).

    ``work`` (6, BLOCK + 2) holds the block's sines, cosines and bonds. Column indices
    are unsigned: numba then emits no wrap-around for negative indices, which (with a
    run-time offset) keeps a loop from vectorising.
    """
    a, b, h, E1, E2, rest1, rest2 = coef[0], coef[1], coef[2], coef[3], coef[4], coef[5], coef[6]
    one = np.uint64(1)
    lo = np.uint64(c0)
    first = lo - one
    m = np.uint64(c1) - first  # bonds c0-1..c1-1, between columns c0-1..c1
    for i in range(m + one):
        s, c = sincos(x[2, first + i])
        work[0, i] = s
        work[1, i] = c
    for i in range(m):
        k = first + i
        fx, fy, m0, m1 = bond(
            a, b, h, E1, E2, rest1, rest2, work[1, i], work[0, i], work[1, i + one], work[0, i + one],
            x[0, k + one] - x[0, k], x[1, k + one] - x[1, k],
        )  # fmt: skip
        work[2, i] = fx
        work[3, i] = fy
        work[4, i] = m0
        work[5, i] = m1
    # Column c0+i: the right end of bond i (-fx, -fy, m1) and the left end of bond i+1.
    for i in range(m - one):
        f[0, lo + i] = work[2, i + one] - work[2, i]
        f[1, lo + i] = work[3, i + one] - work[3, i]
        f[2, lo + i] = work[5, i] + work[4, i + one]


@njit(**FORCE_OPTIONS)
def forces_columns_graded(x, coef, f, work, c0, c1):  # pragma: no cover - compiled
    """:func:`forces_columns` of a chain graded in its bonds: E1 and E2 of bond k at coef[7 + k], coef[7 + nb + k].

    The coefficient layout of ``NonlinearModel.coefficients`` for graded chains; a
    function of its own so that the uniform reference keeps its two scalar stiffnesses.
    """
    a, b, h, rest1, rest2 = coef[0], coef[1], coef[2], coef[5], coef[6]
    nb = np.uint64((coef.size - 7) // 2)
    one = np.uint64(1)
    lo = np.uint64(c0)
    first = lo - one
    m = np.uint64(c1) - first
    e1 = np.uint64(7) + first
    e2 = e1 + nb
    for i in range(m + one):
        s, c = sincos(x[2, first + i])
        work[0, i] = s
        work[1, i] = c
    for i in range(m):
        k = first + i
        fx, fy, m0, m1 = bond(
            a, b, h, coef[e1 + i], coef[e2 + i], rest1, rest2, work[1, i], work[0, i], work[1, i + one], work[0, i + one],
            x[0, k + one] - x[0, k], x[1, k + one] - x[1, k],
        )  # fmt: skip
        work[2, i] = fx
        work[3, i] = fy
        work[4, i] = m0
        work[5, i] = m1
    for i in range(m - one):
        f[0, lo + i] = work[2, i + one] - work[2, i]
        f[1, lo + i] = work[3, i + one] - work[3, i]
        f[2, lo + i] = work[5, i] + work[4, i + one]


@njit(**FORCE_OPTIONS)
def forces_single(x, coef, f, work):  # pragma: no cover - compiled
    """Forces on the free columns 1..n-2 of x (3, n) into f, block by block (a graded chain's: coef longer than 7)."""
    n = x.shape[1]
    graded = coef.size > 7
    for c0 in range(1, n - 1, BLOCK):
        if graded:
            forces_columns_graded(x, coef, f, work, c0, min(c0 + BLOCK, n - 1))
        else:
            forces_columns(x, coef, f, work, c0, min(c0 + BLOCK, n - 1))


@njit(**SUM_OPTIONS)
def close_open(x, v, f, mass, table, close, open_, c0, c1, energy):  # pragma: no cover - compiled
    """Close sub-step ``close`` and open ``open_`` on columns c0..c1-1; the energy removed by damping.

    Reassociation allowed: the two sums vectorise as partial sums. Unsigned column
    indices, as in :func:`forces_columns`.
    """
    dissipated = 0.0
    for r in range(3):
        e_close = table[close, 0, r]
        kick_close = table[close, 1, r]
        e_open = table[open_, 0, r]
        kick_open = table[open_, 1, r]
        drift = table[open_, 2, r]
        if energy:
            before_close = 0.0
            before_open = 0.0
            for k in range(np.uint64(c0), np.uint64(c1)):
                w = v[r, k] + kick_close * f[r, k]
                before_close += w * w
                w *= e_close
                before_open += w * w
                w = e_open * w + kick_open * f[r, k]
                v[r, k] = w
                x[r, k] += drift * w
            dissipated += 0.5 * mass[r] * (before_close * (1.0 - e_close * e_close) + before_open * (1.0 - e_open * e_open))
        else:
            for k in range(np.uint64(c0), np.uint64(c1)):
                w = e_close * (v[r, k] + kick_close * f[r, k])
                w = e_open * w + kick_open * f[r, k]
                v[r, k] = w
                x[r, k] += drift * w
    return dissipated


@njit(**FORCE_OPTIONS)
def _step_fused(x, v, f, coef, mass, table, close, work, energy):  # pragma: no cover - compiled
    """One sweep: kick-drift a block, then the forces one column behind it (their neighbours have moved)."""
    n = x.shape[1]
    dissipated = 0.0
    done = 1  # forces are up to date on columns < done
    for c0 in range(1, n - 1, BLOCK):
        c1 = min(c0 + BLOCK, n - 1)
        dissipated += close_open(x, v, f, mass, table, close, 0, c0, c1, energy)
        # Column c1 has not moved yet, so forces only up to c1 - 2 (the clamped last column never moves).
        stop = c1 if c1 == n - 1 else c1 - 1
        while done < stop:
            top = min(done + BLOCK, stop)
            forces_columns(x, coef, f, work, done, top)
            done = top
    return dissipated


@njit(**CHECK_OPTIONS)
def _out_of_range(x, v, max_displacement):  # pragma: no cover - compiled
    for r in range(3):
        limit = max_displacement if r < 2 else ANGLE_LIMIT
        for k in range(x.shape[1]):
            if not (abs(x[r, k]) <= limit and math.isfinite(v[r, k])):
                return True
    return False


@njit(**FORCE_OPTIONS)
def run_single(x, v, coef, mass, table, n_steps, col, moment, max_displacement, energy, fused, acc):  # pragma: no cover - compiled
    """``n_steps`` damped Verlet steps of one chain in place, from velocities at a step boundary.

    Parameters
    ----------
    x, v : ndarray (3, n)
        State; columns 0 and n-1 are clamped.
    coef : NonlinearModel.coefficients(params), (7,)
    mass : (3,) inertia of the rows
    table : (2, 3, 3) ``substep_table([1.0], dt, mass, gamma)`` (row 1: the empty sub-step)
    col, moment : a constant moment on x[2, col]
    energy : accumulate (load work, dissipated energy) into ``acc`` (2,)
    fused : one sweep per step (kick-drift of a block, then the forces behind it)
        instead of a kick-drift pass and a force pass; less memory traffic on long chains.
        Uniform chains only.

    Returns
    -------
    int
        0, or 1 if a value became non-finite or out of range (then the run stops), or
        2 (nothing done) for ``fused`` with a graded chain's coefficients.
    """
    if fused and coef.size > 7:
        return 2
    n = x.shape[1]
    f = np.zeros((3, n))
    work = np.empty((6, BLOCK + 2))
    forces_single(x, coef, f, work)
    f[2, col] += moment
    empty = 1
    pending = empty
    total = 0.0
    dissipated = 0.0
    status = 0
    to_check = CHECK_EVERY
    for k in range(n_steps):
        q_old = x[2, col]
        if fused:
            dissipated += _step_fused(x, v, f, coef, mass, table, pending, work, energy)
        else:
            dissipated += close_open(x, v, f, mass, table, pending, 0, 1, n - 1, energy)
            forces_single(x, coef, f, work)
        f[2, col] += moment
        total += moment * (x[2, col] - q_old)
        pending = 0
        last = k == n_steps - 1
        if last:
            dissipated += close_open(x, v, f, mass, table, 0, empty, 1, n - 1, energy)
        to_check -= 1
        if to_check == 0 or last:
            to_check = CHECK_EVERY
            if _out_of_range(x, v, max_displacement):
                status = 1
                break
    if energy:
        acc[0] += total
        acc[1] += dissipated
    return status


@njit(**FORCE_OPTIONS)
def run_single_blocked(
    x, v, coef, mass, table, n_steps, col, moment, max_displacement, energy, acc, width, super_steps
):  # pragma: no cover - compiled
    """:func:`run_single` (two passes a step) with temporal blocking: blocks of ``width`` columns take
    ``super_steps`` steps each from the cache.

    Each block is copied with a halo of ``super_steps + 1`` columns a side into scratch
    (the halo's outer column is held, as a clamped end: one column of the halo goes stale
    per force evaluation), advanced ``super_steps`` steps, and its own columns copied into
    a second state, which becomes the state once every block is done (double buffering:
    a block reads its neighbours' columns as they were at the start of the super-step).
    The arithmetic per column is the unblocked run's (its states agree to round-off: the
    two are compiled apart, with fastmath); the dissipated energy is counted on each
    block's own columns and summed block by block. Uniform chains, width and super_steps
    >= 1 only (status 2 otherwise); returns as :func:`run_single`.
    """
    if coef.size > 7 or width < 1 or super_steps < 1:
        return 2
    n = x.shape[1]
    halo = super_steps + 1
    f = np.zeros((3, n))
    work = np.empty((6, BLOCK + 2))
    forces_single(x, coef, f, work)
    f[2, col] += moment
    x_next, v_next, f_next = np.empty_like(x), np.empty_like(v), np.empty_like(f)
    size = min(n, width + 2 * halo)
    xs, vs, fs = np.empty(3 * size), np.empty(3 * size), np.empty(3 * size)
    x_now, v_now, f_now = x, v, f
    swapped = False
    empty = 1
    total = 0.0
    dissipated = 0.0
    status = 0
    done = 0
    to_check = CHECK_EVERY
    while done < n_steps:
        steps = min(super_steps, n_steps - done)
        closes = done + steps == n_steps
        # The edge columns never move: the first block's column 0 and the last block's n-1 are the chain's clamped ends.
        for start in range(1, n - 1, width):
            stop = min(start + width, n - 1)
            first, last = max(0, start - halo), min(n, stop + halo)
            m = last - first
            # Contiguous (3, m) views of the scratch, whatever m (a sliced (3, size) one would not vectorise).
            xb, vb, fb = xs[: 3 * m].reshape((3, m)), vs[: 3 * m].reshape((3, m)), fs[: 3 * m].reshape((3, m))
            for r in range(3):
                for k in range(m):
                    xb[r, k] = x_now[r, first + k]
                    vb[r, k] = v_now[r, first + k]
                    fb[r, k] = f_now[r, first + k]
            own0, own1 = start - first, stop - first
            here = first < col < last - 1
            counts = start <= col < stop
            pending = 0 if done > 0 else empty
            for _ in range(steps):
                q_old = xb[2, col - first] if here else 0.0
                close_open(xb, vb, fb, mass, table, pending, 0, 1, own0, False)
                dissipated += close_open(xb, vb, fb, mass, table, pending, 0, own0, own1, energy)
                close_open(xb, vb, fb, mass, table, pending, 0, own1, m - 1, False)
                forces_single(xb, coef, fb, work)
                if here:
                    fb[2, col - first] += moment
                    if counts:
                        total += moment * (xb[2, col - first] - q_old)
                pending = 0
            if closes:
                dissipated += close_open(xb, vb, fb, mass, table, 0, empty, own0, own1, energy)
            for r in range(3):
                for k in range(own0, own1):
                    x_next[r, first + k] = xb[r, k]
                    v_next[r, first + k] = vb[r, k]
                    f_next[r, first + k] = fb[r, k]
        for r in range(3):  # the clamped ends
            for k in (0, n - 1):
                x_next[r, k], v_next[r, k], f_next[r, k] = x_now[r, k], v_now[r, k], f_now[r, k]
        x_now, x_next = x_next, x_now
        v_now, v_next = v_next, v_now
        f_now, f_next = f_next, f_now
        swapped = not swapped
        done += steps
        to_check -= steps
        if to_check <= 0 or closes:
            to_check = CHECK_EVERY
            if _out_of_range(x_now, v_now, max_displacement):
                status = 1
                break
    if swapped:
        x[:] = x_now
        v[:] = v_now
    if energy:
        acc[0] += total
        acc[1] += dissipated
    return status


# ----------------------------------------------------------------------------- a batch, x[3, n, B]
@njit(**FORCE_OPTIONS)
def forces_batch(x, coef, f, sc, carry):  # pragma: no cover - compiled
    """Forces of B chains, x and f (3, n, B), coef (7, B); sc (2, n, B) and carry (3, B) scratch.

    The innermost loops run over the members; bond k-1's right half is carried to column k.
    """
    n = x.shape[1]
    size = x.shape[2]
    for k in range(n):
        for j in range(size):
            s, c = sincos(x[2, k, j])
            sc[0, k, j] = s
            sc[1, k, j] = c
    for j in range(size):  # bond 0 only starts the carry (the clamped column 0 gets no force)
        fx, fy, m0, m1 = bond(
            coef[0, j], coef[1, j], coef[2, j], coef[3, j], coef[4, j], coef[5, j], coef[6, j],
            sc[1, 0, j], sc[0, 0, j], sc[1, 1, j], sc[0, 1, j], x[0, 1, j] - x[0, 0, j], x[1, 1, j] - x[1, 0, j],
        )  # fmt: skip
        carry[0, j] = fx
        carry[1, j] = fy
        carry[2, j] = m1
    for k in range(1, n - 1):
        for j in range(size):
            fx, fy, m0, m1 = bond(
                coef[0, j], coef[1, j], coef[2, j], coef[3, j], coef[4, j], coef[5, j], coef[6, j],
                sc[1, k, j], sc[0, k, j], sc[1, k + 1, j], sc[0, k + 1, j], x[0, k + 1, j] - x[0, k, j], x[1, k + 1, j] - x[1, k, j],
            )  # fmt: skip
            f[0, k, j] = fx - carry[0, j]
            f[1, k, j] = fy - carry[1, j]
            f[2, k, j] = carry[2, j] + m0
            carry[0, j] = fx
            carry[1, j] = fy
            carry[2, j] = m1


@njit(**SUM_OPTIONS)
def close_open_batch(x, v, f, mass, factors, close, open_, energy, dissipated, sums):  # pragma: no cover - compiled
    """Close and open a sub-step for B members; factors (2, 3 kinds, 3 rows, B), mass (3, B), sums (2, B) scratch."""
    n = x.shape[1]
    size = x.shape[2]
    for r in range(3):
        if energy:
            for j in range(size):
                sums[0, j] = 0.0
                sums[1, j] = 0.0
            for k in range(1, n - 1):
                for j in range(size):
                    w = v[r, k, j] + factors[close, 1, r, j] * f[r, k, j]
                    sums[0, j] += w * w
                    w *= factors[close, 0, r, j]
                    sums[1, j] += w * w
                    w = factors[open_, 0, r, j] * w + factors[open_, 1, r, j] * f[r, k, j]
                    v[r, k, j] = w
                    x[r, k, j] += factors[open_, 2, r, j] * w
            for j in range(size):
                e_close = factors[close, 0, r, j]
                e_open = factors[open_, 0, r, j]
                dissipated[j] += 0.5 * mass[r, j] * (sums[0, j] * (1.0 - e_close * e_close) + sums[1, j] * (1.0 - e_open * e_open))
        else:
            for k in range(1, n - 1):
                for j in range(size):
                    w = factors[close, 0, r, j] * (v[r, k, j] + factors[close, 1, r, j] * f[r, k, j])
                    w = factors[open_, 0, r, j] * w + factors[open_, 1, r, j] * f[r, k, j]
                    v[r, k, j] = w
                    x[r, k, j] += factors[open_, 2, r, j] * w


@njit(**CHECK_OPTIONS)
def _out_of_range_batch(x, v, max_displacement):  # pragma: no cover - compiled
    for r in range(3):
        limit = max_displacement if r < 2 else ANGLE_LIMIT
        for k in range(x.shape[1]):
            for j in range(x.shape[2]):
                if not (abs(x[r, k, j]) <= limit and math.isfinite(v[r, k, j])):
                    return True
    return False


@njit(**FORCE_OPTIONS)
def run_batch(x, v, coef, mass, factors, n_steps, col, moments, max_displacement, energy, acc):  # pragma: no cover - compiled
    """``n_steps`` damped Verlet steps of B chains in place, stored batch-innermost.

    Parameters
    ----------
    x, v : ndarray (3, n, B)
    coef : (7, B) per-member coefficients; mass : (3, B) per-member inertia
    factors : (2, 3, 3, B) per-member ``substep_table`` entries: [sub-step, kind, row, member]
    col : column of the moments; moments : (B,)
    max_displacement : |u|, |v| beyond it is a runaway
    energy : accumulate (load work, dissipated energy) per member into ``acc`` (2, B)

    Returns
    -------
    int
        0, or 1 if some member became non-finite or out of range.
    """
    n = x.shape[1]
    size = x.shape[2]
    f = np.zeros((3, n, size))
    sc = np.empty((2, n, size))
    carry = np.empty((3, size))
    sums = np.empty((2, size))
    q_old = np.empty(size)
    dissipated = np.zeros(size)
    forces_batch(x, coef, f, sc, carry)
    for j in range(size):
        f[2, col, j] += moments[j]
    empty = 1
    pending = empty
    status = 0
    to_check = CHECK_EVERY
    for k in range(n_steps):
        for j in range(size):
            q_old[j] = x[2, col, j]
        close_open_batch(x, v, f, mass, factors, pending, 0, energy, dissipated, sums)
        forces_batch(x, coef, f, sc, carry)
        for j in range(size):
            f[2, col, j] += moments[j]
        if energy:
            for j in range(size):
                acc[0, j] += moments[j] * (x[2, col, j] - q_old[j])
        pending = 0
        last = k == n_steps - 1
        if last:
            close_open_batch(x, v, f, mass, factors, 0, empty, energy, dissipated, sums)
        to_check -= 1
        if to_check == 0 or last:
            to_check = CHECK_EVERY
            if _out_of_range_batch(x, v, max_displacement):
                status = 1
                break
    if energy:
        for j in range(size):
            acc[1, j] += dissipated[j]
    return status


# ----------------------------------------------------------------------------- Python side
def single_arrays(params, dt: float):
    """(coef, mass, table) of one chain for :func:`run_single`."""
    from cosserat_chain.models.nonlinear import NonlinearModel
    from cosserat_chain.numerics.integrators import substep_table

    mass = np.array(params.inertia)
    table = np.ascontiguousarray(substep_table(np.array([1.0]), dt, mass, np.array(params.damping)))
    return NonlinearModel.coefficients(params), mass, table


def batch_arrays(params_list, dts):
    """(coef (7, B), mass (3, B), factors (2, 3, 3, B)) of B chains for :func:`run_batch`."""
    from cosserat_chain.models.nonlinear import NonlinearModel
    from cosserat_chain.numerics.integrators import substep_table

    coef = np.ascontiguousarray(np.array([NonlinearModel.coefficients(p) for p in params_list]).T)
    mass = np.ascontiguousarray(np.array([p.inertia for p in params_list]).T)
    tables = [substep_table(np.array([1.0]), dt, np.array(p.inertia), np.array(p.damping)) for p, dt in zip(params_list, dts)]
    factors = np.ascontiguousarray(np.moveaxis(np.array(tables), 0, -1))
    return coef, mass, factors


def max_displacement(params) -> float:
    """The package's default runaway bound: 100 chain lengths."""
    return 100.0 * 2 * params.N * params.h


def packed_instructions(func, signature=None) -> dict:
    """Counts of packed (SIMD) and scalar instructions in the compiled code of ``func``.

    ``vsqrtpd``/``vdivpd`` on zmm (8 doubles) or ymm (4) registers mean that the square
    roots and divisions of the bonds run in SIMD lanes; ``vsqrtsd``/``vdivsd`` are the
    scalar forms (remainder loops). Numba disables inspection of code loaded from its
    cache: call this on freshly compiled functions (:func:`vectorisation_report`).
    """
    asm = func.inspect_asm(signature if signature is not None else func.signatures[0])
    lines = [line.strip() for line in asm.splitlines()]
    out = {}
    for op in ("vsqrtpd", "vdivpd", "vfmadd", "vmulpd", "vaddpd", "vsqrtsd", "vdivsd"):
        hits = [line.split("#")[0] for line in lines if line.startswith(op)]
        out[op] = {
            "zmm": sum("zmm" in line for line in hits),
            "ymm": sum("ymm" in line for line in hits),
            "xmm": sum("xmm" in line and "ymm" not in line and "zmm" not in line for line in hits),
        }
    return out


def vectorisation_report() -> dict:
    """Compile the hot functions and count their packed instructions (run with an empty NUMBA_CACHE_DIR)."""
    from cosserat_chain import ChainParams

    p = ChainParams(N=600)
    coef, mass, table = single_arrays(p, 0.02)
    x = np.zeros((3, p.n_particles))
    v = np.zeros_like(x)
    acc = np.zeros(2)
    for energy in (True, False):
        run_single(x, v, coef, mass, table, 2, p.N, 0.05, 600.0, energy, True, acc)
        run_single(x, v, coef, mass, table, 2, p.N, 0.05, 600.0, energy, False, acc)
    small = ChainParams(N=3)
    size = 16
    coef_b, mass_b, factors = batch_arrays([small] * size, [0.02] * size)
    xb = np.zeros((3, small.n_particles, size))
    vb = np.zeros_like(xb)
    acc_b = np.zeros((2, size))
    for energy in (True, False):
        run_batch(xb, vb, coef_b, mass_b, factors, 2, small.N, np.zeros(size), 600.0, energy, acc_b)
    out = {}
    for func in (forces_columns, close_open, forces_batch, close_open_batch):
        out[func.__name__] = [{"signature": str(sig), "counts": packed_instructions(func, sig)} for sig in func.signatures]
    return out


if __name__ == "__main__":
    import json
    import os
    import subprocess
    import sys
    import tempfile

    if "--asm" in sys.argv:
        if not os.environ.get("NUMBA_CACHE_DIR", "").startswith(tempfile.gettempdir()):
            # Compile afresh (numba does not show the code of cached functions).
            with tempfile.TemporaryDirectory() as cache:
                env = {**os.environ, "NUMBA_CACHE_DIR": cache}
                sys.exit(subprocess.run([sys.executable, __file__, *sys.argv[1:]], env=env).returncode)
        print(json.dumps(vectorisation_report(), indent=1))
    else:
        print("usage: python benchmarks/reference.py --asm   (packed-instruction counts of the hot loops, as JSON)")
