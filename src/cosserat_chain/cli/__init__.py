"""Command line ``cosserat-chain``: one module per command, all registered on one Typer ``app``."""

from . import (
    breathers,  # noqa: F401  (registers the command)
    diagram,  # noqa: F401  (registers the command)
    draw,  # noqa: F401  (registers draw and animate)
    export,  # noqa: F401  (registers the command)
    models,  # noqa: F401  (registers the command)
    orbit,  # noqa: F401  (registers the command)
    reproduce,  # noqa: F401  (registers the command)
    rotate,  # noqa: F401  (registers the command)
    simulate,  # noqa: F401  (registers the command)
    states,  # noqa: F401  (registers the command)
    statics,  # noqa: F401  (registers sweep and critical)
    study,  # noqa: F401  (registers the command)
    theory,  # noqa: F401  (registers the command)
    waves,  # noqa: F401  (registers the command)
)
from .common import app

__all__ = ["app"]
