"""The dynamics engine: one compiled time loop for a batch of chains (a single run is a batch of one).

Contract
--------
For each row r in (u, v, phi) with inertia m_r (m, m, j) and viscosity gamma_r,

    m_r q_r'' = F_r(q) + L_r(t) - gamma_r q_r'

with F the model's internal forces and L the loads (eqs. (2)-(3)). One step of
size dt is a symmetric composition of damped velocity-Verlet sub-steps of sizes
c_i dt (the method's weights, :mod:`.integrators`), each

    damp(h/2) . kick(h/2) . drift(h) . kick(h/2) . damp(h/2)

with the exact viscous flow v <- v exp(-gamma h / (2 m)) as ``damp``. Between two
force evaluations the closing half of one sub-step and the opening half of the
next are one linear map of (v, f), applied as v <- A v + B f, x <- x + D v with
A, B, D from :func:`pair_table`.

A batch is B chains of the same length stored batch-innermost, x[r, k, b]
(rows, columns, members), each member with its own coefficients, inertia,
damping, time step, start time and load amplitudes, all taking the same number
of steps per call. For B = 1 the model's chain kernel runs, vectorised along
the chain; for B > 1 its batch kernel, vectorised across the members. Member b
of a batch gets the forces a batch of one computes for it to the last bit (the
kernels share their per-bond code, the end columns run the very end kernel), and
its states equal its single run's to round-off: the batch's kick-drift loop is
compiled apart from the chain's, and the compiler may round the two differently.

Along the way the loop accumulates per member the work done by the loads
(trapezoidal in each sub-step, exact for constant loads) and the energy removed
by each damping flow (exact for that flow), which close the energy balance
K + P - W + D = K0 + P0 to within the integrator's error. It stores every
``stride``-th state without changing the run: every kick-drift first closes the
previous sub-step exactly as a stored frame or a run's end closes it (:func:`pair_table`),
and a frame gets those velocities computed from the open sub-step without writing them
back, so that the states are the same bits whichever steps are stored, and a run started
from a stored frame takes the steps of the run that stored it. At every step boundary of a
single chain it counts the angular velocities beyond MAX_SPIN_PER_STEP / dt (a step that does not resolve
a turn), stored or not: a count in the kick-drift that closes them, free; from the first
step that has one on, the loop takes every step's largest exactly (lanes[PEAK_SPIN]; for
that first step the level stands in, its velocities being closed and gone). It optionally follows one column's angle per member (the
loaded particle's turns: :class:`TurnRecord`). It stops at the first check that
finds a member out of bounds (a value not finite, |u| or |v| beyond the
member's bound, a particle turning by more than :data:`MAX_ROTATION_PER_STEP` in
one step, or |phi| beyond the model's ``max_angle`` for a model that does not rotate).

Angles
------
A rotating model's forces are 2 pi-periodic in every angle, so its angles are kept
as whole turns (``winding``, int64, exact) plus an angle phi near
:data:`~cosserat_chain.models.trig.WRAP_ANGLE` (64 rad) or below: every
:data:`WRAP_EVERY` steps (global step numbers, so that a run split into calls wraps
where the whole run does) each |phi| beyond it loses its whole turns to ``winding``
(Cody-Waite, three parts of 2 pi, exact), with the out-of-bounds check, outside the
step loop. The kernels thus see angles below about 100 rad at any winding (at the
paper's spin), and a double resolves them to 1.4e-14 rad, as in a run of ten turns:
a run of 10^7 turns is as accurate as one of ten. An angle never wrapped (|phi| <= 64
throughout) keeps its bits exactly. What leaves the engine (stored
frames' ``record``, the turns' angles, :meth:`Lanes.state`) is the unwrapped angle
phi + 2 pi winding as a double; stored frames keep phi and ``winding`` apart.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numba import njit, types

from ..loads import schedule_value
from ..memory import FLOAT, require
from ..models.base import BATCH_FORCE_KERNEL_TYPE, END_KERNEL_TYPE, FORCE_KERNEL_TYPE, LANES, no_batch_forces, no_chain_forces
from ..models.trig import TWO_PI_1, TWO_PI_2, TWO_PI_3, WRAP_ANGLE, join_turns, split_turns
from ..state import force_columns, held
from .addresses import entry
from .integrators import MAX_SPIN_PER_STEP, check_time_step, default_time_step, substep_table

#: Options of the compiled loop: no fastmath, so that the state arithmetic rounds
#: the same in every copy of the loop (chain or batch, one thread or two).
_OPTIONS = {"cache": True, "nogil": True, "error_model": "numpy"}
#: The kick-drift may reassociate its kinetic-energy sums (and nothing else can be
#: reassociated in it): a strict-order sum is a reduction the vectoriser refuses.
_KICK_OPTIONS = {**_OPTIONS, "fastmath": {"reassoc"}}

#: Codes returned by the compiled loop.
STATUS_OK = 0
STATUS_BLEW_UP = 1
#: Every member has completed its TURN_LIMIT-th turn of the followed column.
STATUS_TURNED = 2

# Rows of the per-member float table ``lanes``: start time, step, bounds on |u|, |v|
# and on |phi| (a model that does not rotate), for the followed column the sense of its
# turns and its start angle (less its whole turns, TURNS_START), the |phi| beyond which
# angles lose whole turns to the winding (infinite: never), the bound on |phi'|, the
# |phi'| at a step boundary beyond which a step is not resolved (MAX_SPIN_PER_STEP / dt)
# and the largest such |phi'| met at any step boundary (0 while none passed it).
T0, DT, MAX_DISPLACEMENT, MAX_ANGLE, DIRECTION, PHI_START, WRAP_LIMIT, MAX_SPIN, WATCH_SPIN, PEAK_SPIN = range(10)
#: Number of rows of ``lanes``.
N_LANE_FIELDS = 10
#: Steps between two reductions of the angles by whole turns, done at the out-of-bounds
#: checks that fall on global multiples of it (callers check every 1024 steps, or every
#: step; a ``check_every`` must divide it): no work in the step loop (a pass every 64
#: steps cost the 7-particle chain 2-3 %), and the angles stay below WRAP_ANGLE plus what
#: a particle turns in so many steps (30 rad at the paper's spin, 0.03 rad a step).
WRAP_EVERY = 1024
#: Largest rotation of a particle in one step (rad) before a run counts as blown up: some
#: 1300 turns a step, which no step resolves; below it angles stay within the exact range
#: of the reduction (2^20 turns) between two reductions. A rotation beyond 0.5 rad a step
#: is already inaccurate (``experiments.simulation``), but not a blow-up.
MAX_ROTATION_PER_STEP = 8192.0
#: Steps between two exchanges of halos when one chain is split into blocks (:class:`Blocks`):
#: the blocks meet once per so many steps, and a block in the cache takes them all from it
#: (64 against 16: benchmarks/TIMINGS.md).
SUPER_STEPS = 64
#: Columns per block of a chain's sub-step (kick-drift then forces while in cache).
SWEEP_BLOCK = 512
#: Blocks per thread, taken by whichever thread is free.
BLOCKS_PER_THREAD = 4
#: From this many columns on, a chain runs as blocks even on one thread: its x, v and f
#: (72 bytes a column, 19 MB here) no longer stay in the cache from one step to the next,
#: and a block of :data:`CACHE_COLUMNS` takes its SUPER_STEPS steps from the cache
#: instead of streaming the chain through memory every step (a gain at 10^6 particles, a
#: loss at 10^5, whose 7 MB stay in the cache: benchmarks/TIMINGS.md).
SPLIT_COLUMNS = 2**18
#: Columns per block of such a chain (x, v, f of a block: 2.4 MB; 2^14 to 2^16 measured alike).
CACHE_COLUMNS = 2**15
# Rows of the per-member int table ``lane_ints``: turns made, blown up (0 or 1), the
# turn after which the loop stops (once every member has made it), and the whole turns
# of the followed column's start angle.
CROSSINGS, BLEW_UP, TURN_LIMIT, TURNS_START = range(4)
N_LANE_INTS = 4
#: TURN_LIMIT of a member that may turn without end.
NO_TURN_LIMIT = np.iinfo(np.int64).max


# Rows of the factors of one (close, open) pair of sub-steps (:func:`pair_table`).
DAMP, KICK, DRIFT, CLOSE_DAMP, CLOSE_KICK, LOSS = range(6)


def pair_table(table: np.ndarray, mass: np.ndarray) -> np.ndarray:
    """Factors of closing one sub-step and opening the next, for every pair and member.

    Every kick-drift closes the sub-step ``close``, kick(h/2) damp(h/2), as c <- C v + K f
    with C = e_c, K = e_c k_c, and then opens ``open``, damp(h/2) kick(h/2) drift(h), as
    v <- A c + B f, x <- x + D v with A = e_o, B = k_o. A step boundary is thus passed
    through the very velocities a stored frame or a run's end computes ([close, S]: the same
    C and K, A = 1, B = D = 0), whether it is stored or not: a run started from a stored frame
    takes the steps of the run that stored it, to the last bit, and a run's states do not
    depend on which steps it stores. The damping flows remove 0.5 m (1 - e_o^2 e_c^2) w^2 of
    kinetic energy, w = v + k_c f = c / e_c: LOSS c^2 with LOSS = 0.5 m (1 - e_o^2 e_c^2) / e_c^2
    (0 where e_c underflows to 0, a damping beyond any step, flagged by ``simulate``).

    Computed here, once, so that the compiled loop does no arithmetic on factors (with
    reassociation allowed there, a product of factors could round differently in different
    copies of the loop).

    Parameters
    ----------
    table : (S+1, 3, 3, B) from :func:`.integrators.substep_table`
    mass : (3, B) inertia of the rows

    Returns
    -------
    ndarray (S+1, S+1, 6, 3, B)
        [close, open, DAMP / KICK / DRIFT / CLOSE_DAMP / CLOSE_KICK / LOSS, row, member].
    """
    closing = table[:, None, 0]  # [close, open]: e_close
    damp = table[None, :, 0] * closing  # e_open e_close
    out = np.empty((table.shape[0], table.shape[0], 6, 3, table.shape[-1]))
    out[:, :, DAMP] = table[None, :, 0]
    out[:, :, KICK] = table[None, :, 1]
    out[:, :, DRIFT] = table[None, :, 2]
    out[:, :, CLOSE_DAMP] = closing
    out[:, :, CLOSE_KICK] = closing * table[:, None, 1]
    with np.errstate(divide="ignore", invalid="ignore"):
        out[:, :, LOSS] = np.where(closing > 0.0, 0.5 * mass * (1.0 - damp * damp) / (closing * closing), 0.0)
    return np.ascontiguousarray(out)


# --------------------------------------------------------------------------- compiled loop
@njit(inline="always", **_KICK_OPTIONS)
def _kick_drift_row(x, v, f, r, start, stop, a, bk, d, ca, ck, level):  # pragma: no cover - compiled
    """Row r of a chain on columns start..stop-1: the kick-drift (:func:`pair_table`); returns the sum of c^2
    and how many closed velocities c have c^2 > ``level`` (a count vectorises, a maximum does not).

    Two-dimensional indexing, no slices: a slice is a new array whose reference
    count is updated atomically, about 250 ns per step over the rows and sub-steps
    of a short chain. Unsigned column indices: numba then adds no wrap-around for
    negative indices, which (with a run-time offset) would keep the loop scalar.
    """
    total = 0.0
    over = 0.0
    for k in range(np.uint64(start), np.uint64(stop)):
        c = ca * v[r, k] + ck * f[r, k]
        total += c * c
        over += 1.0 if c * c > level else 0.0
        w = a * c + bk * f[r, k]
        v[r, k] = w
        x[r, k] += d * w
    return total, over


@njit(inline="always", **_KICK_OPTIONS)
def _kick_drift_row_columns(x, v, f, r, start, stop, pairs, close, open_, level):  # pragma: no cover - compiled
    """:func:`_kick_drift_row` with the factors of every column (pairs (.., 3, n)); returns the energy removed and the count."""
    removed = 0.0
    over = 0.0
    for k in range(np.uint64(start), np.uint64(stop)):
        c = pairs[close, open_, CLOSE_DAMP, r, k] * v[r, k] + pairs[close, open_, CLOSE_KICK, r, k] * f[r, k]
        removed += pairs[close, open_, LOSS, r, k] * c * c
        over += 1.0 if c * c > level else 0.0
        w = pairs[close, open_, DAMP, r, k] * c + pairs[close, open_, KICK, r, k] * f[r, k]
        v[r, k] = w
        x[r, k] += pairs[close, open_, DRIFT, r, k] * w
    return removed, over


@njit(inline="always", **_KICK_OPTIONS)
def _kick_drift_chain(x, v, f, pairs, close, open_, start, stop, level):  # pragma: no cover - compiled
    """Close ``close`` and open ``open_`` on columns start..stop-1 of a chain; returns the energy removed and how
    many closed angular velocities have a square beyond ``level``.

    Inlined into the compiled loop, which is compiled with reassociation: the state
    updates have nothing to reassociate (c <- C v + K f, v <- A c + B f, x <- x + D v with
    factors read from ``pairs``), only the energy sums and the count do, and those vectorise.
    """
    removed = 0.0
    spin = 0.0
    for r in range(3):
        total, over = _kick_drift_row(
            x, v, f, r, start, stop, pairs[close, open_, DAMP, r, 0], pairs[close, open_, KICK, r, 0],
            pairs[close, open_, DRIFT, r, 0], pairs[close, open_, CLOSE_DAMP, r, 0], pairs[close, open_, CLOSE_KICK, r, 0],
            level if r == 2 else math.inf,
        )  # fmt: skip
        removed += pairs[close, open_, LOSS, r, 0] * total
        spin += over
    return removed, spin


@njit(**_KICK_OPTIONS)
def _kick_drift_columns(x, v, f, pairs, close, open_, start, stop, level):  # pragma: no cover - compiled
    """:func:`_kick_drift_chain` of a chain graded in its inertia: the factors of every column
    (pairs (.., 3, n)). Not inlined: the uniform chain's loop must not carry its code."""
    removed = 0.0
    spin = 0.0
    for r in range(3):
        lost, over = _kick_drift_row_columns(x, v, f, r, start, stop, pairs, close, open_, level if r == 2 else math.inf)
        removed += lost
        spin += over
    return removed, spin


@njit(inline="always", **_KICK_OPTIONS)
def _kick_drift_members(x, v, f, pairs, c, o, r, at, total, first, last):  # pragma: no cover - compiled
    """Row r of members first..last-1 of a batch's column at offset ``at``: the kick-drift (:func:`pair_table`); sums c^2 into ``total``."""
    for i in range(first, last):
        closed = pairs[c, o, CLOSE_DAMP, r, i] * v[r, at + i] + pairs[c, o, CLOSE_KICK, r, i] * f[r, at + i]
        total[i] += closed * closed
        w = pairs[c, o, DAMP, r, i] * closed + pairs[c, o, KICK, r, i] * f[r, at + i]
        v[r, at + i] = w
        x[r, at + i] += pairs[c, o, DRIFT, r, i] * w


@njit(**_KICK_OPTIONS)
def _kick_drift_batch(x, v, f, pairs, close, open_, dissipated, total, start, stop):  # pragma: no cover - compiled
    """The kick-drift of a batch (B > 1) on columns [start, stop): one pass per row over (columns, members); ``total`` (B,) scratch.

    Indexed in two and five dimensions, without slices: a slice is an array whose reference
    count is updated atomically, and one per row and column (x, v, f and the factors) cost a
    batch of 1000 members of 7 particles about 5 % of its step. Unsigned indices: numba then
    adds no wrap-around for negative ones. The members in whole turns of LANES and then one
    masked turn, as in the batch force kernels (a remainder loop takes its members one at a
    time; 16 members of 101 particles: 6.5 -> 4.7 ns a particle).
    """
    size = np.uint64(dissipated.size)
    whole = size - size % np.uint64(LANES)
    c, o = np.uint64(close), np.uint64(open_)
    for r in range(3):
        for i in range(size):
            total[i] = 0.0
        for k in range(np.uint64(start), np.uint64(stop)):
            _kick_drift_members(x, v, f, pairs, c, o, r, k * size, total, np.uint64(0), whole)
            _kick_drift_members(x, v, f, pairs, c, o, r, k * size, total, whole, size)
        for i in range(size):
            dissipated[i] += pairs[c, o, LOSS, r, i] * total[i]


@njit(inline="always", **_OPTIONS)
def _segment(c0, stop, first, last):  # pragma: no cover - compiled
    """End c1 of the chain's segment that starts at column c0, and whether its energy counts (1.0 or 0.0).

    Segments are at most :data:`SWEEP_BLOCK` columns and never straddle ``first``
    or ``last``, the ends of the range whose dissipated energy counts (a block of a
    chain split over threads does not count its halo).
    """
    c1 = min(c0 + SWEEP_BLOCK, stop)
    if c0 < first:
        c1 = min(c1, first)
    elif c0 < last:
        c1 = min(c1, last)
    return c1, 1.0 if first <= c0 and c1 <= last else 0.0


@njit(**_KICK_OPTIONS)
def _close_chain(v, f, pairs, close, columns, out):  # pragma: no cover - compiled
    """Close sub-step ``close`` of one chain (B = 1): its velocities at the step boundary into ``out``; returns the energy removed.

    ``out`` (3, n) is a stored frame's slot, so that the run goes on from its open state
    as if nothing had been stored, or ``v`` itself at a run's last step; with no columns
    (3, 0) only the energy is computed. The columns not advanced (a clamped end, the
    outer edge of a block's halo) are copied. The energy removed, summed on
    [columns[2], columns[3]), has a loop of its own that only reads: it rounds alike
    whether ``out`` is ``v`` or not (a loop that writes where it reads may take the
    compiler's scalar path, whose sum rounds otherwise). Positions are not touched.
    """
    empty = pairs.shape[0] - 1
    by = np.uint64(1 if pairs.shape[4] > 1 else 0)  # the factors' column: k for a chain graded in its inertia, else 0
    start, stop, first, last = np.uint64(columns[0]), np.uint64(columns[1]), np.uint64(columns[2]), np.uint64(columns[3])
    removed = 0.0
    for r in range(3):
        for k in range(first, last):
            c = pairs[close, empty, CLOSE_DAMP, r, k * by] * v[r, k] + pairs[close, empty, CLOSE_KICK, r, k * by] * f[r, k]
            removed += pairs[close, empty, LOSS, r, k * by] * c * c
    if out.shape[1] == 0:
        return removed
    for r in range(3):
        for k in range(np.uint64(0), start):
            out[r, k] = v[r, k]
        for k in range(start, stop):
            out[r, k] = pairs[close, empty, CLOSE_DAMP, r, k * by] * v[r, k] + pairs[close, empty, CLOSE_KICK, r, k * by] * f[r, k]
        for k in range(stop, np.uint64(v.shape[1])):
            out[r, k] = v[r, k]
    return removed


@njit(**_KICK_OPTIONS)
def _close_batch(v, f, pairs, close, start, stop, out, removed):  # pragma: no cover - compiled
    """:func:`_close_chain` of a batch (B > 1, members innermost) on columns [start, stop); adds each member's energy removed to ``removed`` (B,)."""
    empty = pairs.shape[0] - 1
    size = np.uint64(removed.size)
    for r in range(3):
        for k in range(np.uint64(start), np.uint64(stop)):
            for i in range(size):
                c = pairs[close, empty, CLOSE_DAMP, r, i] * v[r, k * size + i] + pairs[close, empty, CLOSE_KICK, r, i] * f[r, k * size + i]
                removed[i] += pairs[close, empty, LOSS, r, i] * c * c
    if out.shape[1] == 0:
        return
    for r in range(3):
        for j in range(np.uint64(0), np.uint64(start) * size):
            out[r, j] = v[r, j]
        for k in range(np.uint64(start), np.uint64(stop)):
            for i in range(size):
                j = k * size + i
                out[r, j] = pairs[close, empty, CLOSE_DAMP, r, i] * v[r, j] + pairs[close, empty, CLOSE_KICK, r, i] * f[r, j]
        for j in range(np.uint64(stop) * size, np.uint64(v.shape[1])):
            out[r, j] = v[r, j]


@njit(**_OPTIONS)
def _spin_peak(v, f, pairs, close, first, last, lanes):  # pragma: no cover - compiled
    """Raise lanes[PEAK_SPIN] of every member to its largest |phi'| beyond lanes[WATCH_SPIN] at the step boundary
    on columns [first, last) (the bits of a stored frame).

    Called where the compiled loop counted any beyond the level (a count vectorises, a
    maximum of doubles stays scalar).
    """
    size = lanes.shape[1]
    empty = pairs.shape[0] - 1
    by = 1 if pairs.shape[4] > 1 else 0
    for k in range(first, last):
        for i in range(size):
            col = i + k * by
            w = abs(
                pairs[close, empty, CLOSE_DAMP, 2, col] * v[2, k * size + i] + pairs[close, empty, CLOSE_KICK, 2, col] * f[2, k * size + i]
            )
            if w > lanes[PEAK_SPIN, i] and w > lanes[WATCH_SPIN, i]:
                lanes[PEAK_SPIN, i] = w


# The four columns of a member the end kernel reads (0, 1, n-2, n-1), and its forces there.
_ENDS_SIGNATURE = types.void(
    END_KERNEL_TYPE, types.float64[:, :, ::1], types.float64[:, :, ::1], types.float64[:, ::1], types.boolean, types.boolean,
    types.boolean, types.float64[:, ::1], types.float64[:, ::1], types.float64[::1],
)  # fmt: skip


@njit(_ENDS_SIGNATURE, **_OPTIONS)
def batch_ends(end_force, x3, f3, coef, first, last, ring, sx, sf, sc):  # pragma: no cover - compiled
    """The end columns of every member of a batch (3, n, B) by the model's end kernel, member by member.

    Each member's columns 0, 1, n-2 and n-1 are copied into the (3, 4) scratch ``sx`` (a
    chain of four columns whose ends and ring seam are the member's), so that the very
    code of a single run computes them: the same bits. ``sc`` (c,) holds the member's
    coefficients, ``sf`` (3, 4) the forces.
    """
    n = x3.shape[1]
    for i in range(x3.shape[2]):
        for r in range(3):
            sx[r, 0] = x3[r, 0, i]
            sx[r, 1] = x3[r, 1, i]
            sx[r, 2] = x3[r, n - 2, i]
            sx[r, 3] = x3[r, n - 1, i]
        for c in range(coef.shape[0]):
            sc[c] = coef[c, i]
        end_force(sx, sc, sf, first, last, ring)
        for r in range(3):
            if first:
                f3[r, 0, i] = sf[r, 0]
            if last:
                f3[r, n - 1, i] = sf[r, 3]


#: A batch's sub-step (:func:`_batch_substep`), handed to the compiled loop as its fourth kernel.
_BATCH_STEP_SIGNATURE = types.void(
    BATCH_FORCE_KERNEL_TYPE, types.float64[:, ::1], types.float64[:, ::1], types.float64[:, ::1], types.float64[:, ::1], types.float64[:, :, ::1],
    types.float64[:, :, ::1], types.float64[:, ::1], types.float64[:, :, :, :, ::1], types.int64, types.int64,
    types.float64[::1], types.float64[::1], types.int64, types.int64,
)  # fmt: skip
BATCH_STEP_TYPE = types.FunctionType(_BATCH_STEP_SIGNATURE)


# Compiled at its first use (by the engine, for a batch): handed to the compiled loop as an argument
# rather than called from it, so that a loop that runs single chains, as the report's, compiles
# neither it nor the batch kick-drift (benchmarks/TIMINGS.md).
@njit(**_KICK_OPTIONS)
def _batch_substep(
    batch_force, x, v, f, out, x3, f3, coef, pairs, close, open_, dissipated, scratch, start, stop
):  # pragma: no cover - compiled
    """A batch's sub-step (B > 1) on columns [start, stop): its kick-drift, then the batch kernel on the (3, n, B) views x3, f3.

    With ``open_`` the number of sub-steps (no sub-step opened: a step closed to store it or to
    stop), :func:`_close_batch` instead: the velocities at the step boundary into ``out``, the
    energy removed added to ``dissipated``. ``scratch`` (B,) holds the members' sums.
    """
    if open_ < pairs.shape[0] - 1:
        _kick_drift_batch(x, v, f, pairs, close, open_, dissipated, scratch, start, stop)
        batch_force(x3, coef, f3)
    else:
        _close_batch(v, f, pairs, close, start, stop, out, dissipated)


@njit(_BATCH_STEP_SIGNATURE, cache=True, nogil=True)
def _no_batch_step(
    batch_force, x, v, f, out, x3, f3, coef, pairs, close, open_, dissipated, scratch, start, stop
):  # pragma: no cover - compiled
    """Fills the batch sub-step's slot of a compiled loop that runs one chain: the loop never calls it."""


@njit(**_OPTIONS)
def _close_state(
    batch_step, batch_force, x, v, f, x3, f3, coef, pairs, close, columns, dissipated, removed, scratch
):  # pragma: no cover - compiled
    """Close sub-step ``close`` in place (a run's last step, or a blow-up): velocities at the step boundary, the energy removed added.

    The same closing as a stored frame's (:func:`_close_chain`, :func:`_close_batch`), written
    into the state: a run's last frame has the bits an intermediate frame at that step would have.
    """
    empty = pairs.shape[0] - 1
    if removed.size > 1:
        for i in range(removed.size):
            removed[i] = 0.0
        batch_step(batch_force, x, v, f, v, x3, f3, coef, pairs, close, empty, removed, scratch, columns[0], columns[1])
        for i in range(removed.size):
            dissipated[i] += removed[i]
    else:
        dissipated[0] += _close_chain(v, f, pairs, close, columns, v)


@njit(**_OPTIONS)
def _runaway(x, v, lanes, lane_ints):  # pragma: no cover - compiled
    """Flag the members with a value not finite, |u| or |v| beyond their bound, or |phi'| or |phi| beyond theirs; True if any."""
    size = lanes.shape[1]
    found = False
    for r in range(3):
        for j in range(x.shape[1]):
            i = j % size
            limit = lanes[MAX_DISPLACEMENT, i] if r < 2 else lanes[MAX_ANGLE, i]
            rate = math.inf if r < 2 else lanes[MAX_SPIN, i]
            if not (math.isfinite(x[r, j]) and abs(x[r, j]) <= limit and abs(v[r, j]) <= rate):
                lane_ints[BLEW_UP, i] = 1
                found = True
    return found


@njit(**_OPTIONS)
def _wrap(x, winding, limit):  # pragma: no cover - compiled
    """Move the whole turns of every |phi| beyond ``limit`` (the model's WRAP_LIMIT) into ``winding``; True if any moved.

    Not inlined, and compiled without fastmath: the reduction's three subtractions must
    round in this order (n TWO_PI_1 and n TWO_PI_2 are exact, |n| < 2^20) wherever it runs.
    An angle within the limit keeps its bits.
    """
    moved = False
    for j in range(x.shape[1]):
        phi = x[2, j]
        if abs(phi) > limit and math.isfinite(phi):
            n = math.floor(phi * (1.0 / (2.0 * math.pi)) + 0.5)
            x[2, j] = ((phi - n * TWO_PI_1) - n * TWO_PI_2) - n * TWO_PI_3
            winding[j] += np.int64(n)
            moved = True
    return moved


@njit(inline="always", **_OPTIONS)
def _unwrapped(phi, turns):  # pragma: no cover - compiled
    """phi + 2 pi turns as a double (:func:`~cosserat_chain.models.trig.join_turns`); phi itself for 0 turns."""
    return (phi + turns * TWO_PI_2) + turns * TWO_PI_1


@njit(inline="always", **_OPTIONS)
def _winding(phi, turns, direction, phi_start, turns_start):  # pragma: no cover - compiled
    """Turns made along ``direction`` since (phi_start, turns_start) by (phi, turns), as a real number."""
    return direction * ((phi - phi_start) / (2.0 * math.pi) + (turns - turns_start))


@njit(inline="always", **_OPTIONS)
def _turn_time(level, winding_prev, winding, time_prev, time_now):  # pragma: no cover - compiled
    """When the winding reached the whole number ``level``, linear between two steps."""
    alpha = (level - winding_prev) / (winding - winding_prev)
    return time_prev + alpha * (time_now - time_prev)


@njit(**_OPTIONS)
def _follow_turns(
    x, winding, lanes, lane_ints, col, time_step, winding_prev, time_prev, ring_time, ring_step_time, ring_phi
):  # pragma: no cover - compiled
    """Record the turns of column ``col`` completed since the previous step.

    The package's one turn detector (with :func:`turns_in_frames` for stored
    frames): turn n of member b is complete when its winding
    direction (phi - phi_start) / 2 pi reaches n, and its time is interpolated
    linearly between the two steps around it; a swing back over a turn already
    made does not count again. The ring keeps the last C turns: their
    interpolated times, the time of the step after each and every particle's
    (unwrapped) angle at that step. Returns whether every member has reached its TURN_LIMIT.
    """
    size = lanes.shape[1]
    reached = True
    capacity = ring_time.shape[0]
    for i in range(size):
        at = col * size + i
        made = _winding(x[2, at], winding[at], lanes[DIRECTION, i], lanes[PHI_START, i], lane_ints[TURNS_START, i])
        crossings = lane_ints[CROSSINGS, i]
        while made >= crossings + 1:
            slot = crossings % capacity
            ring_time[slot, i] = _turn_time(crossings + 1, winding_prev[i], made, time_prev[i], time_step[i])
            ring_step_time[slot, i] = time_step[i]
            for k in range(ring_phi.shape[1]):
                ring_phi[slot, k, i] = _unwrapped(x[2, k * size + i], winding[k * size + i])
            crossings += 1
        lane_ints[CROSSINGS, i] = crossings
        winding_prev[i] = made
        time_prev[i] = time_step[i]
        reached = reached and crossings >= lane_ints[TURN_LIMIT, i]
    return reached


@njit(**_OPTIONS)
def turns_in_frames(time, phi, direction, phi_start, made):  # pragma: no cover - compiled
    """The turns completed along stored frames, by the loop's detector (:func:`_follow_turns`).

    Parameters
    ----------
    time, phi : ndarray (F,)
        Times and angles of one particle at consecutive stored steps.
    direction, phi_start : float
        Sense of the turns and the angle they count from.
    made : int
        Turns already made at frame 0.

    Returns
    -------
    made : int
        Turns made at the last frame.
    times : ndarray
        Interpolated times of the turns completed after frame 0, in order.
    """
    last = made
    for f in range(phi.shape[0]):
        last = max(last, math.floor(_winding(phi[f], 0, direction, phi_start, 0)))
    times = np.empty(last - made)
    crossings = made
    winding_prev = _winding(phi[0], 0, direction, phi_start, 0)
    for f in range(1, phi.shape[0]):
        winding = _winding(phi[f], 0, direction, phi_start, 0)
        while winding >= crossings + 1:
            times[crossings - made] = _turn_time(crossings + 1, winding_prev, winding, time[f - 1], time[f])
            crossings += 1
        winding_prev = winding
    return crossings, times


_I8 = types.int64
_STATES = types.float64[:, :, ::1]
_TABLE = types.float64[:, ::1]
_INTS = types.int64[:, ::1]
# The compiled loop's arguments in the groups :class:`Lanes` keeps them in (each named in
# :func:`advance`'s docstring): nine tuples instead of 36 positional arguments.
#: The model's chain, end and batch kernels, and the batch's sub-step.
KERNELS = types.Tuple((FORCE_KERNEL_TYPE, END_KERNEL_TYPE, BATCH_FORCE_KERNEL_TYPE, BATCH_STEP_TYPE))
#: x, v, f (3, n B), winding (n B), acc (2, B).
STATE = types.Tuple((_TABLE, _TABLE, _TABLE, types.int64[::1], _TABLE))
#: coef (c, B), chain_coef (c,), pairs (S+1, S+1, 5, 3, B), weights (S,).
FACTORS = types.Tuple((_TABLE, types.float64[::1], types.float64[:, :, :, :, ::1], types.float64[::1]))
#: load_index (L, 5), knots, load_scale (L, B).
LOADS = types.Tuple((_INTS, _TABLE, _TABLE))
#: lanes (N_LANE_FIELDS, B), lane_ints (N_LANE_INTS, B).
MEMBERS = types.Tuple((_TABLE, _INTS))
#: columns (4,), ring, fixed (H, 2).
LAYOUT = types.Tuple((types.int64[::1], types.boolean, _INTS))
#: n_steps, step0, stride, check_every, pending, close_at_end, frame0.
RUN = types.Tuple((_I8, _I8, _I8, _I8, _I8, types.boolean, _I8))
#: frames_x, frames_v (F, 3, n B), frames_acc (F, 2, B), record (F, B), frames_winding (F, n B).
FRAMES = types.Tuple((_STATES, _STATES, _STATES, _TABLE, _INTS))
#: watch, and the :class:`TurnRecord`'s time (C, B), step_time (C, B), phi (C, n, B).
TURNS = types.Tuple((_I8, _TABLE, _TABLE, _STATES))
ADVANCE_SIGNATURE = types.UniTuple(_I8, 4)(KERNELS, STATE, FACTORS, LOADS, MEMBERS, LAYOUT, RUN, FRAMES, TURNS)


@njit(ADVANCE_SIGNATURE, **_KICK_OPTIONS)
def advance(kernels, state, factors, loads, members, layout, run, frames, turns):  # pragma: no cover - compiled
    """Advance every member ``n_steps`` steps in place; store every ``stride``-th state.

    Parameters
    ----------
    kernels : (force, end_force, batch_force, batch_step)
        The model's compiled chain, end and batch kernels, and :func:`_batch_substep` (for B = 1
        stubs may fill the batch slots, for B > 1 the chain kernel's: the loop calls the chain
        and end kernels for one chain, the end kernel and ``batch_step`` for a batch).
    state : (x, v, f, winding, acc), updated in place
        x, v (3, n B): states at global step ``step0`` (time lanes[T0] + step0 lanes[DT]),
        velocities at the step boundary; column k of member b at index k B + b. f (3, n B):
        forces plus loads at those states (kept between calls: one evaluation per sub-step).
        winding (n B) of int64: whole turns of every angle (the angle is x[2] + 2 pi winding),
        updated every :data:`WRAP_EVERY` global steps (with the check there) where |x[2]| passes
        lanes[WRAP_LIMIT]. acc (2, B): running load work and dissipated energy.
    factors : (coef, chain_coef, pairs, weights)
        coef (c, B) model coefficients; chain_coef (c,) member 0's, for B = 1; pairs
        (S+1, S+1, 5, 3, B) from :func:`pair_table`; weights (S,) the method's sub-step sizes
        as fractions of dt.
    loads : (load_index, knots, load_scale)
        load_index (L, 5): row, column, first and one-past-last knot, and whether the load's
        work counts (0 or 1); knots: the schedules' knots (``Loads.compiled``); load_scale
        (L, B): amplitude of load l on member b.
    members : (lanes, lane_ints)
        Per-member tables (rows T0.., CROSSINGS..); BLEW_UP is set for members found out of bounds.
    layout : (columns, ring, fixed)
        columns (4,): advance columns [columns[0], columns[1]) (all, less a clamped end's); for
        B = 1 count the dissipated energy on [columns[2], columns[3]) (a block of a chain split
        over threads: :class:`Blocks`). ring: whether the last column is bonded to the first
        (``ChainParams.periodic``). fixed (H, 2): row and column of every degree of freedom a
        pinned end holds: their forces are zeroed after every evaluation, so that with zero
        velocity they stay where they are.
    run : (n_steps, step0, stride, check_every, pending, close_at_end, frame0)
        stride: store after every global step that is a multiple of it (and after the last if
        ``close_at_end``); check_every: test for members out of bounds after every global step
        that is a multiple of it and after the call's last step (which changes no state), a divisor of
        WRAP_EVERY; pending: the sub-step left open by the previous call (S, the number of
        sub-steps, if none); close_at_end: close the last step (velocities at the step
        boundary), False leaves it open, to be continued by the next call exactly as if the
        run had not stopped; frame0: first slot of ``frames`` to write. A store leaves the
        state open (its frame gets the closed velocities): only the closing at the end changes it.
    frames : (frames_x, frames_v, frames_acc, record, frames_winding)
        frames_x, frames_v (F, 3, n B), or F = 0 to store no states (a slot that is x and v
        itself is written only at a closed last step); frames_acc (F, 2, B);
        record (F, B): unwrapped angle of column ``watch`` at every store (when watch >= 0);
        frames_winding (F, n B): the winding at every store (F = 0 with frames_x).
    turns : (watch, ring_time, ring_step_time, ring_phi)
        The column whose angle ``record`` keeps (-1: none) and whose turns the ring follows,
        and its :class:`TurnRecord`; a ring of capacity 0 follows no turns.

    Returns
    -------
    status, steps_done, frames_written, pending
        ``status`` is STATUS_OK, STATUS_BLEW_UP (the state is then the first one
        found out of bounds) or STATUS_TURNED (the loop stopped, its step closed
        but stored only if on the stride, at the step where the last member completed its TURN_LIMIT-th
        turn); ``pending`` the sub-step left open (S if none).
    """
    force, end_force, batch_force, batch_step = kernels
    x, v, f, winding, acc = state
    coef, chain_coef, pairs, weights = factors
    load_index, knots, load_scale = loads
    lanes, lane_ints = members
    columns, ring, fixed = layout
    n_steps, step0, stride, check_every, pending, close_at_end, frame0 = run
    frames_x, frames_v, frames_acc, record, frames_winding = frames
    watch, ring_time, ring_step_time, ring_phi = turns
    size = lanes.shape[1]
    n_loads = load_index.shape[0]
    q_old = np.empty((n_loads, size))
    load_old = np.empty((n_loads, size))
    for j in range(n_loads):
        for i in range(size):
            q_old[j, i] = x[load_index[j, 0], load_index[j, 1] * size + i]
            load_old[j, i] = load_scale[j, i] * schedule_value(
                knots, load_index[j, 2], load_index[j, 3], lanes[T0, i] + step0 * lanes[DT, i]
            )
    work = acc[0]
    dissipated = acc[1]
    scratch = np.empty(size)
    removed = np.empty(size)
    no_out = np.empty((3, 0))
    step_time = np.empty(size)
    winding_prev = np.empty(size)
    time_prev = np.empty(size)
    if watch >= 0:
        for i in range(size):
            at = watch * size + i
            winding_prev[i] = _winding(x[2, at], winding[at], lanes[DIRECTION, i], lanes[PHI_START, i], lane_ints[TURNS_START, i])
            time_prev[i] = lanes[T0, i] + step0 * lanes[DT, i]
    # The batch kernel's (3, n, B) views, made once: a reshape in the loop is an array
    # made and freed every sub-step.
    x3 = x.reshape((3, x.shape[1] // size, size))
    f3 = f.reshape((3, x.shape[1] // size, size))
    frame = frame0
    keep_states = frames_x.shape[0] > 0
    n_chain = x.shape[1] // size
    ends = columns[0] == 0 or columns[1] == n_chain
    end_x = np.empty((3, 4))
    end_f = np.empty((3, 4))
    end_coef = np.empty(coef.shape[0])
    n_sub = weights.size
    empty = n_sub
    # A single chain graded in its inertia: its kick-drift factors are per column.
    by_column = size == 1 and pairs.shape[4] > 1
    spin_over = 0.0
    spin_level = lanes[WATCH_SPIN, 0] * lanes[WATCH_SPIN, 0]  # one chain's (a batch does not watch the spin)
    # Countdowns instead of a modulo per step: an integer division costs as much as
    # a small chain's kick-drift.
    to_store = stride - step0 % stride
    to_check = check_every - step0 % check_every
    wrap_limit = lanes[WRAP_LIMIT, 0]  # the model's: the same for every member
    for k in range(n_steps):
        for s in range(n_sub):
            if size > 1:
                batch_step(batch_force, x, v, f, v, x3, f3, coef, pairs, pending, s, dissipated, scratch, columns[0], columns[1])
                if ends:
                    batch_ends(end_force, x3, f3, coef, columns[0] == 0, columns[1] == n_chain, ring, end_x, end_f, end_coef)
            else:
                # One chain segment by segment: the kick-drift of a segment, then the forces one
                # column behind it (a column's force needs its right neighbour moved), while the
                # segment is in cache; two whole sweeps streamed x, v and f through memory twice a
                # step, which bounds a long chain. Written out here rather than in an inlined
                # function: an inlined function that takes arrays increfs and decrefs each of them
                # (atomic operations) around its body, unless numba can prune the pairs, and
                # around a call of the force kernel it cannot; they cost a short chain about a
                # third of its step. The chain kernel takes the interior columns; the end kernel
                # the moving end columns (a free or pinned end, a ring's seam) once all have moved.
                c0 = columns[0]
                done = max(c0, 1)
                stop, first, last = columns[1], columns[2], columns[3]
                # Opening a step the kick-drift closes the previous one: its closed angular velocities
                # are counted against the level of a step that does not resolve a turn (own columns).
                level = spin_level if s == 0 else math.inf
                while c0 < stop:
                    c1, counted = _segment(c0, stop, first, last)
                    if by_column:
                        lost, over = _kick_drift_columns(x, v, f, pairs, pending, s, c0, c1, level)
                    else:
                        lost, over = _kick_drift_chain(x, v, f, pairs, pending, s, c0, c1, level)
                    dissipated[0] += counted * lost
                    spin_over += counted * over
                    top = min(stop if c1 == stop else c1 - 1, n_chain - 1)
                    if top > done:
                        force(x, chain_coef, f, done, top)
                        done = top
                    c0 = c1
                if ends:
                    end_force(x, chain_coef, f, columns[0] == 0, stop == n_chain, ring)
            for j in range(n_loads):
                row = load_index[j, 0]
                at = load_index[j, 1] * size
                first_knot, last_knot = load_index[j, 2], load_index[j, 3]
                counts = load_index[j, 4]
                if last_knot - first_knot == 1:
                    # A constant load: no time, no search. A loop of its own, without the branch
                    # and the call, so that it vectorises across the members (a batch of 1000 spent
                    # a tenth of its step in the loop with both).
                    value = knots[first_knot, 1]
                    for i in range(size):
                        q = x[row, at + i]
                        load = load_scale[j, i] * value
                        f[row, at + i] += load
                        work[i] += counts * (0.5 * (load_old[j, i] + load) * (q - q_old[j, i]))
                        q_old[j, i] = q
                        load_old[j, i] = load
                    continue
                for i in range(size):
                    # The time of sub-step s, summed as t0 + (step0 + k) dt + w_0 dt + ... + w_s dt;
                    # in registers: a time array written every sub-step kept the compiler
                    # from hoisting anything past it (a third of a short chain's step).
                    t = lanes[T0, i] + (step0 + k) * lanes[DT, i]
                    for w in range(s + 1):
                        t += weights[w] * lanes[DT, i]
                    value = schedule_value(knots, first_knot, last_knot, t)
                    q = x[row, at + i]
                    load = load_scale[j, i] * value
                    f[row, at + i] += load
                    work[i] += counts * (0.5 * (load_old[j, i] + load) * (q - q_old[j, i]))
                    q_old[j, i] = q
                    load_old[j, i] = load
            # The pinned ends' u and v: zero force (with zero velocity they stay put). Written out: an inlined function that
            # takes arrays costs atomic reference counts (see the chain's sub-step above).
            for j in range(fixed.shape[0]):
                at = fixed[j, 1] * size
                for i in range(size):
                    f[fixed[j, 0], at + i] = 0.0
            pending = s
        turned = False
        if watch >= 0 and ring_time.shape[0] > 0:
            for i in range(size):
                step_time[i] = lanes[T0, i] + (step0 + k + 1) * lanes[DT, i]
            turned = _follow_turns(
                x, winding, lanes, lane_ints, watch, step_time, winding_prev, time_prev, ring_time, ring_step_time, ring_phi
            )
        # One chain: the angular velocities at the previous step's boundary, closed by this step's first
        # kick-drift as a frame closes them, were counted there against the level of a step that does not
        # resolve a turn (free). Their values are gone; once one has passed, the level stands for it, and
        # from then on every step's largest is taken exactly here (a scalar pass, in such runs only).
        # A batch does not watch (integrate_batch and the relaxation have no such check).
        watching = False
        if size == 1:
            if spin_over > 0.0:
                lanes[PEAK_SPIN, 0] = max(lanes[PEAK_SPIN, 0], lanes[WATCH_SPIN, 0])
                spin_over = 0.0
            watching = lanes[PEAK_SPIN, 0] > 0.0
            if watching:
                _spin_peak(v, f, pairs, pending, columns[2], columns[3], lanes)
        to_store -= 1
        to_check -= 1
        last = (k == n_steps - 1 and close_at_end) or turned
        store = to_store == 0
        if last:
            if size == 1 and not watching:
                _spin_peak(v, f, pairs, pending, columns[2], columns[3], lanes)  # no next kick-drift counts this boundary
            _close_state(batch_step, batch_force, x, v, f, x3, f3, coef, pairs, pending, columns, dissipated, removed, scratch)
            pending = empty
        if store:
            to_store = stride
            # A stored frame gets the velocities at the step boundary computed from the open state,
            # which is not written back: the run goes on as if nothing were stored, so that its
            # states do not depend on which steps are stored. The caller may hand in its last frame
            # slots as x and v (stored at a run's closed last step); nothing to copy then. Copied
            # by loops: an array assigned to a slice compiles numba's shape-mismatch message (string
            # formatting), a large part of this function's compile time with an empty cache.
            copy_states = keep_states and frames_x[frame].ctypes.data != x.ctypes.data
            if copy_states:
                for r in range(3):
                    for j in range(x.shape[1]):
                        frames_x[frame, r, j] = x[r, j]
                if last:
                    for r in range(3):
                        for j in range(x.shape[1]):
                            frames_v[frame, r, j] = v[r, j]
            for i in range(size):
                removed[i] = 0.0
            if not last:
                out = frames_v[frame] if copy_states else no_out
                if size > 1:
                    batch_step(batch_force, x, v, f, out, x3, f3, coef, pairs, pending, empty, removed, scratch, columns[0], columns[1])
                else:
                    removed[0] = _close_chain(v, f, pairs, pending, columns, out)
            if keep_states and frames_winding[frame].ctypes.data != winding.ctypes.data:
                for j in range(winding.shape[0]):
                    frames_winding[frame, j] = winding[j]
            for i in range(size):
                frames_acc[frame, 0, i] = work[i]
                frames_acc[frame, 1, i] = dissipated[i] + removed[i]
                if watch >= 0:
                    record[frame, i] = _unwrapped(x[2, watch * size + i], winding[watch * size + i])
            frame += 1
        if to_check == 0 or last or k == n_steps - 1:
            to_check = check_every
            if _runaway(x, v, lanes, lane_ints):
                if pending != empty:
                    _close_state(batch_step, batch_force, x, v, f, x3, f3, coef, pairs, pending, columns, dissipated, removed, scratch)
                return STATUS_BLEW_UP, k + 1, frame - frame0, empty
            # At the checks on global multiples of WRAP_EVERY only: a run split into calls, or
            # rerun with a check after every step, wraps where the whole run does.
            if (step0 + k + 1) % WRAP_EVERY == 0 and _wrap(x, winding, wrap_limit):
                # The loads' work counts q - q_old: their angles' old values lose the same turns.
                for j in range(n_loads):
                    for i in range(size):
                        q_old[j, i] = x[load_index[j, 0], load_index[j, 1] * size + i]
                if watch >= 0:
                    for i in range(size):
                        at = watch * size + i
                        winding_prev[i] = _winding(
                            x[2, at], winding[at], lanes[DIRECTION, i], lanes[PHI_START, i], lane_ints[TURNS_START, i]
                        )
        if turned:
            return STATUS_TURNED, k + 1, frame - frame0, empty
    return STATUS_OK, n_steps, frame - frame0, pending


@dataclass
class TurnRecord:
    """The turns of one column per member, followed step by step in the compiled loop.

    Attributes
    ----------
    time : ndarray (C, B)
        Interpolated time of each of the last C completed turns (slot n mod C holds turn n+1).
    step_time : ndarray (C, B)
        Time of the step right after each of those turns.
    phi : ndarray (C, 2N+1, B)
        Every particle's angle at that step.
    """

    time: np.ndarray
    step_time: np.ndarray
    phi: np.ndarray

    @classmethod
    def empty(cls, capacity: int, n: int, size: int) -> TurnRecord:
        return cls(np.zeros((capacity, size)), np.zeros((capacity, size)), np.zeros((capacity, n, size)))


# --------------------------------------------------------------------------- Python side
class Lanes:
    """B members of one length and one model, laid out for :func:`advance` (batch innermost).

    Parameters
    ----------
    model : Model
    params : sequence of ChainParams (B), all with the same N
    method : Method
    dt : (B,) time steps
    loads : Loads
        The loads' rows, particles and schedules, shared by all members.
    load_scale : (L, B), optional
        Amplitude of load l on member b (default 1).
    x0, v0 : (B, 3, 2N+1), optional
        Start states (default rest); a rotating model's start angles beyond
        WRAP_ANGLE are split into whole turns and the rest (:meth:`reduce_angles`).
    t0 : (B,), optional
        Start times (default 0).
    max_displacement : (B,), optional
        Bound on |u| and |v| (default 100 chain lengths).
    """

    def __init__(self, model, params, method, dt, loads, load_scale=None, x0=None, v0=None, t0=None, max_displacement=None):
        self.model = model
        self.params = list(params)
        self.method = method
        size = self.size = len(self.params)
        n = self.n = self.params[0].n_particles
        require_batch_memory(self.params)
        index, self.knots = loads.compiled(self.params[0])
        # Column 4: the load's work counts (a block of a split chain also carries its neighbours' loads).
        self.load_index = np.ascontiguousarray(np.column_stack([index, np.ones(len(index), dtype=np.int64)]))
        self.load_scale = (
            np.ones((len(loads), size)) if load_scale is None else np.ascontiguousarray(load_scale, dtype=float).reshape(len(loads), size)
        )
        # Per distinct member (a grid of loads repeats one chain a thousand times), then spread.
        which, first = distinct(self.params)
        if size > 1 and any(p.graded for p in first):
            raise ValueError("a graded chain runs as a batch of one (engine.split gives it its own part)")
        self.coef = np.ascontiguousarray(np.array([model.coefficients(p) for p in first], dtype=float).T[:, which])
        self.mass = np.ascontiguousarray(np.array([p.inertia for p in first], dtype=float).T[:, which])
        self.gamma = np.array([p.damping for p in first], dtype=float)[which]
        self.weights = np.array(method.weights, dtype=float)
        self.force_kernel, self.end_kernel = model.chain_kernels(self.params[0])
        self.lanes = np.zeros((N_LANE_FIELDS, size))
        self.lanes[T0] = 0.0 if t0 is None else t0
        self.lanes[MAX_DISPLACEMENT] = (
            np.array([100.0 * 2 * p.N * p.h for p in first])[which] if max_displacement is None else max_displacement
        )
        # A rotating model's angles are wrapped (module docstring): no bound on them; the
        # others' (the linear model's) are neither wrapped nor bounded but by their own max_angle.
        self.lanes[MAX_ANGLE] = math.inf if model.rotates else model.max_angle
        self.lanes[WRAP_LIMIT] = WRAP_ANGLE if model.rotates else math.inf
        self.lanes[DIRECTION] = 1.0
        self.lane_ints = np.zeros((N_LANE_INTS, size), dtype=np.int64)
        self.lane_ints[TURN_LIMIT] = NO_TURN_LIMIT
        self.lanes[DT] = dt
        self.lanes[MAX_SPIN] = MAX_ROTATION_PER_STEP / self.lanes[DT]
        self.lanes[WATCH_SPIN] = MAX_SPIN_PER_STEP / self.lanes[DT]
        if self.params[0].graded_inertia:
            # Factors per column (the kick-drift reads them so when the last axis is the chain's).
            columns = self.params[0].particle_inertia
            table = substep_table(self.weights, np.full(n, self.lanes[DT, 0]), columns.T, np.repeat(self.gamma, n, axis=0))
            self.pairs = pair_table(table, columns)
        else:
            self.pairs = pair_table(substep_table(self.weights, self.lanes[DT].copy(), self.mass.T, self.gamma), self.mass)
        start, stop = force_columns(self.params[0])
        self.columns = np.array([start, stop, start, stop], dtype=np.int64)
        self.ring = bool(self.params[0].periodic)
        self.fixed = held_dofs(self.params[0])
        self.pending = self.weights.size
        self.x = np.zeros((3, n, size))
        self.v = np.zeros((3, n, size))
        if x0 is not None:
            self.x[...] = np.moveaxis(np.asarray(x0, dtype=float), 0, -1)
        if v0 is not None:
            self.v[...] = np.moveaxis(np.asarray(v0, dtype=float), 0, -1)
        self.winding = np.zeros((n, size), dtype=np.int64)
        if x0 is not None:
            self.reduce_angles("x0")
        self.f = np.zeros((3, n, size))
        self.acc = np.zeros((2, size))
        self.watch = -1
        self.turns = TurnRecord.empty(1, n, size)

    def reduce_angles(self, name: str = "x0") -> None:
        """Split a rotating model's angles beyond WRAP_ANGLE into whole turns (``winding``) and the rest, exactly.

        For a start state (the loop wraps its angles itself): the same state always gives
        the same bits, so a run from phi + 2 pi k continues as a run from phi would.

        Raises
        ------
        ValueError
            For an angle beyond :data:`~cosserat_chain.models.trig.MAX_START_ANGLE` (naming ``name``).
        """
        if not self.model.rotates:
            return
        big = np.abs(self.x[2]) > WRAP_ANGLE
        if not big.any():
            return
        where = np.nonzero(big)
        for k, b in zip(*where):
            # Particle index (-N..N) and member, for the message.
            label = f"{name}[{b}] phi of particle {k - self.n // 2}" if self.size > 1 else f"{name} phi of particle {k - self.n // 2}"
            reduced, turns = split_turns(self.x[2, k, b], label)
            self.x[2, k, b] = reduced
            self.winding[k, b] += turns

    def unwrapped_angles(self) -> np.ndarray:
        """(n, B) every angle as phi + 2 pi winding (a double: exact while the winding is 0)."""
        return join_turns(self.x[2], self.winding) if self.winding.any() else self.x[2].copy()

    def follow_turns(self, col: int, capacity: int) -> None:
        """Follow the turns of column ``col`` from the current state, keeping the last ``capacity``.

        With ``capacity`` 0 the column's angle is only recorded at every store (``record``).
        """
        self.watch = int(col)
        self.turns = TurnRecord.empty(capacity, self.n, self.size)
        self.restart_turns(np.arange(self.size), np.ones(self.size))

    def restart_turns(self, members: np.ndarray, direction: np.ndarray, phi_start=None, made=0) -> None:
        """Count the turns of the given members anew along ``direction``.

        Turn n is complete when direction (phi - phi_start) reaches 2 pi n;
        ``phi_start`` (unwrapped) defaults to the current angles, and ``made`` is the number of
        turns counted already (to go on counting across runs).
        """
        self.lanes[DIRECTION, members] = direction
        if phi_start is None:
            self.lanes[PHI_START, members] = self.x[2, self.watch, members]
            self.lane_ints[TURNS_START, members] = self.winding[self.watch, members]
        else:
            reduced, turns = split_turns(np.broadcast_to(np.asarray(phi_start, dtype=float), np.shape(members)), "phi_start")
            self.lanes[PHI_START, members] = reduced
            self.lane_ints[TURNS_START, members] = turns
        self.lane_ints[CROSSINGS, members] = made

    def latest_turns(self, b: int, made_before: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Member b's turns recorded since it had made ``made_before``, oldest first (at most the ring's capacity).

        Returns (times, step_times, phi): interpolated turn times (k,), times of the
        steps after them (k,) and every particle's angle at those steps (k, 2N+1).
        """
        count = int(self.lane_ints[CROSSINGS, b])
        capacity = self.turns.time.shape[0]
        slots = np.arange(max(made_before, count - capacity), count) % max(capacity, 1)
        return self.turns.time[slots, b], self.turns.step_time[slots, b], self.turns.phi[slots, :, b].copy()

    def evaluate_forces(self) -> None:
        """Forces plus loads at the current states and times (before the first :meth:`advance`)."""
        self.f[...] = 0.0
        kind = type(self.model)
        # The kernels directly: the compiled loop's inline dispatch, called from Python with
        # the kernels as arguments, would be compiled anew in every process (not cacheable).
        if self.size == 1:
            x, coef, f = self._flat(self.x), self.coef[:, 0].copy(), self._flat(self.f)
            self.force_kernel(x, coef, f, max(1, self.columns[0]), min(self.columns[1], self.n - 1))
            if self.columns[0] == 0 or self.columns[1] == self.n:
                self.end_kernel(x, coef, f, self.columns[0] == 0, self.columns[1] == self.n, self.ring)
        else:
            kind.batch_kernel(self.x, self.coef, self.f)
            if self.columns[0] == 0 or self.columns[1] == self.n:
                batch_ends(
                    self.end_kernel, self.x, self.f, self.coef, self.columns[0] == 0, self.columns[1] == self.n, self.ring,
                    np.empty((3, 4)), np.empty((3, 4)), np.empty(self.coef.shape[0]),
                )  # fmt: skip
        for j, (row, col, start, stop, _) in enumerate(self.load_index):
            if stop - start == 1:  # constant: one value for every member
                self.f[row, col] += self.load_scale[j] * self.knots[start, 1]
                continue
            for i in range(self.size):
                self.f[row, col, i] += self.load_scale[j, i] * _schedule(self.knots, start, stop, self.lanes[T0, i])
        self.f[self.fixed[:, 0], self.fixed[:, 1]] = 0.0

    def advance(self, n_steps, step0=0, stride=None, check_every=1024, frames=None, frame0=0, close_at_end=True):
        """Run the compiled loop; returns (status, steps_done, frames_written).

        ``frames``: (frames_x, frames_v, frames_acc, record, frames_winding) to store into, or None
        to store nothing (then ``stride`` defaults to ``n_steps``). With
        ``close_at_end=False`` the last step stays open and the next call goes on
        from it as if the run had not stopped.
        """
        if frames is None:
            frames = self.no_frames()
            stride = n_steps if stride is None else stride
        frames_x, frames_v, frames_acc, record, frames_winding = frames
        flat_frames = frames_x.reshape(frames_x.shape[0], 3, self.n * self.size)
        flat_winding = frames_winding.reshape(frames_winding.shape[0], self.n * self.size)
        kind = type(self.model)
        winding = self.winding.reshape(-1)
        assert np.shares_memory(winding, self.winding)
        # The loop calls the chain kernel for one chain and the batch kernel for a batch, never
        # both: a stub in the other slot, so that a kernel the run does not use is not compiled.
        one = self.size == 1
        status, done, written, self.pending = advance(
            (
                entry(self.force_kernel if one else no_chain_forces, FORCE_KERNEL_TYPE),
                entry(self.end_kernel, END_KERNEL_TYPE),
                entry(no_batch_forces if one else kind.batch_kernel, BATCH_FORCE_KERNEL_TYPE),
                entry(_no_batch_step if one else _batch_substep, BATCH_STEP_TYPE),
            ),
            (self._flat(self.x), self._flat(self.v), self._flat(self.f), winding, self.acc),
            (self.coef, self.coef[:, 0].copy(), self.pairs, self.weights),
            (self.load_index, self.knots, self.load_scale),
            (self.lanes, self.lane_ints),
            (self.columns, self.ring, self.fixed),
            (int(n_steps), int(step0), int(stride), int(check_every), int(self.pending), bool(close_at_end), int(frame0)),
            (flat_frames, frames_v.reshape(flat_frames.shape), frames_acc, record, flat_winding),
            (self.watch, self.turns.time, self.turns.step_time, self.turns.phi),
        )
        return status, done, written

    @staticmethod
    def _flat(a: np.ndarray) -> np.ndarray:
        """(3, n, B) as the (3, n B) view the compiled loop takes (no copy: the arrays are contiguous)."""
        flat = a.reshape(3, -1)
        assert np.shares_memory(flat, a)
        return flat

    def no_frames(self):
        """Frame buffers for a call that stores no states (one store, at the end)."""
        return (
            np.zeros((0, 3, self.n, self.size)),
            np.zeros((0, 3, self.n, self.size)),
            np.zeros((2, 2, self.size)),
            np.zeros((2, self.size)),
            np.zeros((0, self.n, self.size), dtype=np.int64),
        )

    def state(self, b: int) -> tuple[np.ndarray, np.ndarray]:
        """Copies of member b's configuration (angles unwrapped: :meth:`unwrapped_angles`) and velocities, (3, 2N+1) each."""
        x = self.x[:, :, b].copy()
        if self.winding[:, b].any():
            x[2] = join_turns(x[2], self.winding[:, b])
        return x, self.v[:, :, b].copy()

    def runaway(self, b: int) -> tuple[str, str]:
        """Why member b is out of bounds, and what to do, in words (after a blow-up; empty if it is not).

        Returns
        -------
        (cause, remedy) : str, str
            e.g. ("u of particle 3 became non-finite", "use a smaller time step ...").
        """
        x, v, dt = self.x[:, :, b], self.v[:, :, b], float(self.lanes[DT, b])
        half = self.n // 2
        smaller = f"use a smaller time step than dt={dt:g} (e.g. dt={dt / 4:g}), or smaller loads"
        for r, row in enumerate(("u", "v", "phi")):
            for name, values in ((row, x[r]), (f"{row}'", v[r])):
                bad = np.flatnonzero(~np.isfinite(values))
                if bad.size:
                    return f"{name} of particle {bad[0] - half} became non-finite", smaller
        bound = self.lanes[MAX_DISPLACEMENT, b]
        for r, row in enumerate(("u", "v")):
            far = np.flatnonzero(np.abs(x[r]) > bound)
            if far.size:
                return (
                    f"|{row}| of particle {far[0] - half} reached {abs(x[r, far[0]]):.3g}, beyond the bound {bound:g} (100 chain "
                    "lengths unless max_displacement was given)",
                    "a net force that pulls the chain away without end travels so far (raise max_displacement if it is meant "
                    f"to); otherwise the state diverged: {smaller}",
                )
        fast = np.flatnonzero(np.abs(v[2]) > self.lanes[MAX_SPIN, b])
        if fast.size:
            return (
                f"particle {fast[0] - half} turned by {abs(v[2, fast[0]]) * dt:.3g} rad in one step, beyond "
                f"{MAX_ROTATION_PER_STEP:g} (some 1300 turns)",
                f"a moment that spins a particle so fast (without rotational damping, gamma_phi = 0, it spins up without end) "
                f"is beyond any step near dt={dt:g}: a smaller moment, damping or step",
            )
        wide = np.flatnonzero(np.abs(x[2]) > self.lanes[MAX_ANGLE, b])
        if wide.size:
            return (
                f"|phi| of particle {wide[0] - half} reached {abs(x[2, wide[0]]):.3g}, beyond the model's max_angle "
                f"{self.lanes[MAX_ANGLE, b]:g}",
                "the model is accurate only below its max_angle: a model that rotates (nonlinear or sine)",
            )
        return "", ""

    def select(self, members: np.ndarray) -> Lanes:
        """A new Lanes holding copies of the given members' arrays (to drop members)."""
        members = np.asarray(members, dtype=np.int64)
        out = object.__new__(Lanes)
        out.__dict__.update(self.__dict__)
        out.params = [self.params[b] for b in members]
        out.size = members.size
        for name in ("load_scale", "coef", "mass", "lanes", "lane_ints", "acc"):
            setattr(out, name, np.ascontiguousarray(getattr(self, name)[:, members]))
        out.gamma = self.gamma[members]
        # A graded chain's factors are per column, not per member (a batch of one: nothing to select).
        out.pairs = self.pairs if self.params[0].graded_inertia else np.ascontiguousarray(self.pairs[..., members])
        for name in ("x", "v", "f", "winding"):
            setattr(out, name, np.ascontiguousarray(getattr(self, name)[..., members]))
        out.turns = TurnRecord(*(np.ascontiguousarray(a[..., members]) for a in (self.turns.time, self.turns.step_time, self.turns.phi)))
        return out

    def segment(self, first: int, last: int, start: int, stop: int) -> Lanes:
        """Columns [first, last) of a single chain as a chain of their own (a block and its halo).

        The block advances columns first+1..last-2, and its end column where that is
        the chain's own moving end (the far edge of a halo, or a clamped end, stays as
        it is), counts the dissipated energy and the loads' work on columns
        [start, stop) only, and carries the loads and the pinned degrees of freedom of
        its columns.
        """
        out = object.__new__(Lanes)
        out.__dict__.update(self.__dict__)
        out.n = last - first
        out.x = np.ascontiguousarray(self.x[:, first:last])
        out.v = np.ascontiguousarray(self.v[:, first:last])
        out.f = np.ascontiguousarray(self.f[:, first:last])
        out.winding = self.winding[first:last].copy()  # (a slice of rows is contiguous: ascontiguousarray would not copy)
        out.acc = np.zeros((2, 1))
        out.lanes = self.lanes.copy()  # its own PEAK_SPIN: the blocks run at once
        low = 0 if first == 0 and self.columns[0] == 0 else 1
        high = out.n if last == self.n and self.columns[1] == self.n else out.n - 1
        out.columns = np.array([low, high, start - first, stop - first], dtype=np.int64)
        pinned_here = (self.fixed[:, 1] >= first) & (self.fixed[:, 1] < last)
        out.fixed = np.ascontiguousarray(self.fixed[pinned_here] - np.array([0, first]))
        inside = (self.load_index[:, 1] >= first) & (self.load_index[:, 1] < last)
        index = self.load_index[inside].copy()
        index[:, 4] = (index[:, 1] >= start) & (index[:, 1] < stop)
        index[:, 1] -= first
        out.load_index = np.ascontiguousarray(index)
        out.load_scale = np.ascontiguousarray(self.load_scale[inside])
        out.turns = TurnRecord.empty(1, out.n, 1)
        return out


def _halo(substeps: int) -> int:
    """Halo columns that keep a block exact for SUPER_STEPS steps (one column per force evaluation)."""
    return SUPER_STEPS * substeps + 1


class Blocks:
    """One long chain split into blocks with halos that meet only every few steps, on one thread or several.

    Each block is a chain of its own (:meth:`Lanes.segment`) holding its columns and
    a halo of :attr:`halo` columns from each neighbour. A force evaluation reads one
    column on either side, so a halo that wide keeps the block's own columns exact
    for :data:`SUPER_STEPS` steps; then the blocks exchange their halos. Every
    column is computed by the same kernel from the same neighbours as in the whole
    chain, so the states equal an unsplit run's to the last bit (the energy sums,
    added block by block, to round-off). On several threads there are several
    blocks per thread, taken by whichever thread is free: a core that is busy with
    other work takes fewer (two threads that met every step were slower than one on a
    busy machine: benchmarks/TIMINGS.md). A chain of :data:`SPLIT_COLUMNS` or more is split into
    blocks of about :data:`CACHE_COLUMNS` on any number of threads, one included
    (run in the calling thread): each block then takes its steps in the cache.
    """

    def __init__(self, lanes: Lanes, threads: int):
        from concurrent.futures import ThreadPoolExecutor

        self.lanes = lanes
        # The sums before the blocks took over; each block's own sums start at zero.
        self.acc0 = lanes.acc.copy()
        self.halo = _halo(lanes.weights.size)
        n = lanes.n
        cuts = np.linspace(lanes.columns[0], lanes.columns[1], self.count(n, threads, lanes.weights.size) + 1).round().astype(np.int64)
        self.spans = [
            (int(max(0, start - self.halo)), int(min(n, stop + self.halo)), int(start), int(stop))
            for start, stop in zip(cuts[:-1], cuts[1:])
        ]
        self.pool = ThreadPoolExecutor(max_workers=threads) if threads > 1 else None
        # Copied out on the threads (numpy copies without the GIL): done in turn, the copies
        # and gathers of a 10^6-particle chain were a tenth of a two-thread call of 100 steps.
        self.blocks = self._each(lambda span: lanes.segment(*span), self.spans)
        # One frame slot per block (states, sums, record, winding).
        self.slots = [
            (
                np.zeros((1, *b.x.shape)),
                np.zeros((1, *b.v.shape)),
                np.zeros((1, 2, 1)),
                np.zeros((1, 1)),
                np.zeros((1, *b.winding.shape), dtype=np.int64),
            )
            for b in self.blocks
        ]

    def _each(self, work, items) -> list:
        """``work`` of every item, on the threads (in the calling thread if there are none)."""
        return list(map(work, items) if self.pool is None else self.pool.map(work, items))

    @staticmethod
    def count(n: int, threads: int, substeps: int) -> int:
        """Blocks for a chain of n columns, each at least four halos wide (1: not split).

        BLOCKS_PER_THREAD per thread on several threads; for a chain of
        SPLIT_COLUMNS or more, at least one per CACHE_COLUMNS columns on any number
        (then one and two threads split alike, and their sums agree to the bit too).
        """
        in_cache = n // CACHE_COLUMNS if n >= SPLIT_COLUMNS else 1
        per_thread = BLOCKS_PER_THREAD * threads if threads > 1 else 1
        return max(1, min(max(per_thread, in_cache), (n - 2) // (4 * _halo(substeps))))

    def close(self) -> None:
        if self.pool is not None:
            self.pool.shutdown()

    def advance(self, n_steps, step0, stride, check_every, frames, frame0, close_at_end=True):
        """As :meth:`Lanes.advance` on the whole chain (frames of states, ``record`` unused).

        Each block stores its frame in a slot of its own (:attr:`slots`, its state left open
        as the whole chain's would be); the frame is gathered from the blocks' own columns.
        """
        frames_x, frames_v, frames_acc, _, frames_winding = frames
        done = written = 0
        while done < n_steps:
            to_store = stride - (step0 + done) % stride
            length = min(SUPER_STEPS, n_steps - done, to_store)
            final = done + length == n_steps and close_at_end

            def run(item, begin=step0 + done, length=length, final=final):
                block, slot = item
                return block.advance(length, begin, stride, check_every, frames=slot, close_at_end=final)

            outcomes = self._each(run, zip(self.blocks, self.slots))
            done += length
            blew_up = any(code == STATUS_BLEW_UP for code, _, _ in outcomes)
            stored = length == to_store
            if blew_up or final:
                self._gather()
            if stored and not blew_up:
                self._gather_frame(frames_x, frames_v, frames_acc, frames_winding, frame0 + written)
                written += 1
            if blew_up:
                self.lanes.lane_ints[BLEW_UP] = 1
                return STATUS_BLEW_UP, done, written
            if done < n_steps:
                self._exchange()
        if not close_at_end:
            self._gather()
        return STATUS_OK, done, written

    def _gather_frame(self, frames_x, frames_v, frames_acc, frames_winding, frame) -> None:
        """The blocks' stored frames (their own columns, their sums added in the blocks' order) into slot ``frame``."""
        # (The last frame may be the chain's own state, gathered already: the same values.)
        if frames_x.shape[0]:

            def own_columns(item):
                (first, _, start, stop), (slot_x, slot_v, _, _, slot_winding) = item
                frames_x[frame, :, start:stop] = slot_x[0, :, start - first : stop - first]
                frames_v[frame, :, start:stop] = slot_v[0, :, start - first : stop - first]
                frames_winding[frame, start:stop] = slot_winding[0, start - first : stop - first]

            self._each(own_columns, zip(self.spans, self.slots))
        frames_acc[frame] = self.acc0
        for _, _, slot_acc, _, _ in self.slots:
            frames_acc[frame] += slot_acc[0]

    def _exchange(self) -> None:
        """Each block's halo from its neighbours' own columns (a halo is narrower than a block: only the two next to it)."""
        for i, ((first, last, _, _), block) in enumerate(zip(self.spans, self.blocks)):
            for j in (i - 1, i + 1):
                if not 0 <= j < len(self.blocks):
                    continue
                (o_first, _, o_start, o_stop), other = self.spans[j], self.blocks[j]
                lo, hi = max(first, o_start), min(last, o_stop)
                for name in ("x", "v", "f"):
                    getattr(block, name)[:, lo - first : hi - first] = getattr(other, name)[:, lo - o_first : hi - o_first]
                block.winding[lo - first : hi - first] = other.winding[lo - o_first : hi - o_first]

    def _gather(self) -> None:
        """The blocks' own columns into the whole chain, and their energy sums (added in the blocks' order)."""

        def own_columns(item):
            (first, _, start, stop), block = item
            for name in ("x", "v", "f"):
                getattr(self.lanes, name)[:, start:stop] = getattr(block, name)[:, start - first : stop - first]
            self.lanes.winding[start:stop] = block.winding[start - first : stop - first]

        self._each(own_columns, zip(self.spans, self.blocks))
        self.lanes.acc[...] = self.acc0
        for block in self.blocks:
            self.lanes.acc += block.acc
        self.lanes.lanes[PEAK_SPIN] = max(block.lanes[PEAK_SPIN, 0] for block in self.blocks)
        self.lanes.pending = self.blocks[0].pending


def held_dofs(params) -> np.ndarray:
    """(H, 2) row and column of every degree of freedom a pinned end holds; a clamped end's column is not advanced at all."""
    start, stop = force_columns(params)
    pairs = [(row, col) for row, col in held(params) if start <= col < stop]
    return np.array(pairs, dtype=np.int64).reshape(-1, 2)


def _schedule(knots: np.ndarray, start: int, stop: int, t: float) -> float:
    return float(schedule_value(knots, int(start), int(stop), float(t)))


# --------------------------------------------------------------------------- members
def check_members(params_list) -> list:
    """The members of a batch as a list, checked: at least one, all ChainParams of the same N and ends.

    Raises
    ------
    ValueError
        Naming the member that is not a ChainParams or has another N.
    """
    from ..params import ChainParams

    params = list(params_list)
    if not params:
        raise ValueError("params_list must hold at least one ChainParams")
    first = params[0]
    for i, p in enumerate(params):
        if p is first and i:
            continue  # a grid of loads repeats one chain: checked once
        if not isinstance(p, ChainParams):
            raise ValueError(f"params_list[{i}] must be a ChainParams, got {type(p).__name__}")
        if p.N != params[0].N:
            raise ValueError(
                f"params_list[{i}].N={p.N} differs from params_list[0].N={params[0].N}: all members of a batch must have the same chain length"
            )
        if (p.left_end, p.right_end, p.periodic) != (params[0].left_end, params[0].right_end, params[0].periodic):
            raise ValueError(
                f"params_list[{i}] has {p.describe_ends()} but params_list[0] has {params[0].describe_ends()}: "
                "all members of a batch must have the same ends"
            )
    return params


def per_member(values, size: int, name: str) -> np.ndarray:
    """A scalar broadcast to the batch, or one finite value per member.

    Raises
    ------
    ValueError
        For a wrong shape or a value that is not finite (naming the member).
    """
    arr = np.asarray(values, dtype=float)
    if arr.ndim == 0:
        arr = np.full(size, float(arr))
    if arr.shape != (size,):
        raise ValueError(f"{name} must be a number or one value per member ({size}), got shape {arr.shape}")
    bad = np.flatnonzero(~np.isfinite(arr))
    if bad.size:
        raise ValueError(f"{name}[{bad[0]}] (member {bad[0]}) is {arr[bad[0]]}; values must be finite")
    return arr


def require_batch_memory(params: list) -> None:
    """Refuse a batch whose arrays do not fit in memory: state, velocities, forces and the
    loads' and turns' tables, about 16 values a degree of freedom (:func:`cosserat_chain.memory.require`)."""
    n = params[0].n_particles
    require(
        16 * FLOAT * 3 * n * len(params), f"{len(params)} chain(s) of {n} particles (N={params[0].N})", "fewer members or a shorter chain"
    )


def stack_states(params: list, states, name: str) -> np.ndarray:
    """(B, 3, n) start states: rest, one state for all members, or one per member (each checked)."""
    from ..state import check_state

    n = params[0].n_particles
    require_batch_memory(params)  # the first array of a batch's size, made before its Lanes
    out = np.zeros((len(params), 3, n))
    if states is None:
        return out
    arr = np.asarray(states, dtype=float)
    if arr.ndim == 2:
        arr = np.broadcast_to(arr, (len(params), *arr.shape))
    if arr.ndim != 3 or arr.shape[0] != len(params):
        raise ValueError(f"{name} must have shape (3, 2N+1) or ({len(params)}, 3, 2N+1), got {np.shape(states)}")
    # The whole stack at once (member by member was slow: benchmarks/TIMINGS.md); a bad one is
    # then found and named by check_state, with its message.
    if arr.shape[1:] == (3, n) and np.isfinite(arr).all() and not any(np.any(arr[:, row, col] != 0.0) for row, col in held(params[0])):
        out[...] = arr
        return out
    for i, p in enumerate(params):
        out[i] = check_state(p, arr[i], f"{name}[{i}]")
    return out


def member_steps(params: list, dt, method, model) -> np.ndarray:
    """Each member's time step: the given one or its default, checked against its stability limit.

    The default step and the limit cost an eigenvalue scan each: once
    per distinct (params, dt), since a grid of loads repeats one chain.

    Raises
    ------
    ValueError
        Naming the member whose dt is not finite or beyond its stability limit.
    """
    size = len(params)
    if dt is None:
        # The default is far inside every method's stability limit (see integrate): one per distinct member.
        which, first = distinct(params)
        return np.array([default_time_step(p, model) for p in first])[which]
    requested = per_member(dt, size, "dt")
    out = np.empty(size)
    checked: dict = {}
    for i, (p, step) in enumerate(zip(params, requested.tolist())):
        key = (id(p), step)  # the members are alive throughout: their ids are theirs (and cheaper than hashing a ChainParams)
        if key not in checked:
            try:
                check_time_step(p, step, method, model)
            except ValueError as err:
                raise ValueError(f"member {i} (params_list[{i}]): {err}") from None
            checked[key] = step
        out[i] = checked[key]
    return out


def distinct(params: list) -> tuple[np.ndarray, list]:
    """The distinct members (by identity, in order of first appearance) and each member's index among them.

    A grid of loads repeats one ChainParams a thousand times: what depends only on the
    chain is worked out once per distinct member and spread (``values[which]``).
    """
    if all(p is params[0] for p in params):  # the usual grid, quicker than the unique below (benchmarks/TIMINGS.md)
        return np.zeros(len(params), dtype=np.int64), params[:1]
    # Vectorised over the ids (a dictionary member by member was slower: benchmarks/TIMINGS.md).
    ids = np.fromiter(map(id, params), dtype=np.uint64, count=len(params))
    _, first_index, inverse = np.unique(ids, return_index=True, return_inverse=True)
    order = np.argsort(first_index)
    rank = np.empty_like(order)
    rank[order] = np.arange(order.size)
    return rank[inverse].astype(np.int64), [params[i] for i in first_index[order]]


def split(members: np.ndarray, parts: int, params: list | None = None) -> list[np.ndarray]:
    """Members cut into up to ``parts`` runs of consecutive members of about equal size.

    Consecutive, not dealt out in turn: each part becomes its own contiguous
    arrays, so two threads never write to the same cache lines. Graded members of
    ``params`` (per-bond stiffness or per-particle inertia) are parts of one: the
    batch kernels and the batch kick-drift read one value of each coefficient per
    member, a graded chain runs the chain kernel (:meth:`Lanes.__init__`).
    """
    members = np.asarray(members, dtype=np.int64)
    if params is not None and any(p.graded for p in distinct([params[b] for b in members])[1]):
        return [np.array([b], dtype=np.int64) for b in members if params[b].graded] + split(
            np.array([b for b in members if not params[b].graded], dtype=np.int64), parts
        )
    return [part for part in np.array_split(members, max(1, min(parts, members.size))) if part.size]


def run_parts(work, parts: list, threads: int) -> None:
    """Call ``work(part)`` for every part, on up to ``threads`` threads (the compiled loop releases the GIL).

    Errors and Ctrl-C propagate; with threads, the parts already running finish first.
    """
    if threads <= 1 or len(parts) <= 1:
        for part in parts:
            work(part)
        return
    from concurrent.futures import ThreadPoolExecutor

    with ThreadPoolExecutor(max_workers=threads) as pool:
        for future in [pool.submit(work, part) for part in parts]:
            future.result()
