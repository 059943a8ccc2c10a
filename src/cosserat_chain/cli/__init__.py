"""Command line ``cosserat-chain``: one module per command, all registered on one Typer ``app``."""

from . import (
    simulate,  # noqa: F401  (registers the command)
    theory,  # noqa: F401  (registers the command)
    waves,  # noqa: F401  (registers the command)
)
from .common import app

__all__ = ["app"]
