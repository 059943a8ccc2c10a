"""Cost of the periodic-orbit machinery against the chain's length: the flow with and without its monodromy.

Run from the repository root::

    python benchmarks/bench_orbit_scaling.py          # about 10 minutes on one core
    python benchmarks/bench_orbit_scaling.py --json   # also print the JSON on stdout

For the sine and the nonlinear model, N = 3, 10, 20, 30, 50: CPU seconds per unit time of
integration of the state alone and of the state with the variational equations (the
monodromy matrix dPhi_T/dy0 and dPhi_T/dM, 2 n_free (2 n_free + 1) numbers), their force
Jacobian exact from the model's bond kernel and, interleaved, by the coloured differences
of its force kernel (the model without its bond kernel: what a model that has none gets),
from a moving state, with the shooting's tolerances (rtol = atol = 1e-11); the memory of
the variational state; and the time of the dense Floquet eigenproblem of that size. Results go to
``benchmarks/results/orbit_scaling.json`` (``docs/periodic-orbits.md``).
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np
import scipy.linalg as la

from cosserat_chain import ChainParams
from cosserat_chain.models.base import get_model
from cosserat_chain.numerics.periodic import _System

RESULTS = Path(__file__).resolve().parent / "results"
SIZES = (3, 10, 20, 30, 50)
MODELS = ("sine", "nonlinear")
SPAN = 10.0


def _without_bond_kernel(model):
    return type(f"{type(model).__name__}WithoutBonds", (type(model),), {"bond_kernel": None})()


def measure(model: str, n: int) -> dict:
    params = ChainParams(N=n)
    exact = _System(params, get_model(model), 1.5 * 0.64 / n, 0)  # above the sine fold, about 0.64 / N
    differences = _System(params, _without_bond_kernel(get_model(model)), exact.moment, 0)
    rng = np.random.default_rng(0)
    y0 = np.concatenate([0.3 * rng.standard_normal(exact.nf), 0.01 * rng.standard_normal(exact.nf)])
    for system in (exact, differences):
        system.flow(y0, 0.1, rtol=1e-11, atol=1e-11, variations=True)  # compile outside the timing
    times = {}
    for key, system, variations in (("state", exact, False), ("exact", exact, True), ("differences", differences, True)):
        start = time.process_time()
        system.flow(y0, SPAN, rtol=1e-11, atol=1e-11, variations=variations)
        times[key] = (time.process_time() - start) / SPAN
    size = 2 * exact.nf
    matrix = rng.standard_normal((size, size))
    start = time.process_time()
    la.eigvals(matrix)
    return {
        "model": model,
        "N": n,
        "state_only_s_per_time": times["state"],
        "with_monodromy_s_per_time": times["exact"],
        "with_monodromy_differences_s_per_time": times["differences"],
        "monodromy_memory_MB": size * (size + 1) * 8 / 1e6,
        "floquet_eigenvalues_s": time.process_time() - start,
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--json", action="store_true", help="print the results as one JSON object")
    args = parser.parse_args()
    log = sys.stderr if args.json else sys.stdout
    rows = []
    print(
        "| model | N | state only (s per unit time) | with the monodromy (exact Jacobian) | (differences) | its memory (MB) "
        "| Floquet eigenvalues (s) |\n|---|---|---|---|---|---|---|",
        file=log,
    )
    for model in MODELS:
        for n in SIZES:
            row = measure(model, n)
            rows.append(row)
            print(
                f"| {model} | {n} | {row['state_only_s_per_time']:.2g} | {row['with_monodromy_s_per_time']:.2g} | "
                f"{row['with_monodromy_differences_s_per_time']:.2g} | {row['monodromy_memory_MB']:.2g} | "
                f"{row['floquet_eigenvalues_s']:.2g} |",
                file=log,
                flush=True,
            )
    RESULTS.mkdir(exist_ok=True)
    (RESULTS / "orbit_scaling.json").write_text(json.dumps(rows, indent=1))
    if args.json:
        print(json.dumps(rows))


if __name__ == "__main__":
    main()
