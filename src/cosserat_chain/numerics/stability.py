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
(:meth:`~cosserat_chain.models.base.Model.symmetric_similar`), found by bisection on
the number of eigenvalues below a shift (Sylvester's law of inertia: the negative
pivots of a banded LDL^T factorisation, O(N) each; LAPACK's banded eigensolver is
O(N^2): 0.5 s at N = 1000), and the state is stable iff it is positive; the index
is that count at zero. For a
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
import scipy.sparse as sp
from numba import njit

from ..models.base import Model, get_model, upper_bands
from ..params import ChainParams
from ..state import check_state

#: Relative width (to the Gershgorin radius) at which the bisection for the smallest eigenvalue stops.
BISECTION_RTOL = 1e-14


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
        lower = _lower_rows(similar)
        index = negative_count(lower, 0.0)
        critical = _smallest_eigenvalue(lower, similar)
        return Stability(index == 0 and critical > 0.0, critical, math.nan, index)
    k = model.stiffness(params, x).toarray()
    abscissa = float(np.max(la.eigvals(damped_dynamics_matrix(params, k)).real))
    if model.conservative:
        eigenvalues = la.eigvalsh(k)
        return Stability(bool(eigenvalues[0] > 0.0), float(eigenvalues[0]), abscissa, int(np.sum(eigenvalues < 0)))
    # Round-off of the eigenvalue solver, relative to the fastest rate of the chain.
    round_off = 1e-10 * max(1.0, float(np.max(np.abs(k))))
    real = la.eigvals(k).real
    return Stability(abscissa < round_off, float(np.min(real)), abscissa, int(np.sum(real < 0)))


def _lower_rows(matrix: sp.spmatrix) -> np.ndarray:
    """A symmetric banded matrix by rows of its lower band: out[i, d] = M[i, i - d] = M[i - d, i], d = 0..w.

    LAPACK's upper storage (:func:`~cosserat_chain.models.base.upper_bands`) holds M[i - d, i]
    at [w - d, i]: its rows reversed and transposed.
    """
    return np.ascontiguousarray(upper_bands(matrix)[::-1].T)


@njit(cache=True, nogil=True)
def negative_count(lower: np.ndarray, shift: float) -> int:  # pragma: no cover - compiled
    """Number of eigenvalues below ``shift`` of the symmetric banded matrix ``lower`` (:func:`_lower_rows`).

    Sylvester's law of inertia: the negative pivots of the LDL^T factorisation of
    M - shift I, without pivoting, in O(n w^2) (a zero pivot is nudged by the round-off).
    """
    n, width = lower.shape[0], lower.shape[1] - 1
    factor = np.zeros((n, width + 1))  # factor[i, d] = L[i, i - d]
    pivots = np.zeros(n)
    tiny = 1e-300
    count = 0
    for i in range(n):
        for d in range(width, 0, -1):
            j = i - d
            if j < 0:
                continue
            total = lower[i, d]
            for k in range(max(0, i - width), j):
                total -= factor[i, i - k] * pivots[k] * factor[j, j - k]
            factor[i, d] = total / pivots[j]
        total = lower[i, 0] - shift
        for k in range(max(0, i - width), i):
            total -= factor[i, i - k] * factor[i, i - k] * pivots[k]
        pivots[i] = total if total != 0.0 else tiny
        if total < 0.0:
            count += 1
    return count


def _smallest_eigenvalue(lower: np.ndarray, matrix: sp.spmatrix) -> float:
    """Smallest eigenvalue by bisection on the inertia (O(n) a step), to round-off of the matrix's scale."""
    radius = float(abs(matrix).sum(axis=1).max())
    low, high = -radius, float(lower[:, 0].min())  # Gershgorin, and lambda_min <= min diagonal
    while high - low > BISECTION_RTOL * max(radius, 1e-300):
        middle = 0.5 * (low + high)
        if negative_count(lower, middle) > 0:
            high = middle
        else:
            low = middle
    return 0.5 * (low + high)
