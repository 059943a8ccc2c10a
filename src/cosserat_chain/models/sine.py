"""Model (ii): the sine-Cosserat chain, eq. (2).

Linear in the displacements, with the angles entering only through sin(phi):
the forces are those of the linear model (iii) evaluated at (u, v, sin phi),

    F_sine(u, v, phi) = F_linear(u, v, sin phi).

Eq. (2) is **not** the gradient of any potential: dF_v,k / dphi_k+1 carries a
factor cos(phi_k+1) that dF_phi,k+1 / dv_k lacks, so its Jacobian is not
symmetric away from phi = 0 and no energy exists. The model has no ``energy``;
its stiffness is the non-symmetric Jacobian -dF/dq = K diag(1, 1, cos phi).
At phi = 0 it linearises to the linear model, and it supports full rotations.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
from numba import njit

from ..params import ChainParams
from ..state import check_state, pack
from .base import FORCE_SIGNATURE, KERNEL_OPTIONS, Model, register_model
from .linear import cosserat_coefficients, cosserat_forces, stiffness_matrix
from .trig import sincos


@njit(FORCE_SIGNATURE, **KERNEL_OPTIONS)
def sine_forces_kernel(x, coef, out, start, stop):  # pragma: no cover - compiled
    k_u, k_v, h, bend, couple = coef[0], coef[1], coef[2], coef[3], coef[4]
    u, v, phi = x[0], x[1], x[2]
    # One sine per particle: carry sin(phi) of the previous and current columns.
    s_prev = sincos(phi[start - 1])[0]
    s_cur = sincos(phi[start])[0]
    for k in range(start, stop):
        s_next = sincos(phi[k + 1])[0]
        out[0, k] = k_u * (u[k + 1] - 2.0 * u[k] + u[k - 1])
        out[1, k] = k_v * (v[k + 1] - 2.0 * v[k] + v[k - 1] - 0.5 * h * (s_next - s_prev))
        out[2, k] = bend * (s_next - 2.0 * s_cur + s_prev) + couple * ((v[k + 1] - v[k - 1]) / (2.0 * h) - s_cur)
        s_prev = s_cur
        s_cur = s_next


class SineModel(Model):
    """Sine-Cosserat model (ii), eq. (2): not conservative (see the module docstring)."""

    name = "sine"
    conservative = False
    equation = "eq. (2)"
    force_kernel = sine_forces_kernel

    @staticmethod
    def coefficients(params: ChainParams) -> np.ndarray:
        return cosserat_coefficients(params)

    def forces(self, params: ChainParams, x: np.ndarray) -> np.ndarray:
        u, v, phi = check_state(params, x)
        return cosserat_forces(params, u, v, np.sin(phi))

    def stiffness(self, params: ChainParams, x: np.ndarray) -> sp.csr_matrix:
        x = check_state(params, x)
        chain_rule = pack(np.vstack([np.ones_like(x[:2]), np.cos(x[2:3])]))
        return (stiffness_matrix(params) @ sp.diags(chain_rule)).tocsr()


SINE = register_model(SineModel())
