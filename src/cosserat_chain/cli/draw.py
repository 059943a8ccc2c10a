"""``cosserat-chain draw`` and ``cosserat-chain animate``: pictures of a run (paper, Figs. 1 and 3).

Both read a NetCDF run written by ``simulate --out``, or, given no file, simulate
first from ``--model/--moment/--t-end`` (and ``--config``).
"""

from __future__ import annotations

import math
from pathlib import Path

import typer

from ..io import FIGURE_FORMATS
from ..status import Status
from .common import app, bar_callback, fail, model_option, number, outputs_or_exit, params_or_exit, progress_bar, run_or_exit, whole

#: Stored frames of a simulation run only to be drawn: a cap that keeps memory small.
_MAX_SIMULATED_FRAMES = 20001

RUN_HELP = "NetCDF run written by `simulate --out`; without it, simulate first from --model/--moment/--t-end."


def _load_run(run: Path | None, model: str, moment: float, t_end: float, config: Path | None, n_frames: int):
    """The run to draw: read from ``run``, or simulated (an xarray Dataset)."""
    from ..experiments.simulation import simulate as run_simulation
    from ..loads import moment_load

    if run is not None:
        return run_or_exit(run)
    params = params_or_exit(config)
    bar = progress_bar(f"simulate {model}", "step")
    try:
        ds = run_simulation(params, model, moment_load(moment).validate(params), t_end=t_end, n_frames=n_frames, progress=bar_callback(bar))
    except ValueError as err:
        bar.close()
        fail(str(err))
    bar.finish(ds.attrs["status"])
    if ds.attrs["status"] != Status.COMPLETED:
        typer.secho(f"{ds.attrs['status']}: {ds.attrs['message']}; drawing what was computed", err=True, fg=typer.colors.YELLOW)
    return ds


def _parse_times(text: str) -> list[float]:
    times = []
    for item in text.split(","):
        try:
            times.append(float(item))
        except ValueError:
            fail(f"--times must be numbers separated by commas, got {item.strip()!r} in {text!r}")
        if not math.isfinite(times[-1]):
            fail(f"--times must be finite times of the run, got {item.strip()!r} in {text!r}")
    return times


@app.command()
def draw(
    run: Path | None = typer.Argument(None, help=RUN_HELP),
    out: Path = typer.Option(..., "--out", help="Picture to write: .png, .svg or .pdf."),
    times: str | None = typer.Option(None, "--times", help="Comma-separated times, one panel each (default: the last stored time)."),
    model: str = model_option("nonlinear", "Model of the simulation run when no RUN is given."),
    moment: float = number(0.1, "Moment on the central particle when no RUN is given."),
    t_end: float = number(300.0, "Final time of the simulation when no RUN is given.", above=0.0, flags=("--t-end",)),
    config: Path | None = typer.Option(None, help="TOML file with ChainParams fields, when no RUN is given."),
) -> None:
    """Draw the chain at chosen times of a run, one panel per time (paper, Fig. 3)."""
    outputs_or_exit({"--out": out}, {"RUN": run, "--config": config}, formats={"--out": FIGURE_FORMATS})
    from ..plots.chain import snapshot_figure  # matplotlib only when drawing: keeps every command quick to start

    ds = _load_run(run, model, moment, t_end, config, n_frames=201)
    chosen = _parse_times(times) if times is not None else [float(ds.time[-1])]
    try:
        figure = snapshot_figure(None, ds, chosen, path=out)
    except ValueError as err:
        fail(f"--times {times!r}: {err}" if times is not None else str(err))
    typer.echo(f"wrote {out} ({len(figure.axes)} snapshot{'s' if len(figure.axes) > 1 else ''} of {ds.attrs.get('model', 'the run')})")


@app.command()
def animate(
    run: Path | None = typer.Argument(None, help=RUN_HELP),
    out: Path = typer.Option(..., "--out", help="Animation to write: .gif, or .mp4 when imageio-ffmpeg is installed."),
    t_start: float | None = number(None, "Start of the window (default: the start of the run).", flags=("--t-start",)),
    t_stop: float | None = number(None, "End of the window (default: the end of the run).", flags=("--t-stop",)),
    frames: int = whole(200, at_least=1, flags=("--frames",), help="At most this many frames, evenly spread over the window."),
    fps: float = number(
        20.0,
        "Frames per second, 0.01 to 100 (a GIF times its frames in hundredths of a second).",
        at_least=0.01,
        at_most=100.0,
        flags=("--fps",),
    ),
    model: str = model_option("nonlinear", "Model of the simulation run when no RUN is given."),
    moment: float = number(0.1, "Moment on the central particle when no RUN is given."),
    t_end: float = number(300.0, "Final time of the simulation when no RUN is given.", above=0.0, flags=("--t-end",)),
    config: Path | None = typer.Option(None, help="TOML file with ChainParams fields, when no RUN is given."),
) -> None:
    """Animate a time window of a run as a GIF (or MP4), subsampled to at most --frames frames."""
    from ..plots.chain import ANIMATION_FORMATS

    outputs_or_exit({"--out": out}, {"RUN": run, "--config": config}, formats={"--out": ANIMATION_FORMATS})
    if t_start is not None and t_stop is not None and t_start > t_stop:
        fail(f"--t-start {t_start:g} is after --t-stop {t_stop:g}: the window is empty")
    from ..plots.chain import animate as write_animation
    from ..plots.chain import frame_indices

    # A simulation run only to be animated stores enough frames for the window to hold --frames of them.
    window = (t_stop if t_stop is not None else t_end) - (t_start if t_start is not None else 0.0)
    stored = min(_MAX_SIMULATED_FRAMES, math.ceil(frames * t_end / window) + 1) if window > 0 else 201
    ds = _load_run(run, model, moment, t_end, config, n_frames=max(stored, 201))
    try:
        count = frame_indices(ds.time.values, t_start, t_stop, frames).size
        with progress_bar("animate", "frame") as bar:
            write_animation(None, ds, out, t_start=t_start, t_stop=t_stop, max_frames=frames, fps=fps, progress=bar_callback(bar))
    except (ValueError, RuntimeError) as err:
        fail(str(err))
    typer.echo(f"wrote {out} ({count} frames)")
