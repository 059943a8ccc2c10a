"""``cosserat-chain theory``: the continuum theory of Section 3 against the discrete chain, and the errata."""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

import typer

from .common import app, compliance_or_exit, fail, outputs_or_exit, params_or_exit, save_dataset, save_figure, stiff_at_rest_or_exit


def parse_n_list(text: str) -> list[int]:
    """``"3,10,100"`` -> [3, 10, 100]; exits with an error naming the option for anything else."""
    try:
        values = [int(item) for item in text.split(",") if item.strip()]
    except ValueError:
        values = []
    if not values or any(n < 1 for n in values):
        fail(f"--n-list must be comma-separated integers N >= 1 (e.g. 3,10,100), got {text!r}")
    return values


@app.command()
def theory(
    config: Path | None = typer.Option(
        None, help="TOML file with ChainParams fields (E1, E2, h, a, b, m, j, gamma_u, gamma_v, gamma_phi, N, left_end, right_end)."
    ),
    n_list: str = typer.Option("3,10,100", "--n-list", help="Chain half-lengths N to compare (2N+1 particles), comma-separated."),
    at: float = typer.Option(
        0.0,
        "--at",
        help="Position x0/L of the loaded particle in [-1, 1] (0: the centre, 1: the right end); at N must be an integer for every N.",
    ),
    load: str = typer.Option("moment", "--load", help="Load on that particle: 'moment' (compliance phi/M) or 'force' (transverse, v/F)."),
    bend_angle: float | None = typer.Option(
        None,
        "--bend-angle",
        help="Also bend the chain's cantilever (clamped left, free right) by an end moment until its free end turns by this angle "
        "(rad, in (0, 2 pi]; 6.2832 closes it into a ring): model (i) against the geometrically exact beam's circle.",
    ),
    elastica: float | None = typer.Option(
        None,
        "--elastica",
        help="Also load the chain's cantilever with a transverse dead force F = ELASTICA EI / (2L)^2 at its free end (2: about "
        "45 degrees): model (i) against the exact beam's elastica.",
    ),
    front: bool = typer.Option(
        False,
        "--front",
        help="Also turn particles fully with the centres held: model (i)'s bond potential (Fourier content), the quasi-continuum's "
        "2 pi front against the discrete lattice's, and the barrier of one particle turning once.",
    ),
    frequencies: int | None = typer.Option(
        None,
        "--frequencies",
        help="Also compare this many of the finite chain's lowest flexural and axial frequencies, with its ends, against its Timoshenko "
        "beam's (order 2) and eq. (6)'s, per N.",
    ),
    as_json: bool = typer.Option(False, "--json", help="Print the result as one JSON object."),
    plot: Path | None = typer.Option(None, "--plot", help="Write the errors of the continua against N to this PNG or SVG file."),
    out: Path | None = typer.Option(None, "--out", help="Write the tables to this NetCDF file (variables over N)."),
) -> None:
    """The chain's continua against the discrete linear chain per N: the Timoshenko beam (order 2), eq. (11) (order 1), and the errata.

    Eq. (11) is the paper's (both ends clamped, a moment on particle 0); the Timoshenko beam
    takes any ends that hold the chain and any loaded particle.
    """

    from ..analysis.continuum import convergence, printed_D1
    from ..analysis.symbolic import errata
    from ..analysis.timoshenko import LOADS, beam_stiffness, loaded_particle
    from ..analysis.timoshenko import convergence as beam_convergence
    from ..memory import MemoryEstimateError

    outputs_or_exit({"--plot": plot, "--out": out}, {"--config": config})
    params = params_or_exit(config)
    if params.graded:
        fail(
            "--config: theory compares the uniform chain at each N of --n-list with its continua; a graded chain's factors "
            "(E1_factors, E2_factors, m_factors, j_factors) fix its N: leave them out"
        )
    n_values = parse_n_list(n_list)
    if load not in LOADS:
        fail(f"--load must be one of {', '.join(LOADS)}, got {load!r}")
    try:
        for n in n_values:
            loaded_particle(n, at)
    except ValueError as err:
        fail(f"--at {at!r}: {err}")
    paper_applies = params.clamped and at == 0.0 and load == "moment"
    try:
        beam = beam_convergence(params, n_values, at=at, load=load)
        stiffness = beam_stiffness(params)
        table = convergence(params, n_values) if paper_applies else None
    except (ValueError, ArithmeticError) as err:
        if not isinstance(err, MemoryEstimateError):
            stiff_at_rest_or_exit(params.replace(N=min(n_values)))
        fail(str(err))
    for n, value in zip(beam.N, beam.discrete):
        # K's square root solves a K singular to round-off (E1 = 1e-100) without an error: its compliance says so.
        compliance_or_exit(params.replace(N=int(n)), value)
    bending = None
    if bend_angle is not None:
        from ..analysis.exact_beam import bending_convergence

        if not (math.isfinite(bend_angle) and 0 < bend_angle <= 2 * math.pi):
            fail(f"--bend-angle must lie in (0, 2 pi] (rad), got {bend_angle!r}")
        try:
            bending = bending_convergence(params.replace(left_end="clamped", right_end="free"), n_values, angle=bend_angle)
        except (ValueError, ArithmeticError) as err:
            fail(f"--bend-angle {bend_angle!r}: {err}")
    large_force = None
    if elastica is not None:
        from ..analysis.exact_beam import elastica_convergence

        if not (math.isfinite(elastica) and elastica > 0):
            fail(f"--elastica must be a finite number > 0 (F (2L)^2 / EI), got {elastica!r}")
        try:
            large_force = elastica_convergence(params.replace(left_end="clamped", right_end="free"), n_values, load=elastica)
        except (ValueError, ArithmeticError) as err:
            fail(f"--elastica {elastica!r}: {err}")
    modes = None
    if frequencies is not None:
        from ..analysis.beam_frequencies import FAMILIES, frequency_convergence

        if frequencies < 1:
            fail(f"--frequencies must be an integer >= 1 (modes per family), got {frequencies!r}")
        try:
            modes = {family: frequency_convergence(params, n_values, count=frequencies, family=family) for family in FAMILIES}
        except ValueError as err:
            fail(f"--frequencies {frequencies!r}: {err}")
    waves = _long_waves(params)
    rotation = _rotation(params) if front else None
    if out is not None:
        dataset = beam.to_dataset(params)
        if bending is not None:
            extra = bending.to_dataset()
            dataset = dataset.merge(extra)
            dataset.attrs.update(extra.attrs)  # merge keeps the first dataset's attributes only
        save_dataset(dataset, out)
    if plot is not None:
        from ..plots.theory import plot_continua  # matplotlib only when plotting

        save_figure(plot_continua(beam, bending), plot)
    # The errata are about the paper's chain: a chain with other ends gets them for its clamped twin.
    paper_chain = params if params.clamped else params.replace(left_end="clamped", right_end="clamped")
    listed = errata(paper_chain)
    order = None
    if table is not None:
        accurate = table.accurate
        order = table.order() if len(set(table.N[accurate])) >= 2 and all(table.relative_error[accurate] > 0) else None
    if as_json:
        summary = _summary(params, table, order, listed)
        summary["timoshenko"] = {**stiffness.as_dict(), **beam.as_dict(), "at": at, "waves": waves}
        summary["exact_beam"] = None if bending is None else bending.as_dict()
        summary["rotation"] = rotation
        summary["frequencies"] = None if modes is None else {family: table.as_dict() for family, table in modes.items()}
        summary["elastica"] = None if large_force is None else large_force.as_dict()
        summary.update({"plot": str(plot) if plot else None, "out": str(out) if out else None})
        typer.echo(json.dumps(summary))
        return
    typer.echo(f"D1 = {params.D1:.6g} (derived; printed in Section 3: {printed_D1(params):.6g}), D2 = {params.D2:.6g}")
    if table is not None:
        _print_paper(table, order)
    else:
        typer.echo(
            f"eq. (11) is the paper's chain only (both ends clamped, a moment on particle 0); this one has {params.describe_ends()}, --at {at:g}, --load {load}"
        )
    _print_beam(params, stiffness, beam, waves)
    if bending is not None:
        _print_bending(bending)
    if large_force is not None:
        _print_elastica(large_force)
    if modes is not None:
        _print_frequencies(params, modes)
    if rotation is not None:
        _print_rotation(rotation)
    typer.echo(
        f"\nerrata of the paper (docs/errata.md), evaluated for N = {params.N}{'' if params.clamped else ' with both ends clamped'}:"
    )
    for item in listed:
        typer.echo(f"  {item.number}. {item.where}: printed {item.printed}; derived {item.derived}.\n     {item.consequence}")
    for path in (plot, out):
        if path is not None:
            typer.echo(f"wrote {path}")


def _print_paper(table, order: float | None) -> None:
    import numpy as np

    typer.echo(f"{'N':>8}  {'continuum phi0/M':>17}  {'discrete phi0/M':>16}  {'(c - d) / d':>11}  {'residue (12)':>12}")
    for n, c, d, e, r, ok in zip(table.N, table.continuum, table.discrete, table.signed_error, table.residue, table.accurate):
        typer.echo(f"{n:>8d}  {c:>17.8g}  {d:>16.8g}  {e:>+11.3e}  {r:>12.3e}" + ("" if ok else "  (inaccurate)"))
    if np.any(np.diff(np.sign(table.signed_error[table.N > 1])) != 0):
        typer.echo("the continuum's error changes sign along this list: its 1/N fall holds only past the last change")
    for n, error, condition in zip(table.N[~table.accurate], table.discrete_error[~table.accurate], table.condition[~table.accurate]):
        typer.echo(
            f"N = {n}: the discrete value is inaccurate: it is {error:.1e} (relative) off the chain's closed form, the clamped Timoshenko "
            f"beam with the nodal shear compliance (K's condition number {condition:.1e}, about N^4: the clamped chain's softest mode), "
            "so its error is not the continuum's"
        )
    if order is not None:
        typer.echo(f"observed order of the relative error: N^-{order:.3f}")


def _print_beam(params, stiffness, beam, waves: dict[str, Any]) -> None:
    typer.echo(
        f"\nTimoshenko beam of the chain (bond-centred shear): EI = 2 E1 b^2 h = {stiffness.EI:.6g}, GA = k_v h = {stiffness.GA:.6g}, "
        f"EA = k_u h = {stiffness.EA:.6g}\n  the chain is, at its particles, the beam with shear compliance 1/GA - h^2/(12 EI) = "
        f"{stiffness.nodal_shear_compliance:.6g} (1/GA = {stiffness.shear_compliance:.6g}); shear length sqrt(EI/GA) = "
        f"{stiffness.shear_length:.4g} (the errors fall like 1/N^2 and 1/N once N h is well past it)"
    )
    what = "phi/M" if beam.load == "moment" else "v/F"
    typer.echo(
        f"{'N':>8}  {'particle':>8}  {'discrete ' + what:>16}  {'Timoshenko':>16}  {'(T - d) / d':>11}  {'eq. (11)':>16}  {'(11 - d) / d':>12}  {'discrete error':>14}"
    )
    for n, k, d, t, et, p, ep, de in zip(
        beam.N, beam.particle, beam.discrete, beam.timoshenko, beam.timoshenko_error, beam.paper, beam.paper_error, beam.discrete_error
    ):
        paper = f"{p:>16.10g}  {ep:>+12.3e}" if p == p else f"{'n/a':>16}  {'n/a':>12}"
        typer.echo(f"{n:>8d}  {k:>8d}  {d:>16.10g}  {t:>16.10g}  {et:>+11.3e}  {paper}  {de:>14.1e}")
    for which, label in (("timoshenko", "Timoshenko"), ("paper", "eq. (11)")):
        order = beam.order(which)
        if order is not None:
            typer.echo(f"measured order of {label}'s error: N^-{order:.3f}")
        elif which == "timoshenko":
            typer.echo(f"{label}'s error is not above the discrete value's own at two N (it is exact where shear takes no part)")
    typer.echo(
        f"long waves (q = {waves['q']:g} per particle): the Timoshenko branches are within {max(waves['timoshenko_error']):.1e} of the chain's "
        f"(order q^2); eq. (6)'s acoustic omega^2 is {waves['paper_acoustic_ratio']:.4g} times the chain's (D1/E1: its bending is D1, the chain's E1)"
    )


def _print_bending(bending) -> None:
    typer.echo(
        f"\nlarge bending: model (i)'s cantilever, its free end turned by {bending.angle:.6g} rad by an end moment, against the "
        "geometrically exact beam's circle (curvature M/EI)"
    )
    typer.echo(f"{'N':>8}  {'chain M':>14}  {'beam M':>14}  {'(b - c) / c':>11}  {'tip error / 2L':>14}  {'whole chain vs bond':>19}")
    for n, c, b, e, t, spread in zip(
        bending.N, bending.chain_moment, bending.beam_moment, bending.moment_error, bending.tip_error, bending.direct_spread
    ):
        typer.echo(f"{n:>8d}  {c:>14.8g}  {b:>14.8g}  {e:>+11.3e}  {t:>14.3e}  {spread:>19.1e}")
    for which in ("moment", "tip"):
        order = bending.order(which)
        typer.echo(f"measured order of the {which} error: " + (f"N^-{order:.3f}" if order is not None else "none (zero to round-off)"))


def _print_elastica(table) -> None:
    typer.echo(
        f"\nelastica: model (i)'s cantilever under a transverse dead force F (2L)^2 / EI = {table.load:g} at its free end, against the "
        "exact beam (solve_bvp)"
    )
    typer.echo(f"{'N':>8}  {'chain tip angle':>15}  {'beam tip angle':>14}  {'(b - c) / c':>11}  {'tip error / 2L':>14}")
    for n, c, b, e, t in zip(table.N, table.chain_angle, table.beam_angle, table.angle_error, table.tip_error):
        typer.echo(f"{n:>8d}  {c:>15.8g}  {b:>14.8g}  {e:>+11.3e}  {t:>14.3e}")
    for which in ("angle", "tip"):
        order = table.order(which)
        typer.echo(f"measured order of the {which} error: " + (f"N^-{order:.3f}" if order is not None else "none"))


def _print_frequencies(params, modes) -> None:
    typer.echo(
        f"\nfirst natural frequencies (rad per unit time), {params.describe_ends()}: the discrete linear chain against its Timoshenko "
        "beam (T) and eq. (6) (the same beam with bending 2 b^2 D1 h; none where D1 <= 0)"
    )
    for family, table in modes.items():
        typer.echo(f"{family}:")
        typer.echo(f"{'N':>8}  {'mode':>4}  {'chain':>16}  {'(T - d) / d':>11}  {'(6 - d) / d':>11}")
        for row, n in enumerate(table.N):
            for mode in range(table.chain.shape[1]):
                paper = table.paper_error[row, mode]
                paper_text = f"{paper:>+11.3e}" if paper == paper else f"{'none':>11}"
                typer.echo(
                    f"{n:>8d}  {mode + 1:>4d}  {table.chain[row, mode]:>16.10g}  {table.timoshenko_error[row, mode]:>+11.3e}  {paper_text}"
                )
        for label, which in (("Timoshenko", "timoshenko"), ("eq. (6)", "paper")):
            orders = ", ".join("n/a" if order is None else f"{order:.3f}" for order in table.orders(which))
            typer.echo(f"  measured orders of {label}'s errors, mode by mode: {orders}")


#: Half-length of the chain in which ``--front`` frees the centres (its energy depends on it: no intrinsic front).
FREE_HALF_LENGTH = 20


def _rotation(params) -> dict[str, Any]:
    """The held lattice's numbers (:mod:`cosserat_chain.analysis.rotation_front`), as plain data."""
    from ..analysis.rotation_front import discrete_front, fourier_content, free_front, quasi_continuum, turn_barrier

    qc = quasi_continuum(params)
    half_length = int(min(max(30, 6 * (qc.tail if qc.tail == qc.tail else 0)), 200))
    return {
        "fourier": [{"m": m, "n": n, "amplitude": c} for m, n, c in fourier_content(params, count=6)],
        "quasi_continuum": qc.as_dict(),
        "discrete_front": {**discrete_front(params, half_length=half_length).as_dict(), "half_length": half_length},
        "barrier": {**turn_barrier(params, half_length=min(half_length, 30), points=32).as_dict(), "half_length": min(half_length, 30)},
        "free_front": {**free_front(params, half_length=FREE_HALF_LENGTH).as_dict(), "half_length": FREE_HALF_LENGTH},
    }


def _print_rotation(rotation: dict[str, Any]) -> None:
    qc, front, barrier = rotation["quasi_continuum"], rotation["discrete_front"], rotation["barrier"]
    terms = ", ".join(f"({t['m']},{t['n']}) {t['amplitude']:.4g}" for t in rotation["fourier"])
    typer.echo(
        f"\nfull rotation, centres held: bond potential V(phi_k, phi_k+1) of model (i); largest Fourier terms (m,n) amplitude: {terms}"
    )

    def number(value: float | None, fmt: str) -> str:
        return "none" if value is None else format(value, fmt)

    typer.echo(
        f"  quasi-continuum 2 pi front: energy {number(qc['front_energy'], '.6g')}, width {number(qc['width'], '.3g')} particles, "
        f"tails {number(qc['tail'], '.3g')} particles" + ("" if qc["front_energy"] is not None else " (kappa < 0 at some angle: no front)")
    )
    if front["smooth"]:
        typer.echo(
            f"  discrete front: energy {front['energy']:.6g}, width {front['width']:.3g} particles, Peierls barrier {front['peierls_barrier']:.3g}"
        )
    else:
        typer.echo(
            "  discrete front: none; it slips into one bond (neighbours 2 pi apart, no energy) or one particle half-turned "
            f"(energy {front['energy_site']:.6g}): a localized rotation no smooth continuum describes"
        )
    typer.echo(
        f"  barrier of one particle turning once: {barrier['fixed']:.6g} past fixed neighbours; with the others relaxing at least "
        f"{barrier['relaxed']:.6g} (top of the rotation-controlled path)"
        + (
            f" and at most {barrier['saddle']:.6g}, the first-order saddle (one negative Hessian eigenvalue, gradient "
            f"{barrier['saddle_gradient']:.1e}) whose descents end at rest and at the particle turned once"
            if barrier["saddle"] is not None
            else "; no first-order saddle of the turn found from that path (wide fronts: it runs into metastable states)"
        )
    )
    if barrier["barrier"] is not None:
        best = min(barrier["paths"], key=lambda path: path["barrier"])
        typer.echo(
            f"  the turn's minimum energy path (climbing string of {best['images']} images from the {best['start']} path): barrier "
            f"{barrier['barrier']:.6g}, its highest first-order saddle (gradient {best['saddle_gradient']:.1e}), "
            f"{len(best['minima']) - 2} metastable minima on the way"
        )
    if qc["front_energy"] is not None:
        typer.echo(
            f"  the quasi-continuum's barrier: {qc['front_energy']:.6g} (a smooth field cannot slip past its neighbours: turned by pi, "
            "the particle carries two half fronts, the energy of one 2 pi front)"
        )
    free = rotation["free_front"]
    if free["smooth"]:
        typer.echo(
            f"  with the centres free (model (i), 2 x {free['half_length']} + 1 particles, ends clamped): energy {free['energy']:.6g} "
            f"against the held front's {free['held_energy']:.6g}, centres moved by up to {free['displacement']:.3g} h; the energy "
            "falls with the chain's length (docs/which-continuum.md): no intrinsic front"
        )
    for other in barrier["other_saddles"]:
        typer.echo(
            f"  another first-order saddle: energy {other['energy']:.6g}, between minima with the particle at "
            f"{other['descent_angle_0']:.4g} and {other['descent_angle_1']:.4g} rad (the higher one {other['descent_energy']:.4g})"
        )


def _long_waves(params) -> dict[str, Any]:
    """The continua's branches against the chain's at one long wave, q = 0.05 per particle."""
    from ..analysis.dispersion import continuum_dispersion, dispersion
    from ..analysis.timoshenko import timoshenko_dispersion

    q = 0.05
    chain, beam = dispersion(params, q).omega2[:, 0], timoshenko_dispersion(params, q).omega2[:, 0]
    paper = continuum_dispersion(params, q).omega2[:, 0]
    return {
        "q": q,
        "timoshenko_error": [float(abs(b / c - 1.0) / 2) for b, c in zip(beam, chain)],
        "paper_acoustic_ratio": float(paper[1] / chain[1]),
    }


def _summary(params, table, order: float | None, listed) -> dict[str, Any]:
    from ..analysis.continuum import printed_D1

    columns = table.as_dict() if table is not None else {}
    return {
        "params": params.model_dump(),
        "D1": params.D1,
        "D2": params.D2,
        "printed_D1": printed_D1(params),
        "rows": [dict(zip(columns, values)) for values in zip(*columns.values())],
        "order": order,
        "errata": [item.as_dict() for item in listed],
    }
