"""A roto-breather family against the bands: tail amplitude and stability versus the frequency Omega.

Contract
--------
:func:`breather_family_figure` draws, from a computed
:class:`~cosserat_chain.experiments.breathers.BreatherFamily`, the amplitude of the
non-rotating particles (the tail) and the largest Floquet multiplier modulus against
Omega (stable orbits filled, unstable open), and, where the family's lifetimes were measured
(:meth:`~cosserat_chain.experiments.breathers.BreatherFamily.measure_lifetimes`), each member's
lifetime in periods against ln(threshold / eps) / ln max|mu|, with the frequency windows where a harmonic
n Omega lies in a driven band shaded and the resonances n Omega = band edge as dotted
lines. :func:`breather_atlas_figure` draws the existence map of a
:class:`~cosserat_chain.experiments.breather_atlas.BreatherAtlas` over (Omega, field): stable
orbits filled, unstable open, none found crossed, coloured by their participation ratio, on the
windows n Omega inside a driven band (n = 1..3) shaded between the edges' harmonics;
:func:`system_atlas_figure` the same map of a user system's
:class:`~cosserat_chain.experiments.system_breather_atlas.SystemBreatherAtlas`, against its
bands about rest. Where the atlas's lifetimes were measured (``measure_lifetimes``) both add
a second panel below the map: each orbit's lifetime over (Omega, field), coloured by log10 of
its periods, the orbits that outlived the run as triangles. Where the atlas's changes of
stability were located (``locate_changes``) both mark each as a red bar with its accuracy as the
error bar (too small to see, mostly: the change's place is the point): on its row where it was
located along Omega, on its column where along the field. None
computes anything itself.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import matplotlib.pyplot as plt
import numpy as np
from matplotlib.figure import Figure

from ..experiments.breather_atlas import BreatherAtlas
from ..experiments.breathers import BreatherFamily, band_edges

if TYPE_CHECKING:  # only its type: a user system's atlas is drawn from the object handed in
    from ..experiments.system_breather_atlas import SystemBreatherAtlas

#: One colour per band of :data:`~cosserat_chain.analysis.dispersion.BRANCHES`.
BAND_COLORS = {"longitudinal": "tab:green", "transverse_acoustic": "tab:blue", "rotational_optical": "tab:red"}


def breather_family_figure(result: BreatherFamily) -> Figure:
    """Tail amplitude and max |mu| against Omega, the bands' harmonic windows shaded, the located changes of stability dashed.

    Parameters
    ----------
    result : BreatherFamily
        With at least one orbit.

    Returns
    -------
    Figure
    """
    family = result.family
    omega = family.omega
    lives = result.lifetimes
    if lives is None:
        fig, (top, bottom) = plt.subplots(2, 1, sharex=True, figsize=(6.4, 5.6))
    else:
        fig, (top, bottom, below) = plt.subplots(3, 1, sharex=True, figsize=(6.4, 7.8))
        _lifetimes_panel(below, omega, lives)
    stable = family.stable
    top.plot(omega, result.localization(), color="k", lw=1)
    bottom.plot(omega, family.max_multiplier, color="k", lw=1)
    bottom.scatter(omega[stable], family.max_multiplier[stable], color="k", s=12, label="stable")
    bottom.scatter(omega[~stable], family.max_multiplier[~stable], facecolor="none", edgecolor="k", s=12, label="unstable")
    low, high = (float(omega.min()), float(omega.max())) if omega.size else (0.0, 1.0)
    span = max(high - low, 1e-3)
    bands = band_edges(family.orbits[0].params) if family.orbits else {}
    for band in result.bands:
        bottom_edge, top_edge = bands.get(band, (0.0, 0.0))
        for n in range(1, 7):
            a, b = bottom_edge / n, top_edge / n
            if b >= low - 0.05 * span and a <= high + 0.05 * span:
                for ax in (top, bottom):
                    ax.axvspan(max(a, low - 0.05 * span), min(b, high + 0.05 * span), color=BAND_COLORS[band], alpha=0.12, lw=0)
                top.text(
                    0.5 * (max(a, low) + min(b, high)),
                    1.0,
                    f"{n}Ω",
                    transform=top.get_xaxis_transform(),
                    ha="center",
                    va="bottom",
                    fontsize=7,
                )
    for r in result.resonances:
        for ax in (top, bottom):
            ax.axvline(r.omega, color=BAND_COLORS[r.band], ls=":", lw=0.8)
    for i, change in enumerate(result.changes):
        bottom.axvline(change.omega, color="tab:red", ls="--", lw=0.9, label="change of stability (discriminant)" if i == 0 else None)
    for band in result.bands:
        bottom.plot([], [], color=BAND_COLORS[band], alpha=0.4, lw=6, label=f"n Ω in {band.replace('_', ' ')}")
    top.set_ylabel("tail amplitude (max |q| off the rotor)")
    bottom.set_ylabel("max nontrivial |μ|")
    bottom.set_yscale("log")
    (bottom if lives is None else below).set_xlabel("Ω (mean angular velocity of the rotor)")
    bottom.legend(fontsize=7)
    top.set_xlim(low - 0.05 * span, high + 0.05 * span)
    fig.tight_layout()
    return fig


def _lifetimes_panel(ax, omega: np.ndarray, lives: list) -> None:
    """Lifetime in periods against Omega: lost members filled, survivors as a triangle at the run's length, ln(threshold/eps)/ln|mu| crossed."""
    lost = np.array([life.periods is not None for life in lives])
    periods = np.array([life.run_periods if life.periods is None else life.periods for life in lives], dtype=float)
    predicted = np.array([life.predicted_periods for life in lives])
    ax.scatter(omega[lost], periods[lost], color="k", s=14, label="lifetime (direct run)")
    ax.scatter(omega[~lost], periods[~lost], marker="^", color="tab:green", s=18, label="stayed for the whole run")
    ax.scatter(omega, predicted, marker="x", color="tab:red", s=16, label="ln(threshold/ε) / ln max|μ|")
    ax.set_yscale("log")
    ax.set_ylabel("lifetime (periods)")
    ax.legend(fontsize=7)


#: Harmonics n whose windows n Omega in a band the atlas figure shades.
ATLAS_HARMONICS = 3


def breather_atlas_figure(atlas: BreatherAtlas) -> Figure:
    """The existence map over (Omega, field value) against the bands' harmonics.

    Parameters
    ----------
    atlas : BreatherAtlas

    Returns
    -------
    Figure
    """
    fig, ax, below, lives = _atlas_axes(atlas)
    values, omegas = atlas.values, atlas.omegas
    order = np.argsort(values)
    resonance = atlas.resonance_omegas()
    low, high = float(omegas.min()), float(omegas.max())
    span = max(high - low, 1e-3)
    for b, band in enumerate(atlas.bands):
        for n in range(ATLAS_HARMONICS):
            bottom, top = resonance[order, b, 0, n], resonance[order, b, 1, n]
            if np.all(top < low - 0.05 * span) or np.all(bottom > high + 0.05 * span):
                continue
            ax.fill_betweenx(values[order], bottom, top, color=BAND_COLORS[band], alpha=0.12, lw=0)
            ax.text(float(np.mean(0.5 * (bottom + top))), float(values[order][-1]), f"{n + 1}Ω", fontsize=7, ha="center", va="bottom",
                    color=BAND_COLORS[band])  # fmt: skip
        ax.plot([], [], color=BAND_COLORS[band], alpha=0.4, lw=6, label=f"n Ω in {band.replace('_', ' ')}")
    title = f"roto-breathers, {atlas.model} model, N = {atlas.params.N}"
    xlim = (low - 0.05 * span, high + 0.05 * span)
    return _atlas_map(
        fig, ax, below, lives, atlas, xlim, "participation ratio of the energies", "Ω (mean angular velocity of the rotor)", title
    )


def system_atlas_figure(atlas: SystemBreatherAtlas) -> Figure:
    """A user system's existence map over (Omega, parameter value) against its bands' harmonics.

    Parameters
    ----------
    atlas : SystemBreatherAtlas

    Returns
    -------
    Figure
    """
    fig, ax, below, lives = _atlas_axes(atlas)
    values, omegas = atlas.values, atlas.omegas
    order = np.argsort(values)
    bands = atlas.bands()
    low, high = float(omegas.min()), float(omegas.max())
    span = max(high - low, 1e-3)
    for b in range(max((len(row) for row in bands), default=0)):
        edges = np.array([bands[j][b] if b < len(bands[j]) else (np.nan, np.nan) for j in order])
        color = plt.get_cmap("tab10")(b % 10)
        for n in range(1, ATLAS_HARMONICS + 1):
            bottom, top = edges[:, 0] / n, edges[:, 1] / n
            if np.all(~(top >= low - 0.05 * span)) or np.all(~(bottom <= high + 0.05 * span)):
                continue
            ax.fill_betweenx(values[order], bottom, top, color=color, alpha=0.15, lw=0)
            ax.text(float(np.nanmean(0.5 * (bottom + top))), float(values[order][-1]), f"{n}Ω", fontsize=7, ha="center", va="bottom",
                    color=color)  # fmt: skip
        ax.plot([], [], color=color, alpha=0.4, lw=6, label=f"n Ω in band {b}")
    rotors = ", ".join(f"{atlas.system.coordinates[i]} ({k:+d})" for i, k in atlas.rotors.items())
    title = f"roto-breathers of {atlas.system.name}: {rotors}"
    xlim = (low - 0.05 * span, high + 0.05 * span)
    ratio = "participation ratio of the kinetic energies"
    return _atlas_map(fig, ax, below, lives, atlas, xlim, ratio, "Ω (mean angular velocity of the first rotor)", title)


def _atlas_map(fig: Figure, ax, below, lives, atlas, xlim: tuple[float, float], ratio_label: str, xlabel: str, title: str) -> Figure:
    """Both atlases' map on its shaded bands: stable orbits filled and coloured by their participation ratio
    (``ratio_label`` on the colour bar), unstable ones open, points with none found crossed, the located changes of
    stability; the labels, the legend below the axes (inside, it hides points) and, where measured, the lifetimes
    panel ``below``."""
    values, omegas = atlas.values, atlas.omegas
    exists = atlas.grid("exists") > 0
    stable = atlas.grid("stable") > 0
    ratio = atlas.grid("participation_ratio")
    om, va = np.meshgrid(omegas, values)
    finite = ratio[exists]
    norm = plt.Normalize(float(finite.min()), float(finite.max()) + 1e-12) if finite.size else None
    filled = ax.scatter(om[exists & stable], va[exists & stable], c=ratio[exists & stable], cmap="viridis", norm=norm, s=30,
                        edgecolor="k", label="stable")  # fmt: skip
    ax.scatter(om[exists & ~stable], va[exists & ~stable], facecolor="none", edgecolor=plt.get_cmap("viridis")(norm(ratio[exists & ~stable]))
               if norm else "k", s=30, lw=1.5, label="unstable")  # fmt: skip
    ax.scatter(om[~exists], va[~exists], marker="x", color="0.4", s=20, label="not found")
    _atlas_changes(ax, atlas)
    if finite.size:
        fig.colorbar(filled, ax=ax, label=ratio_label)
    ax.set_xlim(*xlim)
    ax.set_xlabel(xlabel)
    ax.set_ylabel(atlas.field)
    ax.set_title(title, fontsize=9)
    ax.legend(fontsize=7, loc="upper center", bbox_to_anchor=(0.5, -0.14), ncol=3)
    if lives is not None:
        _atlas_lifetimes(fig, below, lives, atlas, ax)
    fig.tight_layout()
    return fig


def _atlas_changes(ax, atlas) -> None:
    """The atlas's located changes of stability: those along Omega on their rows (a vertical bar, the accuracy in Omega),
    those along the field on their columns (a horizontal bar, the accuracy in the field); nothing where none were located."""
    for along_omega, marker, label in (
        (True, "|", "stability changes (located)"),
        (False, "_", f"stability changes along {atlas.field} (located)"),
    ):
        changes = [c for c in atlas.changes or [] if (c.axis == "omega") == along_omega]
        if not changes:
            continue
        omega = np.array([c.omega for c in changes])
        value = np.array([c.value for c in changes])
        accuracy = {"xerr" if along_omega else "yerr": np.array([c.accuracy for c in changes])}
        ax.errorbar(omega, value, **accuracy, fmt=marker, color="tab:red", ms=14, mew=1.5, capsize=3, label=label)


def atlas_lifetime_grid(atlas) -> tuple[np.ndarray, np.ndarray] | None:
    """(value, omega) grids of the measured lifetimes in periods (the run's length for a survivor, NaN where no orbit) and of
    whether the orbit outlived the run; None where no lifetime was measured."""
    points = [p for row in atlas.points for p in row]
    if all(p.lifetime is None for p in points):
        return None
    periods = np.full((len(atlas.values), len(atlas.omegas)), np.nan)
    stayed = np.zeros(periods.shape, dtype=bool)
    for j, row in enumerate(atlas.points):
        for i, p in enumerate(row):
            if p.lifetime is not None:
                stayed[j, i] = p.lifetime.periods is None
                periods[j, i] = p.lifetime.run_periods if stayed[j, i] else p.lifetime.periods
    return periods, stayed


def _atlas_axes(atlas):
    """The figure, the map's axes and, where lifetimes were measured, axes below for them and their grids (else None, None)."""
    lives = atlas_lifetime_grid(atlas)
    if lives is None:
        fig, ax = plt.subplots(figsize=(7.0, 4.8))
        return fig, ax, None, None
    fig, (ax, below) = plt.subplots(2, 1, figsize=(7.0, 9.2))
    return fig, ax, below, lives


def _atlas_lifetimes(fig: Figure, ax, lives: tuple[np.ndarray, np.ndarray], atlas, above) -> None:
    """The lifetimes over (Omega, value) on ``ax``, under the map's axes ``above``: coloured by log10 of the periods, survivors as triangles."""
    periods, stayed = lives
    om, va = np.meshgrid(atlas.omegas, atlas.values)
    measured = np.isfinite(periods)
    lost = measured & ~stayed
    norm = plt.Normalize(0.0, float(np.log10(np.nanmax(periods))) + 1e-12)
    shown = ax.scatter(om[lost], va[lost], c=np.log10(periods[lost]), cmap="magma", norm=norm, s=30, edgecolor="k", label="lost after")
    ax.scatter(om[measured & stayed], va[measured & stayed], marker="^", color="tab:green", s=34, edgecolor="k",
               label="stayed for the whole run")  # fmt: skip
    ax.scatter(om[~measured], va[~measured], marker="x", color="0.4", s=20, label="no orbit")
    fig.colorbar(shown, ax=ax, label="log10 lifetime (periods)")
    run = atlas.settings.get("lifetime", {})
    ax.set_title(
        f"lifetimes: direct runs from the orbits perturbed by {run.get('perturbation', 'ε')}, lost at a deviation of "
        f"{run.get('threshold', '?')}, for up to {run.get('max_periods', '?')} periods",
        fontsize=8,
    )
    ax.set_xlim(*above.get_xlim())
    ax.set_xlabel(above.get_xlabel())
    ax.set_ylabel(atlas.field)
    ax.legend(fontsize=7, loc="upper center", bbox_to_anchor=(0.5, -0.14), ncol=3)
