"""Section 3 of the paper: long-wave continuum solutions of the linear chain under a central moment.

Contract
--------
The closed forms here (eqs. (7), (11), (12), phi(0) and the reduced model of
Section 3.2) depend only on :class:`~cosserat_chain.params.ChainParams`, never on
the discrete models, so that they stay an independent check on them. Only the
comparison helpers at the end (:func:`discrete_static`, :func:`convergence`,
:func:`compare_profiles`) solve the discrete linear model (iii).

The chain has 2N+1 particles, the moment M acts on particle 0, the ends k = +-N
are clamped. With the origin at particle 0 and L = N h the continuum fields on
the half chain 0 <= x <= L solve eq. (6),

    v_xx - phi_x = 0,    h^2 D1 phi_xx + D2 (v_x - phi) = 0,

with the boundary conditions (8) v(0) = v(L) = phi(L) = 0 and the nonlocal
condition (10), the discrete moment balance (9) of particle 0 written with the
continuum fields. The discrete profile is v_k = v(kh), phi_k = phi(kh) for
k >= 0, extended by the mirror symmetry of the loaded chain: v_-k = -v_k and
phi_-k = phi_k.

D1 and D2 are the geometry-derived coefficients ``params.D1`` = E1 - (h^2/d^2) E2
and ``params.D2`` = 4 (h^2/d^2) E2. The paper prints D1 = E1 - 2 (h^2/d^2) E2 in
Section 3 (erratum 2 in ``docs/errata.md``); every closed form accepts ``D1=`` to
evaluate it with another value, e.g. :func:`printed_D1`, to see what the misprint
does.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import scipy.linalg as la
import scipy.sparse.linalg as spla

from ..linalg import RootFactor, upper_bands
from ..memory import require
from ..models.linear import n_free, rest_solve, stiffness_matrix, stiffness_root
from ..params import ChainParams
from ..state import pack, require_clamped, unpack
from .beam import clamped_central_compliance


@dataclass(frozen=True)
class _Coefficients:
    h: float
    L: float
    b: float
    D1: float
    D2: float

    @property
    def denominator(self) -> float:
        """h (24 h^2 D1^2 + (8 L^2 + 6 h^2) D1 D2 + L (2L - h) D2^2), common to eq. (11) and phi(0)."""
        h, L, D1, D2 = self.h, self.L, self.D1, self.D2
        return h * (24 * h * h * D1 * D1 + (8 * L * L + 6 * h * h) * D1 * D2 + L * (2 * L - h) * D2 * D2)


def printed_D1(params: ChainParams) -> float:
    """The bending coefficient as printed in Section 3, E1 - 2 (h^2/d^2) E2 (erratum 2).

    The geometry gives ``params.D1`` = E1 - (h^2/d^2) E2; this value exists only to
    show the consequences of the misprint.
    """
    return params.E1 - 2.0 * params.h**2 / params.d**2 * params.E2


def reduced_E1(params: ChainParams) -> float:
    """Stiffness E1 of the horizontal links at which D1 = 0, the reduced model of Section 3.2.

    With the geometry-derived D1 this is E1 = (h/d)^2 E2 (the paper prints
    E1 = 2 (h/d)^2 E2, erratum 2). ``params.replace(E1=reduced_E1(params))`` is
    the reduced chain.
    """
    return params.h**2 / params.d**2 * params.E2


#: The denominator of (11) counts as vanishing below this many roundings of its terms' magnitude.
SINGULAR_ROUNDINGS = 64


def _coefficients(params: ChainParams, D1: float | None, *, solved: bool = True) -> _Coefficients:
    # Section 3's solutions meet the clamped ends' conditions u = v = phi = 0 at x = +-L.
    # ``solved``: refuse a (rounding-)vanishing denominator of (11), where the conditions
    # (8), (10) leave the constants of (7) undetermined (N = 1) or have no solution (N >= 2).
    require_clamped(params, "the continuum solution of Section 3")
    if D1 is not None and not math.isfinite(D1):
        raise ValueError(f"D1 must be a finite number or None (the geometry-derived params.D1), got {D1!r}")
    coef = _Coefficients(params.h, params.N * params.h, params.b, params.D1 if D1 is None else float(D1), params.D2)
    if coef.D2 <= 0:
        raise ValueError(f"the continuum solution needs coupling D2 = 4 (h/d)^2 E2 > 0, i.e. E2 > 0; got E2={params.E2!r}")
    h, L, D1_, D2 = coef.h, coef.L, coef.D1, coef.D2
    size = h * (24 * h * h * D1_ * D1_ + (8 * L * L + 6 * h * h) * abs(D1_) * D2 + L * (2 * L - h) * D2 * D2)
    if solved and abs(coef.denominator) <= SINGULAR_ROUNDINGS * np.finfo(float).eps * size:
        raise ValueError(
            f"the continuum solution (11) is singular for D1={coef.D1!r}, D2={coef.D2!r}, L=N h={coef.L!r}: "
            "its denominator 24 h^2 D1^2 + (8 L^2 + 6 h^2) D1 D2 + L (2L - h) D2^2 vanishes"
        )
    return coef


def _positions(params: ChainParams, x: np.ndarray | float) -> np.ndarray:
    x = np.asarray(x, dtype=float)
    length = params.N * params.h
    if not np.all(np.isfinite(x)) or np.any(x < 0) or np.any(x > length):
        bad = x[~(np.isfinite(x) & (x >= 0) & (x <= length))].ravel()[0]
        raise ValueError(f"x must lie in the half chain 0 <= x <= L = N h = {length!r}, got {float(bad)!r}")
    return x


def _moment(moment: float) -> float:
    if not math.isfinite(moment):
        raise ValueError(f"moment must be finite, got {moment!r}")
    return float(moment)


def general_solution(
    params: ChainParams, x: np.ndarray | float, constants: np.ndarray, *, D1: float | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """General solution (7) of the continuum equations (6).

    v(x) = C1 x^3/6 + C2 x^2/2 + C3 x + C4,
    phi(x) = C1 h^2 D1 / D2 + C1 x^2/2 + C2 x + C3.

    Parameters
    ----------
    params : ChainParams
    x : float or ndarray
        Positions (any shape; not restricted to the half chain).
    constants : array_like, shape (4,)
        The integration constants (C1, C2, C3, C4).
    D1 : float, optional
        Bending coefficient; default the geometry-derived ``params.D1``.

    Returns
    -------
    v, phi : ndarray
        Same shape as ``x``.

    Raises
    ------
    ValueError
        If ``constants`` does not hold four finite numbers, or for E2 = 0.
    """
    c = np.asarray(constants, dtype=float)
    if c.shape != (4,) or not np.all(np.isfinite(c)):
        raise ValueError(f"constants must be four finite numbers (C1, C2, C3, C4), got {constants!r}")
    coef = _coefficients(params, D1)
    x = np.asarray(x, dtype=float)
    c1, c2, c3, c4 = c
    v = c1 * x**3 / 6 + c2 * x**2 / 2 + c3 * x + c4
    phi = c1 * coef.h**2 * coef.D1 / coef.D2 + c1 * x**2 / 2 + c2 * x + c3
    return v, phi


def integration_constants(params: ChainParams, moment: float = 1.0, *, D1: float | None = None) -> np.ndarray:
    """Constants (C1, C2, C3, C4) of eq. (7) from the conditions (8) and (10), by a linear solve.

    This is the route the paper describes; :func:`solution` is its closed form (11),
    and the two are compared in the tests.

    Returns
    -------
    ndarray, shape (4,)
    """
    moment = _moment(moment)
    coef = _coefficients(params, D1)
    h, L, b, D1_, D2 = coef.h, coef.L, coef.b, coef.D1, coef.D2
    alpha = h * h * D1_ / D2
    # Rows: v(0) = 0, v(L) = 0, phi(L) = 0 (eq. 8), and eq. (10)
    # 2 b^2 [2 D1 (phi(h) - phi(0)) + D2 (v(h)/h - phi(0))] = -M, each linear in C.

    def v_row(x: float) -> np.ndarray:
        return np.array([x**3 / 6, x**2 / 2, x, 1.0])

    def phi_row(x: float) -> np.ndarray:
        return np.array([alpha + x**2 / 2, x, 1.0, 0.0])

    rows = np.array(
        [
            v_row(0.0),
            v_row(L),
            phi_row(L),
            2 * b * b * (2 * D1_ * (phi_row(h) - phi_row(0.0)) + D2 * (v_row(h) / h - phi_row(0.0))),
        ]
    )
    return np.linalg.solve(rows, np.array([0.0, 0.0, 0.0, -moment]))


def solution(params: ChainParams, x: np.ndarray | float, moment: float = 1.0, *, D1: float | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Continuum solution (11) on the half chain 0 <= x <= L = N h.

    v(x)   = M x (L - x) (6 h^2 D1 + L (L - x) D2) / (2 b^2 Den),
    phi(x) = M (L - x) (12 h^2 D1 + L (L - 3x) D2) / (2 b^2 Den),
    Den    = h (24 h^2 D1^2 + (8 L^2 + 6 h^2) D1 D2 + L (2L - h) D2^2).

    Parameters
    ----------
    params : ChainParams
    x : float or ndarray
        Positions in [0, L].
    moment : float
        Moment M on particle 0.
    D1 : float, optional
        Bending coefficient; default the geometry-derived ``params.D1``.

    Returns
    -------
    v, phi : ndarray
        Same shape as ``x``.

    Raises
    ------
    ValueError
        For x outside [0, L], a non-finite moment, E2 = 0 (no coupling), or a
        vanishing denominator (to rounding): with the derived D1 at E1 = 2/3 (h/d)^2 E2
        for N = 1, where the conditions leave the profile undetermined, and near
        E1 = (h/d)^2 E2 / (2N) for N >= 2, where (11) has a pole (the continuum problem no solution).
    """
    x = _positions(params, x)
    moment = _moment(moment)
    coef = _coefficients(params, D1)
    h, L, D1_, D2 = coef.h, coef.L, coef.D1, coef.D2
    scale = moment / (2 * coef.b**2 * coef.denominator)
    v = scale * x * (L - x) * (6 * h * h * D1_ + L * (L - x) * D2)
    phi = scale * (L - x) * (12 * h * h * D1_ + L * (L - 3 * x) * D2)
    return v, phi


def central_rotation(params: ChainParams, moment: float = 1.0, *, D1: float | None = None) -> float:
    """Rotation phi(0) = M L (12 h^2 D1 + L^2 D2) / (2 b^2 Den) of the loaded particle (Section 3.1).

    ``central_rotation(params)`` is the continuum compliance phi_0 / M. For N = 1 (L = h)
    the factor 12 D1 + D2 of Den cancels, phi(0) = M / (2 b^2 (2 D1 + D2)), the chain's own
    value, also where Den vanishes (E1 = 2/3 (h/d)^2 E2): the conditions then fix phi(0) but
    not the profile (:func:`solution` refuses it).
    """
    moment = _moment(moment)
    coef = _coefficients(params, D1, solved=params.N > 1)
    if params.N == 1:
        if 2 * coef.D1 + coef.D2 == 0:
            raise ValueError(f"the continuum solution (11) is singular for N = 1 and D1={coef.D1!r} = -D2/2 (D2={coef.D2!r})")
        return moment / (2 * coef.b**2 * (2 * coef.D1 + coef.D2))
    L = coef.L
    return moment * L * (12 * coef.h**2 * coef.D1 + L * L * coef.D2) / (2 * coef.b**2 * coef.denominator)


def residue(params: ChainParams, moment: float = 1.0, *, D1: float | None = None) -> float:
    """Residue (12) of the discrete eq. (5) for the sampled continuum solution, eps = h/L = 1/N.

    Delta_phi = M D2^2 eps / (2 b^2 (24 eps^2 D1^2 + (8 + 6 eps^2) D1 D2 + (2 - eps) D2^2)),

    the same at every interior site 0 < |k| < N, because eq. (11) is a cubic (v)
    and a quadratic (phi), for which the only inexact difference quotient is
    (v_k+1 - v_k-1) / 2h = v_x + h^2 v_xxx / 6. It vanishes like eps as N grows.
    """
    moment = _moment(moment)
    coef = _coefficients(params, D1, solved=params.N > 1)  # N = 1: no interior site, (12) as printed
    eps, D1_, D2 = 1.0 / params.N, coef.D1, coef.D2
    return moment * D2 * D2 * eps / (2 * coef.b**2 * (24 * eps * eps * D1_ * D1_ + (8 + 6 * eps * eps) * D1_ * D2 + (2 - eps) * D2 * D2))


def reduced_solution(params: ChainParams, x: np.ndarray | float, moment: float = 1.0) -> tuple[np.ndarray, np.ndarray]:
    """Solution of the reduced model (D1 = 0, Section 3.2) on the half chain 0 <= x <= L.

    v(x) = M x (L - x)^2 / (2 b^2 h (2L - h) D2),  phi(x) = M (L - x)(L - 3x) / (2 b^2 h (2L - h) D2),

    from the polynomial (14)-(15) with v(0) = 0, 2 b^2 D2 (v(h)/h - phi(0)) + M = 0,
    v(L) = 0, phi(L) = 0. It uses only D2, whatever ``params.D1`` is; the chain that
    actually has D1 = 0 is ``params.replace(E1=reduced_E1(params))``.
    """
    x = _positions(params, x)
    moment = _moment(moment)
    coef = _coefficients(params, 0.0)
    h, L = coef.h, coef.L
    scale = moment / (2 * coef.b**2 * h * (2 * L - h) * coef.D2)
    return scale * x * (L - x) ** 2, scale * (L - x) * (L - 3 * x)


def reduced_family(params: ChainParams, x: np.ndarray | float, moment: float = 1.0, *, alpha: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
    """More solutions of the reduced model (D1 = 0, Section 3.2): the paper's cubic plus alpha w(x).

    v(x) = v_3(x) + alpha w(x),  phi(x) = v_x(x),  w(x) = x (L - x)^2 (x + (L - h)^2 / (2L - h)),

    with v_3 the cubic of :func:`reduced_solution`. The reduced equations
    v_xx - phi_x = 0, v_x - phi = 0 hold for every v with phi = v_x (eq. (13)), and w
    meets the four conditions of Section 3.2 with M = 0: w(0) = w(L) = w_x(L) = 0 and
    w(h)/h - w_x(0) = 0. So every alpha meets them all, while the loaded particle turns by
    phi(0) = phi_3(0) + alpha L^2 (L - h)^2 / (2L - h) (:func:`reduced_family_rotation`):
    for N >= 2 the reduced continuum model does not determine the central rotation. Up to
    a factor, w is the only quartic that meets the four conditions with M = 0 (tested with
    SymPy). The quartic alpha x^2 (L - x)^2, which vanishes with its slope at both ends,
    does not do: it breaks the nonlocal condition by 2 b^2 D2 alpha h (L - h)^2 and leaves
    phi(0) unchanged (``docs/continuum.md``).

    Parameters
    ----------
    params : ChainParams
        Only h, b, N and D2 enter, whatever ``params.D1`` is (as in :func:`reduced_solution`).
    x : float or ndarray
        Positions in [0, L].
    moment : float
        Moment M on particle 0.
    alpha : float
        Coefficient of w, in units of v / length^4.

    Returns
    -------
    v, phi : ndarray
        Same shape as ``x``.

    Raises
    ------
    ValueError
        For x outside [0, L], a non-finite moment or alpha, or E2 = 0.
    """
    if not math.isfinite(alpha):
        raise ValueError(f"alpha must be finite, got {alpha!r}")
    v, phi = reduced_solution(params, x, moment)
    x = np.asarray(x, dtype=float)
    h, L = params.h, params.N * params.h
    shift = (L - h) ** 2 / (2 * L - h)
    w = x * (L - x) ** 2 * (x + shift)
    w_x = (L - x) ** 2 * (x + shift) - 2 * x * (L - x) * (x + shift) + x * (L - x) ** 2
    return v + alpha * w, phi + alpha * w_x


def reduced_family_rotation(params: ChainParams, moment: float = 1.0, *, alpha: float = 0.0) -> float:
    """phi(0) = M L^2 / (2 b^2 h (2L - h) D2) + alpha L^2 (L - h)^2 / (2L - h) of :func:`reduced_family`.

    alpha = 0 is the paper's reduced solution of Section 3.2; every other alpha meets the
    same equations and conditions with another central rotation, except for N = 1 (L = h),
    where alpha drops out.
    """
    if not math.isfinite(alpha):
        raise ValueError(f"alpha must be finite, got {alpha!r}")
    coef = _coefficients(params, 0.0)
    h, L = coef.h, coef.L
    return _moment(moment) * L * L / (2 * coef.b**2 * h * (2 * L - h) * coef.D2) + alpha * L * L * (L - h) ** 2 / (2 * L - h)


def sampled_state(params: ChainParams, moment: float = 1.0, *, D1: float | None = None) -> np.ndarray:
    """The continuum solution (11) at the particles, v_k = v(|k| h) sign(k), phi_k = phi(|k| h).

    Returns
    -------
    ndarray, shape (3, 2N+1)
        Rows (u, v, phi) in the package's state layout; u = 0 (eq. 3 decouples it).
    """
    k = np.arange(-params.N, params.N + 1)
    v, phi = solution(params, np.abs(k) * params.h, moment, D1=D1)
    x = np.zeros((3, params.n_particles))
    x[1] = np.sign(k) * v
    x[2] = phi
    return x


def discrete_residuals(params: ChainParams, moment: float = 1.0, *, D1: float | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Left-hand sides of the discrete eqs. (4) and (5) at the sampled continuum solution.

    Returns
    -------
    r4, r5 : ndarray, shape (2N+1,)
        Residues at particles -N..N. The clamped ends are 0; at particle 0, where
        the moment acts, r5 holds the residue of the moment balance (9) instead.
        Eq. (11) makes r4 vanish identically and r5 equal to :func:`residue` at
        every interior site.
    """
    coef = _coefficients(params, D1)
    _, v, phi = sampled_state(params, moment, D1=D1)
    h = coef.h
    r4 = np.zeros(params.n_particles)
    r5 = np.zeros(params.n_particles)
    r4[1:-1] = (v[2:] - 2 * v[1:-1] + v[:-2]) / h**2 - (phi[2:] - phi[:-2]) / (2 * h)
    r5[1:-1] = coef.D1 * (phi[2:] - 2 * phi[1:-1] + phi[:-2]) + coef.D2 * ((v[2:] - v[:-2]) / (2 * h) - phi[1:-1])
    centre = params.N
    r5[centre] = 2 * coef.b**2 * (2 * coef.D1 * (phi[centre + 1] - phi[centre]) + coef.D2 * (v[centre + 1] / h - phi[centre])) + moment
    return r4, r5


# ---------------------------------------------------------------- comparison with the discrete chain
def discrete_static(params: ChainParams, moment: float = 1.0) -> np.ndarray:
    """Static state (3, 2N+1) of the discrete linear model (iii) under the moment M on particle 0.

    Solves K q = M e_phi0 through K's square root (:func:`~cosserat_chain.models.linear.rest_solve`:
    K's condition number is about 4e16 at N = 10^4, 4e20 at 10^5, where a factor of its rounded
    entries loses the bending modes).
    """
    require_clamped(params, "the continuum comparison of Section 3")
    moment = _moment(moment)
    load = np.zeros((3, params.n_particles))
    load[2, params.N] = moment
    return unpack(params, rest_solve(params, pack(params, load)))


#: A discrete compliance off the chain's closed form by more than this (relative) is flagged inaccurate.
ACCURATE = 1e-6
#: Inverse-iteration steps for K's smallest eigenvalue (the next one is several times larger).
CONDITION_ITERATIONS = 8


@dataclass(frozen=True)
class ConvergenceTable:
    """Continuum against discrete compliance for a list of chain lengths.

    Attributes
    ----------
    N : ndarray of int, shape (n,)
    continuum : ndarray, shape (n,)
        phi(0) / M of the continuum solution.
    discrete : ndarray, shape (n,)
        phi_0 / M of the discrete linear model (iii).
    relative_error : ndarray, shape (n,)
        |continuum - discrete| / |discrete|.
    residue : ndarray, shape (n,)
        Residue (12) per unit moment.
    discrete_error : ndarray, shape (n,)
        Relative difference of ``discrete`` from the chain's phi_0 / M in closed form, the
        clamped Timoshenko beam with the nodal shear compliance
        (:func:`~cosserat_chain.analysis.beam.clamped_central_compliance`, equal to the chain
        in exact arithmetic): the discrete solve's own error. Beyond :data:`ACCURATE` the
        discrete value, and the relative error, are not to be trusted. A factorisation of K
        would not do as the check: K's softest eigenvalue falls like N^-4, and its factor
        loses that mode where the root solve keeps it.
    condition : ndarray, shape (n,)
        Condition number of K: its Gershgorin bound over its smallest eigenvalue (inverse
        iteration), within a factor of about two of the 2-norm one.
    """

    N: np.ndarray
    continuum: np.ndarray
    discrete: np.ndarray
    relative_error: np.ndarray
    residue: np.ndarray
    discrete_error: np.ndarray
    condition: np.ndarray

    @property
    def signed_error(self) -> np.ndarray:
        """(continuum - discrete) / discrete, with its sign.

        It changes sign for some geometries: for N = 2, 3, 5 and a = 0.3, b = 0.1,
        E1 = 2, E2 = 0.3 it is -3.1e-2, ~0, +2.3e-2, and for a = 0.254, b = 0.979,
        h = 1.805, E1 = 1.808, E2 = 0.056 it stays negative up to N = 100 and turns
        positive by N = 300; |error| ~ 1/N holds only once N is past the last change
        (``docs/continuum.md``).
        """
        return (self.continuum - self.discrete) / self.discrete

    @property
    def accurate(self) -> np.ndarray:
        """Rows whose discrete value is accurate to ACCURATE (see ``discrete_error``)."""
        return self.discrete_error <= ACCURATE

    def order(self) -> float:
        """Observed order p of relative_error ~ N^-p, from a least-squares fit on log-log axes over the accurate rows.

        Raises
        ------
        ValueError
            With fewer than two distinct accurate N or a zero error.
        """
        n, error = self.N[self.accurate], self.relative_error[self.accurate]
        if np.unique(n).size < 2 or np.any(error <= 0):
            raise ValueError("the order needs at least two distinct N with accurate discrete values and nonzero errors")
        return float(-np.polyfit(np.log(n), np.log(error), 1)[0])

    def as_dict(self) -> dict[str, list[float]]:
        """Columns as lists (for JSON)."""
        return {
            "N": [int(n) for n in self.N],
            "continuum": self.continuum.tolist(),
            "discrete": self.discrete.tolist(),
            "relative_error": self.relative_error.tolist(),
            "signed_error": self.signed_error.tolist(),
            "residue": self.residue.tolist(),
            "discrete_error": self.discrete_error.tolist(),
            "condition": self.condition.tolist(),
            "accurate": self.accurate.tolist(),
        }


#: Memory of the convergence table per degree of freedom of its longest chain (measured 1.1 kB, with a margin).
BYTES_PER_DOF = 1500


def convergence(params: ChainParams, n_values: list[int] | np.ndarray) -> ConvergenceTable:
    """Compliance phi_0 / M of the continuum solution and of the discrete chain for each N.

    Parameters
    ----------
    params : ChainParams
        Geometry and stiffnesses; its N is replaced by each of ``n_values``.
    n_values : sequence of int
        Half-lengths N >= 1.

    Raises
    ------
    ValueError
        For an empty list or an N below 1 (naming it), or a chain its closed form does not
        describe (graded, or E2 = 0).
    """
    n_values = [int(n) for n in n_values]
    if not n_values:
        raise ValueError("n_values must hold at least one N >= 1, got an empty list")
    chains = [params.replace(N=n) for n in n_values]
    largest = max(n_values)
    # Measured: about 1.1 kB per degree of freedom at its peak (the sparse K, its LU
    # factor and the square root of the condition estimate), at N = 10^5 and 4 10^5.
    require(
        BYTES_PER_DOF * 3 * (2 * largest + 1),
        f"the discrete chain of N = {largest} ({3 * (2 * largest + 1)} degrees of freedom, about {BYTES_PER_DOF} bytes each)",
        "compare shorter chains",
    )
    continuum = np.array([central_rotation(p) for p in chains])
    exact = np.array([clamped_central_compliance(p, nodal=True) for p in chains])
    discrete = np.array([discrete_static(p)[2, p.N] for p in chains])
    return ConvergenceTable(
        N=np.array(n_values),
        continuum=continuum,
        discrete=discrete,
        relative_error=np.abs(continuum - discrete) / np.abs(discrete),
        residue=np.array([residue(p) for p in chains]),
        discrete_error=np.abs(exact - discrete) / np.abs(discrete),
        condition=np.array([_condition(p) for p in chains]),
    )


def _condition(params: ChainParams) -> float:
    """K's condition number: its Gershgorin bound over its smallest eigenvalue."""
    # The smallest eigenvalue by inverse iteration with K's square root (O(N) a step; LAPACK's
    # banded eigensolver is O(N^2): benchmarks/TIMINGS.md; a factor of K's rounded entries
    # loses the softest mode from N of about 10^4 on), the largest bounded by Gershgorin.
    factor = RootFactor(*stiffness_root(params), n_free(params))
    vector = np.random.default_rng(0).standard_normal(n_free(params))
    lowest = math.inf
    for _ in range(CONDITION_ITERATIONS):
        vector = factor.solve(vector / np.linalg.norm(vector))
        lowest = 1.0 / np.linalg.norm(vector)
    highest = float(abs(stiffness_matrix(params)).sum(axis=1).max())
    return highest / lowest


@dataclass(frozen=True)
class ReducedChain:
    """The discrete reduced chain (eq. (3) with D1 = 0): positive definite, so its statics are unique.

    Attributes
    ----------
    params : ChainParams
        The chain with E1 = :func:`reduced_E1`, whose geometry-derived D1 vanishes.
    positive_definite : bool
        Whether K has a Cholesky factor (LAPACK's banded Cholesky), i.e. is positive definite.
    lowest_eigenvalue : float
        K's eigenvalue closest to 0 (shift-invert Lanczos about 0): the smallest one when
        ``positive_definite``.
    compliance : float
        phi_0 / M of the static state under a moment on particle 0 (SuperLU), unique when
        ``positive_definite``.
    continuum_compliance : float
        phi(0) / M of the paper's reduced solution (Section 3.2, alpha = 0 in :func:`reduced_family`).
    family_slope : float
        d phi(0) / d alpha of :func:`reduced_family`, L^2 (L - h)^2 / (2L - h): the continuum's
        freedom, which the discrete chain does not have.
    """

    params: ChainParams
    positive_definite: bool
    lowest_eigenvalue: float
    compliance: float
    continuum_compliance: float
    family_slope: float

    @property
    def matching_alpha(self) -> float | None:
        """The alpha of :func:`reduced_family` whose phi(0) equals the discrete chain's (None for N = 1, where none can)."""
        if self.family_slope == 0:
            return None
        return (self.compliance - self.continuum_compliance) / self.family_slope

    def as_dict(self) -> dict[str, float | bool | None]:
        """Plain numbers (for JSON), with the reduced E1 and ``matching_alpha``."""
        return {
            "E1": self.params.E1,
            "positive_definite": self.positive_definite,
            "lowest_eigenvalue": self.lowest_eigenvalue,
            "compliance": self.compliance,
            "continuum_compliance": self.continuum_compliance,
            "family_slope": self.family_slope,
            "matching_alpha": self.matching_alpha,
        }


def reduced_discrete(params: ChainParams) -> ReducedChain:
    """The discrete reduced chain of ``params``' geometry: K's definiteness and its unique static state.

    The discrete chain keeps the bending energy E1 b^2 (phi_k+1 - phi_k)^2 of each bond:
    D1 = E1 - (h/d)^2 E2 = 0 cancels it only against the coupling's own phi Laplacian in
    eq. (5). With E1 > 0 and E2 > 0 the energy of eq. (3) vanishes only at rest with the
    ends clamped, so K is positive definite and K q = M e_phi0 has one solution, unlike
    the reduced continuum model (:func:`reduced_family`).

    Raises
    ------
    ValueError
        For E2 = 0 (then E1 = 0 too: no chain), or a chain too large for memory.
    """
    require_clamped(params, "the discrete reduced chain of Section 3.2")
    if not params.E2 > 0:
        raise ValueError(f"the reduced chain needs E2 > 0 (its E1 = (h/d)^2 E2 must be > 0); got E2={params.E2!r}")
    require(
        BYTES_PER_DOF * 3 * params.n_particles,
        f"the reduced chain of N = {params.N} ({3 * params.n_particles} degrees of freedom, about {BYTES_PER_DOF} bytes each)",
        "use a shorter chain",
    )
    reduced = params.replace(E1=reduced_E1(params))
    stiffness = stiffness_matrix(reduced)
    try:
        la.cholesky_banded(upper_bands(stiffness))
        positive_definite = True
    except la.LinAlgError:
        positive_definite = False
    # Shift-invert about 0 finds the eigenvalue nearest 0 in a few iterations at any N
    # (the clamped chain's softest mode is far below the rest of the spectrum); a seeded
    # start vector makes the result the same to the last bit on every call.
    start = np.random.default_rng(0).standard_normal(stiffness.shape[0])
    lowest = spla.eigsh(stiffness.tocsc(), k=1, sigma=0.0, which="LM", v0=start, return_eigenvectors=False)[0]
    h, L = reduced.h, reduced.N * reduced.h
    return ReducedChain(
        params=reduced,
        positive_definite=positive_definite,
        lowest_eigenvalue=float(lowest),
        compliance=float(discrete_static(reduced)[2, reduced.N]),
        continuum_compliance=reduced_family_rotation(reduced),
        family_slope=L * L * (L - h) ** 2 / (2 * L - h),
    )


@dataclass(frozen=True)
class ProfileComparison:
    """Continuum solution (11) and discrete linear statics of one chain under one moment.

    Attributes
    ----------
    k : ndarray of int, shape (2N+1,)
        Particles -N..N.
    x : ndarray, shape (n_fine,)
        Fine grid over the whole chain, -L..L, in units of h (so that it shares the axis with k).
    v, phi : ndarray, shape (n_fine,)
        Continuum fields on ``x`` (mirror-extended).
    sampled : ndarray, shape (3, 2N+1)
        The continuum solution at the particles.
    discrete : ndarray, shape (3, 2N+1)
        The discrete static state.
    moment : float
    """

    k: np.ndarray
    x: np.ndarray
    v: np.ndarray
    phi: np.ndarray
    sampled: np.ndarray
    discrete: np.ndarray
    moment: float


def compare_profiles(params: ChainParams, moment: float = 1.0, *, n_fine: int = 401) -> ProfileComparison:
    """Continuum and discrete profiles v_k, phi_k of the chain under the moment on particle 0."""
    if n_fine < 2:
        raise ValueError(f"n_fine must be >= 2, got {n_fine!r}")
    length = params.N * params.h
    x = np.linspace(-length, length, n_fine)
    v, phi = solution(params, np.abs(x), moment)
    return ProfileComparison(
        k=np.arange(-params.N, params.N + 1),
        x=x / params.h,
        v=np.sign(x) * v,
        phi=phi,
        sampled=sampled_state(params, moment),
        discrete=discrete_static(params, moment),
        moment=float(moment),
    )
