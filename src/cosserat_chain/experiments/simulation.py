"""One damped, loaded simulation as a self-describing xarray Dataset.

Contract
--------
:func:`simulate` runs :func:`~cosserat_chain.numerics.dynamics.integrate` (or the
adaptive reference) and returns a Dataset with dimensions ``time`` and
``particle`` (-N..N): ``u, v, phi`` and their velocities ``u_dot, v_dot,
phi_dot``; the energies ``kinetic, potential, load_work, dissipated,
balance_error`` over time; and in the attributes every parameter, the model,
the loads, the method, dt, the status of the run and the package version.

Checkpoints. With ``checkpoint=PATH`` the fixed-step run writes, every
``checkpoint_every`` seconds of wall time (checked between the integrator's chunks
of steps), when it ends, on Ctrl-C and when an error stops it, a checkpoint
holding its state at the latest chunk boundary (x, v, the forces and the energy
sums), its step count, the frames stored so far and its settings, parameters and
loads, atomically (:mod:`cosserat_chain.experiments.checkpoint`, the mechanism the
localization run uses too). ``resume=True`` goes on from it
(:class:`~cosserat_chain.numerics.dynamics.RunState`) and returns bitwise the
Dataset of the uninterrupted run: every variable and the time axis (with another
``threads`` than the checkpoint's, the states bitwise and the energy sums to round-off). A checkpoint
written for other parameters, model, loads, method, dt, t0, t_end, n_frames or
stride, or from another start state, is refused with a ValueError naming what
differs; one that was edited, damaged or is not a simulation checkpoint too.
The checkpoint is kept when the run completes (as ``rotate`` keeps its own): resuming
it again gives the result without computing.
"""

from __future__ import annotations

import json
import logging
import math
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from .._version import __version__
from ..analysis.energy import energy_budget
from ..loads import Loads, Schedule, moment_load
from ..models.base import Model, get_model
from ..numerics.adaptive import integrate_adaptive
from ..numerics.dynamics import IntegrationError, ProgressCallback, RunState, Trajectory, integrate
from ..numerics.integrators import MAX_SPIN_PER_STEP, default_time_step, get_method, spin_hint
from ..params import ChainParams
from ..state import ROWS
from ..status import Status
from .checkpoint import CheckpointClock, open_checkpoint, params_settings, seal

if TYPE_CHECKING:  # xarray is imported where a Dataset is built or read: commands without file output start without it
    import xarray as xr

    from ..systems.base import System

log = logging.getLogger(__name__)

#: Version of the simulation checkpoint's layout; a checkpoint of another version is refused (2: the
#: velocities are the open sub-step's, as the run goes on from them, and the peak spin is kept).
CHECKPOINT_FORMAT = 2
#: The ``experiment`` attribute of a simulation checkpoint (a simulation's result has none).
CHECKPOINT_EXPERIMENT = "simulation_checkpoint"
#: The attributes a resumed run reads: its settings (compared one by one) and the run's state.
_STATE_ATTRIBUTES = (
    "params_json", "model", "loads_json", "method", "dt", "t0", "t_end", "n_frames", "stride",
    "steps", "n_steps", "stride_steps", "chunk_steps", "effective_dt",
)  # fmt: skip
#: The variables a resumed run reads: its frames so far and its state (real and finite in a checkpoint).
_STATE_VARIABLES = (
    *ROWS, *(f"{row}_dot" for row in ROWS), *(f"final_{row}" for row in ROWS), *(f"final_{row}_dot" for row in ROWS),
    *(f"final_force_{row}" for row in ROWS), "load_work", "dissipated", "final_load_work", "final_dissipated", "frame_step",
    "split_sums", "final_peak_spin",
)  # fmt: skip


def trajectory_dataset(params: ChainParams, model: str | Model, loads: Loads, trajectory: Trajectory) -> xr.Dataset:
    """Dataset of a trajectory with its energy budget and full metadata (see the module docstring)."""
    import xarray as xr

    model = get_model(model)
    budget = energy_budget(params, model, trajectory)
    particle = np.arange(-params.N, params.N + 1)
    data: dict[str, Any] = {}
    for i, row in enumerate(ROWS):
        data[row] = (("time", "particle"), trajectory.x[:, i, :])
        data[f"{row}_dot"] = (("time", "particle"), trajectory.v[:, i, :])
    if trajectory.winding is not None and trajectory.winding.any():
        # phi as a double loses bits beyond some turns: the whole turns and the rest keep them all.
        data["phi_winding"] = (("time", "particle"), trajectory.winding, {"long_name": "whole turns of the angle"})
        data["phi_reduced"] = (
            ("time", "particle"),
            trajectory.reduced_phi,
            {"long_name": "the angle less its whole turns: phi = phi_reduced + 2 pi phi_winding"},
        )
    for name, values in budget.as_dict().items():
        data[name] = (("time",), values)
    ds = xr.Dataset(data, coords={"time": trajectory.time, "particle": particle})
    ds["balance_error"].attrs["long_name"] = "K + P - W + D - (K0 + P0)"
    ds.attrs.update(run_attributes(params, model, loads))
    ds.attrs.update(
        {
            "method": trajectory.method,
            "dt": trajectory.dt,
            "steps": trajectory.steps,
            "status": trajectory.status,
            "message": trajectory.message,
        }
    )
    return ds


#: Largest |energy balance error| of a run, relative to its energy scale max_t (K + |P| + |W| + D),
#: before it is flagged ``inaccurate``: damped Verlet at the default step keeps it near 1e-4
#: on the paper's chain, and at 10 times that step it passes 1e-2.
BALANCE_TOLERANCE = 1e-2
#: Largest rotation of a particle in one step, |phi_dot| dt at any step boundary, stored or not (rad),
#: before a run is flagged ``inaccurate``: beyond it a turn takes fewer than 2 pi / 0.5, about 13
#: steps. The engine watches every step at this level (:data:`~cosserat_chain.numerics.integrators.MAX_SPIN_PER_STEP`).
ROTATION_PER_STEP = MAX_SPIN_PER_STEP
#: Largest viscous decay gamma dt / inertia of a degree of freedom in one step before a run is
#: flagged ``inaccurate``: the step applies the damping exactly but splits it from the forces, so
#: a degree of freedom whose velocity relaxes within a step (a light particle in a viscous medium)
#: drifts at the wrong speed, while the energy balance, kept by the split itself, stays closed.
DAMPING_PER_STEP = 0.5


def _check_accuracy(ds: xr.Dataset, load_hint: str = "", peak_spin: float = 0.0) -> None:
    """Flag a completed run ``inaccurate`` when its energy balance, its rotation or its damping per step passes its tolerance.

    The balance is checked for the models with an energy (not the sine model, eq. (2), whose
    forces are not conservative: there the dissipated energy may exceed the load's work, at
    any step). The rotation is |phi_dot| dt at every step boundary: the stored frames', and
    ``peak_spin``, which the compiled loop keeps from every step, stored or not
    (:attr:`~cosserat_chain.numerics.dynamics.Trajectory.peak_spin`), so that a spin between two
    frames is seen: the flag is exact; the number is the largest over the steps from the first
    beyond the tolerance on (below it, the frames' largest). The numbers are stored in the attributes ``balance_relative``,
    ``rotation_per_step`` and ``damping_per_step`` (:data:`DAMPING_PER_STEP`) of every run,
    flagged or not.
    """
    dt = float(ds.attrs["dt"])  # NaN for the adaptive reference, which controls its own error: no rotation check
    rotation = max(float(np.nanmax(np.abs(ds.phi_dot.values), initial=0.0)), peak_spin) * dt
    scale = float((ds.kinetic + np.abs(ds.potential) + np.abs(ds.load_work) + ds.dissipated).max())  # NaN without a potential
    balance = float(np.abs(ds.balance_error).max()) / scale if scale > 0 else (0.0 if scale == 0 else math.nan)
    params = ChainParams.model_validate_json(ds.attrs["params_json"])
    decay = float(np.max(np.asarray(params.damping)[:, None] / params.particle_inertia)) * dt if np.isfinite(dt) else 0.0
    ds.attrs["balance_relative"] = balance
    ds.attrs["rotation_per_step"] = rotation
    ds.attrs["damping_per_step"] = decay
    if ds.attrs["status"] != Status.COMPLETED:
        return
    problems = []
    if np.isfinite(balance) and balance > BALANCE_TOLERANCE:
        problems.append(f"its energy balance is off by {balance:.2g} of the energy scale (tolerance {BALANCE_TOLERANCE:g})")
    if rotation > ROTATION_PER_STEP:
        problems.append(f"a particle turns by up to {rotation:.3g} rad per step (tolerance {ROTATION_PER_STEP:g})")
    if decay > DAMPING_PER_STEP:
        problems.append(
            f"the damping takes a fraction gamma dt / inertia = {decay:.3g} of a velocity in one step (tolerance {DAMPING_PER_STEP:g})"
        )
    if problems:
        ds.attrs["status"] = Status.INACCURATE
        factor = 0.25 if decay <= DAMPING_PER_STEP else min(0.25, DAMPING_PER_STEP / (2.0 * decay))
        remedy = (load_hint[:1].lower() + load_hint[1:]) or (
            f"use a smaller time step than dt={dt:.3g} (e.g. dt={dt * factor:.3g})" if np.isfinite(dt) else "tighten its tolerance (rtol)"
        )
        ds.attrs["message"] = f"the run completed but is inaccurate: {'; '.join(problems)}; {remedy}"


def run_attributes(params: ChainParams, model: Model, loads: Loads) -> dict[str, Any]:
    """Attributes that make a result file self-describing: parameters, model, loads, version."""
    # Fields left at None (a uniform chain's factors) have no attribute: NetCDF stores no None.
    attrs: dict[str, Any] = {f"param_{name}": value for name, value in params.model_dump().items() if value is not None}
    attrs.update(
        {
            "params_json": json.dumps(params.model_dump()),
            "model": model.name,
            "model_equation": model.equation,
            "loads_json": json.dumps(loads.to_list()),
            "cosserat_chain_version": __version__,
        }
    )
    return attrs


def system_attributes(system: System, reference: str | None = None) -> dict[str, Any]:
    """Attributes that make a result file of a user's system self-describing: its parameters, name, how it was named
    (``reference``, e.g. ``takeno_peyrard`` or ``my_lattice.py:build``, where given), definition, angles and the version."""
    attrs: dict[str, Any] = {f"param_{name}": value for name, value in system.parameters.items()}
    attrs["system"] = system.name
    if reference is not None:
        attrs["system_reference"] = reference
    attrs.update(
        {
            "system_json": json.dumps(system.describe()),
            "angles": ",".join(name for name, a in zip(system.coordinates, system.angles, strict=True) if a),
            "cosserat_chain_version": __version__,
        }
    )
    return attrs


def simulate(
    params: ChainParams,
    model: str | Model = "nonlinear",
    loads: Loads | float | Schedule = 0.0,
    *,
    t_end: float,
    t0: float = 0.0,
    dt: float | None = None,
    method: str = "verlet",
    n_frames: int = 201,
    stride: int | None = None,
    x0: np.ndarray | None = None,
    v0: np.ndarray | None = None,
    threads: int = 1,
    reference: bool = False,
    rtol: float = 1e-10,
    progress: ProgressCallback | None = None,
    throw: bool = False,
    checkpoint: str | Path | None = None,
    checkpoint_every: float = 60.0,
    resume: bool = False,
) -> xr.Dataset:
    """Simulate the damped chain under loads and return the trajectory as a Dataset.

    Parameters
    ----------
    params : ChainParams
    model : {"nonlinear", "sine", "linear"} or Model
    loads : Loads, float or Schedule
        A number or a schedule is a moment on the central particle.
    t_end, t0, dt, method, n_frames, stride, x0, v0, threads, progress
        See :func:`cosserat_chain.numerics.dynamics.integrate`; a run that goes on from a
        stored frame takes that frame's time as ``t0`` (:func:`cosserat_chain.io.run_frame`).
    reference : bool
        Use the adaptive DOP853 reference (:func:`integrate_adaptive`) with
        tolerance ``rtol`` instead of the fixed-step integrator.
    throw : bool
        Raise :class:`IntegrationError` (with the partial Dataset as ``dataset``)
        if the run does not complete.
    checkpoint : path, optional
        NetCDF checkpoint file of the fixed-step run (module docstring), written atomically;
        not with ``reference``.
    checkpoint_every : float
        Seconds of wall time between checkpoints (>= 0; 0: after every chunk).
    resume : bool
        Go on from ``checkpoint`` (with the settings it was written for, ``x0`` and ``v0``
        included); if the file does not exist yet the run starts afresh.

    Returns
    -------
    xarray.Dataset
        Its ``status`` attribute is ``completed``, ``inaccurate`` (completed, but its energy
        balance or its rotation per step is beyond :data:`BALANCE_TOLERANCE` or
        :data:`ROTATION_PER_STEP`), ``blew_up``, ``interrupted`` or ``failed``.

    Raises
    ------
    ValueError
        For bad input, or a checkpoint that is not this run's (naming what differs).
    """
    model = get_model(model)
    if not isinstance(loads, Loads):
        loads = moment_load(loads)
    if checkpoint is not None or resume:
        if reference:
            raise ValueError(
                "checkpoints follow the fixed-step integrator's steps: the adaptive reference (reference=True, --reference) "
                "has none; leave out the checkpoint or the reference"
            )
        trajectory = _checkpointed_run(
            params, model, loads, checkpoint, checkpoint_every, resume,
            t_end=t_end, t0=t0, dt=dt, method=method, n_frames=n_frames, stride=stride,
            x0=x0, v0=v0, threads=threads, progress=progress,
        )  # fmt: skip
    elif reference:
        trajectory = integrate_adaptive(
            params, model, loads, t_end=t_end, t0=t0, x0=x0, v0=v0, n_frames=n_frames, rtol=rtol, atol=rtol * 1e-2
        )
    else:
        trajectory = integrate(
            params,
            model,
            loads,
            t_end=t_end,
            t0=t0,
            dt=dt,
            method=method,
            n_frames=n_frames,
            stride=stride,
            x0=x0,
            v0=v0,
            threads=threads,
            progress=progress,
        )
    dataset = trajectory_dataset(params, model, loads, trajectory)
    _check_accuracy(dataset, spin_hint(params, loads, trajectory.dt) if np.isfinite(trajectory.dt) else "", trajectory.peak_spin)
    if checkpoint is not None and trajectory.status == Status.INTERRUPTED:
        dataset.attrs["message"] += f"; resume from the checkpoint {str(checkpoint)!r}"
    if throw and not trajectory.ok:
        error = IntegrationError(trajectory.message, trajectory)
        error.dataset = dataset  # type: ignore[attr-defined]
        raise error
    return dataset


def _checkpointed_run(
    params: ChainParams,
    model: Model,
    loads: Loads,
    checkpoint: str | Path | None,
    checkpoint_every: float,
    resume: bool,
    *,
    t_end: float,
    t0: float,
    dt: float | None,
    method: str,
    n_frames: int,
    stride: int | None,
    x0: np.ndarray | None,
    v0: np.ndarray | None,
    threads: int,
    progress: ProgressCallback | None,
) -> Trajectory:
    """:func:`integrate` with a checkpoint written on its clock, at the end and on the way out of an error (module docstring)."""
    if resume and checkpoint is None:
        raise ValueError("resume=True needs a checkpoint file to resume from (checkpoint=None)")
    pacing = CheckpointClock(checkpoint, checkpoint_every)
    path = Path(checkpoint)
    settings = params_settings(params)
    settings.update(
        {
            "model": model.name,
            "loads_json": json.dumps(loads.to_list()),
            "method": get_method(method).name,
            # The step as asked (the default resolved): with t0 and t_end it fixes the run's steps.
            "dt": default_time_step(params, model) if dt is None else float(dt),
            "t0": float(t0),
            "t_end": float(t_end),
            "n_frames": int(n_frames),
            "stride": 0 if stride is None else int(stride),  # 0: chosen from n_frames
        }
    )
    start = None
    if resume and path.exists():
        ds = open_checkpoint(
            path, CHECKPOINT_EXPERIMENT, CHECKPOINT_FORMAT, settings, _STATE_ATTRIBUTES, kind="simulation",
            counts=("steps", "n_steps", "stride_steps", "chunk_steps"), total="n_steps", state_variables=_STATE_VARIABLES,
        )  # fmt: skip
        start = _run_state(ds)
        _check_frames(path, start)
        _check_start(path, start, params, x0, v0)
        x0 = v0 = None  # the checkpoint's first frame is the start state
        log.info("resuming %s from step %d of %d", path, start.steps, start.n_steps)
    elif resume:
        log.info("no checkpoint at %s yet: starting afresh", path)
    # The latest state at a chunk boundary, replaced by one assignment: what Ctrl-C or an error leaves.
    latest = start

    def keep(state: RunState) -> None:
        nonlocal latest
        latest = state
        if pacing.due:
            pacing.write(_checkpoint_dataset(state, params, model, loads, settings))

    try:
        trajectory = integrate(
            params, model, loads, t_end=t_end, t0=t0, dt=dt, method=method, n_frames=n_frames, stride=stride,
            x0=x0, v0=v0, threads=threads, progress=progress, resume=start, on_chunk=keep,
        )  # fmt: skip
    except BaseException:
        if latest is not None:
            try:
                pacing.write(_checkpoint_dataset(latest, params, model, loads, settings))
                log.warning("the run stopped with an error; the checkpoint %s holds step %d", path, latest.steps)
            except Exception:  # the error that stopped the run is the one to report
                log.exception("could not write the checkpoint %s", path)
        raise
    # integrate hands over a state at the start, so there is always one; after a blow-up it is the last good one.
    pacing.write(_checkpoint_dataset(latest, params, model, loads, settings))
    return trajectory


def _checkpoint_dataset(state: RunState, params: ChainParams, model: Model, loads: Loads, settings: dict[str, Any]) -> xr.Dataset:
    """The checkpoint of a run at ``state``: its frames so far (a readable partial run), its state and its settings."""
    import xarray as xr

    particle = np.arange(-params.N, params.N + 1)
    data: dict[str, Any] = {}
    for i, row in enumerate(ROWS):
        data[row] = (("time", "particle"), state.frames_x[:, i, :])
        data[f"{row}_dot"] = (("time", "particle"), state.frames_v[:, i, :])
        data[f"final_{row}"] = (("particle",), state.x[i])
        data[f"final_{row}_dot"] = (("particle",), state.v[i])
        data[f"final_force_{row}"] = (("particle",), state.f[i], {"long_name": f"force plus load on {row} at the state"})
    data["load_work"] = (("time",), state.frames_acc[:, 0])
    data["dissipated"] = (("time",), state.frames_acc[:, 1])
    data["final_load_work"] = ((), state.acc[0])
    data["final_dissipated"] = ((), state.acc[1])
    data["final_peak_spin"] = (
        (),
        state.peak_spin,
        {"long_name": "largest |phi_dot| beyond the rotation tolerance at a step so far (0: none)"},
    )
    data["frame_step"] = (("time",), state.frame_steps, {"long_name": "step of the stored frame"})
    data["split_sums"] = (
        ("split_sum", "energy_sum"),
        state.split_acc,
        {"long_name": "load work and dissipated energy: at the split over threads, then per block (none on one thread)"},
    )
    # The angles as the engine keeps them: phi less its whole turns, and the turns (exact at any winding).
    winding, frames_winding = state.windings()
    data["phi_winding"] = (("time", "particle"), frames_winding, {"long_name": "whole turns of phi: the angle is phi + 2 pi phi_winding"})
    data["final_phi_winding"] = (("particle",), winding, {"long_name": "whole turns of final_phi"})
    # The times as integrate computes them (informative: a resumed run counts steps).
    times = state.t0 + (settings["t_end"] - state.t0) * state.frame_steps / state.n_steps
    ds = xr.Dataset(data, coords={"time": times, "particle": particle})
    ds.attrs.update(run_attributes(params, model, loads))
    ds.attrs.update({key: value for key, value in settings.items() if not key.startswith("params.")})
    ds.attrs.update(
        {
            "steps": state.steps,
            "n_steps": state.n_steps,
            "stride_steps": state.stride,
            "chunk_steps": state.chunk,
            "effective_dt": state.dt,
        }
    )
    return seal(ds, CHECKPOINT_EXPERIMENT, CHECKPOINT_FORMAT, _STATE_ATTRIBUTES)


def _run_state(ds: xr.Dataset) -> RunState:
    """The :class:`RunState` a checkpoint holds (its settings already checked)."""
    attrs = ds.attrs

    def rows(template: str) -> np.ndarray:
        return np.ascontiguousarray(np.stack([ds[template.format(row)].values for row in ROWS], axis=-2))

    return RunState(
        steps=int(attrs["steps"]),
        n_steps=int(attrs["n_steps"]),
        stride=int(attrs["stride_steps"]),
        chunk=int(attrs["chunk_steps"]),
        t0=float(attrs["t0"]),
        dt=float(attrs["effective_dt"]),
        method=str(attrs["method"]),
        x=rows("final_{}"),
        v=rows("final_{}_dot"),
        f=rows("final_force_{}"),
        acc=np.array([float(ds["final_load_work"]), float(ds["final_dissipated"])]),
        frame_steps=np.asarray(ds["frame_step"].values, dtype=np.int64),
        frames_x=rows("{}"),
        frames_v=rows("{}_dot"),
        frames_acc=np.ascontiguousarray(np.stack([ds["load_work"].values, ds["dissipated"].values], axis=-1)),
        split_acc=np.ascontiguousarray(ds["split_sums"].values.reshape(-1, 2)),
        # (None in a checkpoint written before the angles had whole turns: none then.)
        winding=np.asarray(ds["final_phi_winding"].values, dtype=np.int64) if "final_phi_winding" in ds else None,
        frames_winding=np.ascontiguousarray(ds["phi_winding"].values, dtype=np.int64) if "phi_winding" in ds else None,
        peak_spin=float(ds["final_peak_spin"]),
    )


def _check_frames(path: Path, state: RunState) -> None:
    """Refuse a checkpoint whose stored frames are not every stride-th step up to its step count (frames cut or added).

    A resumed run appends its frames to these: with some missing it would end with fewer
    frames than asked and still look complete.
    """
    expected = list(range(0, state.steps + 1, max(1, state.stride)))
    allowed = [expected]
    if state.steps == state.n_steps and expected[-1] != state.n_steps:
        allowed.append([*expected, state.n_steps])  # a finished run's last step, stored whatever the stride
    if state.frame_steps.tolist() not in allowed:
        raise ValueError(
            f"checkpoint {str(path)!r} holds {state.frame_steps.size} frames, but a run at step {state.steps} with a frame "
            f"every {state.stride} steps has stored {len(expected)}: it is not resumed; start afresh (--force) "
            "or use another checkpoint file"
        )


def _check_start(path: Path, state: RunState, params: ChainParams, x0: np.ndarray | None, v0: np.ndarray | None) -> None:
    """Refuse a checkpoint that started from another state than this run's ``x0``, ``v0`` (rest when not given)."""
    for name, given, saved in (("x0", x0, state.frames_x[0]), ("v0", v0, state.frames_v[0])):
        expected = np.zeros((3, params.n_particles)) if given is None else np.asarray(given, dtype=float)
        if not np.array_equal(saved, expected):
            raise ValueError(
                f"checkpoint {str(path)!r} was written for a run from another start state ({name} differs): "
                "resume with the same start (--x0 and --at) or use another checkpoint file"
            )
