"""The report's roto-breather section: two small families of the undamped chain against the bands.

Contract
--------
:func:`breathers_section` computes, on the report's chain at N = :data:`REPORT_N` with its
viscosities set to 0, the one-site roto-breather families of the sine model
(:data:`SINE_OMEGAS`, across the end of the combination resonance w_TA + w_RO = Omega) and the
nonlinear model (:data:`NONLINEAR_OMEGAS`) from the anti-continuum rotor
(:func:`~cosserat_chain.experiments.breathers.roto_breather_family`): a short chain and a few
frequencies keep the stage to a small part of ``reproduce``'s time. It writes their JSON,
the sine family's figure against the bands' harmonics, and returns the fields of a
:class:`~cosserat_chain.report.stages.Section` (title, paragraphs, a table per model, the
figure, the numbers: the stages build it, and this module imports none of theirs); the atlas over
(Omega, geometry) of long chains is docs/roto-breathers.md's, not the report's.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

if TYPE_CHECKING:  # the stages import this module: their classes are only named here
    from .stages import _Stage

#: Half-length of the report's roto-breather chain (2N + 1 particles).
REPORT_N = 3
#: The sine family's frequencies: stable above 1.569 + 4.804 = 6.373 (the paper's geometry), unstable below.
SINE_OMEGAS = (8.0, 7.0, 6.6, 6.4, 6.2, 5.8, 5.4, 5.0)
#: The nonlinear family's frequencies, above every band.
NONLINEAR_OMEGAS = (10.5, 9.8, 9.4, 9.0)


def breathers_section(stage: _Stage) -> dict:
    """Roto-breather families of the report's chain (undamped, N = :data:`REPORT_N`): the fields of its :class:`~.stages.Section`."""
    from ..analysis.dispersion import wave_summary
    from ..experiments.breathers import roto_breather_family
    from ..plots.breathers import breather_family_figure

    params = stage.params.replace(N=REPORT_N, gamma_u=0.0, gamma_v=0.0, gamma_phi=0.0)
    paragraphs, tables, figures = [], [], []
    paragraphs.append(
        f"Undamped and unloaded, the chain (N = {REPORT_N}, the report's geometry) carries time-periodic states in which "
        "one particle turns while the others oscillate: roto-breathers, found by Newton's method on the period map from "
        "the anti-continuum rotor (the particle alone in the potential of its bonds) and continued in the frequency Omega. "
        "A family is stable where every Floquet multiplier but the Hamiltonian pair at +1 lies on the unit circle; "
        "a pair of phonons whose frequencies sum to a harmonic of Omega is excited parametrically and makes it unstable."
    )
    numbers = {}
    for model, omegas in (("sine", SINE_OMEGAS), ("nonlinear", NONLINEAR_OMEGAS)):
        stage.progress(f"{model} family")
        result = roto_breather_family(params, model, list(omegas))
        summary = result.as_dict()
        numbers[model] = summary
        pairs = result.combination_resonances()
        tables.append(
            (
                f"{model} model: one-site roto-breathers",
                ["Omega", "energy", "max nontrivial |mu|", "stable", "tail (max |q| off the rotor)", "phonon pairs w_A + w_B = n Omega"],
                [
                    [
                        o.omega,
                        "-" if o.energy is None else o.energy,
                        o.max_multiplier,
                        "yes" if o.stable else "no",
                        tail,
                        ", ".join(f"{n}: {a} + {b}" for n, a, b in pair) or "none",
                    ]
                    for o, tail, pair in zip(result.family.orbits, summary["tail_amplitude"], pairs)
                ],
            )
        )
        if model == "sine":
            figures.append(
                (
                    stage.figure(breather_family_figure(result), "roto_breathers_sine"),
                    "Sine model: the tail's amplitude and the largest nontrivial multiplier against Omega; shaded, the "
                    "windows where a harmonic n Omega lies in a band.",
                )
            )
    bands = wave_summary(params).bands
    edge = bands["transverse_acoustic"][1] + bands["rotational_optical"][1]
    sine = numbers["sine"]
    unstable = [o for o, s in zip(sine["omega"], sine["stable"]) if not s]
    stable = [o for o, s in zip(sine["omega"], sine["stable"]) if s and (not unstable or o > max(unstable))]
    numbers["combination_edge"] = edge
    paragraphs.append(
        f"In the infinite chain the pair (transverse acoustic, rotational optical) reaches Omega up to {edge:.4g}: the sine "
        f"family is unstable at and below {max(unstable):.4g} and stable from {min(stable):.4g} up. A chain of "
        f"{params.n_particles} particles has a few discrete modes in each band, so its instabilities are tongues around the "
        "sums of two modes' frequencies and a member between them can be stable. The band "
        "picture, the atlas over the geometry for chains of 101-401 particles, the lifetimes and the damped-to-undamped "
        "homotopy are in the documentation's roto-breather page."
        if unstable and stable
        else f"In the infinite chain the pair (transverse acoustic, rotational optical) reaches Omega up to {edge:.4g}."
    )
    stage.data("roto_breathers", numbers)
    title = "Roto-breathers: localized rotation without damping or load"
    return {"title": title, "paragraphs": paragraphs, "tables": tables, "figures": figures, "numbers": numbers}
