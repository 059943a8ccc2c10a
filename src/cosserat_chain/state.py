"""Layout of the chain's state.

Contract
--------
A configuration is an array ``x`` of shape (3, 2N+1), C-contiguous float64, with
rows (u, v, phi) and columns the particles -N..N (column ``k + N`` is particle k).
Velocities use the same layout. The end particles +-N (columns 0 and 2N) are
stored too: the degrees of freedom their ends hold fixed (all three at a clamped
end, u and v at a pinned one; :data:`~cosserat_chain.params.FIXED_ROWS`) stay
zero. One contiguous row per coordinate is what lets the compiled kernels
vectorise (``PERFORMANCE-NOTES.md``).

Matrices (stiffness, Hessian, Jacobian) act on the *free* degrees of freedom,
ordered particle by particle and (u, v, phi) within a particle, skipping the
fixed ones: for the paper's clamped chain (u, v, phi) of particle -N+1, then of
-N+2, ... This ordering makes every matrix of an open chain banded (bandwidth 5:
a bond couples two neighbours' six degrees of freedom), within the band storage of
the linear-algebra floor (:data:`cosserat_chain.linalg.BANDWIDTH`); a ring's bond
between particles N and -N adds corner blocks.
"""

from __future__ import annotations

from functools import lru_cache

import numpy as np

from .memory import FLOAT, require
from .params import FIXED_ROWS, ChainParams

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


def held(params: ChainParams) -> tuple[tuple[int, int], ...]:
    """(row, column) of every degree of freedom the ends hold fixed: at most six, O(1) for any chain."""
    left, right = params.ends
    return tuple((row, 0) for row in FIXED_ROWS[left]) + tuple((row, params.n_particles - 1) for row in FIXED_ROWS[right])


def zero_held(params: ChainParams, a: np.ndarray) -> np.ndarray:
    """Set ``a[..., row, column]`` to zero where the ends hold the degree of freedom (in place); returns ``a``."""
    for row, col in held(params):
        a[..., row, col] = 0
    return a


def fixed_mask(params: ChainParams) -> np.ndarray:
    """The degrees of freedom the ends hold fixed as a bool array (3, 2N+1) (all False for a ring)."""
    mask = np.zeros((3, params.n_particles), dtype=bool)
    for row, col in held(params):
        mask[row, col] = True
    return mask


@lru_cache(maxsize=8)
def _free(n_particles: int, left: str, right: str) -> np.ndarray:
    # Index into x.T.ravel() (particle by particle, rows within a particle) of every free degree of freedom.
    fixed = [3 * 0 + row for row in FIXED_ROWS[left]] + [3 * (n_particles - 1) + row for row in FIXED_ROWS[right]]
    index = np.delete(np.arange(3 * n_particles), fixed)
    index.flags.writeable = False
    return index


def free_index(params: ChainParams) -> np.ndarray:
    """Positions of the free degrees of freedom in ``x.T.ravel()``, in the order of every matrix (module docstring)."""
    left, right = params.ends
    return _free(params.n_particles, left, right)


def n_free(params: ChainParams) -> int:
    """Number of free degrees of freedom: 3 (2N - 1) for the clamped chain, 3 (2N + 1) for a ring or free ends."""
    return 3 * params.n_particles - len(held(params))


def free_rows(params: ChainParams) -> np.ndarray:
    """The row (0, 1, 2 for u, v, phi) of every free degree of freedom, in matrix order (length n_free)."""
    return free_index(params) % 3


def free_columns(params: ChainParams) -> np.ndarray:
    """The array column (0..2N) of every free degree of freedom, in matrix order (length n_free)."""
    return free_index(params) // 3


def force_columns(params: ChainParams) -> tuple[int, int]:
    """The columns [start, stop) that move: all of them, less a clamped end's column."""
    left, right = params.ends
    return (1 if left == "clamped" else 0), (params.n_particles - 1 if right == "clamped" else params.n_particles)


def dof(params: ChainParams, row: str, particle: int) -> int:
    """Index of degree of freedom ``row`` ("u", "v", "phi") of ``particle`` among the free ones.

    Raises
    ------
    ValueError
        For a particle outside -N..N, an unknown row, or a degree of freedom an end holds fixed.
    """
    col = column(params, particle)
    if row not in ROW_INDEX:
        raise ValueError(f"row must be one of {', '.join(ROWS)}, got {row!r}")
    position = np.searchsorted(free_index(params), 3 * col + ROW_INDEX[row])
    index = free_index(params)
    if position >= index.size or index[position] != 3 * col + ROW_INDEX[row]:
        end = "left" if col == 0 else "right"
        raise ValueError(
            f"{row} of particle {particle} is held fixed by the {end} end ({params.ends[0 if col == 0 else 1]}); "
            "choose a free degree of freedom"
        )
    return int(position)


def require_clamped(params: ChainParams, what: str) -> None:
    """Refuse a chain whose ends are not both clamped, for a computation written for the paper's chain only.

    Raises
    ------
    ValueError
        Naming ``what`` and the ends given.
    """
    if not params.clamped:
        raise ValueError(
            f"{what} needs both ends clamped (left_end = right_end = 'clamped', periodic = false), got {params.describe_ends()}"
        )


def require_held(params: ChainParams) -> None:
    """Refuse a chain that can move rigidly (free ends, one pin and a free end, a ring): it has no unique static state.

    Raises
    ------
    ValueError
        Naming the ends and the rigid motions they leave free.
    """
    if params.rigid_modes:
        motions = (
            "translations" if params.periodic else ("rotation about the pin" if params.rigid_modes == 1 else "translations and rotation")
        )
        raise ValueError(
            f"the chain with {params.describe_ends()} can move rigidly ({params.rigid_modes} zero modes: its {motions}), so its "
            "static states are not unique and a load with a net force or moment has none: the statics need a clamped end "
            "or two pinned ones (left_end, right_end); the dynamics and the modes work for any ends"
        )


@lru_cache(maxsize=8)
def _free_in_rows(n_particles: int, left: str, right: str) -> np.ndarray:
    # The same degrees of freedom as _free, as positions in x.ravel() of a C-contiguous x (3, 2N+1):
    # pack and unpack then take and put in one pass, with no transposed copy of x between.
    index = _free(n_particles, left, right)
    out = index % 3 * n_particles + index // 3
    out.flags.writeable = False
    return out


def pack(params: ChainParams, x: np.ndarray) -> np.ndarray:
    """Free degrees of freedom of ``x`` (3, 2N+1) as a vector of length n_free, in matrix order.

    Raises
    ------
    ValueError
        If ``x`` does not have 3 (2N+1) entries.
    """
    left, right = params.ends
    flat = np.ascontiguousarray(x, dtype=float).reshape(-1)
    if flat.size != 3 * params.n_particles:
        raise ValueError(f"x has {flat.size} entries, a state of this chain has shape (3, {params.n_particles})")
    from .packing import take  # compiled; imported here, so that importing state loads no numba

    return take(flat, _free_in_rows(params.n_particles, left, right))


def unpack(params: ChainParams, q: np.ndarray) -> np.ndarray:
    """Inverse of :func:`pack`: a C-contiguous (3, 2N+1) array, zero at the fixed degrees of freedom.

    Raises
    ------
    ValueError
        If ``q`` does not have n_free entries.
    """
    left, right = params.ends
    index = _free_in_rows(params.n_particles, left, right)
    q = np.ascontiguousarray(q, dtype=float).reshape(-1)
    if q.size != index.size:
        raise ValueError(f"q has {q.size} entries, this chain has {index.size} free degrees of freedom")
    from .packing import put

    out = np.zeros((3, params.n_particles))
    put(out.reshape(-1), index, q)
    return out


def bonded(params: ChainParams, x: np.ndarray) -> np.ndarray:
    """``x`` (..., 3, 2N+1) with, for a ring, its first column repeated after the last.

    Then bond k joins columns k and k+1 for every bond of the chain (2N of them, or
    2N+1 for a ring: particle N to particle -N, a neighbour h further on), so that
    per-bond NumPy code (``np.diff`` along the columns) covers the ring's closing bond.
    """
    x = np.asarray(x, dtype=float)
    return np.concatenate([x, x[..., :1]], axis=-1) if params.periodic else x


def scatter_bonds(params: ChainParams, left: np.ndarray, right: np.ndarray) -> np.ndarray:
    """Per-particle sums (..., 3, 2N+1) of per-bond contributions to each bond's left and right particle.

    ``left`` and ``right`` (..., 3, n_bonds): what bond k gives column k and column k+1
    (column 0 for a ring's closing bond).
    """
    out = np.zeros((*left.shape[:-1], params.n_particles))
    out[..., : left.shape[-1]] += left
    out[..., 1:] += right[..., : params.n_particles - 1]
    if params.periodic:
        out[..., 0] += right[..., -1]
    return out


def per_dof(params: ChainParams, values) -> np.ndarray:
    """A per-row quantity (u, v, phi), e.g. the inertia (m, m, j), for every free degree of freedom."""
    return np.asarray(values, dtype=float)[free_rows(params)]


def check_state(params: ChainParams, x: np.ndarray, name: str = "x") -> np.ndarray:
    """Validate a configuration or velocity array and return it as C-contiguous float64.

    Raises
    ------
    ValueError
        If the shape is not (3, 2N+1), a value is not finite, or a degree of freedom an end holds fixed is not zero.
    """
    arr = np.ascontiguousarray(x, dtype=float)
    if arr.shape != (3, params.n_particles):
        raise ValueError(f"{name} must have shape (3, 2N+1) = (3, {params.n_particles}), got {arr.shape}")
    if not np.all(np.isfinite(arr)):
        bad = np.argwhere(~np.isfinite(arr))[0]
        raise ValueError(f"{name}[{ROWS[bad[0]]}] of particle {bad[1] - params.N} is {float(arr[tuple(bad)])}; values must be finite")
    for row, col in held(params):
        if arr[row, col] == 0.0:
            continue
        raise ValueError(
            f"{name}[{ROWS[row]}] of particle {col - params.N} is {float(arr[row, col])!r}, but its end is "
            f"{params.ends[0 if col == 0 else 1]}: the degrees of freedom an end holds fixed must be zero"
        )
    return arr
