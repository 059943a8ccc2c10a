"""The phase diagram of static and rotating states in (parameter, M) (:mod:`cosserat_chain.experiments.diagram`)."""

from __future__ import annotations

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from matplotlib.figure import Figure  # noqa: E402

#: Colour of each region of :func:`diagram_figure`, keyed by the ``gid`` of its artists.
REGIONS = {
    "static": ("#cfe3f4", "static"),
    "hysteresis": ("#f6d7a7", "static or rotating (hysteresis)"),
    "rotating": ("#f4c6c6", "rotating"),
}


def diagram_regions(diagram) -> dict[str, np.ndarray]:
    """Lower and upper edge of each region at each value of the varied field, in units of E1 h^2.

    Returns
    -------
    dict
        ``"value"``: the values, shape (k,); for each region of :data:`REGIONS`, an array of
        shape (2, k) (lower and upper edge, NaN where the region is absent at that value).
        ``static``: 0 up to the lower of M_c and where the rotation stops (no static state
        exists above M_c, and below where the rotation stops the chain rests); ``hysteresis``:
        from where the rotation stops up to M_c, where it stops below M_c; ``rotating``: M_c up
        to the top of the axes, ``top``. A value whose lower edge is unknown has no static or
        hysteresis region (whether the chain rests below M_c is not known there).
    """
    values = np.array([row.value for row in diagram.rows], dtype=float)
    fold = np.array([np.nan if row.static_fold is None else row.dimensionless(row.static_fold) for row in diagram.rows], dtype=float)
    stops = np.array([np.nan if row.rotation_stops is None else row.dimensionless(row.rotation_stops) for row in diagram.rows], dtype=float)
    top = 1.25 * np.nanmax(np.concatenate([fold, stops])) if np.isfinite(np.concatenate([fold, stops])).any() else 1.0
    known = np.isfinite(fold) & np.isfinite(stops)
    nan = np.full_like(values, np.nan)
    lower = np.where(known, np.minimum(stops, fold), nan)
    open_loop = known & (stops < fold)
    return {
        "value": values,
        "static_fold": fold,
        "rotation_stops": stops,
        "top": np.array(top),
        "static": np.array([np.where(known, 0.0, nan), lower]),
        "hysteresis": np.array([np.where(open_loop, stops, nan), np.where(open_loop, fold, nan)]),
        "rotating": np.array([fold, np.where(np.isfinite(fold), top, nan)]),
    }


def diagram_figure(diagram) -> Figure:
    """Regions of a :class:`~cosserat_chain.experiments.diagram.StateDiagram` against the varied field.

    Below ``rotation_stops`` the particle rests; between it and M_c it rests or rotates
    (hysteresis: which depends on the load's history); above M_c it rotates (no static
    state exists there, also where the followed orbit stops above M_c). Values where an
    edge is unknown are left out of the regions and marked on the axis. The regions are
    :func:`diagram_regions`; with one value they are drawn as a bar at it, with several as
    areas between the values. Every region's artists carry its name as ``gid``, the two
    edges' lines ``static_fold`` and ``rotation_stops``.
    """
    regions = diagram_regions(diagram)
    values, top = regions["value"], float(regions["top"])
    fig, ax = plt.subplots(figsize=(7.0, 4.5), constrained_layout=True)
    if values.size == 1:
        # One value: an area between values would be empty, so each region is a bar at it.
        width = 0.2 * abs(values[0]) if values[0] != 0 else 0.2
        for name, (color, label) in REGIONS.items():
            low, high = regions[name][:, 0]
            if np.isfinite(low) and np.isfinite(high):
                ax.bar(values, [high - low], bottom=[low], width=width, color=color, label=label, gid=name)
        ax.set_xlim(values[0] - 2 * width, values[0] + 2 * width)
    else:
        for name, (color, label) in REGIONS.items():
            low, high = regions[name]
            ax.fill_between(values, low, high, color=color, label=label, gid=name)
    ax.plot(values, regions["static_fold"], "k-", marker="o", markersize=5, label="M_c (static fold)", gid="static_fold")
    ax.plot(values, regions["rotation_stops"], "k--", marker="s", markersize=5, label="rotation stops (falling load)", gid="rotation_stops")
    for row, value, stops in zip(diagram.rows, values, regions["rotation_stops"]):
        if np.isfinite(stops):
            ax.annotate(row.end, (value, stops), textcoords="offset points", xytext=(0, -12), ha="center", fontsize=7)
    missing = values[~(np.isfinite(regions["static_fold"]) & np.isfinite(regions["rotation_stops"]))]
    if missing.size:
        ax.plot(missing, np.zeros_like(missing), "rx", label="an edge not found", gid="edge_not_found")
    ax.set_xlabel(diagram.field)
    ax.set_ylabel("M / (E1 h^2)")
    ax.set_ylim(0.0, top)
    ax.set_title(f"{diagram.model} model: static and rotating states ({diagram.params.describe_ends()}, N = {diagram.params.N})")
    ax.legend(fontsize="small", loc="upper left")
    return fig
