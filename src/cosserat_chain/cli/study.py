"""``cosserat-chain study SPEC.toml``: a parameter study on Dask, saved as cells finish, resumable."""

from __future__ import annotations

import json
import math
from pathlib import Path

import typer

from ..io import read_config
from ..status import Status
from .common import app, bar_callback, exit_on, fail, outputs_or_exit, progress_bar, save_dataset, save_figure, whole

#: Most cells of one study: its spec, grid and file are built whole before the first cell runs.
MAX_CELLS = 1_000_000


def _cells_or_exit(mapping: object, source: Path) -> None:
    """Refuse (exit 2) a grid of more than :data:`MAX_CELLS` cells before it is built (``num = 10^9`` took minutes, then memory)."""
    if not isinstance(mapping, dict) or not isinstance(mapping.get("parameters"), dict):
        return  # the spec's own validation names what is wrong
    counts = {}
    for name, values in mapping["parameters"].items():
        if isinstance(values, dict) and isinstance(values.get("num"), int) and not isinstance(values.get("num"), bool):
            counts[name] = values["num"]
        elif isinstance(values, list):
            counts[name] = len(values)
    models = mapping.get("models")
    n_models = len(models) if isinstance(models, list) and models else 1
    total = math.prod(max(count, 1) for count in counts.values()) * n_models
    if total > MAX_CELLS:
        sizes = " x ".join(f"{name} {count}" for name, count in counts.items())
        fail(
            f"SPEC {str(source)!r} asks for {total:.3g} cells ({sizes}, times {n_models} model(s)), more than {MAX_CELLS:,}: fewer values per field"
        )


@app.command()
def study(
    spec_file: Path = typer.Argument(..., help="TOML study spec (see docs/studies.md)."),
    out: Path | None = typer.Option(None, help="NetCDF file written as cells finish; re-running resumes from it."),
    scheduler: str | None = typer.Option(None, help="Address of an existing Dask scheduler (default: an embedded LocalCluster)."),
    workers: int | None = whole(None, at_least=1, help="Worker processes of the embedded LocalCluster (default: one per core)."),
    chunk: int | None = whole(
        None,
        at_least=1,
        help="Cells per Dask task (cells of one N and model, relaxed as one batch; default: 4 tasks per worker, at most 256 cells).",
    ),
    load: list[str] | None = typer.Option(
        None,
        "--load",
        help="A constant load ROW:PARTICLE=VALUE acting on every cell besides the moment (relaxation quantities); repeatable.",
    ),
    plot: Path | None = typer.Option(None, help="Draw maps (two swept fields) or lines (one) of the quantities to this PNG/SVG file."),
    dashboard: bool = typer.Option(
        False,
        "--dashboard",
        help="Serve the embedded cluster's Dask dashboard on 127.0.0.1 and print its address (default: no dashboard).",
    ),
    as_json: bool = typer.Option(False, "--json", help="Print a summary and every cell's values as one JSON object."),
) -> None:
    """Compute the quantities of a parameter study over every cell of its grid, in chunks of cells per Dask task."""
    from ..experiments.study import spec_from_mapping
    from ..loads import parse_load
    from ..study_runner import ClusterError, run_study

    outputs_or_exit({"--out": out, "--plot": plot}, {"SPEC": spec_file})
    try:
        mapping = read_config(spec_file)
        _cells_or_exit(mapping, spec_file)
        if load:
            # --load adds tables to the spec's loads (its numbers stay the moments of mean_angular_velocity).
            tables = [{"row": p.row, "particle": p.particle, "value": p.schedule.values[0]} for p in map(parse_load, load)]
            entries = mapping.get("loads", [])
            mapping["loads"] = [*entries, *tables] if isinstance(entries, list) else entries
        spec = spec_from_mapping(mapping, source=str(spec_file))
        if scheduler is None:  # the embedded cluster's cells run on this machine: its memory, checked before any runs
            spec.check_memory()
    except ValueError as err:
        fail(str(err))
    bar = progress_bar("study", "cell")
    try:
        run = run_study(
            spec, out=out, scheduler=scheduler, workers=workers, chunk=chunk, progress=bar_callback(bar),
            dashboard=(lambda address: typer.echo(f"Dask dashboard: {address}", err=True)) if dashboard else None,
        )  # fmt: skip
    except (ValueError, ClusterError) as err:
        bar.close()
        fail(str(err))
    bar.finish(run.status)
    if run.unsaved:  # the file could not be written (a full disk): try again, else keep the cells in a fallback file (exit 3)
        save_dataset(run.dataset, out)
    if plot is not None:
        from ..plots.study import study_figure

        save_figure(study_figure(run.dataset), plot)
    ds = run.dataset
    if as_json:
        cells = []
        for index, model, fields in spec.cells():
            where = {**dict(zip(spec.axes(), index)), "model": spec.models.index(model)}
            values = {name: _plain(ds[name][where].values) for name in spec.quantities}
            cells.append(
                {
                    "params": {k: fields[k] for k in spec.parameters},
                    "model": model,
                    **values,
                    "error": str(ds["error"][where].values) or None,
                }
            )
        summary = {"cells": len(cells), "computed": run.computed, "skipped": run.skipped, "failed": run.failed, "completed": run.completed}
        extra = {"extra_loads": spec.extra().to_list()}
        typer.echo(json.dumps({**summary, **extra, "out": str(out) if out else None, "results": cells}))
    else:
        typer.echo(
            f"study: {run.computed} cells computed, {run.skipped} read back, {run.failed} failed" + (f"; wrote {out}" if out else "")
        )
    if not run.completed:
        exit_on(
            run.status, f"{run.message}; the finished cells are saved" + ("" if out is None else "; run the same command again to resume")
        )
    if run.failed:
        done = run.computed + run.skipped
        first = next(str(e) for e in ds["error"].values.ravel() if str(e))
        message = f"{run.failed} of {done} cells failed (their error is in the file and the JSON; the first: {first})"
        if run.failed == done:
            exit_on(Status.FAILED, f"no cell succeeded: {message}")
        typer.secho(f"warning: {message}", err=True, fg=typer.colors.YELLOW)


def _plain(value):
    """JSON value of a cell's quantity: a number (null for NaN) or a list of them."""
    import numpy as np

    if value.ndim == 0:
        return None if not np.isfinite(value) else float(value)
    return [None if not np.isfinite(v) else float(v) for v in value]
