"""Statics against the chain's length: cost per branch point, first fold, full-turn branch, M_c(N).

Run from the repository root::

    python benchmarks/bench_statics_scaling.py            # about 10 minutes on 2 cores
    python benchmarks/bench_statics_scaling.py --quick    # N <= 100 for the branches, about a minute
    python benchmarks/bench_statics_scaling.py --json     # also print the JSON on stdout

Measured for the paper's geometry, nonlinear and sine models:

* ``per_point``: the operations each continuation point repeats, at an equilibrium
  on the branch (the rotation-controlled state at phi_0 = 1): the compiled forces,
  the stiffness assembly, the banded stability (inertia and smallest eigenvalue) and
  one bordered solve (the compiled banded elimination, and SuperLU on the same system
  for comparison), for N = 10, 100, 1000, 10^4, with the exponent p of a fit
  time ~ N^p over N >= 100 (O(N) is p = 1);
* ``first_fold``: :func:`continue_in_moment` up to its first fold (where the stable
  branch from rest ends), for the same N (the sine model at N = 10^4 too: K's
  condition number there exceeds 1/eps, and its fold is off by a few 1e-6, which
  ``critical`` flags; ``M_c_exact`` = 1/compliance, the compliance refined in extended
  precision, gives the error);
* ``critical``: :func:`critical_point` over the whole turn for N up to ``--full-max``
  (default 1000): time, points, folds, whether the branch was complete, M_c and phi_0
  at the fold, ``accurate`` and ``confirmation`` (a second trace from N of about 1500).
  The long chain's branch meanders (N = 1000 passes about 40 folds before the loaded
  particle has turned once), so its time grows faster than N.

Results go to ``benchmarks/results/statics_scaling.json`` and the figure to
``docs/img/statics_scaling.png``.
"""

from __future__ import annotations

import argparse
import json
import platform
import statistics
import sys
import time
from pathlib import Path

import numpy as np

from cosserat_chain import ChainParams
from cosserat_chain.experiments.critical import critical_point
from cosserat_chain.linalg import bordered_jacobian, bordered_solve, sparse_solve
from cosserat_chain.models.base import get_model
from cosserat_chain.numerics.continuation import compliance, continue_in_moment
from cosserat_chain.numerics.newton import NewtonError, moment_dof, solve_rotation_controlled
from cosserat_chain.numerics.stability import static_stability

ROOT = Path(__file__).resolve().parent
RESULTS = ROOT / "results"
FIGURE = ROOT.parent / "docs" / "img" / "statics_scaling.png"
MODELS = ("nonlinear", "sine")
SIZES = (10, 100, 1000, 10000)
CRITICAL_SIZES = (3, 10, 20, 50, 100, 300, 1000)


def median_time(func, repeats: int = 5) -> float:
    """Median CPU time of ``func()`` (the statics are single-threaded)."""
    samples = []
    for _ in range(repeats):
        start = time.process_time()
        func()
        samples.append(time.process_time() - start)
    return statistics.median(samples)


def per_point(model: str, n: int) -> dict:
    params = ChainParams(N=n)
    kind = get_model(model)
    x, _ = solve_rotation_controlled(params, model, 1.0)
    stiffness = kind.stiffness(params, x)
    dof = moment_dof(params)
    row = np.ones(stiffness.shape[0] + 1)
    rhs = np.ones(stiffness.shape[0] + 1)
    guess = static_stability(params, model, x).critical_eigenvalue
    return {
        "N": n,
        "forces_s": median_time(lambda: kind.compiled_forces(params, x)),
        "stiffness_s": median_time(lambda: kind.stiffness(params, x)),
        "stability_s": median_time(lambda: static_stability(params, model, x)),
        "stability_with_guess_s": median_time(lambda: static_stability(params, model, x, guess=guess)),
        "bordered_solve_s": median_time(lambda: bordered_solve(stiffness, dof, row, rhs)),
        "bordered_solve_superlu_s": median_time(lambda: sparse_solve(bordered_jacobian(stiffness, dof, row), rhs)),
    }


def exponent(rows: list[dict], key: str) -> float:
    """Slope of log(time) against log(N) over N >= 100."""
    big = [r for r in rows if r["N"] >= 100]
    return float(np.polyfit(np.log([r["N"] for r in big]), np.log([r[key] for r in big]), 1)[0])


def first_fold(model: str, n: int) -> dict:
    start = time.process_time()
    try:
        branch = continue_in_moment(ChainParams(N=n), model, max_folds=1)
    except NewtonError as err:
        return {"N": n, "seconds": time.process_time() - start, "error": str(err)}
    seconds = time.process_time() - start
    fold = branch.folds[0] if branch.folds else None
    return {
        "N": n,
        "seconds": seconds,
        "points": int(branch.moment.size),
        "moment": None if fold is None else fold.moment,
        "phi0": None if fold is None else fold.phi0,
        "stop": branch.stop,
        # The sine model's fold is 1/(the rotation compliance) exactly: its error, from the refined compliance.
        "M_c_exact": 1.0 / compliance(ChainParams(N=n), model) if model == "sine" else None,
    }


def full_turn(model: str, n: int) -> dict:
    start = time.process_time()
    result = critical_point(ChainParams(N=n), model)
    return {
        "N": n,
        "seconds": time.process_time() - start,
        "points": int(result.branch.moment.size),
        "folds": len(result.branch.folds),
        "complete": result.complete,
        "stop": result.branch.stop,
        "M_c": result.critical_moment,
        "phi0_at_fold": result.phi0_at_fold,
        "first_fold": result.as_dict()["first_fold"],
        "accurate": result.accurate,
        "confirmation": result.confirmation,
        "compliance": result.compliance,
    }


def plot(data: dict, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (ax_cost, ax_mc) = plt.subplots(1, 2, figsize=(10, 4))
    for model, style in zip(MODELS, ("-", "--"), strict=True):
        rows = data["per_point"][model]
        n = [r["N"] for r in rows]
        for key, label in (("stiffness_s", "stiffness"), ("stability_with_guess_s", "stability"), ("bordered_solve_s", "bordered solve")):
            ax_cost.loglog(n, [r[key] for r in rows], style, marker="o", label=f"{model}: {label}")
        done = [r for r in data["first_fold"][model] if "seconds" in r and "error" not in r]
        ax_cost.loglog([r["N"] for r in done], [r["seconds"] for r in done], style, marker="s", color="k", label=f"{model}: first fold")
        rows = [r for r in data["critical"][model] if r["M_c"] is not None]
        ax_mc.semilogx(
            [r["N"] for r in rows],
            [r["M_c"] * (r["N"] if model == "sine" else 1.0) for r in rows],
            style,
            marker="o",
            label="nonlinear: M_c" if model == "nonlinear" else "sine: N M_c",
        )
    ax_cost.set_xlabel("N (2N+1 particles)")
    ax_cost.set_ylabel("CPU seconds")
    ax_cost.set_title("cost against chain length")
    ax_cost.legend(fontsize=6)
    ax_mc.set_xlabel("N")
    ax_mc.set_ylabel("moment (units of E1 h^2)")
    ax_mc.set_title("critical moment against N (paper's geometry)")
    ax_mc.legend(fontsize=8)
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=120)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="branches only up to N = 100")
    parser.add_argument("--full-max", type=int, default=1000, help="largest N of the full-turn branch")
    parser.add_argument("--json", action="store_true", help="print the results as one JSON object")
    args = parser.parse_args()
    log = sys.stderr if args.json else sys.stdout
    full_max = 100 if args.quick else args.full_max
    fold_sizes = tuple(n for n in SIZES if not args.quick or n <= 1000)
    critical_point(ChainParams(N=3), "nonlinear")  # compile the kernels outside the timings
    critical_point(ChainParams(N=3), "sine")
    data = {"per_point": {}, "exponents": {}, "first_fold": {}, "critical": {}}
    for model in MODELS:
        data["per_point"][model] = [per_point(model, n) for n in SIZES]
        data["exponents"][model] = {key: exponent(data["per_point"][model], key) for key in data["per_point"][model][0] if key != "N"}
        print(model, "per point", json.dumps(data["per_point"][model]), "exponents", data["exponents"][model], file=log, flush=True)
        data["first_fold"][model] = []
        for n in fold_sizes:
            data["first_fold"][model].append(first_fold(model, n))
            print(model, "first fold", data["first_fold"][model][-1], file=log, flush=True)
        data["critical"][model] = []
        for n in (n for n in CRITICAL_SIZES if n <= full_max):
            data["critical"][model].append(full_turn(model, n))
            print(model, "critical", data["critical"][model][-1], file=log, flush=True)
    data["environment"] = {"python": platform.python_version(), "machine": platform.machine(), "processor": platform.processor()}
    RESULTS.mkdir(exist_ok=True)
    name = "statics_scaling-quick.json" if args.quick else "statics_scaling.json"
    (RESULTS / name).write_text(json.dumps(data, indent=1))
    if not args.quick:
        plot(data, FIGURE)
    print("\n| model | N | points | folds | complete | M_c | phi_0 at fold | CPU s |\n|---|---|---|---|---|---|---|---|", file=log)
    for model in MODELS:
        for r in data["critical"][model]:
            mc = "-" if r["M_c"] is None else f"{r['M_c']:.6g}"
            phi = "-" if r["phi0_at_fold"] is None else f"{r['phi0_at_fold']:.4f}"
            print(f"| {model} | {r['N']} | {r['points']} | {r['folds']} | {r['complete']} | {mc} | {phi} | {r['seconds']:.2f} |", file=log)
    if args.json:
        print(json.dumps(data))


if __name__ == "__main__":
    main()
