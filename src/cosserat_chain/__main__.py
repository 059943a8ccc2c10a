"""``python -m cosserat_chain ...``: the command line, as ``cosserat-chain ...``."""

from .cli import app

app(prog_name="cosserat-chain")
