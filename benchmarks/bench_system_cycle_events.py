"""Cost and accuracy of the period doublings and tori that a user system's ``shooting.continue_orbits`` locates.

Run from the repository root (one BLAS thread, CPU time)::

    OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1 python benchmarks/bench_system_cycle_events.py --repeats 5

AUTO-07p's ``pen`` demo followed down in I from its in-phase rotation at I = 0.4 to its period doubling
(``stop_at=("period_doubling",)``), against AUTO's 0.17916377626; the rotor beside a circulatory oscillator of
``tests/test_system_cycle_events.py`` followed up in a through its torus, against the closed form c sqrt(k). CPU
seconds of each branch (the least of ``--repeats``), the located value, its distance from the reference and the
critical multiplier's from -1 or the circle. The same script on an older tree (its ``src`` first on PYTHONPATH)
measures that tree, to be interleaved with this one. The load average is written before and after; ``--out``
writes the JSON (docs/periodic-orbits.md, Period doublings and tori on every route).
"""

from __future__ import annotations

import argparse
import json
import math
import os
import sys
import time
from pathlib import Path

import numpy as np

from cosserat_chain.numerics import shooting
from cosserat_chain.systems import pen

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))
from test_system_cycle_events import AUTO_PERIOD_DOUBLING, rotation  # noqa: E402 - the test's system

RESULTS = Path(__file__).parent / "results"


def timed(repeats: int, run):
    """The least CPU seconds of ``repeats`` calls of ``run`` and its last result."""
    times = []
    for _ in range(repeats):
        start = time.process_time()
        result = run()
        times.append(time.process_time() - start)
    return min(times), result


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--out", type=Path, default=None, help="write the JSON here (e.g. benchmarks/results/system_cycle_events.json)")
    args = parser.parse_args()
    load = [os.getloadavg()[0]]
    system = pen()
    guess = shooting.settled_guess(system, np.array([0.0, 0.0, 2.0, 2.0]), coordinate="phi_0")
    orbit = shooting.find_orbit(system, guess, turns={"phi_0": 1, "phi_1": 1})
    start = rotation()
    cases = {
        "pen period_doubling in I": (
            lambda: shooting.continue_orbits(orbit, "I", direction=-1, max_points=60, stop_at=("period_doubling",)),
            "period_doubling",
            AUTO_PERIOD_DOUBLING,
        ),
        "rotor torus in a": (
            lambda: shooting.continue_orbits(start, "a", direction=1, limits=(0.0, 0.3), stop_at=()),
            "torus",
            0.2 * math.sqrt(1.5),
        ),
    }
    rows = []
    for name, (run, kind, reference) in cases.items():
        run()  # compiled once
        seconds, branch = timed(args.repeats, run)
        event = next(e for e in branch.events if e.kind == kind)
        mu = event.point.nontrivial_multipliers
        off = np.min(np.abs(mu + 1.0)) if kind == "period_doubling" else np.min(np.abs(np.abs(mu) - 1.0))
        rows.append(
            {
                "case": name,
                "cpu_s": seconds,
                "orbits": len(branch.orbits),
                "located": event.parameter,
                "reference": reference,
                "off_reference": event.parameter - reference,
                "critical_multiplier_off": float(off),
            }
        )
        print(json.dumps(rows[-1]))
    load.append(os.getloadavg()[0])
    print(f"load average before / after: {load[0]:.1f} / {load[1]:.1f}")
    if args.out is not None:
        args.out.write_text(json.dumps({"rows": rows, "load": load, "repeats": args.repeats}, indent=1) + "\n")


if __name__ == "__main__":
    main()
