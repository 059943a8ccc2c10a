"""Stability of static states: the Hessian for conservative models, the damped dynamics otherwise.

Contract
--------
:func:`static_stability` classifies an equilibrium x of the loaded chain.

* Conservative models (nonlinear, linear): x is a minimum of the total energy iff
  the stiffness K = -dF/dq (the Hessian) is positive definite; the *critical
  eigenvalue* is its smallest eigenvalue.
* The sine model (eq. 2) has no energy. Its stiffness K is not symmetric, and x is
  stable iff every eigenvalue of the damped dynamics linearised about x,

      d/dt (q, v) = A (q, v),   A = [[0, I], [-M^-1 K, -M^-1 Gamma]],

  has a negative real part. The critical eigenvalue is then the real part of
  the eigenvalue of K nearest the imaginary axis from the right: it is the one
  that crosses zero at a fold, for every model alike.

Without dense matrices (the default at every size): the critical eigenvalue is the
smallest eigenvalue of the model's symmetric banded matrix similar to K
(:meth:`~cosserat_chain.models.base.Model.symmetric_similar`), found by inverse
iteration with banded LDL^T factors and certified by their inertia (Sylvester's law:
the negative pivots count the eigenvalues below a shift, O(N) a factor; bisection on
that count is the fallback; LAPACK's banded eigensolver is O(N^2): 0.5 s at N = 1000),
and the state is stable iff it is positive; the index is that count at zero. For a
conservative model with positive damping the damped dynamics decays iff K is
positive definite. For eq. (2), K = S C with S the linear model's (positive
definite) and C = diag(1, 1, cos phi): if every cos phi > 0, C M, C Gamma and C S C
are positive definite and the energy 1/2 q'^T C M q' + 1/2 q^T C S C q of
C M q'' + C Gamma q' + C S C q = 0 decays; a particle beyond pi/2 gives K a negative
eigenvalue (Sylvester's law of inertia) and a growing mode (checked against the dense
reference on random chains). The spectral abscissa is then not computed (NaN).
``dense=True`` runs the dense reference (O(N^3)): eigenvalues of K and of the damped
dynamics matrix A; a model without a symmetric similar matrix always takes it.

:func:`dynamic_stability` decides from the eigenvalues of the damped first-order system
themselves, for every model, and reports K's inertia beside them as what it is (the
*stiffness index*). With mass-scaled unknowns y = M^(1/2) q, w = M^(1/2) q' the system
d/dt (x, p) = (M^-1 p, F(x) - Gamma M^-1 p) linearised about x is

    d/dt (y, w) = A (y, w),   A = [[0, I], [-M^(-1/2) K M^(-1/2), -Gamma M^-1]],

similar to its Jacobian [[0, M^-1], [-K, -Gamma M^-1]] in (x, p) (the same eigenvalues,
better balanced: j is 40 times smaller than m in the paper's chain). For a conservative
model with positive damping the number of its unstable eigenvalues equals K's negative
count (a theorem the tests check against the dense eigenvalues); for eq. (2) it does not:
the sine chain's unstable branch at N = 2 has one real and one complex pair of unstable
eigenvalues where K has one negative eigenvalue, the pair crossing the axis at two Hopf
points (:mod:`cosserat_chain.numerics.hopf`).

Without a dense matrix (``method="sparse"``) the unstable eigenvalues are counted by the
argument principle (:func:`_unstable_count`): the phase of det(A - z I) = det(K~ + z R + z^2 I),
one banded LU a point, followed round a curve enclosing the right half plane's part of the
spectrum; the eigenvalues nearest the axis are found by shift-invert (ARPACK, each product
one banded solve: (A - s I) reduces to the n x n banded K~ + s (R + s I) by its Schur
complement). Cayley transforms with ARPACK's largest |mu| were tried first and did not
converge at N = 100: the slow overdamped modes crowd the unit circle.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from functools import lru_cache

import numpy as np
import scipy.linalg as la
import scipy.sparse as sp
import scipy.sparse.linalg as sla
from numba import njit

from ..band import BandMatrix
from ..models.base import Model, get_model
from ..params import ChainParams
from ..state import BANDWIDTH, check_state, pack, per_dof
from .newton import euclidean_norm, infinity_norm

#: Relative width (to the Gershgorin radius) at which the bisection for the smallest eigenvalue stops.
BISECTION_RTOL = 1e-14
#: Inverse-iteration steps with one factor before the shift moves (each an O(n w) solve).
INVERSE_STEPS = 12


@dataclass(frozen=True)
class Stability:
    """Stability of one static state.

    Attributes
    ----------
    stable : bool
    critical_eigenvalue : float
        Smallest eigenvalue of K (real part for a non-symmetric K); it vanishes at a fold.
    spectral_abscissa : float
        Largest real part of the eigenvalues of the linearised damped dynamics
        (< 0: perturbations decay); NaN where the banded path decided (module docstring).
    index : int
        Number of eigenvalues of K with a negative real part (the Morse index for a
        conservative model): it changes by one at every fold, also between two
        unstable states.
    resolution : float
        Round-off of ``critical_eigenvalue``: BISECTION_RTOL times K's Gershgorin
        radius. A long clamped chain's softest eigenvalue falls below it (it shrinks
        like N^-4: N = 10^4), and its value is then noise.
    """

    stable: bool
    critical_eigenvalue: float
    spectral_abscissa: float
    index: int = 0
    resolution: float = 0.0


def damped_dynamics_matrix(params: ChainParams, stiffness: np.ndarray) -> np.ndarray:
    """The matrix A of the damped dynamics linearised about a static state, shape (2 n_free, 2 n_free).

    Parameters
    ----------
    stiffness : ndarray (n_free, n_free)
        K = -dF/dq at the state (dense).
    """
    n_free = stiffness.shape[0]
    inertia = pack(params, params.particle_inertia)
    damping = per_dof(params, params.damping)
    a = np.zeros((2 * n_free, 2 * n_free))
    a[:n_free, n_free:] = np.eye(n_free)
    a[n_free:, :n_free] = -stiffness / inertia[:, None]
    a[n_free:, n_free:] = -np.diag(damping / inertia)
    return a


def static_stability(
    params: ChainParams,
    model: str | Model,
    x: np.ndarray,
    *,
    dense: bool = False,
    guess: float | None = None,
    similar: sp.spmatrix | BandMatrix | None = None,
    start: np.ndarray | None = None,
    index: int | None = None,
) -> Stability:
    """Stability of the static state ``x`` (3, 2N+1) of ``model`` (see the module docstring).

    For a state with zero damping, purely oscillatory perturbations count as
    stable (spectral abscissa at round-off level). ``dense=True`` runs the dense
    reference instead of the banded path (module docstring). ``guess``: a nearby
    value of the critical eigenvalue (the previous point's along a branch), where the
    banded search starts; it changes the cost, not the result.

    ``similar``: :meth:`~cosserat_chain.models.base.Model.symmetric_similar` at ``x``
    if the caller has it already (a conservative model's stiffness, which a continuation
    assembles at every point anyway: a second assembly was a fifth of the cost of a
    point at N = 1000); it changes the cost, not the result. Ignored with ``dense``
    and for a ring.

    ``start``: a work vector of length n_free where inverse iteration starts and which
    it leaves holding its last iterate, the approximate lowest eigenvector (a
    continuation passes the same one from point to point: the previous point's
    eigenvector is a close start: 1.1 ms a point instead of 2.0 ms from the fixed random
    vector over the turn of N = 1000); it changes the cost, not the result
    beyond the round-off of the certified eigenvalue. Ignored on the dense path.

    The index costs no factor of its own where the smallest eigenvalue is certified
    positive above its round-off (the certificate is a factor at a shift below it with
    no negative pivot, so K itself has none): only an unstable or marginal state pays
    the count at zero, and not even that where the caller gives ``index``, the
    number of negative eigenvalues of ``similar`` it has counted from a factor of that
    matrix at zero (a continuation's tangent solve factors the stiffness at every point:
    :attr:`~.newton.BorderedFactor.negative_eigenvalues`). A factor in another order of
    operations could count differently only where a pivot lies within round-off of zero.
    Ignored without ``similar``.
    """
    model = get_model(model)
    x = check_state(params, x)
    # A ring's matrices have corner blocks (not banded): the dense path, at the sizes a ring's statics reach.
    if dense or params.periodic:
        similar = None
    counted = index if similar is not None else None  # a count of the caller's matrix only
    if similar is None and not (dense or params.periodic):
        similar = model.symmetric_similar(params, x)
    if similar is not None:
        band = _band_storage(similar)
        resolution = _resolution(similar)
        critical, bound = _smallest_eigenvalue(band, resolution / BISECTION_RTOL, guess, start)
        if bound > resolution:
            index = 0
        else:
            index = negative_count(band, 0.0) if counted is None else counted
        return Stability(index == 0 and critical > 0.0, critical, math.nan, index, resolution)
    k = model.stiffness(params, x).toarray()
    abscissa = float(np.max(la.eigvals(damped_dynamics_matrix(params, k)).real))
    if model.conservative:
        eigenvalues = la.eigvalsh(k)
        return Stability(bool(eigenvalues[0] > 0.0), float(eigenvalues[0]), abscissa, int(np.sum(eigenvalues < 0)), _resolution(k))
    # Round-off of the eigenvalue solver, relative to the fastest rate of the chain.
    round_off = 1e-10 * max(1.0, float(np.max(np.abs(k))))
    real = la.eigvals(k).real
    return Stability(abscissa < round_off, float(np.min(real)), abscissa, int(np.sum(real < 0)), _resolution(k))


def smallest_eigenvalue(matrix: sp.spmatrix | BandMatrix) -> tuple[float, float]:
    """The smallest eigenvalue of a symmetric matrix within the chain's band, and its round-off, O(n) a factor.

    Inverse iteration certified by the inertia of banded LDL^T factors, with bisection
    on that count as the fallback (:func:`_smallest_eigenvalue`): where the lowest
    eigenvalues crowd (the edge of a band of a long chain's spectrum), Krylov methods
    slow down with n and this does not.

    Raises
    ------
    ValueError
        If the matrix is wider than the band.
    """
    band = _band_storage(matrix)
    resolution = _resolution(matrix)
    value, _ = _smallest_eigenvalue(band, resolution / BISECTION_RTOL)
    return value, resolution


def _resolution(matrix) -> float:
    """BISECTION_RTOL times the Gershgorin radius of ``matrix`` (sparse, banded or dense)."""
    if sp.issparse(matrix) or isinstance(matrix, BandMatrix):
        return BISECTION_RTOL * infinity_norm(matrix)
    return BISECTION_RTOL * float(abs(matrix).sum(axis=1).max()) if matrix.shape[0] else 0.0


def _band_storage(matrix: sp.spmatrix | BandMatrix) -> np.ndarray:
    """The padded band storage (:class:`~cosserat_chain.band.BandMatrix`) the compiled LDL^T reads.

    Its upper triangle is read (a Hessian summed link by link is symmetric only to round-off:
    one triangle is read, as LAPACK's upper storage reads it, and either gives the same
    inertia), in place: a copy by rows of the lower band cost 55 us at N = 1000, once a point
    of a branch. A sparse matrix goes through its band.

    Raises
    ------
    ValueError
        If the matrix is wider than the band (a ring's corner blocks).
    """
    return (matrix if isinstance(matrix, BandMatrix) else BandMatrix.from_sparse(matrix)).data


@njit(cache=True, nogil=True)
def _factor(band, shift, factor, inverse):  # pragma: no cover - compiled
    """LDL^T of M - shift I without pivoting into ``factor`` (factor[r, d] = L[i, i - d], r = B + i) and ``inverse`` (1 / D).

    Returns the number of negative pivots: by Sylvester's law of inertia the number
    of eigenvalues below ``shift``, in O(n w^2) (a zero pivot is nudged by the round-off).
    ``band`` is the padded storage (:func:`_band_storage`) and M[i, i - d] is read from its
    upper triangle, M[i - d, i] = band[r - d, B + d]; the padding's rows factor as the identity.

    A row's entries are formed as w_d = L[i, i - d] D[i - d] first, each from the ones
    before it, and L's entry is w_d times the reciprocal pivot: the chain of dependences
    along a row holds multiply-adds only, where it held a division per entry (the factor
    0.106 -> 0.086 ms at N = 1000); the one division a row is off that chain.
    """
    rows = band.shape[0]
    tiny = 1e-300
    count = 0
    w = np.zeros(BANDWIDTH + 1)
    for r in range(BANDWIDTH):
        inverse[r] = 1.0
        inverse[rows - 1 - r] = 1.0
    for i in range(BANDWIDTH, rows - BANDWIDTH):
        for d in range(BANDWIDTH, 0, -1):
            j = i - d
            total = band[j, BANDWIDTH + d]
            for e in range(BANDWIDTH, d, -1):  # k = i - e < j: w_e L[j, k]
                total -= w[e] * factor[j, e - d]
            w[d] = total
            factor[i, d] = total * inverse[j]
        total = band[i, BANDWIDTH] - shift
        for d in range(BANDWIDTH, 0, -1):
            total -= w[d] * factor[i, d]
        if total < 0.0:
            count += 1
        inverse[i] = 1.0 / (total if total != 0.0 else tiny)
    return count


@njit(cache=True, nogil=True)
def negative_count(band: np.ndarray, shift: float) -> int:  # pragma: no cover - compiled
    """Number of eigenvalues below ``shift`` of the symmetric matrix in padded band storage ``band`` (:func:`_band_storage`)."""
    return _factor(band, shift, np.zeros((band.shape[0], BANDWIDTH + 1)), np.zeros(band.shape[0]))


@njit(cache=True, nogil=True)
def _inverse_step(factor, inverse, shift, vector, work):  # pragma: no cover - compiled
    """One step of inverse iteration, ``vector`` <- (L D L^T)^-1 vector normalised; returns its Rayleigh quotient.

    With A = L D L^T = M - shift I and y = A^-1 x, the quotient of y is
    shift + x^T y / y^T y: no cancellation, unlike y^T M y, whose round-off (n eps |M|)
    exceeds a long chain's critical eigenvalue. ``work``: as long as the factor has rows.
    Each substitution carries the last B unknowns solved in registers
    (B = :data:`~cosserat_chain.state.BANDWIDTH` = 5) and subtracts the term of the one
    solved last at the end: only one multiply-add a row waits for it, and nothing waits on
    a store and its reload (the step 80 -> 27 us at N = 1000). The back substitution
    forms x^T y and y^T y as it goes, in four partial sums each.
    """
    n = vector.size
    w1 = w2 = w3 = w4 = w5 = 0.0
    for i in range(n):  # L y = b, then D^-1
        r = i + BANDWIDTH
        total = vector[i] - factor[r, 5] * w5
        total -= factor[r, 4] * w4
        total -= factor[r, 3] * w3
        total -= factor[r, 2] * w2
        total -= factor[r, 1] * w1
        work[r] = total * inverse[r]
        w5, w4, w3, w2, w1 = w4, w3, w2, w1, total
    w1 = w2 = w3 = w4 = w5 = 0.0
    cross = np.zeros(4)
    square = np.zeros(4)
    for i in range(n - 1, -1, -1):  # L^T z = y
        r = i + BANDWIDTH
        total = work[r] - factor[r + 5, 5] * w5
        total -= factor[r + 4, 4] * w4
        total -= factor[r + 3, 3] * w3
        total -= factor[r + 2, 2] * w2
        total -= factor[r + 1, 1] * w1
        cross[i % 4] += vector[i] * total
        square[i % 4] += total * total
        vector[i] = total
        w5, w4, w3, w2, w1 = w4, w3, w2, w1, total
    size = (square[0] + square[1]) + (square[2] + square[3])
    quotient = shift + ((cross[0] + cross[1]) + (cross[2] + cross[3])) / size
    vector /= math.sqrt(size)
    return quotient


@njit(cache=True, nogil=True)
def _smallest_eigenvalue_compiled(band, low, high, tolerance, guess, vector):  # pragma: no cover - compiled
    """The smallest eigenvalue of ``band`` in [low, high] to ``tolerance``: inverse iteration certified by the inertia.

    Below the smallest eigenvalue lambda_min, M - shift I is positive definite: its
    LDL^T is stable and inverse iteration with it converges to the lowest eigenvector
    at the rate (lambda_1 - shift) / (lambda_2 - shift), each step a cheap banded solve
    with the same factor. The Rayleigh quotient rho is an upper bound of lambda_min, and
    no eigenvalue below rho - tolerance (a count of zero) certifies it. The first shift
    is just below ``guess``; while eigenvalues lie below the shift it moves down by
    growing distances (a chain's critical eigenvalue is small: a few factors settle it),
    then to the middle of the bracket, so the result is never worse than bisection
    (about 50 factors).

    Returns the eigenvalue and a lower bound of it: ``low`` is the Gershgorin bound or
    a shift whose factor has no negative pivot.
    """
    factor = np.zeros((band.shape[0], BANDWIDTH + 1))
    inverse = np.zeros(band.shape[0])
    work = np.zeros(band.shape[0])
    distance = max(0.05 * abs(guess), tolerance)
    shift = guess - distance if low < guess - distance < high else 0.5 * (low + high)
    width = high - low
    below_found = False
    while high - low > tolerance:
        if _factor(band, shift, factor, inverse) > 0:
            high = shift
        else:
            low = shift
            below_found = True
            previous, decrease = math.inf, math.inf
            for _ in range(INVERSE_STEPS):
                quotient = _inverse_step(factor, inverse, shift, vector, work)
                high = min(high, quotient)
                # Converged, or converging too slowly for this shift (a closer one is cheaper).
                if previous - quotient <= tolerance or previous - quotient > 0.5 * decrease:
                    break
                previous, decrease = quotient, previous - quotient
            if high - low > tolerance:
                if _factor(band, high - tolerance, factor, inverse) == 0:
                    return high, max(low, high - tolerance)
                high -= tolerance
        distance = max(4.0 * distance, 1e-6 * width)
        shift = 0.5 * (low + high) if below_found else max(0.5 * (low + high), high - distance)
    return 0.5 * (low + high), low


@lru_cache(maxsize=8)
def _start_vector(n: int) -> np.ndarray:
    """The fixed start vector of inverse iteration, drawn once a size (a draw cost 0.1 ms at N = 1000, once a point)."""
    vector = np.random.default_rng(0).standard_normal(n)
    vector.flags.writeable = False
    return vector


def _smallest_eigenvalue(
    band: np.ndarray, radius: float, guess: float | None = None, start: np.ndarray | None = None
) -> tuple[float, float]:
    """Smallest eigenvalue to round-off of the matrix's scale, O(n) a round (:func:`_smallest_eigenvalue_compiled`),
    and a lower bound of it certified by a factor without negative pivots (-``radius`` if none was).

    ``start``: see :func:`static_stability` (overwritten with the last iterate)."""
    n = band.shape[0] - 2 * BANDWIDTH  # the rows of the chain (the storage is padded)
    low, high = -radius, float(band[BANDWIDTH : n + BANDWIDTH, BANDWIDTH].min())  # Gershgorin, and lambda_min <= min diagonal
    # A fixed generic start vector: deterministic, and with a component along any
    # mode (all ones would miss an antisymmetric lowest mode and leave it to the bisection).
    # A given start that is not a usable vector (zero, or not finite after a factor
    # with a nudged zero pivot) is reset to it.
    if start is None:
        vector = _start_vector(n).copy()  # the compiled search overwrites it
    else:
        if start.shape != (n,):
            raise ValueError(f"start has shape {start.shape}, expected ({n},)")
        vector = start
        if not 0.0 < euclidean_norm(vector) < math.inf:
            vector[:] = _start_vector(n)
    tolerance = max(BISECTION_RTOL * radius, 1e-300)
    value, bound = _smallest_eigenvalue_compiled(band, low, high, tolerance, 0.0 if guess is None else float(guess), vector)
    return float(value), float(bound)


#: Eigenvalues of the damped dynamics with a real part above this times the scale of A
#: (:func:`dynamic_stability`: the larger of sqrt(|K~|) and Gamma M^-1) count as unstable.
DYNAMIC_RTOL = 1e-10
#: Rightmost eigenvalues :func:`dynamic_stability` reports by default.
RIGHTMOST = 6
#: Largest first-order system (2 n_free unknowns) that ``method="auto"`` solves densely.
DENSE_LIMIT = 400
#: Most eigenvalues nearest the axis the sparse path of :func:`dynamic_stability` asks ARPACK for.
NEAREST_LIMIT = 64
#: The dynamics methods :func:`dynamic_stability` takes.
DYNAMIC_METHODS = ("auto", "dense", "sparse")


@dataclass(frozen=True)
class DynamicStability:
    """Stability of a static state from the eigenvalues of the damped dynamics (:func:`dynamic_stability`).

    Attributes
    ----------
    stable : bool
        Dynamically stable: no eigenvalue of the damped first-order system has a real
        part above ``tolerance`` (an eigenvalue on the axis within it, a rigid mode's
        zero or an undamped oscillation, counts as neutral, not unstable).
    unstable_eigenvalues : int
        Eigenvalues with a real part above ``tolerance``, a complex pair counted twice.
    unstable_real, unstable_pairs : int
        Of those, the real ones and the complex-conjugate pairs
        (``unstable_real + 2 unstable_pairs == unstable_eigenvalues``).
    rightmost : tuple of complex
        Eigenvalues by decreasing real part, every unstable one first and then the
        nearest the axis that were found (exactly the rightmost on the dense path).
    spectral_abscissa : float
        The largest real part: exact where the state is unstable or ``method`` is
        ``"dense"``; otherwise that of the stable eigenvalues found nearest the axis.
    stiffness_index : int
        Eigenvalues of K = -dF/dq with a negative real part (K's inertia: the Morse
        index of a conservative model). It is not a count of unstable eigenvalues of
        the dynamics, except for a conservative model with positive damping.
    tolerance : float
        The real part above which an eigenvalue counts as unstable.
    method : str
        ``"dense"`` or ``"sparse"`` (module docstring).
    """

    stable: bool
    unstable_eigenvalues: int
    unstable_real: int
    unstable_pairs: int
    rightmost: tuple[complex, ...]
    spectral_abscissa: float
    stiffness_index: int
    tolerance: float
    method: str

    def as_dict(self) -> dict[str, object]:
        """Plain types for JSON (complex eigenvalues as [real, imag] pairs)."""
        return {
            "dynamically_stable": self.stable,
            "unstable_eigenvalues": self.unstable_eigenvalues,
            "unstable_real": self.unstable_real,
            "unstable_pairs": self.unstable_pairs,
            "rightmost": [[z.real, z.imag] for z in self.rightmost],
            "spectral_abscissa": self.spectral_abscissa,
            "stiffness_index": self.stiffness_index,
            "tolerance": self.tolerance,
            "method": self.method,
        }

    def describe(self) -> str:
        """One phrase: "dynamically stable" or "unstable eigenvalues: 3 (1 real, 1 complex pair)", with the stiffness index."""
        index = f"stiffness index {self.stiffness_index}"
        if self.stable:
            return f"dynamically stable ({index})"
        pairs = f"{self.unstable_pairs} complex pair{'s' if self.unstable_pairs != 1 else ''}"
        return f"unstable eigenvalues: {self.unstable_eigenvalues} ({self.unstable_real} real, {pairs}; {index})"


def dynamic_stability(
    params: ChainParams,
    model: str | Model,
    x: np.ndarray,
    *,
    method: str = "auto",
    rightmost: int = RIGHTMOST,
) -> DynamicStability:
    """Stability of the static state ``x`` (3, 2N+1) from the eigenvalues of the damped dynamics (module docstring).

    Parameters
    ----------
    params : ChainParams
        Any chain (free ends: the rigid modes' zero eigenvalues are neutral).
    model : str or Model
        Any model; eq. (2)'s stiffness is not symmetric, and its verdict differs from K's inertia.
    x : ndarray, shape (3, 2N+1)
        The state (an equilibrium under a constant load: the load does not enter the Jacobian).
    method : {"auto", "dense", "sparse"}
        ``"dense"``: LAPACK's eigenvalues of A (O(n^3)); ``"sparse"``: the unstable eigenvalues
        counted by the argument principle (for a conservative model with positive damping:
        K's negative count, a theorem) and the eigenvalues nearest the axis by
        shift-invert, both with banded factors (O(n) each); ``"auto"``: dense up to
        :data:`DENSE_LIMIT` unknowns. A ring, or a system too small for ARPACK
        (2 n_free <= 2 ``rightmost`` + 4), is solved densely.
    rightmost : int
        How many eigenvalues to report besides the unstable ones (at least 1).

    Returns
    -------
    DynamicStability

    Raises
    ------
    ValueError
        For a state of the wrong shape or not finite, an unknown ``method`` or
        ``rightmost`` below 1.
    """
    model = get_model(model)
    x = check_state(params, x)
    if method not in DYNAMIC_METHODS:
        raise ValueError(f"method must be one of {', '.join(DYNAMIC_METHODS)}, got {method!r}")
    if not (isinstance(rightmost, int) and not isinstance(rightmost, bool) and rightmost >= 1):
        raise ValueError(f"rightmost must be an integer >= 1 (eigenvalues reported), got {rightmost!r}")
    stiffness = model.stiffness(params, x).tocsr()
    n = stiffness.shape[0]
    root = 1.0 / np.sqrt(pack(params, params.particle_inertia))
    scaled = sp.csr_matrix(sp.diags(root) @ stiffness @ sp.diags(root))
    rate = per_dof(params, params.damping) * root**2  # Gamma M^-1
    norm = float(abs(scaled).sum(axis=1).max()) if n else 0.0
    scale = max(math.sqrt(norm), float(rate.max(initial=0.0)), 1e-300)
    tolerance = DYNAMIC_RTOL * scale
    if params.rigid_modes and not np.all(rate > 0):
        # An undamped rigid mode is a Jordan block at zero (a drift q = a + b t): its computed
        # eigenvalues scatter by sqrt(eps |A|), 2e-8 for a free chain, and are neutral.
        tolerance = math.sqrt(np.finfo(float).eps) * scale
    if method == "auto":
        method = "dense" if 2 * n <= DENSE_LIMIT else "sparse"
    if params.periodic or 2 * n <= 2 * rightmost + 4:
        method = "dense"
    index = _stiffness_index(params, model, x, stiffness)
    if method == "dense":
        a = np.zeros((2 * n, 2 * n))
        a[:n, n:] = np.eye(n)
        a[n:, :n] = -scaled.toarray()
        a[n:, n:] = -np.diag(rate)
        eigenvalues = la.eigvals(a)
        return _verdict(eigenvalues, tolerance, rightmost, index, method, int(np.sum(eigenvalues.real > tolerance)))
    if model.conservative and np.all(rate > 0):
        # Symmetric K, positive damping: the unstable eigenvalues are K's negative ones (the
        # tests check this theorem against the dense eigenvalues); no count needed.
        count = index
    else:
        # The chain at rest as the reference of the count (:func:`_unstable_count`), where its K is symmetric.
        rest = model.stiffness(params, np.zeros_like(x)).tocsr()
        symmetric = abs(rest - rest.T).max() <= 1e-12 * abs(rest).max() if rest.nnz else False
        reference = sp.csr_matrix(sp.diags(root) @ rest @ sp.diags(root)) if symmetric else None
        count = _unstable_count(scaled, rate, tolerance, reference)
    # Shift-invert just right of the axis, far enough for K~ + s (R + s I) to be regular where
    # K~ is singular (rigid modes) and R has zeros.
    shift = max(tolerance, 1e-5 * scale)
    eigenvalues = shift + _nearest_axis(_shifted_solver(scaled, rate, shift), 2 * n, count, rightmost)
    return _verdict(eigenvalues, tolerance, rightmost, index, method, count)


def _verdict(eigenvalues: np.ndarray, tolerance: float, rightmost: int, index: int, method: str, count: int) -> DynamicStability:
    """The :class:`DynamicStability` of ``count`` unstable eigenvalues and those found (all, or the nearest the axis)."""
    eigenvalues = eigenvalues[np.argsort(-eigenvalues.real, kind="stable")]
    unstable = eigenvalues[eigenvalues.real > tolerance]
    # A real eigenvalue's imaginary part is round-off of its size or less; the pairs found
    # are exact, and any unstable eigenvalue not found (far from the axis, the sparse
    # path) is counted with the pairs where the parity asks for it.
    real = int(np.sum(np.abs(unstable.imag) <= max(tolerance, 1e-8 * float(np.max(np.abs(unstable), initial=0.0)))))
    real += (count - unstable.size) % 2 if count > unstable.size else 0
    shown = tuple(complex(z) for z in eigenvalues[: unstable.size + rightmost])
    abscissa = float(eigenvalues[0].real) if eigenvalues.size else -math.inf
    return DynamicStability(count == 0, count, real, (count - real) // 2, shown, abscissa, int(index), tolerance, method)


def _shifted_solver(scaled: sp.spmatrix, rate: np.ndarray, shift: float) -> Callable[[np.ndarray], np.ndarray]:
    """x -> (A - s I)^-1 x for A = [[0, I], [-K~, -R]] (R = Gamma M^-1 diagonal), by one banded LU of n x n.

    From -s y + w = a and -K~ y - (R + s) w = b: w = a + s y and
    (K~ + s (R + s)) y = -b - (R + s) a.
    """
    n = scaled.shape[0]
    lu = sla.splu(sp.csc_matrix(scaled + sp.diags(shift * (rate + shift))), permc_spec="NATURAL")
    damped = rate + shift

    def solve(vector: np.ndarray) -> np.ndarray:
        a, b = vector[:n], vector[n:]
        y = lu.solve(-b - damped * a)
        return np.concatenate([y, a + shift * y])

    return solve


def _pencil_band(scaled: sp.spmatrix) -> tuple[np.ndarray, int]:
    """K~ in LAPACK's general band storage by columns (band[j, 2w + i - j] = K~[i, j]; w rows of fill first), and w."""
    coo = sp.coo_matrix(scaled)
    width = int(np.max(np.abs(coo.row - coo.col), initial=0))
    band = np.zeros((scaled.shape[0], 3 * width + 1), dtype=complex)
    np.add.at(band, (coo.col, 2 * width + coo.row - coo.col), coo.data)
    return band, width


def _phase(band: np.ndarray, width: int, rate: np.ndarray, z: complex) -> float:
    """arg det(K~ + z R + z^2 I) = arg det(A - z I) (not reduced mod 2 pi), from one banded LU (O(n w^2))."""
    value = _band_phase(band, width, rate, complex(z), np.empty_like(band))
    if math.isnan(value):  # z is an eigenvalue: the phase next to it (the caller's steps resolve the jump)
        return _phase(band, width, rate, z + 1e-12 * max(abs(z), 1e-300) * 1j)
    return value


@njit(cache=True, nogil=True)
def _band_phase(band, width, rate, z, work):  # pragma: no cover - compiled
    """arg det(B + diag(z rate + z^2)) for B in band storage by columns ``band`` (:func:`_pencil_band`).

    LAPACK's unblocked banded LU with partial pivoting (xGBTF2, its pivot chosen by
    |Re| + |Im| as izamax does) in ``work``: the sum of the pivots' arguments, plus pi a row
    interchange; NaN at a zero pivot. Compiled, each column's band contiguous: zgbtrf through
    SciPy cost 4.8 ms at n = 6000, w = 4 (its blocking does not pay at this width), and the
    argument principle takes thousands of them.
    """
    n = band.shape[0]
    kl = ku = width
    kv = kl + ku
    work[:, :] = band
    for c in range(n):
        work[c, kv] += z * rate[c] + z * z
    total = 0.0
    last = 0
    for j in range(n):
        km = min(kl, n - 1 - j)
        jp = 0
        best = abs(work[j, kv].real) + abs(work[j, kv].imag)
        for i in range(1, km + 1):
            size = abs(work[j, kv + i].real) + abs(work[j, kv + i].imag)
            if size > best:
                best, jp = size, i
        if best == 0.0:
            return math.nan
        last = max(last, min(j + ku + jp, n - 1))
        if jp != 0:
            total += math.pi
            for c in range(j, last + 1):
                upper, lower = kv + j - c, kv + j + jp - c
                work[c, upper], work[c, lower] = work[c, lower], work[c, upper]
        pivot = work[j, kv]
        total += math.atan2(pivot.imag, pivot.real)
        inverse = 1.0 / pivot
        for i in range(1, km + 1):
            work[j, kv + i] *= inverse
        for c in range(j + 1, last + 1):
            above = work[c, kv + j - c]
            for i in range(1, km + 1):
                work[c, kv + j + i - c] -= work[j, kv + i] * above
    return total


def _wrap_angle(angle: float) -> float:
    """``angle`` reduced to (-pi, pi]."""
    return angle - 2.0 * math.pi * math.ceil((angle - math.pi) / (2.0 * math.pi))


def _unstable_count(scaled: sp.spmatrix, rate: np.ndarray, tolerance: float, reference: sp.spmatrix | None = None) -> int:
    """Eigenvalues of A with a real part above ``tolerance``, by the argument principle, O(n) a point.

    det(A - z I) = det(K~ + z R + z^2 I) winds round zero once for each eigenvalue inside
    a closed curve. The curve: the line Re z = tolerance and a half circle right of it of
    radius 4 rho, rho = (r + sqrt(r^2 + 4 |K~|)) / 2 bounding every |lambda| (from
    lambda^2 + lambda y*Ry + y*K~y = 0, |y| = 1). A is real, so the upper half of the curve
    turns the phase by pi per eigenvalue.

    ``reference``: a symmetric positive semi-definite K~_0 (the chain at rest), whose damped
    dynamics has no eigenvalue right of the line (K~_0 symmetric and R >= 0: no growing mode);
    the phase followed is then that of det(K~ + z R + z^2 I) / det(K~_0 + z R + z^2 I), which
    winds once per eigenvalue of A inside the curve less one per eigenvalue of the reference:
    the eigenvalues the state shares with rest (those of the chain far from where it is
    deformed) cancel, and the phase turns slowly.

    The phase is followed in steps that turn it by less than :data:`PHASE_STEP` (halved on a
    larger turn, grown by half otherwise). Eigenvalues within one step and nearer the line than
    its length could hide each other's turns: the steps are at most a quarter of the least
    damping rate r_min, since a complex eigenvalue of a conservative damped chain lies at least
    r_min / 2 left of the axis (Re lambda = -y*Ry / 2 for its eigenvector y), and they shrink
    geometrically towards the real axis, where the slow overdamped modes lie (within 1e-7 of
    zero at N = 100). The cost is two banded LUs a point, O(rho / r_min) points.
    """
    band, width = _pencil_band(scaled)
    base = None if reference is None else _pencil_band(reference)[0]
    if base is not None and base.shape != band.shape:
        base = None
    n = scaled.shape[0]
    r = float(rate.max(initial=0.0))
    size = abs(scaled)
    norm = math.sqrt(float(size.sum(axis=0).max()) * float(size.sum(axis=1).max())) if n else 0.0
    radius = 4.0 * (r + math.sqrt(r * r + 4.0 * norm)) / 2.0 + tolerance

    def phase(z: complex) -> float:
        if base is None:
            return _phase(band, width, rate, z)
        return _phase(band, width, rate, z) - _phase(base, width, rate, z)

    # Without a reference the phase of z^(2n) is taken out on the circle, where it dominates.
    power = 0 if base is not None else 2 * n

    def arc(theta: float) -> float:
        z = tolerance + radius * complex(math.cos(theta), math.sin(theta))
        return phase(z) - power * math.atan2(z.imag, z.real)

    def line(y: float) -> float:
        return phase(complex(tolerance, y))

    start = complex(tolerance + radius, 0.0)
    corner = complex(tolerance, radius)
    # The arc from the real axis to the line, then the line down to the real axis.
    total = _follow_phase(arc, 0.0, 0.5 * math.pi, 0.5 * math.pi / 64)
    total += power * (math.atan2(corner.imag, corner.real) - math.atan2(start.imag, start.real))
    damped = rate[rate > 0]
    largest = min(0.25 * float(damped.min()) if damped.size else radius / 4096, radius / 64)
    total += _follow_phase(line, radius, 0.0, largest, floor=tolerance * 1e-3, largest=largest)
    return int(round(total / math.pi))


#: Largest turn of the phase of det(A - z I) over one step of :func:`_unstable_count`.
PHASE_STEP = 0.25 * math.pi


def _follow_phase(phase, begin: float, end: float, step: float, floor: float = 0.0, largest: float = math.inf) -> float:
    """The phase's total turn from ``begin`` to ``end`` (a real parameter), in steps that turn it by less than PHASE_STEP.

    Steps grow by half after each accepted one, up to ``largest``, and halve on a larger
    turn; near ``end`` they are kept below half the distance left (geometric towards it,
    down to ``floor``). Growing by half, a step turns the phase by at most about 1.5 times
    the last one's unless its rate jumps sevenfold, so a turn of 2 pi is never taken for none.
    """
    here, value, total = begin, phase(begin), 0.0
    direction = 1.0 if end > begin else -1.0
    while direction * (end - here) > 0.0:
        left = abs(end - here)
        length = min(abs(step), left if left <= floor else max(0.5 * left, floor))
        there = end if length >= left else here + direction * length
        after = phase(there)
        turn = _wrap_angle(after - value)
        if abs(turn) > PHASE_STEP and length > 4.0 * np.finfo(float).eps * max(abs(here), 1.0):
            step = 0.5 * length
            continue
        total += turn
        here, value, step = there, after, min(1.5 * length, largest)
    return total


def _nearest_axis(solve, size: int, count: int, rightmost: int) -> np.ndarray:
    """Eigenvalues nearest the shift of ``solve`` (just right of the axis), enough to hold ``count`` unstable ones if they are near.

    Shift-invert: ARPACK's largest 1 / (lambda - s) converge fast, clusters of slow modes
    included. The number asked for doubles while fewer than ``count`` of those found are
    unstable, up to :data:`NEAREST_LIMIT` (unstable eigenvalues far from the axis among
    many stable ones nearer it are then not all listed; their number is still exact).
    """
    inverse = sla.LinearOperator((size, size), matvec=solve, dtype=float)
    start = np.random.default_rng(0).standard_normal(size)
    wanted = min(count + rightmost + 2, size - 2)
    while True:
        try:
            nu = sla.eigs(inverse, k=wanted, which="LM", v0=start, tol=1e-12, return_eigenvectors=False, maxiter=100 * size)
        except sla.ArpackNoConvergence as err:  # the converged ones (the count does not depend on them)
            nu = err.eigenvalues
        eigenvalues = 1.0 / nu
        if int(np.sum(eigenvalues.real > 0.0)) >= count or wanted >= min(NEAREST_LIMIT, size - 2):
            return eigenvalues
        wanted = min(2 * wanted, NEAREST_LIMIT, size - 2)


def _stiffness_index(params: ChainParams, model: Model, x: np.ndarray, stiffness: sp.spmatrix) -> int:
    """Eigenvalues of K with a real part below minus its round-off (:func:`_resolution`; a rigid mode's zero is not
    negative): the inertia of its symmetric similar matrix where it has one (banded, or dense for a ring), else
    the dense eigenvalues of K (a registered model without one)."""
    similar = model.symmetric_similar(params, x)
    if similar is not None and not params.periodic:
        return int(negative_count(_band_storage(similar), -_resolution(similar)))
    if similar is not None:
        return int(np.sum(la.eigvalsh(similar.toarray()) < -_resolution(similar)))
    return int(np.sum(la.eigvals(stiffness.toarray()).real < -_resolution(stiffness)))
