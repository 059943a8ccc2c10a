"""Cost of the periodic-orbit machinery against the chain's length: the flow with and without its monodromy.

Run from the repository root::

    python benchmarks/bench_orbit_scaling.py          # about 10 minutes on one core
    python benchmarks/bench_orbit_scaling.py --json   # also print the JSON on stdout
    python benchmarks/bench_orbit_scaling.py --columns # where a block of variational columns spends its time (N = 50-200)

For the sine and the nonlinear model, N = 3, 10, 20, 30, 50: CPU seconds per unit time of
integration of the state alone and of the state with the variational equations (the
monodromy matrix dPhi_T/dy0 and dPhi_T/dM, 2 n_free (2 n_free + 1) numbers), their force
Jacobian exact from the model's bond kernel and, interleaved, by the coloured differences
of its force kernel (the model without its bond kernel: what a model that has none gets),
from a moving state, with the shooting's tolerances (rtol = atol = 1e-11); the memory of
the variational state; and the time of the dense Floquet eigenproblem of that size. Results go to
``benchmarks/results/orbit_scaling.json`` (``docs/periodic-orbits.md``).

``--columns``: for the sine chain of ``bench_long_orbits.py`` (all gammas 1, M = 0.3) at N = 50,
100, 200 (``--sizes``), from its settled rotation, CPU seconds per unit time and DOP853 steps of
the state alone and of the state with 1, 16 and 64 variational columns (what one block of the
``blocks`` shooting integrates), so a column's cost against the state's; and, interleaved,
the same steps (the package's step sizes, fixed) by a NumPy reference of the scheme, its stage
sums one BLAS matrix-vector product a stage (vectorised), its right-hand side the same compiled
one: CPU seconds per step of each, with the load average (``results/orbit_columns.json``).
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path

import numpy as np
import scipy.linalg as la

from cosserat_chain import ChainParams
from cosserat_chain.models.base import get_model
from cosserat_chain.numerics import dop853
from cosserat_chain.numerics.periodic import _System, _to_y, initial_guess

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


def _reference_steps(f, y0: np.ndarray, h: float, steps: int) -> np.ndarray:
    """``steps`` DOP853 steps of size h by NumPy: each stage's sum one BLAS product, the error estimate as the package forms it."""
    y, k = y0.copy(), np.empty((dop853.N_STAGES, y0.size))
    k[0] = f(0.0, y)
    for _ in range(steps):
        for s in range(1, dop853.N_STAGES):
            k[s] = f(0.0, y + h * (dop853.A[s, :s] @ k[:s]))
        y_new = y + h * (dop853.B @ k)
        scale = 1e-11 + np.maximum(np.abs(y), np.abs(y_new)) * 1e-11
        err5, err3 = np.sum(((dop853.E5 @ k) / scale) ** 2), np.sum(((dop853.E3 @ k) / scale) ** 2)
        assert np.isfinite(err5 + err3)
        y = y_new
        k[0] = f(0.0, y)
    return y


def columns(n: int, span: float) -> dict:
    """A column's cost against the state's at N = n, and the package's steps against the NumPy reference (``--columns``)."""
    params = ChainParams(N=n, gamma_u=1.0, gamma_v=1.0, gamma_phi=1.0)
    x, v, _ = initial_guess(params, "sine", 0.3)
    system = _System(params, get_model("sine"), 0.3, 0)
    y0 = _to_y(params, x, v)
    size = y0.size
    row = {"N": n, "size": size, "load_average": os.getloadavg()[0], "runs": {}}
    for ncols in (0, 1, 16, 64):
        parameters = system.parameters(ncols)
        start = np.concatenate([y0, np.eye(size)[:, :ncols].ravel()])

        def run(end: float, parameters=parameters, start=start) -> dop853.Solution:
            rhs, kernel, ends, coef, rpar, ipar = parameters
            return dop853.solve(rhs, kernel, coef, rpar, ipar, start, np.array([0.0, end]), rtol=1e-11, atol=1e-11, end_force=ends)

        run(0.01)  # compile outside the timing
        cpu = time.process_time()
        sol = run(span)
        package = time.process_time() - cpu
        entry = {"s_per_time": package / span, "steps": sol.steps, "package_s_per_step": package / sol.steps}
        if ncols:
            f = system.rhs(ncols)
            cpu = time.process_time()
            _reference_steps(f, start, span / sol.steps, sol.steps)
            entry["reference_s_per_step"] = (time.process_time() - cpu) / sol.steps
        row["runs"][ncols] = entry
    state = row["runs"][0]["s_per_time"]
    for ncols in (1, 16, 64):
        row["runs"][ncols]["column_over_state"] = (row["runs"][ncols]["s_per_time"] - state) / ncols / state
    row["load_average_after"] = os.getloadavg()[0]
    return row


COLUMNS_HEADER = (
    "| N | 2 n_free | columns | s per unit time | steps | a column / the state | package s per step | NumPy reference | load |\n"
    "|---|---|---|---|---|---|---|---|---|"
)
SCALING_HEADER = (
    "| model | N | state only (s per unit time) | with the monodromy (exact Jacobian) | (differences) | its memory (MB) "
    "| Floquet eigenvalues (s) |\n|---|---|---|---|---|---|---|"
)


def columns_lines(r: dict) -> list[str]:
    """The ``--columns`` table's rows of one N."""
    lines = []
    for ncols, e in r["runs"].items():
        ratio = f"{e['column_over_state']:.2f}" if ncols else "-"
        reference = f"{e['reference_s_per_step']:.3g}" if ncols else "-"
        lines.append(
            f"| {r['N']} | {r['size']} | {ncols} | {e['s_per_time']:.3g} | {e['steps']} | {ratio} | {e['package_s_per_step']:.3g} | "
            f"{reference} | {r['load_average']:.1f}-{r['load_average_after']:.1f} |"
        )
    return lines


def scaling_lines(row: dict) -> list[str]:
    """The default table's row of one model and N."""
    return [
        f"| {row['model']} | {row['N']} | {row['state_only_s_per_time']:.2g} | {row['with_monodromy_s_per_time']:.2g} | "
        f"{row['with_monodromy_differences_s_per_time']:.2g} | {row['monodromy_memory_MB']:.2g} | {row['floquet_eigenvalues_s']:.2g} |"
    ]


def _sweep(cases: list, measure_one, header: str, row_lines, out: Path, log, as_json: bool) -> None:
    """Print ``header``, then measure each case in turn, print its rows and rewrite ``out`` as each comes (an
    interrupted sweep keeps its rows); with ``as_json`` the rows as one JSON list on stdout."""
    print(header, file=log)
    table = []
    for case in cases:
        table.append(measure_one(case))
        print("\n".join(row_lines(table[-1])), file=log, flush=True)
        out.parent.mkdir(exist_ok=True)
        out.write_text(json.dumps(table, indent=1))
    if as_json:
        print(json.dumps(table))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--json", action="store_true", help="print the results as one JSON object")
    parser.add_argument("--columns", action="store_true", help="a block's columns against the state and a NumPy reference")
    parser.add_argument("--sizes", type=int, nargs="+", default=[50, 100, 200], help="N values of --columns")
    args = parser.parse_args()
    log = sys.stderr if args.json else sys.stdout
    if args.columns:
        _sweep(args.sizes, lambda n: columns(n, 2.0), COLUMNS_HEADER, columns_lines, RESULTS / "orbit_columns.json", log, args.json)
    else:
        cases = [(model, n) for model in MODELS for n in SIZES]
        _sweep(cases, lambda case: measure(*case), SCALING_HEADER, scaling_lines, RESULTS / "orbit_scaling.json", log, args.json)


if __name__ == "__main__":
    main()
