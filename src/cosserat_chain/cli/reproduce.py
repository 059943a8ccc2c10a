"""``cosserat-chain reproduce``: every result of the paper, as a report a person reads."""

from __future__ import annotations

import json
from pathlib import Path

import typer

from .common import app, outputs_or_exit, params_or_exit, progress_bar


@app.command()
def reproduce(
    out: Path = typer.Option(Path("results/paper"), help="Folder for index.html, report.md, figures/, data/, summary.json."),
    config: Path | None = typer.Option(None, help="TOML file with ChainParams fields (default: the paper's chain)."),
    turns: int = typer.Option(1500, min=1, help="Full turns of the localization run (the paper: 1500)."),
    as_json: bool = typer.Option(False, "--json", help="Print summary.json (every number and the time of each stage)."),
) -> None:
    """Compute every result of the paper and write a self-contained report (index.html, report.md)."""
    from ..report import ReproduceSettings
    from ..report import reproduce as run_report

    outputs_or_exit({"--out": out}, {"--config": config}, folders=("--out",))
    params = params_or_exit(config)
    bar = progress_bar("reproduce", "stage")

    def progress(name: str, done: int, total: int) -> None:
        bar.total = total
        bar.set_postfix_str(name)
        bar.update(done - bar.n)

    try:
        report = run_report(out, params, ReproduceSettings(turns=turns), progress=progress)
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
