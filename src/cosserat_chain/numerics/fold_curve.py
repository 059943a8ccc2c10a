"""The static fold followed in a parameter: M_c against E1, E2, h, a or b, by continuation of the fold itself.

Contract
--------
A fold of load control (:class:`~.continuation.Fold`) is a state q, a moment M and a
null vector w of the stiffness K = -dF/dq with

    F(q; p) + M e = 0,    K(q; p) w = 0,    l . w = 1,

2 n + 1 equations in the 2 n + 1 unknowns (q, M, w) for a parameter value p: the
extended system with which AUTO-07p continues limit points (its "LP continuation").
:func:`continue_fold` starts from the first fold of the branch from rest at the first
value (:func:`~.continuation.locate_fold`) and follows the curve of folds in (q, M, w, p)
by the kit's pseudo-arclength driver (:func:`~.kit.continuation`), p the continued
parameter, from each value asked for to the next; each value is an event of the driver
(AUTO-07p's user point), solved with p held at it exactly. The Jacobian of the extended system

    [[ -K,        e,  0  ],
     [ D(K w)/dq, 0,  K  ],
     [ 0,         0,  l^T]]

is sparse, each block banded (D(K w)/dq, the derivative of K along w, by central
differences of the model's exact stiffness), and its column dR/dp is a central difference
in p, so a Newton step is one sparse LU: O(N). A correction that moves the state further
than :data:`JUMP` from its predictor has jumped to another fold and is retaken shorter.
Where p turns back along the curve (the driver's fold of the curve: two folds of the branch
meet there, as at a cusp, and both vanish beyond; the onset of rotation then jumps to
another maximum of M), the turn is located and the curve stops there, saying so; so does a
curve the corrector cannot follow.

The statics read neither the inertia (m, j) nor the viscosities (gamma_u, gamma_v,
gamma_phi): along those fields the fold does not move (:data:`STATIC_INDEPENDENT`).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field, replace

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla
from pydantic import ValidationError

from ..linalg.general import CoreAndColumn
from ..models.base import Model, get_model
from ..params import ChainParams
from ..state import ROW_INDEX, column, pack, require_held, unpack
from .continuation import locate_fold
from .kit import BranchEnd, Correction, Corrector, Evaluation, EvaluationFailed, continuation, newton, tangent
from .newton import moment_dof, round_off_floor

#: Fields along which the fold can be continued (the chain's numbers; N is a whole number).
FIELDS = ("E1", "E2", "h", "a", "b", "m", "j", "gamma_u", "gamma_v", "gamma_phi")
#: Fields the statics do not read: the fold is the same at every value of them.
STATIC_INDEPENDENT = ("m", "j", "gamma_u", "gamma_v", "gamma_phi")
#: Newton iterations of a correction (a step of the curve, or a value with p held) before the step is halved.
MAX_ITERATIONS = 25
#: Halvings of the first step towards a value before the curve is declared ended there.
MAX_HALVINGS = 10
#: Residual asked of the extended system, relative (never below the forces' round-off floor).
TOL = 1e-12
#: Step of the central difference of the extended system in the parameter, relative to max(1, |p|).
PARAMETER_STEP = 1e-6
#: Most points of the curve between two values asked for.
LEG_POINTS = 200
#: Weight of the null vector in the arclength (its unknowns enter the driver scaled by it): the
#: curve is followed in the state, the moment and p, the null vector following them. Near a
#: nearly double fold (a cantilever of N = 3, E2 = 1) the null vector turns 10^5 times faster
#: than p moves, and unweighted steps went to a spurious solution with |w| = 2e4.
NULL_WEIGHT = 1e-3
#: Most growth of the null vector's size in one step (:data:`NULL_WEIGHT`).
NULL_GROWTH = 10.0
#: SuperLU's threshold for a diagonal pivot of the extended system in the interleaved order
#: (benchmarks/TIMINGS.md: a third of the fill and of the time of partial pivoting at N = 1000).
PIVOTING = 0.01
#: Central-difference step of D(K w)/dq, relative to the state's size (w is normalised to |w| = 1 first).
DERIVATIVE_STEP = 1e-6
#: Largest change of the state (in h or rad) Newton may make from its predictor: a longer one
#: has jumped to another fold (one N = 10 chain's landed 35 rad away, on a branch that had
#: turned five times) rather than followed this one, and the parameter step is halved.
JUMP = 0.3


@dataclass
class FoldCurve:
    """The fold M_c followed through the values of one field.

    Attributes
    ----------
    field : str
    values : ndarray (k,)
        The values reached, in the order asked (k <= the number asked when the curve ended).
    moment, phi0 : ndarray (k,)
        The fold's moment M_c and the loaded particle's angle there.
    x : ndarray (k, 3, 2N+1)
        The states at the fold.
    iterations : ndarray (k,)
        Newton iterations each value took at p held there (for the first, from the fold the branch's continuation located).
    independent : bool
        True for a field the statics do not read (:data:`STATIC_INDEPENDENT`).
    complete : bool
        False if the fold could not be followed to the last value; ``message`` says where and why.
    """

    field: str
    values: np.ndarray
    moment: np.ndarray
    phi0: np.ndarray
    x: np.ndarray
    iterations: np.ndarray
    independent: bool
    complete: bool = True
    message: str = ""
    params: dict = field(default_factory=dict)

    def as_dict(self) -> dict:
        """JSON-ready rows, one per value: the fold's moment and angle."""
        return {
            "field": self.field,
            "independent": self.independent,
            "complete": self.complete,
            "message": self.message,
            "rows": [
                {"value": float(v), "static_fold": float(m), "phi0_at_fold": float(p)}
                for v, m, p in zip(self.values, self.moment, self.phi0)
            ],
        }


def field_values(field_name: str, values: Sequence[float]) -> np.ndarray:
    """``values`` as a flat float array; ValueError for a field not in :data:`FIELDS` or values not one or more finite numbers."""
    if field_name not in FIELDS:
        raise ValueError(f"field must be one of {', '.join(FIELDS)} (a number of the chain), got {field_name!r}")
    out = np.asarray(values, dtype=float).ravel()
    if out.size == 0 or not np.all(np.isfinite(out)):
        raise ValueError(f"values of {field_name} must be one or more finite numbers, got {values!r}")
    return out


def chain_with(params: ChainParams, field_name: str, value: float) -> ChainParams:
    """``params`` with ``field_name`` set to ``value``; ValueError naming the field and the value if that chain is not admissible."""
    try:
        return params.replace(**{field_name: value})
    except ValidationError as err:
        reasons = "; ".join(error["msg"].removeprefix("Value error, ") for error in err.errors())
        raise ValueError(f"{field_name} = {value:g} is not an admissible chain: {reasons}") from None


def _null_vector(stiffness: sp.spmatrix) -> np.ndarray:
    """The null vector of K at a fold (singular to round-off), by two steps of inverse iteration, |w| = 1."""
    lu = spla.splu(sp.csc_matrix(stiffness))
    w = lu.solve(np.ones(stiffness.shape[0]))
    w = lu.solve(w / np.linalg.norm(w))
    return w / np.linalg.norm(w)


def _along(model: Model, params: ChainParams, x: np.ndarray, w: np.ndarray) -> sp.csr_matrix:
    """D(K w)/dq: the derivative of the stiffness along w applied to w, by central differences."""
    size = max(1.0, float(np.max(np.abs(x))))
    h = DERIVATIVE_STEP * size / float(np.max(np.abs(w)))
    shift = unpack(params, w) * h
    return ((model.stiffness(params, x + shift) - model.stiffness(params, x - shift)) / (2.0 * h)).tocsr()


class _FoldProblem:
    """The extended system at the field's value p, with p the continued parameter of the kit's
    driver (:func:`~.kit.continuation`).

    The driver's unknowns interleave the state and the null vector degree of freedom by degree
    of freedom, (q_1, w_1, q_2, w_2, ..., M, p), and so do the equations, (F_1, (K w)_1, ...,
    l . w - 1): the Jacobian is then a band with its borders, and SuperLU's factor of it fills
    half as much as in the blocks' order. :meth:`natural` and :meth:`interleaved` convert.

    The driver's built-in fold of this curve is a turn of p along it (two folds of the branch
    meet there: a cusp, or the curve turns back); its other events are the values asked for
    (``"value"``, the test p - target), each located by the driver and then solved with p held
    there exactly (:meth:`at`).
    """

    tol = TOL

    def __init__(self, params: ChainParams, model: Model, field_name: str, dof: int, normal: np.ndarray):
        self.params, self.model, self.field, self.dof, self.normal = params, model, field_name, dof, normal
        nf = self.nf = normal.size
        self.e = sp.csr_matrix((np.ones(1), ([dof], [0])), shape=(nf, 1))
        self.target = math.nan
        self.chains: dict[float, ChainParams] = {}
        # The natural order is (q, M, w, p) and (F, K w, l . w - 1); the driver's interleaves them.
        self.unknowns = np.empty(2 * nf + 2, dtype=int)
        self.unknowns[0 : 2 * nf : 2] = np.arange(nf)
        self.unknowns[1 : 2 * nf : 2] = nf + 1 + np.arange(nf)
        self.unknowns[2 * nf :] = (nf, 2 * nf + 1)
        self.equations = np.empty(2 * nf + 1, dtype=int)
        self.equations[0 : 2 * nf : 2] = np.arange(nf)
        self.equations[1 : 2 * nf : 2] = nf + np.arange(nf)
        self.equations[2 * nf] = 2 * nf
        # The null vector enters the driver's unknowns scaled by NULL_WEIGHT (its arclength: below).
        self.scale = np.ones(2 * nf + 2)
        self.scale[1 : 2 * nf : 2] = NULL_WEIGHT

    def interleaved(self, natural: np.ndarray) -> np.ndarray:
        return natural[self.unknowns] * self.scale

    def natural(self, interleaved: np.ndarray) -> np.ndarray:
        out = np.empty_like(interleaved)
        out[self.unknowns] = interleaved / self.scale
        return out

    def chain(self, value: float) -> ChainParams:
        if value not in self.chains:
            if len(self.chains) > 64:
                self.chains.clear()
            try:
                self.chains[value] = chain_with(self.params, self.field, value)
            except ValueError as err:
                raise EvaluationFailed(str(err)) from None
        return self.chains[value]

    def _residual(self, z: np.ndarray, chain: ChainParams) -> tuple[np.ndarray, sp.csr_matrix, np.ndarray]:
        """The extended system's residual in the natural order at z = (q, M, w), K, and the state."""
        nf = self.nf
        q, moment, w = z[:nf], z[nf], z[nf + 1 :]
        x = unpack(chain, q)
        k = self.model.stiffness(chain, x).tocsr()
        force = pack(chain, self.model.compiled_forces(chain, x))
        force[self.dof] += moment
        return np.concatenate([force, k @ w, [self.normal @ w - 1.0]]), k, x

    def evaluate(self, w: np.ndarray, jacobian: bool) -> Evaluation:
        natural = self.natural(w)
        z, value = natural[:-1], float(natural[-1])
        chain = self.chain(value)
        residual, k, x = self._residual(z, chain)

        def matrix() -> CoreAndColumn:
            along = _along(self.model, chain, x, z[self.nf + 1 :])
            extended = sp.bmat([[-k, self.e, None], [along, None, k], [None, None, sp.csr_matrix(self.normal[None, :])]], format="csr")
            core = extended[self.equations][:, self.unknowns[:-1]] @ sp.diags(1.0 / self.scale[:-1])
            return CoreAndColumn(core, self._by_parameter(z, value)[self.equations], pivoting=PIVOTING)

        return Evaluation(residual[self.equations], matrix, data=(k, natural, residual))

    def _by_parameter(self, z: np.ndarray, value: float) -> np.ndarray:
        """dR/dp at (z, p) by central differences (one-sided next to the end of the admissible range)."""
        step = PARAMETER_STEP * max(1.0, abs(value))
        sides = []
        for shifted in (value + step, value - step):
            try:
                sides.append((shifted, self._residual(z, self.chain(shifted))[0]))
            except EvaluationFailed:
                sides.append((value, self._residual(z, self.chain(value))[0]))
        (high, r_high), (low, r_low) = sides
        return (r_high - r_low) / (high - low)

    def converged(self, evaluation: Evaluation, norm: float) -> bool:
        # The forces to their round-off floor, K w relative to the size of K and of w.
        k, w, residual = evaluation.data
        nf = self.nf
        forces = np.max(np.abs(residual[:nf])) <= max(TOL * (1.0 + abs(w[nf])), round_off_floor(k, w[:nf]))
        return forces and np.max(np.abs(residual[nf:])) <= TOL * max(1.0, float(np.max(np.abs(w[nf + 1 : -1])))) * float(
            abs(k).sum(axis=1).max()
        )

    def correct(self, w: np.ndarray, t: np.ndarray, h: float, jacobian) -> Correction:
        predicted = w + h * t
        corrected = newton(
            self.evaluate, predicted, converged=self.converged, border=(t, predicted), max_iterations=MAX_ITERATIONS, divergence=None
        )
        if corrected.converged and np.max(np.abs(corrected.w[0 : 2 * self.nf : 2] - predicted[0 : 2 * self.nf : 2])) > JUMP:
            return replace(corrected, status=Corrector.JUMPED)  # onto another fold, not along this one
        return corrected

    def at(self, start: np.ndarray, value: float) -> Correction:
        """The fold at p = ``value`` exactly, by Newton from ``start`` with p held."""
        guess = start.copy()
        guess[-1] = value
        keep = np.ones(guess.size, dtype=bool)
        keep[-1] = False
        return newton(self.evaluate, guess, converged=self.converged, keep=keep, max_iterations=MAX_ITERATIONS, divergence=None)

    def point(self, w: np.ndarray, evaluation: Evaluation, iterations: int) -> np.ndarray:
        return w.copy()

    def accept(self, previous: np.ndarray, candidate: np.ndarray) -> bool:
        # A null vector that grew NULL_GROWTH times turned nearly normal to l: the fold is nearly
        # double there (two eigenvalues of K near zero), and the step is retaken shorter.
        grown = np.max(np.abs(candidate[1 : 2 * self.nf : 2])) / max(np.max(np.abs(previous[1 : 2 * self.nf : 2])), NULL_WEIGHT)
        return bool(grown <= NULL_GROWTH)

    def tests(self, point: np.ndarray) -> dict[str, float]:
        return {"value": float(point[-1]) - self.target}

    def events(self, previous: np.ndarray, candidate: np.ndarray, t_before: np.ndarray, t_after: np.ndarray) -> list[str]:
        kinds = ["fold"] if t_before[-1] * t_after[-1] < 0 else []
        if (previous[-1] - self.target) * (candidate[-1] - self.target) < 0:
            kinds.append("value")
        return kinds

    def confirm(self, kind: str, point) -> bool:
        return True

    def stop(self, point: np.ndarray) -> None:
        return None


def continue_fold(
    params: ChainParams,
    model: str | Model,
    field_name: str,
    values: Sequence[float],
    *,
    particle: int = 0,
    progress: Callable[[float, float], None] | None = None,
) -> FoldCurve:
    """Follow the first fold of the branch from rest (M_c) through ``values`` of ``field_name`` (module docstring).

    Parameters
    ----------
    params : ChainParams
        The chain; ``field_name`` takes each of ``values`` in turn, the other fields stay.
    model : str or Model
        A model with a fold: ``"nonlinear"`` or ``"sine"`` (the linear model has none).
    field_name : str
        One of :data:`FIELDS`.
    values : sequence of float
        In the order to follow them (close enough for Newton to step from one to the next;
        steps too long are halved).
    particle : int
        The loaded particle.
    progress : callable(done, total), optional

    Returns
    -------
    FoldCurve

    Raises
    ------
    ValueError
        For an unknown or whole-number field, a value that is not finite or not admissible
        (pydantic's message names the field), a chain that can move rigidly, or a first
        value whose branch has no fold (the linear model).
    """
    model = get_model(model)
    values = field_values(field_name, values)
    independent = field_name in STATIC_INDEPENDENT
    chain = params.replace(**{field_name: float(values[0])})
    require_held(chain)
    dof = moment_dof(chain, particle)
    # The first fold within a whole turn (a long chain's lies beyond pi: phi_0 = 3.58 at N = 1000).
    fold = locate_fold(chain, model, particle=particle, phi0_max=2.0 * math.pi)
    if fold is None:
        raise ValueError(
            f"the {model.name} model's branch from rest has no fold at {field_name} = {values[0]:g}: there is no M_c to follow"
        )
    for value in values[1:]:
        chain_with(params, field_name, float(value))  # every value admissible, or the error names it
    q = pack(chain, fold.x)
    w = _null_vector(model.stiffness(chain, fold.x))
    normal = w / float(w @ w)
    col = column(chain, particle)
    problem = _FoldProblem(params, model, field_name, dof, normal)
    first = problem.at(problem.interleaved(np.concatenate([q, [fold.moment], w, [values[0]]])), float(values[0]))
    if not first.converged:
        raise ValueError(f"the fold at {field_name} = {values[0]:g} could not be solved on the extended system ({first.status})")
    found = [(float(values[0]), first.w, first.iterations)]  # in the driver's order
    message = ""
    for index, target in enumerate(values[1:], start=1):
        if progress is not None:
            progress(index, values.size)
        reached, end_at = _leg(problem, found[-1][1], float(target))
        if reached is None:
            message = (
                f"the fold could not be followed beyond {field_name} = {end_at:.6g} towards {float(target):.6g}: it ends there "
                "(a cusp, where it meets another fold) or the curve turns back in the parameter"
            )
            break
        found.append((float(target), *reached))
    found = [(value, problem.natural(z), iterations) for value, z, iterations in found]
    states = np.array([unpack(params.replace(**{field_name: v}), z[: normal.size]) for v, z, _ in found])
    if progress is not None:
        progress(values.size, values.size)
    return FoldCurve(
        field=field_name,
        values=np.array([entry[0] for entry in found]),
        moment=np.array([float(z[normal.size]) for _, z, _ in found]),
        phi0=states[:, ROW_INDEX["phi"], col].copy(),
        x=states,
        iterations=np.array([entry[2] for entry in found]),
        independent=independent,
        complete=not message,
        message=message,
        params=params.model_dump(),
    )


def _leg(problem: _FoldProblem, start: np.ndarray, target: float) -> tuple[tuple[np.ndarray, int] | None, float]:
    """Follow the fold curve from ``start`` (a solved fold) to p = ``target`` by the kit's driver.

    Returns the fold at the target and its Newton iterations (None where the curve turned back
    in p, or could not be followed, before it), and the value of p where it ended.
    """
    if start[-1] == target:
        return (start, 0), target
    problem.target = target
    direction = 1.0 if target > start[-1] else -1.0
    t0 = tangent(problem.evaluate(start, True).matrix(), None, direction=direction)
    if abs(t0[-1]) < np.finfo(float).eps:
        return None, float(start[-1])  # the curve is normal to p here: it turns back
    # A first step past the target (1.5 times the distance along the tangent), halved while it fails.
    step = 1.5 * abs(target - start[-1]) / abs(t0[-1])
    traced = continuation(
        problem,
        start,
        step=step,
        min_step=step / 2**MAX_HALVINGS,
        max_step=step,
        max_points=LEG_POINTS,
        tangent0=t0,
        stop_at=("value", "fold"),
        first=start.copy(),
    )
    if traced.end == BranchEnd.VALUE and traced.events[-1].located:
        # The secant method's point, within its tolerance of the value: p set to it exactly.
        solved = problem.at(traced.events[-1].point, target)
        if solved.converged:
            return (solved.w, solved.iterations), target
    # Where the driver stopped short (a turn of p, or no step it could correct), Newton with p held
    # at the value from the start: near a fold that is nearly not simple (the N = 3 cantilever's,
    # E2 = 1 ... 1.1) the extended system is nearly singular and the tangent's p component is
    # round-off, which shows as turns that are not there, while the fold at the value is regular.
    direct = problem.at(start, target)
    if direct.converged and np.max(np.abs(direct.w[0 : 2 * problem.nf : 2] - start[0 : 2 * problem.nf : 2])) <= JUMP:
        return (direct.w, direct.iterations), target
    if traced.end == BranchEnd.FOLD:
        return None, float(traced.events[-1].parameter)
    return None, float(traced.points[-1][-1])
