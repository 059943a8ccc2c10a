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
follows the moment-rotation characteristic M(phi_0) over a whole turn.

Both raise :class:`NewtonError` if the residual does not fall below the tolerance.
The tolerance is relative to the problem's scale: a requested ``tol`` (times 1 + the
load), but never below :func:`round_off_floor`, the level at which the forces of the
chain can be evaluated at all (it grows with the stiffness, the size of the state
and the number of particles: an absolute 1e-14 is out of reach from about N = 20).
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla
from numba import njit

from ..band import BandMatrix
from ..errors import CosseratChainError
from ..loads import Loads
from ..models.base import Model, get_model
from ..params import ChainParams
from ..state import BANDWIDTH, ROW_INDEX, check_state, column, dof, n_free, pack, require_held, unpack, zeros


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


def infinity_norm(matrix: sp.spmatrix | BandMatrix) -> float:
    """max_i sum_j |A_ij| of a sparse or banded matrix (0 for an empty one), O(nnz).

    A compiled loop over a CSR matrix's data (:func:`_csr_infinity_norm`): scipy's
    ``abs(A).sum(axis=1).max()`` builds two temporaries and cost 0.25 ms at N = 1000,
    and the continuation asks it at every corrector iteration. A
    :class:`~cosserat_chain.band.BandMatrix` keeps its norm once computed.
    """
    if isinstance(matrix, BandMatrix):
        return matrix.infinity_norm
    if not matrix.shape[0]:
        return 0.0
    if sp.issparse(matrix) and matrix.format == "csr":
        return float(_csr_infinity_norm(matrix.indptr, np.asarray(matrix.data, dtype=float)))
    return float(abs(matrix).sum(axis=1).max())


@njit(cache=True, nogil=True)
def _csr_infinity_norm(indptr, data):  # pragma: no cover - compiled
    """The largest absolute row sum of a CSR matrix given by its ``indptr`` and ``data``."""
    largest = 0.0
    for i in range(indptr.size - 1):
        total = 0.0
        for p in range(indptr[i], indptr[i + 1]):
            total += abs(data[p])
        largest = max(largest, total)
    return largest


@njit(cache=True, nogil=True)
def dot(a: np.ndarray, b: np.ndarray) -> float:  # pragma: no cover - compiled
    """a^T b of two vectors, compiled, on this thread, in eight partial sums.

    OpenBLAS's ddot (NumPy's ``a @ b`` and ``np.linalg.norm``) runs on several threads
    from about 10^4 entries on: the continuation's few dot products a corrector iteration
    then woke a second thread that spun between them, doubling the CPU time of the
    statics of N = 10^4 and slowing its wall time by 15 %. Eight partial sums keep the
    additions off one chain of dependences (and the order fixed on every machine).
    """
    partial = np.zeros(8)
    n = a.size
    head = n - n % 8
    for i in range(0, head, 8):
        for j in range(8):
            partial[j] += a[i + j] * b[i + j]
    total = ((partial[0] + partial[1]) + (partial[2] + partial[3])) + ((partial[4] + partial[5]) + (partial[6] + partial[7]))
    for i in range(head, n):
        total += a[i] * b[i]
    return total


def euclidean_norm(a: np.ndarray) -> float:
    """The Euclidean norm of a vector with :func:`dot` (on this thread)."""
    return math.sqrt(dot(a, a))


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
        For a chain that can move rigidly (:func:`~cosserat_chain.state.require_held`), or an ``x0`` of the wrong shape.
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
    """Newton's method for F(x) + load = 0 from ``x`` with full steps; None if it does not converge."""
    scale = 1.0 + np.max(np.abs(load))
    for _ in range(max_iter):
        r = pack(params, model.compiled_forces(params, x) + load)
        residual = float(np.max(np.abs(r))) if n_free(params) else 0.0
        if not np.isfinite(residual):
            return None
        stiffness = model.stiffness(params, x)
        if residual <= max(tol * scale, round_off_floor(stiffness, x)):
            return x
        x = x + unpack(params, sparse_solve(stiffness, r))
    return None


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
    check = static_stability(params, model, x)
    lam, steps = 0.0, 0
    target = pack(params, load)
    phi = ROW_INDEX["phi"]

    def tangent_at(x: np.ndarray) -> np.ndarray:
        return unpack(params, sparse_solve(model.stiffness(params, x), target))

    def largest_step(tangent: np.ndarray) -> float:
        """The load step over which the tangent turns no angle by more than LOAD_PHI_STEP (1 for a model of small rotations)."""
        if not model.rotates:
            return 1.0
        turn = float(np.max(np.abs(tangent[phi])))
        return LOAD_PHI_STEP / turn if turn > 0.0 else 1.0

    tangent = tangent_at(x)
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


def rotation_controlled_jacobian(stiffness: sp.spmatrix, dof: int) -> sp.csc_matrix:
    """d/d(q without q[dof], M) of F(q) + M e_dof: -K with column ``dof`` replaced by e_dof (O(nnz))."""
    jac = (-stiffness).tocsc()
    first, last = jac.indptr[dof], jac.indptr[dof + 1]
    data = np.concatenate([jac.data[:first], [1.0], jac.data[last:]])
    indices = np.concatenate([jac.indices[:first], [dof], jac.indices[last:]]).astype(jac.indices.dtype)
    indptr = jac.indptr.copy()
    indptr[dof + 1 :] -= last - first - 1
    return sp.csc_matrix((data, indices, indptr), shape=jac.shape)


def bordered_jacobian(stiffness: sp.spmatrix, dof: int, row: np.ndarray) -> sp.csc_matrix:
    """The pseudo-arclength matrix [[-K, e_dof], [row^T]] of the unknowns (q, M), square, O(nnz).

    Every column of -K gains its entry of the dense last row at its end (row index
    n, the largest), and the last column holds e_dof and row[n].
    """
    jac = (-stiffness).tocsc()
    jac.sort_indices()
    n = jac.shape[0]
    data = np.insert(jac.data, jac.indptr[1:], row[:n])
    indices = np.insert(jac.indices, jac.indptr[1:], n)
    indptr = np.concatenate([jac.indptr + np.arange(n + 1), [jac.indptr[-1] + n + 2]])
    data = np.concatenate([data, [1.0, row[n]]])
    indices = np.concatenate([indices, [dof, n]])
    return sp.csc_matrix((data, indices.astype(np.int32), indptr.astype(np.int32)), shape=(n + 1, n + 1))


@njit(cache=True, nogil=True)
def _band_factor(stiffness):  # pragma: no cover - compiled
    """LU without pivoting of -K for K in band storage (:class:`~cosserat_chain.band.BandMatrix`); (band, inverse, ok).

    ``band[i, j - i + BANDWIDTH]`` holds U on and above the diagonal and L's multipliers
    below it, ``inverse`` the reciprocals of U's diagonal (the solves multiply: a division
    on the substitutions' chain of dependences took half their time); ``ok`` is False on
    a zero pivot. Gaussian elimination in the natural order with diagonal pivots, like
    SuperLU with ``diag_pivot_thresh=0`` (:func:`sparse_solve`): the fill stays in the
    band, O(n w^2). The storage has :data:`~cosserat_chain.state.BANDWIDTH` zero rows
    after the last (as K's storage has), read by :func:`_band_column`.

    Row by row (Doolittle): entry (r, c) is -K[r, c] minus L[r, j] U[j, c] over the pivots
    j before both, in increasing j, as the right-looking elimination subtracted them (the
    same factor bit for bit), each row's terms read from rows already final. The sums have
    the band's constant lengths outside the first B rows (the loops unroll), and -K is
    read from K's storage as it goes: the copy of -K and the second copy to eliminate in
    were half the factor's time (133 -> 67 us at N = 1000).
    """
    n = stiffness.shape[0] - 2 * BANDWIDTH
    band = np.empty((n + BANDWIDTH, 2 * BANDWIDTH + 1))
    band[n:, :] = 0.0
    inverse = np.zeros(n)
    for r in range(n):
        k = r + BANDWIDTH  # K's row in its storage
        if r >= BANDWIDTH:
            for o in range(-BANDWIDTH, 0):  # L[r, r + o], from the B + o pivots before column r + o
                total = -stiffness[k, BANDWIDTH + o]
                for m in range(BANDWIDTH + o):
                    total -= band[r, m] * band[r - BANDWIDTH + m, 2 * BANDWIDTH + o - m]
                band[r, BANDWIDTH + o] = total * inverse[r + o]
            for o in range(BANDWIDTH + 1):  # U[r, r + o], from the B - o pivots before row r
                total = -stiffness[k, BANDWIDTH + o]
                for m in range(BANDWIDTH - o):
                    total -= band[r, o + m] * band[r + o - BANDWIDTH + m, 2 * BANDWIDTH - m]
                band[r, BANDWIDTH + o] = total
        else:  # the first rows: the pivots before are fewer than the band
            for o in range(-BANDWIDTH, BANDWIDTH + 1):
                c = r + o
                if c < 0:
                    band[r, BANDWIDTH + o] = 0.0
                    continue
                total = -stiffness[k, BANDWIDTH + o]
                for j in range(max(max(r, c) - BANDWIDTH, 0), min(r, c)):
                    total -= band[r, BANDWIDTH + j - r] * band[j, BANDWIDTH + c - j]
                band[r, BANDWIDTH + o] = total * inverse[c] if o < 0 else total
        pivot = band[r, BANDWIDTH]
        if pivot == 0.0:
            return band, inverse, False
        inverse[r] = 1.0 / pivot
    return band, inverse, True


@njit(cache=True, nogil=True)
def _band_column(band, dof):  # pragma: no cover - compiled
    """L^-1 e_dof with -K's band LU (:func:`_band_factor`): the eliminated last column of the bordered matrix."""
    n = band.shape[0] - BANDWIDTH
    last_column = np.zeros(n + BANDWIDTH)
    last_column[dof] = 1.0
    for j in range(dof, n):  # zero above dof
        for i in range(1, BANDWIDTH + 1):
            last_column[j + i] -= band[j + i, BANDWIDTH - i] * last_column[j]
    return last_column


@njit(cache=True, nogil=True)
def _band_row(band, inverse, last_column, row):  # pragma: no cover - compiled
    """The eliminated last row (U^T l = row) and corner (row[n] - l . L^-1 e_dof) of the bordered matrix."""
    n = band.shape[0] - BANDWIDTH
    last_row = np.zeros(n + BANDWIDTH)
    last_row[:n] = row[:n]
    corner = row[n]
    for j in range(n):
        factor = last_row[j] * inverse[j]
        last_row[j] = factor
        for t in range(1, BANDWIDTH + 1):
            last_row[j + t] -= factor * band[j, BANDWIDTH + t]
        corner -= factor * last_column[j]
    return last_row, corner


@njit(cache=True, nogil=True)
def _band_border_solve(band, inverse, stiffness, last_column, last_row, corner, dof, row, rhs, refine):  # pragma: no cover - compiled
    """Solve [[-K, e_dof], [row^T]] x = rhs with -K's band LU (:func:`_band_factor`) and its border.

    The border (:func:`_band_column`, :func:`_band_row`) costs O(n w) on top of the
    factor; together they are the elimination of the whole bordered matrix without
    pivoting. ``refine`` steps of iterative refinement with the same factor follow. Both
    substitutions go row by row and carry the last B unknowns solved in registers
    (B = :data:`~cosserat_chain.state.BANDWIDTH` = 5), subtracting the term of the one
    solved last at the end: only one multiply-add a row waits for it, and none waits on a
    store and its reload (a solve 52 -> 37 us at N = 1000). The forward one adds its terms
    in the order of the column sweep it replaced, so the solution is the same bit for bit.
    """
    n = band.shape[0] - BANDWIDTH
    solution = np.zeros(n + 1)
    residual = rhs.copy()
    y = np.zeros(n)
    padded = np.zeros(n + 2 * BANDWIDTH if refine else 0)  # the solution with BANDWIDTH zeros either side
    for sweep in range(refine + 1):
        border = residual[n]
        y1 = y2 = y3 = y4 = y5 = 0.0
        for i in range(n):  # L y = b
            total = residual[i] - band[i, 0] * y5
            total -= band[i, 1] * y4
            total -= band[i, 2] * y3
            total -= band[i, 3] * y2
            total -= band[i, 4] * y1
            y[i] = total
            border -= last_row[i] * total
            y5, y4, y3, y2, y1 = y4, y3, y2, y1, total
        border /= corner
        x1 = x2 = x3 = x4 = x5 = 0.0
        for j in range(n - 1, -1, -1):  # U x = y
            total = y[j] - last_column[j] * border - band[j, 10] * x5
            total -= band[j, 9] * x4
            total -= band[j, 8] * x3
            total -= band[j, 7] * x2
            value = (total - band[j, 6] * x1) * inverse[j]
            solution[j] += value
            x5, x4, x3, x2, x1 = x4, x3, x2, x1, value
        solution[n] += border
        if sweep == refine:
            break
        # residual = rhs - B solution, with the matrix as given (``stiffness``: K's storage)
        padded[BANDWIDTH : n + BANDWIDTH] = solution[:n]
        for i in range(n):
            total = rhs[i] - (solution[n] if i == dof else 0.0)
            for t in range(2 * BANDWIDTH + 1):
                total += stiffness[i + BANDWIDTH, t] * padded[i + t]
            residual[i] = total
        total = rhs[n] - row[n] * solution[n]
        for k in range(n):
            total -= row[k] * solution[k]
        residual[n] = total
    return solution


class BorderedFactor:
    """The factor of -K for solving [[-K, e_dof], [row^T]] x = rhs with any border row, O(N) a solve.

    The O(n w^2) elimination of the band is done once (:func:`_band_factor`); each
    :meth:`solve` adds its row's border in O(n w) (:func:`_band_border_solve`), one step
    of refinement, and falls back to :func:`sparse_solve` of :func:`bordered_jacobian`
    at a zero pivot or a non-finite result. The continuation's tangent at a point and
    the chord corrector of the next step share one factor this way.
    """

    def __init__(self, stiffness: sp.spmatrix | BandMatrix, dof: int):
        if not isinstance(stiffness, BandMatrix) and not (sp.issparse(stiffness) and stiffness.format == "csr"):
            stiffness = sp.csr_matrix(stiffness)
        self.stiffness, self.dof = stiffness, dof
        try:
            band = stiffness if isinstance(stiffness, BandMatrix) else BandMatrix.from_sparse(stiffness)
        except ValueError:  # wider than the band (a ring's corner blocks): the sparse solver
            self._ok = False
        else:
            self._stiffness_data = band.data
            self._band, self._inverse, self._ok = _band_factor(band.data)
        self._column = _band_column(self._band, dof) if self._ok else None
        self._row: tuple[np.ndarray, np.ndarray, float] | None = None  # the last border row and its elimination

    @property
    def negative_eigenvalues(self) -> int | None:
        """The number of negative eigenvalues of a symmetric K, from the inertia of its factor; None without one.

        The LU of -K without pivoting is -K = L U with U = -D L^T for K = L D L^T, so
        (Sylvester's law of inertia) K has as many negative eigenvalues as U has positive
        pivots: free where the factor is made anyway (a continuation's tangent). Meaningless
        for a non-symmetric K.
        """
        return int(np.count_nonzero(self._inverse > 0.0)) if self._ok else None

    def solve(self, row: np.ndarray, rhs: np.ndarray, *, refine: int = 1) -> np.ndarray:
        """x with [[-K, e_dof], [row^T]] x = rhs; ``row`` and ``rhs`` of length n_free + 1.

        ``refine``: steps of iterative refinement (a chord corrector's inexact steps need none).
        The last row's elimination is kept for the next solve with the same row.
        """
        out = None
        row = np.asarray(row, float)
        if self._ok:
            if self._row is None or not (self._row[0] is row or np.array_equal(self._row[0], row)):
                self._row = (row.copy(), *_band_row(self._band, self._inverse, self._column, row))
            _, last_row, corner = self._row
            if corner != 0.0:
                out = _band_border_solve(
                    self._band,
                    self._inverse,
                    self._stiffness_data,
                    self._column,
                    last_row,
                    corner,
                    self.dof,
                    row,
                    np.asarray(rhs, float),
                    refine,
                )
        if out is None or not np.all(np.isfinite(out)):
            k = self.stiffness.tocsr() if isinstance(self.stiffness, BandMatrix) else self.stiffness
            return sparse_solve(bordered_jacobian(k, self.dof, row), rhs)
        return out


def bordered_solve(stiffness: sp.spmatrix, dof: int, row: np.ndarray, rhs: np.ndarray) -> np.ndarray:
    """Solve the pseudo-arclength system [[-K, e_dof], [row^T]] x = rhs in O(N).

    Compiled banded elimination with one step of refinement (:class:`BorderedFactor`:
    0.6 ms at N = 1000 against 6.9 ms for SuperLU on the same elimination); a zero pivot or
    a non-finite result falls back to :func:`sparse_solve` of :func:`bordered_jacobian`.
    """
    return BorderedFactor(stiffness, dof).solve(row, rhs)


def sparse_solve(matrix: sp.spmatrix, rhs: np.ndarray) -> np.ndarray:
    """Solve a banded system, or one bordered by a dense last row and column, in O(N).

    In the natural order and with diagonal pivots the fill stays in the band and the
    dense last row; SuperLU's default pivoting moved it up and filled the factor (0.7 s
    a bordered solve at N = 1000 against 4 ms). One step of refinement with the same
    factor recovers what the diagonal pivots lose; a factorisation that fails (a zero
    pivot) or gives a non-finite result falls back to the default pivoting.
    """
    matrix = sp.csc_matrix(matrix)
    try:
        lu = spla.splu(matrix, permc_spec="NATURAL", diag_pivot_thresh=0.0)
        out = lu.solve(rhs)
        out = out + lu.solve(rhs - matrix @ out)
    except RuntimeError:
        return spla.spsolve(matrix, rhs)
    return out if np.all(np.isfinite(out)) else spla.spsolve(matrix, rhs)


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
    moment = float(moment0)
    residual = first = np.inf
    for _ in range(max_iter):
        r = pack(params, model.compiled_forces(params, x))
        r[dof] += moment
        residual = float(np.max(np.abs(r)))
        first = min(first, residual)
        if not residual <= DIVERGED * (1.0 + first):
            break  # diverging (or not finite): no use going on
        stiffness = model.stiffness(params, x)
        if residual <= max(tol * (1.0 + abs(moment)), round_off_floor(stiffness, x)):
            return x, moment
        step = sparse_solve(rotation_controlled_jacobian(stiffness, dof), -r)
        moment += step[dof]
        step[dof] = 0.0
        x = x + unpack(params, step)
    raise NewtonError(
        f"rotation-controlled Newton at phi0={float(phi0)!r} did not converge in {max_iter} iterations (residual {residual:.3g}); "
        "start nearer (a solved neighbouring angle as x0)",
        x,
    )
