"""Running a parameter study on Dask, saving cells as they finish and resuming a killed study.

Contract
--------
:func:`run_study` cuts the cells of a :class:`~cosserat_chain.experiments.study.StudySpec`
that are not yet done into chunks of cells that share N and the model
(:func:`chunk_cells`), and submits each chunk as one task
(:func:`~cosserat_chain.experiments.study.compute_cells`, which batches the chunk's
relaxations) to a ``dask.distributed`` cluster (an embedded ``LocalCluster`` with one
single-threaded worker process per core by default, or an existing scheduler given by
its address). Results are stored in one xarray Dataset (see
:func:`~cosserat_chain.experiments.study.empty_results`) as chunks finish; it is
written atomically to NetCDF when a chunk arrives at least ``save_every`` seconds
after the last write, at the end, and when the study stops early: interrupted (Ctrl-C
or a progress callback raising ``KeyboardInterrupt``) or by an error. Re-running the
same spec with the same output file resumes: finished cells are read back and skipped;
a file written for another spec (or under another time-step rule) is refused. A
scheduler given by its address that does not answer as one within :data:`CONNECT_TIMEOUT`
(refused, silent or speaking another protocol) raises :class:`ClusterError`. The
embedded cluster listens on 127.0.0.1 only and serves no dashboard unless asked. A
cluster lost during the study (the scheduler gone, or no worker left for
:data:`LOST_TIMEOUT` seconds) ends it with status ``failed`` and the finished cells saved; a cluster whose first worker does not come within
:data:`START_TIMEOUT` likewise.

This module sits beside :mod:`cosserat_chain.io` (it persists) and above the experiments
(it runs them); it never computes physics itself.
"""

from __future__ import annotations

import logging
import math
import os
import time
from collections.abc import Callable, Iterator, Sequence
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import xarray as xr

from ._version import __version__
from .errors import CosseratChainError
from .experiments.study import StudySpec, compute_cells, empty_results, store_cell
from .io import OutputError, read_dataset, write_dataset
from .status import Status

log = logging.getLogger(__name__)

#: The default chunk size aims at this many tasks per worker, so that the workers stay
#: busy to the end although chunks take different times.
TASKS_PER_WORKER = 4
#: Largest default chunk: beyond a few hundred members a batch gains no more per member,
#: and a chunk's cells reach the file only when the whole chunk is done.
MAX_CHUNK = 256

#: Seconds to reach a scheduler given by its address before giving up with a message.
CONNECT_TIMEOUT = 10.0
#: Seconds the study waits with no worker (or no scheduler) left before it stops, saving what
#: arrived: a cluster whose workers all died never finishes a task.
LOST_TIMEOUT = 60.0
#: Seconds the study waits for a cluster's first worker (workers queued on a batch system
#: may take minutes to start) before it stops the same way.
START_TIMEOUT = 600.0
#: Seconds between two looks at the cluster while waiting for the next chunk.
POLL = 1.0
#: The only interface the embedded cluster listens on: a study's tasks and parameters are
#: not for the network.
LOOPBACK = "127.0.0.1"

Cell = tuple[tuple[int, ...], str, dict[str, float]]


class ClusterError(CosseratChainError, RuntimeError):
    """The Dask cluster cannot be reached, or was lost during the study."""


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
    status : Status
        ``completed``; ``interrupted`` (Ctrl-C); ``failed`` (the cluster was lost). The
        finished cells are saved either way, and the same call resumes.
    message : str
        Why it stopped early ("" if completed).
    unsaved : str
        Why ``out`` could not be written at the end (a full disk; "" if it was): the
        dataset holds the cells, for the caller to keep elsewhere.
    """

    dataset: xr.Dataset
    computed: int
    skipped: int
    failed: int
    status: Status = Status.COMPLETED
    message: str = ""
    unsaved: str = ""

    @property
    def completed(self) -> bool:
        """Every cell is done."""
        return self.status == Status.COMPLETED


def default_chunk_size(cells: int, workers: int) -> int:
    """Cells per task: about ``TASKS_PER_WORKER`` tasks per worker, at most ``MAX_CHUNK`` cells, at least 1."""
    return max(1, min(MAX_CHUNK, math.ceil(cells / (TASKS_PER_WORKER * max(1, workers)))))


def chunk_cells(cells: Sequence[Cell], size: int) -> list[list[Cell]]:
    """The cells cut into chunks of at most ``size`` that share N and the model, in spec order.

    Neighbours in spec order differ in the innermost swept field only, so a chunk's
    cells tend to share their time step, hence one compiled loop.
    """
    groups: dict[tuple, list[Cell]] = {}
    for cell in cells:
        _, model, fields = cell
        groups.setdefault((fields.get("N"), model), []).append(cell)
    return [group[start : start + size] for group in groups.values() for start in range(0, len(group), size)]


def _reach(address: str) -> None:
    """Ask the scheduler at ``address`` who it is, within :data:`CONNECT_TIMEOUT` seconds in all.

    ``dask.distributed.Client`` bounds the TCP connection by its timeout, but not the wait
    for the first answer: a port that accepts and never answers (a firewall, a stopped
    process, another service) held it for minutes. This probe is bounded as a whole and
    also refuses a port that answers but not as a Dask scheduler. It runs its own event
    loop in a thread of its own, so that it works from inside a running loop (Jupyter).
    """
    import asyncio
    from concurrent.futures import ThreadPoolExecutor

    from distributed.comm import connect

    async def identity() -> Any:
        # Half the time for the connection, so that a refused port (distributed retries until its
        # timeout) is told apart from one that accepts and stays silent.
        comm = await connect(address, timeout=CONNECT_TIMEOUT / 2)
        try:
            await comm.write({"op": "identity", "reply": True})
            return await comm.read()
        finally:
            comm.abort()

    def ask() -> Any:
        return asyncio.run(asyncio.wait_for(identity(), CONNECT_TIMEOUT))

    with ThreadPoolExecutor(1) as pool:
        try:
            answer = pool.submit(ask).result()
        except TimeoutError:
            raise ClusterError(
                f"no Dask scheduler answered at {address!r} within {CONNECT_TIMEOUT:g} s (nothing listens there, "
                "or something accepts the connection and stays silent); check the address and that the scheduler runs"
            ) from None
        except (OSError, ValueError) as err:  # refused, closed, unresolvable, or a malformed address
            reason = str(err).splitlines()[0] if str(err) else type(err).__name__
            raise ClusterError(f"cannot reach the Dask scheduler at {address!r}: {reason}") from None
        except Exception:  # bytes that are not Dask's protocol (they may even decode to absurd frame sizes)
            answer = None
    if not (isinstance(answer, dict) and answer.get("type") == "Scheduler"):
        raise ClusterError(f"{address!r} answered, but not as a Dask scheduler: check the address and port")


@contextmanager
def _client(scheduler: str | None, workers: int | None, dashboard: Callable[[str], None] | None) -> Iterator[tuple[Any, int]]:
    """A Dask client of the scheduler at ``scheduler``, or of an embedded LocalCluster; and its worker count.

    The embedded cluster's scheduler, workers and nannies listen on 127.0.0.1 only, and
    it serves a dashboard (also on 127.0.0.1, its address handed to ``dashboard``) only
    when asked. The client is not made Dask's default: xarray would otherwise guard the
    study's own file writes with a lock held by the scheduler, and a study whose scheduler
    died could not save its cells.
    """
    from dask.distributed import Client, LocalCluster

    cluster = None
    if scheduler is None:
        workers = workers or os.cpu_count() or 1
        cluster = LocalCluster(
            n_workers=workers,
            threads_per_worker=1,
            processes=True,
            host=LOOPBACK,
            dashboard_address=f"{LOOPBACK}:0" if dashboard is not None else None,
        )
        client = Client(cluster, set_as_default=False)
        if dashboard is not None:
            dashboard(cluster.dashboard_link)
    else:
        _reach(scheduler)
        try:
            client = Client(scheduler, timeout=CONNECT_TIMEOUT, set_as_default=False)
        except (OSError, TimeoutError, ValueError, TypeError) as err:
            raise ClusterError(f"cannot reach the Dask scheduler at {scheduler!r} within {CONNECT_TIMEOUT:g} s: {err}") from None
    try:
        yield client, workers or sum(client.nthreads().values())
    finally:
        client.close()
        if cluster is not None:
            cluster.close()


def _resume(spec: StudySpec, out: Path | None) -> xr.Dataset:
    fresh = empty_results(spec)
    if out is None or not out.exists():
        return fresh
    previous = read_dataset(out)
    if previous.attrs.get("study_spec_json") != fresh.attrs["study_spec_json"]:
        raise ValueError(f"{out} holds the results of a different study spec; choose another --out or delete it")
    if previous.attrs.get("time_step_rule") != fresh.attrs["time_step_rule"]:
        raise ValueError(f"{out} was computed under another time-step rule (an earlier version); choose another --out or delete it")
    for name, variable in fresh.variables.items():  # a file edited or damaged under the same spec: never half-trusted
        stored = previous.variables.get(name)
        if stored is None or stored.dims != variable.dims or stored.shape != variable.shape:
            raise ValueError(
                f"{out} lacks the variable {name!r} over {variable.dims} of this study's results; choose another --out or delete it"
            )
    if not np.isin(previous["done"].values, (0, 1)).all():
        raise ValueError(f"{out}: its variable 'done' holds values other than 0 and 1; choose another --out or delete it")
    previous["error"] = previous["error"].astype(object)
    # A file of an earlier version lacks attributes added since (loads_json): the same spec implies their values.
    previous.attrs.update({key: value for key, value in fresh.attrs.items() if key not in previous.attrs})
    return previous


def run_study(
    spec: StudySpec,
    *,
    out: str | Path | None = None,
    scheduler: str | None = None,
    workers: int | None = None,
    chunk: int | None = None,
    save_every: float = 5.0,
    progress: Callable[[int, int], None] | None = None,
    dashboard: Callable[[str], None] | None = None,
) -> StudyRun:
    """Compute every cell of ``spec`` on Dask, in chunks of cells (see the module docstring).

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
    chunk : int, optional
        Cells per task (cells of one N and model); default :func:`default_chunk_size`
        of the cells to compute and the workers.
    save_every : float
        Least seconds between two writes of ``out`` while chunks arrive.
    progress : callable(cells_done, cells_total), optional
        Called once at the start and after every chunk.
    dashboard : callable(address), optional
        Serve the embedded cluster's Dask dashboard (on 127.0.0.1) and call this with its
        address once the cluster is up; default no dashboard. Ignored with ``scheduler``.

    Returns
    -------
    StudyRun

    Raises
    ------
    ValueError
        For a bad spec or chunk, or an ``out`` written for another spec.
    ClusterError
        If the scheduler at ``scheduler`` does not answer as a Dask scheduler within
        :data:`CONNECT_TIMEOUT` (refused, silent, or speaking another protocol).
    """
    if chunk is not None and not (isinstance(chunk, int) and chunk >= 1):
        raise ValueError(f"chunk must be an integer >= 1, got {chunk!r}")
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
    computed, message, status = 0, "", Status.COMPLETED
    unsaved, reached = "", False

    def store(part: list[Cell], values: list[dict[str, Any]]) -> None:
        nonlocal computed
        for (index, model, _), cell_values in zip(part, values):
            store_cell(ds, spec, index, model, cell_values)
        computed += len(part)
        if progress is not None:
            progress(skipped + computed, total)

    try:
        if todo:
            with _client(scheduler, workers, dashboard) as (client, worker_count):
                reached = True
                spec_json = spec.to_json()
                chunks = chunk_cells(todo, chunk or default_chunk_size(len(todo), worker_count))
                futures = {client.submit(compute_cells, [c[2] for c in part], part[0][1], spec_json, pure=False): part for part in chunks}
                try:
                    message = _collect(client, futures, store, lambda: _save(ds, out) if out is not None else None, save_every)
                    status = Status.FAILED if message else status
                except KeyboardInterrupt:
                    message, status = f"interrupted after {skipped + computed} of {total} cells", Status.INTERRUPTED
                if message:
                    log.warning("study stopped: %s; the finished cells are saved", message)
                    try:
                        client.cancel(list(futures))
                    except Exception:  # the scheduler may be gone; nothing left to cancel then
                        pass
    finally:
        # Also on an error (a progress callback raising, a failure of the client): keep the chunks that arrived.
        # A scheduler that could not be reached, or every cell read back: nothing ran, the file stays as it was.
        if out is not None and (computed or reached):
            unsaved = _save(ds, out)
    failed = int(np.sum((ds["done"].values == 1) & (ds["error"].values.astype(str) != "")))
    return StudyRun(ds, computed, skipped, failed, status, message, unsaved)


def _save(ds: xr.Dataset, out: Path) -> str:
    """Write the study's file; returns "" or why it failed (logged): a full disk must not stop the study nor lose its cells."""
    try:
        write_dataset(ds, out)
    except (OSError, OutputError) as err:
        reason = f"{err.strerror or err}" if isinstance(err, OSError) else str(err)
        log.warning("could not write %s (%s); the cells are kept in memory", out, reason)
        return reason
    return ""


def _collect(client, futures: dict, store: Callable, save: Callable[[], None], save_every: float) -> str:
    """Store chunks as they finish until all are in; returns "" or why it stopped (the cluster lost).

    Waits at most :data:`POLL` seconds at a time, and between waits looks at the
    cluster: without a worker (or a scheduler) for :data:`LOST_TIMEOUT` seconds after
    it had one (:data:`START_TIMEOUT` while its first worker has not come), no chunk can
    finish any more, so it stops instead of waiting forever.
    """
    from dask.distributed import wait

    pending = set(futures)
    last_save = lost_since = time.monotonic()
    seen_a_worker = False
    while pending:
        try:
            with client.as_current():  # ``wait`` asks for the current client; the saves below must not see it
                done, pending = wait(pending, timeout=POLL, return_when="FIRST_COMPLETED")
        except TimeoutError:
            done = set()
        except Exception as err:  # the client cancels every future when it loses its scheduler
            return f"the chunks still running were lost with the cluster ({type(err).__name__}: {str(err).splitlines()[0]})"
        for future in done:
            try:
                values = future.result()
            except Exception as err:  # a chunk lost with its scheduler or killed workers; compute_cells itself never raises
                return f"a chunk of {len(futures[future])} cells could not be computed ({type(err).__name__}: {err})"
            store(futures[future], values)
            if time.monotonic() - last_save >= save_every:
                save()
                last_save = time.monotonic()
        if done:
            lost_since = time.monotonic()
            continue
        try:
            alive = client.status == "running" and len(client.scheduler_info(n_workers=-1)["workers"]) > 0
        except Exception:  # the scheduler does not answer
            alive = False
        seen_a_worker = seen_a_worker or alive
        limit = LOST_TIMEOUT if seen_a_worker else START_TIMEOUT
        if alive:
            lost_since = time.monotonic()
        elif time.monotonic() - lost_since > limit:
            return f"the cluster has had no scheduler or no worker for {limit:g} s"
    return ""
