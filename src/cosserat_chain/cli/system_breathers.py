"""``cosserat-chain breathers --system REF``: roto-breather families and atlases of a user's system; the atlases' ``FIELD=V1,V2,...`` parser."""

from __future__ import annotations

import math
from pathlib import Path

import typer

from .common import bar_callback, fail, outputs_or_exit, progress_bar, save_dataset, save_figure
from .systems import _echo_json, system_or_exit


def atlas_values(text: str, fields: tuple[str, ...] | None = None) -> tuple[str, list[float]]:
    """FIELD and its values from ``FIELD=V1,V2,...`` (FIELD among ``fields``, default the chain's); exit 2 naming what is wrong."""
    from ..experiments.breather_atlas import ATLAS_FIELDS

    fields = ATLAS_FIELDS if fields is None else fields
    name, sep, listed = text.partition("=")
    name = name.strip()
    if not sep or name not in fields:
        fail(f"--atlas must be FIELD=V1,V2,... with FIELD one of {', '.join(fields)}, got {text!r}")
    try:
        values = [float(item) for item in listed.split(",") if item.strip()]
    except ValueError:
        fail(f"--atlas {name}: the values must be numbers separated by commas, got {listed!r}")
    if not values or not all(math.isfinite(v) for v in values):
        fail(f"--atlas {name}: give one or more finite values separated by commas, got {listed!r}")
    return name, values


def _angle_or_exit(system, offset: int | None, option: str) -> int | None:
    """The system's angle ``offset`` places from its central one (None for None); exit 2 if it is off the system."""
    import numpy as np

    if offset is None:
        return None
    angles = np.flatnonzero(system.angles)
    index = angles.size // 2 + offset
    if not 0 <= index < angles.size:
        fail(
            f"{option} {offset} is off the system: its {angles.size} angles count from {-(angles.size // 2)} "
            f"to {angles.size - 1 - angles.size // 2} about the central one"
        )
    return int(angles[index])


def atlas_lifetimes(atlas, max_periods: int) -> None:
    """With ``max_periods`` > 0: every orbit of the atlas run from its perturbed velocities (``measure_lifetimes``), with a bar."""
    if max_periods:
        bar = progress_bar("lifetimes", "orbit")
        atlas.measure_lifetimes(max_periods, progress=bar_callback(bar))
        bar.finish()


def locate_tol_or_exit(tol: float | None) -> float:
    """The atlas's locate tolerance (its default for None); exit 2 naming ``--locate-tol`` where it is refused."""
    from ..experiments.breather_atlas import LOCATE_TOL, check_locate_tol

    try:
        return check_locate_tol(LOCATE_TOL if tol is None else tol)
    except ValueError as err:
        fail(f"--locate-tol: {err}")


def locate_along_or_exit(text: str | None, field: str) -> tuple[str, ...] | None:
    """The axes ``--locate-along`` names, comma-separated (None: both); exit 2 naming the option for anything but omega and
    the atlas's ``field``."""
    from ..experiments.breather_atlas import check_along

    if text is None:
        return None
    try:
        return check_along([item.strip() for item in text.split(",")], field)
    except ValueError:
        fail(f"--locate-along must name omega, {field} or both as omega,{field} (the atlas's axes), got {text!r}")


def atlas_changes(atlas, locate: bool, tol: float, every: bool = False, along: tuple[str, ...] | None = None) -> None:
    """With ``locate``: the atlas's changes of stability between neighbours located to ``tol`` (``locate_changes``, with
    ``every``, along the axes ``along``), with a bar that counts the pairs of neighbours to locate between."""
    if locate:
        bar = progress_bar("changes", "pair")
        atlas.locate_changes(tol, progress=bar_callback(bar), every=every, along=along)
        bar.finish(note=f"{len(atlas.changes)} located")


def changes_text(atlas) -> None:
    """The located changes of an atlas, one a line (nothing where they were not located)."""
    if atlas.changes is None:
        return
    along = " and ".join(atlas.settings["locate"]["along"])
    typer.echo(f"changes of stability located along {along} to {atlas.settings['locate']['tol']:g}: {len(atlas.changes)}")
    for c in atlas.changes:
        if c.axis == "omega":
            where = f"{atlas.field} = {c.value:g}: Omega = {c.change.omega:.10g} +- {c.accuracy:.2g}"
        else:
            where = f"Omega = {c.omega:g}: {atlas.field} = {c.value:.10g} +- {c.accuracy:.2g}"
        typer.echo(f"  {where} ({c.placed_by}), pair at {c.change.kind}, stable side {c.change.stable_omega:.8g}")
    for pair in atlas.settings["locate"]["not_one_family"]:
        j, i = pair["row"], pair["column"]
        pairs = f"{atlas.field} = {atlas.values[j]:g}, {atlas.values[j + 1]:g} at Omega = {atlas.omegas[i]:g}"
        typer.echo(f"  not located between {pairs}: not of one family")


def lifetime_text(point) -> str:
    """A point's lifetime for the text tables ('' where none was measured)."""
    life = point.lifetime
    if life is None:
        return ""
    return f"  lifetime {'> ' + str(life.run_periods) if life.periods is None else life.periods} periods"


def atlas_on_system(
    reference: str,
    text: str,
    *,
    config: Path | None,
    sets: list[str] | None,
    omegas: list[float],
    turns: int,
    particle: int,
    partner: int | None,
    counter: bool,
    coupling: str,
    out: Path | None,
    plot: Path | None,
    as_json: bool,
    lifetimes: int = 0,
    locate: bool = True,
    locate_tol: float | None = None,
    locate_every: bool = False,
    locate_along: str | None = None,
) -> None:
    """``breathers --system REF --atlas NAME=V1,V2,...``: the existence map over (Omega, a parameter of the system).

    ``text`` names one of the system's parameters and its values; ``particle`` and ``partner``
    count its angles from the central one; ``lifetimes`` > 0 runs every orbit found from its
    perturbed velocities for that many periods (:func:`atlas_lifetimes`); ``locate`` locates the
    changes of stability between neighbours to ``locate_tol`` (every one with ``locate_every``) along the
    axes ``locate_along`` names (:func:`atlas_changes`). The outputs
    are checked (and locked) before anything is computed. Exit 2 on bad input.
    """
    import numpy as np

    from ..experiments.system_breather_atlas import system_breather_atlas
    from ..experiments.system_breathers import BreatherError
    from ..systems import SystemDefinitionError

    tol = locate_tol_or_exit(locate_tol)
    outputs_or_exit({"--out": out, "--plot": plot}, {"--config": config})
    system = system_or_exit(reference, config, sets)
    if not np.flatnonzero(system.angles).size:
        fail(f"--system {reference}: {system.name} has no angle coordinate: nothing can turn")
    name, values = atlas_values(text, tuple(system.parameters))
    axes = locate_along_or_exit(locate_along, name)
    rotor = _angle_or_exit(system, particle, "--particle")
    other = _angle_or_exit(system, partner, "--partner")
    if other == rotor:
        fail(f"--partner {partner} is the rotating one (--particle {particle}): give a neighbour, e.g. --partner {particle + 1}")
    bar = progress_bar(f"atlas {system.name} {name}", "orbit")
    try:
        atlas = system_breather_atlas(
            system, omegas, name, values, rotor=rotor, partner=other, counter=counter, turns=turns, coupling=coupling,
            progress=bar_callback(bar),
        )  # fmt: skip
    except (BreatherError, SystemDefinitionError) as err:
        bar.close()
        fail(str(err))
    found = int(atlas.grid("exists").sum())
    bar.finish(note=f"{found} of {len(omegas) * len(values)} found")
    atlas_changes(atlas, locate, tol, locate_every, axes)
    atlas_lifetimes(atlas, lifetimes)
    if out is not None:
        save_dataset(atlas.to_dataset(reference), out)
    if plot is not None:
        from ..plots.breathers import system_atlas_figure

        save_figure(system_atlas_figure(atlas), plot)
    if as_json:
        _echo_json({"reference": reference, **atlas.as_dict()})
        return
    rotors = ", ".join(f"{system.coordinates[i]} ({k:+d} turns)" for i, k in atlas.rotors.items())
    typer.echo(f"{system.name}: roto-breathers of {rotors} over Omega and {name}: {found} of {len(omegas) * len(values)} found")
    typer.echo(f"{name:>8}  {'omega':>8}  {'from':>14}  {'energy':>12}  {'max |mu|':>10}  stable  {'PR':>6}  {'xi':>6}  {'max |q|':>8}")
    for row in atlas.points:
        for p in row:
            if p.orbit is None:
                typer.echo(f"{p.value:>8.4g}  {p.omega:>8.4g}  {'not found':>14}")
                continue
            loc, energy = p.localization, p.as_dict()["energy"]
            typer.echo(
                f"{p.value:>8.4g}  {p.omega:>8.4g}  {p.source:>14}  {'-' if energy is None else f'{energy:.8g}':>12}  "
                f"{p.orbit.max_multiplier:>10.6g}  {'yes' if p.orbit.stable else 'no':>6}  {loc.participation_ratio:>6.3g}  "
                f"{loc.length:>6.3g}  {loc.amplitude:>8.3g}" + lifetime_text(p)
            )
    for value, bands in zip(atlas.values, atlas.bands(), strict=True):
        typer.echo(f"bands at {name} = {value:g}: " + ", ".join(f"[{b:.6g}, {t:.6g}]" for b, t in bands))
    changes_text(atlas)


def breathers_on_system(
    reference: str,
    *,
    config: Path | None,
    sets: list[str] | None,
    omega: float,
    to: float | None,
    turns: int,
    particle: int,
    partner: int | None,
    counter: bool,
    coupling: str,
    out: Path | None,
    as_json: bool,
    lifetimes: int = 0,
    arclength: bool = False,
    along: str | None = None,
    branches: bool = False,
) -> None:
    """The family from the anti-continuum limit at ``omega``, continued in ``coupling`` to the system's value, then to ``to``.

    With ``arclength`` the family is followed by pseudo-arclength (to ``to``, or at the fixed
    frequency ``omega`` in the parameter of ``along``, ``NAME=VALUE``), its folds, branch points and
    changes of stability listed as events; ``branches`` follows the family crossing each branch point.

    ``lifetimes`` > 0 runs every member from its perturbed orbit for that many periods
    (:meth:`SystemBreatherFamily.measure_lifetimes`).

    ``particle`` and ``partner`` count the system's angles from the central one (as the chain's
    particles count from its centre). ``out`` is checked (and locked) before anything is computed and
    written atomically at the end (:meth:`SystemBreatherFamily.to_dataset`). Exit 2 on bad input, 3
    when no orbit is found.
    """
    import numpy as np

    from ..experiments.system_breathers import BreatherError, roto_breather_family
    from ..numerics.shooting import OrbitNotFound
    from ..systems import SystemDefinitionError

    if counter and partner is None:
        fail("--counter sets the partner's direction: give --partner as well")
    outputs_or_exit({"--out": out}, {"--config": config})
    system = system_or_exit(reference, config, sets)
    if not np.flatnonzero(system.angles).size:
        fail(f"--system {reference}: {system.name} has no angle coordinate: nothing can turn")
    rotor = _angle_or_exit(system, particle, "--particle")
    other = _angle_or_exit(system, partner, "--partner")
    if other == rotor:
        fail(f"--partner {partner} is the rotating one (--particle {particle}): give a neighbour, e.g. --partner {particle + 1}")
    target = None if along is None else _along_or_exit(system, along)
    bar = progress_bar(f"breathers {system.name}", "orbit")
    try:
        family = roto_breather_family(
            system, omega, to=to, rotor=rotor, partner=other, counter=counter, turns=turns, coupling=coupling,
            arclength=arclength, along=target, branches=branches, progress=bar_callback(bar),
        )  # fmt: skip
    except (BreatherError, SystemDefinitionError) as err:
        bar.close()
        fail(str(err))
    except OrbitNotFound as err:
        bar.close()
        fail(str(err), code=3)
    bar.finish()
    if lifetimes:
        bar = progress_bar("lifetimes", "orbit")
        family.measure_lifetimes(lifetimes, progress=bar_callback(bar))
        bar.finish()
    if out is not None:  # the Dataset (and xarray) only for a file
        save_dataset(family.to_dataset(reference), out)
    summary = family.as_dict()
    if as_json:
        _echo_json({"reference": reference, **summary})
        return
    names = ", ".join(f"{name} ({k:+d} turns)" for name, k in summary["rotors"].items())
    if family.settings.get("arclength"):
        return _arclength_text(family, summary, names)
    typer.echo(f"{system.name}, {coupling} = {summary['coupling_value']:g}: {len(family.orbits)} roto-breathers of {names}")
    typer.echo("bands: " + ", ".join(f"[{b:.6g}, {t:.6g}]" for b, t in family.bands))
    typer.echo(f"{'omega':>10}  {'energy':>14}  {'max |mu|':>10}  stable  harmonics in a band")
    for i, o in enumerate(family.orbits):
        energy = "-" if summary["energy"][i] is None else f"{summary['energy'][i]:.10g}"
        inside = ", ".join(f"{h['harmonic']}x in band {h['band']}" for h in summary["harmonics_in_bands"][i]) or "none"
        typer.echo(f"{summary['omega'][i]:>10.6g}  {energy:>14}  {o.max_multiplier:>10.6g}  {'yes' if o.stable else 'no':>6}  {inside}")
        if family.lifetimes is not None:
            life = family.lifetimes[i].periods
            typer.echo(f"{'':>10}  lifetime: {'beyond ' + str(lifetimes) if life is None else life} periods")
    for change in family.changes:
        r = change.resonance
        typer.echo(
            f"stability {'lost' if change.unstable_omega < change.stable_omega else 'regained'} going down at Omega = {change.omega:.12g} "
            f"{'(accuracy unknown: ' + change.method + ')' if change.accuracy is None else f'+- {change.accuracy:.2g}'} "
            f"(a multiplier leaves the circle at {change.kind}); nearest resonance: {r.harmonic:g} x Omega = {r.edge_frequency:.6g} "
            f"(band {r.band} {r.edge}) at Omega = {r.omega:.6g}"
        )
    _event_lines(summary, "omega")
    for omega in summary["energy_extrema"]:
        typer.echo(f"energy extremal at Omega = {omega:.6g} (dE/dOmega = 0: where a pair of multipliers passes +1)")
    typer.echo(f"family end: {family.message}")


def _along_or_exit(system, text: str) -> tuple[str, float]:
    """NAME and VALUE of ``--along NAME=VALUE`` (NAME a parameter of the system); exit 2 naming what is wrong."""
    name, sep, value = text.partition("=")
    name = name.strip()
    if not sep or name not in system.parameters:
        fail(f"--along must be NAME=VALUE with NAME a parameter of {system.name} ({', '.join(system.parameters)}), got {text!r}")
    try:
        number = float(value)
    except ValueError:
        fail(f"--along {name}: VALUE must be a number, got {value!r}")
    if not math.isfinite(number) or number == system.parameter(name):
        fail(f"--along {name}: VALUE must be finite and differ from {name} = {system.parameter(name):g}, got {value!r}")
    return name, number


def _arclength_text(family, summary: dict, names: str) -> None:
    """The text table of a family traced by pseudo-arclength, its events after it."""
    system, parameter = family.system, family.parameter
    fixed = "" if parameter == "omega" else f" at Omega = {summary['omega'][0]:.8g}"
    typer.echo(f"{system.name}: {len(family.orbits)} roto-breathers of {names} by arclength in {parameter}{fixed}")
    first = parameter if parameter != "omega" else ""  # in Omega the value column is Omega itself
    typer.echo(f"{first:>12}  {'omega':>10}  {'energy':>14}  {'max |mu|':>10}  stable")
    for i, o in enumerate(family.orbits):
        energy = "-" if summary["energy"][i] is None else f"{summary['energy'][i]:.10g}"
        value = "" if not first else f"{summary['values'][i]:.8g}"
        typer.echo(f"{value:>12}  {summary['omega'][i]:>10.8g}  {energy:>14}  {o.max_multiplier:>10.6g}  {'yes' if o.stable else 'no':>6}")
        if family.lifetimes is not None:
            life = family.lifetimes[i]
            typer.echo(f"{'':>12}  lifetime: {'beyond ' + str(life.run_periods) if life.periods is None else life.periods} periods")
    _event_lines(summary, parameter)
    typer.echo(f"family end: {family.message}")


def _event_lines(summary: dict, parameter: str) -> None:
    """A line per located event of the family (fold, branch point, stability), with the branch followed from it."""
    for e in summary.get("events", []):
        accuracy = "" if e["accuracy"] is None else f" +- {e['accuracy']:.2g}"
        typer.echo(
            f"{e['kind'].replace('_', ' ')} at {parameter} = {e['value']:.10g}{accuracy}: energy {e['energy']}, max |mu| "
            f"{e['max_multiplier']:.6g}, fixed-{parameter} Newton system's singular value {e['singular_value']:.2g}, "
            f"pair at +1 split {e['split_before']} -> {e['split_after']}"
        )
        if "discriminant_value" in e:
            typer.echo(
                f"  its pair through +1 by the discriminant: {parameter} = {e['discriminant_value']:.12g} +- {e['discriminant_accuracy']:.2g}"
            )
        if "branch" in e:
            b = e["branch"]
            if b["values"]:
                typer.echo(
                    f"  branch: {len(b['values'])} orbits, {parameter} {b['values'][0]:.8g} to {b['values'][-1]:.8g}, "
                    f"max |mu| {b['max_multiplier'][0]:.4g} to {b['max_multiplier'][-1]:.4g}; {b['message']}"
                )
            else:
                typer.echo(f"  branch: none ({b['message']})")
