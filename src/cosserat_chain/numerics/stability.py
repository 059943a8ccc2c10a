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

Up to :data:`DENSE_LIMIT` free degrees of freedom dense eigenvalue solvers are used
(the reference). Beyond it, for a conservative model, nothing dense is formed: the
critical eigenvalue is the smallest eigenvalue of the banded Hessian (LAPACK's banded
symmetric solver, O(N)), which decides stability (with positive damping the damped
dynamics decays iff K is positive definite); the spectral abscissa is then not
computed (NaN). The sine model's non-symmetric K still goes through the dense
solvers at every size: O(N^3) per state, minutes per branch from N of about 50.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import scipy.linalg as la
import scipy.sparse as sp

from ..models.base import Model, get_model
from ..params import ChainParams
from ..state import check_state

#: Free degrees of freedom up to which the dense solvers run (N up to about 25).
DENSE_LIMIT = 150


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


def static_stability(params: ChainParams, model: str | Model, x: np.ndarray, *, dense: bool | None = None) -> Stability:
    """Stability of the static state ``x`` (3, 2N+1) of ``model`` (see the module docstring).

    For a state with zero damping, purely oscillatory perturbations count as
    stable (spectral abscissa at round-off level). ``dense`` forces the dense
    (True) or the banded (False, conservative models only) path; by default dense
    up to :data:`DENSE_LIMIT` free degrees of freedom.
    """
    model = get_model(model)
    x = check_state(params, x)
    stiffness = model.stiffness(params, x)
    scale = max(1.0, float(abs(stiffness).max())) if stiffness.nnz else 1.0
    # Round-off of the eigenvalue solvers, relative to the fastest rate of the chain.
    round_off = 1e-10 * scale
    if dense if dense is not None else stiffness.shape[0] <= DENSE_LIMIT:
        k = stiffness.toarray()
        abscissa = float(np.max(la.eigvals(damped_dynamics_matrix(params, k)).real))
        if model.conservative:
            critical = float(la.eigvalsh(k)[0])
            return Stability(critical > 0.0, critical, abscissa)
        return Stability(abscissa < round_off, float(np.min(la.eigvals(k).real)), abscissa)
    if not model.conservative:
        return static_stability(params, model, x, dense=True)
    critical = _smallest_banded(stiffness)
    return Stability(critical > 0.0, critical, math.nan)


def _smallest_banded(stiffness: sp.spmatrix) -> float:
    """Smallest eigenvalue of the symmetric banded K (exact, O(n) for a chain's bandwidth)."""
    coo = stiffness.tocoo()
    lower = coo.row >= coo.col
    offset = coo.row[lower] - coo.col[lower]
    bands = np.zeros((int(offset.max(initial=0)) + 1, coo.shape[0]))
    bands[offset, coo.col[lower]] = coo.data[lower]
    return float(la.eig_banded(bands, lower=True, eigvals_only=True, select="i", select_range=(0, 0))[0])
