"""CPU and wall time of the whole ``cosserat-chain reproduce`` command, per stage.

Run from the repository root::

    python benchmarks/bench_reproduce.py            # warm: the compiled kernels from Numba's cache
    python benchmarks/bench_reproduce.py --cold     # cold: an empty Numba cache, every kernel compiled
    python benchmarks/bench_reproduce.py --json     # also print one JSON object
    python benchmarks/bench_reproduce.py --src /tmp/old/src   # another checkout's package (before/after)
    python benchmarks/bench_reproduce.py --against /tmp/old/src --rounds 3   # both, interleaved

It runs the command as a user does (a fresh process, so imports and loading or compiling
the Numba kernels count) into a temporary folder, and reports the CPU time (user + system)
of the command and of every process it started (the state diagram runs in a second process
beside the other stages where two cores are free), the wall time, the load average before and
after (the machine may be shared: wall times only compare on the same load), and each
stage's wall and CPU seconds from the report's ``summary.json``. Results go to
``benchmarks/results/reproduce.json`` (``reproduce_cold.json`` with ``--cold``; with ``--src``,
which runs the package under that folder instead, e.g. one unpacked by ``git archive REV src |
tar -x -C /tmp/old``, nothing is written: its numbers are for comparison, run interleaved with
this checkout's, the machine's load moving the CPU time by 10 % from one run to the next).
``--against OLD --rounds K`` runs that interleaving itself: K rounds of the package under OLD then
this checkout's (or ``--src``'s), one line each (CPU, wall, the state map's CPU, the load) and whether the two
summaries' numbers are the same bit for bit (the floats as JSON writes them, which round-trips them), written to
``benchmarks/results/reproduce_interleaved.json`` (``reproduce_interleaved_cold.json`` with ``--cold``; nothing with ``--src``). Give OLD's Numba cache one
run first: a checkout elsewhere compiles every kernel on its first run.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

RESULTS = Path(__file__).resolve().parent / "results"


def _children_cpu() -> float:
    usage = resource.getrusage(resource.RUSAGE_CHILDREN)
    return usage.ru_utime + usage.ru_stime


def measure(src: Path | None, cold: bool) -> dict:
    """One run of ``reproduce`` in a fresh process (the package under ``src``, or this environment's): the result's fields."""
    env = dict(os.environ)
    if src is not None:
        env["PYTHONPATH"] = os.pathsep.join(filter(None, [str(src.resolve()), env.get("PYTHONPATH")]))
    with tempfile.TemporaryDirectory() as out, tempfile.TemporaryDirectory() as cache:
        if cold:
            env["NUMBA_CACHE_DIR"] = cache
        load_before = os.getloadavg()
        cpu_before = _children_cpu()
        start = time.perf_counter()
        subprocess.run(
            [sys.executable, "-m", "cosserat_chain.cli", "reproduce", "--out", out], check=True, stdout=subprocess.DEVNULL, env=env
        )
        wall = time.perf_counter() - start
        cpu = _children_cpu() - cpu_before
        load_after = os.getloadavg()
        summary = json.loads((Path(out) / "summary.json").read_text())
    stages = {name: {"seconds": stage["seconds"], "cpu_seconds": stage.get("cpu_seconds")} for name, stage in summary["stages"].items()}
    numbers = {name: stage.get("numbers") for name, stage in summary["stages"].items()}
    return {
        "machine": platform.platform(),
        "cores": os.cpu_count(),
        "cold": cold,
        "src": None if src is None else str(src),
        "version": summary["cosserat_chain_version"],
        "load_average_before": load_before[0],
        "load_average_after": load_after[0],
        "cpu_seconds": cpu,
        "wall_seconds": wall,
        "stages": stages,
        "stages_cpu_seconds": sum(stage["cpu_seconds"] or 0.0 for stage in stages.values()),
        "numbers": numbers,
    }


#: Numbers of a summary that are times of the run, not results: left out of :func:`differences`.
TIMES = ("wall_time", "seconds", "cpu_seconds")


def differences(first, second, where: str = "") -> list[str]:
    """Where two summaries' numbers differ (JSON values compared exactly: floats bit for bit, as JSON writes them),
    but for the run's times (:data:`TIMES`)."""
    if isinstance(first, dict) and isinstance(second, dict):
        found = [f"{where}/{key}: only in one" for key in sorted(set(first) ^ set(second), key=str)]
        for key in (first.keys() & second.keys()) - set(TIMES):
            found += differences(first[key], second[key], f"{where}/{key}")
        return found
    if isinstance(first, list) and isinstance(second, list) and len(first) == len(second):
        return [d for k, (a, b) in enumerate(zip(first, second, strict=True)) for d in differences(a, b, f"{where}[{k}]")]
    return [] if first == second or (first != first and second != second) else [f"{where}: {first!r} != {second!r}"]


def _checked(parser: argparse.ArgumentParser, option: str, src: Path | None) -> None:
    if src is not None and not (src / "cosserat_chain" / "__init__.py").is_file():
        parser.error(f"{option} {src}: no cosserat_chain package there (give the folder that holds it, a checkout's src/)")


def interleaved(against: Path, src: Path | None, rounds: int, cold: bool) -> list[dict]:
    """``rounds`` rounds of a run of the package under ``against`` then one of ``src`` (or this environment's), printed as they come."""
    print(f"{'round':>5s} {'package':30s} {'CPU s':>7s} {'wall s':>7s} {'state map CPU s':>16s}  load average")
    runs = []
    for k in range(1, rounds + 1):
        for package in (against, src):
            result = measure(package, cold)
            runs.append({"round": k, **result})
            if package is src:
                found = differences(runs[-2]["numbers"], result["numbers"])
                runs[-1]["numbers_equal_to_against"] = not found
                print("      the summaries' numbers: " + ("the same, bit for bit" if not found else f"{len(found)} differ: {found[:5]}"))
            state_map = result["stages"].get("state_map", {}).get("cpu_seconds") or float("nan")
            name = str(package) if package is not None else "this checkout"
            print(
                f"{k:5d} {name[-30:]:30s} {result['cpu_seconds']:7.1f} {result['wall_seconds']:7.1f} {state_map:16.1f}  "
                f"{result['load_average_before']:.1f} -> {result['load_average_after']:.1f}"
            )
    return runs


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--cold", action="store_true", help="run with an empty Numba cache (every kernel compiled)")
    parser.add_argument("--json", action="store_true", help="print the results as one JSON object")
    parser.add_argument("--src", type=Path, help="run the package under this folder (another checkout's src/); writes no results file")
    parser.add_argument("--against", type=Path, help="another checkout's src/ to run interleaved with this one (see --rounds)")
    parser.add_argument("--rounds", type=int, default=2, help="rounds of the interleaving with --against (default 2)")
    args = parser.parse_args()
    _checked(parser, "--src", args.src)
    _checked(parser, "--against", args.against)
    if args.against is not None:
        if args.rounds < 1:
            parser.error(f"--rounds must be an integer >= 1, got {args.rounds}")
        runs = interleaved(args.against, args.src, args.rounds, args.cold)
        if args.src is None:
            RESULTS.mkdir(exist_ok=True)
            name = "reproduce_interleaved_cold.json" if args.cold else "reproduce_interleaved.json"
            (RESULTS / name).write_text(json.dumps(runs, indent=2) + "\n")
        if args.json:
            print(json.dumps(runs))
        return
    result = measure(args.src, args.cold)
    if args.src is None:
        RESULTS.mkdir(exist_ok=True)
        (RESULTS / ("reproduce_cold.json" if args.cold else "reproduce.json")).write_text(json.dumps(result, indent=2) + "\n")
    stages, cpu, wall = result["stages"], result["cpu_seconds"], result["wall_seconds"]
    print(f"{'stage':16s} {'wall s':>7s} {'CPU s':>7s}")
    for name, stage in stages.items():
        print(f"{name:16s} {stage['seconds']:7.1f} {stage['cpu_seconds'] or float('nan'):7.1f}")
    print(f"{'(outside stages)':16s} {'':7s} {cpu - result['stages_cpu_seconds']:7.1f}")
    print(
        f"{'total':16s} {wall:7.1f} {cpu:7.1f}   ({'cold' if args.cold else 'warm'}; load average "
        f"{result['load_average_before']:.1f} -> {result['load_average_after']:.1f})"
    )
    if args.json:
        print(json.dumps(result))


if __name__ == "__main__":
    main()
