"""Cost of one rotating orbit and its Floquet multipliers against the chain's length, by each shooting method.

Run from the repository root::

    python benchmarks/bench_long_orbits.py                       # N = 10, 30, 100, 200 (about 25 minutes on one core)
    python benchmarks/bench_long_orbits.py --sizes 10 30 --methods dense blocks krylov
    python benchmarks/bench_long_orbits.py --json                # also print the JSON on stdout
    python benchmarks/bench_long_orbits.py --segments 16 --dense-max 50   # blocks with segments, N = 50, 100
    python benchmarks/bench_long_orbits.py --rates               # per unit time, N = 10 ... 1000 (about 2 minutes)
    python benchmarks/bench_long_orbits.py --continuation 8 --sizes 100 200   # an orbit and 3 continuation points
    python benchmarks/bench_long_orbits.py --picard --sizes 50 100 200      # Newton-Picard against the blocks
    python benchmarks/bench_long_orbits.py --picard --sizes 1000 --progress # Newton-Picard alone (hours at N = 1000)
    python benchmarks/bench_long_orbits.py --picard --case short --picard-methods blocks --sizes 500 --blocks-max 1000

The sine chain (eq. (2)) with strong damping (all gammas 1, other fields default) under the
moment 0.3 on particle 0: its rotation settles on one stable one-turn orbit at every length
measured. For each N: the guess (a settled simulation, ``initial_guess``), then from that same
guess ``find_periodic_orbit`` with each method (``dense``: the monodromy integrated in one
piece; ``blocks``: from column blocks; ``krylov``: Newton-Krylov, multipliers by Arnoldi on
products): CPU seconds (all threads; the blocks run on ``--threads``, default 1, so that
CPU time compares methods), wall seconds, Newton iterations, variational columns integrated
over a period (``products``) and integrations, the period, the largest nontrivial
multiplier, the trivial multiplier's distance from 1 and its reported error, and each
method's largest distance of period and multipliers from the first method's. The dense
method runs up to ``--dense-max`` (default 100; its memory is 16 (2 n_free)^2 numbers), the
Krylov method up to ``--krylov-max`` (default 30: at N = 100 its GMRES needs about a
thousand products a Newton step). Results go to
``benchmarks/results/long_orbits.json`` (``docs/periodic-orbits.md``).

``--segments M``: for N = 50, 100 (``--sizes``), the chain of :data:`SEGMENT_DAMPING` (its
angles' modes damped at gamma_phi / j = 3.75, the others at 1; T = 2.13) by the
blocks without and with M segments (``find_periodic_orbit(..., segments=M)``: every block
integrated piece by piece, the multipliers by the periodic Schur form of the pieces' matrices),
and the dense shooting with the same segments up to ``--dense-max``: CPU seconds, the sum of
ln |mu| against Liouville's -T sum gamma_i / m_i, the smallest log10 |mu|, the trivial
multiplier's distance from 1 and its error, the largest difference of log10 |mu| from the
blocks with segments, and the load average (``results/long_orbit_segments.json``).

``--rates``: for N = 10, 30, 100, 200, 1000 (``--sizes``), CPU seconds per unit time of
integration (the same chain and moment, from a moving state) of the state alone, of one
product (the state and one variational column: a GMRES or Arnoldi step), of one block of
:data:`~cosserat_chain.numerics.long_orbits.BLOCK_COLUMNS` columns, and of the dense
monodromy in one piece (up to ``--dense-max``), with the blocks' time for all of M and the
memory of M and of the one-piece integration (``results/long_orbit_rates.json``).

``--picard``: for N = 50, 100, 200, 500, 1000 (``--sizes``), the chain and moment above by
Newton-Picard (``method="picard"``, :mod:`~cosserat_chain.numerics.newton_picard`) and, up to
``--blocks-max`` (default 200), by the blocks from the same guess: CPU seconds with the load
average before and after, Newton iterations, columns integrated and integrations, the period,
the nontrivial multipliers above rho found and those certified (|mu| minus its residual above
rho), the largest residual among them, the trivial multiplier's distance from 1 and its error,
the peak memory estimate (Newton-Picard: its basis and DOP853's copies of the state with it; the
blocks: M and one block's integration), and the blocks' distance from the Newton-Picard orbit
(period, start state, each Newton-Picard multiplier from the nearest of the blocks'); with
``--progress`` the running totals after every block (``results/long_orbit_picard.json``, merged: a
row replaces the one of the same N, rho, guard and settle, the others are kept). ``--rho`` and ``--guard``
set Newton-Picard's options (``find_periodic_orbit(..., rho=, guard=)``); a run that does not
converge is recorded with its message, CPU seconds and columns. ``--settle K``: the guess continued
by K more ``initial_guess`` calls from its own state (each a few turns: the settled run stops
where two turns take the same time to 1e-3, while the period still drifts).
``--case short``: bench_collocation_long.py's chain instead (default fields, M = 0.5, T about
1.26; :data:`CASES`), the row keyed by its case too; ``--picard-methods blocks`` runs the blocks
alone (``--picard --case short --picard-methods blocks --sizes 1000 --blocks-max 1000``). Each
method's entry also has the process's peak resident memory (``peak_rss_GB``, measured) and the
leading multipliers with their residual errors (``leading_multipliers``: [re, im, error], by decreasing
modulus). ``--save-orbits DIR`` writes each converged orbit's start state and period to
``DIR/orbit_CASE_NN.npz``; ``--multipliers-from FILE.npz`` (with ``--case``) computes the multipliers of
such an orbit again with the current code (the monodromy formed again from blocks, or read from
``FILE_M.npy`` beside it) and writes them, their CPU seconds, the load and the warnings into that
orbit's row of the results (``multipliers_recomputed``; the Newton's numbers are kept).

``--continuation M``: for each N of ``--sizes`` (default 100, 200), the chain of
:data:`SEGMENT_DAMPING` under the moment above, by the blocks with M segments: the orbit from the guess (``find_periodic_orbit``), then
``continue_orbit(..., method="blocks", segments=M)`` over :data:`CONTINUATION_POINTS` points
(steps of :data:`CONTINUATION_STEP` in (y0, log T, M)): CPU seconds of each, and per point the
moment, the period, the trivial multiplier's distance from 1 and its error, the largest other
modulus, Liouville's sum against -T sum gamma_i / m_i, and the closure of a direct run of one
period from the orbit's state; with the load average (``results/long_orbit_continuation.json``).
"""

from __future__ import annotations

import argparse
import json
import math
import os
import resource
import sys
import time
from pathlib import Path

import numpy as np

from cosserat_chain import ChainParams
from cosserat_chain.models.base import get_model
from cosserat_chain.numerics import long_orbits, newton_picard
from cosserat_chain.numerics.periodic import ATOL, RTOL, OrbitError, _System, _to_y, continue_orbit, find_periodic_orbit, initial_guess
from cosserat_chain.state import n_free, pack, per_dof

RESULTS = Path(__file__).resolve().parent / "results"
SIZES = (10, 30, 100, 200)
METHODS = ("dense", "blocks", "krylov")
MODEL, MOMENT, DAMPING = "sine", 0.3, 1.0
#: --picard's cases: (gamma_u = gamma_v = gamma_phi, moment); None keeps the fields' defaults. ``strong``: the chain above
#: (T about 21); ``short``: bench_collocation_long.py's (default fields, M = 0.5, T about 1.26).
CASES = {"strong": (DAMPING, MOMENT), "short": (None, 0.5)}
#: (gamma_u, gamma_v, gamma_phi) of --segments: the angles' modes damped at gamma_phi / j = 3.75, the others at 1.
SEGMENT_DAMPING = (1.0, 1.0, 0.1)
#: Time integrated per rate measurement.
RATE_SPAN = 0.5
#: Points and first arclength step of --continuation.
CONTINUATION_POINTS, CONTINUATION_STEP = 3, 0.01


class _Counter:
    """Counts the variational columns and integrations of every Monodromy product (wraps ``Monodromy.apply``);
    with ``progress`` (a stream) it prints the totals after every block of several columns."""

    def __init__(self, progress=None) -> None:
        self.products = self.integrations = 0
        self._apply = long_orbits.Monodromy.apply
        counter = self

        def apply(monodromy, columns):
            out = counter._apply(monodromy, columns)
            block = np.asarray(columns).reshape(monodromy.size, -1)
            counter.products += block.shape[1] * (2 if np.iscomplexobj(block) else 1)
            counter.integrations += 1
            if progress is not None and block.shape[1] > 1:
                print(
                    f"  2 n_free = {monodromy.size}: {counter.integrations} integrations, {counter.products} columns, "
                    f"{time.process_time():.0f} s CPU, load {os.getloadavg()[0]:.1f}",
                    file=progress, flush=True,
                )  # fmt: skip
            return out

        long_orbits.Monodromy.apply = apply

    def reset(self) -> tuple[int, int]:
        out = (self.products, self.integrations)
        self.products = self.integrations = 0
        return out


def measure(n: int, methods: list[str], dense_max: int, krylov_max: int, threads: int, counter: _Counter) -> dict:
    params = ChainParams(N=n, gamma_u=DAMPING, gamma_v=DAMPING, gamma_phi=DAMPING)
    start = time.process_time()
    x, v, period = initial_guess(params, MODEL, MOMENT)
    row = {"N": n, "size": None, "guess_cpu_s": time.process_time() - start, "guess_period": period, "methods": {}}
    first = None
    for method in methods:
        if (method == "dense" and n > dense_max) or (method == "krylov" and n > krylov_max):
            continue
        counter.reset()
        cpu, wall = time.process_time(), time.perf_counter()
        long_orbits.THREADS = threads
        orbit = find_periodic_orbit(params, MODEL, MOMENT, guess=(x, v, period), method=method)
        cpu, wall = time.process_time() - cpu, time.perf_counter() - wall
        products, integrations = counter.reset()
        entry = {
            "cpu_s": cpu,
            "wall_s": wall,
            "iterations": orbit.iterations,
            "products": products,
            "integrations": integrations,
            "period": orbit.period,
            "closure": orbit.closure,
            "multipliers_computed": int(orbit.multipliers.size),
            "max_nontrivial_multiplier": orbit.max_multiplier,
            "trivial_distance_from_1": abs(orbit.trivial_multiplier - 1.0),
            "trivial_error": orbit.trivial_multiplier_error,
        }
        if first is None:
            first = orbit
        else:
            entry["period_difference"] = abs(orbit.period - first.period)
            leading = orbit.multipliers[: min(13, orbit.multipliers.size)]
            entry["multiplier_difference"] = float(max(np.min(np.abs(first.multipliers - mu)) for mu in leading))
        row["methods"][method] = entry
        row["size"] = 2 * (3 * params.n_particles - 6)
    return row


def measure_picard(
    n: int,
    blocks_max: int,
    threads: int,
    counter: _Counter,
    rho: float,
    guard: int,
    settle: int = 0,
    case: str = "strong",
    methods: tuple[str, ...] = ("picard", "blocks"),
    save: Path | None = None,
) -> dict:
    """Newton-Picard (``rho``, ``guard``) and, up to ``blocks_max``, the blocks from the same guess at N = n (``--picard``)
    on ``case`` (:data:`CASES`), those of ``methods``; a run that does not converge is recorded as such (its message, CPU
    and columns) and ends the row. ``settle``: the settled guess continued by that many more calls of ``initial_guess``
    from its own state (each a few turns). Each method's entry has the process's peak resident memory so far
    (``peak_rss_GB``: it never falls, so a row's first method's is its own where the process ran that N alone); with
    ``save`` (a folder) each converged orbit's start state and period (:func:`multipliers_from` reads them)."""
    damping, moment = CASES[case]
    params = ChainParams(N=n) if damping is None else ChainParams(N=n, gamma_u=damping, gamma_v=damping, gamma_phi=damping)
    long_orbits.THREADS = threads
    start = time.process_time()
    guess = initial_guess(params, MODEL, moment)
    for _ in range(settle):
        guess = initial_guess(params, MODEL, moment, x0=guess[0], v0=guess[1])
    size = 2 * n_free(params)
    row = {
        "N": n, "size": size, "guess_cpu_s": time.process_time() - start, "guess_period": guess[2], "settle": settle, "rho": rho,
        "guard": guard, "case": case, "moment": moment, "methods": {},
    }  # fmt: skip
    for method in [m for m in methods if m == "picard" or n <= blocks_max]:
        counter.reset()
        load = os.getloadavg()[0]
        cpu = time.process_time()
        options = {"rho": rho, "guard": guard} if method == "picard" else {}
        try:
            orbit = find_periodic_orbit(params, MODEL, moment, guess=guess, method=method, **options)
        except OrbitError as err:
            products, integrations = counter.reset()
            row["methods"][method] = {
                "converged": False, "message": str(err), "cpu_s": time.process_time() - cpu, "load_average": load,
                "load_average_after": os.getloadavg()[0], "products": products, "integrations": integrations,
                "peak_rss_GB": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1e6,
            }  # fmt: skip
            break
        cpu = time.process_time() - cpu
        products, integrations = counter.reset()
        errors = orbit.multiplier_errors
        above = np.abs(orbit.multipliers) > rho
        nontrivial = np.arange(orbit.multipliers.size) != np.argmin(np.abs(orbit.multipliers - 1.0))
        if method == "picard":
            # The basis (p + max(guard, p / 2) columns) and DOP853's ~16 copies of the state with them.
            p = int(np.count_nonzero(above))
            columns = p + max(guard, p // 2)
            memory = 8 * size * (16 * (columns + 1) + 4 * columns)
        else:
            memory = 8 * size * (size + 16 * (long_orbits.BLOCK_COLUMNS + 1))
        entry = {
            "converged": True,
            "cpu_s": cpu,
            "load_average": load,
            "load_average_after": os.getloadavg()[0],
            "iterations": orbit.iterations,
            "products": products,
            "integrations": integrations,
            "period": orbit.period,
            "closure": orbit.closure,
            "above_rho": int(np.count_nonzero(above & nontrivial)),
            "certified_above_rho": int(np.count_nonzero((np.abs(orbit.multipliers) - errors > rho) & nontrivial)),
            "largest_residual_above_rho": float(np.max(errors[above & nontrivial], initial=0.0)),
            "max_nontrivial_multiplier": orbit.max_multiplier,
            "trivial_distance_from_1": abs(orbit.trivial_multiplier - 1.0),
            "trivial_error": orbit.trivial_multiplier_error,
            "memory_MB": memory / 1e6,
            "peak_rss_GB": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1e6,
        }
        if method == "blocks" and "picard" in row["methods"]:
            picard = row["methods"]["picard"]["orbit"]
            entry["period_difference"] = abs(orbit.period - picard.period)
            entry["state_difference"] = float(max(np.max(np.abs(orbit.x - picard.x)), np.max(np.abs(orbit.v - picard.v))))
            entry["multiplier_difference"] = float(np.max([np.min(np.abs(orbit.multipliers - mu)) for mu in picard.multipliers]))
        entry["leading_multipliers"] = _leading(orbit.multipliers, errors)
        if save is not None:
            save.mkdir(parents=True, exist_ok=True)
            np.savez(
                save / f"orbit_{case}_N{n}.npz", y0=_to_y(params, orbit.x, orbit.v), period=orbit.period, moment=moment, N=n, case=case
            )  # fmt: skip
        entry["orbit"] = orbit
        row["methods"][method] = entry
    for entry in row["methods"].values():
        entry.pop("orbit", None)
    return row


def _leading(multipliers: np.ndarray, errors: np.ndarray | None, count: int = long_orbits.MULTIPLIERS + 1) -> list:
    """[re, im, error] of the ``count`` multipliers of largest modulus (error None where not estimated)."""
    order = np.argsort(-np.abs(multipliers), kind="stable")[:count]
    return [[float(multipliers[i].real), float(multipliers[i].imag), None if errors is None else float(errors[i])] for i in order]


def multipliers_from(path: Path, case: str, out: Path, threads: int) -> dict:
    """The Floquet multipliers of the orbit saved in ``path`` (``--save-orbits``) by the current
    :func:`~cosserat_chain.numerics.long_orbits.leading_multipliers`, written into its row of ``out`` (key: case and N,
    default rho, guard and settle; the row is made where there is none) as ``multipliers_recomputed``."""
    import warnings

    saved = np.load(path)
    n, moment = int(saved["N"]), float(saved["moment"])
    case = str(saved["case"]) if "case" in saved else case
    damping, _ = CASES[case]
    params = ChainParams(N=n) if damping is None else ChainParams(N=n, gamma_u=damping, gamma_v=damping, gamma_phi=damping)
    system = _System(params, get_model(MODEL), moment, 0)
    y0, period = saved["y0"], float(saved["period"])
    long_orbits.THREADS = threads
    load, cpu = os.getloadavg()[0], time.process_time()
    stored = path.with_name(f"{path.stem}_M.npy")
    matrix = np.load(stored) if stored.exists() else long_orbits.Monodromy(system, y0, period, RTOL, ATOL).matrix()
    formed = time.process_time() - cpu
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        values, errors = long_orbits.leading_multipliers(matrix, system.velocity(y0))
    cpu = time.process_time() - cpu
    trivial = int(np.argmin(np.abs(values - 1.0)))
    nontrivial = np.delete(np.arange(values.size), trivial)
    result = {
        "file": str(path), "monodromy": f"read from {stored.name}" if stored.exists() else "formed from blocks", "form_cpu_s": formed,
        "cpu_s": cpu, "load_average": load, "load_average_after": os.getloadavg()[0], "threads": threads,
        "peak_rss_GB": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1e6, "shift": long_orbits.SHIFT,
        "leading_multipliers": _leading(values, errors), "trivial_distance_from_1": abs(values[trivial] - 1.0),
        "trivial_error": float(errors[trivial]), "largest_nontrivial_residual": float(np.max(errors[nontrivial])),
        "max_nontrivial_multiplier": float(np.max(np.abs(values[nontrivial]))), "warnings": [str(w.message) for w in caught],
    }  # fmt: skip
    rows = json.loads(out.read_text()) if out.exists() else []
    key = (case, n, newton_picard.RHO, newton_picard.GUARD, 0)
    row = next((r for r in rows if _key(r) == key), None)
    if row is None:
        row = {"N": n, "size": y0.size, "case": case, "moment": moment, "rho": newton_picard.RHO, "guard": newton_picard.GUARD,
               "settle": 0, "methods": {}}  # fmt: skip
        rows.append(row)
    row["multipliers_recomputed"] = result
    out.write_text(json.dumps(sorted(rows, key=_key), indent=1))
    return result


def _key(row: dict) -> tuple:
    """A --picard row's key: its case, N, rho, guard and settle (rows from before these were recorded: their defaults then)."""
    return (row.get("case", "strong"), row["N"], row.get("rho", 0.5), row.get("guard", 8), row.get("settle", 0))


def _label(method: str, row: dict) -> str:
    """Newton-Picard's row names its rho and guard (rows from before they were options: 0.5 and 8); a row of another case
    than ``strong`` names it."""
    label = f"picard (rho {row.get('rho', 0.5)}, guard {row.get('guard', 8)})" if method == "picard" else method
    return label if row.get("case", "strong") == "strong" else f"{label}, {row['case']} case"


def picard_markdown(rows: list[dict]) -> str:
    lines = [
        "| N | 2 n_free | method | CPU s | load | Newton iterations | columns integrated (integrations) | period T | abs(mu) > rho: found / certified "
        "| largest residual | abs(mu_1 - 1) / its error | memory MB | blocks against Newton-Picard |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for row in rows:
        for method, e in row["methods"].items():
            if not e.get("converged", True):
                lines.append(
                    f"| {row['N']} | {row['size']} | {_label(method, row)} | {e['cpu_s']:.4g} | "
                    f"{e['load_average']:.1f}-{e['load_average_after']:.1f} | not converged: {e['message']} | "
                    f"{e['products']} ({e['integrations']}) | | | | | | |"
                )
                continue
            against = "" if "period_difference" not in e else (
                f"T {e['period_difference']:.1e}, y0 {e['state_difference']:.1e}, mu {e['multiplier_difference']:.1e}"
            )  # fmt: skip
            found = f"{e['above_rho']} / {e['certified_above_rho']}" if method == "picard" else f"{e['above_rho']} / -"
            lines.append(
                f"| {row['N']} | {row['size']} | {_label(method, row)} | {e['cpu_s']:.4g} | {e['load_average']:.1f}-{e['load_average_after']:.1f} | "
                f"{e['iterations']} | {e['products']} ({e['integrations']}) | {e['period']:.10g} | {found} | "
                f"{e['largest_residual_above_rho']:.1e} | {e['trivial_distance_from_1']:.1e} / {e['trivial_error']:.1e} | "
                f"{e['memory_MB']:.4g} | {against} |"
            )
    return "\n".join(lines)


def measure_segments(n: int, segments: int, dense_max: int, threads: int) -> dict:
    """Blocks without and with ``segments``, and the dense shooting with them up to ``dense_max``, at N = n (``--segments``)."""
    gamma_u, gamma_v, gamma_phi = SEGMENT_DAMPING
    params = ChainParams(N=n, gamma_u=gamma_u, gamma_v=gamma_v, gamma_phi=gamma_phi)
    rate = float(np.sum(per_dof(params, params.damping) / pack(params, params.particle_inertia)))
    long_orbits.THREADS = threads
    start = time.process_time()
    guess = initial_guess(params, MODEL, MOMENT)
    row = {"N": n, "size": 2 * n_free(params), "segments": segments, "guess_cpu_s": time.process_time() - start, "runs": {}}
    runs = [("blocks", None), ("blocks", segments)] + ([("dense", segments)] if n <= dense_max else [])
    reference = None
    for method, pieces in runs:
        load = os.getloadavg()[0]
        cpu = time.process_time()
        orbit = find_periodic_orbit(params, MODEL, MOMENT, guess=guess, method=method, segments=pieces)
        cpu = time.process_time() - cpu
        logs = orbit.log_moduli
        entry = {
            "cpu_s": cpu,
            "load_average": load,
            "period": orbit.period,
            "liouville_exact": -orbit.period * rate,
            "liouville_error": float(np.sum(logs) + orbit.period * rate),
            "smallest_log10_abs": float(np.min(logs) / math.log(10.0)),
            "max_nontrivial_multiplier": orbit.max_multiplier,
            "trivial_distance_from_1": abs(orbit.trivial_multiplier - 1.0),
            "trivial_error": orbit.trivial_multiplier_error,
        }
        if pieces is not None:
            if reference is None:
                reference = logs
            else:
                entry["log10_difference_from_blocks"] = float(np.max(np.abs(logs - reference)) / math.log(10.0))
        row["runs"][f"{method}" + ("" if pieces is None else f" + {pieces} segments")] = entry
    return row


def segments_markdown(rows: list[dict]) -> str:
    lines = [
        "| N | 2 n_free | method | CPU s | load | period T | sum ln abs(mu) - Liouville | smallest log10 abs(mu) | abs(mu_1 - 1) / its error | log10 abs(mu) against blocks + segments |",
        "|---|---|---|---|---|---|---|---|---|---|",
    ]
    for row in rows:
        for name, e in row["runs"].items():
            error = "-" if e["trivial_error"] is None else f"{e['trivial_error']:.1e}"
            against = f"{e['log10_difference_from_blocks']:.1e}" if "log10_difference_from_blocks" in e else ""
            lines.append(
                f"| {row['N']} | {row['size']} | {name} | {e['cpu_s']:.3g} | {e['load_average']:.1f} | {e['period']:.10g} | "
                f"{e['liouville_error']:.2e} (of {e['liouville_exact']:.6g}) | {e['smallest_log10_abs']:.2f} | "
                f"{e['trivial_distance_from_1']:.1e} / {error} | {against} |"
            )
    return "\n".join(lines)


def rates(n: int, dense_max: int, span: float) -> dict:
    """CPU seconds per unit time of the state, one product, one block and the one-piece monodromy at N = n."""
    params = ChainParams(N=n, gamma_u=DAMPING, gamma_v=DAMPING, gamma_phi=DAMPING)
    system = _System(params, get_model(MODEL), MOMENT, 0)
    rng = np.random.default_rng(0)
    y0 = np.concatenate([0.3 * rng.standard_normal(system.nf), 0.1 * rng.standard_normal(system.nf)])
    size = 2 * system.nf
    block = rng.standard_normal((size, long_orbits.BLOCK_COLUMNS))
    long_orbits.Monodromy(system, y0, 0.01, 1e-11, 1e-11).apply(block[:, :2])  # compile outside the timing
    row = {"N": n, "size": size}

    def timed(call) -> float:
        start = time.process_time()
        call()
        return (time.process_time() - start) / span

    row["state_s"] = timed(lambda: system.flow(y0, span, rtol=1e-11, atol=1e-11, variations=False))
    row["product_s"] = timed(lambda: long_orbits.Monodromy(system, y0, span, 1e-11, 1e-11).apply(block[:, 0]))
    row["block_s"] = timed(lambda: long_orbits.Monodromy(system, y0, span, 1e-11, 1e-11).apply(block))
    row["blocks_whole_s"] = row["block_s"] * size / long_orbits.BLOCK_COLUMNS
    row["dense_s"] = timed(lambda: system.flow(y0, span, rtol=1e-11, atol=1e-11, variations=True)) if n <= dense_max else None
    row["matrix_MB"] = 8 * size * size / 1e6
    row["dense_integration_MB"] = 16 * 8 * size * (size + 2) / 1e6
    return row


def continuation(n: int, segments: int, threads: int) -> dict:
    """An orbit at N = n by the blocks with ``segments``, and its continuation over CONTINUATION_POINTS points (``--continuation``)."""
    gamma_u, gamma_v, gamma_phi = SEGMENT_DAMPING
    params = ChainParams(N=n, gamma_u=gamma_u, gamma_v=gamma_v, gamma_phi=gamma_phi)
    rate = float(np.sum(per_dof(params, params.damping) / pack(params, params.particle_inertia)))
    long_orbits.THREADS = threads
    row = {"N": n, "size": 2 * n_free(params), "segments": segments, "load_average": os.getloadavg()[0]}
    cpu = time.process_time()
    guess = initial_guess(params, MODEL, MOMENT)
    row["guess_cpu_s"] = time.process_time() - cpu
    cpu = time.process_time()
    orbit = find_periodic_orbit(params, MODEL, MOMENT, guess=guess, method="blocks", segments=segments)
    row["orbit_cpu_s"] = time.process_time() - cpu
    cpu = time.process_time()
    branch = continue_orbit(orbit, method="blocks", segments=segments, max_points=CONTINUATION_POINTS, step=CONTINUATION_STEP)
    row["continuation_cpu_s"] = time.process_time() - cpu
    row["load_average_after"] = os.getloadavg()[0]
    points = []
    for point in branch.orbits:
        system = _System(params, get_model(MODEL), point.moment, 0)
        start = _to_y(params, point.x, point.v)
        end, _, _ = system.flow(start, point.period, rtol=1e-11, atol=1e-11, variations=False)
        end[system.load_dof] -= 2 * math.pi
        points.append(
            {
                "moment": point.moment,
                "period": point.period,
                "iterations": point.iterations,
                "trivial_distance_from_1": abs(point.trivial_multiplier - 1.0),
                "trivial_error": point.trivial_multiplier_error,
                "max_nontrivial_multiplier": point.max_multiplier,
                "liouville_error": float(np.sum(point.multiplier_log_moduli) + point.period * rate),
                "direct_run_closure": float(np.max(np.abs(end - start))),
            }
        )
    row["points"] = points
    return row


def continuation_markdown(rows: list[dict]) -> str:
    lines = [
        "| N | 2 n_free | segments | orbit CPU s | continuation CPU s (points) | load | M | period T | abs(mu_1 - 1) / its error | "
        "sum ln abs(mu) - Liouville | direct run's closure |",
        "|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        for k, p in enumerate(r["points"]):
            head = (
                f"| {r['N']} | {r['size']} | {r['segments']} | {r['orbit_cpu_s']:.3g} | {r['continuation_cpu_s']:.3g} ({len(r['points'])}) | "
                f"{r['load_average']:.1f}-{r['load_average_after']:.1f} |"
                if k == 0
                else "| | | | | | |"
            )
            lines.append(
                f"{head} {p['moment']:.8g} | {p['period']:.10g} | {p['trivial_distance_from_1']:.1e} / {p['trivial_error']:.1e} | "
                f"{p['liouville_error']:.1e} | {p['direct_run_closure']:.1e} |"
            )
    return "\n".join(lines)


def rates_markdown(rows: list[dict]) -> str:
    lines = [
        "| N | 2 n_free | state | one product | one block of 64 | all blocks (M) | dense in one piece | M (MB) | one-piece integration (MB) |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        dense = "-" if r["dense_s"] is None else f"{r['dense_s']:.3g}"
        lines.append(
            f"| {r['N']} | {r['size']} | {r['state_s']:.2g} | {r['product_s']:.2g} | {r['block_s']:.2g} | {r['blocks_whole_s']:.3g} | "
            f"{dense} | {r['matrix_MB']:.3g} | {r['dense_integration_MB']:.3g} |"
        )
    return "\n".join(lines)


def markdown(rows: list[dict]) -> str:
    lines = [
        "| N | 2 n_free | method | CPU s | wall s | Newton iterations | columns integrated | period T | largest other abs(mu) | abs(mu_1 - 1) / its error | against the first |",
        "|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for row in rows:
        for method, e in row["methods"].items():
            against = "" if "period_difference" not in e else f"T {e['period_difference']:.1e}, mu {e['multiplier_difference']:.1e}"
            error = "-" if e["trivial_error"] is None else f"{e['trivial_error']:.1e}"
            lines.append(
                f"| {row['N']} | {row['size']} | {method} | {e['cpu_s']:.3g} | {e['wall_s']:.3g} | {e['iterations']} | {e['products']} | "
                f"{e['period']:.10g} | {e['max_nontrivial_multiplier']:.6f} | {e['trivial_distance_from_1']:.1e} / {error} | {against} |"
            )
    return "\n".join(lines)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sizes", type=int, nargs="+", default=list(SIZES), help="N values")
    parser.add_argument("--methods", nargs="+", default=list(METHODS), choices=METHODS)
    parser.add_argument("--dense-max", type=int, default=100, help="largest N for the dense method")
    parser.add_argument("--krylov-max", type=int, default=30, help="largest N for the Krylov method")
    parser.add_argument("--threads", type=int, default=1, help="threads of the blocks")
    parser.add_argument("--out", type=Path, default=RESULTS / "long_orbits.json")
    parser.add_argument("--json", action="store_true", help="print the results as one JSON object")
    parser.add_argument("--rates", action="store_true", help="only the costs per unit time, N = 10 ... 1000")
    parser.add_argument("--segments", type=int, default=None, metavar="M", help="blocks with M segments against the formed monodromy")
    parser.add_argument("--continuation", type=int, default=None, metavar="M", help="an orbit and a short continuation, M segments")
    parser.add_argument("--picard", action="store_true", help="Newton-Picard against the blocks, N = 50 ... 1000")
    parser.add_argument("--blocks-max", type=int, default=200, help="largest N for the blocks in --picard")
    parser.add_argument("--progress", action="store_true", help="print the columns integrated after every block (--picard)")
    parser.add_argument("--rho", type=float, default=newton_picard.RHO, help="Newton-Picard's rho (--picard)")
    parser.add_argument("--guard", type=int, default=newton_picard.GUARD, help="Newton-Picard's guard columns (--picard)")
    parser.add_argument("--settle", type=int, default=0, help="further initial_guess calls continuing the guess (--picard)")
    parser.add_argument("--case", choices=sorted(CASES), default="strong", help="the chain and moment of --picard (CASES)")
    parser.add_argument("--save-orbits", type=Path, default=None, metavar="DIR", help="write each converged orbit to DIR (--picard)")
    parser.add_argument(
        "--multipliers-from", type=Path, default=None, metavar="FILE", help="the multipliers of a saved orbit again, into its row"
    )
    parser.add_argument(
        "--picard-methods", nargs="+", choices=("picard", "blocks"), default=["picard", "blocks"], help="the methods of --picard, in order"
    )
    args = parser.parse_args()
    log = sys.stderr if args.json else sys.stdout
    default_out = RESULTS / "long_orbits.json"

    def chosen(default_sizes: list[int], name: str) -> tuple[list[int], Path]:
        """A mode's own sizes and file where --sizes and --out were left at the default run's."""
        return (args.sizes if args.sizes != list(SIZES) else default_sizes), (args.out if args.out != default_out else RESULTS / name)

    if args.multipliers_from is not None:
        _, out = chosen([], "long_orbit_picard.json")
        print(json.dumps(multipliers_from(args.multipliers_from, args.case, out, args.threads), indent=1), file=log)
    elif args.picard:
        sizes, out = chosen([50, 100, 200, 500, 1000], "long_orbit_picard.json")
        counter = _Counter(log if args.progress else None)
        _sweep(
            sizes,
            lambda n: measure_picard(
                n, args.blocks_max, args.threads, counter, args.rho, args.guard, args.settle, args.case, tuple(args.picard_methods),
                args.save_orbits,
            ),
            picard_markdown, out, log, args.json, merge=_key,
        )  # fmt: skip
    elif args.continuation is not None:
        sizes, out = chosen([100, 200], "long_orbit_continuation.json")
        _sweep(sizes, lambda n: continuation(n, args.continuation, args.threads), continuation_markdown, out, log, args.json)
    elif args.segments is not None:
        sizes, out = chosen([50, 100], "long_orbit_segments.json")
        _sweep(sizes, lambda n: measure_segments(n, args.segments, args.dense_max, args.threads), segments_markdown, out, log, args.json)
    elif args.rates:
        sizes, out = chosen([10, 30, 100, 200, 1000], "long_orbit_rates.json")
        _sweep(sizes, lambda n: rates(n, args.dense_max, RATE_SPAN), rates_markdown, out, log, args.json)
    else:
        counter = _Counter()
        _sweep(
            args.sizes,
            lambda n: measure(n, args.methods, args.dense_max, args.krylov_max, args.threads, counter),
            markdown,
            args.out,
            log,
            args.json,
        )


def _sweep(sizes: list[int], measure_one, table_markdown, out: Path, log, as_json: bool, merge=None) -> None:
    """Measure each N in turn, print its table row and rewrite ``out`` as each one comes (an interrupted sweep keeps its
    rows), then print the whole table (and the rows as JSON with ``as_json``). With ``merge`` (a row's key), the rows
    already in ``out`` are kept, a new row replacing the old one with its key."""
    table = []
    kept = json.loads(out.read_text()) if merge is not None and out.exists() else []
    for n in sizes:
        table.append(measure_one(n))
        print("\n".join(table_markdown(table[-1:]).splitlines()[2:]), file=log, flush=True)
        out.parent.mkdir(exist_ok=True)
        new = {merge(row) for row in table} if merge is not None else set()
        rows = [row for row in kept if merge(row) not in new] + table if merge is not None else table
        out.write_text(json.dumps(sorted(rows, key=merge) if merge is not None else rows, indent=1))
    print(table_markdown(table), file=log)
    if as_json:
        print(json.dumps(table))


if __name__ == "__main__":
    main()
