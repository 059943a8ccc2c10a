"""One continuation kit: a Newton corrector and a pseudo-arclength driver for any branch.

Contract
--------
A branch is the solution set of n equations in n + 1 unknowns, R(w) = 0, w = (u, lambda),
with lambda the continued parameter last. A :class:`ContinuationProblem` supplies R and
its Jacobian (dense or sparse, n x (n + 1)); :func:`continuation` follows the branch by
pseudo-arclength, as AUTO-07p and BifurcationKit.jl do:

* **predictor**: w_pred = w + ds t, with t the unit tangent, the null vector of dR/dw,
  oriented along the previous one (so a fold is passed, and seen as a sign change of
  t's lambda component);
* **corrector**: :func:`newton` on (R(w), t . (w - w_pred)) = 0. It reports one of the
  named outcomes of :class:`Corrector` (converged, diverged, not contracting, stalled, not finite), in the
  manner of diffrax's root finders, so every caller reads the same reasons. Its named
  options are the package's Newton variants: chord iterations that keep the Jacobian
  while it converges fast (an orbit's variational equations cost ten state integrations),
  damping by halved steps, Deuflhard's natural monotonicity test, a contraction test, a
  problem's own convergence test and step;
* **step control**: the step grows after an easy correction and shrinks after a hard
  one; a failed correction or a step the problem's monitor refuses (a quantity that
  moved farther than its declared budget, such as a Floquet multiplier near the unit
  circle) is retaken at half the step;
* **events**: every test function the problem declares (``fold`` built in: t's lambda
  component, and ``branch_point``: the sign of det [dR/dw; t]) is watched for a sign change
  between consecutive points; the change is located by the secant method on the
  arclength from the earlier point, each trial corrected onto the branch;
* **ends**: :class:`BranchEnd` is the one vocabulary of why a branch stopped, with a
  message that says what to do.

The problem keeps whatever it needs between points (a phase condition's reference
orbit, a monodromy matrix) through :meth:`ContinuationProblem.accept`.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field
from enum import StrEnum
from typing import Any, Protocol

import numpy as np
import scipy.linalg as sla
import scipy.sparse as sp

from ..errors import CosseratChainError
from ..linalg.general import CoreAndColumn, append_row, determinant_sign, solve

#: Corrector iterations before a step is retaken shorter.
MAX_ITERATIONS = 10
#: Two corrector iterations in a row whose max |R| exceeds this times the smallest so far have
#: diverged (one is forgiven: near a nearly singular Jacobian, a kink's translation mode,
#: round-off can throw one step off before Newton converges).
DIVERGENCE = 1.0
#: Step growth after a correction in at most EASY iterations, and shrinking after HARD or more.
EASY, HARD = 3, 7
GROW, SHRINK = 1.5, 0.7
#: Secant iterations that locate an event, and the arclength accuracy asked of them.
EVENT_ITERATIONS = 30
EVENT_TOL = 1e-10
#: The ends that are events located on the branch (the values ``stop_at`` of :func:`continuation` takes).
EVENT_KINDS = ("fold", "branch_point", "period_doubling", "torus", "hopf", "value")


class BranchEnd(StrEnum):
    """Why a branch ended (the one vocabulary of every continuation)."""

    #: The parameter turned back (a fold); the branch goes on beyond it, unstable on one side.
    FOLD = "fold"
    #: Two branches cross here; :func:`branch_directions` gives the other one.
    BRANCH_POINT = "branch_point"
    #: The period of an orbit exceeded its bound: it diverges (a homoclinic or SNIC end).
    INFINITE_PERIOD = "infinite_period"
    #: The parameter left the range asked for.
    PARAMETER_LIMIT = "parameter_limit"
    #: The number of points asked for was reached; the branch goes on.
    MAX_POINTS = "max_points"
    #: No step down to ``min_step`` could be corrected: a singularity the problem cannot pass.
    STEP_TOO_SMALL = "step_too_small"
    #: Stopped at the first point where stability was lost, as asked.
    UNSTABLE = "unstable"
    #: Stopped, as asked, at a period doubling (a Floquet multiplier through -1).
    PERIOD_DOUBLING = "period_doubling"
    #: Stopped, as asked, at a torus (Neimark-Sacker) point (a complex pair of multipliers through the unit circle).
    TORUS = "torus"
    #: Stopped, as asked, at a Hopf point (a complex pair of eigenvalues through the imaginary axis).
    HOPF = "hopf"
    #: Stopped, as asked, at a value of the parameter asked for (AUTO-07p's user point).
    VALUE = "value"
    #: A static branch's loaded particle turned as far as asked (``phi0_stop``).
    ANGLE_LIMIT = "phi0_stop"
    #: A static branch's load exceeded the bound asked for (``moment_stop``).
    LOAD_LIMIT = "moment_stop"
    #: As many folds as asked for were passed (``max_folds``).
    MAX_FOLDS = "max_folds"
    #: The branch came back through its start's mirror image, as a closed loop does: it would repeat.
    RETURNED = "returned"
    #: The trace turned back along the branch already traced (a point it could not pass): the rest is not traced.
    REVERSED = "reversed"
    #: Another coordinate than the one followed turned a full turn further: the system rotates there,
    #: and the branch beyond repeats its folds as it winds on.
    WOUND = "wound"
    #: A static branch's trace ended where what it was traced for is decided (``continue_in_moment(decided=True)``).
    DECIDED = "decided"

    @property
    def advice(self) -> str:
        """What to do about this end."""
        return _ADVICE[self]


_ADVICE = {
    BranchEnd.FOLD: "leave fold out of stop_at to follow the other side",
    BranchEnd.BRANCH_POINT: "switch branches with branch_directions() at the located point",
    BranchEnd.INFINITE_PERIOD: "raise period_max to follow the period further (its fitted end is given)",
    BranchEnd.PARAMETER_LIMIT: "widen the parameter range to go on",
    BranchEnd.MAX_POINTS: "raise max_points to go on",
    BranchEnd.STEP_TOO_SMALL: "try a smaller min_step or tighter integration tolerances; the branch may be singular there",
    BranchEnd.UNSTABLE: "pass until_unstable=False to follow the unstable part",
    BranchEnd.PERIOD_DOUBLING: "continue the period-doubled orbit (turns doubled, period doubled) from the located point",
    BranchEnd.TORUS: "the orbit goes on, unstable, beyond it: leave torus out of stop_at to follow it",
    BranchEnd.HOPF: "a family of periodic orbits is born here: start one from the located eigenvector",
    BranchEnd.VALUE: "continue from the located point towards the next value",
    BranchEnd.ANGLE_LIMIT: "raise phi0_stop to trace further",
    BranchEnd.LOAD_LIMIT: "raise moment_stop to trace further",
    BranchEnd.MAX_FOLDS: "raise max_folds to trace further",
    BranchEnd.RETURNED: "the branch is complete: beyond, its mirror image",
    BranchEnd.REVERSED: "trace the branch from beyond that point, or with a smaller refine_step (continue_in_moment)",
    BranchEnd.WOUND: "follow the rotation as a periodic orbit (orbit) rather than as a static branch",
    BranchEnd.DECIDED: "pass decided=False (continue_in_moment) to trace the rest of the turn",
}


class Corrector(StrEnum):
    """Outcome of one Newton correction."""

    CONVERGED = "converged"
    DIVERGED = "diverged"
    STALLED = "stalled"
    NOT_FINITE = "not_finite"
    NOT_CONTRACTING = "not_contracting"
    #: Converged, but farther from the predicted point than a step allows: onto another part of the branch.
    JUMPED = "jumped"


@dataclass
class Evaluation:
    """R(w), and with a Jacobian request dR/dw (n, n + 1) and whatever the problem computed beside (``data``).

    The Jacobian may be given as a callable, computed only when a step needs it (not at the
    solution of a :func:`newton` that only stores the point): :meth:`matrix` computes it once.
    """

    residual: np.ndarray
    jacobian: Any = None
    data: Any = None

    def matrix(self):
        """dR/dw, computed now if it was given as a callable."""
        if callable(self.jacobian):
            self.jacobian = self.jacobian()
        return self.jacobian


@dataclass
class Correction:
    """Result of :func:`newton`."""

    status: Corrector
    w: np.ndarray
    evaluation: Evaluation | None
    norm: float
    iterations: int
    #: Jacobians computed for the steps (a chord correction's kept first one not counted).
    jacobians: int = 0

    @property
    def converged(self) -> bool:
        return self.status == Corrector.CONVERGED


class ContinuationProblem(Protocol):
    """What a branch is: its equations, tests, monitors and stops.

    ``tol`` is the corrector's tolerance on max |R|.

    A problem may also take over a stage of :func:`continuation` by defining a method of
    the same name (the driver's own is used otherwise); the static branch of a long chain
    does, with banded factors and step control by the turn of its loaded particle:

    ``converged(evaluation, norm) -> bool``
        The corrector's convergence test (one tolerance per block of equations). Default: max |R| <= ``tol``.
    ``correct(w, t, h, jacobian) -> Correction``
        The correction of the step h from w along t (``jacobian``: the last computed).
        Default: :func:`newton` with the arclength border from w + h t.
    ``tangent(jacobian, previous) -> ndarray``
        The unit tangent at a corrected point, oriented along ``previous`` (None at the start).
    ``review(previous, candidate, h) -> float | None``
        None accepts the step to ``candidate``; a step length retakes it with that step.
        Default: :meth:`accept`, halving the step where it refuses.
    ``failed(h) -> float``
        The step after a failed correction; one below ``min_step`` ends the branch
        (:attr:`BranchEnd.STEP_TOO_SMALL`). Default: half, at least ``min_step``, and
        below it once ``min_step`` failed.
    ``events(previous, candidate, t_before, t_after) -> list of str``
        The kinds of event between two accepted points. Default: sign changes of the
        test functions (the built-in fold and branch point, and :meth:`tests`).
    ``locate(kind, w, t, h, previous, candidate, index) -> Event or None``
        The event between the point w (``previous``) and ``candidate``, the step h along t;
        None leaves it to the default: the secant method on the arclength, on the kind's test
        function (a fold's is the tangent's lambda component, others :meth:`tests` gives).
    ``next_step(h, correction, candidate) -> float``
        The step after an accepted point. Default: grown after an easy correction, shrunk after a hard one.
    """

    tol: float
    #: The continued parameter's name in the branch's messages (optional; "lambda" where a problem has none).
    parameter_name: str

    def evaluate(self, w: np.ndarray, jacobian: bool) -> Evaluation:
        """R(w) and, with ``jacobian``, dR/dw."""

    def point(self, w: np.ndarray, evaluation: Evaluation, iterations: int) -> Any:
        """The point the branch stores at a corrected w (an orbit, an equilibrium)."""

    def accept(self, previous: Any, candidate: Any) -> bool:
        """Whether the step from ``previous`` to ``candidate`` kept within the monitors' budgets."""

    def tests(self, point: Any) -> dict[str, float]:
        """Test functions whose sign changes are events, beside the built-in fold and branch point."""

    def stop(self, point: Any) -> tuple[BranchEnd, str] | None:
        """Whether the branch ends at this point, why and with which message."""

    def confirm(self, kind: str, point: Any) -> bool:
        """Whether a located event of this kind is real at ``point`` (a fold of cycles has a second
        multiplier at +1, a torus a pair on the unit circle); a sign change that is not is dropped."""


class EvaluationFailed(CosseratChainError, RuntimeError):
    """What a problem raises when R cannot be evaluated at a trial w (an integration that failed);
    the corrector then reports ``not_finite``."""


_EVALUATION_ERRORS = (ArithmeticError, np.linalg.LinAlgError, EvaluationFailed)


def newton(
    evaluate: Callable[[np.ndarray, bool], Evaluation],
    w0: np.ndarray,
    *,
    tol: float | None = None,
    converged: Callable[[Evaluation, float], bool] | None = None,
    max_iterations: int = MAX_ITERATIONS,
    border: tuple[np.ndarray, np.ndarray] | None = None,
    keep: np.ndarray | None = None,
    divergence: float | None = DIVERGENCE,
    forgive: int = 1,
    chord: float | None = None,
    jacobian0: Any = None,
    damping: int = 0,
    natural: bool = False,
    contraction: float | None = None,
    contraction_of_best: bool = False,
    blowup: float | None = None,
    retreat: float | None = None,
    newton_step: Callable[[np.ndarray, Evaluation, Any], np.ndarray] | None = None,
    iterate: Callable[[np.ndarray, Evaluation], None] | None = None,
    evaluation0: Evaluation | None = None,
) -> Correction:
    """Newton's method on R(w) = 0, the one corrector of the package's continuations and orbit searches.

    Parameters
    ----------
    evaluate : callable(w, jacobian) -> Evaluation
        With ``jacobian`` False only the residual is needed (a chord iteration, a damped trial):
        a problem for which it is cheaper (a state-only integration) computes only that.
    w0 : ndarray
        Start.
    tol : float, optional
        Converged when max |R| <= tol (the residual at the returned w; the Jacobian there is fresh).
    converged : callable(evaluation, norm) -> bool, optional
        The convergence test instead of ``tol`` (one tolerance per block of equations);
        ``norm`` is max |R|.
    max_iterations : int
        Stalled after this many steps.
    border : (t, w_pred), optional
        Adds the arclength condition t . (w - w_pred) = 0 (R has one unknown more than
        equations); without it R is square, or only the unknowns ``keep`` (a boolean mask)
        move.
    keep : ndarray of bool, optional
    divergence : float or None
        A fresh evaluation whose max |R| exceeds ``divergence`` times the smallest max |R| a
        step was taken from has grown; more than ``forgive`` such in a row have diverged.
        None: no divergence test (a damped Newton never grows).
    forgive : int
        Growing iterations forgiven in a row: near a nearly singular Jacobian (a kink's
        translation mode) round-off can throw one step off before Newton converges.
    chord : float, optional
        Chord iterations: the Jacobian is kept while each step divides max |R| by at least
        1 / ``chord``, and computed again (at the current w) when one does not, and at the
        solution. Each kept step then costs one residual, which pays where the Jacobian
        costs many (variational equations of an orbit).
    jacobian0 : matrix, optional
        With ``chord``, the Jacobian the first step uses (the previous point's).
    damping : int
        Trials of a step that does not reduce max |R|, the full step first and each one half
        the one before (each evaluated without the Jacobian; a trial that cannot be evaluated
        counts as not reducing). When none of them does, a kept Jacobian is computed again at w; a fresh one has diverged. A trial
        evaluated with its Jacobian anyway (the problem computes both at once) serves as the
        next iterate's.
    natural : bool
        Damping also takes a trial whose own Newton step is shorter than (1 - f / 4) times
        the full step, f the fraction of it tried (Deuflhard's natural monotonicity test):
        where R's blocks have unrelated scales, max |R| alone does not measure progress.
    contraction : float, optional
        max |R| of the iterates must fall by this factor every two steps, else the
        correction is ``not_contracting`` (cheaper to retake a shorter continuation step).
    contraction_of_best : bool
        With ``contraction``: the smallest max |R| so far must fall so, not each iterate's: an
        iteration that throws one iterate along a soft mode and comes back below where it was
        goes on (a long chain's statics, whose residuals alternate up and down as they converge).
    blowup : float, optional
        A step taken with a freshly computed Jacobian after which max |R| exceeds ``blowup``
        times the first max |R| has left Newton's basin: the correction is ``diverged``
        (a chord correction from a poor start, better retaken from another start than refactored on).
    retreat : float, optional
        With ``chord``: a step with the kept Jacobian that multiplies max |R| by more than this
        (1: does not lower it) is not taken, and the Jacobian is computed anew where it started
        (``damping``'s one trial, for kept Jacobians only): a kept Jacobian next to a soft mode
        can throw the iterate far off, where a fresh one then diverges, while steps with fresh
        Jacobians that raise max |R| a little may still be on their way.
    newton_step : callable(w, evaluation, jacobian) -> ndarray, optional
        The step at w instead of one linear solve with the Jacobian in use (``jacobian``: the
        evaluation's own, or the one a chord iteration keeps, which may be any object the
        problem factors, such as a banded factor): a minimum-norm correction plus a multiple
        of a null vector, or a step the problem damps itself; it may raise where it is not defined.
    iterate : callable(w, evaluation), optional
        Called at each iterate Newton moves to (the start included), before its tests: a
        problem that follows something from iterate to iterate (a Floquet multiplier) keeps it here.
    evaluation0 : Evaluation, optional
        ``evaluate(w0, ...)`` where the caller has it already (its residual decided how to
        call Newton): taken as the first evaluation, with the Jacobian asked for or not as
        the first iteration would (without it where ``jacobian0`` is kept).

    Returns
    -------
    Correction
        Its status names the test that ended it: converged, diverged (max |R| grew beyond
        ``divergence``, or no damped step reduced it), not contracting (``contraction``),
        stalled (``max_iterations``) or not finite.
    """
    if (tol is None) == (converged is None):
        raise ValueError("newton needs exactly one of tol (max |R| <= tol) and converged (a test)")
    if converged is None:
        converged = lambda evaluation, norm: norm <= tol  # noqa: E731
    w = np.array(w0, dtype=float)
    matrix = jacobian0 if chord is not None else None
    fresh = matrix is None
    best, grace, last, steps, jacobians = math.inf, forgive, math.inf, 0, 0
    pending, moved, norms, first, stepped_fresh = evaluation0, True, [], None, False

    def step_at(w: np.ndarray, ev: Evaluation, matrix) -> np.ndarray:
        if newton_step is not None:
            out = np.asarray(newton_step(w, ev, matrix), dtype=float)
        else:
            out = _direction(matrix, np.asarray(ev.residual, dtype=float), w, border, keep)
        if not np.all(np.isfinite(out)):
            raise ArithmeticError("the Newton step is not finite")
        return out

    while True:
        if pending is None:
            try:
                ev = evaluate(w, fresh)
            except _EVALUATION_ERRORS:
                return Correction(Corrector.NOT_FINITE, w, None, math.inf, steps, jacobians)
        else:
            ev, pending = pending, None
        residual = np.asarray(ev.residual, dtype=float)
        norm = float(np.max(np.abs(residual))) if residual.size else 0.0
        if not math.isfinite(norm):
            return Correction(Corrector.NOT_FINITE, w, ev, norm, steps, jacobians)
        if moved:
            norms.append(norm)
            if iterate is not None:
                iterate(w, ev)
        moved = False
        if converged(ev, norm):
            if fresh:
                return Correction(Corrector.CONVERGED, w, ev, norm, steps, jacobians)
            fresh = True  # the solution's own Jacobian, for the caller's tangent and multipliers
            continue
        first = norm if first is None else first
        if blowup is not None and stepped_fresh and norm > blowup * first:
            return Correction(Corrector.DIVERGED, w, ev, norm, steps, jacobians)
        if contraction is not None and len(norms) > 2 and (
            (min(norms) > contraction * min(norms[:-2])) if contraction_of_best else norms[-1] > contraction * norms[-3]
        ):
            return Correction(Corrector.NOT_CONTRACTING, w, ev, norm, steps, jacobians)
        if not fresh and not norm < chord * last:
            fresh = True  # the kept Jacobian converges too slowly now
            continue
        if fresh and divergence is not None and norm > divergence * best:
            if grace == 0:
                return Correction(Corrector.DIVERGED, w, ev, norm, steps, jacobians)
            grace -= 1
        elif norm < best:
            best, grace = norm, forgive
        if steps == max_iterations:
            return Correction(Corrector.STALLED, w, ev, norm, steps, jacobians)
        stepped_fresh = fresh
        steps += 1
        try:
            # A Jacobian computed only now (a callable) that cannot be is a step that cannot be taken.
            if fresh:
                matrix = ev.matrix()
                jacobians += 1
            direction = step_at(w, ev, matrix)
        except (ArithmeticError, np.linalg.LinAlgError, RuntimeError):
            return Correction(Corrector.NOT_FINITE, w, ev, norm, steps - 1, jacobians)
        retreating = bool(retreat) and not damping and not fresh
        trials = 1 if retreating else damping
        allowed = norm * retreat if retreating else norm
        if trials:
            length, fraction = float(np.linalg.norm(direction)), 1.0
            for _ in range(trials):
                trial = _advance(w, direction, keep)
                try:
                    pending = evaluate(trial, False)
                    trial_norm = float(np.max(np.abs(pending.residual)))
                except _EVALUATION_ERRORS:
                    pending, trial_norm = None, math.inf
                if trial_norm < allowed or (
                    natural and pending is not None and _shorter(step_at, trial, pending, fraction, length, newton_step)
                ):
                    break
                # A rough start far from the solution: halve the step while it makes max |R| worse.
                direction, fraction = 0.5 * direction, 0.5 * fraction
            else:
                pending = None
                if fresh:
                    return Correction(Corrector.DIVERGED, w, ev, norm, steps, jacobians)
                fresh = True
                continue
            w, moved = trial, True
            if pending.jacobian is not None:
                fresh, last = True, norm  # the trial's own Jacobian, computed with its residual
                continue
            if chord is None:
                pending = None  # the next step's Jacobian, fresh at the new w
        else:
            w, moved = _advance(w, direction, keep), True
        fresh, last = chord is None, norm
        if not np.all(np.isfinite(w)):
            return Correction(Corrector.NOT_FINITE, w, ev, norm, steps - 1, jacobians)


def _direction(matrix, residual: np.ndarray, w: np.ndarray, border, keep) -> np.ndarray:
    """The Newton step: of all unknowns with the arclength border, of the ``keep`` unknowns, or of a square R."""
    if isinstance(matrix, CoreAndColumn):
        if border is not None:
            t, w_pred = border
            return matrix.solve(t, -np.append(residual, t @ (w - w_pred)))
        if keep is not None and keep[:-1].all() and not keep[-1]:
            return matrix.solve_core(-residual)
        matrix = matrix.tocsc()
    if border is not None:
        t, w_pred = border
        return solve(append_row(matrix, t), -np.append(residual, t @ (w - w_pred)))
    if keep is not None:
        jac = matrix[:, keep] if not sp.issparse(matrix) else sp.csc_matrix(matrix)[:, np.flatnonzero(keep)]
        return solve(jac, -residual)
    return solve(matrix, -residual)


def _shorter(step_at, trial: np.ndarray, evaluation: Evaluation, fraction: float, length: float, newton_step) -> bool:
    """Deuflhard's natural monotonicity test: the Newton step at the trial is shorter than (1 - fraction / 4) length."""
    if evaluation.jacobian is None and newton_step is None:
        return False  # a residual alone: no step to measure
    try:
        after = step_at(trial, evaluation, evaluation.matrix())
    except (ArithmeticError, np.linalg.LinAlgError, RuntimeError):
        return False
    return float(np.linalg.norm(after)) <= (1.0 - fraction / 4.0) * length


def _advance(w: np.ndarray, direction: np.ndarray, keep) -> np.ndarray:
    if keep is None:
        return w + direction
    out = w.copy()
    out[keep] += direction
    return out


def tangent(jacobian, previous: np.ndarray | None = None, *, direction: float = 1.0, method: str = "bordered") -> np.ndarray:
    """Unit null vector of dR/dw (n, n + 1), oriented along ``previous`` (or with sign(t[-1]) = direction).

    ``method`` ``"bordered"`` solves [dR/dw; previous] t = e (one LU, sparse or dense);
    ``"svd"`` takes the last right singular vector of a dense dR/dw (the most accurate
    where dR/dw is small and dense, as a monodromy's).
    """
    if method not in ("bordered", "svd"):
        raise ValueError(f"method must be 'bordered' or 'svd', got {method!r}")
    if method == "svd":
        t = sla.null_space(np.asarray(jacobian, dtype=float))[:, -1]
        reference = previous @ t if previous is not None else t[-1] * direction
        return -t if reference < 0 else t
    if isinstance(jacobian, CoreAndColumn):
        seed = previous if previous is not None else np.append(np.zeros(jacobian.shape[0]), 1.0)
        t = jacobian.solve(seed, np.append(np.zeros(jacobian.shape[0]), 1.0))
    elif previous is not None:
        t = solve(append_row(jacobian, previous), np.append(np.zeros(jacobian.shape[0]), 1.0))
    elif sp.issparse(jacobian):
        seed = np.zeros(jacobian.shape[1])
        seed[-1] = 1.0
        t = solve(append_row(jacobian, seed), np.append(np.zeros(jacobian.shape[0]), 1.0))
    else:
        t = sla.null_space(np.asarray(jacobian, dtype=float))[:, -1]
    t = t / np.linalg.norm(t)
    reference = previous @ t if previous is not None else t[-1] * direction
    return -t if reference < 0 else t


def branch_directions(jacobian: np.ndarray, along: np.ndarray) -> np.ndarray:
    """At a branch point, the unit direction of the other branch: in the two-dimensional null
    space of dR/dw (dense), the direction orthogonal to the branch's own tangent ``along``."""
    _, _, vh = np.linalg.svd(np.asarray(jacobian, dtype=float))
    null = vh[-2:].T
    other = null - np.outer(along, along @ null)
    best = other[:, np.argmax(np.linalg.norm(other, axis=0))]
    return best / np.linalg.norm(best)


@dataclass
class Event:
    """A located zero of a test function between two points."""

    kind: str
    point: Any
    parameter: float
    index: int  # the event lies between points[index - 1] and points[index]
    tangent: np.ndarray | None = None
    located: bool = True


@dataclass
class Continuation:
    """A traced branch: its points, located events, and why it ended."""

    points: list = field(default_factory=list)
    events: list[Event] = field(default_factory=list)
    end: BranchEnd = BranchEnd.MAX_POINTS
    message: str = ""


def continuation(
    problem: ContinuationProblem,
    w0: np.ndarray,
    *,
    step: float,
    min_step: float,
    max_step: float,
    max_points: int,
    direction: float = 1.0,
    tangent0: np.ndarray | None = None,
    stop_at: tuple[str, ...] = (),
    progress: Callable[[int, int], None] | None = None,
    corrector: dict | None = None,
    easy: int = EASY,
    hard: int = HARD,
    locate: bool = True,
    tangent_method: str = "bordered",
    first: Any = None,
) -> Continuation:
    """Follow the branch of ``problem`` from a point w0 on it (pseudo-arclength).

    Parameters
    ----------
    problem : ContinuationProblem
    w0 : ndarray (n + 1,)
        A point on the branch (corrected here with lambda fixed).
    step, min_step, max_step : float
        Initial, smallest and largest arclength steps.
    max_points : int
    direction : float
        +1 to start towards larger lambda, -1 towards smaller (ignored with ``tangent0``).
    tangent0 : ndarray, optional
        Starting direction (e.g. from :func:`branch_directions`, to switch branches, or a
        restart's interpolated tangent). With it w0 is corrected on the hyperplane through w0
        normal to it, not at its parameter held fixed.
    stop_at : tuple of str
        Event kinds that end the branch once located: values of :class:`BranchEnd`
        (``"fold"``, ``"branch_point"``, ``"period_doubling"``, ``"torus"``, ``"hopf"``).
    progress : callable(points, max_points), optional
    corrector : dict, optional
        Options of :func:`newton` for the corrections (``max_iterations``, ``divergence``,
        ``forgive``, ``chord``, ``damping``); with ``chord`` each correction starts with the
        Jacobian of the last corrected point.
    easy, hard : int
        The step grows (x GROW) after a correction of at most ``easy`` iterations and
        shrinks (x SHRINK) after one of ``hard`` or more.
    locate : bool
        Locate events by the secant method (each trial a correction); False reports them at
        the point after the sign change, unlocated (``Event.located`` False), where a
        problem locates them more cheaply itself (a fold of cycles by a parabola).
    tangent_method : str
        ``"bordered"`` or ``"svd"`` (:func:`tangent`).
    first : optional
        The point the problem stores at w0, when the caller has it already; used if w0
        needs no correction.

    Returns
    -------
    Continuation
    """
    for name, value in (("step", step), ("min_step", min_step), ("max_step", max_step)):
        if not (math.isfinite(value) and value > 0):
            raise ValueError(f"{name} must be a finite number > 0, got {value!r}")
    if not min_step <= step <= max_step:
        raise ValueError(f"steps must satisfy min_step <= step <= max_step, got {min_step!r}, {step!r}, {max_step!r}")
    if not (isinstance(max_points, int) and max_points >= 1):
        raise ValueError(f"max_points must be an integer >= 1, got {max_points!r}")
    unknown = [kind for kind in stop_at if kind not in EVENT_KINDS]
    if unknown:
        raise ValueError(f"stop_at: unknown event kinds {unknown}; allowed: {', '.join(EVENT_KINDS)}")
    own_converged = getattr(problem, "converged", None)
    criterion = {"tol": problem.tol} if own_converged is None else {"converged": own_converged}
    if tangent0 is None:
        keep = np.ones(len(w0), dtype=bool)
        keep[-1] = False
        start = newton(problem.evaluate, w0, keep=keep, **criterion)
    else:
        # A restart on a branch whose parameter hardly moves (towards a homoclinic end the period
        # grows at an all but fixed M) is ill-posed with the parameter held: Newton on its hyperplane.
        normal = np.asarray(tangent0, dtype=float) / np.linalg.norm(tangent0)
        start = newton(problem.evaluate, w0, border=(normal, np.asarray(w0, dtype=float)), **criterion)
    if not start.converged:
        raise StartError(f"the start is not on the branch: the corrector {start.status} with max|R| = {start.norm:.3g}")
    options = dict(corrector or {})

    def correct(w: np.ndarray, t: np.ndarray, h: float, jacobian) -> Correction:
        if options.get("chord") is not None:
            options["jacobian0"] = jacobian
        return newton(problem.evaluate, w + h * t, border=(t, w + h * t), **criterion, **options)

    def unit_tangent(jacobian, previous: np.ndarray | None) -> np.ndarray:
        return tangent(jacobian, previous, direction=direction, method=tangent_method)

    def review(previous, candidate, h: float) -> float | None:
        return None if h <= min_step or problem.accept(previous, candidate) else max(min_step, 0.5 * h)

    def failed(h: float) -> float:
        return 0.5 * h if h <= min_step else max(min_step, 0.5 * h)

    def next_step(h: float, corrected: Correction, candidate) -> float:
        return min(max_step, h * (GROW if corrected.iterations <= easy else SHRINK if corrected.iterations >= hard else 1.0))

    correct = getattr(problem, "correct", correct)
    unit_tangent = getattr(problem, "tangent", unit_tangent)
    review = getattr(problem, "review", review)
    failed = getattr(problem, "failed", failed)
    next_step = getattr(problem, "next_step", next_step)
    own_events = getattr(problem, "events", None)
    own_locate = getattr(problem, "locate", None)

    w = start.w
    ev = start.evaluation
    jacobian = ev.matrix()
    if tangent0 is None:
        t = unit_tangent(jacobian, None)
    else:
        t = np.asarray(tangent0, dtype=float) / np.linalg.norm(tangent0)
        try:
            t = unit_tangent(jacobian, t)
        except (np.linalg.LinAlgError, RuntimeError):
            # Started on a branch point, where the null space has two dimensions: the direction given is the tangent.
            pass
    point = first if first is not None and start.iterations == 0 else problem.point(w, ev, start.iterations)
    result = Continuation(points=[point])
    if progress is not None:
        progress(1, max_points)
    tests = None if own_events is not None else _all_tests(problem, point, jacobian, t)
    h = step
    while len(result.points) < max_points:
        corrected = correct(w, t, h, jacobian)
        candidate = None
        if corrected.converged:
            # The latest Jacobian computed, the next chord iterations' start even where the monitor refuses the point.
            jacobian = corrected.evaluation.matrix()
            candidate = problem.point(corrected.w, corrected.evaluation, corrected.iterations)
        if candidate is None:
            h = failed(h)
            if h < min_step:
                result.end = BranchEnd.STEP_TOO_SMALL
                result.message = (
                    f"no step down to min_step={min_step:g} could be corrected after {getattr(problem, 'parameter_name', 'lambda')} = {w[-1]:.10g}: "
                    + BranchEnd.STEP_TOO_SMALL.advice
                )
                break
            continue
        retake = review(result.points[-1], candidate, h)
        if retake is not None:
            h = retake
            continue
        try:
            t_new = unit_tangent(jacobian, t)
        except (np.linalg.LinAlgError, RuntimeError):
            # A point exactly on a branch point: its tangent is not unique, so the step is retaken shorter.
            h = max(min_step, 0.5 * h)
            continue
        previous = result.points[-1]
        result.points.append(candidate)
        if progress is not None:
            progress(len(result.points), max_points)
        if own_events is not None:
            new_tests, kinds = None, own_events(previous, candidate, t, t_new)
        else:
            new_tests = _all_tests(problem, candidate, jacobian, t_new)
            kinds = [kind for kind in new_tests if kind in tests and tests[kind] * new_tests[kind] < 0]
        ended = None
        index = len(result.points) - 1
        for kind in kinds:
            event = None if own_locate is None else own_locate(kind, w, t, h, previous, candidate, index)
            if event is None and locate:
                if new_tests is not None:
                    before, after = tests[kind], new_tests[kind]
                elif kind == "fold":
                    before, after = t[-1], t_new[-1]
                else:
                    before, after = problem.tests(previous)[kind], problem.tests(candidate)[kind]
                event = _locate(problem, kind, w, t, h, before, after, index, candidate, {**criterion, **options}, tangent_method)
            elif event is None:
                event = Event(kind, candidate, float(corrected.w[-1]), index, t_new, located=False)
            if event.located and not problem.confirm(kind, event.point):
                continue
            result.events.append(event)
            if kind in stop_at and ended is None:
                ended = kind
        w, t, tests = corrected.w, t_new, new_tests
        h = next_step(h, corrected, candidate)
        if ended is not None:
            result.end = BranchEnd(ended)
            where = "located at" if result.events[-1].located else "passed before"
            name = getattr(problem, "parameter_name", "lambda")
            result.message = f"{ended.replace('_', ' ')} {where} {name} = {result.events[-1].parameter:.12g}: {result.end.advice}"
            break
        stop = problem.stop(candidate)
        if stop is not None:
            result.end, result.message = stop
            break
    else:
        result.message = f"stopped after max_points={max_points} points: " + BranchEnd.MAX_POINTS.advice
    return result


class StartError(CosseratChainError, ValueError):
    """The start of a continuation is not on its branch."""


def _all_tests(problem: ContinuationProblem, point, jacobian, t: np.ndarray) -> dict[str, float]:
    tests = {"fold": float(t[-1]), "branch_point": determinant_sign(append_row(jacobian, t))}
    tests.update(problem.tests(point))
    return tests


def illinois(x, f: float, low, f_low: float, high, f_high: float, side: int) -> tuple[Any, float, Any, float, int]:
    """One update of the Illinois (modified regula falsi) bracket [low, high] by a trial ``x`` with value ``f``.

    ``x`` replaces the end whose value has the sign of ``f`` (``low`` where f f_low > 0, else ``high``); when the
    same end is replaced twice running, the value kept at the other end is halved, so that the secant's next trial
    moves past it (superlinear convergence, where plain regula falsi keeps one end for ever). The ends may be
    numbers or anything the caller brackets with (orbits, points).

    Parameters
    ----------
    x : object
        The trial.
    f : float
        Its value.
    low, high : object
        The bracket's ends.
    f_low, f_high : float
        Their values (of opposite signs).
    side : int
        Which end the previous update replaced: 1 ``low``, -1 ``high``, 0 none yet.

    Returns
    -------
    low, f_low, high, f_high, side
        The updated bracket and the end this update replaced.
    """
    if f * f_low > 0:
        if side == 1:
            f_high *= 0.5
        return x, f, high, f_high, 1
    if side == -1:
        f_low *= 0.5
    return low, f_low, x, f, -1


def _locate(
    problem, kind: str, w: np.ndarray, t: np.ndarray, h: float, before: float, after: float, index: int, fallback, options, method: str
) -> Event:
    """Zero of test ``kind`` on the arclength in (0, h) from w along t, by the secant (Illinois) method;
    the branch point's test is a sign only, so it is bisected."""
    low, high, f_low, f_high = 0.0, h, before, after
    best = None
    side = 0
    for _ in range(EVENT_ITERATIONS):
        if kind == "branch_point":
            s = 0.5 * (low + high)
        else:
            s = high - f_high * (high - low) / (f_high - f_low)
            if not (low < s < high):
                s = 0.5 * (low + high)
        corrected = newton(problem.evaluate, w + s * t, border=(t, w + s * t), **options)
        if not corrected.converged:
            break
        point = problem.point(corrected.w, corrected.evaluation, corrected.iterations)
        try:
            t_s = tangent(corrected.evaluation.matrix(), t, method=method)
        except (np.linalg.LinAlgError, RuntimeError):
            # The bordered matrix is singular exactly here: a branch point hit on the nose.
            best = (point, corrected.w[-1], t)
            break
        if kind == "fold":
            value = float(t_s[-1])
        elif kind == "branch_point":
            value = determinant_sign(append_row(corrected.evaluation.matrix(), t_s))
        else:
            value = problem.tests(point)[kind]
        best = (point, corrected.w[-1], t_s)
        if value == 0 or (high - low) < EVENT_TOL * max(1.0, h):
            break
        low, f_low, high, f_high, side = illinois(s, value, low, f_low, high, f_high, side)
    if best is None:
        return Event(kind, fallback, float(np.nan), index, None, located=False)
    return Event(kind, best[0], float(best[1]), index, best[2])
