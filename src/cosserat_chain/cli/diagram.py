"""``cosserat-chain diagram``: both edges of the hysteresis loop against one parameter of the chain."""

from __future__ import annotations

import json
from pathlib import Path

import typer

from ..status import Status
from .common import (
    app,
    bar_callback,
    exit_on,
    fail,
    model_option,
    number,
    outputs_or_exit,
    params_or_exit,
    progress_bar,
    save_dataset,
    save_figure,
    snic_line,
    whole,
)
from .systems import chain_only_or_exit, diagram_on_system, set_option, start_option, system_only_or_exit, system_option

#: Most values of one diagram: each is a continuation of the static branch and of a rotating orbit.
MAX_VALUES = 10_000


def _values(values: str | None, span: str | None) -> list[float]:
    """The values of --values V1,V2,... or --range START:STOP:NUM (exactly one of them, at most :data:`MAX_VALUES`)."""
    import numpy as np

    if (values is None) == (span is None):
        fail("give the values of --vary as --values V1,V2,... or as --range START:STOP:NUM (one of them)")
    try:
        if values is not None:
            out = [float(v) for v in values.split(",") if v.strip()]
        else:
            start, stop, num = span.split(":")
            count = int(num)
            if count < 1:
                raise ValueError
            if count > MAX_VALUES:
                fail(f"--range {span!r} asks for {count} values, more than {MAX_VALUES:,} (each is a continuation): a smaller NUM")
            # Rounded to 12 significant digits: linspace's 0.15000000000000002 would be the
            # row's value in the JSON and the file; the rounding moves a value by 1e-12 at most.
            out = [float(f"{v:.12g}") for v in np.linspace(float(start), float(stop), count)]
    except ValueError:
        fail(f"--values must read V1,V2,... and --range START:STOP:NUM (NUM >= 1), got {values if values is not None else span!r}")
    if not out or not all(np.isfinite(out)):
        fail(f"the values of --vary must be finite numbers, got {values if values is not None else span!r}")
    if len(out) > MAX_VALUES:
        fail(f"--values gives {len(out)} values, more than {MAX_VALUES:,} (each is a continuation): fewer values")
    return out


def _chains_or_exit(params, vary: str, values: list[float]) -> None:
    """Refuse (exit 2) before computing a value that makes no chain (``--vary a`` beyond h/2, a negative stiffness)."""
    from pydantic import ValidationError

    for value in values:
        try:
            params.replace(**{vary: value})
        except ValidationError as err:
            fail(f"--values: {vary} = {value!r} makes no chain: " + "; ".join(e["msg"].removeprefix("Value error, ") for e in err.errors()))


@app.command()
def diagram(
    ctx: typer.Context,
    model: str = model_option("sine", "A model that supports full rotations.", rotating=True),
    vary: str = typer.Option(
        ..., "--vary", help="The field of the chain to vary: E1, E2, h, a, b (or m, j, a gamma); with --system, a parameter of the system."
    ),
    values: str | None = typer.Option(None, "--values", help="Its values, V1,V2,... (in the order to follow them)."),
    span: str | None = typer.Option(None, "--range", help="Its values as START:STOP:NUM, evenly spaced."),
    turns: int = whole(3, at_least=1, help="The rotating orbit followed: the first stable one with 1..TURNS turns a period."),
    period_max: float = number(
        100.0, "A period beyond this counts as diverging (homoclinic or SNIC end).", above=0.0, flags=("--period-max",)
    ),
    follow: bool = typer.Option(
        False,
        "--follow",
        help="Follow each fold of cycles, period doubling or torus end from the value before (the lower edge's curve in (M, value)).",
    ),
    codim2: bool = typer.Option(
        False,
        "--codim2",
        help="Between two rows whose ends differ, follow one row's end to the other value and list the codimension-two points on the way (1:2 resonance, ...); with --system, each row's period doubling, torus or fold of cycles to the next value.",
    ),
    config: Path | None = typer.Option(
        None, help="TOML file with ChainParams fields (the other fields of the chain; with --system: its [system] table)."
    ),
    out: Path | None = typer.Option(None, help="Write the rows to this NetCDF file."),
    plot: Path | None = typer.Option(None, help="Draw the phase diagram in (parameter, M) to this PNG/SVG file."),
    as_json: bool = typer.Option(False, "--json", help="Print the rows as one JSON object."),
    system: str | None = system_option(),
    sets: list[str] | None = set_option(),
    drive: str | None = typer.Option(
        None, "--drive", metavar="NAME", help="With --system: the parameter whose rise starts the rotation (the chain's moment)."
    ),
    turn: list[str] | None = typer.Option(
        None, "--turn", metavar="COORDINATE=K", help="With --system: turns of an angle per period; repeatable (default every angle once)."
    ),
    start: str | None = start_option("where Newton starts for the equilibrium (default 0)"),
) -> None:
    """For each value: M_c (rotation starts, rising load), where rotation stops (falling load), how, and whether the loop is open.

    With --system: the same edges in the system's --drive, at each value of its parameter --vary."""
    if system is not None:
        chain_only_or_exit(
            ctx, ("vary", "values", "span", "period_max", "config", "out", "as_json", "sets", "drive", "turn", "start", "codim2")
        )
        return diagram_on_system(
            system, config=config, sets=sets, vary=vary, values=_values(values, span), drive=drive, turns=turn,
            period_max=period_max, start=start, out=out, as_json=as_json, codim2=codim2,
        )  # fmt: skip
    system_only_or_exit(ctx, ("sets", "drive", "turn", "start"))
    from ..experiments.diagram import state_diagram
    from ..numerics.dynamics import IntegrationError
    from ..numerics.fold_curve import FIELDS
    from ..numerics.periodic import OrbitError

    if vary not in FIELDS:
        fail(f"--vary: field must be one of {', '.join(FIELDS)} (a number of the chain), got {vary!r}")
    outputs_or_exit({"--out": out, "--plot": plot}, {"--config": config})
    params = params_or_exit(config)
    chosen = _values(values, span)
    _chains_or_exit(params, vary, chosen)
    bar = progress_bar(f"diagram {model}", "value")
    try:
        result = state_diagram(params, model, vary, chosen, turns=turns, period_max=period_max, follow=follow, codim2=codim2,
                               progress=bar_callback(bar))  # fmt: skip
    except ValueError as err:
        bar.close()
        fail(str(err))
    except (IntegrationError, OrbitError) as err:
        bar.close()
        fail(f"the diagram could not be computed: {err}", code=3)
    except KeyboardInterrupt:
        bar.close()
        exit_on(Status.INTERRUPTED, "the diagram's rows are written only once every value is done, so none is kept")
    bar.finish()
    save_dataset(result.to_dataset(), out)
    if plot is not None:
        from ..plots.diagram import diagram_figure

        save_figure(diagram_figure(result), plot)
    if as_json:
        typer.echo(json.dumps({"params": params.model_dump(), **result.as_dict()}))
        return
    if result.independent:
        typer.echo(f"(the statics do not read {vary}: M_c is the same at every value)")
    typer.echo(f"{vary:>12} {'M_c':>12} {'stops':>12}  end              hysteresis  found")
    for row in result.rows:
        fold = "none" if row.static_fold is None else f"{row.static_fold:.6g}"
        stops = "none" if row.rotation_stops is None else f"{row.rotation_stops:.6g}"
        typer.echo(f"{row.value:>12.6g} {fold:>12} {stops:>12}  {row.end:<16} {str(row.hysteresis):<11} {row.method}")
    for row in result.rows:
        # Where the followed orbit's fold is not the end of rotation: the orbits followed in turn, or the warning.
        if len(row.followed) > 1:
            steps = "; then ".join(
                f"a {o['turns']}-turn orbit (found at M = {o['found_at']:.6g}) to its {o['end']} at {o['rotation_stops']:.6g}"
                + (", below which a run keeps rotating" if o["below"] == "rotating" else "")
                for o in row.followed
            )
            typer.echo(f"{vary} = {row.value:g}: followed {steps}")
        if row.warning:
            typer.echo(f"warning: {vary} = {row.value:g}: {row.warning}")
    point = result.snic_point
    if point is not None:
        typer.echo(snic_line(point, vary, "M_c", "M_c", point.get("moment")))
    for entry in result.codim2_between or []:
        _echo_between(entry, vary)


def _echo_between(entry: dict, vary: str) -> None:
    """One line for each two rows whose ends differ: the codimension-two points between them, or why none is listed."""
    (low, high), (first, second) = entry["between"], entry["ends"]
    where = f"between {vary} = {low:g} ({first}) and {high:g} ({second})"
    points = "; ".join(
        f"a {p['name']} ({p['label']}) at {vary} = {p['value']:.10g} +- {p['accuracy']:.2g} (M = {p['moment']:.10g})"
        for p in entry["points"]
    )
    typer.echo(f"{where}: {points or 'no codimension-two point located'} [{entry['message']}]")
