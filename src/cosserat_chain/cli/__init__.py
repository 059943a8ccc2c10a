"""Command line ``cosserat-chain``: one module per command, all registered on one Typer ``app``.

A command's module is imported when the command is needed (``_App.defer``): ``cosserat-chain
critical ...`` imports :mod:`.statics` and what it uses, not the other commands' modules.
"""

import os

# One BLAS thread unless the user asks for more: the package's dense linear algebra is small
# (a few hundred unknowns: monodromies, eigenvalues of short chains), where OpenBLAS's second
# thread spins and slows it (benchmarks/TIMINGS.md, "BLAS threads"). Set before NumPy loads.
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

from .common import app  # noqa: E402  (after the BLAS setting: common imports NumPy)

#: Each command and the module that registers it, in the order ``--help`` lists them.
COMMAND_MODULES = {
    "breathers": "breathers",
    "diagram": "diagram",
    "draw": "draw",
    "animate": "draw",
    "export": "export",
    "models": "models",
    "orbit": "orbit",
    "reproduce": "reproduce",
    "rotate": "rotate",
    "simulate": "simulate",
    "states": "states",
    "sweep": "statics",
    "critical": "statics",
    "study": "study",
    "theory": "theory",
    "waves": "waves",
}
app.defer(COMMAND_MODULES)

__all__ = ["COMMAND_MODULES", "app"]
