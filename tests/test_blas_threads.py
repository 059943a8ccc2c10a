"""The Python API holds BLAS to one thread while its entry points run (``linalg.threads``), as the command line does.

In a session that imported NumPy first (the test process sets ``OPENBLAS_NUM_THREADS`` for
itself, so these run in a fresh interpreter without it), the decorated entry points see one
BLAS thread and the session gets its threads back afterwards; a number the user chose is kept.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys

import pytest

PROBE = """
import json
import numpy  # the session's NumPy, loaded before the package
from threadpoolctl import threadpool_info
from cosserat_chain.linalg.threads import one_blas_thread

def blas_threads():
    return sorted({lib["num_threads"] for lib in threadpool_info() if lib["user_api"] == "blas"})

@one_blas_thread
def probe():
    return blas_threads()

from cosserat_chain import ChainParams
from cosserat_chain.experiments import critical
seen = []
real = critical.continue_in_moment
def spy(*args, **kwargs):
    seen.append(blas_threads())
    return real(*args, **kwargs)
critical.continue_in_moment = spy
result = critical.critical_point(ChainParams(N=2), "sine")
# A user system's entry points (numerics.equilibria, shooting, homoclinic, experiments.system_diagram) as well.
from cosserat_chain.numerics import equilibria
from cosserat_chain.systems import pen
system_seen = []
real_classify = equilibria.classify
def system_spy(*args, **kwargs):
    system_seen.append(blas_threads())
    return real_classify(*args, **kwargs)
equilibria.classify = system_spy
equilibria.find_equilibrium(pen(), numpy.zeros(2))
print(json.dumps({"before": blas_threads(), "probe": probe(), "critical": seen, "system": system_seen,
                  "after": blas_threads(), "M_c": result.critical_moment}))
"""


def _run(env_extra: dict[str, str]) -> dict:
    env = {k: v for k, v in os.environ.items() if k not in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS", "BLIS_NUM_THREADS")}
    env.update(env_extra)
    done = subprocess.run([sys.executable, "-c", PROBE], capture_output=True, text=True, env=env, timeout=600)
    assert done.returncode == 0, done.stderr
    return json.loads(done.stdout.strip().splitlines()[-1])


@pytest.mark.skipif((os.cpu_count() or 1) < 2, reason="one core: BLAS starts with one thread anyway")
def test_the_entry_points_run_on_one_blas_thread_and_give_the_sessions_threads_back():
    out = _run({})
    assert out["before"] and max(out["before"]) >= 2  # the session's default on this machine
    assert out["probe"] == [1] and out["critical"] == [[1]] and out["system"] and all(seen == [1] for seen in out["system"])
    assert out["after"] == out["before"]
    assert out["M_c"] > 0


def test_a_number_of_threads_the_user_chose_is_kept():
    out = _run({"OPENBLAS_NUM_THREADS": "2"})
    assert out["before"] == out["probe"] == out["after"] and out["critical"] == [out["before"]]
    assert all(seen == out["before"] for seen in out["system"])
