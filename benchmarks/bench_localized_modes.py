"""CPU cost of :func:`~cosserat_chain.analysis.localized_modes.classify_modes` (issue 41) against the dense eigensolve.

Run from the repository root::

    python benchmarks/bench_localized_modes.py              # N = 50, 100, 200, 400
    python benchmarks/bench_localized_modes.py --n 50 100   # chosen lengths

What is measured: the CPU time of the process (``time.process_time``, all threads) of one
uncached ``classify_modes`` of a graded chain (a soft bond, a heavy rotor and a light
particle about the centre, clamped ends), which solves the linear modes of the chain (N) and
of the lengthened one (2N) by the banded solver of :func:`~cosserat_chain.linalg.eigen.band_eigenpairs`,
and, for reference, ``scipy.linalg.eigh`` of the two dense mass-scaled stiffnesses
M^-1/2 K M^-1/2 (the dense solve this replaced, without its post-processing). The machine's
load (``os.getloadavg``) is printed beside each row: the other processes' threads slow
both, the dense one (threaded BLAS) more.
"""

from __future__ import annotations

import argparse
import os
import time

import numpy as np
import scipy.linalg as sla
import scipy.sparse as sp

from cosserat_chain.analysis.localized_modes import classify_modes, lengthened
from cosserat_chain.models import get_model
from cosserat_chain.params import ChainParams
from cosserat_chain.state import pack


def graded(n: int) -> ChainParams:
    """The graded chain of tests/test_localized_modes_fifteenth.py's GRADED about the centre of 2n + 1 particles."""
    e1 = [1.0] * (2 * n)
    e1[n - 1] = 0.5
    m = [1.0] * (2 * n + 1)
    m[n + 1] = 0.5
    j = [1.0] * (2 * n + 1)
    j[n] = 3.0
    return ChainParams(N=n, E1_factors=tuple(e1), m_factors=tuple(m), j_factors=tuple(j))


def dense_eigh(params: ChainParams) -> None:
    """scipy.linalg.eigh of the dense M^-1/2 K M^-1/2 at rest."""
    stiffness = get_model("linear").stiffness(params, np.zeros((3, params.n_particles)))
    root = sp.diags(1.0 / np.sqrt(pack(params, params.particle_inertia)))
    sla.eigh((root @ stiffness @ root).toarray())


def cpu(call, *args) -> float:
    start = time.process_time()
    call(*args)
    return time.process_time() - start


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--n", type=int, nargs="+", default=[50, 100, 200, 400])
    args = parser.parse_args()
    classify_modes.__wrapped__(graded(3))  # compile and import once, outside the timings
    print("N    classify_modes [s CPU]   dense eigh at N and 2N [s CPU]   load (1 min)")
    for n in args.n:
        params = graded(n)
        banded = cpu(classify_modes.__wrapped__, params)
        dense = cpu(dense_eigh, params) + cpu(dense_eigh, lengthened(params))
        print(f"{n:<4d} {banded:>22.3f}   {dense:>30.3f}   {os.getloadavg()[0]:.1f}")


if __name__ == "__main__":
    main()
