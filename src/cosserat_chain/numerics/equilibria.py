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
  the Jacobian sparse, so a chain of 10^4 sites costs O(n) per iteration. Where Newton
  from the start does not converge and the system has an energy, the same corrector
  starts again from there with descent steps: pseudo-transient continuation, implicit
  Euler steps (M / dt - J) dq = F of the gradient flow M q' = F with a pseudo time step
  dt that grows after every step (doubled, or multiplied by the fall of max |F| where that
  is more: switched evolution relaxation) and is cut wherever a step is not a descent
  direction or lowers the energy less than Armijo's condition asks. Every step lowers the
  energy, and as dt grows the steps become Newton's, so the descent ends quadratically at
  an equilibrium no higher than the start: in general a stable one, but a saddle where the
  start lies on its stable manifold (a mirror-symmetric start keeps its symmetry, and ends
  at the symmetric saddle if that is the symmetric minimum); the result's index says which.
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
from ..linalg import band_storage, negative_count, sparse_solve
from ..linalg.threads import one_blas_thread
from ..systems.base import System
from .kit import BranchEnd, Evaluation, continuation, newton

#: Newton tolerance on max |F|.
FORCE_TOL = 1e-10
#: Largest number of coordinates whose dynamic eigenvalues are computed densely.
DENSE_LIMIT = 600
#: A Hopf point is confirmed when a complex pair lies this close to the imaginary axis.
HOPF_CONFIRM = 1e-5
#: Steps of :func:`find_equilibrium`'s descent where Newton does not converge.
MAX_DESCENT_STEPS = 500
#: The descent's pseudo time step grows by DESCENT_GROWTH after a step, or as much as max |F| fell if more, but at
#: most DESCENT_LARGEST_GROWTH; it is cut by DESCENT_CUT where a step does not descend.
DESCENT_GROWTH, DESCENT_LARGEST_GROWTH, DESCENT_CUT = 2.0, 10.0, 0.25
#: Armijo's sufficient decrease of the energy along a descent step (a fraction of F . dq).
ARMIJO = 1e-4


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
    #: Which solver of :func:`find_equilibrium` found it: ``"newton"``, or ``"descent"`` where Newton did not converge.
    method: str = "newton"

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
def find_equilibrium(
    system: System,
    q0: np.ndarray,
    *,
    tol: float = FORCE_TOL,
    max_iterations: int = 50,
    descent: bool = True,
    max_descent_steps: int = MAX_DESCENT_STEPS,
) -> SystemEquilibrium:
    """The equilibrium of ``system`` reached by Newton from ``q0``, or by descent where Newton fails.

    Newton's full steps come first: where they converge the answer is theirs, bit for bit,
    and may be any equilibrium near the start (a saddle as well as a minimum). Where they do
    not (a start far from any equilibrium, or one next to a nearly singular Jacobian, such as
    a lattice kink started between its stationary positions, whose sliding mode is almost
    free) and the system has an energy, the kit's corrector starts again from ``q0`` with
    descent steps (pseudo-transient continuation, the module docstring): the energy falls at
    every step, and the answer is an equilibrium of energy at most the start's; the result's
    ``index`` says whether it is a minimum (0) or the saddle a symmetric start keeps to.
    Each step is one sparse solve, O(n) for a chain.

    Parameters
    ----------
    system : System
    q0 : ndarray (n,)
        The start; finite.
    tol : float
        Converged when max |F| <= tol.
    max_iterations : int
        Newton's steps.
    descent : bool
        Fall back on the descent where Newton does not converge (conservative systems only:
        one without an energy raises as before).
    max_descent_steps : int
        The descent's steps.

    Returns
    -------
    SystemEquilibrium
        ``method`` says which solver found it: ``"newton"`` or ``"descent"``.

    Raises
    ------
    EquilibriumNotFound
        If neither converges (start nearer, or follow the branch from a known one with
        :func:`continue_equilibria`).
    SystemDefinitionError
        For a start of the wrong shape or with a non-finite entry.
    """
    q0 = system.check_state(q0, "q0")

    def evaluate(q, jacobian):
        return Evaluation(system.forces(q), sp.csc_matrix(system.force_jacobian(q)) if jacobian else None)

    corrected = newton(evaluate, q0, tol=tol, max_iterations=max_iterations)
    if corrected.converged:
        return classify(system, corrected.w, corrected.norm)
    message = (
        f"Newton on the equilibrium of {system.name} {corrected.status} after {corrected.iterations} iterations "
        f"(max|F| = {corrected.norm:.3g})"
    )
    if not descent or system.energy(q0) is None:
        why = "" if descent else " (descent=False)"
        raise EquilibriumNotFound(f"{message}{why}; start nearer, or continue from a known equilibrium")
    descended = newton(evaluate, q0, tol=tol, max_iterations=max_descent_steps, divergence=None, newton_step=_DescentStep(system))
    if not descended.converged:
        lowered = (
            f", the energy lowered from {system.energy(q0):.10g} to {system.energy(descended.w):.10g}: an energy without a "
            "minimum below the start keeps falling"
            if np.all(np.isfinite(descended.w))
            else ""
        )
        raise EquilibriumNotFound(
            f"{message}, and the descent from q0 {descended.status} after {descended.iterations} steps "
            f"(max|F| = {descended.norm:.3g}{lowered}); raise max_descent_steps, start nearer, or continue from a known equilibrium"
        )
    found = classify(system, descended.w, descended.norm)
    found.method = "descent"
    return found


class _DescentStep:
    """The descent's step for :func:`~cosserat_chain.numerics.kit.newton` (pseudo-transient continuation).

    At q with forces F and Jacobian J the step solves (M / dt - J) dq = F (one sparse solve);
    dt grows after every step by :data:`DESCENT_GROWTH`, or by the fall of max |F| since the
    last step where that is more (switched evolution relaxation), at most
    :data:`DESCENT_LARGEST_GROWTH`-fold, and is cut by :data:`DESCENT_CUT` until dq is a
    descent direction (F . dq > 0) and E(q + dq) <= E(q) - :data:`ARMIJO` F . dq, up to the
    energy's round-off eps n max(1, |E|). The first dt is the fastest linear time scale's,
    min_i m_i / sum_j |J_ij|.
    """

    def __init__(self, system: System):
        self.system = system
        self.mass = np.asarray(system.mass(), dtype=float)
        self.dt: float | None = None
        self.norm = math.inf

    def __call__(self, q: np.ndarray, evaluation: Evaluation, jacobian) -> np.ndarray:
        forces = np.asarray(evaluation.residual, dtype=float)
        norm = float(np.max(np.abs(forces)))
        if self.dt is None:
            rows = np.asarray(abs(jacobian).sum(axis=1)).ravel()
            self.dt = float(np.min(self.mass / np.maximum(rows, np.finfo(float).tiny)))
        else:
            self.dt *= min(max(DESCENT_GROWTH, self.norm / norm), DESCENT_LARGEST_GROWTH)
        self.norm = norm
        energy = self.system.energy(q)
        slack = np.finfo(float).eps * q.size * max(1.0, abs(energy))
        while self.dt >= np.finfo(float).tiny:
            step = sparse_solve(sp.diags(self.mass / self.dt, format="csc") - jacobian, forces)
            slope = float(forces @ step)
            if np.all(np.isfinite(step)) and slope > 0.0 and self.system.energy(q + step) <= energy - ARMIJO * slope + slack:
                return step
            self.dt *= DESCENT_CUT
        raise ArithmeticError("no pseudo time step lowers the energy")


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
        self.parameter_name = name

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
