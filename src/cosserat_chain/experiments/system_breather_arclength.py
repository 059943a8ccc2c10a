"""A user system's roto-breather family by pseudo-arclength: its folds and branch points as events, and the branches there.

Contract
--------
:func:`~cosserat_chain.numerics.shooting.continue_orbits` follows a conservative orbit of a
system in its period or in one of its parameters by pseudo-arclength, the unknowns
w = (y0, eps, lambda) with the damping eps the unfolding (Munoz-Almaraz et al., Physica D
181, 2003) and lambda = log T, or a parameter at a fixed period. Its fold of cycles needs a
second multiplier at +1, which a Hamiltonian family's fold does not have: at a fold in the
frequency (dT/dE = 0) the fixed-lambda Newton system (the Jacobian without its lambda column)
is singular while every nontrivial multiplier may stay away from +1; the Jordan block of the
pair at +1 (the flow and the family, coupled by dT/dE) turns semisimple there, so the pair,
split by the integration error, often goes from a complex split on one side to a real one on
the other (the split follows the error's sign as well: the singular value is the test). :func:`continue_family` follows the same branch and reports, as :class:`FamilyEvent`:

* ``fold``: the tangent's lambda component changing sign (the kit's secant method on the
  arclength), with the fixed-lambda Jacobian's smallest relative singular value there, the
  split of the pair at +1 on either side and an accuracy, the distance from the located value
  to the vertex of the parabola lambda(s) through the fold and its two neighbours (s the
  arclength along the fold's tangent);
* ``branch_point``: the sign of det [dR/dw; t] changing while lambda does not turn, where a
  nontrivial multiplier pair passes through +1
  (:func:`~cosserat_chain.numerics.breather_arclength.pair_test` changes sign; bisected on the
  chord between the two members, each trial corrected): a family of other orbits crosses there;
* ``stability``: a nontrivial multiplier leaving (or joining) the unit circle (at a branch
  point, the branch point stands for it).

At a fixed period the folds in a coupling are the same points as the folds in the period at
that coupling: both are where dT/dE = 0 on the two-parameter surface of orbits.
With ``branches``, the family through each branch point is followed (:func:`follow_branch`):
one arclength step off along the second null vector of dR/dw
(:func:`~cosserat_chain.numerics.kit.branch_directions`), corrected on the plane normal to it,
then continued.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from ..numerics.breather_arclength import branch_off, pair_split, relocate_branch_point
from ..numerics.kit import BranchEnd, Continuation, continuation
from ..numerics.shooting import ATOL, CLOSURE_TOL, PERIOD, RTOL, Orbit, _OrbitProblem, _Shooting

#: Arclength steps (in the max norm of (y0, eps, lambda)) of a family, and of a branch followed from a branch point.
STEP, MIN_STEP, MAX_STEP = 0.02, 1e-6, 0.05
BRANCH_POINTS = 30
#: The first step off a branch point (the bordered Newton is nearly singular there: a short one).
BRANCH_STEP = 0.005
#: There the closure stalls near the tolerance (the integration error, amplified): it is relaxed this many times.
NEAR_TOL = 10.0


def energy(orbit: Orbit) -> float | None:
    """Kinetic plus potential energy at the orbit's start (None for a system without an energy function)."""
    potential = orbit.system.energy(orbit.q0)
    return None if potential is None else float(potential + 0.5 * np.sum(orbit.system.mass() * orbit.v0**2))


@dataclass
class FamilyEvent:
    """A located fold, branch point or change of stability of a family.

    Attributes
    ----------
    kind : str
        ``fold``, ``branch_point`` or ``stability``.
    parameter : str
        ``omega`` (the family continued in the period) or the system's parameter.
    value : float
        The parameter there (Omega = 2 pi k / T for the period).
    accuracy : float or None
        For a fold: |value - the vertex of the parabola through it and its two neighbours|; for a
        branch point: the half-width of the bisection's final bracket.
    omega, energy : float
        The orbit's frequency and energy (None without an energy function).
    singular_value : float
        The fixed-parameter Jacobian's smallest singular value relative to its largest (0 at a fold).
    split_before, split_after : str
        :func:`pair_split` of the members on either side.
    index : int
        The event lies between ``orbits[index - 1]`` and ``orbits[index]``.
    orbit : Orbit
    branch : list of Orbit, optional
        The family followed from a branch point (:func:`follow_branch`).
    discriminant : (float, float), optional
        For a branch point of a family in the period: the value and accuracy of the zero of the collision discriminant
        of the pair passing through +1 there (its change of stability), the same point located without the singular
        Newton system. By natural members (:func:`~.system_breathers.roto_breather_family` without ``arclength``)
        where it lies within the two accuracies of ``value``; by pseudo-arclength (:func:`~.system_breathers.roto_breather_family`
        with ``arclength``) from the two members around it (:func:`~.system_breathers.branch_point_discriminant`).
    """

    kind: str
    parameter: str
    value: float
    accuracy: float | None
    omega: float
    energy: float | None
    singular_value: float
    split_before: str
    split_after: str
    index: int
    orbit: Orbit = field(repr=False)
    tangent: np.ndarray | None = field(default=None, repr=False)
    branch: list[Orbit] | None = field(default=None, repr=False)
    branch_message: str = ""
    discriminant: tuple[float, float] | None = None

    def as_dict(self) -> dict:
        out = {
            "kind": self.kind, "parameter": self.parameter, "value": self.value, "accuracy": self.accuracy, "omega": self.omega,
            "energy": self.energy, "singular_value": self.singular_value, "max_multiplier": self.orbit.max_multiplier,
            "split_before": self.split_before, "split_after": self.split_after, "between": [self.index - 1, self.index],
        }  # fmt: skip
        if self.discriminant is not None:
            out["discriminant_value"], out["discriminant_accuracy"] = self.discriminant
        if self.branch is not None:
            out["branch"] = {
                "values": [_value(o, self.parameter) for o in self.branch],
                "omega": [2 * math.pi * _first_turns(o) / o.period for o in self.branch],
                "energy": [energy(o) for o in self.branch],
                "max_multiplier": [o.max_multiplier for o in self.branch],
                "message": self.branch_message,
            }
        return out


def _first_turns(orbit: Orbit) -> int:
    turning = np.flatnonzero(orbit.turns)
    return int(abs(orbit.turns[turning[0]])) if turning.size else 1


def _value(orbit: Orbit, parameter: str) -> float:
    return 2 * math.pi * _first_turns(orbit) / orbit.period if parameter == "omega" else orbit.parameter(parameter)


class _HamiltonianProblem(_OrbitProblem):
    """:class:`~cosserat_chain.numerics.shooting._OrbitProblem` whose folds need no multiplier at +1 (a Hamiltonian family's)."""

    def confirm(self, kind: str, orbit: Orbit) -> bool:
        # A branch point is relocated (and confirmed) by :func:`_relocate`: the kit's bisection of a sign corrects
        # ever nearer a singular bordered Jacobian, and may stop short of it.
        return True


def _relocate(shooting: _Shooting, a: Orbit, b: Orbit, parameter: str) -> tuple[Orbit, float, np.ndarray] | None:
    """The branch point between members ``a`` and ``b`` (:func:`~cosserat_chain.numerics.breather_arclength.relocate_branch_point`):
    the orbit, half the final bracket in the parameter, the chord's direction; None without a pair through +1 between them."""
    shooting.set_reference(a.y0)

    def point(w, evaluation, iterations) -> Orbit:
        orbit = shooting.orbit(w, evaluation, iterations)
        orbit.unfold = a.unfold
        return orbit

    found = relocate_branch_point(shooting.evaluate, point, shooting.pack, a, b, NEAR_TOL * shooting.tol, lambda o: _value(o, parameter))
    return None if found is None else (found[0], found[2], found[3])


def _setup(orbit: Orbit, parameter: str, limits, tol: float) -> tuple[_Shooting, _HamiltonianProblem, str]:
    if orbit.unfold is None:
        raise ValueError("a conservative orbit is needed: one found with unfold= (find_orbit, roto_breather_family)")
    name = PERIOD if parameter == "omega" else parameter
    if name != PERIOD:
        orbit.system.parameter(name)
    shooting = _Shooting(orbit.system, orbit.turns, orbit.y0, orbit.period, (orbit.unfold, name), tol, RTOL, ATOL)
    if name == PERIOD:
        k = _first_turns(orbit)
        low, high = (2 * math.pi * k / limits[1], 2 * math.pi * k / limits[0])
    else:
        low, high = limits
    problem = _HamiltonianProblem(shooting, math.inf, (low, high), False, orbit.stable, orbit.unfold)
    return shooting, problem, name


def fixed_parameter_singular_value(orbit: Orbit, parameter: str) -> float:
    """The smallest singular value of the Newton system at ``orbit`` with ``parameter`` held (``omega``: the period), over its largest.

    It vanishes at a fold in that parameter (where natural steps in it stop).
    """
    shooting, _, _ = _setup(orbit, parameter, (-math.inf, math.inf), CLOSURE_TOL)
    singular = np.linalg.svd(shooting.evaluate(shooting.pack(orbit), True).matrix()[:, :-1], compute_uv=False)
    return float(singular[-1] / singular[0])


def fold_accuracy(
    orbits: list, event_orbit, t: np.ndarray, index: int, pack: Callable[[Orbit], np.ndarray], value: Callable[[Orbit], float]
) -> float | None:
    """|located value - vertex of lambda(s)| through the fold and its neighbours, s along the fold's tangent.

    ``pack(orbit)`` is the orbit's unknowns w (the parameter last, as the tangent ``t``), ``value(orbit)`` the
    parameter; the fold lies between ``orbits[index - 1]`` and ``orbits[index]``.
    """
    if not 1 <= index < len(orbits):
        return None
    centre = pack(event_orbit)
    triple = (orbits[index - 1], event_orbit, orbits[index])
    s = np.array([float(t[:-1] @ (pack(o) - centre)[:-1]) for o in triple])
    lam = np.array([value(o) for o in triple])
    if len(set(np.round(s, 14))) < 3:
        return None
    c, b, a = np.polyfit(s, lam, 2)
    if c == 0:
        return None
    return float(abs(a - b * b / (4 * c) - lam[1]))


def _events(traced: Continuation, shooting: _Shooting, parameter: str) -> list[FamilyEvent]:
    out = []
    orbits = traced.points
    # A change of stability beside a branch point is its pair through +1, which the branch point locates better
    # (the kit's secant corrects ever nearer a singular bordered Jacobian there).
    crossings = {e.index for e in traced.events if e.kind == "branch_point"}
    for e in traced.events:
        if e.kind == "stability" and e.index in crossings:
            continue
        tangent, accuracy = e.tangent, None
        if e.kind == "branch_point":
            found = _relocate(shooting, orbits[e.index - 1], orbits[e.index], parameter) if e.index >= 1 else None
            if found is None:
                continue
            point, accuracy, tangent = found
        elif not e.located:
            continue
        else:
            point = e.point
        before = orbits[e.index - 1] if e.index >= 1 else point
        after = orbits[e.index] if e.index < len(orbits) else point
        shooting.set_reference(point.y0)
        singular = np.linalg.svd(shooting.evaluate(shooting.pack(point), True).matrix()[:, :-1], compute_uv=False)
        if e.kind == "fold":
            accuracy = fold_accuracy(orbits, point, tangent, e.index, shooting.pack, lambda o: _value(o, parameter))
        out.append(
            FamilyEvent(
                kind=e.kind,
                parameter=parameter,
                value=_value(point, parameter),
                accuracy=accuracy,
                omega=2 * math.pi * _first_turns(point) / point.period,
                energy=energy(point),
                singular_value=float(singular[-1] / singular[0]),
                split_before=pair_split(before),
                split_after=pair_split(after),
                index=e.index,
                orbit=point,
                tangent=tangent,
            )
        )
    return out


@dataclass
class ArclengthSystemFamily:
    """A system's family traced by pseudo-arclength: its orbits in order, the located events, how it ended."""

    parameter: str
    orbits: list[Orbit]
    events: list[FamilyEvent]
    end: BranchEnd
    message: str

    @property
    def values(self) -> np.ndarray:
        return np.array([_value(o, self.parameter) for o in self.orbits])

    @property
    def folds(self) -> list[FamilyEvent]:
        return [e for e in self.events if e.kind == "fold"]

    @property
    def branch_points(self) -> list[FamilyEvent]:
        return [e for e in self.events if e.kind == "branch_point"]


def continue_family(
    orbit: Orbit,
    parameter: str,
    limits: tuple[float, float],
    *,
    direction: float = 1.0,
    step: float = STEP,
    min_step: float = MIN_STEP,
    max_step: float = MAX_STEP,
    max_points: int = 300,
    tol: float = CLOSURE_TOL,
    branches: bool = False,
    branch_points: int = BRANCH_POINTS,
    progress: Callable[[int, int], None] | None = None,
) -> ArclengthSystemFamily:
    """Follow a conservative orbit's family in ``parameter`` by pseudo-arclength, reporting its folds and branch points.

    Parameters
    ----------
    orbit : Orbit
        A conservative orbit (found with ``unfold=``).
    parameter : str
        ``omega`` (the family in its frequency: the period continued, the parameters held) or a
        parameter of the orbit's system (continued at the orbit's period).
    limits : (float, float)
        The trace stops at the first orbit whose value leaves this range.
    direction : float
        +1 to start towards larger values of the parameter (of Omega for ``omega``), -1 towards smaller.
    step, min_step, max_step, max_points, tol
        Of the kit's driver and Newton.
    branches : bool
        Follow the family through every branch point for ``branch_points`` points (:func:`follow_branch`).

    Raises
    ------
    ValueError
        For an orbit that is not conservative, an unknown parameter, a range that does not hold the start, a bad direction.
    """
    if direction not in (1, -1, 1.0, -1.0):
        raise ValueError(f"direction must be +1 or -1, got {direction!r}")
    low, high = limits
    if not low < high:
        raise ValueError(f"limits must be (low, high) with low < high, got {limits!r}")
    start_value = _value(orbit, parameter) if parameter == "omega" else (orbit.system.parameter(parameter))
    if not low <= start_value <= high:
        raise ValueError(f"the start's {parameter} = {start_value!r} must lie in the limits [{low!r}, {high!r}]")
    shooting, problem, _ = _setup(orbit, parameter, (low, high), tol)
    traced = continuation(
        problem, shooting.pack(orbit), step=step, min_step=min_step, max_step=max_step, max_points=max_points,
        direction=-float(direction) if parameter == "omega" else float(direction), progress=progress, first=orbit,
    )  # fmt: skip
    family = ArclengthSystemFamily(parameter, list(traced.points), _events(traced, shooting, parameter), traced.end, traced.message)
    if branches:
        for event in family.branch_points:
            event.branch, event.branch_message = follow_branch(event, limits, max_points=branch_points, tol=tol)
    return family


def follow_branch(event: FamilyEvent, limits: tuple[float, float], *, step: float = BRANCH_STEP, max_points: int = BRANCH_POINTS,
                  tol: float = CLOSURE_TOL) -> tuple[list[Orbit], str]:  # fmt: skip
    """The family crossing the located branch point ``event``: a step off along the other null vector, then continued.

    Returns
    -------
    (list of Orbit, str)
        The branch's orbits (from the first off the branch point) and how it ended; no orbit and
        the reason where the first step cannot be corrected.
    """
    shooting, problem, _ = _setup(event.orbit, event.parameter, limits, tol)
    return branch_off(problem, shooting.pack(event.orbit), event.tangent, step=step, max_points=max_points, tol=tol)
