"""Hamiltonian rotating orbits (roto-breathers) followed in the frequency by pseudo-arclength, through folds.

Contract
--------
:func:`~.periodic.continue_in_frequency` steps Omega along a grid, so a fold in Omega (the
family turning back, its energy going on) ends it. Here the same unfolded shooting as
:func:`~.periodic.find_hamiltonian_orbit`,

    R(y0, eps, Omega) = Phi_T^eps(y0) - y0 - 2 pi k e_phi = 0,   T = 2 pi k / Omega,

with the phase condition phi_rotor = 0 (phi_rotor not an unknown) and the unfolding eps, is a
branch of n equations in n + 1 unknowns w = (y0 without phi_rotor, eps, Omega), Omega last.
Its Jacobian is [(M - I) without the phi column, dPhi_T/deps, f(Phi_T(y0)) dT/dOmega]: the
variational equations give the first two (one integration, as for the orbit alone), the
vector field at the end the last. :class:`HamiltonianFrequencyProblem` states it as a
:class:`~.kit.ContinuationProblem`, and :func:`continue_hamiltonian_arclength` follows it on
the kit's one driver (:func:`~.kit.continuation`): the tangent's Omega component changing
sign is a fold, located by the kit's secant method on the arclength.

At a fold in Omega the period-energy curve turns (dT/dE = 0): the fixed-frequency problem
that :func:`~.periodic.find_hamiltonian_orbit` solves, the Jacobian without its Omega column,
is singular there (:meth:`HamiltonianFrequencyProblem.fixed_frequency_singular_value`), which is
why natural steps in Omega stop before it. The monodromy's Jordan block at +1 (the flow and the
family, coupled by dT/dE) becomes semisimple there: the pair at +1, split by the integration
error, turns from a real split on one side to a complex one on the other (often: the split
follows the error's sign too, so :attr:`ArclengthFamily.diagnostics` gives it beside the singular
value, which is the test).

:class:`HamiltonianFieldProblem` and :func:`continue_hamiltonian_field` follow the family at a
fixed frequency in a field of the chain instead (its column by central differences); a fold
there is where dT/dE = 0 as well, so it is the fold in Omega at that field value. With
``branches``, :func:`follow_branches` relocates each branch point by bisecting
:func:`pair_test` on the chord between its two orbits (:func:`relocate_branch_point`) and
follows the family crossing it (:func:`branch_off`: a step along the second null vector of
dR/dw, then the kit's driver).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ..state import check_state
from .kit import BranchEnd, Evaluation, EvaluationFailed, Event, StartError, branch_directions, continuation, newton
from .periodic import (
    ATOL,
    CLOSURE_TOL,
    RTOL,
    HamiltonianFamily,
    HamiltonianOrbit,
    OrbitError,
    PeriodicOrbit,
    _orbit,
    _shooting,
    _System,
    _to_y,
    _UndampedSystem,
    hamiltonian_energy,
    hamiltonian_setup,
)

#: Default arclength steps (in the max norm of the state and Omega together).
STEP, MIN_STEP, MAX_STEP = 0.01, 1e-6, 0.05


@dataclass
class HamiltonianFrequencyProblem:
    """The branch R(y0, eps, Omega) = 0 of the module docstring, for :func:`~.kit.continuation`.

    Attributes
    ----------
    orbit : HamiltonianOrbit
        The start: its chain, model, turns, rotating particle and every particle's turns.
    omega_min, omega_max : float
        The branch ends where Omega leaves this range (:attr:`~.kit.BranchEnd.PARAMETER_LIMIT`).
    tol, rtol, atol : float
        Newton's tolerance on the closure, and DOP853's.
    """

    orbit: HamiltonianOrbit
    omega_min: float
    omega_max: float
    tol: float = CLOSURE_TOL
    rtol: float = RTOL
    atol: float = ATOL
    _keep: np.ndarray = field(init=False, repr=False)

    def __post_init__(self) -> None:
        o = self.orbit
        self._model = hamiltonian_setup(
            o.params, o.model, o.omega, o, o.turns, o.particle, o.particle_turns, self.tol, self.rtol, self.atol
        )[0]
        self._base = _System(o.params, self._model, 0.0, o.particle)
        self._keep = np.arange(2 * self._base.nf) != self._base.load_dof

    def start(self) -> np.ndarray:
        """w at the start orbit: (y0 without phi_rotor, eps, Omega)."""
        o = self.orbit
        y0 = _to_y(o.params, check_state(o.params, o.x, "orbit x"), check_state(o.params, o.v, "orbit v"))
        return np.concatenate([y0[self._keep], [o.unfolding, o.omega]])

    def _pack(self, orbit: HamiltonianOrbit) -> np.ndarray:
        y0 = _to_y(orbit.params, orbit.x, orbit.v)
        return np.concatenate([y0[self._keep], [orbit.unfolding, orbit.omega]])

    def _state(self, w: np.ndarray) -> np.ndarray:
        y = np.zeros(len(self._keep))
        y[self._keep] = w[:-2]
        return y

    def evaluate(self, w: np.ndarray, jacobian: bool) -> Evaluation:
        """R(w) and, with ``jacobian``, dR/dw and the monodromy (``data``)."""
        omega = float(w[-1])
        if not (math.isfinite(omega) and omega > 0):
            raise EvaluationFailed(f"a trial frequency {omega!r} is not > 0")
        o = self.orbit
        period = 2.0 * math.pi * o.turns / omega
        system = _UndampedSystem(o.params, self._model, 0.0, o.particle, float(w[-2]))
        try:
            residual, jac_y, d_period, d_eps, mono = _shooting(system, o.particle_turns, self.rtol, self.atol)(
                self._state(w), period, jacobian
            )
        except OrbitError as err:
            raise EvaluationFailed(str(err)) from err
        if jac_y is None:
            return Evaluation(residual)
        d_omega = d_period * (-period / omega)
        return Evaluation(residual, np.column_stack([jac_y[:, self._keep], d_eps, d_omega]), mono)

    def point(self, w: np.ndarray, evaluation: Evaluation, iterations: int) -> HamiltonianOrbit:
        """The orbit at a corrected w, with its multipliers and energy."""
        o = self.orbit
        period = 2.0 * math.pi * o.turns / float(w[-1])
        closure = float(np.max(np.abs(evaluation.residual)))
        base = _orbit(self._base, o.turns, self._state(w), period, evaluation.data, closure, iterations, o.particle_turns)
        fields = {name: getattr(base, name) for name in PeriodicOrbit.__dataclass_fields__}
        energy = hamiltonian_energy(o.params, self._model, base.x, base.v)
        return HamiltonianOrbit(**fields, unfolding=float(w[-2]), energy=energy)

    def fixed_frequency_singular_value(self, orbit: HamiltonianOrbit) -> float:
        """The smallest singular value of dR/d(y0, eps) at ``orbit`` (Omega held): 0 at a fold in Omega.

        It is the Newton Jacobian of :func:`~.periodic.find_hamiltonian_orbit` at that frequency,
        relative to its largest singular value.
        """
        singular = np.linalg.svd(self.evaluate(self._pack(orbit), True).matrix()[:, :-1], compute_uv=False)
        return float(singular[-1] / singular[0])

    def accept(self, previous: HamiltonianOrbit, candidate: HamiltonianOrbit) -> bool:
        return True

    def tests(self, point: HamiltonianOrbit) -> dict[str, float]:
        return {}

    def stop(self, point: HamiltonianOrbit) -> tuple[BranchEnd, str] | None:
        if self.omega_min <= point.omega <= self.omega_max:
            return None
        return BranchEnd.PARAMETER_LIMIT, (
            f"Omega = {point.omega:.10g} left [{self.omega_min:g}, {self.omega_max:g}]: " + BranchEnd.PARAMETER_LIMIT.advice
        )

    def confirm(self, kind: str, point: HamiltonianOrbit) -> bool:
        return True


#: Relative step of the central difference of the closure in a chain field (its column of the Jacobian).
FIELD_STEP = 1e-6


@dataclass
class HamiltonianFieldProblem(HamiltonianFrequencyProblem):
    """The branch R(y0, eps, p) = 0 at the start's frequency, p a field of the chain (a coupling, a geometric one).

    The unknowns are w = (y0 without phi_rotor, eps, p), p last; the chain at p is ``params_at(p)``
    (a geometric field may carry others with it, as a particle's inertia follows its shape). The
    Jacobian's last column is the central difference of the closure in p (two integrations of
    the state alone); the others are those of :class:`HamiltonianFrequencyProblem`. The branch ends
    where p leaves [``omega_min``, ``omega_max``] (here the field's range).

    Attributes
    ----------
    field_name : str
    params_at : callable(float) -> ChainParams
    """

    field_name: str = ""
    params_at: Callable[[float], Any] | None = None

    def start(self) -> np.ndarray:
        """w at the start orbit: (y0 without phi_rotor, eps, p)."""
        w = super().start()
        w[-1] = float(getattr(self.orbit.params, self.field_name))
        return w

    def _pack(self, orbit: HamiltonianOrbit) -> np.ndarray:
        y0 = _to_y(orbit.params, orbit.x, orbit.v)
        return np.concatenate([y0[self._keep], [orbit.unfolding, float(getattr(orbit.params, self.field_name))]])

    def _params(self, value: float):
        if not math.isfinite(value):
            raise EvaluationFailed(f"a trial {self.field_name} = {value!r} is not finite")
        try:
            return self.params_at(value)
        except ValueError as err:
            raise EvaluationFailed(f"no chain at {self.field_name} = {value!r}: {err}") from err

    def _closure(self, params, w: np.ndarray, jacobian: bool):
        o = self.orbit
        system = _UndampedSystem(params, self._model, 0.0, o.particle, float(w[-2]))
        try:
            return _shooting(system, o.particle_turns, self.rtol, self.atol)(self._state(w), 2.0 * math.pi * o.turns / o.omega, jacobian)
        except OrbitError as err:
            raise EvaluationFailed(str(err)) from err

    def evaluate(self, w: np.ndarray, jacobian: bool) -> Evaluation:
        """R(w) and, with ``jacobian``, dR/dw (the field's column by central differences) and the monodromy (``data``)."""
        value = float(w[-1])
        residual, jac_y, _, d_eps, mono = self._closure(self._params(value), w, jacobian)
        if jac_y is None:
            return Evaluation(residual)
        h = FIELD_STEP * max(1.0, abs(value))
        up, down = w.copy(), w.copy()
        up[-1], down[-1] = value + h, value - h
        d_field = (self._closure(self._params(value + h), up, False)[0] - self._closure(self._params(value - h), down, False)[0]) / (2 * h)
        return Evaluation(residual, np.column_stack([jac_y[:, self._keep], d_eps, d_field]), mono)

    def point(self, w: np.ndarray, evaluation: Evaluation, iterations: int) -> HamiltonianOrbit:
        """The orbit at a corrected w (the chain at its field value), with its multipliers and energy."""
        o = self.orbit
        params = self._params(float(w[-1]))
        base_system = _System(params, self._model, 0.0, o.particle)
        closure = float(np.max(np.abs(evaluation.residual)))
        period = 2.0 * math.pi * o.turns / o.omega
        base = _orbit(base_system, o.turns, self._state(w), period, evaluation.data, closure, iterations, o.particle_turns)
        fields = {name: getattr(base, name) for name in PeriodicOrbit.__dataclass_fields__}
        energy = hamiltonian_energy(params, self._model, base.x, base.v)
        return HamiltonianOrbit(**fields, unfolding=float(w[-2]), energy=energy)

    def stop(self, point: HamiltonianOrbit) -> tuple[BranchEnd, str] | None:
        value = float(getattr(point.params, self.field_name))
        if self.omega_min <= value <= self.omega_max:
            return None
        return BranchEnd.PARAMETER_LIMIT, (
            f"{self.field_name} = {value:.10g} left [{self.omega_min:g}, {self.omega_max:g}]: " + BranchEnd.PARAMETER_LIMIT.advice
        )


def pair_split(orbit) -> str:
    """How the two multipliers nearest +1 split: ``real`` (1 +- d), ``complex`` (1 +- i d) or ``none`` (a double 1).

    The Hamiltonian pair at +1 is a Jordan block (the flow and the family, coupled by dT/dE) that
    the integration error splits: real on one side of a fold, complex on the other.
    """
    mu = orbit.multipliers[np.argsort(np.abs(orbit.multipliers - 1.0))[:2]]
    off = float(np.max(np.abs(mu.imag)))
    along = float(np.max(np.abs(mu.real - 1.0)))
    if off == along == 0.0:
        return "none"
    return "complex" if off > along else "real"


def pair_test(orbit) -> float:
    """The sign of prod (mu - 1) over the multipliers but the two nearest +1 (the Hamiltonian pair).

    A pair on the unit circle, a complex quartet and a real pair below 0 each contribute a
    positive factor, a real pair (mu, 1 / mu) above 0 a negative one: the sign changes where a
    nontrivial pair passes through +1 (a branch point, or an extremum of the energy).
    """
    mu = orbit.multipliers[np.argsort(np.abs(orbit.multipliers - 1.0))[2:]]
    return float(np.sign(np.prod(mu - 1.0).real))


#: A nontrivial multiplier counts as off the unit circle beyond this distance from it (the stability test's).
OFF_CIRCLE = 1e-6
#: What :func:`instability_counts` counts, in its order.
COUNTED = ("+1", "-1", "complex")


def off_circle(multipliers: np.ndarray, tol: float = OFF_CIRCLE) -> dict[str, np.ndarray]:
    """The multipliers outside the unit circle (|mu| > 1 + tol) by where their pair left it: ``+1``, ``-1``, ``complex``.

    Of each pair off the circle one member lies outside it. It is real where its distance from
    the real axis is below half its distance from the circle: just off a collision at +-1 the
    eigenvalue solver's imaginary part is round-off far below the pair's split, while a
    quartet's members sit at the collision's angle.
    """
    mu = np.asarray(multipliers, dtype=complex)
    out = mu[np.abs(mu) > 1.0 + tol]
    real = np.abs(out.imag) < 0.5 * (np.abs(out) - 1.0)
    return {"+1": out[real & (out.real > 0)], "-1": out[real & (out.real < 0)], "complex": out[~real]}


def instability_counts(multipliers: np.ndarray, tol: float = OFF_CIRCLE) -> tuple[int, int, int]:
    """How many multiplier pairs are off the unit circle, by where they left it: (real > 0, real < 0, complex quartets).

    :func:`pair_test` is the parity of the first only: two pairs passing through +1 between two
    members leave its sign as it was, and a stable/unstable flag misses a second pair leaving
    an unstable family. The counts do not: each collision changes one of them by one (a pair
    through +1 or -1, a Krein collision making a quartet), so the sum of their differences
    between two members (:func:`collisions_between`) is the number of collisions between them,
    less any that undo each other (a pair leaving and coming back). Which is real and which a
    quartet's: :func:`off_circle`.

    Parameters
    ----------
    multipliers : ndarray
        The nontrivial multipliers (without the Hamiltonian pair at +1).
    tol : float
        Off the circle: |mu| > 1 + tol.
    """
    off = off_circle(multipliers, tol)
    return off["+1"].size, off["-1"].size, int(math.ceil(off["complex"].size / 2))


def collisions_between(a: tuple[int, int, int], b: tuple[int, int, int]) -> int:
    """The number of collisions between two members from their :func:`instability_counts`: the sum of the differences."""
    return int(sum(abs(x - y) for x, y in zip(a, b, strict=True)))


#: A cluster of multipliers is resolved when its farthest member from the cluster's centre is nearer
#: it than this fraction of the next multiplier's distance.
CLUSTER_GAP = 0.5
#: Multipliers in the cluster at a collision of each kind: at +1 the colliding pair and the Hamiltonian pair.
CLUSTER_SIZE = {"+1": 4, "-1": 2, "complex": 2}


def collision_discriminant(multipliers: np.ndarray, kind: str, centre: complex | None = None) -> float | None:
    """The discriminant of the colliding pair's characteristic polynomial: < 0 on the unit circle, > 0 off it.

    A smooth test of a collision of multipliers, where their moduli are not: at the collision
    m multipliers meet (m = :data:`CLUSTER_SIZE`), and an error delta of the monodromy moves
    each of them by delta^(1/m) (four at +1: the pair passing through and the Hamiltonian pair,
    a Jordan block), while the cluster's symmetric functions (its sum, its product) move by
    O(delta) only (they are analytic in the matrix, as the trace is). So:

    * ``+1``: the four multipliers nearest +1; s = their sum - 2 is mu + 1 / mu of the pair
      passing through (the Hamiltonian pair adds exactly 2), and D = s^2 - 4 (s = 2 cos theta
      on the circle, s = mu + 1 / mu > 2 for a real pair);
    * ``-1``: the two nearest -1, s their sum, D = s^2 - 4;
    * ``complex`` (a Krein collision at ``centre`` on the circle): the two nearest ``centre``,
      D = Re (mu_1 - mu_2)^2 / (mu_1 mu_2): -4 sin^2((theta_1 - theta_2) / 2) on the circle,
      (r - 1 / r)^2 for the quartet's r e^(i theta), e^(i theta) / r.

    Returns
    -------
    float or None
        D, or None where the cluster is not resolved (its farthest member is not nearer its centre than
        :data:`CLUSTER_GAP` times the next multiplier) or there are fewer multipliers than it holds.

    Raises
    ------
    ValueError
        For an unknown kind, or ``complex`` without a centre.
    """
    if kind not in CLUSTER_SIZE:
        raise ValueError(f"kind must be one of {', '.join(CLUSTER_SIZE)}, got {kind!r}")
    if kind == "complex" and centre is None:
        raise ValueError("a complex collision needs its centre on the unit circle")
    mu = np.asarray(multipliers, dtype=complex)
    size = CLUSTER_SIZE[kind]
    where = {"+1": 1.0, "-1": -1.0}.get(kind, centre)
    distance = np.abs(mu - where)
    order = np.argsort(distance)
    if mu.size < size or (mu.size > size and distance[order[size - 1]] >= CLUSTER_GAP * distance[order[size]]):
        return None
    cluster = mu[order[:size]]
    if kind == "complex":
        a, b = cluster
        return float(((a - b) ** 2 / (a * b)).real)
    s = float(np.sum(cluster).real) - (2.0 if kind == "+1" else 0.0)
    return s * s - 4.0


#: Bisections of :func:`relocate_branch_point`, and Newton's options there (the bordered Jacobian is nearly singular).
BISECTIONS = 24
NEAR_SINGULAR = {"damping": 6, "max_iterations": 30}


def relocate_branch_point(evaluate, point, pack, a, b, tol: float, value) -> tuple[Any, np.ndarray, float, np.ndarray] | None:
    """Where :func:`pair_test` changes sign between two members ``a`` and ``b`` of a branch, by bisection on their chord.

    The kit's bisection of the sign of det [dR/dw; t] corrects ever nearer a singular bordered
    Jacobian and may stop short of the branch point; here each trial is corrected on the plane
    normal to the chord (damped Newton).

    Parameters
    ----------
    evaluate : callable(w, jacobian) -> Evaluation
    point : callable(w, evaluation, iterations)
        The problem's orbit at a corrected w.
    pack : callable(orbit) -> w
    a, b : orbits
    tol : float
    value : callable(orbit) -> float
        The continued parameter of an orbit (for the accuracy).

    Returns
    -------
    (orbit, w, accuracy, chord) or None
        The last corrected orbit, its w, half the final bracket in the parameter, and the chord's
        unit direction; None where the test does not change sign between a and b.
    """
    fa = pair_test(a)
    if fa * pair_test(b) >= 0:
        return None
    wa, wb = pack(a), pack(b)
    chord = (wb - wa) / np.linalg.norm(wb - wa)
    low, high = 0.0, 1.0
    best, best_w, bracket = a, wa, (a, b)
    for _ in range(BISECTIONS):
        middle = 0.5 * (low + high)
        guess = wa + middle * (wb - wa)
        corrected = newton(evaluate, guess, border=(chord, guess), tol=tol, **NEAR_SINGULAR)
        if not corrected.converged:
            break
        best, best_w = point(corrected.w, corrected.evaluation, corrected.iterations), corrected.w
        if pair_test(best) * fa > 0:
            low, bracket = middle, (best, bracket[1])
        else:
            high, bracket = middle, (bracket[0], best)
    return best, best_w, 0.5 * abs(value(bracket[1]) - value(bracket[0])), chord


def branch_off(problem, w: np.ndarray, along: np.ndarray, *, step: float, max_points: int, tol: float) -> tuple[list, str]:
    """The family crossing the branch at its branch point w (``along`` its tangent there): a step off along the other null vector
    of dR/dw (:func:`~.kit.branch_directions`; 2 and 4 times longer where the first cannot be corrected), corrected on
    the plane normal to it, then the kit's driver.

    Returns
    -------
    (list, str)
        The branch's points from the first off the branch point and how it ended (none, and why, where no first step corrects).
    """
    other = branch_directions(problem.evaluate(w, True).matrix(), along)
    first = None
    for h in (step, 2 * step, 4 * step):  # nearest the branch point the closure stalls: farther is easier
        guess = w + h * other
        first = newton(problem.evaluate, guess, border=(other, guess), tol=tol, **NEAR_SINGULAR)
        if first.converged:
            break
    if not first.converged:
        return [], f"the first step off the branch point along its other null vector could not be corrected ({first.status})"
    try:
        traced = continuation(
            problem, first.w, step=step, min_step=MIN_STEP, max_step=MAX_STEP, max_points=max_points, tangent0=other,
            first=problem.point(first.w, first.evaluation, first.iterations),
        )  # fmt: skip
    except (StartError, EvaluationFailed) as err:
        return [], f"the branch could not be started: {err}"
    return list(traced.points), traced.message


@dataclass
class Branch:
    """A family followed off a branch point of an arclength family.

    Attributes
    ----------
    point : HamiltonianOrbit
        The branch point relocated (:func:`relocate_branch_point`).
    accuracy : float
        Half the bisection's final bracket in the continued parameter.
    orbits : list of HamiltonianOrbit
        The branch, from its first orbit off the branch point.
    message : str
    """

    point: HamiltonianOrbit
    accuracy: float
    orbits: list
    message: str


def follow_branches(family: ArclengthFamily, problem: HamiltonianFrequencyProblem, *, step: float = 0.005, max_points: int = 30) -> None:
    """Relocate every branch point of ``family`` and follow the family crossing it; kept in ``family.branches`` (one per event)."""

    def value(orbit) -> float:
        return orbit.omega if family.parameter == "omega" else float(getattr(orbit.params, family.parameter))

    out = []
    for e in family.events:
        if e.kind != "branch_point" or not 1 <= e.index < len(family.orbits):
            out.append(None)
            continue
        a, b = family.orbits[e.index - 1], family.orbits[e.index]
        found = relocate_branch_point(problem.evaluate, problem.point, problem._pack, a, b, problem.tol, value)
        if found is None:
            out.append(Branch(e.point, math.nan, [], "no nontrivial pair passes through +1 between the two orbits"))
            continue
        orbit, w, accuracy, chord = found
        orbits, message = branch_off(problem, w, chord, step=step, max_points=max_points, tol=problem.tol)
        out.append(Branch(orbit, accuracy, orbits, message))
    family.branches = out


def _diagnostics(problem: HamiltonianFrequencyProblem, points: list, events: list[Event]) -> list[dict]:
    out = []
    for e in events:
        before = points[e.index - 1] if e.index >= 1 else e.point
        after = points[e.index] if e.index < len(points) else e.point
        try:
            singular = problem.fixed_frequency_singular_value(e.point)
        except EvaluationFailed:
            singular = math.nan
        out.append({"singular_value": singular, "split_before": pair_split(before), "split_after": pair_split(after)})
    return out


@dataclass
class ArclengthFamily(HamiltonianFamily):
    """A :class:`~.periodic.HamiltonianFamily` traced by pseudo-arclength: Omega may turn back at folds.

    Attributes
    ----------
    events : list of Event
        The located events of the kit (``fold``, ``branch_point``): ``point`` the orbit there, with
        its energy and multipliers; ``parameter`` its Omega; it lies between ``orbits[index - 1]``
        and ``orbits[index]``.
    end : BranchEnd
        Why the trace stopped.
    """

    events: list[Event] = field(default_factory=list)
    end: BranchEnd = BranchEnd.MAX_POINTS
    #: Per event: the fixed-parameter Newton system's smallest relative singular value there
    #: (``singular_value``) and how the Hamiltonian pair at +1 splits on either side (``split_before``,
    #: ``split_after``: :func:`pair_split`).
    diagnostics: list[dict] = field(default_factory=list)
    #: Per event, with ``branches``: the :class:`Branch` followed off a branch point (None for other events).
    branches: list | None = None
    #: ``omega``, or the chain's field followed at a fixed frequency (:func:`continue_hamiltonian_field`).
    parameter: str = "omega"

    @property
    def values(self) -> np.ndarray:
        """The continued parameter per orbit."""
        if self.parameter == "omega":
            return self.omega
        return np.array([float(getattr(o.params, self.parameter)) for o in self.orbits])

    @property
    def folds(self) -> list[Event]:
        """The located folds in Omega."""
        return [event for event in self.events if event.kind == "fold"]

    @property
    def complete(self) -> bool:
        """Whether the trace left the range asked for (rather than stopping inside it)."""
        return self.end == BranchEnd.PARAMETER_LIMIT


def continue_hamiltonian_arclength(
    orbit: HamiltonianOrbit,
    omega_min: float,
    omega_max: float,
    *,
    direction: float = 1.0,
    step: float = STEP,
    min_step: float = MIN_STEP,
    max_step: float = MAX_STEP,
    max_points: int = 200,
    tol: float = CLOSURE_TOL,
    rtol: float = RTOL,
    atol: float = ATOL,
    progress=None,
    branches: bool = False,
    branch_points: int = 30,
) -> ArclengthFamily:
    """Follow a Hamiltonian orbit's family in Omega by pseudo-arclength, passing and locating its folds.

    Parameters
    ----------
    orbit : HamiltonianOrbit
        The start (:func:`~.periodic.find_hamiltonian_orbit`).
    omega_min, omega_max : float
        The trace stops at the first orbit outside [omega_min, omega_max]; the start must lie inside.
    direction : float
        +1 to start towards larger Omega, -1 towards smaller.
    step, min_step, max_step : float
        Arclength steps (:func:`~.kit.continuation`).
    max_points : int
    tol, rtol, atol : float
        Newton's closure tolerance, DOP853's tolerances.
    progress : callable(done, total), optional
    branches : bool
        Relocate each branch point and follow the family crossing it for ``branch_points`` orbits
        (:func:`follow_branches`, into ``branches``).

    Returns
    -------
    ArclengthFamily
        ``requested`` holds (omega_min, omega_max).

    Raises
    ------
    ValueError
        For a range that is empty, not positive or does not hold the start, a direction other
        than +-1, and as :func:`~.periodic.find_hamiltonian_orbit`.
    """
    for name, value in (("omega_min", omega_min), ("omega_max", omega_max)):
        if not (isinstance(value, (int, float)) and math.isfinite(value) and value > 0):
            raise ValueError(f"{name} must be a finite frequency > 0, got {value!r}")
    if not omega_min <= orbit.omega <= omega_max:
        raise ValueError(f"the start's Omega = {orbit.omega!r} must lie in [omega_min, omega_max] = [{omega_min!r}, {omega_max!r}]")
    if direction not in (1, -1, 1.0, -1.0):
        raise ValueError(f"direction must be +1 or -1, got {direction!r}")
    problem = HamiltonianFrequencyProblem(orbit, float(omega_min), float(omega_max), tol=tol, rtol=rtol, atol=atol)
    return _traced_family(
        problem, orbit, (omega_min, omega_max), "omega", direction, step=step, min_step=min_step, max_step=max_step,
        max_points=max_points, progress=progress, branches=branches, branch_points=branch_points,
    )  # fmt: skip


def continue_hamiltonian_field(
    orbit: HamiltonianOrbit,
    field_name: str,
    params_at: Callable[[float], Any],
    low: float,
    high: float,
    *,
    direction: float = 1.0,
    step: float = STEP,
    min_step: float = MIN_STEP,
    max_step: float = MAX_STEP,
    max_points: int = 200,
    tol: float = CLOSURE_TOL,
    rtol: float = RTOL,
    atol: float = ATOL,
    progress=None,
    branches: bool = False,
    branch_points: int = 30,
) -> ArclengthFamily:
    """Follow a Hamiltonian orbit's family at its frequency in a chain field by pseudo-arclength, passing and locating its folds.

    At a fixed frequency a fold in the field is where dT/dE = 0 on the surface of orbits over
    (Omega, field): the family in Omega at that field value folds there too.

    Parameters
    ----------
    orbit : HamiltonianOrbit
        The start, at the chain's present value of the field.
    field_name : str
        A numeric field of :class:`~cosserat_chain.params.ChainParams` (``E2``, ``a``, ...).
    params_at : callable(float) -> ChainParams
        The chain at a value of the field (a ValueError where there is none).
    low, high : float
        The trace stops at the first orbit outside [low, high]; the start must lie inside.
    direction : float
        +1 to start towards larger values, -1 towards smaller.
    branches, branch_points
        As for :func:`continue_hamiltonian_arclength`.

    Returns
    -------
    ArclengthFamily
        ``parameter`` the field; ``requested`` (low, high).

    Raises
    ------
    ValueError
        For a field the chain does not have, a range that is empty or does not hold the start, a direction other than +-1.
    """
    here = getattr(orbit.params, field_name, None)
    if not isinstance(here, (int, float)) or isinstance(here, bool):
        raise ValueError(f"field_name must be a numeric field of the chain (a, b, h, E1, E2, ...), got {field_name!r}")
    for name, value in (("low", low), ("high", high)):
        if not (isinstance(value, (int, float)) and math.isfinite(value)):
            raise ValueError(f"{name} must be a finite number, got {value!r}")
    if not low <= here <= high or not low < high:
        raise ValueError(f"the start's {field_name} = {here!r} must lie in [low, high] = [{low!r}, {high!r}], low < high")
    if direction not in (1, -1, 1.0, -1.0):
        raise ValueError(f"direction must be +1 or -1, got {direction!r}")
    problem = HamiltonianFieldProblem(
        orbit, float(low), float(high), tol=tol, rtol=rtol, atol=atol, field_name=field_name, params_at=params_at
    )
    return _traced_family(
        problem, orbit, (low, high), field_name, direction, step=step, min_step=min_step, max_step=max_step,
        max_points=max_points, progress=progress, branches=branches, branch_points=branch_points,
    )  # fmt: skip


def _traced_family(
    problem: HamiltonianFrequencyProblem,
    orbit: HamiltonianOrbit,
    requested: tuple[float, float],
    parameter: str,
    direction: float,
    *,
    step: float,
    min_step: float,
    max_step: float,
    max_points: int,
    progress,
    branches: bool,
    branch_points: int,
) -> ArclengthFamily:
    """The family of ``problem`` traced by the kit's continuation from ``orbit`` (the two public traces' common end),
    with each event's diagnostics and, with ``branches``, the families crossing it at its branch points."""
    traced = continuation(
        problem, problem.start(), step=step, min_step=min_step, max_step=max_step, max_points=max_points,
        direction=float(direction), progress=progress, first=orbit,
    )  # fmt: skip
    family = ArclengthFamily(
        orbits=list(traced.points), requested=np.array(requested, dtype=float), message=traced.message,
        events=list(traced.events), end=traced.end, parameter=parameter,
        diagnostics=_diagnostics(problem, traced.points, traced.events),
    )  # fmt: skip
    if branches:
        follow_branches(family, problem, max_points=branch_points)
    return family
