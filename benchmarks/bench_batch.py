"""Batched dynamics: the package's batch loop against batch-innermost references and against its single-run loop.

Run from the repository root::

    python benchmarks/bench_batch.py            # about half a minute on 2 cores
    python benchmarks/bench_batch.py --quick    # smaller work, fewer rounds (< 1 minute)
    python benchmarks/bench_batch.py --json     # also print one JSON object
    python benchmarks/bench_batch.py --markdown benchmarks/results/batch.json   # README / BATCH.md tables

Three parts (see benchmarks/README.md and BATCH.md), nonlinear model unless said, damped
Verlet at each member's default dt, every member starting from its own moving state
(``harness.moving_state``: every angle non-zero), contenders interleaved round by round:

1. **References, B = 1000 loads on the 7-particle chain** (moments 0.02..0.4):
   ``integrate_batch(..., threads=1)`` and ``threads=2`` against the batch-innermost
   references x[3, n, B] (``reference.run_batch`` and ``c/verlet_vectorised.c::run_batch``,
   with and without the energy sums; the package keeps them, so the target is against the
   references with the sums), on one thread
   and on two (the members split into two halves, each half in its own thread), and
   against ``integrate`` on one chain (the single-run loop) doing the same particle-steps.
   One-thread contenders are timed by the CPU time of the calling thread, two-thread ones
   by wall time (and the process CPU time). Before that the references are checked
   against the package member by member.
2. **Batch against single runs**: ``integrate_batch`` with B = 1, 16, 256 on one and two
   threads against ``integrate`` on one chain, 7 and 101 particles, nonlinear and sine.
3. **The relaxation grid**: one relaxation step for 16 loads on the paper's chain (sine,
   from rest, as the protocol starts), ``relax_batch`` against ``relax`` load by load.

Results go to ``benchmarks/results/batch.json`` (or ``batch-quick.json`` with ``--quick``).
"""

from __future__ import annotations

import argparse
import json
import os
import shlex
import sys
import threading
import time
from functools import partial
from pathlib import Path

import numpy as np

import harness
import reference
from cosserat_chain import ChainParams, moment_load
from cosserat_chain.numerics.batch import integrate_batch
from cosserat_chain.numerics.dynamics import default_time_step, integrate
from cosserat_chain.numerics.relaxation import relax

RESULTS = Path(__file__).resolve().parent / "results"
MODELS = ("nonlinear", "sine")
SIZES = (3, 50)  # N: 7 and 101 particles
BATCHES = (1, 16, 256)
GRID = np.linspace(0.02, 0.5, 16)  # loads of the relaxation grid: static and rotating
REFERENCE_BATCH = 1000
#: issue 11: a batch of 1000 loads on the 7-particle chain >= 0.9x a batch-innermost reference.
TARGET = 0.9
#: The references that compute what the package computes (the exact energy sums included):
#: the target's denominator is the fastest of them (the others are reported beside).
ONE_THREAD_REFS = ("numba_batch_sums", "c_vec_batch_sums")


def moments(batch: int) -> np.ndarray:
    """Different loads per member (static and rotating ones), so that members really differ."""
    return np.linspace(0.02, 0.4, batch)


def moving_states(params: ChainParams, batch: int) -> tuple[np.ndarray, np.ndarray]:
    """(B, 3, n) start states, each member its own moving state."""
    states = [harness.moving_state(params, seed=1000 + b) for b in range(batch)]
    return np.array([s[0] for s in states]), np.array([s[1] for s in states])


def innermost(a: np.ndarray) -> np.ndarray:
    """(B, 3, n) -> (3, n, B), contiguous."""
    return np.ascontiguousarray(np.moveaxis(a, 0, -1))


# ----------------------------------------------------------------------------- part 1: references
class Batch:
    """B members of one chain: start states, moments, and the arrays of the references."""

    def __init__(self, N: int, size: int, n_steps: int):
        self.params = p = ChainParams(N=N)
        self.members = [p] * size
        self.size = size
        self.n = p.n_particles
        self.n_steps = n_steps
        self.dt_requested = default_time_step(p)
        self.t_end = n_steps * self.dt_requested
        self.dt = self.t_end / n_steps
        self.moments = moments(size)
        self.x0, self.v0 = moving_states(p, size)
        self.coef, self.mass, self.factors = reference.batch_arrays(self.members, [self.dt] * size)
        self.col = p.N
        self.max_displacement = reference.max_displacement(p)

    def package(self, threads: int = 1):
        run = integrate_batch(
            self.members, "nonlinear", self.moments, t_end=self.t_end, x0=self.x0, v0=self.v0, n_records=2, threads=threads
        )
        assert all(s == "completed" for s in run.status) and (run.steps == self.n_steps).all(), "package batch run failed"
        return run.x, run.v, None

    def _halves(self, threads: int):
        cuts = np.linspace(0, self.size, threads + 1).round().astype(int)
        return [slice(a, b) for a, b in zip(cuts[:-1], cuts[1:])]

    def reference(self, kind: str, energy: bool, threads: int = 1, crefs: harness.CReferences | None = None):
        """The batch-innermost reference; with threads=2 each half of the members runs in its own thread (nogil)."""
        parts = []
        for part in self._halves(threads):
            x = innermost(self.x0[part])
            v = innermost(self.v0[part])
            args = (
                np.ascontiguousarray(self.coef[:, part]), np.ascontiguousarray(self.mass[:, part]),
                np.ascontiguousarray(self.factors[..., part]), self.n_steps, self.col, np.ascontiguousarray(self.moments[part]),
                self.max_displacement, energy, np.zeros((2, part.stop - part.start)),
            )  # fmt: skip
            parts.append((x, v, args))
        fn = reference.run_batch if kind == "numba" else crefs.vec_batch
        status = [0] * len(parts)

        def work(i):
            x, v, args = parts[i]
            status[i] = fn(x, v, *args)

        if threads == 1:
            work(0)
        else:
            pool = [threading.Thread(target=work, args=(i,)) for i in range(len(parts))]
            for t in pool:
                t.start()
            for t in pool:
                t.join()
        assert not any(status), f"{kind} batch reference: a member out of range"
        x = np.concatenate([np.moveaxis(p[0], -1, 0) for p in parts])
        v = np.concatenate([np.moveaxis(p[1], -1, 0) for p in parts])
        acc = np.concatenate([p[2][-1] for p in parts], axis=1) if energy else None
        return x, v, acc

    def single_loop(self):
        """``integrate`` on one chain (member 0) for the same particle-steps as the whole batch."""
        steps = self.n_steps * self.size
        tr = integrate(
            self.params, "nonlinear", moment_load(float(self.moments[0]), 0), t_end=steps * self.dt_requested,
            dt=self.dt_requested, x0=self.x0[0], v0=self.v0[0], n_frames=2,
        )  # fmt: skip
        assert tr.ok and tr.steps == steps, tr.message
        return tr.x[-1], tr.v[-1], None


def verify(crefs: harness.CReferences, log) -> dict:
    """The references reproduce the package's batch and its single runs member by member (short run)."""
    batch = Batch(3, 64, 600)
    pkg = batch.package()
    singles = np.array(
        [
            integrate(
                batch.params, "nonlinear", moment_load(float(m), 0), t_end=batch.t_end, dt=batch.dt_requested,
                x0=batch.x0[b], v0=batch.v0[b], n_frames=2,
            ).x[-1]
            for b, m in enumerate(batch.moments)
        ]
    )  # fmt: skip
    out = {"members": batch.size, "steps": batch.n_steps, "max_abs_x": float(np.abs(pkg[0]).max())}
    out["package_batch_vs_single_runs_max_abs_dx"] = float(np.abs(pkg[0] - singles).max())
    for name, res in (
        ("numba_batch", batch.reference("numba", True)),
        ("numba_batch_2_threads", batch.reference("numba", False, threads=2)),
        ("c_vec_batch", batch.reference("c", True, crefs=crefs)),
        ("c_vec_batch_2_threads", batch.reference("c", False, threads=2, crefs=crefs)),
    ):
        out[f"{name}_vs_single_runs_max_abs_dx"] = float(np.abs(res[0] - singles).max())
        out[f"{name}_vs_package_batch_max_abs_dv"] = float(np.abs(res[1] - pkg[1]).max())
    # Energy sums of the references against the single runs'.
    tr = [
        integrate(
            batch.params, "nonlinear", moment_load(float(batch.moments[b]), 0), t_end=batch.t_end, dt=batch.dt_requested,
            x0=batch.x0[b], v0=batch.v0[b], n_frames=2,
        )
        for b in (0, batch.size - 1)
    ]  # fmt: skip
    acc = batch.reference("numba", True)[2]
    out["numba_batch_energy_sums_vs_single_runs"] = float(
        max(abs(acc[0, b] - t.load_work[-1]) + abs(acc[1, b] - t.dissipated[-1]) for b, t in zip((0, batch.size - 1), tr))
    )
    worst = max(v for k, v in out.items() if k.endswith(("_dx", "_dv", "_runs")) and "package_batch_vs" not in k)
    log(
        f"check: {batch.size} members, {batch.n_steps} steps: references vs single runs / package batch differ by <= {worst:.2e} "
        f"(package batch vs its single runs {out['package_batch_vs_single_runs_max_abs_dx']:.2e})"
    )
    assert worst <= 1e-9, f"a batch reference disagrees with the package: {out}"
    return out


def references(crefs: harness.CReferences, quick: bool, log) -> dict:
    size = REFERENCE_BATCH
    work = 2e6 if quick else 1e7
    # 21 rounds: a round is 60 ms, and a stray 5-10 ms of the machine in a few rounds moved
    # the median of 9 by up to 0.1 between runs (0.86x-0.97x with the same code).
    rounds = 3 if quick else 21
    n = 7
    n_steps = max(10, round(work / (n * size)))
    batch = Batch(3, size, n_steps)
    one = {
        "package": partial(batch.package, 1),
        "numba_batch": partial(batch.reference, "numba", False),
        "numba_batch_sums": partial(batch.reference, "numba", True),
        "c_vec_batch": partial(batch.reference, "c", False, crefs=crefs),
        "c_vec_batch_sums": partial(batch.reference, "c", True, crefs=crefs),
        "package_single_loop": batch.single_loop,
    }
    two = {
        "package_2_threads": partial(batch.package, 2),
        "numba_batch_2_threads": partial(batch.reference, "numba", True, 2),
        "c_vec_batch_2_threads": partial(batch.reference, "c", True, 2, crefs=crefs),
    }
    for fn in (*one.values(), *two.values()):
        if fn is not batch.single_loop:
            fn()  # compile, warm the caches
    cores = harness.free_cores()
    log(
        f"references: B={size} members of {n} particles, {n_steps} steps, {len(one) + len(two)} contenders x {rounds} rounds "
        f"(free cores {cores:.2f}, load {os.getloadavg()[0]:.2f}) ..."
    )
    samples = harness.interleaved({**one, **two}, rounds)
    particle_steps = n * size * n_steps
    rates = {name: harness.rates(s, particle_steps) for name, s in samples.items()}
    best = max(ONE_THREAD_REFS, key=lambda k: rates[k]["thread"]["median"])
    best_two = max(("numba_batch_2_threads", "c_vec_batch_2_threads"), key=lambda k: rates[k]["wall"]["median"])
    out = {
        "members": size,
        "particles": n,
        "steps": n_steps,
        "rounds": rounds,
        "free_cores_probe": cores,
        "samples_s": samples,
        "rates_M_per_s": rates,
        "best_reference": best,
        "package_over_best_thread": rates["package"]["thread"]["median"] / rates[best]["thread"]["median"],
        "package_over_best_wall": rates["package"]["wall"]["median"] / rates[best]["wall"]["median"],
        "package_over_best_per_round_thread": harness.spread(
            [r["thread_s"] / p["thread_s"] for p, r in zip(samples["package"], samples[best])]
        ),
        "best_reference_2_threads": best_two,
        "package_2_threads_over_best_2_threads_wall": rates["package_2_threads"]["wall"]["median"] / rates[best_two]["wall"]["median"],
        "package_2_threads_over_package_1_thread_wall": rates["package_2_threads"]["wall"]["median"] / rates["package"]["wall"]["median"],
        "package_over_single_loop_thread": rates["package"]["thread"]["median"] / rates["package_single_loop"]["thread"]["median"],
        "package_over_numba_batch_sums_thread": rates["package"]["thread"]["median"] / rates["numba_batch_sums"]["thread"]["median"],
    }
    log(
        "  M p-s per thread CPU-s: "
        + ", ".join(f"{k} {rates[k]['thread']['median']:.1f}" for k in one)
        + "; per wall-s: "
        + ", ".join(f"{k} {rates[k]['wall']['median']:.1f}" for k in two)
        + f"\n  package / best reference ({best}): {out['package_over_best_thread']:.2f}x; two threads: "
        f"{out['package_2_threads_over_best_2_threads_wall']:.2f}x the best two-thread reference"
    )
    return out


# ----------------------------------------------------------------------------- part 2: batch vs single runs
def against_single(quick: bool, log) -> list[dict]:
    """Particle-steps per second of single runs and of batches, interleaved, medians."""
    work = 2_000_000 if quick else 4_000_000  # particle-steps per measurement
    rounds = 3 if quick else 7
    rows = []
    for model in MODELS:
        for N in SIZES:
            params = ChainParams(N=N)
            n = params.n_particles
            dt = default_time_step(params)
            single_steps = work // n
            x1, v1 = harness.moving_state(params, seed=N)
            single = partial(integrate, params, model, moment_load(0.1, 0), t_end=single_steps * dt, dt=dt, x0=x1, v0=v1, n_frames=2)
            for size in BATCHES:
                steps = max(64, work // (n * size))
                x0, v0 = moving_states(params, size)
                batched = partial(integrate_batch, [params] * size, model, moments(size), t_end=steps * dt, x0=x0, v0=v0, n_records=2)
                runs = {"single": single, **{f"batch_{t}t": partial(batched, threads=t) for t in (1, 2)}}
                for fn in runs.values():
                    fn()  # compile and warm the caches
                samples = harness.interleaved(runs, rounds)
                work_done = {"single": single_steps * n, "batch_1t": steps * n * size, "batch_2t": steps * n * size}
                rates = {key: harness.rates(samples[key], work_done[key]) for key in runs}
                row = {"model": model, "particles": n, "batch": size, "rates_M_per_s": rates, "samples_s": samples}
                row["ratio_1t_thread"] = rates["batch_1t"]["thread"]["median"] / rates["single"]["thread"]["median"]
                row["ratio_1t_wall"] = rates["batch_1t"]["wall"]["median"] / rates["single"]["wall"]["median"]
                row["ratio_2t_wall"] = rates["batch_2t"]["wall"]["median"] / rates["single"]["wall"]["median"]
                log(
                    f"{model:9s} {n:4d} particles  B={size:4d}  single {rates['single']['thread']['median']:6.1f} M p-s per thread CPU-s  "
                    f"batch 1 thread {rates['batch_1t']['thread']['median']:6.1f} ({row['ratio_1t_thread']:.2f}x)  "
                    f"2 threads {rates['batch_2t']['wall']['median']:6.1f} per wall-s ({row['ratio_2t_wall']:.2f}x the single run's wall rate)"
                )
                rows.append(row)
    return rows


# ----------------------------------------------------------------------------- part 3: relaxation grid
def _relax_batch():
    """``relax_batch`` wherever the package keeps it (numerics.batch before issue 11, numerics.relaxation after)."""
    try:
        from cosserat_chain.numerics.relaxation import relax_batch
    except ImportError:
        from cosserat_chain.numerics.batch import relax_batch
    return relax_batch


def relaxation_grid(quick: bool, log) -> dict:
    """Wall time of one relaxation step for each of 16 loads: relax load by load against relax_batch."""
    relax_batch = _relax_batch()
    params = ChainParams()
    options = {"t_max": 2000.0 if quick else 5000.0}
    members = [params] * GRID.size
    batched = {threads: partial(relax_batch, members, "sine", GRID, threads=threads, **options) for threads in (1, 2)}

    def single():
        return [relax(params, "sine", float(m), **options) for m in GRID]

    reference_status = [s.status for s in single()]
    for fn in batched.values():
        assert [s.status for s in fn()] == reference_status
    samples = harness.interleaved({"single": single, "batch_1t": batched[1], "batch_2t": batched[2]}, 2 if quick else 5)
    out = {f"{k}_s": harness.spread([s["wall_s"] for s in v]) for k, v in samples.items()}
    out.update(
        {
            "model": "sine",
            "particles": params.n_particles,
            "loads": GRID.tolist(),
            "statuses": reference_status,
            "speedup_1t": out["single_s"]["median"] / out["batch_1t_s"]["median"],
            "speedup_2t": out["single_s"]["median"] / out["batch_2t_s"]["median"],
        }
    )
    log(
        f"relaxation grid of {GRID.size} loads (sine, 7 particles): relax one by one {out['single_s']['median']:.3f} s, "
        f"relax_batch {out['batch_1t_s']['median']:.3f} s ({out['speedup_1t']:.2f}x), 2 threads {out['batch_2t_s']['median']:.3f} s "
        f"({out['speedup_2t']:.2f}x)"
    )
    return out


# ----------------------------------------------------------------------------- report
NAMES = {
    "package": "package `integrate_batch`, threads=1",
    "numba_batch": "numba batch-innermost ref",
    "numba_batch_sums": "numba batch-innermost ref, with energy sums",
    "c_vec_batch": "C vectorised batch-innermost ref",
    "c_vec_batch_sums": "C vectorised batch-innermost ref, with energy sums",
    "package_single_loop": "package `integrate`, one chain, same particle-steps",
    "package_2_threads": "package `integrate_batch`, threads=2",
    "numba_batch_2_threads": "numba ref with energy sums, two threads (a half each)",
    "c_vec_batch_2_threads": "C ref with energy sums, two threads (a half each)",
}


def _cell(rate: dict) -> str:
    return f"{rate['median']:.1f} ({rate['min']:.1f}-{rate['max']:.1f})"


def markdown(result: dict) -> str:
    env = result["environment"]
    ref = result["references"]
    lines = [
        f"Package at {harness.package_label(env)}; {env['cpu']} ({env['llvm_cpu']}), {env['cores']} cores; Numba {env['numba']}, "
        f"{env['gcc']}; load average at start {env['loadavg_start'][0]:.2f}.",
        "",
        f"B = {ref['members']} loads on the {ref['particles']}-particle chain, {ref['steps']} steps, moving start states; "
        f"M particle-steps per second, median (min-max) over {ref['rounds']} interleaved rounds (free cores probe "
        f"{ref['free_cores_probe']:.2f}):",
        "",
        "| contender | per thread CPU-second | per wall-second |",
        "|---|---:|---:|",
    ]
    for name, rate in ref["rates_M_per_s"].items():
        thread = _cell(rate["thread"]) if "2_threads" not in name else "-"
        lines.append(f"| {NAMES.get(name, name)} | {thread} | {_cell(rate['wall'])} |")
    lines += [
        "",
        f"- package / best one-thread reference ({NAMES[ref['best_reference']]}): **{ref['package_over_best_thread']:.2f}x** "
        f"per thread CPU-second (per round {ref['package_over_best_per_round_thread']['min']:.2f}-"
        f"{ref['package_over_best_per_round_thread']['max']:.2f}), {ref['package_over_best_wall']:.2f}x per wall-second",
        f"- package threads=2 / best two-thread reference ({NAMES[ref['best_reference_2_threads']]}): "
        f"{ref['package_2_threads_over_best_2_threads_wall']:.2f}x (wall); package threads=2 / threads=1: "
        f"{ref['package_2_threads_over_package_1_thread_wall']:.2f}x (wall)",
        f"- package batch / package single-run loop: {ref['package_over_single_loop_thread']:.2f}x (thread CPU)",
        f"- target (>= {TARGET}x the batch-innermost reference): **{'met' if ref['package_over_best_thread'] >= TARGET else 'not met'}**",
    ]
    rows = result.get("against_single") or []
    if rows:
        lines += [
            "",
            "Batch against the single-run loop (`integrate` on one chain), same model and dt, moving start; thread CPU for one "
            "thread, wall time for two:",
            "",
            "| model | particles | B | single (M p-s per thread CPU-s) | batch, 1 thread | ratio | batch, 2 threads (per wall-s) | ratio to single (wall) |",
            "|---|---:|---:|---:|---:|---:|---:|---:|",
        ]
        for r in rows:
            rt = r["rates_M_per_s"]
            lines.append(
                f"| {r['model']} | {r['particles']} | {r['batch']} | {rt['single']['thread']['median']:.1f} | "
                f"{rt['batch_1t']['thread']['median']:.1f} | {r['ratio_1t_thread']:.2f}x | {rt['batch_2t']['wall']['median']:.1f} | "
                f"{r['ratio_2t_wall']:.2f}x |"
            )
    grid = result.get("relaxation_grid")
    if grid:
        lines += [
            "",
            f"Relaxation grid ({len(grid['loads'])} loads, sine, {grid['particles']} particles, from rest): relax load by load "
            f"{grid['single_s']['median']:.3f} s, relax_batch {grid['batch_1t_s']['median']:.3f} s ({grid['speedup_1t']:.2f}x), "
            f"two threads {grid['batch_2t_s']['median']:.3f} s ({grid['speedup_2t']:.2f}x).",
        ]
    return "\n".join(lines)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--quick", action="store_true", help="smaller work and fewer rounds (< 1 minute)")
    parser.add_argument("--json", action="store_true", help="print one JSON object with all numbers at the end")
    parser.add_argument("--references-only", action="store_true", help="only part 1 (the batch-innermost references)")
    parser.add_argument("--output", type=Path, default=None, help="JSON file (default benchmarks/results/batch[-quick].json)")
    parser.add_argument("--markdown", type=Path, metavar="JSON", help="only print the tables of a saved result")
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
    check = verify(crefs, log)
    ref = references(crefs, args.quick, log)
    rows = None if args.references_only else against_single(args.quick, log)
    grid = None if args.references_only else relaxation_grid(args.quick, log)
    env["loadavg_end"] = list(os.getloadavg())
    result = {
        "benchmark": "bench_batch",
        "command": "python benchmarks/bench_batch.py"
        + (" " + shlex.join(argv if argv is not None else sys.argv[1:]) if (argv or sys.argv[1:]) else ""),
        "environment": env,
        "c_commands": crefs.commands,
        "agreement": check,
        "references": ref,
        "against_single": rows,
        "relaxation_grid": grid,
        "total_wall_s": time.perf_counter() - t_start,
    }
    log("")
    log(markdown(result))
    log(f"\ntotal {result['total_wall_s']:.0f} s")
    output = args.output or RESULTS / ("batch-quick.json" if args.quick else "batch.json")
    output.parent.mkdir(parents=True, exist_ok=True)
    output.write_text(json.dumps(result, indent=1) + "\n")
    log(f"written {output}")
    if args.json:
        print(json.dumps(result))
    return 0


if __name__ == "__main__":
    sys.exit(main())
