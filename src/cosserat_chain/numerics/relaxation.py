"""Relaxation to rest under a constant moment: one step of the paper's protocol (Section 4).

Contract
--------
:func:`relax` integrates the damped dynamics (eqs. (1)-(3) with viscosity) under a
constant moment M from a given state, in chunks, and ends with one of

* ``static``: at rest, max |v| <= v_tol and max |F + L| <= f_tol (1 + |M|), the
  steady-state test of diffrax's steady-state event;
* ``rotating``: the loaded particle turns without end. The engine follows its
  unwrapped angle step by step (the times at which it has advanced by 1, 2, 3,
  ... full turns since the step began); once two consecutive windows of
  ``window_turns`` turns give the same mean angular velocity to ``omega_rtol``,
  it keeps turning at a steady mean rate, and the mean angular velocity of every
  particle over the last two windows is recorded;
* ``not_converged``: neither happened before ``t_max`` (never silently: the
  status and message say so).

The tests are made after ``chunk_time``, then after chunks twice as long each
time up to 16 ``chunk_time``. Time runs in whole chunks: the step is
chunk_time / ceil(chunk_time / dt) (at most ``dt``), and ``t_max`` is rounded up
to a whole number of ``chunk_time``.

:func:`relax_batch` runs one such step for every member of a batch and
:func:`run_plans` a sequence of them per member (the relaxation sweeps): members
with the same step share the SIMD lanes of one compiled loop (:mod:`.engine`),
advancing one ``chunk_time`` per call, each tested at the end of its own chunks.
:func:`relax` is a batch of one, so a member's status, time, turns and end state
equal its own :func:`relax`'s.

A run that blows up raises :class:`~cosserat_chain.numerics.dynamics.IntegrationError`;
Ctrl-C raises ``KeyboardInterrupt`` after the chunk in progress, so that callers
keep the steps already finished.
"""

from __future__ import annotations

import math
import threading
from collections.abc import Generator, Sequence
from dataclasses import asdict, dataclass

import numpy as np

from ..loads import Loads, moment_load
from ..models.base import Model, get_model
from ..params import ChainParams
from ..state import column, zero_held
from ..status import Status
from .dynamics import IntegrationError, Trajectory, require_step_count
from .engine import (
    BLEW_UP,
    CROSSINGS,
    DIRECTION,
    DT,
    PHI_START,
    STATUS_BLEW_UP,
    Lanes,
    check_members,
    member_steps,
    per_member,
    run_parts,
    split,
    stack_states,
)
from .integrators import get_method

#: Longest chunk between two tests, in units of ``chunk_time``.
MAX_CHUNKS = 16


@dataclass(frozen=True)
class RelaxSettings:
    """The options of one relaxation step, checked once (see :func:`relax`)."""

    t_max: float = 20000.0
    v_tol: float = 1e-9
    f_tol: float = 1e-9
    chunk_time: float = 25.0
    window_turns: int = 12
    omega_rtol: float = 0.05
    dt: float | Sequence[float] | None = None
    method: str = "verlet"

    def __post_init__(self) -> None:
        for name in ("t_max", "v_tol", "f_tol", "chunk_time", "omega_rtol"):
            value = getattr(self, name)
            if not (isinstance(value, int | float) and math.isfinite(value) and value > 0):
                raise ValueError(f"{name} must be a finite number > 0, got {value!r}")
        if not (isinstance(self.window_turns, int) and self.window_turns >= 1):
            raise ValueError(f"window_turns must be an integer >= 1, got {self.window_turns!r}")
        get_method(self.method)

    @property
    def chunks(self) -> int:
        """Chunks of ``chunk_time`` up to ``t_max`` (rounded up)."""
        return max(1, math.ceil(self.t_max / self.chunk_time - 1e-9))

    def as_dict(self) -> dict:
        return asdict(self)


@dataclass
class RelaxationStep:
    """Outcome of one relaxation step.

    Attributes
    ----------
    status : Status
        ``static``, ``rotating`` or ``not_converged``.
    x, v : ndarray (3, 2N+1)
        The state at the end of the step (at rest for ``static``).
    time : float
        Time integrated in this step.
    residual : float
        max |F(x) + L| at the end.
    speed : float
        max |v| at the end.
    turns : float
        Turns of the loaded particle since the step began (signed, along M).
    angular_velocity : ndarray (2N+1,)
        Mean d phi / dt of every particle over the last two windows of a
        rotating state; zero for a static state, NaN when not converged.
    message : str
    """

    status: str
    x: np.ndarray
    v: np.ndarray
    time: float
    residual: float
    speed: float
    turns: float
    angular_velocity: np.ndarray
    message: str


#: A member's protocol: yields the next moment, receives that step's RelaxationStep.
Plan = Generator[float, RelaxationStep, None]


def relax(
    params: ChainParams,
    model: str | Model,
    moment: float,
    *,
    particle: int = 0,
    x0: np.ndarray | None = None,
    v0: np.ndarray | None = None,
    **settings,
) -> RelaxationStep:
    """Integrate under the constant ``moment`` until at rest, rotating steadily, or ``t_max``.

    Parameters
    ----------
    params : ChainParams
    model : str or Model
    moment : float
        Constant moment M on ``particle``.
    x0, v0 : ndarray (3, 2N+1), optional
        Start (default rest): the previous step's end state in the protocol.
    **settings
        :class:`RelaxSettings`: ``t_max`` (time cap, default 20000), ``v_tol``,
        ``f_tol`` (rest test: max |v| <= v_tol and max |F + L| <= f_tol (1 + |M|),
        default 1e-9), ``chunk_time`` (default 25), ``window_turns`` (turns per
        window of the rotation test, default 12: rotating states of the paper's
        chain can repeat only after 2 or 3 turns, or be chaotic, so a one-turn test
        would never fire), ``omega_rtol`` (agreement of the two windows' rates,
        default 0.05: a chaotic rotation fluctuates by a few percent over 12 turns),
        ``dt`` (default :func:`~cosserat_chain.numerics.integrators.default_time_step`),
        ``method`` ("verlet" or "yoshida4"), and ``loads`` (constant loads besides the
        moment, acting throughout: :func:`run_plans`).

    Returns
    -------
    RelaxationStep

    Raises
    ------
    ValueError
        For a bad setting, state or moment.
    IntegrationError
        If the dynamics blow up.
    KeyboardInterrupt
        On Ctrl-C.
    """
    x0 = None if x0 is None else np.asarray(x0, dtype=float)[None]
    v0 = None if v0 is None else np.asarray(v0, dtype=float)[None]
    return relax_batch([params], model, [moment], particle=particle, x0=x0, v0=v0, **settings)[0]


def relax_batch(
    params_list: Sequence[ChainParams],
    model: str | Model,
    moments: float | Sequence[float],
    *,
    particle: int = 0,
    x0: np.ndarray | None = None,
    v0: np.ndarray | None = None,
    threads: int = 1,
    **settings,
) -> list[RelaxationStep]:
    """One relaxation step (:func:`relax`) for every member of a batch.

    Member i relaxes ``params_list[i]`` under ``moments[i]`` from ``x0[i]``,
    ``v0[i]``; the result equals ``relax(params_list[i], model, moments[i], ...)``.
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
    threads : int
        Split the members over this many cores.
    **settings
        As in :func:`relax`; ``dt`` may give one step per member.

    Returns
    -------
    list of RelaxationStep (B)

    Raises
    ------
    ValueError
        For members of different N, a non-finite moment, state or dt, a dt beyond a
        member's stability limit (the message names the member and the field), or a
        bad setting.
    IntegrationError
        If a member blows up.
    KeyboardInterrupt
        On Ctrl-C.
    """
    size = len(params_list)
    values = per_member(moments, size, "moments") if size else np.zeros(0)
    results: list[RelaxationStep | None] = [None] * size

    def single(b: int) -> Plan:
        results[b] = yield float(values[b])

    run_plans(params_list, model, [single(b) for b in range(size)], particle=particle, x0=x0, v0=v0, threads=threads, **settings)
    return [r for r in results if r is not None]


@dataclass
class _Member:
    """Bookkeeping of one member's relaxation step in progress."""

    plan: Plan
    moment: float = 0.0
    begun: int = 0  # chunks done before this step began
    chunk: int = 1  # length of the current chunk, in chunks of chunk_time
    due: int = 1  # chunks done at which the next test is due


def run_plans(
    params_list: Sequence[ChainParams],
    model: str | Model,
    plans: Sequence[Plan],
    *,
    particle: int = 0,
    x0: np.ndarray | None = None,
    v0: np.ndarray | None = None,
    threads: int = 1,
    loads: Loads | None = None,
    **settings,
) -> None:
    """Run each member's sequence of relaxation steps, all members in lock-step chunks.

    Member i follows ``plans[i]``: a generator that yields a moment, receives the
    :class:`RelaxationStep` of relaxing under it (from the member's current
    state: ``x0``/``v0`` at first, then the previous step's end state), and so
    on until it returns. A member whose step ends starts its next one at once;
    one that returns leaves the batch. ``loads``: constant loads that act
    throughout, besides the stepped moment (a force along the chain, say); the
    rest test then asks F + M e + loads = 0. Other arguments as in :func:`relax_batch`.

    Raises
    ------
    ValueError
        For bad input (see :func:`relax_batch`), a plan's moment that is not finite, or
        a load in ``loads`` that is not constant (no static state holds under it).
    IntegrationError
        If a member blows up (the message names it).
    KeyboardInterrupt
        On Ctrl-C, after the compiled call in progress.
    """
    options = RelaxSettings(**settings)
    params = check_members(params_list)
    if len(plans) != len(params):
        raise ValueError(f"plans must hold one plan per member ({len(params)}), got {len(plans)}")
    model = get_model(model)
    method = get_method(options.method)
    extra = Loads() if loads is None else Loads(loads)
    changing = [f"{load.row} of particle {load.particle}" for load in extra if not load.schedule.is_constant]
    if changing:
        raise ValueError(
            f"the relaxation protocol needs constant extra loads (a static state under a load that changes does not exist), "
            f"got a schedule on {', '.join(changing)}; use simulate for loads that change"
        )
    loads = Loads([*moment_load(1.0, particle), *extra]).validate(params[0])
    col = column(params[0], particle)
    x0 = stack_states(params, x0, "x0")
    v0 = stack_states(params, v0, "v0")
    requested = member_steps(params, options.dt, method, model)
    for i, (member, step) in enumerate(zip(params, requested.tolist())):
        try:
            require_step_count(member, options.t_max, step, "t_max")
        except ValueError as err:
            raise ValueError(f"member {i} (params_list[{i}]): {err}") from None
    # Whole chunks: chunk_time in a whole number of steps; members with the same step share a loop.
    per_chunk = np.array([math.ceil(options.chunk_time / step - 1e-9) for step in requested], dtype=np.int64)
    steps = options.chunk_time / per_chunk
    stop = threading.Event()

    def run_group(members: np.ndarray) -> None:
        lanes = Lanes(
            model,
            [params[b] for b in members],
            method,
            steps[members],
            loads,
            np.vstack([np.zeros((1, members.size)), np.ones((len(extra), members.size))]),
            x0[members],
            v0[members],
        )
        lanes.follow_turns(col, 2 * options.window_turns + 1)
        active = {int(b): _Member(plans[b]) for b in members}
        index = list(members)  # member of each lane
        for lane, b in enumerate(index):
            _next_step(lanes, lane, active, b, None, 0)
        done = 0
        moved = True  # a member started a step under a new moment
        while active and not stop.is_set():
            if moved:
                # The loaded column of a member with a new moment: forces plus loads anew
                # (for the others this gives the same bits as the loop left there).
                lanes.evaluate_forces()
                moved = False
            code, _, _ = lanes.advance(per_chunk[index[0]], done * per_chunk[index[0]])
            done += 1
            if code == STATUS_BLEW_UP:
                lane = int(np.argmax(lanes.lane_ints[BLEW_UP]))
                raise _blow_up(lanes, lane, index[lane], active[index[lane]].moment, done * options.chunk_time)
            for lane, b in enumerate(index):
                member = active.get(b)
                if member is None or member.due != done:
                    continue
                result = _outcome(lanes, lane, member, done, options, particle, extra)
                if result is None:
                    member.chunk = min(2 * member.chunk, MAX_CHUNKS)
                    member.due = min(done + member.chunk, member.begun + options.chunks)
                else:
                    _next_step(lanes, lane, active, b, result, done)
                    moved = True
            keep = [lane for lane, b in enumerate(index) if b in active]
            if active and len(keep) < len(index):
                lanes = lanes.select(np.array(keep))
                index = [index[lane] for lane in keep]

    groups = [np.flatnonzero(per_chunk == value) for value in np.unique(per_chunk)]
    try:
        run_parts(run_group, [part for group in groups for part in split(group, threads, params)], threads)
    except KeyboardInterrupt:
        stop.set()
        raise


def _next_step(lanes: Lanes, lane: int, active: dict, b: int, result: RelaxationStep | None, done: int) -> None:
    """Hand ``result`` to member b's plan and start its next step in ``lane`` (or retire the member)."""
    member = active[b]
    try:
        moment = next(member.plan) if result is None else member.plan.send(result)
    except StopIteration:
        del active[b]
        return
    if not math.isfinite(moment):
        raise ValueError(f"member {b}: moment must be finite, got {moment!r}")
    member.moment = float(moment)
    member.begun, member.chunk, member.due = done, 1, done + 1
    lanes.load_scale[0, lane] = member.moment
    lanes.restart_turns(np.array([lane]), np.array([1.0 if member.moment >= 0 else -1.0]))


def _outcome(
    lanes: Lanes, lane: int, member: _Member, done: int, options: RelaxSettings, particle: int, extra: Loads
) -> RelaxationStep | None:
    """The tests at the end of a chunk: the finished step, or None to go on."""
    params = lanes.params[lane]
    col = column(params, particle)
    elapsed = (done - member.begun) * options.chunk_time
    x, v = lanes.state(lane)
    load = moment_load(member.moment, particle).as_array(params, 0.0) + extra.as_array(params, 0.0)
    residual = float(np.max(np.abs(zero_held(params, lanes.model.forces(params, x) + load))))
    speed = float(np.max(np.abs(v)))
    count = int(lanes.lane_ints[CROSSINGS, lane])
    turns_record = lanes.turns
    if speed <= options.v_tol and residual <= options.f_tol * (1.0 + abs(member.moment)):
        status, omega = Status.STATIC, np.zeros(params.n_particles)
        message = f"at rest after t={elapsed:.6g} (max|v|={speed:.2g}, residual {residual:.2g})"
    elif (
        omega := steady_rotation(
            turns_record.time[:, lane],
            turns_record.step_time[:, lane],
            turns_record.phi[:, :, lane],
            count,
            options.window_turns,
            options.omega_rtol,
        )
    ) is not None:
        status = Status.ROTATING
        message = f"steady rotation after t={elapsed:.6g}: {count} turns, mean angular velocity {omega[col]:.6g}"
    elif done - member.begun >= options.chunks:
        status, omega = Status.NOT_CONVERGED, np.full(params.n_particles, np.nan)
        message = (
            f"neither at rest nor rotating steadily after t_max={options.t_max:g} (max|v|={speed:.2g}, residual {residual:.2g}, "
            f"{count} turns); raise t_max or loosen v_tol/f_tol"
        )
    else:
        return None
    turns = lanes.lanes[DIRECTION, lane] * (x[2, col] - lanes.lanes[PHI_START, lane]) / (2 * math.pi)
    return RelaxationStep(status, x, v, float(elapsed), residual, speed, float(turns), omega, message)


def steady_rotation(time, step_time, phi, count: int, window: int, rtol: float) -> np.ndarray | None:
    """Mean angular velocities over the last two windows of turns if their rates agree, else None.

    Parameters
    ----------
    time, step_time : (C,) ring of turn times and of the times of the steps after them
    phi : (C, 2N+1) every particle's angle at those steps
    count : turns made (turn n is in slot (n - 1) mod C)
    window : turns per window; C must be at least 2 window + 1
    rtol : relative agreement of the two windows' mean rates
    """
    if count < 2 * window + 1:
        return None
    capacity = time.size
    last, middle, first = (count - 1) % capacity, (count - 1 - window) % capacity, (count - 1 - 2 * window) % capacity
    rate_first = window / (time[middle] - time[first])
    rate_last = window / (time[last] - time[middle])
    if abs(rate_last - rate_first) > rtol * abs(rate_last):
        return None
    return (phi[last] - phi[first]) / (step_time[last] - step_time[first])


def _blow_up(lanes: Lanes, lane: int, b: int, moment: float, time: float) -> IntegrationError:
    """The error for member b's blow-up, carrying its state."""
    x, v = lanes.state(lane)
    dt = float(lanes.lanes[DT, lane])
    cause, remedy = lanes.runaway(lane)
    message = f"member {b} (params_list[{b}], moment {moment:g}) blew up by t={time:.6g}: {cause or 'a value ran out of bounds'}; {remedy}."
    trajectory = Trajectory(
        time=np.array([time]), x=x[None], v=v[None], load_work=np.full(1, np.nan), dissipated=np.full(1, np.nan),
        status=Status.BLEW_UP, message=message, steps=0, dt=dt, method=lanes.method.name,
    )  # fmt: skip
    return IntegrationError(message, trajectory)
