"""The Timoshenko beam of the linear chain: a continuum whose statics converge to the chain's like 1/N^2.

Contract
--------
The linear chain's bond energy (``models.linear``) written with the strains at the bond's
centre,

    P_bond = k_u/2 du^2 + E1 b^2 dphi^2 + k_v/2 (dv - h (phi_k + phi_k+1)/2)^2,

is, with u, v, phi smooth fields sampled at x = k h, h times the energy density of a
Timoshenko beam

    EI/2 phi_x^2 + GA/2 (v_x - phi)^2 + EA/2 u_x^2,
    EI = 2 E1 b^2 h,   GA = k_v h = 8 (b^2/d^2) E2 h,   EA = k_u h,

to leading order in h (derived in :func:`cosserat_chain.analysis.symbolic.timoshenko_derivation`).
EI is positive for every geometry, where the paper's eq. (6) has h^2 D1 = h^2 (E1 - (h/d)^2 E2),
negative for the paper's chain: D1 appears only when the bond-centred shear is written at the
particle, 2 b^2 D1 = EI/h - GA h/4.

More holds: the chain is, at its particles and exactly, the Timoshenko beam whose shear
compliance is 1/GA - h^2/(12 EI) (:attr:`BeamStiffness.nodal_shear_compliance`). Between two
loaded particles the beam's shear force Q is constant and its bending moment linear, so phi is
a quadratic whose mean over the bond is (phi_k + phi_k+1)/2 + h^2 Q/(12 EI); the bond's shear
strain dv/h - (phi_k + phi_k+1)/2 is then Q (1/GA + h^2/(12 EI)), which is the chain's
Q / GA when the beam's compliance is the shifted one, and the particles' balances are the
beam's jump conditions. The plain Timoshenko beam (compliance 1/GA) is therefore softer than
the chain by h^2/(12 EI) in shear: its compliances exceed the chain's by a relative O((h/L)^2)
wherever shear takes part, and equal them where it does not (a cantilever under an end moment).

The statics here are closed forms for any ends (clamped, pinned, free; not a ring) and one loaded
particle: the beam's transfer matrix over a length s is a polynomial in s, and the two end values
the left end leaves free come from the right end's two conditions (a 2 x 2 solve). The discrete
chain's own statics (:func:`discrete_static`) solve K q = f through K's square root
(:func:`~cosserat_chain.models.linear.rest_solve`, which keeps the bending modes a factor of K's
rounded entries loses at long N), so that :func:`convergence` compares the two.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..memory import require
from ..models.linear import rest_solve
from ..params import ChainParams
from ..state import dof, pack, require_held, unpack
from .beam import BeamStiffness, beam_stiffness, clamped_central_compliance, require_uniform_chain
from .continuum import BYTES_PER_DOF, central_rotation
from .dispersion import Dispersion, _wavenumbers

#: The beam's constants live one floor down (:mod:`cosserat_chain.analysis.beam`), where the continuum's comparison uses them too.
__all__ = [
    "LOADS",
    "BeamConvergence",
    "BeamStiffness",
    "PointLoad",
    "beam_stiffness",
    "clamped_central_compliance",
    "convergence",
    "discrete_static",
    "loaded_particle",
    "sampled_static",
    "static_solution",
    "timoshenko_dispersion",
]

#: What a loaded particle carries: a moment, a transverse force (v) or an axial force (u).
LOADS = ("moment", "force")


@dataclass(frozen=True)
class PointLoad:
    """A load on one particle: moment (conjugate to phi), transverse force (v) and axial force (u)."""

    particle: int = 0
    moment: float = 0.0
    force_v: float = 0.0
    force_u: float = 0.0

    def check(self, params: ChainParams) -> None:
        """Refuse a non-finite value or a load on a degree of freedom an end holds (naming it)."""
        for name in ("moment", "force_v", "force_u"):
            value = getattr(self, name)
            if not math.isfinite(value):
                raise ValueError(f"{name} must be finite, got {value!r}")
        for row, value in (("phi", self.moment), ("v", self.force_v), ("u", self.force_u)):
            if value != 0.0:
                dof(params, row, self.particle)


# ---------------------------------------------------------------------------- transfer matrix
def _transfer(state: np.ndarray, s: np.ndarray, EI: float, compliance: float) -> np.ndarray:
    """(v, phi, m, Q) at a distance s >= 0 beyond a section in ``state`` (4,), no load between.

    With m = EI phi_x and Q = (v_x - phi) / compliance: Q' = 0, m' = -Q, so
    m(s) = m0 - Q0 s, phi(s) = phi0 + (m0 s - Q0 s^2/2)/EI and
    v(s) = v0 + phi0 s + (m0 s^2/2 - Q0 s^3/6)/EI + compliance Q0 s. Returns (4,) + s.shape.
    """
    v0, phi0, m0, q0 = state
    s = np.asarray(s, dtype=float)
    return np.array(
        [
            v0 + phi0 * s + (m0 * s**2 / 2 - q0 * s**3 / 6) / EI + compliance * q0 * s,
            phi0 + (m0 * s - q0 * s**2 / 2) / EI,
            m0 - q0 * s + 0 * s,
            q0 + 0 * s,
        ]
    )


#: Per kind of end: the entries of (v, phi, m, Q) it fixes to zero, and those it leaves free.
_HELD = {"clamped": (0, 1), "pinned": (0, 2), "free": (2, 3)}


def _bending_sections(params: ChainParams, load: PointLoad, compliance: float, EI: float) -> tuple[np.ndarray, np.ndarray, float]:
    """Sections (v, phi, m, Q) at the left end and just after the loaded particle, and its position x0."""
    L, x0 = params.N * params.h, load.particle * params.h
    left_kind, right_kind = params.ends
    free_rows = [i for i in range(4) if i not in _HELD[left_kind]]

    def right_end(p: np.ndarray) -> np.ndarray:
        start = np.zeros(4)
        start[free_rows] = p
        before = _transfer(start, x0 + L, EI, compliance)
        after = before - np.array([0.0, 0.0, load.moment, load.force_v])
        return _transfer(after, L - x0, EI, compliance)[list(_HELD[right_kind])]

    # Affine in p: its columns by unit values, the constant at p = 0.
    constant = right_end(np.zeros(2))
    matrix = np.column_stack([right_end(e) - constant for e in np.eye(2)])
    p = np.linalg.solve(matrix, -constant)
    start = np.zeros(4)
    start[free_rows] = p
    after = _transfer(start, x0 + L, EI, compliance) - np.array([0.0, 0.0, load.moment, load.force_v])
    return start, after, x0


def _axial_sections(params: ChainParams, load: PointLoad, EA: float) -> tuple[float, float, float]:
    """u and the axial force n = EA u_x at the left end, and n after the loaded particle."""
    L, x0 = params.N * params.h, load.particle * params.h
    left_free, right_free = (kind == "free" for kind in params.ends)
    if left_free:  # n = 0 on the left, u = 0 at the right end: u(L) = u0 + (n after) (L - x0)/EA
        return load.force_u * (L - x0) / EA, 0.0, -load.force_u
    if right_free:  # u(-L) = 0 and n = 0 after the load
        return 0.0, load.force_u, 0.0
    # u vanishes at both ends: n0 (x0 + L) + (n0 - F)(L - x0) = 0.
    n0 = load.force_u * (L - x0) / (2 * L)
    return 0.0, n0, n0 - load.force_u


def static_solution(
    params: ChainParams, x: np.ndarray | float, load: PointLoad, *, nodal: bool = False
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Closed-form statics (u, v, phi) of the chain's Timoshenko beam on -L <= x <= L, L = N h.

    Parameters
    ----------
    params : ChainParams
        A uniform open chain with E2 > 0 that cannot move rigidly (its ends hold it).
    x : float or ndarray
        Positions in [-L, L]; particle k sits at k h.
    load : PointLoad
        The loaded particle and its moment and forces.
    nodal : bool
        Use the shear compliance 1/GA - h^2/(12 EI) (the chain's values at its particles,
        exactly) instead of the plain beam's 1/GA.

    Returns
    -------
    u, v, phi : ndarray
        Same shape as ``x``.

    Raises
    ------
    ValueError
        For a ring, a graded chain, E2 = 0, ends that let the chain move rigidly, a load on
        a held degree of freedom, a non-finite load, or x outside [-L, L].
    """
    stiffness = beam_stiffness(params)
    require_held(params)
    load.check(params)
    L = params.N * params.h
    x = np.asarray(x, dtype=float)
    if not np.all(np.isfinite(x)) or np.any(np.abs(x) > L * (1 + 1e-12)):
        raise ValueError(f"x must lie in the chain, -L <= x <= L = N h = {L!r}, got values outside")
    compliance = stiffness.nodal_shear_compliance if nodal else stiffness.shear_compliance
    start, after, x0 = _bending_sections(params, load, compliance, stiffness.EI)
    before_load = x <= x0
    left = _transfer(start, np.where(before_load, x + L, 0.0), stiffness.EI, compliance)
    right = _transfer(after, np.where(before_load, 0.0, x - x0), stiffness.EI, compliance)
    v, phi = np.where(before_load, left[0], right[0]), np.where(before_load, left[1], right[1])
    u0, n0, n1 = _axial_sections(params, load, stiffness.EA)
    u = np.where(before_load, u0 + n0 * (x + L) / stiffness.EA, u0 + n0 * (x0 + L) / stiffness.EA + n1 * (x - x0) / stiffness.EA)
    return u, v, phi


def sampled_static(params: ChainParams, load: PointLoad, *, nodal: bool = False) -> np.ndarray:
    """:func:`static_solution` at the particles, shape (3, 2N+1) in the package's state layout."""
    k = np.arange(-params.N, params.N + 1)
    return np.array(static_solution(params, k * params.h, load, nodal=nodal))


def discrete_static(params: ChainParams, load: PointLoad) -> np.ndarray:
    """Static state (3, 2N+1) of the discrete linear chain (iii) under ``load``.

    Solves K q = f through K's square root (:func:`~cosserat_chain.models.linear.rest_solve`):
    the clamped chain's softest eigenvalue falls like N^-4, and a factor of K's rounded entries,
    even refined in extended precision, was 55 % off at N = 10^5 where the square root keeps
    the closed form's digits.

    Raises
    ------
    ValueError
        As :func:`static_solution` (the chain's ends must hold it), or too little memory.
    """
    require_uniform_chain(params, "the discrete chain beside its beam")
    require_held(params)
    require(
        BYTES_PER_DOF * 3 * params.n_particles,
        f"the discrete chain of N = {params.N} ({3 * params.n_particles} degrees of freedom)",
        "compare shorter chains",
    )
    load.check(params)
    forces = np.zeros((3, params.n_particles))
    column = load.particle + params.N
    forces[:, column] = (load.force_u, load.force_v, load.moment)
    return unpack(params, rest_solve(params, pack(params, forces)))


# ---------------------------------------------------------------------------- convergence
#: An error counts in the order's fit only when it exceeds the discrete value's own error this many times.
RESOLVED = 100.0


def _fit_order(n: np.ndarray, error: np.ndarray, floor: float = 0.0) -> float | None:
    """p of |error| ~ N^-p by least squares on log-log axes, over the rows whose |error| is finite and above ``floor``;
    None with fewer than two distinct N among them. The order of every convergence table of the analysis modules."""
    keep = np.isfinite(error) & (np.abs(error) > floor)
    if np.unique(n[keep]).size < 2:
        return None
    return float(-np.polyfit(np.log(n[keep]), np.log(np.abs(error[keep])), 1)[0])


def _half_lengths(n_values) -> list[int]:
    """``n_values`` as a list of ints, each N >= 1: the half-lengths of every convergence table.

    Raises
    ------
    ValueError
        For an empty list or an N below 1.
    """
    n_values = [int(n) for n in n_values]
    if not n_values or min(n_values) < 1:
        raise ValueError(f"n_values must hold integers N >= 1, got {n_values!r}")
    return n_values


@dataclass(frozen=True)
class BeamConvergence:
    """Compliances of the loaded particle: the discrete chain, its Timoshenko beam, and eq. (11) where it applies.

    Attributes
    ----------
    N : ndarray of int, shape (n,)
    particle : ndarray of int, shape (n,)
        The loaded particle of each chain (``at`` N).
    load : str
        ``"moment"`` (compliance phi/M of the loaded particle) or ``"force"`` (v/F).
    discrete : ndarray, shape (n,)
        The chain's compliance (solved through K's square root).
    timoshenko : ndarray, shape (n,)
        The plain Timoshenko beam's (shear compliance 1/GA).
    nodal : ndarray, shape (n,)
        The beam with shear compliance 1/GA - h^2/(12 EI), equal to the chain's at its particles.
    paper : ndarray, shape (n,)
        Eq. (11)'s phi(0)/M; NaN unless both ends are clamped and a moment loads particle 0.
    discrete_error : ndarray, shape (n,)
        The discrete value's relative error: its distance to ``nodal``, which the chain is at its
        particles in exact arithmetic (round-off alone, if the module's claim holds).
    """

    N: np.ndarray
    particle: np.ndarray
    load: str
    discrete: np.ndarray
    timoshenko: np.ndarray
    nodal: np.ndarray
    paper: np.ndarray
    discrete_error: np.ndarray

    @property
    def timoshenko_error(self) -> np.ndarray:
        """(timoshenko - discrete) / discrete, with its sign (>= 0: the beam is softer in shear)."""
        return (self.timoshenko - self.discrete) / self.discrete

    @property
    def paper_error(self) -> np.ndarray:
        """(eq. (11) - discrete) / discrete, with its sign (NaN where eq. (11) does not apply)."""
        return (self.paper - self.discrete) / self.discrete

    @property
    def nodal_error(self) -> np.ndarray:
        """(nodal - discrete) / discrete: round-off, the chain being this beam at its particles."""
        return (self.nodal - self.discrete) / self.discrete

    def _resolved(self, error: np.ndarray) -> np.ndarray:
        return np.abs(error) > RESOLVED * np.maximum(self.discrete_error, np.finfo(float).eps)

    def order(self, which: str = "timoshenko", *, since: int = 1) -> float | None:
        """Observed order p of |error| ~ N^-p of ``"timoshenko"`` or ``"paper"``, over the rows where the error is resolved.

        ``since``: fit only the rows with N >= since. The fall ~ N^-p holds once the chain is
        long against the shear length sqrt(EI/GA) (:attr:`BeamStiffness.shear_length`);
        before that both errors can grow with N (weak diagonals).
        None where fewer than two rows resolve it (the beam is exact for this load, or
        eq. (11) does not apply).
        """
        if which not in ("timoshenko", "paper"):
            raise ValueError(f"which must be 'timoshenko' or 'paper', got {which!r}")
        error = self.timoshenko_error if which == "timoshenko" else self.paper_error
        resolved = self._resolved(error) & np.isfinite(error) & (self.N >= since)
        return _fit_order(self.N[resolved], error[resolved])

    def to_dataset(self, params: ChainParams):
        """The table as an xarray Dataset over ``N``, with the chain's parameters, model and version in its attributes."""
        import json

        import xarray as xr

        from .._version import __version__

        names = {
            "discrete": "compliance of the loaded particle, discrete linear chain (iii)",
            "timoshenko": "compliance of the loaded particle, Timoshenko beam (shear compliance 1/GA)",
            "nodal": "compliance of the loaded particle, beam with shear compliance 1/GA - h^2/(12 EI)",
            "paper": "compliance phi(0)/M of the paper's eq. (11) (NaN where it does not apply)",
            "timoshenko_error": "(timoshenko - discrete) / discrete",
            "paper_error": "(paper - discrete) / discrete",
            "discrete_error": "estimated relative error of the discrete compliance",
        }
        data = {name: ("N", np.asarray(getattr(self, name), dtype=float), {"long_name": text}) for name, text in names.items()}
        data["particle"] = ("N", self.particle, {"long_name": "loaded particle"})
        dataset = xr.Dataset(data, coords={"N": ("N", self.N, {"long_name": "half-length of the chain (2N+1 particles)"})})
        orders = {f"{which}_order": self.order(which) for which in ("timoshenko", "paper")}
        dataset.attrs.update(
            {
                "title": "Timoshenko beam and eq. (11) against the discrete linear chain",
                "experiment": "beam_convergence",
                "load": self.load,
                "params_json": json.dumps(params.model_dump()),
                "model": "linear",
                "model_equation": "eq. (3)",
                "cosserat_chain_version": __version__,
                **{key: np.nan if value is None else value for key, value in orders.items()},
                **{f"beam_{key}": value for key, value in beam_stiffness(params).as_dict().items()},
            }
        )
        return dataset

    def as_dict(self) -> dict[str, object]:
        """Columns as lists and the two orders (for JSON); NaN becomes None."""

        def column(values: np.ndarray) -> list[float | None]:
            return [float(v) if math.isfinite(v) else None for v in values]

        return {
            "N": [int(n) for n in self.N],
            "particle": [int(p) for p in self.particle],
            "load": self.load,
            "discrete": column(self.discrete),
            "timoshenko": column(self.timoshenko),
            "nodal": column(self.nodal),
            "paper": column(self.paper),
            "timoshenko_error": column(self.timoshenko_error),
            "paper_error": column(self.paper_error),
            "nodal_error": column(self.nodal_error),
            "discrete_error": column(self.discrete_error),
            "timoshenko_order": self.order("timoshenko"),
            "paper_order": self.order("paper"),
        }


def loaded_particle(n: int, at: float) -> int:
    """The particle at the fraction ``at`` of the half-length, at N; refuses a position between particles."""
    if not (math.isfinite(at) and -1.0 <= at <= 1.0):
        raise ValueError(f"at (the loaded particle's position x0/L) must lie in [-1, 1], got {at!r}")
    particle = round(at * n)
    if abs(particle - at * n) > 1e-9:
        raise ValueError(
            f"at = {at!r} puts the load between particles at N = {n} (at N = {at * n:g}): choose N that are "
            "multiples of its denominator, or at = 0 (the centre) or +-1 (an end), so that the load keeps its place as N grows"
        )
    return particle


def convergence(params: ChainParams, n_values: list[int] | np.ndarray, *, at: float = 0.0, load: str = "moment") -> BeamConvergence:
    """The loaded particle's compliance of the chain, its Timoshenko beams and eq. (11), for each N.

    Parameters
    ----------
    params : ChainParams
        Geometry, stiffnesses and ends; its N is replaced by each of ``n_values``.
    n_values : sequence of int
        Half-lengths N >= 1.
    at : float
        Position x0/L of the loaded particle in [-1, 1] (0: the centre), the same for every N.
    load : {"moment", "force"}
        A unit moment (compliance phi/M) or a unit transverse force (v/F).

    Raises
    ------
    ValueError
        For an empty list, an N below 1, a bad ``at`` or ``load``, or a chain the beam does
        not describe (see :func:`static_solution`).
    """
    if load not in LOADS:
        raise ValueError(f"load must be one of {', '.join(map(repr, LOADS))}, got {load!r}")
    n_values = _half_lengths(n_values)
    row = 2 if load == "moment" else 1
    columns: dict[str, list[float]] = {key: [] for key in ("particle", "discrete", "timoshenko", "nodal", "paper", "discrete_error")}
    for n in n_values:
        chain = params.replace(N=n)
        particle = loaded_particle(n, at)
        unit = PointLoad(particle, moment=1.0) if load == "moment" else PointLoad(particle, force_v=1.0)
        state = discrete_static(chain, unit)
        discrete = float(state[row, particle + n])
        beam = float(static_solution(chain, particle * chain.h, unit)[row])
        nodal = float(static_solution(chain, particle * chain.h, unit, nodal=True)[row])
        paper = central_rotation(chain) if chain.clamped and particle == 0 and load == "moment" else math.nan
        columns["particle"].append(particle)
        columns["discrete"].append(discrete)
        columns["timoshenko"].append(beam)
        columns["nodal"].append(nodal)
        columns["paper"].append(paper)
        columns["discrete_error"].append(abs(nodal - discrete) / abs(discrete))
    return BeamConvergence(
        N=np.array(n_values),
        particle=np.array(columns["particle"], dtype=int),
        load=load,
        **{key: np.array(values) for key, values in columns.items() if key != "particle"},
    )


# ---------------------------------------------------------------------------- waves
def timoshenko_dispersion(params: ChainParams, q: np.ndarray | float | None = None, *, n_q: int = 257) -> Dispersion:
    """Branches omega(q) of the infinite Timoshenko beam, q the wavenumber times h (the axis of the chain's).

    With kappa = q/h: omega_L^2 = EA kappa^2 / (m/h) = k_u q^2 / m, and the v-phi pair solves
    (m w^2 - k_v q^2)(j w^2 - 2 E1 b^2 q^2 - k_v h^2) = k_v^2 h^2 q^2, whose product of roots
    is 2 E1 b^2 k_v q^4 / (m j) (no cancellation). The chain's own branches are the same with
    q^2 -> 4 sin^2(q/2) in the stiffness terms and q -> sin q in the coupling
    (:func:`cosserat_chain.analysis.dispersion.dispersion`): they agree to a relative O(q^2), while
    eq. (6)'s acoustic branch has D1 in place of E1 already at q -> 0.
    """
    stiffness = beam_stiffness(params)
    q = _wavenumbers(q, n_q)
    m, j, k_v, h = params.m, params.j, params.k_v, params.h
    a = k_v * q**2 / m
    c = (stiffness.EI / h * q**2 + k_v * h**2) / j
    upper = 0.5 * (a + c) + np.sqrt(0.25 * (a - c) ** 2 + k_v**2 * h**2 * q**2 / (m * j))
    product = stiffness.EI / h * k_v * q**4 / (m * j)
    lower = np.divide(product, upper, out=np.zeros_like(upper), where=upper != 0)
    return Dispersion(q, np.vstack([params.k_u * q**2 / m, lower, upper]), "timoshenko")
