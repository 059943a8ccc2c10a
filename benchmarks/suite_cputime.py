"""A pytest plugin that writes each test's CPU time to a JSON-lines file (benchmarks/suite-times.md).

CPU, not wall-clock time, because the suite is measured on a shared, loaded machine: the process's
CPU time over setup, call and teardown (every thread), plus that of the child processes it waited
for (the command-line, docs and example tests run in subprocesses). ``numba`` is the CPU the test
process spent compiling with Numba (outermost compilations only; a kernel loaded from Numba's cache
compiles nothing), so that a kernel compiled again in every session shows. Use::

    PYTHONPATH=benchmarks CPUTIME_OUT=times.jsonl python -m pytest -p suite_cputime -m "not slow"

and read the records with ``python benchmarks/suite_cputime.py times.jsonl [--top 30]`` (the sums, the most expensive
tests and files), or ``python benchmarks/suite_cputime.py old.jsonl new.jsonl`` (the two runs' sums over the tests
both have, and the files and tests that changed most).

Run under ``coverage run`` (coverage is not a dependency of the package; install it in the environment for this
analysis only), the plugin names coverage's context after each test's node id and phase (``ID|setup``, ``ID|call``,
``ID|teardown``), and ``python benchmarks/suite_cputime.py times.jsonl --unique-lines .coverage`` lists, for each
quick test above ``--min`` seconds, the package's lines no other quick test runs, and which of them could move to
``slow`` without the quick suite losing a line (greedy from the most expensive, each move counted before the next).
"""

import argparse
import collections
import json
import os
import resource
import sys
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


def _switch_coverage_context(label: str) -> None:
    # Only under ``coverage run``: the plugin never imports coverage itself.
    coverage = sys.modules.get("coverage")
    current = coverage.Coverage.current() if coverage is not None else None
    if current is not None:
        current.switch_context(label)


@pytest.hookimpl(hookwrapper=True)
def pytest_runtest_setup(item):
    """Name coverage's context after the test's setup."""
    _switch_coverage_context(item.nodeid + "|setup")
    yield


@pytest.hookimpl(hookwrapper=True)
def pytest_runtest_call(item):
    """Name coverage's context after the test's call."""
    _switch_coverage_context(item.nodeid + "|call")
    yield


@pytest.hookimpl(hookwrapper=True)
def pytest_runtest_teardown(item):
    """Name coverage's context after the test's teardown, and none once it is over."""
    _switch_coverage_context(item.nodeid + "|teardown")
    yield
    _switch_coverage_context("")


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


def _records(path: str) -> dict[str, dict]:
    """The quick tests' records of one run, by node id (a test run twice keeps its last record)."""
    with open(path) as fh:
        rows = [json.loads(line) for line in fh if line.strip()]
    return {row["id"]: row for row in rows if not row["slow"]}


def _cost(record: dict) -> float:
    return record["cpu"] + record["children"]


def _by_file(records: dict[str, dict]) -> collections.Counter:
    files: collections.Counter = collections.Counter()
    for node, record in records.items():
        files[node.split("::")[0]] += _cost(record)
    return files


def _summary(path: str, top: int) -> None:
    records = _records(path)
    total, numba = sum(map(_cost, records.values())), sum(r["numba"] for r in records.values())
    print(f"{path}: {len(records)} quick tests, {total:.1f} s of CPU (children included), {numba:.1f} s of it Numba compiling")
    print(f"\n{'CPU s':>7} {'kids s':>7} {'numba s':>7}  test")
    for node, r in sorted(records.items(), key=lambda item: -_cost(item[1]))[:top]:
        print(f"{_cost(r):7.2f} {r['children']:7.2f} {r['numba']:7.2f}  {node}")
    print(f"\n{'CPU s':>7}  file")
    for name, cost in _by_file(records).most_common(top):
        print(f"{cost:7.1f}  {name}")


def _compare(old_path: str, new_path: str, top: int) -> None:
    old, new = _records(old_path), _records(new_path)
    both = old.keys() & new.keys()
    print(f"old {len(old)} tests {sum(map(_cost, old.values())):.1f} s; new {len(new)} tests {sum(map(_cost, new.values())):.1f} s")
    print(f"the {len(both)} tests both have: {sum(_cost(old[k]) for k in both):.1f} -> {sum(_cost(new[k]) for k in both):.1f} s")
    for label, nodes, run in (("only old", old.keys() - new.keys(), old), ("only new", new.keys() - old.keys(), new)):
        print(f"{label}: {len(nodes)} tests, {sum(_cost(run[k]) for k in nodes):.1f} s")
    files_old, files_new = _by_file({k: old[k] for k in both}), _by_file({k: new[k] for k in both})
    print(f"\n{'old s':>7} {'new s':>7}  file (largest changes, tests both runs have)")
    for name in sorted(files_old, key=lambda f: -abs(files_old[f] - files_new[f]))[:top]:
        print(f"{files_old[name]:7.2f} {files_new[name]:7.2f}  {name}")
    print(f"\n{'old s':>7} {'new s':>7}  test")
    for node in sorted(both, key=lambda k: -abs(_cost(old[k]) - _cost(new[k])))[:top]:
        print(f"{_cost(old[node]):7.2f} {_cost(new[node]):7.2f}  {node}")


def _unique_lines(path: str, database: str, least: float) -> None:
    try:
        import coverage
    except ImportError:
        sys.exit("--unique-lines reads a coverage database: install coverage in this environment (pip install coverage)")
    records = _records(path)
    data = coverage.CoverageData(database)
    data.read()
    lines: dict[str, set] = collections.defaultdict(set)
    for name in data.measured_files():
        for number, contexts in data.contexts_by_lineno(name).items():
            for context in contexts:
                node = context.rpartition("|")[0]
                if node in records:
                    lines[node].add((name, number))
    if not lines:
        sys.exit(f"{database} holds no test's context: run the suite with -p suite_cputime under coverage run")
    covers: collections.Counter = collections.Counter(line for node_lines in lines.values() for line in node_lines)
    movable = []
    print(f"{'CPU s':>7} {'kids s':>7} {'unique':>7}  test (greedy from the most expensive: 0 unique lines may move)")
    for node in sorted((n for n in records if _cost(records[n]) > least), key=lambda n: -_cost(records[n])):
        unique = [line for line in lines.get(node, ()) if covers[line] == 1]
        if not unique:
            movable.append(node)
            covers.subtract(lines.get(node, ()))
        print(f"{_cost(records[node]):7.2f} {records[node]['children']:7.2f} {len(unique):7d}  {node}")
    print(f"\n{len(movable)} tests ({sum(_cost(records[n]) for n in movable):.1f} s) run no line that the others do not")
    print("(a test whose CPU is its children's: their lines are not counted; decide it by its claim)")


def main() -> None:
    parser = argparse.ArgumentParser(description="Summarise one run's records, or compare two runs'.")
    parser.add_argument("records", nargs="+", help="one JSON-lines file of this plugin's, or two (old, new)")
    parser.add_argument("--top", type=int, default=30, help="how many tests and files to list")
    parser.add_argument("--unique-lines", metavar="DATABASE", help="a coverage database of the same run (one records file)")
    parser.add_argument("--min", type=float, default=1.0, help="with --unique-lines, the least CPU s of a test listed")
    args = parser.parse_args()
    if args.unique_lines is not None:
        if len(args.records) != 1:
            parser.error(f"--unique-lines takes one records file, got {len(args.records)}")
        _unique_lines(args.records[0], args.unique_lines, args.min)
    elif len(args.records) == 1:
        _summary(args.records[0], args.top)
    elif len(args.records) == 2:
        _compare(*args.records, args.top)
    else:
        parser.error(f"records takes one file or two, got {len(args.records)}")


if __name__ == "__main__":
    main()
