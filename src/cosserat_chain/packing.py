"""Compiled take and put by index: the kernels of :func:`~cosserat_chain.state.pack` and :func:`~cosserat_chain.state.unpack`.

A module of their own, so that importing :mod:`~cosserat_chain.state` (the command line
does, to start quickly) loads no numba. Compiled, because NumPy's fancy indexing is slower (benchmarks/TIMINGS.md)
and a continuation packs and unpacks some seven times a point.
"""

from __future__ import annotations

import numpy as np
from numba import njit


@njit(cache=True, nogil=True)
def take(flat: np.ndarray, index: np.ndarray) -> np.ndarray:  # pragma: no cover - compiled
    """``flat[index]`` (the caller checks the sizes: no bound tests here)."""
    out = np.empty(index.size)
    for i in range(index.size):
        out[i] = flat[index[i]]
    return out


@njit(cache=True, nogil=True)
def put(flat: np.ndarray, index: np.ndarray, values: np.ndarray) -> None:  # pragma: no cover - compiled
    """``flat[index] = values`` in place (the caller checks the sizes)."""
    for i in range(index.size):
        flat[index[i]] = values[i]
