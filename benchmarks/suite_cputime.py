"""A pytest plugin that writes each test's CPU time to a JSON-lines file (benchmarks/suite-times.md).

CPU, not wall-clock time, because the suite is measured on a shared, loaded machine: the process's
CPU time over setup, call and teardown (every thread), plus that of the child processes it waited
for (the command-line, docs and example tests run in subprocesses). Use::

    PYTHONPATH=benchmarks CPUTIME_OUT=times.jsonl python -m pytest -p suite_cputime -m "not slow"
"""

import json
import os
import resource
import time

import pytest

_OUT = os.environ.get("CPUTIME_OUT", "suite-times.jsonl")


@pytest.hookimpl(hookwrapper=True)
def pytest_runtest_protocol(item, nextitem):
    """Time one test's protocol and append its record."""
    c0, w0 = time.process_time(), time.perf_counter()
    k0 = resource.getrusage(resource.RUSAGE_CHILDREN)
    yield
    c1, w1 = time.process_time(), time.perf_counter()
    k1 = resource.getrusage(resource.RUSAGE_CHILDREN)
    kids = (k1.ru_utime + k1.ru_stime) - (k0.ru_utime + k0.ru_stime)
    slow = item.get_closest_marker("slow") is not None
    with open(_OUT, "a") as fh:
        fh.write(json.dumps({"id": item.nodeid, "cpu": c1 - c0, "children": kids, "wall": w1 - w0, "slow": slow}) + "\n")
