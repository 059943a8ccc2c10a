"""Cost of find_equilibrium's descent against the chain's length: Frenkel-Kontorova kinks started between sites.

Run from the repository root::

    OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1 python benchmarks/bench_kink_descent.py          # N = 10^3, 10^4, 10^5
    OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1 python benchmarks/bench_kink_descent.py --quick  # N = 10^3, 10^4

What is measured: ``equilibria.find_equilibrium`` on the free Frenkel-Kontorova chain (V = 1) at
C = 2 and 8 from the arctan kink 4 arctan exp((i - c) / sqrt(C)) centred a quarter site off the
middle site (Newton diverges, the descent finds the minimum between sites) and half a site off
(Newton converges in 3 iterations: the reference cost). CPU seconds of this process
(``time.process_time``, one BLAS thread), the median of ``--rounds`` rounds, the two starts
interleaved; the steps of each solver; the exponent of CPU time against N fitted over the sizes.
The load average is recorded with the results, which go to ``benchmarks/results/kink_descent.json``.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import time
from pathlib import Path

import numpy as np

from cosserat_chain.numerics import equilibria, kit
from cosserat_chain.systems.frenkel_kontorova import frenkel_kontorova


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true")
    parser.add_argument("--rounds", type=int, default=3)
    args = parser.parse_args()
    sizes = (1001, 10001) if args.quick else (1001, 10001, 100001)
    steps: list[tuple[str, int]] = []
    corrector = kit.newton

    def counted(*positional, **named):
        result = corrector(*positional, **named)
        steps.append((str(result.status), result.iterations))
        return result

    equilibria.newton = counted
    rows = []
    for coupling in (2.0, 8.0):
        for sites in sizes:
            system = frenkel_kontorova(sites, C=coupling)
            times: dict[float, list[float]] = {0.25: [], 0.5: []}
            solvers: dict[float, list] = {}
            for _ in range(args.rounds):
                for offset in times:
                    start = 4 * np.arctan(np.exp(np.clip((np.arange(sites) - (sites - 1) / 2 - offset) / math.sqrt(coupling), -700, 700)))
                    steps.clear()
                    before = time.process_time()
                    found = equilibria.find_equilibrium(system, start)
                    times[offset].append(time.process_time() - before)
                    solvers[offset] = [found.method, found.index, list(steps)]
            for offset, spent in times.items():
                row = {
                    "C": coupling,
                    "sites": sites,
                    "offset": offset,
                    "method": solvers[offset][0],
                    "index": solvers[offset][1],
                    "corrections": solvers[offset][2],
                    "cpu_s": float(np.median(spent)),
                }
                rows.append(row)
                print(json.dumps(row), flush=True)
    exponents = {}
    for coupling in (2.0, 8.0):
        for offset in (0.25, 0.5):
            chosen = [r for r in rows if r["C"] == coupling and r["offset"] == offset]
            fit = np.polyfit(np.log([r["sites"] for r in chosen]), np.log([r["cpu_s"] for r in chosen]), 1)[0]
            exponents[f"C={coupling:g} offset={offset:g}"] = float(fit)
    result = {"rows": rows, "cpu_exponent_in_N": exponents, "load_average": os.getloadavg()}
    print(json.dumps({"cpu_exponent_in_N": exponents, "load_average": result["load_average"]}))
    out = Path(__file__).parent / "results" / ("kink_descent-quick.json" if args.quick else "kink_descent.json")
    out.write_text(json.dumps(result, indent=1) + "\n")


if __name__ == "__main__":
    main()
