"""The commands on a user's system: ``states``, ``critical``, ``orbit``, ``simulate`` and ``diagram`` with ``--system REF``.

A command given ``--system`` runs on a :class:`~cosserat_chain.systems.base.System` (a
built-in example, ``module:function`` or ``file.py:function``, built with the config's
``[system]`` table and ``--set NAME=VALUE``) through :mod:`cosserat_chain.numerics.equilibria`
and :mod:`cosserat_chain.numerics.shooting` (``diagram`` through
:mod:`cosserat_chain.experiments.system_diagram`); without it the command runs on the chain as
before. The chain's own options (``--model``, ``--moment``, ...) and the system's
(``--set``, ``--vary``, ...) exclude each other: either kind given with the other command
form exits 2 naming it.
"""

from __future__ import annotations

import json
import math
import re
from pathlib import Path
from typing import Any

import typer

from ..status import Status
from .common import EXIT_CODES, bar_callback, exit_on, fail, outputs_or_exit, progress_bar, save_dataset, snic_line

#: The table of a config file that holds the system's arguments.
SYSTEM_TABLE = "system"

SYSTEM_HELP = (
    "Run on this system instead of the chain: a built-in (pen, josephson_array, frenkel_kontorova, takeno_peyrard), "
    "package.module:function or path/to/file.py:function returning a System; its arguments from the config's [system] "
    "table and --set (see docs/system-commands.md)."
)


def system_option():
    """``--system REF``."""
    return typer.Option(None, "--system", metavar="REF", help=SYSTEM_HELP)


def set_option():
    """``--set NAME=VALUE``, repeatable."""
    return typer.Option(
        None,
        "--set",
        metavar="NAME=VALUE",
        help="With --system: an argument of the system's function (a parameter, sites, boundary); repeatable.",
    )


def vary_option(what: str):
    """``--vary NAME`` of a system (the chain's diagram has its own)."""
    return typer.Option(None, "--vary", metavar="NAME", help=f"With --system: the parameter to continue in ({what}).")


def start_option(what: str):
    """``--start Q``: a state of the system's coordinates."""
    return typer.Option(
        None,
        "--start",
        metavar="Q",
        help=f"With --system: {what}, as Q1,Q2,... (one value per coordinate, or one for all; pi, -pi/2, 2*pi allowed).",
    )


def velocity_option(what: str):
    """``--velocity V``: the velocities of a start."""
    return typer.Option(None, "--velocity", metavar="V", help=f"With --system: the start's velocities, V1,V2,... or one for all ({what}).")


# -- which options belong to which form ------------------------------------------------------


def _given(ctx: typer.Context) -> list[tuple[str, str]]:
    """(name, option as spelled) of each option of the running command given on the line or from the environment."""
    spelled = {p.name: p.opts[0] for p in ctx.command.params}
    return [
        (name, spelled.get(name, name))
        for name in ctx.params
        if getattr(ctx.get_parameter_source(name), "name", None) in ("COMMANDLINE", "ENVIRONMENT")
    ]


def chain_only_or_exit(ctx: typer.Context, allowed: tuple[str, ...]) -> None:
    """With ``--system``: exit 2 naming every option given that only the chain form reads (those not in ``allowed``)."""
    extra = [opt for name, opt in _given(ctx) if name not in (*allowed, "system")]
    if extra:
        fail(
            f"{', '.join(extra)} belong(s) to the chain, not to --system: leave {'it' if len(extra) == 1 else 'them'} out "
            "(a system's arguments go in the config's [system] table or --set NAME=VALUE)"
        )


def system_only_or_exit(ctx: typer.Context, names: tuple[str, ...]) -> None:
    """Without ``--system``: exit 2 naming every one of the system's options (``names``) that was given."""
    given = [opt for name, opt in _given(ctx) if name in names]
    if given:
        fail(f"{', '.join(given)} need(s) --system REF (a system of your own or a built-in); the chain takes --model and its own options")


# -- the system ------------------------------------------------------------------------------

_INTEGER = re.compile(r"[+-]?\d+")


def _argument(text: str) -> Any:
    """A --set value: an integer, a number, else the text (``boundary=periodic``)."""
    if _INTEGER.fullmatch(text.strip()):
        return int(text)
    try:
        return float(text)
    except ValueError:
        return text.strip()


def system_or_exit(reference: str, config: Path | None, sets: list[str] | None):
    """The system ``reference`` names, built with the config's ``[system]`` table and ``--set``; exit 2 saying what is wrong."""
    from ..io import read_config
    from ..systems import SystemDefinitionError, load_system

    arguments: dict[str, Any] = {}
    if config is not None:
        try:
            mapping = read_config(config)
        except ValueError as err:
            fail(str(err))
        other = sorted(set(mapping) - {SYSTEM_TABLE})
        if other:
            fail(
                f"--config {str(config)!r} with --system is read for its [{SYSTEM_TABLE}] table only, and has {', '.join(map(repr, other))} "
                f"besides: put the system's arguments under [{SYSTEM_TABLE}] (the chain's fields belong to the chain's commands)"
            )
        table = mapping.get(SYSTEM_TABLE, {})
        if not isinstance(table, dict):
            fail(f"--config {str(config)!r}: [{SYSTEM_TABLE}] must be a table of the system's arguments, got {table!r}")
        arguments.update(table)
    for text in sets or ():
        name, sep, value = text.partition("=")
        if not sep or not name.strip().isidentifier() or not value.strip():
            fail(f"--set must read NAME=VALUE (e.g. --set I=0.4), got {text!r}")
        arguments[name.strip()] = _argument(value)
    try:
        return load_system(reference, arguments)
    except SystemDefinitionError as err:
        fail(str(err))
    except Exception as err:  # the user's function: any failure is reported as bad input, with its kind
        fail(f"--system {reference}: building the system failed: {type(err).__name__}: {err}")


_PI = re.compile(r"([+-]?)(\d*\.?\d*(?:[eE][+-]?\d+)?)\*?pi(?:/(\d*\.?\d+))?")


def _number(text: str, option: str) -> float:
    text = text.strip().replace(" ", "")
    match = _PI.fullmatch(text)
    try:
        if match:
            sign, factor, divisor = match.groups()
            value = (float(factor) if factor else 1.0) * math.pi / (float(divisor) if divisor else 1.0)
            return -value if sign == "-" else value
        value = float(text)
    except ValueError:
        value = math.nan
    if not math.isfinite(value):
        fail(f"{option}: {text!r} is not a finite number (numbers, pi, -pi/2 or 2*pi are read)")
    return value


def state_or_exit(system, text: str | None, option: str, default=None):
    """(n,) values of ``--start``/``--velocity`` (one for all coordinates, or one each), or ``default`` when not given."""
    import numpy as np

    if text is None:
        return np.zeros(system.size) if default is None else np.asarray(default, dtype=float)
    values = [_number(part, option) for part in text.split(",")]
    if len(values) == 1:
        values = values * system.size
    if len(values) != system.size:
        fail(f"{option} needs one value or {system.size} ({', '.join(system.coordinates)}), got {len(values)}: {text!r}")
    return np.array(values)


def _parameter_or_exit(system, name: str, option: str = "--vary") -> float:
    from ..systems import SystemDefinitionError

    try:
        return system.parameter(name)
    except SystemDefinitionError as err:
        fail(f"{option}: {err}")


def _angles_mod(system, q):
    import numpy as np

    q = np.array(q, dtype=float)
    q[system.angles] = np.mod(q[system.angles] + math.pi, 2 * math.pi) - math.pi
    return q


def _echo_json(payload: dict) -> None:
    typer.echo(json.dumps(payload, default=_plain))


def _plain(value):
    import numpy as np

    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, complex):
        return [value.real, value.imag]
    return str(value)


# -- states ----------------------------------------------------------------------------------


def states_on_system(reference: str, *, config: Path | None, sets: list[str] | None, starts: list[str] | None, as_json: bool) -> None:
    """Equilibria of the system by Newton from each start (default q = 0 and q = pi on every angle), with their stability."""
    import numpy as np

    from ..numerics.equilibria import EquilibriumNotFound, find_equilibrium

    system = system_or_exit(reference, config, sets)
    if starts:
        guesses = [state_or_exit(system, text, "--start") for text in starts]
    else:
        guesses = [np.zeros(system.size), np.where(system.angles, math.pi, 0.0)]
    found, failed = [], []
    bar = progress_bar(f"states {system.name}", "start")
    progress = bar_callback(bar)
    for i, q0 in enumerate(guesses):
        try:
            point = find_equilibrium(system, q0)
        except EquilibriumNotFound as err:
            failed.append({"start": q0.tolist(), "message": str(err)})
        else:
            q = _angles_mod(system, point.q)
            same = next((f for f in found if np.max(np.abs(_angles_mod(system, f["q"] - q)), initial=0.0) < 1e-7), None)
            if same is None:
                growth = None if point.eigenvalues is None else float(np.max(point.eigenvalues.real))
                found.append(
                    {
                        "q": q,
                        "stable": point.stable,
                        "index": point.index,
                        "residual": point.residual,
                        "growth_rate": growth,
                        "starts": [q0.tolist()],
                    }
                )
            else:
                same["starts"].append(q0.tolist())
        progress(i + 1, len(guesses))
    bar.finish()
    if as_json:
        _echo_json({**system.describe(), "reference": reference, "equilibria": found, "failed_starts": failed})
    else:
        typer.echo(f"{system.name} ({_parameters_text(system)}): {len(found)} equilibri{'um' if len(found) == 1 else 'a'}")
        for i, e in enumerate(found):
            verdict = "stability not computed" if e["stable"] is None else ("stable" if e["stable"] else f"unstable, index {e['index']}")
            rate = "" if e["growth_rate"] is None else f", largest Re(lambda) {e['growth_rate']:.6g}"
            q = ", ".join(f"{name} = {value:.10g}" for name, value in zip(system.coordinates, e["q"], strict=True))
            typer.echo(f"  {i}: {q}: {verdict}{rate}; residual {e['residual']:.2g}")
        for f in failed:
            typer.echo(f"  from {f['start']}: {f['message']}")
    if not found:
        exit_on(Status.NOT_CONVERGED, "Newton converged from no start: give --start nearer an equilibrium")


def _parameters_text(system) -> str:
    return ", ".join(f"{name} = {value:g}" for name, value in system.parameters.items())


# -- critical --------------------------------------------------------------------------------


def critical_on_system(
    reference: str,
    *,
    config: Path | None,
    sets: list[str] | None,
    vary: str | None,
    start: str | None,
    down: bool,
    max_points: int | None,
    as_json: bool,
) -> None:
    """The first fold of the equilibrium from ``start`` (default q = 0) continued in ``vary``."""
    from ..numerics.equilibria import EquilibriumNotFound, continue_equilibria, find_equilibrium
    from ..numerics.kit import BranchEnd

    if vary is None:
        fail("critical --system needs --vary NAME: the parameter to continue the equilibrium in until its fold")
    system = system_or_exit(reference, config, sets)
    value = _parameter_or_exit(system, vary)
    bar = progress_bar(f"critical {system.name}", "point")
    try:
        first = find_equilibrium(system, state_or_exit(system, start, "--start"))
        branch = continue_equilibria(
            first, vary, direction=-1.0 if down else 1.0, max_points=500 if max_points is None else max_points, progress=bar_callback(bar)
        )
    except EquilibriumNotFound as err:
        bar.close()
        fail(str(err), code=EXIT_CODES[Status.NOT_CONVERGED])
    bar.finish(note=f"the branch ended: {branch.end}")
    folds = [e for e in branch.events if e.kind == "fold" and e.located]
    fold = folds[0] if folds else None
    result = {
        **system.describe(),
        "reference": reference,
        "vary": vary,
        "start_value": value,
        "start": first.q.tolist(),
        "start_stable": first.stable,
        "fold": None if fold is None else {"value": fold.parameter, "q": fold.point.q.tolist()},
        "branch": branch.as_dict(),
    }
    if as_json:
        _echo_json(result)
    elif fold is not None:
        q = ", ".join(f"{name} = {x:.10g}" for name, x in zip(system.coordinates, fold.point.q, strict=True))
        typer.echo(f"{system.name}: fold at {vary} = {fold.parameter:.15g} ({q}), from {vary} = {value:g}; {len(branch.points)} points")
    else:
        typer.echo(f"{system.name}: no fold in {vary} from {value:g}: {branch.message}")
    if fold is None and branch.end in (BranchEnd.MAX_POINTS, BranchEnd.STEP_TOO_SMALL):
        status = Status.MAX_STEPS if branch.end == BranchEnd.MAX_POINTS else Status.STEP_TOO_SMALL
        exit_on(status, branch.message)


# -- orbit -----------------------------------------------------------------------------------


def _turns_or_exit(system, turns: list[str] | None) -> dict[str, int]:
    """{coordinate: k} of ``--turn NAME=K``; default every angle once (the in-phase rotation)."""
    if not turns:
        angles = [name for name, is_angle in zip(system.coordinates, system.angles, strict=True) if is_angle]
        if not angles:
            fail(f"{system.name} has no angle coordinate: orbit --system follows rotations, which turn an angle")
        return dict.fromkeys(angles, 1)
    out = {}
    for text in turns:
        name, sep, k = text.partition("=")
        name = name.strip()
        if not sep or not _INTEGER.fullmatch(k.strip()):
            fail(f"--turn must read COORDINATE=K with K a whole number (e.g. --turn phi_0=1), got {text!r}")
        if name not in system.coordinates:
            fail(f"--turn: {name!r} is not a coordinate of {system.name}; its coordinates are {', '.join(system.coordinates)}")
        out[name] = int(k)
    if not any(out.values()):
        fail("--turn: at least one angle must turn (K != 0) for a rotation; an orbit with no angle turning is --oscillation")
    return out


#: Most orbits ``orbit --system --vary --through-folds`` follows (a snaking approach takes hundreds between its folds).
THROUGH_FOLDS_POINTS = 3000


def orbit_on_system(
    reference: str,
    *,
    config: Path | None,
    sets: list[str] | None,
    vary: str | None,
    turns: list[str] | None,
    down_to: float | None,
    period_max: float,
    start: str | None,
    velocity: str | None,
    out: Path | None,
    as_json: bool,
    oscillation: bool = False,
    from_hopf: bool = False,
    through_folds: bool = False,
    method: str = "auto",
    mesh: dict | None = None,
) -> None:
    """A rotating orbit of the system (with ``oscillation`` one where no angle turns) from a settled simulation, and with
    ``--vary`` its continuation; with ``from_hopf`` the oscillation born at the first Hopf point of the equilibrium
    found from ``--start``, followed in ``--vary`` towards ``--down-to``. ``method`` "collocation" solves the shooting's
    orbit again by collocation on ``mesh`` (``ntst``, ``ncol``, ``max_interval``, those given, checked by the caller)
    and follows the branch by it (:func:`_orbit_by_collocation`)."""
    import numpy as np

    from ..numerics.kit import EvaluationFailed
    from ..numerics.shooting import OrbitNotFound, continue_orbits, find_orbit, settled_guess

    if down_to is not None and vary is None:
        fail("--down-to needs --vary NAME: the parameter to continue the orbit in")
    if method not in SYSTEM_ORBIT_METHODS:
        fail(f"--method with --system takes {' or '.join(SYSTEM_ORBIT_METHODS)} (auto: shooting), got {method!r}")
    if from_hopf and not (oscillation and down_to is not None):
        fail("--from-hopf starts an --oscillation at a Hopf point sought along --vary NAME up to --down-to X: give all three")
    mesh = mesh or {}
    if from_hopf:
        return _orbit_from_hopf(
            reference, config=config, sets=sets, vary=vary, down_to=down_to, period_max=period_max, start=start, out=out,
            as_json=as_json, method=method, mesh=mesh, through_folds=through_folds,
        )  # fmt: skip
    outputs_or_exit({"--out": out}, {"--config": config})
    system = system_or_exit(reference, config, sets)
    value = _parameter_or_exit(system, vary) if vary is not None else None
    k = {} if oscillation else _turns_or_exit(system, turns)
    q0 = state_or_exit(system, start, "--start")
    forces, damping = system.forces(q0), system.damping()
    # Default start speed: where the drive at q0 meets the damping (the terminal spin I / eps of a driven pendulum).
    drift = np.where(system.angles & (damping > 0), forces / np.where(damping > 0, damping, 1.0), 0.0)
    v0 = state_or_exit(system, velocity, "--velocity", default=drift)
    # An oscillation is timed by the first coordinate's crossings of its mean (settled_guess with no turns).
    first = next((name for name, turn in k.items() if turn), system.coordinates[0])
    hint = (
        "start it off the equilibrium with --start or --velocity"
        if oscillation
        else "start it turning with --velocity (or another --start), or check the drive"
    )
    direction = -1.0 if down_to is None or down_to < value else 1.0
    limits = (-math.inf, math.inf) if down_to is None else (min(down_to, value), max(down_to, value))
    bar = progress_bar(f"orbit {system.name}", "orbit")
    branch = None
    try:
        try:
            guess = settled_guess(system, np.concatenate([q0, v0]), coordinate=first, turns=abs(k.get(first, 0)))
        except OrbitNotFound as err:
            raise OrbitNotFound(f"{err}: {hint}") from None
        orbit = find_orbit(system, guess, turns=k or None)
        if method == "collocation":
            return _orbit_by_collocation(
                reference, orbit, vary=vary, direction=direction, limits=limits, period_max=period_max, through_folds=through_folds,
                mesh=mesh, out=out, as_json=as_json, bar=bar,
            )  # fmt: skip
        if vary is not None:
            stops = () if through_folds else ("fold",)
            branch = continue_orbits(
                orbit, vary, direction=direction, limits=limits, period_max=period_max, stop_at=stops, progress=bar_callback(bar),
                max_points=THROUGH_FOLDS_POINTS if through_folds else 300,
            )  # fmt: skip
            if through_folds and branch.end_method == "fitted":
                from ..numerics.homoclinic import solve_branch_end

                solve_branch_end(branch)
    except ValueError as err:
        bar.close()
        fail(str(err))
    except (OrbitNotFound, EvaluationFailed) as err:
        bar.close()
        fail(str(err), code=EXIT_CODES[Status.NOT_CONVERGED])
    bar.finish(note="" if branch is None else f"the branch ended: {branch.end}")
    summary = None if branch is None else branch.as_dict()
    if out is not None:
        save_dataset(_orbit_dataset(system, reference, orbit, summary), out)
    result = {**orbit.as_dict(), "reference": reference, "multipliers": [[m.real, m.imag] for m in orbit.multipliers]}
    if summary is not None:
        result["branch"] = summary
    if as_json:
        _echo_json(result)
        return
    turned = ", ".join(f"{name} {turn:+d}" for name, turn in k.items() if turn) or "none (an oscillation)"
    typer.echo(f"{system.name} ({_parameters_text(system)}): period T = {orbit.period:.12g}, turns {turned}")
    typer.echo(f"Floquet multipliers |mu|: {' '.join(f'{abs(m):.6g}' for m in orbit.multipliers)}")
    typer.echo(f"largest other |mu| = {orbit.max_multiplier:.6g}: {'stable' if orbit.stable else 'unstable'}; closure {orbit.closure:.2g}")
    if branch is not None:
        for e in branch.events:
            where = f"at {vary} = {e.parameter:.12g}" if e.located else f"not located, passed before {vary} = {e.parameter:.12g}"
            typer.echo(f"  {e.kind} {where}")
        typer.echo(f"continued to {vary} = {branch.values[-1]:.12g} ({len(branch.orbits)} orbits): {branch.end}: {branch.message}")


#: The solvers ``orbit --system --method`` takes: auto (single shooting) or collocation.
SYSTEM_ORBIT_METHODS = ("auto", "collocation")


def _orbit_by_collocation(
    reference: str,
    shot,
    *,
    vary: str | None,
    direction: float,
    limits: tuple[float, float],
    period_max: float,
    through_folds: bool,
    mesh: dict,
    out: Path | None,
    as_json: bool,
    bar,
    hopf: dict | None = None,
) -> None:
    """``orbit --system --method collocation``: the shooting's orbit ``shot`` solved again by collocation on ``mesh``'s
    ``ntst`` intervals of ``ncol`` points (:func:`~cosserat_chain.numerics.system_collocation.find_collocation_orbit`)
    and, with ``vary``, followed by it in ``direction`` within ``limits``, no interval longer than ``mesh``'s
    ``max_interval`` (:func:`~cosserat_chain.numerics.system_collocation.continue_collocation_orbits`); the orbit and
    every branch point carry the trivial multiplier's error, the one multiplier known exactly. Written to ``out``
    (:func:`_orbit_dataset`), printed or as JSON, with the Hopf point ``hopf`` the orbit was born at (``--from-hopf``).
    Called inside :func:`orbit_on_system`'s or :func:`_orbit_from_hopf`'s ``try``, whose handlers take its errors."""
    from ..numerics.collocation_core import CollocationError
    from ..numerics.system_collocation import continue_collocation_orbits, find_collocation_orbit

    system = shot.system
    branch = None
    try:
        orbit = find_collocation_orbit(system, shot, **{key: value for key, value in mesh.items() if key in ("ntst", "ncol")})
        if vary is not None:
            branch = continue_collocation_orbits(
                orbit, vary, direction=direction, limits=limits, period_max=period_max, through_folds=through_folds,
                max_interval=mesh.get("max_interval"), max_points=THROUGH_FOLDS_POINTS if through_folds else 300,
                progress=bar_callback(bar),
            )  # fmt: skip
    except CollocationError as err:
        bar.close()
        fail(str(err), code=EXIT_CODES[Status.NOT_CONVERGED])
    bar.finish(note="" if branch is None else f"the branch ended: {branch.end}")
    summary = None
    if branch is not None:
        # The mesh the branch ended on: --max-interval raises the intervals as the period grows.
        summary = {**branch.as_dict(vary), "end_ntst": branch.orbits[-1].ntst, "max_interval": mesh.get("max_interval")}
    if out is not None:
        save_dataset(_orbit_dataset(system, reference, orbit, summary), out)
    result = {
        **orbit.as_dict(),
        "reference": reference,
        "method": "collocation",
        "multipliers": [[m.real, m.imag] for m in orbit.multipliers],
    }
    if hopf is not None:
        result["hopf"] = hopf
    if summary is not None:
        result["branch"] = summary
    if as_json:
        _echo_json(result)
        return
    if hopf is not None:
        born = system.parameter(vary)
        typer.echo(f"{system.name}: Hopf point at {vary} = {hopf['value']:.12g}; the oscillation born there at {vary} = {born:.12g}:")
    typer.echo(
        f"{system.name} ({_parameters_text(system)}): period T = {orbit.period:.12g} by collocation (NTST = {orbit.ntst}, NCOL = {orbit.ncol})"
    )
    typer.echo(f"Floquet multipliers |mu|: {' '.join(f'{abs(m):.6g}' for m in orbit.multipliers)}")
    typer.echo(
        f"largest other |mu| = {orbit.max_multiplier:.6g}: {'stable' if orbit.stable else 'unstable'}; "
        f"trivial multiplier off by {orbit.trivial_multiplier_error:.2g}"
    )
    if branch is not None:
        for e in branch.events:
            where = f"at {vary} = {e['moment']:.12g}" if e["located"] else f"not located, passed before {vary} = {e['moment']:.12g}"
            typer.echo(f"  {e['kind']} {where}")
        typer.echo(
            f"continued to {vary} = {branch.orbits[-1].moment:.12g} ({len(branch.orbits)} orbits, NTST = {branch.orbits[-1].ntst} "
            f"at the end): {branch.end}: {branch.message}"
        )


#: Amplitude along the crossing eigenvector of the first orbit ``orbit --from-hopf`` solves at a Hopf point.
HOPF_AMPLITUDE = 0.02


def _orbit_from_hopf(
    reference: str, *, config, sets, vary: str, down_to: float, period_max: float, start, out, as_json: bool, method: str = "auto",
    mesh: dict | None = None, through_folds: bool = False,
) -> None:  # fmt: skip
    """``orbit --system --oscillation --from-hopf``: the equilibrium from ``--start`` followed in ``vary`` towards
    ``down_to`` to its first Hopf point, the orbit of amplitude :data:`HOPF_AMPLITUDE` born there
    (:func:`~cosserat_chain.numerics.cycle_switching.system_hopf_orbit`, by shooting: unstable families too, which no
    settling run reaches), and that family followed away from the Hopf point within the same range; with ``method``
    "collocation" the orbit solved again and followed by collocation on ``mesh`` (:func:`_orbit_by_collocation`,
    through the folds of cycles with ``through_folds``)."""
    from ..numerics.cycle_switching import system_hopf_orbit
    from ..numerics.equilibria import EquilibriumNotFound, continue_equilibria, find_equilibrium
    from ..numerics.kit import EvaluationFailed
    from ..numerics.periodic import OrbitError
    from ..numerics.shooting import OrbitNotFound, continue_orbits

    outputs_or_exit({"--out": out}, {"--config": config})
    system = system_or_exit(reference, config, sets)
    value = _parameter_or_exit(system, vary)
    limits = (min(value, down_to), max(value, down_to))
    bar = progress_bar(f"orbit {system.name}", "orbit")
    try:
        equilibrium = find_equilibrium(system, state_or_exit(system, start, "--start"))
        states = continue_equilibria(equilibrium, vary, direction=1.0 if down_to > value else -1.0, limits=limits, stop_at=("hopf",))
        # The last step may leave the range and locate a Hopf point beyond it: only one inside counts.
        hopf = next((e for e in states.events if e.kind == "hopf" and e.located and limits[0] <= e.parameter <= limits[1]), None)
        if hopf is None:
            raise OrbitNotFound(f"the equilibrium from --start has no Hopf point for {vary} between {value:g} and {down_to:g}")
        hopf_record = {"parameter": vary, "value": hopf.parameter, "q": hopf.point.q, "amplitude": HOPF_AMPLITUDE}
        orbit = system_hopf_orbit(hopf.point, vary, HOPF_AMPLITUDE)
        side = 1.0 if orbit.parameter(vary) > hopf.parameter else -1.0
        if method == "collocation":
            return _orbit_by_collocation(
                reference, orbit, vary=vary, direction=side, limits=limits, period_max=period_max, through_folds=through_folds,
                mesh=mesh or {}, out=out, as_json=as_json, bar=bar, hopf=hopf_record,
            )  # fmt: skip
        branch = continue_orbits(orbit, vary, direction=side, limits=limits, period_max=period_max, progress=bar_callback(bar))
    except ValueError as err:
        bar.close()
        fail(str(err))
    except (EquilibriumNotFound, OrbitNotFound, OrbitError, EvaluationFailed) as err:
        bar.close()
        fail(str(err), code=EXIT_CODES[Status.NOT_CONVERGED])
    bar.finish(note=f"the branch ended: {branch.end}")
    summary = branch.as_dict()
    if out is not None:
        save_dataset(_orbit_dataset(system, reference, orbit, summary), out)
    if as_json:
        _echo_json(
            {
                **orbit.as_dict(),
                "reference": reference,
                "multipliers": [[m.real, m.imag] for m in orbit.multipliers],
                "hopf": hopf_record,
                "branch": summary,
            }
        )
        return
    typer.echo(
        f"{system.name}: Hopf point at {vary} = {hopf.parameter:.12g}; the oscillation born there at {vary} = {orbit.parameter(vary):.12g}:"
    )
    typer.echo(
        f"period T = {orbit.period:.12g}, largest other |mu| = {orbit.max_multiplier:.6g}: {'stable' if orbit.stable else 'unstable'}; closure {orbit.closure:.2g}"
    )
    typer.echo(f"continued to {vary} = {branch.values[-1]:.12g} ({len(branch.orbits)} orbits): {branch.end}: {branch.message}")


def _orbit_dataset(system, reference: str, orbit, branch: dict | None):
    """The orbit and its ``branch`` (the branch's ``as_dict``, what --json prints) as a Dataset: the start state over the
    system's coordinates, the multipliers, the branch's points. A collocation orbit (it carries its ``mesh``) also gives
    its method, mesh (``ntst``, ``ncol``) and trivial multiplier's error, and its branch that error at every point, the
    mesh it ended on and the ``max_interval`` asked for; a shooting orbit its closure."""
    import numpy as np
    import xarray as xr

    from ..experiments.simulation import system_attributes

    n = system.size
    ds = xr.Dataset(
        {
            "q0": ("coordinate", orbit.y0[:n]),
            "v0": ("coordinate", orbit.y0[n:]),
            "turns": ("coordinate", orbit.turns),
            "multiplier_real": ("multiplier", np.real(orbit.multipliers)),
            "multiplier_imag": ("multiplier", np.imag(orbit.multipliers)),
        },
        coords={"coordinate": list(system.coordinates)},
    )
    ds["q0"].attrs["long_name"] = "start of the orbit on its phase plane: coordinates"
    ds["v0"].attrs["long_name"] = "start of the orbit on its phase plane: velocities"
    ds["turns"].attrs["long_name"] = "turns of each coordinate per period"
    if branch is not None:
        ds["branch_value"] = ("point", np.asarray(branch["values"], dtype=float))
        ds["branch_value"].attrs["long_name"] = f"the continued parameter {branch['parameter']}"
        ds["branch_period"] = ("point", np.asarray(branch["periods"], dtype=float))
        ds["branch_max_multiplier"] = ("point", np.asarray(branch["max_multiplier"], dtype=float))
        if "trivial_multiplier_error" in branch:
            ds["branch_trivial_multiplier_error"] = ("point", np.asarray(branch["trivial_multiplier_error"], dtype=float))
        ds.attrs.update(
            {
                "varied": branch["parameter"],
                "branch_end": branch["end"],
                "branch_message": branch["message"],
                "events_json": json.dumps(branch["events"], default=_plain),
            }
        )
        if branch.get("end_value") is not None:
            # A homoclinic end fitted from the period's growth or solved (homoclinic.solve_branch_end), with its uncertainty (NaN: none).
            uncertainty = math.nan if branch["end_uncertainty"] is None else branch["end_uncertainty"]
            ds.attrs.update(
                {"branch_end_value": branch["end_value"], "branch_end_uncertainty": uncertainty, "branch_end_method": branch["end_method"]}
            )
        if "end_ntst" in branch:
            ds.attrs["branch_end_ntst"] = branch["end_ntst"]
        if branch.get("max_interval") is not None:
            ds.attrs["max_interval"] = branch["max_interval"]
    ds.attrs.update(system_attributes(system, reference))
    ds.attrs.update(
        {
            "experiment": "system_orbit",
            "title": f"Periodic orbit of the system {system.name}",
            "period": orbit.period,
            "max_multiplier": orbit.max_multiplier,
            "stable": int(orbit.stable),
        }
    )
    if hasattr(orbit, "mesh"):
        ds.attrs.update(
            {
                "method": "collocation",
                "ntst": orbit.ntst,
                "ncol": orbit.ncol,
                "trivial_multiplier_error": orbit.trivial_multiplier_error,
                "residual": orbit.residual,
            }
        )
    else:
        ds.attrs.update({"method": "shooting", "closure": orbit.closure})
    return ds


# -- simulate --------------------------------------------------------------------------------


def simulate_on_system(
    reference: str,
    *,
    config: Path | None,
    sets: list[str] | None,
    t_end: float,
    frames: int,
    start: str | None,
    velocity: str | None,
    out: Path | None,
    as_json: bool,
) -> None:
    """Integrate the system's flow from (start, velocity) to ``t_end``, storing ``frames`` states (DOP853, frame to frame)."""
    import numpy as np
    import xarray as xr

    from ..experiments.simulation import system_attributes
    from ..numerics.kit import EvaluationFailed
    from ..numerics.shooting import flow

    outputs_or_exit({"--out": out}, {"--config": config})
    system = system_or_exit(reference, config, sets)
    y = np.concatenate([state_or_exit(system, start, "--start"), state_or_exit(system, velocity, "--velocity")])
    times = np.linspace(0.0, t_end, frames)
    states = [y]
    status, message = Status.COMPLETED, f"reached t = {t_end:g}"
    bar = progress_bar(f"simulate {system.name}", "frame")
    progress = bar_callback(bar)
    try:
        for i, dt in enumerate(np.diff(times)):
            states.append(flow(system, states[-1], float(dt), variations=False)[0])
            progress(i + 2, frames)
    except EvaluationFailed as err:
        status, message = Status.BLEW_UP, f"{err}; the frames before t = {times[len(states) - 1]:g} are kept"
    except KeyboardInterrupt:
        status, message = Status.INTERRUPTED, f"interrupted; the frames to t = {times[len(states) - 1]:g} are kept"
    bar.finish(status)
    n = system.size
    y = np.array(states)
    ds = xr.Dataset(
        {"q": (("time", "coordinate"), y[:, :n]), "velocity": (("time", "coordinate"), y[:, n:])},
        coords={"time": times[: len(states)], "coordinate": list(system.coordinates)},
    )
    ds["q"].attrs["long_name"] = "generalized coordinates"
    ds["velocity"].attrs["long_name"] = "generalized velocities dq/dt"
    if system.energy(y[0, :n]) is not None:
        mass = system.mass()
        ds["potential_energy"] = ("time", np.array([system.energy(row[:n]) for row in y]))
        ds["kinetic_energy"] = ("time", 0.5 * np.sum(mass * y[:, n:] ** 2, axis=1))
    ds.attrs.update(system_attributes(system, reference))
    ds.attrs.update(
        {
            "experiment": "system_simulation",
            "title": f"Damped simulation of the system {system.name}",
            "status": str(status),
            "message": message,
        }
    )
    save_dataset(ds, out)
    if as_json:
        _echo_json(
            {
                **system.describe(),
                "reference": reference,
                "t_end": t_end,
                "t_reached": float(ds.time[-1]),
                "status": str(status),
                "message": message,
                "final": {"q": y[-1, :n].tolist(), "velocity": y[-1, n:].tolist()},
                "out": str(out) if out else None,
            }
        )
    elif status == Status.COMPLETED:
        final = ", ".join(f"{name} = {x:.6g}" for name, x in zip(system.coordinates, y[-1, :n], strict=True))
        typer.echo(f"{system.name}: t = {t_end:g}, {final}" + (f"; wrote {out}" if out else ""))
    exit_on(status, message)


# -- diagram ---------------------------------------------------------------------------------


def diagram_on_system(
    reference: str,
    *,
    config: Path | None,
    sets: list[str] | None,
    vary: str,
    values: list[float],
    drive: str | None,
    turns: list[str] | None,
    period_max: float,
    start: str | None,
    out: Path | None,
    as_json: bool,
    codim2: bool = False,
) -> None:
    """Both edges of the hysteresis loop in ``drive`` at each value of ``vary``
    (:func:`~cosserat_chain.experiments.system_diagram.system_diagram`): printed, as JSON, or written with ``--out``."""
    from ..experiments.simulation import system_attributes
    from ..experiments.system_diagram import system_diagram

    if drive is None:
        fail("diagram --system needs --drive NAME: the parameter whose rise starts the rotation (the chain's moment), e.g. --drive I")
    if drive == vary:
        fail(f"--drive and --vary must be different parameters, got {drive!r} for both")
    outputs_or_exit({"--out": out}, {"--config": config})
    system = system_or_exit(reference, config, sets)
    _parameter_or_exit(system, vary)
    _parameter_or_exit(system, drive, "--drive")
    k = _turns_or_exit(system, turns)
    q0 = state_or_exit(system, start, "--start")
    bar = progress_bar(f"diagram {system.name}", "value")
    try:
        result = system_diagram(
            system, vary, values, drive, turns=k, start=q0, period_max=period_max, codim2=codim2, progress=bar_callback(bar)
        )
    except ValueError as err:
        bar.close()
        fail(str(err))
    bar.finish()
    if out is not None:
        ds = result.to_dataset()
        ds.attrs.update(system_attributes(system, reference))
        save_dataset(ds, out)
    if as_json:
        _echo_json({**result.as_dict(), "reference": reference})
    else:
        _echo_diagram(result)
    if any(row.end is None for row in result.rows):
        exit_on(Status.NOT_CONVERGED, "some values have no edge of the loop (their messages say why)")


def _echo_diagram(result) -> None:
    """The rows as a table (each edge with how it was found and its accuracy), their warnings and the SNIC point."""
    vary, drive = result.vary, result.drive
    typer.echo(f"{result.system.name}: the loop in {drive} against {vary}")
    typer.echo(f"{vary:>12} {'starts':>14} {'stops':>18}  {'end':<16} {'found':<22} open")
    for row in result.rows:
        onset = "none" if row.starts is None else f"{row.starts:.10g}"
        stops = "none" if row.stops is None else f"{row.stops:.13g}" if row.method == "solved" else f"{row.stops:.10g}"
        if row.method == "solved":
            found = f"solved +- {row.accuracy:.1g}"
        elif row.method == "fitted":
            found = f"fitted +- {row.accuracy:.1g}"
        else:
            found = row.method or "-"
        typer.echo(f"{row.value:>12.6g} {onset:>14} {stops:>18}  {row.end or 'failed':<16} {found:<22} {row.open}")
    for row in result.rows:
        if row.end is None:
            typer.echo(f"  {vary} = {row.value:g}: {row.message}")
        if row.reason:
            what = "a fit" if row.method == "fitted" else "a bound"
            typer.echo(f"  {vary} = {row.value:g}: {what}, not a computed point: {row.reason}")
        if row.warning:
            typer.echo(f"warning: {vary} = {row.value:g}: {row.warning}")
    point = result.snic_point
    if point is not None:
        typer.echo(snic_line(point, vary, "the fold", drive, point["drive"]))
    for entry in result.codim2_between or []:
        points = "; ".join(f"{p['name']} ({p['label']}) at {vary} = {p['value']:.10g} +- {p['accuracy']:.1g}" for p in entry["points"])
        typer.echo(
            f"between {vary} = {entry['between'][0]:g} and {entry['between'][1]:g}: {entry['message']}" + (f"; {points}" if points else "")
        )
