"""Figures of the continuum theory (Section 3) and of the waves in the chain.

Contract
--------
:func:`plot_profiles` draws the continuum solution (11) against the discrete linear
statics (v_k and phi_k), :func:`plot_convergence` the relative error of phi_0 / M
and the residue (12) against N on log axes, :func:`plot_beam_convergence` the errors of
the Timoshenko beam and of eq. (11) against N, :func:`plot_dispersion` the branches
omega(q) with the transverse-rotational band gap shaded. Each takes the result
objects of :mod:`cosserat_chain.analysis.continuum` and
:mod:`cosserat_chain.analysis.dispersion` and an optional Axes, and returns the
Figure (:func:`cosserat_chain.io.write_figure` writes it). Nothing here solves anything.
"""

from __future__ import annotations

import numpy as np
from matplotlib.axes import Axes
from matplotlib.figure import Figure
from matplotlib.ticker import NullLocator

from ..analysis.continuum import ConvergenceTable, ProfileComparison
from ..analysis.dispersion import BRANCHES, Dispersion, WaveSummary
from ..analysis.exact_beam import BendingConvergence
from ..analysis.timoshenko import BeamConvergence

_BRANCH_LABELS = dict(zip(BRANCHES, ("longitudinal (u)", "transverse acoustic (v)", "rotational optical (phi)")))
_BRANCH_COLOURS = dict(zip(BRANCHES, ("tab:green", "tab:blue", "tab:red")))


def _figure(ax: Axes | None, ncols: int = 1) -> tuple[Figure, list[Axes]]:
    if ax is not None:
        return ax.figure, [ax]
    fig = Figure(figsize=(5.0 * ncols, 3.8), layout="constrained")
    return fig, list(np.atleast_1d(fig.subplots(1, ncols)))


#: A log axis spanning more decades than this has its decades ticked and labelled, and no minor ticks.
MINOR_DECADES = 3.0


def _ticks_at(panel: Axes, n: np.ndarray) -> None:
    """A log-log panel's x ticks at the computed N only, and no more tick marks than its reader needs.

    The minor ticks of the log axes (between N's that are not decades, or eight per decade on an error
    axis over ten or more) are marks without labels that each cost a tick's artists at every draw; the
    y axis keeps them where it spans few decades, where they may be its only labelled ticks.
    """
    panel.set_xticks(n, [str(int(v)) for v in n])
    panel.xaxis.set_minor_locator(NullLocator())
    low, high = panel.get_ylim()
    if low > 0 and high / low > 10.0**MINOR_DECADES:
        panel.yaxis.set_minor_locator(NullLocator())


def plot_profiles(comparison: ProfileComparison, axes: tuple[Axes, Axes] | None = None) -> Figure:
    """Continuum (lines) and discrete (markers) profiles v_k and phi_k over the particles.

    Parameters
    ----------
    comparison : ProfileComparison
        From :func:`cosserat_chain.analysis.continuum.compare_profiles`.
    axes : pair of Axes, optional
        For v and phi; default a new figure with two panels.
    """
    if axes is None:
        fig, panels = _figure(None, ncols=2)
    else:
        panels = list(axes)
        if len(panels) != 2:
            raise ValueError(f"axes must be a pair (v, phi), got {len(panels)} axes")
        fig = panels[0].figure
    for panel, row, name in zip(panels, (1, 2), ("v", "phi")):
        field = comparison.v if row == 1 else comparison.phi
        panel.plot(comparison.x, field, color="tab:blue", label="continuum (11)")
        panel.plot(comparison.k, comparison.sampled[row], "o", color="tab:blue", markerfacecolor="none", label=f"{name}(kh)")
        panel.plot(comparison.k, comparison.discrete[row], "x", color="tab:red", label="discrete eq. (3)")
        panel.set_xlabel("particle k")
        panel.set_ylabel(f"{name}_k")
        panel.axhline(0.0, color="0.7", linewidth=0.6)
    panels[0].legend(loc="best", fontsize="small")
    panels[0].set_title(f"M = {comparison.moment:g}", fontsize="small", loc="left")
    return fig


def plot_convergence(table: ConvergenceTable, ax: Axes | None = None) -> Figure:
    """Relative error of the continuum phi_0 / M and the residue (12) against N, log-log."""
    fig, (panel,) = _figure(ax)
    panel.loglog(table.N, table.relative_error, "o-", label="relative error of phi_0 / M")
    panel.loglog(table.N, table.residue, "s--", label="residue (12) per unit M")
    if table.N.size >= 2:
        reference = table.relative_error[0] * table.N[0] / table.N
        panel.loglog(table.N, reference, ":", color="0.5", label="1/N")
    panel.set_xlabel("N (chain of 2N+1 particles)")
    # Ticks at the computed N only: over less than a decade matplotlib labels the minor
    # ticks as well (3 x 10^0, 4 x 10^0, ...), and they overlap.
    _ticks_at(panel, table.N)
    panel.legend(loc="best", fontsize="small")
    return fig


def plot_beam_convergence(table: BeamConvergence, ax: Axes | None = None) -> Figure:
    """|relative error| of the loaded particle's compliance against N, log-log: the Timoshenko beam, eq. (11), and the discrete value's own.

    Guides 1/N and 1/N^2 (dotted) start a factor 3 below the first point of eq. (11) and of the beam. Errors
    that are not above the discrete value's own (the beam is exact for some loads) are not drawn.
    """
    fig, (panel,) = _figure(ax)
    floor = np.maximum(table.discrete_error, np.finfo(float).eps)
    for error, style, label, power in (
        (table.timoshenko_error, "o-", "Timoshenko beam", 2),
        (table.paper_error, "s-", "eq. (11)", 1),
    ):
        shown = np.isfinite(error) & (np.abs(error) > floor)
        if not shown.any():
            continue
        n, value = table.N[shown], np.abs(error[shown])
        (line,) = panel.loglog(n, value, style, label=label)
        if n.size >= 2:
            panel.loglog(n, value[0] / 3 * (n[0] / n) ** power, ":", color=line.get_color(), label=f"1/N^{power}" if power > 1 else "1/N")
    panel.loglog(table.N, floor, "x", color="0.5", label="discrete value's own error")
    panel.set_xlabel("N (chain of 2N+1 particles)")
    panel.set_ylabel(f"|relative error| of the compliance ({table.load})")
    _ticks_at(panel, table.N)
    panel.legend(loc="best", fontsize="small")
    return fig


def plot_bending(table: BendingConvergence, ax: Axes | None = None) -> Figure:
    """Errors of the exact beam's circle against model (i) bent by an end moment: the moment and the tip, against N, log-log."""
    fig, (panel,) = _figure(ax)
    for error, style, label in ((np.abs(table.moment_error), "o-", "end moment"), (table.tip_error, "s-", "tip position / 2L")):
        shown = error > 1e-13
        if shown.sum() >= 1:
            panel.loglog(table.N[shown], error[shown], style, label=label)
    n = table.N
    reference = np.abs(table.moment_error[0])
    if n.size >= 2 and reference > 0:
        panel.loglog(n, reference / 3 * (n[0] / n) ** 2, ":", color="0.5", label="1/N^2")
    panel.set_xlabel("N (chain of 2N+1 particles)")
    panel.set_ylabel("|relative error| of the beam")
    panel.set_title(f"cantilever, end turned by {table.angle:.3g} rad", fontsize="small", loc="left")
    _ticks_at(panel, n)
    panel.legend(loc="best", fontsize="small")
    return fig


def plot_continua(table: BeamConvergence, bending: BendingConvergence | None = None) -> Figure:
    """:func:`plot_beam_convergence` and, given the bending table, :func:`plot_bending` beside it."""
    fig, panels = _figure(None, ncols=1 if bending is None else 2)
    plot_beam_convergence(table, panels[0])
    if bending is not None:
        plot_bending(bending, panels[1])
    return fig


def plot_dispersion(
    curves: Dispersion,
    summary: WaveSummary | None = None,
    continuum: Dispersion | None = None,
    ax: Axes | None = None,
) -> Figure:
    """Branches omega(q) over [0, pi], the band gap shaded.

    Parameters
    ----------
    curves : Dispersion
        The discrete branches (:func:`cosserat_chain.analysis.dispersion.dispersion`).
    summary : WaveSummary, optional
        Its ``gap`` (transverse-rotational) is shaded, and its ``complete_gaps`` more darkly.
    continuum : Dispersion, optional
        Continuum branches, drawn dashed (where real).
    ax : Axes, optional
    """
    fig, (panel,) = _figure(ax)
    for row, name in enumerate(BRANCHES):
        panel.plot(curves.q, curves.omega[row], color=_BRANCH_COLOURS[name], label=_BRANCH_LABELS[name])
        if continuum is not None:
            panel.plot(continuum.q, continuum.omega[row], "--", color=_BRANCH_COLOURS[name], linewidth=0.9)
    if continuum is not None:
        panel.plot([], [], "--", color="0.3", linewidth=0.9, label="continuum (6)")
    if summary is not None:
        if summary.gap is not None:
            panel.axhspan(*summary.gap, color="tab:orange", alpha=0.2, label="v-phi band gap")
        for low, high in summary.complete_gaps:
            panel.axhspan(low, high, color="tab:orange", alpha=0.45)
    top = np.nanmax(curves.omega)
    panel.set_xlim(0.0, np.pi)
    panel.set_ylim(0.0, 1.08 * top)
    panel.set_xticks([0.0, np.pi / 2, np.pi], ["0", "pi/2", "pi"])
    panel.set_xlabel("wavenumber q per particle")
    panel.set_ylabel("angular frequency omega")
    panel.legend(loc="best", fontsize="small")
    return fig
