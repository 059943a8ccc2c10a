"""Branch switching at a period doubling: the orbit of twice the period that emerges there.

Contract
--------
Where a real Floquet multiplier of a rotating orbit (:mod:`~cosserat_chain.numerics.periodic`,
eq. (P), k turns, period T) passes through -1 (a flip, or period doubling: ``period_doubling``
of :mod:`~cosserat_chain.experiments.diagram`, the branch's event located by
:mod:`~cosserat_chain.numerics.cycle_events`), a second family of orbits
leaves it: 2k turns in a period close to 2T. Seen as an orbit of 2k turns, the k-turn orbit
traversed twice has every multiplier squared, the -1 turned into a second +1: there the
doubled family crosses it at a branch point (a pitchfork of the 2T map), tangent to the
eigenvector e of the monodromy matrix for the multiplier -1 (normal form: the doubled orbit's
start y_PD + a e + O(a^2) at the moment M_PD + c a^2 + O(a^3); its period 2 T_PD + O(a^2), its multipliers the
squares of the k-turn orbit's + O(a^2), the -1 become 1 - O(a^2)).

:func:`doubled_orbit` solves for the doubled orbit of amplitude a exactly: Newton's method
(the kit's corrector, :func:`~.kit.newton`) on (P) with 2k turns and the unknowns
(y0, log T, M) of :func:`~.periodic.continue_orbit`'s branch, plus the amplitude condition
e . (y0 - y_PD) = a (the kit's border), from the predictor (y_PD + a e, log 2 T_PD, M_PD);
the phase condition is the located orbit's own (the section phi_0 = const or its phase
plane). The moment is an unknown, so the equations are regular on the doubled branch for
a != 0 (at fixed M they are nearly singular there: the doubled orbit is then within
sqrt(|M - M_PD|) of the double cover). :func:`switch_at_period_doubling` takes the
amplitude from the normal form (a secant in a^2 through two small amplitudes gives c;
the amplitude then puts the first doubled orbit a chosen relative distance in M from the
period doubling), polishes the orbit by :func:`~.periodic.find_periodic_orbit` with 2k
turns, and continues it with :func:`~.periodic.continue_orbit`. The doubled orbits at a and
-a + O(a^2) are the same orbits half their period apart, so both signs of e serve: e's sign is fixed
(:func:`flip_vector`), and where the family's amplitude along it turns back before the probes (the
sine chain's at gamma_phi = 0.15, at 0.0023) the probes are marched along -e.

The doubled family lies below M_PD (in |M|) for a supercritical flip of an orbit that loses
stability as M falls (the doubled orbit inherits its stability), above it for a subcritical
one; :attr:`PeriodDoubling.side` says which. A family below M_PD is continued down by
:func:`~.periodic.continue_orbit`; one above it by :func:`continue_family`, up in |M| and through
its folds of cycles (continued down it would run back into the period doubling).

The same switch serves a user's system (:mod:`~cosserat_chain.numerics.shooting`): from an orbit or
event of :func:`~.shooting.continue_orbits` at a period doubling in any named parameter p, on the
shooting's phase plane (O), the doubled family is continued in p on whichever side it lies.

At a Hopf point of a static branch (:func:`~cosserat_chain.numerics.hopf.hopf_points`: a complex
pair +-i omega of the damped dynamics on the axis) non-rotating orbits are born: :func:`switch_at_hopf`
and :func:`hopf_orbit` solve them the same way, with the chain's shooting and no turns (every
``particle_turns`` 0) on a phase plane, the amplitude along the real part of the eigenvector for
+i omega, from (y_H + a e, 2 pi / omega, M_H): period 2 pi / omega + O(a^2), M_H + c a^2. The
eigenvector's phase and sign, and with them the point the first orbit starts from, are fixed by
:func:`turned_hopf_vector`, not left to LAPACK.
:func:`system_hopf_orbit` does the same at a user system's Hopf point (the located ``hopf`` event of
:func:`~cosserat_chain.numerics.equilibria.continue_equilibria`), on the system's shooting.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np
import scipy.linalg as sla

from ..models.base import Model, get_model
from ..params import ChainParams
from ..state import pack
from ..systems.chain import ChainSystem
from . import shooting
from .cycle_curve import locate_circle_event, locate_cycle_end
from .cycle_events import circle_tests
from .hopf import HopfPoint
from .kit import BranchEnd, continuation, newton
from .periodic import (
    _ORBIT_ENDS,
    ATOL,
    CLOSURE_TOL,
    EASY_ITERATIONS,
    HARD_ITERATIONS,
    MAX_CORRECTOR_ITERATIONS,
    NEWTON_RATE,
    RTOL,
    OrbitBranch,
    OrbitError,
    PeriodicOrbit,
    _crosses_one,
    _from_y,
    _OrbitBranchProblem,
    _phase_for,
    _plane,
    _System,
    _to_y,
    continue_orbit,
    find_periodic_orbit,
)

#: The critical multiplier of a period doubling lies within this of -1 (the located end's is within ~1e-9);
#: an orbit of the chain farther off is located first.
FLIP_TOL = 1e-6
#: Relative distance |p - p_PD| / |p_PD| of the first doubled orbit (from the normal form), by default.
OFFSET = 1e-4
#: The two amplitudes (in the unit eigenvector's norm, units of the state) of the normal form's secant.
PROBE_AMPLITUDES = (2e-3, 4e-3)
#: The probes scaled by these in turn where the family turns back before them (on the sine chain at gamma_phi = 0.15
#: the doubled family's amplitude along one sign of the flip vector turns at 0.0023).
PROBE_SCALES = (1.0, 0.25, 0.0625)
#: Smallest step of the amplitude, relative, while a period doubling's probes are first marched along each sign of the
#: flip vector in turn: a family that turns back before a probe is given up after a few halved steps and the other
#: sign taken (the same doubled orbits, half their period on), where marching to :data:`MIN_STEP` at every scale costs
#: many failed Newton runs (docs/periodic-orbits.md, "After a period doubling").
SIGN_STEP = 0.25
#: Largest amplitude the normal form may ask for (beyond it the quadratic law is not trusted).
MAX_AMPLITUDE = 0.1
#: Relative |sum(v_k^2)| / |v|^2 of a Hopf eigenvector v below which its ellipse is taken for a circle
#: (:func:`turned_hopf_vector`): the major axis's direction carries a round-off of about 1e-16 over this.
CIRCLE_TOL = 1e-6
#: Components of a Hopf eigenvector whose moduli lie within this (relative) of the largest count as equally large
#: (:func:`turned_hopf_vector` takes the first of them): a symmetric system's (the follower rotor's two velocities)
#: differ by round-off only, and which one LAPACK's phase makes the larger must not matter.
TIE_TOL = 1e-10
#: Smallest step of the amplitude, relative to the last one reached (or the first probe), after failed steps are
#: halved: the orbits born at the N = 2 sine chain's second Hopf point have a multiplier exp(2.07 T) = 1.3e6,
#: and single shooting needs amplitudes near 4e-5 there before the predictor's O(a^2) error is amplified too far.
MIN_STEP = 1e-3
#: The same where an orbit far enough out serves (``_March.to``'s ``enough``) and one beyond the probes is solved: the
#: family is then followed by arclength from the largest reached (creeping to where the amplitude turns costs more).
ENOUGH_STEP = 0.1
#: Newton iterations of one orbit of the new family.
MAX_ITERATIONS = 20
#: A solution whose k-turn closure after half its period (at a Hopf point: whose velocity field) is within this
#: many times the Newton tolerance is the k-turn orbit traversed twice (the equilibrium), not a new orbit.
HALF_CLOSURE = 1e3

Point = PeriodicOrbit | shooting.Orbit


@dataclass
class PeriodDoubling:
    """The switch from a k-turn orbit to its period-doubled family (module docstring).

    Attributes
    ----------
    point : PeriodicOrbit or shooting.Orbit
        The located period doubling (period T_PD, a multiplier at -1).
    parameter : str
        The parameter p it lies in: ``M`` for the chain, a system's parameter name otherwise.
    value : float
        p_PD.
    multiplier : complex
        Its critical multiplier (-1 to the located accuracy).
    eigenvector : ndarray (2n,)
        Real unit eigenvector e of the monodromy matrix for it, in the shooting's state y = (q, q'), along
        which ``amplitude`` is measured: :func:`flip_vector`'s, or its opposite where the normal form's probes
        failed along that sign (:func:`switch_at_period_doubling`).
    coefficient : float
        c of p - p_PD = c a^2 on the doubled family (secant through two amplitudes; for the chain
        signed towards larger |M|).
    amplitude : float
        a of the first doubled orbit.
    doubled : PeriodicOrbit or shooting.Orbit
        The first doubled orbit: twice the turns, period near 2 T_PD.
    side : str
        ``below`` (the doubled family exists at smaller p, for the chain smaller |M|, than the period
        doubling) or ``above``.
    branch : periodic.OrbitBranch or shooting.OrbitBranch or None
        The doubled family continued away from the period doubling from ``doubled`` (None where not
        asked for; for the chain above the period doubling, :func:`continue_family`'s up in |M|).
    """

    point: Point
    parameter: str
    value: float
    multiplier: complex
    eigenvector: np.ndarray
    coefficient: float
    amplitude: float
    doubled: Point
    side: str
    branch: Any

    def as_dict(self) -> dict:
        """JSON-ready summary."""
        return {
            "parameter": self.parameter,
            "value": self.value,
            "period": self.point.period,
            "multiplier": [self.multiplier.real, self.multiplier.imag],
            "coefficient": self.coefficient,
            "amplitude": self.amplitude,
            "side": self.side,
            "doubled": self.doubled.as_dict(),
            "branch": None if self.branch is None else self.branch.as_dict() if isinstance(self.branch, shooting.OrbitBranch) else {
                "end": self.branch.end, "end_moment": self.branch.end_moment, "message": self.branch.message
            },
        }  # fmt: skip


def flip_vector(point: Point, *, rtol: float = RTOL, atol: float = ATOL) -> tuple[complex, np.ndarray]:
    """The multiplier of ``point`` nearest -1 among the real negative ones, and its real unit eigenvector.

    A chain's monodromy matrix is integrated again (a :class:`~.periodic.PeriodicOrbit` keeps only its
    multipliers); a system's orbit carries its own. The eigenvector's sign is fixed, its component of largest
    modulus (the first of equal ones to :data:`TIE_TOL`) positive: LAPACK's sign is arbitrary, and with it the sign of e along
    which :func:`switch_at_period_doubling` first marches.

    Raises
    ------
    OrbitError
        Where the orbit has no real negative multiplier.
    """
    if isinstance(point, shooting.Orbit):
        mono = point.monodromy
    else:
        system = _System(point.params, get_model(point.model), point.moment, point.particle)
        _, mono, _ = system.flow(_to_y(point.params, point.x, point.v), point.period, rtol=rtol, atol=atol, variations=True)
    values, vectors = sla.eig(mono)
    real = np.abs(values.imag) <= 1e-6 * np.abs(values)
    candidates = np.flatnonzero(real & (values.real < 0))
    if candidates.size == 0:
        raise OrbitError(f"the orbit at {_where(point)} has no real negative Floquet multiplier: no period doubling")
    i = candidates[np.argmin(np.abs(values[candidates] + 1.0))]
    vector = np.real(vectors[:, i])
    vector = vector / np.linalg.norm(vector)
    return complex(values[i]), vector if vector[_largest(vector)] > 0 else -vector


def _where(point: Point, parameter: str | None = None) -> str:
    if isinstance(point, shooting.Orbit):
        return point.system.name if parameter is None else f"{parameter}={point.parameter(parameter)!r}"
    return f"M={point.moment!r}"


def doubled_orbit(
    point: Point,
    amplitude: float,
    *,
    parameter: str | None = None,
    eigenvector: np.ndarray | None = None,
    tol: float = CLOSURE_TOL,
    rtol: float = RTOL,
    atol: float = ATOL,
) -> Point:
    """The period-doubled orbit of amplitude ``amplitude`` along the flip eigenvector at the period doubling ``point``.

    Parameters
    ----------
    point : PeriodicOrbit or shooting.Orbit
        The located period doubling (a branch's ``period_doubling`` event, :mod:`~.cycle_events`: for the chain
        its ``"orbit"``, for a system the ``point`` of :func:`~.shooting.continue_orbits`' event).
    amplitude : float
        a != 0 of e . (y0 - y_PD) = a (module docstring); its sign picks one of the two starts of the
        same doubled orbit, half a period apart. Beyond the first of :data:`PROBE_AMPLITUDES` the
        orbit is reached by doubling the amplitude, each orbit predicted by the parabola in a
        through the period doubling and the two orbits before (a step that fails is halved).
    parameter : str, optional
        For a system's orbit: the parameter that is unknown beside the period (required); the
        chain's is M.
    eigenvector : ndarray (2n,), optional
        e, from :func:`flip_vector` by default.
    tol, rtol, atol : float
        As for :func:`~.periodic.find_periodic_orbit`.

    Returns
    -------
    PeriodicOrbit or shooting.Orbit
        Twice the turns, at the parameter value the amplitude fixes (near p_PD), its multipliers computed.

    Raises
    ------
    ValueError
        For a zero or non-finite amplitude, or a system's orbit without ``parameter``.
    OrbitError
        Where Newton's method does not converge.
    """
    if not (math.isfinite(amplitude) and amplitude != 0):
        raise ValueError(f"amplitude must be a finite non-zero number (along the flip eigenvector), got {amplitude!r}")
    if eigenvector is None:
        eigenvector = flip_vector(point, rtol=rtol, atol=atol)[1]
    march = _march(point, parameter, math.copysign(1.0, amplitude) * eigenvector, tol, rtol, atol)
    return march.to(abs(amplitude))


class _March:
    """Orbits of growing amplitude on the family that leaves a bifurcation (:func:`doubled_orbit`, :func:`hopf_orbit`).

    Newton on ``evaluate`` (the shooting residual R(w), w = (y0's unknowns, log T, p)) with the amplitude
    a = e . (w - base) fixed by the kit's border, from ``base`` (the bifurcation's w) and e the unit
    critical eigenvector ``tangent`` in w (the flip's, or the real part of the Hopf pair's). Two solution
    sets meet at ``base``: the new family, tangent to e, and the one it leaves (the k-turn orbit traversed
    twice, the equilibrium), tangent to ``tau``. The border e meets the second one O(a) away, and on the
    sine chain at gamma_phi = 0.15 Newton went there: a solution ``refuse`` rejects is not taken, and the
    step is taken again with the border d, e made orthogonal to tau, which meets it only O(sqrt(a)) away.
    """

    def __init__(
        self, evaluate, make_point: Callable, base: np.ndarray, tangent: np.ndarray, tau: np.ndarray, refuse: Callable, tol: float,
        where: str,
    ):  # fmt: skip
        norm = float(np.linalg.norm(tangent))
        if norm < 0.1:
            raise OrbitError(f"the critical eigenvector at {where} lies along the phase condition: no amplitude can be set")
        self.tangent = tangent / norm
        tau = tau / np.linalg.norm(tau)
        direction = self.tangent - (self.tangent @ tau) * tau
        if np.linalg.norm(direction) < 0.1:
            raise OrbitError(f"the critical eigenvector at {where} is nearly the old branch's tangent: a degenerate bifurcation")
        self.direction = direction / np.linalg.norm(direction)
        self.evaluate, self.make_point, self.refuse, self.tol, self.where = evaluate, make_point, refuse, tol, where
        #: (amplitude, w) of the new family, from its limit at the bifurcation (a = 0) on.
        self.done: list[tuple[float, np.ndarray]] = [(0.0, np.array(base, dtype=float))]

    def _predict(self, amplitude: float) -> np.ndarray:
        """The parabola in a through the last three solutions (the tangent e at the period doubling before two)."""
        if len(self.done) < 3:
            return self.done[-1][1] + (amplitude - self.done[-1][0]) * self.tangent
        (a0, w0), (a1, w1), (a2, w2) = self.done[-3:]
        l0 = (amplitude - a1) * (amplitude - a2) / ((a0 - a1) * (a0 - a2))
        l1 = (amplitude - a0) * (amplitude - a2) / ((a1 - a0) * (a1 - a2))
        l2 = (amplitude - a0) * (amplitude - a1) / ((a2 - a0) * (a2 - a1))
        return l0 * w0 + l1 * w1 + l2 * w2

    def solve(self, amplitude: float):
        """The doubled orbit near the prediction at ``amplitude`` (above the last one solved), None where Newton fails.

        The border through the prediction is e's first (Newton converges from farther there: on the nonlinear
        chain d's stalled), d's where that fails or reaches the old branch; the orbit is recorded at
        its own amplitude e . (w - base), which d's border leaves within O(a^2) of ``amplitude``. Asked beyond
        the last one solved, an orbit at an amplitude not beyond it is not taken (asked below it, one at a
        negative amplitude): a doubled orbit at a is the one at -a + O(a^2) half a period on, and from a = 0.004
        on the sine chain at gamma_phi = 0.15 Newton went there (a = -0.0061).
        """
        predictor = self._predict(amplitude)
        for border in (self.tangent, self.direction):
            solved = newton(
                self.evaluate, predictor, tol=self.tol, border=(border, predictor), max_iterations=MAX_ITERATIONS, divergence=None,
                damping=6,
            )  # fmt: skip
            reached = float(self.tangent @ (solved.w - self.done[0][1]))
            onward = reached > self.done[-1][0] if amplitude > self.done[-1][0] else reached > 0.0
            if solved.converged and onward and not self.refuse(solved.w):
                self.done.append((reached, solved.w))
                return self.make_point(solved.w, solved.evaluation, solved.iterations)
        return None

    def to(self, amplitude: float, enough: Callable[[Any], bool] | None = None, min_step: float = MIN_STEP):
        """The doubled orbit at ``amplitude`` > 0, in steps from the largest one solved: each at most doubles the
        amplitude, a failed one is halved down to ``min_step`` (relative). With ``enough``, the first orbit it
        accepts on the way is returned, or the largest one reached where the steps beyond it fail down to
        :data:`ENOUGH_STEP`."""
        last, orbit = self.done[-1][0], None
        a = min(amplitude, max(PROBE_AMPLITUDES[0], 2 * last))
        while True:
            found = self.solve(a)
            if found is not None:
                # The amplitude reached, which the border d leaves O(a^2) off the one asked for.
                orbit, last = found, self.done[-1][0]
                if last >= (1.0 - MIN_STEP) * amplitude or (enough is not None and enough(orbit)):
                    return orbit
                a = min(amplitude, 2 * last)
            elif a - last > (min_step if enough is None or orbit is None else ENOUGH_STEP) * max(last, PROBE_AMPLITUDES[0]):
                a = 0.5 * (a + last)
            elif enough is not None and orbit is not None:
                return orbit  # the family turns back or Newton fails beyond: the largest amplitude reached
            else:
                raise OrbitError(
                    f"Newton did not converge to the orbit of amplitude {a!r} on the family leaving the bifurcation at {self.where}; "
                    f"the family may turn back before amplitude {amplitude!r}: try a smaller amplitude"
                )


def _normal_form(
    new_march: Callable[[float], _March], distance: Callable[[Any], float], signs: tuple[float, ...] = (1.0,)
) -> tuple[_March, float, float, float]:
    """The march, its larger probe amplitude, c of the normal form p - p_* = c a^2 + O(a^3) on the new family, and the
    sign of the critical eigenvector it marched along (``new_march(sign)``).

    c by a secant in a^2 through the orbits at :data:`PROBE_AMPLITUDES` (a and -a + O(a^2) start one doubled orbit,
    half a period apart), at their amplitudes reached. With two ``signs`` (a period doubling: both start the same
    doubled orbits), the probes are first marched along each in turn down to steps of :data:`SIGN_STEP`; where
    that fails, and with one sign, the probes scaled down by :data:`PROBE_SCALES` on a fresh march for each sign,
    steps down to :data:`MIN_STEP`.
    """
    tries = [(1.0, sign, SIGN_STEP) for sign in signs] if len(signs) > 1 else []
    tries += [(scale, sign, MIN_STEP) for scale in PROBE_SCALES for sign in signs]
    failure: OrbitError | None = None
    for scale, sign, min_step in tries:
        march, probes = new_march(sign), []
        try:
            for a in PROBE_AMPLITUDES:
                orbit = march.to(scale * a, min_step=min_step)
                probes.append((march.done[-1][0], distance(orbit)))
        except OrbitError as err:
            failure = err
            continue
        (a1, d1), (a2, d2) = probes
        return march, a2, (d2 - d1) / (a2 * a2 - a1 * a1), sign
    raise failure


def _march(point: Point, parameter: str | None, eigenvector: np.ndarray, tol: float, rtol: float, atol: float) -> _March:
    """The doubled family's equations at ``point``: the chain's (P) with twice the turns on the located orbit's phase
    condition, or a system's (O) with twice the turns on the plane through the point, the period and p unknown.
    The old branch is the k-turn orbit's (tau: the null vector of its own shooting Jacobian); a solution that
    closes after half its period (to :data:`HALF_CLOSURE` tol) is that orbit traversed twice."""
    if isinstance(point, shooting.Orbit):
        if parameter is None:
            raise ValueError("parameter must name the system's parameter of the period doubling (the unknown beside the period)")
        point.parameter(parameter)
        unknowns = (shooting.PERIOD, parameter)
        problem = shooting._Shooting(point.system, 2 * point.turns, point.y0, 2 * point.period, unknowns, tol, rtol, atol)
        single = shooting._Shooting(point.system, point.turns, point.y0, point.period, unknowns, tol, rtol, atol).evaluate
        base = np.concatenate([point.y0, [math.log(2 * point.period), point.parameter(parameter)]])
        tangent = np.concatenate([eigenvector, [0.0, 0.0]])
        evaluate, make_point, where = problem.evaluate, problem.orbit, _where(point, parameter)
    else:
        model = get_model(point.model)
        system = _System(point.params, model, point.moment, point.particle)
        phase = _phase_for(system, _to_y(point.params, point.x, point.v), point.phase_normal)
        start = dataclasses.replace(point, turns=2 * point.turns, period=2 * point.period, particle_turns=2 * point.particle_turns)
        problem = _OrbitBranchProblem(start, model, phase, tol, rtol, atol, 0.0, math.inf, False, False, consistent=False)
        single = _OrbitBranchProblem(point, model, phase, tol, rtol, atol, 0.0, math.inf, False, False).evaluate
        tangent = np.zeros(phase.head + 2)
        tangent[: phase.head] = eigenvector[phase.keep]
        base, evaluate, make_point, where = problem.pack(start), problem.evaluate, problem.point, _where(point)

    def halved(w: np.ndarray) -> np.ndarray:
        out = np.array(w, dtype=float)
        out[-2] -= math.log(2.0)
        return out

    def closes_at_half(w: np.ndarray) -> bool:
        return float(np.max(np.abs(single(halved(w), False).residual))) <= HALF_CLOSURE * tol

    tau = sla.svd(np.asarray(single(halved(base), True).jacobian))[2][-1]
    return _March(evaluate, make_point, base, tangent, tau, closes_at_half, tol, where)


def switch_at_period_doubling(
    start: PeriodicOrbit | OrbitBranch | shooting.Orbit | shooting.OrbitBranch,
    *,
    parameter: str | None = None,
    amplitude: float | None = None,
    offset: float = OFFSET,
    follow: bool = True,
    tol: float = CLOSURE_TOL,
    rtol: float = RTOL,
    atol: float = ATOL,
    **continue_options,
) -> PeriodDoubling:
    """The period-doubled family that leaves an orbit branch at its period doubling.

    Parameters
    ----------
    start : PeriodicOrbit, periodic.OrbitBranch, shooting.Orbit or shooting.OrbitBranch
        The chain's: the period doubling (an orbit with a real multiplier within :data:`FLIP_TOL` of
        -1), an orbit near one (located first by the augmented Newton, :func:`~.cycle_curve.locate_cycle_end`),
        or a branch of :func:`~.periodic.continue_orbit` along which a real multiplier passes -1: at the first
        such passage (where the period-doubling test of :func:`~.cycle_events.circle_tests` changes sign) the
        branch's own located event (:attr:`~.periodic.OrbitBranch.events`, its orbit and multiplier: -1 to
        2e-12 at gamma_phi = 0.2, the augmented Newton's 2.5e-11) where the branch was traced at these
        tolerances, else the same event located again between the two orbits at them
        (:func:`~.cycle_curve.locate_circle_event`). A system's:
        the orbit at a period doubling (the point of a ``period_doubling`` event), or a branch of
        :func:`~.shooting.continue_orbits` with such an event (the first is taken).
    parameter : str, optional
        A system's parameter of the period doubling (a branch's own by default); the chain's is M.
    amplitude : float, optional
        a of the first doubled orbit along the flip eigenvector (signed as the normal form's probes took it,
        :attr:`PeriodDoubling.eigenvector`); by default the normal form's
        amplitude for |p - p_PD| = ``offset`` |p_PD| (capped at :data:`MAX_AMPLITUDE`; the orbit lies
        about that far from p_PD, or nearer where the family bends away from c a^2 sooner).
    offset : float
        Relative distance in p of the first doubled orbit from the period doubling (default amplitude only).
    follow : bool
        Continue the doubled family away from the period doubling: the chain's down in |M|
        (:func:`~.periodic.continue_orbit`) where it lies below, up through its folds
        (:func:`continue_family`) where it lies above; a system's in p on its side
        (:func:`~.shooting.continue_orbits`).
    tol, rtol, atol : float
        As for :func:`~.periodic.find_periodic_orbit`.
    **continue_options
        Passed to the continuation (``period_max``, ``max_points``, ...).

    Returns
    -------
    PeriodDoubling

    Raises
    ------
    ValueError
        For a branch without a passage of -1, bad amplitudes or offsets, a system without its parameter,
        or where the period doubling cannot be located.
    OrbitError
        Where the doubled orbit is not found.
    """
    if not (math.isfinite(offset) and 0 < offset < 1):
        raise ValueError(f"offset must be a number in (0, 1) (relative distance in the parameter), got {offset!r}")
    point, parameter = _located(start, parameter, tol=tol, rtol=rtol, atol=atol)
    system = isinstance(point, shooting.Orbit)
    value = point.parameter(parameter) if system else point.moment
    # p - p_PD, for the chain positive towards larger |M|.
    sign = 1.0 if system else math.copysign(1.0, point.moment)

    def distance(orbit) -> float:
        return sign * ((orbit.parameter(parameter) if system else orbit.moment) - value)

    multiplier, vector = flip_vector(point, rtol=rtol, atol=atol)
    if abs(multiplier + 1.0) > FLIP_TOL:
        raise ValueError(
            f"the orbit at {_where(point, parameter)} has its multiplier nearest -1 at {multiplier:.6g}: not a located period "
            "doubling (take the point of continue_orbits' period_doubling event)"
        )
    march, probe, coefficient, along = _normal_form(
        lambda along: _march(point, parameter, along * vector, tol, rtol, atol), distance, signs=(1.0, -1.0)
    )
    if coefficient == 0:
        raise OrbitError(f"the doubled family at {_where(point, parameter)} does not move with its amplitude (a degenerate flip)")
    vector = along * vector
    if amplitude is None:
        # The normal form's amplitude, approached in steps: the family bends away from c a^2 within a few times the
        # probes on the sine chain at gamma_phi = 0.3, so the first orbit at the wanted distance from p_PD serves.
        wanted = offset * (abs(value) if value != 0 else 1.0)
        guess = max(probe, min(MAX_AMPLITUDE, math.sqrt(wanted / abs(coefficient))))
        doubled = march.to(guess, enough=lambda o: abs(distance(o)) >= wanted)
        amplitude = march.done[-1][0]
    else:
        doubled = doubled_orbit(point, amplitude, parameter=parameter, eigenvector=vector, tol=tol, rtol=rtol, atol=atol)
    side = "below" if distance(doubled) < 0 else "above"
    if system:
        doubled = shooting.find_orbit(doubled.system, doubled, tol=tol, rtol=rtol, atol=atol)
        direction = -1.0 if side == "below" else 1.0
        branch = (
            shooting.continue_orbits(doubled, parameter, direction=direction, tol=tol, rtol=rtol, atol=atol, **continue_options)
            if follow
            else None
        )
    else:
        doubled = find_periodic_orbit(
            point.params, point.model, doubled.moment, turns=doubled.turns, particle=point.particle, guess=doubled, tol=tol,
            rtol=rtol, atol=atol,
        )  # fmt: skip
        branch = None
        if follow and side == "below":
            branch = continue_orbit(doubled, tol=tol, rtol=rtol, atol=atol, **continue_options)
        elif follow:
            branch = continue_family(doubled, tol=tol, rtol=rtol, atol=atol, **continue_options)
    return PeriodDoubling(point, parameter, float(value), multiplier, vector, float(coefficient), float(amplitude), doubled, side, branch)


@dataclass
class HopfOrbits:
    """The periodic orbits born at a Hopf point of a static branch (module docstring).

    Attributes
    ----------
    point : HopfPoint
        The located Hopf point (moment M_H, frequency omega).
    eigenvalue : complex
        The crossing eigenvalue of the damped dynamics there (+i omega to the located accuracy).
    eigenvector : ndarray (2n,) complex
        Its eigenvector, turned by :func:`turned_hopf_vector` (real and imaginary parts orthogonal, the real part
        of unit length and its largest component positive): the same whatever phase LAPACK gave it.
    coefficient : float
        c of M - M_H = c a^2 on the family (secant through two amplitudes; signed towards larger |M|).
    amplitude : float
        a of the first orbit along the real part of the eigenvector.
    orbit : PeriodicOrbit
        The first orbit: no turns (``turns`` 0, every ``particle_turns`` 0), period near 2 pi / omega, on
        the phase plane through it normal to the flow.
    side : str
        ``below`` (the orbits exist at smaller |M| than the Hopf point) or ``above``.
    branch : OrbitBranch or None
        The family continued down in |M| (:func:`~.periodic.continue_orbit`) where it lies below (None
        above, or where not asked for).
    """

    point: HopfPoint
    eigenvalue: complex
    eigenvector: np.ndarray
    coefficient: float
    amplitude: float
    orbit: PeriodicOrbit
    side: str
    branch: OrbitBranch | None

    def as_dict(self) -> dict:
        """JSON-ready summary."""
        return {
            "hopf": self.point.as_dict(),
            "eigenvalue": [self.eigenvalue.real, self.eigenvalue.imag],
            "coefficient": self.coefficient,
            "amplitude": self.amplitude,
            "side": self.side,
            "orbit": self.orbit.as_dict(),
            "branch": None if self.branch is None else {"end": self.branch.end, "end_moment": self.branch.end_moment},
        }


def turned_hopf_vector(vector: np.ndarray) -> np.ndarray:
    """A Hopf eigenvector v (2n,) complex, its phase and sign fixed: the same for v exp(i theta), any theta.

    v exp(i phi) traces the ellipse Re(v exp(i phi)) of the linearised oscillation; the turn puts its real part
    on the major axis (real and imaginary parts orthogonal, the real part the longer: sum(v_k^2) real and
    positive) and the real part's component of largest modulus (the first of equal ones, :data:`TIE_TOL`)
    positive, and scales the real part to unit length. LAPACK returns v with an arbitrary phase and sign, and the real part e is the
    direction :func:`switch_at_hopf` first marches along, so without the turn its first orbit (the point on
    the orbit it starts from, at e . (y0 - y_H) = a) would depend on the LAPACK build. Where the ellipse is a
    circle to :data:`CIRCLE_TOL` (sum(v_k^2) within it of 0 relative to |v|^2: every direction in its plane a
    major axis) the component of v of largest modulus is made real and positive instead.

    Parameters
    ----------
    vector : ndarray (2n,) complex
        An eigenvector for the crossing eigenvalue near +i omega, any phase and length.

    Returns
    -------
    ndarray (2n,) complex
        v exp(i phi) / |Re(v exp(i phi))|.
    """
    vector = np.asarray(vector, dtype=complex)
    square = np.sum(vector * vector)
    if abs(square) > CIRCLE_TOL * float(np.vdot(vector, vector).real):
        # sum(v^2) is unchanged by v -> -v, so LAPACK's sign changes no bit before the sign below is fixed.
        vector = vector * np.exp(-0.5j * np.angle(square))
        real = np.real(vector)
        vector = vector if real[_largest(real)] > 0 else -vector
    else:
        k = _largest(vector)
        vector = vector * (np.conj(vector[k]) / abs(vector[k]))
    return vector / np.linalg.norm(np.real(vector))


def _largest(vector: np.ndarray) -> int:
    """The index of the first component whose modulus is the largest to :data:`TIE_TOL`."""
    size = np.abs(vector)
    return int(np.flatnonzero(size >= (1.0 - TIE_TOL) * size.max())[0])


def hopf_vector(params: ChainParams, model: str | Model, point: HopfPoint) -> tuple[ChainSystem, np.ndarray, complex, np.ndarray]:
    """The chain at a Hopf point as a system, its state y_H (2n,), the crossing eigenvalue near +i omega and its eigenvector.

    The eigenvector is LAPACK's turned by :func:`turned_hopf_vector`: its phase and sign, and with them the first
    orbit of :func:`switch_at_hopf`, do not depend on the LAPACK build.
    """
    system = ChainSystem(params, model, M=point.moment, particle=point.particle)
    n = system.size
    q = pack(params, point.x)
    rate = system.damping() / system.mass()
    jacobian = system.force_jacobian(q).toarray() / system.mass()[:, None]
    matrix = np.block([[np.zeros((n, n)), np.eye(n)], [jacobian, -np.diag(rate)]])
    values, vectors = sla.eig(matrix)
    i = int(np.argmin(np.abs(values - 1j * point.frequency)))
    return system, np.concatenate([q, np.zeros(n)]), complex(values[i]), turned_hopf_vector(vectors[:, i])


def _hopf_march(params: ChainParams, model: str | Model, point: HopfPoint, tol, rtol, atol) -> _March:
    """(P) with no turns (every particle_turns 0), the period and M unknown, on the plane through y_H + a_1 e normal
    to the flow there (the chain's compiled shooting, as :func:`~.periodic.continue_orbit`'s); the old branch is the
    equilibrium's (tau = (dq/dM, 0, 0, 1), K dq/dM = dF/dM), which every solution with max |f(y0)| at most
    HALF_CLOSURE tol is."""
    system, state, _, vector = hopf_vector(params, model, point)
    n = system.size
    e = np.real(vector)
    model = get_model(model)
    chain = _System(params, model, point.moment, point.particle)
    reference = state + PROBE_AMPLITUDES[0] * e
    flow = chain.velocity(reference)
    phase = _phase_for(chain, reference, flow / np.linalg.norm(flow))
    x, v = _from_y(params, state)
    start = PeriodicOrbit(
        params, model.name, point.moment, 0, point.particle, 2.0 * math.pi / point.frequency, x, v, np.ones(1, dtype=complex),
        math.inf, 0, particle_turns=np.zeros(params.n_particles, dtype=np.int64), phase_normal=phase.normal,
    )  # fmt: skip
    problem = _OrbitBranchProblem(start, model, phase, tol, rtol, atol, 0.0, math.inf, False, False, consistent=False)
    q = state[:n]
    slope = -np.linalg.solve(system.force_jacobian(q).toarray(), system.parameter_forces(q, "M"))
    tau = np.concatenate([slope, np.zeros(n + 1), [1.0]])

    def at_rest(w: np.ndarray) -> bool:
        moving = _System(params, model, float(w[-1]), point.particle).velocity(w[: 2 * n])
        return float(np.max(np.abs(moving))) <= HALF_CLOSURE * tol

    tangent = np.concatenate([e, [0.0, 0.0]])
    return _March(problem.evaluate, problem.point, problem.pack(start), tangent, tau, at_rest, tol, f"M={point.moment!r}")


def hopf_orbit(
    params: ChainParams,
    model: str | Model,
    point: HopfPoint,
    amplitude: float,
    *,
    tol: float = CLOSURE_TOL,
    rtol: float = RTOL,
    atol: float = ATOL,
) -> PeriodicOrbit:
    """The periodic orbit of amplitude ``amplitude`` born at the Hopf point ``point`` (no turns, period near 2 pi / omega).

    Parameters
    ----------
    params : ChainParams
    model : str or Model
        Those of the static branch the Hopf point lies on.
    point : HopfPoint
        From :func:`~.hopf.hopf_points`, located.
    amplitude : float
        a > 0 of e . (y0 - y_H) = a, e the real part of the crossing eigenvector (:func:`hopf_vector`);
        reached in steps as in :func:`doubled_orbit`.
    tol, rtol, atol : float
        As for :func:`~.periodic.find_periodic_orbit`.

    Returns
    -------
    PeriodicOrbit
        No turns, at the moment the amplitude fixes, its multipliers computed.

    Raises
    ------
    ValueError
        For an amplitude that is not a finite positive number, or a Hopf point that was not located.
    OrbitError
        Where Newton's method does not converge.
    """
    if not (math.isfinite(amplitude) and amplitude > 0):
        raise ValueError(f"amplitude must be a finite number > 0 (along the Hopf eigenvector), got {amplitude!r}")
    _check_hopf(point)
    return _hopf_march(params, model, point, tol, rtol, atol).to(amplitude)


def system_hopf_orbit(
    point: Any, parameter: str, amplitude: float, *, tol: float = shooting.CLOSURE_TOL, rtol: float = shooting.RTOL,
    atol: float = shooting.ATOL,
) -> shooting.Orbit:  # fmt: skip
    """The periodic orbit of amplitude ``amplitude`` born at a user system's Hopf point, as :func:`hopf_orbit` the chain's.

    Parameters
    ----------
    point : equilibria.SystemEquilibrium
        The equilibrium at the Hopf point (the located point of a ``hopf`` event of
        :func:`~.equilibria.continue_equilibria`): a complex pair of its dynamics on the imaginary axis.
    parameter : str
        The system's parameter unknown beside the period (the one the equilibria were continued in).
    amplitude : float
        a > 0 of e . (y0 - y_H) = a, e the real part of the crossing eigenvector (:func:`turned_hopf_vector`),
        reached in steps as in :func:`doubled_orbit`.
    tol, rtol, atol : float
        As for :func:`~.shooting.find_orbit`.

    Returns
    -------
    shooting.Orbit
        No turns, period near 2 pi / omega, at the parameter value the amplitude fixes; on the phase plane through
        y_H + a_1 e (a_1 the first of :data:`PROBE_AMPLITUDES`), normal to the flow there.

    Raises
    ------
    ValueError
        For an amplitude that is not a finite positive number, or an equilibrium with no pair near the axis.
    OrbitError
        Where Newton's method does not converge.
    """
    if not (math.isfinite(amplitude) and amplitude > 0):
        raise ValueError(f"amplitude must be a finite number > 0 (along the Hopf eigenvector), got {amplitude!r}")
    system, q = point.system, np.asarray(point.q, dtype=float)
    n = system.size
    inverse = 1.0 / system.mass()
    matrix = np.block(
        [[np.zeros((n, n)), np.eye(n)], [inverse[:, None] * system.force_jacobian(q).toarray(), -np.diag(system.damping() * inverse)]]
    )
    values, vectors = sla.eig(matrix)
    upper = np.flatnonzero(values.imag > 1e-9)
    if upper.size == 0:
        raise ValueError(
            f"the equilibrium of {system.name} at {parameter}={system.parameter(parameter)!r} has no complex pair: no Hopf point"
        )
    i = upper[np.argmin(np.abs(values[upper].real))]
    if abs(values[i].real) > 1e-6 * abs(values[i]):
        raise ValueError(
            f"the pair nearest the imaginary axis lies at {values[i]:.6g}: not a located Hopf point (continue_equilibria's hopf event)"
        )
    e = np.real(turned_hopf_vector(vectors[:, i]))
    state = np.concatenate([q, np.zeros(n)])
    period = 2.0 * math.pi / float(values[i].imag)
    unknowns = (shooting.PERIOD, parameter)
    problem = shooting._Shooting(system, np.zeros(n, dtype=np.int64), state + PROBE_AMPLITUDES[0] * e, period, unknowns, tol, rtol, atol)
    # The equilibria's branch: K dq/dp = -dF/dp, the period and the velocities unchanged.
    slope = -np.linalg.solve(system.force_jacobian(q).toarray(), system.parameter_forces(q, parameter))
    tau = np.concatenate([slope, np.zeros(n + 1), [1.0]])

    def at_rest(w: np.ndarray) -> bool:
        moving = system.with_parameters(**{parameter: float(w[-1])}).vector_field(w[: 2 * n])
        return float(np.max(np.abs(moving))) <= HALF_CLOSURE * tol

    base = np.concatenate([state, [math.log(period), system.parameter(parameter)]])
    tangent = np.concatenate([e, [0.0, 0.0]])
    march = _March(problem.evaluate, problem.orbit, base, tangent, tau, at_rest, tol, f"{parameter}={system.parameter(parameter)!r}")
    return march.to(amplitude)


def _check_hopf(point) -> None:
    if not isinstance(point, HopfPoint) or not point.located:
        raise ValueError(f"point must be a located HopfPoint (numerics.hopf.hopf_points), got {point!r:.80}")


def switch_at_hopf(
    params: ChainParams,
    model: str | Model,
    point: HopfPoint,
    *,
    amplitude: float | None = None,
    offset: float = OFFSET,
    follow: bool = True,
    tol: float = CLOSURE_TOL,
    rtol: float = RTOL,
    atol: float = ATOL,
    **continue_options,
) -> HopfOrbits:
    """The family of non-rotating periodic orbits born at a Hopf point of a static branch.

    Parameters
    ----------
    params : ChainParams
    model : str or Model
        Those of the static branch.
    point : HopfPoint
        From :func:`~.hopf.hopf_points`, located.
    amplitude : float, optional
        a of the first orbit; by default the normal form's for |M - M_H| = ``offset`` |M_H| (as in
        :func:`switch_at_period_doubling`).
    offset : float
        Relative distance in M of the first orbit from the Hopf point (default amplitude only).
    follow : bool
        Continue the family down in |M| (:func:`~.periodic.continue_orbit`) where it lies below.
    tol, rtol, atol : float
        As for :func:`~.periodic.find_periodic_orbit`.
    **continue_options
        Passed to :func:`~.periodic.continue_orbit` (``max_points``, ``period_max``, ...).

    Returns
    -------
    HopfOrbits

    Raises
    ------
    ValueError
        For a Hopf point that was not located, or a bad amplitude or offset.
    OrbitError
        Where the orbits are not found.
    """
    if not (math.isfinite(offset) and 0 < offset < 1):
        raise ValueError(f"offset must be a number in (0, 1) (relative distance in M), got {offset!r}")
    if amplitude is not None and not (math.isfinite(amplitude) and amplitude > 0):
        raise ValueError(f"amplitude must be a finite number > 0 (along the Hopf eigenvector), got {amplitude!r}")
    _check_hopf(point)
    _, _, eigenvalue, vector = hopf_vector(params, model, point)
    sign = math.copysign(1.0, point.moment)

    def distance(orbit: PeriodicOrbit) -> float:
        return sign * (orbit.moment - point.moment)

    march, probe, coefficient, _ = _normal_form(lambda _: _hopf_march(params, model, point, tol, rtol, atol), distance)
    if coefficient == 0:
        raise OrbitError(f"the orbits born at the Hopf point M={point.moment!r} do not move in M with their amplitude (degenerate)")
    if amplitude is None:
        wanted = offset * abs(point.moment)
        guess = max(probe, min(MAX_AMPLITUDE, math.sqrt(wanted / abs(coefficient))))
        orbit = march.to(guess, enough=lambda o: abs(distance(o)) >= wanted)
        amplitude = march.done[-1][0]
    else:
        orbit = march.to(amplitude)
    side = "below" if distance(orbit) < 0 else "above"
    branch = continue_orbit(orbit, tol=tol, rtol=rtol, atol=atol, **continue_options) if follow and side == "below" else None
    return HopfOrbits(point, eigenvalue, vector, float(coefficient), float(amplitude), orbit, side, branch)


def continue_family(
    orbit: PeriodicOrbit,
    *,
    direction: float = 1.0,
    moment_min: float = 0.0,
    period_max: float = 2000.0,
    step: float = 0.02,
    min_step: float = 1e-7,
    max_step: float = 0.2,
    max_points: int = 200,
    tol: float = CLOSURE_TOL,
    rtol: float = RTOL,
    atol: float = ATOL,
) -> OrbitBranch:
    """A chain's family of orbits followed from ``orbit`` either way in M and through its folds of cycles.

    :func:`~.periodic.continue_orbit` goes towards smaller |M| and ends at the first fold; a family born
    above its bifurcation (a subcritical flip, the branch points of the nonlinear N = 1 chain) starts
    by rising in |M|. Here the same equations and corrector are followed by pseudo-arclength from
    ``orbit`` towards larger |M| (``direction`` +1) or smaller (-1), on a phase plane normal to the flow
    (re-chosen on the way where the flow turns from it), past every fold, until ``max_points``,
    ``moment_min``, ``period_max`` or a step that cannot be corrected.

    Returns
    -------
    periodic.OrbitBranch
        Its ``events``: ``{"kind": "fold", "moment": M}`` where M turns back and a real multiplier
        crosses +1 between the orbits around the turn (M the middle orbit's), and ``branch_point``
        where one crosses +1 while M does not turn (M interpolated in the multiplier).

    Raises
    ------
    ValueError
        For a direction other than +1 or -1.
    """
    if direction not in (1.0, -1.0):
        raise ValueError(f"direction must be +1 (towards larger |M|) or -1, got {direction!r}")
    params, model = orbit.params, get_model(orbit.model)
    phase = _plane(_System(params, model, orbit.moment, orbit.particle), _to_y(params, orbit.x, orbit.v))
    first = dataclasses.replace(orbit, phase_normal=phase.normal)
    problem = _OrbitBranchProblem(first, model, phase, tol, rtol, atol, moment_min, period_max, False, orbit.stable)
    traced = continuation(
        problem,
        problem.pack(first),
        step=step,
        min_step=min_step,
        max_step=max_step,
        max_points=max_points,
        direction=direction * math.copysign(1.0, orbit.moment),
        corrector={"max_iterations": MAX_CORRECTOR_ITERATIONS, "chord": NEWTON_RATE, "forgive": 0},
        easy=EASY_ITERATIONS,
        hard=HARD_ITERATIONS,
        locate=False,
        tangent_method="svd",
        first=first,
    )
    orbits = traced.points
    events = []
    moments = [o.moment for o in orbits]
    for i in range(len(orbits) - 1):
        if not _crosses_one(orbits[i], orbits[i + 1]):
            continue
        turns = [j for j in (i, i + 1) if 0 < j < len(orbits) - 1 and (moments[j] - moments[j - 1]) * (moments[j + 1] - moments[j]) < 0]
        if turns:
            events.append({"kind": "fold", "moment": float(moments[turns[0]])})
        else:
            ga, gb = (float(np.real(np.prod(o.nontrivial_multipliers - 1.0))) for o in orbits[i : i + 2])
            events.append({"kind": "branch_point", "moment": float(moments[i] + ga * (moments[i + 1] - moments[i]) / (ga - gb))})
    end = _ORBIT_ENDS.get(traced.end, str(traced.end)) if traced.end != BranchEnd.MAX_POINTS else "max_points"
    settings = {"direction": direction, "moment_min": moment_min, "period_max": period_max, "step": step, "max_step": max_step, "tol": tol}
    return OrbitBranch(
        orbits=orbits, end=end, end_moment=float(orbits[-1].moment), message=traced.message, settings=settings, events=events
    )


def _flip_test(orbit: PeriodicOrbit) -> float:
    """The period-doubling test of :func:`~.cycle_events.circle_tests`: its sign changes where a real multiplier passes -1."""
    return circle_tests(orbit.nontrivial_multipliers)["period_doubling"]


def _located(start, parameter: str | None, *, tol: float, rtol: float, atol: float) -> tuple[Point, str]:
    """The period doubling ``start`` is, is near, or lies on (:func:`switch_at_period_doubling`), and its parameter."""
    if isinstance(start, shooting.OrbitBranch):
        events = [e for e in start.events if e.kind == "period_doubling" and e.located]
        if not events:
            raise ValueError(
                f"the branch in {start.parameter} has no located period_doubling event: continue_orbits locates one where a "
                "real multiplier passes -1 (stop_at=('period_doubling',) ends the branch there)"
            )
        return events[0].point, start.parameter if parameter is None else parameter
    if isinstance(start, shooting.Orbit):
        if parameter is None:
            raise ValueError("parameter must name the system's parameter of the period doubling, given an orbit")
        return start, parameter
    if parameter not in (None, "M"):
        raise ValueError(f"the chain's period doubling lies in the moment M, got parameter={parameter!r}")
    if isinstance(start, OrbitBranch):
        orbits = start.orbits
        pairs = [i for i in range(len(orbits) - 1) if _flip_test(orbits[i]) * _flip_test(orbits[i + 1]) < 0]
        if not pairs:
            raise ValueError("no real Floquet multiplier passes -1 along the branch: it has no period doubling to switch at")
        a, b = orbits[pairs[0] : pairs[0] + 2]
        settings = start.settings
        for event in start.events:
            # The branch's own event (cycle_events), where it was located at these tolerances.
            if (
                event["kind"] == "period_doubling" and event.get("orbit") is not None
                and min(a.moment, b.moment) <= event["moment"] <= max(a.moment, b.moment)
                and (settings.get("tol"), settings.get("rtol"), settings.get("atol", atol)) == (tol, rtol, atol)
            ):  # fmt: skip
                return event["orbit"], "M"
        return locate_circle_event([a, b], "period_doubling", resolve=True, tol=tol, rtol=rtol, atol=atol), "M"
    if not isinstance(start, PeriodicOrbit):
        raise ValueError(f"start must be a PeriodicOrbit or an OrbitBranch (of the chain or a system), got {type(start).__name__}")
    if np.min(np.abs(start.multipliers + 1.0)) <= FLIP_TOL:
        return start, "M"
    return locate_cycle_end([start], "period_doubling", rtol=rtol, atol=atol), "M"


__all__ = [
    "HopfOrbits",
    "PeriodDoubling",
    "continue_family",
    "doubled_orbit",
    "flip_vector",
    "hopf_orbit",
    "hopf_vector",
    "switch_at_hopf",
    "switch_at_period_doubling",
    "system_hopf_orbit",
    "turned_hopf_vector",
]
