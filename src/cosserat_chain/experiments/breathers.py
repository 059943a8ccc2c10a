"""Roto-breathers: undamped periodic orbits in which one particle rotates and the rest oscillate.

Contract
--------
With gamma = 0 and no load, a chain whose particle ``particle`` turns k times per
period T = 2 pi k / Omega while the others oscillate about rest is a Hamiltonian
periodic orbit (:func:`~cosserat_chain.numerics.periodic.find_hamiltonian_orbit`).

* :func:`rotor_potential` and :func:`anti_continuum_state` give the anti-continuum
  limit: the rotating particle alone, its neighbours held at rest, is a one-degree-of-freedom
  rotor in the on-site potential V(phi) of its bonds (a pendulum, -c cos phi, for the sine
  model), whose rotation with mean rate Omega has the energy E solving
  T(E) = int_0^{2 pi} sqrt(J / (2 (E - V))) dphi = 2 pi / Omega. Its state (phi = 0,
  phi' = sqrt(2 (E - V(0)) / J), every other particle at rest) starts Newton.
* :func:`roto_breather_family` corrects it by Newton at the first frequency and follows
  the family in Omega (:func:`~cosserat_chain.numerics.periodic.continue_in_frequency`),
  with the Floquet multipliers of every orbit; with ``arclength`` by pseudo-arclength
  (:func:`~cosserat_chain.numerics.breather_arclength.continue_hamiltonian_arclength`),
  through the folds where Omega turns back, which it locates.
* :func:`lifetime` runs the undamped chain directly from a perturbed orbit and measures,
  period by period, how far it has left the orbit: the lifetime of an unstable roto-breather,
  and its growth per period against the largest Floquet multiplier.
* :func:`damped_to_undamped` follows the paper's damped, driven rotating orbit to zero
  damping at its own mean rate (:func:`~cosserat_chain.numerics.undamping.continue_to_undamped`:
  the viscosities scaled by s -> 0, the moment following) and compares where it lands with
  the roto-breather that :func:`roto_breather_family` finds from the anti-continuum limit at
  that frequency.
* :func:`resonances` gives the frequencies Omega = edge / n at which the n-th harmonic of
  the rotation meets a band edge (:func:`band_edges`: the infinite linear chain's,
  :func:`~cosserat_chain.analysis.dispersion.wave_summary`, or a graded chain's host bands,
  its finite extended modes), and :func:`harmonics_in_bands` the harmonics n Omega that fall
  inside a band: a roto-breather is non-resonant (localised, long-lived) only where none does.
  A graded chain's localized modes (:func:`~cosserat_chain.analysis.localized_modes.classify_modes`)
  are no band: :func:`core_modes` gives each one's energy share on the rotors and their
  neighbours, and :func:`resonances` lists a localized mode's Omega = frequency / n only where
  that share is at least :data:`CORE_SHARE` (a mode elsewhere in the chain is barely driven).
"""

from __future__ import annotations

import json
import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from functools import cached_property
from typing import TYPE_CHECKING

import numpy as np

from ..analysis.dispersion import BRANCHES, wave_summary
from ..analysis.localized_modes import LocalizedMode, classify_modes
from ..loads import moment_load
from ..models.base import Model, get_model
from ..numerics.breather_arclength import (
    ArclengthFamily,
    HamiltonianFrequencyProblem,
    continue_hamiltonian_arclength,
    continue_hamiltonian_field,
    pair_test,
)
from ..numerics.dynamics import integrate
from ..numerics.kit import StartError
from ..numerics.periodic import (
    CLOSURE_TOL,
    RTOL,
    HamiltonianFamily,
    HamiltonianOrbit,
    OrbitError,
    PeriodicOrbit,
    continue_in_frequency,
    find_hamiltonian_orbit,
    require_undamped,
)
from ..numerics.shooting import OrbitNotFound
from ..numerics.undamping import UndampingPath, continue_to_undamped
from ..params import ChainParams
from ..state import ROW_INDEX, ROWS, column, n_free, pack, unpack, zeros
from .anti_continuum import potential_from_torque, rotor_energy, sample_angles
from .lifetimes import Lifetime, check_lifetime_run, lifetime_from_deviation
from .simulation import run_attributes
from .system_breather_arclength import fold_accuracy
from .system_breathers import TIGHT_CLOSURE, TIGHT_RTOL, StabilityChange, branch_point_discriminant, locate_stability_changes

if TYPE_CHECKING:  # xarray is imported where a Dataset is built or read: commands without file output start without it
    import xarray as xr

ProgressCallback = Callable[[float, float], None]

#: Highest harmonic n of the rotation compared with the bands.
MAX_HARMONIC = 6
#: Times per period at which the tail's amplitude is sampled.
TAIL_SAMPLES = 32


def _rotor_forces(params: ChainParams, model: Model, particle: int) -> np.ndarray:
    """Forces (POTENTIAL_POINTS, 3, 2N+1) with ``particle`` turned to each of :func:`~.anti_continuum.sample_angles`, every other at rest."""
    col = column(params, particle)
    out = []
    for phi in sample_angles():
        x = zeros(params)
        x[ROW_INDEX["phi"], col] = phi
        out.append(model.forces(params, x))
    return np.array(out)


def rotor_potential(params: ChainParams, model: str | Model, particle: int = 0) -> Callable[[np.ndarray], np.ndarray]:
    """The on-site potential V(phi) of ``particle`` turned alone, every other particle at rest (V(0) = 0).

    From the torque -dV/dphi of the model's forces, sampled at
    :data:`~.anti_continuum.POTENTIAL_POINTS` angles and integrated as a Fourier series
    (:func:`~.anti_continuum.potential_from_torque`; the torque is 2 pi periodic with zero
    mean for every rotating model).

    Returns
    -------
    callable(phi ndarray) -> ndarray
    """
    return potential_from_torque(_rotor_forces(params, get_model(model), particle)[:, ROW_INDEX["phi"], column(params, particle)])


def coupled_bands(params: ChainParams, model: str | Model, particle: int = 0) -> tuple[str, ...]:
    """The bands the rotation drives: all but the longitudinal one where the rotor exerts no force along u.

    In the sine model u decouples (eq. (2) is linear in u and the angles enter only the
    v and phi equations), so its longitudinal band cannot resonate with the rotation.
    """
    forces = _rotor_forces(params, get_model(model), particle)
    drives_u = bool(np.any(forces[:, ROW_INDEX["u"], :] != 0.0))
    return tuple(name for name in BRANCHES if name != "longitudinal" or drives_u)


def anti_continuum_state(
    params: ChainParams, model: str | Model, omega: float, *, particle: int = 0
) -> tuple[np.ndarray, np.ndarray, float]:
    """The anti-continuum limit at frequency ``omega``: the rotor alone in its on-site potential.

    Returns
    -------
    x, v : ndarray (3, 2N+1)
        Every particle at rest but ``particle``, at phi = 0 with phi' = sqrt(2 E / J).
    energy : float
        The rotor's energy E: its turn takes 2 pi / omega.

    Raises
    ------
    ValueError
        For omega not finite and > 0, or too close to 0 for the rotor's turn to be resolved.
    """
    if not (math.isfinite(omega) and omega > 0):
        raise ValueError(f"omega must be a finite number > 0, got {omega!r}")
    potential = rotor_potential(params, model, particle)
    col = column(params, particle)
    inertia = float(params.particle_inertia[ROW_INDEX["phi"], col])
    energy = rotor_energy(potential, inertia, 2 * math.pi / omega)
    x, v = zeros(params), zeros(params)
    v[ROW_INDEX["phi"], col] = math.sqrt(2.0 * energy / inertia)
    return x, v, float(energy)


def rotors_start(
    params: ChainParams, model: str | Model, omega: float, *, turns: int = 1, particle: int = 0, partners: Mapping[int, int] | None = None
) -> tuple[np.ndarray, np.ndarray, float, np.ndarray]:
    """The anti-continuum start of a one- or multi-site roto-breather: each rotor alone in its on-site potential.

    ``particle`` turns ``turns`` times per period, each of ``partners`` (particle: signed
    turns) its own, starting at phi = 0 with the velocity of its anti-continuum rotor at its
    rate; every other particle is at rest.

    Returns
    -------
    x, v : ndarray (3, 2N+1)
    energy : float
        The first rotor's energy.
    particle_turns : ndarray (2N+1,) of int
        Every particle's signed turns per period.

    Raises
    ------
    ValueError
        As :func:`anti_continuum_state`, or for a partner that is the rotor or has no non-zero integer turns.
    """
    model = get_model(model)
    x, v, energy = anti_continuum_state(params, model, omega, particle=particle)
    particle_turns = np.zeros(params.n_particles, dtype=np.int64)
    particle_turns[column(params, particle)] = turns
    for other, other_turns in (partners or {}).items():
        if other == particle or not isinstance(other_turns, int) or isinstance(other_turns, bool) or other_turns == 0:
            raise ValueError(
                f"partners must map particles other than the rotating one ({particle}) to non-zero integer turns, "
                f"got {other!r}: {other_turns!r}"
            )
        rate = omega * abs(other_turns) / turns
        v[ROW_INDEX["phi"], column(params, other)] = math.copysign(
            anti_continuum_state(params, model, rate, particle=other)[1][ROW_INDEX["phi"], column(params, other)], other_turns
        )
        particle_turns[column(params, other)] = other_turns
    return x, v, energy, particle_turns


@dataclass(frozen=True)
class Resonance:
    """A harmonic of the rotation meeting a band edge: n Omega = edge."""

    omega: float
    harmonic: int
    band: str
    edge: str
    edge_frequency: float

    def as_dict(self) -> dict:
        return {"omega": self.omega, "harmonic": self.harmonic, "band": self.band, "edge": self.edge, "edge_frequency": self.edge_frequency}


#: Where :func:`band_edges` takes a chain's bands from: the infinite uniform chain, or the finite graded chain's extended modes.
BAND_SOURCES = {False: "infinite uniform chain, eq. (3)", True: "finite graded chain's extended linear modes"}
#: A localized mode is a resonance of a roto-breather only where at least this share of its energy lies on the
#: rotors and their neighbours (the breather's core): its drive by the rotation scales with its amplitude there.
CORE_SHARE = 0.01


def band_edges(params: ChainParams) -> dict[str, tuple[float, float]]:
    """The (bottom, top) of each band (:data:`~cosserat_chain.analysis.dispersion.BRANCHES`) the chain's rotors meet.

    A uniform chain's are those of the infinite linear chain, eq. (3) (:func:`wave_summary`),
    to which every model linearises at rest. A graded chain (per-bond or per-particle factors)
    is not periodic and has no bands; its harmonics meet its own small oscillations instead, the
    linear modes of the finite chain about rest, and its bands are the host bands of
    :func:`~cosserat_chain.analysis.localized_modes.classify_modes`: the ranges of its extended
    modes, split into the three branches (the modes with u alone longitudinal; of the others,
    sorted, as many as the chain has free v coordinates transverse acoustic and the rest
    rotational optical). Its localized modes (an impurity's, an end's) are not in them
    (:func:`core_modes`).
    """
    if not params.graded:
        return wave_summary(params).bands
    return dict(classify_modes(params).host_bands)  # a copy: the cached one is shared


def core_modes(params: ChainParams, rotors: tuple[int, ...] = (0,)) -> list[tuple[LocalizedMode, float]]:
    """A graded chain's localized modes, each with its energy share on ``rotors`` (-N..N) and their neighbours.

    A uniform chain has none here: its bands are the infinite chain's. A mode whose share is
    at least :data:`CORE_SHARE` is a resonance of the rotors' harmonics (:func:`resonances`).
    """
    if not params.graded:
        return []
    return [(mode, mode.share_near(rotors)) for mode in classify_modes(params).localized]


def localized_mode_summary(params: ChainParams, rotors: tuple[int, ...] = (0,)) -> list[dict]:
    """JSON-ready :func:`core_modes`: each mode with its ``core_share`` and whether it is a resonance (``resonant``)."""
    return [{**mode.as_dict(), "core_share": share, "resonant": share >= CORE_SHARE} for mode, share in core_modes(params, rotors)]


def resonances(
    params: ChainParams,
    low: float,
    high: float,
    *,
    bands: tuple[str, ...] = BRANCHES,
    max_harmonic: int = MAX_HARMONIC,
    rotors: tuple[int, ...] = (0,),
) -> list[Resonance]:
    """The frequencies Omega in [low, high] where n Omega (n = 1..max_harmonic) meets an edge of ``bands``, sorted by Omega.

    The bands are :func:`band_edges`: the infinite linear chain's, or a graded chain's host
    bands. A graded chain's localized modes of those branches whose share on ``rotors`` (-N..N)
    and their neighbours is at least :data:`CORE_SHARE` (:func:`core_modes`) are resonances too,
    with edge ``"localized"`` and their frequency as the edge's.
    """
    out = [
        Resonance(mode.frequency / n, n, mode.branch, "localized", mode.frequency)
        for mode, share in core_modes(params, rotors)
        if mode.branch in bands and share >= CORE_SHARE
        for n in range(1, max_harmonic + 1)
        if low <= mode.frequency / n <= high
    ]
    for band, (bottom, top) in band_edges(params).items():
        if band not in bands:
            continue
        for edge, frequency in (("bottom", bottom), ("top", top)):
            if frequency <= 0:
                continue
            for n in range(1, max_harmonic + 1):
                if low <= frequency / n <= high:
                    out.append(Resonance(frequency / n, n, band, edge, frequency))
    return sorted(out, key=lambda r: r.omega)


def harmonics_in_bands(
    params: ChainParams, omega: float, *, bands: tuple[str, ...] = BRANCHES, max_harmonic: int = MAX_HARMONIC
) -> list[tuple[int, str]]:
    """The (n, band) with n ``omega`` inside one of ``bands`` (n = 1..max_harmonic): the resonant harmonics."""
    edges = band_edges(params)
    return [(n, band) for n in range(1, max_harmonic + 1) for band in bands if edges[band][0] <= n * omega <= edges[band][1]]


def combination_resonances(
    params: ChainParams, omega: float, *, bands: tuple[str, ...] = BRANCHES, max_harmonic: int = MAX_HARMONIC
) -> list[tuple[int, str, str]]:
    """The (n, band A, band B) with w_A + w_B = n ``omega`` for some w_A, w_B in the bands (A = B included).

    The rotation modulates the chain's stiffness with period T = 2 pi k / Omega: a pair of
    phonons whose frequencies add up to a harmonic of Omega is parametrically excited (its
    Floquet multipliers, exp(+-i w T), collide off the unit circle), so these are the
    frequencies where a roto-breather of a long chain may be unstable even with every
    harmonic in a gap.
    """
    edges = band_edges(params)
    out = []
    for n in range(1, max_harmonic + 1):
        for i, a in enumerate(bands):
            for b in bands[i:]:
                if edges[a][0] + edges[b][0] <= n * omega <= edges[a][1] + edges[b][1]:
                    out.append((n, a, b))
    return out


@dataclass(eq=False)
class _Member:
    """A chain's orbit as :func:`~.system_breathers.locate_stability_change` reads a member.

    ``y0`` is the free coordinates, then their velocities; ``monodromy`` is integrated again at the
    orbit's ``rtol`` (the chain's orbits keep their multipliers, not the matrix).
    """

    orbit: HamiltonianOrbit
    rtol: float = RTOL

    @property
    def y0(self) -> np.ndarray:
        return np.concatenate([pack(self.orbit.params, self.orbit.x), pack(self.orbit.params, self.orbit.v)])

    @property
    def period(self) -> float:
        return self.orbit.period

    @property
    def stable(self) -> bool:
        return self.orbit.stable

    @property
    def multipliers(self) -> np.ndarray:
        return self.orbit.multipliers

    @property
    def nontrivial_multipliers(self) -> np.ndarray:
        return self.orbit.nontrivial_multipliers

    @cached_property
    def monodromy(self) -> np.ndarray:
        problem = HamiltonianFrequencyProblem(self.orbit, 0.0, math.inf, rtol=self.rtol, atol=self.rtol)
        return problem.evaluate(problem.start(), True).data


def _solvers(
    orbit: HamiltonianOrbit, field: str | None = None
) -> tuple[Callable[[np.ndarray, float], _Member], Callable[[_Member], _Member | None]]:
    """``solve(y0, period)``: the member of ``orbit``'s family with that period from the start ``y0`` (OrbitNotFound where
    Newton fails), with ``field`` instead ``solve(y0, value)``: the member at ``orbit``'s frequency on the chain with that
    value of the field (:func:`chain_at`); ``tighten(member)``: the same orbit on its chain at
    :data:`~.system_breathers.TIGHT_RTOL` (None where it fails)."""
    nf = n_free(orbit.params)

    def find(params: ChainParams, y0: np.ndarray, period: float, tol: float = CLOSURE_TOL, rtol: float = RTOL) -> _Member:
        try:
            found = find_hamiltonian_orbit(
                params, orbit.model, 2 * math.pi * orbit.turns / period, (unpack(params, y0[:nf]), unpack(params, y0[nf:])),
                turns=orbit.turns, particle=orbit.particle, particle_turns=orbit.particle_turns, tol=tol, rtol=rtol, atol=rtol,
            )  # fmt: skip
        except OrbitError as err:
            raise OrbitNotFound(str(err)) from None
        return _Member(found, rtol)

    def solve(y0: np.ndarray, at: float) -> _Member:
        return find(orbit.params, y0, at) if field is None else find(chain_at(orbit.params, field, at), y0, orbit.period)

    def tighten(member: _Member) -> _Member | None:
        try:
            return find(member.orbit.params, member.y0, member.period, TIGHT_CLOSURE, TIGHT_RTOL)
        except OrbitNotFound:
            return None

    return solve, tighten


def located_changes(orbits: list[HamiltonianOrbit], bands: tuple[str, ...], tol: float | None = None) -> list[StabilityChange]:
    """Where stability changes between consecutive members of a family in Omega whose pairs off the unit circle differ.

    Each bracketed by bisection in the period on the multipliers' moduli, then placed at the zero of
    the colliding pair's discriminant with its accuracy measured against the orbits found again at
    :data:`~.system_breathers.TIGHT_RTOL` (:func:`~.system_breathers.locate_stability_change`, the
    user systems' mechanism, :func:`~.system_breathers.locate_stability_changes`: two pairs crossing
    between the same members give two changes). The resonances are named by the index of their band
    in ``bands``; ``tol`` is the accuracy in Omega wanted (None: the full bisections and secant).
    """
    if len(orbits) < 2:
        return []
    solve, tighten = _solvers(orbits[0])
    edges = band_edges(orbits[0].params)
    driven = [edges[name] for name in bands]
    return [
        change
        for a, b in zip(orbits[:-1], orbits[1:], strict=True)
        for change in locate_stability_changes(_Member(a), _Member(b), solve, driven, a.turns, tighten, tol)
    ]


#: The most orbits the kit's driver traces from a natural member (:func:`natural_events`).
SEGMENT_POINTS = 60


def _unknowns(orbit: HamiltonianOrbit) -> np.ndarray:
    """The orbit's unknowns w = (y0 without phi_rotor, eps, Omega) of the driver's problem in Omega."""
    return HamiltonianFrequencyProblem(orbit, 0.0, math.inf).start()


def natural_events(orbits: list[HamiltonianOrbit], requested: np.ndarray) -> list[dict]:
    """The natural family's folds and branch points, traced by the kit's driver in Omega where they can lie.

    Natural steps pass a branch point (a nontrivial pair through +1) unseen or as a change of
    stability, and stop before a fold, so the driver
    (:func:`~cosserat_chain.numerics.breather_arclength.continue_hamiltonian_arclength`, at most
    :data:`SEGMENT_POINTS` orbits) traces the family from each member to the next where
    :func:`~cosserat_chain.numerics.breather_arclength.pair_test` changes sign between them (an odd
    number of pairs through +1: a branch point, or the energy's extremum, where the driver finds
    none), and from the last member towards the next frequency asked for where the family ends before it.

    Returns
    -------
    list of dict
        Per event: ``kind`` (``fold``, ``branch_point``), ``omega`` and ``accuracy`` (a branch point:
        the zero of its pair's discriminant, :func:`branch_discriminants`, and the kit's location
        ``kit_omega``; a fold: the kit's location, and the distance to the vertex of the parabola
        through it and its two neighbours, :func:`~.system_breather_arclength.fold_accuracy`),
        ``energy``, ``max_multiplier``, ``located`` and ``between``, the members it lies between (the
        last and None past it); ``untraced`` (with its ``message``) where the driver could not start
        from the member.
    """
    segments = [
        (orbits[i], orbits[i + 1].omega, [i, i + 1]) for i in range(len(orbits) - 1) if pair_test(orbits[i]) != pair_test(orbits[i + 1])
    ]
    if orbits and len(orbits) < len(requested):
        segments.append((orbits[-1], float(requested[len(orbits)]), [len(orbits) - 1, None]))
    out = []
    for start, target, between in segments:
        if target == start.omega:
            continue
        try:
            trace = continue_hamiltonian_arclength(
                start, min(start.omega, target), max(start.omega, target), direction=math.copysign(1.0, target - start.omega),
                max_points=SEGMENT_POINTS,
            )  # fmt: skip
        except StartError as err:  # the member does not correct as the driver's start (beside a singular point)
            out.append({"kind": "untraced", "omega": start.omega, "between": between, "message": str(err)})
            continue
        zeros = branch_discriminants(trace)
        for j, e in enumerate(trace.events):
            entry = {"kind": e.kind, "omega": e.parameter, "accuracy": None, "energy": e.point.energy,
                     "max_multiplier": e.point.max_multiplier, "located": e.located, "between": between}  # fmt: skip
            if e.kind == "branch_point":
                entry["kit_omega"] = e.parameter
                if zeros.get(j) is not None:
                    entry["omega"], entry["accuracy"] = zeros[j]
            elif e.kind == "fold" and e.located and e.tangent is not None:
                entry["accuracy"] = fold_accuracy(trace.orbits, e.point, e.tangent, e.index, _unknowns, lambda o: o.omega)
            out.append(entry)
    return out


def branch_discriminants(family: ArclengthFamily) -> dict[int, tuple[float, float] | None]:
    """Per index of a branch point in the events of a family traced in Omega: the zero of the discriminant of its
    pair through +1 and its accuracy (:func:`~.system_breathers.branch_point_discriminant`, from the two
    orbits around it), None where that pair's discriminant is not resolved there."""
    orbits = family.orbits
    if family.parameter != "omega" or not orbits:
        return {}
    solve, tighten = _solvers(orbits[0])
    return {
        i: branch_point_discriminant(_Member(orbits[e.index - 1]), _Member(orbits[e.index]), solve, orbits[0].turns, tighten)
        for i, e in enumerate(family.events)
        if e.kind == "branch_point" and 1 <= e.index < len(orbits)
    }


@dataclass
class BreatherFamily:
    """A family of roto-breathers (one rotor, or several with ``partners``) followed in Omega, with the band picture beside it.

    Attributes
    ----------
    family : HamiltonianFamily
    anti_continuum_energy : float
        The rotor's energy at the first frequency (the anti-continuum start).
    bands : tuple of str
        The bands the rotation drives (:func:`coupled_bands`).
    resonances : list of Resonance
        Edges of those bands met by a harmonic within the requested frequencies.
    settings : dict
    changes : list of StabilityChange
        Where the natural family's stability changes between members (:func:`located_changes`).
    events : list of dict or None
        The natural family's folds and branch points (:func:`natural_events`), with ``locate``.
    discriminants : dict
        For a family traced by pseudo-arclength in Omega: per index of a branch point in its
        events, the zero of its pair's discriminant and the accuracy (or None where unresolved;
        :func:`~.system_breathers.branch_point_discriminant`).
    """

    family: HamiltonianFamily
    anti_continuum_energy: float
    bands: tuple[str, ...]
    resonances: list[Resonance]
    settings: dict = field(default_factory=dict)
    lifetimes: list[Lifetime] | None = None
    changes: list[StabilityChange] = field(default_factory=list)
    discriminants: dict[int, tuple[float, float] | None] = field(default_factory=dict)
    events: list[dict] | None = None
    _tail: np.ndarray | None = field(default=None, init=False, repr=False)

    def measure_lifetimes(
        self, max_periods: int, *, perturbation: float = 1e-8, threshold: float = 1e-2, progress: ProgressCallback | None = None
    ) -> list[Lifetime]:
        """Run every member from its perturbed orbit (:func:`lifetime`) and keep the lifetimes with the family.

        They go into :meth:`as_dict` (``lifetimes``), :meth:`to_dataset` and the family's figure.

        Parameters
        ----------
        max_periods : int
            Length of each run in periods.
        perturbation, threshold : float
            Of :func:`lifetime`.
        progress : callable(done, total), optional
            Called after each member.

        Raises
        ------
        ValueError
            As :func:`lifetime` does.
        """
        orbits = self.family.orbits
        out = []
        for i, orbit in enumerate(orbits):
            out.append(lifetime(orbit, perturbation=perturbation, threshold=threshold, max_periods=max_periods))
            if progress is not None:
                progress(i + 1, len(orbits))
        self.lifetimes = out
        self.settings["lifetime"] = {"max_periods": max_periods, "perturbation": perturbation, "threshold": threshold}
        return out

    def resonant_harmonics(self) -> list[list[tuple[int, str]]]:
        """For every orbit, the harmonics n Omega inside a driven band."""
        return [harmonics_in_bands(o.params, o.omega, bands=self.bands) for o in self.family.orbits]

    def combination_resonances(self) -> list[list[tuple[int, str, str]]]:
        """For every orbit, the phonon pairs of driven bands with w_A + w_B = n Omega (:func:`combination_resonances`)."""
        return [combination_resonances(o.params, o.omega, bands=self.bands) for o in self.family.orbits]

    def mode_picture(self) -> dict:
        """The bands the harmonics were held against and the chain's localized modes, JSON-ready.

        ``host_bands``: :func:`band_edges` of the first orbit's chain; ``localized_modes``: its
        :func:`core_modes` on the rotors (the particle and its partners), each with its
        ``core_share`` and whether it counts as a resonance (``resonant``: share >= :data:`CORE_SHARE`).
        """
        orbits = self.family.orbits
        if not orbits:
            return {"host_bands": None, "localized_modes": []}
        rotors = (self.settings.get("particle", orbits[0].particle), *(self.settings.get("partners") or {}))
        params = orbits[0].params
        return {
            "host_bands": {name: list(edge) for name, edge in band_edges(params).items()},
            "localized_modes": localized_mode_summary(params, rotors),
        }

    def localization(self) -> np.ndarray:
        """Per orbit, the largest |u|, |v|, |phi| of the particles that do not turn, over the period (the tail's amplitude).

        Sampled at :data:`TAIL_SAMPLES` times: on the section itself the sine model's orbits have
        every coordinate at 0 (its forces are odd, so (q, q') -> (-q, q') reverses time).
        """
        if self._tail is None:
            # Computed once: it integrates every orbit again.
            out = []
            for o in self.family.orbits:
                x, _ = o.trajectory(o.period * np.arange(1, TAIL_SAMPLES + 1) / TAIL_SAMPLES)
                others = np.delete(x, np.flatnonzero(o.particle_turns), axis=2)
                out.append(float(np.max(np.abs(others), initial=0.0)))
            self._tail = np.array(out)
        return self._tail

    def as_dict(self) -> dict:
        """JSON-ready summary of the family."""
        orbits = self.family.orbits
        return {
            "model": self.settings.get("model"),
            "turns": self.settings.get("turns"),
            "particle": self.settings.get("particle"),
            "partners": {str(k): t for k, t in (self.settings.get("partners") or {}).items()},
            "requested_omega": self.family.requested.tolist(),
            "complete": self.family.complete,
            "message": self.family.message,
            "anti_continuum_energy": self.anti_continuum_energy,
            "omega": self.family.omega.tolist(),
            "period": [o.period for o in orbits],
            "energy": [o.energy for o in orbits],
            "rotor_velocity": [float(o.v[ROW_INDEX["phi"], column(o.params, o.particle)]) for o in orbits],
            "tail_amplitude": self.localization().tolist(),
            "max_multiplier": self.family.max_multiplier.tolist(),
            "stable": self.family.stable.tolist(),
            "unfolding": [o.unfolding for o in orbits],
            "closure": [o.closure for o in orbits],
            "bands": list(self.bands),
            "bands_from": BAND_SOURCES[orbits[0].params.graded] if orbits else None,
            **self.mode_picture(),
            "resonant_harmonics": [[{"harmonic": n, "band": b} for n, b in h] for h in self.resonant_harmonics()],
            "combination_resonances": [[{"harmonic": n, "bands": [a, b]} for n, a, b in h] for h in self.combination_resonances()],
            "resonances": [r.as_dict() for r in self.resonances],
            "stability_changes": self._changes(),
            **(
                {"events": self._events()}
                if isinstance(self.family, ArclengthFamily)
                else {"events": self.events}
                if self.events is not None
                else {}
            ),
            **(
                {}
                if not isinstance(self.family, ArclengthFamily) or self.family.parameter == "omega"
                else {"parameter": self.family.parameter, "values": self.family.values.tolist()}
            ),
            **({} if self.lifetimes is None else {"lifetimes": [life.as_dict() for life in self.lifetimes]}),
        }

    def _changes(self) -> list[dict]:
        """The located changes of stability (:meth:`~.system_breathers.StabilityChange.as_dict`), bands by name."""
        out = []
        for change in self.changes:
            entry = change.as_dict()
            for key in ("resonance", "nearest_resonance"):
                entry[key]["band"] = self.bands[entry[key]["band"]]
            out.append(entry)
        return out

    def _events(self) -> list[dict]:
        """The arclength family's folds and branch points: kind, Omega, energy, largest multiplier, the orbits they lie between.

        An event the secant method did not locate (``located`` False) is given at the orbit after its sign change.
        A family followed in a field at a fixed frequency gives the field's value there as ``value``. Each has
        the fixed-parameter Newton system's ``singular_value`` and the pair at +1's ``split_before`` and
        ``split_after`` (:attr:`~cosserat_chain.numerics.breather_arclength.ArclengthFamily.diagnostics`). A branch point
        of a family in Omega has the zero of its pair's discriminant (``discriminant_value``,
        ``discriminant_accuracy``: :attr:`discriminants`; None where it was not resolved).
        """
        along = self.family.parameter != "omega"
        return [
            {
                "kind": e.kind,
                **({"parameter": self.family.parameter, "value": float(getattr(e.point.params, self.family.parameter))} if along else {}),
                "omega": e.point.omega if along or not e.located else e.parameter,
                "energy": e.point.energy,
                "max_multiplier": e.point.max_multiplier,
                "located": e.located,
                "between": [e.index - 1, e.index],
                **diagnostic,
                **({} if branch is None else {"branch": _branch_summary(branch, self.family.parameter)}),
                **(
                    {}
                    if i not in self.discriminants
                    else dict(zip(("discriminant_value", "discriminant_accuracy"), self.discriminants[i] or (None, None), strict=True))
                ),
            }
            for i, (e, diagnostic, branch) in enumerate(
                zip(
                    self.family.events,
                    self.family.diagnostics or [{}] * len(self.family.events),
                    self.family.branches or [None] * len(self.family.events),
                    strict=True,
                )
            )
        ]

    def to_dataset(self) -> xr.Dataset:
        """Dataset with dims ``point`` (the family), ``particle`` and ``multiplier``; parameters in the attributes."""
        import xarray as xr

        orbits = self.family.orbits
        if not orbits:
            raise ValueError("the family holds no orbit: nothing to write")
        params = orbits[0].params
        data = {
            "omega": (("point",), self.family.omega),
            "period": (("point",), np.array([o.period for o in orbits])),
            "energy": (("point",), self.family.energy),
            "max_multiplier": (("point",), self.family.max_multiplier),
            "stable": (("point",), self.family.stable.astype(np.int8)),
            "tail_amplitude": (("point",), self.localization()),
            "multiplier_real": (("point", "multiplier"), np.array([o.multipliers.real for o in orbits])),
            "multiplier_imag": (("point", "multiplier"), np.array([o.multipliers.imag for o in orbits])),
        }
        for i, row in enumerate(ROWS):
            data[row] = (("point", "particle"), np.array([o.x[i] for o in orbits]))
            data[f"{row}_dot"] = (("point", "particle"), np.array([o.v[i] for o in orbits]))
        coords = {
            "point": np.arange(len(orbits)),
            "particle": np.arange(-params.N, params.N + 1),
            "multiplier": np.arange(orbits[0].multipliers.size),
        }
        ds = xr.Dataset(data, coords=coords)
        # Variables the shared CF table (io.VARIABLES) does not describe.
        ds["omega"].attrs.update(units="rad", long_name="mean angular velocity Omega = 2 pi k / T of the rotating particle")
        ds["energy"].attrs.update(units="1", long_name="total energy of the orbit (NaN: the model has no energy)")
        ds["tail_amplitude"].attrs.update(units="1", long_name="largest |u|, |v|, |phi| of the non-rotating particles over a period")
        if self.lifetimes is not None:
            lives = self.lifetimes
            ds["lifetime_periods"] = (
                "point",
                np.array([math.nan if life.periods is None else life.periods for life in lives], dtype=float),
            )
            ds["lifetime_periods"].attrs.update(
                units="1", long_name="periods of a direct run from the perturbed orbit until it left it (NaN: it stayed for the whole run)"
            )
            ds["growth_per_period"] = ("point", np.array([life.growth_per_period for life in lives]))
            ds["growth_per_period"].attrs.update(units="1", long_name="growth of the deviation per period in the direct run")
            ds["predicted_lifetime_periods"] = ("point", np.array([life.predicted_periods for life in lives]))
            ds["predicted_lifetime_periods"].attrs.update(
                units="1", long_name="ln(threshold / perturbation) / ln max|mu| (NaN: a stable orbit); the run's settings in settings_json"
            )
        ds.attrs.update(run_attributes(params, get_model(orbits[0].model), moment_load(0.0, orbits[0].particle)))
        picture = self.mode_picture()
        ds.attrs.update(
            {
                "experiment": "roto_breathers",
                "turns": orbits[0].turns,
                "rotating_particle": orbits[0].particle,
                "complete": int(self.family.complete),
                "message": self.family.message,
                "bands": ", ".join(self.bands),
                "bands_from": BAND_SOURCES[params.graded],
                "host_bands_json": json.dumps(picture["host_bands"]),
                "localized_modes_json": json.dumps(picture["localized_modes"]),
                "resonances_json": json.dumps([r.as_dict() for r in self.resonances]),
                "stability_changes_json": json.dumps(self._changes()),
                "settings_json": json.dumps({k: v for k, v in self.settings.items() if k != "params"}),
            }
        )
        if isinstance(self.family, ArclengthFamily):
            ds.attrs["events_json"] = json.dumps(self._events())
        elif self.events is not None:
            ds.attrs["events_json"] = json.dumps(self.events)
        return ds


def _branch_summary(branch, parameter: str) -> dict:
    """A followed branch for the JSON: the relocated branch point, its accuracy, and per orbit Omega (or the field), energy, max |mu|."""

    def value(o) -> float:
        return o.omega if parameter == "omega" else float(getattr(o.params, parameter))

    return {
        "at": value(branch.point),
        "accuracy": branch.accuracy,
        "values": [value(o) for o in branch.orbits],
        "energy": [o.energy for o in branch.orbits],
        "max_multiplier": [o.max_multiplier for o in branch.orbits],
        "message": branch.message,
    }


def roto_breather_family(
    params: ChainParams,
    model: str | Model,
    omegas: np.ndarray | list[float],
    *,
    turns: int = 1,
    particle: int = 0,
    partners: Mapping[int, int] | None = None,
    progress: ProgressCallback | None = None,
    arclength: bool = False,
    max_points: int = 200,
    along: tuple[str, float] | None = None,
    branches: bool = False,
    locate: bool = True,
) -> BreatherFamily:
    """One-site roto-breathers at the frequencies ``omegas``, from the anti-continuum limit at the first.

    Parameters
    ----------
    params : ChainParams
        Undamped (gamma_u = gamma_v = gamma_phi = 0).
    model : str or Model
        ``sine`` or ``nonlinear``.
    omegas : sequence of float
        Frequencies Omega > 0 of the rotating particle (mean angular velocity), in the order followed.
    turns : int
        k: the rotating particle's turns per period (T = 2 pi k / Omega).
    particle : int
        The rotating particle (its angle is 0 on the section).
    partners : {particle: signed turns}, optional
        Other rotors of a multi-site roto-breather and their turns per period: ``{1: turns}``
        turns particle 1 with it, ``{1: -turns}`` against it. Each starts as its own
        anti-continuum rotor at phi = 0.
    progress : callable(done, total), optional
    arclength : bool
        Follow the family by pseudo-arclength from ``omegas[0]`` towards ``omegas[-1]`` until
        Omega leaves [min(omegas), max(omegas)] (or ``max_points`` orbits): the orbits are the
        driver's, not at ``omegas``, and folds in Omega are passed and located
        (:class:`~cosserat_chain.numerics.breather_arclength.ArclengthFamily`).
    max_points : int
        With ``arclength``, the most orbits traced.
    along : (str, float), optional
        With ``arclength``: follow the family at the frequency ``omegas[0]`` in this field of the
        chain (:data:`ATLAS_FIELDS`: a coupling or a geometric field) from its
        value to the one given, instead of in Omega
        (:func:`~cosserat_chain.numerics.breather_arclength.continue_hamiltonian_field`); a or b
        carry the inertia j with them where it is their rectangle's (:func:`chain_at`).
    branches : bool
        With ``arclength``: relocate each branch point and follow the family crossing it
        (:func:`~cosserat_chain.numerics.breather_arclength.follow_branches`; in the events' ``branch``).
    locate : bool
        Locate every change of stability between the members (:func:`located_changes`: the
        discriminant's zero with its accuracy) and the folds and branch points by the kit's driver
        where they can lie (:func:`natural_events`); with ``arclength`` in Omega, give every branch
        point the zero of its pair's discriminant instead (:attr:`BreatherFamily.discriminants`).

    Returns
    -------
    BreatherFamily

    Raises
    ------
    ValueError
        For a damped chain, an empty or non-positive ``omegas``, and with ``arclength`` fewer than
        two distinct frequencies.
    OrbitError
        If Newton fails at the first frequency (no roto-breather found from the anti-continuum start).
    """
    model = get_model(model)
    require_undamped(params)
    omegas = np.asarray(omegas, dtype=float)
    if omegas.ndim != 1 or omegas.size == 0 or not np.all(np.isfinite(omegas)) or np.any(omegas <= 0):
        raise ValueError(f"omegas must be one or more finite frequencies > 0, got {omegas.tolist()!r}")
    if branches and not arclength:
        raise ValueError("branches are followed off a family traced by pseudo-arclength: set arclength=True")
    if along is not None:
        return _along_field(params, model, omegas, along, turns, particle, partners, progress, arclength, max_points, branches)
    if arclength and omegas[-1] == omegas[0]:
        raise ValueError(
            f"omegas must start and end at different frequencies for arclength (the direction and range), got {omegas.tolist()!r}"
        )
    partners = dict(partners or {})
    x, v, energy, particle_turns = rotors_start(params, model, float(omegas[0]), turns=turns, particle=particle, partners=partners)
    first = find_hamiltonian_orbit(params, model, float(omegas[0]), (x, v), turns=turns, particle=particle, particle_turns=particle_turns)
    if arclength:
        family = continue_hamiltonian_arclength(
            first, float(omegas.min()), float(omegas.max()), direction=math.copysign(1.0, omegas[-1] - omegas[0]),
            max_points=max_points, progress=progress, branches=branches,
        )  # fmt: skip
    else:
        family = continue_in_frequency(first, omegas, progress=progress)
    settings = {"model": model.name, "turns": turns, "particle": particle, "partners": partners, "params": params.model_dump()}
    if arclength:
        settings["arclength"] = True
    bands = coupled_bands(params, model, particle)
    changes, discriminants, events = [], {}, None
    if locate and not arclength:
        changes = located_changes(family.orbits, bands)
        events = natural_events(family.orbits, family.requested)
    elif locate:
        discriminants = branch_discriminants(family)
    return BreatherFamily(
        family=family,
        anti_continuum_energy=energy,
        bands=bands,
        resonances=resonances(params, float(omegas.min()), float(omegas.max()), bands=bands, rotors=(particle, *partners)),
        settings=settings,
        changes=changes,
        discriminants=discriminants,
        events=events,
    )


#: The fields an atlas may vary: the geometry (a, b, h) and the links' stiffnesses.
ATLAS_FIELDS = ("a", "b", "h", "E1", "E2")


def chain_at(params: ChainParams, field: str, value: float) -> ChainParams:
    """``params`` with ``field`` = ``value``; a change of a or b re-derives j = m (a^2 + b^2) / 3 where the chain's j is that default.

    A particle is a 2a x 2b rectangle: its moment of inertia follows its shape unless it was given apart.

    Raises
    ------
    ValueError
        For a value the chain refuses (naming the field).
    """
    changes: dict = {field: float(value)}
    if field in ("a", "b") and math.isclose(params.j, params.m * (params.a**2 + params.b**2) / 3.0, rel_tol=1e-12):
        changes["j"] = None
    return params.replace(**changes)


def _along_field(params, model, omegas, along, turns, particle, partners, progress, arclength, max_points, branches) -> BreatherFamily:
    """:func:`roto_breather_family` with ``along``: the family at ``omegas[0]`` followed in a chain field by pseudo-arclength."""
    if not arclength:
        raise ValueError("along follows the family by pseudo-arclength: set arclength=True")
    name, target = along
    if name not in ATLAS_FIELDS:
        raise ValueError(f"along: the field must be one of {', '.join(ATLAS_FIELDS)}, got {name!r}")
    here = float(getattr(params, name))
    if not (isinstance(target, (int, float)) and math.isfinite(target)) or target == here:
        raise ValueError(f"along: {name} must go to a finite value other than its {here!r}, got {target!r}")
    chain_at(params, name, target)  # a target the chain refuses is named before any solve
    partners = dict(partners or {})
    omega = float(omegas[0])
    x, v, energy, particle_turns = rotors_start(params, model, omega, turns=turns, particle=particle, partners=partners)
    first = find_hamiltonian_orbit(params, model, omega, (x, v), turns=turns, particle=particle, particle_turns=particle_turns)
    family = continue_hamiltonian_field(
        first, name, lambda value: chain_at(params, name, value), min(here, target), max(here, target),
        direction=1.0 if target > here else -1.0, max_points=max_points, progress=progress, branches=branches,
    )  # fmt: skip
    settings = {
        "model": model.name, "turns": turns, "particle": particle, "partners": partners, "params": params.model_dump(),
        "arclength": True, "along": [name, float(target)],
    }  # fmt: skip
    bands = coupled_bands(params, model, particle)
    return BreatherFamily(
        family=family, anti_continuum_energy=energy, bands=bands, resonances=resonances(params, omega, omega, bands=bands, rotors=(particle, *partners)),
        settings=settings,
    )  # fmt: skip


#: Time steps per period of the direct runs of :func:`lifetime` (Yoshida-4).
LIFETIME_STEPS = 1000


def lifetime(
    orbit: HamiltonianOrbit,
    *,
    perturbation: float = 1e-8,
    threshold: float = 1e-2,
    max_periods: int = 200,
    seed: int = 0,
) -> Lifetime:
    """Run the undamped chain from the orbit with its velocities perturbed and follow it period by period.

    Parameters
    ----------
    orbit : HamiltonianOrbit
    perturbation : float
        Size (max norm) of a random velocity perturbation (seeded).
    threshold : float
        Deviation from the orbit at which the roto-breather counts as lost.
    max_periods : int
        Length of the run in periods.
    seed : int

    Returns
    -------
    Lifetime

    Raises
    ------
    ValueError
        For a non-positive perturbation, a threshold not above it, or max_periods < 1.
    """
    check_lifetime_run(perturbation, threshold, max_periods)
    params = orbit.params
    rng = np.random.default_rng(seed)
    # On the free degrees of freedom only: an end holds the others.
    kick = unpack(params, rng.uniform(-1.0, 1.0, n_free(params)))
    v0 = orbit.v + kick * (perturbation / np.max(np.abs(kick)))
    run = integrate(
        params, orbit.model, moment_load(0.0, orbit.particle), t_end=max_periods * orbit.period, dt=orbit.period / LIFETIME_STEPS,
        x0=orbit.x, v0=v0, method="yoshida4", n_frames=max_periods + 1, check_stability=False,
    )  # fmt: skip
    k = np.arange(len(run.time))
    shift = np.zeros_like(orbit.x)
    shift[ROW_INDEX["phi"]] = 2 * math.pi * orbit.particle_turns
    drift = run.x - orbit.x[None] - k[:, None, None] * shift[None]
    deviation = np.maximum(np.max(np.abs(drift), axis=(1, 2)), np.max(np.abs(run.v - orbit.v[None]), axis=(1, 2)))
    return lifetime_from_deviation(
        deviation, period=orbit.period, perturbation=perturbation, threshold=threshold,
        max_multiplier=None if orbit.stable else orbit.max_multiplier,
    )  # fmt: skip


@dataclass
class DampedToUndamped:
    """Where a damped, driven rotating orbit lands at zero damping, against the anti-continuum family there.

    Attributes
    ----------
    path : UndampingPath
        The homotopy s = 1 -> 0 at the orbit's mean rate.
    landed : HamiltonianOrbit or None
        The homotopy's end as an orbit of the undamped chain (multipliers, energy; Newton
        from the end converges at once), None where the path did not reach s = 0.
    family : HamiltonianOrbit or None
        The roto-breather :func:`roto_breather_family` finds from the anti-continuum limit
        at the same frequency, None where Newton fails from it (``message`` says so).
    message : str
    """

    path: UndampingPath
    landed: HamiltonianOrbit | None
    family: HamiltonianOrbit | None
    message: str

    @property
    def state_difference(self) -> float | None:
        """max |x - x_family|, |v - v_family| (both on the section phi_rotor = 0); None without both orbits."""
        if self.landed is None or self.family is None:
            return None
        return float(max(np.max(np.abs(self.landed.x - self.family.x)), np.max(np.abs(self.landed.v - self.family.v))))

    @property
    def same_orbit(self) -> bool:
        """Whether the homotopy landed on the anti-continuum family's orbit (states equal to 1e-6)."""
        difference = self.state_difference
        return difference is not None and difference <= 1e-6

    def as_dict(self) -> dict:
        def orbit(o: HamiltonianOrbit | None) -> dict | None:
            if o is None:
                return None
            return {"energy": o.energy, "max_multiplier": o.max_multiplier, "stable": o.stable, "period": o.period,
                    "rotor_velocity": float(o.v[ROW_INDEX["phi"], column(o.params, o.particle)])}  # fmt: skip

        return {
            "path": self.path.as_dict(),
            "landed": orbit(self.landed),
            "family": orbit(self.family),
            "state_difference": self.state_difference,
            "same_orbit": self.same_orbit,
            "message": self.message,
        }


def damped_to_undamped(orbit: PeriodicOrbit, *, stop_at_fold: bool = True, max_points: int = 200) -> DampedToUndamped:
    """Follow a damped, driven rotating orbit to gamma = 0 at its mean rate and compare it with the family there.

    Parameters
    ----------
    orbit : PeriodicOrbit
        From :func:`~cosserat_chain.numerics.periodic.find_periodic_orbit` on a damped chain.
    stop_at_fold, max_points
        Of :func:`~cosserat_chain.numerics.undamping.continue_to_undamped`.

    Returns
    -------
    DampedToUndamped

    Raises
    ------
    ValueError
        For an orbit of an undamped chain, or one under a negative moment (the roto-breathers
        turn the rotor forwards: take the mirror orbit, M > 0).
    """
    if orbit.moment < 0:
        raise ValueError(
            f"orbit: its moment is M = {orbit.moment!r} < 0, and roto-breathers are computed turning forwards: "
            "find the orbit at M > 0 (the chain's mirror image) and follow that"
        )
    path = continue_to_undamped(orbit, stop_at_fold=stop_at_fold, max_points=max_points)
    end = path.undamped
    if end is None:
        return DampedToUndamped(path, None, None, f"the homotopy did not reach gamma = 0: {path.message}")
    params = orbit.params.replace(gamma_u=0.0, gamma_v=0.0, gamma_phi=0.0)
    omega = abs(end.omega)
    landed = find_hamiltonian_orbit(
        params, orbit.model, omega, (end.x, end.v), turns=orbit.turns, particle=orbit.particle, particle_turns=end.particle_turns
    )
    try:
        family = roto_breather_family(params, orbit.model, [omega], turns=orbit.turns, particle=orbit.particle).family.orbits[0]
    except OrbitError as err:
        return DampedToUndamped(path, landed, None, f"no roto-breather from the anti-continuum limit at Omega = {omega:.10g}: {err}")
    result = DampedToUndamped(path, landed, family, "")
    result.message = (
        f"landed on the anti-continuum family's orbit at Omega = {omega:.10g} (states equal to {result.state_difference:.2g})"
        if result.same_orbit
        else f"landed on another undamped orbit at Omega = {omega:.10g} than the anti-continuum family's (states differ by {result.state_difference:.3g})"
    )
    return result
