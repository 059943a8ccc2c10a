"""``cosserat-chain breathers``: one-site roto-breathers of the undamped chain, followed in the frequency."""

from __future__ import annotations

import json
from pathlib import Path

import typer

from .common import app, bar_callback, fail, model_option, number, outputs_or_exit, params_or_exit, progress_bar, save_dataset, save_figure
from .systems import chain_only_or_exit, set_option, system_only_or_exit, system_option


@app.command()
def breathers(
    ctx: typer.Context,
    model: str = model_option("sine", "A model that supports full rotations (the linear model does not).", rotating=True),
    omega: float = number(..., "Frequency Omega of the rotating particle (its mean angular velocity) to start from.", above=0.0),
    to: float | None = number(None, "Follow the family in Omega to here (default: the start alone).", above=0.0),
    steps: int = typer.Option(11, min=2, help="Frequencies from --omega to --to, both included."),
    turns: int = typer.Option(1, min=1, help="Turns of the rotating particle per period (T = 2 pi turns / Omega)."),
    particle: int = typer.Option(0, help="The rotating particle (default the central one)."),
    partner: int | None = typer.Option(None, help="A second rotor (a two-site roto-breather), turning as often as the first."),
    counter: bool = typer.Option(False, "--counter", help="The partner turns against the first rotor (default: with it)."),
    lifetimes: int = typer.Option(
        0, min=0, help="Run each orbit, its velocities perturbed by 1e-8, for up to this many periods: its lifetime (0: none)."
    ),
    config: Path | None = typer.Option(None, help="TOML file with ChainParams fields; its viscosities are set to 0 (undamped)."),
    out: Path | None = typer.Option(None, help="Write the family to this NetCDF file."),
    plot: Path | None = typer.Option(None, help="Draw the family against the bands' harmonics to this PNG/SVG file."),
    as_json: bool = typer.Option(False, "--json", help="Print the result as one JSON object."),
    system: str | None = system_option(),
    sets: list[str] | None = set_option(),
    coupling: str = typer.Option(
        "C", "--coupling", metavar="NAME", help="With --system: the coupling, continued from 0 (the anti-continuum limit) to its value."
    ),
) -> None:
    """Roto-breathers: one particle rotating, the rest oscillating, undamped; Newton from the anti-continuum limit, Floquet multipliers, resonances with the bands.

    With --system: the system's family (its angles counted from the central one by --particle and --partner), continued in --coupling from 0, then in the frequency to --to; --out writes it to NetCDF.
    """
    if system is not None:
        from .system_breathers import breathers_on_system

        chain_only_or_exit(ctx, ("omega", "to", "turns", "particle", "partner", "counter", "config", "out", "as_json", "sets", "coupling"))
        return breathers_on_system(
            system, config=config, sets=sets, omega=omega, to=to, turns=turns, particle=particle, partner=partner, counter=counter,
            coupling=coupling, out=out, as_json=as_json,
        )  # fmt: skip
    system_only_or_exit(ctx, ("sets", "coupling"))
    import numpy as np

    from ..experiments.breathers import lifetime, roto_breather_family
    from ..numerics.periodic import OrbitError

    if counter and partner is None:
        fail("--counter sets the partner's direction: give --partner as well")
    outputs_or_exit({"--out": out, "--plot": plot}, {"--config": config})
    params = params_or_exit(config).replace(gamma_u=0.0, gamma_v=0.0, gamma_phi=0.0)
    omegas = np.array([omega]) if to is None else np.linspace(omega, to, steps)
    bar = progress_bar(f"breathers {model}", "orbit")
    try:
        partners = None if partner is None else {partner: -turns if counter else turns}
        result = roto_breather_family(params, model, omegas, turns=turns, particle=particle, partners=partners, progress=bar_callback(bar))
    except ValueError as err:
        bar.close()
        fail(str(err))
    except OrbitError as err:
        bar.close()
        fail(str(err), code=3)
    family = result.family
    bar.finish(note="" if family.complete else "the family ended early")
    lives = [lifetime(o, max_periods=lifetimes).as_dict() for o in family.orbits] if lifetimes else None
    if out is not None:  # the Dataset (and xarray) only for a file: --json alone starts quickly
        save_dataset(result.to_dataset(), out)
    if plot is not None:
        from ..plots.breathers import breather_family_figure

        save_figure(breather_family_figure(result), plot)
    summary = result.as_dict()
    if lives is not None:
        summary["lifetimes"] = lives
    if as_json:
        typer.echo(json.dumps({"params": params.model_dump(), **summary}))
        return
    also = "" if partner is None else f" and {partner} ({'against' if counter else 'with'} it)"
    typer.echo(f"{model}: {len(family.orbits)} of {len(omegas)} roto-breathers, {turns} turn(s) per period, particle {particle}{also}")
    typer.echo(f"{'omega':>10}  {'energy':>12}  {'rotor rate':>11}  {'tail':>10}  {'max |mu|':>10}  stable  harmonics in a band")
    for i, o in enumerate(family.orbits):
        energy = "-" if o.energy is None else f"{o.energy:.8g}"
        inside = ", ".join(f"{h['harmonic']}x in {h['band']}" for h in summary["resonant_harmonics"][i]) or "none"
        typer.echo(
            f"{o.omega:>10.6g}  {energy:>12}  {summary['rotor_velocity'][i]:>11.6g}  {summary['tail_amplitude'][i]:>10.3g}  "
            f"{o.max_multiplier:>10.6g}  {'yes' if o.stable else 'no':>6}  {inside}"
        )
        if lives is not None:
            life = lives[i]["lifetime_periods"]
            typer.echo(f"{'':>10}  lifetime: {'beyond ' + str(lifetimes) if life is None else life} periods")
    for r in result.resonances:
        typer.echo(f"resonance: {r.harmonic} x Omega = {r.edge_frequency:.6g} ({r.band} band {r.edge}) at Omega = {r.omega:.6g}")
    if not family.complete:
        typer.echo(family.message)
