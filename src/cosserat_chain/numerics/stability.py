"""Stability of static states: the Hessian for conservative models, the damped dynamics otherwise.

Contract
--------
:func:`static_stability` classifies an equilibrium x of the loaded chain.

* Conservative models (nonlinear, linear): x is a minimum of the total energy iff
  the stiffness K = -dF/dq (the Hessian) is positive definite; the *critical
  eigenvalue* is its smallest eigenvalue.
* The sine model (eq. 2) has no energy. Its stiffness K is not symmetric, and x is
  stable iff every eigenvalue of the damped dynamics linearised about x,

      d/dt (q, v) = A (q, v),   A = [[0, I], [-M^-1 K, -M^-1 Gamma]],

  has a negative real part. The critical eigenvalue is then the real part of
  the eigenvalue of K nearest the imaginary axis from the right: it is the one
  that crosses zero at a fold, for every model alike.

Dense eigenvalue solvers are used: O(n^3) in the 3(2N-1) free degrees of freedom,
which is instant for the chains of the paper and fine up to a few hundred particles.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.linalg as la

from ..models.base import Model, get_model
from ..params import ChainParams
from ..state import check_state


@dataclass(frozen=True)
class Stability:
    """Stability of one static state.

    Attributes
    ----------
    stable : bool
    critical_eigenvalue : float
        Smallest eigenvalue of K (real part for a non-symmetric K); it vanishes at a fold.
    spectral_abscissa : float
        Largest real part of the eigenvalues of the linearised damped dynamics
        (< 0: perturbations decay). Computed for every model.
    """

    stable: bool
    critical_eigenvalue: float
    spectral_abscissa: float


def damped_dynamics_matrix(params: ChainParams, stiffness: np.ndarray) -> np.ndarray:
    """The matrix A of the damped dynamics linearised about a static state, shape (2 n_free, 2 n_free).

    Parameters
    ----------
    stiffness : ndarray (n_free, n_free)
        K = -dF/dq at the state (dense).
    """
    n_free = stiffness.shape[0]
    inertia = np.tile(np.asarray(params.inertia), n_free // 3)
    damping = np.tile(np.asarray(params.damping), n_free // 3)
    a = np.zeros((2 * n_free, 2 * n_free))
    a[:n_free, n_free:] = np.eye(n_free)
    a[n_free:, :n_free] = -stiffness / inertia[:, None]
    a[n_free:, n_free:] = -np.diag(damping / inertia)
    return a


def static_stability(params: ChainParams, model: str | Model, x: np.ndarray) -> Stability:
    """Stability of the static state ``x`` (3, 2N+1) of ``model`` (see the module docstring).

    For a state with zero damping, purely oscillatory perturbations count as
    stable (spectral abscissa at round-off level).
    """
    model = get_model(model)
    x = check_state(params, x)
    stiffness = model.stiffness(params, x).toarray()
    abscissa = float(np.max(la.eigvals(damped_dynamics_matrix(params, stiffness)).real))
    if model.conservative:
        critical = float(la.eigvalsh(stiffness)[0])
        return Stability(critical > 0.0, critical, abscissa)
    critical = float(np.min(la.eigvals(stiffness).real))
    # Round-off of the eigenvalue solver, relative to the fastest rate of the chain.
    round_off = 1e-10 * max(1.0, float(np.max(np.abs(stiffness))))
    return Stability(abscissa < round_off, critical, abscissa)
