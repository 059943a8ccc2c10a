"""``cosserat-chain breathers``: one-site roto-breathers of the undamped chain, followed in the frequency."""

from __future__ import annotations

import json
import math
from pathlib import Path

import typer

from .common import (
    app,
    bar_callback,
    fail,
    model_option,
    number,
    outputs_or_exit,
    params_or_exit,
    progress_bar,
    save_dataset,
    save_figure,
    whole,
)
from .systems import chain_only_or_exit, set_option, system_only_or_exit, system_option

#: Largest frequency taken: the rotor's energy j Omega^2 / 2 stays far inside double precision's range.
MAX_OMEGA = 1e100
#: Most turns of the rotor a period (as the damped orbits': numerics.periodic.MAX_TURNS).
MAX_TURNS = 1000


@app.command()
def breathers(
    ctx: typer.Context,
    model: str = model_option("sine", "A model that supports full rotations (the linear model does not).", rotating=True),
    omega: float | None = number(
        None, "Frequency Omega of the rotating particle (its mean angular velocity) to start from.", above=0.0, at_most=MAX_OMEGA
    ),
    to: float | None = number(None, "Follow the family in Omega to here (default: the start alone).", above=0.0, at_most=MAX_OMEGA),
    steps: int = whole(11, at_least=2, help="Frequencies from --omega to --to, both included."),
    turns: int = whole(1, at_least=1, at_most=MAX_TURNS, help="Turns of the rotating particle per period (T = 2 pi turns / Omega)."),
    particle: int = typer.Option(0, help="The rotating particle (default the central one)."),
    partner: int | None = typer.Option(None, help="A second rotor (a two-site roto-breather), turning as often as the first."),
    counter: bool = typer.Option(False, "--counter", help="The partner turns against the first rotor (default: with it)."),
    lifetimes: int = whole(
        0,
        at_least=0,
        help="Run each orbit (of the family, or found by --atlas), its velocities perturbed by 1e-8, for up to this many periods: "
        "its lifetime (0: none); also in --json, --out and --plot (a family's or an atlas's figure).",
    ),
    config: Path | None = typer.Option(None, help="TOML file with ChainParams fields; its viscosities are set to 0 (undamped)."),
    out: Path | None = typer.Option(None, help="Write the family to this NetCDF file."),
    plot: Path | None = typer.Option(None, help="Draw the family against the bands' harmonics to this PNG/SVG file."),
    as_json: bool = typer.Option(False, "--json", help="Print the result as one JSON object."),
    system: str | None = system_option(),
    sets: list[str] | None = set_option(),
    coupling: str = typer.Option(
        "C", "--coupling", metavar="NAME", help="With --system: the coupling, continued from 0 (the anti-continuum limit) to its value."
    ),
    atlas: str | None = typer.Option(
        None,
        "--atlas",
        metavar="FIELD=V1,V2,...",
        help="The existence map: roto-breathers over the frequencies --omega..--to (--steps) and these values of a chain field "
        "(a, b, h, E1, E2), or with --system of a system parameter, continued in both; existence, stability, localization against "
        "the bands' harmonics; with --partner, of two rotors.",
    ),
    method: str = typer.Option(
        "auto",
        help="With --atlas: the monodromy in one integration (dense), in column blocks (blocks), or by N (auto: blocks from N = 50).",
    ),
    locate: bool = typer.Option(
        True,
        "--locate/--no-locate",
        help="With --atlas: locate each change of stability between neighbours of opposite stability, along Omega and along "
        "the field (--locate-along), every pair crossing there (the zero of the colliding pair's discriminant, with its accuracy); "
        "in the table, --json, --out and --plot.",
    ),
    locate_along: str | None = typer.Option(
        None,
        "--locate-along",
        metavar="AXES",
        help="With --atlas: the axes the changes are located along: omega, the atlas's FIELD, or both as omega,FIELD (the default): "
        "between neighbours at one field value, at one Omega, or both.",
    ),
    locate_every: bool = typer.Option(
        False,
        "--locate-every",
        help="With --atlas: also locate between two unstable neighbours whose pairs off the unit circle differ (a second pair "
        "leaving, one coming back): more changes, at more cost.",
    ),
    locate_tol: float | None = number(
        None,
        "With --atlas: the accuracy the changes are located to, in Omega and in the field (default 1e-6; at most 0.01): a looser "
        "one stops the bisection and the secant sooner.",
        above=0.0,
        flags=("--locate-tol",),
    ),
    from_moment: float | None = number(
        None,
        "Instead of a family: find the damped chain's rotating orbit at this moment M (the config's viscosities, or --gamma) and "
        "follow it to zero damping at its mean rate (damped to undamped), against the anti-continuum family there.",
        above=0.0,
    ),
    gamma: float | None = number(None, "With --from-moment: the viscosities gamma_u = gamma_v = gamma_phi of the damped start.", above=0.0),
    arclength: bool = typer.Option(
        False, "--arclength", help="Follow the family from --omega towards --to by pseudo-arclength: through folds in Omega, located."
    ),
    along: str | None = typer.Option(
        None,
        "--along",
        metavar="NAME=VALUE",
        help="With --arclength: follow the family at the fixed frequency --omega in this parameter (with --system one of its "
        "parameters; of the chain a field a, b, h, E1, E2) from its value to VALUE, instead of in Omega to --to.",
    ),
    branches: bool = typer.Option(
        False,
        "--branches",
        help="With --arclength: follow the family crossing each located branch point (a step off along its null vector).",
    ),
) -> None:
    """Roto-breathers: one particle rotating, the rest oscillating, undamped; Newton from the anti-continuum limit, Floquet multipliers, resonances with the bands.

    With --system: the system's family (its angles counted from the central one by --particle and --partner), continued in --coupling from 0, then in the frequency to --to; --out writes it to NetCDF.
    With --atlas FIELD=V1,V2,...: the existence map over (Omega, FIELD), of the chain or of the --system. With --from-moment M: the damped, driven orbit followed to zero damping.
    """
    if arclength and (atlas is not None or from_moment is not None):
        fail("--arclength follows one family from --omega: leave out --atlas and --from-moment")
    if arclength and (to is None) == (along is None):
        fail("--arclength follows the family in Omega to --to, or in a parameter with --along NAME=VALUE: give one of them")
    if (along is not None or branches) and not arclength:
        fail("--along and --branches follow a family by pseudo-arclength: give --arclength as well")
    if from_moment is not None:
        if system is not None or atlas is not None:
            fail("--from-moment follows the chain's damped orbit: leave out --system and --atlas")
        return _damped_to_undamped(model, from_moment, gamma, turns=turns, particle=particle, config=config, as_json=as_json)
    if gamma is not None:
        fail("--gamma sets the damped start of --from-moment: give --from-moment M as well")
    if omega is None:
        fail("give --omega, the rotating particle's frequency to start from (or --from-moment M for the damped-to-undamped homotopy)")
    if to is not None and to == omega:
        fail(
            f"--to must differ from --omega (the family runs from one frequency to another), got {to:g} for both; leave --to out for the one orbit"
        )
    if atlas is None and (locate_tol is not None or locate_every or locate_along is not None):
        fail("--locate-tol, --locate-every and --locate-along set how an atlas's changes are located: give --atlas FIELD=V1,V2,... as well")
    if (locate_every or locate_along is not None) and not locate:
        fail("--locate-every and --locate-along set how changes are located: leave out --no-locate")
    if atlas is not None:
        if counter and partner is None:
            fail("--counter sets the partner's direction: give --partner as well")
        if system is not None:
            import numpy as np

            from .system_breathers import atlas_on_system

            chain_only_or_exit(ctx, ("omega", "to", "steps", "turns", "particle", "partner", "counter", "config", "out", "plot", "as_json",
                                     "sets", "coupling", "atlas", "lifetimes", "locate", "locate_tol", "locate_every", "locate_along"))  # fmt: skip
            omegas = [omega] if to is None else [float(w) for w in np.linspace(omega, to, steps)]
            return atlas_on_system(
                system, atlas, config=config, sets=sets, omegas=omegas, turns=turns, particle=particle, partner=partner, counter=counter,
                coupling=coupling, out=out, plot=plot, as_json=as_json, lifetimes=lifetimes, locate=locate, locate_tol=locate_tol,
                locate_every=locate_every, locate_along=locate_along,
            )  # fmt: skip
        system_only_or_exit(ctx, ("sets", "coupling"))
        return _atlas(atlas, model, omega, to, steps, turns=turns, particle=particle, partner=partner, counter=counter, method=method,
                      config=config, out=out, plot=plot, as_json=as_json, lifetimes=lifetimes, locate=locate,
                      locate_tol=locate_tol, locate_every=locate_every, locate_along=locate_along)  # fmt: skip
    if method != "auto":
        fail("--method chooses the atlas's shooting: give --atlas FIELD=V1,V2,... as well")
    if system is not None:
        from .system_breathers import breathers_on_system

        chain_only_or_exit(
            ctx, ("omega", "to", "turns", "particle", "partner", "counter", "config", "out", "as_json", "sets", "coupling", "lifetimes",
                  "arclength", "along", "branches"),
        )  # fmt: skip
        return breathers_on_system(
            system, config=config, sets=sets, omega=omega, to=to, turns=turns, particle=particle, partner=partner, counter=counter,
            coupling=coupling, out=out, as_json=as_json, lifetimes=lifetimes, arclength=arclength, along=along, branches=branches,
        )  # fmt: skip
    system_only_or_exit(ctx, ("sets", "coupling"))
    field_target = None if along is None else _chain_along_or_exit(along)
    import numpy as np

    from ..experiments.breathers import roto_breather_family
    from ..numerics.periodic import OrbitError

    if counter and partner is None:
        fail("--counter sets the partner's direction: give --partner as well")
    outputs_or_exit({"--out": out, "--plot": plot}, {"--config": config})
    params = params_or_exit(config).replace(gamma_u=0.0, gamma_v=0.0, gamma_phi=0.0)
    omegas = np.array([omega]) if to is None else np.array([omega, to]) if arclength else np.linspace(omega, to, steps)
    bar = progress_bar(f"breathers {model}", "orbit")
    try:
        partners = None if partner is None else {partner: -turns if counter else turns}
        result = roto_breather_family(
            params, model, omegas, turns=turns, particle=particle, partners=partners, progress=bar_callback(bar), arclength=arclength,
            along=field_target, branches=branches,
        )  # fmt: skip
    except ValueError as err:
        bar.close()
        fail(str(err))
    except OrbitError as err:
        bar.close()
        fail(str(err), code=3)
    family = result.family
    bar.finish(note="" if family.complete else "the family ended early")
    lives = None
    if lifetimes:
        bar = progress_bar("lifetimes", "orbit")
        lives = [life.as_dict() for life in result.measure_lifetimes(lifetimes, progress=bar_callback(bar))]
        bar.finish()
    if out is not None:  # the Dataset (and xarray) only for a file: --json alone starts quickly
        save_dataset(result.to_dataset(), out)
    if plot is not None:
        from ..plots.breathers import breather_family_figure

        save_figure(breather_family_figure(result), plot)
    summary = result.as_dict()
    if as_json:
        typer.echo(json.dumps({"params": params.model_dump(), **summary}))
        return
    also = "" if partner is None else f" and {partner} ({'against' if counter else 'with'} it)"
    count = f"{len(family.orbits)} roto-breathers by arclength" if arclength else f"{len(family.orbits)} of {len(omegas)} roto-breathers"
    if field_target is not None:
        count += f" in {field_target[0]} from {summary['values'][0]:g} (Omega = {omega:g} held)"
    typer.echo(f"{model}: {count}, {turns} turn(s) per period, particle {particle}{also}")
    typer.echo(f"{'omega':>10}  {'energy':>12}  {'rotor rate':>11}  {'tail':>10}  {'max |mu|':>10}  stable  harmonics in a band")
    for i, o in enumerate(family.orbits):
        energy = "-" if o.energy is None else f"{o.energy:.8g}"
        inside = ", ".join(f"{h['harmonic']}x in {h['band']}" for h in summary["resonant_harmonics"][i]) or "none"
        typer.echo(
            f"{o.omega:>10.6g}  {energy:>12}  {summary['rotor_velocity'][i]:>11.6g}  {summary['tail_amplitude'][i]:>10.3g}  "
            f"{o.max_multiplier:>10.6g}  {'yes' if o.stable else 'no':>6}  {inside}"
        )
        if lives is not None:
            life = lives[i]["lifetime_periods"]
            typer.echo(f"{'':>10}  lifetime: {'beyond ' + str(lifetimes) if life is None else life} periods")
    if field_target is not None:
        typer.echo(f"{field_target[0]} per orbit: " + ", ".join(f"{value:.8g}" for value in summary["values"]))
    for e in summary.get("events") or []:
        if e["kind"] == "untraced":
            typer.echo(f"not traced by the driver from Omega = {e['omega']:.10g}: {e['message']}")
            continue
        where = f"Omega = {e['omega']:.10g}" if "value" not in e else f"{e['parameter']} = {e['value']:.10g}"
        if e.get("accuracy") is not None:
            where += f" +- {e['accuracy']:.2g}"
        found = f"{e['kind'].replace('_', ' ')} at {where}: energy {e['energy']}, max |mu| {e['max_multiplier']:.6g}"
        if "singular_value" in e:
            found += (
                f", fixed-{e.get('parameter', 'Omega')} Newton system's singular value {e['singular_value']:.2g}, "
                f"pair at +1 split {e['split_before']} -> {e['split_after']}"
            )
        typer.echo(found)
        if "discriminant_value" in e:
            value, accuracy = e["discriminant_value"], e["discriminant_accuracy"]
            typer.echo(
                "  its pair through +1 by the discriminant: "
                + ("not resolved" if value is None else f"Omega = {value:.12g} +- {accuracy:.2g}")
            )
        if "branch" in e:
            b = e["branch"]
            where = f"relocated at {b['at']:.10g} +- {b['accuracy']:.2g}"
            if b["values"]:
                typer.echo(
                    f"  branch ({where}): {len(b['values'])} orbits, {b['values'][0]:.8g} to {b['values'][-1]:.8g}, "
                    f"max |mu| {b['max_multiplier'][0]:.4g} to {b['max_multiplier'][-1]:.4g}; {b['message']}"
                )
            else:
                typer.echo(f"  branch ({where}): none ({b['message']})")
    for c in summary["stability_changes"]:
        r = c["resonance"]
        typer.echo(
            f"stability {'lost' if c['unstable_omega'] < c['stable_omega'] else 'regained'} going down at Omega = {c['omega']:.12g} "
            f"{'(accuracy unknown: ' + c['method'] + ')' if c['accuracy'] is None else '+- ' + format(c['accuracy'], '.2g')} "
            f"(a multiplier leaves the circle at {c['kind']}; the moduli's bisection: {c['moduli_omega']:.10g}); nearest resonance: "
            f"{r['harmonic']:g} x Omega = {r['edge_frequency']:.6g} ({r['band']} band {r['edge']}) at Omega = {r['omega']:.6g}"
        )
    for m in summary["localized_modes"]:
        typer.echo(
            f"localized mode: omega = {m['frequency']:.6g} ({m['branch']}) at particle {m['particle']}, "
            f"share on the rotors' core {m['core_share']:.3g}: {'a resonance' if m['resonant'] else 'no resonance'}"
        )
    for r in result.resonances:
        where = f"{r.band} localized mode" if r.edge == "localized" else f"{r.band} band {r.edge}"
        typer.echo(f"resonance: {r.harmonic} x Omega = {r.edge_frequency:.6g} ({where}) at Omega = {r.omega:.6g}")
    if not family.complete:
        typer.echo(family.message)


def _chain_along_or_exit(text: str) -> tuple[str, float]:
    """FIELD and VALUE of ``--along FIELD=VALUE`` for the chain (FIELD one the atlas takes); exit 2 naming what is wrong."""
    from ..experiments.breather_atlas import ATLAS_FIELDS

    name, sep, value = text.partition("=")
    name = name.strip()
    if not sep or name not in ATLAS_FIELDS:
        fail(f"--along must be FIELD=VALUE with FIELD one of {', '.join(ATLAS_FIELDS)}, got {text!r}")
    try:
        number = float(value)
    except ValueError:
        fail(f"--along {name}: VALUE must be a number, got {value!r}")
    if not math.isfinite(number):
        fail(f"--along {name}: VALUE must be finite, got {value!r}")
    return name, number


def _atlas(
    text: str, model: str, omega: float, to: float | None, steps: int, *, turns: int, particle: int, partner: int | None, counter: bool,
    method: str, config: Path | None, out: Path | None, plot: Path | None, as_json: bool, lifetimes: int = 0, locate: bool = True,
    locate_tol: float | None = None, locate_every: bool = False, locate_along: str | None = None,
) -> None:  # fmt: skip
    """``breathers --atlas``: the existence map over (Omega, a field), of one rotor or of two (``partner``, against it with ``counter``);
    ``lifetimes`` > 0: every orbit found run from its perturbed velocities for that many periods; ``locate``: the changes of
    stability between neighbours located to ``locate_tol`` (every one with ``locate_every``) along the axes ``locate_along``
    names (:func:`~.system_breathers.atlas_changes`)."""
    import numpy as np

    from ..experiments.breather_atlas import breather_atlas
    from .system_breathers import (
        atlas_changes,
        atlas_lifetimes,
        atlas_values,
        changes_text,
        lifetime_text,
        locate_along_or_exit,
        locate_tol_or_exit,
    )

    name, values = atlas_values(text)
    tol = locate_tol_or_exit(locate_tol)
    axes = locate_along_or_exit(locate_along, name)
    if method not in ("auto", "dense", "blocks"):
        fail(f"--method must be auto, dense or blocks, got {method!r}")
    outputs_or_exit({"--out": out, "--plot": plot}, {"--config": config})
    params = params_or_exit(config).replace(gamma_u=0.0, gamma_v=0.0, gamma_phi=0.0)
    omegas = np.array([omega]) if to is None else np.linspace(omega, to, steps)
    bar = progress_bar(f"atlas {model} {name}", "orbit")
    try:
        partners = None if partner is None else {partner: -turns if counter else turns}
        result = breather_atlas(
            params,
            model,
            omegas,
            name,
            values,
            turns=turns,
            particle=particle,
            method=method,
            partners=partners,
            progress=bar_callback(bar),
        )
    except ValueError as err:
        bar.close()
        fail(str(err))
    found = int(result.grid("exists").sum())
    bar.finish(note=f"{found} of {omegas.size * len(values)} found")
    atlas_changes(result, locate, tol, locate_every, axes)
    atlas_lifetimes(result, lifetimes)
    if out is not None:
        save_dataset(result.to_dataset(), out)
    if plot is not None:
        from ..plots.breathers import breather_atlas_figure

        save_figure(breather_atlas_figure(result), plot)
    if as_json:
        typer.echo(json.dumps({"params": params.model_dump(), **result.as_dict()}))
        return
    typer.echo(f"{model}: roto-breathers over Omega and {name}, N = {params.N}: {found} of {omegas.size * len(values)} found")
    header = f"{name:>8}  {'omega':>8}  {'from':>14}  {'max |mu|':>10}  stable  {'PR':>6}  {'xi':>6}  {'phi':>7}  {'u/h':>7}  {'v/h':>7}  localized"
    typer.echo(header)
    for row in result.points:
        for p in row:
            if p.orbit is None:
                typer.echo(f"{p.value:>8.4g}  {p.omega:>8.4g}  {'not found':>14}")
                continue
            loc = p.localization
            amp = loc.amplitudes
            typer.echo(
                f"{p.value:>8.4g}  {p.omega:>8.4g}  {p.source:>14}  {p.orbit.max_multiplier:>10.6g}  {'yes' if p.orbit.stable else 'no':>6}  "
                f"{loc.participation_ratio:>6.3g}  {loc.length:>6.3g}  {amp['phi']:>7.3g}  {amp['u_over_h']:>7.3g}  {amp['v_over_h']:>7.3g}  "
                f"{'yes' if loc.localized else 'no'}" + lifetime_text(p)
            )
    edges = result.band_edges()
    for j, value in enumerate(result.values):
        listed = ", ".join(f"{band} {lo:.4g}-{hi:.4g}" for band, (lo, hi) in zip(result.bands, edges[j]))
        typer.echo(f"bands at {name} = {value:g}: {listed}")
    changes_text(result)


def _damped_to_undamped(
    model: str, moment: float, gamma: float | None, *, turns: int, particle: int, config: Path | None, as_json: bool
) -> None:
    """``breathers --from-moment``: the damped, driven orbit followed to zero damping at its mean rate."""
    from ..experiments.breathers import damped_to_undamped
    from ..numerics.periodic import OrbitError, find_periodic_orbit

    params = params_or_exit(config)
    if gamma is not None:
        params = params.replace(gamma_u=gamma, gamma_v=gamma, gamma_phi=gamma)
    if params.gamma_phi <= 0:
        fail(f"--from-moment needs a damped chain (gamma_phi > 0) to start from, got gamma_phi={params.gamma_phi!r}: give --gamma")
    try:
        orbit = find_periodic_orbit(params, model, moment, turns=turns, particle=particle)
        result = damped_to_undamped(orbit)
    except ValueError as err:
        fail(str(err))
    except OrbitError as err:
        fail(str(err), code=3)
    summary = result.as_dict()
    if as_json:
        typer.echo(json.dumps({"params": params.model_dump(), "model": model, "moment": moment, "orbit": orbit.as_dict(), **summary}))
        return
    typer.echo(
        f"{model}: the rotating orbit at M = {moment:g} (gamma_phi = {params.gamma_phi:g}), Omega = {abs(orbit.mean_angular_velocity):.8g}"
    )
    typer.echo(f"homotopy: {summary['path'].get('message') or 'reached gamma = 0'}")
    typer.echo(result.message)
