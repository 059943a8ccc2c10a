"""From damped to undamped: a driven rotating orbit followed to zero damping at a fixed mean rate.

Contract
--------
A rotating orbit of the damped chain under a moment M (:func:`~.periodic.find_periodic_orbit`,
eq. (P)) has a period T and a mean rate Omega = 2 pi k / T of its loaded particle. Scale
every viscosity by s (gamma -> s gamma; s = 1 is the orbit's chain) and let the moment follow
so that the period, hence the mean rate, stays fixed. The unknowns are
w = (y0 on the orbit's phase condition, M, s) and the equations (P) at the fixed T,

    Phi_T^{M, s}(y0) - y0 - 2 pi k e_phi = 0,

2 n_free equations in 2 n_free + 1 unknowns: a curve, which :func:`continue_to_undamped`
follows from s = 1 down to s = 0 by pseudo-arclength on the kit's driver
(:func:`~.kit.continuation`; the driver's ``value`` event at s = 0, then the kit's
:func:`~.kit.newton` at s = 0 exactly).

Why the moment follows as M = s gamma Omega (to a factor), and why the end is regular: for a
conservative model (the nonlinear one) the energy changes over a period by the moment's work
minus the dissipated energy, and returns (the potential is 2 pi periodic in the angles), so on
every orbit

    M Omega = (1 / T) int_0^T sum_i s gamma_i v_i^2 dt                     (B)

(the moment's mean power is the mean dissipated power, :meth:`UndampingPoint.dissipated_power`):
M falls with s, M = s gamma_phi Omega times the ratio of the dissipation to the rotor's
uniform-rotation share (:attr:`UndampingPoint.dissipation_ratio`). At s = 0 the flow conserves
energy and has a double multiplier at +1 (the flow and the family of orbits), so (P) in the
state alone is singular there; the moment is the unfolding that makes it regular (its work
2 pi k M over a period is the one term of the energy's change that does not vanish with s),
as the uniform damping eps is for :func:`~.periodic.find_hamiltonian_orbit`. The curve therefore
crosses s = 0 transversally unless it has folded before, and its point there is an orbit of the
undamped, unloaded chain with period T (M = 0 to the closure tolerance): a roto-breather of
frequency Omega. The sine model (eq. (2)) has no energy and (B) does not hold for it, but its
reversible orbits form the same families, and M (which breaks the reversibility, as damping
does) unfolds them alike.

The Jacobian: dR/dy0 and dR/dM from the shooting's variational equations (the monodromy and the
moment's column, :func:`~.periodic._shooting`); dR/ds by central differences of two state-only
flows at s +- :data:`SCALE_STEP` (the compiled right-hand side has no column for a damping's
scale), accurate to about 1e-7: it steers the predictor and the corrector, while every point
solves (P) to the closure tolerance.

A branch ends at ``value`` (s = 0 reached: :attr:`UndampingPath.undamped`), ``fold`` (s turns
back before 0: below that damping no orbit with this mean rate lies on the curve; its s is
located), ``step_too_small``, ``max_points``, or ``parameter_limit`` where the flow becomes
nearly tangent to the section (:data:`~.periodic.TRANSVERSAL_MIN`).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np
import scipy.linalg as sla
from scipy.integrate import solve_ivp

from ..models.base import Model, get_model
from ..params import ChainParams
from ..state import ROW_INDEX, column, n_free, per_dof
from .kit import BranchEnd, Evaluation, EvaluationFailed, continuation, newton
from .periodic import (
    ATOL,
    CLOSURE_TOL,
    EASY_ITERATIONS,
    HARD_ITERATIONS,
    MAX_CORRECTOR_ITERATIONS,
    NEWTON_RATE,
    RTOL,
    TRANSVERSAL_MIN,
    OrbitError,
    PeriodicOrbit,
    _from_y,
    _Phase,
    _phase_for,
    _shooting,
    _System,
    _to_y,
)

ProgressCallback = Callable[[int, int], None]

#: Step of the central differences of the flow in the damping's scale s.
SCALE_STEP = 1e-6
#: Samples of a period in the quadrature of the dissipated power (trapezoid: spectral for a periodic integrand).
POWER_SAMPLES = 256


@dataclass(frozen=True)
class _ScaledSystem(_System):
    """The chain with every viscosity times ``scale`` (any real: the curve is followed through s = 0)."""

    scale: float = 1.0

    def parameters(self, ncols: int):
        # rpar = (M, 1/mass, gamma/mass), the last two of the shooting's parameters (:meth:`_System.parameters`).
        *kernels, rpar, ipar = super().parameters(ncols)
        rpar[1 + self.nf :] *= self.scale
        return (*kernels, rpar, ipar)


@dataclass
class UndampingPoint:
    """One orbit of the homotopy: the chain's viscosities times ``gamma_scale``, the moment that keeps the period.

    Attributes
    ----------
    params : ChainParams
        The chain at s = 1 (the start's); this point's viscosities are its own times ``gamma_scale``.
    model : str
    gamma_scale : float
        s.
    moment : float
        M on the loaded particle.
    period : float
        T, the start's.
    turns, particle : int
    particle_turns : ndarray (2N+1,) int
    x, v : ndarray (3, 2N+1)
        The state on the phase condition.
    multipliers : ndarray complex
        Floquet multipliers, by decreasing modulus.
    closure : float
        max |R| at the point.
    """

    params: ChainParams
    model: str
    gamma_scale: float
    moment: float
    period: float
    turns: int
    particle: int
    particle_turns: np.ndarray
    x: np.ndarray
    v: np.ndarray
    multipliers: np.ndarray
    closure: float

    @property
    def omega(self) -> float:
        """The loaded particle's mean rate 2 pi k / T (signed along its turns)."""
        k = int(self.particle_turns[column(self.params, self.particle)])
        return 2.0 * math.pi * k / self.period

    @property
    def damping(self) -> tuple[float, float, float]:
        """(gamma_u, gamma_v, gamma_phi) of this point: the start's times s."""
        return tuple(self.gamma_scale * g for g in self.params.damping)

    @property
    def input_power(self) -> float:
        """M Omega: the moment's mean power."""
        return self.moment * self.omega

    def _system(self) -> _ScaledSystem:
        return _ScaledSystem(self.params, get_model(self.model), self.moment, self.particle, self.gamma_scale)

    def dissipated_power(self, samples: int = POWER_SAMPLES) -> float:
        """(1 / T) int_0^T sum_i s gamma_i v_i^2 dt over the orbit, the right side of (B).

        The orbit is integrated again by SciPy's DOP853 (rtol = atol = 1e-12), independent of
        the shooting's compiled integrator, and sampled at ``samples`` equal steps.
        """
        system = self._system()
        nf = n_free(self.params)
        f = system.rhs(0)
        times = self.period * np.arange(samples) / samples
        sol = solve_ivp(f, (0.0, self.period), _to_y(self.params, self.x, self.v), method="DOP853", t_eval=times, rtol=1e-12, atol=1e-12)
        if not sol.success:
            raise OrbitError(f"integration along the homotopy's orbit at s = {self.gamma_scale!r} failed: {sol.message}")
        gamma = self.gamma_scale * per_dof(self.params, self.params.damping)
        return float(np.mean(np.sum(gamma[:, None] * sol.y[nf:] ** 2, axis=0)))

    @property
    def dissipation_ratio(self) -> float:
        """M / (s gamma_phi Omega): 1 for a rotor that turns uniformly and alone dissipates (NaN at s = 0)."""
        rate = self.gamma_scale * self.params.gamma_phi * self.omega
        return self.moment / rate if rate != 0 else math.nan

    def as_dict(self) -> dict:
        return {
            "gamma_scale": self.gamma_scale,
            "damping": list(self.damping),
            "moment": self.moment,
            "omega": self.omega,
            "period": self.period,
            "max_multiplier": float(np.max(np.abs(self.multipliers))),
            "closure": self.closure,
            "rotor_velocity": float(self.v[ROW_INDEX["phi"], column(self.params, self.particle)]),
        }


@dataclass
class UndampingPath:
    """The homotopy from a damped orbit (s = 1) towards the undamped chain (s = 0) at a fixed mean rate.

    Attributes
    ----------
    points : list of UndampingPoint
        In the order traced; the last is at s = 0 exactly where the path got there.
    end : BranchEnd
        ``value`` (s = 0 reached), ``fold`` (s turned back first), or why the driver stopped.
    message : str
    fold : UndampingPoint or None
        The located fold (where s turns back), on the curve.
    """

    points: list[UndampingPoint]
    end: BranchEnd
    message: str
    fold: UndampingPoint | None = None
    settings: dict = field(default_factory=dict)

    @property
    def fold_scale(self) -> float | None:
        """The s of the located fold (None without one)."""
        return None if self.fold is None else self.fold.gamma_scale

    @property
    def undamped(self) -> UndampingPoint | None:
        """The point at s = 0 (an orbit of the undamped, unloaded chain), None where the path did not get there."""
        last = self.points[-1]
        return last if self.end == BranchEnd.VALUE and last.gamma_scale == 0.0 else None

    @property
    def gamma_scale(self) -> np.ndarray:
        return np.array([p.gamma_scale for p in self.points])

    @property
    def moment(self) -> np.ndarray:
        return np.array([p.moment for p in self.points])

    def as_dict(self) -> dict:
        return {
            "end": str(self.end),
            "message": self.message,
            "fold": None if self.fold is None else self.fold.as_dict(),
            "omega": self.points[0].omega,
            "period": self.points[0].period,
            "points": [p.as_dict() for p in self.points],
        }


class _UndampingProblem:
    """(P) at the fixed period with the moment and the damping's scale unknown: w = (y0's unknowns, M, s)."""

    def __init__(self, start: PeriodicOrbit, model: Model, phase: _Phase, tol: float, rtol: float, atol: float):
        self.start, self.model, self.phase = start, model, phase
        self.tol, self.rtol, self.atol = tol, rtol, atol
        self.crossing0 = self._crossing(self.pack(start, 1.0))

    def pack(self, orbit: PeriodicOrbit, scale: float) -> np.ndarray:
        """w of the start orbit at the damping's scale ``scale``."""
        return np.concatenate([_to_y(orbit.params, orbit.x, orbit.v)[self.phase.keep], [orbit.moment, scale]])

    def _system(self, moment: float, scale: float) -> _ScaledSystem:
        return _ScaledSystem(self.start.params, self.model, float(moment), self.start.particle, float(scale))

    def _crossing(self, w: np.ndarray) -> float:
        head = self.phase.head
        return self.phase.crossing(self._system(w[head], w[head + 1]), self.phase.state(w[:head]))

    def evaluate(self, w: np.ndarray, jacobian: bool) -> Evaluation:
        head = self.phase.head
        y0, moment, scale = self.phase.state(w[:head]), w[head], w[head + 1]
        period, turns = self.start.period, self.start.particle_turns
        try:
            residual, jac_y, _, d_moment, mono = _shooting(self._system(moment, scale), turns, self.rtol, self.atol)(y0, period, jacobian)
            if jacobian:
                up = _shooting(self._system(moment, scale + SCALE_STEP), turns, self.rtol, self.atol)(y0, period, False)[0]
                down = _shooting(self._system(moment, scale - SCALE_STEP), turns, self.rtol, self.atol)(y0, period, False)[0]
        except OrbitError as err:
            raise EvaluationFailed(str(err)) from err
        residual = np.append(residual, self.phase.residual(y0))
        if not jacobian:
            return Evaluation(residual)
        d_scale = (up - down) / (2 * SCALE_STEP)
        top = np.column_stack([jac_y[:, self.phase.keep], d_moment, d_scale])
        return Evaluation(residual, np.vstack([top, self.phase.rows(len(w))]), mono)

    def point(self, w: np.ndarray, evaluation: Evaluation, iterations: int) -> UndampingPoint:
        head = self.phase.head
        x, v = _from_y(self.start.params, self.phase.state(w[:head]))
        multipliers = sla.eigvals(evaluation.data)
        return UndampingPoint(
            params=self.start.params, model=self.model.name, gamma_scale=float(w[head + 1]), moment=float(w[head]),
            period=self.start.period, turns=self.start.turns, particle=self.start.particle,
            particle_turns=self.start.particle_turns, x=x, v=v,
            multipliers=multipliers[np.argsort(-np.abs(multipliers), kind="stable")],
            closure=float(np.max(np.abs(evaluation.residual))),
        )  # fmt: skip

    def packed(self, point: UndampingPoint) -> np.ndarray:
        """w of a point of the homotopy."""
        return np.concatenate([_to_y(point.params, point.x, point.v)[self.phase.keep], [point.moment, point.gamma_scale]])

    def accept(self, previous: UndampingPoint, candidate: UndampingPoint) -> bool:
        # A step onto a crossing of the section the other way has slid to where the particle backs up.
        return self._crossing(self.packed(candidate)) * self.crossing0 > 0

    def tests(self, point: UndampingPoint) -> dict[str, float]:
        return {"value": point.gamma_scale}

    def stop(self, point: UndampingPoint) -> tuple[BranchEnd, str] | None:
        if abs(self._crossing(self.packed(point))) < TRANSVERSAL_MIN:
            return (
                BranchEnd.PARAMETER_LIMIT,
                f"the flow became nearly tangent to the phase condition at s = {point.gamma_scale:.8g}: the section cannot fix the phase",
            )
        return None

    def confirm(self, kind: str, point: UndampingPoint) -> bool:
        return True


def continue_to_undamped(
    orbit: PeriodicOrbit,
    *,
    step: float = 0.05,
    min_step: float = 1e-6,
    max_step: float = 0.25,
    max_points: int = 200,
    stop_at_fold: bool = True,
    tol: float = CLOSURE_TOL,
    rtol: float = RTOL,
    atol: float = ATOL,
    progress: ProgressCallback | None = None,
) -> UndampingPath:
    """Follow a damped, driven rotating orbit to zero damping at its own mean rate (module docstring).

    Parameters
    ----------
    orbit : PeriodicOrbit
        A rotating orbit of a damped chain (:func:`~.periodic.find_periodic_orbit`).
    step, min_step, max_step : float
        Initial, smallest and largest arclength steps in (y0, M, s).
    max_points : int
    stop_at_fold : bool
        End at the first fold in s (where the orbit at this mean rate ceases to exist); False
        follows the curve on through it.
    tol, rtol, atol : float
        Closure tolerance and the DOP853 tolerances, as for :func:`~.periodic.find_periodic_orbit`.
    progress : callable(points, max_points), optional

    Returns
    -------
    UndampingPath

    Raises
    ------
    ValueError
        For an orbit of an undamped chain, or bad steps (the driver's messages).
    """
    if not any(g > 0 for g in orbit.params.damping):
        raise ValueError(
            f"orbit: its chain is undamped already (gamma_u, gamma_v, gamma_phi = {orbit.params.damping}); "
            "the homotopy starts from a damped, driven orbit"
        )
    model = get_model(orbit.model)
    system = _ScaledSystem(orbit.params, model, orbit.moment, orbit.particle, 1.0)
    phase = _phase_for(system, _to_y(orbit.params, orbit.x, orbit.v), orbit.phase_normal)
    problem = _UndampingProblem(orbit, model, phase, tol, rtol, atol)
    traced = continuation(
        problem, problem.pack(orbit, 1.0), step=step, min_step=min_step, max_step=max_step, max_points=max_points,
        direction=-1.0, stop_at=("value", "fold") if stop_at_fold else ("value",), progress=progress,
        corrector={"max_iterations": MAX_CORRECTOR_ITERATIONS, "chord": NEWTON_RATE, "forgive": 0},
        easy=EASY_ITERATIONS, hard=HARD_ITERATIONS, tangent_method="svd",
    )  # fmt: skip
    points = list(traced.points)
    settings = {"step": step, "max_step": max_step, "tol": tol, "rtol": rtol, "atol": atol}
    fold = next((e for e in traced.events if e.kind == "fold" and e.located), None)
    message = traced.message
    if traced.end == BranchEnd.VALUE:
        # The located event lies on s = 0 to the secant's tolerance; corrected onto it exactly.
        event = traced.events[-1]
        keep = np.ones(phase.head + 2, dtype=bool)
        keep[-1] = False
        w = problem.packed(event.point)
        w[-1] = 0.0
        landed = newton(problem.evaluate, w, tol=tol, keep=keep, divergence=None)
        if not landed.converged:
            message = f"s = 0 was passed but the correction onto it {landed.status} (closure {landed.norm:.3g})"
            return UndampingPath(points, BranchEnd.STEP_TOO_SMALL, message, None, settings)
        points[-1] = problem.point(landed.w, landed.evaluation, landed.iterations)
        message = f"reached the undamped chain (s = 0) with M = {points[-1].moment:.3g}"
    return UndampingPath(points, traced.end, message, None if fold is None else fold.point, settings)
