"""``cosserat-chain rotate``: the localization run, one particle turned for many turns by a constant moment."""

from __future__ import annotations

import json
from pathlib import Path

import typer

from ..experiments.localization import localization_run
from ..io import write_dataset
from ..numerics.dynamics import IntegrationError
from .common import app, bar_callback, exit_on, fail, model_option, params_or_exit, progress_bar


def default_checkpoint(out: Path | None) -> Path | None:
    """OUT.checkpoint.nc next to ``--out``, or no checkpoint without ``--out``."""
    return None if out is None else out.with_name(f"{out.stem}.checkpoint.nc")


@app.command()
def rotate(
    model: str = model_option("nonlinear", "A model that supports full rotations (the linear model does not).", rotating=True),
    moment: float = typer.Option(..., help="Constant moment M on the loaded particle (rotation needs M above M_c, see `critical`)."),
    turns: int = typer.Option(1500, help="Stop when the loaded particle has made this many full turns."),
    t_max: float = typer.Option(100000.0, "--t-max", help="Stop at this time if the turns are not made by then."),
    particle: int = typer.Option(0, help="Loaded particle, in -N+1..N-1 (default the central one)."),
    dt: float | None = typer.Option(None, help="Time step (default 0.1 / highest linear frequency, rounded down to 10 bits)."),
    config: Path | None = typer.Option(None, help="TOML file with ChainParams fields."),
    out: Path | None = typer.Option(None, help="Write the per-particle diagnostics to this NetCDF file."),
    checkpoint: Path | None = typer.Option(None, help="Checkpoint file (default OUT.checkpoint.nc next to --out; none without --out)."),
    checkpoint_every: float = typer.Option(60.0, "--checkpoint-every", help="Seconds of wall time between checkpoints."),
    resume: bool = typer.Option(False, "--resume", help="Continue from the checkpoint (same parameters and settings)."),
    as_json: bool = typer.Option(False, "--json", help="Print the result as one JSON object."),
) -> None:
    """Turn one particle with a constant moment for many turns; report how localized the rotation stays.

    Exit status: 0 done (turns made or t_max reached), 2 bad input, 3 blow-up, 130 interrupted (saved).
    """
    params = params_or_exit(config)
    checkpoint = checkpoint if checkpoint is not None else default_checkpoint(out)
    if resume and checkpoint is None:
        fail("--resume needs --checkpoint or --out (whose checkpoint is OUT.checkpoint.nc)")
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
        )
    except ValueError as err:
        bar.close()
        fail(str(err))
    except IntegrationError as err:
        bar.close()
        fail(str(err), code=3)
    bar.close()
    if out is not None:
        write_dataset(result.to_dataset(), out)
    summary = result.as_dict()
    if as_json:
        typer.echo(json.dumps(summary))
    else:
        typer.echo(
            f"{summary['model']}, M={moment:g}: {summary['turns_completed']} turns by t={summary['t_end']:.6g}, "
            f"mean angular velocity {_number(summary['mean_angular_velocity'])}, {summary['classification']}; "
            f"others: max |phi| {summary['max_abs_phi_others']:.4g}, |v| {summary['max_abs_v_others']:.4g}, "
            f"|u| {summary['max_abs_u_others']:.4g}" + (f"; wrote {out}" if out else "")
        )
    exit_on(result.status, result.message)


def _number(value: float | None) -> str:
    return "n/a" if value is None else f"{value:.6g}"
