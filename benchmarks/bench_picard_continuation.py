"""Cost of continuing a long chain's orbit in M: Newton-Picard steps against the blocks, per point.

Run from the repository root (one BLAS thread, CPU time)::

    OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1 python benchmarks/bench_picard_continuation.py --sizes 50 100
    python benchmarks/bench_picard_continuation.py --sizes 50 --points 4 --out /tmp/picard_continuation.json

The chain and moment of ``bench_long_orbits.py`` (the sine chain, all gammas 1, M = 0.3 on
particle 0). For each N: the orbit by Newton-Picard from the settled guess, then from that orbit,
interleaved, ``continue_orbit(..., method="picard")`` and ``continue_orbit(..., method="blocks")``
over ``--points`` points (the start included; first step :data:`STEP`): CPU seconds of each branch
and per point beyond the start, the variational columns integrated (``products``), the load
average before and after, and per point the moment, the period, the corrector's iterations, the
largest nontrivial multiplier and how many multipliers the point carries; the two branches point
by point (they take the same steps where their corrections take as many iterations): the largest
differences of moment and period, and of the period less the branch's slope times the moment's. Results go to ``benchmarks/results/picard_continuation.json``
(``docs/periodic-orbits.md``, Continuation of long chains' orbits).
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path

import numpy as np

from cosserat_chain import ChainParams
from cosserat_chain.numerics import long_orbits
from cosserat_chain.numerics.periodic import continue_orbit, find_periodic_orbit, initial_guess
from cosserat_chain.state import n_free

RESULTS = Path(__file__).parent / "results"
MODEL, MOMENT, DAMPING = "sine", 0.3, 1.0
#: First arclength step in (y0, log T, M).
STEP = 0.01


class _Products:
    """Counts the variational columns of every Monodromy product (wraps ``Monodromy.apply``)."""

    def __init__(self) -> None:
        self.columns = 0
        apply = long_orbits.Monodromy.apply
        counter = self

        def counted(monodromy, columns):
            block = np.asarray(columns).reshape(monodromy.size, -1)
            counter.columns += block.shape[1] * (2 if np.iscomplexobj(block) else 1)
            return apply(monodromy, columns)

        long_orbits.Monodromy.apply = counted

    def take(self) -> int:
        out, self.columns = self.columns, 0
        return out


def measure(n: int, points: int, products: _Products) -> dict:
    params = ChainParams(N=n, gamma_u=DAMPING, gamma_v=DAMPING, gamma_phi=DAMPING)
    row = {"N": n, "size": 2 * n_free(params), "points": points, "step": STEP, "load_average": os.getloadavg()[0]}
    cpu = time.process_time()
    orbit = find_periodic_orbit(params, MODEL, MOMENT, guess=initial_guess(params, MODEL, MOMENT), method="picard")
    row["orbit_cpu_s"], row["orbit_products"] = time.process_time() - cpu, products.take()
    branches = {}
    for method in ("picard", "blocks"):
        load = os.getloadavg()[0]
        cpu = time.process_time()
        branch = continue_orbit(orbit, method=method, max_points=points, step=STEP)
        spent = time.process_time() - cpu
        branches[method] = branch
        row[method] = {
            "cpu_s": spent,
            "cpu_s_per_point": spent / max(1, len(branch.orbits) - 1),
            "products": products.take(),
            "load_average": load,
            "load_average_after": os.getloadavg()[0],
            "end": branch.end,
            "orbits": [
                {
                    "moment": o.moment,
                    "period": o.period,
                    "iterations": o.iterations,
                    "max_nontrivial_multiplier": o.max_multiplier,
                    "multipliers": int(o.multipliers.size),
                }
                for o in branch.orbits
            ],
        }
        print(f"N = {n} {method}: {spent:.1f} s CPU, {len(branch.orbits)} points, load {load:.1f}", file=sys.stderr, flush=True)
    row.update(compare(row))
    return row


def compare(row: dict) -> dict:
    """The two branches point by point (the same step sequence where both correct alike): the largest differences of
    moment and of period, and of the period less the branch's slope dT/dM times the moment's difference."""
    pairs = list(zip(row["picard"]["orbits"][1:], row["blocks"]["orbits"][1:], strict=False))
    if not pairs:
        return {"compared_points": 0}
    moments, periods = np.array([[a["moment"], b["moment"]] for a, b in pairs]), np.array([[a["period"], b["period"]] for a, b in pairs])
    first, last = row["blocks"]["orbits"][0], row["blocks"]["orbits"][-1]
    slope = (last["period"] - first["period"]) / (last["moment"] - first["moment"])
    d_moment, d_period = moments[:, 0] - moments[:, 1], periods[:, 0] - periods[:, 1]
    return {
        "compared_points": len(pairs),
        "moment_difference": float(np.max(np.abs(d_moment))),
        "period_difference": float(np.max(np.abs(d_period))),
        "period_difference_along_branch": float(np.max(np.abs(d_period - slope * d_moment))),
    }


def markdown(rows: list[dict]) -> str:
    lines = [
        "| N | 2 n_free | points | picard CPU s / point | blocks CPU s / point | ratio | columns picard / blocks | load | max dM, dT, dT - T' dM |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        p, b = r["picard"], r["blocks"]
        loads = [r["load_average"], p["load_average_after"], b["load_average_after"]]
        lines.append(
            f"| {r['N']} | {r['size']} | {r['points']} | {p['cpu_s_per_point']:.1f} | {b['cpu_s_per_point']:.1f} | "
            f"{p['cpu_s_per_point'] / b['cpu_s_per_point']:.2f} | {p['products']} / {b['products']} | "
            f"{min(loads):.1f}-{max(loads):.1f} | {r['moment_difference']:.1e}, {r['period_difference']:.1e}, "
            f"{r['period_difference_along_branch']:.1e} |"
        )
    return "\n".join(lines)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sizes", type=int, nargs="+", default=[50, 100], help="N values")
    parser.add_argument("--points", type=int, default=4, help="points of each branch, the start included")
    parser.add_argument("--out", type=Path, default=RESULTS / "picard_continuation.json")
    args = parser.parse_args()
    long_orbits.THREADS = 1
    products = _Products()
    rows = []
    for n in args.sizes:
        rows.append(measure(n, args.points, products))
        args.out.parent.mkdir(exist_ok=True)
        args.out.write_text(json.dumps(rows, indent=1))
        print(markdown(rows[-1:]).splitlines()[-1], flush=True)
    print(markdown(rows))


if __name__ == "__main__":
    main()
