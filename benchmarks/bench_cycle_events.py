"""Cost and agreement of the period doublings and tori that ``continue_orbit`` locates, on every route.

Run from the repository root (one BLAS thread, CPU time)::

    OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1 python benchmarks/bench_cycle_events.py --repeats 3

The sine chain's one-turn orbit from 1.1 M_c down to its first unstable orbit (``until_unstable``), on the
paper's default chain (a torus) and at gamma_phi = 0.15 (a period doubling): for each method (dense, blocks,
picard) the branch with the location (``cycle_events.locate_circle_events``) and without it (the locator
replaced by one that finds nothing), interleaved ``--repeats`` times; CPU seconds (the least of the repeats),
the location's trials (orbits re-solved), the located moment, the critical multiplier's distance from -1 or the
circle, and the shooting's augmented Newton (``cycle_curve.locate_cycle_end``) for comparison. The load average
is written before and after. Results go to ``benchmarks/results/cycle_events.json`` (docs/periodic-orbits.md,
Period doublings and tori on every route).
"""

from __future__ import annotations

import argparse
import json
import os
import time
from pathlib import Path

import numpy as np

from cosserat_chain import ChainParams
from cosserat_chain.numerics import cycle_events, periodic
from cosserat_chain.numerics.continuation import locate_fold
from cosserat_chain.numerics.cycle_curve import locate_cycle_end

RESULTS = Path(__file__).parent / "results"
CASES = {"torus": ChainParams(), "period_doubling": ChainParams(gamma_phi=0.15)}
METHODS = ("dense", "blocks", "picard")


def run(start, method: str, locate: bool) -> tuple[float, periodic.OrbitBranch, int]:
    """CPU seconds of the branch, the branch, and the location's trials."""
    original = cycle_events.locate_circle_events
    trials = []

    def counted(orbits, solve, **options):
        def solve_counted(moment, a, b):
            trials.append(moment)
            return solve(moment, a, b)

        return original(orbits, solve_counted, **options) if locate else []

    periodic.cycle_events.locate_circle_events = counted
    try:
        t = time.process_time()
        branch = periodic.continue_orbit(start, period_max=100.0, until_unstable=True, method=method)
        return time.process_time() - t, branch, len(trials)
    finally:
        periodic.cycle_events.locate_circle_events = original


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--out", type=Path, default=RESULTS / "cycle_events.json")
    args = parser.parse_args()
    out = {"load_before": os.getloadavg(), "cases": []}
    for kind, params in CASES.items():
        start = periodic.find_periodic_orbit(params, "sine", 1.1 * locate_fold(params, "sine").moment)
        for method in METHODS:
            with_, without, trials, branch = [], [], 0, None
            for _ in range(args.repeats):
                seconds, branch, trials = run(start, method, True)
                with_.append(seconds)
                without.append(run(start, method, False)[0])
            (event,) = [e for e in branch.events if e["kind"] == kind]
            index = int(np.argmin(branch.stable))
            augmented = locate_cycle_end(branch.orbits[index - 1 : index + 1], kind)
            mu = complex(*event["multiplier"])
            row = {
                "kind": kind,
                "method": method,
                "orbits": len(branch.orbits),
                "cpu_with_location": min(with_),
                "cpu_without_location": min(without),
                "trials": trials,
                "moment": event["moment"],
                "augmented_newton": augmented.moment,
                "critical_off_circle": abs(mu + 1.0) if kind == "period_doubling" else abs(abs(mu) - 1.0),
            }
            out["cases"].append(row)
            print(json.dumps(row))
    out["load_after"] = os.getloadavg()
    args.out.write_text(json.dumps(out, indent=1))
    print("load", out["load_before"], out["load_after"])


if __name__ == "__main__":
    main()
