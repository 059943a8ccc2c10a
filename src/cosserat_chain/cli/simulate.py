"""``cosserat-chain simulate``: one damped simulation under a moment load."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import typer

from ..status import Status
from .common import (
    MethodName,
    app,
    bar_callback,
    exit_on,
    fail,
    finite_or_none,
    model_option,
    number,
    outputs_or_exit,
    params_or_exit,
    progress_bar,
    save_dataset,
)


@app.command()
def simulate(
    model: str = model_option("nonlinear", "Model."),
    moment: float = number(0.1, "Moment M on the loaded particle."),
    t_end: float = number(300.0, "Final time.", above=0.0, flags=("--t-end",)),
    dt: float | None = number(None, "Time step (default 0.1 / highest linear frequency).", above=0.0),
    particle: int = typer.Option(0, help="Loaded particle, in -N+1..N-1 (default the central one)."),
    ramp: float = number(0.0, "Raise the moment linearly over this time (0: applied at once).", at_least=0.0),
    method: MethodName = typer.Option(MethodName.verlet, help="verlet (order 2) or yoshida4 (order 4)."),
    frames: int = typer.Option(201, min=2, help="Number of stored states (>= 2: the start and the end)."),
    threads: int = typer.Option(1, min=1, help="Threads per step (worth it from ~10^4 particles)."),
    reference: bool = typer.Option(False, help="Use the adaptive DOP853 reference instead of the fixed step."),
    config: Path | None = typer.Option(
        None, help="TOML file with ChainParams fields (E1, E2, h, a, b, m, j, gamma_u, gamma_v, gamma_phi, N)."
    ),
    out: Path | None = typer.Option(None, help="Write the trajectory to this NetCDF file."),
    as_json: bool = typer.Option(False, "--json", help="Print the result as one JSON object."),
) -> None:
    """Run one damped simulation of the chain under a moment load."""
    from ..experiments.simulation import simulate as run_simulation
    from ..loads import Schedule, moment_load

    outputs_or_exit({"--out": out}, {"--config": config})
    params = params_or_exit(config)
    try:
        schedule = Schedule.ramp(moment, ramp) if ramp > 0 else Schedule.constant(moment)
        loads = moment_load(schedule, particle).validate(params)
    except ValueError as err:
        fail(str(err))
    bar = progress_bar(f"simulate {model}", "step")
    progress = bar_callback(bar)
    try:
        ds = run_simulation(
            params,
            model,
            loads,
            t_end=t_end,
            dt=dt,
            method=method.value,
            n_frames=frames,
            threads=threads,
            reference=reference,
            progress=progress,
        )
    except ValueError as err:
        bar.close()
        fail(str(err))
    bar.close()
    save_dataset(ds, out)
    status = ds.attrs["status"]
    if as_json:
        typer.echo(json.dumps(_summary(ds, params, model, t_end, out)))
    elif status == Status.COMPLETED:
        final = ds.isel(time=-1)
        typer.echo(
            f"{model}: t={float(final.time):g}, phi_0={float(final.phi.sel(particle=particle)):.6g} rad, "
            f"balance error {float(final.balance_error):.3g}" + (f"; wrote {out}" if out else "")
        )
    exit_on(status, ds.attrs["message"])


def _summary(ds, params, model: str, t_end: float, out: Path | None) -> dict[str, Any]:
    final = ds.isel(time=-1)
    energy = {name: finite_or_none(float(final[name])) for name in ("kinetic", "potential", "load_work", "dissipated", "balance_error")}
    return {
        "model": model,
        "params": params.model_dump(),
        "t_end": t_end,
        "t_reached": float(final.time),
        "dt": finite_or_none(float(ds.attrs["dt"])),
        "method": ds.attrs["method"],
        "steps": int(ds.attrs["steps"]),
        "status": ds.attrs["status"],
        "message": ds.attrs["message"],
        "final": {row: [float(x) for x in final[row].values] for row in ("u", "v", "phi")},
        "energy": energy,
        "accuracy": {
            "balance_relative": finite_or_none(float(ds.attrs["balance_relative"])),
            "rotation_per_step": finite_or_none(float(ds.attrs["rotation_per_step"])),
        },
        "out": str(out) if out else None,
    }
