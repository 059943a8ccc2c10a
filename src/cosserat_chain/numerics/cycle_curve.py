"""The end of a rotating state followed in a second parameter: the lower edge of the hysteresis loop in (M, p).

Contract
--------
A rotating orbit (:mod:`~cosserat_chain.numerics.periodic`, eq. (P)) followed down in M
stops being the state a slowly falling load keeps at one of a few kinds of points (the
``end`` of :mod:`cosserat_chain.experiments.diagram`); three of them are regular points of an
augmented system. Each is a curve in the plane of the
moment M and a field p of the chain, and :func:`continue_cycle_end` follows it through
values of p on the kit's driver (:func:`~.kit.continuation`, natural steps in p:
:class:`_EndCurve`), each step Newton's method (the kit's corrector, :func:`~.kit.newton`) on an
*augmented shooting system* at its value, started
from the point before (extrapolated along the curve from the two before it):

* ``fold_of_cycles``: (P) and g = 0, g the bordered test function of the shooting
  Jacobian A = d(P)/d(y0, log T): [[A, b], [c^T, 0]] [v; g] = [0; 1], zero exactly where A is
  singular (the minimally augmented system of MatCont and BifurcationKit.jl; b and c are A's
  singular vectors of its smallest singular value at the point before, which keeps the
  bordered matrix regular). At a fold the multiplier at +1 is double (beside the trivial
  one) and not a smooth function of the unknowns, so it cannot serve as g there.
* ``period_doubling``: (P) and the same bordered function of monodromy + I, singular where a
  multiplier equals -1. (The multiplier itself is no good test function there: in the
  paper's chain it has just split off a complex pair on the negative real axis, and a
  small change of the unknowns joins them again.)
* ``torus``: (P) and |mu|^2 - 1 = 0, mu a complex multiplier: at the start the largest
  (at the edge every other one lies inside), then the one nearest it at the iterate or point
  before (a Neimark-Sacker bifurcation of the cycle; a simple pair is a smooth function of
  the unknowns).
The unknowns are z = (y0 without phi_0, log T, M), or (y0, log T, M) with the phase plane's
equation beside (P) for an orbit that carries one (:attr:`~.periodic.PeriodicOrbit.phase_normal`:
where the flow is nearly tangent to the section phi_0 = 0, whose system is singular there
without a fold). A located ``fold_of_cycles`` must have a second multiplier at +1 beside the
trivial one (:data:`FOLD_MULTIPLIER_TOL`), else it is refused. The
Jacobian R_z of (P) is exact (the monodromy matrix and the flow's derivative in M). The test
function's gradient is needed only along two directions: the minimum-norm correction of
(P) and the null vector of R_z (the orbit branch's tangent in M); every Newton step of (P)
is one of them plus a multiple of the other, and the multiple is fixed by the linearised
g = 0. Both derivatives are one-sided differences, two more monodromy integrations an
iteration instead of the size of z.

Each point is checked to be the lower edge it claims to be: every other nontrivial
multiplier inside the unit circle (by :data:`EDGE_MARGIN`), and the critical one outside
it a short step down the orbit branch (where it re-enters the circle as M falls, the orbit
regains stability there: no edge). Where one is not, another
multiplier has left the circle first (the edge changes kind between two values) and the
curve stops there, saying so; so it does where Newton fails from the previous point even
on halved parameter steps (the curve turns back in p, or ends at a codimension-two point:
the paper's chain's torus end cannot be followed beyond E2 = 1.12 and is a period doubling at
1.2: the two meet at a 1:2 resonance; the multiplier's codimension-two points along each
kind, :data:`CODIM2`, are located by :func:`_codim2_points`).

Where a ``fold_of_cycles`` curve stops so (natural steps fail, jump, or reach no fold: anything but an
edge check, on the chain's curves and a user system's alike), it is followed on by pseudo-arclength in
w = (z, p) (:class:`_FoldArc`: the augmented system with p free and the condition t . (w - w_pred) = 0),
which passes a turn of p. On a fold curve p turns exactly where the fold's quadratic
coefficient vanishes (at fixed p the folds are the critical points of M along the orbit
branch; their curve can turn in p only where that critical point is degenerate): two folds of
the branch meet there and both vanish beyond, a *cusp* of cycles (AUTO-07p's CP), where the
curve's tangent has no M-component either. The zero of the tangent's p-component is located
(:func:`_cusp`) and reported as a :class:`Codim2Point` ``cusp`` with the curve's points on
either side of the turn (the two folds); below the cusp their moments part like the distance
to it to the power 3/2 (the cusp's normal form).

Not followed: a homoclinic end. Approximating the homoclinic orbit by an orbit of fixed
long period (AUTO-07p's way) needs collocation or multiple shooting: with single shooting the
orbit's passage near the saddle makes Newton fail at the first step in p (the pendulum at
gamma_phi = 0.02: a step of 0.5 % from an orbit 1e-4 above M_h, and a change of 3 % in the
period), so :mod:`~cosserat_chain.experiments.diagram` reads each value's homoclinic end
from its own one-parameter continuation.
"""

from __future__ import annotations

import dataclasses
import functools
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import numpy as np
import scipy.linalg as sla

from ..models.base import get_model
from ..params import ChainParams
from ..state import n_free
from . import shooting
from .cycle_events import CIRCLE_KINDS, circle_events_between
from .fold_curve import FIELDS, chain_with, field_values
from .kit import BranchEnd, Correction, Corrector, Evaluation, EvaluationFailed, Event, continuation, illinois, newton
from .periodic import (
    ATOL,
    CLOSURE_TOL,
    RTOL,
    OrbitError,
    PeriodicOrbit,
    _orbit,
    _orbit_between,
    _phase_for,
    _shooting,
    _System,
    _to_y,
    find_periodic_orbit,
)

#: Kinds of end that can be followed (:mod:`~cosserat_chain.experiments.diagram`'s ends that are
#: regular points of an augmented system; a SNIC lies on the static fold, followed by
#: :func:`~.fold_curve.continue_fold`; a homoclinic end: module docstring).
KINDS = ("fold_of_cycles", "period_doubling", "torus")
#: Kinds whose test function is bordered (a matrix singular at the end); the torus's is its multiplier's modulus.
BORDERED = ("fold_of_cycles", "period_doubling")
#: Newton iterations per value before its parameter step is halved.
MAX_ITERATIONS = 12
#: Halvings of a parameter step (in all, towards one value) before the curve is declared ended there.
MAX_HALVINGS = 10
#: The secant predictor's longest extrapolation, in units of the spacing of the two points it uses
#: (a step grows at most twofold after a success).
MAX_EXTRAPOLATION = 4.0
#: Newton gives up when two iterations do not divide max(|R|, |g|) by 1 / CONTRACTION.
CONTRACTION = 0.5
#: Halvings of one Newton step that makes the residual or the test function larger.
NEWTON_HALVINGS = 4
#: Newton stops when the test function is this small (a multiplier's distance from the
#: circle; the bordered function of a fold is of the order of A's smallest singular value).
TEST_TOL = 1e-9
#: One-sided difference step of the test function's directional derivatives (the unknowns are O(1)).
DIFFERENCE_STEP = 1e-6
#: Largest change of the state (in h or rad) from the predictor: a longer Newton step has
#: jumped to another orbit rather than followed this one, and the parameter step is halved.
JUMP = 0.3
#: The other nontrivial multipliers of a point on the edge lie inside |mu| < 1 - EDGE_MARGIN.
EDGE_MARGIN = 1e-6
#: Step along the orbit branch (in the unknowns) at which the critical multiplier is checked to lie outside the circle.
CROSSING_STEP = 1e-4
#: An imaginary part above this (relative to the modulus) makes a multiplier complex.
COMPLEX_RTOL = 1e-6
#: A fold of cycles has a second Floquet multiplier at +1 beside the trivial one: the two nearest +1 lie
#: within this of it (a double multiplier of a monodromy accurate to ~1e-10 splits like its square root).
FOLD_MULTIPLIER_TOL = 1e-3
#: Codimension-two points watched along each kind's curve (module docstring), by the names of :class:`Codim2Point`.
CODIM2 = {
    "fold_of_cycles": ("fold_flip", "fold_torus"),
    "period_doubling": ("resonance_1_2", "fold_flip"),
    "torus": ("resonance_1_1", "resonance_1_2", "resonance_1_3", "resonance_1_4", "fold_torus"),
}
#: AUTO-07p's labels of the same points (its manual's table of codimension-two points: R1 ... R4, LPD for fold-flip,
#: LTR for fold-torus; MatCont calls the last two LPPD and LPNS).
AUTO_LABELS = {
    "resonance_1_1": "R1",
    "resonance_1_2": "R2",
    "resonance_1_3": "R3",
    "resonance_1_4": "R4",
    "fold_flip": "LPD",
    "fold_torus": "LTR",
}
#: The codimension-two point where a ``fold_of_cycles`` curve turns back in the field (no multiplier's test
#: function: located by pseudo-arclength through the turn, :func:`_cusp`), with AUTO-07p's label.
CUSP_LABELS = {"cusp": "CP"}
#: Pseudo-arclength steps (:class:`_FoldArc`) that look for the cusp where a fold-of-cycles curve stopped...
CUSP_STEPS = 8
#: ... and halvings of one of them before the search gives up.
CUSP_HALVINGS = 4
#: How the reasons of the chain's edge checks begin (:func:`continue_cycle_end`): a fold curve stopped by one
#: changes kind there (another multiplier leaves the circle first) and is not searched for a cusp.
EDGE_CHECKED = ("another Floquet multiplier", "the critical multiplier")
#: Where a torus curve's pair turns real (at +1 or -1) the curve ends: its test function reaches zero without changing sign.
ENDS_AT = ("resonance_1_1", "resonance_1_2")
#: A codimension-two point is located when its test function is this small (a multiplier's or a cosine's distance
#: from its value there, accurate to about the monodromy's round-off)...
CODIM2_TOL = 1e-9
#: ... or its bracket in the field this narrow, relative to max(1, |p|).
CODIM2_XTOL = 1e-11
#: A search that ends with its test function above this, and no sign change bracketed as narrowly (relative to
#: max(1, |p|)), has not located its point (the curve stopped for another reason): nothing is reported.
CODIM2_ACCEPT = 1e-6
#: Secant (Illinois) iterations, each an augmented solve, that locate one codimension-two point.
CODIM2_ITERATIONS = 40


@dataclass
class CycleEndCurve:
    """The lower edge of one kind followed through the values of one field.

    Attributes
    ----------
    kind : str
        One of :data:`KINDS`.
    field : str
    values : ndarray (k,)
        The values reached, in the order asked (k <= the number asked when the curve stopped).
    moment, period : ndarray (k,)
        Where the rotating orbit ends at each value, and its period there.
    orbits : list of PeriodicOrbit
        The orbit at the edge for each value (its multipliers include the critical one(s)).
    iterations : ndarray (k,)
    complete : bool
        False if the curve could not be followed to the last value; ``message`` says where and why.
    message : str
    points : list of Codim2Point
    parameter : str
        The parameter the end lies at in ``moment``: M for the chain, a user system's own (``I`` of ``pen``).
    """

    kind: str
    field: str
    values: np.ndarray
    moment: np.ndarray
    period: np.ndarray
    orbits: list[PeriodicOrbit]
    iterations: np.ndarray
    complete: bool = True
    message: str = ""
    points: list[Codim2Point] = field(default_factory=list)
    parameter: str = "M"

    def as_dict(self) -> dict:
        """JSON-ready rows, one per value reached, and the codimension-two points located on the way."""
        return {
            "kind": self.kind,
            "field": self.field,
            "parameter": self.parameter,
            "complete": self.complete,
            "message": self.message,
            "rows": [
                {"value": float(v), "moment": float(m), "period": float(t), "iterations": int(i)}
                for v, m, t, i in zip(self.values, self.moment, self.period, self.iterations)
            ],
            "codim2": [point.as_dict() for point in self.points],
        }


@dataclass
class Codim2Point:
    """A codimension-two point located on an end's curve (:data:`CODIM2`).

    Attributes
    ----------
    kind : str
        One of :data:`CODIM2` for the curve's kind (``resonance_1_2``, ``fold_flip``, ...).
    label : str
        AUTO-07p's label of the same point (:data:`AUTO_LABELS`: R1 ... R4, LPD, LTR; :data:`CUSP_LABELS`: CP).
    value : float
        The field's value there.
    moment, period : float
    orbit : PeriodicOrbit
        The orbit there (its multipliers show the point: two at -1, the pair at angle pi / 2, ...).
    test : float
        The test function's value at ``orbit`` (zero at the point).
    uncertainty : float
        Bound on the error of ``value``: the width of the last bracket in the field (between
        solved points on either side of the zero, or a solved point and a value where the
        curve does not exist).
    angle : float or None
        On a torus curve, the critical pair's angle arg(mu) in (0, pi) at ``orbit``; at a ``fold_torus`` on a fold
        curve, the angle of the pair on the circle.
    branches : tuple of two (value, PeriodicOrbit) or None
        At a ``cusp``: the fold curve's points on either side of the turn (the pseudo-arclength
        bracket's ends, each the field's value and the orbit at the fold), both on the same side of
        ``value`` in the field: the two folds of cycles that meet there.
    tangent_moment : float or None
        At a ``cusp``: the M-component of the fold curve's unit tangent there (zero at a cusp, with
        the p-component ``test``: the curve's projection on (p, M) has its cusp there).
    branch_moments : tuple of two float or None
        At a ``cusp``: M (a system's parameter) at the two ``branches``' folds.
    """

    kind: str
    label: str
    value: float
    moment: float
    period: float
    orbit: PeriodicOrbit
    test: float
    uncertainty: float
    angle: float | None = None
    branches: tuple[tuple[float, PeriodicOrbit], tuple[float, PeriodicOrbit]] | None = None
    branch_moments: tuple[float, float] | None = None
    tangent_moment: float | None = None

    @property
    def name(self) -> str:
        """The point's name in words: ``1:2 resonance``, ``fold-flip``."""
        if self.kind.startswith("resonance_"):
            return self.kind.removeprefix("resonance_").replace("_", ":") + " resonance"
        return self.kind.replace("_", "-")

    def as_dict(self) -> dict:
        """JSON-ready summary."""
        return {
            "kind": self.kind,
            "label": self.label,
            "value": self.value,
            "moment": self.moment,
            "period": self.period,
            "test": self.test,
            "uncertainty": self.uncertainty,
            "angle": self.angle,
            "branches": None
            if self.branches is None
            else [{"value": v, "moment": m, "period": o.period} for (v, o), m in zip(self.branches, self.branch_moments)],
            "tangent_moment": self.tangent_moment,
        }


@dataclass
class _Point:
    """(P), its Jacobian R_z, the monodromy and the test function at one z."""

    residual: np.ndarray
    jac: np.ndarray
    mono: np.ndarray
    g: float
    pair: complex | None
    step: np.ndarray | None = None

    @property
    def norm(self) -> float:
        return float(np.max(np.abs(self.residual)))


@dataclass
class _Augmented:
    """(P) and the test function of one kind for a chain, in the unknowns z (module docstring)."""

    kind: str
    orbit: PeriodicOrbit
    tol: float
    rtol: float
    atol: float
    borders: tuple[np.ndarray, np.ndarray] | None = field(default=None)  # b, c of a bordered test function
    pair: complex | None = field(default=None)  # the torus's critical multiplier at the last point
    field_name: str = ""  # the second parameter, followed through its values

    def __post_init__(self) -> None:
        self.size = 2 * n_free(self.orbit.params)
        system = _System(self.orbit.params, get_model(self.orbit.model), self.orbit.moment, self.orbit.particle)
        # The orbit's own phase condition: its section, or its plane where the flow is nearly tangent to the section.
        self.phase = _phase_for(system, _to_y(self.orbit.params, self.orbit.x, self.orbit.v), self.orbit.phase_normal)
        self.keep, self.head = self.phase.keep, self.phase.head

    def pack(self, orbit: PeriodicOrbit) -> np.ndarray:
        return np.concatenate([_to_y(orbit.params, orbit.x, orbit.v)[self.keep], [math.log(orbit.period), orbit.moment]])

    def split(self, z: np.ndarray) -> tuple[np.ndarray, float, float]:
        return self.phase.state(z[: self.head]), math.exp(z[self.head]), float(z[-1])

    def at(self, value: float) -> ChainParams:
        """The chain with the second parameter at ``value``."""
        return chain_with(self.orbit.params, self.field_name, value)

    def orbit_at(self, chain: ChainParams, z: np.ndarray, mono: np.ndarray, closure: float, iterations: int) -> PeriodicOrbit:
        """The orbit of a solution z of the augmented system for ``chain``."""
        y0, period, moment = self.split(z)
        system = _System(chain, get_model(self.orbit.model), moment, self.orbit.particle)
        return _orbit(system, self.orbit.turns, y0, period, mono, closure, iterations, self.orbit.particle_turns, self.phase.normal)

    def evaluate(self, chain: ChainParams, z: np.ndarray):
        """(R, R_z, monodromy, A) at z: (P) and the phase condition, their Jacobian in z, and the shooting Jacobian in (y0, log T)."""
        if not (np.all(np.isfinite(z)) and abs(z[self.head] - math.log(self.orbit.period)) < math.log(1e3)):
            # A Newton step that left the orbit (a period a thousand times off): refused, the step is halved.
            raise OrbitError(f"the period exp({z[self.head]:.6g}) is far from the orbit's {self.orbit.period:.6g}")
        y0, period, moment = self.split(z)
        system = _System(chain, get_model(self.orbit.model), moment, self.orbit.particle)
        residual, jac_y, jac_t, d_moment, mono = _shooting(system, self.orbit.particle_turns, self.rtol, self.atol)(y0, period)
        residual = np.append(residual, self.phase.residual(y0))
        shooting = np.vstack([np.column_stack([jac_y[:, self.keep], period * jac_t]), self.phase.rows(self.head + 1)])
        return residual, np.column_stack([shooting, np.append(d_moment, np.zeros(shooting.shape[0] - d_moment.size))]), mono, shooting

    def bordered(self, mono: np.ndarray, shooting: np.ndarray) -> np.ndarray:
        """The matrix that is singular at a ``fold_of_cycles`` (A) or a ``period_doubling`` (monodromy + I)."""
        return shooting if self.kind == "fold_of_cycles" else mono + np.eye(mono.shape[0])

    def test(self, mono: np.ndarray, shooting: np.ndarray) -> tuple[float, complex | None]:
        """The test function g (module docstring) and, for a torus, the pair it was taken from."""
        if self.kind == "torus":
            pair = _critical(sla.eigvals(mono), self.kind, self.pair)
            return abs(pair) ** 2 - 1.0, pair
        b, c = self.borders
        matrix = self.bordered(mono, shooting)
        bordered = np.block([[matrix, b[:, None]], [c[None, :], np.zeros((1, 1))]])
        rhs = np.zeros(matrix.shape[0] + 1)
        rhs[-1] = 1.0
        return float(np.linalg.solve(bordered, rhs)[-1]), None

    def solve(self, chain: ChainParams, z: np.ndarray) -> tuple[np.ndarray, np.ndarray, float, int] | None:
        """Newton on the augmented system from z for ``chain``: (z, monodromy, closure, iterations), or None.

        A step that makes neither max(|R|, |g|) nor the next Newton step smaller, or leads
        where g is not defined (no complex multiplier left), is halved. A failed solve keeps
        the borders it started with.
        """
        saved = self.borders, self.pair
        solved = self._newton(chain, z)
        if solved is None:
            self.borders, self.pair = saved
        return solved

    def _newton(self, chain: ChainParams, z: np.ndarray) -> tuple[np.ndarray, np.ndarray, float, int] | None:
        if self.kind in BORDERED and self.borders is None:
            try:
                _, _, mono, shooting = self.evaluate(chain, z)
            except OrbitError:
                return None
            self.borders = _singular_vectors(self.bordered(mono, shooting))

        def evaluate(w: np.ndarray, jacobian: bool) -> Evaluation:
            # (P) and g in one residual: its max |.| is max(|R|, |g|).
            point = self._point(chain, w)
            if point is None:
                raise EvaluationFailed("(P) or the test function is not defined there")
            return Evaluation(np.append(point.residual, point.g), point.jac, point)

        def step(w: np.ndarray, evaluation: Evaluation, jacobian) -> np.ndarray:
            point = evaluation.data
            if point.step is None:
                point.step = self._step(chain, w, point.residual, jacobian, point.g)
            return point.step

        def follow(w: np.ndarray, evaluation: Evaluation) -> None:
            # The torus's pair is followed from iterate to iterate (nearest the last one).
            self.pair = evaluation.data.pair

        # A step is taken when it makes max(|R|, |g|) smaller or, by Deuflhard's natural
        # monotonicity test, the Newton step after it shorter (residual and test function
        # have unrelated scales, so neither measures progress alone); otherwise it is halved.
        # An iteration that does not contract ends it: cheaper to halve the parameter step.
        solved = newton(
            evaluate,
            z,
            converged=lambda evaluation, norm: evaluation.data.norm <= self.tol and abs(evaluation.data.g) <= TEST_TOL,
            max_iterations=MAX_ITERATIONS,
            divergence=None,
            contraction=CONTRACTION,
            damping=NEWTON_HALVINGS + 1,
            natural=True,
            newton_step=step,
            iterate=follow,
        )
        if not solved.converged:
            return None
        current = solved.evaluation.data
        if self.kind in BORDERED:
            # Borders for the next value: the singular vectors at this point.
            self.borders = _singular_vectors(self.bordered(current.mono, current.jac[:, :-1]))
        return solved.w, current.mono, current.norm, solved.iterations

    def leaves_circle(self, chain: ChainParams, z: np.ndarray, orbit: PeriodicOrbit) -> bool:
        """Whether the critical multiplier of the end at z lies outside the circle a step down the orbit branch
        (the orbit loses stability as M falls there, not regains it)."""
        target = _critical(orbit.nontrivial_multipliers, self.kind, self.pair)
        _, jac, _, _ = self.evaluate(chain, z)
        tangent = np.linalg.svd(jac)[2][-1]
        # Along the branch's tangent towards smaller |M| (to first order on the branch).
        tangent *= -math.copysign(1.0, tangent[-1] * z[-1])
        mono = self.evaluate(chain, z + CROSSING_STEP * tangent)[2]
        multipliers = sla.eigvals(mono)
        return bool(abs(multipliers[np.argmin(np.abs(multipliers - target))]) > 1.0)

    def _point(self, chain: ChainParams, z: np.ndarray) -> _Point | None:
        """(P) and g at z, or None where they are not defined (the integration fails, no multiplier to follow)."""
        try:
            residual, jac, mono, shooting = self.evaluate(chain, z)
            g, pair = self.test(mono, shooting)
        except (OrbitError, np.linalg.LinAlgError):
            return None
        return _Point(residual, jac, mono, g, pair)

    def _step(self, chain: ChainParams, z: np.ndarray, residual: np.ndarray, jac: np.ndarray, g: float) -> np.ndarray:
        """The Newton step of (P) and g = 0: the minimum-norm correction of (P) plus the multiple of its null vector that zeroes the linearised g."""
        u, s, vt = np.linalg.svd(jac)
        correction = vt[: s.size].T @ ((u.T @ -residual) / s)
        tangent = vt[-1]

        def slope(direction: np.ndarray) -> float:
            trial = z + DIFFERENCE_STEP * direction
            _, _, mono, shooting = self.evaluate(chain, trial)
            return (self.test(mono, shooting)[0] - g) / DIFFERENCE_STEP

        size = float(np.linalg.norm(correction))
        along_correction = slope(correction / size) * size if size > 1e-14 else 0.0
        along_tangent = slope(tangent)
        if along_tangent == 0.0:
            raise np.linalg.LinAlgError("the test function does not change along the orbit branch: the end is not a regular point")
        return correction - (g + along_correction) / along_tangent * tangent


@dataclass
class _SystemAugmented(_Augmented):
    """(O) of a user system (:mod:`~.shooting`) and the test function of one kind, in z = (y0, log T, p), p the
    system's parameter the end was found in (``parameter``, the chain's M); the phase condition is the orbit's own
    plane (through its y0, normal to the flow there), kept for the whole curve. The test functions, Newton's
    method and the codimension-two watch are :class:`_Augmented`'s; the context of an evaluation is the system
    with the second parameter set (:meth:`at`) instead of a chain."""

    parameter: str = ""

    def __post_init__(self) -> None:
        self.size = 2 * self.orbit.system.size
        self.reference = np.array(self.orbit.y0, dtype=float)
        self.normal = self.orbit.system.vector_field(self.reference)
        self.head = self.size

    def pack(self, orbit: shooting.Orbit) -> np.ndarray:
        return np.concatenate([orbit.y0, [math.log(orbit.period), orbit.parameter(self.parameter)]])

    def split(self, z: np.ndarray) -> tuple[np.ndarray, float, float]:
        return z[: self.size], math.exp(z[self.head]), float(z[-1])

    def at(self, value: float):
        """The system with the second parameter at ``value``."""
        return self.orbit.system.with_parameters(**{self.field_name: value})

    def orbit_at(self, system, z: np.ndarray, mono: np.ndarray, closure: float, iterations: int) -> shooting.Orbit:
        y0, period, value = self.split(z)
        return shooting.Orbit(
            system=system.with_parameters(**{self.parameter: value}),
            y0=y0.copy(),
            period=period,
            turns=self.orbit.turns,
            multipliers=np.linalg.eigvals(mono),
            closure=closure,
            iterations=iterations,
            monodromy=mono,
        )

    def evaluate(self, system, z: np.ndarray):
        """As :meth:`_Augmented.evaluate`, on (O) of ``system`` (:class:`~.shooting._Shooting`, p its second unknown)."""
        if not (np.all(np.isfinite(z)) and abs(z[self.head] - math.log(self.orbit.period)) < math.log(1e3)):
            raise OrbitError(f"the period exp({z[self.head]:.6g}) is far from the orbit's {self.orbit.period:.6g}")
        problem = shooting._Shooting(
            system, self.orbit.turns, self.reference, self.orbit.period, (shooting.PERIOD, self.parameter), self.tol, self.rtol, self.atol
        )
        problem.normal = self.normal  # one plane for the whole curve, not the flow's direction at each value
        try:
            evaluation = problem.evaluate(z, True)
        except EvaluationFailed as err:
            raise OrbitError(str(err)) from None
        jac = np.asarray(evaluation.jacobian)
        return evaluation.residual, jac, evaluation.data, jac[:, :-1]


def _singular_vectors(matrix: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The left and right singular vectors of the smallest singular value: the borders of a bordered test function."""
    u, _, vt = np.linalg.svd(matrix)
    return u[:, -1].copy(), vt[-1].copy()


class _EndCurve:
    """The end's curve in (z, p) as a problem of the kit's driver (:func:`~.kit.continuation`), in the
    natural parameterization: each step sets p and solves the augmented system there.

    A step of the driver is a change of p (towards the value asked for, and ending on it within
    round-off); its correction is the augmented system's Newton at that p (:class:`_Augmented`)
    from the point before, extrapolated along the curve from the two before it (at most
    :data:`MAX_EXTRAPOLATION` times their spacing), checked to be the lower edge it claims to be.
    A failed step is halved, at most :data:`MAX_HALVINGS` times towards one value; an accepted one
    doubles the next (the residual's sensitivity to p can be large: 135 per unit of E2 for the
    paper's chain's torus end). The value reached is the driver's ``"value"`` event. Natural
    steps, not pseudo-arclength ones: the augmented system's Jacobian in p would cost a monodromy
    integration per unknown, and every point of the curve here is one the caller asked for or a
    step towards it.
    """

    tol = 0.0  # the driver's start is the located end itself (:meth:`evaluate`)

    def __init__(self, solve_at: Callable, first: tuple, size: int):
        self.solve_at = solve_at  # (value, guess) -> ((value, z, orbit, iterations), "") or (None, reason)
        self.found = [first]  # every point solved, in order (the steps towards a value included)
        self.size = size
        self.target = math.nan
        self.sign = 1.0
        self.failures = 0
        self.reason = ""

    def follow(self, target: float) -> bool:
        """Follow the curve from the last point found to p = ``target``; whether it got there."""
        last = self.found[-1]
        self.target, self.failures = target, 0
        distance = target - last[0]
        self.sign = 1.0 if distance >= 0 else -1.0
        step = abs(distance)
        if step == 0.0:  # the same value again: solved again there
            entry, self.reason = self.solve_at(target, last[1])
            if entry is not None:
                self.found.append(entry)
            return entry is not None
        traced = continuation(
            self,
            self._packed(last),
            step=step,
            min_step=step / 2 ** (MAX_HALVINGS + 2),
            max_step=step,
            max_points=2**31,
            stop_at=("value",),
            first=last,
        )
        return traced.end == BranchEnd.VALUE

    @staticmethod
    def _packed(entry: tuple) -> np.ndarray:
        return np.append(entry[1], entry[0])

    def evaluate(self, w: np.ndarray, jacobian: bool) -> Evaluation:
        # Asked only at the driver's start, the located end: solved already.
        if not np.array_equal(w, self._packed(self.found[-1])):
            raise EvaluationFailed("the end's curve is corrected by the augmented system at each value (correct)")
        return Evaluation(np.zeros(1))

    def correct(self, w: np.ndarray, t: np.ndarray, h: float, jacobian) -> Correction:
        start, step, target = float(w[-1]), self.sign * h, self.target
        # A step that ends within round-off of the target ends on it (0.85 + 0.05 is not 0.9).
        close = abs(target - start - step) <= 1e-9 * abs(step)
        value = target if close or abs(step) >= abs(target - start) else start + step
        guess = self.found[-1][1]
        if len(self.found) >= 2 and self.found[-2][0] != self.found[-1][0]:
            # Secant predictor along the curve: the end moves smoothly with the parameter.
            # It extrapolates at most MAX_EXTRAPOLATION times the last spacing: beyond, the
            # last point is the better guess.
            ratio = (value - self.found[-1][0]) / (self.found[-1][0] - self.found[-2][0])
            if abs(ratio) <= MAX_EXTRAPOLATION:
                guess = guess + ratio * (guess - self.found[-2][1])
        entry, self.reason = self.solve_at(value, guess)
        if entry is None:
            return Correction(Corrector.DIVERGED, w, None, math.inf, 0)
        return Correction(Corrector.CONVERGED, np.append(entry[1], value), Evaluation(np.zeros(1), None, entry), 0.0, entry[3])

    def point(self, w: np.ndarray, evaluation: Evaluation, iterations: int) -> tuple:
        self.found.append(evaluation.data)
        return evaluation.data

    def tangent(self, jacobian, previous: np.ndarray | None) -> np.ndarray:
        direction = np.zeros(self.size)
        direction[-1] = self.sign  # the steps are changes of p (correct)
        return direction

    def failed(self, h: float) -> float:
        self.failures += 1
        return h / 2 if self.failures <= MAX_HALVINGS else 0.0

    def next_step(self, h: float, correction: Correction, candidate: tuple) -> float:
        return 2.0 * h

    def accept(self, previous: tuple, candidate: tuple) -> bool:
        return True

    def events(self, previous: tuple, candidate: tuple, t_before: np.ndarray, t_after: np.ndarray) -> list[str]:
        return ["value"] if candidate[0] == self.target else []

    def locate(self, kind: str, w: np.ndarray, t: np.ndarray, h: float, previous: tuple, candidate: tuple, index: int) -> Event:
        return Event(kind, candidate, self.target, index)

    def tests(self, point: tuple) -> dict[str, float]:
        return {}

    def confirm(self, kind: str, point: tuple) -> bool:
        return True

    def stop(self, point: tuple) -> None:
        return None


def continue_cycle_end(
    orbit: PeriodicOrbit | shooting.Orbit,
    kind: str,
    field_name: str,
    values: Sequence[float],
    *,
    parameter: str | None = None,
    tol: float = CLOSURE_TOL,
    rtol: float = RTOL,
    atol: float = ATOL,
    progress: Callable[[float, float], None] | None = None,
) -> CycleEndCurve:
    """Follow the end of a rotating orbit of one ``kind`` through ``values`` of ``field_name`` (module docstring).

    A user system's orbit (:class:`~.shooting.Orbit`) is followed the same way on (O) with the phase plane
    of ``orbit`` (:class:`_SystemAugmented`), its end in ``parameter`` (the chain's M); a system's
    bifurcation need not be an edge of rotation, so its points are not checked to be one (every other
    multiplier inside the circle). The codimension-two points of :data:`CODIM2` and the cusp of a fold
    curve are located on both.

    Parameters
    ----------
    orbit : PeriodicOrbit or shooting.Orbit
        An orbit near the end at the first value (for the chain of ``orbit.params`` with
        ``field_name`` set to ``values[0]``): one of :func:`~.periodic.continue_orbit`'s
        orbits next to where it turns or loses stability; or a system's orbit
        (:func:`~.shooting.continue_orbits`'), its system with ``field_name`` at ``values[0]``.
    kind : str
        One of :data:`KINDS`.
    field_name : str
        A number of the chain (:data:`~.fold_curve.FIELDS`), or a parameter of the system.
    parameter : str, optional
        For a system's orbit (required there): the system's parameter in which the end is located at
        each value of ``field_name``. Not for the chain (its end lies in M).
    values : sequence of float
        In the order to follow them; the first is solved from ``orbit`` (which locates the end
        there to Newton's tolerance), each next one from the point before.
    tol, rtol, atol : float
        Newton's closure tolerance and the DOP853 tolerances (:func:`~.periodic.find_periodic_orbit`).
    progress : callable(done, total), optional

    Returns
    -------
    CycleEndCurve
        ``complete`` False, with the message, where the curve stopped before the last value.

    Raises
    ------
    ValueError
        For an unknown kind or field, values that are not finite, a value that makes no
        admissible chain, or a first value Newton cannot reach from ``orbit``.
    """
    if kind not in KINDS:
        raise ValueError(f"kind must be one of {', '.join(KINDS)}, got {kind!r}")
    system_orbit = isinstance(orbit, shooting.Orbit)
    if system_orbit:
        values = _system_values(orbit, field_name, parameter, values)
        augmented = _SystemAugmented(kind, orbit, tol, rtol, atol, field_name=field_name, parameter=parameter)
    else:
        if parameter is not None:
            raise ValueError(f"parameter is for a system's orbit; a chain's end lies in M, got parameter={parameter!r}")
        values = field_values(field_name, values)
        augmented = _Augmented(kind, orbit, tol, rtol, atol, field_name=field_name)

    def solved(value: float, z: np.ndarray):
        """The augmented system's solution at ``value`` from the guess z, not checked to be the lower edge:
        (entry, reason) or (None, reason); an entry is (value, z, orbit, iterations, the torus's pair)."""
        chain = augmented.at(value)
        solution = augmented.solve(chain, z)
        if solution is None:
            return None, "Newton did not converge"
        z_new, mono, closure, iterations = solution
        if np.max(np.abs(z_new[: augmented.head] - z[: augmented.head])) > JUMP:
            return None, "Newton jumped to another orbit"
        found = augmented.orbit_at(chain, z_new, mono, closure, iterations)
        if kind == "fold_of_cycles" and np.sort(np.abs(found.multipliers - 1.0))[1] > FOLD_MULTIPLIER_TOL:
            return None, (
                f"no second Floquet multiplier at +1 there (the nearest is {np.sort(np.abs(found.multipliers - 1.0))[1]:.3g} "
                "from it): not a fold of cycles"
            )
        return (value, z_new, found, iterations, augmented.pair), ""

    def point(value: float, z: np.ndarray):
        """The end at ``value`` from the guess z, checked to be the lower edge; (entry, reason) or (None, reason)."""
        entry, reason = solved(value, z)
        if entry is None or system_orbit:
            return entry, reason
        chain, z_new, found = augmented.at(value), entry[1], entry[2]
        others = _other_multipliers(found, kind)
        if others.size and float(np.max(np.abs(others))) >= 1.0 - EDGE_MARGIN:
            return None, (
                f"another Floquet multiplier is outside the unit circle there (|mu| = {float(np.max(np.abs(others))):.6g}): "
                "the rotating state is lost before this end, the edge changes kind"
            )
        if kind != "fold_of_cycles" and not augmented.leaves_circle(chain, z_new, found):
            return None, "the critical multiplier enters the unit circle as M falls there: the orbit regains stability, no lower edge"
        return entry, ""

    def located(value: float, guess: np.ndarray, pair: complex | None):
        """A trial of the codimension-two search: the augmented system solved at ``value``, the edge not checked
        (the search passes through the point, where the edge changes kind), its borders taken at the guess."""
        augmented.borders, augmented.pair = None, pair
        return solved(value, guess)[0]

    first, reason = point(float(values[0]), augmented.pack(orbit))
    if first is None:
        raise ValueError(
            f"the {kind} end could not be located at {field_name} = {values[0]:g} from the orbit at "
            f"{parameter or 'M'} = {augmented.pack(orbit)[-1]:.6g}: {reason}"
        )
    curve = _EndCurve(point, first, augmented.pack(orbit).size + 1)
    complete, message, target = True, "", float(values[-1])
    for index, target in enumerate(values[1:], start=1):
        if progress is not None:
            progress(index, values.size)
        if not curve.follow(float(target)):
            complete = False
            message = (
                f"the {kind} end could not be followed beyond {field_name} = {curve.found[-1][0]:.6g} towards {float(target):.6g} "
                f"({curve.reason})"
            )
            break
    found = curve.found
    points, at_stop = _codim2_points(kind, found, located, None if complete else float(target))
    if not complete and at_stop is None and kind == "fold_of_cycles" and not curve.reason.startswith(EDGE_CHECKED):
        # Natural steps found no fold beyond (not an edge check): the curve may turn back in the field there.
        at_stop = _cusp(augmented, found, kind)
        if at_stop is not None:
            points.append(at_stop)
            message += (
                f": the curve turns back in {field_name} at a cusp (CP) at {field_name} = {at_stop.value:.10g} "
                f"+- {at_stop.uncertainty:.2g} ({parameter or 'M'} = {at_stop.moment:.10g}): two folds of cycles meet there "
                "and vanish beyond"
            )
    if not complete and (at_stop is None or at_stop.kind != "cusp"):
        if at_stop is not None:
            message += (
                f": it meets a {at_stop.name} ({at_stop.label}) at {field_name} = {at_stop.value:.10g} "
                f"+- {at_stop.uncertainty:.2g} ({parameter or 'M'} = {at_stop.moment:.10g}), where the edge changes kind"
            )
        else:
            message += f": the curve turns back in {field_name}, ends at a codimension-two point not watched, or the edge changes kind"
    if progress is not None:
        progress(values.size, values.size)
    asked = [entry for entry in found if np.any(entry[0] == values)]
    return CycleEndCurve(
        kind=kind,
        field=field_name,
        values=np.array([e[0] for e in asked]),
        moment=np.array([e[1][-1] for e in asked]),
        period=np.array([e[2].period for e in asked]),
        orbits=[e[2] for e in asked],
        iterations=np.array([e[3] for e in asked]),
        complete=complete,
        message=message,
        points=points,
        parameter=parameter or "M",
    )


def _system_values(orbit: shooting.Orbit, field_name: str, parameter: str | None, values: Sequence[float]) -> np.ndarray:
    """The values of a system's ``field_name`` to follow an end in ``parameter`` through, checked."""
    known = orbit.system.parameters
    if parameter not in known or field_name not in known or parameter == field_name:
        raise ValueError(
            f"parameter and field must be two different parameters of {orbit.system.name} ({', '.join(known) or 'none'}), "
            f"got parameter={parameter!r}, field={field_name!r}"
        )
    if orbit.unfold is not None:
        raise ValueError(f"the orbit is a conservative one (unfolded in {orbit.unfold!r}): its ends are not followed in a second parameter")
    array = np.atleast_1d(np.asarray(values, dtype=float))
    if array.ndim != 1 or array.size == 0 or not np.all(np.isfinite(array)):
        raise ValueError(f"values of {field_name} must be one or more finite numbers, got {values!r}")
    return array


def _codim2_tests(kind: str, orbit, pair: complex | None) -> dict[str, float]:
    """The test functions of :data:`CODIM2` for a point of a ``kind`` curve, each zero at its point.

    Each is a continuous function of the multipliers, well conditioned where two of them meet (each of a
    double multiplier is only accurate to the square root of the round-off; a symmetric function of the
    two, a sum or a product, to the round-off):

    * ``resonance_1_1`` ... ``resonance_1_4`` (torus): cos(theta) - 1, + 1, + 1/2 and cos(theta), theta the
      pair's angle;
    * ``resonance_1_2`` (period doubling): :func:`_cluster_test` of x = mu + 1 over the nontrivial multipliers
      (a second one reaches -1 beside the period doubling's);
    * ``fold_flip``: on a period-doubling curve :func:`_cluster_test` of x = mu - 1 over all multipliers (a real
      one reaches +1 beside the trivial one); on a fold curve Re prod(mu + 1) over the nontrivial ones;
    * ``fold_torus`` (Kuznetsov's fold-Neimark-Sacker, Elements of Applied Bifurcation Theory, 3rd ed., Sect. 9.6
      and 10.3; AUTO-07p's LTR): on a torus curve :func:`_cluster_test` of x = mu - 1 over the multipliers but
      the torus's pair (a second real one reaches +1, as ``fold_flip`` on a period-doubling curve); on a fold
      curve, over the multipliers but the trivial one and the fold's, sign(P) min |mu_i mu_j - 1| with
      P = prod_{i<j} (mu_i mu_j - 1) (the determinant of MatCont's bialternate-product test): zero where a
      complex pair lies on the circle, or where a real pair's product is 1, a neutral saddle that
      :func:`_genuine` refuses. P is a symmetric function of the multipliers, continuous where a pair turns
      real; the minimum gives the test the scale of the critical factor, |mu|^2 - 1 near the point, and keeps
      it continuous where two factors swap places.
    """
    if kind == "torus":
        cosine = pair.real / abs(pair)
        return {
            "resonance_1_1": cosine - 1.0,
            "resonance_1_2": cosine + 1.0,
            "resonance_1_3": cosine + 0.5,
            "resonance_1_4": cosine,
            "fold_torus": _cluster_test(_beside_pair(orbit.multipliers, pair) - 1.0),
        }
    if kind == "fold_of_cycles":
        factors = _pair_products(orbit)[0]
        fold_torus = _sign(factors) * float(np.min(np.abs(factors))) if factors.size else 1.0  # no pair to reach the circle
        return {"fold_flip": float(np.real(np.prod(orbit.nontrivial_multipliers + 1.0))), "fold_torus": fold_torus}
    return {"resonance_1_2": _cluster_test(orbit.nontrivial_multipliers + 1.0), "fold_flip": _cluster_test(orbit.multipliers - 1.0)}


def _sign(factors: np.ndarray) -> float:
    """The sign of the real product of ``factors`` (closed under conjugation), from their arguments: conjugate
    factors cancel, a real negative one adds pi (no underflow of a long product)."""
    return 1.0 if math.cos(float(np.sum(np.angle(factors)))) > 0 else -1.0


def _cluster_test(x: np.ndarray) -> float:
    """e_{n-1}(x) / prod_O |x_k|: e_{n-1} the sum of the products of all but one of the x (a coefficient of the
    characteristic polynomial, well conditioned), O all but the two x nearest zero, a and b.

    It equals u (a + b + a b sum_O 1 / x_k), u = prod_O x / |prod_O x| (the sign of prod_O x where O is closed
    under conjugation; a unit number that makes the whole real where one of a conjugate pair is b): where a is a
    multiplier that stays put (the trivial one, a period doubling's -1), about b, the other's distance from its
    value, which it changes sign with; and it does wherever b lies, also far away (a sum over the two nearest
    alone keeps its sign when b leaves the cluster between two points). Continuous where b and an x_k swap
    places (|b| = |x_k| there)."""
    order = np.argsort(np.abs(x))
    a, b, others = x[order[0]], x[order[1]], x[order[2:]]
    unit = np.exp(1j * np.sum(np.angle(others)))
    return float(np.real(unit * (a + b + a * b * np.sum(1.0 / others))))


def _beside_pair(multipliers: np.ndarray, pair: complex) -> np.ndarray:
    """The multipliers but the torus's ``pair`` and its conjugate, nearest +1 first."""
    drop = {int(np.argmin(np.abs(multipliers - pair))), int(np.argmin(np.abs(multipliers - np.conj(pair))))}
    rest = np.delete(multipliers, sorted(drop))
    return rest[np.argsort(np.abs(rest - 1.0))]


def _pair_products(orbit) -> tuple[np.ndarray, np.ndarray]:
    """mu_i mu_j - 1 over the pairs i < j of a fold's multipliers but the trivial one and the fold's (the two
    nearest +1), and each pair's mu_i."""
    rest = orbit.nontrivial_multipliers
    rest = np.delete(rest, int(np.argmin(np.abs(rest - 1.0))))
    i, j = np.triu_indices(rest.size, 1)
    return rest[i] * rest[j] - 1.0, rest[i]


def _angle(kind: str, name: str, orbit, pair: complex | None) -> float | None:
    """The angle in [0, pi] of the pair on the circle at a point of ``kind``'s curve: the torus's pair, or at a
    ``fold_torus`` on a fold curve the pair whose |mu|^2 - 1 is the smallest factor; None for other points."""
    if kind == "torus":
        return float(np.angle(pair))
    if name != "fold_torus":
        return None
    factors, first = _pair_products(orbit)
    return float(abs(np.angle(first[int(np.argmin(np.abs(factors)))])))


def _genuine(kind: str, name: str, orbit, pair: complex | None) -> bool:
    """Whether a located zero of ``name``'s test function is the point it names: a ``fold_torus`` on a fold curve
    where the factor mu_i mu_j - 1 that vanishes is a complex pair's |mu|^2 - 1 (not a neutral saddle, a real pair
    with mu_i mu_j = 1: no bifurcation); on a torus curve where the two multipliers nearest +1 beside the pair lie
    within :data:`FOLD_MULTIPLIER_TOL` of it (a second one at +1, not a complex pair passing Re mu = 1). Every other
    point is what its test function's zero says."""
    if name != "fold_torus":
        return True
    if kind == "torus":
        return bool(np.all(np.abs(_beside_pair(orbit.multipliers, pair)[:2] - 1.0) <= FOLD_MULTIPLIER_TOL))
    factors, first = _pair_products(orbit)
    mu = first[int(np.argmin(np.abs(factors)))]
    return bool(abs(mu.imag) > COMPLEX_RTOL * abs(mu))


def _codim2_points(kind: str, found: list[tuple], solve: Callable, target: float | None) -> tuple[list[Codim2Point], Codim2Point | None]:
    """The codimension-two points on a curve's points ``found`` (entries of :func:`continue_cycle_end`), and the
    one where the curve stopped short of ``target`` (None where it did not stop, or stopped elsewhere).

    Between two points where a test function changes sign, its zero is located by the Illinois secant in the
    field (:func:`_locate_codim2`). Where the curve stopped, a test function whose secant through the last two
    points reaches zero within :data:`MAX_EXTRAPOLATION` of their spacing towards ``target`` is searched
    for beyond the last point: the curve's own checks of the edge (or its existence: a torus pair turning
    real) stop it at such a point.
    """
    entries = [e for i, e in enumerate(found) if i == 0 or e[0] != found[i - 1][0]]
    tests = [_codim2_tests(kind, e[2], e[4]) for e in entries]
    points: list[Codim2Point] = []
    for i in range(1, len(entries)):
        for name in CODIM2[kind]:
            if tests[i - 1][name] * tests[i][name] < 0:
                before = entries[max(0, i - 2) : i]
                located = _locate_codim2(kind, name, solve, before, entries[i], entries[i][0])
                if located is not None:
                    points.append(located)
    at_stop = None
    if target is not None and len(entries) >= 2:
        (p0, p1), (t0, t1) = (entries[-2][0], entries[-1][0]), (tests[-2], tests[-1])
        reach = []
        for name in CODIM2[kind]:
            if t1[name] == t0[name]:
                continue
            zero = p1 - t1[name] * (p1 - p0) / (t1[name] - t0[name])
            ahead = (zero - p1) * (target - p1)
            if 0 <= ahead and abs(zero - p1) <= min(MAX_EXTRAPOLATION * abs(p1 - p0), abs(target - p1)):
                reach.append((abs(zero - p1), name))
        if reach:
            at_stop = _locate_codim2(kind, min(reach)[1], solve, entries[-2:], None, target)
            if at_stop is not None:
                points.append(at_stop)
    return points, at_stop


def _locate_codim2(kind: str, name: str, solve: Callable, before: list[tuple], after: tuple | None, limit: float) -> Codim2Point | None:
    """The zero of test function ``name`` beyond the curve's points ``before`` (the last the bracket's near end),
    towards the point ``after`` on the other side of it or, without one, towards ``limit`` (the search for where
    the curve stopped: a trial that fails there moves the bracket's far end to it).

    Illinois secant steps in the field, each trial the augmented system solved from the guess interpolated
    (extrapolated without a far point) along the curve; a step outside the bracket is a bisection. None where
    the search ends with the test function above :data:`CODIM2_ACCEPT` and no bracket that narrow.
    """

    def test(entry: tuple) -> float:
        return _codim2_tests(kind, entry[2], entry[4])[name]

    low, f_low = before[-1], test(before[-1])
    other = before[-2] if len(before) > 1 else None
    f_other = test(other) if other is not None else math.nan
    high, f_high = (after, test(after)) if after is not None else (None, math.nan)
    far = limit if high is None else high[0]
    best, f_best, side = low, f_low, 0
    if high is not None and abs(f_high) < abs(f_best):
        best, f_best = high, f_high
    for _ in range(CODIM2_ITERATIONS):
        if abs(f_best) <= CODIM2_TOL or abs(far - low[0]) <= CODIM2_XTOL * max(1.0, abs(low[0])):
            break
        if high is not None:
            reference, f_reference = high, f_high
        else:
            reference, f_reference = other, f_other
        value = math.nan
        if reference is not None and f_reference != f_low:
            value = low[0] - f_low * (low[0] - reference[0]) / (f_low - f_reference)
        if not (min(low[0], far) < value < max(low[0], far)):
            value = 0.5 * (low[0] + far)
        guess = low[1] if reference is None else low[1] + (value - low[0]) / (reference[0] - low[0]) * (reference[1] - low[1])
        entry = solve(value, guess, low[4])
        if entry is None:
            if high is not None:
                break  # no solution between two solved points: the bracket is kept as it is
            far = value  # the curve does not reach this value: the zero lies nearer
            continue
        f = test(entry)
        if abs(f) < abs(f_best):
            best, f_best = entry, f
        if f * f_low > 0:
            other, f_other, low, f_low = low, f_low, entry, f
            if side == 1 and high is not None:
                f_high *= 0.5
            side = 1
        else:
            high, f_high, far = entry, f, entry[0]
            if side == -1:
                f_low *= 0.5
            side = -1
    bracket = abs(far - low[0]) if best is low else abs(far - best[0]) if high is None else abs(high[0] - low[0])
    if abs(f_best) > CODIM2_ACCEPT and (high is None or bracket > CODIM2_ACCEPT * max(1.0, abs(low[0]))):
        return None  # neither near the zero nor bracketing it closely: not located
    if not _genuine(kind, name, best[2], best[4]):
        return None  # the test function's zero is not the point it names (a neutral saddle)
    slope = (f_low - f_other) / (low[0] - other[0]) if other is not None and other[0] != low[0] else math.nan
    estimate = 10.0 * abs(f_best / slope) if math.isfinite(slope) and slope != 0 else math.inf
    orbit = best[2]
    angle = _angle(kind, name, orbit, best[4])
    # z ends with the first parameter's value (the chain's M, a system's own).
    return Codim2Point(
        name,
        AUTO_LABELS[name],
        float(best[0]),
        float(best[1][-1]),
        orbit.period,
        orbit,
        float(f_best),
        float(min(bracket, estimate)),
        angle,
    )


class _FoldArc:
    """The fold-of-cycles curve in (z, p) by pseudo-arclength: the augmented system (P), g = 0 with the field p
    free and the arclength condition t . (w - w_pred) = 0, w = (z, p) (module docstring, "cusp").

    The Jacobian [R_z, R_p] of (P) (R_p a one-sided difference in p) has a two-dimensional null space; a Newton
    step is its minimum-norm correction plus the combination of two null vectors that zeroes the linearised
    g and the arclength condition (g's gradient along three directions, one-sided differences). The curve's
    tangent is the combination of the same null vectors along which g does not change.
    """

    def __init__(self, augmented: _Augmented):
        self.augmented = augmented  # a chain's or a system's (its ``at`` sets the field)

    def _at(self, w: np.ndarray):
        return self.augmented.evaluate(self.augmented.at(float(w[-1])), w[:-1])

    def _g(self, w: np.ndarray) -> float:
        _, _, mono, shooting = self._at(w)
        return self.augmented.test(mono, shooting)[0]

    def _linear(self, w: np.ndarray):
        """(R, g, the minimum-norm correction of (P) in w, its two null vectors, g's slopes along the three, the
        monodromy, the p-row of [R_z, R_p]'s pseudo-inverse)."""
        residual, jac, mono, shooting = self._at(w)
        g = self.augmented.test(mono, shooting)[0]
        step = DIFFERENCE_STEP * max(1.0, abs(w[-1]))
        shifted = w.copy()
        shifted[-1] += step
        by_field = (self._at(shifted)[0] - residual) / step
        u, s, vt = np.linalg.svd(np.column_stack([jac, by_field]))
        correction = vt[: s.size].T @ ((u.T @ -residual) / s)
        null = vt[s.size :]
        pinv_row = (vt[: s.size, -1] / s) @ u[:, : s.size].T  # p's change per unit residual of (P)

        def slope(direction: np.ndarray) -> float:
            size = float(np.linalg.norm(direction))
            if size < 1e-14:
                return 0.0
            return (self._g(w + DIFFERENCE_STEP * direction / size) - g) / DIFFERENCE_STEP * size

        slopes = np.array([slope(correction), slope(null[0]), slope(null[1])])
        return residual, g, correction, null, slopes, mono, pinv_row

    def accuracy(self, w: np.ndarray) -> float:
        """Bound on the error in p of a point w of the curve from Newton's tolerances: (P) solved to ``tol``
        (each row's effect on p through the minimum-norm correction) and g to :data:`TEST_TOL` (along the null
        direction across the curve, which is where p changes at a turn)."""
        *_, null, slopes, _, pinv_row = self._linear(w)
        across = slopes[1] * null[0] + slopes[2] * null[1]
        size = float(np.hypot(slopes[1], slopes[2]))
        return float(np.sum(np.abs(pinv_row)) * self.augmented.tol + abs(across[-1]) / size**2 * TEST_TOL)

    def tangent(self, w: np.ndarray, previous: np.ndarray | None) -> np.ndarray:
        """The curve's unit tangent at a point w of it, oriented along ``previous``."""
        _, _, _, null, slopes, _, _ = self._linear(w)
        t = -slopes[2] * null[0] + slopes[1] * null[1]
        t /= np.linalg.norm(t)
        return -t if previous is not None and t @ previous < 0 else t

    def correct(self, predicted: np.ndarray, t: np.ndarray) -> tuple[np.ndarray, np.ndarray, float, int] | None:
        """Newton from ``predicted`` on the curve's system with the arclength condition along ``t``:
        (w, monodromy, closure, iterations), or None where it does not converge (its borders kept)."""
        saved = self.augmented.borders
        w, last = predicted.copy(), math.inf
        for iteration in range(1, MAX_ITERATIONS + 1):
            try:
                residual, g, correction, null, slopes, mono, _ = self._linear(w)
            except (OrbitError, ValueError, np.linalg.LinAlgError):
                break
            norm = max(float(np.max(np.abs(residual))), abs(g))
            if norm <= self.augmented.tol and abs(g) <= TEST_TOL:
                self.augmented.borders = _singular_vectors(self.augmented.bordered(mono, self._at(w)[3]))
                return w, mono, float(np.max(np.abs(residual))), iteration
            if norm > CONTRACTION * last and iteration > 2:
                break
            last = norm
            system = np.array([[slopes[1], slopes[2]], [t @ null[0], t @ null[1]]])
            rhs = -np.array([g + slopes[0], t @ (w + correction - predicted)])
            w = w + correction + null.T @ np.linalg.solve(system, rhs)
        self.augmented.borders = saved
        return None


def _cusp(augmented: _Augmented, found: list[tuple], kind: str) -> Codim2Point | None:
    """The cusp where a fold-of-cycles curve that stopped after the points ``found`` turns back in the field, or None.

    From the last two points (distinct values) the curve is followed by pseudo-arclength (:class:`_FoldArc`) at
    most :data:`CUSP_STEPS` steps, each as long as their spacing in (z, p) (halved where Newton fails, at most
    :data:`CUSP_HALVINGS` times), until the tangent's p-component t_p changes sign; its zero is then located by
    the Illinois secant in the arclength from the point before the turn (:data:`CODIM2_TOL` on t_p, of the unit
    tangent). Near the cusp p = p* - k s^2, so the value is the best point's p plus the remainder t_p^2 / (4 k);
    the uncertainty is that remainder (t_p taken no smaller than :data:`DIFFERENCE_STEP`, the accuracy of the
    tangent's differences) plus the point's error in p from Newton's tolerances (:meth:`_FoldArc.accuracy`).
    None where no turn is met (the natural steps failed for another reason), or where the orbit there has no second
    multiplier at +1 (:data:`FOLD_MULTIPLIER_TOL`: not a fold of cycles).
    """
    entries = [e for i, e in enumerate(found) if i == 0 or e[0] != found[i - 1][0]]
    if kind != "fold_of_cycles" or len(entries) < 2:
        return None
    arc = _FoldArc(augmented)
    w0, w1 = (np.append(e[1], e[0]) for e in entries[-2:])
    h = float(np.linalg.norm(w1 - w0))
    try:
        _, _, mono, matrix = arc._at(w1)
        augmented.borders = _singular_vectors(augmented.bordered(mono, matrix))
        t = arc.tangent(w1, w1 - w0)
    except (OrbitError, ValueError, np.linalg.LinAlgError):
        return None
    before = (w1, t, entries[-1][2])
    after = None
    for _ in range(CUSP_STEPS):
        corrected = None
        for _halving in range(CUSP_HALVINGS):
            corrected = arc.correct(before[0] + h * before[1], before[1])
            if corrected is not None and float(np.max(np.abs(corrected[0][: augmented.head] - before[0][: augmented.head]))) <= JUMP:
                break
            corrected, h = None, h / 2
        if corrected is None:
            return None
        w = corrected[0]
        tw = arc.tangent(w, before[1])
        point = (w, tw, corrected, h)
        if tw[-1] * before[1][-1] <= 0:
            after = point
            break
        before = (w, tw, corrected)
    if after is None:
        return None
    # The Illinois secant in the arclength s from ``before`` along its tangent: t_p(0) and t_p(h) bracket zero.
    start, t_start = before[0], before[1]
    low, f_low, high, f_high = 0.0, float(t_start[-1]), after[3], float(after[1][-1])
    best = (abs(f_high), after[0], after[1], after[2]) if abs(f_high) < abs(f_low) else (abs(f_low), before[0], before[1], None)
    side = 0
    for _ in range(CODIM2_ITERATIONS):
        if best[0] <= CODIM2_TOL or high - low <= CODIM2_XTOL:
            break
        s = high - f_high * (high - low) / (f_high - f_low)
        if not low < s < high:
            s = 0.5 * (low + high)
        corrected = arc.correct(start + s * t_start, t_start)
        if corrected is None:
            break
        ts = arc.tangent(corrected[0], t_start)
        f = float(ts[-1])
        if abs(f) < best[0]:
            best = (abs(f), corrected[0], ts, corrected)
        low, f_low, high, f_high, side = illinois(s, f, low, f_low, high, f_high, side)
    _, w, tw, corrected = best

    def orbit_of(w: np.ndarray, corrected) -> PeriodicOrbit:
        if isinstance(corrected, (PeriodicOrbit, shooting.Orbit)):  # the curve's own last point
            return corrected
        _, mono, closure, iterations = corrected
        return augmented.orbit_at(augmented.at(float(w[-1])), w[:-1], mono, closure, iterations)

    orbit = orbit_of(w, before[2] if corrected is None else corrected)
    if np.sort(np.abs(orbit.multipliers - 1.0))[1] > FOLD_MULTIPLIER_TOL:
        return None  # the turn of a curve of singular shooting Jacobians that are no folds of cycles (a section's)
    # p = p* - k (s - s*)^2 near the cusp, t_p = -2 k (s - s*): k from the secant's last slope. The tangent's
    # p-component is no more accurate than the one-sided differences of g (relative DIFFERENCE_STEP).
    k = abs(f_high - f_low) / max(2.0 * (high - low), 1e-300)
    remainder = max(abs(float(tw[-1])), DIFFERENCE_STEP) ** 2 / (4.0 * k) if k > 0 else math.inf
    value = float(w[-1]) + math.copysign(abs(float(tw[-1])) ** 2 / (4.0 * k), float(start[-1] - w0[-1]))
    remainder += arc.accuracy(w)
    branches = ((float(before[0][-1]), orbit_of(*before[::2])), (float(after[0][-1]), orbit_of(after[0], after[2])))
    # w = (z, p) and z ends with the first parameter's value (the chain's M, a system's own).
    return Codim2Point(
        "cusp",
        CUSP_LABELS["cusp"],
        value,
        float(w[-2]),
        orbit.period,
        orbit,
        float(tw[-1]),
        remainder,
        branches=branches,
        tangent_moment=float(tw[-2]),
        branch_moments=(float(before[0][-2]), float(after[0][-2])),
    )


def _critical(multipliers: np.ndarray, kind: str, pair: complex | None) -> complex:
    """The multiplier on the circle at a ``period_doubling`` end (the real negative one nearest -1) or a
    ``torus`` end (the complex one, positive imaginary part, nearest ``pair``: the one followed; without
    it the largest).

    At a torus end every other multiplier lies inside the circle, so the crossing pair starts as
    the largest; nearness to the circle does not tell it: with damping nearly proportional to the
    inertia the multipliers crowd onto one circle (a random N = 4 chain's pairs at 0.9975 and 0.9686
    swap places before the second crosses), so the pair is then followed by nearness in the plane.
    """
    complex_ = np.abs(multipliers.imag) > COMPLEX_RTOL * np.abs(multipliers)
    if kind == "period_doubling":
        candidates = multipliers[~complex_ & (multipliers.real < 0)]
    else:
        candidates = multipliers[complex_ & (multipliers.imag > 0)]
    if candidates.size == 0:
        raise OrbitError(f"no {'real negative' if kind == 'period_doubling' else 'complex'} Floquet multiplier")
    if kind == "period_doubling":
        return complex(candidates[np.argmin(np.abs(candidates + 1.0))])
    if pair is None:
        return complex(candidates[np.argmax(np.abs(candidates))])
    return complex(candidates[np.argmin(np.abs(candidates - pair))])


def torus_angle(orbit: PeriodicOrbit | shooting.Orbit) -> float:
    """The angle arg(mu) in (0, pi) of an orbit's torus pair (its largest complex multiplier; at a torus end the
    one on the unit circle); its strong resonances lie at 2 pi / 3 (1:3) and pi / 2 (1:4).

    Raises
    ------
    OrbitError
        If the orbit has no complex multiplier.
    """
    return float(np.angle(_critical(orbit.nontrivial_multipliers, "torus", None)))


def locate_cycle_end(orbits: Sequence[PeriodicOrbit], kind: str, *, field_name: str | None = None, **options) -> PeriodicOrbit:
    """The end of one ``kind`` between ``orbits`` of one chain, to Newton's tolerance.

    Newton starts from, in turn: for a loss of stability, the orbit interpolated between the
    first two where their largest multiplier's modulus crosses 1 (much nearer the end than
    either: from the orbits themselves Newton can fail, the paper's chain's torus from an orbit
    2e-4 below it); then each orbit as given.

    Parameters
    ----------
    orbits : sequence of PeriodicOrbit
        Orbits of one branch around the end (:func:`~.periodic.continue_orbit`'s): the last
        stable and the first unstable one for ``period_doubling`` and ``torus``, those
        around the turn for ``fold_of_cycles``.
    kind : str
        One of :data:`KINDS`.
    field_name : str, optional
        The field a caller varies (its messages name it); default the first of :data:`FIELDS`.
    **options
        As for :func:`continue_cycle_end`, whose first point this is.

    Returns
    -------
    PeriodicOrbit
        The orbit at the end (its multipliers include the critical one(s) on the circle).

    Raises
    ------
    ValueError
        Where Newton converges from none of the starts (the message gives each reason).
    """
    starts = list(orbits)
    if kind != "fold_of_cycles" and len(starts) >= 2 and starts[0].max_multiplier != starts[1].max_multiplier:
        a, b = starts[:2]
        w = min(1.0, max(0.0, (1.0 - a.max_multiplier) / (b.max_multiplier - a.max_multiplier)))
        between = {name: getattr(a, name) + w * (getattr(b, name) - getattr(a, name)) for name in ("x", "v", "period", "moment")}
        starts.insert(0, dataclasses.replace(a, **between))
    field_name = FIELDS[0] if field_name is None else field_name  # any field: its one value is the chain's own
    reasons = []
    for start in starts:
        try:
            return continue_cycle_end(start, kind, field_name, [getattr(start.params, field_name)], **options).orbits[0]
        except ValueError as err:
            reasons.append(str(err))
    raise ValueError("; ".join(reasons))


def locate_circle_event(
    orbits: Sequence[PeriodicOrbit],
    kind: str,
    *,
    field_name: str | None = None,
    resolve: bool = False,
    tol: float = CLOSURE_TOL,
    rtol: float = RTOL,
    atol: float = ATOL,
) -> PeriodicOrbit:
    """The period doubling or torus between the first two ``orbits`` of one chain's branch, by the one mechanism.

    :func:`~.cycle_events.circle_events_between` at these tolerances: Brent's method in M on the event's test
    function, each trial re-solved by the dense shooting (:func:`~.periodic.find_periodic_orbit`) from the orbit
    interpolated between the two, and one secant step; the located orbit's critical multiplier lies on -1 or the
    circle to the orbits' accuracy (:data:`~.cycle_events.CIRCLE_MULTIPLIER` at least). :func:`locate_cycle_end`
    solves the same end by the augmented Newton from one orbit; this is the branch's own event, found again.

    Parameters
    ----------
    orbits : sequence of PeriodicOrbit
        The last orbit before the event and the first after it (a branch's, :func:`~.periodic.continue_orbit`).
    kind : str
        ``period_doubling`` or ``torus``.
    field_name : str, optional
        The field a caller varies (its messages name it and its value); default the first of :data:`FIELDS`.
    resolve : bool
        Solve the two orbits again at these tolerances first (orbits of a branch traced at looser ones).
    tol, rtol, atol : float
        As for :func:`~.periodic.find_periodic_orbit`.

    Returns
    -------
    PeriodicOrbit
        The orbit at the event.

    Raises
    ------
    ValueError
        For a ``kind`` other than the two, fewer than two orbits, or no such event located between them (the message
        names the field and its value).
    """
    if kind not in CIRCLE_KINDS:
        raise ValueError(f"kind must be one of {CIRCLE_KINDS} (located by cycle_events), got {kind!r}")
    field_name = FIELDS[0] if field_name is None else field_name
    where = f"{field_name} = {getattr(orbits[0].params, field_name):g}" if len(orbits) else field_name
    if len(orbits) < 2:
        raise ValueError(
            f"the {kind} end could not be located at {where}: it needs the two orbits of a branch around it, got {len(orbits)}"
        )
    a, b = orbits[:2]
    options = {"tol": tol, "rtol": rtol, "atol": atol}
    if resolve:
        a, b = (find_periodic_orbit(o.params, o.model, o.moment, turns=o.turns, particle=o.particle, guess=o, **options) for o in (a, b))
    solve = functools.partial(_orbit_between, method="dense", segments=None, **options)
    located = [e for e in circle_events_between(a, b, solve) if e["kind"] == kind and e["located"]]
    if not located:
        raise ValueError(
            f"the {kind} end could not be located at {where} between the orbits at M = {a.moment:.10g} and {b.moment:.10g}: "
            "its test function does not change sign there, or its critical multiplier is not on the circle"
        )
    return located[0]["orbit"]


def _other_multipliers(orbit: PeriodicOrbit, kind: str) -> np.ndarray:
    """The nontrivial multipliers but the critical one(s) of ``kind``, which lie on the unit circle at the end."""
    rest = orbit.nontrivial_multipliers
    if kind == "fold_of_cycles":
        critical = [int(np.argmin(np.abs(rest - 1.0)))]
    else:
        mu = _critical(rest, kind, None)
        critical = [int(np.argmin(np.abs(rest - mu))), int(np.argmin(np.abs(rest - np.conj(mu))))]
    return np.delete(rest, sorted(set(critical)))
