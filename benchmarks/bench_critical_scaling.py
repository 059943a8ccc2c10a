"""``critical`` against N for both models: CPU time, peak memory and the fitted exponent.

Run from the repository root::

    python benchmarks/bench_critical_scaling.py              # N = 10, 100, 1000, 10^4, both models
    python benchmarks/bench_critical_scaling.py --large      # and N = 10^5 (minutes, a few GiB)
    python benchmarks/bench_critical_scaling.py --sizes 10 100 --models sine
    python benchmarks/bench_critical_scaling.py --sizes 100000 --models nonlinear --out results/critical_scaling_large_nonlinear.json
    python benchmarks/bench_critical_scaling.py --sizes 100000 --merge    # N = 10^5's rows into the results' file

Each (model, N) runs :func:`~cosserat_chain.experiments.critical.critical_point` as
``cosserat-chain critical`` does, in a fresh process (so that its peak memory, ``ru_maxrss``,
is that run's alone, and the compiled kernels come from the on-disk cache after a first
small warm-up call). Reported per row: the CPU time of the call (``time.process_time``: what
a busy neighbour on the other core does not change), wall time, peak resident memory of the
process, the branch's points and folds, the states kept (a long chain's branch keeps a
thinned set: ``critical.STATE_BYTES``), M_c, how the folds were confirmed, whether the
result is ``accurate`` and whether relaxations just above M_c decided that the chain leaves rest there (``onset_checked``); then, per model, the exponent of CPU time against N fitted by least
squares on log-log axes over N >= 100 (below, start-up costs dominate) with the free
memory and the load average at the start, which the numbers depend on. Results go to
``benchmarks/results/critical_scaling_models.json``.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import subprocess
import sys
import threading
from pathlib import Path

import numpy as np

RESULTS = Path(__file__).resolve().parent / "results" / "critical_scaling_models.json"
MODELS = ("nonlinear", "sine")
SIZES = (10, 100, 1000, 10_000)
LARGE = 100_000
#: A long row shows its progress (phi_0, CPU time, peak memory) every this many seconds of its CPU time.
PROGRESS_SECONDS = 20.0

#: The child: one critical_point, timed, with its peak memory, printed as one JSON line.
CHILD = """
import json, resource, sys, time
from cosserat_chain import ChainParams
from cosserat_chain.experiments.critical import critical_memory, critical_point

model, n = sys.argv[1], int(sys.argv[2])
critical_point(ChainParams(N=3), model, dynamics=False)  # compiled kernels loaded before the clock starts
start_rss = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
cpu, wall = time.process_time(), time.perf_counter()
shown = [cpu]


def progress(done, total):  # every PROGRESS_SECONDS of CPU: phi_0, CPU time and peak memory so far, on stderr
    now = time.process_time()
    if now - shown[0] >= float(sys.argv[3]):
        shown[0] = now
        peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
        print(f"{model} N={n}: phi_0 {done:.6f} of {total:.4f} rad, {now - cpu:.1f} s CPU, peak {peak:.0f} MiB", file=sys.stderr, flush=True)


result = critical_point(ChainParams(N=n), model, progress=progress)
cpu, wall = time.process_time() - cpu, time.perf_counter() - wall
branch = result.branch
print(json.dumps({
    "model": model, "N": n, "cpu_seconds": cpu, "wall_seconds": wall,
    "peak_rss_mib": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024,
    "points": int(branch.moment.size), "folds": len(branch.folds),
    "states_kept": int(branch.x.shape[0]), "approach": branch.approach, "stop": branch.stop, "complete": result.complete,
    "M_c": result.critical_moment, "confirmation": result.confirmation, "accurate": result.accurate,
    "onset_checked": result.onset_checked,
    "compliance": result.compliance, "first_fold_phi0": None if result.first_fold is None else result.first_fold.phi0,
    "folds_confirmed": [f.confirmed for f in branch.folds][:3], "message": branch.message,
    "estimate_mib": critical_memory(ChainParams(N=n), model) / 2**20, "start_rss_mib": start_rss,
}))
"""


def run(model: str, n: int, timeout: float) -> dict:
    """One (model, N) row from a fresh process; its progress lines (:data:`PROGRESS_SECONDS`) are shown as they come."""
    child = subprocess.Popen(
        [sys.executable, "-c", CHILD, model, str(n), str(PROGRESS_SECONDS)], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True
    )
    timer = threading.Timer(timeout, child.kill)
    timer.start()
    errors = []
    for line in child.stderr:
        print("   ", line.rstrip(), flush=True) if " rad, " in line else errors.append(line)
    out = child.stdout.read()
    child.wait()
    timer.cancel()
    if child.returncode != 0:
        return {"model": model, "N": n, "error": errors[-1].strip() if errors else str(child.returncode)}
    return json.loads(out.strip().splitlines()[-1])


def exponent(rows: list[dict]) -> float | None:
    """Least-squares slope of log(CPU time) against log(N) over the rows with N >= 100."""
    fit = [(r["N"], r["cpu_seconds"]) for r in rows if "cpu_seconds" in r and r["N"] >= 100]
    if len(fit) < 2:
        return None
    n, t = np.log([f[0] for f in fit]), np.log([f[1] for f in fit])
    return float(np.polyfit(n, t, 1)[0])


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sizes", type=int, nargs="+", default=list(SIZES), help="chain lengths N")
    parser.add_argument("--large", action="store_true", help=f"also N = {LARGE}")
    parser.add_argument("--models", nargs="+", default=list(MODELS), choices=MODELS)
    parser.add_argument("--timeout", type=float, default=3600.0, help="seconds one run may take")
    parser.add_argument("--out", type=Path, default=RESULTS, help="the results' JSON file")
    parser.add_argument(
        "--merge", action="store_true", help="keep the file's other rows, replacing those of the same model and N (the fit over all)"
    )
    args = parser.parse_args()
    sizes = sorted(set(args.sizes) | ({LARGE} if args.large else set()))
    import psutil

    env = {
        "machine": platform.platform(),
        "python": platform.python_version(),
        "cpus": os.cpu_count(),
        "load_average_at_start": os.getloadavg(),
        "free_memory_gib_at_start": psutil.virtual_memory().available / 2**30,
    }
    rows = []
    print(
        f"{'model':>9} {'N':>7} {'CPU s':>8} {'wall s':>8} {'peak MiB':>9} {'points':>6} {'folds':>5} {'states':>6} {'M_c':>14}  confirmation"
    )
    for model in args.models:
        for n in sizes:
            row = run(model, n, args.timeout)
            rows.append(row)
            if "error" in row:
                print(f"{model:>9} {n:>7} failed: {row['error']}")
                continue
            flag = "" if row["accurate"] else " (not accurate)"
            print(
                f"{model:>9} {n:>7} {row['cpu_seconds']:8.2f} {row['wall_seconds']:8.2f} {row['peak_rss_mib']:9.0f} {row['points']:6d} "
                f"{row['folds']:5d} {row['states_kept']:6d} {row['M_c']:14.9g}  {row['confirmation']}{flag}"
            )
    if args.merge and args.out.exists():
        measured = {(r["model"], r["N"]) for r in rows}
        old = json.loads(args.out.read_text())
        rows = sorted(
            [r for r in old["rows"] if (r["model"], r["N"]) not in measured] + rows, key=lambda r: (MODELS.index(r["model"]), r["N"])
        )
        env["merged_with"] = {key: old[key] for key in ("machine", "load_average_at_start", "free_memory_gib_at_start") if key in old}
    fits = {model: exponent([r for r in rows if r["model"] == model]) for model in sorted({r["model"] for r in rows}, key=MODELS.index)}
    for model, slope in fits.items():
        print(f"{model}: CPU time ~ N^{slope:.2f} over N >= 100" if slope is not None else f"{model}: too few rows to fit")
    args.out.parent.mkdir(exist_ok=True)
    args.out.write_text(json.dumps({**env, "rows": rows, "cpu_exponent": fits}, indent=2) + "\n")


if __name__ == "__main__":
    main()
