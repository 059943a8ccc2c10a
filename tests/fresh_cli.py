"""The command line run in a fresh interpreter as ``python -m cosserat_chain ARGS`` runs it, once a session for each
``ARGS``: test_api.py's ``-m`` and version test and test_cli_startup.py's start-up tests read the same runs."""

from __future__ import annotations

import functools
import json
import os
import subprocess
import sys

# Run the command line as ``python -m cosserat_chain`` does; an ``atexit`` handler registered
# before the command (so run after every other) reports the modules loaded and the frozen objects.
_PROBE = """\
import atexit, gc, json, runpy, sys
atexit.register(lambda: print("PROBE", json.dumps({"modules": sorted(sys.modules), "frozen": gc.get_freeze_count()}), file=sys.stderr))
sys.argv = ["cosserat-chain", *sys.argv[1:]]
runpy.run_module("cosserat_chain", run_name="__main__")
"""


@functools.cache
def fresh_run(*args: str) -> tuple[subprocess.CompletedProcess, dict]:
    """The fresh interpreter's run of ``args`` (``COLUMNS=80``, one BLAS thread) and its probe: ``{"modules": the
    modules it loaded, "frozen": the objects frozen out of the teardown's collections}``."""
    env = dict(os.environ, COLUMNS="80", OMP_NUM_THREADS="1", OPENBLAS_NUM_THREADS="1")
    done = subprocess.run([sys.executable, "-c", _PROBE, *args], capture_output=True, text=True, env=env, timeout=300)
    line = next(line for line in done.stderr.splitlines() if line.startswith("PROBE "))
    return done, json.loads(line.removeprefix("PROBE "))
