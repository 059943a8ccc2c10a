"""CPU of a two-worker Dask ``LocalCluster`` that starts, runs one task and waits (benchmarks/suite-times.md, seventh round).

The test suite's shared cluster and the studies' embedded ones mostly wait between tests. Run with and without the
suite's settings (tests/conftest.py: no worker profiler, slower liveness ticks and system samples)::

    python benchmarks/bench_dask_idle.py plain 30
    python benchmarks/bench_dask_idle.py quiet 30

It prints the test process's CPU while starting and while idle, and the workers' (its children's) whole CPU.
"""

import os
import resource
import sys
import time

QUIET = {
    "distributed.worker.profile.enabled": False,
    "distributed.admin.tick.interval": "1s",
    "distributed.admin.system-monitor.interval": "5s",
}


def main() -> None:
    os.environ["OPENBLAS_NUM_THREADS"] = "1"
    import dask
    import dask.distributed

    mode, idle = sys.argv[1], float(sys.argv[2])
    c0 = time.process_time()
    with dask.config.set(QUIET if mode == "quiet" else {}):
        cluster = dask.distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True, host="127.0.0.1", dashboard_address=None)
        with dask.distributed.Client(cluster) as client:
            client.submit(sum, [1, 2]).result()
        c1 = time.process_time()
        time.sleep(idle)
        c2 = time.process_time()
        cluster.close()
    kids = resource.getrusage(resource.RUSAGE_CHILDREN)
    print(
        f"{mode}: start {c1 - c0:.2f} s, idle {c2 - c1:.2f} s (test process), workers {kids.ru_utime + kids.ru_stime:.2f} s, "
        f"load {os.getloadavg()[0]:.1f}"
    )


if __name__ == "__main__":
    main()
