"""The rotation characteristic: mean angular velocity of the rotating state against M, from periodic orbits.

Contract
--------
:func:`rotation_characteristic_figure` draws, from results already computed, the
mean angular velocity 2 pi k / T of the periodic orbits against M (stable solid,
unstable dashed), the static branch's end M_c as a dotted vertical line (the static
state, at zero angular velocity, exists up to it), where the continued orbit ceases
to exist, and optionally the relaxation sweep's steps, up (filled) and down (open):
together the two edges of the hysteresis loop. It never computes anything itself.
"""

from __future__ import annotations

from collections.abc import Sequence

import matplotlib.pyplot as plt
import numpy as np
from matplotlib.axes import Axes
from matplotlib.figure import Figure

from ..experiments.orbits import RotationCharacteristic
from ..experiments.sweep import SweepResult
from ..numerics.periodic import OrbitBranch
from .statics import MOMENT_LABEL, model_color, model_label


def _curve(ax: Axes, moment: np.ndarray, rate: np.ndarray, stable: np.ndarray, color: str, label: str) -> None:
    """Stable stretches solid, unstable dashed; consecutive stretches share their end point."""
    order = np.argsort(moment)
    moment, rate, stable = moment[order], rate[order], stable[order]
    edges = [0, *(np.flatnonzero(np.diff(stable.astype(int))) + 1).tolist(), len(moment)]
    for k, (lo, hi) in enumerate(zip(edges[:-1], edges[1:])):
        idx = np.arange(max(lo - 1, 0), hi)
        ax.plot(moment[idx], rate[idx], color=color, ls="-" if stable[lo] else "--", label=label if k == 0 else None)


def rotation_characteristic_figure(
    characteristic: RotationCharacteristic | None = None,
    *,
    branches: Sequence[OrbitBranch] = (),
    sweep: SweepResult | None = None,
    static_fold: float | None = None,
    model: str | None = None,
    ax: Axes | None = None,
    figsize: tuple[float, float] = (6.5, 4.5),
) -> Figure:
    """Mean angular velocity against M: orbits, static fold and (optionally) the relaxation sweep.

    Parameters
    ----------
    characteristic : RotationCharacteristic, optional
        Orbits at chosen moments (:func:`~cosserat_chain.experiments.orbits.rotation_characteristic`).
    branches : sequence of OrbitBranch
        Continuations (:func:`~cosserat_chain.numerics.periodic.continue_orbit`); the end of each is marked.
    sweep : SweepResult, optional
        Relaxation sweep up and down (:func:`~cosserat_chain.experiments.sweep.relaxation_sweep`).
    static_fold : float, optional
        M_c; by default the characteristic's. Every moment is drawn in units of E1 h^2 of the
        first chain given (characteristic, branches, sweep), the paper's dimensionless moment.
    model : str, optional
        Name for colours and labels; by default the characteristic's or the sweep's.
    ax : matplotlib Axes, optional

    Returns
    -------
    matplotlib.figure.Figure
    """
    if ax is None:
        fig, ax = plt.subplots(figsize=figsize, constrained_layout=True)
    else:
        fig = ax.figure
    name = model or (characteristic.model if characteristic is not None else sweep.model if sweep is not None else "")
    # Moments in units of E1 h^2 (the paper's dimensionless moment), as on every statics figure.
    chains = [
        *([characteristic.params] if characteristic is not None else []),
        *(branch.orbits[0].params for branch in branches),
        *([sweep.params] if sweep is not None else []),
    ]
    scale = chains[0].moment_scale if chains else 1.0
    color = model_color(name)
    label = model_label(name)
    if characteristic is not None:
        found = characteristic.found
        _curve(
            ax,
            characteristic.moment[found] / scale,
            characteristic.mean_angular_velocity[found],
            characteristic.stable[found],
            color,
            f"{label}: periodic orbits",
        )
        if static_fold is None:
            static_fold = characteristic.static_fold
    for branch in branches:
        _curve(
            ax,
            branch.moment / scale,
            branch.mean_angular_velocity,
            branch.stable,
            color,
            None if characteristic is not None else f"{label}: periodic orbits",
        )
        ax.plot(
            branch.end_moment / scale,
            branch.mean_angular_velocity[-1],
            "x",
            color=color,
            ms=9,
            mew=2,
            label=f"orbit ends ({branch.end}) at M / (E1 h^2) = {branch.end_moment / scale:.4g}",
        )
        if branch.stability_lost_at is not None:
            # The lower edge of the hysteresis loop: below it the rotating state is not observed.
            lost = branch.stability_lost_at / scale
            ax.axvline(lost, color=color, ls="--", lw=1, label=f"orbit loses stability at M / (E1 h^2) = {lost:.4g}")
    if static_fold is not None and np.isfinite(static_fold):
        fold = static_fold / scale
        ax.plot([0.0, fold], [0.0, 0.0], color=color, lw=2.5, alpha=0.6, label="static states")
        ax.axvline(fold, color=color, ls=":", lw=1, label=f"static fold $M_c / (E_1 h^2)$ = {fold:.4g}")
    if sweep is not None:
        rate = sweep.angular_velocity[:, sweep.params.N + sweep.particle]
        for direction, style in (("up", {"mfc": color}), ("down", {"mfc": "white"})):
            sel = (sweep.direction == direction) & np.isfinite(rate)
            ax.plot(
                sweep.moment[sel] / scale,
                rate[sel],
                "o" if direction == "up" else "s",
                color=color,
                mec=color,
                ms=5,
                ls="none",
                label=f"relaxation sweep, load {direction}",
                **style,
            )
    ax.set(xlabel=MOMENT_LABEL, ylabel="mean angular velocity of the loaded particle")
    ax.set_title("rotation characteristic (dashed: unstable orbits)", fontsize=10)
    ax.legend(fontsize=8)
    return fig
