"""Branch switching at a period doubling: the orbit of twice the period that emerges there.

Contract
--------
Where a real Floquet multiplier of a rotating orbit (:mod:`~cosserat_chain.numerics.periodic`,
eq. (P), k turns, period T) passes through -1 (a flip, or period doubling: ``period_doubling``
of :mod:`~cosserat_chain.experiments.diagram`, located by
:func:`~cosserat_chain.numerics.cycle_curve.locate_cycle_end`), a second family of orbits
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
turns, and continues it with :func:`~.periodic.continue_orbit`.

The doubled family lies below M_PD (in |M|) for a supercritical flip of an orbit that loses
stability as M falls (the doubled orbit inherits its stability), above it for a subcritical
one; :attr:`PeriodDoubling.side` says which. :func:`~.periodic.continue_orbit` follows orbits
towards smaller |M| only, so a family above M_PD is returned as its first orbit, not
continued (continued down it would run back into the period doubling).
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import scipy.linalg as sla

from ..models.base import get_model
from .cycle_curve import locate_cycle_end
from .kit import newton
from .periodic import (
    ATOL,
    CLOSURE_TOL,
    RTOL,
    OrbitBranch,
    OrbitError,
    PeriodicOrbit,
    _OrbitBranchProblem,
    _phase_for,
    _System,
    _to_y,
    continue_orbit,
    find_periodic_orbit,
)

#: The critical multiplier of a period doubling lies within this of -1 (the located end's is within ~1e-9);
#: an orbit farther off is located first.
FLIP_TOL = 1e-6
#: Relative distance |M - M_PD| / |M_PD| of the first doubled orbit (from the normal form), by default.
MOMENT_OFFSET = 1e-4
#: The two amplitudes (in the unit eigenvector's norm, units of h and rad) of the normal form's secant.
PROBE_AMPLITUDES = (2e-3, 4e-3)
#: Largest amplitude the normal form may ask for (beyond it the quadratic law is not trusted).
MAX_AMPLITUDE = 0.1
#: Newton iterations of one doubled orbit.
MAX_ITERATIONS = 20


@dataclass
class PeriodDoubling:
    """The switch from a k-turn orbit to its period-doubled family (module docstring).

    Attributes
    ----------
    point : PeriodicOrbit
        The located period doubling (k turns, period T_PD, a multiplier at -1).
    multiplier : complex
        Its critical multiplier (-1 to the located accuracy).
    eigenvector : ndarray (2 n_free,)
        Real unit eigenvector of the monodromy matrix for it, in the shooting's state y = (q, q').
    coefficient : float
        c of M - M_PD = c a^2 on the doubled family (secant through two amplitudes).
    amplitude : float
        a of the first doubled orbit.
    doubled : PeriodicOrbit
        The first doubled orbit: 2k turns, period near 2 T_PD.
    side : str
        ``below`` (the doubled family exists at smaller |M| than the period doubling) or ``above``.
    branch : OrbitBranch or None
        The doubled family continued down in |M| from ``doubled`` (None above the period doubling or
        when not asked for).
    """

    point: PeriodicOrbit
    multiplier: complex
    eigenvector: np.ndarray
    coefficient: float
    amplitude: float
    doubled: PeriodicOrbit
    side: str
    branch: OrbitBranch | None

    def as_dict(self) -> dict:
        """JSON-ready summary."""
        return {
            "moment": self.point.moment,
            "period": self.point.period,
            "turns": self.point.turns,
            "multiplier": [self.multiplier.real, self.multiplier.imag],
            "coefficient": self.coefficient,
            "amplitude": self.amplitude,
            "side": self.side,
            "doubled": self.doubled.as_dict(),
            "branch_end": None if self.branch is None else self.branch.end,
            "branch_end_moment": None if self.branch is None else self.branch.end_moment,
        }


def flip_vector(point: PeriodicOrbit, *, rtol: float = RTOL, atol: float = ATOL) -> tuple[complex, np.ndarray]:
    """The multiplier of ``point`` nearest -1 among the real negative ones, and its real unit eigenvector.

    The monodromy matrix is integrated again (an orbit keeps only its multipliers).

    Raises
    ------
    OrbitError
        Where the orbit has no real negative multiplier.
    """
    system = _System(point.params, get_model(point.model), point.moment, point.particle)
    _, mono, _ = system.flow(_to_y(point.params, point.x, point.v), point.period, rtol=rtol, atol=atol, variations=True)
    values, vectors = sla.eig(mono)
    real = np.abs(values.imag) <= 1e-6 * np.abs(values)
    candidates = np.flatnonzero(real & (values.real < 0))
    if candidates.size == 0:
        raise OrbitError(f"the orbit at M={point.moment!r} has no real negative Floquet multiplier: no period doubling")
    i = candidates[np.argmin(np.abs(values[candidates] + 1.0))]
    vector = np.real(vectors[:, i])
    return complex(values[i]), vector / np.linalg.norm(vector)


def doubled_orbit(
    point: PeriodicOrbit,
    amplitude: float,
    *,
    eigenvector: np.ndarray | None = None,
    tol: float = CLOSURE_TOL,
    rtol: float = RTOL,
    atol: float = ATOL,
) -> PeriodicOrbit:
    """The period-doubled orbit of amplitude ``amplitude`` along the flip eigenvector at the period doubling ``point``.

    Parameters
    ----------
    point : PeriodicOrbit
        The located period doubling (:func:`~.cycle_curve.locate_cycle_end`).
    amplitude : float
        a != 0 of e . (y0 - y_PD) = a (module docstring); its sign picks one of the two starts of the
        same doubled orbit, half a period apart. Beyond the first of :data:`PROBE_AMPLITUDES` the
        orbit is reached by doubling the amplitude, each orbit predicted by the parabola in a
        through the period doubling and the two orbits before (a step that fails is halved).
    eigenvector : ndarray (2 n_free,), optional
        e, from :func:`flip_vector` by default.
    tol, rtol, atol : float
        As for :func:`~.periodic.find_periodic_orbit`.

    Returns
    -------
    PeriodicOrbit
        2k turns, at the moment the amplitude fixes (near M_PD), its multipliers computed.

    Raises
    ------
    ValueError
        For a zero or non-finite amplitude.
    OrbitError
        Where Newton's method does not converge.
    """
    if not (math.isfinite(amplitude) and amplitude != 0):
        raise ValueError(f"amplitude must be a finite non-zero number (along the flip eigenvector), got {amplitude!r}")
    if eigenvector is None:
        eigenvector = flip_vector(point, rtol=rtol, atol=atol)[1]
    march = _March(point, math.copysign(1.0, amplitude) * eigenvector, tol, rtol, atol)
    return march.to(abs(amplitude))


class _March:
    """Doubled orbits of growing amplitude from one period doubling (:func:`doubled_orbit`)."""

    def __init__(self, point: PeriodicOrbit, eigenvector: np.ndarray, tol: float, rtol: float, atol: float):
        model = get_model(point.model)
        system = _System(point.params, model, point.moment, point.particle)
        phase = _phase_for(system, _to_y(point.params, point.x, point.v), point.phase_normal)
        start = dataclasses.replace(point, turns=2 * point.turns, period=2 * point.period, particle_turns=2 * point.particle_turns)
        self.point, self.tol = point, tol
        self.problem = _OrbitBranchProblem(start, model, phase, tol, rtol, atol, 0.0, math.inf, False, False)
        head = phase.head
        direction = np.zeros(head + 2)
        direction[:head] = eigenvector[phase.keep]
        norm = float(np.linalg.norm(direction))
        if norm < 0.1:
            raise OrbitError(f"the flip eigenvector at M={point.moment!r} lies along the phase condition: no amplitude can be set")
        self.direction = direction / norm
        #: (amplitude, w) of the doubled family, from its limit at the period doubling (a = 0) on.
        self.done: list[tuple[float, np.ndarray]] = [(0.0, self.problem.pack(start))]
        self.orbits: dict[float, PeriodicOrbit] = {}

    def _predict(self, amplitude: float) -> np.ndarray:
        """The parabola in a through the last three solutions (the tangent e at the period doubling before two)."""
        if len(self.done) < 3:
            return self.done[-1][1] + (amplitude - self.done[-1][0]) * self.direction
        (a0, w0), (a1, w1), (a2, w2) = self.done[-3:]
        l0 = (amplitude - a1) * (amplitude - a2) / ((a0 - a1) * (a0 - a2))
        l1 = (amplitude - a0) * (amplitude - a2) / ((a1 - a0) * (a1 - a2))
        l2 = (amplitude - a0) * (amplitude - a1) / ((a2 - a0) * (a2 - a1))
        return l0 * w0 + l1 * w1 + l2 * w2

    def solve(self, amplitude: float) -> PeriodicOrbit | None:
        """The doubled orbit at ``amplitude`` (above the last one solved) from the prediction, None where Newton fails."""
        predictor = self._predict(amplitude)
        # The border fixes e . (w - w_pred) = 0, which is the amplitude condition: the predictor satisfies it.
        solved = newton(
            self.problem.evaluate, predictor, tol=self.tol, border=(self.direction, predictor), max_iterations=MAX_ITERATIONS,
            divergence=None, damping=6,
        )  # fmt: skip
        if not solved.converged:
            return None
        self.done.append((amplitude, solved.w))
        return self.problem.point(solved.w, solved.evaluation, solved.iterations)

    def to(self, amplitude: float, enough: Callable[[PeriodicOrbit], bool] | None = None) -> PeriodicOrbit:
        """The doubled orbit at ``amplitude`` > 0, in steps from the largest one solved: each at most doubles the
        amplitude, a failed one is halved. With ``enough``, the first orbit it accepts on the way is returned."""
        last, orbit = self.done[-1][0], None
        a = min(amplitude, max(PROBE_AMPLITUDES[0], 2 * last))
        while True:
            found = self.solve(a)
            if found is not None:
                orbit, last = found, a
                if a >= amplitude or (enough is not None and enough(orbit)):
                    return orbit
                a = min(amplitude, 2 * a)
            elif a - last > 0.05 * max(last, PROBE_AMPLITUDES[0]):
                a = 0.5 * (a + last)
            elif enough is not None and orbit is not None:
                return orbit  # the family turns back or Newton fails beyond: the largest amplitude reached
            else:
                raise OrbitError(
                    f"Newton did not converge to the doubled orbit of amplitude {a!r} at the period doubling M={self.point.moment!r}; "
                    f"the doubled family may turn back before amplitude {amplitude!r}: try a smaller amplitude"
                )


def _moment_offset(point: PeriodicOrbit, orbit: PeriodicOrbit) -> float:
    """M - M_PD, positive towards larger |M|."""
    return math.copysign(1.0, point.moment) * (orbit.moment - point.moment)


def switch_at_period_doubling(
    start: PeriodicOrbit | OrbitBranch,
    *,
    amplitude: float | None = None,
    moment_offset: float = MOMENT_OFFSET,
    follow: bool = True,
    tol: float = CLOSURE_TOL,
    rtol: float = RTOL,
    atol: float = ATOL,
    **continue_options,
) -> PeriodDoubling:
    """The period-doubled family that leaves an orbit branch at its period doubling.

    Parameters
    ----------
    start : PeriodicOrbit or OrbitBranch
        The period doubling (an orbit with a real multiplier within :data:`FLIP_TOL` of -1), an orbit
        near one (located first), or a branch of :func:`~.periodic.continue_orbit` along which a real
        multiplier passes -1 (the first such passage is located).
    amplitude : float, optional
        a of the first doubled orbit along the flip eigenvector; by default the normal form's
        amplitude for |M - M_PD| = ``moment_offset`` |M_PD| (capped at :data:`MAX_AMPLITUDE`; the orbit
        lies about that far from M_PD, or nearer where the family bends away from c a^2 sooner).
    moment_offset : float
        Relative distance in M of the first doubled orbit from the period doubling (default amplitude only).
    follow : bool
        Continue the doubled family down in |M| (:func:`~.periodic.continue_orbit`) where it lies below.
    tol, rtol, atol : float
        As for :func:`~.periodic.find_periodic_orbit`.
    **continue_options
        Passed to :func:`~.periodic.continue_orbit` (``moment_min``, ``period_max``, ``max_points``, ...).

    Returns
    -------
    PeriodDoubling

    Raises
    ------
    ValueError
        For a branch without a passage of -1, bad amplitudes or offsets, or where the period doubling
        cannot be located.
    OrbitError
        Where the doubled orbit is not found.
    """
    if not (math.isfinite(moment_offset) and 0 < moment_offset < 1):
        raise ValueError(f"moment_offset must be a number in (0, 1) (relative distance in M), got {moment_offset!r}")
    point = _located(start, rtol=rtol, atol=atol)
    multiplier, vector = flip_vector(point, rtol=rtol, atol=atol)
    march = _March(point, vector, tol, rtol, atol)
    probes = [march.to(a) for a in PROBE_AMPLITUDES]
    # The normal form M - M_PD = c a^2 + O(a^3) (a and -a + O(a^2) start one orbit, half a period apart), by a secant in a^2.
    (a1, a2), (m1, m2) = PROBE_AMPLITUDES, [_moment_offset(point, o) for o in probes]
    coefficient = (m2 - m1) / (a2 * a2 - a1 * a1)
    if coefficient == 0:
        raise OrbitError(f"the doubled family at M={point.moment!r} does not move in M with its amplitude (a degenerate flip)")
    if amplitude is None:
        # The normal form's amplitude, approached in steps: the family's M bends away from c a^2 within a few times the
        # probes on the sine chain at gamma_phi = 0.3, so the first orbit at the wanted distance from M_PD serves.
        wanted = moment_offset * abs(point.moment)
        guess = max(PROBE_AMPLITUDES[-1], min(MAX_AMPLITUDE, math.sqrt(wanted / abs(coefficient))))
        doubled = march.to(guess, enough=lambda o: abs(_moment_offset(point, o)) >= wanted)
        amplitude = march.done[-1][0]
    else:
        doubled = doubled_orbit(point, amplitude, eigenvector=vector, tol=tol, rtol=rtol, atol=atol)
    doubled = find_periodic_orbit(
        point.params,
        point.model,
        doubled.moment,
        turns=doubled.turns,
        particle=point.particle,
        guess=doubled,
        tol=tol,
        rtol=rtol,
        atol=atol,
    )
    side = "below" if _moment_offset(point, doubled) < 0 else "above"
    branch = continue_orbit(doubled, tol=tol, rtol=rtol, atol=atol, **continue_options) if follow and side == "below" else None
    return PeriodDoubling(point, multiplier, vector, float(coefficient), float(amplitude), doubled, side, branch)


def _flip_test(orbit: PeriodicOrbit) -> float:
    """Re prod (mu + 1) over the multipliers: its sign changes where a real one passes -1."""
    return float(np.real(np.prod(orbit.multipliers + 1.0)))


def _located(start: PeriodicOrbit | OrbitBranch, *, rtol: float, atol: float) -> PeriodicOrbit:
    """The period doubling ``start`` is, is near, or lies on (module docstring of :func:`switch_at_period_doubling`)."""
    if isinstance(start, OrbitBranch):
        orbits = start.orbits
        pairs = [i for i in range(len(orbits) - 1) if _flip_test(orbits[i]) * _flip_test(orbits[i + 1]) < 0]
        if not pairs:
            raise ValueError("no real Floquet multiplier passes -1 along the branch: it has no period doubling to switch at")
        around = orbits[pairs[0] : pairs[0] + 2]
        if abs(around[1].max_multiplier - 1.0) < abs(around[0].max_multiplier - 1.0):
            around = around[::-1]
        return locate_cycle_end(around, "period_doubling", rtol=rtol, atol=atol)
    if not isinstance(start, PeriodicOrbit):
        raise ValueError(f"start must be a PeriodicOrbit or an OrbitBranch, got {type(start).__name__}")
    if np.min(np.abs(start.multipliers + 1.0)) <= FLIP_TOL:
        return start
    return locate_cycle_end([start], "period_doubling", rtol=rtol, atol=atol)


__all__ = ["PeriodDoubling", "doubled_orbit", "flip_vector", "switch_at_period_doubling"]
