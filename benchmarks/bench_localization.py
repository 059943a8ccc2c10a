"""The paper's 1500-rotation localization run: time per model, accuracy, and the solve_ivp baseline.

Run from the repository root::

    python benchmarks/bench_localization.py            # about a minute
    python benchmarks/bench_localization.py --json     # also print one JSON object

For the nonlinear (M = 0.25) and sine (M = 0.3) models on the paper's chain, in the same run:

* the package: :func:`~cosserat_chain.experiments.localization.localization_run` for
  1500 turns at the default step (damped Verlet, dt = 0.1 / omega_max), one core;
* its accuracy: the same run at half the step. The rotation of the nonlinear model is
  irregular (no stable orbit, see docs/periodic-orbits.md), so single trajectories
  diverge and the accuracy is stated for what the run reports: the mean angular
  velocity and the time to 1500 turns, compared between dt and dt/2 (Verlet is
  second order, so the dt run's error is about 4/3 of that difference);
* the baseline: the NumPy right-hand side of ``bench_throughput.py`` integrated by
  ``scipy.integrate.solve_ivp`` (RK45, rtol=1e-6, atol=1e-9) over the first
  ``--baseline-turns`` turns' time span, and the measured time scaled to 1500 turns.

Results go to ``benchmarks/results/localization.json``.
"""

from __future__ import annotations

import argparse
import json
import platform
import time
from pathlib import Path

from bench_throughput import ivp_run
from cosserat_chain import ChainParams
from cosserat_chain.experiments.localization import localization_run
from cosserat_chain.numerics.dynamics import default_time_step

RESULTS = Path(__file__).resolve().parent / "results"
RUNS = {"nonlinear": 0.25, "sine": 0.3}
TURNS = 1500


def timed(func, *args, **kwargs):
    start = time.perf_counter()
    value = func(*args, **kwargs)
    return time.perf_counter() - start, value


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--baseline-turns", type=int, default=30, help="turns over whose time span solve_ivp is timed")
    parser.add_argument("--json", action="store_true", help="print the results as one JSON object")
    args = parser.parse_args()
    params = ChainParams()
    dt = default_time_step(params)
    localization_run(params, "sine", 0.3, turns=2, t_max=100.0)  # load the compiled kernels outside the timings
    rows = []
    for model, moment in RUNS.items():
        seconds, run = timed(localization_run, params, model, moment, turns=TURNS, t_max=100.0 * TURNS)
        _, fine = timed(localization_run, params, model, moment, turns=TURNS, t_max=100.0 * TURNS, dt=dt / 2)
        coarse, half = run.as_dict(), fine.as_dict()
        short = localization_run(params, model, moment, turns=args.baseline_turns, t_max=100.0 * TURNS).as_dict()
        _, ivp_seconds = ivp_run(params, model, short["t_end"], rtol=1e-6, atol=1e-9)
        ivp_full = ivp_seconds * coarse["t_end"] / short["t_end"]
        rows.append(
            {
                "model": model,
                "moment": moment,
                "turns": coarse["turns_completed"],
                "t_end": coarse["t_end"],
                "seconds": seconds,
                "mean_angular_velocity": coarse["mean_angular_velocity"],
                "mean_angular_velocity_half_dt": half["mean_angular_velocity"],
                "relative_difference_half_dt": abs(coarse["mean_angular_velocity"] / half["mean_angular_velocity"] - 1),
                "t_end_half_dt": half["t_end"],
                "classification": coarse["classification"],
                "solve_ivp_seconds_measured": ivp_seconds,
                "solve_ivp_span": short["t_end"],
                "solve_ivp_seconds_for_1500_turns": ivp_full,
                "speed_up": ivp_full / seconds,
            }
        )
    result = {"machine": platform.platform(), "python": platform.python_version(), "dt": dt, "runs": rows}
    RESULTS.mkdir(exist_ok=True)
    (RESULTS / "localization.json").write_text(json.dumps(result, indent=2) + "\n")
    print(f"{'model':10s} {'seconds':>8s} {'omega':>9s} {'|d omega| dt/2':>15s} {'solve_ivp s (scaled)':>21s} {'speed-up':>9s}")
    for r in rows:
        print(
            f"{r['model']:10s} {r['seconds']:8.2f} {r['mean_angular_velocity']:9.5f} {r['relative_difference_half_dt']:15.2e} "
            f"{r['solve_ivp_seconds_for_1500_turns']:21.1f} {r['speed_up']:9.0f}"
        )
    if args.json:
        print(json.dumps(result))


if __name__ == "__main__":
    main()
