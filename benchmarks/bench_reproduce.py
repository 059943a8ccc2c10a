"""Wall time of the whole ``cosserat-chain reproduce`` command, per stage.

Run from the repository root::

    python benchmarks/bench_reproduce.py            # the paper's defaults, about a minute on 2 cores
    python benchmarks/bench_reproduce.py --json     # also print one JSON object

It runs the command as a user does (a fresh process, so imports and loading the
cached Numba kernels count), reads the per-stage times from the report's
``summary.json``, and reports the stages' share of the total. Results go to
``benchmarks/results/reproduce.json``.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import subprocess
import sys
import tempfile
import time
from pathlib import Path

RESULTS = Path(__file__).resolve().parent / "results"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--json", action="store_true", help="print the results as one JSON object")
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as out:
        start = time.perf_counter()
        subprocess.run([sys.executable, "-m", "cosserat_chain.cli", "reproduce", "--out", out], check=True, stdout=subprocess.DEVNULL)
        wall = time.perf_counter() - start
        summary = json.loads((Path(out) / "summary.json").read_text())
    stages = {name: stage["seconds"] for name, stage in summary["stages"].items()}
    result = {
        "machine": platform.platform(),
        "cores": os.cpu_count(),
        "version": summary["cosserat_chain_version"],
        "wall_seconds": wall,
        "stage_seconds": stages,
        "outside_stages_seconds": wall - sum(stages.values()),
    }
    RESULTS.mkdir(exist_ok=True)
    (RESULTS / "reproduce.json").write_text(json.dumps(result, indent=2) + "\n")
    for name, seconds in stages.items():
        print(f"{name:14s} {seconds:7.1f} s  {100 * seconds / wall:5.1f} %")
    print(f"{'(start-up)':14s} {result['outside_stages_seconds']:7.1f} s")
    print(f"{'total':14s} {wall:7.1f} s")
    if args.json:
        print(json.dumps(result))


if __name__ == "__main__":
    main()
