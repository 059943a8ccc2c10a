"""A particle's full rotation against its neighbours: model (i) with the centres held, its bond potential and quasi-continuum.

Contract
--------
With every centre held at (k h, 0), model (i) is a lattice of angles with the energy
sum_k V(phi_k, phi_k+1), V the potential (1) of one bond's four links (:func:`bond_potential`,
exact, 2 pi-periodic in each angle and symmetric, V(a, b) = V(b, a), by the bond's two mirror
symmetries). Expanded about the bond's mean angle, V(p - d/2, p + d/2) = W(p) + kappa(p) d^2/2
+ O(d^4) with

    W(p) = V(p, p)                                 (both neighbours turned together),
    kappa(p) = (V_11 - V_12)(p, p) / 2             (the cost of their difference),

so a slowly varying phi has the quasi-continuum energy integral of W(phi)/h + h kappa(phi) phi_x^2/2:
a sine-Gordon-like equation with the exact potential W in place of a cosine. Its 2 pi front (a
kink from phi = 0 to 2 pi) has the energy integral_0^2pi sqrt(2 W kappa) dphi, the largest slope
phi_x = max sqrt(2 W / kappa) / h, so the width 2 pi / max sqrt(2 W / kappa) particles, and tails
of length sqrt(kappa(0) / W''(0)) particles; at rest W''(0) = k_v h^2 and kappa(0) = 2 E1 b^2,
whose ratio is EI / (GA h^2) = E1 d^2 / (4 E2 h^2): a smooth front needs weak diagonals.

:func:`discrete_front` minimises the lattice's energy with its ends held at 0 and 2 pi (the front
centred on a particle and on a bond: the two stationary fronts, whose energies differ by the
Peierls barrier; V being 2 pi-periodic, a narrow front slips into one bond, where it costs
nothing); :func:`turn_barrier` is the energy barrier of one particle turning once, past
fixed neighbours (2 max V(0, phi)) and past relaxing ones. Every path of the turn crosses each
value of the turning particle's angle, so the largest over that angle of the constrained minimum
over the others is a lower bound of the barrier; a first-order saddle whose two descents end at
rest and at the particle turned once is an upper bound (its two descents are a path of the turn).
Where the rotation-controlled path is continuous its top is such a saddle and the two meet; where
it jumps (wide fronts: the dragged neighbours and the ones left behind are two valleys) they do not.
The barrier itself is the top of the turn's minimum energy path (:class:`TurnPath`), relaxed by the
climbing-image string method (:mod:`cosserat_chain.numerics.mep`) from the rotation-controlled path
and from a one-sided one, its tops refined to first-order saddles: where fronts are wide the turn
goes over two slips with a metastable front between them, inside the bracket.

:func:`free_front` frees the centres: model (i) with both ends clamped, the right one turned once,
minimised from the held front.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..geometry import bond_links, rotate
from ..params import ChainParams

#: Step of the central differences of V (rad): error about 1e-8 of kappa and W''.
DIFFERENCE_STEP = 1e-4
#: Points of the angle grids (Fourier content, front energy, barrier scans).
GRID = 256


def _require_uniform(params: ChainParams) -> None:
    if params.graded_stiffness:
        raise ValueError("the bond potential needs a uniform chain: leave E1_factors and E2_factors out")


def _links_energy(params: ChainParams, phi0: np.ndarray, phi1: np.ndarray, order: int):
    """V and, for ``order`` >= 1, its first derivatives (V_0, V_1), for ``order`` 2 also (V_00, V_01, V_11).

    Per link, D = (h, 0) + R(phi1) r1 - R(phi0) r0 and its length l = |D|: D_0 = -J R0 r0,
    D_1 = J R1 r1 (J the quarter turn), D_00 = R0 r0, D_11 = -R1 r1, D_01 = 0;
    l_i = D . D_i / l and l_ij = (D_i . D_j + D . D_ij) / l - l_i l_j / l; the link stores
    E (l - l0)^2 / 2.
    """
    shape = np.broadcast(phi0, phi1).shape
    out = [np.zeros(shape) for _ in range(6)]
    for link in bond_links(params):
        p0 = np.stack(rotate(link.left_corner, phi0))
        p1 = np.stack(rotate(link.right_corner, phi1))
        D = np.stack([params.h + p1[0] - p0[0], p1[1] - p0[1]])
        length = np.hypot(D[0], D[1])
        stretch = length - link.rest_length
        out[0] = out[0] + 0.5 * link.stiffness * stretch**2
        if order < 1:
            continue
        safe = np.where(length > 0, length, 1.0)
        d0 = np.stack([p0[1], -p0[0]])  # -J R0 r0
        d1 = np.stack([-p1[1], p1[0]])  # J R1 r1
        l0 = (D * d0).sum(axis=0) / safe
        l1 = (D * d1).sum(axis=0) / safe
        out[1] = out[1] + link.stiffness * stretch * l0
        out[2] = out[2] + link.stiffness * stretch * l1
        if order < 2:
            continue
        l00 = ((d0 * d0).sum(axis=0) + (D * p0).sum(axis=0)) / safe - l0 * l0 / safe
        l01 = (d0 * d1).sum(axis=0) / safe - l0 * l1 / safe
        l11 = ((d1 * d1).sum(axis=0) - (D * p1).sum(axis=0)) / safe - l1 * l1 / safe
        out[3] = out[3] + link.stiffness * (l0 * l0 + stretch * l00)
        out[4] = out[4] + link.stiffness * (l0 * l1 + stretch * l01)
        out[5] = out[5] + link.stiffness * (l1 * l1 + stretch * l11)
    return out[: (1, 3, 6)[order]]


def bond_potential(params: ChainParams, phi0: np.ndarray | float, phi1: np.ndarray | float) -> np.ndarray:
    """V(phi0, phi1): the potential (1) of one bond's four links with both centres held at rest (exact).

    Parameters
    ----------
    params : ChainParams
        A uniform chain (its N and ends play no part).
    phi0, phi1 : float or ndarray
        Angles of the left and right particle (broadcast together).

    Returns
    -------
    ndarray
        The broadcast shape.
    """
    _require_uniform(params)
    return _links_energy(params, np.asarray(phi0, dtype=float), np.asarray(phi1, dtype=float), 0)[0]


def fourier_content(params: ChainParams, *, grid: int = GRID, count: int = 8) -> list[tuple[int, int, float]]:
    """The largest Fourier coefficients of V: ``count`` entries (m, n, |c_mn|), V = sum c_mn exp(i (m phi0 + n phi1)).

    From the FFT of V on a ``grid`` x ``grid`` lattice of angles; (m, n) and (-m, -n) are one
    entry (V is real), listed with m > 0, or m = 0 and n >= 0, largest first (the mean, (0, 0), included).
    """
    _require_uniform(params)
    angles = 2 * np.pi * np.arange(grid) / grid
    values = bond_potential(params, angles[:, None], angles[None, :])
    coefficients = np.fft.fft2(values) / grid**2
    frequencies = np.fft.fftfreq(grid, 1.0 / grid).astype(int)
    entries = []
    for i, m in enumerate(frequencies):
        for j, n in enumerate(frequencies):
            if m > 0 or (m == 0 and n >= 0):
                entries.append((int(m), int(n), float(abs(coefficients[i, j]) * (1 if (m, n) == (0, 0) else 2))))
    entries.sort(key=lambda item: -item[2])
    return entries[:count]


@dataclass(frozen=True)
class QuasiContinuum:
    """The quasi-continuum of the held lattice: W, kappa on a grid of angles, and its 2 pi front.

    Attributes
    ----------
    phi : ndarray, shape (GRID + 1,)
        Angles 0..2 pi.
    W, kappa : ndarray, same shape
        V(p, p) and (V_11 - V_12)(p, p)/2 (module docstring).
    front_energy : float
        integral_0^2pi sqrt(2 W kappa) dphi; NaN where kappa < 0 somewhere (no front).
    width : float
        2 pi / max sqrt(2 W / kappa), in particles: the front's width at its steepest.
    tail : float
        sqrt(kappa(0) / W''(0)), in particles: the length over which the front's tails decay.
    """

    phi: np.ndarray
    W: np.ndarray
    kappa: np.ndarray
    front_energy: float
    width: float
    tail: float

    def as_dict(self) -> dict[str, float | None]:
        """The front's numbers (for JSON), NaN as None."""
        return {
            key: (float(value) if math.isfinite(value) else None)
            for key, value in (("front_energy", self.front_energy), ("width", self.width), ("tail", self.tail))
        }


def quasi_continuum(params: ChainParams, *, grid: int = GRID) -> QuasiContinuum:
    """W, kappa and the quasi-continuum's 2 pi front (module docstring)."""
    _require_uniform(params)
    step = DIFFERENCE_STEP
    phi = np.linspace(0.0, 2 * np.pi, grid + 1)

    def V(a, b):
        return bond_potential(params, a, b)

    W = V(phi, phi)
    v11 = (V(phi + step, phi) - 2 * W + V(phi - step, phi)) / step**2
    v12 = (V(phi + step, phi + step) - V(phi + step, phi - step) - V(phi - step, phi + step) + V(phi - step, phi - step)) / (4 * step**2)
    kappa = (v11 - v12) / 2
    w2 = (V(np.array(step), np.array(step)) - 2 * V(np.array(0.0), np.array(0.0)) + V(np.array(-step), np.array(-step))) / step**2
    if np.any(kappa <= 0):
        energy = width = math.nan
    else:
        density = np.sqrt(2 * np.maximum(W, 0.0) * kappa)
        energy = float(np.trapezoid(density, phi))
        width = float(2 * np.pi / np.max(np.sqrt(2 * np.maximum(W, 0.0) / kappa)))
    tail = float(np.sqrt(kappa[0] / w2)) if kappa[0] > 0 and w2 > 0 else math.nan
    return QuasiContinuum(phi, W, kappa, energy, width, tail)


# ---------------------------------------------------------------------------- the discrete lattice
def lattice_energy(params: ChainParams, phi: np.ndarray) -> tuple[float, np.ndarray]:
    """sum_k V(phi_k, phi_k+1) of a held chain with angles ``phi`` (n,), and its gradient (n,)."""
    phi = np.asarray(phi, dtype=float)
    energy, d0, d1 = _links_energy(params, phi[:-1], phi[1:], 1)
    gradient = np.zeros_like(phi)
    gradient[:-1] += d0
    gradient[1:] += d1
    return float(energy.sum()), gradient


def lattice_hessian(params: ChainParams, phi: np.ndarray) -> np.ndarray:
    """The Hessian (n, n) of :func:`lattice_energy` (tridiagonal, stored dense)."""
    phi = np.asarray(phi, dtype=float)
    _, _, _, h00, h01, h11 = _links_energy(params, phi[:-1], phi[1:], 2)
    hessian = np.zeros((phi.size, phi.size))
    index = np.arange(phi.size - 1)
    hessian[index, index] += h00
    hessian[index + 1, index + 1] += h11
    hessian[index, index + 1] = h01
    hessian[index + 1, index] = h01
    return hessian


def _minimise(params: ChainParams, phi: np.ndarray, free: np.ndarray) -> tuple[float, np.ndarray]:
    """Minimise over the ``free`` angles by a trust-region Newton method (exact Hessian; safe where it is indefinite)."""
    from scipy.optimize import minimize

    if not np.any(free):  # one particle between held neighbours: nothing to minimise
        return lattice_energy(params, phi)[0], phi.copy()

    def full(values: np.ndarray) -> np.ndarray:
        trial = phi.copy()
        trial[free] = values
        return trial

    def objective(values: np.ndarray) -> tuple[float, np.ndarray]:
        energy, gradient = lattice_energy(params, full(values))
        return energy, gradient[free]

    def hessian(values: np.ndarray) -> np.ndarray:
        return lattice_hessian(params, full(values))[np.ix_(free, free)]

    result = minimize(objective, phi[free], jac=True, hess=hessian, method="trust-exact", options={"gtol": 1e-10, "maxiter": 2000})
    return float(result.fun), full(result.x)


@dataclass(frozen=True)
class DiscreteFront:
    """The held lattice's 2 pi fronts: centred on a particle and on a bond.

    Attributes
    ----------
    phi_site, phi_bond : ndarray, shape (2 n + 1,) and (2 n + 2,)
        The minimised angles, ends held at 0 and 2 pi.
    energy_site, energy_bond : float
        Their energies.
    width : float
        2 pi / the largest angle difference between neighbours, in particles, of the lower one.

    Notes
    -----
    V is 2 pi-periodic in each angle, so a front squeezed into one bond (neighbours 2 pi apart)
    costs nothing: a narrow front does not stay, it slips into that state or into one particle
    turned half-way (energy the single-particle barrier). ``smooth`` says whether the front stayed
    spread, a local minimum of its own.
    """

    phi_site: np.ndarray
    phi_bond: np.ndarray
    energy_site: float
    energy_bond: float
    width: float

    @property
    def smooth(self) -> bool:
        """Whether the lower front is spread: no two neighbours differ by pi/2 or more."""
        lower = self.phi_site if self.energy_site <= self.energy_bond else self.phi_bond
        return bool(np.max(np.abs(np.diff(lower))) < np.pi / 2)

    @property
    def energy(self) -> float:
        """The front's energy: the lower of the two."""
        return min(self.energy_site, self.energy_bond)

    @property
    def peierls_barrier(self) -> float:
        """|energy_site - energy_bond|: what it costs the front to move by half a particle."""
        return abs(self.energy_site - self.energy_bond)

    def as_dict(self) -> dict[str, float | bool]:
        """The front's numbers (for JSON)."""
        return {
            "smooth": self.smooth,
            "energy": self.energy,
            "energy_site": self.energy_site,
            "energy_bond": self.energy_bond,
            "peierls_barrier": self.peierls_barrier,
            "width": self.width,
        }


def discrete_front(params: ChainParams, *, half_length: int = 30) -> DiscreteFront:
    """Minimise the held lattice with its ends at 0 and 2 pi, from fronts centred on a particle and on a bond.

    Parameters
    ----------
    params : ChainParams
        A uniform chain (its N and ends play no part).
    half_length : int
        Particles on each side of the front's centre (>= 2); the tails must fit in it.

    Raises
    ------
    ValueError
        For half_length < 2 or a graded chain.
    """
    _require_uniform(params)
    if half_length < 2:
        raise ValueError(f"half_length must be >= 2 (particles on each side of the front), got {half_length!r}")
    qc = quasi_continuum(params)
    scale = qc.width / 4 if math.isfinite(qc.width) and qc.width > 0.5 else 0.5
    results = []
    for offset in (0.0, 0.5):
        positions = np.arange(-half_length, half_length + 1 + (1 if offset else 0)) - offset
        start = 4 * np.arctan(np.exp(positions / scale))  # a sine-Gordon kink, 0 to 2 pi
        start[0], start[-1] = 0.0, 2 * np.pi
        free = np.zeros(start.size, dtype=bool)
        free[1:-1] = True
        if offset == 0.0:  # the centre particle at pi keeps the front centred on it
            free[half_length] = False
            start[half_length] = np.pi
            energy, phi = _minimise(params, start, free)
            free[half_length] = True
        energy, phi = _minimise(params, start if offset else phi, free)
        results.append((energy, phi))
    (energy_site, phi_site), (energy_bond, phi_bond) = results
    lower = phi_site if energy_site <= energy_bond else phi_bond
    return DiscreteFront(phi_site, phi_bond, energy_site, energy_bond, float(2 * np.pi / np.max(np.abs(np.diff(lower)))))


#: A saddle's gradient counts as zero below this fraction of the Hessian's largest entry (per radian).
SADDLE_GTOL = 1e-11
#: Newton (P-RFO) steps of the saddle search, and its largest step (rad).
SADDLE_STEPS = 200
SADDLE_TRUST = 0.3


@dataclass(frozen=True)
class TurnBarrier:
    """The energy barrier of one particle turning once against its neighbours.

    Attributes
    ----------
    fixed : float
        With the neighbours held at 0: 2 max V(0, phi).
    relaxed : float
        With the other particles of a held lattice relaxing (each end held at 0): the largest,
        over the turning particle's angle, of the minimum over the others (the lower of the
        minima reached from the last angle and from rest): the top of the rotation-controlled
        path, a lower bound of the barrier (module docstring), and at most ``fixed``.
    angle_fixed, angle_relaxed : float
        The turning particle's angle at the two barriers.
    saddle : float
        The energy of the lowest first-order saddle of the turn found (:func:`turn_barrier`):
        the barrier of the turn with every other particle free; NaN if no candidate converged
        to one that descends to rest on one side and to the particle turned once on the other.
    saddle_state : ndarray, shape (2 half_length + 1,)
        The lattice's angles there (the turning particle in the middle; NaN if none).
    saddle_gradient : float
        The largest |dE/dphi_k| over the free particles there.
    negative_eigenvalues : int
        Negative eigenvalues of the Hessian over the free particles there (1 for a first-order saddle).
    descents : tuple of float
        The turning particle's angle at the minima reached by descending from the saddle along
        either side of its unstable mode (rest and the particle turned once, 0 and 2 pi), with
        the larger energy of the two minima.
    others : tuple of (energy, angle, descent angle, descent angle, descent energy)
        The other first-order saddles the search converged to (those leading to a metastable
        state, such as a pair of fronts, rather than through the turn).
    paths : tuple of TurnPath
        The turn's validated minimum energy paths (:func:`turn_barrier`); :attr:`barrier` is
        the lowest of their tops.
    """

    fixed: float
    relaxed: float
    angle_fixed: float
    angle_relaxed: float
    saddle: float = math.nan
    saddle_state: np.ndarray | None = None
    saddle_gradient: float = math.nan
    negative_eigenvalues: int = -1
    descents: tuple[float, float, float] = (math.nan, math.nan, math.nan)
    others: tuple[tuple[float, float, float, float, float], ...] = ()
    paths: tuple[TurnPath, ...] = ()

    @property
    def barrier(self) -> float:
        """The turn's barrier: the lowest top of the validated minimum energy paths (NaN if none)."""
        return min((path.barrier for path in self.paths), default=math.nan)

    @property
    def saddle_angle(self) -> float:
        """The turning particle's angle at the saddle."""
        return math.nan if self.saddle_state is None else float(self.saddle_state[self.saddle_state.size // 2])

    def as_dict(self) -> dict[str, float]:
        """The barriers and their angles (for JSON), NaN as None."""

        def plain(value: float) -> float | None:
            return float(value) if math.isfinite(value) else None

        return {
            "fixed": self.fixed,
            "relaxed": self.relaxed,
            "angle_fixed": self.angle_fixed,
            "angle_relaxed": self.angle_relaxed,
            "saddle": plain(self.saddle),
            "saddle_angle": plain(self.saddle_angle),
            "saddle_gradient": plain(self.saddle_gradient),
            "negative_eigenvalues": self.negative_eigenvalues,
            "descents": [plain(value) for value in self.descents],
            "barrier": plain(self.barrier),
            "paths": [path.as_dict() for path in self.paths],
            "other_saddles": [
                dict(zip(("energy", "angle", "descent_angle_0", "descent_angle_1", "descent_energy"), item)) for item in self.others
            ],
        }


def _tridiagonal_eigh(matrix: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Eigenvalues (ascending) and vectors of a symmetric tridiagonal matrix stored dense (LAPACK stemr: no BLAS threads)."""
    from scipy.linalg import eigh_tridiagonal

    return eigh_tridiagonal(np.diag(matrix).copy(), np.diag(matrix, 1).copy())


def _saddle_search(params: ChainParams, phi: np.ndarray, free: np.ndarray) -> tuple[np.ndarray, float, int, bool]:
    """A first-order saddle of the lattice over the ``free`` angles by P-RFO Newton steps (:func:`~cosserat_chain.numerics.mep.saddle_search`).

    Each step ascends along the Hessian's lowest mode and descends along the others, at most
    :data:`SADDLE_TRUST` long. Returns the angles, the largest gradient entry, the Hessian's
    negative eigenvalues there, and whether the gradient reached :data:`SADDLE_GTOL` of the
    Hessian's scale.
    """
    from ..numerics.mep import saddle_search

    def gradient_hessian(values: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        trial = phi.copy()
        trial[free] = values
        return lattice_energy(params, trial)[1][free], lattice_hessian(params, trial)[np.ix_(free, free)]

    found = saddle_search(
        gradient_hessian, phi[free], tolerance=SADDLE_GTOL, steps=SADDLE_STEPS, trust=SADDLE_TRUST, eigh=_tridiagonal_eigh
    )
    x = phi.copy()
    x[free] = found.x
    return x, found.gradient, found.negative, found.converged


def _descent_states(params: ChainParams, saddle: np.ndarray, free: np.ndarray, middle: int) -> list[tuple[float, np.ndarray]]:
    """Minimise from the saddle displaced along either side of its unstable mode (the turning particle's side first backwards): two (energy, angles)."""
    values, vectors = _tridiagonal_eigh(lattice_hessian(params, saddle)[np.ix_(free, free)])
    mode = vectors[:, 0] * (1.0 if vectors[np.flatnonzero(free).tolist().index(middle), 0] >= 0 else -1.0)
    ends = []
    for sign in (-1.0, 1.0):
        start = saddle.copy()
        start[free] += sign * 0.05 * mode / np.max(np.abs(mode))
        ends.append(_minimise(params, start, free))
    return ends


def _descents(params: ChainParams, saddle: np.ndarray, free: np.ndarray, middle: int) -> tuple[float, float, float]:
    """The turning particle's angles at the two minima of :func:`_descent_states`, and the larger energy."""
    ends = _descent_states(params, saddle, free, middle)
    return float(ends[0][1][middle]), float(ends[1][1][middle]), max(ends[0][0], ends[1][0])


#: Images of the turn's minimum energy path (the ends included), and the force left on it (E1 h^2 per radian).
PATH_IMAGES = 48
PATH_TOLERANCE = 1e-6
#: Two minima (or saddles) reached along the path are one where no angle differs by more than this (rad).
SAME_STATE = 1e-4


@dataclass(frozen=True)
class TurnPath:
    """The turn's minimum energy path (climbing-image string) and the validated saddles and minima along it.

    Attributes
    ----------
    start : str
        The first path: ``"rotation-controlled"`` (the path's states, mirror-symmetric) or
        ``"one-sided"`` (the particle slipping past its left neighbours while dragging its right
        ones, then the straight line to the particle turned once).
    images : ndarray, shape (M, 2 half_length + 1)
        The relaxed string, from rest to the particle turned once.
    energies : ndarray, shape (M,)
        The images' energies.
    force : float
        The force left on the string (largest move per unit time step of an image, the climbing one's whole force).
    iterations : int
        String steps.
    saddles : tuple of float
        The first-order saddles refined (P-RFO) from the string's local tops, in order along it.
    minima : tuple of float
        The minima between them, in order, rest and the particle turned once included.
    state : ndarray, shape (2 half_length + 1,)
        The angles at the highest saddle, the path's top.
    gradient : float
        The largest |dE/dphi_k| over the free particles there.
    """

    start: str
    images: np.ndarray
    energies: np.ndarray
    force: float
    iterations: int
    saddles: tuple[float, ...]
    minima: tuple[float, ...]
    state: np.ndarray
    gradient: float

    @property
    def barrier(self) -> float:
        """The highest saddle along the path: the turn's barrier over this path."""
        return max(self.saddles)

    def as_dict(self) -> dict[str, object]:
        """The path's numbers (for JSON)."""
        return {
            "start": self.start,
            "barrier": self.barrier,
            "saddle_angle": float(self.state[self.state.size // 2]),
            "saddle_gradient": self.gradient,
            "images": int(self.images.shape[0]),
            "force": self.force,
            "iterations": self.iterations,
            "saddles": list(self.saddles),
            "minima": list(self.minima),
        }


def _lattice_energies(params: ChainParams, phis: np.ndarray, free: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Energies (M,) and gradients (M, n) of M lattices at once, the held angles' entries zero."""
    energy, d0, d1 = _links_energy(params, phis[:, :-1], phis[:, 1:], 1)
    gradient = np.zeros_like(phis)
    gradient[:, :-1] += d0
    gradient[:, 1:] += d1
    gradient[:, ~free] = 0.0
    return energy.sum(axis=1), gradient


def _turn_path(params: ChainParams, path: np.ndarray, free: np.ndarray, start: str, images: int) -> TurnPath | None:
    """Relax ``path`` (rest to the particle turned once) by the climbing string and validate it; None if it fails.

    Each local top of the string is refined to a first-order saddle (P-RFO: zero gradient,
    exactly one negative eigenvalue), and its descents give the minima on either side, so the
    path is a chain of saddles and minima from rest to the particle turned once. Where the
    string's images miss a minimum (the wide front's Peierls hops, 1e-3 of the barrier, are
    finer than the images), the descent that should come back to the last minimum does not:
    the images between the two tops join them, and they must stay below the highest saddle. A
    top that refines to the saddle just passed is one top; where the chain reaches the particle
    turned once early (and comes back), or comes back to rest, the turn is the part between
    the last rest and the first arrival.
    """
    from ..numerics.mep import string_method

    middle = path.shape[1] // 2
    # The explicit step's stability: 1 / Gershgorin's bound on the Hessian's largest eigenvalue along the path.
    _, _, _, h00, h01, h11 = _links_energy(params, path[:, :-1], path[:, 1:], 2)
    rows = np.zeros_like(path)
    rows[:, :-1] += np.abs(h00) + np.abs(h01)
    rows[:, 1:] += np.abs(h11) + np.abs(h01)
    step = 1.0 / float(np.max(rows[:, free]))
    string = string_method(lambda x: _lattice_energies(params, x, free), path, step=step, images=images, tolerance=PATH_TOLERANCE)
    if not string.converged:
        return None
    rest, turned = string.images[0], string.images[-1]
    states, energies = [rest], [float(string.energies[0])]  # the chain's minima
    saddles: list[tuple[float, np.ndarray, float]] = []
    gaps: list[float] = []  # before each saddle: the images' top where they alone join it to the last minimum
    previous = 0
    for top in sorted(string.maxima()):
        saddle, gradient, negative, converged = _saddle_search(params, string.images[top], free)
        if not converged or negative != 1:
            return None
        if saddles and np.max(np.abs(saddle - saddles[-1][1])) < SAME_STATE:
            continue
        ends = _descent_states(params, saddle, free, middle)
        # The descent that goes on along the string: of the two ways to pair the ends with the
        # images either side of the top, the closer one.
        before, after = string.images[top - 1], string.images[top + 1]
        forward = int(
            np.linalg.norm(ends[1][1] - after) + np.linalg.norm(ends[0][1] - before)
            < np.linalg.norm(ends[0][1] - after) + np.linalg.norm(ends[1][1] - before)
        )
        joined = np.max(np.abs(ends[1 - forward][1] - states[-1])) >= SAME_STATE
        gaps.append(float(np.max(string.energies[previous + 1 : top], initial=-math.inf)) if joined else -math.inf)
        saddles.append((lattice_energy(params, saddle)[0], saddle, gradient))
        energies.append(float(ends[forward][0]))
        states.append(ends[forward][1])
        previous = top
    # The turn proper: from the last visit of rest before the first arrival at the particle turned once.
    arrivals = [k for k, state in enumerate(states) if np.max(np.abs(state - turned)) < SAME_STATE]
    last = arrivals[0] if arrivals else len(states) - 1
    first = max(k for k in range(last + 1) if np.max(np.abs(states[k] - rest)) < SAME_STATE)
    tail = [] if arrivals else [float(np.max(string.energies[previous + 1 :]))]
    saddles, gaps = saddles[first:last], gaps[first:last] + tail
    energies = energies[first : last + 1] + ([] if arrivals else [float(string.energies[-1])])
    if not saddles:
        return None
    highest = max(saddles, key=lambda item: item[0])
    if max(gaps) >= highest[0]:
        return None
    return TurnPath(
        start=start,
        images=string.images,
        energies=string.energies,
        force=string.force,
        iterations=string.iterations,
        saddles=tuple(float(item[0]) for item in saddles),
        minima=tuple(energies),
        state=highest[1],
        gradient=highest[2],
    )


def turn_barrier(params: ChainParams, *, half_length: int = 10, points: int = 64, images: int = PATH_IMAGES) -> TurnBarrier:
    """Barriers of one particle turning past fixed and past relaxing neighbours, and the turn's saddle (module docstring).

    The relaxed barrier scans the turning particle's angle over ``points`` values in [0, 2 pi],
    each minimisation started from the last, and refines the largest by a bounded scalar search.
    The saddle search then frees the turning particle too and runs P-RFO Newton steps
    (:func:`_saddle_search`) from the path's top, from the fixed-neighbour barrier's state and
    from the path's highest scanned states, and keeps the lowest first-order saddle that
    descends to rest and to the particle turned once: where the path is smooth its top is that
    saddle (there dE/dphi of the turning particle vanishes with the others' gradients) and
    ``saddle`` equals ``relaxed``; where it jumps from dragging the neighbours to leaving them
    behind, the saddle lies above the path's top.

    With ``images`` > 0 the turn's minimum energy path decides the barrier: a climbing string of
    that many images (:func:`~cosserat_chain.numerics.mep.string_method`) relaxed from the
    rotation-controlled path's states and from the one-sided path (the particle slipping past
    its left neighbours while its right ones are dragged), each validated as a chain of
    first-order saddles and minima from rest to the particle turned once (:class:`TurnPath`).
    Both first paths are needed: the gradient flow and the P-RFO steps keep the lattice's mirror
    symmetry, so the rotation-controlled path never leaves it.
    """
    from scipy.optimize import minimize_scalar

    _require_uniform(params)
    if half_length < 1 or points < 8 or not (images == 0 or images >= 3):
        raise ValueError(
            f"half_length must be >= 1, points >= 8 and images 0 (no path) or >= 3, got half_length={half_length!r}, "
            f"points={points!r}, images={images!r}"
        )
    grid = np.linspace(0.0, 2 * np.pi, GRID + 1)
    single = 2 * bond_potential(params, 0.0, grid)
    top = int(np.argmax(single))
    fine = minimize_scalar(
        lambda a: -2 * float(bond_potential(params, 0.0, a)), bounds=(grid[max(top - 1, 0)], grid[min(top + 1, GRID)]), method="bounded"
    )
    fixed, angle_fixed = -float(fine.fun), float(fine.x)

    phi = np.zeros(2 * half_length + 1)
    free = np.ones(phi.size, dtype=bool)
    free[[0, half_length, -1]] = False

    def constrained(angle: float, start: np.ndarray) -> tuple[float, np.ndarray]:
        # The lower of two local minima: the one followed from the last angle (the neighbours
        # dragged along) and the one from the others at rest (the neighbours left behind).
        candidates = []
        for guess in (start, phi):
            trial = guess.copy()
            trial[half_length] = angle
            candidates.append(_minimise(params, trial, free))
        return min(candidates, key=lambda item: item[0])

    angles = np.linspace(0.0, 2 * np.pi, points)
    energies, states = [], []
    state = phi
    for angle in angles:
        energy, state = constrained(float(angle), state)
        energies.append(energy)
        states.append(state)
    best = int(np.argmax(energies))
    start = states[best]
    fine = minimize_scalar(
        lambda a: -constrained(float(a), start)[0],
        bounds=(angles[max(best - 1, 0)], angles[min(best + 1, points - 1)]),
        method="bounded",
        options={"xatol": 1e-6},
    )
    relaxed = max(-float(fine.fun), float(energies[best]))
    angle_relaxed = float(fine.x) if -float(fine.fun) >= energies[best] else float(angles[best])

    everyone = free.copy()
    everyone[half_length] = True
    symmetric = phi.copy()
    symmetric[half_length] = angle_fixed
    candidates = [constrained(float(fine.x), start)[1], symmetric] + [states[i] for i in np.argsort(energies)[::-1][:4]]
    saddles: dict[float, tuple[np.ndarray, float, tuple[float, float, float]]] = {}
    for candidate in candidates:
        saddle, gradient, negative, converged = _saddle_search(params, candidate, everyone)
        if converged and negative == 1:
            energy = lattice_energy(params, saddle)[0]
            if all(abs(energy - known) > 1e-9 * max(fixed, 1e-300) for known in saddles):
                saddles[energy] = (saddle, gradient, _descents(params, saddle, everyone, half_length))
    # The turn's saddles: descending on one side to rest, on the other to the particle turned once.
    tolerance = 1e-9 * fixed
    turns = {
        energy: found
        for energy, found in saddles.items()
        if found[2][2] <= tolerance and sorted(round(angle / (2 * np.pi)) for angle in found[2][:2]) in ([0, 1], [-1, 0])
    }
    others = tuple(
        (float(energy), float(found[0][half_length]), found[2][0], found[2][1], found[2][2])
        for energy, found in sorted(saddles.items())
        if energy not in turns
    )
    paths: tuple[TurnPath, ...] = ()
    if images:
        one_sided, state = [], phi
        for angle in angles:
            trial = state.copy()
            trial[:half_length] = 0.0
            trial[half_length] = angle
            state = _minimise(params, trial, free)[1]
            one_sided.append(state)
        turned = phi.copy()
        turned[half_length] = 2 * np.pi
        found = (
            _turn_path(params, np.array(states), everyone, "rotation-controlled", images),
            _turn_path(params, np.array([*one_sided, turned]), everyone, "one-sided", images),
        )
        paths = tuple(path for path in found if path is not None)
    if not turns:
        return TurnBarrier(fixed, relaxed, angle_fixed, angle_relaxed, others=others, paths=paths)
    energy = min(turns)
    saddle, gradient, descents = turns[energy]
    return TurnBarrier(
        fixed,
        relaxed,
        angle_fixed,
        angle_relaxed,
        saddle=energy,
        saddle_state=saddle,
        saddle_gradient=gradient,
        negative_eigenvalues=1,
        descents=descents,
        others=others,
        paths=paths,
    )


# ---------------------------------------------------------------------------- free centres
@dataclass(frozen=True)
class FreeFront:
    """The 2 pi front of model (i) with its centres free: both ends clamped, the right one turned by 2 pi.

    Attributes
    ----------
    state : ndarray, shape (3, 2 half_length + 1)
        u, v, phi of the minimised chain (the right end's angle written as 2 pi).
    energy : float
        Its energy.
    held_energy : float
        The held lattice's front (:func:`discrete_front`, the same half-length) it started from.
    width : float
        2 pi / the largest angle difference between neighbours, in particles.
    displacement : float
        The largest |u| or |v| of a centre, in units of h.
    gradient : float
        The largest force on a free degree of freedom at the minimum.
    """

    state: np.ndarray
    energy: float
    held_energy: float
    width: float
    displacement: float
    gradient: float

    @property
    def smooth(self) -> bool:
        """Whether the front stayed spread: no two neighbours differ by pi/2 or more."""
        return bool(np.max(np.abs(np.diff(self.state[2]))) < np.pi / 2)

    def as_dict(self) -> dict[str, float | bool]:
        """The front's numbers (for JSON)."""
        return {
            "smooth": self.smooth,
            "energy": self.energy,
            "held_energy": self.held_energy,
            "width": self.width,
            "displacement": self.displacement,
            "gradient": self.gradient,
        }


def free_front(params: ChainParams, *, half_length: int = 30) -> FreeFront:
    """Relax the held lattice's 2 pi front with its centres free: model (i) with both ends clamped.

    Model (i)'s energy is 2 pi-periodic in each angle, so a clamped end at phi = 0 is one turned
    by 2 pi: the chain of N = ``half_length`` with both ends clamped holds a front whose right
    part has turned once. Its energy is minimised over every free u, v, phi by a trust-region
    Newton method with the model's exact stiffness, from the held front (:func:`discrete_front`),
    which is admissible: the free front's energy is at most the held one's.

    Raises
    ------
    ValueError
        For half_length < 2 or a graded chain.
    """
    from scipy.optimize import minimize

    from ..models import NONLINEAR
    from ..state import pack, unpack

    held = discrete_front(params, half_length=half_length)
    chain = params.replace(N=half_length, left_end="clamped", right_end="clamped", periodic=False)
    start = np.zeros((3, chain.n_particles))
    start[2] = held.phi_site if held.energy_site <= held.energy_bond else held.phi_bond[:-1]
    start[2, -1] = 0.0  # the clamped end's 2 pi

    def objective(q: np.ndarray) -> tuple[float, np.ndarray]:
        x = unpack(chain, q)
        return NONLINEAR.energy(chain, x), -pack(chain, NONLINEAR.forces(chain, x))

    def hessian(q: np.ndarray) -> np.ndarray:
        return NONLINEAR.stiffness(chain, unpack(chain, q)).toarray()

    result = minimize(objective, pack(chain, start), jac=True, hess=hessian, method="trust-exact", options={"gtol": 1e-10, "maxiter": 2000})
    state = unpack(chain, result.x)
    state[2, -1] = 2 * np.pi
    return FreeFront(
        state=state,
        energy=float(result.fun),
        held_energy=held.energy,
        width=float(2 * np.pi / np.max(np.abs(np.diff(state[2])))),
        displacement=float(np.max(np.abs(state[:2])) / params.h),
        gradient=float(np.max(np.abs(result.jac))),
    )
