"""A pytest plugin that writes each test's CPU time to a JSON-lines file (benchmarks/suite-times.md).

CPU, not wall-clock time, because the suite is measured on a shared, loaded machine: the process's
CPU time over setup, call and teardown (every thread), plus that of the child processes it waited
for (the command-line, docs and example tests run in subprocesses). ``numba`` is the CPU the test
process spent compiling with Numba (outermost compilations only; a kernel loaded from Numba's cache
compiles nothing), so that a kernel compiled again in every session shows. Use::

    PYTHONPATH=benchmarks CPUTIME_OUT=times.jsonl python -m pytest -p suite_cputime -m "not slow"
"""

import json
import os
import resource
import time

import pytest

_OUT = os.environ.get("CPUTIME_OUT", "suite-times.jsonl")

#: Nesting depth of Numba compilations under way, when the outermost began, and the CPU compiling in the current test.
_COMPILING = {"depth": 0, "since": 0.0, "seconds": 0.0}


def _listen_to_numba() -> None:
    # Called at the session's start, not when the plugin loads: importing Numba loads NumPy, and NumPy loaded
    # before tests/conftest.py sets OPENBLAS_NUM_THREADS=1 starts OpenBLAS with a thread a core, which the
    # suite does not have without the plugin (dense eigenvalues outside the package's one_blas_thread
    # entry points then spin a second thread on the loaded machine: many times the CPU).
    try:
        from numba.core import event
    except ImportError:
        return

    class Compilations(event.Listener):
        def on_start(self, ev):
            if _COMPILING["depth"] == 0:
                _COMPILING["since"] = time.process_time()
            _COMPILING["depth"] += 1

        def on_end(self, ev):
            _COMPILING["depth"] -= 1
            if _COMPILING["depth"] == 0:
                _COMPILING["seconds"] += time.process_time() - _COMPILING["since"]

    event.register("numba:compile", Compilations())


def pytest_sessionstart(session):
    """Listen to Numba's compilations once the suite's conftest has set the environment."""
    _listen_to_numba()


@pytest.hookimpl(hookwrapper=True)
def pytest_runtest_protocol(item, nextitem):
    """Time one test's protocol and append its record."""
    c0, w0 = time.process_time(), time.perf_counter()
    k0 = resource.getrusage(resource.RUSAGE_CHILDREN)
    _COMPILING["seconds"] = 0.0
    yield
    c1, w1 = time.process_time(), time.perf_counter()
    k1 = resource.getrusage(resource.RUSAGE_CHILDREN)
    kids = (k1.ru_utime + k1.ru_stime) - (k0.ru_utime + k0.ru_stime)
    slow = item.get_closest_marker("slow") is not None
    record = {"id": item.nodeid, "cpu": c1 - c0, "children": kids, "wall": w1 - w0, "numba": _COMPILING["seconds"], "slow": slow}
    with open(_OUT, "a") as fh:
        fh.write(json.dumps(record) + "\n")
