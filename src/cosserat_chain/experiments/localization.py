"""The localization run (paper, end of Section 4): a constant moment turns one particle for many turns.

Contract
--------
:func:`localization_run` drives one particle with a constant moment M from rest
and integrates chunk by chunk (every step of a chunk kept, so maxima are exact
over the steps; the frames of a chunk are dropped once the streaming
:class:`~cosserat_chain.analysis.diagnostics.StreamingDiagnostics` have taken
them in) until the loaded particle has made ``turns`` full turns (the run stops
at the step that completes the last one) or the time reaches ``t_max``.

Checkpoints and resuming. Every ``checkpoint_every`` seconds of wall time, and
when the run ends or is interrupted, the state (x, v, step count), the
diagnostics and all settings are written atomically to the checkpoint (NetCDF,
the same content as :meth:`LocalizationResult.to_dataset`). ``resume=True``
continues from it and gives bitwise the same result as an uninterrupted run:
the time step is rounded down to a number with 10 significant bits
(:func:`grid_time_step`), so every time step * dt is exact, a run resumed at
any step takes exactly the steps the uninterrupted run takes, and the
compiled integrator recomputes the forces it carried. A checkpoint written for
other parameters, model, moment, loaded particle, time step, method or chunk
length is refused with a ValueError naming the field; ``turns`` and ``t_max``
may change (to extend a finished run). A checkpoint holds the SHA-256 of what a
resumed run reads (every variable and the state attributes): one that was edited
or damaged, truncated, or is not a checkpoint at all is refused with a ValueError
naming the file, never trusted.

Ctrl-C stops the run between or inside chunks; everything computed up to the
last finished step is kept in the returned result (status ``interrupted``) and
in the checkpoint. A blow-up raises
:class:`~cosserat_chain.numerics.dynamics.IntegrationError` asking for a
smaller time step.
"""

from __future__ import annotations

import json
import logging
import math
import time as clock
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from ..analysis.diagnostics import THRESHOLDS, StreamingDiagnostics
from ..loads import Loads, moment_load
from ..models.base import Model, get_model
from ..numerics.dynamics import IntegrationError, TurnWatch, integrate
from ..numerics.integrators import MAX_SPIN_PER_STEP, default_time_step, get_method
from ..params import ChainParams
from ..state import ROWS, column, zeros
from ..status import Status
from .checkpoint import CheckpointClock, open_checkpoint, params_settings, seal
from .simulation import DAMPING_PER_STEP, run_attributes

if TYPE_CHECKING:  # xarray is imported where a Dataset is built or read: commands without file output start without it
    import xarray as xr

log = logging.getLogger(__name__)

#: Version of the checkpoint layout; a checkpoint of another version is refused (2: the loads
#: besides the moment are part of what a resumed run must share).
CHECKPOINT_FORMAT = 2
#: Default simulated time per chunk (about 2400 steps of the paper's chain).
DEFAULT_CHUNK_TIME = 50.0
#: A chunk stores at most this many particle-steps, so its frames stay a few MB for any chain.
MAX_CHUNK_VALUES = 2**18
#: Significant bits kept in the time step (see :func:`grid_time_step`).
GRID_BITS = 10

ProgressCallback = Callable[[int, int], None]


def grid_time_step(dt: float) -> float:
    """Round a time step down to ``GRID_BITS`` significant bits (at most 0.1 % smaller).

    With such a step, k * dt is exact for every step count k < 2^42, and
    (k1 - k0) dt / (k1 - k0) == dt, so integrating between any two steps of the
    grid repeats the arithmetic of one uninterrupted run.

    Raises
    ------
    ValueError
        If dt is not finite and positive.
    """
    if not (math.isfinite(dt) and dt > 0):
        raise ValueError(f"dt must be a finite number > 0, got {dt!r}")
    unit = 2.0 ** (math.floor(math.log2(dt)) - GRID_BITS)
    return math.floor(dt / unit) * unit


@dataclass
class LocalizationResult:
    """Outcome of :func:`localization_run`.

    Attributes
    ----------
    params : ChainParams
    model : str
    moment : float
    particle : int
        The loaded particle.
    turns_requested : int
    t_max : float
    dt : float
        Time step (on the grid of :func:`grid_time_step`).
    method : str
    chunk_steps : int
        Steps per chunk.
    step : int
        Steps taken; the time reached is ``step * dt``.
    x, v : ndarray (3, 2N+1)
        State at that step.
    diagnostics : StreamingDiagnostics
    status : {"completed", "inaccurate", "time_limit", "interrupted"}
        ``inaccurate``: the turns were made, but the loaded particle turned by more than
        :data:`~cosserat_chain.numerics.integrators.MAX_SPIN_PER_STEP` radians per step on average,
        or its damping relaxes a velocity within a step (:data:`~.simulation.DAMPING_PER_STEP`).
        ``completed``: the loaded particle made the requested turns.
    message : str
    wall_time : float
        Seconds of computation, summed over resumed sessions.
    """

    params: ChainParams
    model: str
    moment: float
    particle: int
    turns_requested: int
    t_max: float
    dt: float
    method: str
    chunk_steps: int
    step: int
    x: np.ndarray
    v: np.ndarray
    diagnostics: StreamingDiagnostics
    status: str
    message: str
    wall_time: float
    #: Loads besides the moment, acting throughout (``localization_run(loads=...)``).
    extra_loads: Loads = field(default_factory=Loads)

    @property
    def t_end(self) -> float:
        """Time reached."""
        return self.step * self.dt

    def as_dict(self) -> dict[str, Any]:
        """JSON-ready summary: the keys of issue 5 (``model`` ... ``t_end``) first, then extras.

        ``max_abs_u_others`` and ``max_abs_v_others`` are in the units of h, ``..._over_h``
        divided by h; ``thresholds`` are those of the classification
        (:data:`~cosserat_chain.analysis.diagnostics.THRESHOLDS`: ``phi`` in rad, the
        others in units of h), ``large_motion`` the amplitudes of the others beyond them,
        ``outside_model_validity`` the rows in which the model is linear and went beyond them.
        """
        d = self.diagnostics
        n = self.params.N
        amplitudes = d.amplitudes_of_others
        return {
            "model": self.model,
            "moment": self.moment,
            "turns_completed": d.turns_completed,
            "mean_angular_velocity": _finite(d.mean_angular_velocity),
            "max_abs_phi_others": d.max_over_others(d.max_abs_phi),
            "max_abs_v_others": d.max_over_others(d.max_abs_v),
            "max_abs_u_others": d.max_over_others(d.max_abs_u),
            "classification": d.classification,
            "t_end": self.t_end,
            "moment_scale": self.params.moment_scale,
            "max_abs_u_others_over_h": amplitudes["u_over_h"],
            "max_abs_v_others_over_h": amplitudes["v_over_h"],
            "thresholds": dict(THRESHOLDS),
            "large_motion": list(d.large_motion),
            "outside_model_validity": list(d.outside_validity),
            "recent_angular_velocity": _finite(d.recent_angular_velocity),
            "participation_ratio": _finite(d.participation_ratio),
            "loaded_energy_share": _finite(float(d.mean_energy_share[d.column])),
            "winding": {str(k - n): int(w) for k, w in enumerate(d.winding)},
            "rotating_particles": [int(k - n) for k in np.flatnonzero(d.rotating)],
            "particle": self.particle,
            "turns_requested": self.turns_requested,
            "t_max": self.t_max,
            "dt": self.dt,
            "method": self.method,
            "steps": self.step,
            "status": self.status,
            "message": self.message,
            "wall_time": self.wall_time,
            "params": self.params.model_dump(),
        }

    def to_dataset(self) -> xr.Dataset:
        """Self-describing Dataset: per-particle diagnostics over ``particle``, the final state, and in
        the attributes the parameters, model, version, settings and summary (also a checkpoint)."""
        import xarray as xr

        d = self.diagnostics
        model = get_model(self.model)
        data: dict[str, Any] = {
            "winding": (("particle",), d.winding, {"long_name": "signed full turns trunc(theta / 2 pi) at t_end"}),
            "turns": (("particle",), d.turns, {"long_name": "largest number of full turns reached"}),
            "unwrapped_angle": (("particle",), d.unwrapped_angle, {"long_name": "phi(t_end) - phi(0)"}),
            "max_abs_u": (("particle",), d.max_abs_u, {"long_name": "max over the steps of |u|"}),
            "max_abs_v": (("particle",), d.max_abs_v, {"long_name": "max over the steps of |v|"}),
            "max_abs_phi": (("particle",), d.max_abs_phi, {"long_name": "max over the steps of |phi|"}),
            "last_turn_time": (("particle",), d.last_turn_time, {"long_name": "time of the latest new full turn"}),
            "mean_energy_share": (("particle",), d.mean_energy_share, {"long_name": "mean fraction of the chain's energy"}),
            "rotating": (("particle",), d.rotating.astype(np.int8), {"long_name": "1 if still rotating at t_end"}),
        }
        for i, row in enumerate(ROWS):
            data[f"final_{row}"] = (("particle",), self.x[i], {"long_name": f"{row} at t_end"})
            data[f"final_{row}_dot"] = (("particle",), self.v[i], {"long_name": f"d{row}/dt at t_end"})
        for name, (dims, values) in d.to_variables().items():
            data[name] = (dims, values, {"long_name": "streaming-diagnostics state (for resuming)"})
        ds = xr.Dataset(data, coords={"particle": np.arange(-self.params.N, self.params.N + 1)})
        ds.attrs.update(run_attributes(self.params, model, Loads([*moment_load(self.moment, self.particle), *self.extra_loads])))
        summary = self.as_dict()
        # NetCDF attributes hold numbers and strings: the thresholds one by one, the lists joined.
        summary.update({f"threshold_{name}": value for name, value in summary.pop("thresholds").items()})
        summary.update({key: ",".join(summary[key]) for key in ("large_motion", "outside_model_validity")})
        summary = {key: value for key, value in summary.items() if key not in ("winding", "rotating_particles", "params")}
        ds.attrs.update({key: ("" if value is None else value) for key, value in summary.items()})
        ds.attrs["chunk_steps"] = self.chunk_steps
        return seal(ds, "localization_run", CHECKPOINT_FORMAT, _STATE_ATTRIBUTES)


#: The attributes a resumed run reads besides its settings (those are compared one by one).
_STATE_ATTRIBUTES = ("steps", "wall_time", "params_json", "model", "moment", "particle", "dt", "method", "chunk_steps", "loads_json")


def _finite(value: float) -> float | None:
    return float(value) if math.isfinite(value) else None


def localization_run(
    params: ChainParams,
    model: str | Model,
    moment: float,
    *,
    turns: int,
    t_max: float,
    particle: int = 0,
    dt: float | None = None,
    method: str = "verlet",
    checkpoint: str | Path | None = None,
    checkpoint_every: float = 60.0,
    resume: bool = False,
    progress: ProgressCallback | None = None,
    chunk_time: float = DEFAULT_CHUNK_TIME,
    loads: Loads | None = None,
) -> LocalizationResult:
    """Turn one particle with a constant moment until it has made ``turns`` full turns (module docstring).

    Parameters
    ----------
    params : ChainParams
    model : {"nonlinear", "sine", "linear"} or Model
    moment : float
        Constant moment M on the loaded particle from t = 0 (rest); above the
        critical moment M_c (:func:`~cosserat_chain.numerics.continuation.locate_fold`)
        the particle keeps rotating.
    turns : int
        Stop at the step that completes this many full turns of the loaded particle (>= 1).
    t_max : float
        Stop at the first step at or after this time (> 0).
    particle : int
        Loaded particle, in -N+1..N-1.
    loads : Loads, optional
        Loads besides the moment, acting throughout (a force along the chain, a drive);
        part of what a resumed run must share with its checkpoint.
    dt : float, optional
        Largest time step; default the model's :func:`~cosserat_chain.numerics.integrators.default_time_step`,
        rounded down by :func:`grid_time_step`.
    method : {"verlet", "yoshida4"}
    checkpoint : path, optional
        NetCDF checkpoint file (written atomically).
    checkpoint_every : float
        Seconds of wall time between checkpoints (>= 0; 0: after every chunk).
    resume : bool
        Continue from ``checkpoint``; if the file does not exist yet the run starts from rest.
    progress : callable(turns_done, turns_requested), optional
        Called after every chunk.
    chunk_time : float
        Simulated time per chunk (> 0); capped so that a chunk stores at most
        ``MAX_CHUNK_VALUES`` particle-steps.

    Returns
    -------
    LocalizationResult

    Raises
    ------
    ValueError
        For bad input, or a checkpoint written for other parameters or settings.
    IntegrationError
        If the run blows up (use a smaller ``dt``).
    """
    started = clock.perf_counter()
    model = get_model(model)
    method = get_method(method).name
    if not math.isfinite(moment):
        raise ValueError(f"moment must be finite, got {moment!r}")
    moment = float(moment)
    if not (isinstance(turns, (int, np.integer)) and not isinstance(turns, bool) and turns >= 1):
        raise ValueError(f"turns must be an integer >= 1, got {turns!r}")
    if not (math.isfinite(t_max) and t_max > 0):
        raise ValueError(f"t_max must be a finite number > 0, got {t_max!r}")
    pacing = CheckpointClock(checkpoint, checkpoint_every)
    if not (math.isfinite(chunk_time) and chunk_time > 0):
        raise ValueError(f"chunk_time must be a finite number > 0, got {chunk_time!r}")
    if resume and checkpoint is None:
        raise ValueError("resume=True needs a checkpoint file to resume from (checkpoint=None)")
    extra = Loads(loads or ())
    loads = Loads([*moment_load(moment, particle), *extra]).validate(params)
    col = column(params, particle)
    direction = 1.0 if moment >= 0 else -1.0
    dt = grid_time_step(default_time_step(params, model) if dt is None else float(dt))
    chunk_steps = max(1, min(round(chunk_time / dt), MAX_CHUNK_VALUES // params.n_particles))
    max_steps = max(1, math.ceil(t_max / dt - 1e-9))
    checkpoint = None if checkpoint is None else Path(checkpoint)

    def result(step, x, v, diagnostics, status, message, wall_before) -> LocalizationResult:
        return LocalizationResult(
            params,
            model.name,
            moment,
            particle,
            int(turns),
            float(t_max),
            dt,
            method,
            chunk_steps,
            step,
            x,
            v,
            diagnostics,
            status,
            message,
            wall_before + clock.perf_counter() - started,
            extra,
        )

    wall_before = 0.0
    if resume and checkpoint.exists():
        expected = params_settings(params)
        expected.update(
            {"model": model.name, "moment": moment, "particle": particle, "dt": dt, "method": method, "chunk_steps": chunk_steps,
             "loads_json": json.dumps(loads.to_list())}
        )  # fmt: skip
        diagnostics = (*StreamingDiagnostics._PER_PARTICLE, "turn_times", *StreamingDiagnostics._SCALARS)
        ds = open_checkpoint(
            checkpoint, "localization_run", CHECKPOINT_FORMAT, expected, _STATE_ATTRIBUTES, kind="localization-run",
            state_variables=[f"final_{row}{rate}" for row in ROWS for rate in ("", "_dot")], variables=[f"diag_{n}" for n in diagnostics],
        )  # fmt: skip
        step = int(ds.attrs["steps"])
        x = np.ascontiguousarray(np.stack([ds[f"final_{row}"].values for row in ROWS]))
        v = np.ascontiguousarray(np.stack([ds[f"final_{row}_dot"].values for row in ROWS]))
        diagnostics = StreamingDiagnostics.from_variables(params, model, particle, ds, direction)
        wall_before = float(ds.attrs["wall_time"])
        log.info("resuming %s from step %d (t=%g)", checkpoint, step, step * dt)
    else:
        if resume:
            log.info("no checkpoint at %s yet: starting from rest", checkpoint)
        step, x, v = 0, zeros(params), zeros(params)
        diagnostics = StreamingDiagnostics(params, model, particle, x, v, direction=direction)
    # One object holds the latest consistent state, replaced by a single assignment,
    # so that Ctrl-C anywhere leaves a state that can be saved.
    state = result(step, x, v, diagnostics, Status.INTERRUPTED, "", wall_before)
    try:
        while state.diagnostics.turns_completed < turns and state.step < max_steps:
            first = state.step
            stop = min((first // chunk_steps + 1) * chunk_steps, max_steps)
            run = integrate(
                params,
                model,
                loads,
                t0=first * dt,
                t_end=stop * dt,
                dt=dt,
                x0=state.x,
                v0=state.v,
                method=method,
                stride=1,
                # Stop at the step that completes the last turn.
                turns=TurnWatch(
                    particle,
                    direction,
                    phi_start=state.diagnostics.angle_start[col],
                    made=state.diagnostics.turns_completed,
                    keep=1,
                    stop_after=turns,
                ),
            )
            if run.status == Status.BLEW_UP:
                raise IntegrationError(f"localization run ({model.name}, M={moment:g}): {run.message}", run)
            frames = run.x.shape[0]
            times = (first + np.arange(frames)) * dt
            updated = _copy(state.diagnostics)
            updated.update(times, run.x[:frames], run.v[:frames])
            state = result(
                first + frames - 1,
                np.ascontiguousarray(run.x[frames - 1]),
                np.ascontiguousarray(run.v[frames - 1]),
                updated,
                Status.INTERRUPTED,
                "",
                wall_before,
            )
            if run.status == Status.INTERRUPTED:
                break
            if progress is not None:
                progress(updated.turns_completed, turns)
            if pacing.due:
                pacing.write(state.to_dataset())
    except KeyboardInterrupt:
        log.warning("interrupted at t=%g; saving what was computed", state.t_end)
    final = state
    spin = final.diagnostics.mean_angular_velocity
    if final.diagnostics.turns_completed >= turns and math.isfinite(spin) and abs(spin) * dt > MAX_SPIN_PER_STEP:
        # The turns were made, but a turn took fewer than 2 pi / MAX_SPIN_PER_STEP steps: not resolved.
        final.status = Status.INACCURATE
        final.message = (
            f"{final.diagnostics.turns_completed} full turns at t={final.t_end:.6g}, but at {abs(spin) * dt:.3g} rad per step "
            f"(mean angular velocity {spin:.4g}, dt={dt:g}; tolerance {MAX_SPIN_PER_STEP:g}): inaccurate; "
            f"use dt <= {MAX_SPIN_PER_STEP / abs(spin):.3g}"
        )
    elif final.diagnostics.turns_completed >= turns and (decay := float(np.max(np.asarray(params.damping)[:, None] / params.particle_inertia)) * dt) > DAMPING_PER_STEP:
        # A velocity relaxes within a step: the split damping moves the particle at the wrong speed.
        final.status = Status.INACCURATE
        final.message = (
            f"{final.diagnostics.turns_completed} full turns at t={final.t_end:.6g}, but the damping takes a fraction "
            f"gamma dt / inertia = {decay:.3g} of a velocity in one step (tolerance {DAMPING_PER_STEP:g}): inaccurate; "
            f"use dt <= {dt * DAMPING_PER_STEP / decay:.3g}"
        )
    elif final.diagnostics.turns_completed >= turns:
        final.status, final.message = Status.COMPLETED, f"{final.diagnostics.turns_completed} full turns at t={final.t_end:.6g}"
    elif final.step >= max_steps:
        final.status = Status.TIME_LIMIT
        final.message = (
            f"t_max={t_max:g} reached after {final.diagnostics.turns_completed} of {turns} turns; resume with a larger t_max to go on"
        )
    else:
        final.message = f"interrupted at t={final.t_end:.6g} after {final.diagnostics.turns_completed} of {turns} turns" + (
            f"; resume from {str(checkpoint)!r}" if checkpoint is not None else ""
        )
    final.wall_time = wall_before + clock.perf_counter() - started
    if checkpoint is not None:
        pacing.write(final.to_dataset())
    return final


def _copy(diagnostics: StreamingDiagnostics) -> StreamingDiagnostics:
    """An independent copy, so that a chunk is taken in all or not at all."""
    return StreamingDiagnostics.from_variables(
        diagnostics.params, diagnostics.model, diagnostics.particle, diagnostics.to_variables(), diagnostics.direction
    )
