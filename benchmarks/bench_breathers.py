"""Cost of a roto-breather family against the chain's length, by the dense shooting and the column blocks.

Run from the repository root::

    python benchmarks/bench_breathers.py                          # N = 10, 25, 50, 100 (dense to 50)
    python benchmarks/bench_breathers.py --sizes 10 50 200 --dense-max 25
    python benchmarks/bench_breathers.py --json                   # also print the JSON on stdout
    python benchmarks/bench_breathers.py --located-atlas --sizes 10 25 50   # the cost of locating an atlas's changes
    python benchmarks/bench_breathers.py --located-field --sizes 10 25      # ... along b against along Omega

The undamped sine chain (eq. (2), other fields default), one rotor on particle 0, the family at
Omega = 6.6, 6.5, 6.4 (above the optical band, every member stable): Newton from the
anti-continuum rotor at the first frequency, then each member from the secant through the two
before it, the blocks' Newton starting from the last member's Jacobian
(:func:`~cosserat_chain.numerics.long_breathers.find_breather_orbit`). For each N and method:
CPU seconds of the family (all threads: the blocks run on ``--threads``, default 1, so that CPU
time compares methods) and per member, wall seconds, Newton iterations, and the largest
distance of the members' states and largest multipliers from the dense method's. The dense
method runs up to ``--dense-max`` (its memory is 16 (2 n_free)^2 numbers). Results go to
``benchmarks/results/breathers.json`` (docs/roto-breathers.md).

With ``--located-atlas``: the atlas of the same chain over :data:`ATLAS_OMEGAS` at its own b (the
family loses stability between 6.4 and 6.2: a Krein collision, the combination w_TA + w_RO = Omega), then its changes of stability located
(:meth:`~cosserat_chain.experiments.breather_atlas.BreatherAtlas.locate_changes`) at the
default tolerance between neighbours of opposite stability (``default``), between every pair of
neighbours whose pairs off the circle differ (``every``), and by a family's full bisections and
secant over every pair (``family``: :func:`~cosserat_chain.experiments.breathers.located_changes`
over the same members, no tolerance), alternately, ``--repeats`` times: CPU seconds of the atlas
and of each location, the changes with their accuracies. Results go to ``benchmarks/results/breather_atlas_located.json``.

With ``--located-field``: the atlas over :data:`FIELD_OMEGAS` and b = :data:`FIELD_VALUES`, its changes located along Omega
and along b (``along``), alternately, ``--repeats`` times: CPU seconds of each; and each change along b found again along
Omega on the row at its b (Omega +- :data:`ACROSS` about its column, with ``every``: other quartets may be off the circle at both ends):
the distance of the two places in Omega against the row's accuracy. Results go to ``benchmarks/results/breather_atlas_located_field.json``.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path

import numpy as np

from cosserat_chain import ChainParams
from cosserat_chain.experiments.breathers import anti_continuum_state
from cosserat_chain.numerics import long_orbits
from cosserat_chain.numerics.long_breathers import find_breather_orbit

RESULTS = Path(__file__).resolve().parent / "results"
SIZES = (10, 25, 50, 100)
OMEGAS = (6.6, 6.5, 6.4)
MODEL = "sine"
ATLAS_OMEGAS = (6.6, 6.4, 6.2, 6.0)
FIELD_OMEGAS = (6.6, 6.4, 6.2)
FIELD_VALUES = (0.18, 0.2, 0.22)
#: The row through a change along b spans its Omega +- this (narrow: on a long chain's dense circle a wider row may hold
#: another quartet leaving and one coming back, equal counts at its ends).
ACROSS = 1e-3


def located_field(params: ChainParams, repeats: int) -> dict:
    """The atlas over :data:`FIELD_OMEGAS` x b = :data:`FIELD_VALUES`, the cost of locating its changes along Omega and along b,
    and each change along b found again along Omega on the row through it."""
    from cosserat_chain.experiments.breather_atlas import breather_atlas

    cpu = time.process_time()
    atlas = breather_atlas(params, MODEL, FIELD_OMEGAS, "b", FIELD_VALUES)
    out = {"atlas_cpu_s": time.process_time() - cpu, "stable": atlas.grid("stable").tolist(), "locate": {"omega": [], "b": []}}
    for _ in range(repeats):
        for axis in ("omega", "b"):
            cpu = time.process_time()
            atlas.locate_changes(along=axis)
            out["locate"][axis].append(time.process_time() - cpu)
            out[f"changes_{axis}"] = [c.as_dict() for c in atlas.changes]
    out["across"] = []
    for change in out["changes_b"]:
        row = breather_atlas(params, MODEL, [change["omega"] + ACROSS, change["omega"] - ACROSS], "b", [change["value"]])
        row.locate_changes(along="omega", every=True)
        nearest = min(row.changes, key=lambda c: abs(c.omega - change["omega"]), default=None)
        out["across"].append(None if nearest is None else {
            "omega": nearest.omega, "accuracy": nearest.accuracy, "distance": abs(nearest.omega - change["omega"]),
            "kind": nearest.change.kind, "value_accuracy": change["accuracy"],
        })  # fmt: skip
    return out


def located_atlas(params: ChainParams, repeats: int) -> dict:
    """The atlas over :data:`ATLAS_OMEGAS` and the cost of locating its changes by default, with ``every`` and as a family does."""
    from cosserat_chain.experiments.breather_atlas import LOCATE_TOL, breather_atlas
    from cosserat_chain.experiments.breathers import located_changes

    cpu = time.process_time()
    atlas = breather_atlas(params, MODEL, ATLAS_OMEGAS, "b", [params.b])
    out = {"atlas_cpu_s": time.process_time() - cpu, "stable": atlas.grid("stable").tolist()}
    out["locate"] = {name: [] for name in ("default", "every", "family")}
    for _ in range(repeats):
        for name, every in (("default", False), ("every", True)):
            cpu = time.process_time()
            atlas.locate_changes(LOCATE_TOL, every=every)
            out["locate"][name].append(time.process_time() - cpu)
            out[f"changes_{name}"] = [{"omega": c.change.omega, "accuracy": c.accuracy, "kind": c.change.kind} for c in atlas.changes]
        cpu = time.process_time()
        changes = located_changes([p.orbit for p in atlas.points[0]], atlas.bands)
        out["locate"]["family"].append(time.process_time() - cpu)
        out["changes_family"] = [{"omega": c.omega, "accuracy": c.accuracy, "kind": c.kind} for c in changes]
    return out


def family(params: ChainParams, method: str) -> dict:
    """The family at :data:`OMEGAS` by ``method``: its cost and members."""
    cpu, wall = time.process_time(), time.perf_counter()
    members, solved = [], None
    for i, omega in enumerate(OMEGAS):
        if i == 0:
            guess = anti_continuum_state(params, MODEL, omega)[:2]
        elif i == 1:
            guess = members[-1]
        else:
            a, b = members[-2], members[-1]
            r = (omega - b.omega) / (b.omega - a.omega)
            guess = (b.x + r * (b.x - a.x), b.v + r * (b.v - a.v))
        solved = find_breather_orbit(params, MODEL, omega, guess, method=method, jacobian0=None if solved is None else solved.jacobian)
        members.append(solved.orbit)
    cpu, wall = time.process_time() - cpu, time.perf_counter() - wall
    return {
        "cpu_s": cpu,
        "cpu_s_per_member": cpu / len(OMEGAS),
        "wall_s": wall,
        "iterations": [o.iterations for o in members],
        "max_multiplier": [o.max_multiplier for o in members],
        "stable": [bool(o.stable) for o in members],
        "members": members,
    }


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sizes", type=int, nargs="+", default=list(SIZES))
    parser.add_argument("--dense-max", type=int, default=50)
    parser.add_argument("--threads", type=int, default=1)
    parser.add_argument("--json", action="store_true")
    parser.add_argument("--located-atlas", action="store_true")
    parser.add_argument("--located-field", action="store_true")
    parser.add_argument("--repeats", type=int, default=2)
    args = parser.parse_args()
    long_orbits.THREADS = args.threads
    if args.located_field:
        rows = []
        for n in args.sizes:
            row = {"N": n, **located_field(ChainParams(N=n, gamma_u=0.0, gamma_v=0.0, gamma_phi=0.0), args.repeats)}
            rows.append(row)
            costs = ", ".join(f"along {a} {len(row['changes_' + a])} changes {min(c):.3g} s" for a, c in row["locate"].items())
            print(f"N = {n}: atlas {row['atlas_cpu_s']:.3g} s; {costs}", file=sys.stderr, flush=True)
            RESULTS.mkdir(exist_ok=True)
            text = json.dumps(
                {"model": MODEL, "omegas": FIELD_OMEGAS, "values": FIELD_VALUES, "load_average": list(os.getloadavg()), "rows": rows},
                indent=1,
            )
            (RESULTS / "breather_atlas_located_field.json").write_text(text + "\n")
        if args.json:
            print(text)
        return 0
    if args.located_atlas:
        rows = []
        for n in args.sizes:
            row = {"N": n, **located_atlas(ChainParams(N=n, gamma_u=0.0, gamma_v=0.0, gamma_phi=0.0), args.repeats)}
            rows.append(row)
            costs = ", ".join(f"{t} {min(c):.3g} s" for t, c in row["locate"].items())
            print(f"N = {n}: atlas {row['atlas_cpu_s']:.3g} s; locating its changes: {costs}", file=sys.stderr, flush=True)
            RESULTS.mkdir(exist_ok=True)
            text = json.dumps({"model": MODEL, "omegas": ATLAS_OMEGAS, "load_average": list(os.getloadavg()), "rows": rows}, indent=1)
            (RESULTS / "breather_atlas_located.json").write_text(text + "\n")
        if args.json:
            print(text)
        return 0
    rows = []
    for n in args.sizes:
        params = ChainParams(N=n, gamma_u=0.0, gamma_v=0.0, gamma_phi=0.0)
        row = {"N": n, "size": 2 * (3 * (2 * n + 1) - 6), "methods": {}}
        for method in ("dense", "blocks"):
            if method == "dense" and n > args.dense_max:
                continue
            row["methods"][method] = family(params, method)
        if "dense" in row["methods"]:
            dense = row["methods"]["dense"]["members"]
            blocks = row["methods"]["blocks"]["members"]
            row["blocks_vs_dense"] = {
                "state": max(float(max(np.abs(a.x - b.x).max(), np.abs(a.v - b.v).max())) for a, b in zip(dense, blocks)),
                "max_multiplier": max(abs(a.max_multiplier - b.max_multiplier) for a, b in zip(dense, blocks)),
                "cpu_ratio": row["methods"]["blocks"]["cpu_s"] / row["methods"]["dense"]["cpu_s"],
            }
        for result in row["methods"].values():
            del result["members"]
        rows.append(row)
        line = ", ".join(f"{m} {r['cpu_s']:.3g} s ({r['cpu_s_per_member']:.3g} s a member)" for m, r in row["methods"].items())
        print(f"N = {n} (2 n_free = {row['size']}): {line}", file=sys.stderr, flush=True)
    RESULTS.mkdir(exist_ok=True)
    text = json.dumps({"model": MODEL, "omegas": OMEGAS, "threads": args.threads, "rows": rows}, indent=1)
    (RESULTS / "breathers.json").write_text(text + "\n")
    if args.json:
        print(text)
    return 0


if __name__ == "__main__":
    sys.exit(main())
