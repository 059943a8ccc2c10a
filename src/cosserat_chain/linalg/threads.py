"""One BLAS thread around the package's dense linear algebra, from the Python API as from the command line.

The package's dense matrices are small (eigenvalues of a short chain's damped dynamics,
monodromies of a few hundred unknowns). There OpenBLAS's second thread spins and slows the
work: on the busy 2-core development machine, ``scipy.linalg.eigvals`` of the sine model's
dynamics at N = 10 (114 x 114) took a hundred times the CPU of one thread
(benchmarks/TIMINGS.md, "BLAS threads"). The command line sets ``OPENBLAS_NUM_THREADS=1``
before NumPy loads; a Python session has loaded NumPy before the package, so the entry points
that do such work (:func:`one_blas_thread`) hold BLAS to one thread while they run, through
threadpoolctl, and give back the threads the session had. A user who has set the number of
threads (``OPENBLAS_NUM_THREADS``, ``OMP_NUM_THREADS``, ``MKL_NUM_THREADS`` or
``BLIS_NUM_THREADS``) keeps that number.
"""

from __future__ import annotations

import functools
import os
from collections.abc import Callable
from typing import Any, TypeVar

#: The environment variables through which a user chooses the BLAS threads (left as they are).
THREAD_VARIABLES = ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS", "BLIS_NUM_THREADS")

F = TypeVar("F", bound=Callable[..., Any])

_controller = None


def _blas_controller():
    """threadpoolctl's controller of the loaded BLAS libraries, made once (it scans the loaded libraries)."""
    global _controller
    if _controller is None:
        from threadpoolctl import ThreadpoolController

        _controller = ThreadpoolController()
    return _controller


def user_chose_threads() -> bool:
    """Whether the environment names a number of BLAS threads (the user's choice, or the command line's)."""
    return any(os.environ.get(name) for name in THREAD_VARIABLES)


def one_blas_thread(function: F) -> F:
    """``function`` run with BLAS held to one thread (unless the user chose the threads; module docstring)."""

    @functools.wraps(function)
    def wrapper(*args, **kwargs):
        if user_chose_threads():
            return function(*args, **kwargs)
        with _blas_controller().limit(limits=1, user_api="blas"):
            return function(*args, **kwargs)

    return wrapper  # type: ignore[return-value]
