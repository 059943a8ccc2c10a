"""Parameter studies: cells per second with chunks of cells per task against one cell per task.

Run from the repository root::

    python benchmarks/bench_study.py            # 2000 cells, about 4 minutes on 2 cores
    python benchmarks/bench_study.py --quick    # 200 cells, about 2 minutes (most of it compiling)
    python benchmarks/bench_study.py --json     # also print one JSON object

The study: the paper's chain (N = 3, nonlinear model), one swept field (the particles'
half-width ``a``, ``--cells`` values from 0.1 to 0.3) and the mean angular velocity at two
loads (0.15: the chain comes to rest; 0.3: it rotates), ``t_max`` = 2000; a cell is two
relaxations from rest. The cells' default time steps differ (0.0204 to 0.0209); rounded
down to a power of 2^(1/8) they are all 0.02026, so a chunk runs in one compiled loop.

Measured, each way once (wall time):

1. **Dask**: on a LocalCluster of 2 single-threaded worker processes (what
   ``cosserat-chain study`` starts on this machine), ``run_study(chunk=1)`` (one cell per
   task) against ``run_study()`` (the default chunk: 4 tasks per worker), results written
   to a NetCDF file as the command does. Both workers compile first (``Client.run``):
   numba compiles once per process, and that is not what is measured.
2. **In process**, without Dask: ``compute_cell`` cell by cell against ``compute_cells`` on
   chunks of the same size, on the first ``--in-process`` cells, one core.

Both ways must give the same cells to the last bit (checked). Results go to
``benchmarks/results/study.json`` (``study-quick.json`` with ``--quick``).
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

import harness
from cosserat_chain.experiments.study import compute_cell, compute_cells, spec_from_mapping
from cosserat_chain.study_runner import default_chunk_size, run_study

RESULTS = Path(__file__).resolve().parent / "results"
MODEL = "nonlinear"
WORKERS = 2
LOADS = [0.15, 0.3]
T_MAX = 2000.0
#: Cells studied: 10^5 of them take 10^5 / (cells per second) seconds.
PRACTICAL = 10**5


def study_spec(cells: int):
    return spec_from_mapping(
        {
            "parameters": {"a": {"start": 0.1, "stop": 0.3, "num": cells}},
            "models": [MODEL],
            "quantities": ["mean_angular_velocity"],
            "loads": LOADS,
            "sweep": {"t_max": T_MAX},
        }
    )


def on_dask(spec, log) -> dict:
    """Both runners on one LocalCluster, its workers compiled first; the datasets checked equal."""
    from dask.distributed import Client, LocalCluster

    fields = [f for _, _, f in spec.cells()]
    spec_json = spec.to_json()
    with (
        LocalCluster(n_workers=WORKERS, threads_per_worker=1, processes=True, dashboard_address=":0") as cluster,
        Client(cluster) as client,
    ):
        start = time.perf_counter()
        client.run(compute_cells, fields[:8], MODEL, spec_json)
        client.run(compute_cell, fields[0], MODEL, spec_json)
        log(f"workers compiled in {time.perf_counter() - start:.1f} s")
        out, runs = {}, {}
        with tempfile.TemporaryDirectory() as folder:
            for name, chunk in (("one cell per task", 1), ("chunked", None)):
                start = time.perf_counter()
                run = run_study(spec, out=Path(folder) / f"{chunk}.nc", scheduler=cluster.scheduler_address, chunk=chunk)
                seconds = time.perf_counter() - start
                assert run.completed and run.failed == 0, name
                runs[name] = run.dataset
                size = chunk or default_chunk_size(len(fields), WORKERS)
                out[name] = {"chunk": size, "tasks": -(-len(fields) // size), "seconds": seconds, "cells_per_s": len(fields) / seconds}
                log(f"dask, {name}: {seconds:.1f} s, {out[name]['cells_per_s']:.1f} cells/s")
    single, chunked = (runs[name]["mean_angular_velocity"].values for name in ("one cell per task", "chunked"))
    np.testing.assert_array_equal(single, chunked)
    return out


def in_process(spec, cells: int, log) -> dict:
    """``compute_cell`` cell by cell against ``compute_cells`` on chunks, on the first ``cells`` cells."""
    fields = [f for _, _, f in spec.cells()][:cells]
    spec_json = spec.to_json()
    size = default_chunk_size(len(spec.cells()), WORKERS)
    compute_cells(fields[:8], MODEL, spec_json)  # compile both paths
    compute_cell(fields[0], MODEL, spec_json)
    out, values = {}, {}
    for name, run in (
        ("one cell per call", lambda: [compute_cell(f, MODEL, spec_json) for f in fields]),
        ("chunked", lambda: [v for i in range(0, len(fields), size) for v in compute_cells(fields[i : i + size], MODEL, spec_json)]),
    ):
        start, cpu = time.perf_counter(), time.thread_time()
        values[name] = run()
        seconds, cpu = time.perf_counter() - start, time.thread_time() - cpu
        out[name] = {
            "chunk": 1 if name == "one cell per call" else size,
            "seconds": seconds,
            "thread_cpu_s": cpu,
            "cells_per_s": len(fields) / seconds,
        }
        log(f"in process, {name}: {seconds:.1f} s, {out[name]['cells_per_s']:.1f} cells/s")
    assert json.dumps(values["one cell per call"]) == json.dumps(values["chunked"])  # NaN-aware, to the last digit
    return out


def markdown(result: dict) -> str:
    cells = result["settings"]["cells"]
    rows = ["| runner | cells | chunk | tasks | seconds | cells/s | speed-up | 10^5 cells |", "|---|---:|---:|---:|---:|---:|---:|---:|"]
    for where, part, count, base in (
        ("Dask, 2 workers", result["dask"], cells, "one cell per task"),
        ("in process, 1 core", result["in_process"], result["settings"]["in_process_cells"], "one cell per call"),
    ):
        for name, row in part.items():
            tasks = row.get("tasks", "-")
            speed = row["cells_per_s"] / part[base]["cells_per_s"]
            hours = PRACTICAL / row["cells_per_s"] / 3600
            rows.append(
                f"| {where}, {name} | {count} | {row['chunk']} | {tasks} | {row['seconds']:.1f} | {row['cells_per_s']:.1f} | {speed:.2f}x | {hours:.2f} h |"
            )
    return "\n".join(rows)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--cells", type=int, default=2000, help="cells of the study (default 2000)")
    parser.add_argument("--in-process", type=int, default=250, help="cells of the in-process comparison (default 250)")
    parser.add_argument("--quick", action="store_true", help="200 cells, 100 in process")
    parser.add_argument("--json", action="store_true", help="also print the JSON on stdout (the log goes to stderr)")
    args = parser.parse_args(argv)
    cells, local = (200, 100) if args.quick else (args.cells, args.in_process)

    def log(message: str) -> None:
        print(message, file=sys.stderr if args.json else sys.stdout, flush=True)

    env = harness.environment()
    log(f"package {harness.package_label(env)}; load average {env['loadavg_start']}")
    spec = study_spec(cells)
    result = {
        "environment": env,
        "settings": {
            "cells": cells,
            "in_process_cells": min(local, cells),
            "model": MODEL,
            "loads": LOADS,
            "t_max": T_MAX,
            "workers": WORKERS,
            "a": [0.1, 0.3],
        },
        "free_cores_start": harness.free_cores(),
        "in_process": in_process(spec, local, log),
        "dask": on_dask(spec, log),
        "free_cores_end": harness.free_cores(),
        "loadavg_end": list(os.getloadavg()),
    }
    table = markdown(result)
    result["markdown"] = table
    RESULTS.mkdir(exist_ok=True)
    output = RESULTS / ("study-quick.json" if args.quick else "study.json")
    output.write_text(json.dumps(result, indent=1) + "\n")
    log(f"\n{table}\n\nwrote {output}")
    if args.json:
        print(json.dumps(result))
    return 0


if __name__ == "__main__":
    sys.exit(main())
