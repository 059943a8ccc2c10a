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
that count is the fallback; LAPACK's banded eigensolver is O(N^2): benchmarks/TIMINGS.md),
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
model with damping Gamma >= 0 the number of its unstable eigenvalues equals K's negative
count (a theorem the tests check against the dense eigenvalues, undamped degrees of freedom
included: an eigenvalue on the imaginary axis, i w, has D y = 0 and K y = w^2 M y, a positive
mode, and so is never the limit of an unstable one); for eq. (2) it does not:
the sine chain's unstable branch at N = 2 has one real and one complex pair of unstable
eigenvalues where K has one negative eigenvalue, the pair crossing the axis at two Hopf
points (:mod:`cosserat_chain.numerics.hopf`).

Without a dense matrix (``method="sparse"``) the unstable eigenvalues are counted by the
argument principle and the eigenvalues nearest the axis are found by shift-invert, both on
the banded pencil K~ + z R + z^2 I, O(n) a point (:mod:`cosserat_chain.linalg.pencil`). The
count's steps rely on every degree of freedom being damped (a complex eigenvalue then lies at
least half the least damping rate left of the axis); a model without the theorem whose chain
has an undamped degree of freedom (gamma_u, gamma_v or gamma_phi zero) has eigenvalues on the
axis, next to the counting line, and is solved densely up to :data:`PARTLY_DAMPED_DENSE_LIMIT`
unknowns and refused beyond.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import scipy.linalg as la
import scipy.sparse as sp

from ..linalg import BandMatrix, band_storage, eigenvalue_resolution, infinity_norm, negative_count
from ..linalg.eigen import BISECTION_RTOL, smallest_band_eigenvalue
from ..linalg.pencil import nearest_axis, shifted_solver, unstable_count
from ..linalg.threads import one_blas_thread
from ..models.base import Model, get_model
from ..params import ChainParams
from ..state import check_state, free_rows, pack, per_dof


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
        Round-off of ``critical_eigenvalue``: :data:`~cosserat_chain.linalg.eigen.BISECTION_RTOL` times K's Gershgorin
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
    eigenvector is a close start, quicker than the fixed random vector: benchmarks/TIMINGS.md);
    it changes the cost, not the result
    beyond the round-off of the certified eigenvalue. Ignored on the dense path.

    The index costs no factor of its own where the smallest eigenvalue is certified
    positive above its round-off (the certificate is a factor at a shift below it with
    no negative pivot, so K itself has none): only an unstable or marginal state pays
    the count at zero, and not even that where the caller gives ``index``, the
    number of negative eigenvalues of ``similar`` it has counted from a factor of that
    matrix at zero (a continuation's tangent solve factors the stiffness at every point:
    :attr:`~cosserat_chain.linalg.BorderedFactor.negative_eigenvalues`). A factor in another order of
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
        similar = model.symmetric_similar_band(params, x)
    if similar is not None:
        band = band_storage(similar)
        resolution = eigenvalue_resolution(similar)
        critical, bound = smallest_band_eigenvalue(band, resolution / BISECTION_RTOL, guess, start)
        if bound > resolution:
            index = 0
        else:
            index = negative_count(band, 0.0) if counted is None else counted
        return Stability(index == 0 and critical > 0.0, critical, math.nan, index, resolution)
    k = model.stiffness(params, x).toarray()
    abscissa = float(np.max(la.eigvals(damped_dynamics_matrix(params, k)).real))
    if model.conservative:
        eigenvalues = la.eigvalsh(k)
        return Stability(
            bool(eigenvalues[0] > 0.0), float(eigenvalues[0]), abscissa, int(np.sum(eigenvalues < 0)), eigenvalue_resolution(k)
        )
    # Round-off of the eigenvalue solver, relative to the fastest rate of the chain.
    round_off = 1e-10 * max(1.0, float(np.max(np.abs(k))))
    real = la.eigvals(k).real
    return Stability(abscissa < round_off, float(np.min(real)), abscissa, int(np.sum(real < 0)), eigenvalue_resolution(k))


#: Eigenvalues of the damped dynamics with a real part above this times the scale of A
#: (:func:`dynamic_stability`: the larger of sqrt(|K~|) and Gamma M^-1) count as unstable.
DYNAMIC_RTOL = 1e-10
#: Rightmost eigenvalues :func:`dynamic_stability` reports by default.
RIGHTMOST = 6
#: Largest first-order system (2 n_free unknowns) that ``method="auto"`` solves densely.
DENSE_LIMIT = 400
#: Largest first-order system solved densely where the sparse count does not hold (:func:`dynamic_stability`: a model
#: without the theorem on a chain with an undamped degree of freedom); beyond it such a chain is refused.
PARTLY_DAMPED_DENSE_LIMIT = 4000
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


@one_blas_thread
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
    root, scaled, rate, scale, tolerance = _damped_system(params, model, x)
    n = scaled.shape[0]
    if method == "auto":
        method = "dense" if 2 * n <= DENSE_LIMIT else "sparse"
    if params.periodic or 2 * n <= 2 * rightmost + 4:
        method = "dense"
    theorem = model.conservative and bool(np.all(rate >= 0.0))
    if method == "sparse" and not theorem and not np.all(rate > 0.0):
        if 2 * n > PARTLY_DAMPED_DENSE_LIMIT:
            undamped = ", ".join(f"gamma_{row}" for row in ("u", "v", "phi") if getattr(params, f"gamma_{row}") == 0.0)
            raise ValueError(
                f"the {model.name} model's unstable eigenvalues are counted without a dense matrix only where every degree of "
                f"freedom is damped, but {undamped} = 0; the dense count takes 2 n_free = {2 * n} unknowns, above "
                f"{PARTLY_DAMPED_DENSE_LIMIT}: give {undamped} a positive value, or a shorter chain"
            )
        method = "dense"
    index = _stiffness_index(params, model, x)
    if method == "dense":
        a = np.zeros((2 * n, 2 * n))
        a[:n, n:] = np.eye(n)
        a[n:, :n] = -scaled.toarray()
        a[n:, n:] = -np.diag(rate)
        eigenvalues = la.eigvals(a)
        return _verdict(eigenvalues, tolerance, rightmost, index, method, int(np.sum(eigenvalues.real > tolerance)))
    scaled = scaled.tocsr()  # the band as CSR for SuperLU and the pencil (a ring is solved densely, above)
    if theorem:
        # Symmetric K, damping >= 0: the unstable eigenvalues are K's negative ones (module
        # docstring; the tests check this theorem against the dense eigenvalues); no count needed.
        count = index
    else:
        # The chain at rest as the reference of the count (:func:`unstable_count`), where its K is symmetric.
        rest = model.stiffness(params, np.zeros_like(x)).tocsr()
        symmetric = abs(rest - rest.T).max() <= 1e-12 * abs(rest).max() if rest.nnz else False
        reference = sp.csr_matrix(sp.diags(root) @ rest @ sp.diags(root)) if symmetric else None
        count = unstable_count(scaled, rate, tolerance, reference)
    # Shift-invert just right of the axis, far enough for K~ + s (R + s I) to be regular where
    # K~ is singular (rigid modes) and R has zeros.
    shift = max(tolerance, 1e-5 * scale)
    eigenvalues = shift + nearest_axis(shifted_solver(scaled, rate, shift), 2 * n, count, rightmost)
    return _verdict(eigenvalues, tolerance, rightmost, index, method, count, real_only=theorem)


def _damped_system(
    params: ChainParams, model: Model, x: np.ndarray
) -> tuple[np.ndarray, BandMatrix | sp.csr_matrix, np.ndarray, float, float]:
    """M^(-1/2)'s diagonal, K~ = M^(-1/2) K M^(-1/2), R = Gamma M^-1 (its diagonal), the scale of A and the tolerance
    of :func:`dynamic_stability`.

    K~ is banded (:meth:`~cosserat_chain.models.base.Model.stiffness_band` scaled in band storage, no sparse
    product: the same entries bit for bit) except for a ring, whose corner blocks lie outside the band (CSR)."""
    root = 1.0 / np.sqrt(pack(params, params.particle_inertia))
    if params.periodic:
        scaled = sp.csr_matrix(sp.diags(root) @ model.stiffness(params, x).tocsr() @ sp.diags(root))
    else:
        scaled = model.stiffness_band(params, x).scaled(root)
    rate = per_dof(params, params.damping) * root**2  # Gamma M^-1
    norm = infinity_norm(scaled)
    scale = max(math.sqrt(norm), float(rate.max(initial=0.0)), 1e-300)
    tolerance = DYNAMIC_RTOL * scale
    if params.rigid_modes and not np.all(rate > 0):
        # An undamped rigid mode is a Jordan block at zero (a drift q = a + b t): its computed
        # eigenvalues scatter by sqrt(eps |A|), 2e-8 for a free chain, and are neutral.
        tolerance = math.sqrt(np.finfo(float).eps) * scale
    return root, scaled, rate, scale, tolerance


#: ``DynamicStability.method`` of a verdict by :func:`sine_theorem_stability`.
THEOREM = "eq. (2) theorem"


def sine_theorem_stability(params: ChainParams, model: str | Model, x: np.ndarray) -> DynamicStability | None:
    """The damped dynamics' verdict on a state of eq. (2) with every free angle within pi/2 of rest, without eigenvalues.

    There K = S C with S the linear model's stiffness (symmetric, positive semi-definite)
    and C = diag(1, 1, cos phi) positive. An eigenvalue z with (z^2 M + z Gamma + S C) v = 0,
    multiplied by (C v)^H, solves a z^2 + b z + c = 0 with a = v^H C M v > 0,
    b = v^H C Gamma v >= 0 and c = (C v)^H S (C v) >= 0, whose roots have no positive real
    part: none counts as unstable (the module docstring's energy argument, at every
    state of the kind, not only on the branch from rest). The verdict is that of
    :func:`dynamic_stability` (the tests compare them along branches) with no eigenvalue
    found: ``rightmost`` empty, ``spectral_abscissa`` NaN, ``method`` :data:`THEOREM`;
    the stiffness index is counted as there (0 by Sylvester's law).

    Returns
    -------
    DynamicStability or None
        None where the theorem does not apply: another model, a ring, a chain with rigid
        modes, or a free angle at or beyond pi/2 from rest.
    """
    model = get_model(model)
    if model.name != "sine" or params.periodic or params.rigid_modes:
        return None
    x = check_state(params, x)
    if not np.all(np.cos(pack(params, x)[free_rows(params) == 2]) > 0.0):
        return None
    *_, tolerance = _damped_system(params, model, x)
    index = _stiffness_index(params, model, x)
    return DynamicStability(True, 0, 0, 0, (), math.nan, index, tolerance, THEOREM)


def _verdict(
    eigenvalues: np.ndarray, tolerance: float, rightmost: int, index: int, method: str, count: int, *, real_only: bool = False
) -> DynamicStability:
    """The :class:`DynamicStability` of ``count`` unstable eigenvalues and those found (all, or the nearest the axis).

    ``real_only``: a conservative model with damping >= 0, whose unstable eigenvalues are all real (an eigenvalue
    with eigenvector y solves m z^2 + d z + k = 0 with m = y*My > 0, d = y*Dy >= 0, k = y*Ky real: a complex root
    has Re z = -d / 2m <= 0), found or not."""
    eigenvalues = eigenvalues[np.argsort(-eigenvalues.real, kind="stable")]
    unstable = eigenvalues[eigenvalues.real > tolerance]
    # A real eigenvalue's imaginary part is round-off of its size or less; the pairs found
    # are exact, and any unstable eigenvalue not found (far from the axis, the sparse
    # path) is counted with the pairs where the parity asks for it.
    real = int(np.sum(np.abs(unstable.imag) <= max(tolerance, 1e-8 * float(np.max(np.abs(unstable), initial=0.0)))))
    real += (count - unstable.size) % 2 if count > unstable.size else 0
    if real_only:
        real = count
    shown = tuple(complex(z) for z in eigenvalues[: unstable.size + rightmost])
    abscissa = float(eigenvalues[0].real) if eigenvalues.size else -math.inf
    return DynamicStability(count == 0, count, real, (count - real) // 2, shown, abscissa, int(index), tolerance, method)


def _stiffness_index(params: ChainParams, model: Model, x: np.ndarray) -> int:
    """Eigenvalues of K with a real part below minus its round-off (:func:`_resolution`; a rigid mode's zero is not
    negative): the inertia of its symmetric similar matrix where it has one (banded, or dense for a ring), else
    the dense eigenvalues of K (a registered model without one)."""
    if not params.periodic:
        similar = model.symmetric_similar_band(params, x)
        if similar is not None:
            return int(negative_count(band_storage(similar), -eigenvalue_resolution(similar)))
    similar = model.symmetric_similar(params, x)
    if similar is not None:
        return int(np.sum(la.eigvalsh(similar.toarray()) < -eigenvalue_resolution(similar)))
    stiffness = model.stiffness(params, x)
    return int(np.sum(la.eigvals(stiffness.toarray()).real < -eigenvalue_resolution(stiffness)))
