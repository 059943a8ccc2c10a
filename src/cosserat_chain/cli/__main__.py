"""``python -m cosserat_chain.cli``: the same as the ``cosserat-chain`` command."""

from . import app

app()
