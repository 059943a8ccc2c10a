"""Many independent chains of the same length integrated together, in one compiled loop.

Contract
--------
A *batch* is B chains of the same number of particles (same model), each with its
own parameters (coefficients, inertia, damping, time step), its own start state
and its own constant moment on the same particle. :func:`integrate_batch`
advances every member to ``t_end`` and :func:`relax_batch` runs the relaxation
step of :func:`~cosserat_chain.numerics.relaxation.relax` for every member, with
the same tests and tolerances.

The time stepping is exactly that of :func:`~cosserat_chain.numerics.dynamics.integrate`
(damped velocity Verlet or Yoshida-4 sub-steps with the exact damping flow, the
same step count and step size for the same ``t_end``, the model's compiled force
kernel), so every member's states equal the single run's to the last bit;
:func:`relax_batch` also keeps :func:`relax`'s chunks (``chunk_time``, doubling
up to 16 of them), so its statuses, times, turns and end states equal
:func:`relax`'s.

Layout and threads
------------------
States are stacked as (B, 3, n): each member is one contiguous (3, n) block, so
the model's own force kernel (one first-class function type, ``FORCE_SIGNATURE``)
serves the batch and no model code is duplicated. A compiled call runs whole
members one after the other (no Python per step); with ``threads=2`` the members
are split into two runs of consecutive members of about equal work that run on the
two cores without synchronising per step (``PERFORMANCE-NOTES.md``: threads only at
coarse grain).
The turns of the loaded particle are detected inside the compiled loop, into a
fixed ring of the last ``2 window_turns + 1`` crossings per member (all the
rotation test reads); members that have finished leave the batch.
"""

from __future__ import annotations

import math
from collections.abc import Generator, Sequence
from dataclasses import dataclass

import numpy as np
from numba import njit, prange, types

from ..loads import moment_load
from ..models.base import FORCE_KERNEL_TYPE, Model, get_model
from ..params import ChainParams
from ..state import ROW_INDEX, check_state, column
from .dynamics import IntegrationError, Trajectory, check_time_step, default_time_step
from .integrators import STATUS_BLEW_UP, STATUS_OK, Method, get_method, substep_table
from .relaxation import FRAME_BUDGET, MAX_CHUNKS, RelaxationStep

#: Numba options of the compiled loop: those of the single run's kick-drift, without
#: fastmath "contract" (where fused multiply-adds went would depend on the code around
#: each copy), so that a member's states equal the single run's to the last bit.
_OPTIONS = {"cache": True, "nogil": True, "error_model": "numpy"}
#: Runaway test every so many steps, as in ``integrate``.
CHECK_EVERY = 1024

# Columns of the per-member float and int tables passed to the compiled loop: one
# table each instead of a dozen positional arrays.
_MOMENT, _T0, _T_END, _DIRECTION, _PHI_START, _MAX_DISPLACEMENT = range(6)
_N_FLOATS = 6
_COL, _N_STEPS, _STRIDE, _CROSSINGS, _STATUS, _DONE = range(6)
_N_INTS = 6
_PHI = ROW_INDEX["phi"]


# --------------------------------------------------------------------------- compiled loop
@njit(**_OPTIONS)
def _kick_drift(x, v, f, table, close, open_):  # pragma: no cover - compiled
    """End sub-step ``close`` and begin ``open_`` (the arithmetic of ``integrators._close_and_open``
    without its energy bookkeeping, which does not feed back into the state)."""
    n = x.shape[1]
    for r in range(3):
        e_close = table[close, 0, r]
        kick_close = table[close, 1, r]
        e_open = table[open_, 0, r]
        kick_open = table[open_, 1, r]
        drift = table[open_, 2, r]
        xr = x[r]
        vr = v[r]
        fr = f[r]
        for k in range(1, n - 1):
            w = vr[k] + kick_close * fr[k]
            w *= e_close
            w = e_open * w + kick_open * fr[k]
            vr[k] = w
            xr[k] += drift * w


@njit(**_OPTIONS)
def _runaway(x, v, max_displacement):  # pragma: no cover - compiled
    for r in range(3):
        for k in range(x.shape[1]):
            if not (math.isfinite(x[r, k]) and math.isfinite(v[r, k])):
                return True
            if r < 2 and abs(x[r, k]) > max_displacement:
                return True
    return False


@njit(**_OPTIONS)
def _run_member(force, x, v, f, coef, table, weights, floats, ints, ring_time, ring_phi, record):  # pragma: no cover - compiled
    """One member's chunk: ``ints[_N_STEPS]`` steps from t0 to t_end, in place.

    Frames are the steps that are multiples of ``ints[_STRIDE]`` and the last
    one, as ``integrate`` stores them; at each frame the loaded particle's angle
    goes to ``record`` (while it has room) and every completed turn since the
    step began is interpolated linearly between frames, as ``relax`` does, into
    the ring buffers (time, angles of all particles).
    """
    n = x.shape[1]
    col = ints[_COL]
    n_steps = ints[_N_STEPS]
    stride = ints[_STRIDE]
    crossings = ints[_CROSSINGS]
    moment = floats[_MOMENT]
    t0 = floats[_T0]
    span = floats[_T_END] - t0
    direction = floats[_DIRECTION]
    phi_start = floats[_PHI_START]
    capacity = ring_time.size
    two_pi = 2 * math.pi

    force(x, coef, f, 1, n - 1)
    f[_PHI, col] += moment
    phi_prev = x[_PHI].copy()
    winding_prev = direction * (phi_prev[col] - phi_start) / two_pi
    time_prev = t0
    if record.size > 0:
        record[0] = x[_PHI, col]
    frame = 1
    empty = weights.size
    pending = empty
    to_store = stride
    to_check = CHECK_EVERY
    for k in range(n_steps):
        for s in range(weights.size):
            _kick_drift(x, v, f, table, pending, s)
            force(x, coef, f, 1, n - 1)
            f[_PHI, col] += moment
            pending = s
        to_store -= 1
        to_check -= 1
        last = k == n_steps - 1
        if last:
            _kick_drift(x, v, f, table, pending, empty)
            pending = empty
        if to_store == 0 or last:
            to_store = stride
            if frame < record.size:
                record[frame] = x[_PHI, col]
            frame += 1
            time = t0 + (span * (k + 1)) / n_steps
            winding = direction * (x[_PHI, col] - phi_start) / two_pi
            while winding >= crossings + 1:
                alpha = (crossings + 1 - winding_prev) / (winding - winding_prev)
                slot = crossings % capacity
                ring_time[slot] = time_prev + alpha * (time - time_prev)
                for j in range(n):
                    ring_phi[slot, j] = phi_prev[j] + alpha * (x[_PHI, j] - phi_prev[j])
                crossings += 1
            winding_prev = winding
            time_prev = time
            phi_prev[:] = x[_PHI]
        if to_check == 0 or last:
            to_check = CHECK_EVERY
            if _runaway(x, v, floats[_MAX_DISPLACEMENT]):
                if pending != empty:
                    _kick_drift(x, v, f, table, pending, empty)
                ints[_CROSSINGS] = crossings
                ints[_STATUS] = STATUS_BLEW_UP
                ints[_DONE] = k + 1
                return
    ints[_CROSSINGS] = crossings
    ints[_STATUS] = STATUS_OK
    ints[_DONE] = n_steps


_I8 = types.int64
_STATES = types.float64[:, :, ::1]
RUN_SIGNATURE = types.void(
    FORCE_KERNEL_TYPE,
    _STATES, _STATES, _STATES,  # x, v, f: (B, 3, n)
    types.float64[:, ::1], types.float64[:, :, :, ::1], types.float64[::1],  # coef (B, c), table (B, S+1, 3, 3), weights (S,)
    types.int64[::1], _I8, _I8,  # members, first, stop: run members[first:stop]
    types.float64[:, ::1], types.int64[:, ::1],  # floats (B, _N_FLOATS), ints (B, _N_INTS)
    types.float64[:, ::1], _STATES, types.float64[:, ::1],  # ring_time (B, C), ring_phi (B, C, n), record (B, R)
)  # fmt: skip
GROUPS_SIGNATURE = types.void(*RUN_SIGNATURE.args[:7], types.int64[::1], types.int64[::1], *RUN_SIGNATURE.args[10:])


@njit(RUN_SIGNATURE, **_OPTIONS)
def _run_members(
    force, x, v, f, coef, table, weights, members, first, stop, floats, ints, ring_time, ring_phi, record
):  # pragma: no cover - compiled
    for i in range(first, stop):
        b = members[i]
        _run_member(force, x[b], v[b], f[b], coef[b], table[b], weights, floats[b], ints[b], ring_time[b], ring_phi[b], record[b])


@njit(GROUPS_SIGNATURE, parallel=True, **_OPTIONS)
def _run_groups(
    force, x, v, f, coef, table, weights, members, bounds, floats, ints, ring_time, ring_phi, record
):  # pragma: no cover - compiled
    # One iteration per core, each a whole group of members: no synchronisation per step.
    for g in prange(bounds.size - 1):
        _run_members(force, x, v, f, coef, table, weights, members, bounds[g], bounds[g + 1], floats, ints, ring_time, ring_phi, record)


# --------------------------------------------------------------------------- Python side
def _groups(work: np.ndarray, members: np.ndarray, threads: int) -> tuple[np.ndarray, np.ndarray]:
    """Members split into ``threads`` runs of consecutive members of about equal work.

    Consecutive, not dealt out in turn: members are adjacent in memory, and two
    threads working on neighbouring members would write to the same cache lines
    at every step (false sharing; a batch of 16 short chains then gained nothing
    from a second core).
    """
    order = np.sort(members).astype(np.int64)
    count = min(threads, order.size)
    cumulative = np.cumsum(work[order])
    targets = cumulative[-1] * np.arange(1, count) / count
    cuts = np.searchsorted(cumulative, targets, side="left") + 1
    bounds = np.concatenate(([0], np.clip(cuts, 1, order.size - 1), [order.size])).astype(np.int64)
    return order, np.maximum.accumulate(bounds)


class _Batch:
    """Validated members and their stacked arrays (see the module docstring)."""

    def __init__(self, params_list, model, moments, *, particle, x0, v0, dt, method, ring_capacity=1):
        self.params = list(params_list)
        if not self.params:
            raise ValueError("params_list must hold at least one ChainParams")
        for i, p in enumerate(self.params):
            if not isinstance(p, ChainParams):
                raise ValueError(f"params_list[{i}] must be a ChainParams, got {type(p).__name__}")
            if p.N != self.params[0].N:
                raise ValueError(
                    f"params_list[{i}].N={p.N} differs from params_list[0].N={self.params[0].N}: "
                    "all members of a batch must have the same chain length"
                )
        size = len(self.params)
        self.size = size
        self.model = get_model(model)
        self.method = get_method(method)
        self.moments = _per_member(moments, size, "moments")
        moment_load(0.0, particle).validate(self.params[0])
        self.particle = particle
        self.col = column(self.params[0], particle)
        n = self.n = self.params[0].n_particles
        self.x = _stack_states(self.params, x0, "x0")
        self.v = _stack_states(self.params, v0, "v0")
        requested = [None] * size if dt is None else _per_member(dt, size, "dt")
        self.dt = np.empty(size)
        # The default step and the stability limit cost an eigenvalue scan each (about
        # 1 ms): once per distinct (params, dt), since a grid of loads repeats one chain.
        checked: dict[tuple[ChainParams, float | None], float] = {}
        for i, (p, step) in enumerate(zip(self.params, requested)):
            key = (p, step)
            if key not in checked:
                value = default_time_step(p) if step is None else float(step)
                try:
                    check_time_step(p, value, self.method)
                except ValueError as err:
                    raise ValueError(f"member {i} (params_list[{i}]): {err}") from None
                checked[key] = value
            self.dt[i] = checked[key]
        self.coef = np.ascontiguousarray([self.model.coefficients(p) for p in self.params], dtype=float)
        self.mass = np.array([p.inertia for p in self.params])
        self.gamma = np.array([p.damping for p in self.params])
        self.weights = np.array(self.method.weights)
        self.f = np.zeros_like(self.x)
        self.table = np.zeros((size, self.weights.size + 1, 3, 3))
        self.floats = np.zeros((size, _N_FLOATS))
        self.floats[:, _MOMENT] = self.moments
        self.floats[:, _MAX_DISPLACEMENT] = [100.0 * 2 * p.N * p.h for p in self.params]
        self.ints = np.zeros((size, _N_INTS), dtype=np.int64)
        self.ints[:, _COL] = self.col
        self.ring_time = np.zeros((size, ring_capacity))
        self.ring_phi = np.zeros((size, ring_capacity, n))
        self.record = np.zeros((size, 0))

    def set_chunk(self, b: int, t0: float, t_end: float, n_frames: int) -> None:
        """Member b's next call: from t0 to t_end with ``integrate``'s step count, step and stride."""
        n_steps = max(1, math.ceil((t_end - t0) / self.dt[b] - 1e-9))
        step = (t_end - t0) / n_steps
        self.table[b] = substep_table(self.weights, step, self.mass[b], self.gamma[b])
        self.floats[b, _T0] = t0
        self.floats[b, _T_END] = t_end
        self.ints[b, _N_STEPS] = n_steps
        self.ints[b, _STRIDE] = max(1, math.ceil(n_steps / max(1, n_frames - 1)))

    def run(self, members: np.ndarray, threads: int) -> None:
        """Advance the given members through their chunks in one compiled call."""
        kernel = type(self.model).force_kernel
        work = self.ints[:, _N_STEPS].astype(float)
        order, bounds = _groups(work, np.asarray(members, dtype=np.int64), max(1, int(threads)))
        arrays = (self.coef, self.table, self.weights, order)
        tail = (self.floats, self.ints, self.ring_time, self.ring_phi, self.record)
        if bounds.size == 2:
            _run_members(kernel, self.x, self.v, self.f, *arrays, 0, order.size, *tail)
        else:
            _run_groups(kernel, self.x, self.v, self.f, *arrays, bounds, *tail)

    def blow_up(self, b: int) -> IntegrationError:
        """The error for member b's blow-up, carrying its last state."""
        t = self.floats[b, _T0] + (self.floats[b, _T_END] - self.floats[b, _T0]) * self.ints[b, _DONE] / self.ints[b, _N_STEPS]
        message = (
            f"member {b} (params_list[{b}], moment {self.floats[b, _MOMENT]:g}) blew up at t={t:.6g}: a value became "
            f"non-finite or |u|, |v| exceeded {self.floats[b, _MAX_DISPLACEMENT]:g}. Use a smaller time step than dt={self.dt[b]:g}."
        )
        trajectory = Trajectory(
            time=np.array([t]), x=self.x[b : b + 1].copy(), v=self.v[b : b + 1].copy(), load_work=np.full(1, np.nan),
            dissipated=np.full(1, np.nan), status="blew_up", message=message, steps=int(self.ints[b, _DONE]),
            dt=float(self.dt[b]), method=self.method.name,
        )  # fmt: skip
        return IntegrationError(message, trajectory)


def _per_member(values, size: int, name: str) -> np.ndarray:
    """A scalar broadcast to the batch, or one finite value per member."""
    arr = np.asarray(values, dtype=float)
    if arr.ndim == 0:
        arr = np.full(size, float(arr))
    if arr.shape != (size,):
        raise ValueError(f"{name} must be a number or one value per member ({size}), got shape {arr.shape}")
    bad = np.flatnonzero(~np.isfinite(arr))
    if bad.size:
        raise ValueError(f"{name}[{bad[0]}] (member {bad[0]}) is {arr[bad[0]]}; values must be finite")
    return arr


def _stack_states(params: list[ChainParams], states, name: str) -> np.ndarray:
    """(B, 3, n) start states: rest, one state for all members, or one per member (each checked)."""
    n = params[0].n_particles
    out = np.zeros((len(params), 3, n))
    if states is None:
        return out
    arr = np.asarray(states, dtype=float)
    if arr.ndim == 2:
        arr = np.broadcast_to(arr, (len(params), *arr.shape))
    if arr.ndim != 3 or arr.shape[0] != len(params):
        raise ValueError(f"{name} must have shape (3, 2N+1) or ({len(params)}, 3, 2N+1), got {np.shape(states)}")
    for i, p in enumerate(params):
        out[i] = check_state(p, arr[i], f"{name}[{i}]")
    return out


# --------------------------------------------------------------------------- integrate_batch
@dataclass
class BatchRun:
    """End states of a batch run and the record of the loaded particle's angle.

    Attributes
    ----------
    x, v : ndarray (B, 3, 2N+1)
        Final configurations and velocities.
    dt : ndarray (B,)
        Step actually taken by each member (at most the requested one; t_end is reached exactly).
    steps : ndarray of int (B,)
    record_time, record_angle : ndarray (B, R)
        Times and angles of the loaded particle at every stored step (steps 0,
        stride, 2 stride, ... and the last), NaN after a member's last record.
    status : list of str
        ``completed`` or ``blew_up`` per member.
    """

    x: np.ndarray
    v: np.ndarray
    dt: np.ndarray
    steps: np.ndarray
    record_time: np.ndarray
    record_angle: np.ndarray
    status: list[str]


def integrate_batch(
    params_list: Sequence[ChainParams],
    model: str | Model,
    moments: float | Sequence[float],
    *,
    t_end: float,
    dt: float | Sequence[float] | None = None,
    x0: np.ndarray | None = None,
    v0: np.ndarray | None = None,
    particle: int = 0,
    method: str | Method = "verlet",
    n_records: int = 201,
    threads: int = 1,
) -> BatchRun:
    """Integrate B chains from t = 0 to ``t_end`` under constant moments, in one compiled call.

    Each member's states equal those of ``integrate(params_list[i], model,
    moment_load(moments[i], particle), t_end=t_end, dt=dt[i], ...)`` to the last bit.

    Parameters
    ----------
    params_list : sequence of ChainParams (B)
        The members; all with the same N.
    model : str or Model
    moments : float or sequence of float (B)
        Constant moment on ``particle`` of every member.
    t_end : float
    dt : float or sequence (B), optional
        Largest time step per member; default each member's ``default_time_step``.
    x0, v0 : ndarray (3, 2N+1) or (B, 3, 2N+1), optional
        Start states (default rest).
    particle : int
    method : {"verlet", "yoshida4"}
    n_records : int
        About this many records of the loaded particle's angle per member (>= 2).
    threads : int
        Split the members over this many cores (in groups of about equal work).

    Returns
    -------
    BatchRun

    Raises
    ------
    ValueError
        For members of different N, a non-finite moment, state or dt, or a dt
        beyond a member's stability limit; the message names the member and the field.
    """
    if not (math.isfinite(t_end) and t_end > 0):
        raise ValueError(f"t_end must be a finite number > 0, got {t_end!r}")
    if not (isinstance(n_records, int) and n_records >= 2):
        raise ValueError(f"n_records must be an integer >= 2, got {n_records!r}")
    batch = _Batch(params_list, model, moments, particle=particle, x0=x0, v0=v0, dt=dt, method=method)
    for b in range(batch.size):
        batch.set_chunk(b, 0.0, t_end, n_records)
    n_steps = batch.ints[:, _N_STEPS].copy()
    strides = batch.ints[:, _STRIDE].copy()
    counts = n_steps // strides + 1 + (n_steps % strides != 0)
    batch.record = np.full((batch.size, int(counts.max())), np.nan)
    batch.floats[:, _PHI_START] = batch.x[:, _PHI, batch.col]
    batch.floats[:, _DIRECTION] = 1.0
    batch.run(np.arange(batch.size), threads)
    record_time = np.full_like(batch.record, np.nan)
    for b in range(batch.size):
        steps = np.minimum(strides[b] * np.arange(counts[b]), n_steps[b])
        record_time[b, : counts[b]] = t_end * steps / n_steps[b]
    blew_up = batch.ints[:, _STATUS] == STATUS_BLEW_UP
    return BatchRun(
        x=batch.x,
        v=batch.v,
        dt=t_end / n_steps,
        steps=batch.ints[:, _DONE].copy(),
        record_time=np.where(np.isnan(batch.record), np.nan, record_time),
        record_angle=batch.record,
        status=["blew_up" if bad else "completed" for bad in blew_up],
    )


# --------------------------------------------------------------------------- relax_batch
#: A member's protocol: yields the next moment, receives that step's RelaxationStep.
Plan = Generator[float, RelaxationStep, None]


@dataclass
class _Step:
    """Bookkeeping of one member's relaxation step in progress (the locals of ``relax``)."""

    moment: float
    load: np.ndarray
    elapsed: float = 0.0
    chunk: float = 0.0


def run_plans(
    params_list: Sequence[ChainParams],
    model: str | Model,
    plans: Sequence[Plan],
    *,
    particle: int = 0,
    x0: np.ndarray | None = None,
    v0: np.ndarray | None = None,
    t_max: float = 20000.0,
    v_tol: float = 1e-9,
    f_tol: float = 1e-9,
    chunk_time: float = 25.0,
    window_turns: int = 12,
    omega_rtol: float = 0.05,
    dt: float | Sequence[float] | None = None,
    method: str = "verlet",
    threads: int = 1,
) -> None:
    """Run each member's sequence of relaxation steps, all members in lock-step chunks.

    Member i follows ``plans[i]``: a generator that yields a moment, receives the
    :class:`RelaxationStep` of relaxing under it (from the member's current
    state: ``x0``/``v0`` at first, then the previous step's end state), and so
    on until it returns. A member whose step ends starts its next one at once;
    one that returns leaves the batch. Arguments as in :func:`relax_batch`.

    Raises
    ------
    ValueError
        For bad input (see :func:`relax_batch`), or a plan's moment that is not finite.
    IntegrationError
        If a member blows up (the message names it).
    KeyboardInterrupt
        On Ctrl-C, after the compiled call in progress.
    """
    for name, value in (("t_max", t_max), ("v_tol", v_tol), ("f_tol", f_tol), ("chunk_time", chunk_time), ("omega_rtol", omega_rtol)):
        if not (math.isfinite(value) and value > 0):
            raise ValueError(f"{name} must be a finite number > 0, got {value!r}")
    if not (isinstance(window_turns, int) and window_turns >= 1):
        raise ValueError(f"window_turns must be an integer >= 1, got {window_turns!r}")
    if len(plans) != len(params_list):
        raise ValueError(f"plans must hold one plan per member ({len(params_list)}), got {len(plans)}")
    capacity = 2 * window_turns + 1
    batch = _Batch(
        params_list, model, np.zeros(len(params_list)), particle=particle, x0=x0, v0=v0, dt=dt, method=method, ring_capacity=capacity
    )
    n = batch.n
    frames = [int(min(MAX_CHUNKS * chunk_time / batch.dt[b] + 1, FRAME_BUDGET // (6 * n))) for b in range(batch.size)]
    steps: dict[int, _Step] = {}

    def start(b: int, moment: float) -> None:
        if not math.isfinite(moment):
            raise ValueError(f"member {b}: moment must be finite, got {moment!r}")
        batch.floats[b, _MOMENT] = moment
        batch.floats[b, _DIRECTION] = 1.0 if moment >= 0 else -1.0
        batch.floats[b, _PHI_START] = batch.x[b, _PHI, batch.col]
        batch.ints[b, _CROSSINGS] = 0
        steps[b] = _Step(moment, moment_load(moment, particle).as_array(batch.params[b], 0.0), chunk=chunk_time)

    def advance_plan(b: int, result: RelaxationStep | None) -> None:
        try:
            moment = next(plans[b]) if result is None else plans[b].send(result)
        except StopIteration:
            steps.pop(b, None)
            return
        start(b, float(moment))

    for b in range(batch.size):
        advance_plan(b, None)
    while steps:
        active = np.array(sorted(steps), dtype=np.int64)
        for b in active:
            step = steps[b]
            span = min(step.chunk, t_max - step.elapsed)
            step.chunk = min(2 * step.chunk, MAX_CHUNKS * chunk_time)
            batch.set_chunk(b, step.elapsed, step.elapsed + span, frames[b])
        batch.run(active, threads)
        for b in active:
            if batch.ints[b, _STATUS] == STATUS_BLEW_UP:
                raise batch.blow_up(b)
            result = _chunk_outcome(batch, b, steps[b], t_max, v_tol, f_tol, window_turns, omega_rtol)
            if result is not None:
                advance_plan(b, result)


def _chunk_outcome(batch: _Batch, b: int, step: _Step, t_max, v_tol, f_tol, window, rtol) -> RelaxationStep | None:
    """``relax``'s tests at the end of a chunk: the finished step, or None to go on."""
    params = batch.params[b]
    t0, t_end, n_steps = batch.floats[b, _T0], batch.floats[b, _T_END], int(batch.ints[b, _N_STEPS])
    # The time of integrate's last frame, to the same rounding.
    step.elapsed = float(t0 + (t_end - t0) * n_steps / n_steps)
    x, v = batch.x[b].copy(), batch.v[b].copy()
    residual = float(np.max(np.abs((batch.model.forces(params, x) + step.load)[:, 1:-1])))
    speed = float(np.max(np.abs(v)))
    count = int(batch.ints[b, _CROSSINGS])
    col = batch.col
    if speed <= v_tol and residual <= f_tol * (1.0 + abs(step.moment)):
        status, omega = "static", np.zeros(params.n_particles)
        message = f"at rest after t={step.elapsed:.6g} (max|v|={speed:.2g}, residual {residual:.2g})"
    elif (omega := _steady_rotation(batch.ring_time[b], batch.ring_phi[b], count, window, rtol)) is not None:
        status = "rotating"
        message = f"steady rotation after t={step.elapsed:.6g}: {count} turns, mean angular velocity {omega[col]:.6g}"
    elif step.elapsed >= t_max * (1 - 1e-12):
        status, omega = "not_converged", np.full(params.n_particles, np.nan)
        message = (
            f"neither at rest nor rotating steadily after t_max={t_max:g} (max|v|={speed:.2g}, residual {residual:.2g}, "
            f"{count} turns); raise t_max or loosen v_tol/f_tol"
        )
    else:
        return None
    direction = batch.floats[b, _DIRECTION]
    turns = direction * (x[_PHI, col] - batch.floats[b, _PHI_START]) / (2 * math.pi)
    return RelaxationStep(status, x, v, step.elapsed, residual, speed, turns, omega, message)


def _steady_rotation(ring_time, ring_phi, count: int, window: int, rtol: float) -> np.ndarray | None:
    """``relaxation._steady_rotation`` on the ring of the last 2 window + 1 crossings."""
    if count < 2 * window + 1:
        return None
    capacity = ring_time.size
    last, middle, first = (count - 1) % capacity, (count - 1 - window) % capacity, (count - 1 - 2 * window) % capacity
    rate_first = window / (ring_time[middle] - ring_time[first])
    rate_last = window / (ring_time[last] - ring_time[middle])
    if abs(rate_last - rate_first) > rtol * abs(rate_last):
        return None
    return (ring_phi[last] - ring_phi[first]) / (ring_time[last] - ring_time[first])


def relax_batch(
    params_list: Sequence[ChainParams],
    model: str | Model,
    moments: float | Sequence[float],
    *,
    particle: int = 0,
    x0: np.ndarray | None = None,
    v0: np.ndarray | None = None,
    t_max: float = 20000.0,
    v_tol: float = 1e-9,
    f_tol: float = 1e-9,
    chunk_time: float = 25.0,
    window_turns: int = 12,
    omega_rtol: float = 0.05,
    dt: float | Sequence[float] | None = None,
    method: str = "verlet",
    threads: int = 1,
) -> list[RelaxationStep]:
    """One relaxation step (:func:`~cosserat_chain.numerics.relaxation.relax`) for every member of a batch.

    Member i relaxes ``params_list[i]`` under ``moments[i]`` from ``x0[i]``,
    ``v0[i]``; the result equals ``relax(params_list[i], model, moments[i], ...)``
    (same chunks, steps and tests, so the same status, time, turns and end state).
    A grid of loads on one chain is ``relax_batch([params] * L, model, loads)``.

    Parameters
    ----------
    params_list : sequence of ChainParams (B), all with the same N
    model : str or Model
    moments : float or sequence of float (B)
    particle : int
        The loaded particle, the same for every member.
    x0, v0 : ndarray (3, 2N+1) or (B, 3, 2N+1), optional
        Start states (default rest).
    t_max, v_tol, f_tol, chunk_time, window_turns, omega_rtol, method
        As in :func:`relax`, for every member.
    dt : float or sequence (B), optional
        Time step per member (default each member's ``default_time_step``).
    threads : int
        Split the members over this many cores.

    Returns
    -------
    list of RelaxationStep (B)

    Raises
    ------
    ValueError
        For members of different N, a non-finite moment, state or dt, a dt beyond a
        member's stability limit (the message names the member and the field), or a
        non-positive tolerance, time or window.
    IntegrationError
        If a member blows up.
    KeyboardInterrupt
        On Ctrl-C.
    """
    size = len(params_list)
    values = _per_member(moments, size, "moments") if size else np.zeros(0)
    results: list[RelaxationStep | None] = [None] * size

    def single(b: int) -> Plan:
        results[b] = yield float(values[b])

    run_plans(
        params_list, model, [single(b) for b in range(size)], particle=particle, x0=x0, v0=v0, t_max=t_max, v_tol=v_tol,
        f_tol=f_tol, chunk_time=chunk_time, window_turns=window_turns, omega_rtol=omega_rtol, dt=dt, method=method, threads=threads,
    )  # fmt: skip
    return [r for r in results if r is not None]
