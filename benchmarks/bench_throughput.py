"""Throughput of the package's damped Verlet loop against vectorised references, one chain, one and two threads.

Run from the repository root::

    python benchmarks/bench_throughput.py            # full run, about 3 minutes on 2 cores
    python benchmarks/bench_throughput.py --quick    # 7 and 101 particles, fewer rounds, about a minute
    python benchmarks/bench_throughput.py --json     # also print one JSON object (the log goes to stderr)
    python benchmarks/bench_throughput.py --markdown benchmarks/results/throughput.json   # README tables

What is measured (see benchmarks/README.md): the nonlinear model, damped velocity Verlet
at the package's default dt, a constant moment on particle 0, from a *moving* chain
(``harness.moving_state``: every angle non-zero, random velocities), the same number of
steps for every contender of a size, contenders interleaved round by round:

* ``package``: ``cosserat_chain.numerics.dynamics.integrate(params, "nonlinear",
  moment_load(M, 0), t_end=steps*dt, dt=dt, x0=x0, v0=v0, n_frames=2, threads=1)``, the
  whole call;
* ``numba``, ``numba_fused``, ``numba_no_sums``: ``reference.run_single`` (two passes per
  step; one fused sweep per step; without the energy sums);
* ``numba_blocked``: ``reference.run_single_blocked``, the two-pass step with temporal
  blocking (blocks of 2^15 columns taking 64 steps from the cache), from 4 * 2^15 particles
  on (the package splits a chain as long into blocks in the same way);
* ``c_vec``, ``c_vec_no_sums``: ``c/verlet_vectorised.c`` built now with
  ``harness.VECTOR_CFLAGS``;
* ``c_same``: ``c/verlet_nonlinear.c``, the package's loop copied line by line (libm
  sin/cos, ``-O3 -march=native``).

Reported per contender: M particle-steps per CPU-second of the calling thread, per
CPU-second of the process and per wall-second, medians with quartiles and min/max, and
the ratios package / best reference. Then ``threads=2`` against ``threads=1`` on the
10^6-particle chain, once as the machine is and once with a competing CPU-bound process
started by the benchmark (wall time: what a second thread is for).

Results go to ``benchmarks/results/throughput.json`` (``throughput-quick.json`` with
``--quick``, ``throughput-partial.json`` with ``--sizes`` or ``--no-threads``); the README
tables are printed at the end.
"""

from __future__ import annotations

import argparse
import contextlib
import json
import os
import statistics
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

import harness
import reference
from cosserat_chain import ChainParams, moment_load
from cosserat_chain.numerics.dynamics import default_time_step, integrate

HERE = Path(__file__).resolve().parent
RESULTS = HERE / "results"
MOMENT = 0.05
#: The vectorised references that compute what the package computes (the energy sums included):
#: the target's denominator is the fastest of them.
WITH_SUMS = ("numba", "numba_fused", "numba_blocked", "c_vec")
#: Every reference (also those without the energy sums, and the scalar same-arithmetic loop).
ALL_REFERENCES = (*WITH_SUMS, "numba_no_sums", "c_vec_no_sums", "c_same")
#: The target of issue 11: package >= 0.9x the best vectorised reference at these sizes.
TARGET_SINGLE = 0.9
TARGET_THREADS_IDLE = 1.7
#: A threads=2 run this many times slower than the one-thread median ends its repetitions.
COLLAPSE_FACTOR = 4.0


def plan(quick: bool) -> dict:
    """(N, particle-steps per measurement, rounds) per size, and the threads measurement."""
    if quick:
        return {"sizes": [(3, 2e6, 3), (50, 2e6, 3)], "threads": (50_000, 2e7, 3)}
    # At 10^6 particles 300 steps: integrate's set-up there (its frames, forces and start
    # state allocated and written, the first forces: 50-250 ms, most of it the kernel's first
    # touches of fresh memory on this virtual machine) would be a third of a 20-step
    # measurement and 5-20 % of a 100-step one.
    return {
        "sizes": [(3, 1e7, 9), (50, 1e7, 9), (5000, 1e7, 9), (500_000, 3e8, 3)],
        "threads": (500_000, 1e8, 5),
    }


# ----------------------------------------------------------------------------- contenders
class Chain:
    """One size: parameters, default dt, start state and the arrays of every contender."""

    def __init__(self, N: int, n_steps: int):
        self.params = p = ChainParams(N=N)
        self.n = p.n_particles
        self.n_steps = n_steps
        dt = default_time_step(p)
        self.t_end = n_steps * dt
        self.dt_requested = dt
        self.dt = self.t_end / n_steps  # the step integrate() takes for this t_end
        self.x0, self.v0 = harness.moving_state(p, seed=N)
        self.coef, self.mass, self.table = reference.single_arrays(p, self.dt)
        self.col = p.N  # particle 0
        self.max_displacement = reference.max_displacement(p)

    def package(self, threads: int = 1, n_steps: int | None = None):
        steps = self.n_steps if n_steps is None else n_steps
        t_end = self.t_end if n_steps is None else steps * self.dt_requested
        tr = integrate(
            self.params, "nonlinear", moment_load(MOMENT, 0), t_end=t_end, dt=self.dt_requested,
            x0=self.x0, v0=self.v0, n_frames=2, threads=threads,
        )  # fmt: skip
        if not tr.ok or tr.steps != steps:
            raise RuntimeError(f"package run failed: {tr.status}: {tr.message}")
        return tr.x[-1], tr.v[-1], np.array([tr.load_work[-1], tr.dissipated[-1]])

    def numba(self, energy: bool = True, fused: bool = False, n_steps: int | None = None):
        x, v, acc = self.x0.copy(), self.v0.copy(), np.zeros(2)
        status = reference.run_single(
            x, v, self.coef, self.mass, self.table, self.n_steps if n_steps is None else n_steps, self.col, MOMENT,
            self.max_displacement, energy, fused, acc,
        )  # fmt: skip
        assert status == 0, "numba reference: state out of range"
        return x, v, acc if energy else None

    def numba_blocked(self, width: int = reference.CACHE_WIDTH, super_steps: int = reference.SUPER_STEPS):
        x, v, acc = self.x0.copy(), self.v0.copy(), np.zeros(2)
        status = reference.run_single_blocked(
            x, v, self.coef, self.mass, self.table, self.n_steps, self.col, MOMENT, self.max_displacement, True, acc, width, super_steps
        )  # fmt: skip
        assert status == 0, "blocked numba reference: state out of range"
        return x, v, acc

    def c_vec(self, crefs: harness.CReferences, energy: bool = True, n_steps: int | None = None):
        x, v, acc = self.x0.copy(), self.v0.copy(), np.zeros(2)
        status = crefs.vec_single(
            x, v, self.coef, self.mass, self.table, self.n_steps if n_steps is None else n_steps, self.col, MOMENT,
            self.max_displacement, energy, acc,
        )  # fmt: skip
        assert status == 0, "vectorised C reference: state out of range"
        return x, v, acc if energy else None

    def c_same(self, crefs: harness.CReferences, n_steps: int | None = None):
        x, v = self.x0.copy(), self.v0.copy()
        acc, status = crefs.same_single(x, v, self.coef, self.table, self.n_steps if n_steps is None else n_steps, self.col, MOMENT)
        assert status == 0, "same-arithmetic C loop: blew up"
        return x, v, acc

    def contenders(self, crefs: harness.CReferences) -> dict:
        out = {
            "package": self.package,
            "numba": lambda: self.numba(True, False),
            "numba_fused": lambda: self.numba(True, True),
            "numba_no_sums": lambda: self.numba(False, False),
            "numba_blocked": self.numba_blocked,
            "c_vec": lambda: self.c_vec(crefs, True),
            "c_vec_no_sums": lambda: self.c_vec(crefs, False),
            "c_same": lambda: self.c_same(crefs),
        }
        if self.n <= reference.BLOCK + 2:  # one block: the fused sweep is the two-pass step
            del out["numba_fused"]
        if self.n < 4 * reference.CACHE_WIDTH:  # a chain that stays in the cache gains nothing from blocks
            del out["numba_blocked"]
        return out


def compare(ref, other) -> dict:
    """Largest differences of final x, v and of the energy sums between two results."""
    out = {"max_abs_dx": float(np.abs(other[0] - ref[0]).max()), "max_abs_dv": float(np.abs(other[1] - ref[1]).max())}
    if ref[2] is not None and other[2] is not None:
        out["abs_d_load_work"] = float(abs(other[2][0] - ref[2][0]))
        out["abs_d_dissipated"] = float(abs(other[2][1] - ref[2][1]))
    return out


# ----------------------------------------------------------------------------- part 0: agreement
def verify(crefs: harness.CReferences, log) -> dict:
    """Every contender reproduces the package's states from the moving start (short runs)."""
    out = {}
    for N, n_steps in ((3, 5000), (50, 2000), (700, 300)):
        chain = Chain(N, n_steps)
        pkg = chain.package()
        rows = {
            "c_same": chain.c_same(crefs),
            "numba": chain.numba(True, False),
            "numba_fused": chain.numba(True, True),
            "numba_no_sums": chain.numba(False, False),
            # Blocks narrow enough to split these chains (several blocks, super-steps and a shorter last one).
            "numba_blocked": chain.numba_blocked(width=max(8, chain.n // 7), super_steps=max(1, min(16, chain.n // 40))),
            "c_vec": chain.c_vec(crefs, True),
            "c_vec_no_sums": chain.c_vec(crefs, False),
        }
        diffs = {name: compare(pkg, res) for name, res in rows.items()}
        scale = float(np.abs(pkg[0]).max())
        out[str(chain.n)] = {"steps": n_steps, "dt": chain.dt, "max_abs_x": scale, "vs_package": diffs}
        worst = max(max(d.values()) for d in diffs.values())
        log(
            f"check vs package, {chain.n} particles, {n_steps} steps: largest difference of x, v or energy sums {worst:.2e} (max|x| {scale:.3g})"
        )
        # The same-arithmetic loop rounds as the package does; the vectorised ones use
        # fast-math and other fused multiply-adds, so they agree to round-off growth.
        assert max(diffs["c_same"].values()) <= 1e-10, f"same-arithmetic C loop disagrees: {diffs['c_same']}"
        assert worst <= 1e-8, f"a reference disagrees with the package: {diffs}"
    return out


# ----------------------------------------------------------------------------- part 1: one thread
def single_thread(crefs: harness.CReferences, quick: bool, log, only: set[int] | None = None) -> list[dict]:
    rows = []
    for N, work, rounds in plan(quick)["sizes"]:
        n = 2 * N + 1
        if only is not None and n not in only:
            continue
        n_steps = max(10, round(work / n))
        chain = Chain(N, n_steps)
        contenders = chain.contenders(crefs)
        results = {}

        def keep(name, res, results=results):
            results.setdefault(name, res)  # the first round's final state, for the comparison below

        log(
            f"{n} particles: {n_steps} steps of dt={chain.dt:.4g}, {len(contenders)} contenders x {rounds} rounds (load {os.getloadavg()[0]:.2f}) ..."
        )
        samples = harness.interleaved(contenders, rounds, check=keep)
        particle_steps = n * n_steps
        row = {
            "N": N,
            "particles": n,
            "steps": n_steps,
            "dt": chain.dt,
            "rounds": rounds,
            "load_average_start": os.getloadavg()[0],
            "min_abs_angle_start": float(np.abs(chain.x0[2, 1:-1]).min()),
            "min_abs_angle_end_package": float(np.abs(results["package"][0][2, 1:-1]).min()),
            "samples_s": samples,
            "rates_M_per_s": {name: harness.rates(s, particle_steps) for name, s in samples.items()},
            "final_state_vs_package": {name: compare(results["package"], res) for name, res in results.items() if name != "package"},
        }
        row.update(ratios(row, samples))
        rows.append(row)
        r = row["rates_M_per_s"]
        log(
            "  M p-s per thread CPU-s (median): "
            + ", ".join(f"{name} {r[name]['thread']['median']:.1f}" for name in contenders)
            + f"\n  package / best reference ({row['best_reference']}): {row['package_over_best']['thread']:.2f}x thread CPU, "
            f"{row['package_over_best']['wall']:.2f}x wall; / fastest of all references ({row['best_reference_any']}): "
            f"{row['package_over_best_any']['thread']:.2f}x"
        )
    return rows


def ratios(row: dict, samples: dict) -> dict:
    """Ratios of medians package / best reference, and the spread of the per-round ratios."""
    med = {name: row["rates_M_per_s"][name] for name in samples}
    present = [name for name in WITH_SUMS if name in med]
    best = max(present, key=lambda name: med[name]["thread"]["median"])
    best_any = max([n for n in ALL_REFERENCES if n in med], key=lambda name: med[name]["thread"]["median"])

    def over(name):
        return {key: med["package"][key]["median"] / med[name][key]["median"] for key in ("thread", "process", "wall")}

    def per_round(name, key="thread_s"):
        # Rounds are interleaved, so round r of both saw the same machine.
        return harness.spread([ref[key] / pkg[key] for pkg, ref in zip(samples["package"], samples[name])])

    return {
        "best_reference": best,
        "best_reference_any": best_any,
        "package_over_best": over(best),
        "package_over_best_per_round_thread": per_round(best),
        "package_over_best_any": over(best_any),
        "package_over": {name: over(name) for name in med if name != "package"},
    }


# ----------------------------------------------------------------------------- part 2: two threads
def wait_for_idle(seconds: float, log) -> float:
    """Probe the free cores until two are free (>= 1.8) or ``seconds`` have passed; the last probe."""
    end = time.perf_counter() + seconds
    cores = harness.free_cores()
    while cores < 1.8 and time.perf_counter() < end:
        time.sleep(2.0)
        cores = harness.free_cores()
    if cores < 1.8:
        log(f"  the machine did not become idle within {seconds:g} s (two spinning processes got {cores:.2f} cores)")
    return cores


def threads(quick: bool, wait_idle: float, log) -> dict:
    """threads=2 against threads=1 on one long chain, on the machine as it is and beside a busy process."""
    N, work, rounds = plan(quick)["threads"]
    n = 2 * N + 1
    n_steps = max(10, round(work / n))
    chain = Chain(N, n_steps)
    chain.package(threads=2, n_steps=2)  # compile / load the parallel code
    out = {"N": N, "particles": n, "steps": n_steps, "rounds": rounds}
    for label in ("as_is", "busy"):
        cores = wait_for_idle(wait_idle, log) if label == "as_is" else None
        one = []
        two = []
        collapsed = False
        with harness.busy_neighbour() if label == "busy" else contextlib.nullcontext():
            if cores is None:
                cores = harness.free_cores()
            for r in range(rounds):
                pair = [("1", one), ("2", two)] if r % 2 == 0 else [("2", two), ("1", one)]
                for threads_, store in pair:
                    if threads_ == "2" and collapsed:
                        continue
                    times, _ = harness.timed(lambda t=int(threads_): chain.package(threads=t))
                    store.append(times)
                    if threads_ == "2" and one and times["wall_s"] > COLLAPSE_FACTOR * max(s["wall_s"] for s in one):
                        collapsed = True
                        log(f"  threads=2 took {times['wall_s']:.2f} s, more than {COLLAPSE_FACTOR}x one thread: no more repetitions")
        log(f"threads, {n} particles, {n_steps} steps, {label.replace('_', ' ')}: two spinning processes got {cores:.2f} cores")
        particle_steps = n * n_steps
        res = {
            "free_cores_probe": cores,
            "load_average": os.getloadavg()[0],
            "threads1_samples_s": one,
            "threads2_samples_s": two,
            "threads1": harness.rates(one, particle_steps),
            "threads2": harness.rates(two, particle_steps),
            "threads2_collapsed": collapsed,
        }
        res["speedup_wall"] = res["threads2"]["wall"]["median"] / res["threads1"]["wall"]["median"]
        res["speedup_wall_per_round"] = harness.spread([a["wall_s"] / b["wall_s"] for a, b in zip(one, two)])
        out[label] = res
        log(
            f"  threads=1 {res['threads1']['wall']['median']:.1f} M p-s per wall-s, threads=2 {res['threads2']['wall']['median']:.1f}: "
            f"{res['speedup_wall']:.2f}x (per round {res['speedup_wall_per_round']['min']:.2f}-{res['speedup_wall_per_round']['max']:.2f})"
        )
    return out


# ----------------------------------------------------------------------------- evidence of SIMD
def vectorisation(crefs: harness.CReferences) -> dict:
    """Packed-instruction counts of the numba references (compiled afresh) and of the C library."""
    out = {}
    try:
        text = subprocess.run(
            [sys.executable, str(HERE / "reference.py"), "--asm"], capture_output=True, text=True, check=True, cwd=HERE.parent
        ).stdout
        report = json.loads(text)
        out["numba"] = {name: [e["counts"] for e in entries] for name, entries in report.items()}
    except Exception as err:  # noqa: BLE001 - evidence only
        out["numba"] = f"failed: {err}"
    try:
        library = crefs.vec._name
        asm = subprocess.run(["objdump", "-d", "--no-show-raw-insn", library], capture_output=True, text=True, check=True).stdout
        counts = {}
        for op in ("vsqrtpd", "vdivpd", "vsqrtsd", "vdivsd"):
            hits = [line for line in asm.splitlines() if f"\t{op}" in line or f" {op} " in line]
            counts[op] = {reg: sum(f"%{reg}" in h for h in hits) for reg in ("zmm", "ymm", "xmm")}
        out["c_vectorised"] = counts
    except Exception as err:  # noqa: BLE001 - evidence only
        out["c_vectorised"] = f"failed: {err}"
    return out


# ----------------------------------------------------------------------------- report
NAMES = {
    "package": "package",
    "numba": "numba ref",
    "numba_fused": "numba ref, fused sweep",
    "numba_no_sums": "numba ref, no energy sums",
    "numba_blocked": "numba ref, blocks in the cache",
    "c_vec": "C vectorised",
    "c_vec_no_sums": "C vectorised, no energy sums",
    "c_same": "C same arithmetic",
}


def _cell(rate: dict) -> str:
    return f"{rate['median']:.1f} ({rate['min']:.1f}-{rate['max']:.1f})"


def markdown(result: dict) -> str:
    env = result["environment"]
    lines = [
        f"Package at {harness.package_label(env)}; {env['cpu']} ({env['llvm_cpu']}), {env['cores']} cores; "
        f"Python {env['python']}, NumPy {env['numpy']}, Numba {env['numba']}, {env['gcc']}; load average at start "
        f"{env['loadavg_start'][0]:.2f}.",
        "",
        "M particle-steps per CPU-second of the calling thread, median (min-max) over the rounds; nonlinear model, damped "
        "Verlet, default dt, moving chain, one thread:",
        "",
    ]
    rows = result["single_thread"]
    names = [name for name in NAMES if any(name in r["rates_M_per_s"] for r in rows)]
    lines.append("| contender | " + " | ".join(f"{r['particles']} ({r['steps']} steps)" for r in rows) + " |")
    lines.append("|---|" + "---:|" * len(rows))
    for name in names:
        cells = [_cell(r["rates_M_per_s"][name]["thread"]) if name in r["rates_M_per_s"] else "-" for r in rows]
        lines.append(f"| {NAMES[name]} | " + " | ".join(cells) + " |")
    lines.append(
        "| **package / best vectorised reference with the sums** (thread CPU; per-round range) | "
        + " | ".join(
            f"**{r['package_over_best']['thread']:.2f}x** ({r['package_over_best_per_round_thread']['min']:.2f}-"
            f"{r['package_over_best_per_round_thread']['max']:.2f}) vs {NAMES[r['best_reference']]}"
            for r in rows
        )
        + " |"
    )
    lines.append("| the same, wall time | " + " | ".join(f"{r['package_over_best']['wall']:.2f}x" for r in rows) + " |")
    lines.append(
        "| package / fastest of all references (thread CPU) | "
        + " | ".join(f"{r['package_over_best_any']['thread']:.2f}x vs {NAMES[r['best_reference_any']]}" for r in rows)
        + " |"
    )
    lines.append(
        "| package / C same arithmetic (thread CPU) | " + " | ".join(f"{r['package_over']['c_same']['thread']:.2f}x" for r in rows) + " |"
    )
    if all("system_s" in r["samples_s"]["package"][0] for r in rows):
        # Part of the thread CPU above: the kernel's first touches of fresh memory (the package
        # allocates its frames, forces and restart buffers; a reference only copies its start).
        lines.append(
            "| of which kernel (system) time, median ms: package / best reference | "
            + " | ".join(
                f"{1e3 * statistics.median(s['system_s'] for s in r['samples_s']['package']):.0f} / "
                f"{1e3 * statistics.median(s['system_s'] for s in r['samples_s'][r['best_reference']]):.0f}"
                for r in rows
            )
            + " |"
        )
    th = result.get("threads")
    if th:
        lines += [
            "",
            f"threads=2 against threads=1, {th['particles']} particles, {th['steps']} steps, M particle-steps per wall-second, "
            "median (min-max):",
            "",
            "| machine | free cores (probe) | threads=1 | threads=2 | threads=2 / threads=1 (per-round range) |",
            "|---|---:|---:|---:|---:|",
        ]
        for label, text in (
            ("as_is", "as it was (other engineers' jobs beside)"),
            ("busy", "+ a spinning process started by the benchmark"),
        ):
            t = th[label]
            lines.append(
                f"| {text} | {t['free_cores_probe']:.2f} | {_cell(t['threads1']['wall'])} | {_cell(t['threads2']['wall'])}"
                f"{' (collapsed)' if t['threads2_collapsed'] else ''} | **{t['speedup_wall']:.2f}x** "
                f"({t['speedup_wall_per_round']['min']:.2f}-{t['speedup_wall_per_round']['max']:.2f}) |"
            )
    targets = result.get("targets")
    if targets:
        lines += ["", "| target | measured | met |", "|---|---|---|"]
        for t in targets:
            lines.append(f"| {t['target']} | {t['measured']} | {'yes' if t['met'] else '**no**'} |")
    return "\n".join(lines)


def targets(rows: list[dict], th: dict | None) -> list[dict]:
    out = []
    for r in rows:
        if r["particles"] in (101, 10001, 1000001):
            value = r["package_over_best"]["thread"]
            out.append(
                {
                    "target": f"{r['particles']} particles, one thread: package >= {TARGET_SINGLE}x the best vectorised reference",
                    "measured": f"{value:.2f}x ({NAMES[r['best_reference']]})",
                    "met": value >= TARGET_SINGLE,
                }
            )
    if th and th["particles"] > 500_000:
        idle, busy = th["as_is"]["speedup_wall"], th["busy"]["speedup_wall"]
        out.append(
            {
                "target": f"10^6 particles: threads=2 >= {TARGET_THREADS_IDLE}x threads=1 on an idle machine",
                "measured": f"{idle:.2f}x (free cores probe {th['as_is']['free_cores_probe']:.2f})",
                "met": idle >= TARGET_THREADS_IDLE,
            }
        )
        out.append(
            {
                "target": "10^6 particles: threads=2 never slower than threads=1 beside a busy process",
                "measured": f"{busy:.2f}x (slowest round {th['busy']['speedup_wall_per_round']['min']:.2f}x)",
                "met": th["busy"]["speedup_wall_per_round"]["min"] >= 1.0 and not th["busy"]["threads2_collapsed"],
            }
        )
    return out


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--quick", action="store_true", help="7 and 101 particles, threads at 10^5, 3 rounds (about a minute)")
    parser.add_argument("--json", action="store_true", help="print one JSON object with all numbers at the end")
    parser.add_argument("--no-threads", action="store_true", help="skip the threads=2 measurement")
    parser.add_argument(
        "--wait-idle", type=float, default=None, metavar="SECONDS",
        help="before the threads measurement, wait up to this long for two free cores (default 60, 0 with --quick)",
    )  # fmt: skip
    parser.add_argument("--output", type=Path, default=None, help="JSON file (default benchmarks/results/throughput[-quick|-partial].json)")
    parser.add_argument("--markdown", type=Path, metavar="JSON", help="only print the README tables of a saved result")
    parser.add_argument(
        "--sizes", default=None, metavar="N1,N2",
        help="only these chain sizes (particles, of the plan's: 7,101,10001,1000001), each in this process after the others' warm-up",
    )  # fmt: skip
    args = parser.parse_args(argv)
    if args.markdown:
        print(markdown(json.loads(args.markdown.read_text())))
        return 0

    def log(msg: str) -> None:
        print(msg, file=sys.stderr if args.json else sys.stdout, flush=True)

    t_start = time.perf_counter()
    env = harness.environment()
    crefs = harness.CReferences()
    log(f"package at {harness.package_label(env)}; C: {crefs.commands['vectorised']}")
    warm = time.perf_counter()
    Chain(3, 10).package()
    Chain(600, 10).package()
    for energy in (True, False):
        for fused in (True, False):
            Chain(600, 10).numba(energy, fused)
    log(f"warm-up (numba compile / cache load): {time.perf_counter() - warm:.1f} s")
    check = verify(crefs, log)
    only = None if args.sizes is None else {int(size) for size in args.sizes.split(",")}
    rows = single_thread(crefs, args.quick, log, only)
    wait_idle = args.wait_idle if args.wait_idle is not None else (0.0 if args.quick else 60.0)
    th = None if args.no_threads else threads(args.quick, wait_idle, log)
    env["loadavg_end"] = list(os.getloadavg())
    result = {
        "benchmark": "bench_throughput",
        "quick": args.quick,
        "command": "python benchmarks/bench_throughput.py"
        + (" --quick" if args.quick else "")
        + (f" --sizes {args.sizes}" if args.sizes else ""),
        "environment": env,
        "c_commands": crefs.commands,
        "moment": MOMENT,
        "agreement_with_package": check,
        "single_thread": rows,
        "threads": th,
        "vectorisation": vectorisation(crefs),
        "targets": targets(rows, th),
        "total_wall_s": time.perf_counter() - t_start,
    }
    log("")
    log(markdown(result))
    log(f"\ntotal {result['total_wall_s']:.0f} s")
    # A run of part of the plan (--sizes, --no-threads) goes to a file of its own: it
    # overwrote the full run's before.
    default = "throughput-quick.json" if args.quick else "throughput-partial.json" if args.sizes or args.no_threads else "throughput.json"
    output = args.output or RESULTS / default
    output.parent.mkdir(parents=True, exist_ok=True)
    partial = output.with_name(output.name + ".part")
    partial.write_text(json.dumps(result, indent=1) + "\n")
    partial.replace(output)  # whole or not at all
    log(f"wrote {output}")
    if args.json:
        print(json.dumps(result))
    return 0


if __name__ == "__main__":
    sys.exit(main())
