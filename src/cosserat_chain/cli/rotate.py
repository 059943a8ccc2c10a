"""``cosserat-chain rotate``: the localization run, one particle turned for many turns by a constant moment."""

from __future__ import annotations

import json
import math
from pathlib import Path

import typer

from .common import (
    LARGER_STEP,
    app,
    bar_callback,
    checkpoint_or_exit,
    config_or_exit,
    exit_on,
    fail,
    model_option,
    number,
    progress_bar,
    save_dataset,
    spin_or_exit,
    step_for_checks,
    whole,
    work_or_exit,
)


@app.command()
def rotate(
    model: str = model_option("nonlinear", "A model that supports full rotations (the linear model does not).", rotating=True),
    moment: float = number(..., "Constant moment M on the loaded particle (rotation needs M above M_c, see `critical`)."),
    turns: int = whole(1500, at_least=1, help="Stop when the loaded particle has made this many full turns."),
    t_max: float = number(100000.0, "Stop at this time if the turns are not made by then (exit 4; --resume with a larger --t-max goes on).", above=0.0, flags=("--t-max",)),
    particle: int = typer.Option(0, help="Loaded particle, in -N+1..N-1 (default the central one)."),
    dt: float | None = number(None, "Time step (default 0.1 / highest linear frequency, rounded down to 10 bits).", above=0.0),
    load: list[str] | None = typer.Option(
        None, "--load", help="A constant load ROW:PARTICLE=VALUE acting throughout besides the moment; repeatable."
    ),
    config: Path | None = typer.Option(None, help="TOML file with ChainParams fields and [[loads]] tables (acting throughout)."),
    out: Path | None = typer.Option(None, help="Write the per-particle diagnostics to this NetCDF file."),
    checkpoint: Path | None = typer.Option(None, help="Checkpoint file (default OUT.checkpoint.nc next to --out; none without --out)."),
    checkpoint_every: float = number(60.0, "Seconds of wall time between checkpoints.", at_least=0.0, flags=("--checkpoint-every",)),
    resume: bool = typer.Option(False, "--resume", help="Continue from the checkpoint (same parameters and settings)."),
    force: bool = typer.Option(False, "--force", help="Start afresh even if the checkpoint exists (it is replaced)."),
    as_json: bool = typer.Option(False, "--json", help="Print the result as one JSON object."),
) -> None:
    """Turn one particle with a constant moment for many turns; report how localized the rotation stays.

    The classification compares the other particles' largest |phi|, |u| / h and |v| / h with the
    thresholds of a small motion; --json gives them as ``thresholds``.

    Exit status: 0 the turns made, 2 bad input, 3 blow-up, 4 --t-max reached first (saved; --resume with a larger
    --t-max goes on), 5 inaccurate (a smaller --dt is needed), 130 interrupted (saved).
    """
    from ..experiments.localization import localization_run
    from ..numerics.dynamics import IntegrationError

    checkpoint = checkpoint_or_exit(checkpoint, out, resume=resume, force=force, inputs={"--config": config})
    params, extra = config_or_exit(config, load)
    step = step_for_checks(params, model, dt)
    if step is not None:
        spin_or_exit(params, moment, step)
        # The turns take at least theta gamma_phi / |M| (the spin stays below |M| / gamma_phi) and
        # sqrt(2 j theta / |M|) (the spin-up from rest), whatever the chain does.
        drive = abs(moment) + sum(load.schedule.bound() for load in extra if load.row == "phi" and load.particle == particle)
        theta = 2 * math.pi * turns
        inertia = params.j * min(params.j_factors or (1.0,))
        least = min(t_max, max(theta * params.gamma_phi / drive, math.sqrt(2 * inertia * theta / drive))) if drive else t_max
        what = f"{least:.3g} time units of turning at dt={step:.3g}"
        larger = "a larger --dt" if dt is not None else LARGER_STEP
        work_or_exit(least / step, params.n_particles, what, f"fewer --turns, a smaller --t-max, or {larger}")
    bar = progress_bar(f"rotate {model}", "turn")
    try:
        result = localization_run(
            params,
            model,
            moment,
            turns=turns,
            t_max=t_max,
            particle=particle,
            dt=dt,
            checkpoint=checkpoint,
            checkpoint_every=checkpoint_every,
            resume=resume,
            progress=bar_callback(bar),
            loads=extra,
        )
    except ValueError as err:
        bar.close()
        fail(str(err))
    except IntegrationError as err:
        bar.close()
        fail(str(err), code=3)
    bar.finish(result.status)
    if out is not None:  # the Dataset (and xarray) only for a file: --json alone starts quickly
        save_dataset(result.to_dataset(), out)
    summary = result.as_dict()
    if as_json:
        typer.echo(json.dumps(summary))
    else:
        limits = summary["thresholds"]
        outside = summary["outside_model_validity"]
        typer.echo(
            f"{summary['model']}, M={moment:g}: {summary['turns_completed']} turns by t={summary['t_end']:.6g}, "
            f"mean angular velocity {_number(summary['mean_angular_velocity'])}, {summary['classification']}; "
            f"others: max |phi| {summary['max_abs_phi_others']:.4g} rad, |v| {summary['max_abs_v_others_over_h']:.4g} h, "
            f"|u| {summary['max_abs_u_others_over_h']:.4g} h (small: |phi| <= {limits['phi']:g} rad, |u|, |v| <= "
            f"{limits['v_over_h']:g} h)"
            + (f"; outside the {summary['model']} model's linear range: {', '.join(outside)}" if outside else "")
            + (f"; wrote {out}" if out else "")
        )
    exit_on(result.status, result.message)


def _number(value: float | None) -> str:
    return "n/a" if value is None else f"{value:.6g}"
