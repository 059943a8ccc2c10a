"""Where a cold ``cosserat-chain reproduce`` spends its compile time: Numba's compilations, per function and signature.

Run from the repository root::

    python benchmarks/bench_cold_compile.py                  # the report, an empty Numba cache
    python benchmarks/bench_cold_compile.py --top 40 --json   # more rows; also one JSON object
    python benchmarks/bench_cold_compile.py --src /tmp/old/src  # another checkout's package (before/after)

It runs the command as a user does, in a fresh process with a fresh Numba cache folder (and a
fresh ``$COSSERAT_CHAIN_CACHE``), with a listener on Numba's ``numba:compile`` event installed
before the package is imported; the background process of the report is forked, so it inherits
the listener. Every compilation is written down as it ends (a forked process leaves without
running ``atexit``): the function, its argument types, its time inclusive of the compilations
it started (a callee compiled for the first time inside its caller's compilation) and its own
time (exclusive). It prints the functions by own time, the total, and the command's CPU time
(this process's children, ``os.times``) with the load average before and after. Results go to
``benchmarks/results/cold_compile.json`` (nothing with ``--src``).
"""

from __future__ import annotations

import argparse
import collections
import json
import os
import platform
import subprocess
import sys
import tempfile
import time
from pathlib import Path

RESULTS = Path(__file__).resolve().parent / "results"

#: Installed in the measured process before the package is imported: one JSON line per compilation, appended
#: to the file named by ``_COLD_COMPILE_LOG`` as soon as it ends (own time = inclusive minus nested compilations).
_RECORDER = r"""
import json, os, sys, threading, time
from numba.core import event

_log = open(os.environ["_COLD_COMPILE_LOG"], "a", buffering=1)
_stacks = threading.local()

class _Listener(event.Listener):
    def on_start(self, ev):
        stack = getattr(_stacks, "stack", None)
        if stack is None:
            stack = _stacks.stack = []
        function = ev.data["dispatcher"].py_func
        stack.append([time.perf_counter(), time.thread_time(), 0.0, f"{function.__module__}.{function.__qualname__}"])

    def on_end(self, ev):
        start, cpu_start, nested, name = _stacks.stack.pop()
        seconds = time.perf_counter() - start
        cpu = time.thread_time() - cpu_start
        if _stacks.stack:
            _stacks.stack[-1][2] += cpu
        parent = _stacks.stack[0][3] if _stacks.stack else None
        args = ", ".join(str(a) for a in ev.data["args"])
        _log.write(json.dumps({"pid": os.getpid(), "function": name, "args": args, "seconds": seconds,
                               "cpu_inclusive": cpu, "cpu_own": cpu - nested,
                               "parent": parent, "at": time.time()}) + "\n")

event.register("numba:compile", _Listener())
sys.argv = ["cosserat-chain", *sys.argv[1:]]
from cosserat_chain.cli import app
app()
"""


def measure(src: Path | None, argv: list[str]) -> dict:
    """One cold run of ``cosserat-chain`` with ``argv`` (the package under ``src``, or this environment's): the compilations."""
    env = dict(os.environ)
    if src is not None:
        env["PYTHONPATH"] = os.pathsep.join(filter(None, [str(src.resolve()), env.get("PYTHONPATH")]))
    with tempfile.TemporaryDirectory() as work:
        out, cache, systems, log = (Path(work) / name for name in ("out", "numba", "systems", "compile.jsonl"))
        env.update(NUMBA_CACHE_DIR=str(cache), COSSERAT_CHAIN_CACHE=str(systems), _COLD_COMPILE_LOG=str(log))
        load_before = os.getloadavg()
        times_before = os.times()
        start = time.perf_counter()
        subprocess.run([sys.executable, "-c", _RECORDER, *argv, "--out", str(out)], check=True, stdout=subprocess.DEVNULL, env=env)
        wall = time.perf_counter() - start
        times_after = os.times()
        load_after = os.getloadavg()
        records = [json.loads(line) for line in log.read_text().splitlines()] if log.exists() else []
        summary_file = out / "summary.json"
        stages = json.loads(summary_file.read_text()).get("stages", {}) if summary_file.exists() else {}
    cpu = (times_after.children_user - times_before.children_user) + (times_after.children_system - times_before.children_system)
    return {
        "machine": platform.platform(),
        "cores": os.cpu_count(),
        "command": ["cosserat-chain", *argv],
        "src": None if src is None else str(src),
        "load_average_before": load_before[0],
        "load_average_after": load_after[0],
        "cpu_seconds": cpu,
        "wall_seconds": wall,
        "compile_cpu_seconds": sum(r["cpu_own"] for r in records),
        "compilations": len(records),
        "stages": {name: {"seconds": s["seconds"], "cpu_seconds": s.get("cpu_seconds")} for name, s in stages.items()},
        "records": records,
    }


def by_function(records: list[dict]) -> list[dict]:
    """The compilations summed per function: own CPU seconds, signatures, largest inclusive time; largest own time first."""
    table: dict[str, dict] = collections.defaultdict(lambda: {"cpu_own": 0.0, "cpu_inclusive": 0.0, "signatures": []})
    for record in records:
        row = table[record["function"]]
        row["cpu_own"] += record["cpu_own"]
        row["cpu_inclusive"] = max(row["cpu_inclusive"], record["cpu_inclusive"])
        row["signatures"].append(record["args"])
    rows = [{"function": name, **row} for name, row in table.items()]
    return sorted(rows, key=lambda row: -row["cpu_own"])


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--src", type=Path, help="run the package under this folder (another checkout's src/); writes no results file")
    parser.add_argument("--top", type=int, default=25, help="rows of the per-function table printed (default 25)")
    parser.add_argument("--json", action="store_true", help="print the results as one JSON object")
    parser.add_argument("--command", default="reproduce", help="the cosserat-chain command and its options (default: reproduce)")
    args = parser.parse_args()
    if args.src is not None and not (args.src / "cosserat_chain" / "__init__.py").is_file():
        parser.error(f"--src {args.src}: no cosserat_chain package there (give the folder that holds it, a checkout's src/)")
    result = measure(args.src, args.command.split())
    result["by_function"] = by_function(result["records"])
    if args.src is None:
        RESULTS.mkdir(exist_ok=True)
        (RESULTS / "cold_compile.json").write_text(json.dumps(result, indent=2) + "\n")
    print(f"{'own CPU s':>9s} {'incl. s':>8s} {'sigs':>4s}  function")
    for row in result["by_function"][: args.top]:
        print(f"{row['cpu_own']:9.2f} {row['cpu_inclusive']:8.2f} {len(row['signatures']):4d}  {row['function']}")
    print(
        f"compilations {result['compilations']}, their own CPU {result['compile_cpu_seconds']:.1f} s; command CPU "
        f"{result['cpu_seconds']:.1f} s, wall {result['wall_seconds']:.1f} s (load average "
        f"{result['load_average_before']:.1f} -> {result['load_average_after']:.1f})"
    )
    if args.json:
        print(json.dumps(result))


if __name__ == "__main__":
    main()
