"""Adaptive, error-controlled reference runs: SciPy's DOP853 on the same compiled right-hand side.

Contract
--------
:func:`integrate_adaptive` solves the same equations as
:func:`cosserat_chain.numerics.dynamics.integrate` (viscosity as a force
-gamma v instead of an exact sub-step) with ``scipy.integrate.solve_ivp``. The
state is extended by the load work W and the dissipated energy D, integrated
as W' = L(t) . q' and D' = gamma v^2, so the energy balance of a reference run
is as accurate as its tolerances. It returns a :class:`Trajectory` on the
requested output times; it is slower than the fixed-step integrators and meant
as the reference they are checked against.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit, types
from scipy.integrate import solve_ivp

from ..loads import Loads, schedule_value
from ..models.base import FORCE_KERNEL_TYPE, Model, get_model
from ..params import ChainParams
from ..state import check_state, zeros
from .dynamics import Trajectory

_RHS_SIGNATURE = types.float64[::1](
    FORCE_KERNEL_TYPE,
    types.float64,
    types.float64[::1],
    types.float64[::1],
    types.float64[::1],
    types.float64[::1],
    types.int64[:, ::1],
    types.float64[:, ::1],
)


@njit(_RHS_SIGNATURE, cache=True, nogil=True, error_model="numpy")
def _rhs(force, t, y, coef, mass, gamma, load_index, knots):  # pragma: no cover - compiled
    size = (y.size - 2) // 2
    n = size // 3
    x = y[:size].reshape((3, n))
    v = y[size : 2 * size].reshape((3, n))
    f = np.zeros((3, n))
    force(x, coef, f, 1, n - 1)
    dy = np.empty_like(y)
    work_rate = 0.0
    for i in range(load_index.shape[0]):
        row = load_index[i, 0]
        col = load_index[i, 1]
        value = schedule_value(knots, load_index[i, 2], load_index[i, 3], t)
        f[row, col] += value
        work_rate += value * v[row, col]
    dissipation = 0.0
    for r in range(3):
        for k in range(1, n - 1):
            dy[r * n + k] = v[r, k]
            dy[size + r * n + k] = (f[r, k] - gamma[r] * v[r, k]) / mass[r]
            dissipation += gamma[r] * v[r, k] * v[r, k]
        for k in (0, n - 1):
            dy[r * n + k] = 0.0
            dy[size + r * n + k] = 0.0
    dy[2 * size] = work_rate
    dy[2 * size + 1] = dissipation
    return dy


def integrate_adaptive(
    params: ChainParams,
    model: str | Model,
    loads: Loads = Loads(),
    *,
    t_end: float,
    t0: float = 0.0,
    x0: np.ndarray | None = None,
    v0: np.ndarray | None = None,
    n_frames: int = 201,
    rtol: float = 1e-10,
    atol: float = 1e-12,
    method: str = "DOP853",
) -> Trajectory:
    """Reference run with an adaptive, error-controlled SciPy solver.

    Parameters
    ----------
    params, model, loads, t_end, t0, x0, v0
        As for :func:`cosserat_chain.numerics.dynamics.integrate`.
    n_frames : int
        Number of equally spaced output times from t0 to t_end (>= 2).
    rtol, atol : float
        Tolerances of the solver.
    method : str
        Any explicit ``solve_ivp`` method; DOP853 (order 8) by default.

    Returns
    -------
    Trajectory
        ``status`` is ``completed`` or ``failed`` (the solver's message is kept);
        ``steps`` counts the solver's right-hand-side evaluations.
    """
    model = get_model(model)
    if not (math.isfinite(t_end) and t_end > t0):
        raise ValueError(f"t_end must be finite and > t0={t0!r}, got {t_end!r}")
    if n_frames < 2:
        raise ValueError(f"n_frames must be >= 2, got {n_frames!r}")
    n = params.n_particles
    x = zeros(params) if x0 is None else check_state(params, x0, "x0")
    v = zeros(params) if v0 is None else check_state(params, v0, "v0")
    load_index, knots = loads.compiled(params)
    kernel = type(model).force_kernel
    coef = model.coefficients(params)
    mass = np.array(params.inertia)
    gamma = np.array(params.damping)

    def rhs(t: float, y: np.ndarray) -> np.ndarray:
        return _rhs(kernel, t, y, coef, mass, gamma, load_index, knots)

    y0 = np.concatenate([x.ravel(), v.ravel(), [0.0, 0.0]])
    times = np.linspace(t0, t_end, n_frames)
    sol = solve_ivp(rhs, (t0, t_end), y0, method=method, t_eval=times, rtol=rtol, atol=atol)
    size = 3 * n
    frames = sol.y.T
    return Trajectory(
        time=sol.t,
        x=frames[:, :size].reshape(-1, 3, n),
        v=frames[:, size : 2 * size].reshape(-1, 3, n),
        load_work=frames[:, -2],
        dissipated=frames[:, -1],
        status="completed" if sol.success else "failed",
        message=sol.message,
        steps=int(sol.nfev),
        dt=float("nan"),
        method=method,
    )
