"""Maps and lines of a parameter study's results (matplotlib only; nothing is computed here)."""

from __future__ import annotations

from typing import TYPE_CHECKING

import matplotlib.pyplot as plt
import numpy as np
from matplotlib.figure import Figure

from .statics import model_color

if TYPE_CHECKING:  # xarray is imported where a Dataset is built or read: commands without file output start without it
    import xarray as xr

#: Swept fields are the study Dataset's dimensions other than these.
_NON_PARAMETER_DIMS = ("model", "load")


def study_figure(ds: xr.Dataset, quantities: list[str] | None = None) -> Figure:
    """Lines over one swept field, or maps over two (one panel per quantity and model); a study of one
    cell as points.

    With ``mean_angular_velocity`` in the study, the regime at each of its loads is
    drawn too: 1 where the loaded particle rotates, 0 where the chain comes to rest.

    Parameters
    ----------
    ds : xarray.Dataset
        A study result (:func:`~cosserat_chain.study_runner.run_study`).
    quantities : list of str, optional
        Default: every scalar quantity of the study.

    Raises
    ------
    ValueError
        If the study sweeps more than two fields (select a slice first, e.g. ``ds.isel(N=0)``).
    """
    swept = [d for d in ds.dims if d not in _NON_PARAMETER_DIMS and ds.sizes[d] > 1]
    if len(swept) > 2:
        raise ValueError(f"a figure shows one or two swept fields; this study sweeps {swept}: select a slice first")
    if not swept:
        # One cell: its values as points (markers) at the first field's one value, not an empty map.
        swept = [d for d in ds.dims if d not in _NON_PARAMETER_DIMS][:1]
    ds = _with_regimes(ds.squeeze([d for d in ds.dims if d not in _NON_PARAMETER_DIMS and d not in swept]))
    quantities = quantities or [name for name in ds.data_vars if name not in ("done", "error") and "load" not in ds[name].dims]
    models = list(ds.model.values)
    if len(swept) == 1:
        fig, axes = plt.subplots(1, len(quantities), figsize=(4.2 * len(quantities), 3.6), squeeze=False, constrained_layout=True)
        for ax, name in zip(axes[0], quantities):
            for model in models:
                ax.plot(ds[swept[0]], ds[name].sel(model=model), "o-", color=model_color(str(model)), label=str(model))
            ax.set(xlabel=swept[0], title=name)
            if _is_log(ds[swept[0]].values):
                ax.set_xscale("log")
        axes[0][0].legend(fontsize=8)
        return fig
    fig, axes = plt.subplots(
        len(models), len(quantities), figsize=(4.2 * len(quantities), 3.6 * len(models)), squeeze=False, constrained_layout=True
    )
    for row, model in zip(axes, models):
        for ax, name in zip(row, quantities):
            values = ds[name].sel(model=model).transpose(swept[1], swept[0])
            mesh = ax.pcolormesh(ds[swept[0]], ds[swept[1]], values, shading="nearest")
            fig.colorbar(mesh, ax=ax)
            ax.set(xlabel=swept[0], ylabel=swept[1], title=f"{name} ({model})")
            for dim, setter in ((swept[0], ax.set_xscale), (swept[1], ax.set_yscale)):
                if _is_log(ds[dim].values):
                    setter("log")
    return fig


def _with_regimes(ds: xr.Dataset) -> xr.Dataset:
    """Add ``regime at M=...`` per load of ``mean_angular_velocity``: 1 rotating, 0 at rest, NaN not settled."""
    import xarray as xr

    if "mean_angular_velocity" not in ds:
        return ds
    rate = ds["mean_angular_velocity"]
    regime = xr.where(np.isfinite(rate), (np.abs(rate) > 0).astype(float), np.nan)
    return ds.assign({f"regime at M={float(load):g}": regime.sel(load=load, drop=True) for load in rate["load"].values})


def _is_log(values: np.ndarray) -> bool:
    """Values evenly spaced on a log scale (and not on a linear one)."""
    values = np.asarray(values, dtype=float)
    if len(values) < 3 or np.any(values <= 0):
        return False
    return bool(
        np.allclose(np.diff(np.log(values)), np.log(values[1] / values[0])) and not np.allclose(np.diff(values), values[1] - values[0])
    )
