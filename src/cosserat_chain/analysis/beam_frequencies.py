"""The finite chain's first natural frequencies against its Timoshenko beam's and eq. (6)'s.

Contract
--------
The linear chain's u decouples from (v, phi), so its modes come in two families: axial (u) and
flexural (v, phi). :func:`chain_frequencies` takes each family's lowest elastic modes of the
discrete chain (sparse shift-invert Lanczos on that family's stiffness, then the Rayleigh
quotient of each mode from its bond strains, whose error is the square of the shape's: the
stiffness matrix's own round-off, about N^4 eps relative for the softest flexural mode, never
enters it).

:func:`beam_frequencies` solves the finite beam's frequency equation. Below the beam's cut-off
sqrt(GA / rotary) (where its second spectrum begins) a flexural mode is
v = sum c_i f_i(x) over cos(a x), sin(a x), exp(-b (x + L)) and exp(b (x - L)), a and b the
oscillating and evanescent wavenumbers of omega (the decaying exponentials keep the 4 x 4
matrix of end conditions bounded at any length); the frequencies are the zeros of its
determinant, bracketed on a grid of a finer than the spacing of the modes and refined by
Brent's method. The chain's end particle carries half a particle more than the beam's last
half-bond, so an end that lets it move gets that much point inertia (m/2 and j/2) in its natural
conditions, right end: EI phi' = omega^2 (j/2) phi, GA (v' - phi) = omega^2 (m/2) v (the left
end's with the signs of the derivatives flipped). Axial modes are the same with cos and sin of
omega sqrt((m/h)/EA) x alone.

Eq. (6) with the inertia of eq. (3) is the same beam with the bending stiffness
2 b^2 D1 h = EI - GA h^2/4 (:mod:`cosserat_chain.analysis.dispersion`): its flexural frequencies
tend to sqrt(D1/E1) times the chain's as N grows (its error does not fall), and where D1 <= 0
(the paper's chain) it has none.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..numerics.brent import brentq
from ..params import ChainParams
from ..state import free_rows
from .beam import beam_stiffness
from .timoshenko import _fit_order, _half_lengths

#: The two families of modes of the linear chain.
FAMILIES = ("flexural", "axial")
#: Grid points of the bracketing scan per expected spacing of the modes.
SCAN_PER_MODE = 16


def _family_rows(params: ChainParams, family: str) -> np.ndarray:
    """Positions, in the stiffness matrix's order, of the family's free degrees of freedom."""
    rows = free_rows(params)
    return np.flatnonzero(rows == 0) if family == "axial" else np.flatnonzero(rows != 0)


def _require(params: ChainParams, family: str, count: int) -> None:
    if family not in FAMILIES:
        raise ValueError(f"family must be one of {', '.join(map(repr, FAMILIES))}, got {family!r}")
    if not (isinstance(count, int | np.integer) and count >= 1):
        raise ValueError(f"count (modes per family) must be an integer >= 1, got {count!r}")


def _rigid_in_family(params: ChainParams, family: str) -> int:
    """Rigid motions of the family: u translation (free ends, axial); v translation and rotation (flexural)."""
    both_free = params.ends == ("free", "free")
    if family == "axial":
        return int(both_free)
    return params.rigid_modes - int(both_free)


def _strain_energy(params: ChainParams, u: np.ndarray, v: np.ndarray, phi: np.ndarray) -> float:
    """sum of the bond energies k_u du^2/2 + E1 b^2 dphi^2 + k_v (dv - h (phi_k + phi_k+1)/2)^2 / 2, from the strains."""
    shear = np.diff(v) - params.h * (phi[1:] + phi[:-1]) / 2
    return float(
        0.5 * params.k_u * np.sum(np.diff(u) ** 2)
        + params.E1 * params.b**2 * np.sum(np.diff(phi) ** 2)
        + 0.5 * params.k_v * np.sum(shear**2)
    )


def chain_frequencies(params: ChainParams, count: int = 3, family: str = "flexural") -> np.ndarray:
    """The ``count`` lowest elastic angular frequencies of the discrete linear chain's ``family`` (module docstring).

    Parameters
    ----------
    params : ChainParams
        A uniform open chain (any ends, rigid motions left out).
    count : int
        Modes to return.
    family : {"flexural", "axial"}

    Raises
    ------
    ValueError
        For a bad family or count, a ring or a graded chain, or a chain with fewer modes.
    """
    import scipy.sparse as sp
    import scipy.sparse.linalg as spla

    from ..models.linear import stiffness_matrix
    from ..state import pack, unpack

    _require(params, family, count)
    stiffness = beam_stiffness(params)
    rows = _family_rows(params, family)
    rigid = _rigid_in_family(params, family)
    if count + rigid > rows.size - 1:
        raise ValueError(f"count = {count} asks for more {family} modes than the chain of N = {params.N} has ({rows.size - 1 - rigid})")
    K = stiffness_matrix(params).tocsr()[rows][:, rows]
    mass_all = pack(params, params.particle_inertia)
    mass = mass_all[rows]
    # A shift below zero keeps the factorisation regular where rigid motions make K singular.
    L = params.N * params.h
    if family == "axial":
        scale = stiffness.EA / stiffness.mass * (math.pi / (4 * L)) ** 2
    else:
        scale = stiffness.EI / stiffness.mass * (math.pi / (2 * L)) ** 4
    wanted = count + rigid
    if rows.size < 60:
        import scipy.linalg as sla

        _, vectors = sla.eigh(K.toarray(), np.diag(mass))
        vectors = vectors[:, :wanted]
    else:
        # A fixed start: ARPACK's own is random, and the modes' last digits would change from run to run.
        start = np.random.default_rng(0).standard_normal(rows.size)
        _, vectors = spla.eigsh(K.tocsc(), k=wanted, M=sp.diags(mass).tocsc(), sigma=-0.01 * scale, which="LM", v0=start)
    omega2 = []
    for vector in vectors.T:
        flat = np.zeros(mass_all.size)
        flat[rows] = vector
        u, v, phi = unpack(params, flat)
        omega2.append(2 * _strain_energy(params, u, v, phi) / float(vector @ (mass * vector)))
    omega2 = np.sort(np.array(omega2))[rigid:]
    return np.sqrt(np.maximum(omega2, 0.0))


def _end_matrix(
    params: ChainParams, omega: float, a: float, b: float, EI: float, GA: float, end_mass: float, end_rotary: float
) -> np.ndarray:
    """The 4 x 4 matrix of the flexural end conditions, columns the four basis functions (module docstring)."""
    L = params.N * params.h
    mu = beam_stiffness(params).mass
    ratio = mu * omega**2 / GA
    # v, v', phi, phi' of each basis function at x = -L and x = L.
    values = {}
    for x in (-L, L):
        c, s = math.cos(a * x), math.sin(a * x)
        left, right = math.exp(-b * (x + L)), math.exp(b * (x - L))
        pa, pb = (ratio - a * a) / a, (ratio + b * b) / b
        values[x] = np.array(
            [
                [c, s, left, right],
                [-a * s, a * c, -b * left, b * right],
                [pa * s, -pa * c, -pb * left, pb * right],
                [pa * a * c, pa * a * s, pb * b * left, pb * b * right],
            ]
        )
    conditions = []
    for kind, x, sign in ((params.left_end, -L, -1.0), (params.right_end, L, 1.0)):
        v, dv, phi, dphi = values[x]
        moment = EI * dphi - sign * omega**2 * end_rotary * phi
        shear = GA * (dv - phi) - sign * omega**2 * end_mass * v
        conditions.extend({"clamped": (v, phi), "pinned": (v, moment), "free": (moment, shear)}[kind])
    return np.array(conditions)


def _flexural_omega(a: float, EI: float, GA: float, mu: float, rho: float) -> tuple[float, float]:
    """omega and the evanescent b of the oscillating wavenumber a on the beam's acoustic branch (b NaN above the cut-off).

    The wavenumbers s of exp(s x) solve GA EI s^4 + omega^2 (GA rho + mu EI) s^2 + mu omega^2 (rho omega^2 - GA) = 0;
    with s^2 = -a^2 that is a quadratic in omega^2 whose lower root is the acoustic branch, and
    the other s^2 is b^2 = mu omega^2 (GA - rho omega^2) / (GA EI a^2).
    """
    B = a * a * (GA * rho + mu * EI) + mu * GA
    C = GA * EI * a**4
    omega2 = 2 * C / (B + math.sqrt(B * B - 4 * mu * rho * C))
    b2 = mu * omega2 * (GA - rho * omega2) / (GA * EI * a * a)
    return math.sqrt(omega2), (math.sqrt(b2) if b2 > 0 else math.nan)


def beam_frequencies(params: ChainParams, count: int = 3, family: str = "flexural", *, bending: float | None = None) -> np.ndarray:
    """The ``count`` lowest elastic angular frequencies of the chain's finite Timoshenko beam (module docstring).

    Parameters
    ----------
    params : ChainParams
        A uniform open chain (any ends that hold it or not; the beam's rigid motions are left out).
    count : int
    family : {"flexural", "axial"}
    bending : float, optional
        The bending stiffness to use instead of EI = 2 E1 b^2 h: ``2 b^2 D1 h`` gives eq. (6).

    Raises
    ------
    ValueError
        For a bad family or count, a ring, a graded chain or E2 = 0, a bending stiffness <= 0, or
        a mode above the beam's cut-off sqrt(GA / rotary) (ask for fewer).
    """

    _require(params, family, count)
    beam = beam_stiffness(params)
    L, h = params.N * params.h, params.h
    EI = beam.EI if bending is None else float(bending)
    if not EI > 0:
        raise ValueError(f"bending (the beam's bending stiffness) must be > 0, got {EI!r}: with D1 <= 0 eq. (6) has no real frequencies")
    end_mass, end_rotary = params.m / 2, params.j / 2
    spacing = math.pi / (2 * L)  # the modes' wavenumbers are about this far apart
    if family == "axial":
        speed = math.sqrt(beam.EA / beam.mass)

        def determinant(a: float) -> float:
            omega = a * speed
            rows = []
            for kind, x, sign in ((params.left_end, -L, -1.0), (params.right_end, L, 1.0)):
                c, s = math.cos(a * x), math.sin(a * x)
                if kind == "free":
                    rows.append([beam.EA * -a * s - sign * omega**2 * end_mass * c, beam.EA * a * c - sign * omega**2 * end_mass * s])
                else:
                    rows.append([c, s])
            return float(np.linalg.det(np.array(rows)))

        def frequency(a: float) -> float:
            return a * speed

        limit = math.inf
    else:

        def determinant(a: float) -> float:
            omega, b = _flexural_omega(a, EI, beam.GA, beam.mass, beam.rotary)
            return float(np.linalg.det(_end_matrix(params, omega, a, b, EI, beam.GA, end_mass, end_rotary)))

        def frequency(a: float) -> float:
            return _flexural_omega(a, EI, beam.GA, beam.mass, beam.rotary)[0]

        limit = math.sqrt(beam.GA / beam.rotary)
    step = spacing / SCAN_PER_MODE
    roots: list[float] = []
    a, value = step / 4, determinant(step / 4)
    while len(roots) < count:
        if frequency(a + step) >= limit:
            raise ValueError(
                f"the beam's {family} mode {len(roots) + 1} lies above its cut-off sqrt(GA / rotary) = {limit:.6g} at N = {params.N} "
                f"(h = {h!r}): ask for fewer modes or a longer chain"
            )
        following = determinant(a + step)
        if value == 0.0 or value * following < 0:
            root = a if value == 0.0 else brentq(determinant, a, a + step, xtol=1e-15 * (a + step), rtol=4 * np.finfo(float).eps)
            roots.append(frequency(root))
        a, value = a + step, following
    return np.array(roots)


@dataclass(frozen=True)
class FrequencyConvergence:
    """The first frequencies of the chain, its Timoshenko beam and eq. (6), per N.

    Attributes
    ----------
    N : ndarray of int, shape (n,)
    family : str
    chain, timoshenko, paper : ndarray, shape (n, count)
        Angular frequencies; ``paper`` (eq. (6)) NaN where D1 <= 0.
    """

    N: np.ndarray
    family: str
    chain: np.ndarray
    timoshenko: np.ndarray
    paper: np.ndarray

    @property
    def timoshenko_error(self) -> np.ndarray:
        """(beam - chain) / chain, with its sign, shape (n, count)."""
        return (self.timoshenko - self.chain) / self.chain

    @property
    def paper_error(self) -> np.ndarray:
        """(eq. (6) - chain) / chain, NaN where eq. (6) has no real frequencies."""
        return (self.paper - self.chain) / self.chain

    def orders(self, which: str = "timoshenko", *, since: int = 1) -> list[float | None]:
        """The measured order p of |error| ~ N^-p of each mode over N >= ``since`` (None where it cannot be fitted)."""
        if which not in ("timoshenko", "paper"):
            raise ValueError(f"which must be 'timoshenko' or 'paper', got {which!r}")
        error = self.timoshenko_error if which == "timoshenko" else self.paper_error
        keep = self.N >= since
        return [_fit_order(self.N[keep], error[keep, mode]) for mode in range(error.shape[1])]

    def as_dict(self) -> dict[str, object]:
        """Columns as nested lists and the orders (for JSON); NaN becomes None."""

        def table(values: np.ndarray) -> list[list[float | None]]:
            return [[float(v) if math.isfinite(v) else None for v in row] for row in values]

        return {
            "N": [int(n) for n in self.N],
            "family": self.family,
            "chain": table(self.chain),
            "timoshenko": table(self.timoshenko),
            "paper": table(self.paper),
            "timoshenko_error": table(self.timoshenko_error),
            "paper_error": table(self.paper_error),
            "timoshenko_order": self.orders("timoshenko"),
            "paper_order": self.orders("paper"),
        }


def frequency_convergence(
    params: ChainParams, n_values: list[int] | np.ndarray, *, count: int = 3, family: str = "flexural"
) -> FrequencyConvergence:
    """The first ``count`` frequencies of the chain, its Timoshenko beam and eq. (6) for each N (its ends as in ``params``).

    Raises
    ------
    ValueError
        For an empty list or an N below 1, and as :func:`chain_frequencies` and :func:`beam_frequencies`.
    """
    _require(params, family, count)
    n_values = _half_lengths(n_values)
    chain, beam, paper = [], [], []
    bending = 2 * params.b**2 * params.D1 * params.h
    for n in n_values:
        sized = params.replace(N=n)
        chain.append(chain_frequencies(sized, count, family))
        beam.append(beam_frequencies(sized, count, family))
        if family == "axial":
            paper.append(beam[-1])  # eq. (6)'s axial equation is the beam's
        elif bending > 0:
            paper.append(beam_frequencies(sized, count, family, bending=bending))
        else:
            paper.append(np.full(count, math.nan))
    return FrequencyConvergence(np.array(n_values), family, np.array(chain), np.array(beam), np.array(paper))
