"""The static fold followed in a parameter: M_c against E1, E2, h, a or b, by continuation of the fold itself.

Contract
--------
A fold of load control (:class:`~.continuation.Fold`) is a state q, a moment M and a
null vector w of the stiffness K = -dF/dq with

    F(q; p) + M e = 0,    K(q; p) w = 0,    l . w = 1,

2 n + 1 equations in the 2 n + 1 unknowns (q, M, w) for a parameter value p: the
extended system with which AUTO-07p continues limit points (its "LP continuation").
:func:`continue_fold` starts from the first fold of the branch from rest at the first
value (:func:`~.continuation.locate_fold`) and follows it through the values in turn:
each value's Newton (the kit's corrector, :func:`~.kit.newton`) starts from the previous
fold, extrapolated along the curve from the two before it. Its Jacobian

    [[ -K,        e,  0  ],
     [ D(K w)/dq, 0,  K  ],
     [ 0,         0,  l^T]]

is sparse, each block banded (D(K w)/dq, the derivative of K along w, by central
differences of the model's exact stiffness), so a Newton step is one sparse LU: O(N).
A value that Newton cannot reach from the previous one, or reaches only by a jump to
another fold (a correction beyond :data:`JUMP`), is approached through halved parameter
steps; where even that fails the fold has ended (a cusp, where it meets another fold and
both vanish: the onset of rotation then jumps to another maximum of M) or the curve turns
back in p, and the curve stops there, saying so.

The statics read neither the inertia (m, j) nor the viscosities (gamma_u, gamma_v,
gamma_phi): along those fields the fold does not move (:data:`STATIC_INDEPENDENT`).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla
from pydantic import ValidationError

from ..models.base import Model, get_model
from ..params import ChainParams
from ..state import ROW_INDEX, column, pack, require_held, unpack
from .continuation import locate_fold
from .kit import Evaluation, newton
from .newton import moment_dof, round_off_floor

#: Fields along which the fold can be continued (the chain's numbers; N is a whole number).
FIELDS = ("E1", "E2", "h", "a", "b", "m", "j", "gamma_u", "gamma_v", "gamma_phi")
#: Fields the statics do not read: the fold is the same at every value of them.
STATIC_INDEPENDENT = ("m", "j", "gamma_u", "gamma_v", "gamma_phi")
#: Newton iterations per value before its parameter step is halved.
MAX_ITERATIONS = 25
#: Halvings of a parameter step before the curve is declared ended there.
MAX_HALVINGS = 10
#: Residual asked of the extended system, relative (never below the forces' round-off floor).
TOL = 1e-12
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
        Newton iterations each value took (0 for the first, located by continuation).
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


def _newton(model, params, dof, q, moment, w, normal) -> tuple[np.ndarray, float, np.ndarray, int] | None:
    """Solve the extended system for ``params`` from (q, M, w) by the kit's corrector; None if it does not converge."""
    nf = q.size
    e = sp.csr_matrix((np.ones(1), ([dof], [0])), shape=(nf, 1))

    def evaluate(z: np.ndarray, jacobian: bool) -> Evaluation:
        q, moment, w = z[:nf], z[nf], z[nf + 1 :]
        x = unpack(params, q)
        k = model.stiffness(params, x).tocsr()
        force = pack(params, model.compiled_forces(params, x))
        force[dof] += moment
        residual = np.concatenate([force, k @ w, [normal @ w - 1.0]])

        def matrix() -> sp.csc_matrix:
            along = _along(model, params, x, w)
            return sp.bmat([[-k, e, None], [along, None, k], [None, None, sp.csr_matrix(normal[None, :])]], format="csc")

        return Evaluation(residual, matrix, data=(k, z))

    def converged(evaluation: Evaluation, norm: float) -> bool:
        # The forces to their round-off floor, K w relative to the size of K and of w.
        k, z = evaluation.data
        residual = evaluation.residual
        return np.max(np.abs(residual[:nf])) <= max(TOL * (1.0 + abs(z[nf])), round_off_floor(k, z[:nf])) and np.max(
            np.abs(residual[nf:])
        ) <= TOL * max(1.0, float(np.max(np.abs(z[nf + 1 :])))) * float(abs(k).sum(axis=1).max())

    corrected = newton(evaluate, np.concatenate([q, [moment], w]), converged=converged, max_iterations=MAX_ITERATIONS, divergence=None)
    if not corrected.converged:
        return None
    z = corrected.w
    return z[:nf].copy(), float(z[nf]), z[nf + 1 :].copy(), corrected.iterations


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
    q = pack(chain, fold.x)
    w = _null_vector(model.stiffness(chain, fold.x))
    normal = w / float(w @ w)
    col = column(chain, particle)
    found = [(float(values[0]), q, fold.moment, w, 0)]
    message = ""
    for index, target in enumerate(values[1:], start=1):
        if progress is not None:
            progress(index, values.size)
        start, step, reached = found[-1][0], float(target) - found[-1][0], None
        for _ in range(MAX_HALVINGS + 1):
            value = start + step
            guess = found[-1]
            if len(found) >= 2 and found[-2][0] != guess[0]:
                # Secant predictor along the curve: the fold moves smoothly with the parameter.
                ratio = (value - guess[0]) / (guess[0] - found[-2][0])
                guess = (value, *(g + ratio * (g - h) for g, h in zip(guess[1:4], found[-2][1:4])), 0)
            chain = chain_with(params, field_name, value)
            solved = _newton(model, chain, dof, guess[1], guess[2], guess[3], normal)
            if solved is not None and np.max(np.abs(solved[0] - guess[1])) > JUMP:
                solved = None  # a jump to another fold, not this one followed
            if solved is not None:
                found.append((value, *solved))
                if value == float(target):
                    reached = True
                    break
                start, step = value, float(target) - value
                continue
            step /= 2.0
        if not reached:
            message = (
                f"the fold could not be followed beyond {field_name} = {found[-1][0]:.6g} towards {float(target):.6g}: it ends there "
                "(a cusp, where it meets another fold) or the curve turns back in the parameter"
            )
            break
    # The values asked for, in order (the intermediate points of halved steps are dropped).
    asked = [entry for entry in found if np.any(entry[0] == values)]
    states = np.array([unpack(params.replace(**{field_name: v}), entry_q) for v, entry_q, *_ in asked])
    if progress is not None:
        progress(values.size, values.size)
    return FoldCurve(
        field=field_name,
        values=np.array([entry[0] for entry in asked]),
        moment=np.array([entry[2] for entry in asked]),
        phi0=states[:, ROW_INDEX["phi"], col].copy(),
        x=states,
        iterations=np.array([entry[4] for entry in asked]),
        independent=independent,
        complete=not message,
        message=message,
        params=params.model_dump(),
    )
