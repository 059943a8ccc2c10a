"""Branch switching at a branch point of cycles: the family of orbits that crosses an orbit branch.

Contract
--------
Where a real Floquet multiplier of an orbit branch (the chain's :func:`~.periodic.continue_orbit`
in M, a user's system's :func:`~.shooting.continue_orbits` in any parameter p) passes +1 while the
parameter does not turn, a second family of orbits crosses the branch: a branch point of cycles
(AUTO-07p's BP of periodic solutions). The shooting equations (P) or (O) with the parameter
unknown, R(w) = 0 in w = (y0's unknowns, log T, p), have a Jacobian R_w whose null space is
two-dimensional there: the branch's own tangent tau, and the other family's tangent e, taken as
the null direction orthogonal to tau (AUTO's and :func:`~.kit.branch_directions`' switch).

:func:`switch_at_branch_point` locates the point (the chain's by the fold's augmented system of
:func:`~.cycle_curve.locate_cycle_end`, singular there as at a fold; a system's is the located
``branch_point`` event of its continuation), takes tau from the branch (the chord between the
chain's orbits around it, a system's event tangent, projected onto the null space) and solves
orbits of the other family at growing amplitudes a = e . (w - w_BP) by Newton's method with the
amplitude fixed (:class:`~.cycle_switching._March`, as at a period doubling), until the parameter
lies ``offset`` |p_BP| from p_BP. The orbit found is polished by the ordinary shooting Newton and
the family continued away from the point: the chain's down in |M| where it lies below
(:func:`~.periodic.continue_orbit`), up and through its folds where it lies above
(:func:`~.cycle_switching.continue_family`), a system's in p on its side.

The chain's mirror symmetry. A chain whose loaded particle is its middle one and whose two
halves are alike is symmetric under the point reflection S about that particle (particle k to
-k, u and v to -u and -v, phi kept; the moment stays). Its one-turn orbit is then S-invariant
at every instant, the monodromy matrix commutes with S and splits into a symmetric and an
antisymmetric block. Where the multiplier through +1 belongs to the antisymmetric block (two
multipliers at +1, one each way: a pitchfork) the new family breaks the symmetry:
:attr:`BranchSwitch.kind` is then ``mirror_symmetry_breaking``, a solution that is S-invariant
is the old branch and is refused, and the family comes as a pair of mirror images (S y(t) is an
orbit of it too, at the same M and T). Otherwise the kind is ``branch_point``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
import scipy.linalg as sla

from ..models.base import get_model
from ..params import ChainParams
from ..state import n_free, pack, unpack
from . import shooting
from .cycle_curve import locate_cycle_end
from .cycle_switching import OFFSET, Point, _March, _where, continue_family
from .kit import branch_directions, illinois
from .periodic import (
    ATOL,
    CLOSURE_TOL,
    RTOL,
    OrbitBranch,
    OrbitError,
    PeriodicOrbit,
    _crosses_one,
    _OrbitBranchProblem,
    _phase_for,
    _System,
    _to_y,
    continue_orbit,
    find_periodic_orbit,
)

#: The branch point's second multiplier lies within this of +1 (a double multiplier of a monodromy accurate to
#: about 1e-10 splits like its square root).
BRANCH_POINT_TOL = 1e-4
#: An orbit is mirror-symmetric, and its monodromy commutes with S, to this relative accuracy.
MIRROR_TOL = 1e-6
#: Largest amplitude of the first orbit of the new family (the default's search stops there).
MAX_AMPLITUDE = 0.2
#: A located event whose tangent's parameter component is below this (unit tangent) lies on a fold, not a branch point.
TURN_TOL = 1e-3
#: A system's branch point is refined on its old branch until the crossing multiplier is this near +1 ...
REFINE_TOL = 1e-9
#: ... in at most this many secant steps, each orbit found at its parameter value in this many steps.
REFINE_ITERATIONS, SUBSTEPS = 30, 5
#: Kinds of branch point (:attr:`BranchSwitch.kind`).
KINDS = ("mirror_symmetry_breaking", "branch_point")


@dataclass
class BranchSwitch:
    """The switch from an orbit branch onto the family that crosses it at a branch point of cycles.

    Attributes
    ----------
    point : PeriodicOrbit or shooting.Orbit
        The located branch point (two multipliers at +1).
    parameter : str
        ``M`` for the chain, the system's parameter otherwise.
    value : float
        p_BP.
    multiplier : complex
        The second multiplier nearest +1 (beside the trivial one) at the point.
    kind : str
        ``mirror_symmetry_breaking`` (the chain's new family breaks its mirror symmetry: module
        docstring) or ``branch_point``.
    along, direction : ndarray
        Unit tangents in w of the old branch and of the new family at the point.
    amplitude : float
        e . (w - w_BP) of the first orbit of the new family.
    orbit : PeriodicOrbit or shooting.Orbit
        That orbit (same turns as the branch), polished by the shooting Newton.
    side : str
        ``below`` (the new family's first orbit at smaller p, for the chain smaller |M|) or ``above``.
    branch : periodic.OrbitBranch or shooting.OrbitBranch or None
        The new family continued away from the point (None where not asked for; for the chain above it,
        :func:`~.cycle_switching.continue_family`'s, up in |M| and through its folds).
    """

    point: Point
    parameter: str
    value: float
    multiplier: complex
    kind: str
    along: np.ndarray
    direction: np.ndarray
    amplitude: float
    orbit: Point
    side: str
    branch: Any

    def as_dict(self) -> dict:
        """JSON-ready summary."""
        if self.branch is None:
            branch = None
        elif isinstance(self.branch, shooting.OrbitBranch):
            branch = self.branch.as_dict()
        else:
            branch = {"end": self.branch.end, "end_moment": self.branch.end_moment, "message": self.branch.message}
        return {
            "parameter": self.parameter,
            "value": self.value,
            "kind": self.kind,
            "period": self.point.period,
            "multiplier": [self.multiplier.real, self.multiplier.imag],
            "amplitude": self.amplitude,
            "side": self.side,
            "orbit": self.orbit.as_dict(),
            "branch": branch,
        }


def mirror(params: ChainParams) -> np.ndarray:
    """The chain's point reflection S about its middle particle as a matrix on the shooting's state y = (q, q').

    Raises
    ------
    ValueError
        Where the chain has no such symmetry: ends of different kinds, or a periodic chain.
    """
    left, right = params.ends
    if left != right or params.periodic:
        raise ValueError(f"the chain's ends ({left}, {right}, periodic={params.periodic}) are not mirror images: no mirror symmetry")
    nf = n_free(params)
    signs = np.array([-1.0, -1.0, 1.0])[:, None]
    columns = []
    for i in range(nf):
        q = np.zeros(nf)
        q[i] = 1.0
        columns.append(pack(params, signs * unpack(params, q)[:, ::-1]))
    block = np.column_stack(columns)
    return sla.block_diag(block, block)


def _symmetry(orbit: PeriodicOrbit, mono: np.ndarray) -> np.ndarray | None:
    """S where the chain's orbit is mirror-symmetric (S y0 = y0, S M = M S, the loaded particle the middle one), else None."""
    if orbit.particle != 0:
        return None
    try:
        s = mirror(orbit.params)
    except ValueError:
        return None
    y0 = _to_y(orbit.params, orbit.x, orbit.v)
    scale = max(1.0, float(np.max(np.abs(y0))))
    if np.max(np.abs(s @ y0 - y0)) > MIRROR_TOL * scale:
        return None
    if np.max(np.abs(s @ mono - mono @ s)) > MIRROR_TOL * max(1.0, float(np.max(np.abs(mono)))):
        return None
    return s


def _is_branch_point(event) -> bool:
    """Whether a system's located event has two multipliers at +1: the kit's ``branch_point``, or a change of
    stability through +1 (the kit's determinant test is lost where the continuation jumps onto the crossing
    family at the point, as on the pen's out-of-phase family: its stability event remains). Whether the
    parameter turns there (a fold) is asked of the branch's tangents (:func:`_old_tangent`)."""
    if not event.located or event.kind not in ("branch_point", "stability"):
        return False
    return bool(np.sort(np.abs(event.point.multipliers - 1.0))[1] <= BRANCH_POINT_TOL)


def _old_tangent(branch: shooting.OrbitBranch, event, tol: float, rtol: float, atol: float) -> np.ndarray:
    """The old branch's direction at a system's branch point: the mean of its unit tangents (null vectors of the
    shooting Jacobian) at the two orbits around the event. The event's own tangent will not do: the null space
    is two-dimensional at the point, and the kit's tangent there is any direction in it.

    Raises
    ------
    ValueError
        Where the parameter turns there (a fold of cycles, not a branch point).
    """
    tangents = []
    for orbit in branch.orbits[event.index - 1 : event.index + 1]:
        problem = shooting._Shooting(
            orbit.system, orbit.turns, orbit.y0, orbit.period, (shooting.PERIOD, branch.parameter), tol, rtol, atol
        )
        t = sla.svd(np.asarray(problem.evaluate(problem.pack(orbit), True).jacobian))[2][-1]
        tangents.append(t if not tangents or t @ tangents[0] >= 0 else -t)
    along = (tangents[0] + tangents[-1]) / 2
    if tangents[0][-1] * tangents[-1][-1] <= 0 or abs(along[-1]) < TURN_TOL * np.linalg.norm(along):
        raise ValueError(f"the parameter {branch.parameter} turns at {event.parameter!r}: a fold of cycles, not a branch point")
    return along


def _plus_one(orbit) -> float:
    """Re(mu_1 + mu_2) - 2 over the two multipliers nearest +1: the crossing one's distance from +1 beside the
    trivial one (a sum, well conditioned where the two meet)."""
    mu = orbit.multipliers
    return float(np.sum(mu[np.argsort(np.abs(mu - 1.0))[:2]]).real) - 2.0


def _old_family_orbit(orbit: shooting.Orbit, name: str, value: float, tol: float, rtol: float, atol: float) -> shooting.Orbit:
    """The orbit of ``orbit``'s family at ``name`` = ``value``, by :func:`~.shooting.find_orbit` in :data:`SUBSTEPS` steps."""
    for step in np.linspace(orbit.parameter(name), value, SUBSTEPS + 1)[1:]:
        orbit = shooting.find_orbit(orbit.system.with_parameters(**{name: float(step)}), orbit, tol=tol, rtol=rtol, atol=atol)
    return orbit


def _refined(branch: shooting.OrbitBranch, event, tol: float, rtol: float, atol: float):
    """A system's branch point on the old branch itself: the kit locates its event on the arclength, where the
    corrector can land on the crossing family near the point (the pen's event point lies 2e-3 off the old,
    symmetric, family). Here orbits of the old branch at fixed values of the parameter, each found by
    :func:`~.shooting.find_orbit` in :data:`SUBSTEPS` steps from the nearer of the two orbits around the event,
    bracket the zero of :func:`_plus_one`, narrowed by the Illinois secant to :data:`REFINE_TOL`."""
    name = branch.parameter
    low, high = branch.orbits[event.index - 1], branch.orbits[event.index]
    f_low, f_high = _plus_one(low), _plus_one(high)
    if f_low * f_high > 0:
        # The orbit after the event is the crossing family's (the continuation turned onto it at the point): the old
        # family's orbit just beyond the event (a twentieth of the last step), from the orbit before it, is the
        # bracket's other end.
        try:
            beyond = event.parameter + (event.parameter - low.parameter(name)) / 20.0
            high = _old_family_orbit(low, name, beyond, tol, rtol, atol)
        except shooting.OrbitNotFound:
            return event.point
        f_high = _plus_one(high)
        if f_low * f_high > 0:
            return event.point
    best = min((low, high), key=lambda o: abs(_plus_one(o)))
    side = 0
    for _ in range(REFINE_ITERATIONS):
        p_low, p_high = low.parameter(name), high.parameter(name)
        value = p_high - f_high * (p_high - p_low) / (f_high - f_low)
        nearer = low if abs(value - p_low) <= abs(value - p_high) else high
        orbit = nearer
        try:
            orbit = _old_family_orbit(nearer, name, value, tol, rtol, atol)
        except shooting.OrbitNotFound:
            break
        f = _plus_one(orbit)
        if abs(f) < abs(_plus_one(best)):
            best = orbit
        if abs(f) <= REFINE_TOL or abs(p_high - p_low) <= 1e-13 * max(1.0, abs(value)):
            break
        low, f_low, high, f_high, side = illinois(orbit, f, low, f_low, high, f_high, side)
    return best


def _located(start, parameter: str | None, index: int, tol: float, rtol: float, atol: float) -> tuple[Point, str, np.ndarray | None]:
    """The branch point ``start`` is or lies on, its parameter, and the old branch's direction (a chord or a
    tangent in w, None where only the point is given)."""
    if isinstance(start, shooting.OrbitBranch):
        found = []
        for event in (e for e in start.events if _is_branch_point(e)):
            try:
                found.append((event, _old_tangent(start, event, tol, rtol, atol)))
            except ValueError:
                continue  # a fold of cycles
        if len(found) <= index:
            raise ValueError(
                f"the branch in {start.parameter} has {len(found)} located branch point(s) of cycles, asked for number {index}: "
                "continue_orbits locates one where a real multiplier passes +1 while the parameter does not turn"
            )
        event, along = found[index]
        return _refined(start, event, tol, rtol, atol), start.parameter if parameter is None else parameter, along
    if isinstance(start, shooting.Orbit):
        raise ValueError("a system's branch point is switched from its branch (continue_orbits' located branch_point event)")
    if parameter not in (None, "M"):
        raise ValueError(f"the chain's branch point lies in the moment M, got parameter={parameter!r}")
    if isinstance(start, OrbitBranch):
        orbits = start.orbits
        # As the branch's events: crossings of +1 between consecutive orbits, but a fold's (the last pair at a fold end).
        last = len(orbits) - 1 - (start.end == "fold")
        pairs = [i for i in range(last) if _crosses_one(orbits[i], orbits[i + 1])]
        if len(pairs) <= index:
            raise ValueError(
                f"the branch has {len(pairs)} branch point(s) of cycles (a real multiplier through +1 while M does not turn), "
                f"asked for number {index}"
            )
        a, b = orbits[pairs[index]], orbits[pairs[index] + 1]
        point = locate_cycle_end([a, b], "fold_of_cycles", rtol=rtol, atol=atol)
        return point, "M", np.concatenate([_to_y(b.params, b.x, b.v) - _to_y(a.params, a.x, a.v), [0.0, b.moment - a.moment]])
    if not isinstance(start, PeriodicOrbit):
        raise ValueError(
            f"start must be an OrbitBranch or a PeriodicOrbit of the chain, or a system's OrbitBranch, got {type(start).__name__}"
        )
    return start, "M", None


def switch_at_branch_point(
    start: OrbitBranch | PeriodicOrbit | shooting.OrbitBranch,
    *,
    index: int = 0,
    parameter: str | None = None,
    amplitude: float | None = None,
    offset: float = OFFSET,
    follow: bool = True,
    tol: float = CLOSURE_TOL,
    rtol: float = RTOL,
    atol: float = ATOL,
    **continue_options,
) -> BranchSwitch:
    """The family of orbits that crosses an orbit branch at a branch point of cycles (module docstring).

    Parameters
    ----------
    start : periodic.OrbitBranch, PeriodicOrbit or shooting.OrbitBranch
        The chain's branch of :func:`~.periodic.continue_orbit` with a branch point among its
        ``events`` (its orbits around it are located first), or the chain's orbit at a located
        mirror-symmetry-breaking branch point; a system's branch of :func:`~.shooting.continue_orbits`
        with a located ``branch_point`` event.
    index : int
        Which branch point along the branch (0: the first).
    parameter : str, optional
        A system's parameter (the branch's own by default); the chain's is M.
    amplitude : float, optional
        a of the first orbit of the new family along its tangent (its sign picks one side, or one of
        the two mirror images); by default the first orbit at least ``offset`` |p_BP| from p_BP on the
        way out to :data:`MAX_AMPLITUDE`.
    offset : float
        Relative distance in p of the first orbit from the branch point (default amplitude only).
    follow : bool
        Continue the new family away from the branch point.
    tol, rtol, atol : float
        As for :func:`~.periodic.find_periodic_orbit`.
    **continue_options
        Passed to the continuation (``period_max``, ``max_points``, ``stop_at``, ...).

    Returns
    -------
    BranchSwitch

    Raises
    ------
    ValueError
        For a branch without the branch point asked for, a point without a second multiplier at +1,
        a chain's orbit given alone at a branch point that does not break the mirror symmetry (pass
        its branch), or bad amplitudes and offsets.
    OrbitError
        Where no orbit of the new family is found.
    """
    if not (math.isfinite(offset) and 0 < offset < 1):
        raise ValueError(f"offset must be a number in (0, 1) (relative distance in the parameter), got {offset!r}")
    if amplitude is not None and not (math.isfinite(amplitude) and amplitude != 0):
        raise ValueError(f"amplitude must be a finite non-zero number (along the new family's tangent), got {amplitude!r}")
    if not (isinstance(index, int) and index >= 0):
        raise ValueError(f"index must be an integer >= 0 (which branch point along the branch), got {index!r}")
    point, parameter, chord = _located(start, parameter, index, tol, rtol, atol)
    if isinstance(point, shooting.Orbit):
        problem = shooting._Shooting(point.system, point.turns, point.y0, point.period, (shooting.PERIOD, parameter), tol, rtol, atol)
        base, make_point, value = problem.pack(point), problem.orbit, point.parameter(parameter)
        evaluation = problem.evaluate(base, True)
        s_w = None
    else:
        model = get_model(point.model)
        phase = _phase_for(
            _System(point.params, model, point.moment, point.particle), _to_y(point.params, point.x, point.v), point.phase_normal
        )
        problem = _OrbitBranchProblem(point, model, phase, tol, rtol, atol, 0.0, math.inf, False, False)
        base, make_point, value = problem.pack(point), problem.point, point.moment
        if chord is not None:
            # The chord in y and M, into w = (y0's unknowns, log T, M).
            chord = np.concatenate([chord[:-2][phase.keep], [0.0, chord[-1]]])
        evaluation = problem.evaluate(base, True)
        s = _symmetry(point, evaluation.data)
        s_w = None if s is None else sla.block_diag(s[np.ix_(phase.keep, phase.keep)], np.eye(2))
    jacobian, mono = np.asarray(evaluation.jacobian), evaluation.data
    multipliers = np.linalg.eigvals(mono)
    second = complex(multipliers[np.argsort(np.abs(multipliers - 1.0))[1]])
    where = _where(point, parameter)
    if abs(second - 1.0) > BRANCH_POINT_TOL:
        raise ValueError(
            f"the orbit at {where} has its second multiplier nearest +1 at {second:.6g}: not a branch point of cycles "
            "(take a branch with the point among its events)"
        )
    null = sla.svd(jacobian)[2][-2:].T
    breaking = s_w is not None and abs(_antisymmetric_multiplier(s, mono) - 1.0) <= BRANCH_POINT_TOL
    if breaking:
        # In the null space S is +1 on the old (symmetric) branch's tangent and -1 on the new family's.
        values, vectors = np.linalg.eigh(null.T @ s_w @ null)
        along, direction = null @ vectors[:, -1], null @ vectors[:, 0]
        if not (values[0] < -0.5 and values[-1] > 0.5):
            raise OrbitError(f"the null space at {where} is not split by the mirror symmetry (S's values {values})")
        scale = max(1.0, float(np.max(np.abs(base))))

        def refuse(w: np.ndarray) -> bool:
            return bool(np.max(np.abs(s_w @ w - w)) <= MIRROR_TOL * scale)  # symmetric: the old branch

    else:
        if chord is None:
            raise ValueError(f"the branch point at {where} does not break the mirror symmetry: pass its branch, not the orbit")
        along = null @ (null.T @ chord)
        if np.linalg.norm(along) < 1e-3 * np.linalg.norm(chord):
            raise OrbitError(f"the old branch's direction at {where} lies outside the Jacobian's null space: not its branch point")
        along /= np.linalg.norm(along)
        direction = branch_directions(jacobian, along)

        def refuse(w: np.ndarray) -> bool:
            return False

    sign = 1.0 if amplitude is None else math.copysign(1.0, amplitude)
    march = _March(problem.evaluate, make_point, base, sign * direction, along, refuse, tol, where)
    system = isinstance(point, shooting.Orbit)

    def distance(orbit) -> float:
        return (orbit.parameter(parameter) if system else orbit.moment) - value

    if amplitude is None:
        wanted = offset * (abs(value) if value != 0 else 1.0)
        orbit = march.to(MAX_AMPLITUDE, enough=lambda o: abs(distance(o)) >= wanted)
    else:
        orbit = march.to(abs(amplitude))
    reached = sign * march.done[-1][0]
    if system:
        orbit = shooting.find_orbit(orbit.system, orbit, tol=tol, rtol=rtol, atol=atol)
        side = "below" if distance(orbit) < 0 else "above"
        branch = None
        if follow:
            branch = shooting.continue_orbits(
                orbit, parameter, direction=-1.0 if side == "below" else 1.0, tol=tol, rtol=rtol, atol=atol, **continue_options
            )
    else:
        orbit = find_periodic_orbit(
            point.params, point.model, orbit.moment, turns=orbit.turns, particle=point.particle, guess=orbit, tol=tol, rtol=rtol,
            atol=atol,
        )  # fmt: skip
        # For the chain "below" is towards smaller |M|, the way continue_orbit goes.
        side = "below" if distance(orbit) * math.copysign(1.0, value) < 0 else "above"
        branch = None
        if follow and side == "below":
            branch = continue_orbit(orbit, tol=tol, rtol=rtol, atol=atol, **continue_options)
        elif follow:
            branch = continue_family(orbit, tol=tol, rtol=rtol, atol=atol, **continue_options)
    return BranchSwitch(
        point, parameter, float(value), second, KINDS[0] if breaking else KINDS[1], along, direction, float(reached), orbit, side, branch
    )


def _antisymmetric_multiplier(s: np.ndarray, mono: np.ndarray) -> complex:
    """The multiplier nearest +1 of the monodromy's block on S's antisymmetric subspace."""
    q = sla.orth(np.eye(s.shape[0]) - s)
    mu = np.linalg.eigvals(q.T @ mono @ q)
    return complex(mu[np.argmin(np.abs(mu - 1.0))])


__all__ = ["KINDS", "BranchSwitch", "mirror", "switch_at_branch_point"]
