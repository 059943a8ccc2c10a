"""Start-up: the CPU time of a computing command with ``--json`` (issue 44, item 3).

Run from the repository root::

    python benchmarks/bench_startup.py                              # critical --model sine --json, median of 5
    python benchmarks/bench_startup.py --runs 9 -- orbit --model sine --moment 0.3 --json
    python benchmarks/bench_startup.py --src /tmp/old/src           # another checkout's package, same interpreter
    python benchmarks/bench_startup.py --against /tmp/old/src --runs 5 --out benchmarks/results/startup-h44u.json
    python benchmarks/bench_startup.py --floor --runs 3                # what any computing command pays
    python benchmarks/bench_startup.py --phases --runs 5               # where critical's CPU goes, stage by stage
    python benchmarks/bench_startup.py --phases --no-jit --runs 5      # the same with every compiled function as Python

Each run is a fresh ``python -m cosserat_chain ARGS`` (its output discarded); its CPU time is
user + system of the child (``resource.getrusage(RUSAGE_CHILDREN)``), which a busy neighbour
on the other core does not change. One run first warms Numba's on-disk cache (not counted). The
children keep their bytecode under :data:`PYCACHE`, as an installed package has it (``--no-bytecode``:
the sources compiled every run, as in a shell with ``PYTHONDONTWRITEBYTECODE``).
With ``--against OLD``, the runs of this tree and of ``OLD`` (a ``src`` folder) alternate.

Also printed, from one more run of each tree: the heavy libraries loaded by the end of the
command (none of xarray, pandas, Dask or matplotlib for ``--json`` without ``--out``/``--plot``),
the CPU time of the interpreter's teardown (after the last ``atexit`` handler), the Numba
dispatchers entered (each cached function's load and type resolution), and the slowest
top-level imports from ``python -X importtime``.
"""

from __future__ import annotations

import argparse
import json
import os
import re
import resource
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

HEAVY = ("numba", "scipy", "scipy.optimize", "mpmath", "xarray", "pandas", "dask", "distributed", "matplotlib")
# Registered first, so run last among the atexit handlers: the CPU time before the teardown.
PROBE = """\
import atexit, json, runpy, sys, time
import numba.core.dispatcher as dispatcher

loads = []
compile_ = dispatcher.Dispatcher.compile


def timed(self, sig):
    start = time.process_time()
    try:
        return compile_(self, sig)
    finally:
        loads.append((self.py_func.__module__ + "." + self.py_func.__qualname__, time.process_time() - start))


dispatcher.Dispatcher.compile = timed
report = sys.stderr
atexit.register(lambda: print("PROBE", json.dumps({
    "cpu_before_teardown_s": time.process_time(),
    "loaded": [m for m in HEAVY if m in sys.modules],
    "dispatchers": loads,
}), file=report))
sys.argv = ["cosserat-chain", *sys.argv[1:]]
runpy.run_module("cosserat_chain", run_name="__main__")
""".replace("HEAVY", repr(HEAVY))


# The floor: the libraries any computing command imports, then one cached compiled function entered
# (Numba sets up its CPU target on the first); each line adds to the one before, frozen at exit as the CLI does.
_FROZEN = "import atexit, gc; atexit.register(gc.freeze)\n"
_LIBRARIES = "import numpy, pydantic, typer; from pydantic import BaseModel\n"
_KERNEL = (
    "import numba, tempfile, pathlib, sys\n"
    "folder = pathlib.Path(tempfile.gettempdir()) / 'bench_startup_floor'; folder.mkdir(exist_ok=True)\n"
    "(folder / 'floor_kernel.py').write_text('import numba\\n@numba.njit(cache=True)\\ndef one(x):\\n    return x + 1.0\\n')\n"
    "sys.path.insert(0, str(folder)); import floor_kernel; floor_kernel.one(1.0)\n"
)
FLOOR = {
    "python -c pass": "pass",
    "import numpy": _FROZEN + "import numpy",
    "numpy + pydantic (BaseModel) + typer": _FROZEN + _LIBRARIES,
    "... + numba": _FROZEN + _LIBRARIES + "import numba",
    "... + scipy.sparse.linalg": _FROZEN + _LIBRARIES + "import numba, scipy.sparse.linalg",
    "... + one cached njit function entered": _FROZEN + _LIBRARIES + "import scipy.sparse.linalg\n" + _KERNEL,
    "(not cumulative: the floor + scipy.optimize, which critical and orbit no longer import)": _FROZEN
    + _LIBRARIES
    + "import scipy.sparse.linalg, scipy.optimize\n"
    + _KERNEL,
}


def floor(runs: int, bytecode: bool = True) -> dict[str, float]:
    """The median CPU time of each line of :data:`FLOOR` in a fresh interpreter, the lines interleaved."""
    env = environment(None, bytecode)
    cpu_seconds([sys.executable, "-c", FLOOR["... + one cached njit function entered"]], env)  # compile and cache it
    times: dict[str, list[float]] = {label: [] for label in FLOOR}
    for _ in range(runs):
        for label, code in FLOOR.items():
            times[label].append(cpu_seconds([sys.executable, "-c", code], env))
    return {label: round(statistics.median(t), 3) for label, t in times.items()}


# Where critical's CPU goes, stage by stage in one fresh interpreter (each line's CPU after the one before): the
# libraries, the command line, Numba's set-up on the first compiled function, the models, the experiment's imports,
# critical_point on each model of the paper's chain (its compiled functions loaded on the first call), then again
# (the computation alone).
PHASES = """\
import json, os, sys, time
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
marks = []
def mark(label):
    marks.append((label, time.process_time()))
mark("interpreter start")
import numpy; mark("import numpy")
import pydantic, typer, tqdm; mark("import pydantic, typer, tqdm")
import numba; mark("import numba")
import scipy.linalg, scipy.sparse; mark("import scipy.linalg, scipy.sparse (critical's SciPy)")
import cosserat_chain.params; mark("cosserat_chain.params (ChainParams' pydantic schema)")
import cosserat_chain.cli
cosserat_chain.cli.app._chosen = "critical"  # as a run naming critical sets it (_App.__call__): its module alone
import cosserat_chain.cli.statics; mark("the command line: cli, cli.common, io, cli.statics")
KERNEL
mark("the first cached compiled function (Numba's target set-up)")
import cosserat_chain.models; mark("cosserat_chain.models (kernels with a signature loaded at import)")
import cosserat_chain.experiments.critical as critical; mark("experiments.critical and the numerics it imports")
params = cosserat_chain.params.ChainParams()
for again in ("first call (its compiled functions loaded)", "again (the computation alone)"):
    for name in ("nonlinear", "sine", "linear"):
        try:
            critical.critical_point(params, name).as_dict(); mark(f"critical_point {name}, {again}")
        except NotImplementedError as err:  # NUMBA_DISABLE_JIT: a kernel built on a Numba intrinsic has no Python form
            mark(f"critical_point {name}, {again.split(' (')[0]}: cannot run without Numba ({err})")
print("PHASES", json.dumps(marks))
"""


def phases(runs: int, bytecode: bool = True, src: str | None = None, jit: bool = True) -> list[tuple[str, float]]:
    """The median CPU of each stage of :data:`PHASES` over ``runs`` fresh interpreters (``jit`` False: every compiled
    function run as its Python source, ``NUMBA_DISABLE_JIT=1``, what a Numba-free start of a small chain would cost)."""
    env = environment(src, bytecode)
    if not jit:
        env["NUMBA_DISABLE_JIT"] = "1"
    code = PHASES.replace("KERNEL", _KERNEL)
    rows: list[list[tuple[str, float]]] = []
    for _ in range(runs + 1):  # the first warms the caches
        out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env, check=True).stdout
        marks = json.loads(next(line for line in out.splitlines() if line.startswith("PHASES ")).removeprefix("PHASES "))
        rows.append([(label, t - (marks[i - 1][1] if i else 0.0)) for i, (label, t) in enumerate(marks)])
    return [(label, round(statistics.median(row[i][1] for row in rows[1:]), 3)) for i, (label, _) in enumerate(rows[0])]


#: Where the children keep their bytecode (``PYTHONPYCACHEPREFIX``): cached as an installed package has it, also in a
#: shell that sets ``PYTHONDONTWRITEBYTECODE`` (this project's sessions do), where every run would otherwise compile
#: the package's sources again, a cost no installed package pays. ``--no-bytecode`` measures that way instead.
PYCACHE = Path(tempfile.gettempdir()) / "bench_startup_pycache"


def environment(src: str | None, bytecode: bool = True) -> dict[str, str]:
    env = dict(os.environ, OMP_NUM_THREADS="1", OPENBLAS_NUM_THREADS="1")
    if bytecode:
        env.pop("PYTHONDONTWRITEBYTECODE", None)
        env["PYTHONPYCACHEPREFIX"] = str(PYCACHE)
    else:
        env["PYTHONDONTWRITEBYTECODE"] = "1"
    if src:
        env["PYTHONPATH"] = src + os.pathsep + env.get("PYTHONPATH", "")
    return env


def cpu_seconds(cmd: list[str], env: dict[str, str]) -> float:
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    subprocess.run(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, env=env, check=True)
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    return (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)


def probe(args: list[str], env: dict[str, str]) -> dict:
    """One run with the probe: libraries loaded, CPU before the teardown and the teardown's, dispatchers entered."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    err = subprocess.run([sys.executable, "-c", PROBE, *args], capture_output=True, text=True, env=env).stderr
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    found = json.loads(next(line for line in err.splitlines() if line.startswith("PROBE ")).removeprefix("PROBE "))
    total = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    found["teardown_s"] = total - found["cpu_before_teardown_s"]
    return found


def top_imports(args: list[str], env: dict[str, str], count: int = 8) -> list[tuple[str, float]]:
    """The slowest top-level imports (cumulative seconds) of one run, from ``-X importtime``."""
    err = subprocess.run(
        [sys.executable, "-X", "importtime", "-m", "cosserat_chain", *args], capture_output=True, text=True, env=env
    ).stderr
    rows = []
    for line in err.splitlines():
        m = re.match(r"import time:\s+\d+ \|\s+(\d+) \| (\s*)(\S+)", line)
        if m and len(m.group(2)) <= 1:  # top level (one space after the bar)
            rows.append((m.group(3), int(m.group(1)) / 1e6))
    return sorted(rows, key=lambda r: -r[1])[:count]


def describe(label: str, times: list[float], found: dict, imports: list[tuple[str, float]]) -> dict:
    entered = found["dispatchers"]
    row = {
        "cpu_median_s": round(statistics.median(times), 3),
        "cpu_runs_s": [round(t, 3) for t in times],
        "teardown_s": round(found["teardown_s"], 3),
        "loaded_at_exit": found["loaded"],
        "dispatchers_entered": len(entered),
        "dispatchers_s": round(sum(t for _, t in entered), 3),
        "first_dispatcher_s": round(entered[0][1], 3) if entered else 0.0,
    }
    print(f"  {label}: CPU (user + sys) median of {len(times)}: {row['cpu_median_s']:.2f} s  runs: {' '.join(f'{t:.2f}' for t in times)}")
    print(f"    teardown after the last atexit handler: {row['teardown_s']:.2f} s; loaded at exit: {row['loaded_at_exit']}")
    print(
        f"    Numba dispatchers entered: {row['dispatchers_entered']}, {row['dispatchers_s']:.2f} s "
        f"(the first, with Numba's target set-up: {row['first_dispatcher_s']:.2f} s)"
    )
    print("    slowest top-level imports (cumulative, one run): " + ", ".join(f"{name} {sec:.2f} s" for name, sec in imports))
    return row


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--runs", type=int, default=5)
    parser.add_argument("--src", help="put this folder first on PYTHONPATH (measure another checkout)")
    parser.add_argument("--against", help="a second src folder (the old code), its runs interleaved with this tree's")
    parser.add_argument("--out", type=Path, help="add this run's row to a JSON file (rows keyed by the command)")
    parser.add_argument("--floor", action="store_true", help="measure the floor (FLOOR) instead of a command")
    parser.add_argument("--phases", action="store_true", help="where critical's CPU goes, stage by stage (PHASES)")
    parser.add_argument("--no-bytecode", action="store_true", help="compile the sources every run (PYTHONDONTWRITEBYTECODE)")
    parser.add_argument("--no-jit", action="store_true", help="with --phases: every compiled function as Python (NUMBA_DISABLE_JIT=1)")
    parser.add_argument("args", nargs="*", default=["critical", "--model", "sine", "--json"])
    ns = parser.parse_args()
    if ns.phases:
        stages = phases(ns.runs, not ns.no_bytecode, ns.src, not ns.no_jit)
        for label, seconds in stages:
            print(f"  {seconds:6.3f} s  {label}")
        print(f"  {sum(t for _, t in stages):6.3f} s  in all; load average: {' '.join(f'{x:.2f}' for x in os.getloadavg())}")
        if ns.out:
            results = json.loads(ns.out.read_text()) if ns.out.exists() else {}
            results["phases" + (" (NUMBA_DISABLE_JIT=1)" if ns.no_jit else "")] = {
                "cpu_median_s": dict(stages),
                "runs": ns.runs,
                "load_average_after": [round(x, 2) for x in os.getloadavg()],
            }
            ns.out.write_text(json.dumps(results, indent=1) + "\n")
        return
    if ns.floor:
        medians = floor(ns.runs, not ns.no_bytecode)
        for label, seconds in medians.items():
            print(f"  {label}: {seconds:.2f} s")
        print(f"  load average: {' '.join(f'{x:.2f}' for x in os.getloadavg())}")
        if ns.out:
            results = json.loads(ns.out.read_text()) if ns.out.exists() else {}
            results["floor"] = {"cpu_median_s": medians, "runs": ns.runs, "load_average_after": [round(x, 2) for x in os.getloadavg()]}
            ns.out.write_text(json.dumps(results, indent=1) + "\n")
        return
    trees = {"this tree": environment(ns.src, not ns.no_bytecode)}
    if ns.against:
        trees["against"] = environment(ns.against, not ns.no_bytecode)
    cmd = [sys.executable, "-m", "cosserat_chain", *ns.args]
    for env in trees.values():
        cpu_seconds(cmd, env)  # warm Numba's cache
    load_before = os.getloadavg()
    times: dict[str, list[float]] = {label: [] for label in trees}
    for _ in range(ns.runs):
        for label, env in trees.items():
            times[label].append(cpu_seconds(cmd, env))
    load_after = os.getloadavg()
    print(f"cosserat-chain {' '.join(ns.args)}")
    rows = {label: describe(label, times[label], probe(ns.args, env), top_imports(ns.args, env)) for label, env in trees.items()}
    print(f"  load average: before {' '.join(f'{x:.2f}' for x in load_before)}, after {' '.join(f'{x:.2f}' for x in load_after)}")
    if ns.out:
        results = json.loads(ns.out.read_text()) if ns.out.exists() else {}
        results[" ".join(ns.args)] = {
            "trees": {"this tree": ns.src or "the installed package", **({"against": ns.against} if ns.against else {})},
            **rows,
            "load_average_before": [round(x, 2) for x in load_before],
            "load_average_after": [round(x, 2) for x in load_after],
            "cpu": next(
                (line.split(":", 1)[1].strip() for line in Path("/proc/cpuinfo").read_text().splitlines() if line.startswith("model name")),
                "?",
            ),
        }
        ns.out.write_text(json.dumps(results, indent=1) + "\n")


if __name__ == "__main__":
    main()
