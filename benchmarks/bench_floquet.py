"""Floquet multipliers from the segments' product (periodic Schur form) against the formed product's eigenvalues.

Run from the repository root::

    python benchmarks/bench_floquet.py                      # all parts (a few minutes on one core)
    python benchmarks/bench_floquet.py --parts products     # only the synthetic products
    python benchmarks/bench_floquet.py --sizes 6 18 54 --segments 10 40 160 --repeats 3

CPU seconds (``time.process_time``, one BLAS thread), the methods interleaved, each timed
``--repeats`` times and the least kept:

``products``
    m factors G_k = S_{k+1} D_k S_k^-1 of size n (S_k = I + 0.2 / sqrt(n) * random, S_{m+1} = S_1;
    D_k block diagonal with n / 2 rotating pairs of radius exp(-c_i), c_i spread over [0, 3]),
    whose product's multipliers are exactly exp(-m c_i) e^{+-i theta}, down to e^{-3m}. Against
    n (``--sizes``) and m (``--segments``): ``periodic_schur_multipliers``, the formed product's
    eigenvalues (``numpy.linalg.eigvals`` of G_m ... G_1), and the pencil of the pairwise
    QR-eliminated chain (Fairgrieve and Jepson's, AUTO's FLOWKM: what the collocation used
    before); each method's worst error in ln |mu| over the multipliers above 1e-300 (the
    formed product's and the pencil's below their round-off are counted as they come).
``orbits``
    The nonlinear N = 1 chain near its SNIC (M = 0.265, T = 15.9, smallest multiplier about
    1e-26): the relative error of sum ln |mu| against Liouville's -T sum gamma_i / m_i for the
    dense shooting's formed monodromy and for ``segments`` = 4, 16, 64 (with each call's CPU
    time), and for the collocation on 100 intervals of NCOL = 7 by the periodic Schur form and
    by the pencil, with the cost of the multipliers alone; and the cost of the two on the sine
    chain's collocation orbits at N = 2, 5, 10 (M = 0.5, the default mesh), with their largest
    difference over the multipliers above 1e-10.

Results go to ``benchmarks/results/floquet.json`` (``docs/periodic-orbits.md``).
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import time
from pathlib import Path

import numpy as np
import scipy.linalg as sla

from cosserat_chain import ChainParams
from cosserat_chain.linalg.threads import one_blas_thread
from cosserat_chain.numerics import collocation_core
from cosserat_chain.numerics.collocation import find_collocation_orbit
from cosserat_chain.numerics.floquet import periodic_schur_multipliers
from cosserat_chain.numerics.periodic import find_periodic_orbit
from cosserat_chain.state import pack, per_dof

RESULTS = Path(__file__).resolve().parent / "results"
SIZES = (6, 18, 54, 114)
SEGMENTS = (10, 40, 160)
N1 = ChainParams(N=1)
SHOOTING = {"tol": 1e-10, "rtol": 1e-12, "atol": 1e-12}


def _least(calls: dict, repeats: int) -> tuple[dict, dict]:
    """The least CPU seconds of each named call over ``repeats`` interleaved rounds, and each call's last result."""
    best, results = dict.fromkeys(calls, math.inf), {}
    for _ in range(repeats):
        for name, call in calls.items():
            start = time.process_time()
            results[name] = call()
            best[name] = min(best[name], time.process_time() - start)
    return best, results


def pencil_multipliers(factors: np.ndarray) -> np.ndarray:
    """The pencil (E, -F) of the chain G_k x_k - x_{k+1} = 0 eliminated pairwise by QR (FLOWKM), its eigenvalues."""
    n = factors.shape[1]
    eye = np.eye(n)
    e_chain, f_chain = factors[0], -eye
    for transfer in factors[1:]:
        q, _ = sla.qr(np.vstack([f_chain, transfer]), mode="full")
        e_chain, f_chain = q[:n, n:].T @ e_chain, -q[n:, n:].T
    mu = sla.eigvals(e_chain, -f_chain)
    return mu[np.isfinite(mu)]


def _product(rng, n: int, m: int) -> tuple[np.ndarray, np.ndarray]:
    """The factors (m, n, n) and the exact ln |mu| (n,) by decreasing modulus (module docstring)."""
    pairs = n // 2
    decay = np.linspace(0.0, 3.0, pairs)
    s = [np.eye(n) + 0.2 / math.sqrt(n) * rng.standard_normal((n, n)) for _ in range(m)]
    s.append(s[0])
    factors = np.empty((m, n, n))
    for k in range(m):
        d = np.zeros((n, n))
        for i in range(pairs):
            angle = rng.uniform(0.1, 1.0)
            d[2 * i : 2 * i + 2, 2 * i : 2 * i + 2] = math.exp(-decay[i]) * np.array(
                [[math.cos(angle), -math.sin(angle)], [math.sin(angle), math.cos(angle)]]
            )
        factors[k] = s[k + 1] @ d @ np.linalg.inv(s[k])
    return factors, np.repeat(-m * decay, 2)


def _formed(factors: np.ndarray) -> np.ndarray:
    """G_m ... G_1, one product at a time."""
    product = factors[0]
    for factor in factors[1:]:
        product = factor @ product
    return product


def _log_error(values: np.ndarray, exact: np.ndarray) -> float:
    """Worst |ln |mu| - exact| over the exact ones above 1e-300, matched by rank."""
    with np.errstate(divide="ignore"):
        logs = np.sort(np.log(np.abs(values)))[::-1]
    keep = exact > math.log(1e-300)
    return float(np.max(np.abs(logs[keep] - exact[keep])))


def products(sizes, segments, repeats: int) -> list[dict]:
    rows = []
    rng = np.random.default_rng(0)
    for n in sizes:
        for m in segments:
            factors, exact = _product(rng, n, m)
            calls = {
                "periodic_schur": lambda f=factors: periodic_schur_multipliers(f),
                "formed": lambda f=factors: np.linalg.eigvals(_formed(f)),
                "pencil": lambda f=factors: pencil_multipliers(f),
            }
            cpu, found = _least(calls, repeats)
            row = {
                "n": n,
                "m": m,
                "smallest_exact_log10": float(exact[-1] / math.log(10.0)),
                "cpu_s": cpu,
                "ratio_to_formed": {name: cpu[name] / cpu["formed"] for name in cpu},
                "log_error": {
                    "periodic_schur": float(np.max(np.abs(found["periodic_schur"].log_moduli - exact))),
                    "formed": _log_error(found["formed"], exact),
                    "pencil": _log_error(found["pencil"], exact),
                },
            }
            rows.append(row)
            print(json.dumps(row), flush=True)
    return rows


def _rate(params: ChainParams) -> float:
    return float(np.sum(per_dof(params, params.damping) / pack(params, params.particle_inertia)))


def orbits(repeats: int) -> dict:
    out = {"shooting": [], "collocation": {}}
    exact_rate = _rate(N1)
    calls = {"formed": lambda: find_periodic_orbit(N1, "nonlinear", 0.265, **SHOOTING)}
    for m in (4, 16, 64):
        calls[f"segments={m}"] = lambda m=m: find_periodic_orbit(N1, "nonlinear", 0.265, segments=m, **SHOOTING)
    cpu, found = _least(calls, repeats)
    for name, orbit in found.items():
        exact = -orbit.period * exact_rate
        row = {
            "method": name,
            "period": orbit.period,
            "cpu_s": cpu[name],
            "liouville_relative_error": float(abs(np.sum(orbit.log_moduli) - exact) / abs(exact)),
            "smallest_log10": float(orbit.log_moduli[-1] / math.log(10.0)),
        }
        out["shooting"].append(row)
        print(json.dumps(row), flush=True)
    orbit = find_collocation_orbit(N1, "nonlinear", 0.265, ntst=100, ncol=7)
    transfers = _transfers(orbit)
    cpu, found = _least(
        {"periodic_schur": lambda: periodic_schur_multipliers(transfers), "pencil": lambda: pencil_multipliers(transfers)}, repeats
    )
    exact = -orbit.period * exact_rate
    with np.errstate(divide="ignore"):
        pencil_sum = float(np.sum(np.log(np.abs(found["pencil"]))))
    out["collocation"] = {
        "period": orbit.period,
        "ntst": orbit.ntst,
        "ncol": orbit.ncol,
        "liouville_log10": exact / math.log(10.0),
        "cpu_s": cpu,
        "liouville_relative_error": {
            "periodic_schur": float(abs(np.sum(found["periodic_schur"].log_moduli) - exact) / abs(exact)),
            "pencil": abs(pencil_sum - exact) / abs(exact),
        },
        "smallest_log10": {
            "periodic_schur": float(found["periodic_schur"].log10_moduli[-1]),
            "pencil": float(np.log10(np.min(np.abs(found["pencil"])))),
        },
    }
    print(json.dumps(out["collocation"]), flush=True)
    out["collocation_chains"] = []
    for n_half in (2, 5, 10):
        params = ChainParams(N=n_half)
        transfers = _transfers(find_collocation_orbit(params, "sine", 0.5))
        cpu, found = _least(
            {"periodic_schur": lambda t=transfers: periodic_schur_multipliers(t), "pencil": lambda t=transfers: pencil_multipliers(t)},
            repeats,
        )
        big = found["pencil"][np.abs(found["pencil"]) > 1e-10]
        row = {
            "N": n_half,
            "n": transfers.shape[1],
            "ntst": transfers.shape[0],
            "cpu_s": cpu,
            "ratio_to_pencil": cpu["periodic_schur"] / cpu["pencil"],
            "max_difference_above_1e-10": float(max(np.min(np.abs(found["periodic_schur"].values - z)) for z in big)),
        }
        out["collocation_chains"].append(row)
        print(json.dumps(row), flush=True)
    return out


def _transfers(orbit) -> np.ndarray:
    """The collocation orbit's intervals' transfer matrices (the factors its multipliers come from)."""
    from cosserat_chain.models.base import get_model
    from cosserat_chain.numerics.periodic import _System

    system = _System(orbit.params, get_model(orbit.model), orbit.moment, orbit.particle)
    shift = collocation_core._shift(system, orbit.particle_turns)
    problem = collocation_core._Collocation(system, orbit.mesh, orbit.ncol, shift, orbit.profile, free_moment=False)
    evaluation = problem.evaluate(problem.pack(orbit.profile, orbit.period), True)
    a_values, period = evaluation.data
    return problem.transfers(a_values, period)


@one_blas_thread
def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--parts", nargs="+", choices=("products", "orbits"), default=("products", "orbits"))
    parser.add_argument("--sizes", nargs="+", type=int, default=SIZES)
    parser.add_argument("--segments", nargs="+", type=int, default=SEGMENTS)
    parser.add_argument("--repeats", type=int, default=3)
    args = parser.parse_args(argv)
    out = {"repeats": args.repeats}
    if "products" in args.parts:
        out["products"] = products(args.sizes, args.segments, args.repeats)
    if "orbits" in args.parts:
        out["orbits"] = orbits(args.repeats)
    RESULTS.mkdir(exist_ok=True)
    (RESULTS / "floquet.json").write_text(json.dumps(out, indent=1) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
