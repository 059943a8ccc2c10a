"""Time to the critical moment of the paper's chain: exact statics against the relaxation protocol.

Run from the repository root::

    python benchmarks/bench_critical.py            # about a minute
    python benchmarks/bench_critical.py --json     # also print one JSON object

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
"""

from __future__ import annotations

import argparse
import json
import platform
import statistics
import time
from pathlib import Path

from cosserat_chain import ChainParams
from cosserat_chain.experiments.sweep import relaxation_sweep
from cosserat_chain.numerics.continuation import continue_in_moment, locate_fold

RESULTS = Path(__file__).resolve().parent / "results"
MODELS = ("nonlinear", "sine")
RESOLUTIONS = (1e-2, 1e-3)


def median_time(repeats: int, func, *args, **kwargs):
    """Median wall time of ``func(*args, **kwargs)`` over ``repeats`` calls, and its last value."""
    times, value = [], None
    for _ in range(repeats):
        start = time.perf_counter()
        value = func(*args, **kwargs)
        times.append(time.perf_counter() - start)
    return statistics.median(times), value


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--json", action="store_true", help="print the results as one JSON object")
    args = parser.parse_args()
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
            t_relax, sweep = median_time(
                args.repeats, relaxation_sweep, params, model, m_max=2 * fold.moment, dm=dm, stop_at_onset=True
            )
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
        print(f"{'':10s} {'continuation past fold':24s} {row['continuation_seconds']:9.3f} {row['continuation_M_c_error']:10.1e} {row['continuation_seconds'] / row['fold_seconds']:12.1f}")
        for r in row["relaxation"]:
            print(f"{'':10s} {'relaxation dM=' + format(r['dm'], 'g'):24s} {r['seconds']:9.3f} {r['onset_minus_M_c']:10.1e} {r['ratio_to_fold']:12.1f}")
    if args.json:
        print(json.dumps(result))


if __name__ == "__main__":
    main()
