"""Collocation of long chains: one orbit and its leading multipliers against N, with the factor's fill, against the
shooting's ``blocks`` method.

Run from the repository root::

    python benchmarks/bench_collocation_long.py                                   # sine and nonlinear, N = 10 ... 200
    python benchmarks/bench_collocation_long.py --models sine --sizes 10 20 50 100 200 500 --shooting-max 100

CPU seconds (``time.process_time``, one BLAS thread), each measured once (a long chain's run is long; the load
average is written with every row). For each model and N, from one settled guess (``initial_guess`` at M = 0.5,
the same tuple for both methods):

* ``find_collocation_orbit`` (NTST = 40, NCOL = 4, two mesh adaptations): the CPU of the whole solve (Newton on
  the nested-dissection factor, then the multipliers), the multipliers' own CPU (computed again at the solution:
  all of them by the periodic Schur form up to 2 n_free = ``ALL_MULTIPLIERS_UP_TO``, the leading ones by ARPACK
  above), the factorisations of the Newton solves and the largest nnz(L + U), and the same system's fill in
  SuperLU's minimum-degree order (``PERMUTATION``, the order used before) where N <= ``--minimum-degree-max``;
* the process's peak resident memory so far (``peak_memory_gb``: it never falls, so a row's is at least its own);
* ``find_periodic_orbit(method="blocks")`` (closure 1e-10, DOP853 rtol = atol = 1e-12) where N <= ``--shooting-max``:
  its CPU, and the differences of the periods and of the largest nontrivial multiplier.

Before each N the peak memory is estimated (``--gb-per-n`` per unit of N: the factors, the Jacobian's assembly and
the shooting's monodromy; 3.5 GB was measured at N = 100) and printed; an N whose estimate exceeds ``--memory-gb``
is skipped. Results go to
``benchmarks/results/collocation_long.json`` (``docs/collocation.md``, Long chains).
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import sys
import time
from pathlib import Path

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from cosserat_chain import ChainParams
from cosserat_chain.linalg.threads import one_blas_thread
from cosserat_chain.models.base import get_model
from cosserat_chain.numerics import collocation_core, periodic
from cosserat_chain.numerics.collocation import find_collocation_orbit
from cosserat_chain.numerics.periodic import find_periodic_orbit, initial_guess

RESULTS = Path(__file__).resolve().parent / "results"
SIZES = (10, 20, 50, 100, 200)
MOMENT = 0.5
SHOOTING = {"tol": 1e-10, "rtol": 1e-12, "atol": 1e-12}


def _cpu(function):
    start = time.process_time()
    result = function()
    return time.process_time() - start, result


class _Spy:
    """Counts the Newton factorisations and keeps the largest fill (wraps ``_SparseStep.__init__``)."""

    def __init__(self):
        self.steps = []
        self._original = collocation_core._SparseStep.__init__

    def __enter__(self):
        spy = self

        def init(step, *args, **kwargs):
            spy._original(step, *args, **kwargs)
            spy.steps.append(step)

        collocation_core._SparseStep.__init__ = init
        return self

    def __exit__(self, *exc):
        collocation_core._SparseStep.__init__ = self._original


def _minimum_degree_fill(problem, orbit) -> int:
    """nnz(L + U) of the same (fixed-M) Newton system at the orbit in SuperLU's minimum-degree order."""
    matrix = problem.evaluate(problem.pack(orbit.profile, orbit.period), True).matrix()
    factor = spla.splu(sp.csc_matrix(matrix), permc_spec=collocation_core.PERMUTATION)
    return int(factor.L.nnz + factor.U.nnz)


def row(model: str, n: int, shooting_max: int, minimum_degree_max: int) -> dict:
    params = ChainParams(N=n)
    guess = tuple(initial_guess(params, model, MOMENT))[:3]
    with _Spy() as spy:
        solve_s, orbit = _cpu(lambda: find_collocation_orbit(params, model, MOMENT, guess=guess))
    system = periodic._System(params, get_model(model), MOMENT, 0)
    shift = collocation_core._shift(system, orbit.particle_turns)
    problem = collocation_core._Collocation(system, orbit.mesh, orbit.ncol, shift, orbit.profile, free_moment=False)
    a_values, period = problem.evaluate(problem.pack(orbit.profile, orbit.period), True).data
    multipliers_s, found = _cpu(lambda: problem.floquet(a_values, period))
    out = {
        "model": model,
        "N": n,
        "phase_space_dimension": problem.n,
        "unknowns": problem.size,
        "period": orbit.period,
        "collocation_cpu_s": solve_s,
        "multipliers_cpu_s": multipliers_s,
        "multipliers": "all" if problem.n <= collocation_core.ALL_MULTIPLIERS_UP_TO else "leading",
        "multipliers_computed": int(found.values.size),
        "largest_multiplier_error": None if found.errors is None else float(np.max(found.errors)),
        "factorizations": sum(step.factorizations for step in spy.steps),
        "fill": max(step.fill for step in spy.steps),
        "fill_per_N": max(step.fill for step in spy.steps) / n,
        "minimum_degree_fill": _minimum_degree_fill(problem, orbit) if n <= minimum_degree_max else None,
        "trivial_error": orbit.trivial_multiplier_error,
        "max_multiplier": orbit.max_multiplier,
        "load_average": os.getloadavg()[0],
        "peak_memory_gb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1e6,
    }
    if n <= shooting_max:
        shot_s, shot = _cpu(lambda: find_periodic_orbit(params, model, MOMENT, guess=guess, method="blocks", **SHOOTING))
        out.update(
            {
                "blocks_cpu_s": shot_s,
                "period_difference": abs(shot.period - orbit.period),
                "max_multiplier_difference": abs(shot.max_multiplier - orbit.max_multiplier),
                "load_average_after": os.getloadavg()[0],
            }
        )
    return out


@one_blas_thread
def main(argv: list[str] | None = None) -> dict:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--models", nargs="+", default=["sine", "nonlinear"])
    parser.add_argument("--sizes", nargs="+", type=int, default=list(SIZES))
    parser.add_argument("--shooting-max", type=int, default=100, help="the blocks shooting up to this N")
    parser.add_argument("--minimum-degree-max", type=int, default=50, help="the minimum-degree fill up to this N")
    parser.add_argument("--gb-per-n", type=float, default=0.035, help="estimated peak memory per unit of N (GB)")
    parser.add_argument("--memory-gb", type=float, default=8.0, help="skip an N whose estimated peak memory exceeds this")
    args = parser.parse_args(argv)
    path = RESULTS / "collocation_long.json"
    results = json.loads(path.read_text()) if path.exists() else {}
    results.update({"benchmark": "collocation_long", "cpu": "time.process_time, one BLAS thread", "rows": results.get("rows", [])})
    for model in args.models:
        for n in args.sizes:
            estimate = args.gb_per_n * n
            print(f"{model} N={n}: about {estimate:.1f} GB of memory at the peak", file=sys.stderr, flush=True)
            if estimate > args.memory_gb:
                print(f"  skipped (--memory-gb {args.memory_gb:g})", file=sys.stderr, flush=True)
                continue
            measured = row(model, n, args.shooting_max, args.minimum_degree_max)
            print(json.dumps(measured), file=sys.stderr, flush=True)
            results["rows"] = [r for r in results["rows"] if (r["model"], r["N"]) != (model, n)] + [measured]
            RESULTS.mkdir(exist_ok=True)
            tmp = path.with_suffix(".json.tmp")
            tmp.write_text(json.dumps(results, indent=1) + "\n")
            tmp.replace(path)
    return results


if __name__ == "__main__":
    main()
