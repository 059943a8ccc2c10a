"""Layout of the chain's state.

Contract
--------
A configuration is an array ``x`` of shape (3, 2N+1), C-contiguous float64, with
rows (u, v, phi) and columns the particles -N..N (column ``k + N`` is particle k).
Velocities use the same layout. Columns 0 and 2N are the clamped particles +-N;
they stay zero. One contiguous row per coordinate is what lets the compiled
kernels vectorise (``PERFORMANCE-NOTES.md``).

Matrices (stiffness, Hessian, Jacobian) act on the *free* degrees of freedom,
ordered particle by particle: (u, v, phi) of particle -N+1, then of -N+2, ...
This ordering makes every matrix block-tridiagonal with 3x3 blocks (bandwidth 5).
"""

from __future__ import annotations

import numpy as np

from .memory import FLOAT, require
from .params import ChainParams

ROWS = ("u", "v", "phi")
ROW_INDEX = {name: i for i, name in enumerate(ROWS)}


#: Arrays of the chain's size that any computation holds (state, velocities, forces, the
#: stiffness's bands and factors): a chain is refused by :func:`zeros`, usually the first
#: array a computation makes, unless that many fit in the free memory.
MIN_STATES = 40
#: A state below this size (bytes) is made without asking how much memory is free.
_SMALL = 1 << 26


def zeros(params: ChainParams) -> np.ndarray:
    """The rest configuration (or zero velocity), shape (3, 2N+1).

    Raises
    ------
    MemoryEstimateError
        For a chain so long that :data:`MIN_STATES` of its states do not fit in the free memory.
    """
    nbytes = FLOAT * 3 * params.n_particles
    if nbytes > _SMALL:
        require(MIN_STATES * nbytes, f"{MIN_STATES} states of {params.n_particles} particles (N={params.N})", "a shorter chain")
    return np.zeros((3, params.n_particles))


def column(params: ChainParams, particle: int) -> int:
    """Array column of particle ``particle`` in -N..N.

    Raises
    ------
    ValueError
        If the particle is outside -N..N.
    """
    if not -params.N <= particle <= params.N:
        raise ValueError(f"particle must be in -N..N = {-params.N}..{params.N}, got {particle!r}")
    return particle + params.N


def n_free(params: ChainParams) -> int:
    """Number of free degrees of freedom 3 (2N - 1)."""
    return 3 * (params.n_particles - 2)


def pack(x: np.ndarray) -> np.ndarray:
    """Free degrees of freedom of ``x`` (3, n) as a vector of length 3 (n - 2), particle by particle."""
    return np.ascontiguousarray(x[:, 1:-1].T).reshape(-1)


def unpack(q: np.ndarray, n_particles: int) -> np.ndarray:
    """Inverse of :func:`pack`: a (3, n) array with zero clamped ends."""
    x = np.zeros((3, n_particles))
    x[:, 1:-1] = np.asarray(q, dtype=float).reshape(n_particles - 2, 3).T
    return x


def check_state(params: ChainParams, x: np.ndarray, name: str = "x") -> np.ndarray:
    """Validate a configuration or velocity array and return it as C-contiguous float64.

    Raises
    ------
    ValueError
        If the shape is not (3, 2N+1), a value is not finite, or a clamped end is not zero.
    """
    arr = np.ascontiguousarray(x, dtype=float)
    if arr.shape != (3, params.n_particles):
        raise ValueError(f"{name} must have shape (3, 2N+1) = (3, {params.n_particles}), got {arr.shape}")
    if not np.all(np.isfinite(arr)):
        bad = np.argwhere(~np.isfinite(arr))[0]
        raise ValueError(f"{name}[{ROWS[bad[0]]}] of particle {bad[1] - params.N} is {float(arr[tuple(bad)])}; values must be finite")
    if np.any(arr[:, [0, -1]] != 0.0):
        raise ValueError(f"{name} must be zero at the clamped particles +-N={params.N}")
    return arr
