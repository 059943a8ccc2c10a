"""The report's stages: each computes one part of the paper with the public API and returns its :class:`Section`.

Contract
--------
A stage is a function of a :class:`_Stage` (the chain, the settings, the output folder and
the results the stages share) that writes its figures (PNG and SVG) and data (NetCDF and
JSON) through it and returns a :class:`Section`: paragraphs, tables, figures and the numbers
that :mod:`.claims` and ``summary.json`` read. :data:`STAGES` lists them in the report's
order. A stage may raise: :func:`~cosserat_chain.report.reproduce` turns the error into its
section.
"""

from __future__ import annotations

import json
import math
import re
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from ..io import stack_models, write_dataset, write_figure, write_text
from ..params import ChainParams
from .breathers import breathers_section
from .folder import json_default, write_manifest
from .settings import ABOVE_CRITICAL, MODELS, READINGS, ROTATING, ReproduceSettings, above_critical


@dataclass
class Section:
    """One part of the report: paragraphs, tables (header + rows) and figures (stem -> caption)."""

    title: str
    paragraphs: list[str] = field(default_factory=list)
    tables: list[tuple[str, list[str], list[list[Any]]]] = field(default_factory=list)
    figures: list[tuple[str, str]] = field(default_factory=list)
    numbers: dict[str, Any] = field(default_factory=dict)
    error: str | None = None
    seconds: float = 0.0


#: Width (inches) of every figure of the report.
FIGURE_WIDTH = 10.0
#: Resolution (dots per inch) of the report's PNG figures.
FIGURE_DPI = 130


class _Stage:
    """What every stage works with: the chain, the settings, the output folder (every file written
    through :meth:`path`, for the manifest) and the results the stages share."""

    def __init__(self, out: Path, params: ChainParams, settings: ReproduceSettings):
        self.out, self.params, self.settings = out, params, settings
        #: Results one stage shares with a later one (the sweeps of Fig. 2 feed the hysteresis picture).
        self.shared: dict[str, Any] = {}
        #: Every file written, relative to ``out`` (the manifest).
        self.written: set[str] = set()
        #: How far the running stage is, for :func:`~cosserat_chain.report.reproduce`'s ``progress`` (set by it).
        self.progress: Callable[[str], None] = lambda detail: None
        (out / "figures").mkdir(parents=True, exist_ok=True)
        (out / "data").mkdir(parents=True, exist_ok=True)

    def critical(self, model: str):
        """The model's :class:`~cosserat_chain.experiments.critical.CriticalPoint` on this chain (computed once, shared by the stages)."""
        from ..experiments.critical import critical_point

        exact = self.shared.setdefault("exact", {})
        if model not in exact:
            exact[model] = critical_point(self.params, model)
        return exact[model]

    def within(self, what: str, unit: str) -> Callable[[float, float], None]:
        """A library ``progress(done, total)`` callback that reports ``what`` of the running stage: whole counts
        of ``unit`` as such, a quantity that is not a count as a whole percentage."""

        def progress(done: float, total: float) -> None:
            if float(done).is_integer() and float(total).is_integer():
                self.progress(f"{what} {int(done)}/{int(total)} {unit}")
            elif total > 0:
                self.progress(f"{what} {min(100, int(100 * done / total))} %")

        return progress

    def load(self, model: str, configured: float) -> tuple[float, str]:
        """:func:`above_critical` for ``model`` on this chain."""
        return above_critical(configured, self.critical(model).critical_moment)

    def path(self, relative: str) -> Path:
        """Where the report's file ``relative`` goes, recorded in the manifest."""
        self.written.add(relative)
        return self.out / relative

    def figure(self, fig, stem: str) -> str:
        import matplotlib.pyplot as plt

        # Every figure of the report at the same width (a single panel grows to it, its text
        # keeping its size), so that the page shows them alike at any window width.
        width, height = fig.get_size_inches()
        if width < FIGURE_WIDTH:
            fig.set_size_inches(FIGURE_WIDTH, max(height, min(height * FIGURE_WIDTH / width, 0.6 * FIGURE_WIDTH)))
        # The figure is laid out once, at the saved resolution, and both files keep those places: savefig
        # with a layout engine draws the figure twice (once to lay it out) and lays it out at each draw.
        # The engine is then removed, not set to "none": savefig draws once more before printing while
        # a figure has any engine, the placeholder that "none" leaves included.
        fig.set_dpi(FIGURE_DPI)
        engine = fig.get_layout_engine()
        if engine is not None:
            engine.execute(fig)
            with plt.rc_context({"figure.autolayout": False, "figure.constrained_layout.use": False}):
                fig.set_layout_engine(None)
        write_figure(fig, self.path(f"figures/{stem}.png"), dpi=FIGURE_DPI)
        write_figure(fig, self.path(f"figures/{stem}.svg"), dpi=FIGURE_DPI)
        plt.close(fig)
        return stem

    def data(self, name: str, payload: Any) -> None:
        if hasattr(payload, "to_netcdf"):
            write_dataset(payload, self.path(f"data/{name}.nc"))
        else:
            write_text(json.dumps(payload, indent=1, default=json_default), self.path(f"data/{name}.json"))

    def finish(self) -> None:
        """Write the manifest of this report (:func:`~cosserat_chain.report.folder.write_manifest`)."""
        write_manifest(self.out, self.written)


def _statics(stage: _Stage) -> Section:
    from ..experiments.sweep import relaxation_sweep
    from ..plots.statics import figure2, hysteresis_figure

    p, s = stage.params, stage.settings
    exact = {m: stage.critical(m) for m in MODELS}
    largest = max((e.critical_moment for e in exact.values() if e.critical_moment is not None), default=0.0)
    # The protocol must pass every fold to show an onset: raise its top for a stiffer chain.
    m_max = max(s.m_max, math.ceil(ABOVE_CRITICAL * largest / s.dm) * s.dm)
    sweeps = {m: relaxation_sweep(p, m, m_max=m_max, dm=s.dm, down=True, progress=stage.within(f"{m} sweep", "loads")) for m in MODELS}
    stage.shared.update(sweeps=sweeps)
    stage.data("critical", stack_models({m: r.to_dataset() for m, r in exact.items()}))
    stage.data("sweep", stack_models({m: r.to_dataset() for m, r in sweeps.items()}))
    rows, numbers = [], {}
    for m in MODELS:
        e, w = exact[m], sweeps[m]
        numbers[m] = {
            "compliance": e.compliance,
            "M_c": e.critical_moment,
            "M_c_dimensionless": None if e.critical_moment is None else e.critical_moment / p.moment_scale,
            "phi0_at_fold": e.phi0_at_fold,
            "onset": e.onset,
            "phi0_at_onset": e.phi0_at_onset,
            "onset_load": w.onset_load,
            "stop_load": w.stop_load,
        }
        rows.append([m, e.compliance, e.critical_moment, e.phi0_at_onset, w.onset_load, w.stop_load])
    numbers["moment_scale"] = p.moment_scale
    stage.data("statics", numbers)
    section = Section("Static response and the onset of rotation (Fig. 2)", numbers=numbers)
    section.paragraphs.append(
        f"The moment on the central particle is raised in steps of {s.dm:g} up to {m_max:g}, each step run to rest "
        "(the paper's relaxation protocol, dots), then lowered again; a star marks the first step at which the particle "
        "rotates. Lines: the exact static branches by pseudo-arclength continuation (dashed: unstable), open circles: "
        "the folds, located to round-off. The linear model never rotates."
    )
    section.tables.append(
        (
            "Compliance, critical moment and fold angle: exact (continuation) and by the relaxation protocol",
            ["model", "compliance dphi0/dM", "M_c exact", "phi0 at M_c (rad)", "onset (relaxation)", "rotation stops (down)"],
            rows,
        )
    )
    agreement = _agreement(stage, exact)
    numbers["agreement"] = agreement
    section.paragraphs.append(_agreement_sentence(agreement))
    section.tables.append(
        (
            f"How far the models agree: within {100 * agreement['tolerance']:g} % of the linear phi0 = c M (exact branches)",
            ["model", "up to M", "linear phi0 there (rad)", "model's phi0 there (rad)", "ends by",
             f"deviation at linear phi0 = {agreement['phi0_linear']:g}"],
            [[m, r["moment"], r["phi0_linear"], r["phi0"], r["bound"], agreement["deviation"][m]] for m, r in agreement["ranges"].items()],
        )
    )  # fmt: skip
    seven = _seven_particles(stage)
    numbers["seven_particles"] = seven
    section.paragraphs.append(_readings_sentence(seven))
    section.tables.append(
        (
            "The paper's seven particles, both readings (this chain's geometry): exact statics",
            ["reading", "N", "particles (free)", "compliance dphi0/dM", *(f"M_c {m}" for m in ROTATING),
             *(f"phi0 at fold {m} (rad)" for m in ROTATING), "this report"],
            [[name, r["N"], f"{2 * r['N'] + 1} ({2 * r['N'] - 1})", r["compliance"], *(r["M_c"][m] for m in ROTATING),
              *(r["phi0_at_fold"][m] for m in ROTATING), name == seven["used"]] for name, r in seven["readings"].items()],
        )
    )  # fmt: skip
    section.figures.append(
        (
            stage.figure(figure2(exact, sweeps), "fig2"),
            "Fig. 2: phi_0 of the loaded particle against M (small circles: relaxation steps; stars: onset of rotation; lines: "
            "exact branches, dashed where unstable; open circles: folds); right: M(phi_0) over one turn.",
        )
    )
    section.figures.append(
        (
            stage.figure(hysteresis_figure({m: sweeps[m] for m in ROTATING}, {m: exact[m] for m in ROTATING}), "hysteresis"),
            "Hysteresis loop: mean angular velocity of the loaded particle at each load step, going up and coming down; "
            "dotted: the exact static fold M_c.",
        )
    )
    return section


def _seven_particles(stage: _Stage) -> dict[str, Any]:
    """Exact statics of both readings of "seven particles" (:data:`READINGS`) with this chain's geometry.

    The rotating models' M_c and fold angle, and the compliance at rest (every model's),
    for N = 3 and N = 4; the chain's own N reuses the statics already computed.
    """
    from ..experiments.critical import critical_point

    readings = {}
    for name, n in READINGS.items():
        chain = stage.params.replace(N=n)
        exact = {m: stage.critical(m) if n == stage.params.N else critical_point(chain, m, dynamics=False) for m in ROTATING}
        readings[name] = {
            "N": n,
            "compliance": exact[ROTATING[0]].compliance,
            "M_c": {m: exact[m].critical_moment for m in ROTATING},
            "phi0_at_fold": {m: exact[m].phi0_at_fold for m in ROTATING},
        }
    first, second = readings.values()
    change = {
        m: None if first["M_c"][m] is None or second["M_c"][m] is None else second["M_c"][m] / first["M_c"][m] - 1.0 for m in ROTATING
    }
    used = next((name for name, n in READINGS.items() if n == stage.params.N), None)
    return {
        "readings": readings,
        "M_c_change": change,
        "compliance_change": second["compliance"] / first["compliance"] - 1.0,
        "N": stage.params.N,
        "used": used,
    }


def _readings_sentence(seven: dict[str, Any]) -> str:
    """What the choice between the two readings of "seven particles" changes, in a sentence computed from them."""
    (first, a), (second, b) = seven["readings"].items()
    changes = ", ".join(f"{m} {100 * c:+.3g} %" for m, c in seven["M_c_change"].items() if c is not None)
    order = {name: sorted(ROTATING, key=lambda m: r["M_c"][m] or math.inf) for name, r in seven["readings"].items()}
    flips = (
        f"; the model that starts to rotate first changes ({order[first][0]} for N = {a['N']}, {order[second][0]} for N = {b['N']})"
        if order[first][0] != order[second][0]
        else ""
    )
    used = (
        f"This report's chain is the reading {seven['used']!r}"
        if seven["used"]
        else f"This report's chain has N = {seven['N']}, neither reading"
    )
    return (
        f'Section 4\'s "seven particles" reads two ways: seven with the clamped ends among them ({first}, N = {a["N"]}) or seven '
        f"free particles between clamped walls ({second}, N = {b['N']}). From N = {a['N']} to N = {b['N']} the compliance at rest "
        f"changes by {100 * seven['compliance_change']:+.3g} % and M_c by {changes}{flips}. {used}; the setting reading = "
        '"..." of [reproduce] selects one.'
    )


#: Tolerance of the small-load agreement, and the linear angle at which the deviations and the
#: errors against the nonlinear model are given (``docs/agreement.md``).
AGREEMENT_TOLERANCE = 0.01
AGREEMENT_ANGLE = 0.1


def _agreement(stage: _Stage, exact: dict[str, Any]) -> dict[str, Any]:
    """The models' small-load agreement on this chain, from the branches already traced, and the errors of (2) and (3)
    against (1) on this chain and on the same geometry with N = 1 (where the paper's remark on them fails)."""
    from ..analysis.agreement import agreement_range, errors_against, static_deviation

    p = stage.params
    angle = [AGREEMENT_ANGLE]
    # The linear model is the reference: its branch is the tangent itself.
    ranges = {m: agreement_range(p, m, tolerance=AGREEMENT_TOLERANCE, branch=exact[m].branch).as_dict() for m in ROTATING}
    errors = {}
    for label, chain in (("this chain", p), ("N = 1", p.model_copy(update={"N": 1}))):
        errors[label] = {m: float(e[0]) for m, e in errors_against(chain, "nonlinear", ["sine", "linear"], angle).items()}
    return {
        "tolerance": AGREEMENT_TOLERANCE,
        "phi0_linear": AGREEMENT_ANGLE,
        "ranges": ranges,
        "deviation": {m: float(static_deviation(p, m, angle)[0]) for m in ROTATING},
        "errors_against_nonlinear": errors,
    }


def _agreement_sentence(agreement: dict[str, Any]) -> str:
    r, dev = agreement["ranges"], agreement["deviation"]
    return (
        f"All three models share the tangent phi0 = c M at rest, and they stay within {100 * agreement['tolerance']:g} % of it "
        f"up to M = {r['nonlinear']['moment']:.4g} (nonlinear, linear phi0 {r['nonlinear']['phi0_linear']:.4g}) and "
        f"M = {r['sine']['moment']:.4g} (sine, linear phi0 {r['sine']['phi0_linear']:.6g}: arcsin(p) = 1.01 p on every chain). "
        f"At a linear phi0 of {agreement['phi0_linear']:g} the nonlinear model lies {100 * dev['nonlinear']:+.3g} % and the sine "
        f"model {100 * dev['sine']:+.3g} % (= arcsin(p)/p - 1) from the linear one. The nonlinear chain stiffens through its "
        "transverse displacements, which grow with the chain's length: the range of agreement shrinks like 1/N "
        "(docs/agreement.md)."
    )


def _orbits(stage: _Stage) -> Section:
    from ..experiments.orbits import periodic_orbit
    from ..experiments.sweep import relaxation_sweep
    from ..plots.orbits import rotation_characteristic_figure

    p, s = stage.params, stage.settings
    model = "sine"
    critical = stage.critical(model)
    moment, relation = stage.load(model, s.orbit_moment)
    sweep = stage.shared.get("sweeps", {}).get(model) or relaxation_sweep(p, model, m_max=max(s.m_max, moment), dm=s.dm, down=True)
    result = periodic_orbit(p, model, moment, down_to=min(s.orbit_down_to, moment), progress=stage.within("continuation", "orbits"))
    stage.data("orbits", result.to_dataset())
    branch = result.branch
    numbers = {
        "model": model,
        "moment": moment,
        "period": result.orbit.period,
        "mean_angular_velocity": result.orbit.mean_angular_velocity,
        "stable": bool(result.orbit.stable),
        "orbit_end": branch.end,
        "orbit_end_moment": branch.end_moment,
        "stability_lost_at": branch.stability_lost_at,
        "static_fold": critical.critical_moment,
        "relaxation_onset": sweep.onset_load,
        "relaxation_stop": sweep.stop_load,
    }
    stage.data("orbit_summary", numbers)
    section = Section("Rotating states as periodic orbits: the hysteresis loop", numbers=numbers)
    section.paragraphs.append(
        f"Above M_c the rotating state of the {model} model is a limit cycle: the loaded particle advances by one turn per "
        f"period while everything else returns. It is found at M = {moment:.4g} ({relation}) by Newton's method on a "
        "shooting map and continued downwards in M. " + _loop_edges(numbers)
    )
    section.tables.append(
        (
            "Edges of the hysteresis loop: exact, and by the relaxation protocol",
            [
                "model",
                "static fold M_c",
                "orbit loses stability at",
                "orbit ends at",
                "how",
                "onset (relaxation up)",
                "stop (relaxation down)",
            ],
            [[model, numbers["static_fold"], branch.stability_lost_at, branch.end_moment, branch.end, sweep.onset_load, sweep.stop_load]],
        )
    )
    section.tables.append(
        (
            f"Periodic orbit at M = {moment:.4g}",
            ["period T", "mean angular velocity", "largest non-trivial Floquet multiplier", "stable"],
            [[result.orbit.period, result.orbit.mean_angular_velocity, result.orbit.max_multiplier, bool(result.orbit.stable)]],
        )
    )
    fig = rotation_characteristic_figure(branches=[branch], sweep=sweep, static_fold=numbers["static_fold"], model=model)
    section.figures.append(
        (
            stage.figure(fig, "rotation_characteristic"),
            "Rotation characteristic: mean angular velocity of the periodic orbit against M "
            "(dashed: unstable), with the relaxation sweep's steps up and down, the static fold M_c (dotted), where the "
            "orbit loses stability (dashed line) and where it ends (cross).",
        )
    )
    return section


def _state_map(stage: _Stage) -> Section:
    """Issue 13: the phase diagram in (gamma_phi, M) of the paper's chain for both rotating models."""
    from ..experiments.diagram import state_diagram
    from ..plots.diagram import diagram_figure

    p, s = stage.params, stage.settings
    section = Section("The map of static and rotating states against the damping")
    section.paragraphs.append(
        "For each value of the rotational damping gamma_phi: the static fold M_c (the onset of rotation under a rising "
        "load; it does not depend on the damping) and where a falling load stops the stable periodic rotation, and how: "
        "at a fold of cycles, a period doubling or a torus (a Floquet multiplier leaving the unit circle), at a homoclinic "
        "orbit, or at a saddle-node on the invariant circle (snic: the loop closes, no hysteresis). Between the two edges "
        "the chain rests or rotates depending on its history."
    )
    rows, numbers = [], {}
    for model in ROTATING:
        values = s.diagram_damping.get(model, ())
        if not values:
            continue
        result = state_diagram(p, model, "gamma_phi", list(values), progress=stage.within(model, "values"))
        stage.data(f"diagram_{model}", result.to_dataset())
        numbers[model] = result.as_dict()["rows"]
        for row in result.rows:
            rows.append([model, row.value, row.static_fold, row.rotation_stops, row.end, row.hysteresis])
        section.figures.append(
            (
                stage.figure(diagram_figure(result), f"state_diagram_{model}"),
                f"{model} model: static (blue), static or rotating (hysteresis, orange) and rotating (red) in "
                "(gamma_phi, M / (E1 h^2)); solid: M_c, dashed: where the rotation stops, labelled with how.",
            )
        )
    section.numbers = numbers
    stage.data("state_diagram", numbers)
    section.tables.append(
        (
            "Both edges of the hysteresis loop against gamma_phi",
            ["model", "gamma_phi", "M_c", "rotation stops at", "how", "hysteresis"],
            rows,
        )
    )
    return section


def _rotation(stage: _Stage) -> Section:
    from ..experiments.simulation import simulate
    from ..plots.chain import animate, snapshot_figure

    p, s = stage.params, stage.settings
    t_end = max(s.snapshot_times) + 1.0
    section = Section("The rotating chain (Figs. 3a and 3b)")
    # The paper's figures: Fig. 3a is the sine model, Fig. 3b (and the animation) the nonlinear one.
    for label, m in (("fig3a", "sine"), ("fig3b", "nonlinear")):
        moment, relation = stage.load(m, s.rotation_moment[m])
        run = simulate(p, m, moment, t_end=t_end, n_frames=int(t_end / 0.05) + 1)
        stage.data(f"rotation_{m}", run)
        shown = [float(run.time.sel(time=t, method="nearest")) for t in s.snapshot_times]  # the stored frames drawn
        section.figures.append(
            (
                stage.figure(snapshot_figure(p, run, list(s.snapshot_times)), label),
                f"Fig. {label[-2:]}: the {m} model under M = {moment:.4g} ({relation}), snapshots at t = "
                + ", ".join(f"{t:.6g}" for t in shown)
                + ".",
            )
        )
        if m == "nonlinear":
            animate(p, run, stage.path("figures/rotation.gif"), t_start=t_end - 10.0, t_stop=t_end, max_frames=s.animation_frames, fps=15)
    section.paragraphs.append(
        "In the sine model u decouples, so the other particles only move transversally (Fig. 3a); in the nonlinear model "
        "every degree of freedom is coupled (Fig. 3b). Animation of the nonlinear chain over the last 10 time units "
        "(the loaded particle in colour, the links as lines): [figures/rotation.gif](figures/rotation.gif)."
    )
    return section


def _localization(stage: _Stage) -> Section:
    from ..experiments.localization import localization_run

    p, s = stage.params, stage.settings
    rows, numbers = [], {}
    relations = {}
    for m in ROTATING:
        moment, relations[m] = stage.load(m, s.rotation_moment[m])
        result = localization_run(p, m, moment, turns=s.turns, t_max=100.0 * s.turns, progress=stage.within(m, "turns"))
        stage.data(f"localization_{m}", result.to_dataset())
        d = result.as_dict()
        numbers[m] = d
        rows.append(
            [
                m,
                moment,
                d["turns_completed"],
                d["t_end"],
                d["mean_angular_velocity"],
                d["max_abs_phi_others"],
                d["max_abs_v_others_over_h"],
                d["max_abs_u_others_over_h"],
                ", ".join(d["outside_model_validity"]) or "—",
                d["classification"],
            ]
        )
    stage.data("localization", numbers)
    section = Section(f"Localization: {s.turns} rotations of the central particle", numbers=numbers)
    section.paragraphs.append(
        f"The central particle is driven from rest until it has made {s.turns} full turns (the paper's test), at "
        + "; ".join(f"M = {numbers[m]['moment']:.4g} for the {m} model ({relations[m]})" for m in ROTATING)
        + ". "
        + " ".join(_localization_outcome(m, numbers[m], s.turns) for m in ROTATING)
        + " Their largest excursions over the whole run are below, against the thresholds of a small motion "
        + thresholds_text(numbers[ROTATING[0]]["thresholds"])
        + ": where the first neglected term of the linear models is a tenth of the kept one."
    )
    section.tables.append(
        (
            "Statistics of the localization run",
            [
                "model",
                "M",
                "turns",
                "t_end",
                "mean angular velocity",
                "max abs phi, others (rad)",
                "max abs v / h, others",
                "max abs u / h, others",
                "outside the model's linear range",
                "state",
            ],
            rows,
        )
    )
    return section


def _localization_outcome(model: str, result: dict[str, Any], turns: int) -> str:
    """What the run shows for one model, in a sentence computed from its result."""
    made = result["turns_completed"]
    if result["classification"] == "localized_rotation":
        return (
            f"In the {model} model the loaded particle made {made} turns, no other particle turned and the others' motion "
            "stayed small: the rotation stays localized."
        )
    if result["classification"] == "rotation_with_large_motion":
        beyond = ", ".join(AMPLITUDES[name] for name in result["large_motion"])
        outside = [AMPLITUDES[name] for name in result["outside_model_validity"]]
        return (
            f"In the {model} model the loaded particle made {made} turns and no other particle turned, but the others' "
            f"motion is not small ({beyond} beyond the thresholds)"
            + (f", and the model, linear in {', '.join(outside)}, is outside its range of validity there." if outside else ".")
        )
    if made < turns:
        return f"In the {model} model the loaded particle made only {made} of the {turns} turns by t = {result['t_end']:.6g} ({result['classification']})."
    return f"In the {model} model other particles turned as well ({result['classification']}): the rotation is not localized."


#: The localization amplitudes' names (those of ``diagnostics.THRESHOLDS``) as the report writes them.
AMPLITUDES = {"phi": "|phi|", "u_over_h": "|u|/h", "v_over_h": "|v|/h"}


def thresholds_text(thresholds: dict[str, float]) -> str:
    """The localization thresholds in words (phi in rad, the displacements in units of h)."""
    return f"(|phi| <= {thresholds['phi']:g} rad, |u|, |v| <= {thresholds['v_over_h']:g} h)"


def _loop_edges(numbers: dict[str, Any]) -> str:
    """Both edges of the hysteresis loop as the orbit stage found them, in a sentence."""

    def value(x: float | None) -> str:
        return "none" if x is None or not math.isfinite(x) else f"{x:.4g}"

    lost = numbers["stability_lost_at"]
    down = (
        f"coming down, the orbit loses stability at M = {value(lost)} and ends at M = {value(numbers['orbit_end_moment'])} ({numbers['orbit_end']})"
        if lost is not None
        else f"coming down, the orbit stays stable until it ends at M = {value(numbers['orbit_end_moment'])} ({numbers['orbit_end']})"
    )
    return (
        f"Going up, the static branch ends at its fold M_c = {value(numbers['static_fold'])} and the relaxation protocol sees "
        f"rotation start at M = {value(numbers['relaxation_onset'])}; {down}, and the protocol sees rotation stop at "
        f"M = {value(numbers['relaxation_stop'])}: the two edges of the hysteresis loop."
    )


def _trend(model: str, items: list[dict[str, Any]]) -> str:
    """How the model's M_c changes along the chain lengths computed, in a sentence."""
    found = [item for item in items if item["M_c"] is not None]
    if len(found) < 2:
        return f"The {model} model has a fold for {len(found)} of the {len(items)} lengths."
    first, last = found[0], found[-1]
    scaled = [item["N"] * item["M_c"] for item in found]
    if model == "sine":
        spread = max(scaled) / min(scaled) - 1.0
        return (
            f"The sine model's M_c is 1/(largest rotation compliance); N M_c goes from {scaled[0]:.4g} (N = {first['N']}) to "
            f"{scaled[-1]:.4g} (N = {last['N']})" + (f", within {100 * spread:.2g} %: M_c falls like 1/N." if spread < 0.1 else ".")
        )
    return (
        f"The {model} model's M_c goes from {first['M_c']:.4g} (N = {first['N']}) to {last['M_c']:.4g} (N = {last['N']}), "
        f"and phi_0 at its fold from {first['phi0_at_fold']:.3g} to {last['phi0_at_fold']:.3g} rad."
    )


def _long_chains(stage: _Stage) -> Section:
    from ..experiments.critical import critical_point
    from ..plots.statics import critical_against_length

    p, s = stage.params, stage.settings
    # The chain's own N is the statics stage's point where it is computed already (the same branch and fold: its
    # dynamics only add the stability along it, which this stage does not read).
    known = stage.shared.get("exact", {})
    results = {
        m: [known[m] if n == p.N and m in known else critical_point(p.replace(N=n), m, dynamics=False) for n in s.long_n_list]
        for m in ROTATING
    }

    def summary(result) -> dict:
        whole = result.as_dict()
        picked = {k: whole[k] for k in ("M_c", "phi0_at_fold", "first_fold", "snap_through", "branch_complete")}
        return {"N": result.params.N, **picked, "folds": len(result.branch.folds)}

    numbers = {m: [summary(r) for r in rows] for m, rows in results.items()}
    stage.data("long_chains", numbers)
    section = Section("The critical moment of longer chains", numbers=numbers)
    section.paragraphs.append(
        "The statics of this chain's geometry for longer chains (2N+1 particles, both ends clamped), each branch traced over "
        "one turn of the loaded particle. "
        + " ".join(_trend(m, items) for m, items in numbers.items())
        + " (docs/statics.md has the paper chain's table to N = 1000, the first fold of N = 10^4 and the cost.)"
    )
    rows = []
    for m, items in numbers.items():
        for item in items:
            first = item["first_fold"]
            rows.append(
                [
                    m,
                    item["N"],
                    item["M_c"],
                    item["phi0_at_fold"],
                    None if first is None else first["moment"],
                    item["folds"],
                    item["branch_complete"],
                ]
            )
    section.tables.append(
        ("M_c against N", ["model", "N", "M_c", "phi0 at fold (rad)", "first fold M", "folds over the turn", "branch complete"], rows)
    )
    section.figures.append(
        (stage.figure(critical_against_length(results), "critical_vs_N"), "M_c (sine: N M_c) and phi_0 at the fold against N.")
    )
    return section


def _continuum(stage: _Stage) -> Section:
    from ..analysis.continuum import compare_profiles, convergence, reduced_discrete
    from ..plots.theory import plot_convergence, plot_profiles

    p, s = stage.params, stage.settings
    table = convergence(p, list(s.n_list))
    reduced = reduced_discrete(p).as_dict()
    stage.data("continuum", table.as_dict())
    stage.data("reduced", reduced)
    section = Section(
        "Continuum theory (Section 3) against the discrete chain",
        numbers={"table": table.as_dict(), "order": table.order(), "reduced": reduced},
    )
    section.paragraphs.append(
        "phi_0 / M of the long-wave solution (11) with the geometry-derived D1, D2, against the discrete linear chain (3), "
        f"and the residue (12); the relative error falls like N^-{table.order():.2f}. "
        + (
            "For this chain continuum - discrete keeps one sign over the list; "
            if np.all(np.sign(table.signed_error[table.N > 1]) == np.sign(table.signed_error[-1]))
            else "For this chain continuum - discrete changes sign along the list; "
        )
        + "for some geometries it changes sign at small N, and the 1/N fall holds only past the change (docs/continuum.md)."
    )
    section.tables.append(
        (
            "Continuum against discrete compliance",
            ["N", "continuum phi0/M", "discrete phi0/M", "relative error", "residue", "(continuum - discrete) / discrete"],
            [
                [int(n), c, d, e, r, se]
                for n, c, d, e, r, se in zip(
                    table.N, table.continuum, table.discrete, table.relative_error, table.residue, table.signed_error
                )
            ],
        )
    )
    section.figures.append(
        (
            stage.figure(plot_profiles(compare_profiles(p)), "profiles"),
            "Continuum solution (lines, open circles at the particles) against the discrete chain (crosses): profiles v_k and phi_k.",
        )
    )
    section.figures.append((stage.figure(plot_convergence(table), "convergence"), "Relative error and residue against N."))
    section.paragraphs.append(_reduced_sentence(reduced))
    section.tables.append(
        (
            "The reduced model (D1 = 0, Section 3.2): continuum family against the discrete chain",
            ["E1 of the reduced chain", "K positive definite", "lowest eigenvalue of K", "discrete phi0/M",
             "continuum phi(0)/M (the paper's cubic)", "d phi(0) / d alpha", "alpha matching the chain"],
            [[reduced["E1"], reduced["positive_definite"], reduced["lowest_eigenvalue"], reduced["compliance"],
              reduced["continuum_compliance"], reduced["family_slope"], reduced["matching_alpha"]]],
        )
    )  # fmt: skip
    return section


def _which_continuum(stage: _Stage) -> Section:
    """The paper's open problem (its introduction): which continuum describes small deformations, large bending, a full rotation."""
    from ..analysis.which_continuum import answer
    from ..plots.theory import plot_continua

    result = answer(stage.params)
    numbers = result.as_dict()
    stage.data("which_continuum", numbers)
    section = Section("Which continuum? The paper's open problem answered in numbers", numbers=numbers)
    section.paragraphs.extend(result.lines())
    section.paragraphs.append(
        "Each number is computed against the discrete chain of this report's geometry; docs/which-continuum.md derives the "
        "three levels and maps where each stops being valid over the geometry."
    )
    section.figures.append(
        (
            stage.figure(plot_continua(result.beam, result.bending), "which_continuum"),
            "Left: compliance error of the Timoshenko beam and of eq. (11) against the discrete chain, against N. "
            "Right: model (i)'s cantilever bent by an end moment against the exact beam's circle.",
        )
    )
    return section


def _reduced_sentence(reduced: dict[str, Any]) -> str:
    """The reduced model's continuum arbitrariness against the discrete chain's uniqueness, in a sentence from the numbers."""
    continuum = (
        "the four conditions fix phi(0) only for N = 1"
        if reduced["family_slope"] == 0
        else f"phi(0)/M = {reduced['continuum_compliance']:.4g} + {reduced['family_slope']:.4g} alpha takes any value"
    )
    discrete = (
        f"positive definite (lowest eigenvalue {reduced['lowest_eigenvalue']:.4g}), so its static state is unique: "
        f"phi_0/M = {reduced['compliance']:.4g}"
        if reduced["positive_definite"]
        else "not positive definite"
    )
    return (
        "The reduced model (D1 = 0) as a continuum is arbitrary, as Section 3.2 says, beyond the paper's cubic as well: "
        "v = v_3 + alpha x (L - x)^2 (x + (L - h)^2 / (2L - h)) meets its equations and all four conditions for every alpha, "
        f"and {continuum}. The discrete reduced chain (E1 = {reduced['E1']:.4g}, so that D1 = 0) keeps its bending "
        f"energy E1 b^2 (phi_k+1 - phi_k)^2; its stiffness K is {discrete}."
    )


def _waves(stage: _Stage) -> Section:
    from ..analysis.dispersion import continuum_dispersion, dispersion, wave_summary
    from ..plots.theory import plot_dispersion

    summary = wave_summary(stage.params)
    data = summary.as_dict()
    stage.data("waves", data)
    section = Section("Waves: dispersion of the infinite linear chain", numbers=data)
    section.tables.append(
        (
            "Branch frequencies",
            ["branch", "omega at q = 0", "omega at q = pi/h"],
            [[b, data["at_zero"][b], data["at_pi"][b]] for b in data["at_zero"]],
        )
    )
    gap = data["gap"]
    section.paragraphs.append(
        "Transverse and rotational waves cannot travel for "
        + (f"{gap[0]:.4g} < omega < {gap[1]:.4g}." if gap else "no frequency: the bands overlap.")
    )
    fig = plot_dispersion(dispersion(stage.params), summary, continuum_dispersion(stage.params))
    section.figures.append((stage.figure(fig, "dispersion"), "Dispersion curves, gap shaded; dashed: the continuum theory."))
    return section


def readable(formula: str) -> str:
    """A SymPy string as a reader writes it: ``2*E2*b**2*h**2/d**2`` -> ``2 E2 b² h² / d²``."""
    superscripts = str.maketrans("0123456789", "⁰¹²³⁴⁵⁶⁷⁸⁹")
    text = re.sub(r"(?:\*\*|\^)(\d+)", lambda m: m.group(1).translate(superscripts), formula)
    text = re.sub(r"(?<=\S)\*(?=\S)", " ", text)
    return re.sub(r"(?<=[\w)²³⁴'])/(?=[\w(])", " / ", text)


def _errata(stage: _Stage) -> Section:
    from ..analysis.symbolic import errata

    items = [e.as_dict() for e in errata(stage.params)]
    stage.data("errata", items)
    section = Section("Errata: where the printed equations disagree with the derivation", numbers={"errata": items})
    section.tables.append(
        (
            "Errata (derived with SymPy from the geometry of model (i))",
            ["#", "where", "printed", "derived", "consequence"],
            [[e["number"], e["where"], readable(e["printed"]), readable(e["derived"]), readable(e["consequence"])] for e in items],
        )
    )
    return section


STAGES: dict[str, Callable[[_Stage], Section]] = {
    "statics": _statics,
    "long_chains": _long_chains,
    "orbits": _orbits,
    "state_map": _state_map,
    "rotation": _rotation,
    "localization": _localization,
    "continuum": _continuum,
    "which_continuum": _which_continuum,
    "waves": _waves,
    "roto_breathers": lambda stage: Section(**breathers_section(stage)),
    "errata": _errata,
}
