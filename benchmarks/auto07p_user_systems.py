"""AUTO-07p beside the package on two user systems that no test holds, each rotation (every angle one turn a period)
followed down in its drive to its end:

* a Josephson array of three junctions with free ends (``systems.josephson_array``, kappa = 0.37, alpha = 0.23),
  phi_i'' + alpha phi_i' + sin phi_i = I + kappa (phi_{i+1} - 2 phi_i + phi_{i-1}), from I = 0.8: it period-doubles
  three times and ends at a homoclinic orbit;
* a Frenkel-Kontorova chain of three particles with free ends and springs of rest length a0
  (``systems.frenkel_kontorova``, C = 0.61, V = 1, gamma = 0.29, a0 = 1.3: the ends pulled apart, no symmetry reduces
  the sliding state), from F = 0.9: two torus points and a fold of cycles.

Each system is written as an AUTO-07p equations file (PAR(1) the drive, PAR(2..4) the other parameters), checked
against the package's vector field at a random state. The package's orbit at the start is AUTO's starting data (AUTO
takes the angles' whole turns over a period from it). AUTO continues it down in the drive (ICP = [1, 11]) with user
points at the checkpoints (periods, Floquet multipliers), labels its period doublings (PD), tori (TR) and folds (LP),
and stops at the first fold (the sliding state) or where the period reaches ``PERIOD_STOP`` (the array: the orbit's
I there equals its value at period 35 to AUTO's 11 printed digits, so AUTO's last I is its homoclinic end). Twice:
NTST = 100 and 200 (NCOL = 4), the difference AUTO's own error.

The package: ``numerics.shooting.continue_orbits`` in the drive (its located events), ``find_orbit`` at each checkpoint
from the branch's orbit nearest to it, ``experiments.system_diagram`` for the end (a homoclinic end solved as a
boundary-value problem, with its accuracy; a fold of cycles located by the continuation).

Needs ``auto-07p`` on the PATH (the Debian package auto-07p, with gfortran). Usage::

    python benchmarks/auto07p_user_systems.py [WORKDIR]

writes ``benchmarks/results/auto07p_user_systems.json``.
"""

from __future__ import annotations

import json
import platform
import resource
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from auto07p_common import EQUATIONS, b_rows, constants_file, fortran, multipliers, one_run_script, orbit_files, run_auto  # noqa: F401 - auto07p_jj3_snake reads EQUATIONS and fortran from here
from cosserat_chain.experiments.system_diagram import system_diagram
from cosserat_chain.numerics.shooting import continue_orbits, find_orbit, settled_guess
from cosserat_chain.systems.base import System
from cosserat_chain.systems.frenkel_kontorova import frenkel_kontorova
from cosserat_chain.systems.josephson import josephson_array

#: AUTO's run stops where the period reaches this (a homoclinic end, see the module docstring).
PERIOD_STOP = 150.0
RESULTS = Path(__file__).resolve().parent / "results" / "auto07p_user_systems.json"


@dataclass
class Case:
    """One system: how the package builds it, its drive and other parameters (AUTO's PAR(1), PAR(2), ...), the
    accelerations in Fortran (U(1..3) the angles, U(4..6) their rates) and in numpy (the check), the start, the
    checkpoints, the parameter the package's diagram varies, and AUTO's STOP."""

    name: str
    build: Callable[..., System]
    drive: str
    others: dict[str, float]
    fortran: tuple[str, str, str]
    numpy: Callable[[np.ndarray, np.ndarray, dict], np.ndarray]
    start: float
    checkpoints: tuple[float, ...]
    vary: str
    stop: list[str]


def _jj(p: np.ndarray, v: np.ndarray, c: dict) -> np.ndarray:
    lap = np.array([p[1] - p[0], p[0] - 2 * p[1] + p[2], p[1] - p[2]])
    return c["I"] - np.sin(p) - c["alpha"] * v + c["kappa"] * lap


def _fk(p: np.ndarray, v: np.ndarray, c: dict) -> np.ndarray:
    bonds = np.array([p[1] - p[0] - c["a0"], p[0] - 2 * p[1] + p[2], p[1] - p[2] + c["a0"]])
    return c["F"] - np.sin(p) - c["gamma"] * v + c["C"] * bonds


CASES = (
    Case(
        "josephson_array",
        lambda **k: josephson_array(3, **k),
        "I",
        {"kappa": 0.37, "alpha": 0.23},
        (
            "PAR(1)-SIN(U(1))-PAR(3)*U(4)+PAR(2)*(U(2)-U(1))",
            "PAR(1)-SIN(U(2))-PAR(3)*U(5)+PAR(2)*(U(1)-2.0D0*U(2)+U(3))",
            "PAR(1)-SIN(U(3))-PAR(3)*U(6)+PAR(2)*(U(2)-U(3))",
        ),
        _jj,
        0.8,
        (0.7, 0.5, 0.4, 0.3),
        "alpha",
        [],
    ),
    Case(
        "frenkel_kontorova",
        lambda **k: frenkel_kontorova(3, V=1.0, **k),
        "F",
        {"C": 0.61, "gamma": 0.29, "a0": 1.3},
        (
            "PAR(1)-SIN(U(1))-PAR(3)*U(4)+PAR(2)*(U(2)-U(1)-PAR(4))",
            "PAR(1)-SIN(U(2))-PAR(3)*U(5)+PAR(2)*(U(1)-2.0D0*U(2)+U(3))",
            "PAR(1)-SIN(U(3))-PAR(3)*U(6)+PAR(2)*(U(2)-U(3)+PAR(4))",
        ),
        _fk,
        0.9,
        (0.8, 0.7, 0.6, 0.55),
        "gamma",
        ["LP1"],
    ),
)

#: AUTO's run down in the drive (NTST, the user points and the stop are each case's).
SETTINGS = dict(NDIM=6, NMX=3000, RL0=0.2, RL1=1.0, A1=1e6, NPR=5000, DS=-0.002, DSMIN=1e-9, DSMAX=0.02, UZSTOP={11: PERIOD_STOP})

#: AUTO-07p's label types in a b-file, and the package's event kinds they answer.
LABELS = {-4: "UZ", 4: "UZ", 7: "PD", -7: "PD", 5: "LP", 6: "BP", 8: "TR", -9: "EP", 9: "EP"}
KINDS = {"period_doubling": "PD", "torus": "TR", "fold": "LP"}


def package_start(case: Case):
    """The package's rotation at the start: a settling run, then shooting."""
    system = case.build(**{case.drive: case.start}, **case.others)
    damping = case.others.get("alpha", case.others.get("gamma"))
    guess = settled_guess(system, np.concatenate([np.zeros(3), np.full(3, case.start / damping)]), coordinate=0)
    return find_orbit(system, guess, turns={name: 1 for name in system.coordinates})


def check_equations(case: Case, system: System) -> None:
    """AUTO's FUNC (written out in numpy) equals the package's vector field at a random state."""
    y = np.random.default_rng(3).standard_normal(6)
    acc = case.numpy(y[:3], y[3:], system.parameters)
    assert np.allclose(system.vector_field(y), np.concatenate([y[3:], acc]), atol=1e-13), f"AUTO's {case.name} differs from the package's"


def run_auto07p(workdir: Path, case: Case, orbit, ntst: int) -> dict:
    """AUTO's continuation at NTST = ``ntst``: its labelled points (drive, period, multipliers), last point, CPU time."""
    workdir.mkdir(parents=True, exist_ok=True)
    files = {
        **orbit_files(case.fortran, [case.start, *case.others.values()], orbit),
        "c.u": constants_file(NTST=ntst, UZR={1: list(case.checkpoints)}, **SETTINGS, STOP=case.stop),
        "u.auto": one_run_script("u", "u", dat="u"),
    }
    before, children = time.process_time(), resource.getrusage(resource.RUSAGE_CHILDREN)
    run_auto(workdir, "u.auto", files)
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = (after.ru_utime + after.ru_stime) - (children.ru_utime + children.ru_stime) + time.process_time() - before
    mu: dict[int, list[complex]] = {}
    for point, m in multipliers(workdir / "d.u"):
        mu.setdefault(point, []).append(m)
    labelled, last = [], None
    for point, kind, row in b_rows(workdir / "b.u"):
        last = {"value": row[0], "period": row[-1]}
        if kind in LABELS:
            # A located point's multipliers are printed at each of its iterations: the last six are the point's.
            final = mu.get(point, [])[-6:]
            labelled.append({"label": LABELS[kind], "value": row[0], "period": row[-1], "multipliers": [[z.real, z.imag] for z in final]})
    return {"ntst": ntst, "points": labelled, "last": last, "cpu_s_with_compile": cpu}


def package_numbers(case: Case, start, checkpoints: list[float]) -> dict:
    """The package's periods and multipliers at ``checkpoints`` (AUTO's user points, where it printed them), its
    located events and its end."""
    branch = continue_orbits(start, case.drive, period_max=200.0)
    out: dict = {"checkpoints": []}
    for target in checkpoints:
        # Newton at the checkpoint from the branch's orbit nearest to it.
        near = branch.orbits[int(np.argmin(np.abs(branch.values - target)))]
        orbit = find_orbit(near.system.with_parameters(**{case.drive: target}), near)
        out["checkpoints"].append(
            {
                "value": target,
                "period": orbit.period,
                "multipliers": [[z.real, z.imag] for z in orbit.multipliers],
                "closure": orbit.closure,
            }
        )
    out["events"] = [{"kind": e.kind, "value": e.parameter, "located": e.located} for e in branch.events]
    out["branch_end"] = {"end": str(branch.end), "fitted": branch.end_value, "fit_uncertainty": branch.end_uncertainty}
    # The diagram continues the equilibrium up in the drive from zero (none exists at the start above the fold).
    at_rest = start.system.with_parameters(**{case.drive: 0.0})
    row = system_diagram(at_rest, case.vary, [case.others[case.vary]], case.drive).rows[0]
    out["end"] = {
        "end": row.end,
        "value": row.stops,
        "method": row.method,
        "accuracy": row.accuracy,
        "starts": row.starts,
        "message": row.message,
        "reason": row.reason,
    }
    return out


def nearest_distance(a: list, b: list) -> float:
    """The largest distance from a multiplier of ``a`` to the nearest of ``b`` (both lists of [re, im])."""
    za, zb = (np.array([complex(*z) for z in zs]) for zs in (a, b))
    return float(max(np.min(np.abs(zb - z)) for z in za))


def compare(case: Case, ours: dict, auto: dict) -> list[dict]:
    """The table's rows: periods and multipliers at the checkpoints, each located event, the end."""
    fine, coarse = auto[200], auto[100]
    d = case.drive
    table = []
    for mine in ours["checkpoints"]:
        (theirs,) = [p for p in fine["points"] if p["label"] == "UZ" and p["value"] == mine["value"]]
        (theirs100,) = [p for p in coarse["points"] if p["label"] == "UZ" and abs(p["value"] - mine["value"]) < 1e-6]
        table.append(
            {
                "what": f"period at {d} = {mine['value']:.11g}",
                "package": mine["period"],
                "auto07p": theirs["period"],
                "difference": mine["period"] - theirs["period"],
                "auto07p_ntst100_minus_ntst200": theirs100["period"] - theirs["period"],
                "auto07p_ntst100_value_minus_ntst200": theirs100["value"] - theirs["value"],
                "multipliers_max_distance": nearest_distance(theirs["multipliers"], mine["multipliers"]),
                "package_multipliers": mine["multipliers"],
                "auto07p_multipliers": theirs["multipliers"],
            }
        )
    for kind, label in KINDS.items():
        mine_events = [e for e in ours["events"] if e["kind"] == kind]
        theirs, theirs100 = ([p for p in run["points"] if p["label"] == label] for run in (fine, coarse))
        for k, (m, t) in enumerate(zip(mine_events, theirs)):
            table.append(
                {
                    "what": f"{kind} {k + 1}: {d}",
                    "package": m["value"],
                    "auto07p": t["value"],
                    "difference": m["value"] - t["value"],
                    "auto07p_ntst100_minus_ntst200": theirs100[k]["value"] - t["value"] if k < len(theirs100) else None,
                    "auto07p_period": t["period"],
                }
            )
        if len(mine_events) != len(theirs):
            table.append(
                {"what": f"{kind}: the package located {len(mine_events)}, AUTO-07p {len(theirs)}", "package": None, "auto07p": None}
            )
    table.append(
        {
            "what": f"end ({ours['end']['end']}, {ours['end']['method']}): {d}",
            "package": ours["end"]["value"],
            "package_accuracy": ours["end"]["accuracy"],
            "auto07p": fine["last"]["value"],
            "auto07p_period": fine["last"]["period"],
            "difference": None if ours["end"]["value"] is None else ours["end"]["value"] - fine["last"]["value"],
            "auto07p_ntst100_minus_ntst200": coarse["last"]["value"] - fine["last"]["value"],
        }
    )
    return table


def main(workdir: Path) -> None:
    results = {}
    for case in CASES:
        start = package_start(case)
        check_equations(case, start.system)
        auto = {ntst: run_auto07p(workdir / case.name / f"ntst{ntst}", case, start, ntst) for ntst in (100, 200)}
        before = time.process_time()
        ours = package_numbers(
            case,
            start,
            [p["value"] for p in auto[200]["points"] if p["label"] == "UZ" and min(abs(p["value"] - c) for c in case.checkpoints) < 1e-6],
        )
        ours_cpu = time.process_time() - before
        table = compare(case, ours, auto)
        print(f"{case.name} {case.others}, continued down in {case.drive} from {case.start}:")
        for row in table:
            if row["package"] is None or row["auto07p"] is None:
                print(f"  {row['what']}: package {row['package']}, AUTO-07p {row['auto07p']}")
                continue
            print(f"  {row['what']:<44} package {row['package']:.12g}  AUTO-07p {row['auto07p']:.12g}  difference {row['difference']:.2e}")
            if "multipliers_max_distance" in row:
                print(f"  {'':<44} multipliers: largest distance {row['multipliers_max_distance']:.2e}")
        results[case.name] = {
            "parameters": {case.drive: case.start, **case.others},
            "table": table,
            "package": ours,
            "auto07p": {str(k): v for k, v in auto.items()},
            "cpu_s": {"package": ours_cpu, "auto07p_ntst200_with_compile": auto[200]["cpu_s_with_compile"]},
        }
    load = Path("/proc/loadavg").read_text().split()[:3]
    RESULTS.write_text(json.dumps({"cases": results, "load_average": load, "machine": platform.machine()}, indent=1) + "\n")
    print(f"wrote {RESULTS} (load average {' '.join(load)})")


if __name__ == "__main__":
    main(Path(sys.argv[1] if len(sys.argv) > 1 else "auto07p-user-systems"))
