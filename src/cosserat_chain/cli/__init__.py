"""Command line ``cosserat-chain``: one module per command, all registered on one Typer ``app``."""

import os

# One BLAS thread unless the user asks for more: the package's dense linear algebra is small
# (a few hundred unknowns: monodromies, eigenvalues of short chains), where OpenBLAS's second
# thread spins and slows it (benchmarks/TIMINGS.md, "BLAS threads"). Set before NumPy loads.
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

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
