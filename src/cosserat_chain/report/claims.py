"""The report's first table: what the paper says, what this package computes, and whether they agree.

Contract
--------
:func:`claims` reads the numbers of the stages' sections (never recomputes) and returns one row
per claim of the paper's Sections 3 and 4, in the columns :data:`CLAIMS_HEADER`; a claim whose
stage failed or did not run says so in its row.
"""

from __future__ import annotations

import math
from typing import Any

from .settings import MODELS, ROTATING, ReproduceSettings
from .stages import AMPLITUDES, Section, thresholds_text

#: Columns of :func:`claims`.
CLAIMS_HEADER = ("the paper says", "this package computes", "agreement")


def claims(results: dict[str, Section], settings: ReproduceSettings) -> list[list[str]]:
    """The report's first table: what the paper says, what this package computes, and whether they agree.

    One row per claim of the paper's Section 4 (and Section 3's continuum solution), each
    computed from the stage that tests it; a stage that failed or did not run says so.
    """

    def number(value: Any, digits: int = 4) -> str:
        return "none" if value is None or (isinstance(value, float) and not math.isfinite(value)) else f"{value:.{digits}g}"

    rows: list[list[str]] = []

    def stage(name: str) -> dict[str, Any] | None:
        section = results.get(name)
        return None if section is None or section.error else section.numbers

    def missing(name: str, claim: str) -> None:
        rows.append([claim, f"stage {name!r} {'failed' if name in results else 'was not run'}", "—"])

    statics = stage("statics")
    claim = "Under small loads all three models give very similar static deformations"
    if statics is None:
        missing("statics", claim)
    else:
        slopes = [statics[m]["compliance"] for m in MODELS]
        spread = max(slopes) / min(slopes) - 1.0
        rows.append([claim, "compliance dphi0/dM at rest: " + ", ".join(f"{m} {number(statics[m]['compliance'], 8)}" for m in MODELS),
                     "yes: the same slope at rest" if spread < 1e-9 else f"no: slopes differ by {spread:.2g}"])  # fmt: skip
        agreement = statics["agreement"]
        r, tol = agreement["ranges"], agreement["tolerance"]
        claim = "The results for all three models agree quite well for small applied moments and induced angles"
        rows.append([claim, f"within {100 * tol:g} % of the linear phi0 up to M = {number(r['nonlinear']['moment'])} (nonlinear), "
                            f"{number(r['sine']['moment'])} (sine); at linear phi0 = {agreement['phi0_linear']:g}: nonlinear "
                            f"{100 * agreement['deviation']['nonlinear']:+.3g} %, sine {100 * agreement['deviation']['sine']:+.3g} %",
                     f"yes, up to linear phi0 = {number(min(r[m]['phi0_linear'] for m in ROTATING), 3)} on this chain; the range shrinks "
                     "like 1/N (geometric stiffening of the nonlinear chain through its transverse displacements)"])  # fmt: skip
        claim = "The error of the sine model (2) increases compared with the error of the linear model (3)"
        errors = agreement["errors_against_nonlinear"]
        worse = {label: abs(e["sine"]) > abs(e["linear"]) for label, e in errors.items()}
        rows.append([claim, f"against model (1) at linear phi0 = {agreement['phi0_linear']:g}: " + "; ".join(
                         f"{label}: sine {100 * e['sine']:+.3g} %, linear {100 * e['linear']:+.3g} %" for label, e in errors.items()),
                     "; ".join(f"{'yes' if w else 'no'} ({label})" for label, w in worse.items())
                     + ("" if all(worse.values()) else ": where the nonlinear chain is softer than the linear one by more than "
                        "half the sine model's excess, the sine model is the closer")])  # fmt: skip
        claim = "Under strong load the central particle rotates; the linear model (3) does not describe it"
        folds = {m: statics[m]["M_c"] for m in MODELS}
        rotating_ok = all(folds[m] is not None for m in ROTATING) and folds["linear"] is None
        rows.append([claim, "M_c: " + ", ".join(f"{m} {number(folds[m])}" for m in MODELS),
                     "yes: a fold (M_c) for models (1) and (2), none for (3)" if rotating_ok else "no"])  # fmt: skip
        claim = "Stars in Fig. 2: the load step at which the central particle starts to rotate"
        onsets = {m: statics[m]["onset_load"] for m in ROTATING}
        within = all(onsets[m] is not None and folds[m] < onsets[m] <= folds[m] + settings.dm + 1e-12 for m in ROTATING)
        rows.append([claim, "; ".join(f"{m}: onset {number(onsets[m])}, exact M_c {number(folds[m])}" for m in ROTATING),
                     f"yes: the first step above M_c (steps of {settings.dm:g})" if within else "no: the onset is not the first step above M_c"])  # fmt: skip
    localization = stage("localization")
    claim = "A test run: the central particle made 1500 full rotations, while the other particles performed small oscillations only"
    if localization is None:
        missing("localization", claim)
    else:
        made = {m: localization[m] for m in ROTATING}
        turned = all(d["turns_completed"] >= settings.turns for d in made.values())
        classes = {d["classification"] for d in made.values()}
        outside = [
            f"{m} ({', '.join(AMPLITUDES[n] for n in d['outside_model_validity'])})" for m, d in made.items() if d["outside_model_validity"]
        ]
        if turned and classes == {"localized_rotation"}:
            verdict = f"yes over {settings.turns} turns: no other particle turned, and their motion stayed small"
        elif turned and classes <= {"localized_rotation", "rotation_with_large_motion"}:
            verdict = (
                f"partly: over {settings.turns} turns no other particle turned, but their oscillations are not small "
                + thresholds_text(next(iter(made.values()))["thresholds"])
                + (f"; outside the linear range of the model: {', '.join(outside)}" if outside else "")
            )
        else:
            verdict = "no: see the localization section"
        rows.append([claim, "; ".join(f"{m}: {d['turns_completed']} turns, {d['classification']}, others max |phi| "
                                      f"{number(d['max_abs_phi_others'], 3)} rad, |v| {number(d['max_abs_v_others_over_h'], 3)} h, "
                                      f"|u| {number(d['max_abs_u_others_over_h'], 3)} h" for m, d in made.items()),
                     verdict])  # fmt: skip
    continuum = stage("continuum")
    claim = "The continuum solution (11) approximates the discrete chain's rotation of the central particle"
    if continuum is None:
        missing("continuum", claim)
    else:
        table = continuum["table"]
        errors = dict(zip(table["N"], table["relative_error"]))
        first, last = min(errors), max(errors)
        rows.append([claim, f"relative error {number(100 * errors[first], 3)} % at N = {first}, {number(100 * errors[last], 3)} % at N = {last}",
                     f"approximately, better for longer chains (error like N^-{continuum['order']:.2f})"])  # fmt: skip
    errata = stage("errata")
    claim = "The coefficients of eqs. (2)-(3) and of Section 3"
    if errata is None:
        missing("errata", claim)
    else:
        rows.append([claim, f"{len(errata['errata'])} printed coefficients or statements disagree with the derivation from model (1)",
                     "no: see the errata (the package uses the derived ones)"])  # fmt: skip
    claim = 'Section 4: "In our simulations a finite 1D chain consists of seven particles"'
    if statics is None:
        missing("statics", claim)
    else:
        seven = statics["seven_particles"]
        computed = "; ".join(
            f"{name} (N = {r['N']}): compliance {number(r['compliance'])}, M_c " + ", ".join(f"{m} {number(r['M_c'][m])}" for m in ROTATING)
            for name, r in seven["readings"].items()
        )
        changes = ", ".join(f"{m} {number(100 * c, 3)} %" for m, c in seven["M_c_change"].items() if c is not None)
        used = f"this report uses {seven['used']!r}" if seven["used"] else f"this report's chain (N = {seven['N']}) is neither"
        rows.append([claim, f"{computed}; M_c changes by {changes}",
                     f"ambiguous: both readings computed, {used} (reading in [reproduce] selects one)"])  # fmt: skip
    claim = "Section 3.2: the reduced model (D1 = 0) exhibits some arbitrariness; with the cubic (14) the four conditions give its solution"
    if continuum is None:
        missing("continuum", claim)
    else:
        reduced = continuum["reduced"]
        rows.append([claim, f"continuum: v + alpha x (L - x)^2 (x + (L - h)^2/(2L - h)) meets all four for every alpha, "
                            f"phi(0)/M = {number(reduced['continuum_compliance'])} + {number(reduced['family_slope'])} alpha; "
                            f"discrete reduced chain (E1 = {number(reduced['E1'])}): lowest eigenvalue of K "
                            f"{number(reduced['lowest_eigenvalue'])}, phi_0/M = {number(reduced['compliance'])}",
                     ("yes for the continuum, beyond the cubic too (phi(0) is not determined); the discrete chain's K is positive "
                      "definite: one static state" if reduced["positive_definite"] else "no: the discrete reduced chain's K is not "
                      "positive definite")])  # fmt: skip
    claim = 'Fig. 2: the applied moment is plotted as a "dimensionless moment"'
    if statics is None:
        missing("statics", claim)
    else:
        rows.append([claim, f"M / (E1 h^2) on every moment axis and as M_c_dimensionless in the JSON; E1 h^2 = "
                            f"{number(statics['moment_scale'])} here: M_c / (E1 h^2) = "
                            + ", ".join(f"{m} {number(statics[m]['M_c_dimensionless'])}" for m in ROTATING),
                     "the paper does not name its unit; E1 h^2 (a link's stiffness times the spacing squared) makes chains "
                     "of other E1 or h comparable, and equals 1 for the paper's chain"])  # fmt: skip
    return rows
