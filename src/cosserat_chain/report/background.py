"""Stages that run beside the others, in a second process: the report on two cores.

Contract
--------
:func:`start` forks one process that runs the stages of :data:`BACKGROUND` asked for, in
its order, with the same chain, settings and output folder as the main process (the fork copies
the :class:`~cosserat_chain.report.stages._Stage`), and sends back, through a queue, the
progress details each reports, then its :class:`~cosserat_chain.report.stages.Section` (an
error caught as in the main loop), the files it wrote (for the manifest) and its CPU time.
The stages of :data:`BACKGROUND` read nothing that another stage computes and leave nothing
for one (``_Stage.shared``), so the report is the same, file for file, as when they run in
order; together they take about as much CPU as the others (``benchmarks/bench_reproduce.py``).
The modules they import (:data:`IMPORTS`) are imported before the fork, once for both processes, and so is
what the first dataset and figure written import (:func:`_first_writes`).

:func:`start` returns None (the stages then run in order) where fork is not the platform's
safe way to start a process (only Linux forks here), where fewer than two cores are free to
this process, or where nothing else is asked for beside the background stages.
"""

from __future__ import annotations

import os
import queue
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

from .stages import Section, _Stage

#: Stages that share no result with another (they read only the chain and the settings), in the order run: the state
#: diagram first, as the longest, and the longer chains last, when the main process's statics have put the kernels
#: they share in Numba's cache (a cold cache would otherwise be compiled in both processes at once).
BACKGROUND = ("state_map", "which_continuum", "long_chains")
#: What each background stage imports, and what every stage's data and figures need (xarray's NetCDF engine,
#: pyplot): imported before the fork, so that the second process inherits the modules and the compiled kernels they
#: load (Numba compiles those with a signature at import) rather than loading them again, or with a cold cache
#: compiling them again, beside the main process, which imports most of them too (benchmarks/TIMINGS.md).
IMPORTS = {
    "state_map": ("cosserat_chain.experiments.diagram", "cosserat_chain.plots.diagram"),
    "which_continuum": ("cosserat_chain.analysis.which_continuum", "cosserat_chain.plots.theory"),
    "long_chains": ("cosserat_chain.experiments.critical", "cosserat_chain.plots.statics"),
}
SHARED_IMPORTS = ("xarray", "h5netcdf", "matplotlib.pyplot")
#: Seconds between looks at a process that has not reported while the main process waits for it.
POLL_SECONDS = 0.5


def free_cores() -> int:
    """The cores this process may run on."""
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # not on Linux
        return os.cpu_count() or 1


@dataclass
class Background:
    """The background stages under way (:func:`start`)."""

    names: list[str]
    channel: Any
    process: Any
    #: Sections received, by stage name, with their CPU seconds.
    sections: dict[str, Section] = field(default_factory=dict)
    cpu_seconds: dict[str, float] = field(default_factory=dict)

    def poll(self, stage: _Stage, report: Callable[[str, str], None], *, wait: bool = False) -> None:
        """Take what the processes sent: ``report(name, detail)`` for each progress detail, each section
        and its files into ``stage.written``. With ``wait``, until every section has come."""
        while len(self.sections) < len(self.names):
            try:
                message = self.channel.get(timeout=POLL_SECONDS) if wait else self.channel.get_nowait()
            except queue.Empty:
                if not wait:
                    return
                self._check_alive()
                continue
            kind, name, *payload = message
            if kind == "progress":
                report(name, payload[0])
            else:
                section, written, cpu = payload
                self.sections[name] = section
                self.cpu_seconds[name] = cpu
                stage.written.update(written)

    def _check_alive(self) -> None:
        """Error sections for the stages a process that ended (killed, out of memory) did not send."""
        if self.process.is_alive() or not self.channel.empty():
            return
        for name in self.names:
            if name not in self.sections:
                self.sections[name] = Section(name, error=f"the stage's process ended without a result (exit code {self.process.exitcode})")
                self.cpu_seconds[name] = 0.0

    def stop(self) -> None:
        """End the process if it still runs (an interrupted report)."""
        if self.process.is_alive():
            self.process.terminate()
        self.process.join()


def _child(channel, stage: _Stage, names: list[str], run: Callable[[_Stage, str], Section]) -> None:
    try:
        for name in names:
            stage.progress = lambda detail, name=name: channel.put(("progress", name, detail))
            stage.written = set()
            cpu = time.process_time()
            section = run(stage, name)
            channel.put(("done", name, section, stage.written, time.process_time() - cpu))
    except KeyboardInterrupt:  # Ctrl-C reaches both processes: the main one reports it, once
        return


def _first_writes() -> None:
    """A tiny dataset and figure written to memory, so that what their first writes import happens once, before the fork.

    xarray imports its duck-array and parallel back-ends (pint, Dask, distributed) when it first builds
    a coordinate and writes a file, and matplotlib its SVG back-end and Pillow its plugins when they first
    save: both processes write, and each would pay for those imports itself.
    """
    import io

    import numpy as np
    import xarray as xr
    from matplotlib.figure import Figure

    from ..io import netcdf_image

    netcdf_image(xr.Dataset({"x": ("i", np.zeros(1))}, coords={"i": [0]}))
    figure = Figure(figsize=(1, 1))
    for kind in ("png", "svg"):
        figure.savefig(io.BytesIO(), format=kind)


def _critical_points(stage: _Stage) -> None:
    """Every model's critical point, which the statics stage computes first, computed before the fork.

    The state diagram computes the same statics: forked after them, its process inherits the kernels they
    compiled (with an empty cache, both processes compiled them at once) and finds the rest in the cache.
    A failure is left to the statics stage, which computes the point again and reports it.
    """
    from .settings import MODELS

    for model in MODELS:
        try:
            stage.critical(model)
        except Exception:  # the statics stage reports it
            return


def start(stage: _Stage, names: list[str], run: Callable[[_Stage, str], Section]) -> Background | None:
    """Fork a process that runs ``run(stage, name)`` for the stages of :data:`BACKGROUND` in ``names`` (module docstring)."""
    chosen = [name for name in BACKGROUND if name in names]
    if not chosen or len(chosen) == len(names) or not sys.platform.startswith("linux") or free_cores() < 2:
        return None
    import importlib
    import multiprocessing

    for module in [*SHARED_IMPORTS, *(module for name in chosen for module in IMPORTS[name])]:
        importlib.import_module(module)
    _first_writes()
    if "statics" in names:
        _critical_points(stage)
    context = multiprocessing.get_context("fork")
    channel = context.Queue()
    process = context.Process(target=_child, args=(channel, stage, chosen, run), name="report-background", daemon=True)
    process.start()
    return Background(chosen, channel, process)
