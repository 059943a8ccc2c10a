"""What the benchmarks share: the C references (built now, called through ctypes), the moving
start state, timing of interleaved rounds, summaries, a competing CPU-bound process, the
environment.

Benchmark code only, not part of the package. Timing: every measurement records the CPU
time of the calling thread (``time.thread_time``: what a busy neighbour on the other
core does not change), the CPU time of the process (all threads) and the wall time.
"""

from __future__ import annotations

import contextlib
import ctypes
import hashlib
import os
import platform
import resource
import shlex
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
#: Flags of the vectorised C reference (issue 11).
VECTOR_CFLAGS = "-O3 -march=native -ffast-math -mprefer-vector-width=512 -fopenmp-simd"
#: Flags of the same-arithmetic C loop: no fast-math, so that it rounds as the package does.
SAME_CFLAGS = "-O3 -march=native"

_DP = ctypes.POINTER(ctypes.c_double)
_L, _I, _D = ctypes.c_long, ctypes.c_int, ctypes.c_double


def _ptr(a: np.ndarray):
    assert a.dtype == np.float64 and a.flags.c_contiguous, "C references take C-contiguous float64 arrays"
    return a.ctypes.data_as(_DP)


def build(source: Path, cflags: str, directory: Path) -> tuple[ctypes.CDLL, list[str]]:
    """Compile ``source`` into a shared library in ``directory`` with gcc and ``cflags``; (library, command)."""
    library = directory / f"lib{source.stem}.so"
    command = ["gcc", *shlex.split(cflags), "-shared", "-fPIC", "-o", str(library), str(source), "-lm"]
    subprocess.run(command, check=True)
    return ctypes.CDLL(str(library)), command


class CReferences:
    """Both C references, compiled at benchmark time into a temporary directory.

    * ``vectorised``: ``c/verlet_vectorised.c`` with :data:`VECTOR_CFLAGS`, one chain and a
      batch-innermost batch, with or without the energy sums.
    * ``same``: ``c/verlet_nonlinear.c`` with :data:`SAME_CFLAGS`, a line-by-line copy of
      the package's loop (libm sin/cos), which reproduces its states to round-off.
    """

    def __init__(self, vector_cflags: str = VECTOR_CFLAGS, same_cflags: str = SAME_CFLAGS):
        self._tmp = tempfile.TemporaryDirectory(prefix="cosserat-bench-")
        directory = Path(self._tmp.name)
        self.vec, vec_cmd = build(HERE / "c" / "verlet_vectorised.c", vector_cflags, directory)
        self.same, same_cmd = build(HERE / "c" / "verlet_nonlinear.c", same_cflags, directory)
        self.commands = {"vectorised": " ".join(vec_cmd), "same_arithmetic": " ".join(same_cmd)}
        self.vec.run_single.argtypes = [_DP, _DP, _L, _DP, _DP, _DP, _L, _L, _D, _D, _I, _DP]
        self.vec.run_single.restype = _I
        self.vec.run_batch.argtypes = [_DP, _DP, _L, _L, _DP, _DP, _DP, _L, _L, _DP, _D, _I, _DP]
        self.vec.run_batch.restype = _I
        self.same.run.argtypes = [_DP, _DP, _DP, _I, _DP, _DP, _I, _I, _D]
        self.same.run.restype = None
        self.same.prepare.argtypes = [_DP, _DP, _I, _DP, _I, _D]
        self.same.prepare.restype = None
        self.same.run_acc.argtypes = [_DP]
        self.same.run_acc.restype = _I

    def vec_single(self, x, v, coef, mass, table, n_steps, col, moment, max_displacement, energy, acc) -> int:
        """``c/verlet_vectorised.c::run_single`` (arguments as :func:`reference.run_single` without ``fused``)."""
        n = x.shape[1]
        return self.vec.run_single(
            _ptr(x), _ptr(v), n, _ptr(coef), _ptr(mass), _ptr(table), n_steps, col, moment, max_displacement, int(energy), _ptr(acc)
        )

    def vec_batch(self, x, v, coef, mass, factors, n_steps, col, moments, max_displacement, energy, acc) -> int:
        """``c/verlet_vectorised.c::run_batch`` (arguments as :func:`reference.run_batch`)."""
        _, n, size = x.shape
        return self.vec.run_batch(
            _ptr(x), _ptr(v), n, size, _ptr(coef), _ptr(mass), _ptr(factors), n_steps, col, _ptr(moments), max_displacement,
            int(energy), _ptr(acc),
        )  # fmt: skip

    def same_single(self, x, v, coef, table, n_steps, col, moment) -> tuple[np.ndarray, int]:
        """``c/verlet_nonlinear.c``: forces at the start state, then ``n_steps`` steps in place; (acc, status)."""
        n = x.shape[1]
        f = np.zeros((3, n))
        self.same.prepare(_ptr(x), _ptr(f), n, _ptr(coef), col, moment)
        self.same.run(_ptr(x), _ptr(v), _ptr(f), n, _ptr(coef), _ptr(table), n_steps, col, moment)
        acc = np.zeros(2)
        status = self.same.run_acc(_ptr(acc))
        return acc, status


# ----------------------------------------------------------------------------- states
def moving_state(params, seed: int = 0, angle: float = 0.05) -> tuple[np.ndarray, np.ndarray]:
    """A chain in motion with every angle non-zero: (x0, v0), each (3, 2N+1), ends clamped.

    Angles |phi| uniform in [angle/5, angle] with random signs, displacements up to
    0.005 h, velocities of about 0.01 (a chain at rest would let a kernel with a
    tiny-angle shortcut skip its trigonometry).
    """
    rng = np.random.default_rng(seed)
    n = params.n_particles
    x = np.zeros((3, n))
    v = np.zeros((3, n))
    free = n - 2
    x[0, 1:-1] = 0.005 * params.h * rng.uniform(-1.0, 1.0, free)
    x[1, 1:-1] = 0.005 * params.h * rng.uniform(-1.0, 1.0, free)
    x[2, 1:-1] = angle * rng.uniform(0.2, 1.0, free) * rng.choice((-1.0, 1.0), free)
    v[:, 1:-1] = 0.01 * rng.standard_normal((3, free))
    return x, v


# ----------------------------------------------------------------------------- timing
def timed(fn) -> tuple[dict, object]:
    """Call ``fn()``; its thread CPU, process CPU and wall seconds, the thread's kernel (system) seconds, and its result.

    The thread CPU time includes the kernel's work for the thread, mostly first touches of
    freshly allocated memory: on this machine (a virtual machine) a fresh huge page can cost
    tens of microseconds, so a call that allocates its output pays for it there.
    """
    usage = resource.getrusage(resource.RUSAGE_THREAD).ru_stime
    thread, process, wall = time.thread_time(), time.process_time(), time.perf_counter()
    out = fn()
    times = {"thread_s": time.thread_time() - thread, "process_s": time.process_time() - process, "wall_s": time.perf_counter() - wall}
    times["system_s"] = resource.getrusage(resource.RUSAGE_THREAD).ru_stime - usage
    return times, out


def interleaved(contenders: dict, rounds: int, log=None, check=None) -> dict:
    """Run every contender once per round, the order rotated each round; all samples per contender.

    ``contenders``: name -> callable (returning anything). ``check(name, result)`` is called
    after each run (e.g. to assert a status). Returns name -> list of :func:`timed` dicts.
    """
    names = list(contenders)
    samples = {name: [] for name in names}
    for r in range(rounds):
        order = names[r % len(names) :] + names[: r % len(names)]
        for name in order:
            times, out = timed(contenders[name])
            if check is not None:
                check(name, out)
            samples[name].append(times)
        if log is not None:
            log(f"    round {r + 1}/{rounds} done")
    return samples


def spread(values) -> dict:
    """Median, quartiles, min and max of a list of numbers."""
    values = sorted(float(x) for x in values)
    if len(values) >= 2:
        q1, _, q3 = statistics.quantiles(values, n=4, method="inclusive")
    else:
        q1 = q3 = values[0]
    return {"median": statistics.median(values), "q1": q1, "q3": q3, "min": values[0], "max": values[-1], "n": len(values)}


def rates(samples: list[dict], work: float) -> dict:
    """M work units per second (per thread CPU-second, process CPU-second, wall-second), each with its spread."""
    return {
        key.replace("_s", ""): spread([work / s[key] / 1e6 for s in samples if s[key] > 0]) for key in ("thread_s", "process_s", "wall_s")
    }


# ----------------------------------------------------------------------------- a busy machine
_SPIN = "while True:\n    pass\n"


@contextlib.contextmanager
def busy_neighbour():
    """A competing CPU-bound process (a spinning Python loop) for the duration of the block.

    Only this process is stopped afterwards, by its own pid.
    """
    proc = subprocess.Popen([sys.executable, "-c", _SPIN], stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    try:
        time.sleep(0.2)  # let it start spinning
        yield proc.pid
    finally:
        proc.terminate()
        try:
            proc.wait(timeout=5)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait()


def free_cores(seconds: float = 0.4) -> float:
    """How many cores two spinning threads got: CPU seconds of the process per wall second.

    Near 2 on an idle two-core machine, near 1 when another process keeps a core busy.
    Two Python threads cannot spin together (the GIL), so this uses two processes.
    """
    code = f"import time\nend = time.perf_counter() + {seconds}\nwhile time.perf_counter() < end:\n    pass\nprint(time.process_time())"
    start = time.perf_counter()
    procs = [subprocess.Popen([sys.executable, "-c", code], stdout=subprocess.PIPE, text=True) for _ in range(2)]
    cpu = sum(float(p.communicate()[0]) for p in procs)
    return cpu / max(time.perf_counter() - start, seconds)


# ----------------------------------------------------------------------------- environment
def _run(cmd: list[str]) -> str | None:
    try:
        return subprocess.run(cmd, capture_output=True, text=True, cwd=ROOT, check=True).stdout.strip()
    except Exception:  # noqa: BLE001 - informational only
        return None


def environment() -> dict:
    """Machine, versions and the state of the package's source (commit, and a hash of any local changes)."""
    import numba
    import scipy

    cpu = None
    with contextlib.suppress(OSError):
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                cpu = line.split(":", 1)[1].strip()
                break
    gcc = _run(["gcc", "--version"])
    import cosserat_chain

    package_file = Path(cosserat_chain.__file__).resolve()
    if ROOT in package_file.parents:
        head = _run(["git", "rev-parse", "--short", "HEAD"])
        diff = _run(["git", "diff", "HEAD", "--", "src"]) or ""
        diff += _run(["git", "ls-files", "--others", "--exclude-standard", "--", "src"]) or ""
        modified = bool(diff)
        diff_sha1 = hashlib.sha1(diff.encode()).hexdigest()[:12] if diff else None
    else:
        # The package imported from elsewhere (e.g. `git archive HEAD src` unpacked into a
        # temporary folder, to measure a commit while the checkout is being edited).
        head = os.environ.get("BENCH_PACKAGE_COMMIT", f"unknown (imported from {package_file.parent})")
        modified, diff_sha1 = False, None
    try:
        import llvmlite.binding as llvm

        llvm_cpu = llvm.get_host_cpu_name()
    except Exception:  # noqa: BLE001 - informational only
        llvm_cpu = None
    return {
        "cpu": cpu,
        "llvm_cpu": llvm_cpu,
        "cores": os.cpu_count(),
        "python": platform.python_version(),
        "numpy": np.__version__,
        "scipy": scipy.__version__,
        "numba": numba.__version__,
        "numba_threading_layer": _threading_layer(),
        "gcc": gcc.splitlines()[0] if gcc else None,
        "package_path": str(package_file.parent),
        "git_head": head,
        "src_modified": modified,
        "src_diff_sha1": diff_sha1,
        "loadavg_start": list(os.getloadavg()),
    }


def _threading_layer() -> str | None:
    import numba

    try:
        return numba.threading_layer()
    except ValueError:  # no parallel function has run yet
        return None


def package_label(env: dict) -> str:
    """``abc1234`` or ``abc1234 + local changes (diff sha1 ...)``."""
    if env.get("src_modified"):
        return f"{env['git_head']} + uncommitted changes in src/ (diff sha1 {env['src_diff_sha1']})"
    return str(env["git_head"])
