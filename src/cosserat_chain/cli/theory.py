"""``cosserat-chain theory``: the continuum theory of Section 3 against the discrete chain, and the errata."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import typer

from .common import app, fail, params_or_exit


def parse_n_list(text: str) -> list[int]:
    """``"3,10,100"`` -> [3, 10, 100]; exits with an error naming the option for anything else."""
    try:
        values = [int(item) for item in text.split(",") if item.strip()]
    except ValueError:
        values = []
    if not values or any(n < 1 for n in values):
        fail(f"--n-list must be comma-separated integers N >= 1 (e.g. 3,10,100), got {text!r}")
    return values


@app.command()
def theory(
    config: Path | None = typer.Option(
        None, help="TOML file with ChainParams fields (E1, E2, h, a, b, m, j, gamma_u, gamma_v, gamma_phi, N)."
    ),
    n_list: str = typer.Option("3,10,100", "--n-list", help="Chain half-lengths N to compare (2N+1 particles), comma-separated."),
    as_json: bool = typer.Option(False, "--json", help="Print the result as one JSON object."),
) -> None:
    """Continuum phi_0/M (eq. 11) against the discrete linear chain per N, the residue (12), and the paper's errata."""
    import numpy as np

    from ..analysis.continuum import convergence, printed_D1
    from ..analysis.symbolic import errata

    params = params_or_exit(config)
    n_values = parse_n_list(n_list)
    try:
        table = convergence(params, n_values)
    except ValueError as err:
        fail(str(err))
    listed = errata(params)
    accurate = table.accurate
    order = table.order() if len(set(table.N[accurate])) >= 2 and all(table.relative_error[accurate] > 0) else None
    if as_json:
        typer.echo(json.dumps(_summary(params, table, order, listed)))
        return
    typer.echo(f"D1 = {params.D1:.6g} (derived; printed in Section 3: {printed_D1(params):.6g}), D2 = {params.D2:.6g}")
    typer.echo(f"{'N':>8}  {'continuum phi0/M':>17}  {'discrete phi0/M':>16}  {'(c - d) / d':>11}  {'residue (12)':>12}")
    for n, c, d, e, r, ok in zip(table.N, table.continuum, table.discrete, table.signed_error, table.residue, table.accurate):
        typer.echo(f"{n:>8d}  {c:>17.8g}  {d:>16.8g}  {e:>+11.3e}  {r:>12.3e}" + ("" if ok else "  (inaccurate)"))
    if np.any(np.diff(np.sign(table.signed_error[table.N > 1])) != 0):
        typer.echo("the continuum's error changes sign along this list: its 1/N fall holds only past the last change")
    for n, spread, condition in zip(table.N[~table.accurate], table.discrete_spread[~table.accurate], table.condition[~table.accurate]):
        typer.echo(
            f"N = {n}: the discrete value is inaccurate: two factorisations of K, each refined in extended precision, differ by {spread:.1e} (relative; "
            f"K's condition number {condition:.1e}, about N^4: the clamped chain's softest mode), so its error is not the continuum's"
        )
    if order is not None:
        typer.echo(f"observed order of the relative error: N^-{order:.3f}")
    typer.echo(f"\nerrata of the paper (docs/errata.md), evaluated for N = {params.N}:")
    for item in listed:
        typer.echo(f"  {item.number}. {item.where}: printed {item.printed}; derived {item.derived}.\n     {item.consequence}")


def _summary(params, table, order: float | None, listed) -> dict[str, Any]:
    from ..analysis.continuum import printed_D1

    columns = table.as_dict()
    return {
        "params": params.model_dump(),
        "D1": params.D1,
        "D2": params.D2,
        "printed_D1": printed_D1(params),
        "rows": [dict(zip(columns, values)) for values in zip(*columns.values())],
        "order": order,
        "errata": [item.as_dict() for item in listed],
    }
