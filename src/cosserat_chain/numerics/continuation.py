"""Static branches under a moment load: continuation, the fold (critical moment) and the compliance.

Contract
--------
The equilibria of the chain under a moment M on one particle form a curve
(x(s), M(s)) in the space of configurations and loads, F(x) + M e = 0
(eqs. (1)-(3) with the velocities zero). This module traces it three ways:

* :func:`continue_in_moment`: pseudo-arclength continuation in M (Keller): the
  arclength constraint makes the bordered Jacobian [[-K, e], [t^T]] regular at
  folds, so the branch is followed past the critical moment, over a whole turn.
* :func:`rotation_branch`: the angle phi_0 of the loaded particle as the parameter
  (:func:`~cosserat_chain.numerics.newton.solve_rotation_controlled`), which gives
  the moment-rotation characteristic M(phi_0) at chosen angles.
* :func:`locate_fold`: the fold is where load control fails, K singular. On the
  rotation-controlled branch this is exactly dM/dphi_0 = 0 (from K q' = M' e along
  the branch: M' = 0 iff K q' = 0 with q' != 0), and dM/dphi_0 is an exact scalar
  function of phi_0 (implicit function theorem, one sparse solve), so the fold
  angle is a root of a smooth function found with Brent's method to round-off,
  and M_c = M(phi_fold) is accurate to round-off because M is stationary there.

:func:`compliance` is d phi_0 / dM at a state, (K^-1 e)_phi0; at rest it is the
slope of every model's branch at M = 0 (they share K there).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from typing import Any, NamedTuple

import numpy as np

from ..linalg import (
    BandMatrix,
    BorderedFactor,
    MixedBorderedFactor,
    MixedFactor,
    dot,
    euclidean_norm,
    infinity_norm,
    refined_solve,
    rotation_controlled_jacobian,
    sparse_solve,
)
from ..memory import FLOAT, require
from ..models.base import Model, get_model
from ..models.linear import rest_solve
from ..params import ChainParams
from ..state import ROW_INDEX, column, n_free, pack, unpack, zeros
from .brent import brentq
from .kit import BranchEnd, Continuation, Correction, Corrector, Evaluation, Event, continuation, newton
from .newton import NewtonError, moment_dof, round_off_floor, solve_rotation_controlled
from .stability import static_stability

#: Residual tolerance of the Newton solves at and around a fold: M_c is read off the
#: converged state, so it is only as accurate as the residual. Never below the round-off
#: floor of the chain's forces (:func:`~.newton.round_off_floor`), which exceeds it from
#: about N = 20 on.
FOLD_TOL = 1e-14
#: Most corrector iterations while locating a fold (linear convergence at a fold that is not simple).
FOLD_ITERATIONS = 60
#: First continuation step (arclength in (q, M)) on the paper's chain; see continue_in_moment.
STEP = 0.05
#: Largest step, in units of the first: the step grows where the branch is straight.
MAX_STEP_FACTOR = 20.0
#: Largest change of the loaded particle's angle in one step (rad): resolves M(phi_0).
PHI0_STEP = 0.1
#: Largest turn of the tangent in one step (rad): resolves the curve in (q, M) and
#: keeps the corrector on its branch.
MAX_TURN = 0.2
#: A step is sized for this fraction of PHI0_STEP and MAX_TURN, from the turns of the step before.
STEP_TARGET = 0.85
#: Most growth of the step from one point to the next.
STEP_GROWTH = 1.3
#: A fold passed again the other way, within these of an earlier one's angle (rad) and moment (relative), is
#: the trace going back along itself (``_StaticBranch._check_retrace``); the folds of the paper's geometry
#: at N = 3000, traced twice, agreed to 7e-11 in both.
RETRACE_PHI0_ATOL = 1e-8
RETRACE_MOMENT_RTOL = 1e-8
#: A corrector that moves further than this fraction of the state's size (and than the step) jumped.
#: The paper's chain of N = 1000 jumped by 0.0067 of its state's size (1.2 with a step of 0.19)
#: with a tenth allowed, onto a closed loop of the branch it then went round twice.
JUMP = 1e-3
#: The same, for steps shorter than ``refine_step`` of :func:`continue_in_moment` (next to a singular point).
JUMP_SINGULAR = 0.1
#: A corrector that moves further than this many steps jumped, whatever the state's size
#: (the largest correction that was not a jump: 7 steps, the sine model next to its fold at N = 1000).
JUMP_STEPS = 20.0
#: Most iterations of a continuation step's corrector that reuses factors of the Jacobian (then full Newton takes over).
CHORD_ITERATIONS = 16
#: That corrector factors the Jacobian anew at an iterate whose residual shrank by less than this.
CHORD_CONTRACTION = 0.25
#: ... and gives up where a step with a fresh factor raises the residual above this many times its first.
CHORD_DIVERGED = 100.0
#: That corrector refuses a step with the last point's factor that raises the residual (the kit's ``retreat``)
#: only from a start whose residual lies this many times above its limit (below, round-off rules it).
RETREAT_ABOVE = 10.0
#: Full Newton from the plain predictor, where the chord corrector fails, gives up (the step is
#: halved) when its smallest max |R| so far has not fallen by this factor over two iterations (the
#: kit's ``contraction`` of the best). Without it, the sine model at N = 10^4 spent seven fresh
#: factors on each of 134 of its 146 fallbacks, their residuals wandering between 1e-5 and 1e-2
#: against a limit of 9e-8. Of the best, not of each iterate: the nonlinear model's fallbacks at
#: N = 10^4 converge with residuals alternating up and down (1.3e-4, 2.3e-6, 2.3e-4, 2.3e-8, ...).
FALLBACK_CONTRACTION = 0.5
#: A fold's or branch point's corrector whose residual stops falling within this many times the
#: round-off floor (:func:`~.newton.round_off_floor`, an estimate) has converged to round-off.
STALL = 100.0
#: Halvings of the distance to the nearest solved angle before a fold search gives up.
MAX_HALVINGS = 12
#: A model's K at rest is the linear model's where they agree to this, relative to its norm (:func:`moment_response`).
REST_RTOL = 1e-12
#: The approach from rest (:func:`approach_from_rest`) solves the branch at angles phi_0 = APPROACH_ANGLE 2^-k, k = APPROACH_HALVINGS
#: .. 0 (rad; the trace starts at the last): where the moment is still far below the corrector's limit and K's bending modes
#: beyond double precision (a clamped chain of N = 10^5: M = 1e-14 at the first points, the limit 1e-11), the states are set
#: by the predictor alone, and past 1 rad the branch of the paper's geometry at N = 3 10^4 and 10^5 has stiffened (K's
#: smallest eigenvalue 1e-12 and 1e-13, 20 000 and 2 000 times the bending mode's at rest).
APPROACH_ANGLE = 1.0
APPROACH_HALVINGS = 12
#: The trace starts from rest where the band factor's compliance at rest lies within this of the rest response's
#: (:func:`moment_response`, through K's square root): 1.5e-3 at N = 10^4 on the paper's geometry, 0.33 at 3 10^4, 0.8 at 10^5.
APPROACH_RTOL = 1e-2
#: Where M_c is decided before the turn's end (``continue_in_moment(decided=True)``): the trace ends once the stable branch
#: from rest has ended at a fold, the loaded particle lies within END_ANGLE (rad) of the turn (``phi0_until_unstable``, else
#: ``phi0_stop``) and |M| has fallen to END_MOMENT times the largest maximum of M traced. On a long clamped chain the rest of
#: the turn runs towards the chain at rest turned once, where M falls towards the corrector's limit and K's soft modes are
#: those at rest, beyond its rounded entries (N = 10^4: M = 0.0108 at phi_0 = 6.02, 0.0033 at 6.20, 2.3e-5 at its last
#: fold at 6.2826, against M_c = 0.0672; N = 10^5's trace crawled there): a maximum holding more than M_c would need M to
#: rise fivefold within the last quarter radian.
END_ANGLE = 0.25
END_MOMENT = 0.2
#: Values a degree of freedom of the mixed form's factor (:class:`~cosserat_chain.linalg.MixedFactor`): its band LU over
#: the unknowns and four multipliers a bond, 28 values a column (half-bandwidth 9, LAPACK's storage), and the rows.
MIXED_VALUES = 90
#: Callback ``progress(done, total)`` used by the long-running functions.
ProgressCallback = Callable[[float, float], None]


@dataclass
class Fold:
    """A fold (limit point) of the static branch: the critical moment of load control.

    Attributes
    ----------
    moment : float
        M_c, the largest moment a static state on the branch can hold.
    phi0 : float
        Angle of the loaded particle at the fold (rad).
    x : ndarray (3, 2N+1)
        The state at the fold.
    particle : int
    """

    moment: float
    phi0: float
    x: np.ndarray
    particle: int = 0
    #: True at a maximum of M along the branch, False at a minimum, None if not known
    #: (a fold located on its own by :func:`locate_fold`).
    maximum: bool | None = None
    #: Negative eigenvalues of K just before and just after the fold along the branch
    #: (they differ by one: the change of stability; 0 is stable), None for a fold
    #: located on its own.
    index_before: int | None = None
    index_after: int | None = None
    #: Whether a re-solve near the fold found it too
    #: (:func:`~cosserat_chain.experiments.critical.critical_point` re-solves the folds that decide
    #: M_c where K's softest eigenvalue is near its round-off); None where it was not re-solved.
    confirmed: bool | None = None
    #: |M| difference to the re-solved fold of the same kind (inf where the re-solve found none;
    #: None where it was not re-solved): how well the two agree on M.
    discrepancy: float | None = None
    #: The particle (-N..N) whose angle the fold's mode (K's null vector: the branch's tangent
    #: there) turns most: the one that starts to rotate where a slowly loaded chain leaves the
    #: branch at this fold. None for a fold located on its own.
    mode_particle: int | None = None


@dataclass(frozen=True)
class BranchPoint:
    """A point of the static branch where K turns singular without a fold: another branch crosses it.

    The number of negative eigenvalues of K changes while M goes on rising or falling
    (a cantilever's free half under the nonlinear model, N = 3: at M = 0.0820,
    phi_0 = 4.23, before the fold at 0.0837). The branch traced on through it has
    changed its stability there; which state a chain pushed past it reaches, the
    crossing branch or a jump, the dynamics decide.

    Attributes
    ----------
    moment, phi0 : float
        Where the smallest eigenvalue of K vanishes, located along the arclength.
    x : ndarray (3, 2N+1)
    particle : int
    index_before, index_after : int
        Negative eigenvalues of K on either side (in the direction of tracing).
    after_point : int
        The branch point lies between the traced points ``after_point`` and ``after_point + 1``.
    mode_particle : int or None
        The particle (-N..N) whose angle K's softest eigenvector there turns most (None where not computed).
    located : bool
        Whether it was solved for (the smallest eigenvalue's root along the arclength); False
        where the corrector failed next to it or both sides are unstable: it is then a solved
        point within ``bracket`` of arclength of it.
    bracket : float
        That arclength (0 for a located point).
    """

    moment: float
    phi0: float
    x: np.ndarray
    particle: int
    index_before: int
    index_after: int
    after_point: int
    located: bool = True
    bracket: float = 0.0
    mode_particle: int | None = None


@dataclass
class Branch:
    """Points of a static branch, in the order they were traced.

    Attributes
    ----------
    moment : ndarray (k,)
    phi0 : ndarray (k,)
        Angle of the loaded particle.
    x : ndarray (k, 3, 2N+1), or (j, 3, 2N+1) with ``state_points``
        The states.
    stable : ndarray of bool (k,)
    critical_eigenvalue : ndarray (k,)
        See :class:`~cosserat_chain.numerics.stability.Stability`.
    folds : list of Fold
        Folds passed on the way, each located to round-off.
    branch_points : list of BranchPoint
        Changes of stability without a fold, in the order passed.
    particle : int
    stop : BranchEnd or str
        Why the tracing ended, in the kit's vocabulary (:class:`~.kit.BranchEnd`, equal to its
        string): "phi0_stop", "moment_stop", "max_folds" (the requested end), "returned" (the
        branch came back through the rest state before the loaded particle turned once, as a
        closed loop does), "reversed" (the trace turned back along itself where a cluster of
        folds or a branch point lies within the corrector's resolution: the branch beyond is not
        traced, ``message`` says where), "wound" (a particle other than the loaded one turned a full turn
        further than it: the chain rotates there, and the branch repeats its folds as that
        particle winds on; ``message`` names it), "max_points" (the point budget ran out
        first) or "step_too_small" (the corrector failed even at ``min_step``: a point where
        the branch is not smooth, such as a link of zero length; ``message`` says where): the
        branch is then incomplete; "given" for the angles of :func:`rotation_branch`.
    message : str
        What stopped a stalled, wound or reversed branch (empty otherwise).
    state_points : ndarray of int (j,) or None
        The points whose states ``x`` holds, where a trace kept only some
        (``max_states`` of :func:`continue_in_moment`); None where ``x`` holds every point's.
    approach : int
        The points after rest solved with the angle held at fixed angles before the trace
        (:func:`approach_from_rest`: a chain whose K at rest is beyond double precision), 0 where the trace starts at rest.
    """

    moment: np.ndarray
    phi0: np.ndarray
    x: np.ndarray
    stable: np.ndarray
    critical_eigenvalue: np.ndarray
    folds: list[Fold] = field(default_factory=list)
    particle: int = 0
    stop: str = "given"
    message: str = ""
    branch_points: list[BranchPoint] = field(default_factory=list)
    state_points: np.ndarray | None = None
    approach: int = 0

    @property
    def complete(self) -> bool:
        """False if the point budget ran out, the corrector stalled or the trace turned back along itself before the requested end."""
        return self.stop not in (BranchEnd.MAX_POINTS, BranchEnd.STEP_TOO_SMALL, BranchEnd.REVERSED)

    @property
    def stable_end(self) -> BranchPoint | None:
        """The branch point where the stable branch from rest ends (between the last stable point and
        the first unstable one), or None where it ends otherwise (at a fold) or never."""
        lost = np.flatnonzero(~self.stable)
        return next((q for q in self.branch_points if lost.size and q.after_point == lost[0] - 1), None)


def compliance(params: ChainParams, model: str | Model, *, particle: int = 0, x: np.ndarray | None = None) -> float:
    """d phi_0 / dM at the state ``x`` (default rest): the rotation compliance (K^-1 e)_phi0.

    Raises
    ------
    ValueError
        If K is singular at ``x`` (a fold).
    """
    return float(moment_response(params, model, particle=particle, x=x)[moment_dof(params, particle)])


def moment_response(params: ChainParams, model: str | Model, *, particle: int = 0, x: np.ndarray | None = None) -> np.ndarray:
    """K^-1 e at the state ``x`` (default rest): every free degree of freedom's response to a unit moment on ``particle``.

    At rest every model of the package has the linear model's K (eq. (3) is derived as the
    Hessian at rest): wherever the model's own K at rest equals it to round-off, an open chain's
    response is solved through K's square root (:func:`~cosserat_chain.models.linear.rest_solve`),
    which keeps the clamped chain's bending modes, eigenvalues falling like N^-4, that every
    factor of K's rounded entries loses: at N = 10^5 the band LU's compliance was 80 % off, and
    refined with residuals in extended precision 55 %; the square root's is 1.8e-14 from the
    closed form (:func:`~cosserat_chain.analysis.continuum.discrete_static` solves the same way:
    ``theory`` and ``critical`` give one compliance). Elsewhere (a ring, a state away from rest, a
    user's model whose K at rest differs) K is solved with residuals refined in extended
    precision (:func:`~cosserat_chain.linalg.refined_solve`).

    Raises
    ------
    ValueError
        If K is singular at ``x`` (a fold).
    """
    model = get_model(model)
    e = np.zeros(n_free(params))
    e[moment_dof(params, particle)] = 1.0
    singular = "the stiffness is singular at this state (a fold): the compliance is infinite"
    if x is None:
        stiffness = model.stiffness(params, zeros(params)).tocsr()
        linear = get_model("linear").stiffness(params).tocsr()
        shared = model.name == "linear" or infinity_norm(stiffness - linear) <= REST_RTOL * infinity_norm(linear)
        if shared and not params.periodic:
            try:
                return rest_solve(params, e)
            except ValueError:
                raise ValueError(singular) from None
        if shared:
            stiffness = linear
    else:
        stiffness = model.stiffness(params, x)
    try:
        return refined_solve(stiffness, e).x
    except ValueError:
        raise ValueError(singular) from None


def rest_resolved(params: ChainParams, model: str | Model, *, particle: int = 0, response: np.ndarray | None = None) -> bool:
    """Whether the trace's band factor of K at rest gives the rest response's compliance to :data:`APPROACH_RTOL`
    (``response``: :func:`moment_response` at rest, where known).

    Where it does not (a clamped chain of N = 3 10^4 on the paper's geometry: K's bending modes beyond double precision),
    :func:`continue_in_moment` starts from the approach (:func:`approach_from_rest`) instead of from rest.
    """
    model = get_model(model)
    dof = moment_dof(params, particle)
    seed = np.zeros(n_free(params) + 1)
    seed[-1] = 1.0
    banded = BorderedFactor(model.stiffness_band(params, zeros(params)), dof).solve(seed, seed)[dof]
    exact = (moment_response(params, model, particle=particle) if response is None else response)[dof]
    return bool(abs(banded - exact) <= APPROACH_RTOL * abs(exact))


def approach_from_rest(
    params: ChainParams, model: str | Model, *, particle: int = 0, response: np.ndarray | None = None
) -> list[tuple[np.ndarray, float]]:
    """The branch from rest at the angles phi_0 = :data:`APPROACH_ANGLE` 2^-k, k = :data:`APPROACH_HALVINGS` .. 0, as (state, M).

    Each is solved with the angle held (:func:`~.newton.solve_rotation_controlled`), the first from the rest response
    (:func:`moment_response`, K^-1 e through K's square root) scaled to its angle, each next from the one before scaled
    likewise. The list ends before the first angle whose moment does not rise (the branch passed a maximum of M between:
    the trace from the last point finds it) or whose solve fails. Where the angle is held, M is read off the equilibrium
    (the moment that holds it), which K's bending modes, undetermined by the residual, do not move. ``response``: the
    rest response where known.
    """
    model = get_model(model)
    dof = moment_dof(params, particle)
    response = moment_response(params, model, particle=particle) if response is None else response
    x, moment, angle = unpack(params, response / response[dof]), 1.0 / response[dof], 1.0
    out: list[tuple[np.ndarray, float]] = []
    for k in range(APPROACH_HALVINGS, -1, -1):
        target = APPROACH_ANGLE * 2.0**-k
        try:
            x, found = solve_rotation_controlled(
                params, model, target, particle=particle, x0=x * (target / angle), moment0=moment * (target / angle)
            )
        except NewtonError:
            break
        if out and found <= moment:
            break
        out.append((x, found))
        moment, angle = found, target
    return out


def largest_step(params: ChainParams, model: Model, particle: int, response: np.ndarray | None = None) -> float:
    """The default ``max_step`` of :func:`continue_in_moment`: :data:`MAX_STEP_FACTOR` times the first step, or the
    arclength along the branch's tangent at rest over which the loaded particle turns by 2 :data:`PHI0_STEP`, if longer.

    The branch's length per radian of phi_0 grows with N faster than the first step: the sine model's
    u and v are linear in the load, like N^2 times M (N = 3000: 23000 per radian; a first step of 1.7).
    Capped at 20 first steps, its full turn took 2782 points at N = 3000 and every one at the cap, and
    N = 10^4 crawled at 4e-4 rad a point; the turn limits, not the cap, then size the steps. ``response``: K^-1 e at
    rest (:func:`moment_response`) where the caller has it, else solved here.
    """
    try:
        response = moment_response(params, model, particle=particle) if response is None else response
    except ValueError:
        return MAX_STEP_FACTOR * default_step(params)
    turn = abs(float(response[moment_dof(params, particle)]))
    if not turn > 0.0:  # no rotation at rest: the first step's scale
        return MAX_STEP_FACTOR * default_step(params)
    return max(MAX_STEP_FACTOR * default_step(params), 2 * PHI0_STEP * float(np.linalg.norm(response)) / turn)


def moment_slope(params: ChainParams, model: str | Model, x: np.ndarray, *, particle: int = 0) -> float:
    """dM/dphi_0 along the rotation-controlled branch at the equilibrium ``x``.

    Differentiating F(q(phi_0)) + M(phi_0) e = 0 gives J dz/dphi_0 = K[:, phi_0]
    with J the rotation-controlled Jacobian and z the unknowns (q without phi_0, M).
    """
    model = get_model(model)
    dof = moment_dof(params, particle)
    stiffness = model.stiffness(params, x).tocsc()
    dz = sparse_solve(rotation_controlled_jacobian(stiffness, dof), stiffness[:, dof].toarray().ravel())
    return float(dz[dof])


def _assemble_branch(params, model, particle, moments, states, folds, checks=None, stop="given", phi0=None) -> Branch:
    """A Branch from its points; ``checks`` their stabilities if already computed, ``phi0`` their angles where
    ``states`` holds only some of them."""
    col = column(params, particle)
    x = np.asarray(states, dtype=float)
    checks = [static_stability(params, model, xi) for xi in x] if checks is None else checks
    return Branch(
        moment=np.array(moments, dtype=float),
        phi0=x[:, ROW_INDEX["phi"], col].copy() if phi0 is None else np.array(phi0, dtype=float),
        x=x,
        stable=np.array([c.stable for c in checks]),
        critical_eigenvalue=np.array([c.critical_eigenvalue for c in checks]),
        folds=folds,
        particle=particle,
        stop=stop,
    )


def rotation_branch(
    params: ChainParams,
    model: str | Model,
    phi0: np.ndarray,
    *,
    particle: int = 0,
    progress: ProgressCallback | None = None,
) -> Branch:
    """The characteristic M(phi_0) at the angles ``phi0`` (traced in order from rest).

    Parameters
    ----------
    phi0 : array_like (k,)
        Angles of the loaded particle; consecutive angles should be close (a few
        degrees) since each solve starts from the previous one.

    Raises
    ------
    NewtonError
        If a point cannot be solved (for example a step in phi0 that is too large).
    """
    model = get_model(model)
    angles = np.asarray(phi0, dtype=float)
    x, moment = zeros(params), 0.0
    previous = None
    moments, states = [], []
    for i, angle in enumerate(angles):
        guess_x, guess_m = x, moment
        if previous is not None and i > 0 and angles[i - 1] != previous[2]:
            # Secant predictor from the last two points.
            ratio = (angle - angles[i - 1]) / (angles[i - 1] - previous[2])
            guess_x = x + ratio * (x - previous[0])
            guess_m = moment + ratio * (moment - previous[1])
        new_x, new_m = solve_rotation_controlled(params, model, angle, particle=particle, x0=guess_x, moment0=guess_m)
        previous = (x, moment, angles[i - 1] if i > 0 else 0.0)
        x, moment = new_x, new_m
        moments.append(moment)
        states.append(x)
        if progress is not None:
            progress(i + 1, len(angles))
    return _assemble_branch(params, model, particle, moments, states, [])


def locate_fold(
    params: ChainParams,
    model: str | Model,
    *,
    particle: int = 0,
    bracket: tuple[float, float] | None = None,
    phi0_max: float = math.pi,
    seed: tuple[np.ndarray, float] | None = None,
) -> Fold | None:
    """The first fold of the branch from rest under a positive moment, to round-off.

    Parameters
    ----------
    bracket : (float, float), optional
        Angles phi_0 between which dM/dphi_0 changes sign (any fold, also a
        minimum of M), located on the rotation-controlled branch; by default the
        first fold of :func:`continue_in_moment` up to |phi_0| = ``phi0_max``
        (a scan in phi_0 missed the folds of long chains, whose branch turns back in phi_0).
    seed : (ndarray (3, 2N+1), float), optional
        A nearby equilibrium and its moment to start Newton from.

    Returns
    -------
    Fold or None
        None if M(phi_0) has no maximum up to ``phi0_max`` (the linear model).
    """
    model = get_model(model)
    cache: dict[float, tuple[np.ndarray, float]] = {0.0: (zeros(params), 0.0)}
    if seed is not None:
        cache[float(seed[0][ROW_INDEX["phi"], column(params, particle)])] = seed

    def solve(angle: float, depth: int = 0) -> tuple[np.ndarray, float]:
        nearest = min(cache, key=lambda a: abs(a - angle))
        try:
            x, moment = solve_rotation_controlled(
                params, model, angle, particle=particle, x0=cache[nearest][0], moment0=cache[nearest][1], tol=FOLD_TOL
            )
        except NewtonError:
            # Too far from the nearest solved angle (a long chain's branch changes shape
            # quickly): walk there through the midpoint.
            if depth >= MAX_HALVINGS:
                raise
            solve(0.5 * (nearest + angle), depth + 1)
            return solve(angle, depth + 1)
        cache[angle] = (x, moment)
        return x, moment

    def slope(angle: float) -> float:
        return moment_slope(params, model, solve(angle)[0], particle=particle)

    if bracket is None:
        folds = continue_in_moment(params, model, particle=particle, phi0_stop=phi0_max, max_folds=1).folds
        return folds[0] if folds else None
    phi_fold = brentq(slope, *bracket, xtol=1e-15, rtol=4 * np.finfo(float).eps)
    x, moment = solve(phi_fold)
    return Fold(moment=moment, phi0=phi_fold, x=x, particle=particle)


def _turning_particle(params: ChainParams, mode: np.ndarray) -> int:
    """The particle (-N..N) whose angle a mode (3, 2N+1) turns most."""
    return int(np.argmax(np.abs(mode[ROW_INDEX["phi"]]))) - params.N


def _passes_rest(before: np.ndarray, after: np.ndarray, moment_before: float, moment_after: float) -> bool:
    """Whether the chord between two points of the branch, on which M changes sign, passes the rest state.

    The state where the chord crosses M = 0 lies within half the chord's length of
    rest, with every angle small. Other static states without load have a particle
    turned by pi or more (the sine model's forces vanish at phi = pi), which a long
    chord can also pass within half its length: the angles tell them apart.
    """
    crossing = before + moment_before / (moment_before - moment_after) * (after - before)
    near = np.linalg.norm(crossing) <= 0.5 * np.linalg.norm(after - before)
    return bool(near and np.max(np.abs(crossing[ROW_INDEX["phi"]]), initial=0.0) < 0.5)


def branch_memory(params: ChainParams, max_points: int, max_states: int | None = None, *, mixed: bool = False) -> int:
    """Bytes a branch of up to ``max_points`` points needs, keeping at most ``max_states`` states (None: every one).

    The kept states (the branch's x) are held twice at the end (the list and its array), beside
    the stiffness and its banded factors (about 60 values a degree of freedom; with ``mixed``, the
    mixed form's band LU, :data:`MIXED_VALUES` more) and, for every point, its moment, angle and
    stability (about 40 values: the per-point record, not the state).
    """
    states = max_points if max_states is None else min(max_points, max_states)
    factors = 60 + (MIXED_VALUES if mixed else 0)
    return FLOAT * (3 * params.n_particles * (states + 2 + factors) + 40 * max_points)


def require_branch_memory(params: ChainParams, max_points: int, max_states: int | None = None, *, mixed: bool = False) -> None:
    """Refuse a branch that would not fit in memory (:func:`branch_memory`, :func:`cosserat_chain.memory.require`)."""
    states = max_points if max_states is None else min(max_points, max_states)
    require(
        branch_memory(params, max_points, max_states, mixed=mixed),
        f"a branch of up to {max_points} points keeping {states} states of {params.n_particles} particles (N={params.N})",
        "trace fewer points (max_points, --max-points) or a shorter chain",
    )


def default_step(params: ChainParams) -> float:
    """The first arclength step of :func:`continue_in_moment`: :data:`STEP` sqrt(n_free / 15) (0.05 for the paper's chain)."""
    return STEP * math.sqrt(n_free(params) / 15)


@dataclass(frozen=True)
class _Stops:
    """Where :func:`continue_in_moment` stops tracing (its parameters of the same names)."""

    phi0_stop: float
    phi0_until_unstable: float | None
    moment_stop: float
    max_folds: int | None
    decided: bool = False


class _Assembled(NamedTuple):
    """What a corrector's evaluation of the static branch carries beside F + M e: K (None in a chord
    iteration), the residual's round-off floor and the tolerance it is held to there."""

    k: BandMatrix | None
    floor: float
    limit: float


@dataclass
class _Point:
    """A corrected point of the static branch: w = (q, M), its state, stiffness, the factor of K that
    solved for its tangent, the turns of the step to it and (once reviewed) its stability.

    Once the next point is kept, only ``index`` is read: the rest is dropped (a long chain's branch
    keeps thousands of points, each state as large as the chain).
    """

    z: np.ndarray | None
    x: np.ndarray | None
    k: BandMatrix | None
    factor: BorderedFactor | None
    tangent: np.ndarray | None
    check: Any = None
    index: int = 0
    iterations: int = 0
    chord: bool = False
    turned: float = 0.0
    turn: float = 0.0

    def drop(self) -> None:
        self.z = self.x = self.k = self.factor = self.tangent = None


class _StaticBranch:
    """The static branch F(q) + M e = 0, w = (q, M), as a problem of the kit's driver (:func:`~.kit.continuation`).

    The driver steps; this problem takes over the stages where a long chain's branch needs
    more than the driver's defaults (see :class:`~.kit.ContinuationProblem`):

    * ``correct``: the kit's corrector in chord iterations with the banded factor of the last
      point, from a start bent along the branch's curvature, then in full Newton from the plain
      predictor where they fail; a correction that moved far off the predictor jumped (:meth:`_jumped`);
    * ``review``: a step is retaken shorter where the loaded particle turned by more than
      :data:`PHI0_STEP` or the tangent by more than :data:`MAX_TURN`, and down to
      ``refine_step`` towards a crossing of an eigenvalue of K;
    * ``events`` and ``locate``: a fold where the tangent's M component changes sign (its root
      along the arclength, Brent's method), a branch point where the index of K changes without
      it (the root of K's smallest eigenvalue);
    * ``next_step``: sized for :data:`STEP_TARGET` of the turn limits at the rates of the step taken.

    Every point's moment, angle and stability is kept, and the states of every ``stride``-th point (``max_states``).
    """

    def __init__(self, params: ChainParams, model: Model, particle: int, *, tol, min_step, max_step, refine_step, stops, max_states, progress, mixed=False):
        self.params, self.model, self.particle, self.mixed = params, model, particle, mixed
        self.tol, self.min_step, self.max_step, self.refine_step = tol, min_step, max_step, refine_step
        self.stops, self.max_states, self.progress = stops, max_states, progress
        self.dof = moment_dof(params, particle)
        self.nf = n_free(params)
        self.col = column(params, particle)
        # A conservative model's symmetric matrix is its stiffness (Model.symmetric_similar):
        # the stability of a point then reuses the stiffness its corrector assembled.
        self.reuse_stiffness = model.conservative and type(model).symmetric_similar is Model.symmetric_similar
        # Inverse iteration at a point starts from the previous point's lowest eigenvector.
        self.eigenvector = np.zeros(self.nf)
        # A step shortened on the way to a crossing of an eigenvalue (``resume``: the step from
        # before), and the arclength within which the crossing lies ahead (``crossing``).
        self.resume = self.crossing = 0.0
        self.lost = False  # whether a traced point is unstable: the stable branch from rest has ended
        self.bend = np.zeros(self.nf + 1)
        self.folds = 0
        self.located_folds: list[Fold] = []
        self.unlocated = ""  # a fold the corrector could not locate (stop: BranchEnd.STEP_TOO_SMALL), empty while none
        self.reversal = ""  # why the trace is going back along itself (stop: BranchEnd.REVERSED), empty while it is not
        self.last_step = 0.0  # the last step tried, for the message of a stalled branch

    # The equations and their pieces.

    def residual(self, w: np.ndarray) -> np.ndarray:
        r = self.model.packed_forces(self.params, w[:-1])
        r[self.dof] += w[-1]
        return r

    def stiffness(self, w: np.ndarray) -> BandMatrix:
        return self.model.stiffness_band(self.params, unpack(self.params, w[:-1]))

    def factor_of(self, w: np.ndarray, k: BandMatrix) -> BorderedFactor | MixedBorderedFactor:
        """The factor of the bordered systems at w whose stiffness is ``k``: the band LU of K's entries, or where
        ``mixed`` (K's soft modes beyond them) the mixed form of the model's rows (:mod:`~cosserat_chain.linalg.mixed`)."""
        if not self.mixed:
            return BorderedFactor(k, self.dof)
        rows = self.model.stiffness_rows(self.params, unpack(self.params, w[:-1]))
        return MixedBorderedFactor(MixedFactor.from_rows(rows, self.nf), k, self.dof)

    def evaluate(self, w: np.ndarray, jacobian: bool) -> Evaluation:
        """F + M e at w; the Jacobian is the bordered factor of K (only the driver's start asks for it)."""
        r = self.residual(w)
        if not jacobian:
            return Evaluation(r)
        k = self.stiffness(w)
        floor = round_off_floor(k, w[:-1])
        return Evaluation(r, lambda: self.factor_of(w, k), _Assembled(k, floor, max(self.tol * (1.0 + abs(w[-1])), floor)))

    def converged(self, evaluation: Evaluation, size: float) -> bool:
        """The driver's test of its start (rest, or the last point of the approach): max |F + M e| within the corrector's
        limit there, its tolerance or the residual's round-off floor (:meth:`evaluate`)."""
        return size <= (self.tol if evaluation.data is None else evaluation.data.limit)

    def _unit_tangent(self, factor: BorderedFactor, previous: np.ndarray) -> np.ndarray:
        """The unit tangent at the point of ``factor``, oriented along ``previous`` (the bordered solve's border)."""
        rhs = np.zeros(self.nf + 1)
        rhs[-1] = 1.0
        t = factor.solve(previous, rhs)
        return t / euclidean_norm(t)

    def stability(self, x: np.ndarray, k: BandMatrix | None, guess: float | None = None, factor: BorderedFactor | None = None):
        """The stability of x (``factor``: the tangent's factor of K there, whose inertia is the index)."""
        if not self.reuse_stiffness:
            return static_stability(self.params, self.model, x, guess=guess, start=self.eigenvector)
        index = None if factor is None else factor.negative_eigenvalues
        return static_stability(self.params, self.model, x, guess=guess, similar=k, start=self.eigenvector, index=index)

    def rest(self, approach: list[tuple[np.ndarray, float]] = ()) -> _Point:
        """The branch's first point, the rest state, then the ``approach`` (states and moments solved at angles, rising
        from rest: :func:`approach_from_rest`); the last is the trace's start (the driver's start gives its tangent).

        An approach point's critical eigenvalue within its round-off keeps the index last decided (as :meth:`review`).
        """
        x = zeros(self.params)
        check = self.stability(x, None)
        self.y_phi0 = 0.0
        self.moments, self.angles, self.checks = [0.0], [0.0], [check]
        self.states, self.kept, self.stride = [x], [0], 1
        for state, moment in approach:
            found = self.stability(state, self.stiffness(np.append(pack(self.params, state), moment)))
            if abs(found.critical_eigenvalue) <= found.resolution:
                found = replace(found, index=check.index, stable=check.index == 0)
            check = found
            self.y_phi0 = float(state[ROW_INDEX["phi"], self.col])
            self._record(state, moment, check)
            x = state
        self.previous_state, self.previous_moment = x, self.moments[-1]
        self.step_tangent = np.zeros(self.nf + 1)
        self.step_tangent[-1] = 1.0
        self.last = _Point(None, None, None, None, None, check, check.index)
        return self.last

    def _record(self, x: np.ndarray, moment: float, check) -> None:
        """A new last point's moment, angle and stability, and its state where kept (every ``stride``-th, ``max_states``)."""
        self.moments.append(moment)
        self.angles.append(self.y_phi0)
        if (len(self.moments) - 1) % self.stride == 0:
            self.kept.append(len(self.moments) - 1)
            self.states.append(x)
            if self.max_states is not None and len(self.states) > self.max_states:
                # Every other kept state goes: the points kept stay evenly spaced from rest.
                self.kept, self.states, self.stride = self.kept[::2], self.states[::2], 2 * self.stride
        self.checks.append(check)

    # The stages the driver calls.

    def tangent(self, jacobian: BorderedFactor, previous: np.ndarray | None) -> np.ndarray:
        """At the start, towards increasing M; after, the candidate's (:meth:`point`)."""
        if previous is not None:
            return self.candidate.tangent
        seed = np.zeros(self.nf + 1)
        seed[-1] = 1.0
        self.factor, self.norm = jacobian, infinity_norm(jacobian.stiffness)
        return self._unit_tangent(jacobian, seed)

    def correct(self, w: np.ndarray, t: np.ndarray, h: float, jacobian) -> Correction:
        """Chord iterations from the bent predictor, and full Newton from the plain one where they fail
        (while it contracts: :data:`FALLBACK_CONTRACTION`)."""
        self.last_step, self.step_tangent = h, t
        found = self._correct_chord(w, t, h)
        self.chord = found.converged
        return found if found.converged else self._correct(w, t, h, self.tol, contraction=FALLBACK_CONTRACTION)

    def point(self, w: np.ndarray, evaluation: Evaluation, iterations: int) -> _Point:
        factor = evaluation.matrix()
        x = unpack(self.params, w[:-1])
        t = self._unit_tangent(factor, self.step_tangent)
        self.candidate = _Point(
            w,
            x,
            evaluation.data.k,
            factor,
            t,
            iterations=iterations,
            chord=self.chord,
            turned=abs(x[ROW_INDEX["phi"], self.col] - self.y_phi0),
            turn=math.acos(min(1.0, abs(dot(t, self.step_tangent)))),
        )
        return self.candidate

    def review(self, previous: _Point, candidate: _Point, h: float) -> float | None:
        """Retake a step whose turns exceed their limits, or that approaches or hides a crossing of an eigenvalue."""
        if (candidate.turned > PHI0_STEP or candidate.turn > MAX_TURN) and h > self.min_step:
            return max(self.min_step, h / 2)
        before = self.checks[-1]
        check = self.stability(candidate.x, candidate.k, before.critical_eigenvalue, candidate.factor)
        if abs(check.critical_eigenvalue) <= check.resolution:
            # An eigenvalue within its round-off (Stability.resolution) has no sign: the
            # stability and index it gives are noise, and the branch keeps the index last
            # decided (a clamped-free chain of N = 1000 has its softest eigenvalue at 6e-14,
            # below its resolution 1.4e-13, computed at -6e-15 at every third point: those
            # were "unstable", and the stable branch from rest ended at its first point).
            # A real crossing shows at the next point whose eigenvalue is decided.
            check = replace(check, index=previous.index, stable=previous.index == 0)
        falling = check.critical_eigenvalue < 0.5 * before.critical_eigenvalue
        if falling and before.critical_eigenvalue > 100.0 * check.resolution and h > self.refine_step:
            # A positive critical eigenvalue falling fast (or through zero): a fold ahead, or a pair of folds
            # (a small maximum and minimum of M) that a longer step passes with no change
            # of the index. Approach it in shorter steps (N = 10, a = 0.3, b = 0.1,
            # E1 = 2, E2 = 0.3 has such a pair within 0.015 rad of phi_0 near 1.0). An
            # eigenvalue near its round-off (a long chain's softest) is noise: not a sign.
            # The step from before comes back once the crossing is passed (next_step).
            self.resume = max(self.resume, h)
            return max(self.refine_step, h / 2)
        turns_back = candidate.tangent[-1] * self.step_tangent[-1] < 0
        unmatched = abs(check.index - previous.index) != 1 if turns_back else check.index != previous.index
        if unmatched and h > self.refine_step:
            # An eigenvalue of K crosses zero within this step without the one turn of M
            # that a single fold shows, or M turns without the one crossing a simple fold
            # has: more folds (a maximum and a minimum of M that the step passes together)
            # or a branch point lie in it, or the corrector landed off the branch traced (the
            # paper's geometry with N = 20, clamped-pinned: a step of 0.05 across a minimum
            # of M, index 1 at both ends where short steps find 1 before the fold and 2
            # after it, and the fold's corrector found no point between). Approach the crossing in
            # steps down to refine_step, so that each fold shows as a turn between points,
            # then go on with the step from before. The crossing lies within ``crossing`` of
            # y: the steps bisect towards it (steps of 1/8 that then grew by 1.3 a point
            # approached it in many short accepted steps).
            self.resume, self.crossing = max(self.resume, h), h
            return max(self.refine_step, h / 2)
        candidate.check, candidate.index = check, check.index
        return None

    def failed(self, h: float) -> float:
        """Half the step; the driver ends the branch below ``min_step``."""
        return h / 2

    def events(self, previous: _Point, candidate: _Point, t_before: np.ndarray, t_after: np.ndarray) -> list[str]:
        if t_after[-1] * t_before[-1] < 0:
            return ["fold"]  # M turned between the two points
        if candidate.index != previous.index and (self.model.conservative or (candidate.index - previous.index) % 2):
            # Eigenvalues of K through zero at the shortest step without a turn of M: K
            # singular off a fold, a branch point. (A non-symmetric K's complex pair
            # crossing changes the count by two and leaves K regular.)
            return ["branch_point"]
        return []

    def locate(self, kind: str, w: np.ndarray, t: np.ndarray, h: float, previous: _Point, candidate: _Point, index: int) -> Event:
        if kind == "fold":
            self.folds += 1
            try:
                fold = self._fold_between(w, t, h, candidate.z, candidate.tangent[-1], previous.index, candidate.index)
            except NewtonError as err:
                # The trace so far is kept and ends here (BranchEnd.STEP_TOO_SMALL), rather than lost.
                self.unlocated = (
                    f"a fold lies between M = {w[-1]:.10g} and M = {candidate.z[-1]:.10g} (phi_0 = {self.y_phi0:.10g} to "
                    f"{candidate.x[ROW_INDEX['phi'], self.col]:.10g} rad) but was not located ({err}): the branch beyond is not traced"
                )
                return Event(kind, None, float(candidate.z[-1]), index, located=False)
            self._check_retrace(fold)
            self.located_folds.append(fold)
            return Event(kind, fold, fold.moment, index)
        point = self._branch_point_between(w, t, h, previous.index, candidate.index, index - 1)
        return Event(kind, point, point.moment, index, located=point.located)

    def confirm(self, kind: str, point) -> bool:
        return True  # every fold and branch point is located along the arclength, none is a false alarm

    def _check_retrace(self, fold: Fold) -> None:
        """Note a trace that has turned back along itself: ``fold`` is an earlier fold passed the other way.

        Where a cluster of folds or a branch point lies within the corrector's resolution, an odd
        number of false turns of the tangent there sends the trace back along the branch already
        traced: it then passes the same folds in reverse order, each at the same moment and angle
        with its stiffness index changing the other way (the paper's geometry at N = 3000 turned back
        at phi_0 = 6.27536, M = 3.6e-4, and came back through the rest state: a "returned" branch, as
        if complete). A pair of adjacent folds may be a real small maximum and minimum of M; a
        non-adjacent one repeated is the retrace, and the branch beyond the turning point is not traced.
        """
        for earlier in self.located_folds[:-1]:
            if (
                (earlier.index_before, earlier.index_after) == (fold.index_after, fold.index_before)
                and abs(earlier.phi0 - fold.phi0) <= RETRACE_PHI0_ATOL
                and abs(earlier.moment - fold.moment) <= RETRACE_MOMENT_RTOL * max(abs(earlier.moment), abs(fold.moment))
            ):
                turned = self.located_folds[-1]
                self.reversal = (
                    f"the trace turned back along itself near phi_0 = {turned.phi0:.10g} rad, M = {turned.moment:.10g} (a cluster "
                    f"of folds or a branch point within the corrector's resolution) and passed again the fold at phi_0 = "
                    f"{earlier.phi0:.10g} rad, M = {earlier.moment:.10g}: the branch beyond that point is not traced"
                )
                return

    def next_step(self, h: float, correction: Correction, candidate: _Point) -> float:
        """Keep the point (:meth:`_keep`) and size the next step."""
        ds, before = h, self.checks[-1]
        rising = 0.0 < before.critical_eigenvalue < candidate.check.critical_eigenvalue
        if self.resume > 0.0 and (candidate.index != before.index or rising):
            # The refined crossing is passed (the index changed), or the critical eigenvalue
            # turned back up before zero: the step from before the refinement resumes
            # (growing back by 1.3 a point took 30 points after each of the 60 folds and
            # branch points of N = 1000; where it is too long, the turn limits halve it).
            ds, self.resume, self.crossing = self.resume, 0.0, 0.0
        elif self.crossing > 0.0:
            # Short of a crossing known to lie ahead: half the rest of the way, or, where the
            # arclength's estimate of it is spent without a crossing, on with the step from before.
            self.crossing -= h
            if self.crossing > 0.0:
                ds = max(self.refine_step, self.crossing / 2)
            else:
                ds, self.resume, self.crossing = self.resume, 0.0, 0.0
        self._keep(h, candidate)
        if self.crossing == 0.0:
            # The next step is sized for STEP_TARGET of the turn limits at the rate of this one
            # (growing the step by 1.3 where both turns stayed below half their limits, and
            # keeping it otherwise, left the loaded particle turning 0.065 rad a step on average:
            # 2080 points for the turn of N = 1000 where this takes 1709). It grows only where
            # its corrector needed at most one new factor (full Newton: two iterations).
            grow = min(
                STEP_GROWTH,
                STEP_TARGET * PHI0_STEP / max(candidate.turned, 1e-300),
                STEP_TARGET * MAX_TURN / max(candidate.turn, 1e-300),
            )
            if candidate.iterations > (1 if candidate.chord else 2):
                grow = min(grow, 1.0)
            ds = min(self.max_step, max(self.min_step, max(0.5, grow) * ds))
        return ds

    def _keep(self, taken: float, candidate: _Point) -> None:
        """The candidate becomes the branch's last point: its records, and the next step's start."""
        # The tangent's turn per arclength, normal to the new tangent: the next corrector's bent start.
        bend = (candidate.tangent - self.step_tangent) / taken
        bend -= dot(bend, candidate.tangent) * candidate.tangent
        self.bend, self.factor, self.norm = bend, candidate.factor, infinity_norm(candidate.k)
        self.previous_moment = self.moments[-1]
        self.y_phi0 = candidate.x[ROW_INDEX["phi"], self.col]
        self._record(candidate.x, candidate.z[-1], candidate.check)
        self.lost = self.lost or not candidate.check.stable
        self.last.drop()
        self.last = candidate

    def stop(self, candidate: _Point) -> tuple[BranchEnd, str] | None:
        stops, x, moment = self.stops, candidate.x, candidate.z[-1]
        phi = abs(self.y_phi0)
        angles = np.abs(x[ROW_INDEX["phi"]])
        lead = int(np.argmax(angles))
        if self.progress is not None:
            until = stops.phi0_until_unstable
            total = until if until is not None and (phi < until or self.lost) else stops.phi0_stop
            self.progress(min(phi, total), total)
        end = None
        if self.unlocated:
            end = (BranchEnd.STEP_TOO_SMALL, self.unlocated)
        elif self.reversal:
            end = (BranchEnd.REVERSED, self.reversal)
        elif moment * self.previous_moment < 0 and len(self.moments) > 2 and _passes_rest(self.previous_state, x, self.previous_moment, moment):
            # Back through the rest state: going on would trace the mirrored branch
            # (x -> -x, M -> -M) and come back here, as a closed loop does.
            end = (BranchEnd.RETURNED, "")
        elif phi >= stops.phi0_stop or (stops.phi0_until_unstable is not None and phi >= stops.phi0_until_unstable and self.lost):
            end = (BranchEnd.ANGLE_LIMIT, "")
        elif abs(moment) > stops.moment_stop:
            end = (BranchEnd.LOAD_LIMIT, "")
        elif stops.max_folds is not None and self.folds >= stops.max_folds:
            end = (BranchEnd.MAX_FOLDS, "")
        elif stops.decided and (decided := self._decided(phi, moment)):
            end = (BranchEnd.DECIDED, decided)
            if self.progress is not None:
                self.progress(total, total)  # what the trace was for is done: the progress to its end
        elif angles[lead] - phi >= 2 * math.pi:
            # Another particle has turned a full turn further than the loaded one (a pinned end
            # that turns first: clamped-pinned N = 1, h = 1, a = 0.45, b = 0.1, E1 = 0.5, E2 = 1.5,
            # sine model): it winds on while phi_0 stays bounded, M repeating its folds (208 in
            # 5000 points before), and phi0_stop would never come.
            end = (
                BranchEnd.WOUND,
                f"particle {lead - self.params.N} turned by {angles[lead]:.6g} rad, a full turn more than the loaded particle "
                f"{self.particle} (phi_0 = {self.y_phi0:.6g}): the chain rotates at particle {lead - self.params.N}, and the branch "
                "beyond repeats its folds as it winds on",
            )
        self.previous_state = x
        return end

    def _decided(self, phi: float, moment: float) -> str:
        """Why M_c is decided at a point at |phi_0| = ``phi`` holding ``moment`` (:data:`END_ANGLE`, :data:`END_MOMENT`), or ''."""
        turn = self.stops.phi0_until_unstable if self.stops.phi0_until_unstable is not None else self.stops.phi0_stop
        peak = max((f.moment for f in self.located_folds if f.maximum), default=None)
        if not self.lost or peak is None or peak <= 0.0 or phi < turn - END_ANGLE or abs(moment) > END_MOMENT * peak:
            return ""
        return (
            f"M_c is decided: the stable branch from rest has ended, and {turn - phi:.3g} rad short of the turn M = {moment:.6g}, "
            f"{abs(moment) / peak:.3g} of the largest maximum traced ({peak:.10g}); the rest of the turn is not traced"
        )

    def branch(self, traced: Continuation) -> Branch:
        """The traced branch with its folds, branch points and end."""
        message = ""
        if self.unlocated:
            message = self.unlocated
        elif traced.end == BranchEnd.STEP_TOO_SMALL:
            # The branch is not smooth here (the nonlinear model's energy has a cone where a
            # link's length vanishes: two particles' corners meet), or the corrector cannot
            # follow it. What was traced is kept.
            message = (
                f"continuation stalled at M = {self.moments[-1]:.6g}, phi_0 = {self.y_phi0:.6g}: the corrector failed even with "
                f"step {self.last_step:.3g} (a point where the branch is not smooth, e.g. a link of zero length)"
            )
        elif traced.end in (BranchEnd.WOUND, BranchEnd.REVERSED, BranchEnd.DECIDED):
            message = traced.message
        folds = [event.point for event in traced.events if event.kind == "fold" and event.located]
        # The kept states into one array, each let go once copied: a long chain's branch is not held twice.
        states = np.empty((len(self.states),) + self.states[0].shape)
        for i in range(len(self.states)):
            states[i], self.states[i] = self.states[i], None
        branch = _assemble_branch(self.params, self.model, self.particle, self.moments, states, folds, self.checks, traced.end, self.angles)
        branch.state_points = None if self.stride == 1 else np.array(self.kept)
        branch.message = message
        branch.branch_points = [event.point for event in traced.events if event.kind == "branch_point"]
        return branch

    # The correctors and the searches for folds and branch points.

    def _jumped(self, y: np.ndarray, predicted: np.ndarray, z: np.ndarray, ds: float) -> bool:
        """Whether the corrector's point z of the step ds from y lies on another part of the branch (or another branch).

        Newton on the plane normal to the tangent can converge to a far part of the branch
        that crosses the plane: a jump, not a step (one N = 4 chain jumped by 1.6, its
        state's size, with steps of 0.01). A step's correction is a fraction of the step
        where the tangent turns by MAX_TURN at most, but an ill-conditioned corrector moves
        further along the soft directions (the sine model next to its fold at N = 1000: 7
        times the step, 1e-7 of the state's size): a jump is a correction beyond the step
        and beyond :data:`JUMP` of the state's size or :data:`JUMP_STEPS` steps, whichever
        is less (a long chain's state is large: at N = 10^4, 1e-3 of it is 1.25, and
        corrections of 100 steps passed where the branch winds near M = 0). Steps shorter than ``refine_step``
        (next to a singular point of the branch, where the corrector moves along the kernel
        of the bordered Jacobian: a cantilever's branch points) allow :data:`JUMP_SINGULAR`.
        """
        size = euclidean_norm(z - predicted)
        if abs(ds) < self.refine_step:
            return bool(size > max(abs(ds), JUMP_SINGULAR * (1.0 + euclidean_norm(y))))
        return bool(size > max(abs(ds), min(JUMP * (1.0 + euclidean_norm(y)), JUMP_STEPS * abs(ds))))

    def _checked(self, corrected: Correction, y: np.ndarray, predicted: np.ndarray, ds: float) -> Correction:
        if corrected.converged and self._jumped(y, predicted, corrected.w, ds):
            return replace(corrected, status=Corrector.JUMPED)
        return corrected

    def _correct(
        self, y: np.ndarray, tangent: np.ndarray, ds: float, tol: float, max_iter: int = 8, contraction: float | None = None
    ) -> Correction:
        """The point of the branch on the plane through y + ds tangent normal to tangent, by full Newton
        (the kit's corrector, at most ``max_iter`` evaluations); ``data`` of its evaluation holds K there.
        ``contraction``: the kit's test of progress (a step's fallback, :data:`FALLBACK_CONTRACTION`).

        With more iterations than a step's (``max_iter`` > 8: locating a fold or a branch point),
        a residual that no longer falls within :data:`STALL` times the round-off floor has
        converged (one random chain's branch point stalled at four, another at twelve times
        the floor), and each step is halved while it raises the residual above where it was
        and above STALL times the floor (near the floor the residual is noise): the bordered
        Jacobian is nearly singular there, and a full Newton step from a point already close
        can throw the iterate off the branch (a cantilever's branch point, N = 3: from a
        residual of 1e-10 to 2e-3, then a jump).
        """
        predicted = y + ds * tangent
        locating = max_iter > 8
        last = [math.inf]

        def bordered(w: np.ndarray) -> np.ndarray:
            return np.append(self.residual(w), dot(tangent, w - predicted))

        def evaluate(w: np.ndarray, jacobian: bool) -> Evaluation:
            r = bordered(w)
            k = self.stiffness(w)
            floor = round_off_floor(k, w[:-1])
            return Evaluation(r, lambda: self.factor_of(w, k), _Assembled(k, floor, max(tol * (1.0 + abs(w[-1])), floor)))

        def converged(evaluation: Evaluation, size: float) -> bool:
            stalled = locating and size <= STALL * evaluation.data.floor and size > 0.5 * last[0]
            last[0] = size
            return size <= evaluation.data.limit or stalled

        def step(w: np.ndarray, evaluation: Evaluation, factor: BorderedFactor) -> np.ndarray:
            update = factor.solve(tangent, evaluation.residual)
            if locating:
                bound = max(np.max(np.abs(evaluation.residual)), STALL * evaluation.data.floor)
                for _ in range(MAX_HALVINGS * 4):
                    trial = w - update
                    if np.max(np.abs(bordered(trial))) <= bound:
                        break
                    update = 0.5 * update
            return -update

        corrected = newton(
            evaluate,
            predicted,
            converged=converged,
            newton_step=step,
            max_iterations=max_iter - 1,
            divergence=None,
            contraction=contraction,
            contraction_of_best=True,
        )
        return self._checked(corrected, y, predicted, ds)

    def _correct_chord(self, y: np.ndarray, tangent: np.ndarray, ds: float) -> Correction:
        """:meth:`_correct` in chord iterations with the last point's factor, from the predictor bent by ``bend``.

        Newton with the Jacobian kept (one residual and one O(n w) solve instead of an
        assembly of K and an O(n w^2) elimination) while each iteration shrinks the
        residual by :data:`CHORD_CONTRACTION` at least, and factored anew at the iterate
        otherwise (a long chain's soft modes make the chord contract slowly). Its iterations
        count the factors. The round-off floor takes K's norm at the last factor.

        The iterations start from the predictor bent by ``bend``, the change of the unit
        tangent per arclength over the step before, normal to the tangent (a second-order
        predictor): at N = 1000 the iterations are far from Newton's quadratic regime along
        the soft modes (a fresh factor shrinks the residual only 4-6 times), and the bent
        start took 7.2 residuals and 2.9 factors a point where the tangent's took 9.1 and 3.6.
        The plane of the step (and the jump test) stays that of the tangent's predictor.

        A step with a fresh factor that raises the residual above :data:`CHORD_DIVERGED` times
        the start's has left Newton's basin (the bent start on the long steps of N = 10^4,
        where this corrector went on refactoring a diverging iterate, to residuals of 1e5-1e9,
        for all its iterations in 192 of its first 318 steps: twice the time of the turn):
        full Newton from the plain predictor takes over. Not at the first rise: an iterate
        that rises a little and comes back is on its way (N = 20, clamped-pinned, whose full
        Newton from the predictor went back along the branch). A step with the last point's factor
        that does not lower the residual is not taken (the kit's ``retreat``): the factor is
        renewed where it started. Past the first fold of N = 10^4 that factor sent the iterate
        from residuals of 2e-3 to 1e3-1e5 along the soft modes, the factor renewed there
        diverged, and 416 of 513 steps fell back on full Newton; retreating halved the factors
        of the whole trace. Not from a start within :data:`RETREAT_ABOVE` times the residual's
        limit: there the residual is round-off, no step lowers it, and a step away and back is
        how Newton finds a point below it (the sine model at N = 10^4 next to its second fold,
        whose starts lay at its limit 9e-8: retreating from them stalled the trace).
        """
        predicted = y + ds * tangent
        kept = [self.factor, self.norm]  # the factor in use and its K's norm

        def evaluate(w: np.ndarray, jacobian: bool) -> Evaluation:
            r = np.append(self.residual(w), dot(tangent, w - predicted))
            floor = round_off_floor(None, w[:-1], norm=kept[1])
            data = _Assembled(self.stiffness(w) if jacobian else None, floor, max(self.tol * (1.0 + abs(w[-1])), floor))
            return Evaluation(r, (lambda: self.factor_of(w, data.k)) if jacobian else None, data)

        def step(w: np.ndarray, evaluation: Evaluation, factor: BorderedFactor) -> np.ndarray:
            if factor is not kept[0]:
                kept[0], kept[1] = factor, infinity_norm(factor.stiffness)
            return -factor.solve(tangent, evaluation.residual, refine=0)

        start = predicted + (0.5 * ds * ds) * self.bend
        first = evaluate(start, False)
        corrected = newton(
            evaluate,
            start,
            converged=lambda evaluation, size: size <= evaluation.data.limit,
            max_iterations=CHORD_ITERATIONS - 1,
            divergence=None,
            chord=CHORD_CONTRACTION,
            jacobian0=self.factor,
            blowup=CHORD_DIVERGED,
            retreat=1.0 if np.max(np.abs(first.residual)) > RETREAT_ABOVE * first.data.limit else None,
            newton_step=step,
            evaluation0=first,
        )
        if corrected.converged:
            corrected = replace(corrected, iterations=corrected.jacobians)
        return self._checked(corrected, y, predicted, ds)

    def _solved(self, y: np.ndarray, tangent: np.ndarray, s: float, what: str) -> Correction:
        """The branch's point at arclength s from y, to the fold's tolerance (more iterations than a step's)."""
        found = self._correct(y, tangent, s, FOLD_TOL, FOLD_ITERATIONS)
        if not found.converged:
            raise NewtonError(f"the corrector failed at arclength {s:.3g} from M={y[-1]:.10g} while locating a {what}", unpack(self.params, y[:-1]))
        return found

    def _fold_between(self, y: np.ndarray, tangent: np.ndarray, ds: float, end: np.ndarray, end_slope: float, before: int, after: int) -> Fold:
        """The fold between y and its successor ``end`` at arclength ds: where the tangent's M component vanishes.

        ``before``, ``after``: the index of K at y and at ``end``.

        Along the arclength, not in phi_0: a branch whose phi_0 turns back near a fold
        is no function of phi_0 there. The bracket's ends are the two points whose
        tangents showed the turn (``end_slope`` the M component at ``end``): solved anew at
        ds to the fold's tolerance, a fold within round-off of the end had the slope's
        sign of the start there (N = 10^4), and there was no bracket.
        """
        cache: dict[float, np.ndarray] = {}

        def slope(s: float) -> float:
            if s == 0.0:
                cache[s] = y  # the fold at the step's start itself (Brent's root at the bracket's end: N = 10^5)
                return tangent[-1]
            if s == ds:
                cache[s] = end
                return end_slope
            # More iterations than a step takes: at a fold that is not simple (a cantilever's
            # free half turned to 3 pi / 2 under the sine model, where the bordered Jacobian
            # is singular) Newton converges only linearly, halving the error each time.
            # Newton starts from the predicted point, not from the nearest solved one: at a
            # fold that is not simple the root's position hangs on where Newton starts
            # (a cantilever's phi_0 at its fold moved by 1e-8 with a warm start).
            found = self._solved(y, tangent, s, "fold")
            cache[s] = found.w
            return self._unit_tangent(found.evaluation.matrix(), tangent)[-1]

        # To 1e-12 of the arclength (of the step beyond unit length): within four or five
        # evaluations the slope is at its round-off (1e-15 at N = 1000, with a random sign),
        # and Brent's method went on bisecting that noise to 1e-15, 15 evaluations a fold.
        s_fold = brentq(slope, 0.0, ds, xtol=1e-12 * max(1.0, ds), rtol=4 * np.finfo(float).eps)
        point = cache.get(s_fold)
        if point is None:
            slope(s_fold)
            point = cache[s_fold]
        x = unpack(self.params, point[:-1])
        # At a fold the branch's tangent is K's null vector (its M component vanishes): the mode that turns.
        mode = unpack(self.params, self._unit_tangent(self.factor_of(point, self.stiffness(point)), tangent)[:-1])
        return Fold(
            moment=float(point[-1]),
            phi0=float(x[ROW_INDEX["phi"], self.col]),
            x=x,
            particle=self.particle,
            maximum=bool(tangent[-1] > 0),
            index_before=before,
            index_after=after,
            mode_particle=_turning_particle(self.params, mode),
        )

    def _branch_point_between(self, y: np.ndarray, tangent: np.ndarray, ds: float, before: int, after: int, after_point: int) -> BranchPoint:
        """Where the smallest eigenvalue of K vanishes between y and its successor at arclength ds (no fold between).

        Where the corrector fails inside the step (K singular there makes its Newton
        iterations stall on some chains: clamped-free random geometries), the point is
        the solved one of the tightest sign change found so far, with ``located`` False
        and ``bracket`` the arclength it is known within, rather than no result at all.
        """
        evaluated: dict[float, tuple[np.ndarray, float]] = {}

        def smallest(s: float) -> float:
            if s > 0.0:
                found = self._solved(y, tangent, s, "branch point")
                z, k = found.w, found.evaluation.data.k
            else:
                z, k = y, None
            value = self.stability(unpack(self.params, z[:-1]), k).critical_eigenvalue
            evaluated[s] = (z, value)
            return value

        low = smallest(0.0)
        try:
            high = smallest(ds)
            # The crossing eigenvalue is the smallest one only where the other side is stable;
            # between two unstable states (no sign change of the smallest) the step's end is kept.
            s_point = brentq(smallest, 0.0, ds, xtol=1e-13 * max(1.0, ds)) if low * high < 0 else ds
            if s_point not in evaluated:
                smallest(s_point)
            point, located, bracket = evaluated[s_point][0], low * high < 0, 0.0 if low * high < 0 else ds
        except NewtonError:
            keys = sorted(evaluated)
            pairs = [(b - a, a, b) for a, b in zip(keys, keys[1:]) if evaluated[a][1] * evaluated[b][1] <= 0]
            width, a, b = min(pairs) if pairs else (ds, keys[-1], keys[-1])
            s_point = a if abs(evaluated[a][1]) <= abs(evaluated[b][1]) else b
            point, located, bracket = evaluated[s_point][0], False, width
        x = unpack(self.params, point[:-1])
        mode = self.eigenvector.copy()
        static_stability(self.params, self.model, x, start=mode)  # leaves K's softest eigenvector (of its symmetric similar) in ``mode``
        return BranchPoint(
            float(point[-1]),
            float(x[ROW_INDEX["phi"], self.col]),
            x,
            self.particle,
            before,
            after,
            after_point,
            located,
            bracket,
            _turning_particle(self.params, unpack(self.params, mode)),
        )


def continue_in_moment(
    params: ChainParams,
    model: str | Model,
    *,
    particle: int = 0,
    phi0_stop: float = 2 * math.pi,
    phi0_until_unstable: float | None = None,
    moment_stop: float = math.inf,
    step: float | None = None,
    min_step: float = 1e-6,
    max_step: float | None = None,
    max_points: int = 5000,
    tol: float = 1e-11,
    refine_step: float = 2e-4,
    max_folds: int | None = None,
    progress: ProgressCallback | None = None,
    max_states: int | None = None,
    from_approach: bool = False,
    mixed: bool = False,
    decided: bool = False,
    response: np.ndarray | None = None,
) -> Branch:
    """Pseudo-arclength continuation of the static branch from rest, in the direction of increasing M.

    Parameters
    ----------
    particle : int
        The loaded particle.
    phi0_stop : float
        Stop once |phi_0| of the loaded particle reaches this (default one full turn).
    phi0_until_unstable : float, optional
        With it, ``phi0_stop`` is a budget: the tracing stops ("phi0_stop") already once |phi_0|
        has reached this and some traced point is unstable, the stable branch from rest having
        ended (a cantilever's stays stable for N times 1.41 rad of phi_0 on the paper's geometry).
    moment_stop : float
        Stop once |M| exceeds this (the linear model's branch is an endless line).
    step, min_step, max_step : float
        Arclength step in the (q, M) space: initial, smallest before giving up, largest.
        ``step`` defaults to :data:`STEP` sqrt(n_free / 15) (0.05 for the paper's chain,
        15 free degrees of freedom; longer chains have longer branches in (q, M)),
        ``max_step`` to :data:`MAX_STEP_FACTOR` times that or, where longer, the arclength over which the
        loaded particle turns by 2 :data:`PHI0_STEP` along the branch's tangent at rest
        (:func:`largest_step`: long chains). A step is retaken shorter
        when the loaded particle turns by more than :data:`PHI0_STEP`, the tangent by
        more than :data:`MAX_TURN`, or a positive critical eigenvalue (above its
        round-off) falls below half its previous value or through zero. The next step is
        sized for :data:`STEP_TARGET` of both turn limits at the rates of the step just
        taken, at most :data:`STEP_GROWTH` times longer, and no longer where the corrector
        factored the Jacobian more than once (:data:`CHORD_CONTRACTION`; full Newton: two
        iterations): the points follow the curvature of the branch, not its length (the sine model's branch at N = 100 is
        long in (q, M) and straight). A step shortened on the way to a crossing of an
        eigenvalue comes back once the crossing is passed.
    max_points : int
    tol : float
        Corrector tolerance on max |F + M e| (never below the round-off floor, :func:`~.newton.round_off_floor`).
    refine_step : float
        A step across which the number of negative eigenvalues of K changes other than
        by the one fold the tangent shows is retaken in steps down to this, so that
        every fold shows as a turn of the tangent between points (two folds within one
        step whose eigenvalue crossings cancel are still missed: :data:`PHI0_STEP` and
        :data:`MAX_TURN` keep the steps short where the branch bends). The crossing is
        approached by halving the distance to it.
    max_folds : int, optional
        Stop once this many folds have been passed.
    progress : callable(|phi_0|, total), optional
        ``total`` is ``phi0_until_unstable`` until |phi_0| passes it on a stable branch, then ``phi0_stop``.
    max_states : int, optional
        Keep at most this many states (at least 2; default every point's): a longer trace keeps the
        states of every 2^j-th point from rest, j the smallest that fits (``Branch.state_points``),
        halving the kept ones each time they overflow, so that the memory of a long chain's branch
        is bounded whatever the points (:func:`branch_memory`). Every point's moment, angle and
        stability are kept, and the folds and branch points keep their own states.
    from_approach : bool
        Start the trace from the last point of the approach from rest (:func:`approach_from_rest`, the branch solved
        with the angle held at fixed angles up to :data:`APPROACH_ANGLE`, kept as the branch's first points) instead
        of from rest: where K's bending modes at rest are beyond double precision (:func:`rest_resolved` False; a
        clamped chain of N = 10^5, whose trace from rest crawled at moments of 1e-14, below the corrector's limit,
        and turned back at a fold of round-off). A fold between the approach's angles is not seen unless M falls
        at one of them (the approach then ends before it, and the trace finds it).
    mixed : bool
        Solve the corrector's and the tangent's systems in the mixed form of the model's rows
        (``Model.stiffness_rows``, :class:`~cosserat_chain.linalg.MixedFactor`) instead of the band LU of K's
        entries, which loses K's soft modes on a long clamped chain (at N = 10^5 its compliance at rest is 80 %
        off). Not the default: its full turn costs several times the band trace's (docs/statics.md). A model
        without rows keeps the band LU.
    decided : bool
        End the trace where the largest maximum of M, M_c, is decided short of the turn (``stop`` "decided",
        ``message`` says where): once the stable branch from rest has ended at a fold, the loaded particle lies within
        :data:`END_ANGLE` of the turn and |M| has fallen to :data:`END_MOMENT` times the largest maximum traced. For a
        long clamped chain, whose turn ends near the chain at rest turned once, where the trace hangs on round-off.
    response : ndarray, optional
        K^-1 e at rest (:func:`moment_response`) where the caller has it: the largest step and the approach use it.

    Returns
    -------
    Branch
        With every fold passed on the way: where the tangent's M component changes
        sign between two points, located along the arclength to round-off (a root of
        that component), a maximum or a minimum of M, with the particle its mode turns
        most (``mode_particle``); ``stop`` says whether the
        requested end was reached or ``max_points`` ran out (long chains: the branch
        of N = 1000 passes 40 folds, turning back and forth in phi_0, before the
        loaded particle completes a turn).

    Raises
    ------
    NewtonError
        If locating a fold fails (the corrector fails next to it).
    ValueError
        If a step size is not positive or ``min_step > max_step``.

    Notes
    -----
    Cost: every point is a fixed number of O(N) banded passes. The tangent at a point is
    solved with a banded factor of K there (:class:`~cosserat_chain.linalg.BorderedFactor`), and the
    next step's corrector iterates with that factor (chord iterations: a residual and an
    O(N w) solve each) while each shrinks the residual by :data:`CHORD_CONTRACTION`,
    assembling and factoring K anew only where it does not, from a start bent along the
    branch's curvature: about 3.1 assemblies and factors a point at N = 1000 (the searches
    for the 40 folds and 20 branch points and the retaken steps included; 2.9 on the
    shorter steps before :data:`STEP_TARGET`, where full Newton in every corrector took
    4.7). The
    stability of a point of a conservative model takes the K assembled at the converged
    state (``static_stability(similar=...)``), starts its inverse iteration from the
    previous point's eigenvector, and takes its index from the inertia of the tangent's
    factor of that K (:attr:`~cosserat_chain.linalg.BorderedFactor.negative_eigenvalues`): no factor of
    its own for the count. The cost of the full turn against N is measured by
    ``benchmarks/bench_critical.py --scaling`` (``docs/statics.md`` has the history and
    what a point costs; benchmarks/TIMINGS.md). A point whose
    critical eigenvalue lies within its round-off (``Stability.resolution``) keeps the
    index and stability last decided. The folds and branch points are located with full Newton (the bordered
    Jacobian is singular at a branch point, where a full step is halved while it raises
    the residual). The number of points grows with the folds of the branch, not with N itself.
    """
    model = get_model(model)
    default = default_step(params)
    step = default if step is None else step
    if response is None and max_step is None:
        try:
            response = moment_response(params, model, particle=particle)
        except ValueError:
            pass  # K singular at rest: largest_step's fallback
    max_step = max(largest_step(params, model, particle, response), step) if max_step is None else max_step
    if not (0 < min_step <= step <= max_step):
        raise ValueError(f"steps must satisfy 0 < min_step <= step <= max_step, got {min_step!r}, {step!r}, {max_step!r}")
    if max_states is not None and max_states < 2:
        raise ValueError(f"max_states must be at least 2 (the states kept of the branch), got {max_states!r}")
    mixed = mixed and model.stiffness_rows(params, zeros(params)) is not None
    require_branch_memory(params, max_points, max_states, mixed=mixed)
    problem = _StaticBranch(
        params,
        model,
        particle,
        tol=tol,
        min_step=min_step,
        max_step=max_step,
        refine_step=refine_step,
        stops=_Stops(phi0_stop, phi0_until_unstable, moment_stop, max_folds, decided),
        max_states=max_states,
        progress=progress,
        mixed=mixed,
    )
    approach = approach_from_rest(params, model, particle=particle, response=response) if from_approach else []
    first = problem.rest(approach)
    start = np.zeros(n_free(params) + 1) if not approach else np.append(pack(params, approach[-1][0]), approach[-1][1])
    traced = continuation(problem, start, step=step, min_step=min_step, max_step=max_step, max_points=max_points, first=first)
    branch = problem.branch(traced)
    branch.approach = len(approach)
    return branch
