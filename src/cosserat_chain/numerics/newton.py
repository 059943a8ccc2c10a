"""Static equilibria by Newton's method with the model's sparse stiffness.

Contract
--------
:func:`solve_equilibrium` (load control) finds x with F(x) + L = 0 for constant
loads L (the loads' values at time ``t``), using the analytic stiffness K = -dF/dq of
the model (banded, O(n) per iteration): by default the state on the branch from rest
that a slowly rising load reaches, followed as the load rises from zero (or
:class:`BranchEndError` where that branch ends first), else Newton from a given ``x0``;
the answer is an :class:`Equilibrium`, the state with its stability.

:func:`solve_rotation_controlled` (rotation control) prescribes the angle phi_0
of the loaded particle and solves for every other degree of freedom *and* the
moment M that holds the particle there: F(x) + M e = 0 with x[phi, particle] = phi_0.
Its Jacobian is -K with the loaded angle's column replaced by e, which stays
regular at the fold of the load-controlled problem (where K is singular), so it
follows the moment-rotation characteristic M(phi_0) over a whole turn (its solves:
:mod:`cosserat_chain.linalg.bordered`).

Both raise :class:`NewtonError` if the residual does not fall below the tolerance.
The tolerance is relative to the problem's scale: a requested ``tol`` (times 1 + the
load), but never below :func:`round_off_floor`, the level at which the forces of the
chain can be evaluated at all (it grows with the stiffness, the size of the state
and the number of particles: an absolute 1e-14 is out of reach from about N = 20).
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import scipy.sparse as sp

from ..errors import CosseratChainError
from ..linalg import BandMatrix, infinity_norm, rotation_controlled_jacobian, sparse_solve
from ..loads import Loads
from ..models.base import Model, get_model
from ..params import ChainParams
from ..state import ROW_INDEX, check_state, column, dof, pack, require_held, unpack, zeros
from .kit import Evaluation, newton


class NewtonError(CosseratChainError, RuntimeError):
    """Newton's method did not converge; ``x`` is the last iterate."""

    def __init__(self, message: str, x: np.ndarray):
        super().__init__(message)
        self.x = x


#: Newton is diverging once its residual exceeds the smallest one so far by this factor.
DIVERGED = 1e6
#: Safety factor of :func:`round_off_floor` over the measured floor (about 1e-15 N on the paper's chain).
ROUND_OFF_FACTOR = 1.0


def round_off_floor(stiffness: sp.spmatrix | BandMatrix | None, x: np.ndarray, *, norm: float | None = None) -> float:
    """The smallest residual max |F + L| that can be asked of a state x: eps ||K||_inf max(1, |x|_inf) (2N+1).

    ``x`` is a state (3, 2N+1) or its free degrees of freedom packed (3 (2N-1),).

    The forces of a chain are evaluated to about eps times the stiffness times the
    size of the state per particle, and the residual's round-off grows about linearly
    with the number of particles (measured: 2e-14 at N = 20, 1.3e-12 at N = 1000 on the
    paper's chain); this bound lies 5-10 times above those. ``norm``: ||K||_inf if known
    (``stiffness`` is then not read).
    """
    norm = infinity_norm(stiffness) if norm is None else norm
    return ROUND_OFF_FACTOR * np.finfo(float).eps * norm * max(1.0, float(np.max(np.abs(x)))) * (x.size / 3 + 2)


class BranchEndError(NewtonError):
    """The stable branch from rest ends before the requested load: no state a slowly rising load reaches holds it.

    ``x`` is the last state followed (at ``load_factor`` times the load), ``index`` the
    number of negative eigenvalues of K there.
    """

    def __init__(self, message: str, x: np.ndarray, load_factor: float):
        super().__init__(message, x)
        self.load_factor = load_factor


class Equilibrium(np.ndarray):
    """A static state (3, 2N+1) that says how it was found and how stable it is (:func:`solve_equilibrium`).

    An array like any state (``x[2, N]`` is phi_0), with the attributes

    stability : Stability
        :func:`~cosserat_chain.numerics.stability.static_stability` of the state: ``index``
        (negative eigenvalues of K) and K's verdict.
    from_rest : bool
        True where the state was followed from rest as the load rose from zero (the state a
        slowly loaded chain reaches); False where Newton started from a given ``x0``, whose
        answer may lie on any branch.
    load_steps : int
        Load steps of that following (0 from a given start).

    and, computed when first asked (an eigenvalue problem of twice the size: seconds at N = 100),
    ``dynamic``, the damped dynamics' verdict for a non-conservative model. Arrays computed from
    it (sums, copies, slices) are plain: the attributes describe this state only.
    """

    stability = None
    from_rest = False
    load_steps = 0
    _system = None
    _dynamic = None

    def __new__(cls, x: np.ndarray, system: tuple[ChainParams, Model], stability, from_rest: bool, load_steps: int):
        out = np.asarray(x, dtype=float).view(cls)
        out._system, out.stability, out.from_rest, out.load_steps = system, stability, from_rest, load_steps
        return out

    def __array_finalize__(self, obj) -> None:
        """Views keep the class defaults (no verdict): a slice is not the state that was classified."""

    def __array_wrap__(self, array, context=None, return_scalar=False):
        """Results of ufuncs are plain arrays (a perturbed state is not the classified one)."""
        out = np.asarray(array).view(np.ndarray)
        return out[()] if return_scalar else out

    def __reduce__(self):
        """Pickled (multiprocessing, Dask) as the plain state."""
        return np.asarray(self).view(np.ndarray).__reduce__()

    def _classified(self) -> tuple[ChainParams, Model]:
        """The chain and model this state was classified for; AttributeError on a copy or slice (no verdict)."""
        if self._system is None:
            raise AttributeError("a copy or slice of an Equilibrium carries no stability: ask the solved state itself")
        return self._system

    @property
    def index(self) -> int:
        """Negative eigenvalues of K at the state (0: a minimum of the energy for a conservative model)."""
        self._classified()
        return self.stability.index

    @property
    def dynamic(self):
        """:func:`~cosserat_chain.numerics.stability.dynamic_stability` of the state for a non-conservative model
        (eq. (2): K's inertia is not its dynamics' stability), None for a conservative one; computed once, when asked."""
        params, model = self._classified()
        if model.conservative:
            return None
        if self._dynamic is None:
            from .stability import dynamic_stability  # see _classified

            self._dynamic = dynamic_stability(params, model, np.asarray(self))
        return self._dynamic

    @property
    def stable(self) -> bool:
        """Stable: K positive definite (for eq. (2) this implies decaying dynamics, :mod:`.stability`); where it is
        not, a non-conservative model's dynamics decide (:attr:`dynamic`)."""
        conservative = self._classified()[1].conservative
        if self.stability.stable or conservative:
            return self.stability.stable
        return self.dynamic.stable


#: Largest change of any particle's angle in one load step of :func:`solve_equilibrium` (rad),
#: predicted along the branch's tangent: the tangent resolves the branch over such a step.
LOAD_PHI_STEP = 0.1
#: A load step whose Newton correction exceeds this fraction of its predicted move left the branch.
LOAD_CORRECTION = 0.5
#: Smallest load step (a fraction of the load) before the branch is declared ended.
MIN_LOAD_STEP = 1e-9
#: Most load steps of one following.
MAX_LOAD_STEPS = 20000
#: Newton iterations of one load step.
STEP_ITERATIONS = 8


def solve_equilibrium(
    params: ChainParams,
    model: str | Model,
    loads: Loads,
    *,
    x0: np.ndarray | None = None,
    t: float = 0.0,
    tol: float = 1e-12,
    max_iter: int = 50,
) -> Equilibrium:
    """The static state (3, 2N+1) under the loads at time ``t``: by default the one a slowly rising load reaches.

    Without ``x0`` the state is followed from rest as the loads rise from zero to their value
    (F(x) + lambda L = 0, lambda from 0 to 1): each load step predicts along the branch's tangent
    dx/dlambda = K^-1 L (no angle turning by more than :data:`LOAD_PHI_STEP`), corrects by Newton,
    and is taken only where the correction stays below :data:`LOAD_CORRECTION` of the predicted
    move and the number of negative eigenvalues of K is the rest state's; otherwise it is
    halved. Newton from rest with full steps, as before, converged from N of about 10-20 on to
    far-away wound states (N = 30, M = 0.1: phi_0 = 90.9 rad with 35 negative eigenvalues where
    the branch from rest has phi_0 = 0.951, stable). Where the stable branch ends first (K turns
    singular: a fold, beyond which M cannot rise, or a branch point) a :class:`BranchEndError`
    says at which fraction of the load.

    With ``x0``, Newton's method starts there (full steps): the answer may lie on any branch, and says so (``from_rest`` False).

    Parameters
    ----------
    params : ChainParams
    model : str or Model
    loads : Loads
        Constant in the solve: their values at ``t``.
    x0 : ndarray (3, 2N+1), optional
        A start of the caller's own.
    t : float
    tol : float
        Stop when max |F + L| <= max(tol (1 + max |L|), :func:`round_off_floor`).
    max_iter : int
        Newton iterations from ``x0`` (each load step takes :data:`STEP_ITERATIONS` at most).

    Returns
    -------
    Equilibrium
        The state, an array (3, 2N+1) with its stability (``index``, ``stable``; the damped
        dynamics' verdict ``dynamic`` for a non-conservative model) and ``from_rest``.

    Raises
    ------
    BranchEndError
        Without ``x0``: the stable branch from rest ends before the load (its ``load_factor``).
    NewtonError
        If the residual is still above the tolerance after ``max_iter`` iterations (from ``x0``).
    ValueError
        For a chain that can move rigidly (:func:`~cosserat_chain.state.require_held`), an ``x0`` of the wrong shape,
        or, without ``x0``, a stiffness at rest that is singular (E2 = 0 in the linear and sine models).
    """
    model = get_model(model)
    require_held(params)
    load = loads.as_array(params, t)
    if x0 is not None:
        x = _newton(params, model, check_state(params, x0, "x0").copy(), load, tol, max_iter)
        if x is None:
            raise NewtonError(f"Newton from x0 did not converge in {max_iter} iterations", check_state(params, x0, "x0"))
        return _classified(params, model, x, from_rest=False, load_steps=0)
    return _follow_from_rest(params, model, load, tol)


def _newton(params: ChainParams, model: Model, x: np.ndarray, load: np.ndarray, tol: float, max_iter: int) -> np.ndarray | None:
    """Newton's method for F(x) + load = 0 from ``x`` with full steps (the kit's corrector, at most
    ``max_iter`` evaluations); None if it does not converge."""
    scale = 1.0 + np.max(np.abs(load))
    shape = x.shape

    def evaluate(w: np.ndarray, jacobian: bool) -> Evaluation:
        state = w.reshape(shape)
        return Evaluation(pack(params, model.compiled_forces(params, state) + load), lambda: model.stiffness(params, state), state)

    def converged(ev: Evaluation, norm: float) -> bool:
        return norm <= max(tol * scale, round_off_floor(ev.matrix(), ev.data))

    def step(w: np.ndarray, ev: Evaluation, jacobian) -> np.ndarray:
        # The step of the free degrees of freedom, added to the whole state (the held ones stay as they are).
        return unpack(params, sparse_solve(jacobian, ev.residual)).ravel()

    corrected = newton(evaluate, x.ravel(), converged=converged, newton_step=step, max_iterations=max_iter - 1, divergence=None)
    return corrected.w.reshape(shape) if corrected.converged else None


def _classified(params: ChainParams, model: Model, x: np.ndarray, *, from_rest: bool, load_steps: int, stability=None) -> Equilibrium:
    """``x`` with its stability (:class:`Equilibrium`)."""
    # The stability floor builds on this module's norms: imported here, where a state is classified.
    from .stability import static_stability

    stability = static_stability(params, model, x) if stability is None else stability
    return Equilibrium(x, (params, model), stability, from_rest, load_steps)


def _follow_from_rest(params: ChainParams, model: Model, load: np.ndarray, tol: float) -> Equilibrium:
    """The state on the branch from rest at ``load`` (:func:`solve_equilibrium` without a start)."""
    from .stability import static_stability

    x = zeros(params)
    lam, steps = 0.0, 0
    target = pack(params, load)
    phi = ROW_INDEX["phi"]

    def tangent_at(x: np.ndarray) -> np.ndarray:
        return unpack(params, sparse_solve(model.stiffness(params, x), target))

    try:
        check = static_stability(params, model, x)
        tangent = tangent_at(x)
    except np.linalg.LinAlgError:
        tangent = None
    if tangent is None or not np.all(np.isfinite(tangent)):
        # E2 = 0 leaves v without stiffness (k_v = 0): the linear and sine models' K is singular at every state.
        raise ValueError(
            f"the {model.name} model's stiffness K at rest is singular for this chain (E2={params.E2!r}, E1={params.E1!r}, "
            f"b={params.b!r}; E2 = 0 leaves the transverse displacements v without stiffness): no static state follows "
            "from rest under the loads; give x0 to solve from a start of your own"
        )

    def largest_step(tangent: np.ndarray) -> float:
        """The load step over which the tangent turns no angle by more than LOAD_PHI_STEP (1 for a model of small rotations)."""
        if not model.rotates:
            return 1.0
        turn = float(np.max(np.abs(tangent[phi])))
        return LOAD_PHI_STEP / turn if turn > 0.0 else 1.0

    step = min(1.0, largest_step(tangent))
    while lam < 1.0:
        if steps >= MAX_LOAD_STEPS or step < MIN_LOAD_STEP:
            reason = f"{MAX_LOAD_STEPS} load steps" if steps >= MAX_LOAD_STEPS else f"a load step below {MIN_LOAD_STEP:g} of the load"
            raise BranchEndError(
                f"no state on the stable branch from rest holds this load: the branch ends at {lam:.10g} of it "
                f"(K turns singular there: a fold or a branch point; {reason}), where a slowly loaded chain leaves it "
                "(critical_point gives M_c); give x0 to solve from a start of your own",
                x,
                lam,
            )
        size = min(step, 1.0 - lam)
        predicted = x + size * tangent
        found = _newton(params, model, predicted.copy(), (lam + size) * load, tol, STEP_ITERATIONS)
        if found is not None:
            moved = float(np.linalg.norm(predicted - x))
            corrected = float(np.linalg.norm(found - predicted))
            trial = (
                static_stability(params, model, found, guess=check.critical_eigenvalue) if corrected <= LOAD_CORRECTION * moved else None
            )
            if trial is not None and abs(trial.critical_eigenvalue) <= trial.resolution:
                # An eigenvalue within its round-off has no sign (a long clamped chain's softest): the index stays.
                trial = replace(trial, index=check.index, stable=check.stable)
            if trial is not None and trial.index == check.index:
                x, check, lam = found, trial, (1.0 if size == 1.0 - lam else lam + size)
                steps += 1
                tangent = tangent_at(x)
                step = min(2.0 * size, largest_step(tangent))
                continue
        step = 0.5 * size
    return _classified(params, model, x, from_rest=True, load_steps=steps, stability=check)


def moment_dof(params: ChainParams, particle: int = 0) -> int:
    """Index of the angle of ``particle`` among the free degrees of freedom (:func:`~cosserat_chain.state.pack` order).

    Raises
    ------
    ValueError
        If ``particle`` is outside the chain or its angle is held by a clamped end, or if
        the chain can move rigidly (:func:`~cosserat_chain.state.require_held`).
    """
    require_held(params)
    return dof(params, "phi", particle)


def solve_rotation_controlled(
    params: ChainParams,
    model: str | Model,
    phi0: float,
    *,
    particle: int = 0,
    x0: np.ndarray | None = None,
    moment0: float = 0.0,
    tol: float = 1e-12,
    max_iter: int = 50,
) -> tuple[np.ndarray, float]:
    """Equilibrium with the loaded particle's angle held at ``phi0``, and the moment that holds it.

    Parameters
    ----------
    params : ChainParams
    model : str or Model
    phi0 : float
        Prescribed angle of ``particle`` (rad; any real value, not reduced mod 2 pi).
    particle : int
        The loaded particle (default the central one).
    x0 : ndarray (3, 2N+1), optional
        Starting guess (its angle of ``particle`` is replaced by ``phi0``); default rest.
    moment0 : float
        Starting guess for the moment.
    tol : float
        Stop when max |F + M e| <= max(tol (1 + |M|), :func:`round_off_floor`).
    max_iter : int

    Returns
    -------
    x : ndarray (3, 2N+1)
        The equilibrium, with x[phi, particle] = phi0.
    moment : float
        The moment M on ``particle`` that holds it (the characteristic M(phi_0)).

    Raises
    ------
    NewtonError
        If the residual is still above the tolerance after ``max_iter`` iterations.
    """
    model = get_model(model)
    dof = moment_dof(params, particle)
    col = column(params, particle)
    x = zeros(params) if x0 is None else check_state(params, x0, "x0").copy()
    x[ROW_INDEX["phi"], col] = phi0
    shape = x.shape
    smallest = [np.inf]  # the smallest residual so far

    # The kit's corrector on w = (x, M): phi_0 is held, M takes its place among the unknowns
    # (the rotation-controlled Jacobian), and the step of phi_0 is zero. K is assembled only at
    # an iterate that is not diverging (``data``: the state, M, and K once assembled); at one
    # that is, there is no Jacobian, and the corrector stops there.
    def evaluate(w: np.ndarray, jacobian: bool) -> Evaluation:
        state = w[:-1].reshape(shape)
        r = pack(params, model.compiled_forces(params, state))
        r[dof] += w[-1]
        data = [state, w[-1], None]

        def matrix():
            if data[2] is None:
                raise ArithmeticError("diverging: no use going on")
            return rotation_controlled_jacobian(data[2], dof)

        return Evaluation(r, matrix, data)

    def converged(evaluation: Evaluation, residual: float) -> bool:
        smallest[0] = min(smallest[0], residual)
        if not residual <= DIVERGED * (1.0 + smallest[0]):
            return False
        state, moment, _ = evaluation.data
        evaluation.data[2] = stiffness = model.stiffness(params, state)
        return residual <= max(tol * (1.0 + abs(moment)), round_off_floor(stiffness, state))

    def step(w: np.ndarray, evaluation: Evaluation, jacobian) -> np.ndarray:
        solved = sparse_solve(jacobian, -evaluation.residual)
        moment_step = solved[dof]
        solved[dof] = 0.0
        return np.append(unpack(params, solved).ravel(), moment_step)

    w0 = np.append(x.ravel(), float(moment0))
    corrected = newton(evaluate, w0, converged=converged, newton_step=step, max_iterations=max_iter - 1, divergence=None)
    x, moment = corrected.w[:-1].reshape(shape), float(corrected.w[-1])
    if corrected.converged:
        return x, moment
    residual = corrected.norm
    raise NewtonError(
        f"rotation-controlled Newton at phi0={float(phi0)!r} did not converge in {max_iter} iterations (residual {residual:.3g}); "
        "start nearer (a solved neighbouring angle as x0)",
        x,
    )
