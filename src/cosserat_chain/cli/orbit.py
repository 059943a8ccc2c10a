"""``cosserat-chain orbit``: the rotating state as a periodic orbit (period, Floquet multipliers, continuation in M)."""

from __future__ import annotations

import json
from pathlib import Path

import typer

from .common import (
    app,
    bar_callback,
    fail,
    finite_or_none,
    model_option,
    number,
    outputs_or_exit,
    params_or_exit,
    progress_bar,
    save_dataset,
    save_figure,
    spin_or_exit,
    step_for_checks,
)
from .systems import (
    chain_only_or_exit,
    orbit_on_system,
    set_option,
    start_option,
    system_only_or_exit,
    system_option,
    vary_option,
    velocity_option,
)


@app.command()
def orbit(
    ctx: typer.Context,
    model: str = model_option("sine", "A model that supports full rotations (the linear model does not).", rotating=True),
    moment: float | None = number(None, "Moment M on the loaded particle (above M_c, or near an orbit; required without --system)."),
    turns: int | None = typer.Option(
        None,
        min=1,
        help="Turns of the loaded particle per period (default: the first of 1, 2, 3 whose orbit is stable, else the first found).",
    ),
    particle: int = typer.Option(0, help="Loaded particle (default the central one)."),
    down_to: float | None = number(None, "Continue the orbit down in M (with --system: in --vary, either way) to here, reporting where it ceases to exist.", flags=("--down-to",)),
    period_max: float = number(2000.0, "Continuation: a period beyond this counts as diverging.", above=0.0, flags=("--period-max",)),
    config: Path | None = typer.Option(None, help="TOML file with ChainParams fields (with --system: the system's [system] table)."),
    out: Path | None = typer.Option(None, help="Write the orbit (and the continuation) to this NetCDF file."),
    plot: Path | None = typer.Option(None, help="Draw the rotation characteristic (needs --down-to) to this PNG/SVG file."),
    as_json: bool = typer.Option(False, "--json", help="Print the result as one JSON object."),
    system: str | None = system_option(),
    sets: list[str] | None = set_option(),
    vary: str | None = vary_option("from its value down, or towards --down-to"),
    turn: list[str] | None = typer.Option(
        None, "--turn", metavar="COORDINATE=K", help="With --system: turns of an angle per period; repeatable (default every angle once)."
    ),
    start: str | None = start_option("the coordinates the settling run starts from (default 0)"),
    velocity: str | None = velocity_option("default: the drive at the start over the damping, on the angles"),
) -> None:
    """Find the rotating state as a limit cycle: period, mean angular velocity, Floquet multipliers, stability.

    With --system: a rotation of the system (from a settled run, then shooting), and with --vary its continuation.
    """
    if system is not None:
        chain_only_or_exit(ctx, ("config", "as_json", "out", "down_to", "period_max", "sets", "vary", "turn", "start", "velocity"))
        return orbit_on_system(
            system, config=config, sets=sets, vary=vary, turns=turn, down_to=down_to, period_max=period_max, start=start,
            velocity=velocity, out=out, as_json=as_json,
        )  # fmt: skip
    system_only_or_exit(ctx, ("sets", "vary", "turn", "start", "velocity"))
    if moment is None:
        fail("--moment is required: the moment M on the loaded particle (or give --system REF for a system's orbit)")
    from ..experiments.orbits import periodic_orbit
    from ..numerics.dynamics import IntegrationError
    from ..numerics.periodic import OrbitError

    if plot is not None and down_to is None:
        fail("--plot draws the continued branch: give --down-to as well")
    outputs_or_exit({"--out": out, "--plot": plot}, {"--config": config})
    params = params_or_exit(config)
    spin_or_exit(params, moment, step_for_checks(params, model, None), dt_option=False)
    bar = progress_bar(f"orbit {model}", "orbit")
    try:
        result = None
        if turns is None:
            turns, result = _turns_to_follow(params, model, moment, particle)
        if result is None or down_to is not None:
            # The search found the orbit without its continuation: computed again only to continue it.
            result = periodic_orbit(
                params, model, moment, turns=turns, particle=particle, down_to=down_to, period_max=period_max, progress=bar_callback(bar)
            )
    except ValueError as err:
        bar.close()
        fail(str(err))
    except (OrbitError, IntegrationError) as err:
        bar.close()
        fail(str(err), code=3)
    bar.finish(note=f"the branch ended: {result.branch.end}" if result.branch is not None else "")
    if out is not None:  # the Dataset (and xarray) only for a file: --json alone starts quickly
        save_dataset(result.to_dataset(), out)
    if plot is not None:
        from ..plots.orbits import rotation_characteristic_figure

        fig = rotation_characteristic_figure(branches=[result.branch], static_fold=result.static_fold, model=model)
        save_figure(fig, plot)
    if as_json:
        typer.echo(json.dumps({"params": params.model_dump(), **result.as_dict(), "static_fold": finite_or_none(result.static_fold)}))
        return
    o = result.orbit
    typer.echo(
        f"{model}: M = {o.moment:g}, {o.turns} turn(s) per period T = {o.period:.10g}, mean angular velocity {o.mean_angular_velocity:.10g}"
    )
    typer.echo(f"Floquet multipliers |mu|: {' '.join(f'{abs(m):.4g}' for m in o.multipliers)}")
    typer.echo(
        f"trivial multiplier {o.trivial_multiplier.real:.12g}; largest other |mu| = {o.max_multiplier:.6g}: {'stable' if o.stable else 'unstable'}"
    )
    if result.branch is not None:
        b = result.branch
        typer.echo(f"continued to M = {b.moment[-1]:.10g} ({len(b.orbits)} orbits): {b.message}; the orbit ends at M = {b.end_moment:.10g}")
        if b.stability_lost_at is not None:
            typer.echo(f"the orbit loses stability at M = {b.stability_lost_at:.6g}")
    typer.echo(f"static fold M_c = {result.static_fold:.15g}")


#: The turns per period tried when --turns is not given (states of the paper's chain repeat after up to 3).
AUTO_TURNS = (1, 2, 3)


def _turns_to_follow(params, model: str, moment: float, particle: int):
    """(k, its result) for the first k of :data:`AUTO_TURNS` whose orbit is stable, else the first with an orbit.

    Raises the last :class:`~cosserat_chain.numerics.periodic.OrbitError` when none converges
    (its message suggests what to try).
    """
    from ..experiments.orbits import periodic_orbit
    from ..numerics.periodic import OrbitError

    found, error = None, None
    for k in AUTO_TURNS:
        try:
            result = periodic_orbit(params, model, moment, turns=k, particle=particle)
        except OrbitError as err:
            error = err
            continue
        if result.orbit.stable:
            return k, result
        found = (k, result) if found is None else found
    if found is None:
        raise error
    return found
