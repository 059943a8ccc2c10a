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
    :func:`diagram_regions`: a region present at consecutive values is an area between them,
    one present at a value alone (or a diagram of one value) a bar at it, since an area
    would be empty there. Every region's artists carry its name as ``gid``, the two edges'
    lines ``static_fold`` and ``rotation_stops``.
    """
    regions = diagram_regions(diagram)
    values, top = regions["value"], float(regions["top"])
    fig, ax = plt.subplots(figsize=(7.0, 4.5), constrained_layout=True)
    for name, (color, label) in REGIONS.items():
        low, high = regions[name]
        drawn = np.isfinite(low) & np.isfinite(high)
        for run in _runs(drawn):
            if run.size > 1:
                ax.fill_between(values[run], low[run], high[run], color=color, label=label, gid=name)
            else:
                # A region at one value only (or a single value): an area between values would be empty there.
                ax.bar(
                    values[run], high[run] - low[run], bottom=low[run], width=_bar_width(values, run[0]), color=color, label=label, gid=name
                )
            label = None
    if values.size == 1:
        width = _bar_width(values, 0)
        ax.set_xlim(values[0] - 2 * width, values[0] + 2 * width)
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


def _runs(flags: np.ndarray) -> list[np.ndarray]:
    """Indices of each run of consecutive True values of ``flags``."""
    edges = np.flatnonzero(np.diff(np.concatenate([[0], flags.astype(int), [0]])))
    return [np.arange(start, stop) for start, stop in zip(edges[::2], edges[1::2])]


def _bar_width(values: np.ndarray, index: int) -> float:
    """Width of a region drawn at ``values[index]`` alone: half the distance to its nearest neighbour."""
    gaps = np.abs(np.delete(values, index) - values[index])
    gaps = gaps[gaps > 0]
    if gaps.size:
        return 0.5 * float(gaps.min())
    return 0.2 * abs(float(values[index])) if values[index] != 0 else 0.2
