"""Damped dynamics of the loaded chain with the compiled fixed-step integrators.

Contract
--------
:func:`integrate` advances ``x' = v, M v' = F(x) + L(t) - Gamma v`` from t0 to
t_end with a fixed step, storing every ``stride``-th state, and returns a
:class:`Trajectory`. It calls the compiled loop in chunks of roughly a fraction
of a second, so that progress can be reported and Ctrl-C stops the run cleanly
between chunks with everything computed so far kept (status ``interrupted``).
A run that blows up (a non-finite value, a runaway displacement or a particle
turning by thousands of turns a step) stops with status ``blew_up``, keeps the
frames before it, and, with ``throw=True``, raises :class:`IntegrationError`
carrying the partial trajectory; its message says which value ran away and what to change.

Angles never overflow: the engine keeps a rotating model's angles as whole turns
plus an angle near 64 rad or below (:mod:`.engine`), so a run 10^7 turns from the start
is as accurate as one of ten. The trajectory's ``x[:, 2]`` is the unwrapped angle
as a double; ``reduced_phi`` and ``winding`` hold it without a bit lost.

With ``turns=TurnWatch(particle, ...)`` the compiled loop follows that
particle's turns step by step (the package's one turn detector: turn n is
complete when direction (phi - phi_start) reaches 2 pi n, its time interpolated
linearly between the two steps around it) and can stop at the step that
completes a given turn; the trajectory's :class:`TurnLog` holds the latest turns
and continues the count in the next run.

A run can be continued where it stopped: ``integrate(on_chunk=...)`` hands a
:class:`RunState` to the caller at the start and after every chunk, and
``integrate(resume=state)`` goes on from it with the chunks, forces and energy
sums the uninterrupted run had, so that the result equals that run's to the last
bit (the experiments' checkpoints store it: :mod:`cosserat_chain.experiments.simulation`).
"""

from __future__ import annotations

import logging
import math
from collections.abc import Callable
from dataclasses import dataclass, field, replace

import numpy as np

from ..errors import CosseratChainError
from ..loads import Loads
from ..memory import FLOAT, require
from ..models.base import Model, get_model
from ..models.trig import join_turns
from ..params import BOND_FACTORS, PARTICLE_FACTORS, ChainParams
from ..state import check_state, column, held
from ..status import Status
from .engine import CROSSINGS, PEAK_SPIN, STATUS_BLEW_UP, STATUS_OK, STATUS_TURNED, TURN_LIMIT, Blocks, Lanes
from .integrators import Method, check_time_step, default_time_step, get_method, spin_hint

log = logging.getLogger(__name__)

#: Compiled work per chunk (particle force evaluations); about 0.5-2 s, the rate of progress
#: reports and of chances to stop (Ctrl-C, checkpoints). Each chunk ends with its frame stored,
#: an out-of-bounds test and a copy of the state (to find a blow-up's first bad step): about
#: 1.5 steps' worth of work at 10^6 particles, 7 % of a chunk of 2 * 10^7 (20 steps), 1.5 % of
#: one of 10^8. A chunk is whole strides; where one stride is more work than this (a run of few
#: frames), a single-threaded run calls the compiled loop for pieces of this much work, left open
#: between them (the same bits), so that progress and Ctrl-C do not wait for the stride's end.
CHUNK_WORK = 100_000_000

ProgressCallback = Callable[[int, int], None]


class IntegrationError(CosseratChainError, RuntimeError):
    """A run that could not be completed; ``trajectory`` holds what was computed."""

    def __init__(self, message: str, trajectory: Trajectory):
        super().__init__(message)
        self.trajectory = trajectory


@dataclass(frozen=True)
class TurnWatch:
    """Which turns :func:`integrate` follows, and when it stops.

    Parameters
    ----------
    particle : int
        Index -N..N of the particle whose turns are counted.
    direction : {1.0, -1.0}
        Turns count along this sense (the sign of the driving moment).
    phi_start : float, optional
        Angle from which turns count; default the particle's angle at the start.
    made : int
        Turns already made from ``phi_start`` (a run that continues another).
    keep : int
        The latest turns whose times and angles are kept.
    stop_after : int, optional
        Stop at the step that completes this turn (counted from ``phi_start``);
        the run then ends before t_end with status ``completed``.
    """

    particle: int
    direction: float = 1.0
    phi_start: float | None = None
    made: int = 0
    keep: int = 16
    stop_after: int | None = None

    def __post_init__(self):
        if self.direction not in (1.0, -1.0):
            raise ValueError(f"TurnWatch.direction must be 1.0 or -1.0, got {self.direction!r}")
        if self.keep < 1:
            raise ValueError(f"TurnWatch.keep must be >= 1, got {self.keep!r}")
        if self.stop_after is not None and self.stop_after <= self.made:
            raise ValueError(f"TurnWatch.stop_after must exceed made={self.made}, got {self.stop_after!r}")


@dataclass
class TurnLog:
    """The followed particle's turns at the end of a run (:class:`TurnWatch`).

    Attributes
    ----------
    watch : TurnWatch
        What was followed (with ``phi_start`` filled in).
    made : int
        Turns made from ``phi_start`` by the end of the run.
    times : ndarray (k,)
        Interpolated times of the latest k <= ``keep`` turns completed in this run, oldest first.
    step_times : ndarray (k,)
        Times of the steps right after them.
    phi : ndarray (k, 2N+1)
        Every particle's angle at those steps.
    """

    watch: TurnWatch
    made: int
    times: np.ndarray
    step_times: np.ndarray
    phi: np.ndarray

    def following(self, stop_after: int | None = None) -> TurnWatch:
        """The watch that goes on counting in a run that starts where this one ended."""
        return replace(self.watch, made=self.made, stop_after=stop_after)


@dataclass
class Trajectory:
    """Stored states of a run.

    Attributes
    ----------
    time : ndarray (n_frames,)
    x, v : ndarray (n_frames, 3, 2N+1)
        Configurations and velocities (rows u, v, phi).
    load_work, dissipated : ndarray (n_frames,)
        Work done by the loads and energy removed by viscosity since the start.
    status : Status
        ``completed``, ``blew_up`` or ``interrupted``.
    message : str
        Human-readable explanation of the status (how to fix a failure).
    steps : int
        Steps actually taken.
    dt : float, method : str
    turns : TurnLog or None
        The followed particle's turns (``integrate(turns=...)``).
    winding : ndarray (n_frames, 2N+1) of int64, or None
        Whole turns of every angle (None where the run did not record them).
    reduced_phi : ndarray (n_frames, 2N+1), or None
        The angles less their whole turns: phi = reduced_phi + 2 pi winding exactly, of
        which ``x[:, 2]`` is the nearest double (the same bits while the winding is 0).
    peak_spin : float
        0 where |phi'| stayed within ``MAX_SPIN_PER_STEP / dt`` (a step that resolves a turn)
        at every step boundary, stored or not; else the largest |phi'| at the step boundaries
        from the first beyond it on (for that first one, the level itself: :mod:`.engine`).
    """

    time: np.ndarray
    x: np.ndarray
    v: np.ndarray
    load_work: np.ndarray
    dissipated: np.ndarray
    status: str
    message: str
    steps: int
    dt: float
    method: str
    turns: TurnLog | None = None
    winding: np.ndarray | None = None
    reduced_phi: np.ndarray | None = None
    peak_spin: float = 0.0

    @property
    def ok(self) -> bool:
        return self.status == Status.COMPLETED


@dataclass(frozen=True)
class RunState:
    """A fixed-step run at a chunk boundary: what :func:`integrate` needs to go on as if it had not stopped.

    The forces and the energy sums are carried rather than recomputed: a force
    evaluated anew at the restart would take its loads at ``t0 + steps dt``,
    which may differ in the last bit from the time the run summed sub-step by
    sub-step, and the chunk length is carried because where a chunk closes its
    last step changes the rounding of the steps around it.

    Attributes
    ----------
    steps : int
        Steps taken; the state is at ``t0 + steps * dt``.
    n_steps, stride, chunk : int
        Steps of the whole run, steps between stored frames, steps per chunk.
    t0, dt : float
        Start time and (effective) time step of the whole run.
    method : str
    x, v, f : ndarray (3, 2N+1)
        Configuration (angles less their whole turns, as the engine keeps them), velocities
        and forces plus loads at that step (copies). The velocities are those of the open
        sub-step that the run goes on from (a stored frame has them closed), at the start
        (steps 0) and the end (steps n_steps) those at the step boundary.
    acc : ndarray (2,)
        Load work and dissipated energy since the start.
    frame_steps : ndarray (k,) of int
        Steps of the frames stored so far (the first is 0).
    frames_x, frames_v : ndarray (k, 3, 2N+1)
    frames_acc : ndarray (k, 2)
        The frames stored so far and their energy sums (views that the run never writes again).
    split_acc : ndarray (b + 1, 2)
        A run split into b blocks (on threads, or a chain too long for the cache): the sums when
        the blocks took over, then each block's own (``acc`` is their total; summed in another
        order they would differ in the last bits). Empty (0, 2) for a run not split. A run resumed on as many blocks goes
        on with them; on another number its states are still bitwise the same, its energy
        sums equal to round-off.
    winding : ndarray (2N+1,) of int64, optional
        Whole turns of the angles of ``x`` (None: none).
    frames_winding : ndarray (k, 2N+1) of int64, optional
        Whole turns of the frames' angles (None: none).
    peak_spin : float
        :attr:`Trajectory.peak_spin` so far.
    """

    def windings(self) -> tuple[np.ndarray, np.ndarray]:
        """(winding, frames_winding), zeros where not given."""
        k, n = self.frames_x.shape[0], self.x.shape[-1]
        winding = np.zeros(n, dtype=np.int64) if self.winding is None else self.winding
        frames = np.zeros((k, n), dtype=np.int64) if self.frames_winding is None else self.frames_winding
        return winding, frames

    steps: int
    n_steps: int
    stride: int
    chunk: int
    t0: float
    dt: float
    method: str
    x: np.ndarray
    v: np.ndarray
    f: np.ndarray
    acc: np.ndarray
    frame_steps: np.ndarray
    frames_x: np.ndarray
    frames_v: np.ndarray
    frames_acc: np.ndarray
    split_acc: np.ndarray = field(default_factory=lambda: np.zeros((0, 2)))
    winding: np.ndarray | None = None
    frames_winding: np.ndarray | None = None
    peak_spin: float = 0.0

    def check(self, params: ChainParams, n_steps: int, stride: int, t0: float, dt: float, method: str) -> None:
        """Refuse a state that is not of this run (its steps, frames, time axis, method or chain).

        Raises
        ------
        ValueError
            Naming the first thing that differs.
        """
        for name, mine, theirs in (
            ("n_steps", self.n_steps, n_steps),
            ("stride", self.stride, stride),
            ("t0", self.t0, t0),
            ("dt", self.dt, dt),
            ("method", self.method, method),
        ):
            if mine != theirs:
                raise ValueError(f"the run state to resume is of a run with {name}={mine!r}, but this run has {name}={theirs!r}")
        k = self.frame_steps.shape[0]
        shape = (3, params.n_particles)
        if not (0 <= self.steps <= n_steps and self.chunk >= stride and self.chunk % stride == 0):
            raise ValueError(f"the run state to resume has steps={self.steps}, chunk={self.chunk}: not a chunk boundary of this run")
        if not (1 <= k <= n_steps // stride + 2 and self.frame_steps[0] == 0 and self.frame_steps[-1] <= self.steps):
            raise ValueError(f"the run state to resume has {k} frames up to step {self.frame_steps[-1]}: not this run's")
        for name, array, expected in (
            ("x", self.x, shape),
            ("v", self.v, shape),
            ("f", self.f, shape),
            ("acc", self.acc, (2,)),
            ("frames_x", self.frames_x, (k, *shape)),
            ("frames_v", self.frames_v, (k, *shape)),
            ("frames_acc", self.frames_acc, (k, 2)),
            ("split_acc", self.split_acc, (self.split_acc.shape[0], 2)),
            ("winding", self.windings()[0], (params.n_particles,)),
            ("frames_winding", self.windings()[1], (k, params.n_particles)),
        ):
            if np.shape(array) != expected:
                raise ValueError(f"the run state's {name} has the shape {np.shape(array)}, this run needs {expected}")


@dataclass
class _Restart:
    """A chain's state between two chunks, to rerun a chunk that blew up step by step.

    The positions are those of the frame stored at the chunk's start (a chunk is a whole
    number of strides), so the open velocities, the forces and the sums are kept. At the start of
    a fresh run the forces are evaluated again when needed (:meth:`Lanes.evaluate_forces` on
    the same state at the same time gives the same bits); later they are copied into a
    buffer made once a run, when first needed: a fresh copy every chunk page-faulted its
    memory anew, at 10^6 particles about as much as the chunk's closing work (benchmarks/TIMINGS.md),
    and a run of one chunk copies nothing.
    """

    acc: np.ndarray
    lane_ints: np.ndarray
    f: np.ndarray | None = None
    x: np.ndarray | None = None
    v: np.ndarray | None = None
    winding: np.ndarray | None = None
    open_v: np.ndarray | None = None
    pending: int = 0
    evaluate: bool = False

    @classmethod
    def like(cls, lanes: Lanes) -> _Restart:
        return cls(np.empty_like(lanes.acc), np.empty_like(lanes.lane_ints))

    def save(self, lanes: Lanes, x: np.ndarray, v: np.ndarray, winding: np.ndarray, fresh: bool = False) -> _Restart:
        """Keep ``lanes``' forces and sums at the start of a chunk whose state is the stored frame (x, v, winding).

        ``fresh``: the chunk is a fresh run's first, whose forces :meth:`Lanes.evaluate_forces` gave
        (and whose velocities are the frame's); a later chunk starts from the open sub-step.
        """
        self.evaluate = fresh
        if not fresh:
            if self.f is None:
                self.f, self.open_v = np.empty_like(lanes.f), np.empty_like(lanes.v)
            np.copyto(self.f, lanes.f)
            np.copyto(self.open_v, lanes.v)
            v = self.open_v
        np.copyto(self.acc, lanes.acc)
        np.copyto(self.lane_ints, lanes.lane_ints)
        self.x, self.v, self.winding, self.pending = x, v, winding, lanes.pending
        return self

    def restore(self, lanes: Lanes) -> None:
        """Put ``lanes`` back to the chunk's start: its stored positions, velocities, forces and sums."""
        lanes.x[...], lanes.v[...], lanes.acc[...], lanes.lane_ints[...] = self.x, self.v, self.acc, self.lane_ints
        lanes.winding[...] = self.winding
        if self.evaluate:
            # The start state as given: split into turns as the run's start was.
            lanes.reduce_angles()
            lanes.evaluate_forces()
        else:
            lanes.f[...] = self.f
        lanes.pending = self.pending

    def first_bad_step(self, lanes: Lanes, step0: int, steps: int, stride: int) -> int:
        """Steps from ``step0`` to the first state out of bounds (the loop checks only every 1024 steps).

        The chunk is run again from its start with a check after every step, storing no
        state (a store changes no state): the same kernels on the same bits reach the same
        states, and it stops at the first bad one, which is left in ``lanes``.
        """
        self.restore(lanes)
        stores = steps // stride + 2
        scratch = (
            np.zeros((0, *lanes.x.shape)),
            np.zeros((0, *lanes.x.shape)),
            np.zeros((stores, 2, 1)),
            np.zeros((stores, 1)),
            np.zeros((0, *lanes.winding.shape), dtype=np.int64),
        )
        _, done, _ = lanes.advance(steps, step0, stride, 1, scratch, 0)
        return done


#: Most steps of one run: beyond 2^53 the step counter and the times it gives stop being exact.
MAX_STEPS = 2.0**53

#: Arrays of the chain's size that a run holds besides its frames (forces, the lanes' tables, scratch,
#: the open velocities kept at a chunk's start and the blocks' own frame slots).
_WORKING_ARRAYS = 15


def _require_frames(params: ChainParams, n_stored: int) -> None:
    """Refuse a run whose stored frames (positions and velocities) and working arrays do not fit in memory."""
    n = params.n_particles
    require(
        FLOAT * 3 * n * (2 * n_stored + _WORKING_ARRAYS) + np.dtype(np.int64).itemsize * n * n_stored,
        f"{n_stored} frames x 3 rows x {n} particles (N={params.N}) x 2 (positions and velocities)",
        "store fewer frames (n_frames, --frames) or simulate a shorter chain",
    )


def _check_winding(params: ChainParams, winding0, model: Model) -> np.ndarray:
    """winding0 as int64 (2N+1,), checked: whole numbers, none for a model that does not rotate or at a held angle.

    Raises
    ------
    ValueError
        Naming the particle and the value that is not allowed.
    """
    arr = np.asarray(winding0)
    if arr.shape != (params.n_particles,):
        raise ValueError(f"winding0 must have shape (2N+1,) = ({params.n_particles},), got {arr.shape}")
    whole = np.asarray(arr, dtype=float)
    bad = np.flatnonzero(~(np.isfinite(whole) & (whole == np.round(whole)) & (np.abs(whole) < 2.0**62)))
    if bad.size:
        raise ValueError(
            f"winding0 of particle {bad[0] - params.N} is {arr[bad[0]].item()!r}; whole numbers of turns below 2^62 are allowed"
        )
    turns = whole.astype(np.int64)
    if turns.any() and not model.rotates:
        raise ValueError(f"winding0 gives whole turns, but the {model.name} model does not rotate (its forces are not periodic in phi)")
    for row, col in held(params):
        if row == 2 and turns[col]:
            raise ValueError(f"winding0 of particle {col - params.N} is {turns[col]}, but its end holds phi fixed: it must be 0")
    return turns


def require_step_count(params: ChainParams, span: float, dt: float, what: str) -> float:
    """The steps of ``dt`` over ``span``; refuse more than :data:`MAX_STEPS`, naming the chain's stiffness and inertia.

    Raises
    ------
    ValueError
        Where span / dt exceeds :data:`MAX_STEPS` (the step counters' exact integers).
    """
    steps = span / dt
    if not steps <= MAX_STEPS:
        raise ValueError(
            f"the run would take {steps:.3g} steps of dt={dt:.3g} ({what} = {span:g}), more than {MAX_STEPS:.3g}: "
            f"the time step follows the fastest mode sqrt(stiffness / inertia), here E1={params.E1:g}, E2={params.E2:g}, "
            f"m={params.m:g}, j={params.j:g}"
            + "".join(
                f", {name} from {min(f):g} to {max(f):g}" for name in (*BOND_FACTORS, *PARTICLE_FACTORS) if (f := getattr(params, name))
            )
            + f"; the model is dimensionless, so scale them to order 1 or shorten {what}"
        )
    return steps


def integrate(
    params: ChainParams,
    model: str | Model,
    loads: Loads = Loads(),
    *,
    t_end: float,
    dt: float | None = None,
    t0: float = 0.0,
    x0: np.ndarray | None = None,
    v0: np.ndarray | None = None,
    winding0: np.ndarray | None = None,
    method: str | Method = "verlet",
    stride: int | None = None,
    n_frames: int | None = 201,
    threads: int = 1,
    max_displacement: float | None = None,
    check_stability: bool = True,
    progress: ProgressCallback | None = None,
    throw: bool = False,
    turns: TurnWatch | None = None,
    resume: RunState | None = None,
    on_chunk: Callable[[RunState], None] | None = None,
) -> Trajectory:
    """Integrate the damped, loaded chain with a compiled fixed-step method.

    Parameters
    ----------
    params : ChainParams
    model : str or Model
        ``"nonlinear"``, ``"sine"``, ``"linear"`` or a registered model.
    loads : Loads
        Point loads (moments and forces) with their schedules.
    t_end : float
        Final time, reached exactly: the run takes n = ceil((t_end - t0) / dt) steps
        of size (t_end - t0) / n, which is at most ``dt``.
    dt : float, optional
        Largest time step; default :func:`default_time_step`.
    x0, v0 : ndarray (3, 2N+1), optional
        Initial state; default rest.
    winding0 : ndarray (2N+1,) of int, optional
        Whole turns to add to x0's angles: the start is x0[2] + 2 pi winding0 exactly. To go on
        from a run without a bit lost at any winding: ``x0`` with ``run.reduced_phi[-1]`` as its
        angles and ``winding0=run.winding[-1]`` (``x0=run.x[-1]`` alone rounds the angles to
        doubles of their size).
    method : {"verlet", "yoshida4"}
    stride, n_frames : int, optional
        Store every ``stride``-th step; if not given, ``stride`` is chosen so that
        about ``n_frames`` states are stored (always including the first and last).
    threads : int
        Run the chain on this many threads as blocks with halos that meet every 64
        steps (:class:`~cosserat_chain.numerics.engine.Blocks`; worth it from about
        10^5 particles on, a chain too short for blocks runs on one). The states
        equal a one-thread run's to the last bit. From 2^18 particles on the chain
        runs as blocks that fit in the cache on one thread too.
    max_displacement : float, optional
        |u| or |v| beyond this is a runaway; default 100 chain lengths.
    check_stability : bool
        Refuse a dt beyond the linear stability limit before running.
    progress : callable(steps_done, steps_total), optional
    throw : bool
        Raise :class:`IntegrationError` instead of returning a failed trajectory.
    turns : TurnWatch, optional
        Follow a particle's turns (on one thread) and stop after one of them if asked.
    resume : RunState, optional
        Go on from this state of the same run (the same chain, loads, t0, t_end, dt,
        method and frames; ``x0`` and ``v0`` are then not given): the result equals the
        uninterrupted run's to the last bit. Not with ``turns``.
    on_chunk : callable(RunState), optional
        Called with the run's state at the start and after every chunk that ended
        normally (not after a blow-up), before ``progress``; the state stays valid
        after the call, so the latest one received is what an interrupted run can be
        resumed from. Not with ``turns``.

    Returns
    -------
    Trajectory

    Raises
    ------
    ValueError
        For bad input (non-finite state, t_end <= t0, dt beyond the stability limit, ...).
    """
    model = get_model(model)
    method = get_method(method)
    if n_frames is not None and not (isinstance(n_frames, (int, np.integer)) and n_frames >= 2):
        raise ValueError(f"n_frames must be an integer >= 2 (the start and the end), got {n_frames!r}")
    if not (isinstance(threads, (int, np.integer)) and threads >= 1):
        raise ValueError(f"threads must be an integer >= 1, got {threads!r}")
    n = params.n_particles
    # Before anything of the chain's size is made (the default step's eigenvalue bound is one).
    _require_frames(params, n_frames or 2)
    if dt is None:
        # omega_max dt = DEFAULT_OMEGA_DT, far inside every method's stability limit: no check
        # (it would compute the frequency bound a second time).
        dt = default_time_step(params, model)
    elif check_stability:
        check_time_step(params, float(dt), method, model)
    elif not (math.isfinite(dt) and dt > 0):
        raise ValueError(f"dt must be a finite number > 0, got {dt!r}")
    dt = float(dt)
    if not (math.isfinite(t_end) and t_end > t0):
        raise ValueError(f"t_end must be finite and > t0={t0!r}, got {t_end!r}")
    steps = require_step_count(params, t_end - t0, dt, "t_end - t0")
    n_steps = max(1, math.ceil(steps - 1e-9))
    dt = (t_end - t0) / n_steps  # at most the requested step, and t_end is reached exactly
    if stride is None:
        stride = max(1, math.ceil(n_steps / max(1, (n_frames or 2) - 1)))
    if stride < 1:
        raise ValueError(f"stride must be >= 1, got {stride!r}")
    if x0 is not None:
        x0 = check_state(params, x0, "x0")
    if winding0 is not None:
        winding0 = _check_winding(params, winding0, model)
    if v0 is not None:
        v0 = check_state(params, v0, "v0")
    if turns is not None and (resume is not None or on_chunk is not None):
        raise ValueError("resume and on_chunk do not follow turns: the turn count is not part of a RunState")
    if resume is not None:
        if x0 is not None or v0 is not None or winding0 is not None:
            raise ValueError("resume holds the run's start state: give no x0, v0 or winding0 with it")
        resume.check(params, n_steps, stride, t0, dt, method.name)
    if max_displacement is None:
        max_displacement = 100.0 * 2 * params.N * params.h
    loads.validate(params)
    n_stored = n_steps // stride + 1 + (n_steps % stride != 0)
    _require_frames(params, n_stored)
    # The state evolves in the last frame slots, where it ends: two arrays fewer to
    # allocate and copy. np.zeros leaves the pages unmapped until written, so a run
    # from rest writes neither its first frame nor its start state (at 10^6
    # particles, each such (3, n) pass costs about a kick-drift).
    frames_x = np.zeros((n_stored, 3, n, 1))
    frames_v = np.zeros((n_stored, 3, n, 1))
    frames_acc = np.zeros((n_stored, 2, 1))
    record = np.zeros((n_stored, 1))
    frames_winding = np.zeros((n_stored, n, 1), dtype=np.int64)
    lanes = Lanes(model, [params], method, [dt], loads, t0=[t0], max_displacement=[max_displacement])
    lanes.x, lanes.v, lanes.winding = frames_x[-1], frames_v[-1], frames_winding[-1]
    if x0 is not None:
        # Frame 0 keeps the start as given (with winding0); the state splits off whole turns beyond 64 rad.
        frames_x[0, ..., 0] = lanes.x[..., 0] = x0
    if winding0 is not None:
        frames_winding[0, :, 0] = lanes.winding[:, 0] = winding0
    if resume is None:
        lanes.reduce_angles("x0")
    if v0 is not None:
        frames_v[0, ..., 0] = lanes.v[..., 0] = v0
    frame_steps = np.empty(n_stored, dtype=np.int64)
    frame_steps[0] = 0
    stored = 1
    steps_done = 0
    if resume is None:
        lanes.evaluate_forces()
    else:
        # Before the blocks are made: they copy the chain's state and energy sums.
        stored, steps_done = resume.frame_steps.shape[0], resume.steps
        frame_steps[:stored] = resume.frame_steps
        frames_x[:stored, ..., 0], frames_v[:stored, ..., 0], frames_acc[:stored, :, 0] = (
            resume.frames_x, resume.frames_v, resume.frames_acc
        )  # fmt: skip
        lanes.x[..., 0], lanes.v[..., 0], lanes.f[..., 0], lanes.acc[:, 0] = resume.x, resume.v, resume.f, resume.acc
        lanes.winding[:, 0], frames_winding[:stored, :, 0] = resume.windings()
        lanes.lanes[PEAK_SPIN, 0] = resume.peak_spin
        if 0 < steps_done < n_steps:
            lanes.pending = method.force_evaluations - 1  # between its first and last step a run is open (RunState.v)
    if turns is not None:
        lanes.follow_turns(column(params, turns.particle), turns.keep)
        # The current angle by default: from its turns and the rest as they are, not through a double.
        lanes.restart_turns(np.array([0]), np.array([turns.direction]), turns.phi_start, turns.made)
        phi_start = lanes.unwrapped_angles()[lanes.watch, 0] if turns.phi_start is None else turns.phi_start
        turns = replace(turns, phi_start=float(phi_start))
        if turns.stop_after is not None:
            lanes.lane_ints[TURN_LIMIT] = turns.stop_after
    # The blocks follow no turns: a run that follows them stays on one thread; so does a
    # ring, whose two ends are neighbours (its blocks would need a halo across the seam).
    # A graded chain on one thread: a block is a chain of its own, numbered from its first
    # column, while the graded coefficients are numbered along the whole chain.
    split = turns is None and not params.periodic and not params.graded and Blocks.count(n, threads, method.force_evaluations) > 1
    blocks = Blocks(lanes, threads) if split else None
    if blocks is not None and resume is not None and resume.split_acc.shape[0] == len(blocks.blocks) + 1:
        blocks.acc0[:, 0] = resume.split_acc[0]
        for block, sums in zip(blocks.blocks, resume.split_acc[1:]):
            block.acc[:, 0] = sums
    runner = lanes if blocks is None else blocks

    status, message = Status.COMPLETED, f"{n_steps} steps of {method.name} with dt={dt:g}"
    chunk = max(stride, CHUNK_WORK // (n * method.force_evaluations) // stride * stride) if resume is None else resume.chunk
    frames = (frames_x, frames_v, frames_acc, record, frames_winding)

    def run_state() -> RunState:
        return RunState(
            steps_done, n_steps, stride, chunk, t0, dt, method.name,
            lanes.x[..., 0].copy(), lanes.v[..., 0].copy(), lanes.f[..., 0].copy(), lanes.acc[:, 0].copy(),
            frame_steps[:stored].copy(), frames_x[:stored, ..., 0], frames_v[:stored, ..., 0], frames_acc[:stored, :, 0],
            np.zeros((0, 2)) if blocks is None else np.array([blocks.acc0[:, 0], *(block.acc[:, 0] for block in blocks.blocks)]),
            lanes.winding[:, 0].copy(), frames_winding[:stored, :, 0], float(lanes.lanes[PEAK_SPIN, 0]),
        )  # fmt: skip

    # A chunk of blocks that blew up is rerun whole, unsplit, from its start: the same bits.
    restart = None if turns is not None else _Restart.like(lanes)
    # Pieces of a chunk for one thread that keeps the chunk's start (CHUNK_WORK): Ctrl-C within a chunk goes back there.
    piece = chunk if blocks is not None or restart is None else max(1, CHUNK_WORK // (n * method.force_evaluations))
    chunk_start = chunk_stored = steps_done
    inside = False
    try:
        if on_chunk is not None:
            on_chunk(run_state())
        while steps_done < n_steps:
            todo = min(chunk, n_steps - steps_done)
            # The chunk's start, kept to find the first bad step of a blow-up (checked every 1024 steps):
            # the last frame stored (chunks are whole strides, so every chunk starts on one).
            assert frame_steps[stored - 1] == steps_done, "a chunk starts at a stored frame"
            start = (
                None
                if restart is None
                else restart.save(
                    lanes, frames_x[stored - 1], frames_v[stored - 1], frames_winding[stored - 1], fresh=steps_done == 0 and resume is None
                )
            )
            chunk_start, chunk_stored, code, inside = steps_done, stored, STATUS_OK, True
            while code == STATUS_OK and steps_done < chunk_start + todo:
                length = min(piece, chunk_start + todo - steps_done)
                if steps_done + length == chunk_start + todo:
                    # Open at a chunk's end too (its frame stored): only the run's last step is closed.
                    code, done, written = runner.advance(length, steps_done, stride, 1024, frames, stored, steps_done + length == n_steps)
                else:  # left open: the next piece goes on as if the loop had not stopped (only the lanes run pieces)
                    code, done, written = lanes.advance(length, steps_done, stride, 1024, frames, stored, close_at_end=False)
                if code == STATUS_BLEW_UP and start is not None:
                    done = start.first_bad_step(lanes, chunk_start, steps_done - chunk_start + done, stride) - (steps_done - chunk_start)
                first = (steps_done // stride + 1) * stride
                frame_steps[stored : stored + written] = first + stride * np.arange(written)
                stored += written
                steps_done += done
                # A chunk done (or stopped) is kept: a Ctrl-C from here on stops after it.
                inside = code == STATUS_OK and steps_done < chunk_start + todo
                if inside and progress is not None:
                    progress(steps_done, n_steps)
            if on_chunk is not None and code == STATUS_OK:
                on_chunk(run_state())
            if progress is not None:
                progress(steps_done, n_steps)
            if code == STATUS_TURNED:
                message = f"stopped after turn {turns.stop_after} of particle {turns.particle} at t={t0 + steps_done * dt:.6g}"
                break
            if code == STATUS_BLEW_UP:
                status = Status.BLEW_UP
                cause, remedy = lanes.runaway(0)
                message = (
                    f"the run blew up at t={t0 + steps_done * dt:.6g} (step {steps_done}"
                    + (", the first state out of bounds" if start is not None else ", found at the periodic check")
                    + f"): {cause or 'a value ran out of bounds'}. {remedy[:1].upper() + remedy[1:]}"
                    + (f". {hint}" if (hint := spin_hint(params, loads, dt)) else "")
                    + "; the states up to then are kept."
                )
                break
    except KeyboardInterrupt:
        if inside and restart is not None:
            # Within a chunk (its state may be open between pieces): back to its start, its last stored frame.
            restart.restore(lanes)
            steps_done, stored = chunk_start, chunk_stored
        status = Status.INTERRUPTED
        message = f"interrupted at t={t0 + steps_done * dt:.6g} after {steps_done} of {n_steps} steps; states up to then are kept"
        log.warning(message)
    finally:
        if blocks is not None:
            blocks.close()
    x, v, acc = lanes.x, lanes.v, lanes.acc
    frames_x, frames_v, frames_acc = frames_x[..., 0], frames_v[..., 0], frames_acc[..., 0]
    frames_winding = frames_winding[..., 0]
    if steps_done % stride != 0 and status != Status.BLEW_UP:
        # The last step is always kept, even off the stride.
        frames_x[stored], frames_v[stored], frames_acc[stored] = x[..., 0], v[..., 0], acc[:, 0]
        frames_winding[stored] = lanes.winding[:, 0]
        frame_steps[stored] = steps_done
        stored += 1
    keep = stored
    if status == Status.BLEW_UP:
        # The frames before the first bad state (those the first pass stored past it, up to its check, go).
        good = (
            (frame_steps[:stored] < steps_done)
            & np.isfinite(frames_x[:stored]).all(axis=(1, 2))
            & np.isfinite(frames_v[:stored]).all(axis=(1, 2))
        )
        keep = int(np.argmin(good)) if not good.all() else stored
    winding, reduced_phi, x = frames_winding[:keep], frames_x[:keep, 2], frames_x[:keep]
    if winding.any():
        # A copy: the frames are a RunState's too (with the angles as the engine keeps them).
        x = x.copy()
        x[:, 2] = join_turns(reduced_phi, winding)
    trajectory = Trajectory(
        time=t0 + (t_end - t0) * frame_steps[:keep] / n_steps,
        x=x,
        v=frames_v[:keep],
        load_work=frames_acc[:keep, 0],
        dissipated=frames_acc[:keep, 1],
        status=status,
        message=message,
        steps=steps_done,
        dt=dt,
        method=method.name,
        turns=None if turns is None else TurnLog(turns, int(lanes.lane_ints[CROSSINGS, 0]), *lanes.latest_turns(0, turns.made)),
        winding=winding,
        reduced_phi=reduced_phi,
        peak_spin=float(lanes.lanes[PEAK_SPIN, 0]),
    )
    if throw and status != Status.COMPLETED:
        raise IntegrationError(message, trajectory)
    return trajectory
