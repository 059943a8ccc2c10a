"""``cosserat-chain orbit``: the rotating state as a periodic orbit (period, Floquet multipliers, continuation in M)."""

from __future__ import annotations

import json
import math
from pathlib import Path

import typer

from .common import (
    app,
    bar_callback,
    fail,
    finite_or_none,
    model_option,
    number,
    outputs_or_exit,
    params_or_exit,
    progress_bar,
    save_dataset,
    save_figure,
    spin_or_exit,
    step_for_checks,
    whole,
)
from .systems import (
    chain_only_or_exit,
    orbit_on_system,
    set_option,
    start_option,
    system_only_or_exit,
    system_option,
    vary_option,
    velocity_option,
)


@app.command()
def orbit(
    ctx: typer.Context,
    model: str = model_option("sine", "A model that supports full rotations (the linear model does not).", rotating=True),
    moment: float | None = number(
        None, "Moment M on the loaded particle (above M_c; below it with --from-above or --guess; required without --system)."
    ),
    turns: int | None = whole(
        None,
        at_least=1,
        help="Turns of the loaded particle per period (default: the first of 1, 2, 3 whose orbit is stable, else the first found).",
    ),
    particle: int = typer.Option(0, help="Loaded particle (default the central one)."),
    down_to: float | None = number(
        None,
        "Continue the orbit down in M (with --system: in --vary, either way) to here, reporting where it ceases to exist.",
        flags=("--down-to",),
    ),
    period_max: float = number(2000.0, "Continuation: a period beyond this counts as diverging.", above=0.0, flags=("--period-max",)),
    switch: str | None = typer.Option(
        None,
        "--switch",
        metavar="KIND",
        help="With --down-to: switch at the branch's first period-doubling or branch-point (of cycles) onto the family born there.",
    ),
    from_above: float | None = number(
        None,
        "Find the orbit at this larger moment (above M_c) and continue it down to --moment: reaches rotating states below M_c.",
        flags=("--from-above",),
    ),
    guess: Path | None = typer.Option(
        None,
        "--guess",
        metavar="FILE",
        help="Start from a stored state: an orbit (orbit --out: Newton from it) or the last frame of a run (simulate --out: "
        "a settling run from it); reaches rotating states below M_c.",
    ),
    config: Path | None = typer.Option(None, help="TOML file with ChainParams fields (with --system: the system's [system] table)."),
    out: Path | None = typer.Option(None, help="Write the orbit (and the continuation) to this NetCDF file."),
    plot: Path | None = typer.Option(None, help="Draw the rotation characteristic (needs --down-to) to this PNG/SVG file."),
    as_json: bool = typer.Option(False, "--json", help="Print the result as one JSON object."),
    method: str = typer.Option(
        "auto",
        "--method",
        help="How the orbit (and --down-to's branch) is solved: auto, dense, blocks or krylov shooting (auto: by the chain's "
        "length; krylov's branch by auto, which forms the monodromy), picard (Newton-Picard: the orbit and its branch on the "
        "multipliers above rho, for long chains near a known orbit), or collocation, whose cost does not grow with the "
        "period (a branch towards a homoclinic or SNIC end). With --system: auto (shooting) or collocation (the shooting's "
        "orbit solved again by collocation, and --vary's branch followed by it).",
    ),
    segments: int | None = whole(
        None,
        at_least=1,
        flags=("--segments",),
        help="The Floquet multipliers from the Jacobians of this many pieces of the orbit, by the periodic Schur form of "
        "their product: every multiplier of a long, strongly damped orbit with its log10 modulus (the formed monodromy "
        "loses those below 1e-16); dense or blocks shooting (the blocks integrated piece by piece; above 2 n_free = 2500 "
        "the leading ones only), not krylov (collocation always takes them so).",
    ),
    ntst: int | None = typer.Option(
        None,
        "--ntst",
        help="With --method collocation: mesh intervals of the orbit (default 40; AUTO-07p's NTST; a branch keeps them "
        "unless --max-interval asks for more).",
    ),
    ncol: int | None = typer.Option(
        None, "--ncol", help="With --method collocation: Gauss collocation points per interval, 2 to 7 (default 4; AUTO-07p's NCOL)."
    ),
    max_interval: float | None = number(
        None,
        "With --method collocation and a branch (--down-to, --from-above; with --system --vary): the longest mesh interval "
        "in time units; each mesh adaptation raises the intervals to 2 T / this (at most 4000), so that a long orbit's damped "
        "multipliers stay resolved, at a cost that grows with T.",
        above=0.0,
        flags=("--max-interval",),
    ),
    system: str | None = system_option(),
    sets: list[str] | None = set_option(),
    vary: str | None = vary_option("from its value down, or towards --down-to"),
    turn: list[str] | None = typer.Option(
        None, "--turn", metavar="COORDINATE=K", help="With --system: turns of an angle per period; repeatable (default every angle once)."
    ),
    oscillation: bool = typer.Option(
        False,
        "--oscillation",
        help="With --system: an oscillation (no angle turns a period: a limit cycle, e.g. one born at a Hopf point), "
        "from a settling run of --start/--velocity (off the equilibrium) timed by its first coordinate's crossings of "
        "its mean; not with --turn.",
    ),
    from_hopf: bool = typer.Option(
        False,
        "--from-hopf",
        help="With --system --oscillation --vary NAME --down-to X: the oscillation born at the first Hopf point of the "
        "equilibrium found from --start, sought along NAME towards X (unstable families too), followed within that range.",
    ),
    through_folds: bool = typer.Option(
        False,
        "--through-folds",
        help="With --system --vary: follow the orbit through its folds of cycles (each one named in --json's branch events) "
        "to where it really ends, as AUTO-07p does, and solve a homoclinic end there (a snaking approach to a saddle-focus "
        "too); without it the branch stops at its first fold.",
    ),
    start: str | None = start_option("the coordinates the settling run starts from (default 0)"),
    velocity: str | None = velocity_option("default: the drive at the start over the damping, on the angles"),
) -> None:
    """Find the rotating state as a limit cycle: period, mean angular velocity, Floquet multipliers, stability.

    Below M_c a run from rest stays static: --from-above M continues the orbit found at M down to --moment,
    --guess FILE starts from a stored orbit or run. With --system: a rotation of the system (from a settled run,
    then shooting), and with --vary its continuation.
    """
    if system is not None:
        chain_only_or_exit(
            ctx,
            (
                "config", "as_json", "out", "down_to", "period_max", "sets", "vary", "turn", "oscillation", "from_hopf", "start",
                "velocity", "through_folds", "method", "ntst", "ncol", "max_interval",
            ),
        )  # fmt: skip
        mesh = _mesh_or_exit(method, ntst, ncol, max_interval, vary is not None, "--vary NAME")
        if oscillation and turn:
            fail(f"--oscillation turns no angle: leave out --turn (got {', '.join(turn)})")
        if through_folds and vary is None:
            fail("--through-folds follows a branch: give --vary NAME (and --down-to X)")
        return orbit_on_system(
            system, config=config, sets=sets, vary=vary, turns=turn, down_to=down_to, period_max=period_max, start=start,
            velocity=velocity, out=out, as_json=as_json, oscillation=oscillation, from_hopf=from_hopf, through_folds=through_folds,
            method=method, mesh=mesh,
        )  # fmt: skip
    system_only_or_exit(ctx, ("sets", "vary", "turn", "oscillation", "from_hopf", "start", "velocity", "through_folds"))
    if method not in ORBIT_METHODS:
        fail(f"--method takes {', '.join(ORBIT_METHODS)}, got {method!r}")
    if moment is None:
        fail("--moment is required: the moment M on the loaded particle (or give --system REF for a system's orbit)")
    mesh = _mesh_or_exit(method, ntst, ncol, max_interval, down_to is not None or from_above is not None, "--down-to or --from-above")
    from ..experiments.orbits import periodic_orbit
    from ..numerics.dynamics import IntegrationError
    from ..numerics.periodic import OrbitError

    if plot is not None and down_to is None:
        fail("--plot draws the continued branch: give --down-to as well")
    if switch is not None and (switch not in SWITCHES or down_to is None):
        fail(f"--switch takes {' or '.join(SWITCHES)} with --down-to (the branch it switches from), got {switch!r}")
    if from_above is not None and guess is not None:
        fail("--from-above and --guess are two ways to start the orbit: give one of them")
    if from_above is not None and not (moment != 0 and from_above / moment > 1):
        fail(f"--from-above must be a moment beyond --moment {moment:g} (same sign, larger in size), got {from_above:g}")
    outputs_or_exit({"--out": out, "--plot": plot}, {"--config": config, "--guess": guess})
    params = params_or_exit(config)
    spin_or_exit(params, moment, step_for_checks(params, model, None), dt_option=False)
    if from_above is not None:
        spin_or_exit(params, from_above, step_for_checks(params, model, None), dt_option=False)
    stored: dict = {} if guess is None else _guess_or_exit(guess, params, particle)
    if turns is None and "turns" in stored:
        turns = stored["turns"]
    begin = {"from_above": from_above, "method": method, **mesh, **{key: stored[key] for key in ("guess", "start") if key in stored}}
    if segments is not None:
        begin["segments"] = segments
    bar = progress_bar(f"orbit {model}", "orbit")
    try:
        if turns is None:
            turns, result = _turns_to_follow(params, model, moment, particle, period_max=period_max, progress=bar_callback(bar), **begin)
            if down_to is not None:
                result = result.continued(down_to, period_max=period_max, progress=bar_callback(bar))
        else:
            result = periodic_orbit(
                params, model, moment, turns=turns, particle=particle, down_to=down_to, period_max=period_max,
                progress=bar_callback(bar), **begin,
            )  # fmt: skip
    except ValueError as err:
        bar.close()
        fail(str(err))
    except (OrbitError, IntegrationError) as err:
        bar.close()
        # Below M_c a run from rest stays static: the command line's two other starts.
        hint = "" if from_above is not None or guess is not None else " (from the command line: --from-above M or --guess FILE)"
        fail(f"{err}{hint}", code=3)
    if guess is not None:
        result.start["file"] = str(guess)
        result.start["file_holds"] = stored["holds"]
    bar.finish(note=f"the branch ended: {result.branch.end}" if result.branch is not None else "")
    switched = None if switch is None else _switched(switch, result.branch, period_max)
    if out is not None:  # the Dataset (and xarray) only for a file: --json alone starts quickly
        save_dataset(result.to_dataset(), out)
    if plot is not None:
        from ..plots.orbits import rotation_characteristic_figure

        fig = rotation_characteristic_figure(branches=[result.branch], static_fold=result.static_fold, model=model)
        save_figure(fig, plot)
    if as_json:
        extra = {} if switched is None else {"switch": switched.as_dict()}
        typer.echo(
            json.dumps({"params": params.model_dump(), **result.as_dict(), "static_fold": finite_or_none(result.static_fold), **extra})
        )
        return
    o = result.orbit
    typer.echo(_started(result.start))
    typer.echo(
        f"{model}: M = {o.moment:g}, {o.turns} turn(s) per period T = {o.period:.10g}, mean angular velocity {o.mean_angular_velocity:.10g}"
    )
    typer.echo(f"Floquet multipliers |mu|: {' '.join(f'{abs(m):.4g}' for m in o.multipliers)}")
    if o.multiplier_log_moduli is not None:
        typer.echo(f"log10 |mu| (periodic Schur form): {' '.join(f'{v / math.log(10.0):.6g}' for v in o.multiplier_log_moduli)}")
    typer.echo(
        f"trivial multiplier {o.trivial_multiplier.real:.12g}; largest other |mu| = {o.max_multiplier:.6g}: {'stable' if o.stable else 'unstable'}"
    )
    if result.collocation is not None:
        c = result.collocation
        typer.echo(f"by collocation: NTST = {c.ntst}, NCOL = {c.ncol}; the trivial multiplier off by {c.trivial_multiplier_error:.2g}")
    if result.branch is not None:
        b = result.branch
        typer.echo(f"continued to M = {b.moment[-1]:.10g} ({len(b.orbits)} orbits): {b.message}; the orbit ends at M = {b.end_moment:.10g}")
        if b.stability_lost_at is not None:
            typer.echo(f"the orbit loses stability at M = {b.stability_lost_at:.6g}")
    if switched is not None:
        new = switched.doubled if switch == "period-doubling" else switched.orbit
        typer.echo(
            f"switched at the {switch} at M = {switched.value:.10g}: {new.turns} turn(s), T = {new.period:.10g} at M = {new.moment:.10g} "
            f"({'stable' if new.stable else 'unstable'}), the family {switched.side} it"
            + (f", followed to M = {switched.branch.orbits[-1].moment:.10g} ({switched.branch.end})" if switched.branch is not None else "")
        )
    typer.echo(f"static fold M_c = {result.static_fold:.15g}")


#: The solvers --method takes (:func:`~cosserat_chain.numerics.periodic.find_periodic_orbit`'s ``method``).
ORBIT_METHODS = ("auto", "dense", "blocks", "krylov", "picard", "collocation")


def _mesh_or_exit(method: str, ntst: int | None, ncol: int | None, max_interval: float | None, branch: bool, follow: str) -> dict:
    """The collocation mesh options given ({"ntst": ..., "ncol": ..., "max_interval": ...}, those given only), checked
    (:func:`~cosserat_chain.numerics.collocation_core.check_mesh`, and at most
    :data:`~cosserat_chain.numerics.collocation.NTST_MAX` intervals); exit 2 naming the option, the value and what is
    allowed, for any of them without --method collocation, or --max-interval without a branch (``branch``; ``follow``
    says how to ask for one)."""
    given = {"--ntst": ntst, "--ncol": ncol, "--max-interval": max_interval}
    named = [option for option, value in given.items() if value is not None]
    if not named:
        return {}
    if method != "collocation":
        fail(f"{', '.join(named)} set(s) the collocation's mesh: give --method collocation as well (got --method {method})")
    if max_interval is not None and not branch:
        fail(f"--max-interval bounds the mesh intervals of a branch: give {follow} as well (a lone orbit's mesh is --ntst)")
    from ..numerics.collocation import NTST_MAX
    from ..numerics.collocation_core import NCOL, NTST, check_mesh

    for option, value, check in (("--ntst", ntst, lambda v: check_mesh(v, NCOL)), ("--ncol", ncol, lambda v: check_mesh(NTST, v))):
        if value is None:
            continue
        try:
            check(value)
        except ValueError as err:
            fail(f"{option}: {err}")
    if ntst is not None and ntst > NTST_MAX:
        fail(f"--ntst: ntst must be at most {NTST_MAX} (the most a branch's --max-interval may ask for), got {ntst}")
    return {key: value for key, value in (("ntst", ntst), ("ncol", ncol), ("max_interval", max_interval)) if value is not None}


#: The points --switch takes.
SWITCHES = ("period-doubling", "branch-point")


def _switched(kind: str, branch, period_max: float):
    """The family born at the branch's first point of ``kind`` (numerics.cycle_switching, numerics.cycle_branch_points);
    a branch without one exits 3 saying so."""
    from ..numerics.cycle_branch_points import switch_at_branch_point
    from ..numerics.cycle_switching import switch_at_period_doubling
    from ..numerics.periodic import OrbitError

    try:
        return (switch_at_period_doubling if kind == "period-doubling" else switch_at_branch_point)(branch, period_max=period_max)
    except (ValueError, OrbitError) as err:
        fail(f"--switch {kind}: {err}", code=3)


#: The turns per period tried when --turns is not given (states of the paper's chain repeat after up to 3).
AUTO_TURNS = (1, 2, 3)


def _turns_to_follow(params, model: str, moment: float, particle: int, **start):
    """(k, its result) for the first k of :data:`AUTO_TURNS` whose orbit is stable, else the first with an orbit.

    ``start`` goes to :func:`~cosserat_chain.experiments.orbits.periodic_orbit` (``from_above``, ``guess``,
    ``start``, ``period_max``, ``progress``). Raises the last :class:`~cosserat_chain.numerics.periodic.OrbitError` when
    none converges (its message suggests what to try).
    """
    from ..experiments.orbits import periodic_orbit
    from ..numerics.periodic import OrbitError

    found, error = None, None
    for k in AUTO_TURNS:
        try:
            result = periodic_orbit(params, model, moment, turns=k, particle=particle, **start)
        except OrbitError as err:
            error = err
            continue
        if result.orbit.stable:
            return k, result
        found = (k, result) if found is None else found
    if found is None:
        raise error
    return found


def _started(start: dict) -> str:
    """One line on how the orbit was reached (:attr:`~cosserat_chain.experiments.orbits.OrbitResult.start`)."""
    method = start["method"]
    source = f" {start['file']}" if "file" in start else ""
    if method == "from_above":
        lost = start["stability_lost_at"]
        note = "" if lost is None else f"; it lost stability on the way down at M = {lost:.6g} (a falling load leaves it there)"
        return f"reached from the orbit at M = {start['from_moment']:g}, continued down over {start['approach_points']} orbits{note}"
    if method == "guess":
        return f"Newton from the stored orbit{source}" if source else "Newton from the guess"
    if method == "state":
        return f"a run settled from the last frame of{source}" if source else "a run settled from the given state"
    return "a run settled from rest"


def _guess_or_exit(path: Path, params, particle: int) -> dict:
    """The start stored in ``path`` for :func:`~cosserat_chain.experiments.orbits.periodic_orbit`, or exit 2 naming what is wrong.

    An orbit (``orbit --out``) gives ``guess`` = (x, v, T, turns of every particle) and its ``turns``;
    a run (``simulate --out``) its last frame as ``start``. ``holds`` says which.
    """
    import math

    import numpy as np

    from ..io import params_of, read_dataset, run_frame
    from ..state import ROWS

    label = f"--guess {str(path)!r}"
    try:
        ds = read_dataset(path)
        if "time" in ds.dims:
            run_params, _, _, x, v = run_frame(ds, source=label)
            holds = "run"
        elif ds.attrs.get("experiment") == "periodic_orbit":
            run_params = params_of(ds)
            holds = "orbit"
        else:
            fail(
                f"{label} holds neither an orbit (orbit --out) nor a run (simulate --out): its experiment is "
                f"{ds.attrs.get('experiment')!r}, allowed 'periodic_orbit' or a run over time"
            )
    except ValueError as err:
        fail(str(err) if str(err).startswith(label) else f"{label}: {err}")
    if run_params.n_particles != params.n_particles or (run_params.left_end, run_params.right_end) != (params.left_end, params.right_end):
        fail(
            f"{label} holds a chain of {run_params.n_particles} particles with ends {run_params.left_end}/{run_params.right_end}; "
            f"the chain asked (--config) has {params.n_particles} with ends {params.left_end}/{params.right_end}: they must agree"
        )
    if holds == "run":
        return {"start": (x, v), "holds": holds}
    loaded = int(ds.attrs.get("loaded_particle", particle))
    if loaded != particle:
        fail(f"{label} holds an orbit loaded at particle {loaded}; --particle is {particle}: they must agree")
    needed = [*ROWS, *(f"{row}_dot" for row in ROWS), "particle_turns"]
    missing = [name for name in needed if name not in ds.variables]
    if missing:
        fail(f"{label} lacks {', '.join(missing)}: an orbit file (orbit --out, this version) holds {', '.join(needed)}")
    ordered = ds.sortby("particle")
    x = np.stack([np.asarray(ordered[row].values, dtype=float) for row in ROWS])
    v = np.stack([np.asarray(ordered[f"{row}_dot"].values, dtype=float) for row in ROWS])
    period, turns = float(ds.attrs.get("period", math.nan)), ds.attrs.get("turns")
    if not (np.all(np.isfinite(x)) and np.all(np.isfinite(v))):
        fail(f"{label}: the orbit's state holds a value that is not a finite number; allowed: finite numbers")
    if not (math.isfinite(period) and period > 0):
        fail(f"{label}: the orbit's period is {period!r}; allowed: a finite number > 0")
    if not (isinstance(turns, (int, np.integer)) and turns >= 1):
        fail(f"{label}: the orbit's turns is {turns!r}; allowed: an integer >= 1")
    particle_turns = np.asarray(ordered["particle_turns"].values)
    return {"guess": (x, v, period, particle_turns), "turns": int(turns), "holds": holds}
