"""Adaptive, error-controlled reference runs: the compiled DOP853 on the chain's equations of motion.

Contract
--------
:func:`integrate_adaptive` solves the same equations as
:func:`cosserat_chain.numerics.dynamics.integrate` (viscosity as a force
-gamma v instead of an exact sub-step) with :func:`cosserat_chain.numerics.dop853.solve`,
whose tolerances mean what they mean for ``scipy.integrate.solve_ivp(method="DOP853")``.
The state is extended by the load work W and the dissipated energy D, integrated
as W' = L(t) . q' and D' = gamma v^2, so the energy balance of a reference run
is as accurate as its tolerances. It returns a :class:`Trajectory` on the
requested output times, which are steps of the method (no interpolation); it is
slower than the fixed-step integrators and meant as the reference they are checked against.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from ..loads import Loads, schedule_value
from ..models.base import Model, get_model
from ..params import ChainParams
from ..state import check_state, force_columns, zero_held, zeros
from ..status import Status
from . import dop853
from .dynamics import Trajectory

#: The only method: the name is kept for the Trajectory and for callers that passed it.
METHOD = "DOP853"


# Compiled at its first use (for dop853.RHS_SIGNATURE, by dop853.solve), not at import: the commands that import
# this module (the report among them) seldom run a reference, and with an empty cache it cost them its compilation.
@njit(cache=True, nogil=True, error_model="numpy")
def _rhs(force, end_force, t, y, coef, rpar, ipar, dy):  # pragma: no cover - compiled
    # y = (x (3, n), v (3, n), W, D) flattened; rpar = (gamma (3), inertia (3 n) of every degree of
    # freedom (a graded chain's particles differ), free (3 n): 1.0 where the ends leave the degree
    # of freedom free, knots (K, 2)); ipar = (n, number of loads L, start, stop, ring, load index
    # (L, 4)), as :meth:`Loads.compiled` lays it out.
    n = ipar[0]
    start, stop, ring = ipar[2], ipar[3], ipar[4] != 0
    load_index = ipar[5 : 5 + 4 * ipar[1]].reshape((ipar[1], 4))
    size = 3 * n
    gamma = rpar[0:3]
    mass = rpar[3 : 3 + size].reshape((3, n))
    free = rpar[3 + size : 3 + 2 * size].reshape((3, n))
    knots = rpar[3 + 2 * size :].reshape(((rpar.size - 3 - 2 * size) // 2, 2))
    x = y[:size].reshape((3, n))
    v = y[size : 2 * size].reshape((3, n))
    f = np.zeros((3, n))
    force(x, coef, f, 1, n - 1)
    if start == 0 or stop == n:
        end_force(x, coef, f, start == 0, stop == n, ring)
    work_rate = 0.0
    for i in range(load_index.shape[0]):
        row = load_index[i, 0]
        col = load_index[i, 1]
        value = schedule_value(knots, load_index[i, 2], load_index[i, 3], t)
        f[row, col] += value
        work_rate += value * v[row, col]
    dissipation = 0.0
    for r in range(3):
        for k in range(n):
            dy[r * n + k] = free[r, k] * v[r, k]
            dy[size + r * n + k] = free[r, k] * (f[r, k] - gamma[r] * v[r, k]) / mass[r, k]
            dissipation += free[r, k] * gamma[r] * v[r, k] * v[r, k]
    dy[2 * size] = work_rate
    dy[2 * size + 1] = dissipation


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
    method: str = METHOD,
    max_steps: int = dop853.MAX_STEPS,
) -> Trajectory:
    """Reference run with the adaptive, error-controlled DOP853.

    Parameters
    ----------
    params, model, loads, t_end, t0, x0, v0
        As for :func:`cosserat_chain.numerics.dynamics.integrate`.
    n_frames : int
        Number of equally spaced output times from t0 to t_end (>= 2).
    rtol, atol : float
        Tolerances of the solver (rtol >= 2.2e-14, atol > 0).
    method : str
        ``"DOP853"`` (order 8), the only one.
    max_steps : int
        Most attempted steps.

    Returns
    -------
    Trajectory
        ``status`` is ``completed`` or ``failed`` (the solver's message says why and what
        to try; the frames reached are kept); ``steps`` counts right-hand-side evaluations.

    Raises
    ------
    ValueError
        For another method, t_end <= t0, n_frames < 2, bad tolerances or a non-finite start.
    """
    if method != METHOD:
        raise ValueError(f"method must be {METHOD!r} (the compiled adaptive integrator), got {method!r}")
    model = get_model(model)
    if not (math.isfinite(t_end) and t_end > t0):
        raise ValueError(f"t_end must be finite and > t0={t0!r}, got {t_end!r}")
    if n_frames < 2:
        raise ValueError(f"n_frames must be >= 2, got {n_frames!r}")
    n = params.n_particles
    x = zeros(params) if x0 is None else check_state(params, x0, "x0")
    v = zeros(params) if v0 is None else check_state(params, v0, "v0")
    load_index, knots = loads.compiled(params)
    free = zero_held(params, np.ones((3, n))).ravel()
    rpar = np.concatenate([params.damping, params.particle_inertia.ravel(), free, knots.ravel()])
    ipar = np.concatenate([[n, len(load_index), *force_columns(params), int(params.periodic)], load_index.ravel()]).astype(np.int64)
    y0 = np.concatenate([x.ravel(), v.ravel(), [0.0, 0.0]])
    times = np.linspace(t0, t_end, n_frames)
    force, ends = model.chain_kernels(params)
    sol = dop853.solve(
        _rhs,
        force,
        model.coefficients(params),
        rpar,
        ipar,
        y0,
        times,
        rtol=rtol,
        atol=atol,
        max_steps=max_steps,
        end_force=ends,
    )
    size = 3 * n
    return Trajectory(
        time=sol.t,
        x=sol.y[:, :size].reshape(-1, 3, n),
        v=sol.y[:, size : 2 * size].reshape(-1, 3, n),
        load_work=sol.y[:, -2],
        dissipated=sol.y[:, -1],
        status=Status.COMPLETED if sol.success else Status.FAILED,
        message=sol.message,
        steps=sol.evaluations,
        dt=float("nan"),
        method=METHOD,
    )
