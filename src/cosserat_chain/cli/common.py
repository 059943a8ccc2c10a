"""The Typer application and what every command shares: option types, errors, progress bars.

The CLI is thin by design: options -> ChainParams and loads -> experiment -> NetCDF / JSON.
Each command lives in its own module of this package and registers itself on ``app``.
"""

from __future__ import annotations

import math
import sys
from enum import Enum
from pathlib import Path
from typing import NoReturn

import typer
from pydantic import ValidationError
from tqdm import tqdm

from ..io import load_params
from ..params import ChainParams

app = typer.Typer(add_completion=False, help="Discrete Cosserat chains of finite-size particles.", no_args_is_help=True)


class ModelName(str, Enum):
    nonlinear = "nonlinear"
    sine = "sine"
    linear = "linear"


class MethodName(str, Enum):
    verlet = "verlet"
    yoshida4 = "yoshida4"


def finite_or_none(value: float) -> float | None:
    """JSON has no NaN or infinity: map them to null."""
    return float(value) if math.isfinite(value) else None


def fail(message: str, code: int = 2) -> NoReturn:
    """Print ``error: message`` on stderr and exit with ``code`` (2: bad input)."""
    typer.secho(f"error: {message}", err=True, fg=typer.colors.RED)
    raise typer.Exit(code)


def params_or_exit(config: Path | None) -> ChainParams:
    """Read the TOML config (or the paper's defaults); a bad field exits with its name and value."""
    try:
        return load_params(config)
    except ValidationError as err:
        fail("invalid parameters:\n" + "\n".join(f"  {'.'.join(map(str, e['loc'])) or 'params'}: {e['msg']} (got {e.get('input')!r})" for e in err.errors()))
    except ValueError as err:
        fail(str(err))


def progress_bar(desc: str, unit: str) -> tqdm:
    """A tqdm bar on stderr, shown only on a terminal (``disable=None``)."""
    return tqdm(total=None, unit=unit, unit_scale=True, desc=desc, disable=None, file=sys.stderr)


def bar_callback(bar: tqdm):
    """Turn a bar into the library's ``progress(done, total)`` callback."""

    def progress(done: float, total: float) -> None:
        bar.total = total
        bar.update(done - bar.n)

    return progress


def save_figure(fig, path: Path) -> None:
    """Write a matplotlib figure to ``path`` (format from the extension), creating its folder."""
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=150)


@app.callback()
def main() -> None:
    """Simulate chains of rectangular particles that translate and rotate (nonlinear, sine and linear Cosserat models)."""
