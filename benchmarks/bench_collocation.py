"""Collocation against shooting: one orbit against the chain's length, and orbits of growing period towards a SNIC.

Run from the repository root::

    python benchmarks/bench_collocation.py                       # all parts (about 10 minutes on one core)
    python benchmarks/bench_collocation.py --parts sizes         # only the chain lengths
    python benchmarks/bench_collocation.py --sizes 1 2 5 10 20 --repeats 3

CPU seconds (``time.process_time``, one BLAS thread), the two methods interleaved, each timed
``--repeats`` times and the least kept:

``sizes``
    The sine chain (eq. (2), default fields) at N = 1, 2, 5, 10 (``--sizes``) under the moment
    0.5 (above the N = 1 chain's static fold 0.468) on particle 0. From one settled guess
    (``initial_guess``, the same tuple for both): ``find_periodic_orbit`` by dense shooting
    (closure 1e-10, DOP853 rtol = atol = 1e-12) and ``find_collocation_orbit`` (NTST = 40,
    NCOL = 4, two mesh adaptations, max |R| 1e-10); the period, the largest nontrivial
    multiplier, each method's trivial multiplier's distance from 1 and the methods' differences.
``periods``
    The nonlinear N = 1 chain (the issue's ``orbit --model nonlinear --moment 0.3 --down-to
    0.1``), whose orbit ends at a saddle-node on the invariant circle: the orbits of period
    nearest 10, 30, 100, 300, 1000 on a collocation branch, each solved again from that orbit by
    shooting (closure 1e-8: 1e-10 does not converge at the longest periods) and by collocation
    from the CollocationOrbit (what a continuation step pays; NTST = 80), with both periods.
``branch``
    The whole branch from M = 0.3 until the period exceeds 2000 by ``continue_collocation``
    (NTST = 40; and with ``max_interval`` = 1 time unit, which keeps the damped modes'
    multipliers resolved), against the shooting's ``continue_orbit`` to each period
    ``--shooting-period-max`` (default 100 and 300; the issue's run to 2000 did not end in 30
    minutes). Each result is written as soon as it is measured.

Results go to ``benchmarks/results/collocation.json`` (``docs/collocation.md``).
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

from cosserat_chain import ChainParams
from cosserat_chain.linalg.threads import one_blas_thread
from cosserat_chain.numerics.collocation import continue_collocation, find_collocation_orbit
from cosserat_chain.numerics.periodic import continue_orbit, find_periodic_orbit, initial_guess

RESULTS = Path(__file__).resolve().parent / "results"
SIZES = (1, 2, 5, 10)
MOMENT = 0.5
SHOOTING = {"tol": 1e-10, "rtol": 1e-12, "atol": 1e-12}
LONG_SHOOTING = {"tol": 1e-8, "rtol": 1e-12, "atol": 1e-12}
PERIODS = (10.0, 30.0, 100.0, 300.0, 1000.0)
N1 = ChainParams(N=1)


def _cpu(function):
    """(CPU seconds, result) of one call."""
    start = time.process_time()
    result = function()
    return time.process_time() - start, result


def _interleaved(first, second, repeats: int):
    """The least CPU seconds of each of two calls, alternated ``repeats`` times, and their last results."""
    times, results = [np.inf, np.inf], [None, None]
    for _ in range(repeats):
        for k, function in enumerate((first, second)):
            seconds, results[k] = _cpu(function)
            times[k] = min(times[k], seconds)
    return times, results


def _distance(a: np.ndarray, b: np.ndarray) -> float:
    """Largest difference of the sorted moduli (multipliers carry no labels)."""
    return float(np.max(np.abs(np.sort(np.abs(a)) - np.sort(np.abs(b)))))


def sizes_part(sizes: tuple[int, ...], repeats: int) -> list[dict]:
    rows = []
    for n in sizes:
        params = ChainParams(N=n)
        guess = tuple(initial_guess(params, "sine", MOMENT))[:3]
        (shot_s, colloc_s), (shot, colloc) = _interleaved(
            lambda params=params, guess=guess: find_periodic_orbit(params, "sine", MOMENT, guess=guess, method="dense", **SHOOTING),
            lambda params=params, guess=guess: find_collocation_orbit(params, "sine", MOMENT, guess=guess),
            repeats,
        )
        rows.append(
            {
                "N": n,
                "phase_space_dimension": int(shot.multipliers.size),
                "period": shot.period,
                "shooting_cpu_s": shot_s,
                "collocation_cpu_s": colloc_s,
                "shooting_over_collocation": shot_s / colloc_s,
                "period_difference": abs(colloc.period - shot.period),
                "multiplier_difference": _distance(colloc.multipliers, shot.multipliers),
                "shooting_trivial_error": abs(shot.trivial_multiplier - 1.0),
                "collocation_trivial_error": colloc.trivial_multiplier_error,
                "max_multiplier": shot.max_multiplier,
            }
        )
        print(json.dumps(rows[-1]), file=sys.stderr, flush=True)
    return rows


def periods_part(repeats: int) -> list[dict]:
    start = find_collocation_orbit(N1, "nonlinear", 0.3, ntst=80)
    branch = continue_collocation(start, moment_min=0.1, period_max=1.2 * PERIODS[-1])
    rows = []
    for target in PERIODS:
        orbit = branch.orbits[int(np.argmin(np.abs(np.log(branch.period / target))))]
        guess = orbit.periodic_orbit()
        (shot_s, colloc_s), (shot, colloc) = _interleaved(
            lambda orbit=orbit, guess=guess: _or_none(
                lambda: find_periodic_orbit(N1, "nonlinear", orbit.moment, guess=guess, method="dense", **LONG_SHOOTING)
            ),
            lambda orbit=orbit: find_collocation_orbit(N1, "nonlinear", orbit.moment, guess=orbit, ntst=80),
            repeats,
        )
        rows.append(
            {
                "moment": orbit.moment,
                "period": colloc.period,
                "shooting_cpu_s": shot_s if shot is not None else None,
                "collocation_cpu_s": colloc_s,
                "shooting_over_collocation": shot_s / colloc_s if shot is not None else None,
                "shooting_period": shot.period if shot is not None else None,
                "relative_period_difference": abs(colloc.period / shot.period - 1.0) if shot is not None else None,
                "collocation_trivial_error": colloc.trivial_multiplier_error,
            }
        )
        print(json.dumps(rows[-1]), file=sys.stderr, flush=True)
    return rows


def _or_none(function):
    try:
        return function()
    except Exception as err:  # noqa: BLE001 - a benchmark records that a method failed, and why
        print(f"shooting failed: {err}", file=sys.stderr)
        return None


def branch_part(shooting_period_max: list[float], save) -> dict:
    start = find_collocation_orbit(N1, "nonlinear", 0.3)
    out: dict = {"shooting": []}
    for name, options in (("collocation", {}), ("collocation_max_interval_1", {"max_interval": 1.0})):
        seconds, branch = _cpu(lambda options=options: continue_collocation(start, moment_min=0.1, period_max=2000.0, **options))
        out[name] = {
            "cpu_s": seconds,
            "points": len(branch.orbits),
            "end": str(branch.end),
            "last_period": float(branch.period[-1]),
            "last_moment": float(branch.moment[-1]),
            "last_ntst": branch.orbits[-1].ntst,
            "worst_trivial_error": float(max(o.trivial_multiplier_error for o in branch.orbits)),
            "message": branch.message,
        }
        print(json.dumps({name: out[name]}), file=sys.stderr, flush=True)
        save(out)
    shot = find_periodic_orbit(N1, "nonlinear", 0.3)
    for period_max in shooting_period_max:
        seconds, branch = _cpu(lambda period_max=period_max: continue_orbit(shot, moment_min=0.1, period_max=period_max, max_points=5000))
        out["shooting"].append(
            {
                "cpu_s": seconds,
                "period_max": period_max,
                "points": len(branch.orbits),
                "end": str(branch.end),
                "last_period": float(branch.orbits[-1].period),
                "last_moment": float(branch.orbits[-1].moment),
            }
        )
        print(json.dumps(out["shooting"][-1]), file=sys.stderr, flush=True)
        save(out)
    return out


@one_blas_thread
def main(argv: list[str] | None = None) -> dict:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--parts", nargs="+", default=["sizes", "periods", "branch"], choices=["sizes", "periods", "branch"])
    parser.add_argument("--sizes", nargs="+", type=int, default=list(SIZES))
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--shooting-period-max", nargs="+", type=float, default=[100.0, 300.0])
    parser.add_argument("--json", action="store_true", help="also print the results on stdout")
    args = parser.parse_args(argv)
    results: dict = {"benchmark": "collocation", "cpu": "time.process_time, one BLAS thread"}
    path = RESULTS / "collocation.json"
    if path.exists():
        results.update(json.loads(path.read_text()))

    def save(part: str):
        def write(rows) -> None:
            results[part] = rows
            RESULTS.mkdir(exist_ok=True)
            tmp = path.with_suffix(".json.tmp")
            tmp.write_text(json.dumps(results, indent=1) + "\n")
            tmp.replace(path)

        return write

    if "sizes" in args.parts:
        save("sizes")(sizes_part(tuple(args.sizes), args.repeats))
    if "periods" in args.parts:
        save("periods")(periods_part(args.repeats))
    if "branch" in args.parts:
        branch_part(args.shooting_period_max, save("branch"))
    if args.json:
        print(json.dumps(results, indent=1))
    return results


if __name__ == "__main__":
    main()
