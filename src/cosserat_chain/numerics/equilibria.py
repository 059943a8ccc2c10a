"""Equilibria of any system: Newton, stability, and continuation in any parameter with folds, branch and Hopf points.

Contract
--------
An equilibrium of a :class:`~cosserat_chain.systems.base.System` solves F(q; p) = 0. Its
linear dynamics M x'' = J x - C x' (J = dF/dq) has the eigenvalues of
A = [[0, I], [M^-1 J, -M^-1 C]]; the equilibrium is stable when all lie in the left half
plane (the count of the others is its dynamic index). For a conservative system with
damping this is the inertia of -J; a non-conservative one (a follower torque, the
sine-Cosserat model (2)) can lose stability at a Hopf point with J regular.

* :func:`find_equilibrium`: Newton (:func:`cosserat_chain.numerics.kit.newton`) on F = 0,
  the Jacobian sparse, so a chain of 10^4 sites costs O(n) per iteration.
* :func:`continue_equilibria`: the branch in any named parameter by the one
  pseudo-arclength driver, unknowns (q, p); folds (the parameter turns), branch points
  (det [dF/d(q,p); t] changes sign) and Hopf points (a complex pair of A crosses the
  imaginary axis) are located as events. The dynamic eigenvalues are computed densely
  up to :data:`DENSE_LIMIT` coordinates; beyond, the index of a conservative system with
  passive damping is the inertia of -J, counted exactly by a band LDL^T (open ends, up to
  three degrees of freedom a site), and Hopf points are not sought.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from ..errors import CosseratChainError
from ..linalg import band_storage, negative_count
from ..linalg.threads import one_blas_thread
from ..systems.base import System
from .kit import BranchEnd, Evaluation, continuation, newton

#: Newton tolerance on max |F|.
FORCE_TOL = 1e-10
#: Largest number of coordinates whose dynamic eigenvalues are computed densely.
DENSE_LIMIT = 600
#: A Hopf point is confirmed when a complex pair lies this close to the imaginary axis.
HOPF_CONFIRM = 1e-5


class EquilibriumNotFound(CosseratChainError, RuntimeError):
    """Newton on F = 0 did not converge."""


@dataclass
class SystemEquilibrium:
    """An equilibrium q of ``system``, with its dynamic eigenvalues (None where not computed)."""

    system: System
    q: np.ndarray
    eigenvalues: np.ndarray | None
    residual: float
    stable: bool | None
    index: int | None

    def parameter(self, name: str) -> float:
        return self.system.parameter(name)


def classify(system: System, q: np.ndarray, residual: float = 0.0) -> SystemEquilibrium:
    """The equilibrium q of ``system`` with its stability (see the module docstring)."""
    n = system.size
    jac = system.force_jacobian(q)
    if n <= DENSE_LIMIT:
        inverse = 1.0 / system.mass()
        a = np.zeros((2 * n, 2 * n))
        a[:n, n:] = np.eye(n)
        a[n:, :n] = inverse[:, None] * jac.toarray()
        a[n:, n:] = -np.diag(system.damping() * inverse)
        eig = np.linalg.eigvals(a)
        scale = max(1.0, float(np.max(np.abs(eig))))
        unstable = int(np.sum(eig.real > 1e-9 * scale))
        return SystemEquilibrium(system, q, eig, residual, unstable == 0, unstable)
    if system.energy(q) is None or np.any(system.damping() < 0):
        return SystemEquilibrium(system, q, None, residual, None, None)
    # A conservative system with passive damping: its dynamic index is the inertia of -J, counted
    # exactly by a band LDL^T (Sylvester); a ring's corners or a wider band leave it unknown.
    try:
        negative = int(negative_count(band_storage(-sp.csr_matrix(jac)), 0.0))
    except ValueError:
        return SystemEquilibrium(system, q, None, residual, None, None)
    return SystemEquilibrium(system, q, None, residual, negative == 0, negative)


@one_blas_thread
def find_equilibrium(system: System, q0: np.ndarray, *, tol: float = FORCE_TOL, max_iterations: int = 50) -> SystemEquilibrium:
    """The equilibrium of ``system`` reached by Newton from ``q0``.

    Raises
    ------
    EquilibriumNotFound
        If Newton does not converge (start nearer, or follow the branch from a known one with
        :func:`continue_equilibria`).
    """
    q0 = system.check_state(q0, "q0")

    def evaluate(q, jacobian):
        return Evaluation(system.forces(q), sp.csc_matrix(system.force_jacobian(q)) if jacobian else None)

    corrected = newton(evaluate, q0, tol=tol, max_iterations=max_iterations)
    if not corrected.converged:
        raise EquilibriumNotFound(
            f"Newton on the equilibrium of {system.name} {corrected.status} after {corrected.iterations} iterations "
            f"(max|F| = {corrected.norm:.3g}); start nearer, or continue from a known equilibrium"
        )
    return classify(system, corrected.w, corrected.norm)


@dataclass
class EquilibriumBranch:
    """Equilibria continued in one parameter, with located events and how the branch ended."""

    parameter: str
    points: list[SystemEquilibrium]
    events: list
    end: BranchEnd
    message: str

    @property
    def values(self) -> np.ndarray:
        return np.array([p.parameter(self.parameter) for p in self.points])

    def folds(self) -> list[float]:
        return [e.parameter for e in self.events if e.kind == "fold" and e.located]

    def as_dict(self) -> dict:
        return {
            "parameter": self.parameter,
            "values": self.values.tolist(),
            "stable": [p.stable for p in self.points],
            "events": [{"kind": e.kind, "value": e.parameter} for e in self.events],
            "end": str(self.end),
            "message": self.message,
        }


class _EquilibriumProblem:
    def __init__(self, system: System, name: str, limits: tuple[float, float], tol: float):
        self.system, self.name, self.limits, self.tol = system, name, limits, tol

    def evaluate(self, w, jacobian):
        system = self.system.with_parameters(**{self.name: float(w[-1])})
        q = w[:-1]
        residual = system.forces(q)
        if not jacobian:
            return Evaluation(residual)
        jac = sp.hstack([system.force_jacobian(q), sp.csr_matrix(system.parameter_forces(q, self.name)[:, None])], format="csc")
        return Evaluation(residual, jac, system)

    def point(self, w, ev, iterations):
        return classify(ev.data, w[:-1].copy(), float(np.max(np.abs(ev.residual), initial=0.0)))

    def accept(self, previous, candidate):
        return True

    def tests(self, point: SystemEquilibrium) -> dict[str, float]:
        if point.eigenvalues is None:
            return {}
        eig = point.eigenvalues
        pairs = eig[eig.imag > 1e-9]
        return {"hopf": float(np.prod(np.sign(pairs.real))) if pairs.size else 1.0}

    def confirm(self, kind: str, point: SystemEquilibrium) -> bool:
        if kind == "hopf":
            eig = point.eigenvalues
            pairs = eig[eig.imag > 1e-6]
            return bool(pairs.size and np.min(np.abs(pairs.real)) < HOPF_CONFIRM * max(1.0, float(np.max(np.abs(pairs)))))
        return True

    def stop(self, point: SystemEquilibrium):
        value = point.parameter(self.name)
        if not self.limits[0] <= value <= self.limits[1]:
            return BranchEnd.PARAMETER_LIMIT, f"{self.name} = {value:.12g} left [{self.limits[0]:g}, {self.limits[1]:g}]"
        return None


@one_blas_thread
def continue_equilibria(
    start: SystemEquilibrium,
    parameter: str,
    *,
    direction: float = 1.0,
    limits: tuple[float, float] = (-math.inf, math.inf),
    step: float = 0.02,
    min_step: float = 1e-8,
    max_step: float = 0.2,
    max_points: int = 500,
    stop_at: tuple[str, ...] = ("fold",),
    tol: float = FORCE_TOL,
    progress: Callable[[int, int], None] | None = None,
) -> EquilibriumBranch:
    """Follow the equilibrium ``start`` in the named ``parameter`` (pseudo-arclength in (q, p)).

    Parameters
    ----------
    start : SystemEquilibrium
        From :func:`find_equilibrium`.
    parameter : str
        Any parameter of the system.
    direction : float
        +1 towards larger values, -1 towards smaller.
    limits : (float, float)
    stop_at : tuple of str
        Events that end the branch: ``fold``, ``branch_point``, ``hopf``.

    Returns
    -------
    EquilibriumBranch
    """
    system = start.system
    system.parameter(parameter)
    problem = _EquilibriumProblem(system, parameter, limits, tol)
    w0 = np.append(start.q, system.parameter(parameter))
    traced = continuation(
        problem,
        w0,
        step=step,
        min_step=min_step,
        max_step=max_step,
        max_points=max_points,
        direction=direction,
        stop_at=stop_at,
        progress=progress,
    )
    return EquilibriumBranch(parameter, traced.points, traced.events, traced.end, traced.message)
