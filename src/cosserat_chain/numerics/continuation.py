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

import numpy as np
import scipy.optimize as so

from ..linalg import (
    BandMatrix,
    BorderedFactor,
    dot,
    euclidean_norm,
    infinity_norm,
    refined_solve,
    rotation_controlled_jacobian,
    sparse_solve,
)
from ..memory import FLOAT, require
from ..models.base import Model, get_model
from ..params import ChainParams
from ..state import ROW_INDEX, column, n_free, unpack, zeros
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
#: A fold's or branch point's corrector whose residual stops falling within this many times the
#: round-off floor (:func:`~.newton.round_off_floor`, an estimate) has converged to round-off.
STALL = 100.0
#: Halvings of the distance to the nearest solved angle before a fold search gives up.
MAX_HALVINGS = 12
#: A model's K at rest is the linear model's where they agree to this, relative to its norm (:func:`moment_response`).
REST_RTOL = 1e-12
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
    stop : str
        Why the tracing ended: "phi0_stop", "moment_stop", "max_folds" (the
        requested end), "returned" (the branch came back through the rest state
        before the loaded particle turned once, as a closed loop does), "wound"
        (a particle other than the loaded one turned a full turn further than it:
        the chain rotates there, and the branch repeats its folds as that particle
        winds on; ``message`` names it),
        "max_points" (the point budget ran out first) or "stalled" (the corrector
        failed even at ``min_step``: a point where the branch is not smooth, such as a
        link of zero length; ``message`` says where): the branch is then incomplete;
        "given" for the angles of :func:`rotation_branch`.
    message : str
        What stopped a stalled or wound branch (empty otherwise).
    state_points : ndarray of int (j,) or None
        The points whose states ``x`` holds, where a trace kept only some
        (``max_states`` of :func:`continue_in_moment`); None where ``x`` holds every point's.
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

    @property
    def complete(self) -> bool:
        """False if the point budget ran out or the corrector stalled before the requested end."""
        return self.stop not in ("max_points", "stalled")

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

    Refined with residuals in extended precision (:func:`~cosserat_chain.linalg.refined_solve`): K's
    condition number grows like N^4, and at N = 10^4 a double-precision solve's compliance
    was 1.2 % off (15434.5 for the paper's chain, 15625.000 refined).

    At rest every model of the package has the linear model's K (eq. (3) is derived as the
    Hessian at rest), and that one is assembled from the derived coefficients, one rounding
    an entry: it is solved wherever the model's own K at rest equals it to round-off. The
    nonlinear model's Hessian, summed link by link, rounds its entries otherwise, and at
    N = 10^4 its compliance was 4.2e-8 off the exact one where the linear K's is 7e-11 off
    (:func:`~cosserat_chain.analysis.continuum.discrete_static` solves the same matrix: ``theory``
    and ``critical`` give one compliance). A model whose K at rest differs (a user's model) is solved with its own.

    Raises
    ------
    ValueError
        If K is singular at ``x`` (a fold).
    """
    model = get_model(model)
    e = np.zeros(n_free(params))
    e[moment_dof(params, particle)] = 1.0
    if x is None:
        stiffness = model.stiffness(params, zeros(params)).tocsr()
        linear = get_model("linear").stiffness(params).tocsr()
        if model.name != "linear" and infinity_norm(stiffness - linear) <= REST_RTOL * infinity_norm(linear):
            stiffness = linear
    else:
        stiffness = model.stiffness(params, x)
    try:
        return refined_solve(stiffness, e).x
    except ValueError:
        raise ValueError("the stiffness is singular at this state (a fold): the compliance is infinite") from None


def largest_step(params: ChainParams, model: Model, particle: int) -> float:
    """The default ``max_step`` of :func:`continue_in_moment`: :data:`MAX_STEP_FACTOR` times the first step, or the
    arclength along the branch's tangent at rest over which the loaded particle turns by 2 :data:`PHI0_STEP`, if longer.

    The branch's length per radian of phi_0 grows with N faster than the first step: the sine model's
    u and v are linear in the load, like N^2 times M (N = 3000: 23000 per radian; a first step of 1.7).
    Capped at 20 first steps, its full turn took 2782 points at N = 3000 and every one at the cap, and
    N = 10^4 crawled at 4e-4 rad a point; the turn limits, not the cap, then size the steps.
    """
    try:
        response = moment_response(params, model, particle=particle)
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
    x = np.array(states)
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
    phi_fold = so.brentq(slope, *bracket, xtol=1e-15, rtol=4 * np.finfo(float).eps)
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


def branch_memory(params: ChainParams, max_points: int, max_states: int | None = None) -> int:
    """Bytes a branch of up to ``max_points`` points needs, keeping at most ``max_states`` states (None: every one).

    The kept states (the branch's x) are held twice at the end (the list and its array), beside
    the stiffness and its banded factors (about 60 values a degree of freedom) and, for every point,
    its moment, angle and stability (about 40 values: the per-point record, not the state).
    """
    states = max_points if max_states is None else min(max_points, max_states)
    return FLOAT * (3 * params.n_particles * (2 * states + 60) + 40 * max_points)


def require_branch_memory(params: ChainParams, max_points: int, max_states: int | None = None) -> None:
    """Refuse a branch that would not fit in memory (:func:`branch_memory`, :func:`cosserat_chain.memory.require`)."""
    states = max_points if max_states is None else min(max_points, max_states)
    require(
        branch_memory(params, max_points, max_states),
        f"a branch of up to {max_points} points keeping {states} states of {params.n_particles} particles (N={params.N})",
        "trace fewer points (max_points, --max-points) or a shorter chain",
    )


def default_step(params: ChainParams) -> float:
    """The first arclength step of :func:`continue_in_moment`: :data:`STEP` sqrt(n_free / 15) (0.05 for the paper's chain)."""
    return STEP * math.sqrt(n_free(params) / 15)


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
    max_step = max(largest_step(params, model, particle), step) if max_step is None else max_step
    if not (0 < min_step <= step <= max_step):
        raise ValueError(f"steps must satisfy 0 < min_step <= step <= max_step, got {min_step!r}, {step!r}, {max_step!r}")
    if max_states is not None and max_states < 2:
        raise ValueError(f"max_states must be at least 2 (the states kept of the branch), got {max_states!r}")
    require_branch_memory(params, max_points, max_states)
    dof = moment_dof(params, particle)
    nf = n_free(params)
    y = np.zeros(nf + 1)  # (q, M)
    tangent = np.zeros(nf + 1)
    tangent[-1] = 1.0

    def residual(y: np.ndarray) -> np.ndarray:
        r = model.packed_forces(params, y[:-1])
        r[dof] += y[-1]
        return r

    def stiffness(y: np.ndarray) -> BandMatrix:
        return model.stiffness_band(params, unpack(params, y[:-1]))

    def new_tangent(y: np.ndarray, previous: np.ndarray, k: BandMatrix | None = None) -> tuple[np.ndarray, BorderedFactor]:
        """The unit tangent at y oriented along ``previous``, and the factor of K(y) that solved for it."""
        rhs = np.zeros(nf + 1)
        rhs[-1] = 1.0
        factor = BorderedFactor(stiffness(y) if k is None else k, dof)
        t = factor.solve(previous, rhs)
        return t / euclidean_norm(t), factor

    # A conservative model's symmetric matrix is its stiffness (Model.symmetric_similar):
    # the stability of a point then reuses the stiffness its corrector assembled.
    reuse_stiffness = model.conservative and type(model).symmetric_similar is Model.symmetric_similar

    # Inverse iteration at a point starts from the previous point's lowest eigenvector.
    eigenvector = np.zeros(nf)

    def stability(x: np.ndarray, k: BandMatrix | None, guess: float | None = None, factor: BorderedFactor | None = None):
        """The stability of x (``factor``: the tangent's factor of K there, whose inertia is the index)."""
        if not reuse_stiffness:
            return static_stability(params, model, x, guess=guess, start=eigenvector)
        index = None if factor is None else factor.negative_eigenvalues
        return static_stability(params, model, x, guess=guess, similar=k, start=eigenvector, index=index)

    def jumped(y: np.ndarray, predicted: np.ndarray, z: np.ndarray, ds: float) -> bool:
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
        if abs(ds) < refine_step:
            return bool(size > max(abs(ds), JUMP_SINGULAR * (1.0 + euclidean_norm(y))))
        return bool(size > max(abs(ds), min(JUMP * (1.0 + euclidean_norm(y)), JUMP_STEPS * abs(ds))))

    def correct(y: np.ndarray, tangent: np.ndarray, ds: float, tol: float, max_iter: int = 8) -> tuple[np.ndarray, int, BandMatrix] | None:
        """The point of the branch on the plane through y + ds tangent normal to tangent, its iterations
        and stiffness (None: no convergence)."""
        predicted = y + ds * tangent
        z = predicted.copy()
        previous = math.inf
        for iterations in range(max_iter):
            r = np.append(residual(z), dot(tangent, z - predicted))
            k = stiffness(z)
            floor = round_off_floor(k, z[:-1])
            size = np.max(np.abs(r))
            # Locating a fold or a branch point (more iterations than a step), a residual
            # that no longer falls within STALL times the floor is the round-off itself (one
            # random chain's branch point stalled at four, another at twelve times the floor).
            stalled = max_iter > 8 and size <= STALL * floor and size > 0.5 * previous
            previous = size
            if size <= max(tol * (1.0 + abs(z[-1])), floor) or stalled:
                if jumped(y, predicted, z, ds):
                    return None
                return z, iterations, k
            update = BorderedFactor(k, dof).solve(tangent, r)
            if max_iter > 8:
                # Locating a fold or branch point (more iterations than a step): the bordered
                # Jacobian is nearly singular there, and a full Newton step from a point
                # already close can throw the iterate off the branch (a cantilever's branch
                # point, N = 3: from a residual of 1e-10 to 2e-3, then a jump). Halve the
                # step while it raises the residual above where it was and above STALL times
                # the round-off floor (near the floor the residual is noise).
                bound = max(size, STALL * floor)
                for _ in range(MAX_HALVINGS * 4):
                    trial = z - update
                    if np.max(np.abs(np.append(residual(trial), dot(tangent, trial - predicted)))) <= bound:
                        break
                    update = 0.5 * update
            z = z - update
            if not np.all(np.isfinite(z)):
                return None
        return None

    def correct_chord(
        y: np.ndarray, tangent: np.ndarray, ds: float, tol: float, factor: BorderedFactor, norm: float, bend: np.ndarray
    ) -> tuple[np.ndarray, int, BandMatrix] | None:
        """:func:`correct` reusing a factor of the Jacobian while it contracts (``factor`` at y, ``norm`` its ||K||_inf).

        Newton with the Jacobian kept (a chord iteration: one residual and one O(n w) solve
        instead of an assembly of K and an O(n w^2) elimination) while each iteration
        shrinks the residual by :data:`CHORD_CONTRACTION` at least, and factored anew at
        the iterate otherwise (a long chain's soft modes make the chord contract slowly).
        Returns as :func:`correct`, the iterations counting the factors (one per full Newton
        iteration). The round-off floor takes K's norm at the last factor.

        The iterations start from the predictor bent by ``bend``, the change of the unit
        tangent per arclength over the step before, normal to the tangent (a second-order
        predictor): at N = 1000 the iterations are far from Newton's quadratic regime along
        the soft modes (a fresh factor shrinks the residual only 4-6 times), and the bent
        start took 7.2 residuals and 2.9 factors a point where the tangent's took 9.1 and 3.6.
        The plane of the step (and the jump test) stays that of the tangent's predictor.
        """
        predicted = y + ds * tangent
        z = predicted + (0.5 * ds * ds) * bend
        previous = math.inf
        factors = 0
        fresh = False
        first = None
        for _ in range(CHORD_ITERATIONS):
            r = np.append(residual(z), dot(tangent, z - predicted))
            size = np.max(np.abs(r))
            if size <= max(tol * (1.0 + abs(z[-1])), round_off_floor(None, z[:-1], norm=norm)):
                if jumped(y, predicted, z, ds):
                    return None
                return z, factors, stiffness(z)
            first = size if first is None else first
            if fresh and size > CHORD_DIVERGED * first:
                # A Newton step with a fresh factor that raised the residual far above the
                # start's: the iterate left Newton's basin (the bent start on the long steps of
                # N = 10^4, where this corrector went on refactoring a diverging iterate, to
                # residuals of 1e5-1e9, for all its iterations in 192 of its first 318 steps:
                # twice the time of the turn). Full Newton from the plain predictor takes over.
                # Not at the first rise: an iterate that rises a little and comes back is on
                # its way (N = 20, clamped-pinned, whose full Newton from the predictor went
                # back along the branch).
                return None
            fresh = not size < CHORD_CONTRACTION * previous
            if fresh:
                k = stiffness(z)
                factor, norm = BorderedFactor(k, dof), infinity_norm(k)
                factors += 1
            previous = size
            z = z - factor.solve(tangent, r, refine=0)
            if not np.all(np.isfinite(z)):
                return None
        return None

    def fold_between(y: np.ndarray, tangent: np.ndarray, ds: float, end: np.ndarray, end_slope: float, before: int, after: int) -> Fold:
        """The fold between y and its successor ``end`` at arclength ds: where the tangent's M component vanishes.

        ``before``, ``after``: the index of K at y and at ``end``.

        Along the arclength, not in phi_0: a branch whose phi_0 turns back near a fold
        is no function of phi_0 there. The bracket's ends are the two points whose
        tangents showed the turn (``end_slope`` the M component at ``end``): solved anew at
        ds to the fold's tolerance, a fold within round-off of the end had the slope's
        sign of the start there (N = 10^4), and there was no bracket.
        """

        def slope(s: float) -> float:
            if s == 0.0:
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
            found = correct(y, tangent, s, FOLD_TOL, FOLD_ITERATIONS)
            if found is None:
                raise NewtonError(
                    f"the corrector failed at arclength {s:.3g} from M={y[-1]:.10g} while locating a fold",
                    unpack(params, y[:-1]),
                )
            point, _, k = found
            cache[s] = point
            return new_tangent(point, tangent, k)[0][-1]

        cache: dict[float, np.ndarray] = {}
        # To 1e-12 of the arclength (of the step beyond unit length): within four or five
        # evaluations the slope is at its round-off (1e-15 at N = 1000, with a random sign),
        # and Brent's method went on bisecting that noise to 1e-15, 15 evaluations a fold.
        s_fold = so.brentq(slope, 0.0, ds, xtol=1e-12 * max(1.0, ds), rtol=4 * np.finfo(float).eps)
        point = cache.get(s_fold)
        if point is None:
            slope(s_fold)
            point = cache[s_fold]
        x = unpack(params, point[:-1])
        # At a fold the branch's tangent is K's null vector (its M component vanishes): the mode that turns.
        mode = unpack(params, new_tangent(point, tangent)[0][:-1])
        return Fold(
            moment=float(point[-1]),
            phi0=float(x[ROW_INDEX["phi"], column(params, particle)]),
            x=x,
            particle=particle,
            maximum=bool(tangent[-1] > 0),
            index_before=before,
            index_after=after,
            mode_particle=_turning_particle(params, mode),
        )

    def branch_point_between(y: np.ndarray, tangent: np.ndarray, ds: float, before: int, after: int) -> BranchPoint:
        """Where the smallest eigenvalue of K vanishes between y and its successor at arclength ds (no fold between).

        Where the corrector fails inside the step (K singular there makes its Newton
        iterations stall on some chains: clamped-free random geometries), the point is
        the solved one of the tightest sign change found so far, with ``located`` False
        and ``bracket`` the arclength it is known within, rather than no result at all.
        """
        evaluated: dict[float, tuple[np.ndarray, float]] = {}

        def smallest(s: float) -> float:
            found = correct(y, tangent, s, FOLD_TOL, FOLD_ITERATIONS) if s > 0.0 else (y, 0, None)
            if found is None:
                raise NewtonError(
                    f"the corrector failed at arclength {s:.3g} from M={y[-1]:.10g} while locating a branch point",
                    unpack(params, y[:-1]),
                )
            value = stability(unpack(params, found[0][:-1]), found[2]).critical_eigenvalue
            evaluated[s] = (found[0], value)
            return value

        low = smallest(0.0)
        try:
            high = smallest(ds)
            # The crossing eigenvalue is the smallest one only where the other side is stable;
            # between two unstable states (no sign change of the smallest) the step's end is kept.
            s_point = so.brentq(smallest, 0.0, ds, xtol=1e-13 * max(1.0, ds)) if low * high < 0 else ds
            if s_point not in evaluated:
                smallest(s_point)
            point, located, bracket = evaluated[s_point][0], low * high < 0, 0.0 if low * high < 0 else ds
        except NewtonError:
            keys = sorted(evaluated)
            pairs = [(b - a, a, b) for a, b in zip(keys, keys[1:]) if evaluated[a][1] * evaluated[b][1] <= 0]
            width, a, b = min(pairs) if pairs else (ds, keys[-1], keys[-1])
            s_point = a if abs(evaluated[a][1]) <= abs(evaluated[b][1]) else b
            point, located, bracket = evaluated[s_point][0], False, width
        x = unpack(params, point[:-1])
        phi0 = float(x[ROW_INDEX["phi"], column(params, particle)])
        mode = eigenvector.copy()
        static_stability(params, model, x, start=mode)  # leaves K's softest eigenvector (of its symmetric similar) in ``mode``
        return BranchPoint(
            float(point[-1]),
            phi0,
            x,
            particle,
            before,
            after,
            len(moments) - 1,
            located,
            bracket,
            _turning_particle(params, unpack(params, mode)),
        )

    tangent, factor = new_tangent(y, tangent)
    norm = infinity_norm(factor.stiffness)
    moments, states, folds, branch_points = [0.0], [zeros(params)], [], []
    angles_traced, kept, stride, previous_state = [0.0], [0], 1, states[0]
    checks = [stability(states[0], None)]
    index = checks[0].index
    col = column(params, particle)
    y_phi0 = 0.0
    ds, resume, crossing = step, 0.0, 0.0
    stop, message = "max_points", ""
    lost = False  # whether a traced point is unstable: the stable branch from rest has ended
    previous_moment = 0.0
    bend = np.zeros(nf + 1)
    while len(moments) < max_points:
        found = correct_chord(y, tangent, ds, tol, factor, norm, bend)
        chord = found is not None
        if found is None:
            found = correct(y, tangent, ds, tol)
        if found is None:
            ds /= 2
            if ds < min_step:
                # The branch is not smooth here (the nonlinear model's energy has a cone
                # where a link's length vanishes: two particles' corners meet), or the
                # corrector cannot follow it. What was traced is kept.
                stop = "stalled"
                message = (
                    f"continuation stalled at M = {y[-1]:.6g}, phi_0 = {y_phi0:.6g}: the corrector failed even with step "
                    f"{ds * 2:.3g} (a point where the branch is not smooth, e.g. a link of zero length)"
                )
                break
            continue
        z, iterations, k = found
        x = unpack(params, z[:-1])
        turned = abs(x[ROW_INDEX["phi"], col] - y_phi0)
        next_tangent, next_factor = new_tangent(z, tangent, k)
        turn = math.acos(min(1.0, abs(dot(next_tangent, tangent))))
        if (turned > PHI0_STEP or turn > MAX_TURN) and ds > min_step:
            ds = max(min_step, ds / 2)
            continue
        check = stability(x, k, checks[-1].critical_eigenvalue, next_factor)
        if abs(check.critical_eigenvalue) <= check.resolution:
            # An eigenvalue within its round-off (Stability.resolution) has no sign: the
            # stability and index it gives are noise, and the branch keeps the index last
            # decided (a clamped-free chain of N = 1000 has its softest eigenvalue at 6e-14,
            # below its resolution 1.4e-13, computed at -6e-15 at every third point: those
            # were "unstable", and the stable branch from rest ended at its first point).
            # A real crossing shows at the next point whose eigenvalue is decided.
            check = replace(check, index=index, stable=index == 0)
        falling = check.critical_eigenvalue < 0.5 * checks[-1].critical_eigenvalue
        if falling and checks[-1].critical_eigenvalue > 100.0 * check.resolution and ds > refine_step:
            # A positive critical eigenvalue falling fast (or through zero): a fold ahead, or a pair of folds
            # (a small maximum and minimum of M) that a longer step passes with no change
            # of the index. Approach it in shorter steps (N = 10, a = 0.3, b = 0.1,
            # E1 = 2, E2 = 0.3 has such a pair within 0.015 rad of phi_0 near 1.0). An
            # eigenvalue near its round-off (a long chain's softest) is noise: not a sign.
            # The step from before comes back once the crossing is passed (below).
            resume = max(resume, ds)
            ds = max(refine_step, ds / 2)
            continue
        now_index = check.index
        turns_back = next_tangent[-1] * tangent[-1] < 0
        unmatched = abs(now_index - index) != 1 if turns_back else now_index != index
        if unmatched and ds > refine_step:
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
            resume, crossing = max(resume, ds), ds
            ds = max(refine_step, ds / 2)
            continue
        taken = ds  # the step from y to z (the step below may resume a longer one)
        rising = 0.0 < checks[-1].critical_eigenvalue < check.critical_eigenvalue
        if resume > 0.0 and (now_index != index or rising):
            # The refined crossing is passed (the index changed), or the critical eigenvalue
            # turned back up before zero: the step from before the refinement resumes
            # (growing back by 1.3 a point took 30 points after each of the 60 folds and
            # branch points of N = 1000; where it is too long, the turn limits halve it).
            ds, resume, crossing = resume, 0.0, 0.0
        elif crossing > 0.0:
            # Short of a crossing known to lie ahead: half the rest of the way, or, where the
            # arclength's estimate of it is spent without a crossing, on with the step from before.
            crossing -= taken
            ds, resume, crossing = (max(refine_step, crossing / 2), resume, crossing) if crossing > 0.0 else (resume, 0.0, 0.0)
        if turns_back:
            # M turned between the two points: a fold, located along the arc.
            folds.append(fold_between(y, tangent, taken, z, next_tangent[-1], index, now_index))
        elif now_index != index and (model.conservative or (now_index - index) % 2):
            # Eigenvalues of K through zero at the shortest step without a turn of M: K
            # singular off a fold, a branch point. (A non-symmetric K's complex pair
            # crossing changes the count by two and leaves K regular.)
            branch_points.append(branch_point_between(y, tangent, taken, index, now_index))
        index = now_index
        # The tangent's turn per arclength, normal to the new tangent: the next corrector's bent start.
        bend = (next_tangent - tangent) / taken
        bend -= dot(bend, next_tangent) * next_tangent
        tangent, factor, norm = next_tangent, next_factor, infinity_norm(k)
        previous_moment = y[-1]
        y = z
        y_phi0 = x[ROW_INDEX["phi"], col]
        moments.append(y[-1])
        angles_traced.append(y_phi0)
        if (len(moments) - 1) % stride == 0:
            kept.append(len(moments) - 1)
            states.append(x)
            if max_states is not None and len(states) > max_states:
                # Every other kept state goes: the points kept stay evenly spaced from rest.
                kept, states, stride = kept[::2], states[::2], 2 * stride
        checks.append(check)
        lost = lost or not check.stable
        phi = abs(y_phi0)
        angles = np.abs(x[ROW_INDEX["phi"]])
        lead = int(np.argmax(angles))
        if progress is not None:
            total = phi0_until_unstable if phi0_until_unstable is not None and (phi < phi0_until_unstable or lost) else phi0_stop
            progress(min(phi, total), total)
        if y[-1] * previous_moment < 0 and len(moments) > 2 and _passes_rest(previous_state, x, previous_moment, y[-1]):
            # Back through the rest state: going on would trace the mirrored branch
            # (x -> -x, M -> -M) and come back here, as a closed loop does.
            stop = "returned"
        elif phi >= phi0_stop or (phi0_until_unstable is not None and phi >= phi0_until_unstable and lost):
            stop = "phi0_stop"
        elif abs(y[-1]) > moment_stop:
            stop = "moment_stop"
        elif max_folds is not None and len(folds) >= max_folds:
            stop = "max_folds"
        elif angles[lead] - phi >= 2 * math.pi:
            # Another particle has turned a full turn further than the loaded one (a pinned end
            # that turns first: clamped-pinned N = 1, h = 1, a = 0.45, b = 0.1, E1 = 0.5, E2 = 1.5,
            # sine model): it winds on while phi_0 stays bounded, M repeating its folds (208 in
            # 5000 points before), and phi0_stop would never come.
            stop = "wound"
            message = (
                f"particle {lead - params.N} turned by {angles[lead]:.6g} rad, a full turn more than the loaded particle "
                f"{particle} (phi_0 = {y_phi0:.6g}): the chain rotates at particle {lead - params.N}, and the branch beyond "
                "repeats its folds as it winds on"
            )
        previous_state = x
        if stop != "max_points":
            break
        if crossing == 0.0:
            # The next step is sized for STEP_TARGET of the turn limits at the rate of this one
            # (growing the step by 1.3 where both turns stayed below half their limits, and
            # keeping it otherwise, left the loaded particle turning 0.065 rad a step on average:
            # 2080 points for the turn of N = 1000 where this takes 1709). It grows only where
            # its corrector needed at most one new factor (full Newton: two iterations).
            grow = min(STEP_GROWTH, STEP_TARGET * PHI0_STEP / max(turned, 1e-300), STEP_TARGET * MAX_TURN / max(turn, 1e-300))
            if iterations > (1 if chord else 2):
                grow = min(grow, 1.0)
            ds = min(max_step, max(min_step, max(0.5, grow) * ds))
    branch = _assemble_branch(params, model, particle, moments, states, folds, checks, stop, angles_traced)
    branch.state_points = None if stride == 1 else np.array(kept)
    branch.message = message
    branch.branch_points = branch_points
    return branch
