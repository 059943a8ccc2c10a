"""The phase diagram of static and rotating states in (parameter, M) (:mod:`cosserat_chain.experiments.diagram`)."""

from __future__ import annotations

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from matplotlib.figure import Figure  # noqa: E402


def diagram_figure(diagram) -> Figure:
    """Regions of a :class:`~cosserat_chain.experiments.diagram.StateDiagram` against the varied field.

    Below ``rotation_stops`` the particle rests; between it and M_c it rests or rotates
    (hysteresis: which depends on the load's history); above M_c it rotates. Values
    where an edge is unknown are left out of the regions and marked on the axis.
    """
    values = np.array([row.value for row in diagram.rows])
    fold = np.array([np.nan if row.static_fold is None else row.static_fold for row in diagram.rows])
    stops = np.array([np.nan if row.rotation_stops is None else row.rotation_stops for row in diagram.rows])
    # Each row in its own E1 h^2: the varied field may be E1 or h.
    scale = np.array([row.moment_scale for row in diagram.rows])
    fold, stops = fold / scale, stops / scale
    fig, ax = plt.subplots(figsize=(7.0, 4.5), constrained_layout=True)
    top = 1.25 * np.nanmax(fold) if np.isfinite(fold).any() else 1.0
    known = np.isfinite(fold) & np.isfinite(stops)
    ax.fill_between(values, 0.0, np.where(known, stops, np.nan), color="#cfe3f4", label="static")
    ax.fill_between(
        values, np.where(known, stops, np.nan), np.where(known, fold, np.nan), color="#f6d7a7", label="static or rotating (hysteresis)"
    )
    ax.fill_between(values, np.where(np.isfinite(fold), fold, np.nan), top, color="#f4c6c6", label="rotating")
    ax.plot(values, fold, "k-", marker="o", markersize=3, label="M_c (static fold)")
    ax.plot(values, stops, "k--", marker="s", markersize=3, label="rotation stops (falling load)")
    for row, value in zip(diagram.rows, values):
        if row.rotation_stops is not None:
            ax.annotate(
                row.end,
                (value, row.dimensionless(row.rotation_stops)),
                textcoords="offset points",
                xytext=(0, -12),
                ha="center",
                fontsize=7,
            )
    missing = values[~known]
    if missing.size:
        ax.plot(missing, np.zeros_like(missing), "rx", label="an edge not found")
    ax.set_xlabel(diagram.field)
    ax.set_ylabel("M / (E1 h^2)")
    ax.set_ylim(0.0, top)
    ax.set_title(f"{diagram.model} model: static and rotating states ({diagram.params.describe_ends()}, N = {diagram.params.N})")
    ax.legend(fontsize="small", loc="upper left")
    return fig
