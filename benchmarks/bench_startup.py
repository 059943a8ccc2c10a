"""Start-up: the CPU time of a computing command with ``--json`` (issue 44, item 3).

Run from the repository root::

    python benchmarks/bench_startup.py                              # critical --model sine --json, median of 5
    python benchmarks/bench_startup.py --runs 9 -- orbit --model sine --moment 0.3 --json
    python benchmarks/bench_startup.py --src /tmp/old/src           # another checkout's package, same interpreter

Each run is a fresh ``python -m cosserat_chain ARGS`` (its output discarded); its CPU time is
user + system of the child (``resource.getrusage(RUSAGE_CHILDREN)``), which a busy neighbour
on the other core does not change. One run first warms Numba's on-disk cache (not counted).
Also printed: the heavy libraries loaded by the end of the command (none of xarray, pandas,
Dask or matplotlib for ``--json`` without ``--out``/``--plot``), and the slowest top-level
imports of one run from ``python -X importtime``.
"""

from __future__ import annotations

import argparse
import os
import re
import resource
import statistics
import subprocess
import sys

HEAVY = ("numba", "scipy", "xarray", "pandas", "dask", "distributed", "matplotlib")
PROBE = (
    "import atexit, runpy, sys\n"
    f"atexit.register(lambda: print('HEAVY', sorted(m for m in {HEAVY!r} if m in sys.modules)))\n"
    "sys.argv = ['cosserat-chain', *sys.argv[1:]]\n"
    "runpy.run_module('cosserat_chain', run_name='__main__')\n"
)


def cpu_seconds(cmd: list[str], env: dict[str, str]) -> float:
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    subprocess.run(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, env=env, check=True)
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    return (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)


def top_imports(args: list[str], env: dict[str, str], count: int = 8) -> list[tuple[str, float]]:
    """The slowest top-level imports (cumulative seconds) of one run, from ``-X importtime``."""
    err = subprocess.run(
        [sys.executable, "-X", "importtime", "-m", "cosserat_chain", *args], capture_output=True, text=True, env=env
    ).stderr
    rows = []
    for line in err.splitlines():
        m = re.match(r"import time:\s+\d+ \|\s+(\d+) \| (\s*)(\S+)", line)
        if m and len(m.group(2)) <= 1:  # top level (one space after the bar)
            rows.append((m.group(3), int(m.group(1)) / 1e6))
    return sorted(rows, key=lambda r: -r[1])[:count]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--runs", type=int, default=5)
    parser.add_argument("--src", help="put this folder first on PYTHONPATH (measure another checkout)")
    parser.add_argument("args", nargs="*", default=["critical", "--model", "sine", "--json"])
    ns = parser.parse_args()
    env = dict(os.environ)
    if ns.src:
        env["PYTHONPATH"] = ns.src + os.pathsep + env.get("PYTHONPATH", "")
    cmd = [sys.executable, "-m", "cosserat_chain", *ns.args]
    cpu_seconds(cmd, env)  # warm Numba's cache
    times = [cpu_seconds(cmd, env) for _ in range(ns.runs)]
    heavy = subprocess.run([sys.executable, "-c", PROBE, *ns.args], capture_output=True, text=True, env=env).stdout.strip().splitlines()[-1]
    print(f"cosserat-chain {' '.join(ns.args)}")
    print(f"  CPU (user + sys) median of {ns.runs}: {statistics.median(times):.2f} s  runs: {' '.join(f'{t:.2f}' for t in times)}")
    print(f"  loaded at exit: {heavy.removeprefix('HEAVY ')}")
    print(
        "  slowest top-level imports (cumulative, one run): " + ", ".join(f"{name} {sec:.2f} s" for name, sec in top_imports(ns.args, env))
    )
    print(f"  load average: {' '.join(f'{x:.2f}' for x in os.getloadavg())}")


if __name__ == "__main__":
    main()
