"""``cosserat-chain models``: the registered models, with their equations and what they support."""

from __future__ import annotations

import json

import typer

from .common import app


@app.command()
def models(as_json: bool = typer.Option(False, "--json", help="Print the list as one JSON object.")) -> None:
    """List the registered models: name (the --model value), equation, conservative, supports full rotations."""
    from ..models import available_models, get_model

    rows = [
        {"name": name, "equation": m.equation, "conservative": bool(m.conservative), "rotates": bool(m.rotates)}
        for name, m in ((name, get_model(name)) for name in available_models())
    ]
    if as_json:
        typer.echo(json.dumps({"models": rows}))
        return
    for row in rows:
        typer.echo(
            f"{row['name']:<12} {row['equation']:<10} {'conservative' if row['conservative'] else 'not conservative':<17} "
            f"{'rotates' if row['rotates'] else 'no full rotations'}"
        )
