"""``cosserat-chain sweep`` (the paper's relaxation protocol) and ``cosserat-chain critical`` (exact statics)."""

from __future__ import annotations

import json
import math
from pathlib import Path

import typer

from ..io import stack_models
from ..status import Status
from .common import (
    ALL_MODELS,
    LARGER_STEP,
    app,
    bar_callback,
    chosen_models,
    compliance_or_exit,
    config_or_exit,
    exit_on,
    fail,
    held_or_exit,
    model_option,
    number,
    outputs_or_exit,
    params_or_exit,
    progress_bar,
    save_dataset,
    save_figure,
    short_stiff_at_rest_or_exit,
    statics_failed,
    step_for_checks,
    whole,
    work_or_exit,
)
from .systems import chain_only_or_exit, critical_on_system, set_option, start_option, system_only_or_exit, system_option, vary_option

MODEL_HELP = "Model, or all for every registered one."

#: Most load steps a sweep starts (up and down together): the paper's protocol takes about a
#: hundred, and each step relaxes for up to --t-max.
MAX_LOAD_STEPS = 100_000


@app.command()
def sweep(
    model: str = model_option(ALL_MODELS, MODEL_HELP, all_models=True),
    m_max: float = number(..., "Largest moment of the upward sweep.", above=0.0, flags=("--m-max",)),
    steps: int | None = whole(None, at_least=1, help="Number of load steps from 0 to m_max."),
    dm: float | None = number(None, "Load increment (instead of --steps).", above=0.0),
    down: bool = typer.Option(False, "--down", help="Then lower the load step by step to 0 (hysteresis)."),
    particle: int = typer.Option(0, help="Loaded particle (default the central one)."),
    t_max: float = number(20000.0, "Time cap of one load step.", above=0.0, flags=("--t-max",)),
    load: list[str] | None = typer.Option(
        None, "--load", help="A constant load ROW:PARTICLE=VALUE acting throughout besides the stepped moment; repeatable."
    ),
    config: Path | None = typer.Option(
        None, help="TOML file with ChainParams fields and [[loads]] tables (constant loads acting throughout)."
    ),
    out: Path | None = typer.Option(None, help="Write the steps to this NetCDF file."),
    plot: Path | None = typer.Option(None, help="Draw Fig. 2 (with the exact branches) to this PNG/SVG file."),
    as_json: bool = typer.Option(False, "--json", help="Print the result as one JSON object."),
) -> None:
    """Raise the moment step by step, relaxing to rest at each step (the paper's protocol); report the onset of rotation."""
    from ..experiments.critical import critical_point
    from ..experiments.sweep import relaxation_sweep
    from ..numerics.relaxation import RelaxSettings

    outputs_or_exit({"--out": out, "--plot": plot}, {"--config": config})
    if (steps is None) == (dm is None):
        given = f"both (--steps {steps}, --dm {dm:g})" if steps is not None else "neither"
        fail(f"give exactly one of --steps (the number of load steps) and --dm (the load increment), got {given}")
    count = steps if steps is not None else math.ceil(m_max / dm)
    if count * (2 if down else 1) > MAX_LOAD_STEPS:
        asked = "--steps" if steps is not None else f"--m-max / --dm = {m_max:g} / {dm:g}"
        fail(
            f"{asked} asks for {count:.3g} load steps, each relaxed for up to --t-max {t_max:g}: more than {MAX_LOAD_STEPS:,} "
            "(the paper's protocol takes about a hundred); fewer steps or a larger --dm"
        )
    params, extra = config_or_exit(config, load)
    if extra and plot is not None:
        fail("--plot draws the exact static branches, which hold the moment alone: leave out --plot or the extra loads")
    # Each load step relaxes for at least one chunk of time before its first test.
    chunk = min(t_max, RelaxSettings.chunk_time)
    for name in chosen_models(model):
        step = step_for_checks(params, name, None)
        if step is not None:
            what = f"{name}: {count * (2 if down else 1)} load steps of at least {chunk:g} time units at dt={step:.3g}"
            work_or_exit(count * (2 if down else 1) * chunk / step, params.n_particles, what, f"fewer load steps, or {LARGER_STEP}")
    results = {}
    interrupted = False
    for name in chosen_models(model):
        bar = progress_bar(f"sweep {name}", "load")
        try:
            result = relaxation_sweep(
                params, name, m_max=m_max, steps=steps, dm=dm, down=down, particle=particle, t_max=t_max,
                progress=bar_callback(bar), loads=extra,
            )  # fmt: skip
        except ValueError as err:
            bar.close()
            fail(str(err))
        bar.finish(None if result.completed else Status.INTERRUPTED)
        results[name] = result
        if not result.completed:
            interrupted = True
            break
    if out is not None:  # the Dataset (and xarray) only for a file: --json alone starts quickly
        save_dataset(stack_models({name: r.to_dataset() for name, r in results.items()}), out)
    if plot is not None:
        from ..plots.statics import figure2

        criticals = {name: critical_point(params, name, particle=particle, dynamics=False) for name in results}
        save_figure(figure2(criticals, results), plot)
    if as_json:
        typer.echo(json.dumps({"params": params.model_dump(), "models": {name: r.as_dict() for name, r in results.items()}}))
    else:
        for name, r in results.items():
            onset = "none" if r.onset_load is None else f"{r.onset_load:g}"
            stop = "" if not down else f", rotation stops at {'none' if r.stop_load is None else f'{r.stop_load:g}'}"
            typer.echo(f"{name}: {len(r.moment)} load steps, onset of rotation at M = {onset}{stop}")
    if interrupted:
        exit_on(Status.INTERRUPTED, "the finished load steps are kept")
    for name, r in results.items():
        unsettled = sum(1 for status in r.status if status == Status.NOT_CONVERGED)
        if unsettled:
            message = f"{name}: {unsettled} of {len(r.status)} load steps neither came to rest nor rotated steadily within --t-max {t_max:g}"
            if unsettled == len(r.status):
                exit_on(Status.NOT_CONVERGED, f"no load step converged ({message}); raise --t-max")
            typer.secho(f"warning: {message}; their status is not_converged", err=True, fg=typer.colors.YELLOW)


@app.command()
def critical(
    ctx: typer.Context,
    model: str = model_option(ALL_MODELS, MODEL_HELP, all_models=True),
    particle: int = typer.Option(0, help="Loaded particle (default the central one)."),
    config: Path | None = typer.Option(None, help="TOML file with ChainParams fields (with --system: the system's [system] table)."),
    out: Path | None = typer.Option(None, help="Write the branches to this NetCDF file."),
    plot: Path | None = typer.Option(None, help="Draw the branches (Fig. 2 without the relaxation points) to this PNG/SVG file."),
    max_points: int | None = whole(
        None, at_least=2, help="Most points of each branch (default 5000); a branch cut short exits with max_steps (3)."
    ),
    turns: float | None = number(
        None,
        "Budget in turns of the loaded particle for a branch that stays stable past one turn (default 16); reached, "
        "it exits with max_steps (3).",
        at_least=1.0,
    ),
    as_json: bool = typer.Option(False, "--json", help="Print the result as one JSON object."),
    system: str | None = system_option(),
    sets: list[str] | None = set_option(),
    vary: str | None = vary_option("upwards from its value; --down for downwards"),
    start: str | None = start_option("where Newton starts for the first equilibrium (default 0)"),
    down: bool = typer.Option(False, "--down", help="With --system: continue towards smaller values of --vary."),
) -> None:
    """Critical moment M_c and phi_0 at the fold (to round-off), compliance, and the static branch over one turn and on to
    where its stable part from rest ends.

    With --system: the equilibrium from --start continued in --vary to its first fold."""
    if system is not None:
        chain_only_or_exit(ctx, ("config", "as_json", "max_points", "sets", "vary", "start", "down"))
        return critical_on_system(
            system, config=config, sets=sets, vary=vary, start=start, down=down, max_points=max_points, as_json=as_json
        )
    system_only_or_exit(ctx, ("sets", "vary", "start", "down"))
    from ..experiments.critical import CONFIRM_MOMENT_RTOL, CONFIRM_PHI0_ATOL, MAX_POINTS, TURNS, critical_point
    from ..memory import MemoryEstimateError
    from ..numerics.kit import BranchEnd
    from ..numerics.newton import NewtonError

    max_points = MAX_POINTS if max_points is None else max_points
    turns = TURNS if turns is None else turns
    outputs_or_exit({"--out": out, "--plot": plot}, {"--config": config})
    params = params_or_exit(config)
    held_or_exit(params, particle)
    # Up front, not only on a failure: a K at rest singular to round-off can also end the trace quietly. On a
    # short chain: the chain's own response at rest is critical_point's (its compliance), checked on its result.
    short_stiff_at_rest_or_exit(params)
    results = {}
    for name in chosen_models(model):
        bar = progress_bar(f"critical {name}", "rad")
        try:
            results[name] = critical_point(params, name, particle=particle, max_points=max_points, turns=turns, progress=bar_callback(bar))
        except NewtonError as err:
            bar.close()
            fail(str(err), code=3)
        except (ValueError, ArithmeticError) as err:
            bar.close()
            if isinstance(err, MemoryEstimateError):
                raise
            statics_failed(params, err, particle)
        bar.finish()
        compliance_or_exit(params, results[name].compliance)
    if out is not None:  # the Dataset (and xarray) only for a file: --json alone starts quickly
        save_dataset(stack_models({name: r.to_dataset() for name, r in results.items()}), out)
    if plot is not None:
        from ..plots.statics import figure2

        save_figure(figure2(results), plot)
    if as_json:
        typer.echo(json.dumps({"params": params.model_dump(), "models": {name: r.as_dict() for name, r in results.items()}}))
    else:
        for name, r in results.items():
            fold = "no fold" if r.fold is None else f"M_c = {r.fold.moment:.15g} at phi_0 = {r.fold.phi0:.15g} rad (onset of rotation)"
            if r.branch_point is not None:
                q = r.branch_point
                part = "the stable branch from rest" if r.end == "branch_point" else "the highest stable part of the branch"
                fold = (
                    f"M_c = {q.moment:.15g} at phi_0 = {q.phi0:.15g} rad (onset of rotation: {part} "
                    f"ends at a branch point, K singular with M still rising; the branch's largest fold, "
                    + ("none" if r.fold is None else f"M = {r.fold.moment:.15g} at phi_0 = {r.fold.phi0:.15g} rad")
                    + ", lies on its unstable part)"
                )
            if r.crossing is not None:
                q, c = r.branch_point or r.first_fold, r.crossing
                where = "a branch point" if r.branch_point is not None else "a fold past which the trace was cut short"
                fold = (
                    f"M_c = {c.moment:.15g} at phi_0 = {c.phi0:.15g} rad (onset of rotation: the stable branch from rest ends at "
                    f"{where}, M = {q.moment:.15g} at phi_0 = {q.phi0:.15g} rad, past which a relaxation comes to rest on a "
                    "stable branch that carries the chain, at rest, to this fold"
                    + (": a lower bound, the chain still rests past it)" if r.crossing_unresolved else ")")
                )
            elif r.crossing_unresolved:
                fold += "; a stable crossing branch carries the chain past it, not followed to its end: M_c is a lower bound"
            if r.snap_through and r.crossing is None:
                fold += f"; the stable branch from rest ends earlier, at M = {r.first_fold.moment:.15g}, phi_0 = {r.first_fold.phi0:.15g} rad (snap-through"
                fold += ")" if r.snap_to is None else f" to the stable state at phi_0 = {r.snap_to.phi0:.15g} rad)"
            if r.onset_particle is not None and r.onset_particle != r.particle:
                fold += f"; particle {r.onset_particle}, not the loaded one, turns first there"
            over = (
                f"to phi_0 = {r.branch.phi0[-1]:.6g} rad"
                if r.complete
                else f"on the traced part (incomplete: {len(r.branch.moment)} points)"
            )
            if r.branch.stop in (BranchEnd.WOUND, BranchEnd.DECIDED):
                over += f" (the trace stopped: {r.branch.message})"
            elif r.branch.stop == BranchEnd.MAX_FOLDS and r.confirmation == "closed form":
                over += " (the branch in closed form to one step past its first fold: no static state of eq. (2) holds more)"
            if r.confirmation == "closed form":
                over += ", each at eq. (2)'s closed form M = +-1 / max_j |dphi_j/dM|"
            elif r.confirmation == "re-solved":
                checked = [f.confirmed for f in r.branch.folds if f.confirmed is not None]
                over += f", {sum(checked)} of the {len(checked)} that decide M_c confirmed by a re-solve on the rotation-controlled branch"
            typer.echo(f"{name}: {fold}; compliance dphi_0/dM = {r.compliance:.15g}; {len(r.branch.folds)} folds {over}")
            typer.echo(f"  {_stability_line(r)}")
    for name, r in results.items():
        if r.budget_reached:
            exit_on(
                Status.MAX_STEPS,
                f"the {name} branch from rest is still stable after {turns:g} turns of the loaded particle (phi_0 = "
                f"{r.branch.phi0[-1]:.6g}): its end, and M_c, lie beyond (raise --turns)",
            )
        decided = "M_c is decided on the traced part" if r.crossing is None else "M_c is decided past it, by relaxations"
        if r.onset_checked and r.branch.stop in (BranchEnd.MAX_POINTS, BranchEnd.STEP_TOO_SMALL, BranchEnd.REVERSED):
            # M_c is decided by relaxations that leave rest just above it: only the branch beyond it is cut short.
            typer.echo(
                f"note: the {name} branch was traced only in part ({r.branch.stop}: {r.branch.message}); M_c is decided, "
                "a relaxation just above it leaves rest (onset_checked); the branch past it is incomplete (branch_complete false)",
                err=True,
            )
        elif r.branch.stop == BranchEnd.MAX_POINTS:
            exit_on(
                Status.MAX_STEPS,
                f"the {name} branch used all {max_points} points before the loaded particle turned once: "
                "M_c is decided on the traced part (raise --max-points)",
            )
        elif r.branch.stop == BranchEnd.STEP_TOO_SMALL:
            exit_on(Status.STEP_TOO_SMALL, f"the {name} branch: {r.branch.message}; {decided}")
        elif r.branch.stop == BranchEnd.REVERSED:
            exit_on(Status.FAILED, f"the {name} branch: {r.branch.message}; {decided}")
        if r.crossing_unresolved:
            past = r.crossing or r.branch_point or r.first_fold
            exit_on(
                Status.INACCURATE,
                f"the {name} branch: past M = {past.moment:.15g} a relaxation comes to rest on a stable branch, which could "
                "not be followed to where the chain leaves rest: M_c is a lower bound (the relaxation protocol, sweep, finds "
                "the onset)",
            )
        if not r.accurate:
            spread = max((f.discrepancy for f in (r.fold, r.first_fold) if f is not None and f.discrepancy is not None), default=math.inf)
            exit_on(
                Status.INACCURATE,
                f"the {name} branch: K is near singular at rest (a long chain: its condition number grows like N^4) and a re-solve "
                f"on the rotation-controlled branch did not find the fold of M_c or the first fold within {CONFIRM_MOMENT_RTOL:g} "
                f"of the branch's largest moment and {CONFIRM_PHI0_ATOL:g} rad of its phi_0 ("
                + ("no such fold there" if not math.isfinite(spread) else f"the moments differ by up to {spread:.2g}")
                + "): M_c is known only to that",
            )


def _stability_line(r) -> str:
    """The dynamic verdict of the branch from rest up to M_c and the branch's Hopf points, each named for what it is."""
    verdict = r.dynamically_stable_to_onset
    rest = {True: "dynamically stable", False: "has unstable eigenvalues", None: "dynamic verdict not computed"}[verdict]
    upto = "up to M_c" if r.critical_moment is not None else "over the traced turn"
    line = f"branch from rest {upto}: {rest} (verdict from {r.dynamics_from}: {r.dynamics_note})"
    if r.hopf is None:
        return line + "; Hopf points of the branch: not searched (beyond the dense limit: numerics.hopf.hopf_points searches it)"
    if r.hopf_search == "searched":
        points = "; ".join(
            f"M = {h.moment:.10g} at phi_0 = {h.phi0:.10g} rad, omega = {h.frequency:.6g}, unstable eigenvalues "
            f"{h.unstable_before} -> {h.unstable_after} (stiffness index {h.stiffness_index})" + ("" if h.located else ", not located")
            for h in r.hopf
        )
        line += f"; Hopf points of the traced branch: {len(r.hopf)}" + (f": {points}" if r.hopf else "")
    return line + "; index before/after of folds: stiffness index (K's negative eigenvalues)"
