"""Rotating states as periodic orbits by orthogonal collocation (AUTO-07p's scheme).

Contract
--------
The orbit of eq. (P) of :mod:`~cosserat_chain.numerics.periodic` is sought as a function of the
scaled time tau = t / T on [0, 1]: u(tau) = y(T tau) solves

    u' = T f(u),    u(1) = u(0) + s,    int_0^1 <u - u_ref, u_ref'> dtau = 0,         (C)

s = 2 pi (turns of every particle) on the angles (the rotating angle's phase gain), and the
integral phase condition pins the orbit's phase against a reference orbit u_ref (the guess,
or the previous point of a continuation). The scheme (NTST intervals, NCOL Gauss points, the
sparse bordered Newton, the adapted mesh and the multipliers by condensation) is
:mod:`~cosserat_chain.numerics.collocation_core`'s; here are the orbits built on it:

* :func:`find_collocation_orbit`: one orbit (:class:`CollocationOrbit`), from rest, a state and
  a period, or another orbit; :meth:`CollocationOrbit.periodic_orbit` puts it on the shooting's
  section as a :class:`~cosserat_chain.numerics.periodic.PeriodicOrbit`
  (``find_periodic_orbit(..., method="collocation")`` does both).
* :func:`continue_collocation` follows the orbit in M with the package's one pseudo-arclength
  driver (:func:`~cosserat_chain.numerics.kit.continuation`) in (node values, log T, M), the
  mesh re-adapted and the phase reference renewed on the way, until the period exceeds
  ``period_max`` (a homoclinic or SNIC end), M leaves the range, or M turns (a fold of cycles:
  located by the driver's secant method on the tangent's M component, and accepted only with a
  second multiplier at +1, as issue 40 asks). Period doublings (a real multiplier through -1) and
  tori (a complex pair through the unit circle) are located on the way by the same secant method on
  test functions of the multipliers near the unit circle (:func:`circle_tests`), and the branch goes
  on through them. Its loop, :func:`trace_collocation`, also follows a user's system's orbits in any
  parameter (:mod:`~cosserat_chain.numerics.system_collocation`; its messages then call the parameter's value M).
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from ..linalg.threads import one_blas_thread
from ..models.base import get_model
from ..params import ChainParams
from ..state import check_state
from . import periodic
from .collocation_core import (
    ADAPTATIONS,
    CHORD_RATE,
    LEADING_MULTIPLIERS,
    MAX_HALVINGS,
    NCOL,
    NCOL_RANGE,
    NTST,
    SHIFT,
    TOL,
    CollocationError,
    ProfileOrbit,
    Solution,
    _adapted_mesh,
    _Collocation,
    _interpolate,
    _node_times,
    _shift,
    _SparseStep,
    check_mesh,
    scheme,
    section_state,
    solve_profile,
)
from .cycle_events import CIRCLE_KINDS, circle_tests, critical_multiplier, on_circle
from .kit import BranchEnd, Evaluation, Event, continuation, newton

__all__ = [
    "NCOL",
    "NCOL_RANGE",
    "NTST",
    "CollocationBranch",
    "CollocationError",
    "CollocationOrbit",
    "check_mesh",
    "circle_tests",
    "continue_collocation",
    "critical_multiplier",
    "find_collocation_orbit",
    "scheme",
    "solve_collocation",
]


@dataclass
class CollocationOrbit(ProfileOrbit):
    """A rotating state solved by collocation (module docstring, eq. (C)).

    Attributes
    ----------
    params : ChainParams
    model : str
    moment : float
    turns : int
    particle : int
    period : float
    mesh : ndarray (ntst + 1,)
        tau_0 = 0 < ... < tau_ntst = 1.
    ncol : int
    profile : ndarray (ntst ncol + 1, 2 n_free)
        u at the nodes (unwrapped: the winding angles gain 2 pi times their turns from the first to the last).
    multipliers : ndarray (2 n_free,) complex
        Floquet multipliers by decreasing modulus (the collocation's own monodromy, module docstring).
    residual : float
        max |R| at the solution.
    iterations : int
        Newton iterations of the last solve.
    particle_turns : ndarray (2N+1,) int
    multiplier_log_moduli : ndarray (2 n_free,) or None
        ln |mu| of each multiplier, in range where the value under- or overflows (:attr:`log_moduli`).
    """

    params: ChainParams
    model: str
    moment: float
    turns: int
    particle: int
    period: float
    mesh: np.ndarray
    ncol: int
    profile: np.ndarray
    multipliers: np.ndarray
    residual: float
    iterations: int
    particle_turns: np.ndarray
    multiplier_log_moduli: np.ndarray | None = None

    @property
    def mean_angular_velocity(self) -> float:
        """2 pi k / T, signed along the moment."""
        return math.copysign(2.0 * math.pi * self.turns / self.period, self.moment)

    def periodic_orbit(self) -> periodic.PeriodicOrbit:
        """The orbit as a :class:`~cosserat_chain.numerics.periodic.PeriodicOrbit`, started on the loaded angle's section.

        The start is the crossing of phi = 0 (mod 2 pi) by the loaded particle where the flow
        crosses it most steeply; where even there |phi'| / |f| < ``periodic.TRANSVERSAL_MIN``, the
        start carries the plane normal to the flow (``phase_normal``), as the shooting would.
        ``closure`` is the collocation's residual; ``multiplier_errors`` is None (the trivial
        multiplier's distance to 1 is :attr:`trivial_multiplier_error`).
        """
        system = periodic._System(self.params, get_model(self.model), self.moment, self.particle)
        y, normal = section_state(system, self.mesh, self.ncol, self.profile, self.particle_turns, periodic.TRANSVERSAL_MIN)
        return periodic._orbit_from(
            system, self.turns, y, self.period, self.multipliers, self.residual, self.iterations, self.particle_turns, normal,
            multiplier_log_moduli=self.multiplier_log_moduli,
        )  # fmt: skip

    def as_dict(self) -> dict:
        """JSON-ready summary."""
        return {
            "model": self.model,
            "moment": self.moment,
            "turns": self.turns,
            "particle": self.particle,
            "period": self.period,
            "mean_angular_velocity": self.mean_angular_velocity,
            "ntst": self.ntst,
            "ncol": self.ncol,
            "floquet_multipliers_abs": np.abs(self.multipliers).tolist(),
            "floquet_multipliers_log10_abs": (self.log_moduli / math.log(10.0)).tolist(),
            "trivial_multiplier": [self.trivial_multiplier.real, self.trivial_multiplier.imag],
            "trivial_multiplier_error": self.trivial_multiplier_error,
            "max_nontrivial_multiplier": self.max_multiplier,
            "stable": self.stable,
            "residual": self.residual,
            "iterations": self.iterations,
        }


@one_blas_thread
def solve_collocation(
    system: periodic._System,
    turns: int,
    y0: np.ndarray,
    period: float,
    particle_turns: np.ndarray,
    **options,
) -> CollocationOrbit:
    """:func:`~cosserat_chain.numerics.collocation_core.solve_profile` (its ``options``) as a :class:`CollocationOrbit`."""
    solution = solve_profile(system, y0, period, particle_turns, **options)
    return _orbit_of(system, turns, particle_turns, solution)


def _orbit_of(system: periodic._System, turns: int, particle_turns: np.ndarray, solution: Solution) -> CollocationOrbit:
    return CollocationOrbit(
        params=system.params, model=system.model.name, moment=float(system.moment), turns=turns, particle=system.particle,
        period=solution.period, mesh=solution.mesh, ncol=solution.ncol, profile=solution.profile,
        multipliers=solution.multipliers, residual=solution.residual, iterations=solution.iterations,
        particle_turns=np.asarray(particle_turns), multiplier_log_moduli=solution.log_moduli,
    )  # fmt: skip


def find_collocation_orbit(
    params: ChainParams,
    model,
    moment: float,
    *,
    turns: int = 1,
    particle: int = 0,
    guess: periodic.PeriodicOrbit | CollocationOrbit | None = None,
    ntst: int = NTST,
    ncol: int = NCOL,
    adapt: int = ADAPTATIONS,
    tol: float = TOL,
    max_iter: int = 25,
) -> CollocationOrbit:
    """The rotating state at ``moment`` by collocation, eq. (C).

    Parameters
    ----------
    params : ChainParams
    model : str or Model
    moment : float
    turns, particle : int
        As :func:`~cosserat_chain.numerics.periodic.find_periodic_orbit`.
    guess : PeriodicOrbit, CollocationOrbit or (x (3, 2N+1), v (3, 2N+1), T[, particle_turns (2N+1,)]), optional
        An orbit at this or a nearby moment, or a state on it and its period; by default the shooting's settled guess from rest
        (a simulation until the rotation repeats).
    ntst, ncol : int
        Mesh intervals (>= 2) and Gauss points per interval (2..7).
    adapt : int
        Mesh adaptations after the first solve.
    tol : float
        Newton stops when max |R| <= tol.
    max_iter : int

    Returns
    -------
    CollocationOrbit

    Raises
    ------
    ValueError
        For bad mesh sizes, tolerances, moment or turns (naming the field).
    CollocationError
        If Newton's method does not converge.
    """
    model = get_model(model)
    check_mesh(ntst, ncol)
    periodic._check_moment_and_turns(moment, turns)
    periodic.require_orbit_ends(params)
    system = periodic._System(params, model, float(moment), particle)
    if isinstance(guess, CollocationOrbit):
        return solve_collocation(
            system, turns, guess.profile[0], guess.period, guess.particle_turns, ntst=ntst, ncol=ncol, adapt=adapt, tol=tol,
            max_iter=max_iter, profile=guess.profile, mesh=guess.mesh,
        )  # fmt: skip
    if isinstance(guess, periodic.PeriodicOrbit):
        y0, period, particle_turns = periodic._to_y(params, guess.x, guess.v), guess.period, guess.particle_turns
    elif isinstance(guess, tuple) and len(guess) in (3, 4):
        x0, v0, period = guess[:3]
        y0 = periodic._to_y(params, check_state(params, x0, "guess x"), check_state(params, v0, "guess v"))
        particle_turns = (
            periodic._check_particle_turns(params, particle, turns, moment, guess[3])
            if len(guess) == 4
            else periodic._loaded_turns(params, particle, turns, moment)
        )
    elif guess is None:
        x0, v0, period, particle_turns = periodic._settled_guess(
            params, model, moment, turns=turns, particle=particle, x0=None, v0=None, transient_turns=30, t_max=periodic.GUESS_T_MAX
        )
        y0 = periodic._to_y(params, x0, v0)
    else:
        raise ValueError(
            f"guess must be a PeriodicOrbit, a CollocationOrbit, (x, v, T[, particle_turns]) or None, got {type(guess).__name__}"
        )
    return solve_collocation(system, turns, y0, period, particle_turns, ntst=ntst, ncol=ncol, adapt=adapt, tol=tol, max_iter=max_iter)


#: Continuation points between two mesh adaptations (the phase reference is renewed at every point).
REMESH_EVERY = 8
#: A continuation adapts its mesh also once the period has grown by this factor since the last adaptation
#: (1.25 with ``max_interval``, whose intervals then stay within 1.25 times it).
REMESH_GROWTH = 1.5
#: The most intervals a continuation's ``max_interval`` may ask for.
NTST_MAX = 4000
#: A located fold or branch point of cycles is confirmed where the second multiplier nearest +1 lies this close to it.
FOLD_MULTIPLIER = 1e-2
#: A branch's message warns where |mu_trivial - 1| exceeds this.
TRIVIAL_WARNING = 1e-6
#: Default bound on the period: beyond it the branch ends as infinite-period (a homoclinic or SNIC end).
PERIOD_MAX = 2000.0


@dataclass
class CollocationBranch:
    """Orbits traced in M by :func:`continue_collocation`.

    Attributes
    ----------
    orbits : list of CollocationOrbit
        In the order traced.
    end : BranchEnd
        ``infinite_period`` (T exceeded ``period_max``), ``parameter_limit`` (M left the range),
        ``fold`` (M turned: a fold of cycles, located and confirmed, :attr:`events`), ``max_points``
        or ``step_too_small``.
    message : str
    adaptations : int
        Mesh adaptations along the way.
    events : list of dict
        ``{"kind", "moment", "located", "orbit"}``: folds of cycles (located by the secant method on
        the tangent's M component) and branch points of cycles (bisected on the sign of the kit's
        bordered determinant), each kept only with a second multiplier within :data:`FOLD_MULTIPLIER`
        of +1; the branch goes on through branch points. Period doublings (``period_doubling``) and
        tori (``torus``), located by the secant method on :func:`circle_tests` and kept only with the
        critical multiplier within :data:`~.cycle_events.CIRCLE_MULTIPLIER` of -1 or of the unit circle, carry it as
        ``"multiplier"`` (complex) and, for a torus, its angle arg mu in (0, pi) as ``"angle"`` (where the
        secant fails, ``"located"`` is False and the moment is the first orbit's past the sign change); the
        branch goes on through them.
    """

    orbits: list[CollocationOrbit]
    end: BranchEnd
    message: str
    adaptations: int = 0
    events: list[dict] = dataclasses.field(default_factory=list)

    @property
    def moment(self) -> np.ndarray:
        return np.array([o.moment for o in self.orbits])

    @property
    def period(self) -> np.ndarray:
        return np.array([o.period for o in self.orbits])

    @property
    def max_multiplier(self) -> np.ndarray:
        return np.array([o.max_multiplier for o in self.orbits])

    def as_dict(self, parameter: str = "M") -> dict:
        """JSON-ready summary, keyed as the shooting's branch (:meth:`~cosserat_chain.numerics.shooting.OrbitBranch.as_dict`),
        with each orbit's trivial multiplier's error and each event's critical multiplier (period doublings, tori)."""
        events = []
        for e in self.events:
            record = {"kind": e["kind"], "value": e["moment"], "located": e["located"], "period": e["orbit"].period}
            if e["kind"] in CIRCLE_KINDS:
                record["multiplier"] = [e["multiplier"].real, e["multiplier"].imag]
            events.append(record)
        return {
            "parameter": parameter,
            "values": self.moment.tolist(),
            "periods": self.period.tolist(),
            "max_multiplier": self.max_multiplier.tolist(),
            "trivial_multiplier_error": [o.trivial_multiplier_error for o in self.orbits],
            "events": events,
            "end": str(self.end),
            "message": self.message,
            "adaptations": self.adaptations,
        }

    def orbit_branch(self, settings: dict | None = None) -> periodic.OrbitBranch:
        """The branch as the shooting's :class:`~cosserat_chain.numerics.periodic.OrbitBranch` (what ``orbit --down-to`` reports).

        Every orbit is started on the loaded angle's section (:meth:`CollocationOrbit.periodic_orbit`);
        the end ``parameter_limit`` is the shooting's ``moment_min``; the end moment is the located fold's
        where the branch ends at one, else the last orbit's; the branch points of cycles, period doublings
        and tori are its events (the last two with ``"located"``, ``"multiplier"`` as [re, im] and, for a torus, ``"angle"``).
        """
        end = periodic.END_MOMENT_MIN if self.end == BranchEnd.PARAMETER_LIMIT else str(self.end)
        folds = [e["moment"] for e in self.events if e["kind"] == "fold" and e["located"]]
        end_moment = folds[-1] if self.end == BranchEnd.FOLD and folds else self.orbits[-1].moment
        events = []
        for e in self.events:
            if e["kind"] == "branch_point":
                events.append({"kind": "branch_point", "moment": e["moment"]})
            elif e["kind"] in CIRCLE_KINDS:
                mu = e["multiplier"]
                events.append({"kind": e["kind"], "moment": e["moment"], "located": e["located"], "multiplier": [mu.real, mu.imag]})
                if e["kind"] == "torus":
                    events[-1]["angle"] = e["angle"]
        return periodic.OrbitBranch(
            [o.periodic_orbit() for o in self.orbits], end, float(end_moment), self.message,
            settings={"method": "collocation", "ntst": self.orbits[-1].ntst, "ncol": self.orbits[-1].ncol, **(settings or {})},
            events=events,
        )  # fmt: skip


@one_blas_thread
def continue_periodic_orbit(
    orbit: periodic.PeriodicOrbit | CollocationOrbit,
    *,
    moment_min: float = 0.0,
    period_max: float = PERIOD_MAX,
    max_points: int = 400,
    max_interval: float | None = None,
    progress: Callable[[int, int], None] | None = None,
) -> periodic.OrbitBranch:
    """:func:`~cosserat_chain.numerics.periodic.continue_orbit` by collocation: the orbit followed towards smaller |M|.

    The orbit is solved again by collocation (:func:`find_collocation_orbit`, from it; a
    :class:`CollocationOrbit` is taken as it is), followed by
    :func:`continue_collocation` down to |M| = ``moment_min`` or a period beyond ``period_max``, and
    returned as :meth:`CollocationBranch.orbit_branch`. Its cost does not grow with the period,
    where the shooting's does (docs/collocation.md), so a branch towards a homoclinic or SNIC end
    reaches long periods. ``max_interval`` is :func:`continue_collocation`'s (the longest interval in time units).

    Raises
    ------
    ValueError
        For a ``moment_min`` not between 0 and |M|, or a ``period_max`` not above the orbit's period.
    CollocationError
        If the orbit cannot be solved by collocation.
    """
    if not (math.isfinite(moment_min) and 0.0 <= moment_min < abs(orbit.moment)):
        raise ValueError(f"moment_min must lie between 0 and |M| = {abs(orbit.moment)!r}, got {moment_min!r}")
    start = orbit
    if not isinstance(orbit, CollocationOrbit):
        start = find_collocation_orbit(orbit.params, orbit.model, orbit.moment, turns=orbit.turns, particle=orbit.particle, guess=orbit)
    sign = math.copysign(1.0, orbit.moment)
    bounds = (moment_min, math.inf) if sign > 0 else (-math.inf, -moment_min)
    branch = continue_collocation(
        start, moment_min=bounds[0], moment_max=bounds[1], period_max=period_max, direction=-sign, max_points=max_points,
        max_interval=max_interval, progress=progress,
    )  # fmt: skip
    return branch.orbit_branch({"moment_min": moment_min, "period_max": period_max})


#: The most a bracket orbit's trivial multiplier may be off for it to tell on which side of +1 the others lie
#: (:func:`_crossing_between`; the junctions' thirteenth fold has an orbit of its step 0.017 off, the others 1e4 and
#: more away from +1).
BRACKET_TRIVIAL = 0.1


@dataclass
class _BranchProblem:
    """(C) with M free, for :func:`~cosserat_chain.numerics.kit.continuation` (its ContinuationProblem)."""

    collocation: _Collocation
    template: CollocationOrbit
    moment_range: tuple[float, float]
    period_max: float
    #: The segment ends (for a new mesh) once the period exceeds this.
    remesh_above: float = math.inf
    tol: float = TOL
    #: A fold's or branch point's test of the multipliers (default: the second nearest +1 within :data:`FOLD_MULTIPLIER`).
    second_at_one: Callable[[np.ndarray], bool] | None = None
    #: The continued parameter's name in the messages (a user system's, or the chain's M).
    parameter: str = "M"
    #: The last step's two orbits (:meth:`accept`): a located fold's bracket (:meth:`confirm`).
    step: tuple[CollocationOrbit, CollocationOrbit] | None = None

    def evaluate(self, w: np.ndarray, jacobian: bool) -> Evaluation:
        return self.collocation.evaluate(w, jacobian)

    def correct(self, w: np.ndarray, t: np.ndarray, h: float, jacobian):
        """The kit's chord corrector with the arclength row appended to the sparse system (:class:`_SparseStep`)."""
        border = (t, w + h * t)
        return newton(
            self.evaluate, w + h * t, tol=self.tol, divergence=None, damping=MAX_HALVINGS, chord=CHORD_RATE,
            newton_step=_SparseStep(border, self.collocation.elimination_order(True)),
        )  # fmt: skip

    def point(self, w: np.ndarray, evaluation: Evaluation, iterations: int) -> CollocationOrbit:
        profile, period, moment = self.collocation.unpack(w)
        a_values, _ = evaluation.data
        found = self.collocation.floquet(a_values, period)
        return dataclasses.replace(
            self.template, moment=moment, period=period, mesh=self.collocation.mesh, profile=profile,
            multipliers=found.values, residual=float(np.max(np.abs(evaluation.residual))), iterations=iterations,
            multiplier_log_moduli=found.log_moduli,
        )  # fmt: skip

    def accept(self, previous: CollocationOrbit, candidate: CollocationOrbit) -> bool:
        # A multiplier near the unit circle that moves farther than the shooting's budget can hide a pair of
        # crossings of +1 within one step (two branch points of the nonlinear N = 1 orbit lie 5e-4 apart in M):
        # the step is retaken shorter. AUTO's practice otherwise: the phase reference is the last point.
        before, after = _complete(previous), _complete(candidate)
        if periodic._multiplier_motion(before, after) > periodic.MAX_MULTIPLIER_MOTION:
            return False
        self.collocation.set_reference(candidate.profile)
        self.step = (previous, candidate)
        return True

    def tests(self, point: CollocationOrbit) -> dict[str, float]:
        return circle_tests(point.nontrivial_multipliers)

    def stop(self, point: CollocationOrbit) -> tuple[BranchEnd, str] | None:
        if point.period > self.period_max:
            return BranchEnd.INFINITE_PERIOD, (
                f"the period reached {point.period:.6g} > period_max={self.period_max:g} at {self.parameter}={point.moment!r}: "
                "raise period_max to follow the period further (the end is this last orbit's moment, not a fit)"
            )
        low, high = self.moment_range
        if not low <= point.moment <= high:
            return (
                BranchEnd.PARAMETER_LIMIT,
                f"{self.parameter}={point.moment!r} left [{low!r}, {high!r}]: " + BranchEnd.PARAMETER_LIMIT.advice,
            )
        if point.period > self.remesh_above:
            return BranchEnd.MAX_POINTS, "the period grew: a new mesh"
        return None

    def locate(self, kind: str, w, t, h, previous, candidate, index: int) -> Event | None:
        """Folds, branch points, period doublings and tori are located by the kit (None); other sign changes are left where they were seen."""
        if kind in ("fold", "branch_point", *CIRCLE_KINDS):
            return None
        return Event(kind, candidate, candidate.moment, index, None, located=False)

    def confirm(self, kind: str, point: CollocationOrbit) -> bool:
        """A fold or branch point of cycles needs a second multiplier at +1 (issue 40's first item): within
        :data:`FOLD_MULTIPLIER`; a period doubling a multiplier at -1, a torus a complex pair on the circle:
        within :data:`~.cycle_events.CIRCLE_MULTIPLIER` (a pair outside the circle that turns real also changes the torus test's sign).
        A fold whose located orbit does not resolve its multipliers (next to a saddle-focus, ||M|| ~ 1e14 and the trivial
        one lost) is confirmed by a real multiplier through +1 between the step's two orbits (:func:`_crossing_between`)."""
        if kind in CIRCLE_KINDS:
            return on_circle(point.nontrivial_multipliers, kind)
        if kind not in ("fold", "branch_point"):
            return True
        if self.second_at_one is not None:
            at_one = self.second_at_one(point.multipliers)
        else:
            at_one = bool(np.sort(np.abs(point.multipliers - 1.0))[1] < FOLD_MULTIPLIER)
        return at_one or (kind == "fold" and self.step is not None and _crossing_between(*self.step))


def _crossing_between(before, after) -> bool:
    """Whether a real nontrivial multiplier crosses +1 between two orbits: the sign of Re prod (mu - 1) over the
    nontrivial ones changes (a complex pair's factor is positive; a -1's does not change sign). Each orbit must know all
    its multipliers and decide that sign: its trivial one off 1 by e < :data:`BRACKET_TRIVIAL`, every other farther
    than 2 e from +1."""

    def sign(orbit) -> float:
        error = abs(orbit.trivial_multiplier - 1.0)
        others = orbit.nontrivial_multipliers
        if orbit.multipliers.size != orbit.profile.shape[1] or not error < BRACKET_TRIVIAL or np.min(np.abs(others - 1.0)) <= 2 * error:
            return math.nan
        return float(np.real(np.prod(others - 1.0)))

    return sign(before) * sign(after) < 0


def _complete(orbit: CollocationOrbit) -> np.ndarray:
    """The multipliers the step's motion check compares: all of them, or of a long chain's leading ones
    (collocation_core.ALL_MULTIPLIERS_UP_TO) those nearer the shift than its ``LEADING_MULTIPLIERS``-th nearest,
    which no orbit can miss; within a damped ring of nearly equal moduli the members found change from orbit to orbit."""
    multipliers = orbit.multipliers
    if multipliers.size == orbit.profile.shape[1]:
        return multipliers
    distance = np.abs(multipliers - SHIFT)
    radius = np.sort(distance)[min(LEADING_MULTIPLIERS, distance.size) - 1]
    return multipliers[distance < radius]


@one_blas_thread
def continue_collocation(
    orbit: CollocationOrbit,
    *,
    moment_min: float = -math.inf,
    moment_max: float = math.inf,
    period_max: float = PERIOD_MAX,
    direction: float = -1.0,
    step: float = 0.02,
    min_step: float = 1e-7,
    max_step: float = 0.3,
    max_points: int = 400,
    remesh_every: int = REMESH_EVERY,
    ntst: int | None = None,
    max_interval: float | None = None,
    ntst_max: int = NTST_MAX,
    progress: Callable[[int, int], None] | None = None,
) -> CollocationBranch:
    """Follow a collocation orbit in M by pseudo-arclength (module docstring), downwards by default.

    The unknowns are the profile (scaled to its mean square norm), log T (steps of one size while
    T grows without bound towards a homoclinic end) and M. Every ``remesh_every`` points the mesh
    is adapted to the last orbit (and sooner once the period has grown by :data:`REMESH_GROWTH`)
    and the driver restarts there with the tangent interpolated.

    Parameters
    ----------
    orbit : CollocationOrbit
        The start.
    moment_min, moment_max : float
        The range of M.
    period_max : float
        The branch ends as ``infinite_period`` beyond this period.
    direction : float
        -1 towards smaller M, +1 towards larger.
    step, min_step, max_step : float
        Arclength steps of :func:`~cosserat_chain.numerics.kit.continuation`.
    max_points : int
    remesh_every : int
        Points between mesh adaptations (>= 2).
    ntst : int, optional
        Mesh intervals along the branch (default: the start's). Towards a homoclinic end the
        period comes out right on coarse meshes, the strongly damped multipliers do not (an
        interval spanning many damping times damps too little): the message warns where the
        trivial multiplier's error exceeds :data:`TRIVIAL_WARNING`, and a finer mesh cures it.
    max_interval : float, optional
        Longest interval in time units: at each adaptation ntst is raised to 2 T / ``max_interval``
        (at most ``ntst_max``) and the monitor floored at its mean, so that every interval is that
        short. The damped modes then stay resolved and the multipliers right as T grows, at a cost
        that grows with T (the orbit and its period alone need no such bound).
    ntst_max : int
        The most intervals ``max_interval`` may ask for.
    progress : callable(points, max_points), optional

    Returns
    -------
    CollocationBranch

    Raises
    ------
    ValueError
        For a bad range, period_max, direction or remesh_every.
    """
    system = periodic._System(orbit.params, get_model(orbit.model), orbit.moment, orbit.particle)
    shift = _shift(system, orbit.particle_turns)
    return trace_collocation(
        orbit, lambda mesh, profile: _Collocation(system, mesh, orbit.ncol, shift, profile, free_moment=True),
        moment_min=moment_min, moment_max=moment_max, period_max=period_max, direction=direction, step=step, min_step=min_step,
        max_step=max_step, max_points=max_points, remesh_every=remesh_every, ntst=ntst, max_interval=max_interval,
        ntst_max=ntst_max, progress=progress,
    )  # fmt: skip


def trace_collocation(
    orbit,
    build: Callable[[np.ndarray, np.ndarray], _Collocation],
    *,
    moment_min: float,
    moment_max: float,
    period_max: float,
    direction: float,
    step: float,
    min_step: float,
    max_step: float,
    max_points: int,
    remesh_every: int,
    ntst: int | None,
    max_interval: float | None,
    ntst_max: int,
    progress: Callable[[int, int], None] | None,
    stop_at: tuple[str, ...] = ("fold",),
    fold_message: str = periodic.FOLD_OF_CYCLES,
    second_at_one: Callable[[np.ndarray], bool] | None = None,
    parameter: str = "M",
) -> CollocationBranch:
    """:func:`continue_collocation`'s loop for any orbit with its fields (``moment`` the continued parameter's value,
    ``period``, ``mesh``, ``ncol``, ``profile``, ``multipliers``): ``build(mesh, profile)`` poses (C) with the parameter
    free on a new mesh (:mod:`~cosserat_chain.numerics.system_collocation` for a user's system). ``stop_at`` = () follows
    the branch through its folds (each an event); ``second_at_one(multipliers)`` replaces :class:`_BranchProblem`'s test that
    confirms a fold or branch point; ``parameter`` names the continued parameter in the messages; the other arguments and
    the errors are :func:`continue_collocation`'s.
    """
    if not moment_min < moment_max or math.isnan(moment_min) or math.isnan(moment_max):
        raise ValueError(f"moment_min must be < moment_max, got {moment_min!r}, {moment_max!r}")
    if not (math.isfinite(period_max) and period_max > orbit.period):
        raise ValueError(f"period_max must be finite and above the start's period {orbit.period:.6g}, got {period_max!r}")
    if direction not in (-1, 1, -1.0, 1.0):
        raise ValueError(f"direction must be -1 or +1, got {direction!r}")
    if not (isinstance(remesh_every, int) and remesh_every >= 2):
        raise ValueError(f"remesh_every must be an integer >= 2, got {remesh_every!r}")
    if not (isinstance(max_points, int) and max_points >= 1):
        raise ValueError(f"max_points must be an integer >= 1, got {max_points!r}")
    if max_interval is not None and not (math.isfinite(max_interval) and max_interval > 0):
        raise ValueError(f"max_interval must be a finite number > 0 (time units) or None, got {max_interval!r}")
    ntst = orbit.ntst if ntst is None else ntst
    check_mesh(ntst, orbit.ncol)
    sch = scheme(orbit.ncol)
    orbits, events = [orbit], []
    current, tangent0, adaptations = orbit, None, 0
    end, message = BranchEnd.MAX_POINTS, f"stopped after max_points={max_points} points: " + BranchEnd.MAX_POINTS.advice
    while len(orbits) < max_points:
        if max_interval is None:
            mesh = _adapted_mesh(current.mesh, current.profile, sch, ntst)
        else:
            intervals = min(ntst_max, max(ntst, math.ceil(2.0 * current.period / max_interval)))
            mesh = _adapted_mesh(current.mesh, current.profile, sch, intervals, floor=1.0)
        profile = _interpolate(current.mesh, current.profile, sch, _node_times(mesh, sch))
        if tangent0 is not None:
            nodes = current.profile.shape[0]
            moved = _interpolate(current.mesh, tangent0[:-2].reshape(nodes, -1) * math.sqrt(nodes), sch, _node_times(mesh, sch))
            adaptations += 1
        collocation = build(mesh, profile)
        if tangent0 is not None:
            tangent0 = np.concatenate([collocation.scale * moved.ravel(), tangent0[-2:]])
        growth = REMESH_GROWTH if max_interval is None else 1.25
        problem = _BranchProblem(
            collocation,
            current,
            (moment_min, moment_max),
            period_max,
            growth * current.period,
            second_at_one=second_at_one,
            parameter=parameter,
        )
        count = min(remesh_every, max_points - len(orbits) + 1)
        traced = continuation(
            problem, collocation.pack(profile, current.period, current.moment), step=step, min_step=min_step, max_step=max_step,
            max_points=count, direction=direction, tangent0=tangent0, stop_at=stop_at, locate=True,
        )  # fmt: skip
        orbits.extend(traced.points[1:])
        events.extend(_event_record(e) for e in traced.events)
        if progress is not None:
            progress(len(orbits), max_points)
        if traced.end != BranchEnd.MAX_POINTS or len(traced.points) < 2:
            end, message = traced.end, (fold_message if traced.end == BranchEnd.FOLD else traced.message)
            break
        current = traced.points[-1]
        step = min(max_step, max(min_step, _last_step(traced.points)))
        tangent0 = _secant(collocation, traced.points[-2], traced.points[-1])
    worst = max(orbits, key=lambda o: o.trivial_multiplier_error)
    if worst.trivial_multiplier_error > TRIVIAL_WARNING:
        message += (
            f"; the trivial multiplier is off by {worst.trivial_multiplier_error:.2g} at {parameter}={worst.moment!r} (T={worst.period:.6g}): "
            "the multipliers there are not resolved: raise ntst or give max_interval"
        )
    return CollocationBranch(orbits, end, message, adaptations, events)


def _event_record(event: Event) -> dict:
    """An event of the driver as an entry of :attr:`CollocationBranch.events` (a period doubling's or torus's with its multiplier)."""
    record = {"kind": event.kind, "moment": event.parameter, "located": event.located, "orbit": event.point}
    if event.kind in CIRCLE_KINDS:
        if not event.located:
            # The secant failed: the event is reported at the first orbit past the sign change.
            record["moment"] = event.point.moment
        mu = critical_multiplier(event.point.nontrivial_multipliers, event.kind)
        record["multiplier"] = complex(math.nan, math.nan) if mu is None else mu
        if event.kind == "torus":
            record["angle"] = math.nan if mu is None else float(np.angle(mu))
    return record


def _last_step(points: list[CollocationOrbit]) -> float:
    """A restart's first step: a fraction of the last chord's length in the unknowns' scaled norm (log T and M included)."""
    a, b = points[-2], points[-1]
    scale = 1.0 / math.sqrt(b.profile.shape[0])
    chord = np.concatenate([scale * (b.profile - a.profile).ravel(), [math.log(b.period / a.period), b.moment - a.moment]])
    return max(1e-6, float(np.linalg.norm(chord)))


def _secant(collocation: _Collocation, a: CollocationOrbit, b: CollocationOrbit) -> np.ndarray:
    """The unit secant from a to b in the unknowns of ``collocation`` (both on its mesh)."""
    chord = collocation.pack(b.profile, b.period, b.moment) - collocation.pack(a.profile, a.period, a.moment)
    return chord / np.linalg.norm(chord)
