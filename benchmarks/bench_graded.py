"""Speed of graded and disordered chains (issue 14, item 3) against the uniform chain and a vectorised reference.

Run from the repository root::

    python benchmarks/bench_graded.py            # 7, 101 and 10^4 particles, about 2 minutes on 2 cores
    python benchmarks/bench_graded.py --quick    # 7 and 101 particles, fewer rounds
    python benchmarks/bench_graded.py --json     # also print one JSON object (the log goes to stderr)

What is measured (as in ``bench_throughput.py``): the nonlinear model, damped velocity
Verlet at the uniform chain's default dt, a constant moment on particle 0, from a moving
chain (``harness.moving_state``), the same number of steps for every contender of a
size, contenders interleaved round by round, one thread:

* ``uniform``: ``integrate`` on the uniform chain (the package's fastest path);
* ``graded_stiffness``: ``integrate`` on the chain with per-bond E1 and E2 factors
  (``params.disordered(..., 0.3, ("E1", "E2"))``): the graded interior kernel;
* ``graded_inertia``: per-particle m and j factors: the per-column kick-drift;
* ``graded_all``: both;
* ``numba``: ``reference.run_single`` on the uniform chain (vectorised, two passes per step);
* ``numba_graded``: ``reference.run_single`` on the stiffness-graded chain
  (``reference.forces_columns_graded``, per-bond stiffness read from the coefficients).

Reported: M particle-steps per thread CPU-second and per wall-second (medians, quartiles),
and the ratios ``graded_stiffness / numba_graded`` (the graded kernel against the best
reference of the same scheme), ``uniform / numba``, and every graded variant against
``uniform`` (what the grading costs). No reference is built for graded inertia: its
ratio to ``uniform`` is what is claimed. Results go to ``benchmarks/results/graded.json``
(``graded-quick.json`` with ``--quick``).
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

import harness
import reference
from cosserat_chain import ChainParams, moment_load
from cosserat_chain.numerics.dynamics import default_time_step, integrate
from cosserat_chain.params import disordered

HERE = Path(__file__).resolve().parent
RESULTS = HERE / "results"
MOMENT = 0.05
SPREAD = 0.3
VARIANTS = {"uniform": (), "graded_stiffness": ("E1", "E2"), "graded_inertia": ("m", "j"), "graded_all": ("E1", "E2", "m", "j")}


def plan(quick: bool) -> list[tuple[int, float, int]]:
    """(N, particle-steps per measurement, rounds) per size."""
    if quick:
        return [(3, 2e6, 3), (50, 2e6, 3)]
    return [(3, 1e7, 7), (50, 1e7, 7), (5000, 1e7, 5)]


class Size:
    """One chain length: the variants' parameters, one dt and start state for all, the references' arrays."""

    def __init__(self, N: int, particle_steps: float):
        uniform = ChainParams(N=N)
        self.params = {name: disordered(uniform, 7, SPREAD, fields) if fields else uniform for name, fields in VARIANTS.items()}
        self.n = uniform.n_particles
        self.n_steps = max(10, int(particle_steps / self.n))
        # One dt for every variant (the uniform chain's default; the graded chains' own differ
        # a little), so that every contender does the same steps.
        self.dt = default_time_step(uniform)
        self.x0, self.v0 = harness.moving_state(uniform, seed=N)
        self.col = uniform.N
        self.max_displacement = reference.max_displacement(uniform)
        self.arrays = {name: reference.single_arrays(self.params[name], self.dt) for name in ("uniform", "graded_stiffness")}

    def package(self, name: str):
        tr = integrate(
            self.params[name], "nonlinear", moment_load(MOMENT, 0), t_end=self.n_steps * self.dt, dt=self.dt,
            x0=self.x0, v0=self.v0, n_frames=2, threads=1,
        )  # fmt: skip
        if not tr.ok or tr.steps != self.n_steps:
            raise RuntimeError(f"package run of {name} failed: {tr.status}: {tr.message}")
        return tr.x[-1]

    def numba(self, name: str):
        coef, mass, table = self.arrays[name]
        x, v, acc = self.x0.copy(), self.v0.copy(), np.zeros(2)
        status = reference.run_single(x, v, coef, mass, table, self.n_steps, self.col, MOMENT, self.max_displacement, True, False, acc)
        if status != 0:
            raise RuntimeError(f"numba reference of {name}: status {status}")
        return x

    def contenders(self) -> dict:
        out = {name: (lambda name=name: self.package(name)) for name in VARIANTS}
        out["numba"] = lambda: self.numba("uniform")
        out["numba_graded"] = lambda: self.numba("graded_stiffness")
        return out


def verify(log) -> dict:
    """The graded reference computes what the package computes: final states agree to round-off after 2000 steps."""
    size = Size(50, 2000 * 101)
    package, ref = size.package("graded_stiffness"), size.numba("graded_stiffness")
    difference = float(np.max(np.abs(package - ref)))
    log(f"graded reference against the package after {size.n_steps} steps: max |dx| = {difference:.2e}")
    if difference > 1e-9:
        raise RuntimeError(f"the graded reference disagrees with the package: max |dx| = {difference:.3g}")
    return {"steps": size.n_steps, "max_abs_difference": difference}


def measure(quick: bool, log) -> list[dict]:
    rows = []
    for N, particle_steps, rounds in plan(quick):
        size = Size(N, particle_steps)
        work = size.n * size.n_steps
        log(f"{size.n} particles, {size.n_steps} steps, {rounds} rounds")
        samples = harness.interleaved(size.contenders(), rounds, log)
        rate = {name: harness.rates(s, work) for name, s in samples.items()}

        def ratio(top: str, bottom: str, key: str = "thread", rate: dict = rate) -> float:
            return rate[top][key]["median"] / rate[bottom][key]["median"]

        row = {
            "particles": size.n,
            "steps": size.n_steps,
            "rounds": rounds,
            "rates_M_particle_steps_per_s": rate,
            "ratios_thread_cpu": {
                "graded_stiffness/numba_graded": ratio("graded_stiffness", "numba_graded"),
                "uniform/numba": ratio("uniform", "numba"),
                **{f"{name}/uniform": ratio(name, "uniform") for name in VARIANTS if name != "uniform"},
            },
            "ratios_wall": {
                "graded_stiffness/numba_graded": ratio("graded_stiffness", "numba_graded", "wall"),
                "uniform/numba": ratio("uniform", "numba", "wall"),
                **{f"{name}/uniform": ratio(name, "uniform", "wall") for name in VARIANTS if name != "uniform"},
            },
        }
        log("    " + ", ".join(f"{k} {v:.2f}" for k, v in row["ratios_thread_cpu"].items()))
        rows.append(row)
    return rows


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--quick", action="store_true", help="7 and 101 particles, 3 rounds")
    parser.add_argument("--json", action="store_true", help="print one JSON object with all numbers at the end")
    parser.add_argument("--output", type=Path, default=None, help="JSON file (default benchmarks/results/graded[-quick].json)")
    args = parser.parse_args(argv)

    def log(msg: str) -> None:
        print(msg, file=sys.stderr if args.json else sys.stdout, flush=True)

    output = args.output or RESULTS / ("graded-quick.json" if args.quick else "graded.json")
    if output.parent.exists() and not output.parent.is_dir():
        parser.error(f"--output: {str(output.parent)!r} is not a folder")
    if output.exists() and not output.is_file():
        parser.error(f"--output: {str(output)!r} exists and is not a regular file")
    start = time.perf_counter()
    env = harness.environment()
    warm = time.perf_counter()
    for name in ("uniform", "graded_stiffness"):
        Size(50, 10 * 101).numba(name)
    for name in VARIANTS:
        Size(50, 10 * 101).package(name)
    log(f"package at {harness.package_label(env)}; warm-up {time.perf_counter() - warm:.1f} s")
    result = {
        "benchmark": "bench_graded",
        "quick": args.quick,
        "command": "python benchmarks/bench_graded.py" + (" --quick" if args.quick else ""),
        "environment": env,
        "spread": SPREAD,
        "verification": verify(log),
        "sizes": measure(args.quick, log),
        "seconds": time.perf_counter() - start,
    }
    output.parent.mkdir(parents=True, exist_ok=True)
    tmp = output.with_name(output.name + ".tmp")
    tmp.write_text(json.dumps(result, indent=1))
    tmp.replace(output)
    log(f"written {output} ({result['seconds']:.0f} s)")
    if args.json:
        print(json.dumps(result))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
