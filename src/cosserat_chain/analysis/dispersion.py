"""Waves in the chain: dispersion of the infinite linear chain, its continuum limit, and the finite chain's modes.

Contract
--------
*Infinite chain.* A wave exp(i (q k - omega t)) of eq. (3) (wavenumber q per
particle, -pi <= q <= pi) has (u, v, phi) amplitudes that solve
(B(q) - omega^2 diag(m, m, j)) a = 0 with the Bloch stiffness B(q) of
:func:`cosserat_chain.models.linear.bloch_stiffness`. With s2 = 4 sin^2(q/2),
u decouples, omega_L^2 = k_u s2 / m (longitudinal), and v, phi form the 2 x 2
problem

    | k_v s2 - m w^2           i k_v h sin q             |
    | -i (couple/h) sin q      bend s2 + couple - j w^2  | = 0,

bend = 2 b^2 D1, couple = 2 b^2 D2, whose two roots are the transverse-acoustic
branch (omega -> 0 at q -> 0) and the rotational-optical branch. Its determinant
is k_v s2^2 (bend + couple/4) = 2 b^2 E1 k_v s2^2, so the chain at rest is stable
for every geometry. Closed-form limits: omega_L ~ q sqrt(k_u/m),
omega_TA ~ q^2 b sqrt(2 E1/m) / h, omega_RO(0) = sqrt(couple/j); at q = pi the
branches decouple into 2 sqrt(k_u/m), 2 sqrt(k_v/m) and sqrt(8 b^2 E1/j).
These are the uniform chain's: a graded chain (per-bond or per-particle factors) is not
periodic and has no bands, and :func:`dispersion`, :func:`continuum_dispersion`,
:func:`wave_summary` and :func:`parameter_scan` refuse it, naming the factors
(:func:`require_uniform`); :func:`finite_modes` takes it.

*Continuum.* Eq. (6) with the inertia of eq. (3) (m v_tt = k_v h^2 (v_xx - phi_x),
j phi_tt = 2 b^2 (h^2 D1 phi_xx + D2 (v_x - phi))) is the same problem with
s2 -> q^2 and sin q -> q. Its acoustic branch tends to omega^2 ~ 2 b^2 D1 q^4/(m h^2):
the long-wave equations (6) give the flexural stiffness D1 where the chain has
E1 = D1 + D2/4, and for D1 < 0 (the paper's chain) that branch is imaginary
(``Dispersion.omega`` is NaN there).

*Finite chain.* :func:`finite_modes` solves K a = omega^2 M a over the
free degrees of freedom for the stiffness -dF/dq of any model at any state; the
sine model's Jacobian is not symmetric there (erratum 4), so non-conservative
models go through a general eigen solver. Viscosity is left out: these are the
undamped frequencies.

*Rigid modes.* A chain its ends do not hold moves rigidly
(:attr:`~cosserat_chain.params.ChainParams.rigid_modes`): free ends translate in u
and v and rotate, a pinned end with a free one rotates about the pin, a ring
translates. :func:`rigid_motions` builds these infinitesimal motions about the state
(a rotation by theta moves particle k by theta (-(v_k - v_c), (k - c) h + u_k - u_c)
about the pin or the middle particle c, and turns every particle by theta); those K
annihilates to round-off (:data:`RIGID_RTOL`: every one of them for every model at
rest, checked by the tests) are split off exactly: their omega^2 is 0, not the
+-1e-15 of round-off, whose negative half made NaN frequencies and "unstable"
chains at rest, and the elastic modes are solved on the complement.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import scipy.linalg as sla
import scipy.sparse as sp
from scipy.optimize import minimize_scalar
from scipy.sparse.csgraph import reverse_cuthill_mckee

from ..linalg import band_eigenpairs, upper_bands
from ..models.base import Model, get_model
from ..models.linear import cosserat_coefficients
from ..params import BOND_FACTORS, PARTICLE_FACTORS, ChainParams
from ..state import ROW_INDEX, check_state, free_index, pack, zeros

#: A rigid motion r with |K r| <= RIGID_RTOL |K| |r| (infinity norms) is a zero mode of the chain.
RIGID_RTOL = 1e-12
#: The three branches, in the row order of ``Dispersion.omega2``.
BRANCHES = ("longitudinal", "transverse_acoustic", "rotational_optical")


@dataclass(frozen=True)
class Dispersion:
    """Branches omega(q) of the infinite chain (discrete or continuum).

    Attributes
    ----------
    q : ndarray, shape (n_q,)
        Wavenumbers per particle (radians; the Brillouin zone is [-pi, pi]).
    omega2 : ndarray, shape (3, n_q)
        Squared angular frequencies, rows in the order of :data:`BRANCHES`; negative
        where the continuum equations are unstable.
    kind : str
        ``"discrete"`` (eq. 3) or ``"continuum"`` (eq. 6).
    """

    q: np.ndarray
    omega2: np.ndarray
    kind: str

    @property
    def omega(self) -> np.ndarray:
        """Angular frequencies (3, n_q); NaN where omega^2 < 0."""
        return np.sqrt(np.where(self.omega2 >= 0, self.omega2, np.nan))


def _wavenumbers(q: np.ndarray | float | None, n_q: int) -> np.ndarray:
    if q is None:
        if n_q < 2:
            raise ValueError(f"n_q must be >= 2, got {n_q!r}")
        return np.linspace(0.0, np.pi, n_q)
    q = np.atleast_1d(np.asarray(q, dtype=float))
    if q.ndim != 1 or not np.all(np.isfinite(q)):
        raise ValueError(f"q must be a finite number or 1-D array of wavenumbers per particle, got {q!r}")
    return q


def _branches(params: ChainParams, s2: np.ndarray, sin2: np.ndarray, det: np.ndarray) -> np.ndarray:
    """Roots of the u equation and of the v-phi 2 x 2 problem, without cancellation.

    ``det`` is the determinant of the v-phi stiffness, passed in factored form
    because k_v s2 (bend s2 + couple) - k_v couple sin^2 q loses all digits at small q.
    """
    k_u, k_v, _, bend, couple = cosserat_coefficients(params)
    m, j = params.m, params.j
    a = k_v * s2 / m
    c = (bend * s2 + couple) / j
    upper = 0.5 * (a + c) + np.sqrt(0.25 * (a - c) ** 2 + k_v * couple * sin2 / (m * j))
    lower = np.divide(det / (m * j), upper, out=np.zeros_like(upper), where=upper != 0)
    return np.vstack([k_u * s2 / m, lower, upper])


def require_uniform(params: ChainParams, what: str) -> None:
    """Refuse a graded chain where ``what`` is a property of the infinite uniform chain.

    A graded or disordered chain (``E1_factors``, ``E2_factors``, ``m_factors``, ``j_factors``)
    is not periodic: it has no Bloch waves, and the scalar fields alone would give the
    uniform chain's bands as if they were its own. Its own small oscillations are
    :func:`finite_modes`.

    Raises
    ------
    ValueError
        Naming each factor field given, its number of factors and their range.
    """
    given = [name for name in (*BOND_FACTORS, *PARTICLE_FACTORS) if getattr(params, name) is not None]
    if given:
        fields = ", ".join(
            f"{name} ({len(getattr(params, name))} factors in [{min(getattr(params, name)):.6g}, {max(getattr(params, name)):.6g}])"
            for name in given
        )
        raise ValueError(
            f"{what} is that of the infinite uniform chain, but this chain is graded: {fields}; a graded chain is not "
            "periodic and has no bands: finite_modes(params) gives its modes, or leave the factors out "
            f"(params.replace({', '.join(f'{name}=None' for name in given)})) for the uniform chain's bands"
        )


def dispersion(params: ChainParams, q: np.ndarray | float | None = None, *, n_q: int = 257) -> Dispersion:
    """Dispersion branches of the infinite linear chain, eq. (3) with derived coefficients.

    Parameters
    ----------
    params : ChainParams
        N is irrelevant here.
    q : float or ndarray, optional
        Wavenumbers per particle; default ``n_q`` points over [0, pi].
    n_q : int

    Returns
    -------
    Dispersion
        With ``kind="discrete"``; the branches are sorted (acoustic below optical).

    Raises
    ------
    ValueError
        For a graded chain (:func:`require_uniform`), or wavenumbers that are not finite.
    """
    require_uniform(params, "the dispersion")
    q = _wavenumbers(q, n_q)
    _, k_v, _, bend, couple = cosserat_coefficients(params)
    s2 = 4.0 * np.sin(q / 2) ** 2
    det = k_v * s2**2 * (bend + couple / 4)
    return Dispersion(q, _branches(params, s2, np.sin(q) ** 2, det), "discrete")


def continuum_dispersion(params: ChainParams, q: np.ndarray | float | None = None, *, n_q: int = 257) -> Dispersion:
    """Dispersion of the continuum equations (6) with inertia (see the module docstring).

    ``q`` is the continuum wavenumber times h, so that it shares the axis with
    :func:`dispersion`. Uses the geometry-derived D1 and D2. A graded chain is refused
    (:func:`require_uniform`).
    """
    require_uniform(params, "the continuum dispersion")
    q = _wavenumbers(q, n_q)
    _, k_v, _, bend, _ = cosserat_coefficients(params)
    return Dispersion(q, _branches(params, q**2, q**2, k_v * bend * q**4), "continuum")


@dataclass(frozen=True)
class WaveSummary:
    """Cut-off frequencies, bands and gaps of the infinite linear chain.

    Attributes
    ----------
    at_zero, at_pi : dict
        Angular frequency of each branch (:data:`BRANCHES`) at q = 0 and q = pi.
    bands : dict
        (lowest, highest) frequency of each branch over the Brillouin zone.
    gap : tuple of float or None
        (top of the transverse-acoustic band, bottom of the rotational-optical band):
        no transverse or rotational wave propagates in between. None if they overlap.
    complete_gaps : tuple of tuples
        Frequency intervals where no branch at all propagates (longitudinal waves
        included, which decouple in eq. (3) and often fill ``gap``).
    """

    at_zero: dict[str, float]
    at_pi: dict[str, float]
    bands: dict[str, tuple[float, float]]
    gap: tuple[float, float] | None
    complete_gaps: tuple[tuple[float, float], ...]

    def as_dict(self) -> dict[str, object]:
        """Plain types (for JSON)."""
        return {
            "at_zero": dict(self.at_zero),
            "at_pi": dict(self.at_pi),
            "bands": {name: list(band) for name, band in self.bands.items()},
            "gap": list(self.gap) if self.gap else None,
            "gap_width": self.gap[1] - self.gap[0] if self.gap else 0.0,
            "complete_gaps": [list(g) for g in self.complete_gaps],
        }


def _extreme(params: ChainParams, branch: int, grid: np.ndarray, values: np.ndarray, sign: float) -> float:
    """Largest (sign=+1) or smallest (sign=-1) omega of a branch: grid search, then refined between neighbours."""
    i = int(np.argmax(sign * values))
    best = values[i]
    if 0 < i < grid.size - 1:
        result = minimize_scalar(
            lambda q: -sign * float(dispersion(params, q).omega[branch, 0]),
            bounds=(grid[i - 1], grid[i + 1]),
            method="bounded",
            options={"xatol": 1e-12},
        )
        best = sign * max(sign * best, -float(result.fun))
    return float(best)


def wave_summary(params: ChainParams, *, n_q: int = 1025) -> WaveSummary:
    """Cut-offs at q = 0 and q = pi, band edges and gaps of the infinite linear chain.

    Parameters
    ----------
    params : ChainParams
    n_q : int
        Grid over [0, pi] for locating band edges inside the zone; each is then
        refined to about 1e-12 in q.

    Raises
    ------
    ValueError
        For a graded chain (:func:`require_uniform`).
    """
    require_uniform(params, "the wave summary")
    curves = dispersion(params, n_q=n_q)
    omega = curves.omega
    at_zero = dict(zip(BRANCHES, omega[:, 0].tolist()))
    at_pi = dict(zip(BRANCHES, omega[:, -1].tolist()))
    bands = {
        name: (_extreme(params, b, curves.q, omega[b], -1.0), _extreme(params, b, curves.q, omega[b], 1.0))
        for b, name in enumerate(BRANCHES)
    }
    acoustic, optical = bands["transverse_acoustic"], bands["rotational_optical"]
    gap = (acoustic[1], optical[0]) if acoustic[1] < optical[0] else None
    holes = []
    reach = 0.0
    for low, high in sorted(bands.values()):
        if low > reach:
            holes.append((reach, low))
        reach = max(reach, high)
    return WaveSummary(at_zero, at_pi, bands, gap, tuple(holes))


def parameter_scan(params: ChainParams, field: str, values: np.ndarray | list[float]) -> dict[str, np.ndarray]:
    """Cut-off frequencies and the band gap as functions of one parameter.

    Parameters
    ----------
    params : ChainParams
        The other parameters (including j, which is not re-derived when a, b or m change).
    field : str
        A field of :class:`ChainParams` other than N.
    values : sequence of float

    Returns
    -------
    dict of ndarray, each of shape (len(values),)
        ``value``; ``<branch>_at_zero`` and ``<branch>_at_pi`` for each branch;
        ``gap_lower``, ``gap_upper`` and ``gap_width`` (NaN, NaN, 0 where there is no gap).

    Raises
    ------
    ValueError
        For a graded chain (:func:`require_uniform`), an unknown field, or a value the parameters do not allow (naming it).
    """
    require_uniform(params, "the parameter scan")
    allowed = [name for name in ChainParams.model_fields if name != "N"]
    if field not in allowed:
        raise ValueError(f"field must be one of {allowed}, got {field!r}")
    values = np.asarray(values, dtype=float)
    out: dict[str, list[float]] = {"value": []}
    for value in values:
        summary = wave_summary(params.replace(**{field: float(value)}))
        out["value"].append(float(value))
        for name in BRANCHES:
            out.setdefault(f"{name}_at_zero", []).append(summary.at_zero[name])
            out.setdefault(f"{name}_at_pi", []).append(summary.at_pi[name])
        lower, upper = summary.gap if summary.gap else (math.nan, math.nan)
        out.setdefault("gap_lower", []).append(lower)
        out.setdefault("gap_upper", []).append(upper)
        out.setdefault("gap_width", []).append(upper - lower if summary.gap else 0.0)
    return {key: np.array(column) for key, column in out.items()}


@dataclass(frozen=True)
class Modes:
    """Small oscillations of the finite clamped chain about a state.

    Attributes
    ----------
    omega2 : ndarray, complex, shape (n,)
        Eigenvalues omega^2 of M^-1 K: the ``rigid`` rigid modes' zeros first, then the
        others sorted by real part; real (zero imaginary part) for conservative models.
    shapes : ndarray, shape (n, 3, 2N+1)
        Mode shapes in the state layout (zero clamped ends), normalised to
        a^H M a = 1 with the largest component real and positive; complex only
        when a non-conservative model has complex eigenvalues.
    model : str
    rigid : int
        Rigid modes split off (:func:`rigid_motions`): the first ``rigid`` entries, omega^2 = 0 exactly.
    """

    omega2: np.ndarray
    shapes: np.ndarray
    model: str
    rigid: int = 0

    @property
    def frequencies(self) -> np.ndarray:
        """Angular frequencies sqrt(omega^2) (radians per unit time), NaN for unstable or complex eigenvalues.

        :meth:`~cosserat_chain.loads.Schedule.harmonic` takes cycles per unit time: drive a
        mode with ``frequency = omega / (2 pi)``.
        """
        scale = max(float(np.max(np.abs(self.omega2))), 1.0) if self.omega2.size else 1.0
        real = np.abs(self.omega2.imag) <= 1e-9 * scale
        return np.where(real & (self.omega2.real >= 0), np.sqrt(np.abs(self.omega2.real)), np.nan)

    @property
    def stable(self) -> bool:
        """Whether every eigenvalue is real and non-negative (the state is a stable equilibrium)."""
        return bool(np.all(np.isfinite(self.frequencies)))


def rigid_motions(params: ChainParams, x: np.ndarray | None = None) -> np.ndarray:
    """The infinitesimal rigid motions the chain's ends leave free, about the state ``x`` (default rest).

    Parameters
    ----------
    params : ChainParams
    x : ndarray, shape (3, 2N+1), optional

    Returns
    -------
    ndarray, shape (params.rigid_modes, n_free)
        In matrix order (:func:`~cosserat_chain.state.pack`): the u and v translations
        (free ends, a ring), then the rotation (free ends: about the middle particle; a
        pinned end with a free one: about the pin). Not normalised.
    """
    x = np.zeros((3, params.n_particles)) if x is None else check_state(params, x)
    if params.rigid_modes == 0:
        return np.zeros((0, len(free_index(params))))
    motions = []
    if params.periodic or params.ends == ("free", "free"):
        for row in ("u", "v"):
            shift = zeros(params)
            shift[ROW_INDEX[row]] = 1.0
            motions.append(shift)
    if not params.periodic:
        centre = 0 if params.left_end == "pinned" else params.n_particles - 1 if params.right_end == "pinned" else params.N
        k = np.arange(params.n_particles)
        u, v = x[ROW_INDEX["u"]], x[ROW_INDEX["v"]]
        turn = zeros(params)
        turn[ROW_INDEX["u"]] = -(v - v[centre])
        turn[ROW_INDEX["v"]] = (k - centre) * params.h + u - u[centre]
        turn[ROW_INDEX["phi"]] = 1.0
        motions.append(turn)
    return np.array([pack(params, m) for m in motions])


def finite_modes(params: ChainParams, model: str | Model = "linear", x: np.ndarray | None = None) -> Modes:
    """Eigenfrequencies and mode shapes of the chain (any ends, or a ring) linearised about ``x``.

    Parameters
    ----------
    params : ChainParams
    model : str or Model
        ``"linear"``, ``"sine"``, ``"nonlinear"`` or a registered model.
    x : ndarray, shape (3, 2N+1), optional
        State to linearise about, e.g. a static state under a load (constant loads
        do not change the Jacobian); default rest.

    Returns
    -------
    Modes

    Raises
    ------
    ValueError
        For an unknown model or a state of the wrong shape, not finite, or not zero where
        the ends hold it.

    Notes
    -----
    A conservative model's modes come from its symmetric band matrix, without a dense one
    (:func:`~cosserat_chain.linalg.band_eigenpairs`: O((6N)^2) with the eigenvectors; a ring's
    rows reordered into a band); a non-conservative model's (eq. (2)) from the dense
    eigen solver, O((6N)^3), fine up to N of a few hundred. A chain that can
    move rigidly (``ChainParams.rigid_modes``: free ends, a ring) has that many zero
    frequencies, its rigid motions (:func:`rigid_motions`), given omega^2 = 0 exactly and
    listed first (``Modes.rigid``) where K annihilates them.
    """
    model = get_model(model)
    x = np.zeros((3, params.n_particles)) if x is None else check_state(params, x)
    stiffness = model.stiffness(params, x).tocsr()
    mass = pack(params, params.particle_inertia)
    root = 1.0 / np.sqrt(mass)
    scaled = (sp.diags(root) @ stiffness @ sp.diags(root)).tocsr()  # M^-1/2 K M^-1/2, similar to M^-1 K
    motions = rigid_motions(params, x)
    scale = max(float(abs(stiffness).max()), np.finfo(float).tiny)
    zero = [r for r in motions if np.max(np.abs(stiffness @ r)) <= RIGID_RTOL * scale * np.max(np.abs(r))]
    # An orthonormal basis Q_r of the rigid modes in the mass-scaled space: S Q_r = 0, and the
    # elastic modes are S's on its complement.
    n_rigid = len(zero)
    rigid = (np.array(zero) / root[None, :]).T if n_rigid else np.zeros((mass.size, 0))
    rigid_basis = sla.qr(rigid, mode="economic")[0] if n_rigid else rigid
    if model.conservative:
        elastic, elastic_vectors = _banded_modes(0.5 * (scaled + scaled.T), rigid_basis)
        elastic = elastic.astype(complex)
    else:
        # A full basis [Q_r, P]: S = [[0, X], [0, Y]] in it, and the elastic modes are Y's.
        basis = sla.qr(rigid)[0] if n_rigid else np.eye(mass.size)
        complement = basis[:, n_rigid:]
        dense = scaled.toarray()
        elastic, z = sla.eig(complement.T @ dense @ complement)
        order = np.argsort(elastic.real, kind="stable")
        elastic, z = elastic[order], z[:, order]
        coupling = rigid_basis.T @ dense @ complement
        # The rigid part of an elastic mode: X z / mu (none where mu is zero).
        mixed = np.divide(coupling @ z, elastic, out=np.zeros((n_rigid, z.shape[1]), dtype=complex), where=elastic != 0)
        elastic_vectors = rigid_basis @ mixed + complement @ z
    eigenvalues = np.concatenate([np.zeros(n_rigid, dtype=complex), elastic])
    vectors = root[:, None] * np.hstack([rigid_basis, elastic_vectors])
    vectors = vectors / np.sqrt(np.einsum("ij,i,ij->j", vectors.conj(), mass, vectors).real)
    # A deterministic sign (phase): the largest component of each mode real and positive.
    largest = vectors[np.argmax(np.abs(vectors), axis=0), np.arange(vectors.shape[1])]
    vectors = vectors * (np.abs(largest) / largest)
    if model.conservative:
        vectors = vectors.real
    # Columns of ``vectors`` are in pack order (:func:`~cosserat_chain.state.free_index`).
    flat = np.zeros((vectors.shape[1], 3 * params.n_particles), dtype=vectors.dtype)
    flat[:, free_index(params)] = vectors.T
    shapes = np.ascontiguousarray(flat.reshape(-1, params.n_particles, 3).transpose(0, 2, 1))
    return Modes(eigenvalues, shapes, model.name, n_rigid)


def _banded_modes(scaled: sp.csr_matrix, rigid_basis: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The eigenpairs of the symmetric sparse ``scaled`` off the span of ``rigid_basis``, by :func:`band_eigenpairs`.

    Its rows are first ordered by reverse Cuthill-McKee: an open chain's matrix keeps its band
    (half-bandwidth 5), a ring's closing bond, which couples the first and the last particle,
    comes within a band of half-bandwidth 8 (the particles taken alternately from both ends).
    """
    order = reverse_cuthill_mckee(scaled, symmetric_mode=True)
    values, vectors = band_eigenpairs(upper_bands(scaled[order][:, order]), rigid_basis[order])
    unpermuted = np.empty_like(vectors)
    unpermuted[order] = vectors
    return values, unpermuted
