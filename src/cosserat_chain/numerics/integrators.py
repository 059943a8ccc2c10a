"""Compiled fixed-step integrators for the damped, loaded chain.

Contract
--------
The equations of motion are, for each row r in (u, v, phi) with inertia m_r
(m, m, j) and viscosity gamma_r,

    m_r q_r'' = F_r(q) + L_r(t) - gamma_r q_r'

with F the model's internal forces and L the loads (eqs. (2)-(3)). One step of
size dt is a symmetric composition of damped velocity-Verlet sub-steps of sizes
c_i dt (coefficients in :class:`Method`), each sub-step being

    damp(h/2) . kick(h/2) . drift(h) . kick(h/2) . damp(h/2)

where ``damp`` is the exact viscous flow v <- v exp(-gamma h / (2 m)) (stable for
any gamma) and ``kick`` uses the forces at the current positions and time. The
composition is time-symmetric, so Verlet is of order 2 and the Yoshida triple
jump of order 4.

The whole trajectory runs in one compiled call (:func:`advance`); the model is
passed as its compiled force kernel (a first-class function), so one cached
integrator serves every model. Along the way it accumulates the work done by the
loads (trapezoidal in each sub-step, exact for constant loads) and the energy
removed by each damping sub-step (exact for that sub-step), which close the
energy balance K + P - W + D = K0 + P0 to within the integrator's error.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import cached_property

import numpy as np
from numba import njit, prange, types

from ..loads import schedule_value
from ..models.base import FORCE_KERNEL_TYPE, KERNEL_OPTIONS

# The force kernels' options without fastmath "contract": the kick-drift is inlined in
# several places, and where fused multiply-adds go would depend on the code around each
# copy, so threads=2 would no longer reproduce threads=1 bit for bit.
_OPTIONS = {**KERNEL_OPTIONS, "fastmath": False}

#: Status codes returned by :func:`advance`.
STATUS_OK = 0
STATUS_BLEW_UP = 1


@dataclass(frozen=True)
class Method:
    """A fixed-step method: a symmetric composition of damped Verlet sub-steps.

    Parameters
    ----------
    name : str
    order : int
        Declared global order of accuracy (checked by the test suite).
    weights : tuple of float
        Sub-step sizes as fractions of dt; they sum to 1 and read the same backwards.
    """

    name: str
    order: int
    weights: tuple[float, ...]
    description: str

    @property
    def force_evaluations(self) -> int:
        """Force evaluations per step."""
        return len(self.weights)

    def transfer_matrix(self, omega_dt: float) -> np.ndarray:
        """One undamped step on x'' = -omega^2 x, as the 2x2 map of (x, v/omega)."""
        step = np.eye(2)
        for c in self.weights:
            z = c * omega_dt
            kick = np.array([[1.0, 0.0], [-z / 2, 1.0]])
            drift = np.array([[1.0, z], [0.0, 1.0]])
            step = kick @ drift @ kick @ step
        return step

    @cached_property
    def stability_limit(self) -> float:
        """Largest omega dt for which the undamped harmonic oscillator stays bounded.

        Found from the transfer matrix (stable while |trace| < 2), so it is exact for
        the method's coefficients rather than a quoted constant.
        """
        z = np.linspace(1e-3, 4.0, 4001)
        traces = np.array([abs(np.trace(self.transfer_matrix(zi))) for zi in z])
        first_bad = int(np.argmax(traces >= 2.0))
        lo, hi = z[first_bad - 1], z[first_bad]
        for _ in range(60):
            mid = 0.5 * (lo + hi)
            lo, hi = (mid, hi) if abs(np.trace(self.transfer_matrix(mid))) < 2.0 else (lo, mid)
        return float(lo)


_CBRT2 = 2.0 ** (1.0 / 3.0)
METHODS: dict[str, Method] = {
    "verlet": Method("verlet", 2, (1.0,), "damped velocity Verlet (Strang splitting with exact damping)"),
    "yoshida4": Method(
        "yoshida4",
        4,
        (1.0 / (2.0 - _CBRT2), -_CBRT2 / (2.0 - _CBRT2), 1.0 / (2.0 - _CBRT2)),
        "Yoshida's fourth-order triple jump of the damped Verlet step",
    ),
}


def get_method(name: str | Method) -> Method:
    """The method of that name (a :class:`Method` passes through).

    Raises
    ------
    ValueError
        For an unknown name, listing the known ones.
    """
    if isinstance(name, Method):
        return name
    try:
        return METHODS[name]
    except KeyError:
        raise ValueError(f"method must be one of {sorted(METHODS)}, got {name!r}") from None


# --------------------------------------------------------------------------- kernels
def substep_table(weights: np.ndarray, dt: float, mass: np.ndarray, gamma: np.ndarray) -> np.ndarray:
    """Factors of every sub-step, shape (S+1, 3, 3): [s, 0, r] damping exp(-gamma_r h_s / (2 m_r)),
    [s, 1, r] kick h_s / (2 m_r), [s, 2, r] drift h_s, with h_s = weights[s] dt; row S is the empty sub-step."""
    sizes = np.append(np.asarray(weights, dtype=float) * dt, 0.0)
    table = np.empty((sizes.size, 3, 3))
    table[:, 0] = np.exp(-np.outer(sizes, gamma / (2.0 * mass)))
    table[:, 1] = np.outer(sizes, 0.5 / mass)
    table[:, 2] = sizes[:, None]
    return table


@njit(inline="always", **_OPTIONS)
def _close_and_open(x, v, f, mass, table, close, open_, start, stop):  # pragma: no cover - compiled
    """End sub-step ``close`` and begin sub-step ``open_`` on columns start..stop-1.

    Closing: kick(h/2), damp(h/2). Opening: damp(h/2), kick(h/2), drift(h). The
    empty sub-step (last row of ``table``) skips a half exactly. Returns the
    kinetic energy removed by the two damping flows.
    """
    dissipated = 0.0
    for r in range(3):
        e_close = table[close, 0, r]
        kick_close = table[close, 1, r]
        e_open = table[open_, 0, r]
        kick_open = table[open_, 1, r]
        drift = table[open_, 2, r]
        before_close = 0.0
        before_open = 0.0
        # Slices indexed from 0: the compiler then knows that no index is negative
        # and drops the wrap-around arithmetic (1.7x faster at 10^4 columns).
        xr = x[r, start:stop]
        vr = v[r, start:stop]
        fr = f[r, start:stop]
        for k in range(stop - start):
            w = vr[k] + kick_close * fr[k]
            before_close += w * w
            w *= e_close
            before_open += w * w
            w = e_open * w + kick_open * fr[k]
            vr[k] = w
            xr[k] += drift * w
        dissipated += 0.5 * mass[r] * (before_close * (1.0 - e_close * e_close) + before_open * (1.0 - e_open * e_open))
    return dissipated


@njit(parallel=True, **_OPTIONS)
def _close_and_open_blocks(x, v, f, mass, table, close, open_, bounds):  # pragma: no cover - compiled
    n_blocks = bounds.size - 1
    parts = np.zeros(n_blocks)
    for i in prange(n_blocks):
        parts[i] = _close_and_open(x, v, f, mass, table, close, open_, bounds[i], bounds[i + 1])
    return parts.sum()


@njit(parallel=True, **_OPTIONS)
def _forces_blocks(force, x, coef, f, bounds):  # pragma: no cover - compiled
    for i in prange(bounds.size - 1):
        force(x, coef, f, bounds[i], bounds[i + 1])


@njit(inline="always", **_OPTIONS)
def _close(x, v, f, mass, table, close, empty, bounds):  # pragma: no cover - compiled
    """Close sub-step ``close`` without opening another (velocities at the step boundary)."""
    if bounds.size == 2:
        return _close_and_open(x, v, f, mass, table, close, empty, bounds[0], bounds[1])
    return _close_and_open_blocks(x, v, f, mass, table, close, empty, bounds)


@njit(**_OPTIONS)
def _runaway(x, v, max_displacement):  # pragma: no cover - compiled
    """True if a value is not finite or a displacement exceeds ``max_displacement``."""
    for r in range(3):
        for k in range(x.shape[1]):
            if not (math.isfinite(x[r, k]) and math.isfinite(v[r, k])):
                return True
            if r < 2 and abs(x[r, k]) > max_displacement:
                return True
    return False


_F8 = types.float64
_I8 = types.int64
_ROWS = types.float64[:, ::1]
_VEC = types.float64[::1]
_FRAMES = types.float64[:, :, ::1]
# fmt: off
ADVANCE_SIGNATURE = types.UniTuple(_I8, 3)(
    FORCE_KERNEL_TYPE,  # force
    _ROWS, _ROWS, _ROWS,  # x, v, f
    _VEC, _VEC, _FRAMES, _VEC,  # coef, mass, table, weights
    types.int64[:, ::1], _ROWS, types.int64[::1],  # load_index, knots, bounds
    _F8, _F8, _I8, _I8, _I8, _I8, _F8,  # t0, dt, n_steps, step0, stride, check_every, max_displacement
    _VEC, _FRAMES, _FRAMES, _ROWS, _I8,  # acc, frames_x, frames_v, frames_acc, frame0
)


@njit(ADVANCE_SIGNATURE, **_OPTIONS)
def advance(
    force, x, v, f, coef, mass, table, weights, load_index, knots, bounds,
    t0, dt, n_steps, step0, stride, check_every, max_displacement,
    acc, frames_x, frames_v, frames_acc, frame0,
):  # pragma: no cover - compiled
    # fmt: on
    """Advance ``n_steps`` steps in place and store every ``stride``-th state.

    Parameters
    ----------
    force : compiled force kernel of the model (``FORCE_SIGNATURE``)
    x, v : ndarray (3, n)
        State at global step ``step0`` (time t0 + step0 dt), velocities at the step boundary.
    f : ndarray (3, n)
        Forces plus loads at that state and time (kept between calls: one
        evaluation per sub-step).
    coef : model coefficients; mass : (3,) inertia of the rows
    table : ndarray (S+1, 3, 3)
        Sub-step factors from :func:`substep_table` for this dt.
    weights : sub-step sizes of the method, as fractions of dt (S of them)
    load_index, knots : compiled loads (``Loads.compiled``)
    bounds : ndarray of int64
        Column ranges [bounds[i], bounds[i+1]) of the blocks; two entries
        (1, n-1) run on one thread, more split every step over threads.
    stride : store a frame after every global step that is a multiple of it
    check_every : test for a runaway state every so many steps
    max_displacement : |u| or |v| beyond it counts as a runaway
    acc : ndarray (2,)
        Running (load work, dissipated energy); updated in place.
    frames_x, frames_v : ndarray (n_frames, 3, n); frames_acc : (n_frames, 2)
        Output, written from index ``frame0`` on. ``x`` and ``v`` may be the last
        slots of ``frames_x`` and ``frames_v`` (then the last store copies nothing).

    Returns
    -------
    status, steps_done, frames_written
        ``status`` is ``STATUS_OK`` or ``STATUS_BLEW_UP``; after a blow-up the
        state is the first one found out of bounds.
    """
    n_loads = load_index.shape[0]
    q_old = np.empty(n_loads)
    load_old = np.empty(n_loads)
    for i in range(n_loads):
        q_old[i] = x[load_index[i, 0], load_index[i, 1]]
        load_old[i] = schedule_value(knots, load_index[i, 2], load_index[i, 3], t0 + step0 * dt)
    # The running sums stay in registers; acc is written back before every return.
    work = acc[0]
    dissipated = acc[1]
    frame = frame0
    n_sub = weights.size
    empty = n_sub
    pending = empty
    single = bounds.size == 2
    start = bounds[0]
    stop = bounds[-1]
    # Countdowns instead of a modulo per step: an integer division costs as much as
    # a small chain's kick-drift.
    to_store = stride - step0 % stride
    to_check = check_every
    # The sub-step is written out here rather than in helpers: a call to a compiled
    # helper passes every array as ~10 scalar arguments, and a helper inlined by
    # numba adds reference-count updates on its array arguments; either costs about
    # a third of a 7-particle step.
    for k in range(n_steps):
        t = t0 + (step0 + k) * dt
        for s in range(n_sub):
            if single:
                dissipated += _close_and_open(x, v, f, mass, table, pending, s, start, stop)
                force(x, coef, f, start, stop)
            else:
                dissipated += _close_and_open_blocks(x, v, f, mass, table, pending, s, bounds)
                _forces_blocks(force, x, coef, f, bounds)
            t += weights[s] * dt
            for i in range(n_loads):
                row = load_index[i, 0]
                col = load_index[i, 1]
                q = x[row, col]
                load = schedule_value(knots, load_index[i, 2], load_index[i, 3], t)
                f[row, col] += load
                work += 0.5 * (load_old[i] + load) * (q - q_old[i])
                q_old[i] = q
                load_old[i] = load
            pending = s
        to_store -= 1
        to_check -= 1
        store = to_store == 0
        last = k == n_steps - 1
        if store or last:
            dissipated += _close(x, v, f, mass, table, pending, empty, bounds)
            pending = empty
        if store:
            to_store = stride
            # The caller may hand in its last frame slots as x and v; nothing to copy then.
            if frames_x[frame].ctypes.data != x.ctypes.data:
                frames_x[frame] = x
                frames_v[frame] = v
            frames_acc[frame, 0] = work
            frames_acc[frame, 1] = dissipated
            frame += 1
        if to_check == 0 or last:
            to_check = check_every
            if _runaway(x, v, max_displacement):
                if pending != empty:
                    dissipated += _close(x, v, f, mass, table, pending, empty, bounds)
                acc[0] = work
                acc[1] = dissipated
                return STATUS_BLEW_UP, k + 1, frame - frame0
    acc[0] = work
    acc[1] = dissipated
    return STATUS_OK, n_steps, frame - frame0
