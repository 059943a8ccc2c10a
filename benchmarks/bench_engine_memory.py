"""Fresh memory of a long chain's run: system time and page faults of `integrate` at 10^6 particles, by stage.

Run from the repository root::

    python benchmarks/bench_engine_memory.py            # 3 calls of 300 steps, about 15 s
    python benchmarks/bench_engine_memory.py --calls 5 --particles 1000001 --steps 300

What is measured: ``integrate(params, "nonlinear", moment_load(0.05, 0), n_frames=2,
threads=1)`` from a moving chain (``harness.moving_state``), called back to back in one
process; for each call the calling thread's system and user time and its minor page faults
(``resource.getrusage(RUSAGE_THREAD)``), in total and inside ``Blocks.__init__`` (each
block's copy of x, v, f and the winding), ``Blocks.advance`` (the chunks of steps) and
``Blocks._gather`` (the blocks' columns back into the chain). A buffer made once a run and
touched once shows as faults at the set-up and none in the chunks. Prints one JSON object.
"""

from __future__ import annotations

import argparse
import json
import resource

import harness
from cosserat_chain import ChainParams, moment_load
from cosserat_chain.numerics import engine
from cosserat_chain.numerics.dynamics import integrate
from cosserat_chain.numerics.integrators import default_time_step

STAGES = ("__init__", "advance", "_gather")


def usage() -> tuple[float, float, int]:
    r = resource.getrusage(resource.RUSAGE_THREAD)
    return r.ru_stime, r.ru_utime, r.ru_minflt


def difference(before, after) -> dict:
    return {"system_s": after[0] - before[0], "user_s": after[1] - before[1], "minor_faults": after[2] - before[2]}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--calls", type=int, default=3)
    parser.add_argument("--particles", type=int, default=1_000_001)
    parser.add_argument("--steps", type=int, default=300)
    args = parser.parse_args()
    totals: dict = {}

    def measured(name, method):
        def wrapper(*a, **k):
            before = usage()
            out = method(*a, **k)
            for key, value in difference(before, usage()).items():
                totals.setdefault(name, {}).setdefault(key, 0)
                totals[name][key] += value
            return out

        return wrapper

    for name in STAGES:
        setattr(engine.Blocks, name, measured(f"Blocks.{name}", getattr(engine.Blocks, name)))
    params = ChainParams(N=(args.particles - 1) // 2)
    dt = default_time_step(params)
    x0, v0 = harness.moving_state(params)
    calls = []
    for _ in range(args.calls):
        totals.clear()
        before = usage()
        integrate(params, "nonlinear", moment_load(0.05, 0), t_end=args.steps * dt, dt=dt, x0=x0, v0=v0, n_frames=2, threads=1)
        calls.append({"whole call": difference(before, usage()), **{k: dict(v) for k, v in totals.items()}})
    print(json.dumps({"particles": args.particles, "steps": args.steps, "calls": calls, "environment": harness.environment()}, indent=1))


if __name__ == "__main__":
    main()
