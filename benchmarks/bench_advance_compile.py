"""Compile time of the engine's loop (``numerics.engine.advance``) with an empty Numba cache, and of what it compiles inside.

Run from the repository root::

    python benchmarks/bench_advance_compile.py --src /tmp/old/src --src /tmp/new/src --rounds 2

Each round runs every tree in turn (interleaved), each in a fresh process with a fresh Numba
cache folder: the models, loads and state modules are imported first (their kernels are not
counted), then the engine, whose loop has an explicit signature and so compiles at import. A
listener on Numba's ``numba:compile`` event takes the process CPU time of every compilation
(inclusive of the compilations nested in it). Prints one line per tree and round, with the load
average; nothing is written (copy the numbers into ``benchmarks/results``).
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
from pathlib import Path

_PROBE = r"""
import json, time, warnings
from numba.core import event
warnings.simplefilter("ignore")
records = []

class _Listener(event.Listener):
    def on_start(self, ev):
        records.append([ev.data["dispatcher"].py_func.__qualname__, time.process_time(), None])

    def on_end(self, ev):
        name = ev.data["dispatcher"].py_func.__qualname__
        for record in reversed(records):
            if record[2] is None and record[0] == name:
                record[2] = time.process_time() - record[1]
                break

import cosserat_chain.loads, cosserat_chain.models, cosserat_chain.state  # noqa: E401,F401
event.register("numba:compile", _Listener())
from cosserat_chain.numerics import engine  # noqa: F401
print(json.dumps([(name, round(cpu, 3)) for name, _, cpu in records]))
"""


def measure(src: Path) -> list:
    """(function, inclusive CPU seconds) of every compilation that importing the engine of ``src`` starts."""
    with tempfile.TemporaryDirectory() as cache:
        env = dict(os.environ, NUMBA_CACHE_DIR=cache, PYTHONPATH=str(src.resolve()), OMP_NUM_THREADS="1", OPENBLAS_NUM_THREADS="1")
        out = subprocess.run([sys.executable, "-c", _PROBE], env=env, capture_output=True, text=True, check=True)
    return json.loads(out.stdout.strip().splitlines()[-1])


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--src", type=Path, action="append", required=True, help="a checkout's src/ (repeat to compare trees)")
    parser.add_argument("--rounds", type=int, default=1, help="rounds over the trees (default 1)")
    args = parser.parse_args()
    for src in args.src:
        if not (src / "cosserat_chain" / "__init__.py").is_file():
            parser.error(f"--src {src}: no cosserat_chain package there (give the folder that holds it, a checkout's src/)")
    for _ in range(args.rounds):
        for src in args.src:
            records = measure(src)
            total = dict(records).get("advance")
            print(f"{src}: advance {total} s inclusive; {json.dumps(records)} (load average {os.getloadavg()[0]:.1f})")


if __name__ == "__main__":
    main()
