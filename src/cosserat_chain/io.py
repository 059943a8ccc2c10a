"""Files: NetCDF results written atomically, and TOML configuration files.

Contract
--------
:func:`write_dataset` writes an xarray Dataset to NetCDF (h5netcdf), and
:func:`write_text` a text file, through :func:`atomic_path`: a temporary file in
the same folder and an atomic rename, so that a reader never sees a half-written file. :func:`load_params` reads ``ChainParams`` fields from
a TOML file (top-level keys, the paper's symbols) and names any unknown key.
"""

from __future__ import annotations

import os
import tempfile
import tomllib
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import xarray as xr

from .params import ChainParams


@contextmanager
def atomic_path(path: str | Path) -> Iterator[Path]:
    """A temporary file beside ``path`` (same extension), renamed onto it if the block succeeds.

    A reader never sees a half-written file, and an interrupted write leaves none
    behind. The file gets the usual permissions (mkstemp creates it 0600).
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.stem}.", suffix=path.suffix, dir=path.parent)
    os.close(fd)
    try:
        yield Path(tmp)
        umask = os.umask(0)
        os.umask(umask)
        os.chmod(tmp, 0o666 & ~umask)
        os.replace(tmp, path)
    finally:
        if os.path.exists(tmp):
            os.unlink(tmp)


def write_dataset(dataset: xr.Dataset, path: str | Path) -> Path:
    """Write ``dataset`` to NetCDF at ``path`` atomically; returns the path.

    Attribute values that are subclasses of ``str`` (a :class:`~cosserat_chain.status.Status`)
    are written as plain strings: h5netcdf finds no conversion for them.
    """
    dataset = dataset.copy()
    for attrs in [dataset.attrs, *(variable.attrs for variable in dataset.variables.values())]:
        attrs.update({key: str(value) for key, value in attrs.items() if isinstance(value, str) and type(value) is not str})
    with atomic_path(path) as tmp:
        dataset.to_netcdf(tmp, engine="h5netcdf")
    return Path(path)


def write_text(text: str, path: str | Path) -> Path:
    """Write ``text`` (UTF-8) to ``path`` atomically; returns the path."""
    with atomic_path(path) as tmp:
        tmp.write_text(text, encoding="utf-8")
    return Path(path)


def stack_models(datasets: dict[str, xr.Dataset]) -> xr.Dataset:
    """One Dataset with a ``model`` dimension from per-model results of the same experiment.

    Dimensions of different lengths (e.g. the points of each model's branch) are
    padded with NaN; attributes that differ between models (the model's name and
    equation) are dropped, and the names are the ``model`` coordinate.
    """
    if len(datasets) == 1:
        return next(iter(datasets.values()))
    stacked = xr.concat(list(datasets.values()), dim="model", join="outer", combine_attrs="drop_conflicts")
    return stacked.assign_coords(model=list(datasets))


def read_dataset(path: str | Path) -> xr.Dataset:
    """Load a NetCDF result written by :func:`write_dataset` into memory."""
    with xr.open_dataset(path, engine="h5netcdf") as ds:
        return ds.load()


def read_config(path: str | Path) -> dict[str, Any]:
    """Parse a TOML file into a dict.

    Raises
    ------
    ValueError
        If the file does not exist or is not valid TOML.
    """
    path = Path(path)
    try:
        with path.open("rb") as fh:
            return tomllib.load(fh)
    except FileNotFoundError:
        raise ValueError(f"config file {str(path)!r} does not exist") from None
    except tomllib.TOMLDecodeError as err:
        raise ValueError(f"config file {str(path)!r} is not valid TOML: {err}") from None


def params_from_mapping(mapping: dict[str, Any], source: str = "config") -> ChainParams:
    """Validated ``ChainParams`` from a mapping of field names.

    Raises
    ------
    ValueError
        Naming an unknown (e.g. misspelled) key and listing the allowed ones, or
        the field, value and rule of an invalid value.
    """
    allowed = list(ChainParams.model_fields)
    unknown = [key for key in mapping if key not in allowed]
    if unknown:
        raise ValueError(f"unknown key(s) {unknown} in {source}; allowed keys: {', '.join(allowed)}")
    return ChainParams(**mapping)


def load_params(path: str | Path | None = None) -> ChainParams:
    """``ChainParams`` from a TOML file, or the paper's defaults when ``path`` is None."""
    if path is None:
        return ChainParams()
    return params_from_mapping(read_config(path), source=str(path))
