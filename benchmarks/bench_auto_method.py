"""Where ``method="auto"`` should pick Newton-Picard: blocks against picard, interleaved, near the crossover.

Run from the repository root (one BLAS thread, CPU time)::

    OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1 python benchmarks/bench_auto_method.py --sizes 20 30 --cases sine nonlinear random0 random1
    python benchmarks/bench_auto_method.py --sizes 50 --cases sine --points 3 --out /tmp/auto.json

Cases (all gammas 1 as in ``bench_long_orbits.py``, the moment on particle 0): ``sine`` and
``nonlinear``, the paper's chain (other fields default); ``random0``, ``random1``, the sine
model on random admissible geometries (the ranges of ``tests/conftest.py``'s random geometries:
h in (0.5, 2), a in (0.05, 0.45) h, b in (0.05, 0.6) h, E1 in (0.5, 2), E2 in (0, 3), m in
(0.5, 2); drawn with seed :data:`SEED`, N set per row). The moment is
:data:`FACTOR` times the case's M_c (``critical_point`` without the dynamics). For each case and
N, interleaved: ``find_periodic_orbit`` with ``method="blocks"`` and with ``method="picard"``,
each from its own default guess (picard's is continued by ``PICARD_SETTLE`` settled runs; both
CPU times include the guess), then with ``--points`` > 1 ``continue_orbit`` from the blocks'
orbit by each method over that many points. Recorded: CPU seconds, the load average before
each, convergence (a failure with its message), iterations, the period and the largest
nontrivial multiplier, and the two orbits' period difference. Results go to
``benchmarks/results/auto_method.json`` (merged by case and N; ``benchmarks/README.md``).
"""

from __future__ import annotations

import argparse
import json
import os
import time
from pathlib import Path

import numpy as np

from cosserat_chain import ChainParams
from cosserat_chain.experiments.critical import critical_point
from cosserat_chain.numerics.periodic import OrbitError, continue_orbit, find_periodic_orbit

RESULTS = Path(__file__).parent / "results"
DAMPING = 1.0
#: The moment as a multiple of the case's M_c.
FACTOR = 10.0
#: Seed of the random geometries.
SEED = 12


def case(name: str, n: int) -> tuple[ChainParams, str]:
    """The chain and model of ``name`` at length ``n``."""
    gammas = {"gamma_u": DAMPING, "gamma_v": DAMPING, "gamma_phi": DAMPING}
    if name in ("sine", "nonlinear"):
        return ChainParams(N=n, **gammas), name
    rng = np.random.default_rng(SEED)
    for _ in range(int(name.removeprefix("random")) + 1):
        h = rng.uniform(0.5, 2.0)
        fields = {"E1": rng.uniform(0.5, 2.0), "E2": rng.uniform(0.0, 3.0), "h": h, "a": rng.uniform(0.05, 0.45) * h,
                  "b": rng.uniform(0.05, 0.6) * h, "m": rng.uniform(0.5, 2.0)}  # fmt: skip
    return ChainParams(N=n, **fields, **gammas), "sine"


def orbit_row(run) -> dict:
    load = os.getloadavg()[0]
    cpu = time.process_time()
    try:
        orbit = run()
    except OrbitError as err:
        return {"converged": False, "message": str(err), "cpu_s": time.process_time() - cpu, "load_average": load}, None
    row = {"converged": True, "cpu_s": time.process_time() - cpu, "load_average": load}
    if hasattr(orbit, "orbits"):
        row.update(points=len(orbit.orbits), end=str(orbit.end), moments=[o.moment for o in orbit.orbits])
    else:
        nontrivial = np.abs(orbit.multipliers)[1:] if len(orbit.multipliers) > 1 else np.array([0.0])
        row.update(iterations=orbit.iterations, period=orbit.period, largest_nontrivial=float(np.max(nontrivial)))
    return row, orbit


def measure(name: str, n: int, points: int) -> dict:
    params, model = case(name, n)
    cpu = time.process_time()
    mc = critical_point(params, model, dynamics=False).critical_moment
    moment = FACTOR * mc
    row = {"case": name, "N": n, "model": model, "M_c": mc, "moment": moment, "critical_cpu_s": time.process_time() - cpu}
    orbits = {}
    for method in ("blocks", "picard"):
        row[method], orbits[method] = orbit_row(lambda method=method: find_periodic_orbit(params, model, moment, method=method))
        print(name, n, method, row[method], flush=True)
    if orbits["blocks"] is not None and orbits["picard"] is not None:
        row["period_difference"] = abs(orbits["blocks"].period - orbits["picard"].period)
    start = orbits["blocks"] or orbits["picard"]
    if points > 1 and start is not None:
        for method in ("blocks", "picard"):
            row[f"continuation_{method}"], _ = orbit_row(
                lambda method=method: continue_orbit(start, method=method, max_points=points, step=0.01)
            )
            print(name, n, "continuation", method, row[f"continuation_{method}"], flush=True)
    return row


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sizes", type=int, nargs="+", default=[20, 30, 50, 75])
    parser.add_argument("--cases", nargs="+", default=["sine", "nonlinear", "random0", "random1"])
    parser.add_argument("--points", type=int, default=0, help="continuation points (the start included); 0: none")
    parser.add_argument("--out", type=Path, default=RESULTS / "auto_method.json")
    args = parser.parse_args()
    rows = json.loads(args.out.read_text())["rows"] if args.out.exists() else []
    for n in args.sizes:
        for name in args.cases:
            new = measure(name, n, args.points)
            rows = [r for r in rows if (r["case"], r["N"]) != (name, n)] + [new]
            args.out.write_text(json.dumps({"rows": rows}, indent=1) + "\n")


if __name__ == "__main__":
    main()
