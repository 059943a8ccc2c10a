"""Static equilibria by Newton's method with the model's sparse stiffness.

Contract
--------
:func:`solve_equilibrium` finds x with F(x) + L = 0 for constant loads L (the
loads' values at time ``t``), starting from ``x0`` (default rest), using the
analytic stiffness -dF/dq of the model (banded, O(n) per iteration). It raises
:class:`NewtonError` if the residual does not fall below the tolerance.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse.linalg as spla

from ..loads import Loads
from ..models.base import Model, get_model
from ..params import ChainParams
from ..state import check_state, n_free, pack, unpack, zeros


class NewtonError(RuntimeError):
    """Newton's method did not converge; ``x`` is the last iterate."""

    def __init__(self, message: str, x: np.ndarray):
        super().__init__(message)
        self.x = x


def solve_equilibrium(
    params: ChainParams,
    model: str | Model,
    loads: Loads,
    *,
    x0: np.ndarray | None = None,
    t: float = 0.0,
    tol: float = 1e-12,
    max_iter: int = 50,
) -> np.ndarray:
    """Static state (3, 2N+1) under the loads at time ``t``.

    Parameters
    ----------
    tol : float
        Stop when max |F + L| <= tol (1 + max |L|).
    max_iter : int

    Raises
    ------
    NewtonError
        If the residual is still above the tolerance after ``max_iter`` iterations.
    """
    model = get_model(model)
    x = zeros(params) if x0 is None else check_state(params, x0, "x0").copy()
    load = loads.as_array(params, t)
    scale = 1.0 + np.max(np.abs(load))
    residual = np.inf
    for _ in range(max_iter):
        r = pack(model.forces(params, x) + load)
        residual = float(np.max(np.abs(r))) if n_free(params) else 0.0
        if residual <= tol * scale:
            return x
        step = spla.spsolve(model.stiffness(params, x).tocsc(), r)
        x = x + unpack(step, params.n_particles)
    raise NewtonError(f"Newton did not converge in {max_iter} iterations (residual {residual:.3g})", x)
