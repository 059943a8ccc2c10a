"""Branch switching at a period doubling of a collocation branch, AUTO-07p's way (IPS = 2, ISW = -1).

Contract
--------
Where a real Floquet multiplier of a k-turn orbit u (period T, eq. (C) of
:mod:`~cosserat_chain.numerics.collocation`) passes -1 at M_PD (a ``period_doubling`` event of
:func:`~cosserat_chain.numerics.collocation.continue_collocation`), a family of 2k-turn orbits of
period near 2T leaves it. As AUTO does, the switch works on the *doubled mesh*: the scaled time
[0, 1] of the doubled orbit covers two periods, the mesh is the old one halved and repeated
(2 NTST intervals), and the first guess is u run twice, u_2(tau) = u(2 tau) on [0, 1/2] and
u(2 tau - 1) + s on [1/2, 1] (s the one-turn shift of the boundary condition), with the period 2T
and the boundary shift 2s. On that mesh the doubled system at fixed M_PD has the *flip mode* in
the null space of its Jacobian: the linearised flow's solution x of the multiplier -1 on [0, 1/2]
continued by -x on [1/2, 1] (so it changes sign after one period and closes after two; it is
orthogonal to u_2' in the phase integral, a -1 and +1 half cancelling). It is found by inverse
iteration with the sparse factor of that Jacobian; its log T component vanishes with it.

The doubled orbit of amplitude a is then solved by Newton's method on the doubled collocation
system with M free, from the predictor w_PD + a t (t the flip mode, unit in the collocation's
scaled unknowns, with zero M and log T parts) on the plane t . (w - w_PD) = a, AUTO's first
pseudo-arclength step along the bifurcating direction. The plane meets the family u run twice
(whose tangent is even under the half-period shift, so nearly orthogonal to t) only far away:
the corrector lands on the doubled family, whose M moves like M_PD + c a^2 and period like
2 T_PD + O(a^2). :func:`switch_collocation_at_period_doubling` estimates c from one probe
amplitude, takes the amplitude that puts the first orbit ``offset`` |M_PD| away from M_PD,
and continues the doubled family with :func:`~cosserat_chain.numerics.collocation.continue_collocation`
on the side where it lies.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from ..linalg.threads import one_blas_thread
from ..models.base import get_model
from . import periodic
from .collocation import (
    CollocationBranch,
    CollocationError,
    CollocationOrbit,
    continue_collocation,
    critical_multiplier,
)
from .collocation_core import CHORD_RATE, MAX_HALVINGS, PERMUTATION, TOL, _Collocation, _shift, _SparseStep
from .kit import newton

__all__ = [
    "CollocationPeriodDoubling",
    "doubled_collocation_orbit",
    "flip_mode",
    "half_period_gap",
    "switch_collocation_at_period_doubling",
]

#: The critical multiplier of a period doubling lies within this of -1 (a located event's within ~1e-12).
FLIP_TOL = 1e-6
#: Relative distance |M - M_PD| / |M_PD| of the first doubled orbit, by default (the shooting's ``OFFSET``).
OFFSET = 1e-4
#: The probe amplitude (in the profile's mean-square norm) whose orbit gives the normal form's c of M - M_PD = c a^2.
PROBE_AMPLITUDE = 1e-3
#: Largest amplitude the normal form may ask for.
MAX_AMPLITUDE = 0.1
#: Inverse iterations for the flip mode (the doubled Jacobian is singular to the located accuracy: one or two suffice).
INVERSE_ITERATIONS = 4
#: A doubled orbit whose half-period closure is below this is the single orbit run twice, not a new one.
HALF_CLOSURE = 1e-7


@dataclass
class CollocationPeriodDoubling:
    """The switch from a collocation orbit at a period doubling to its doubled family (module docstring).

    Attributes
    ----------
    point : CollocationOrbit
        The located period doubling (k turns, period T_PD, a multiplier at -1).
    multiplier : complex
        Its critical multiplier.
    doubled_point : CollocationOrbit
        The point run twice on the doubled mesh (2k turns, period 2 T_PD), its multipliers those of the
        doubled linearised system (the squares of the point's).
    mode : ndarray (2 NTST NCOL + 1, 2 n_free)
        The flip mode on the doubled mesh's nodes, in state units, unit mean-square norm: x on the first
        half, -x on the second.
    coefficient : float
        c of M - M_PD = c a^2 (from the probe orbit).
    amplitude : float
        a of :attr:`doubled`.
    doubled : CollocationOrbit
        The first doubled orbit.
    side : str
        ``below`` (the doubled family lies at smaller |M| than the period doubling) or ``above``.
    branch : CollocationBranch or None
        The doubled family continued away from the period doubling (None where not asked for).
    """

    point: CollocationOrbit
    multiplier: complex
    doubled_point: CollocationOrbit
    mode: np.ndarray
    coefficient: float
    amplitude: float
    doubled: CollocationOrbit
    side: str
    branch: CollocationBranch | None

    def as_dict(self) -> dict:
        """JSON-ready summary."""
        return {
            "moment": self.point.moment,
            "period": self.point.period,
            "multiplier": [self.multiplier.real, self.multiplier.imag],
            "coefficient": self.coefficient,
            "amplitude": self.amplitude,
            "side": self.side,
            "doubled": self.doubled.as_dict(),
            "branch": None if self.branch is None else {"end": str(self.branch.end), "message": self.branch.message},
        }


def _point(start) -> CollocationOrbit:
    """The located period doubling that ``start`` is (an orbit), carries (an event) or has (a branch's first)."""
    if isinstance(start, CollocationBranch):
        events = [e for e in start.events if e["kind"] == "period_doubling" and e["located"]]
        if not events:
            kinds = sorted({e["kind"] for e in start.events})
            raise ValueError(
                f"the collocation branch has no located period_doubling event (its events: {kinds or 'none'}): "
                "continue_collocation locates one where a real multiplier passes -1"
            )
        return events[0]["orbit"]
    if isinstance(start, dict):
        kind = start.get("kind")
        if kind != "period_doubling":
            raise ValueError(f"the event is a {kind!r}, not a 'period_doubling': only a period doubling is switched at here")
        if not start.get("located", False):
            raise ValueError(f"the period_doubling event at M={start.get('moment')!r} was not located (located=False)")
        start = start["orbit"]
    if not isinstance(start, CollocationOrbit):
        raise ValueError(
            f"start must be a CollocationBranch, one of its period_doubling events or a CollocationOrbit, got {type(start).__name__}"
        )
    mu = critical_multiplier(start.nontrivial_multipliers, "period_doubling")
    if mu is None or abs(mu + 1.0) > FLIP_TOL:
        raise ValueError(
            f"the orbit at M={start.moment!r} has its real multiplier nearest -1 at {mu!r}: not a located period doubling "
            f"(within {FLIP_TOL:g}; take the orbit of a period_doubling event of continue_collocation)"
        )
    return start


def _run_twice(orbit: CollocationOrbit) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The doubled mesh (2 NTST + 1,), the profile run twice on it and the one-period shift s."""
    system = periodic._System(orbit.params, get_model(orbit.model), orbit.moment, orbit.particle)
    shift = _shift(system, orbit.particle_turns)
    mesh = np.concatenate([0.5 * orbit.mesh, 0.5 + 0.5 * orbit.mesh[1:]])
    profile = np.concatenate([orbit.profile, orbit.profile[1:] + shift[None, :]])
    return mesh, profile, shift


def _problem(orbit: CollocationOrbit, mesh: np.ndarray, profile: np.ndarray, *, free_moment: bool) -> _Collocation:
    system = periodic._System(orbit.params, get_model(orbit.model), orbit.moment, orbit.particle)
    return _Collocation(system, mesh, orbit.ncol, _shift(system, 2 * orbit.particle_turns), profile, free_moment=free_moment)


def _doubled(orbit: CollocationOrbit, problem: _Collocation, w: np.ndarray, evaluation, iterations: int) -> CollocationOrbit:
    profile, period, moment = problem.unpack(w)
    a_values, _ = evaluation.data
    return replace(
        orbit, moment=float(moment), turns=2 * orbit.turns, period=float(period), mesh=problem.mesh, profile=profile,
        multipliers=problem.multipliers(a_values, period), residual=float(np.max(np.abs(evaluation.residual))),
        iterations=iterations, particle_turns=2 * np.asarray(orbit.particle_turns),
    )  # fmt: skip


@one_blas_thread
def flip_mode(point: CollocationOrbit) -> tuple[CollocationOrbit, np.ndarray]:
    """The period doubling ``point`` run twice on the doubled mesh, and its flip mode there (module docstring).

    Returns
    -------
    doubled_point : CollocationOrbit
        2k turns, period 2 T_PD, the doubled linearised system's multipliers.
    mode : ndarray (2 NTST NCOL + 1, 2 n_free)
        The null vector of the doubled Jacobian at fixed M, in state units, unit mean-square norm.

    Raises
    ------
    ValueError
        Where ``point`` is not a located period doubling.
    """
    point = _point(point)
    mesh, profile, _ = _run_twice(point)
    problem = _problem(point, mesh, profile, free_moment=False)
    w = problem.pack(profile, 2.0 * point.period)
    evaluation = problem.evaluate(w, True)
    factor = spla.splu(sp.csc_matrix(evaluation.jacobian), permc_spec=PERMUTATION)
    # A start with no preference between the two halves; the iteration keeps the mode that changes sign.
    z = np.cos(np.arange(w.size, dtype=float))
    for _ in range(INVERSE_ITERATIONS):
        z = factor.solve(z)
        z /= np.linalg.norm(z)
    mode = z[: problem.nodes * problem.n].reshape(problem.nodes, problem.n)
    mode /= math.sqrt(float(np.mean(np.sum(mode**2, axis=1))))
    return _doubled(point, problem, w, evaluation, 0), mode


def _plane(point: CollocationOrbit, mode: np.ndarray) -> tuple[_Collocation, np.ndarray, np.ndarray]:
    """The doubled system with M free, the orbit run twice in its unknowns (w_PD) and the unit flip direction t there."""
    mesh, profile, _ = _run_twice(point)
    problem = _problem(point, mesh, profile, free_moment=True)
    t = np.concatenate([problem.scale * mode.ravel(), [0.0, 0.0]])
    return problem, problem.pack(profile, 2.0 * point.period, point.moment), t / np.linalg.norm(t)


def doubled_collocation_orbit(
    point: CollocationOrbit, amplitude: float, *, mode: np.ndarray | None = None, probe: CollocationOrbit | None = None, tol: float = TOL
) -> CollocationOrbit:
    """The doubled orbit of amplitude ``amplitude`` along the flip mode at the period doubling ``point``.

    Newton on the doubled collocation system with M free, from w_PD + a t (or, given ``probe``, from the
    parabola w_PD + a t + (a / a_1)^2 (w_1 - w_PD - a_1 t) through the probe's w_1 at its amplitude a_1)
    on the plane t . (w - w_PD) = a (module docstring).

    Parameters
    ----------
    point : CollocationOrbit
        The located period doubling.
    amplitude : float
        a != 0, in the profile's mean-square norm; its sign picks one of the two starts of the same
        doubled orbit, a period apart.
    mode : ndarray, optional
        The flip mode of :func:`flip_mode` (computed by default).
    probe : CollocationOrbit, optional
        A doubled orbit of this function at a smaller amplitude (the parabola's a^2 term is even in a).
    tol : float
        Newton stops at max |R| <= tol.

    Returns
    -------
    CollocationOrbit
        2k turns on the doubled mesh, at the M the amplitude fixes, with its multipliers.

    Raises
    ------
    ValueError
        For a zero or non-finite amplitude, or a ``point`` that is no period doubling.
    CollocationError
        Where Newton does not converge, or converges to the single orbit run twice.
    """
    if not (math.isfinite(amplitude) and amplitude != 0):
        raise ValueError(f"amplitude must be a finite non-zero number (along the flip mode), got {amplitude!r}")
    point = _point(point)
    if mode is None:
        mode = flip_mode(point)[1]
    problem, base, t = _plane(point, mode)
    start = base + amplitude * t
    if probe is not None:
        w1 = problem.pack(probe.profile, probe.period, probe.moment)
        a1 = float(t @ (w1 - base))
        start += (amplitude / a1) ** 2 * (w1 - base - a1 * t)
    solved = newton(
        problem.evaluate, start, tol=tol, divergence=None, damping=MAX_HALVINGS, chord=CHORD_RATE,
        newton_step=_SparseStep((t, base + amplitude * t)),
    )  # fmt: skip
    if not solved.converged:
        raise CollocationError(
            f"Newton on the doubled collocation system did not converge at amplitude {amplitude!r} from M={point.moment!r} "
            f"({solved.status}, max|R| {solved.norm:.3g}): try a smaller amplitude"
        )
    orbit = _doubled(point, problem, solved.w, solved.evaluation, solved.iterations)
    if half_period_gap(orbit, _run_twice(point)[2]) < HALF_CLOSURE:
        raise CollocationError(f"Newton at amplitude {amplitude!r} found the orbit at M={orbit.moment!r} run twice, not a doubled one")
    return orbit


def half_period_gap(orbit: CollocationOrbit, shift: np.ndarray) -> float:
    """max |u(1/2) - u(0) - s| of a doubled orbit (s the one-period shift): zero for an orbit run twice."""
    return float(np.max(np.abs(orbit.states(np.array([0.5]))[0] - orbit.profile[0] - shift)))


@one_blas_thread
def switch_collocation_at_period_doubling(
    start: CollocationBranch | dict | CollocationOrbit,
    *,
    amplitude: float | None = None,
    offset: float = OFFSET,
    follow: bool = True,
    tol: float = TOL,
    **continue_options,
) -> CollocationPeriodDoubling:
    """The period-doubled family leaving a collocation branch at its period doubling, on the doubled mesh.

    Parameters
    ----------
    start : CollocationBranch, dict or CollocationOrbit
        A branch of :func:`~cosserat_chain.numerics.collocation.continue_collocation` (its first located
        ``period_doubling`` event), one of its events of that kind, or the event's orbit.
    amplitude : float, optional
        a of the first doubled orbit along the flip mode (profile's mean-square norm); by default the normal
        form's for |M - M_PD| = ``offset`` |M_PD| (capped at :data:`MAX_AMPLITUDE`), from the probe at
        :data:`PROBE_AMPLITUDE`.
    offset : float
        In (0, 1): relative distance in M of the first doubled orbit (default amplitude only).
    follow : bool
        Continue the doubled family away from M_PD with ``continue_collocation`` (``continue_options``:
        ``moment_min``, ``max_points``, ``period_max``, ...).
    tol : float
        Newton's tolerance.

    Returns
    -------
    CollocationPeriodDoubling

    Raises
    ------
    ValueError
        For an event that is not a period doubling, a branch without one, an orbit off -1, or bad
        ``amplitude`` or ``offset``.
    CollocationError
        Where the doubled orbit is not found.
    """
    if not (math.isfinite(offset) and 0 < offset < 1):
        raise ValueError(f"offset must be a number in (0, 1) (relative distance in M), got {offset!r}")
    if amplitude is not None and not (math.isfinite(amplitude) and amplitude != 0):
        raise ValueError(f"amplitude must be a finite non-zero number (along the flip mode) or None, got {amplitude!r}")
    point = _point(start)
    doubled_point, mode = flip_mode(point)
    probe = doubled_collocation_orbit(point, PROBE_AMPLITUDE, mode=mode, tol=tol)
    coefficient = (probe.moment - point.moment) / PROBE_AMPLITUDE**2
    if coefficient == 0:
        raise CollocationError(f"the doubled family at M={point.moment!r} does not move with its amplitude (a degenerate flip)")
    if amplitude is None:
        amplitude = min(MAX_AMPLITUDE, max(PROBE_AMPLITUDE, math.sqrt(offset * abs(point.moment) / abs(coefficient))))
    if amplitude == PROBE_AMPLITUDE:
        doubled = probe
    else:
        doubled = doubled_collocation_orbit(point, amplitude, mode=mode, probe=probe, tol=tol)
    below = abs(doubled.moment) < abs(point.moment)
    branch = None
    if follow:
        direction = math.copysign(1.0, doubled.moment - point.moment)
        branch = continue_collocation(doubled, direction=direction, **continue_options)
    return CollocationPeriodDoubling(
        point, critical_multiplier(point.nontrivial_multipliers, "period_doubling"), doubled_point, mode, float(coefficient),
        float(amplitude), doubled, "below" if below else "above", branch,
    )  # fmt: skip
