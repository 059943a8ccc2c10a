"""Checkpoints of long runs, the one mechanism that ``rotate`` and ``simulate`` share.

Contract
--------
A checkpoint is a NetCDF Dataset written atomically (:func:`cosserat_chain.io.write_dataset`:
a temporary file beside the target, then a rename; never onto a folder, a FIFO or a device).
:func:`seal` marks it with its experiment, its layout version and the SHA-256 of what a
resumed run reads (every variable and the named state attributes); :func:`open_checkpoint`
reads it back and refuses, with a ValueError naming the file and the reason, one that is
unreadable, of another experiment or version, written for other settings (naming the first
field that differs, ``params.E2`` for a parameter) or altered after it was written.
:class:`CheckpointClock` says when the next write is due (every so many seconds of wall time);
a write that fails (a full disk) is logged and the run goes on: the checkpoint is a safety
net, and the run's result is still saved (or kept in a fallback file) at the end.
"""

from __future__ import annotations

import hashlib
import json
import logging
import math
import time as clock
from collections.abc import Iterable, Mapping
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from ..inputs import InputFileError, check_counts, check_finite
from ..io import OutputError, read_dataset, write_dataset

if TYPE_CHECKING:  # xarray is imported where a Dataset is built or read: commands without file output start without it
    import xarray as xr

log = logging.getLogger(__name__)


def checksum(ds: xr.Dataset, state_attributes: Iterable[str]) -> str:
    """SHA-256 of what a resumed run reads: every variable's values (dtype, shape, bytes) and the state attributes.

    A checkpoint edited by hand or damaged on disk then fails its check instead of
    being trusted (NetCDF keeps the values bit for bit, so a sound file always passes).
    Signed integers count as 64-bit ones: the file holds those that fit as 32-bit ones
    (CF-1.8 has no 64-bit type: :func:`~cosserat_chain.io.netcdf_image`).
    """
    digest = hashlib.sha256()
    for name in sorted(map(str, ds.variables)):
        values = np.ascontiguousarray(ds[name].values)
        values = values.astype(np.int64) if values.dtype.kind == "i" else values
        digest.update(f"{name}:{values.dtype.str}:{values.shape}:".encode())
        digest.update(values.tobytes())
    for key in state_attributes:
        digest.update(f"{key}={_plain(ds.attrs.get(key))!r};".encode())
    return digest.hexdigest()


def seal(ds: xr.Dataset, experiment: str, version: int, state_attributes: Iterable[str]) -> xr.Dataset:
    """Mark ``ds`` (in place) as a checkpoint of ``experiment`` in layout ``version``, with its checksum; returns it."""
    ds.attrs.update({"experiment": experiment, "checkpoint_format": version})
    ds.attrs["checkpoint_sha256"] = checksum(ds, state_attributes)
    return ds


def params_settings(params: Any) -> dict[str, Any]:
    """A chain's parameters as settings to compare, ``params.<field>``, as the checkpoint's ``params_json`` gives them back.

    Through JSON, so that a graded chain's factors (tuples) compare with the lists JSON returns.
    """
    return {f"params.{key}": value for key, value in json.loads(json.dumps(params.model_dump())).items()}


def saved_settings(ds: xr.Dataset, keys: Iterable[str]) -> dict[str, Any]:
    """The settings a checkpoint was written for: ``params.<field>`` from ``params_json``, the others from the attributes."""
    params = json.loads(ds.attrs.get("params_json", "{}"))
    return {key: params.get(key[len("params.") :]) if key.startswith("params.") else _plain(ds.attrs.get(key)) for key in keys}


def open_checkpoint(
    path: str | Path,
    experiment: str,
    version: int,
    expected: Mapping[str, Any],
    state_attributes: Iterable[str],
    *,
    kind: str,
    counts: Iterable[str] = ("steps",),
    total: str | None = None,
    state_variables: Iterable[str] = (),
    variables: Iterable[str] = (),
) -> xr.Dataset:
    """Read the checkpoint at ``path`` for a run with the settings ``expected``, or refuse it.

    Parameters
    ----------
    path : path
    experiment : str
        The ``experiment`` attribute the checkpoint must carry.
    version : int
        Its layout version (``checkpoint_format``).
    expected : mapping
        This run's settings by name: ``params.<field>`` for a parameter, otherwise an
        attribute of the checkpoint; compared for equality, in order.
    state_attributes : iterable of str
        The attributes its checksum covers (as given to :func:`seal`).
    kind : str
        What the checkpoint is, for the messages (``"localization-run"``).
    counts : iterable of str
        Attributes that are step counts: whole numbers >= 0 (:func:`cosserat_chain.inputs.check_counts`).
    total : str, optional
        The count that ``steps`` may not pass (the run's number of steps).
    state_variables : iterable of str
        Variables of the state the resumed run reads: present, real and finite.
    variables : iterable of str
        Other variables it reads: present (their values may be NaN, as a time not reached yet).

    Raises
    ------
    ValueError
        If the file cannot be read, is not such a checkpoint, was written for other
        settings (naming the first that differs, both values), was altered after it
        was written, or holds step counts or a state no run could have written (a
        checkpoint edited and sealed again: "from step -5").
    """
    path = Path(path)
    try:
        ds = read_dataset(path)
    except ValueError as err:
        raise ValueError(f"cannot resume from the checkpoint: {err}; start afresh without --resume (or with --force)") from None
    if ds.attrs.get("experiment") != experiment or _plain(ds.attrs.get("checkpoint_format")) != version:
        raise ValueError(
            f"{str(path)!r} is not a {kind} checkpoint of format {version} "
            f"(experiment={ds.attrs.get('experiment')!r}, checkpoint_format={ds.attrs.get('checkpoint_format')!r})"
        )
    try:
        saved = saved_settings(ds, expected)
    except (ValueError, TypeError, AttributeError) as err:  # params_json that is not a JSON object
        raise ValueError(f"{str(path)!r} is not a readable {kind} checkpoint: its params_json is damaged ({err})") from None
    for key, value in expected.items():
        try:
            differs = bool(saved[key] != value)
        except (ValueError, TypeError):  # an attribute edited into an array compares element-wise
            differs = True
        if differs:
            raise ValueError(
                f"checkpoint {str(path)!r} was written for {key}={saved[key]!r}, but this run has {key}={value!r}; "
                "resume with the same settings or use another checkpoint file"
            )
    if ds.attrs.get("checkpoint_sha256") != checksum(ds, state_attributes):
        raise ValueError(
            f"checkpoint {str(path)!r} was altered or damaged after it was written (its SHA-256 does not match "
            "its contents): it is not resumed; start afresh (--force) or use another checkpoint file"
        )
    try:
        check_counts(ds.attrs, counts, f"checkpoint {str(path)!r}", total=total)
        check_finite(ds, state_variables, f"checkpoint {str(path)!r}")
        missing = [name for name in variables if name not in ds.variables]
        if missing:
            raise InputFileError(f"checkpoint {str(path)!r} lacks the variable(s) {missing}")
    except InputFileError as err:
        raise ValueError(f"{err}: no run writes such a checkpoint; start afresh (--force) or use another checkpoint file") from None
    return ds


class CheckpointClock:
    """A checkpoint file written every ``every`` seconds of wall time (0: whenever asked), or none.

    Parameters
    ----------
    path : path or None
        The file; None for a run without a checkpoint (never due, nothing written).
    every : float
        Seconds of wall time between writes (finite, >= 0); the first is due that long after
        the clock is made.

    Raises
    ------
    ValueError
        If ``every`` is not a finite number >= 0 (with or without a file: a script's typo is
        refused before it matters).
    """

    def __init__(self, path: str | Path | None, every: float):
        if not (isinstance(every, (int, float)) and math.isfinite(every) and every >= 0):
            raise ValueError(f"checkpoint_every must be a finite number of seconds >= 0, got {every!r}")
        self.path = None if path is None else Path(path)
        self.every = float(every)
        self.last = clock.perf_counter()
        #: Why the latest write failed ("" if it succeeded or none was made).
        self.error = ""

    @property
    def due(self) -> bool:
        """Whether there is a file and ``every`` seconds have passed since the last write."""
        return self.path is not None and clock.perf_counter() - self.last >= self.every

    def write(self, ds: xr.Dataset) -> None:
        """Write ``ds`` to the file atomically (if there is one) and restart the clock.

        A write that fails (a full disk, a quota, an I/O error, the file refused) leaves the
        previous checkpoint as it was, is logged, and its reason kept in :attr:`error`; the
        next one is tried when due.
        """
        if self.path is not None:
            try:
                write_dataset(ds, self.path)
                self.error = ""
            except (OSError, OutputError) as err:
                self.error = f"{err.strerror or err}" if isinstance(err, OSError) else str(err)
                log.warning("could not write the checkpoint %s (%s); the run goes on", self.path, self.error)
        self.last = clock.perf_counter()


def _plain(value: Any) -> Any:
    """A NumPy scalar (as NetCDF gives attributes back) as the Python number it was written from."""
    return value.item() if isinstance(value, np.generic) else value
