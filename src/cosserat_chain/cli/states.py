"""``cosserat-chain states``: the coexisting static states, rotating orbits and irregular rotations at one moment."""

from __future__ import annotations

import json
import math
from pathlib import Path

import typer

from ..status import Status
from .common import (
    EXIT_CODES,
    app,
    bar_callback,
    config_or_exit,
    exit_on,
    fail,
    held_or_exit,
    model_option,
    number,
    progress_bar,
    spin_or_exit,
    statics_failed,
    step_for_checks,
    work_or_exit,
)
from .systems import chain_only_or_exit, set_option, start_option, states_on_system, system_only_or_exit, system_option


@app.command()
def states(
    ctx: typer.Context,
    model: str = model_option("sine", "The model (the linear one has one static state and no orbit)."),
    moment: float | None = number(None, "Constant moment M on the loaded particle (required without --system)."),
    particle: int = typer.Option(0, help="Loaded particle (default the central one)."),
    turns: int = typer.Option(3, help="Shoot for orbits of 1..TURNS turns a period; long runs look for repetition after up to 2 TURNS."),
    random_starts: int = typer.Option(8, "--random-starts", help="Long runs from this many seeded random states."),
    seed: int = typer.Option(0, help="Seed of the random starts and of the static states' perturbations."),
    t_long: float = number(5000.0, "Length of each long run (its second half is analysed).", above=0.0, flags=("--t-long",)),
    config: Path | None = typer.Option(None, help="TOML file with ChainParams fields (with --system: the system's [system] table)."),
    as_json: bool = typer.Option(False, "--json", help="Print the result as one JSON object."),
    system: str | None = system_option(),
    sets: list[str] | None = set_option(),
    start: list[str] | None = start_option("a start of Newton, repeatable (default q = 0 and q = pi on every angle)"),
) -> None:
    """List the states at one moment, each with its stability, and say which one the protocol from rest reaches.

    Static states on the branch from rest over one full turn (residual; the damped dynamics' verdict,
    "dynamically stable" or its unstable eigenvalues, beside K's inertia, the stiffness index) and the
    branch's Hopf points; periodic
    orbits from shooting and from long runs (turns, period, mean rate, Floquet stability);
    irregular rotation (rates over windows of whole turns); what each start's run reached.

    With --system: the system's equilibria by Newton from each --start, with their stability.

    Exit status: 0 done, 2 bad input, 3 a run blew up.
    """
    if system is not None:
        chain_only_or_exit(ctx, ("config", "as_json", "sets", "start"))
        return states_on_system(system, config=config, sets=sets, starts=start, as_json=as_json)
    system_only_or_exit(ctx, ("sets", "start"))
    if moment is None:
        fail("--moment is required: the constant moment M on the loaded particle (or give --system REF for a system's states)")
    from ..experiments.coexisting import states_at
    from ..memory import MemoryEstimateError
    from ..numerics.dynamics import IntegrationError

    if turns < 1:
        fail(f"--turns must be an integer >= 1 (turns of the loaded particle per period), got {turns!r}")
    if random_starts < 0:
        fail(f"--random-starts must be an integer >= 0, got {random_starts!r}")
    if seed < 0:
        fail(f"--seed must be an integer >= 0 (a seed of NumPy's generator), got {seed!r}")
    params, loads = config_or_exit(config)
    if len(loads):
        fail("--config: states takes no [[loads]] tables (the moment is the only load)")
    held_or_exit(params, particle)
    step = step_for_checks(params, model, None)
    if step is not None:
        spin_or_exit(params, moment, step, dt_option=False)
        # The long runs, and the shots for orbits of k = 1..TURNS turns, each at least k turns long
        # (2 pi k gamma_phi / |M| at the spin's bound |M| / gamma_phi).
        shots = math.pi * turns * (turns + 1) * params.gamma_phi / abs(moment) if moment else 0.0
        what = f"{random_starts} long runs of {t_long:g} and shots over {shots:.3g} time units at dt={step:.3g}"
        remedy = "fewer --random-starts or --turns, or a shorter --t-long"
        work_or_exit((random_starts * t_long + shots) / step, params.n_particles, what, remedy)
    bar = progress_bar(f"states {model}", "start")
    try:
        result = states_at(
            params, model, moment, particle=particle, turns=tuple(range(1, turns + 1)), random_starts=random_starts, seed=seed,
            t_long=t_long, progress=bar_callback(bar),
        )  # fmt: skip
    except (ValueError, ArithmeticError) as err:
        # The inputs were checked above: what is left is the computation's own failure (a state gone NaN).
        bar.close()
        if isinstance(err, MemoryEstimateError):
            raise
        statics_failed(params, err, particle)
    except IntegrationError as err:
        bar.close()
        if getattr(err.trajectory, "status", None) == Status.INTERRUPTED:
            exit_on(Status.INTERRUPTED, f"{err}; the states are listed only once every start has run, so none is kept")
        fail(str(err), code=EXIT_CODES[Status.BLEW_UP])
    except KeyboardInterrupt:
        bar.close()
        exit_on(Status.INTERRUPTED, "the states are listed only once every start has run, so none is kept")
    bar.finish()
    if as_json:
        typer.echo(json.dumps({"params": params.model_dump(), **result.as_dict()}))
    else:
        _print(result)
    exit_on(result.status, "")


def _print(result) -> None:
    typer.echo(f"{result.model}, M = {result.moment:g}:")
    if not result.static:
        typer.echo("  no static state on the branch from rest over one full turn")
    for i, s in enumerate(result.static):
        where = "" if s.on_branch else " (off the traced branch)"
        typer.echo(f"  static {i}: phi_0 = {s.phi0:.10g}, residual {s.residual:.2g}, {s.dynamics.describe()}{where}")
    if result.hopf is None:
        typer.echo("  Hopf points of the branch: not searched (a chain beyond the dense limit: numerics.hopf.hopf_points searches it)")
    for h in result.hopf or []:
        where = "" if h.located else f" (not located: between traced points {h.after_point} and {h.after_point + 1})"
        typer.echo(
            f"  Hopf point of the branch: M = {h.moment:.10g}, phi_0 = {h.phi0:.10g}, omega = {h.frequency:.6g}, "
            f"unstable eigenvalues {h.unstable_before} -> {h.unstable_after} at stiffness index {h.stiffness_index}{where}"
        )
    for i, f in enumerate(result.orbits):
        o = f.orbit
        typer.echo(
            f"  orbit {i}: {o.turns} turn(s) per period T = {o.period:.10g}, mean rate {o.mean_angular_velocity:.10g}, "
            f"largest other |mu| {o.max_multiplier:.4g}: {'stable' if o.stable else 'unstable'} (found from {len(f.found_from)} start(s))"
        )
    for i, r in enumerate(result.irregular):
        typer.echo(
            f"  irregular {i}: rate {r.rate_mean:.6g} (windows of {r.window_turns} turns: {r.rate_min:.6g} to {r.rate_max:.6g}), "
            f"no repetition after 1..{r.max_turns} turns"
        )
    rest = result.from_rest
    reached = rest.reached if rest.index is None else f"{rest.reached} {rest.index}"
    typer.echo(
        f"  from rest: the relaxation step ends {result.relaxation['status']} (t = {result.relaxation['time']:g}) and settles on {reached}"
    )
    counts: dict[str, int] = {}
    for run in result.runs:
        key = run.reached if run.index is None else f"{run.reached} {run.index}"
        counts[key] = counts.get(key, 0) + 1
    typer.echo("  long runs reached: " + ", ".join(f"{key} ({n})" for key, n in counts.items()))
