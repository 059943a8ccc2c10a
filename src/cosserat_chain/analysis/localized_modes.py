"""Host bands and localized (impurity, defect, end) modes of a finite chain, told apart by how they scale with its length.

Contract
--------
A graded chain (per-bond or per-particle factors) has no Bloch bands; its small oscillations about
rest (:func:`~cosserat_chain.analysis.dispersion.finite_modes` of the linear model) are the modes
its rotors meet. Most extend over the host chain; an impurity (a heavy rotor, a light mass, a soft
bond) or a pinned end may hold a mode of its own, localized about one particle, often in a gap of
the host's spectrum. Counted with the host's modes it widens a band down (or up) to it, and the gap
between them is lost.

:func:`classify_modes` tells the two kinds apart by their participation ratio
P = 1 / sum_k w_k^2, with w_k the share of particle k in the mode's energy (sum over its rows of
M a^2; a^T M a = 1, so sum_k w_k = 1): about P particles take part. An extended mode's P grows
with the chain (a standing wave's is 2/3 of the particles), a localized one's does not. So the
modes are solved again for the chain lengthened (:func:`lengthened`: each end's particle and the
bond beside it repeated outward, N -> 2N, n -> 2n - 1 particles), and a mode is localized when its
counterpart there (the mode of the same branch nearest in frequency) has a P grown by less than
sqrt(n' / n), the geometric middle between no growth and the chain's. The branches are split as
a uniform finite chain's are at its gap: modes with u alone (u decouples from v and phi at rest)
are longitudinal; of the others, sorted, as many as the chain has free v coordinates are
transverse acoustic, the rest rotational optical. Each host band is the range of its extended
modes; each localized mode is reported with its frequency, its branch, the particle that holds
most of its energy, P at both lengths, and its localization length (the decay of the particles'
amplitudes sqrt(w_k) away from that particle, fitted over the tail above round-off).
A pinned or free end holds modes of its own (end modes, in the gap below the optical band): they
are localized modes too, at the end particles.

The modes are :func:`finite_modes`'s of the linear model, from its symmetric band matrix
(:func:`~cosserat_chain.linalg.band_eigenpairs`, a ring's rows reordered into a band):
O((6N)^2) for the lengthened chain, with no dense matrix (benchmarks/bench_localized_modes.py).
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass

import numpy as np

from ..params import BOND_FACTORS, PARTICLE_FACTORS, ChainParams
from ..state import ROW_INDEX, free_rows
from .dispersion import BRANCHES, finite_modes

#: The particles' amplitudes sqrt(w_k) below this fraction of the peak are round-off, left out of the decay's fit.
TAIL_FLOOR = 1e-7


@dataclass(frozen=True)
class LocalizedMode:
    """A linear mode of the finite chain whose participation does not grow with its length.

    Attributes
    ----------
    frequency : float
        Angular frequency omega (rad per unit time).
    branch : str
        The branch of :data:`~cosserat_chain.analysis.dispersion.BRANCHES` it splits from.
    particle : int
        The particle (-N..N) holding the largest share of its energy.
    participation : float
        P = 1 / sum_k w_k^2 (particles) in the chain.
    participation_longer : float
        P of its counterpart in the lengthened chain (:func:`lengthened`).
    localization_length : float
        1 / kappa (particles), the particles' amplitudes falling as exp(-kappa |k - particle|)
        in its tail (:func:`_localization_length`); NaN where the tail holds fewer than two
        particles above round-off.
    shares : ndarray, shape (2N+1,)
        w_k, each particle's share of the mode's energy (sums to 1).
    """

    frequency: float
    branch: str
    particle: int
    participation: float
    participation_longer: float
    localization_length: float
    shares: np.ndarray

    def share_near(self, particles: tuple[int, ...], reach: int = 1) -> float:
        """The mode's energy share on ``particles`` (-N..N) and those within ``reach`` of them."""
        n = self.shares.size // 2
        near = {k for p in particles for k in range(p - reach, p + reach + 1) if -n <= k <= n}
        return float(sum(self.shares[k + n] for k in near))

    def as_dict(self) -> dict:
        """JSON-ready, without the shares."""
        return {
            "frequency": self.frequency,
            "branch": self.branch,
            "particle": self.particle,
            "participation": self.participation,
            "participation_longer": self.participation_longer,
            "localization_length": None if math.isnan(self.localization_length) else self.localization_length,
        }


@dataclass(frozen=True)
class ModeClasses:
    """A finite chain's linear modes split into host bands and localized modes (:func:`classify_modes`).

    Attributes
    ----------
    host_bands : dict of str to (float, float)
        Per branch the (bottom, top) of its extended modes; (NaN, NaN) if it has none.
    localized : tuple of LocalizedMode
        Sorted by frequency.
    growth_threshold : float
        sqrt(n' / n): a mode whose P grew less between the two lengths is localized.
    """

    host_bands: dict[str, tuple[float, float]]
    localized: tuple[LocalizedMode, ...]
    growth_threshold: float


def lengthened(params: ChainParams) -> ChainParams:
    """The chain with N more particles beyond each end, copies of the end particle and of the bond beside it (N -> 2N).

    A ring is cut open for this at its closing bond, which stays last.
    """
    changes: dict = {"N": 2 * params.N}
    pad = params.N
    for name in PARTICLE_FACTORS:
        factors = getattr(params, name)
        if factors is not None:
            changes[name] = (factors[0],) * pad + tuple(factors) + (factors[-1],) * pad
    for name in BOND_FACTORS:
        factors = getattr(params, name)
        if factors is not None:
            inner, closing = (factors[:-1], factors[-1:]) if params.periodic else (factors, ())
            changes[name] = (inner[0],) * pad + tuple(inner) + (inner[-1],) * pad + tuple(closing)
    return params.replace(**changes)


def _branches_and_shares(params: ChainParams) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Frequencies (n_modes,), branch index into BRANCHES (n_modes,) and energy shares (n_modes, 2N+1) of the elastic modes."""
    modes = finite_modes(params, "linear")
    frequencies = np.sqrt(np.clip(modes.omega2.real, 0.0, None))
    energy = params.particle_inertia[None] * np.abs(modes.shapes) ** 2  # (mode, row, particle)
    rows = np.sum(energy, axis=2)
    longitudinal = rows[:, ROW_INDEX["u"]] > rows[:, ROW_INDEX["v"]] + rows[:, ROW_INDEX["phi"]]
    branch = np.zeros(frequencies.size, dtype=int)
    transverse = np.flatnonzero(~longitudinal)
    transverse = transverse[np.argsort(frequencies[transverse], kind="stable")]
    acoustic = int(np.count_nonzero(free_rows(params) == ROW_INDEX["v"]))
    branch[transverse[:acoustic]] = 1
    branch[transverse[acoustic:]] = 2
    elastic = np.arange(frequencies.size) >= modes.rigid
    shares = np.sum(energy, axis=1)
    shares = shares / np.sum(shares, axis=1, keepdims=True)
    return frequencies[elastic], branch[elastic], shares[elastic]


def _localization_length(shares: np.ndarray, peak: int, periodic: bool) -> float:
    """1 / kappa from a least-squares fit of ln sqrt(w_k) against the distance to ``peak``, over the tail.

    The tail runs from the peak outward on each side while the amplitude keeps falling and stays
    above round-off: two modes of equal frequency at the two ends of a chain come out of the
    eigen solver mixed, each end holding half, and each half falls only to the chain's middle.
    """
    amplitude = np.sqrt(shares)
    n = shares.size
    floor = TAIL_FLOOR * amplitude[peak]
    distances, values = [], []
    for step in (-1, 1):
        k, d = peak, 0
        while True:
            nxt = (k + step) % n if periodic else k + step
            if not 0 <= nxt < n or d + 1 > n // 2 or not floor < amplitude[nxt] < amplitude[k]:
                break
            k, d = nxt, d + 1
            distances.append(d)
            values.append(math.log(amplitude[k]))
    if len(set(distances)) < 2:
        return math.nan
    return float(-1.0 / np.polyfit(distances, values, 1)[0])


@functools.lru_cache(maxsize=64)
def classify_modes(params: ChainParams) -> ModeClasses:
    """Split the chain's linear modes about rest into host bands and localized modes (module docstring).

    Parameters
    ----------
    params : ChainParams
        Any chain, graded or not, any ends or a ring.

    Returns
    -------
    ModeClasses
        Cached per chain (a family asks at every member): do not change it.
    """
    longer = lengthened(params)
    frequencies, branch, shares = _branches_and_shares(params)
    frequencies_l, branch_l, shares_l = _branches_and_shares(longer)
    participation = 1.0 / np.sum(shares**2, axis=1)
    participation_l = 1.0 / np.sum(shares_l**2, axis=1)
    threshold = math.sqrt(longer.n_particles / params.n_particles)
    localized = []
    extended = np.ones(frequencies.size, dtype=bool)
    for i in range(frequencies.size):
        same = np.flatnonzero(branch_l == branch[i])
        counterpart = same[np.argmin(np.abs(frequencies_l[same] - frequencies[i]))]
        if participation_l[counterpart] < threshold * participation[i]:
            extended[i] = False
            peak = int(np.argmax(shares[i]))
            localized.append(
                LocalizedMode(
                    frequency=float(frequencies[i]),
                    branch=BRANCHES[branch[i]],
                    particle=peak - params.N,
                    participation=float(participation[i]),
                    participation_longer=float(participation_l[counterpart]),
                    localization_length=_localization_length(shares[i], peak, params.periodic),
                    shares=shares[i],
                )
            )
    host = {}
    for b, name in enumerate(BRANCHES):
        band = frequencies[extended & (branch == b)]
        host[name] = (float(band.min()), float(band.max())) if band.size else (math.nan, math.nan)
    return ModeClasses(host_bands=host, localized=tuple(sorted(localized, key=lambda m: m.frequency)), growth_threshold=threshold)
