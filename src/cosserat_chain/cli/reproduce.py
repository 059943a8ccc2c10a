"""``cosserat-chain reproduce``: every result of the paper, as a report a person reads."""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import typer

from ..io import params_from_mapping, read_config
from .common import app, fail, outputs_or_exit, progress_bar, whole

#: The table of a ``--config`` file that holds the report's settings (``ReproduceSettings`` fields).
SETTINGS_TABLE = "reproduce"


@app.command()
def reproduce(
    out: Path = typer.Option(Path("results/paper"), help="Folder for index.html, report.md, figures/, data/, summary.json."),
    config: Path | None = typer.Option(
        None,
        help="TOML file with ChainParams fields (default: the paper's chain) and, in a [reproduce] table, the report's "
        "settings (ReproduceSettings fields: m_max, dm, rotation_moment, turns, orbit_moment, n_list, reading, ...).",
    ),
    turns: int | None = whole(None, at_least=1, help="Full turns of the localization run (default 1500, the paper's)."),
    reading: str | None = typer.Option(
        None,
        help="Which reading of the paper's 'seven particles' sets N: clamped-ends-among-seven (N = 3, the default chain) or "
        "seven-between-walls (N = 4); overrides the [reproduce] table's reading. The report computes both.",
    ),
    as_json: bool = typer.Option(False, "--json", help="Print summary.json (every number and the time of each stage)."),
) -> None:
    """Compute every result of the paper and write a self-contained report (index.html, report.md)."""
    from ..io import OutputError
    from ..report import READINGS, ReproduceSettings, chain_for_reading, check_folder, reading_error, settings_from_mapping
    from ..report import reproduce as run_report

    outputs_or_exit({"--out": out}, {"--config": config}, folders=("--out",))
    try:
        check_folder(out)
    except OutputError as err:
        fail(str(err))
    error = reading_error(reading)
    if error:
        fail(f"--{error}")
    mapping, settings = {}, ReproduceSettings()
    if config is not None:
        try:
            mapping = read_config(config)
            table = mapping.pop(SETTINGS_TABLE, {})
            if not isinstance(table, dict):
                raise ValueError(f"[{SETTINGS_TABLE}] in {str(config)!r} must be a table of ReproduceSettings fields")
            settings = settings_from_mapping(table, source=f"[{SETTINGS_TABLE}] of {str(config)!r}")
        except ValueError as err:  # pydantic's ValidationError included: it names the field and the value
            fail(str(err))
    if reading is not None:
        settings = dataclasses.replace(settings, reading=reading)
    # A reading fills in N where the config gives none, and must agree with one it gives.
    if settings.reading is not None and "N" not in mapping:
        mapping["N"] = READINGS[settings.reading]
    try:
        params = chain_for_reading(settings, params_from_mapping(mapping, source=str(config)))
    except ValueError as err:  # pydantic's ValidationError included
        fail(str(err))
    if turns is not None:
        settings = dataclasses.replace(settings, turns=turns)
    # Every stage would fail alike on a chain no memory holds (each with its traceback): refused here, as every command does.
    from ..experiments.critical import critical_memory
    from ..memory import MemoryEstimateError, require

    try:
        require(
            critical_memory(params, "nonlinear", near_singular=False),
            f"the report's static branch of {params.n_particles} particles (N={params.N})",
            "a shorter chain",
        )
    except MemoryEstimateError as err:
        fail(f"--config: {err}")
    bar = progress_bar("reproduce", "stage")

    def progress(name: str, done: int, total: int) -> None:
        bar.total = total
        bar.set_postfix_str(name, refresh=False)
        bar.update(done - bar.n)
        bar.refresh()

    try:
        report = run_report(out, params, settings, progress=progress)
    except (OSError, OutputError) as err:  # a full disk: the stages' files written so far stay
        reason = f"{err.strerror}: {err.filename}" if isinstance(err, OSError) and err.filename else str(err)
        fail(f"could not write the report in {str(out)!r} ({reason}); the files written before stay", code=3)
    finally:
        bar.close()
    if as_json:
        typer.echo(json.dumps(report.summary, default=str))
    else:
        for section in report.sections:
            typer.echo(f"{section.seconds:7.1f} s  {'FAILED ' if section.error else ''}{section.title}")
        typer.echo(f"wrote {out / 'index.html'} and {out / 'report.md'}")
    if report.failed:
        typer.secho(f"{len(report.failed)} stage(s) failed; their errors are in the report", err=True, fg=typer.colors.YELLOW)
        raise typer.Exit(1)
