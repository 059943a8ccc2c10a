"""Throughput of the batched loop against the single-run compiled loop, measured in the same run.

Run from the repository root::

    python benchmarks/bench_batch.py            # about 2 minutes on 2 cores
    python benchmarks/bench_batch.py --quick    # fewer repetitions, smaller work (< 30 s)
    python benchmarks/bench_batch.py --json     # also print one JSON object

Two parts (see benchmarks/BATCH.md):

1. Throughput in particle-steps per second (p-s/s; particles = all 2N+1 columns)
   of ``integrate_batch`` with B members (B = 1, 16, 256; members with
   different moments, damped Verlet, default dt) on one thread and on two,
   against ``integrate`` on one chain (the single-run compiled loop, one thread,
   same model, same dt), for 7 and 101 particles, nonlinear and sine models.
   Each configuration does about the same work; the three are interleaved and
   repeated, and medians are reported with the ratios batch / single, in wall
   time and per CPU-second of the process (which a busy machine distorts less).
   Before and after, the speed-up of a perfectly parallel loop on two threads
   says how many cores the machine actually gave the run.
2. The relaxation step for a grid of 16 loads on the paper's chain:
   ``relax_batch`` (one and two threads) against ``relax`` called load by load,
   wall time of the whole grid.

Results go to stdout (a table), to ``benchmarks/results/batch.json`` (or
``batch-quick.json`` with ``--quick``) and, with ``--json``, to stdout as one
JSON object.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import shlex
import statistics
import sys
import time
from functools import partial
from pathlib import Path

import numba
import numpy as np

from cosserat_chain import ChainParams, moment_load
from cosserat_chain.numerics.batch import integrate_batch, relax_batch
from cosserat_chain.numerics.dynamics import default_time_step, integrate
from cosserat_chain.numerics.relaxation import relax

RESULTS = Path(__file__).resolve().parent / "results"
MODELS = ("nonlinear", "sine")
SIZES = (3, 50)  # N: 7 and 101 particles
BATCHES = (1, 16, 256)
GRID = np.linspace(0.02, 0.5, 16)  # loads of the relaxation grid: static and rotating


def moments(batch: int) -> np.ndarray:
    """Different loads per member (static and rotating ones), so that members really differ."""
    return np.linspace(0.02, 0.4, batch)


def timed(fn) -> tuple[float, float]:
    """Wall time and CPU time of the process (all threads) of one call."""
    wall, cpu = time.perf_counter(), time.process_time()
    fn()
    return time.perf_counter() - wall, time.process_time() - cpu


def throughput(quick: bool, log) -> list[dict]:
    """Particle-steps per second of single runs and of batches, interleaved, medians."""
    work = 2_000_000 if quick else 8_000_000  # particle-steps per measurement
    repeats = 3 if quick else 7
    rows = []
    for model in MODELS:
        for N in SIZES:
            params = ChainParams(N=N)
            n = params.n_particles
            dt = default_time_step(params)
            single_steps = work // n
            single = partial(integrate, params, model, moment_load(0.1), t_end=single_steps * dt, dt=dt, n_frames=2)
            for batch in BATCHES:
                steps = max(64, work // (n * batch))
                batched = partial(integrate_batch, [params] * batch, model, moments(batch), t_end=steps * dt, dt=dt, n_records=2)
                runs = {f"batch_{threads}t": partial(batched, threads=threads) for threads in (1, 2)}
                for fn in (single, *runs.values()):
                    fn()  # compile and warm the caches
                work_done = {"single": single_steps * n, **{key: steps * n * batch for key in runs}}
                wall: dict[str, list[float]] = {key: [] for key in work_done}
                cpu: dict[str, list[float]] = {key: [] for key in work_done}
                for _ in range(repeats):
                    for key, fn in (("single", single), *runs.items()):
                        w, c = timed(fn)
                        wall[key].append(work_done[key] / w)
                        cpu[key].append(work_done[key] / c)
                row = {"model": model, "particles": n, "batch": batch}
                row.update({f"{key}_ps": statistics.median(v) for key, v in wall.items()})
                # Per CPU-second of the process: what a busy machine does not distort
                # (it shows the cost of the work, not how many cores were free).
                row.update({f"{key}_ps_per_cpu_s": statistics.median(v) for key, v in cpu.items()})
                row["ratio_1t"] = row["batch_1t_ps"] / row["single_ps"]
                row["ratio_2t"] = row["batch_2t_ps"] / row["single_ps"]
                row["cpu_ratio_1t"] = row["batch_1t_ps_per_cpu_s"] / row["single_ps_per_cpu_s"]
                log(
                    f"{model:9s} {n:4d} particles  B={batch:4d}  single {row['single_ps'] / 1e6:6.1f} M p-s/s  "
                    f"batch 1 thread {row['batch_1t_ps'] / 1e6:6.1f} M ({row['ratio_1t']:.2f}x)  "
                    f"2 threads {row['batch_2t_ps'] / 1e6:6.1f} M ({row['ratio_2t']:.2f}x)  per CPU-second {row['cpu_ratio_1t']:.2f}x"
                )
                rows.append(row)
    return rows


def relaxation_grid(quick: bool, log) -> dict:
    """Wall time of one relaxation step for each of 16 loads: relax load by load against relax_batch."""
    params = ChainParams()
    options = {"t_max": 2000.0 if quick else 5000.0}
    members = [params] * GRID.size
    batched = {threads: partial(relax_batch, members, "sine", GRID, threads=threads, **options) for threads in (1, 2)}

    def single():
        return [relax(params, "sine", float(m), **options) for m in GRID]

    reference = [s.status for s in single()]
    for fn in batched.values():
        assert [s.status for s in fn()] == reference
    samples: dict[str, list[float]] = {"single": [], "batch_1t": [], "batch_2t": []}
    for _ in range(2 if quick else 5):
        samples["single"].append(timed(single)[0])
        for threads, fn in batched.items():
            samples[f"batch_{threads}t"].append(timed(fn)[0])
    out = {f"{k}_s": statistics.median(v) for k, v in samples.items()}
    out.update(
        {
            "model": "sine",
            "particles": params.n_particles,
            "loads": GRID.tolist(),
            "statuses": reference,
            "speedup_1t": out["single_s"] / out["batch_1t_s"],
            "speedup_2t": out["single_s"] / out["batch_2t_s"],
        }
    )
    log(
        f"relaxation grid of {GRID.size} loads (sine, 7 particles): relax one by one {out['single_s']:.3f} s, "
        f"relax_batch {out['batch_1t_s']:.3f} s ({out['speedup_1t']:.2f}x), 2 threads {out['batch_2t_s']:.3f} s ({out['speedup_2t']:.2f}x)"
    )
    return out


@numba.njit(cache=True)
def _spin(n: int) -> float:
    total = 0.0
    for i in range(n):
        total += (i % 7) * 1e-9
    return total


@numba.njit(cache=True, parallel=True)
def _spin_two(n: int) -> np.ndarray:
    out = np.zeros(2)
    for g in numba.prange(2):
        out[g] = _spin(n)
    return out


def free_cores(quick: bool) -> float:
    """Speed-up of a perfectly parallel loop on two threads: how many cores the machine gave this run.

    On a shared machine the two-thread ratios mean something only when this is near 2.
    """
    n = 50_000_000 if quick else 200_000_000
    _spin(10), _spin_two(10)
    one = statistics.median(timed(lambda: _spin(2 * n))[0] for _ in range(3))
    two = statistics.median(timed(lambda: _spin_two(n))[0] for _ in range(3))
    return one / two


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--quick", action="store_true", help="smaller work and fewer repetitions (< 30 s)")
    parser.add_argument("--json", action="store_true", help="print one JSON object with all numbers at the end")
    parser.add_argument("--output", type=Path, default=None, help="JSON file (default benchmarks/results/batch[-quick].json)")
    args = parser.parse_args(argv)

    def log(msg: str) -> None:
        print(msg, file=sys.stderr if args.json else sys.stdout, flush=True)

    numba.set_num_threads(min(2, numba.config.NUMBA_NUM_THREADS))
    load_before = os.getloadavg()[0]
    cores_before = free_cores(args.quick)
    log(f"a perfectly parallel loop runs {cores_before:.2f}x faster on two threads than on one (free cores)")
    rows = throughput(args.quick, log)
    grid = relaxation_grid(args.quick, log)
    cores_after = free_cores(args.quick)
    log(f"... and {cores_after:.2f}x after the runs")
    result = {
        "command": "python benchmarks/bench_batch.py"
        + (" " + shlex.join(argv if argv is not None else sys.argv[1:]) if (argv or sys.argv[1:]) else ""),
        "environment": {
            "python": platform.python_version(),
            "numba": numba.__version__,
            "numpy": np.__version__,
            "cpu_count": os.cpu_count(),
            "numba_threads": numba.get_num_threads(),
            "load_average_before_after": [load_before, os.getloadavg()[0]],
            "free_cores_before_after": [cores_before, cores_after],
        },
        "throughput": rows,
        "relaxation_grid": grid,
        "summary": {
            "min_ratio_1t": min(r["ratio_1t"] for r in rows),
            "min_cpu_ratio_1t": min(r["cpu_ratio_1t"] for r in rows),
            "min_ratio_2t_batch_16_up": min(r["ratio_2t"] for r in rows if r["batch"] >= 16),
        },
    }
    output = args.output or RESULTS / ("batch-quick.json" if args.quick else "batch.json")
    output.parent.mkdir(parents=True, exist_ok=True)
    output.write_text(json.dumps(result, indent=2) + "\n")
    log(f"written {output}")
    if args.json:
        print(json.dumps(result))
    return 0


if __name__ == "__main__":
    sys.exit(main())
