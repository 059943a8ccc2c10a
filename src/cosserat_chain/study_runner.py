"""Running a parameter study on Dask, saving cells as they finish and resuming a killed study.

Contract
--------
:func:`run_study` submits every cell of a :class:`~cosserat_chain.experiments.study.StudySpec`
that is not yet done as one task to a ``dask.distributed`` cluster (an embedded
``LocalCluster`` with one single-threaded worker process per core by default, or an
existing scheduler given by its address). Results are stored in one xarray Dataset
(see :func:`~cosserat_chain.experiments.study.empty_results`) that is written
atomically to NetCDF every ``save_every`` seconds, at the end, and when the study is
interrupted (Ctrl-C or a progress callback raising ``KeyboardInterrupt``). Re-running
the same spec with the same output file resumes: finished cells are read back and
skipped; a file written for another spec is refused.

This module sits beside :mod:`cosserat_chain.io` (it persists) and above the experiments
(it runs them); it never computes physics itself.
"""

from __future__ import annotations

import logging
import os
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import xarray as xr

from . import __version__
from .experiments.study import StudySpec, compute_cell, empty_results, store_cell
from .io import read_dataset, write_dataset

log = logging.getLogger(__name__)


@dataclass
class StudyRun:
    """Outcome of :func:`run_study`.

    Attributes
    ----------
    dataset : xarray.Dataset
        All cells (finished ones filled in).
    computed : int
        Cells computed by this call (not read back from an earlier run).
    skipped : int
        Cells already done in the output file.
    failed : int
        Cells (of all done ones) that recorded an error.
    completed : bool
        False if the study was interrupted.
    """

    dataset: xr.Dataset
    computed: int
    skipped: int
    failed: int
    completed: bool


def _resume(spec: StudySpec, out: Path | None) -> xr.Dataset:
    fresh = empty_results(spec)
    if out is None or not out.exists():
        return fresh
    previous = read_dataset(out)
    if previous.attrs.get("study_spec_json") != fresh.attrs["study_spec_json"]:
        raise ValueError(f"{out} holds the results of a different study spec; choose another --out or delete it")
    previous["error"] = previous["error"].astype(object)
    return previous


def run_study(
    spec: StudySpec,
    *,
    out: str | Path | None = None,
    scheduler: str | None = None,
    workers: int | None = None,
    save_every: float = 5.0,
    progress: Callable[[int, int], None] | None = None,
) -> StudyRun:
    """Compute every cell of ``spec`` on Dask (see the module docstring).

    Parameters
    ----------
    spec : StudySpec
    out : path, optional
        NetCDF file the results are written to as they finish (and resumed from).
    scheduler : str, optional
        Address of an existing Dask scheduler (``tcp://host:8786``); default an
        embedded LocalCluster.
    workers : int, optional
        Worker processes of the LocalCluster (default: one per core).
    save_every : float
        Seconds between two writes of ``out``.
    progress : callable(cells_done, cells_total), optional

    Returns
    -------
    StudyRun
    """
    from dask.distributed import Client, LocalCluster, as_completed

    spec.check()
    out = None if out is None else Path(out)
    ds = _resume(spec, out)
    ds.attrs["cosserat_chain_version"] = __version__
    cells = spec.cells()
    names = list(spec.axes())
    todo, skipped = [], 0
    for index, model, fields in cells:
        where = {**dict(zip(names, index)), "model": spec.models.index(model)}
        if int(ds["done"][where]):
            skipped += 1
        else:
            todo.append((index, model, fields))
    total = len(cells)
    if progress is not None:
        progress(skipped, total)
    computed, completed = 0, True
    if todo:
        cluster = None
        if scheduler is None:
            cluster = LocalCluster(n_workers=workers or os.cpu_count() or 1, threads_per_worker=1, processes=True, dashboard_address=":0")
        client = Client(scheduler or cluster)
        spec_json = spec.to_json()
        last_save = time.monotonic()
        try:
            futures = {client.submit(compute_cell, fields, model, spec_json, pure=False): (index, model) for index, model, fields in todo}
            try:
                for future in as_completed(futures):
                    index, model = futures[future]
                    store_cell(ds, spec, index, model, future.result())
                    computed += 1
                    if progress is not None:
                        progress(skipped + computed, total)
                    if out is not None and time.monotonic() - last_save >= save_every:
                        write_dataset(ds, out)
                        last_save = time.monotonic()
            except KeyboardInterrupt:
                completed = False
                log.warning("study interrupted after %d of %d cells; the finished cells are saved", skipped + computed, total)
                client.cancel(list(futures))
        finally:
            client.close()
            if cluster is not None:
                cluster.close()
    if out is not None:
        write_dataset(ds, out)
    failed = int(np.sum((ds["done"].values == 1) & (ds["error"].values.astype(str) != "")))
    return StudyRun(ds, computed, skipped, failed, completed)
