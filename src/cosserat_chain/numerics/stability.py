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

Without dense matrices (the default at every size): the critical eigenvalue is the
smallest eigenvalue of the model's symmetric banded matrix similar to K
(:meth:`~cosserat_chain.models.base.Model.symmetric_similar`; LAPACK's banded
symmetric solver, O(N)), and the state is stable iff it is positive. For a
conservative model with positive damping the damped dynamics decays iff K is
positive definite. For eq. (2), K = S C with S the linear model's (positive
definite) and C = diag(1, 1, cos phi): if every cos phi > 0, C M, C Gamma and C S C
are positive definite and the energy 1/2 q'^T C M q' + 1/2 q^T C S C q of
C M q'' + C Gamma q' + C S C q = 0 decays; a particle beyond pi/2 gives K a negative
eigenvalue (Sylvester's law of inertia) and a growing mode (checked against the dense
reference on random chains). The spectral abscissa is then not computed (NaN).
``dense=True`` runs the dense reference (O(N^3)): eigenvalues of K and of the damped
dynamics matrix A; a model without a symmetric similar matrix always takes it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import scipy.linalg as la

from ..models.base import Model, get_model, upper_bands
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
        (< 0: perturbations decay); NaN where the banded path decided (module docstring).
    index : int
        Number of eigenvalues of K with a negative real part (the Morse index for a
        conservative model): it changes by one at every fold, also between two
        unstable states.
    """

    stable: bool
    critical_eigenvalue: float
    spectral_abscissa: float
    index: int = 0


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


def static_stability(params: ChainParams, model: str | Model, x: np.ndarray, *, dense: bool = False) -> Stability:
    """Stability of the static state ``x`` (3, 2N+1) of ``model`` (see the module docstring).

    For a state with zero damping, purely oscillatory perturbations count as
    stable (spectral abscissa at round-off level). ``dense=True`` runs the dense
    reference instead of the banded path (module docstring).
    """
    model = get_model(model)
    x = check_state(params, x)
    similar = None if dense else model.symmetric_similar(params, x)
    if similar is not None:
        bands = upper_bands(similar)
        critical = float(la.eig_banded(bands, eigvals_only=True, select="i", select_range=(0, 0))[0])
        index = 0 if critical >= 0 else la.eig_banded(bands, eigvals_only=True, select="v", select_range=(-np.inf, 0.0)).size
        return Stability(critical > 0.0, critical, math.nan, int(index))
    k = model.stiffness(params, x).toarray()
    abscissa = float(np.max(la.eigvals(damped_dynamics_matrix(params, k)).real))
    if model.conservative:
        eigenvalues = la.eigvalsh(k)
        return Stability(bool(eigenvalues[0] > 0.0), float(eigenvalues[0]), abscissa, int(np.sum(eigenvalues < 0)))
    # Round-off of the eigenvalue solver, relative to the fastest rate of the chain.
    round_off = 1e-10 * max(1.0, float(np.max(np.abs(k))))
    real = la.eigvals(k).real
    return Stability(abscissa < round_off, float(np.min(real)), abscissa, int(np.sum(real < 0)))
