"""One damped, loaded simulation as a self-describing xarray Dataset.

Contract
--------
:func:`simulate` runs :func:`~cosserat_chain.numerics.dynamics.integrate` (or the
adaptive reference) and returns a Dataset with dimensions ``time`` and
``particle`` (-N..N): ``u, v, phi`` and their velocities ``u_dot, v_dot,
phi_dot``; the energies ``kinetic, potential, load_work, dissipated,
balance_error`` over time; and in the attributes every parameter, the model,
the loads, the method, dt, the status of the run and the package version.
"""

from __future__ import annotations

import json
import math
from typing import Any

import numpy as np
import xarray as xr

from .. import __version__
from ..analysis.energy import energy_budget
from ..loads import Loads, Schedule, moment_load
from ..models.base import Model, get_model
from ..numerics.adaptive import integrate_adaptive
from ..numerics.dynamics import IntegrationError, ProgressCallback, Trajectory, integrate, spin_hint
from ..params import ChainParams
from ..state import ROWS
from ..status import Status


def trajectory_dataset(params: ChainParams, model: str | Model, loads: Loads, trajectory: Trajectory) -> xr.Dataset:
    """Dataset of a trajectory with its energy budget and full metadata (see the module docstring)."""
    model = get_model(model)
    budget = energy_budget(params, model, trajectory)
    particle = np.arange(-params.N, params.N + 1)
    data: dict[str, Any] = {}
    for i, row in enumerate(ROWS):
        data[row] = (("time", "particle"), trajectory.x[:, i, :])
        data[f"{row}_dot"] = (("time", "particle"), trajectory.v[:, i, :])
    for name, values in budget.as_dict().items():
        data[name] = (("time",), values)
    ds = xr.Dataset(data, coords={"time": trajectory.time, "particle": particle})
    units = {"u": "h", "v": "h", "phi": "rad", "u_dot": "h/time", "v_dot": "h/time", "phi_dot": "rad/time"}
    for name, unit in units.items():
        ds[name].attrs["units"] = unit
    ds["potential"].attrs["long_name"] = "potential energy (NaN for the non-conservative sine model)"
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
#: Largest rotation of a particle in one step, |phi_dot| dt over the stored frames (rad), before a
#: run is flagged ``inaccurate``: beyond it a turn takes fewer than 2 pi / 0.5, about 13 steps.
ROTATION_PER_STEP = 0.5


def _check_accuracy(ds: xr.Dataset, load_hint: str = "") -> None:
    """Flag a completed run ``inaccurate`` when its energy balance or its rotation per step passes its tolerance.

    The balance is checked for the models with an energy (not the sine model, eq. (2), whose
    forces are not conservative: there the dissipated energy may exceed the load's work, at
    any step). The numbers are stored in the attributes ``balance_relative`` and
    ``rotation_per_step`` of every run, flagged or not.
    """
    dt = float(ds.attrs["dt"])  # NaN for the adaptive reference, which controls its own error: no rotation check
    rotation = float(np.nanmax(np.abs(ds.phi_dot.values), initial=0.0)) * dt
    scale = float((ds.kinetic + np.abs(ds.potential) + np.abs(ds.load_work) + ds.dissipated).max())  # NaN without a potential
    balance = float(np.abs(ds.balance_error).max()) / scale if scale > 0 else (0.0 if scale == 0 else math.nan)
    ds.attrs["balance_relative"] = balance
    ds.attrs["rotation_per_step"] = rotation
    if ds.attrs["status"] != Status.COMPLETED:
        return
    problems = []
    if np.isfinite(balance) and balance > BALANCE_TOLERANCE:
        problems.append(f"its energy balance is off by {balance:.2g} of the energy scale (tolerance {BALANCE_TOLERANCE:g})")
    if rotation > ROTATION_PER_STEP:
        problems.append(f"a particle turns by up to {rotation:.3g} rad per step (tolerance {ROTATION_PER_STEP:g})")
    if problems:
        ds.attrs["status"] = Status.INACCURATE
        remedy = (load_hint[:1].lower() + load_hint[1:]) or (
            f"use a smaller time step than dt={dt:.3g} (e.g. dt={dt / 4:.3g})" if np.isfinite(dt) else "tighten its tolerance (rtol)"
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

    Returns
    -------
    xarray.Dataset
        Its ``status`` attribute is ``completed``, ``inaccurate`` (completed, but its energy
        balance or its rotation per step is beyond :data:`BALANCE_TOLERANCE` or
        :data:`ROTATION_PER_STEP`), ``blew_up``, ``interrupted`` or ``failed``.
    """
    model = get_model(model)
    if not isinstance(loads, Loads):
        loads = moment_load(loads)
    if reference:
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
    _check_accuracy(dataset, spin_hint(params, loads, trajectory.dt) if np.isfinite(trajectory.dt) else "")
    if throw and not trajectory.ok:
        error = IntegrationError(trajectory.message, trajectory)
        error.dataset = dataset  # type: ignore[attr-defined]
        raise error
    return dataset
