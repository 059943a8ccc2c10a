"""Relaxation to rest under a constant moment: one step of the paper's protocol (Section 4).

Contract
--------
:func:`relax` integrates the damped dynamics (eqs. (1)-(3) with viscosity) under a
constant moment M from a given state, in chunks, and ends with one of

* ``static``: at rest, max |v| <= v_tol and max |F + L| <= f_tol (1 + |M|), the
  steady-state test of diffrax's steady-state event;
* ``rotating``: the loaded particle turns without end. Its unwrapped angle is
  followed turn by turn (the times at which it has advanced by 1, 2, 3, ... full
  turns since the step began); once two consecutive windows of ``window_turns``
  turns give the same mean angular velocity to ``omega_rtol``, it keeps turning
  at a steady mean rate, and the mean angular velocity of every particle over
  the last two windows is recorded;
* ``not_converged``: neither happened before ``t_max`` (never silently: the
  status and message say so).

A run that blows up raises :class:`~cosserat_chain.numerics.dynamics.IntegrationError`;
Ctrl-C raises ``KeyboardInterrupt`` after the chunk in progress, so that callers
keep the steps already finished.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..loads import moment_load
from ..models.base import Model, get_model
from ..params import ChainParams
from ..state import ROW_INDEX, check_state, column, zeros
from .dynamics import default_time_step, integrate

#: Longest chunk between two tests, in units of ``chunk_time``.
MAX_CHUNKS = 16
#: Most floats a chunk may store (frames of x and v), whatever the chain length.
FRAME_BUDGET = 4_000_000


@dataclass
class RelaxationStep:
    """Outcome of one relaxation step.

    Attributes
    ----------
    status : {"static", "rotating", "not_converged"}
    x, v : ndarray (3, 2N+1)
        The state at the end of the step (at rest for ``static``).
    time : float
        Time integrated in this step.
    residual : float
        max |F(x) + L| at the end.
    speed : float
        max |v| at the end.
    turns : float
        Turns of the loaded particle since the step began (signed, along M).
    angular_velocity : ndarray (2N+1,)
        Mean d phi / dt of every particle over the last two windows of a
        rotating state; zero for a static state, NaN when not converged.
    message : str
    """

    status: str
    x: np.ndarray
    v: np.ndarray
    time: float
    residual: float
    speed: float
    turns: float
    angular_velocity: np.ndarray
    message: str


def relax(
    params: ChainParams,
    model: str | Model,
    moment: float,
    *,
    particle: int = 0,
    x0: np.ndarray | None = None,
    v0: np.ndarray | None = None,
    t_max: float = 20000.0,
    v_tol: float = 1e-9,
    f_tol: float = 1e-9,
    chunk_time: float = 25.0,
    window_turns: int = 12,
    omega_rtol: float = 0.05,
    dt: float | None = None,
    method: str = "verlet",
) -> RelaxationStep:
    """Integrate under the constant ``moment`` until at rest, rotating steadily, or ``t_max``.

    Parameters
    ----------
    params : ChainParams
    model : str or Model
    moment : float
        Constant moment M on ``particle``.
    x0, v0 : ndarray (3, 2N+1), optional
        Start (default rest): the previous step's end state in the protocol.
    t_max : float
        Time cap of the step.
    v_tol, f_tol : float
        Rest test: max |v| <= v_tol and max |F + L| <= f_tol (1 + |M|).
    chunk_time : float
        The rest and rotation tests are made after ``chunk_time``, then after
        chunks twice as long each time up to 16 ``chunk_time`` (a slow step near
        the fold then costs few tests, a fast one is not run much past rest).
    window_turns : int
        Turns per window of the rotation test. Rotating states need not repeat
        after one turn (the paper's chain has states that swing back within a
        period of 2 or 3 turns, and chaotic ones), so the default 12 is a common
        multiple of short periods.
    omega_rtol : float
        Relative agreement of two consecutive windows' mean angular velocities;
        loose by default, since a chaotic rotation fluctuates by a few percent
        over 12 turns.
    dt : float, optional
        Time step (default :func:`~cosserat_chain.numerics.dynamics.default_time_step`).
    method : {"verlet", "yoshida4"}

    Returns
    -------
    RelaxationStep

    Raises
    ------
    ValueError
        For a non-positive or non-finite tolerance, time or window.
    IntegrationError
        If the dynamics blow up.
    KeyboardInterrupt
        On Ctrl-C.
    """
    for name, value in (("t_max", t_max), ("v_tol", v_tol), ("f_tol", f_tol), ("chunk_time", chunk_time), ("omega_rtol", omega_rtol)):
        if not (math.isfinite(value) and value > 0):
            raise ValueError(f"{name} must be a finite number > 0, got {value!r}")
    if not (isinstance(window_turns, int) and window_turns >= 1):
        raise ValueError(f"window_turns must be an integer >= 1, got {window_turns!r}")
    model = get_model(model)
    loads = moment_load(float(moment), particle).validate(params)
    load = loads.as_array(params, 0.0)
    x = zeros(params) if x0 is None else check_state(params, x0, "x0").copy()
    v = zeros(params) if v0 is None else check_state(params, v0, "v0").copy()
    dt = default_time_step(params) if dt is None else dt
    col = column(params, particle)
    phi_row = ROW_INDEX["phi"]
    direction = 1.0 if moment >= 0 else -1.0
    phi_start = x[phi_row, col]
    frames = int(min(MAX_CHUNKS * chunk_time / dt + 1, FRAME_BUDGET // (6 * params.n_particles)))
    crossing_times: list[float] = []
    crossing_phi: list[np.ndarray] = []
    elapsed = 0.0
    status, message = "not_converged", ""
    omega = np.full(params.n_particles, np.nan)
    chunk = chunk_time
    while True:
        span = min(chunk, t_max - elapsed)
        chunk = min(2 * chunk, MAX_CHUNKS * chunk_time)
        run = integrate(params, model, loads, t0=elapsed, t_end=elapsed + span, dt=dt, x0=x, v0=v, method=method, n_frames=frames, throw=True)
        if run.status == "interrupted":
            raise KeyboardInterrupt
        _record_turns(run.time, run.x[:, phi_row, :], col, direction, phi_start, crossing_times, crossing_phi)
        x, v = run.x[-1].copy(), run.v[-1].copy()
        elapsed = float(run.time[-1])
        residual = float(np.max(np.abs((model.forces(params, x) + load)[:, 1:-1])))
        speed = float(np.max(np.abs(v)))
        if speed <= v_tol and residual <= f_tol * (1.0 + abs(moment)):
            status, omega = "static", np.zeros(params.n_particles)
            message = f"at rest after t={elapsed:.6g} (max|v|={speed:.2g}, residual {residual:.2g})"
            break
        steady = _steady_rotation(crossing_times, crossing_phi, window_turns, omega_rtol)
        if steady is not None:
            status, omega = "rotating", steady
            message = f"steady rotation after t={elapsed:.6g}: {len(crossing_times)} turns, mean angular velocity {omega[col]:.6g}"
            break
        if elapsed >= t_max * (1 - 1e-12):
            message = (
                f"neither at rest nor rotating steadily after t_max={t_max:g} (max|v|={speed:.2g}, residual {residual:.2g}, "
                f"{len(crossing_times)} turns); raise t_max or loosen v_tol/f_tol"
            )
            break
    turns = direction * (x[phi_row, col] - phi_start) / (2 * math.pi)
    return RelaxationStep(status, x, v, elapsed, residual, speed, turns, omega, message)


def _record_turns(time, phi, col, direction, phi_start, crossing_times, crossing_phi) -> None:
    """Append the times (and all angles) at which the loaded particle completes its next full turns.

    Linear interpolation between stored frames: the frames are one time step
    apart, so the crossing times are accurate to O(dt^2).
    """
    winding = direction * (phi[:, col] - phi_start) / (2 * math.pi)
    level = len(crossing_times) + 1
    while True:
        above = np.flatnonzero(winding >= level)
        if above.size == 0 or above[0] == 0:
            return
        i = above[0]
        alpha = (level - winding[i - 1]) / (winding[i] - winding[i - 1])
        crossing_times.append(time[i - 1] + alpha * (time[i] - time[i - 1]))
        crossing_phi.append(phi[i - 1] + alpha * (phi[i] - phi[i - 1]))
        level += 1


def _steady_rotation(crossing_times, crossing_phi, window: int, rtol: float) -> np.ndarray | None:
    """Mean angular velocities over the last two windows if their rates agree, else None."""
    if len(crossing_times) < 2 * window + 1:
        return None
    t = crossing_times
    first = window / (t[-1 - window] - t[-1 - 2 * window])
    last = window / (t[-1] - t[-1 - window])
    if abs(last - first) > rtol * abs(last):
        return None
    return (crossing_phi[-1] - crossing_phi[-1 - 2 * window]) / (t[-1] - t[-1 - 2 * window])
