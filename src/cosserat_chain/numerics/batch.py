"""Many independent chains of the same length integrated together on the engine.

Contract
--------
A *batch* is B chains of the same number of particles (same model), each with its
own parameters (coefficients, inertia, damping, time step), its own start state
and its own constant moment on the same particle. :func:`integrate_batch`
advances every member to ``t_end``: members that take the same number of steps
share the SIMD lanes of one compiled loop (:mod:`.engine`, batch innermost), so
a grid of loads on one chain runs as one vectorised batch. Every member's states
equal its single run's (:func:`~cosserat_chain.numerics.dynamics.integrate`) to
round-off: the same step count and step and the same forces to the last bit, but
the batch's kick-drift loop is compiled apart from the chain's and the two may
round differently (measured: up to a few 1e-17 after a thousand steps; often equal).

With ``threads=2`` the members are split into two halves that run on the two
cores without synchronising per step (``PERFORMANCE-NOTES.md``: threads only at
coarse grain). The batched relaxation protocol is in :mod:`.relaxation`.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from ..loads import moment_load
from ..models.base import Model, get_model
from ..params import ChainParams
from ..state import column
from ..status import Status
from .engine import BLEW_UP, STATUS_BLEW_UP, Lanes, check_members, member_steps, per_member, run_parts, split, stack_states
from .integrators import Method, get_method


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
    load_work, dissipated : ndarray (B,)
        Work done by the moment and energy removed by viscosity up to each member's
        last step (the engine's exact sums, as :class:`~.dynamics.Trajectory` has them;
        equal to the single run's to round-off: the batch sums its columns in another order).
    """

    x: np.ndarray
    v: np.ndarray
    dt: np.ndarray
    steps: np.ndarray
    record_time: np.ndarray
    record_angle: np.ndarray
    status: list[str]
    load_work: np.ndarray
    dissipated: np.ndarray


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
    """Integrate B chains from t = 0 to ``t_end`` under constant moments.

    Each member's states equal those of ``integrate(params_list[i], model,
    moment_load(moments[i], particle), t_end=t_end, dt=dt[i], ...)`` to round-off (module docstring).

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
        Split the members over this many cores.

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
    params = check_members(params_list)
    size = len(params)
    model = get_model(model)
    method = get_method(method)
    moments = per_member(moments, size, "moments")
    loads = moment_load(1.0, particle).validate(params[0])
    col = column(params[0], particle)
    x0 = stack_states(params, x0, "x0")
    v0 = stack_states(params, v0, "v0")
    requested = member_steps(params, dt, method, model)
    n_steps = np.maximum(1, np.ceil(t_end / requested - 1e-9)).astype(np.int64)
    strides = np.maximum(1, np.ceil(n_steps / (n_records - 1)).astype(np.int64))
    counts = n_steps // strides + 1 + (n_steps % strides != 0)
    out_x, out_v = x0.copy(), v0.copy()
    steps = np.zeros(size, dtype=np.int64)
    sums = np.zeros((2, size))
    record = np.full((size, int(counts.max())), np.nan)
    status = [Status.COMPLETED] * size

    def run_group(members: np.ndarray) -> None:
        """Members with the same step count, in one compiled loop until done (members that blow up leave)."""
        count, stride, total = int(counts[members[0]]), int(strides[members[0]]), int(n_steps[members[0]])
        lanes = Lanes(
            model, [params[b] for b in members], method, t_end / n_steps[members], loads, moments[None, members], x0[members], v0[members]
        )
        lanes.follow_turns(col, 0)
        lanes.evaluate_forces()
        frames_acc = np.zeros((count, 2, members.size))
        angles = np.zeros((count, members.size))
        angles[0] = record[members, 0] = lanes.unwrapped_angles()[col]
        done, stored = 0, 1
        while True:
            no_states = np.zeros((0, 3, lanes.n, lanes.size))
            frames = (no_states, no_states, frames_acc, angles, np.zeros((0, lanes.n, lanes.size), dtype=np.int64))
            code, taken, written = lanes.advance(total - done, done, stride, frames=frames, frame0=stored)
            done += taken
            if done % stride != 0 and code != STATUS_BLEW_UP:
                angles[stored + written] = lanes.unwrapped_angles()[col]
                written += 1
            record[members, stored : stored + written] = angles[stored : stored + written].T
            stored += written
            out_x[members] = np.moveaxis(lanes.x, -1, 0)
            out_x[members, 2] = lanes.unwrapped_angles().T
            out_v[members] = np.moveaxis(lanes.v, -1, 0)
            sums[:, members] = lanes.acc
            steps[members] = done
            if code != STATUS_BLEW_UP:
                return
            bad = lanes.lane_ints[BLEW_UP] == 1
            for b in members[bad]:
                status[b] = Status.BLEW_UP
                record[b, stored:] = np.nan
            if bad.all():
                return
            keep = np.flatnonzero(~bad)
            members, lanes = members[keep], lanes.select(keep)
            frames_acc, angles = frames_acc[..., keep].copy(), angles[:, keep].copy()
            if done == total:
                return

    groups = [np.flatnonzero(n_steps == value) for value in np.unique(n_steps)]
    run_parts(run_group, [part for group in groups for part in split(group, threads, params)], threads)
    slot = np.arange(record.shape[1])
    stored_steps = np.minimum(strides[:, None] * slot, n_steps[:, None])
    record_time = np.where(slot < counts[:, None], t_end * stored_steps / n_steps[:, None], np.nan)
    return BatchRun(
        x=out_x,
        v=out_v,
        dt=t_end / n_steps,
        steps=steps,
        record_time=np.where(np.isnan(record), np.nan, record_time),
        record_angle=record,
        status=status,
        load_work=sums[0],
        dissipated=sums[1],
    )
