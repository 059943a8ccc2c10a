"""The nonlinear chain kernel without the IEEE divider: reciprocal square roots by estimate and Newton steps, against IEEE.

Run from the repository root::

    python benchmarks/bench_engine_rsqrt.py            # about two minutes on 2 cores
    python benchmarks/bench_engine_rsqrt.py --quick    # 7 rounds instead of 15
    python benchmarks/bench_engine_rsqrt.py --markdown benchmarks/results/engine_rsqrt.json

Issue 44 item 4 asks for a bond pass without the IEEE divider "if it keeps forces within a
few ulps of the IEEE ones" and is faster. Each bond of the nonlinear model has four links,
each needing rest / sqrt(q) with q the squared link length: a ``vsqrtpd`` and a ``vdivpd``
(0.86 ns a double on this machine's divider). The contenders are the package's chain kernel
(``models/nonlinear.py``: sines, bonds, differences in blocks of 519 columns) compiled here
with that one expression replaced:

* ``ieee``: rest / sqrt(q), the package's kernel;
* ``bits``: the integer estimate 0x5FE6EB50C7B537A9 - (bits(q) >> 1) (3.4 % error), three
  Newton steps and a last step on the residual 1 - q y^2: plain arithmetic only, portable;
* ``f32``: q rounded to float32, 1 / sqrt(q) there with the fast-math flags ``afn arcp`` on
  those two instructions only (LLVM then emits a float32 estimate, ``vrsqrtps`` or ``vrsqrt14ps``, and one Newton step,
  about 2^-22), then two Newton steps in double;
* ``f32_series``: the same estimate, then one second-order correction
  y (1 + e/2 + 3 e^2/8), e = 1 - q y^2;
* ``rsqrt14``: the hardware estimate ``vrsqrt14pd`` (2^-14, AVX-512 only) through a
  vector-function-ABI variant that LLVM's loop vectoriser substitutes for a scalar call,
  then a third-order correction y (1 + e/2 + 3 e^2/8 + 5 e^3/16). Numba has no vector
  types; this is the only way found to put the instruction into an auto-vectorised loop.

Measured: thread CPU per column of the kernel alone, interleaved rounds (each round runs
every contender once, the order rotated), medians and the range of the per-round ratios
to ``ieee``; 7, 101 and 10^4 particles, a moving chain (``harness.moving_state``). Then the
same in a child process with ``NUMBA_OPT=max``, numba's process-wide setting under which
the vectoriser runs before the inliner, so that the ``rsqrt14`` variant's vector calls are
inlined (in the default setting they stay calls, one per 8 lanes, and the registers spill
around them). Accuracy: each variant's rest * (1 / sqrt(q)) against the IEEE quotient in
ulps on random q over the range a moving chain sees, and its forces against the IEEE
kernel's on random states of several chains (max |dF| / max |F|). Last, whole steps: ``integrate``
as ``bench_throughput.py`` times the package, with the ``ieee``, ``f32_series`` and ``rsqrt14``
kernels each as a model of its own (the package's engine and loop), against the package's own
nonlinear model, interleaved, M particle-steps per thread CPU-second.

Results go to ``benchmarks/results/engine_rsqrt.json`` (``engine_rsqrt-quick.json`` with
``--quick``); the markdown table is printed at the end.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
from llvmlite import binding, ir
from numba import carray, njit, types
from numba.extending import intrinsic

import harness
from cosserat_chain import ChainParams
from cosserat_chain.models import nonlinear as nl
from cosserat_chain.models.base import FORCE_SIGNATURE, KERNEL_OPTIONS, stack_floats

HERE = Path(__file__).resolve().parent
RESULTS = HERE / "results"
OPTIONS = {**KERNEL_OPTIONS, "cache": False}
SIZES = (7, 101, 10001)
MAGIC = 0x5FE6EB50C7B537A9
HAS_AVX512 = "+avx512f" in binding.get_host_cpu_features().flatten()


# ----------------------------------------------------------------------------- LLVM pieces
@intrinsic
def _as_int(typingctx, x):
    def codegen(context, builder, sig, args):
        return builder.bitcast(args[0], ir.IntType(64))

    return types.int64(types.float64), codegen


@intrinsic
def _as_float(typingctx, i):
    def codegen(context, builder, sig, args):
        return builder.bitcast(args[0], ir.DoubleType())

    return types.float64(types.int64), codegen


_FAST = ("afn", "arcp", "contract", "nnan", "ninf")


@intrinsic
def _rsqrt_f32(typingctx, x):
    """1 / sqrt(x) in float32 with fast-math flags on these instructions only (LLVM: the float32 estimate and a Newton step)."""

    def codegen(context, builder, sig, args):
        f = builder.fptrunc(args[0], ir.FloatType())
        sqrt = builder.module.declare_intrinsic("llvm.sqrt", [ir.FloatType()])
        root = builder.call(sqrt, [f], fastmath=_FAST)
        return builder.fpext(builder.fdiv(ir.Constant(ir.FloatType(), 1.0), root, flags=_FAST), ir.DoubleType())

    return types.float64(types.float64), codegen


_V8 = ir.VectorType(ir.DoubleType(), 8)
_SCALAR, _VECTOR, _MASKED = "bench_rsqrt14", "bench_rsqrt14_v8", "bench_rsqrt14_m8"


def _hardware(builder, module, vec):
    name = "llvm.x86.avx512.rsqrt14.pd.512"
    fn = module.globals.get(name) or ir.Function(module, ir.FunctionType(_V8, [_V8, _V8, ir.IntType(8)]), name)
    return builder.call(fn, [vec, ir.Constant(_V8, None), ir.Constant(ir.IntType(8), -1)])


def _rsqrt14_functions(module):
    """The scalar function (one lane of the vector instruction: the same bits) and its unmasked and masked 8-lane variants."""
    if _SCALAR in module.globals:
        return module.globals[_SCALAR]
    ones = ir.Constant(_V8, [1.0] * 8)
    vector = ir.Function(module, ir.FunctionType(_V8, [_V8]), _VECTOR)
    masked = ir.Function(module, ir.FunctionType(_V8, [_V8, ir.VectorType(ir.IntType(1), 8)]), _MASKED)
    for fn in (vector, masked):
        fn.linkage = "weak_odr"  # not discardable before the vectoriser looks them up
        set.add(fn.attributes, "alwaysinline")
    b = ir.IRBuilder(vector.append_basic_block())
    b.ret(_hardware(b, module, vector.args[0]))
    b = ir.IRBuilder(masked.append_basic_block())
    b.ret(_hardware(b, module, b.select(masked.args[1], masked.args[0], ones)))
    scalar = ir.Function(module, ir.FunctionType(ir.DoubleType(), [ir.DoubleType()]), _SCALAR)
    scalar.linkage = "linkonce_odr"
    # llvmlite knows no string attributes: added to the set as they are printed.
    for attribute in ("noinline", "nounwind", "willreturn", "memory(none)"):
        set.add(scalar.attributes, attribute)
    set.add(scalar.attributes, f'"vector-function-abi-variant"="_ZGV_LLVM_N8v_{_SCALAR}({_VECTOR}),_ZGV_LLVM_M8v_{_SCALAR}({_MASKED})"')
    b = ir.IRBuilder(scalar.append_basic_block())
    lane = ir.Constant(ir.IntType(32), 0)
    b.ret(b.extract_element(_hardware(b, module, b.insert_element(ones, scalar.args[0], lane)), lane))
    return scalar


@intrinsic
def _rsqrt14(typingctx, x):
    def codegen(context, builder, sig, args):
        return builder.call(_rsqrt14_functions(builder.module), [args[0]])

    return types.float64(types.float64), codegen


# ----------------------------------------------------------------------------- rest / sqrt(q)
@njit(inline="always", **OPTIONS)
def ieee(rest, q):  # pragma: no cover - compiled
    return rest / math.sqrt(q)


@njit(inline="always", **OPTIONS)
def _newton(y, q):  # pragma: no cover - compiled
    return y + (0.5 * y) * (1.0 - (q * y) * y)


@njit(inline="always", **OPTIONS)
def bits(rest, q):  # pragma: no cover - compiled
    y = _as_float(np.int64(MAGIC) - (_as_int(q) >> np.int64(1)))
    half = 0.5 * q
    y = y * (1.5 - half * y * y)
    y = y * (1.5 - half * y * y)
    y = y * (1.5 - half * y * y)
    return rest * _newton(y, q)


@njit(inline="always", **OPTIONS)
def f32(rest, q):  # pragma: no cover - compiled
    return rest * _newton(_newton(_rsqrt_f32(q), q), q)


@njit(inline="always", **OPTIONS)
def f32_series(rest, q):  # pragma: no cover - compiled
    y = _rsqrt_f32(q)
    e = 1.0 - (q * y) * y
    ry = rest * y
    return ry + ry * (e * (0.5 + 0.375 * e))


@njit(inline="always", **OPTIONS)
def rsqrt14(rest, q):  # pragma: no cover - compiled
    y = _rsqrt14(q)
    e = 1.0 - (q * y) * y
    ry = rest * y
    return ry + ry * (e * (0.5 + e * (0.375 + e * 0.3125)))


VARIANTS = {"ieee": ieee, "bits": bits, "f32": f32, "f32_series": f32_series}
if HAS_AVX512:
    VARIANTS["rsqrt14"] = rsqrt14


# ----------------------------------------------------------------------------- the kernel
def kernel_with(quotient):
    """``models.nonlinear.nonlinear_forces_kernel`` with rest / sqrt(q) of every link computed by ``quotient``."""

    @njit(inline="always", **OPTIONS)
    def bond(a, b, h, E1, E2, rest1, rest2, c0, s0, c1, s1, du, dv):  # pragma: no cover - compiled
        # models/nonlinear.py::_bond line by line but for the quotient.
        ax, ay, bx, by = a * c0 - b * s0, a * s0 + b * c0, a * c0 + b * s0, a * s0 - b * c0
        cx, cy, dx, dy = -a * c1 - b * s1, -a * s1 + b * c1, -a * c1 + b * s1, -a * s1 - b * c1
        ex, ey = h + du, dv
        lx, ly = ex + cx - ax, ey + cy - ay
        t = E1 * (1.0 - quotient(rest1, lx * lx + ly * ly))
        top_x, top_y = t * lx, t * ly
        lx, ly = ex + dx - bx, ey + dy - by
        t = E1 * (1.0 - quotient(rest1, lx * lx + ly * ly))
        bot_x, bot_y = t * lx, t * ly
        lx, ly = ex + dx - ax, ey + dy - ay
        t = E2 * (1.0 - quotient(rest2, lx * lx + ly * ly))
        ad_x, ad_y = t * lx, t * ly
        lx, ly = ex + cx - bx, ey + cy - by
        t = E2 * (1.0 - quotient(rest2, lx * lx + ly * ly))
        bc_x, bc_y = t * lx, t * ly
        fx = top_x + bot_x + ad_x + bc_x
        fy = top_y + bot_y + ad_y + bc_y
        m0 = ax * (top_y + ad_y) - ay * (top_x + ad_x) + bx * (bot_y + bc_y) - by * (bot_x + bc_x)
        m1 = -(cx * (top_y + bc_y) - cy * (top_x + bc_x) + dx * (bot_y + ad_y) - dy * (bot_x + ad_x))
        return fx, fy, m0, m1

    @njit(inline="always", **OPTIONS)
    def bonds(a, b, h, E1, E2, rest1, rest2, trig, out, u, v, first, last):  # pragma: no cover - compiled
        for i in range(first, last):
            j = i + np.uint64(1)
            fx, fy, m0, m1 = bond(a, b, h, E1, E2, rest1, rest2, trig[1, i], trig[0, i], trig[1, j], trig[0, j], u[j] - u[i], v[j] - v[i])
            out[0, i], out[1, i], out[2, i], out[3, i] = fx, fy, m0, m1

    width, trig_size, bond_size, block = nl._WIDTH, nl._TRIG_SIZE, nl._BOND_SIZE, nl.BLOCK
    turns, sines, differences = nl._whole_turns, nl._sines, nl._differences

    @njit(FORCE_SIGNATURE, **OPTIONS)
    def kernel(x, coef, out, start, stop):  # pragma: no cover - compiled
        a, b, h, E1, E2, rest1, rest2 = coef[0], coef[1], coef[2], coef[3], coef[4], coef[5], coef[6]
        trig = carray(stack_floats(trig_size), (2, width))
        scratch = carray(stack_floats(bond_size), (4, width))
        for c0 in range(start, stop, block):
            c1 = min(c0 + block, stop)
            u, v, phi = x[0, c0 - 1 :], x[1, c0 - 1 :], x[2, c0 - 1 :]
            count = np.uint64(c1 - c0)
            one, two = np.uint64(1), np.uint64(2)
            sines(trig, phi, np.uint64(0), turns(count + two))
            sines(trig, phi, turns(count + two), count + two)
            bonds(a, b, h, E1, E2, rest1, rest2, trig, scratch, u, v, np.uint64(0), turns(count + one))
            bonds(a, b, h, E1, E2, rest1, rest2, trig, scratch, u, v, turns(count + one), count + one)
            out_u, out_v, out_phi = out[0, c0:c1], out[1, c0:c1], out[2, c0:c1]
            differences(scratch, out_u, out_v, out_phi, np.uint64(0), turns(count))
            differences(scratch, out_u, out_v, out_phi, turns(count), count)

    return kernel


def quotients_of(quotient):
    @njit(**OPTIONS)
    def apply(rest, q, out):  # pragma: no cover - compiled
        for i in range(q.size):
            out[i] = quotient(rest, q[i])

    return apply


@njit(**OPTIONS)
def repeat(kernel, x, coef, out, start, stop, times):  # pragma: no cover - compiled
    for _ in range(times):
        kernel(x, coef, out, start, stop)


# ----------------------------------------------------------------------------- measurements
def packed_counts(kernel) -> dict:
    import re

    asm = kernel.inspect_asm(kernel.signatures[0])
    return {
        "vsqrtpd": len(re.findall(r"\bvsqrtpd\b", asm)),
        "vdivpd": len(re.findall(r"\bvdivpd\b", asm)),
        "vrsqrt": len(re.findall(r"\bvrsqrt\w*p[sd]\b", asm)),
        "calls": len(re.findall(r"\bcall", asm)),
        "packed": len(re.findall(r"\bv\w+p[ds]\s+[^\n]*%[yz]mm", asm)),
    }


def accuracy(kernels: dict) -> dict:
    """Each variant's quotient in ulps of the IEEE one, and its forces against the IEEE kernel's on several chains."""
    rng = np.random.default_rng(1)
    out = {}
    chains = [ChainParams(N=3), ChainParams(N=50), ChainParams(N=50, a=0.45, b=0.1, E2=0.3), ChainParams(N=500, a=0.1, b=0.4, E1=2.0)]
    rest = ChainParams().h - 2 * ChainParams().a
    q = (rest * rng.uniform(0.5, 2.0, 200_000)) ** 2
    reference = np.empty_like(q)
    quotients_of(ieee)(rest, q, reference)
    for name in kernels:
        mine = np.empty_like(q)
        quotients_of(VARIANTS[name])(rest, q, mine)
        ulps = np.abs(mine - reference) / np.spacing(np.abs(reference))
        worst = 0.0
        for p in chains:
            coef = nl.NonlinearModel.coefficients(p)
            for seed in range(5):
                x, _ = harness.moving_state(p, seed=seed, angle=0.5)
                n = p.n_particles
                f_ref, f_new = np.zeros_like(x), np.zeros_like(x)
                kernels["ieee"](x, coef, f_ref, 1, n - 1)
                kernels[name](x, coef, f_new, 1, n - 1)
                worst = max(worst, float(np.abs(f_new - f_ref).max() / np.abs(f_ref).max()))
        out[name] = {"quotient_ulps_max": float(ulps.max()), "quotient_ulps_mean": float(ulps.mean()), "forces_max_relative": worst}
    return out


def timings(kernels: dict, rounds: int, log) -> dict:
    out = {}
    for n in SIZES:
        p = ChainParams(N=(n - 1) // 2)
        x, _ = harness.moving_state(p)
        coef = nl.NonlinearModel.coefficients(p)
        f = np.zeros_like(x)
        times = max(1, int(2e6 / n))
        contenders = {
            name: (lambda k=k, x=x, coef=coef, f=f, n=n, times=times: repeat(k, x, coef, f, 1, n - 1, times)) for name, k in kernels.items()
        }
        for k in kernels.values():
            repeat(k, x, coef, f, 1, n - 1, 1)
        samples = harness.interleaved(contenders, rounds)
        per_column = {name: [s["thread_s"] / times / (n - 2) * 1e9 for s in runs] for name, runs in samples.items()}
        row = {}
        for name, values in per_column.items():
            ratios = [b / v for b, v in zip(per_column["ieee"], values)]
            row[name] = {"ns_per_column": harness.spread(values), "speed_vs_ieee": harness.spread(ratios)}
        out[str(n)] = row
        log(f"  {n} particles: " + ", ".join(f"{k} {v['speed_vs_ieee']['median']:.3f}x" for k, v in row.items()))
    return out


#: The variants timed in whole steps: the reference and the fastest of the portable and the hardware estimates.
STEP_VARIANTS = ("ieee", "f32_series", "rsqrt14")


def step_timings(kernels: dict, rounds: int, log) -> dict:
    """Whole damped Verlet steps, ``integrate`` as bench_throughput.py times the package, with each variant's kernel.

    Each variant runs as a model of its own (the nonlinear model with that ``force_kernel``),
    so the engine, its loop and its cached code are the package's; ``package`` is the
    package's own nonlinear model (the IEEE kernel, compiled into the package's cache).
    """
    from cosserat_chain import moment_load
    from cosserat_chain.models import NonlinearModel, register_model, unregister_model
    from cosserat_chain.numerics.dynamics import integrate
    from cosserat_chain.numerics.integrators import default_time_step

    names = {"package": "nonlinear"}
    for name in STEP_VARIANTS:
        if name in kernels:
            model = type(f"Bench_{name}", (NonlinearModel,), {"name": f"bench_{name}", "force_kernel": kernels[name]})()
            names[name] = register_model(model).name
    out = {}
    try:
        for n in SIZES:
            p = ChainParams(N=(n - 1) // 2)
            dt = default_time_step(p)
            steps = max(300, int(1e7 / n))
            x0, v0 = harness.moving_state(p)

            def run(model, p=p, dt=dt, steps=steps, x0=x0, v0=v0):
                return integrate(p, model, moment_load(0.05, 0), t_end=steps * dt, dt=dt, x0=x0, v0=v0, n_frames=2, threads=1)

            contenders = {name: (lambda model=model: run(model)) for name, model in names.items()}
            for call in contenders.values():
                call()
            samples = harness.interleaved(contenders, rounds)
            rate = {name: [n * steps / s["thread_s"] / 1e6 for s in runs] for name, runs in samples.items()}
            row = {}
            for name, values in rate.items():
                ratios = [v / b for b, v in zip(rate["ieee"], values)]
                row[name] = {"M_particle_steps_per_cpu_s": harness.spread(values), "speed_vs_ieee": harness.spread(ratios)}
            out[str(n)] = row
            log(f"  steps, {n} particles: " + ", ".join(f"{k} {v['speed_vs_ieee']['median']:.3f}x" for k, v in row.items()))
    finally:
        for name, model in names.items():
            if name != "package":
                unregister_model(model)
    return out


def measure(rounds: int, log) -> dict:
    kernels = {name: kernel_with(fn) for name, fn in VARIANTS.items()}
    return {
        "numba_opt": os.environ.get("NUMBA_OPT", "default"),
        "code": {name: packed_counts(k) for name, k in kernels.items()},
        "accuracy": accuracy(kernels),
        "timings": timings(kernels, rounds, log),
        "steps": step_timings(kernels, max(5, rounds * 3 // 5), log),
    }


def markdown(result: dict) -> str:
    lines = [
        f"Kernel alone, thread CPU, {result['rounds']} interleaved rounds; {result['environment'].get('cpu', '')}; "
        f"load average at start {result['load_average']:.1f}.",
        "",
        "| numba setting | variant | "
        + " | ".join(f"{n} particles" for n in SIZES)
        + " | quotient, ulps (max) | forces, max abs(dF) / max abs(F) | vsqrtpd / vdivpd / vrsqrt / calls |",
        "|---|---|" + "---:|" * len(SIZES) + "---:|---:|---:|",
    ]
    for setting, part in result["runs"].items():
        for name in part["code"]:
            cells = []
            for n in SIZES:
                row = part["timings"][str(n)][name]
                ratio = row["speed_vs_ieee"]
                cells.append(f"{row['ns_per_column']['median']:.2f} ns, {ratio['median']:.2f}x ({ratio['min']:.2f}-{ratio['max']:.2f})")
            acc, code = part["accuracy"][name], part["code"][name]
            lines.append(
                f"| {setting} | {name} | " + " | ".join(cells) + f" | {acc['quotient_ulps_max']:.1f} | {acc['forces_max_relative']:.1e} | "
                f"{code['vsqrtpd']} / {code['vdivpd']} / {code['vrsqrt']} / {code['calls']} |"
            )
    lines += [
        "",
        "Whole steps (`integrate`, damped Verlet, one thread), each variant's kernel as a model of its own; M particle-steps per "
        "thread CPU-second and speed against the `ieee` model, median (per-round range):",
        "",
        "| numba setting | variant | " + " | ".join(f"{n} particles" for n in SIZES) + " |",
        "|---|---|" + "---:|" * len(SIZES),
    ]
    for setting, part in result["runs"].items():
        for name in part.get("steps", {}).get(str(SIZES[0]), {}):
            cells = []
            for n in SIZES:
                row = part["steps"][str(n)][name]
                ratio = row["speed_vs_ieee"]
                cells.append(
                    f"{row['M_particle_steps_per_cpu_s']['median']:.1f}, {ratio['median']:.2f}x ({ratio['min']:.2f}-{ratio['max']:.2f})"
                )
            lines.append(f"| {setting} | {name} | " + " | ".join(cells) + " |")
    return "\n".join(lines)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--quick", action="store_true", help="7 rounds instead of 15")
    parser.add_argument("--child", action="store_true", help=argparse.SUPPRESS)
    parser.add_argument("--markdown", type=Path, metavar="JSON", help="only print the table of a saved result")
    args = parser.parse_args()
    if args.markdown:
        print(markdown(json.loads(args.markdown.read_text())))
        return
    rounds = 7 if args.quick else 15

    def log(message):
        print(message, file=sys.stderr, flush=True)

    if args.child:
        print(json.dumps(measure(rounds, log)))
        return
    start = time.perf_counter()
    result = {"rounds": rounds, "load_average": os.getloadavg()[0], "environment": harness.environment(), "runs": {}}
    log("numba's default optimisation")
    result["runs"]["default"] = measure(rounds, log)
    log("NUMBA_OPT=max (a child process)")
    # With a cache of its own: numba's cache key does not hold the optimisation setting, so a
    # package function compiled anew under NUMBA_OPT=max would be saved for every later process.
    with tempfile.TemporaryDirectory(prefix="cosserat-opt-max-") as cache:
        child = subprocess.run(
            [sys.executable, __file__, "--child", *(["--quick"] if args.quick else [])],
            env={**os.environ, "NUMBA_OPT": "max", "NUMBA_CACHE_DIR": cache}, capture_output=True, text=True, check=True,
        )  # fmt: skip
    log(child.stderr.strip())
    result["runs"]["NUMBA_OPT=max"] = json.loads(child.stdout)
    result["elapsed_s"] = time.perf_counter() - start
    path = RESULTS / ("engine_rsqrt-quick.json" if args.quick else "engine_rsqrt.json")
    path.write_text(json.dumps(result, indent=1))
    log(f"wrote {path}")
    print(markdown(result))


if __name__ == "__main__":
    main()
