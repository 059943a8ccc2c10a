"""``cosserat-chain waves``: branch frequencies and the band gap of the infinite linear chain."""

from __future__ import annotations

import json
from pathlib import Path

import typer

from .common import app, fail, outputs_or_exit, params_or_exit, save_figure


@app.command()
def waves(
    config: Path | None = typer.Option(
        None, help="TOML file with ChainParams fields (E1, E2, h, a, b, m, j, gamma_u, gamma_v, gamma_phi, N)."
    ),
    as_json: bool = typer.Option(False, "--json", help="Print the result as one JSON object."),
    plot: Path | None = typer.Option(None, "--plot", help="Write the dispersion curves, gap shaded, to this PNG or SVG file."),
) -> None:
    """Frequencies of the longitudinal, transverse-acoustic and rotational-optical branches at q = 0 and q = pi, and the band gap."""
    from ..analysis.dispersion import BRANCHES, continuum_dispersion, dispersion, wave_summary

    outputs_or_exit({"--plot": plot}, {"--config": config})
    params = params_or_exit(config)
    if params.graded:
        fail(
            "--config: waves are those of the infinite uniform chain; a graded chain's factors (E1_factors, E2_factors, "
            "m_factors, j_factors) have no dispersion relation: leave them out"
        )
    summary = wave_summary(params)
    if plot is not None:
        from ..plots.theory import plot_dispersion  # matplotlib only when plotting

        save_figure(plot_dispersion(dispersion(params), summary, continuum_dispersion(params)), plot)
    if as_json:
        typer.echo(json.dumps({"params": params.model_dump(), **summary.as_dict(), "plot": str(plot) if plot else None}))
        return
    typer.echo(f"{'branch':<20}  {'omega(q=0)':>11}  {'omega(q=pi)':>11}  {'band':>21}")
    for name in BRANCHES:
        low, high = summary.bands[name]
        typer.echo(f"{name:<20}  {summary.at_zero[name]:>11.6g}  {summary.at_pi[name]:>11.6g}  [{low:>8.6g}, {high:>8.6g}]")
    if summary.gap is None:
        typer.echo("band gap (transverse/rotational): none, the two bands overlap")
    else:
        low, high = summary.gap
        typer.echo(f"band gap (transverse/rotational): {low:.6g} < omega < {high:.6g} (width {high - low:.6g})")
    complete = ", ".join(f"{low:.6g} < omega < {high:.6g}" for low, high in summary.complete_gaps) or "none (longitudinal waves fill it)"
    typer.echo(f"complete gap (all branches): {complete}")
    if plot is not None:
        typer.echo(f"wrote {plot}")
