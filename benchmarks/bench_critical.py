"""Time to the critical moment: exact statics against the relaxation protocol, and critical_point against N.

Run from the repository root::

    python benchmarks/bench_critical.py            # both parts below
    python benchmarks/bench_critical.py --json     # also print one JSON object
    python benchmarks/bench_critical.py --scaling           # only critical_point against N, N = 10 ... 10^4
    python benchmarks/bench_critical.py --scaling --quick   # the same without N = 10^4 (about a minute)

**Against the relaxation protocol** (the paper's chain, N = 3; about a minute):

For each model that has a fold (nonlinear, sine), in the same run:

* ``fold``: :func:`~cosserat_chain.numerics.continuation.locate_fold`, M_c to round-off;
* ``continuation``: pseudo-arclength continuation from rest just past the fold,
  with the fold located on the way (:func:`continue_in_moment` with phi0_stop
  a little beyond the fold angle);
* ``relaxation``: the paper's protocol with load increment dM up to the onset of
  rotation (``stop_at_onset``), which brackets M_c only to within dM; run for
  dM = 1e-2 and 1e-3.

Reported: median wall times over repetitions, the ratio relaxation / fold, and the
error of each method's critical moment against the exact M_c (the relaxation's
onset load minus M_c is at most dM with strong enough damping, see tests).
Results go to ``benchmarks/results/critical.json``.

**critical_point against N** (``--scaling``; the paper's geometry, nonlinear model,
the whole turn of the loaded particle as ``cosserat-chain critical`` traces it): CPU
time (``time.process_time``: what a busy neighbour on the other core does not change)
and wall time of :func:`~cosserat_chain.experiments.critical.critical_point` for
N = 10, 100, 1000 and 10^4 (``--quick`` leaves out 10^4, whose turn runs into the
default point budget), with the points, folds, M_c and the cost per point, whose
growth with N is the O(N) claim (the number of points grows with the folds of the
branch, not with N itself). Results go to ``benchmarks/results/critical_scaling.json``
(``critical_scaling-quick.json`` for ``--quick``) and the figure, time against N on
log-log axes with a slope-1 guide, to ``docs/img/critical_scaling.png``.
"""

from __future__ import annotations

import argparse
import json
import platform
import statistics
import time
from pathlib import Path

from cosserat_chain import ChainParams
from cosserat_chain.experiments.critical import critical_point
from cosserat_chain.experiments.sweep import relaxation_sweep
from cosserat_chain.numerics.continuation import continue_in_moment, locate_fold

RESULTS = Path(__file__).resolve().parent / "results"
FIGURE = Path(__file__).resolve().parent.parent / "docs" / "img" / "critical_scaling.png"
MODELS = ("nonlinear", "sine")
RESOLUTIONS = (1e-2, 1e-3)
#: Chain lengths of the scaling part (``--quick`` drops those above 1000).
SCALING_SIZES = (10, 100, 1000, 10000)


def median_time(repeats: int, func, *args, **kwargs):
    """Median wall time of ``func(*args, **kwargs)`` over ``repeats`` calls, and its last value."""
    times, value = [], None
    for _ in range(repeats):
        start = time.perf_counter()
        value = func(*args, **kwargs)
        times.append(time.perf_counter() - start)
    return statistics.median(times), value


def critical_row(n: int, repeats: int) -> dict:
    """CPU and wall time of the full-turn :func:`critical_point` at N = ``n`` (medians over ``repeats``)."""
    cpu, wall, result = [], [], None
    for _ in range(repeats):
        start_cpu, start_wall = time.process_time(), time.perf_counter()
        result = critical_point(ChainParams(N=n), "nonlinear")
        cpu.append(time.process_time() - start_cpu)
        wall.append(time.perf_counter() - start_wall)
    points = int(result.branch.moment.size)
    return {
        "N": n,
        "cpu_seconds": statistics.median(cpu),
        "wall_seconds": statistics.median(wall),
        "cpu_samples": cpu,
        "wall_samples": wall,
        "points": points,
        "folds": len(result.branch.folds),
        "complete": result.complete,
        "stop": result.branch.stop,
        "M_c": result.critical_moment,
        "phi0_at_fold": result.phi0_at_fold,
        "cpu_ms_per_point": 1e3 * statistics.median(cpu) / points,
    }


def plot_scaling(rows: list[dict], path: Path) -> None:
    """Left: CPU and wall time of the full turn against N; right: CPU time a point. Log-log, slope-1 guides."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    n = [r["N"] for r in rows]
    fig, (ax_turn, ax_point) = plt.subplots(1, 2, figsize=(10, 4))
    ax_turn.loglog(n, [r["cpu_seconds"] for r in rows], "o-", label="CPU time")
    ax_turn.loglog(n, [r["wall_seconds"] for r in rows], "s--", label="wall time")
    ax_turn.loglog(n, [rows[-1]["cpu_seconds"] * m / n[-1] for m in n], ":", color="k", label="slope 1 (time ~ N)")
    for r in rows:
        ax_turn.annotate(
            f"{r['points']} points, {r['folds']} folds", (r["N"], r["cpu_seconds"]), textcoords="offset points", xytext=(4, -10), fontsize=7
        )
    ax_turn.set_title("critical_point, full turn (nonlinear, paper's geometry)", fontsize=9)
    ax_turn.set_ylabel("seconds")
    ax_point.loglog(n, [r["cpu_ms_per_point"] for r in rows], "o-", label="CPU time a point")
    ax_point.loglog(n, [rows[-1]["cpu_ms_per_point"] * m / n[-1] for m in n], ":", color="k", label="slope 1")
    ax_point.set_title("cost a branch point (the turn's time / its points)", fontsize=9)
    ax_point.set_ylabel("milliseconds")
    for ax in (ax_turn, ax_point):
        ax.set_xlabel("N (2N+1 particles)")
        ax.legend(fontsize=8)
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=120)


def scaling(quick: bool, repeats: int) -> dict:
    """The ``--scaling`` part: :func:`critical_row` for every size, the JSON and the figure."""
    critical_point(ChainParams(N=3), "nonlinear")  # compile the kernels outside the timings
    sizes = tuple(n for n in SCALING_SIZES if not quick or n <= 1000)
    rows = []
    for n in sizes:
        rows.append(critical_row(n, repeats if n <= 100 else 1))
        print(json.dumps({k: v for k, v in rows[-1].items() if not k.endswith("samples")}), flush=True)
    result = {"machine": platform.platform(), "python": platform.python_version(), "model": "nonlinear", "rows": rows}
    RESULTS.mkdir(exist_ok=True)
    (RESULTS / ("critical_scaling-quick.json" if quick else "critical_scaling.json")).write_text(json.dumps(result, indent=2) + "\n")
    if not quick:
        plot_scaling(rows, FIGURE)
    print("\n| N | points | folds | M_c | CPU s | wall s | CPU ms / point |\n|---:|---:|---:|---:|---:|---:|---:|")
    for r in rows:
        print(
            f"| {r['N']} | {r['points']} | {r['folds']} | {r['M_c']:.6g} | {r['cpu_seconds']:.3g} | {r['wall_seconds']:.3g} | {r['cpu_ms_per_point']:.3g} |"
        )
    return result


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--json", action="store_true", help="print the results as one JSON object")
    parser.add_argument("--scaling", action="store_true", help="only critical_point against N")
    parser.add_argument("--quick", action="store_true", help="with --scaling: leave out N = 10^4")
    args = parser.parse_args()
    if args.scaling:
        result = scaling(args.quick, args.repeats)
        if args.json:
            print(json.dumps(result))
        return
    params = ChainParams()
    locate_fold(params, "sine")  # compile the kernels outside the timings
    relaxation_sweep(params, "sine", m_max=0.1, steps=1)
    rows = []
    for model in MODELS:
        t_fold, fold = median_time(args.repeats, locate_fold, params, model)
        t_cont, branch = median_time(args.repeats, continue_in_moment, params, model, phi0_stop=fold.phi0 + 0.3)
        row = {
            "model": model,
            "M_c": fold.moment,
            "phi0_at_fold": fold.phi0,
            "fold_seconds": t_fold,
            "continuation_seconds": t_cont,
            "continuation_M_c_error": abs(branch.folds[0].moment - fold.moment),
            "relaxation": [],
        }
        for dm in RESOLUTIONS:
            t_relax, sweep = median_time(args.repeats, relaxation_sweep, params, model, m_max=2 * fold.moment, dm=dm, stop_at_onset=True)
            row["relaxation"].append(
                {
                    "dm": dm,
                    "seconds": t_relax,
                    "steps": len(sweep.moment),
                    "onset_load": sweep.onset_load,
                    "onset_minus_M_c": sweep.onset_load - fold.moment,
                    "ratio_to_fold": t_relax / t_fold,
                    "ratio_to_continuation": t_relax / t_cont,
                }
            )
        rows.append(row)
    result = {"machine": platform.platform(), "python": platform.python_version(), "repeats": args.repeats, "models": rows}
    RESULTS.mkdir(exist_ok=True)
    (RESULTS / "critical.json").write_text(json.dumps(result, indent=2) + "\n")
    print(f"{'model':10s} {'method':24s} {'seconds':>9s} {'M_c error':>10s} {'x fold time':>12s}")
    for row in rows:
        print(f"{row['model']:10s} {'fold (exact)':24s} {row['fold_seconds']:9.3f} {0.0:10.1e} {1.0:12.1f}")
        print(
            f"{'':10s} {'continuation past fold':24s} {row['continuation_seconds']:9.3f} {row['continuation_M_c_error']:10.1e} {row['continuation_seconds'] / row['fold_seconds']:12.1f}"
        )
        for r in row["relaxation"]:
            print(
                f"{'':10s} {'relaxation dM=' + format(r['dm'], 'g'):24s} {r['seconds']:9.3f} {r['onset_minus_M_c']:10.1e} {r['ratio_to_fold']:12.1f}"
            )
    if args.json:
        print(json.dumps(result))
    scaling(args.quick, args.repeats)


if __name__ == "__main__":
    main()
