"""Roto-breathers of a user's system: families from the anti-continuum limit, their stability and resonances.

Contract
--------
For a :class:`~cosserat_chain.systems.base.System` with a coupling parameter (``C`` of
:func:`~cosserat_chain.systems.takeno_peyrard`) and a damping parameter (``gamma``), a
roto-breather is a periodic orbit of the undamped system in which one angle (or two
neighbouring ones) turns k times per period T = 2 pi k / Omega while the others oscillate.

* :func:`rotor_potential` and :func:`anti_continuum_orbit` give the anti-continuum limit:
  with the coupling at 0 the rotor is a pendulum in its on-site potential V (every other
  coordinate at rest), whose turn at energy E takes T(E) = int_0^{2 pi} sqrt(m / (2 (E - V))) dphi
  (for V = 1 - cos phi the closed form 4 K(2/E) / sqrt(2 E)); the state (phi = 0,
  phi' = sqrt(2 (E - V(0)) / m)) is an orbit there.
* :func:`held_rotor_energy` is the family's energy to first order in the coupling: the
  rotor between neighbours held at rest.
* :func:`roto_breather_family` continues it in the coupling (at fixed period, Newton at
  stepped values) up to the system's value, then in the period over the frequencies asked
  for on the kit's driver (:func:`~.system_breather_arclength.continue_family`; conservative
  orbits by the damping's unfolding, returned at zero), which locates the family's folds and
  branch points with their accuracy, and locates every frequency where stability is lost or
  regained: bracketed by bisection in the period on the multipliers' moduli, then placed at
  the zero of the colliding pair's discriminant with an accuracy measured against a tighter
  integration (:class:`StabilityChange`). A loss at +1 sits where the family's energy is
  extremal (:meth:`SystemBreatherFamily.energy_extrema`).
* :func:`linear_bands` gives the phonon bands of the lattice about rest from its force
  Jacobian (a ring's Bloch matrix, sampled in the wavenumber), and :func:`resonances` the
  frequencies where a harmonic of the rotation meets a band edge: the phonons' Floquet
  multipliers exp(+-i w T) reach +1 where w = n Omega (a harmonic, n whole) and -1 where
  2 w = m Omega (m odd: a parametric, half-integer harmonic); :func:`nearest_resonance` names
  the one next to a located loss of stability.
"""

from __future__ import annotations

import json
import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np

from ..errors import CosseratChainError
from ..numerics.breather_arclength import (
    CLUSTER_SIZE,
    COUNTED,
    collision_discriminant,
    collisions_between,
    instability_counts,
    off_circle,
)
from ..numerics.kit import EvaluationFailed, illinois
from ..numerics.shooting import PERIOD, Orbit, OrbitNotFound, find_orbit, flow
from ..systems.base import System
from ..systems.lattice import LatticeSystem
from .anti_continuum import POTENTIAL_POINTS, potential_from_torque, rotor_energy, sample_angles
from .lifetimes import Lifetime, check_lifetime_run, lifetime_from_deviation
from .simulation import system_attributes

if TYPE_CHECKING:  # xarray is imported where a Dataset is built: commands without file output start without it
    import xarray as xr

ProgressCallback = Callable[[int, int], None]

#: Wavenumbers in [0, pi] at which the Bloch matrix is sampled for the band edges.
BAND_SAMPLES = 257
#: Highest harmonic n (and half-harmonic m / 2) of the rotation compared with the band edges.
MAX_HARMONIC = 6
#: First steps of the coupling from 0 to its value, and the most halvings of a step.
COUPLING_STEPS = 8
COUPLING_HALVINGS = 10
#: Bisections in the period that locate a change of stability between two members of a family.
BISECTIONS = 12
#: rtol and atol of the second monodromy that measures the shooting's and locates a collision's discriminant.
TIGHT_RTOL = 1e-13
#: Newton's closure there.
TIGHT_CLOSURE = 1e-12
#: Secant iterations on the discriminant, the most widenings of its first bracket, and the secant's end: a
#: discriminant below this fraction of its own measured error.
SECANT_ITERATIONS = 12
WIDENINGS = 8
RESOLVED = 0.01


class BreatherError(CosseratChainError, ValueError):
    """A roto-breather that cannot be posed as asked (a bad rotor, coupling, frequency)."""


# -- the anti-continuum limit -----------------------------------------------------------------


def _coordinate(system: System, which: int | str, what: str) -> int:
    names = system.coordinates
    i = names.index(which) if isinstance(which, str) and which in names else which
    if not (isinstance(i, int | np.integer) and not isinstance(i, bool) and 0 <= i < system.size):
        raise BreatherError(f"{what} must be a coordinate of {system.name} (a name or an index 0..{system.size - 1}), got {which!r}")
    if not system.angles[i]:
        angles = ", ".join(n for n, a in zip(names, system.angles, strict=True) if a) or "none"
        raise BreatherError(f"{what} {names[i]!r} is not an angle of {system.name}: only angles can turn (its angles: {angles})")
    return int(i)


def rotor_potential(system: System, rotor: int | str, coupling: str | None) -> Callable[[np.ndarray], np.ndarray]:
    """The on-site potential V(phi) of the coordinate ``rotor`` turned alone, the coupling at 0 and every other at rest (V(0) = 0).

    With ``coupling`` None the coupling keeps its value: V is then the potential of the rotor
    between neighbours held at rest (:func:`held_rotor_energy`).

    From the torque F_rotor sampled at :data:`~.anti_continuum.POTENTIAL_POINTS` angles and
    integrated as a Fourier series (:func:`~.anti_continuum.potential_from_torque`), so it needs
    no energy function (the torque must have zero mean: a constant torque would make the rotor
    accelerate, not rotate periodically).

    Raises
    ------
    BreatherError
        For a rotor that is not an angle, or a torque with a non-zero mean.
    """
    i = _coordinate(system, rotor, "rotor")
    alone = system if coupling is None else system.with_parameters(**{coupling: 0.0})
    q = np.zeros(system.size)
    torque = np.empty(POTENTIAL_POINTS)
    for j, angle in enumerate(sample_angles()):
        q[i] = angle
        torque[j] = alone.forces(q)[i]
    mean = float(np.mean(torque))
    if abs(mean) > 1e-12 * max(1.0, float(np.max(np.abs(torque)))):
        raise BreatherError(
            f"the torque on {system.coordinates[i]} has the mean {mean:.6g} over a turn (a drive): "
            "roto-breathers are orbits of the undriven system; set the drive to 0"
        )
    return potential_from_torque(torque)


@dataclass
class AntiContinuum:
    """The anti-continuum orbit: its state, period and every rotor's energy in its on-site potential."""

    y0: np.ndarray
    period: float
    turns: dict[int, int]
    energies: dict[int, float]


def anti_continuum_orbit(system: System, omega: float, rotors: Mapping[int | str, int], coupling: str) -> AntiContinuum:
    """The rotors turning alone at frequency ``omega`` (of the first rotor), the coupling at 0, every other coordinate at rest.

    Parameters
    ----------
    system : System
    omega : float
        Mean angular velocity of the first rotor: T = 2 pi |k_1| / omega.
    rotors : mapping coordinate -> k
        The turning coordinates and their signed turns per period (``{3: 1, 4: -1}``: two rotors against each other).
    coupling : str
        The parameter set to 0.

    Raises
    ------
    BreatherError
        For omega not finite and > 0, a rotor that is not an angle, or zero turns.
    """
    if not (isinstance(omega, float | int) and math.isfinite(omega) and omega > 0):
        raise BreatherError(f"omega must be a finite number > 0, got {omega!r}")
    system.parameter(coupling)
    if not rotors:
        raise BreatherError("at least one rotor is needed")
    turns = {}
    for key, k in rotors.items():
        if not (isinstance(k, int | np.integer) and not isinstance(k, bool) and k != 0):
            raise BreatherError(f"the turns of rotor {key!r} must be a non-zero integer, got {k!r}")
        turns[_coordinate(system, key, "rotor")] = int(k)
    first = next(iter(turns.values()))
    period = 2 * math.pi * abs(first) / omega
    y0 = np.zeros(2 * system.size)
    energies = {}
    mass = system.mass()
    for i, k in turns.items():
        potential = rotor_potential(system, i, coupling)
        try:
            energy = rotor_energy(potential, float(mass[i]), period / abs(k))
        except ValueError as err:
            raise BreatherError(str(err)) from None
        y0[system.size + i] = math.copysign(math.sqrt(2.0 * energy / mass[i]), k)
        energies[i] = energy
    return AntiContinuum(y0=y0, period=period, turns=turns, energies=energies)


def held_rotor_energy(system: System, omega: float, *, rotor: int | str | None = None, turns: int = 1) -> float:
    """The energy of the one-site roto-breather at frequency ``omega`` to first order in the coupling.

    The rotor turning between neighbours held at rest, in the potential V_C of the system at
    its coupling (:func:`rotor_potential` with ``coupling`` None), plus the energy of the
    lattice at rest: E(Omega, C) = E_C(Omega) + O(C^2), the anti-continuum expansion of the
    frequency-energy relation (the neighbours move by O(C), which changes the energy at fixed
    period by O(C^2); derivation in the docs, "Roto-breathers" > "An analytic value"). For the
    Takeno-Peyrard lattice V_C = (1 + 2 C)(1 - cos phi) and E_C(Omega) = (1 + 2 C) E_0(Omega /
    sqrt(1 + 2 C)), E_0 the free pendulum's.

    Parameters
    ----------
    system : System
        Undriven (its torque has zero mean over a turn).
    omega : float
        Mean angular velocity of the rotor: one turn takes 2 pi / omega.
    rotor : int or str, optional
        The turning coordinate (default the central angle).
    turns : int
        Turns per period (the energy depends on the turn time 2 pi / omega only).

    Raises
    ------
    BreatherError
        For omega not finite and > 0, a rotor that is not an angle, or a driven rotor.
    """
    if not (isinstance(omega, float | int) and math.isfinite(omega) and omega > 0):
        raise BreatherError(f"omega must be a finite number > 0, got {omega!r}")
    if not (isinstance(turns, int) and not isinstance(turns, bool) and turns != 0):
        raise BreatherError(f"turns must be a non-zero integer, got {turns!r}")
    if rotor is None:
        angles = np.flatnonzero(system.angles)
        if not angles.size:
            raise BreatherError(f"{system.name} has no angle: nothing can turn")
        rotor = int(angles[angles.size // 2])
    i = _coordinate(system, rotor, "rotor")
    try:
        energy = rotor_energy(rotor_potential(system, i, None), float(system.mass()[i]), 2 * math.pi / omega)
    except ValueError as err:
        raise BreatherError(str(err)) from None
    rest = system.energy(np.zeros(system.size))
    return energy + (0.0 if rest is None else float(rest))


# -- bands and resonances ---------------------------------------------------------------------


def linear_bands(system: System, rest: np.ndarray | None = None) -> list[tuple[float, float]]:
    """The phonon bands (bottom, top) about rest, lowest first.

    For a :class:`~cosserat_chain.systems.lattice.LatticeSystem` with nearest-neighbour bonds:
    the Bloch matrix D(q) = -(J_0 + J_1 e^{iq} + J_1^T e^{-iq}) / m of a ring's force Jacobian
    at rest (J_0 a site's own block, J_1 its coupling to the next), its eigenvalues w^2(q) at
    :data:`BAND_SAMPLES` wavenumbers in [0, pi] (for Takeno-Peyrard, w^2 = 1 + 4 C sin^2(q / 2)).
    For any other system, one band spanning the frequencies of -M^-1 dF/dq at rest.

    Parameters
    ----------
    rest : (n,) ndarray, optional
        The state about which to linearise (default every coordinate 0); for a lattice, the
        state of the first site is repeated on the ring.

    Raises
    ------
    BreatherError
        If rest is not a stable equilibrium (a negative w^2).
    """
    if isinstance(system, LatticeSystem):
        nd = len(system.dofs)
        site = np.zeros(nd) if rest is None else np.asarray(rest, dtype=float)[:nd]
        # A ring of 4 sites holds every bond of a site and no boundary; the copy shares the compiled kernels.
        ring = system.with_sites(4).with_boundary("periodic")
        jac = ring.force_jacobian(np.tile(site, 4)).toarray()
        own, nxt = jac[nd : 2 * nd, nd : 2 * nd], jac[nd : 2 * nd, 2 * nd : 3 * nd]
        scale = 1.0 / np.sqrt(system.mass()[:nd])
        waves = np.linspace(0.0, math.pi, BAND_SAMPLES)
        squares = np.array(
            [np.linalg.eigvalsh(-(scale[:, None] * (own + nxt * np.exp(1j * k) + nxt.T * np.exp(-1j * k)) * scale[None, :])) for k in waves]
        )
    else:
        q = np.zeros(system.size) if rest is None else system.check_state(rest, "rest")
        scale = 1.0 / np.sqrt(system.mass())
        matrix = -(scale[:, None] * system.force_jacobian(q).toarray() * scale[None, :])
        spectrum = np.linalg.eigvals(matrix).real
        squares = np.array([[spectrum.min()], [spectrum.max()]])
    if np.min(squares) < -1e-12:
        raise BreatherError(
            f"the rest state of {system.name} is not a stable equilibrium (w^2 = {np.min(squares):.6g} < 0): it has no bands"
        )
    frequencies = np.sqrt(np.clip(squares, 0.0, None))
    return [(float(frequencies[:, b].min()), float(frequencies[:, b].max())) for b in range(frequencies.shape[1])]


@dataclass(frozen=True)
class Resonance:
    """A harmonic of the rotation at a band edge: (m / 2) Omega = edge.

    ``order`` is m: even m is the harmonic n = m / 2 (the phonon multipliers at +1), odd m a
    parametric resonance 2 w = m Omega (at -1).
    """

    omega: float
    order: int
    band: int
    edge: str
    edge_frequency: float

    @property
    def harmonic(self) -> float:
        return self.order / 2

    @property
    def multiplier(self) -> int:
        return 1 if self.order % 2 == 0 else -1

    def as_dict(self) -> dict:
        return {
            "omega": self.omega,
            "harmonic": self.harmonic,
            "multiplier": self.multiplier,
            "band": self.band,
            "edge": self.edge,
            "edge_frequency": self.edge_frequency,
        }


def resonances(
    bands: list[tuple[float, float]], low: float = 0.0, high: float = math.inf, *, max_harmonic: int = MAX_HARMONIC
) -> list[Resonance]:
    """Every Omega in [low, high] with (m / 2) Omega at a band edge, m = 1 .. 2 max_harmonic, sorted by Omega."""
    out = []
    for b, (bottom, top) in enumerate(bands):
        for edge, frequency in (("bottom", bottom), ("top", top)):
            for m in range(1, 2 * max_harmonic + 1):
                omega = 2 * frequency / m
                if frequency > 0 and low <= omega <= high:
                    out.append(Resonance(omega, m, b, edge, frequency))
    return sorted(out, key=lambda r: r.omega)


def nearest_resonance(
    bands: list[tuple[float, float]], omega: float, *, multiplier: int | None = None, max_harmonic: int = MAX_HARMONIC
) -> Resonance:
    """The resonance (:func:`resonances`) nearest ``omega``; with ``multiplier`` (+1 or -1) only those of that kind."""
    found = [r for r in resonances(bands, max_harmonic=max_harmonic) if multiplier is None or r.multiplier == multiplier]
    return min(found, key=lambda r: abs(r.omega - omega))


def harmonics_in_bands(bands: list[tuple[float, float]], omega: float, *, max_harmonic: int = MAX_HARMONIC) -> list[tuple[int, int]]:
    """The (n, band) with n Omega inside a band (n = 1 .. max_harmonic): the rotation drives those phonons resonantly."""
    return [(n, b) for n in range(1, max_harmonic + 1) for b, (bottom, top) in enumerate(bands) if bottom <= n * omega <= top]


# -- families ---------------------------------------------------------------------------------


def orbit_energy(orbit: Orbit) -> float | None:
    """Kinetic plus potential energy of the undamped orbit at its start (None for a system without energy)."""
    system = orbit.system
    potential = system.energy(orbit.q0)
    return None if potential is None else float(potential + 0.5 * np.sum(system.mass() * orbit.v0**2))


@dataclass(frozen=True)
class StabilityChange:
    """Where a family loses (or regains) stability, and how well that is known.

    ``stable_omega`` and ``unstable_omega`` are the members that bracket the change after
    :data:`BISECTIONS` bisections in the period on the multipliers' moduli (``moduli_omega`` their
    middle; fewer with a tolerance, :func:`locate_stability_change`). The ``stable`` side is the
    one with the colliding pair on the circle (where another pair is off it on both sides, both
    are unstable). That bracket is not the accuracy: at the collision m multipliers meet (four at +1),
    and the monodromy's error delta moves each of them by delta^(1/m), so the moduli say
    stable or unstable wrongly within ``moduli_accuracy`` = 4 delta^(2/m) / |dD/dOmega| of the
    collision (D the discriminant below; the pair's split is sqrt(D) / 2 there). ``omega`` is
    instead the zero of the colliding pair's discriminant D
    (:func:`~cosserat_chain.numerics.breather_arclength.collision_discriminant`), smooth in Omega
    and resolved to O(delta), found by the Illinois secant method in the period, each orbit found
    again and its monodromy integrated at :data:`TIGHT_RTOL`. ``shooting_omega`` is the zero that
    the shooting's own orbits and monodromies (at its rtol) give, and ``accuracy`` =
    |D - D_tight| / |dD/dOmega|, the largest over the secant's points, is its error measured
    against the tight ones: a bound for ``omega``, whose error is smaller by about the ratio of
    the tolerances, so [omega - accuracy, omega + accuracy] (``bracket``) holds the change;
    ``monodromy_error`` is delta = max |M - M_tight| there (the orbit's own error included). Where the discriminant cannot be followed (its cluster not
    resolved, no sign change found), ``method`` is ``moduli`` and ``omega`` the bisection's
    middle, its accuracy ``moduli_accuracy`` if a slope was measured (None if not).

    ``multiplier`` is the unstable side's largest one of the colliding pair's kind; ``kind`` is
    ``+1`` (a real multiplier > 1: a collision at +1), ``-1`` (real < -1: at -1) or ``complex``
    (a Krein collision off the real axis), as
    :func:`~cosserat_chain.numerics.breather_arclength.instability_counts` counts them;
    ``resonance`` the nearest resonance of the multiplier's sector (+1 within pi / 3 of +1, -1
    within pi / 3 of -1: a Krein collision near -1 is a parametric resonance too), ``nearest``
    the nearest of any. With a tolerance the secant's last step, not taken, is added to ``accuracy``.
    """

    omega: float
    stable_omega: float
    unstable_omega: float
    multiplier: complex
    kind: str
    resonance: Resonance
    nearest: Resonance
    accuracy: float | None = None
    method: str = "moduli"
    moduli_omega: float = math.nan
    moduli_accuracy: float | None = None
    monodromy_error: float | None = None
    slope: float | None = None
    shooting_omega: float = math.nan

    @property
    def bracket(self) -> tuple[float, float] | None:
        """[omega - accuracy, omega + accuracy], or None without an accuracy."""
        return None if self.accuracy is None else (self.omega - self.accuracy, self.omega + self.accuracy)

    def as_dict(self) -> dict:
        return {
            "omega": self.omega,
            "accuracy": self.accuracy,
            "bracket": None if self.bracket is None else list(self.bracket),
            "method": self.method,
            "stable_omega": self.stable_omega,
            "unstable_omega": self.unstable_omega,
            "moduli_omega": self.moduli_omega,
            "moduli_accuracy": self.moduli_accuracy,
            "monodromy_error": self.monodromy_error,
            "shooting_omega": self.shooting_omega,
            "discriminant_slope": self.slope,
            "multiplier": [self.multiplier.real, self.multiplier.imag],
            "kind": self.kind,
            "resonance": self.resonance.as_dict(),
            "nearest_resonance": self.nearest.as_dict(),
        }


@dataclass
class SystemBreatherFamily:
    """A roto-breather family of a system: the anti-continuum start, the orbits in the frequency, stability changes, bands.

    Attributes
    ----------
    start : AntiContinuum
    coupling : str
        The parameter continued from 0 to its value in the system.
    orbits : list of Orbit
        The family at that coupling, in the order followed from the first frequency.
    bands : list of (bottom, top)
    changes : list of StabilityChange
    message : str
        How the continuation in the period ended.
    """

    system: System
    start: AntiContinuum
    coupling: str
    orbits: list[Orbit]
    bands: list[tuple[float, float]]
    changes: list[StabilityChange]
    message: str
    settings: dict = field(default_factory=dict)
    lifetimes: list[Lifetime] | None = None
    #: The family's located folds and branch points (:class:`~.system_breather_arclength.FamilyEvent`, each with
    #: its accuracy), found by the kit's driver on the way in the period; with ``arclength=True`` its changes of
    #: stability as well (``changes`` holds them otherwise), and the parameter continued.
    events: list | None = None
    parameter: str = "omega"

    def measure_lifetimes(
        self, max_periods: int, *, perturbation: float = 1e-8, threshold: float = 1e-2, progress: ProgressCallback | None = None
    ) -> list[Lifetime]:
        """Run every member from its perturbed orbit (:func:`system_lifetime`) and keep the lifetimes with the family.

        They go into :meth:`as_dict` (``lifetimes``) and :meth:`to_dataset`.

        Raises
        ------
        ValueError
            As :func:`system_lifetime` does.
        """
        out = []
        for i, orbit in enumerate(self.orbits):
            out.append(system_lifetime(orbit, perturbation=perturbation, threshold=threshold, max_periods=max_periods))
            if progress is not None:
                progress(i + 1, len(self.orbits))
        self.lifetimes = out
        self.settings["lifetime"] = {"max_periods": max_periods, "perturbation": perturbation, "threshold": threshold}
        return out

    @property
    def values(self) -> np.ndarray:
        """The continued parameter per orbit: Omega, or the parameter followed at a fixed frequency (``along``)."""
        return self.omegas if self.parameter == "omega" else np.array([o.parameter(self.parameter) for o in self.orbits])

    @property
    def first_turns(self) -> int:
        return abs(next(iter(self.start.turns.values())))

    @property
    def omegas(self) -> np.ndarray:
        """Mean angular velocity of the first rotor, 2 pi k / T, per orbit."""
        return np.array([2 * math.pi * self.first_turns / o.period for o in self.orbits])

    def energies(self) -> np.ndarray:
        """Energy of every orbit (NaN for a system without an energy)."""
        return np.array([math.nan if (e := orbit_energy(o)) is None else e for o in self.orbits])

    def energy_extrema(self) -> list[float]:
        """Frequencies where the energy is extremal along the family (dE/dOmega changes sign).

        Each the vertex of the parabola E(Omega) through the three members around the sign
        change. A Hamiltonian family's pair of multipliers at +1 turns real exactly where
        dE/dOmega = 0 (the energy's fold), so a loss of stability at +1 sits at one of these.
        """
        omegas, energy = self.omegas, self.energies()
        if self.settings.get("arclength"):  # Omega may turn or stay put; its events say where a pair meets +1
            return []
        steps = np.diff(omegas)
        slope = np.diff(energy) / steps
        out = []
        # Where Omega turns (a fold, in ``events``) the slope changes sign with the energy still going on: not an extremum.
        for j in np.flatnonzero((np.sign(slope[:-1]) * np.sign(slope[1:]) < 0) & (np.sign(steps[:-1]) == np.sign(steps[1:]))):
            a, b, c = np.polyfit(omegas[j : j + 3], energy[j : j + 3], 2)
            out.append(float(-b / (2 * a)))
        return out

    def to_dataset(self, reference: str | None = None) -> xr.Dataset:
        """The family as a self-describing Dataset: dims ``point`` (the members), ``coordinate``, ``multiplier``, ``band``.

        Per member: omega, period, energy (NaN without one), the start (q0, v0), the Floquet
        multipliers, max |mu|, stability, the unfolding and the closure; the bands' edges; in the
        attributes, the system (name, parameters, coordinates, angles), the coupling, the
        rotors and their anti-continuum energies, the stability changes, the resonances and the
        package's version. Numbers are in the system's own units (``experiment`` ``system_*``:
        :func:`cosserat_chain.io.describe` marks them so when the file is written).

        Parameters
        ----------
        reference : str, optional
            How the system was named (``takeno_peyrard``, ``my_lattice.py:build``), kept as ``system_reference``.

        Raises
        ------
        ValueError
            For a family with no member.
        """
        import xarray as xr

        if not self.orbits:
            raise ValueError("the family holds no orbit: nothing to write")
        summary = self.as_dict()
        data = {
            "omega": ("point", self.omegas),
            "period": ("point", np.array([o.period for o in self.orbits])),
            "energy": ("point", self.energies()),
            "max_multiplier": ("point", np.array([o.max_multiplier for o in self.orbits])),
            "stable": ("point", np.array([o.stable for o in self.orbits], dtype=np.int8)),
            "unfolding": ("point", np.array([o.unfolding for o in self.orbits], dtype=float)),
            "closure": ("point", np.array([o.closure for o in self.orbits])),
            "q0": (("point", "coordinate"), np.array([o.q0 for o in self.orbits])),
            "v0": (("point", "coordinate"), np.array([o.v0 for o in self.orbits])),
            "multiplier_real": (("point", "multiplier"), np.array([o.multipliers.real for o in self.orbits])),
            "multiplier_imag": (("point", "multiplier"), np.array([o.multipliers.imag for o in self.orbits])),
            "band_bottom": ("band", np.array([b for b, _ in self.bands])),
            "band_top": ("band", np.array([t for _, t in self.bands])),
        }
        coords = {
            "point": np.arange(len(self.orbits)),
            "coordinate": list(self.system.coordinates),
            "multiplier": np.arange(self.orbits[0].multipliers.size),
            "band": np.arange(len(self.bands)),
        }
        ds = xr.Dataset(data, coords=coords)
        names = {
            "omega": "mean angular velocity Omega = 2 pi k / T of the first rotor",
            "period": "period T of the orbit",
            "energy": "total energy of the orbit (NaN: the system has no energy function)",
            "max_multiplier": "largest modulus of a non-trivial Floquet multiplier",
            "stable": "1 if every non-trivial Floquet multiplier lies on the unit circle, 0 if not",
            "unfolding": f"the unfolding damping {self.settings.get('unfold')} at the solution (0 for an orbit of the undamped system)",
            "closure": "max |Phi_T(y0) - y0 - 2 pi k| of the converged orbit",
            "q0": "start of the orbit: coordinates",
            "v0": "start of the orbit: velocities",
            "band_bottom": "lowest frequency of a phonon band about rest",
            "band_top": "highest frequency of a phonon band about rest",
        }
        if self.lifetimes is not None:
            lives = self.lifetimes
            ds["lifetime_periods"] = ("point", np.array([math.nan if x.periods is None else x.periods for x in lives], dtype=float))
            ds["growth_per_period"] = ("point", np.array([x.growth_per_period for x in lives]))
            ds["predicted_lifetime_periods"] = ("point", np.array([x.predicted_periods for x in lives]))
            names["lifetime_periods"] = (
                "periods of a direct run from the perturbed orbit until it left it (NaN: it stayed for the whole run)"
            )
            names["growth_per_period"] = "growth of the deviation per period in the direct run"
            names["predicted_lifetime_periods"] = (
                "ln(threshold / perturbation) / ln max|mu| (NaN: a stable orbit); the run's settings in settings_json"
            )
        for name, long_name in names.items():
            ds[name].attrs["long_name"] = long_name
        ds.attrs.update(system_attributes(self.system, reference))
        ds.attrs.update(
            {
                "experiment": "system_roto_breathers",
                "title": f"Roto-breather family of the system {self.system.name}",
                "coupling": self.coupling,
                "rotors_json": json.dumps(summary["rotors"]),
                "anti_continuum_json": json.dumps({"energy": summary["anti_continuum_energy"], "period": self.start.period}),
                "stability_changes_json": json.dumps(summary["stability_changes"]),
                "resonances_json": json.dumps(summary["resonances"]),
                "energy_extrema_json": json.dumps(summary["energy_extrema"]),
                "parameter": self.parameter,
                "events_json": json.dumps(summary.get("events", [])),
                "message": self.message,
                "settings_json": json.dumps(self.settings),
            }
        )
        return ds

    def as_dict(self) -> dict:
        omegas = self.omegas
        rotors = list(self.start.turns)
        return {
            **self.system.describe(),
            "coupling": self.coupling,
            "coupling_value": self.system.parameter(self.coupling),
            "rotors": {self.system.coordinates[i]: k for i, k in self.start.turns.items()},
            "anti_continuum_energy": {self.system.coordinates[i]: e for i, e in self.start.energies.items()},
            "anti_continuum_period": self.start.period,
            "omega": omegas.tolist(),
            "period": [o.period for o in self.orbits],
            "energy": [orbit_energy(o) for o in self.orbits],
            "energy_extrema": self.energy_extrema() if self.orbits else [],
            "rotor_velocity": [o.v0[rotors[0]] for o in self.orbits],
            "max_multiplier": [o.max_multiplier for o in self.orbits],
            "stable": [bool(o.stable) for o in self.orbits],
            "unfolding": [o.unfolding for o in self.orbits],
            "closure": [o.closure for o in self.orbits],
            "harmonics_in_bands": [[{"harmonic": n, "band": b} for n, b in harmonics_in_bands(self.bands, w)] for w in omegas],
            "bands": [list(b) for b in self.bands],
            "resonances": [r.as_dict() for r in resonances(self.bands, float(omegas.min()), float(omegas.max()))] if self.orbits else [],
            "stability_changes": [c.as_dict() for c in self.changes],
            **({} if self.lifetimes is None else {"lifetimes": [x.as_dict() for x in self.lifetimes]}),
            **(
                {}
                if self.events is None
                else {
                    "parameter": self.parameter,
                    "values": self.values.tolist(),
                    "events": [e.as_dict() for e in self.events],
                }
            ),  # fmt: skip
            "message": self.message,
            **{k: v for k, v in self.settings.items() if k not in ("system",)},
        }


def system_lifetime(
    orbit: Orbit, *, perturbation: float = 1e-8, threshold: float = 1e-2, max_periods: int = 200, seed: int = 0
) -> Lifetime:
    """Run the undamped system from the orbit with its velocities perturbed and follow it period by period.

    The system's own flow (:func:`~cosserat_chain.numerics.shooting.flow`, the compiled DOP853
    of ``simulate --system``), one period at a time; a flow that fails leaves the rest of the
    run infinitely far (lost).

    Parameters
    ----------
    orbit : Orbit
        A conservative orbit (its unfolding parameter is set to 0 for the run).
    perturbation : float
        Size (max norm) of a random velocity perturbation (seeded).
    threshold : float
        Deviation (max over coordinates and velocities, the rotors' angles advanced by 2 pi
        times their turns) at which the roto-breather counts as lost.
    max_periods : int
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
    system = orbit.system if orbit.unfold is None else orbit.system.with_parameters(**{orbit.unfold: 0.0})
    kick = np.random.default_rng(seed).uniform(-1.0, 1.0, system.size)
    y = np.concatenate([orbit.q0, orbit.v0 + kick * (perturbation / np.max(np.abs(kick)))])
    shift = np.concatenate([2 * math.pi * orbit.turns, np.zeros(system.size)])
    deviation = np.full(max_periods + 1, np.inf)
    deviation[0] = float(np.max(np.abs(y - orbit.y0)))
    for k in range(1, max_periods + 1):
        try:
            y = flow(system, y, orbit.period, variations=False)[0]
        except EvaluationFailed:
            break
        deviation[k] = float(np.max(np.abs(y - orbit.y0 - k * shift)))
        if not np.isfinite(deviation[k]):
            break
    return lifetime_from_deviation(
        deviation, period=orbit.period, perturbation=perturbation, threshold=threshold,
        max_multiplier=None if orbit.stable else orbit.max_multiplier,
    )  # fmt: skip


def _unfolding_parameter(system: System, unfold: str | None) -> str:
    if unfold is not None:
        system.parameter(unfold)
        return unfold
    for name in system.parameters:
        if np.any(system.parameter_mass_damping(name)[1] != 0.0):
            return name
    raise BreatherError(
        f"{system.name} has no damping parameter (a parameter the damping depends on): the conservative orbits are found "
        "with a damping as the unfolding unknown; give the system one (e.g. damping='gamma')"
    )


def _at(system: System, turns: np.ndarray, unfold: str, y0: np.ndarray, period: float) -> Orbit:
    return find_orbit(system, (y0, period), turns=turns, unfold=unfold)


def _land(branch_orbits: list[Orbit], value: float, name: str, target: System, turns, unfold: str) -> Orbit:
    """The orbit at ``name`` = value exactly, from the two members of a branch that bracket it (a linear guess)."""
    values = np.array([o.period if name == PERIOD else o.parameter(name) for o in branch_orbits])
    j = next((j for j in range(1, len(values)) if min(values[j - 1], values[j]) <= value <= max(values[j - 1], values[j])), len(values) - 1)
    a, b = branch_orbits[j - 1], branch_orbits[j]
    span = values[j] - values[j - 1]
    s = 0.0 if span == 0 else (value - values[j - 1]) / span
    guess = (1 - s) * a.y0 + s * b.y0
    period = value if name == PERIOD else (1 - s) * a.period + s * b.period
    return _at(target, turns, unfold, guess, period)


def _continue_coupling(orbit: Orbit, system: System, coupling: str, target: float, turns, unfold: str) -> Orbit:
    """From the anti-continuum orbit to the coupling ``target`` at fixed period: Newton at coupling values
    stepped from 0, each guess extrapolated from the last two orbits, the step halved where Newton fails.

    Natural steps rather than arclength: at coupling 0 every rotor's phase is free (a
    multi-site start is degenerate there), and the symmetric start picks the branch that
    persists; the coupling never folds on a roto-breather's way from the anti-continuum limit.
    """
    done, previous, value, step = orbit, None, 0.0, target / COUPLING_STEPS
    while value != target:
        trial = target if abs(target - value) <= abs(step) else value + step
        guess = (
            done.y0 if previous is None else done.y0 + (done.y0 - previous.y0) * (trial - value) / (value - previous.parameter(coupling))
        )
        try:
            found = _at(system.with_parameters(**{coupling: trial}), turns, unfold, guess, orbit.period)
        except OrbitNotFound:
            step /= 2
            if abs(step) < abs(target) / 2**COUPLING_HALVINGS:
                raise OrbitNotFound(
                    f"the anti-continuum orbit continued in {coupling} stops at {coupling} = {value:.6g} before {target:g}: "
                    "no orbit at the next steps (a resonance of a harmonic with the band on the way: try another frequency)"
                ) from None
            continue
        previous, done, value, step = done, found, trial, step * 1.5
    return done


def _classify(orbit: Orbit) -> tuple[complex, str]:
    """The largest nontrivial multiplier and where it left the circle: near +1, near -1, or elsewhere (a complex quartet).

    By its sector rather than its imaginary part: a pair leaving at +1 splits from a multiple
    multiplier there (the family's own pair), which the eigenvalue solver returns slightly complex.
    """
    mu = orbit.nontrivial_multipliers
    top = complex(mu[int(np.argmax(np.abs(mu)))])
    angle = abs(math.atan2(top.imag, top.real))
    return top, "+1" if angle < math.pi / 3 else "-1" if angle > 2 * math.pi / 3 else "complex"


@dataclass
class _Sample:
    """An orbit with its collision discriminant: from the monodromy at :data:`TIGHT_RTOL`, its difference
    from the shooting's own monodromy's, and max |M - M_tight|."""

    omega: float
    orbit: Orbit
    value: float
    loose: float
    delta: float

    @property
    def error(self) -> float:
        return abs(self.loose - self.value)


def _tight(orbit: Orbit) -> Orbit | None:
    """``orbit`` found again, and its monodromy integrated, at :data:`TIGHT_RTOL` (None where Newton fails)."""
    try:
        return find_orbit(orbit.system, orbit, unfold=orbit.unfold, tol=TIGHT_CLOSURE, rtol=TIGHT_RTOL, atol=TIGHT_RTOL)
    except OrbitNotFound:
        return None


def _sample(orbit: Orbit, omega: float, kind: str, centre: complex | None, tighten: Callable[[Orbit], Orbit | None]) -> _Sample | None:
    """The discriminant at ``orbit`` (found at the shooting's rtol) and at ``tighten(orbit)``, the same orbit found
    again, and its monodromy integrated, at :data:`TIGHT_RTOL`: the error of the first includes the orbit's own."""
    tight = tighten(orbit)
    if tight is None:
        return None
    loose = collision_discriminant(orbit.multipliers, kind, centre)
    sharp = collision_discriminant(tight.multipliers, kind, centre)
    if loose is None or sharp is None:
        return None
    return _Sample(omega, tight, sharp, loose, float(np.max(np.abs(orbit.monodromy - tight.monodromy))))


@dataclass(frozen=True)
class Axis:
    """The coordinate along which a change of stability between two members is located (:func:`locate_stability_change`).

    Omega (:func:`omega_axis`: members of one family in the period, bisected in the period), or a
    parameter of the system at a fixed frequency (:func:`parameter_axis`: the atlases' other axis,
    bisected in the value). Along a parameter, the :class:`StabilityChange`'s ``omega``, ``stable_omega``,
    ``unstable_omega``, ``moduli_omega``, ``shooting_omega``, ``accuracy`` and ``slope`` are in the
    parameter's value, not in Omega.

    Attributes
    ----------
    parameter : callable(member) -> float
        The member's parameter p, which the bisection halves: its period, or the parameter's value.
    solve : callable(y0, p) -> member
        The member at p from the start ``y0``; raises :class:`~cosserat_chain.numerics.shooting.OrbitNotFound`
        where Newton fails.
    coordinate : callable(p) -> float
        The coordinate the change is placed in (the secant's): Omega = 2 pi k / T, or the value itself.
    parameter_at : callable(coordinate) -> float
        Its inverse.
    bands : callable(coordinate) -> list of (bottom, top)
        The phonon bands there (the resonances are named from them).
    omega : callable(coordinate) -> float
        The frequency there: the coordinate itself, or the fixed one.
    """

    parameter: Callable[[Orbit], float]
    solve: Callable[[np.ndarray, float], Orbit]
    coordinate: Callable[[float], float]
    parameter_at: Callable[[float], float]
    bands: Callable[[float], list[tuple[float, float]]]
    omega: Callable[[float], float]

    def at(self, member) -> float:
        """The member's coordinate."""
        return self.coordinate(self.parameter(member))


def omega_axis(solve: Callable[[np.ndarray, float], Orbit], k: int, bands: list[tuple[float, float]]) -> Axis:
    """Omega = 2 pi k / T along a family: ``solve(y0, period)`` the member of that period, the same ``bands`` throughout."""
    return Axis(
        lambda member: member.period, solve, lambda period: 2 * math.pi * k / period, lambda omega: 2 * math.pi * k / omega,
        lambda omega: bands, lambda omega: omega,
    )  # fmt: skip


def parameter_axis(
    value: Callable[[Orbit], float], solve: Callable[[np.ndarray, float], Orbit], bands: Callable[[float], list[tuple[float, float]]],
    omega: float,
) -> Axis:  # fmt: skip
    """A parameter at the fixed frequency ``omega``: ``value(member)`` its value at a member, ``solve(y0, value)`` the member
    there, ``bands(value)`` the phonon bands there."""
    return Axis(value, solve, float, float, bands, lambda _: omega)


def _collision(stable: Orbit, unstable: Orbit, kind: str, centre: complex | None, axis: Axis,
               tighten: Callable[[Orbit], Orbit | None], tol: float = 0.0):  # fmt: skip
    """The zero of the collision discriminant along ``axis`` near the members ``stable`` and ``unstable``.

    Returns (coordinate, samples, slope, step) or None where a discriminant is unresolved or no sign change is found.
    The secant runs in the axis's coordinate (Omega, or a parameter's value) and stops early where its next step
    is below ``tol`` (that step, not taken, is ``step``; 0 where the secant ran to its end).
    """
    samples = []

    def solve(omega: float, guess: np.ndarray) -> Orbit:
        return axis.solve(guess, axis.parameter_at(omega))

    def at(omega: float) -> _Sample | None:
        near = sorted(samples, key=lambda x: abs(x.omega - omega))[:2]
        a, b = near
        s = (omega - a.omega) / (b.omega - a.omega)
        try:
            found = _sample(solve(omega, a.orbit.y0 + s * (b.orbit.y0 - a.orbit.y0)), omega, kind, centre, tighten)
        except OrbitNotFound:
            return None
        if found is not None:
            samples.append(found)
        return found

    for orbit in (stable, unstable):
        found = _sample(orbit, axis.at(orbit), kind, centre, tighten)
        if found is None:
            return None
        samples.append(found)
    lo, hi = samples
    for _ in range(WIDENINGS):
        if lo.value * hi.value <= 0:
            break
        # Both on one side: past the secant's zero by as far again, away from the nearer sample.
        root = hi.omega - hi.value * (hi.omega - lo.omega) / (hi.value - lo.value)
        nearer = lo if abs(lo.omega - root) < abs(hi.omega - root) else hi
        beyond = at(root + (root - nearer.omega))
        if beyond is None:
            return None
        lo, hi = nearer, beyond
    else:
        return None
    f_lo, f_hi, side, step = lo.value, hi.value, 0, 0.0
    omega = lo.omega if lo.value == 0 else hi.omega
    for _ in range(SECANT_ITERATIONS):
        if f_hi == f_lo:
            break
        last = samples[-1].omega
        omega = hi.omega - f_hi * (hi.omega - lo.omega) / (f_hi - f_lo)
        if not min(lo.omega, hi.omega) < omega < max(lo.omega, hi.omega):
            omega = 0.5 * (lo.omega + hi.omega)
        if abs(omega - last) < tol:
            step = abs(omega - last)
            break
        middle = at(omega)
        if middle is None or abs(middle.value) <= RESOLVED * middle.error:
            break
        lo, f_lo, hi, f_hi, side = illinois(middle, middle.value, lo, f_lo, hi, f_hi, side)
    slope = (hi.value - lo.value) / (hi.omega - lo.omega) if hi.omega != lo.omega else math.nan
    if not (math.isfinite(slope) and slope != 0):
        return None
    return omega, samples, slope, step


def branch_point_discriminant(
    a, b, solve: Callable[[np.ndarray, float], Orbit], k: int, tighten: Callable[[Orbit], Orbit | None] = _tight
) -> tuple[float, float] | None:
    """The zero in Omega of the discriminant of the multiplier pair passing through +1 between members ``a`` and ``b``.

    The Illinois secant method of the natural family's located changes of stability
    (:func:`locate_stability_change`), started from the two members, each point's
    discriminant measured against the orbit found again at :data:`TIGHT_RTOL`.

    Parameters
    ----------
    a, b : Orbit
        The members on either side of the branch point (or any orbits in the shape
        :func:`locate_stability_change` reads).
    solve : callable(y0, period) -> orbit
        The member of that period from the start ``y0``.
    k : int
        The first rotor's turns per period.
    tighten : callable(orbit) -> orbit or None
        The same orbit at the tight tolerances.

    Returns
    -------
    (omega, accuracy) or None
        None where the pair's discriminant is unresolved or has no zero near the two members.
    """
    found = _collision(a, b, "+1", None, omega_axis(solve, k, []), tighten)
    if found is None:
        return None
    omega, samples, slope, _ = found
    return omega, max(x.error for x in samples) / abs(slope)


def _counts(orbit) -> tuple[int, int, int]:
    """The member's :func:`~cosserat_chain.numerics.breather_arclength.instability_counts`."""
    return instability_counts(orbit.nontrivial_multipliers)


def _off(orbit, kind: str) -> np.ndarray:
    """The member's nontrivial multipliers outside the unit circle that left it as ``kind`` (counted as
    :func:`~cosserat_chain.numerics.breather_arclength.instability_counts` counts them)."""
    return off_circle(orbit.nontrivial_multipliers)[kind]


def _centre(unstable, kind: str) -> complex | None:
    """A Krein collision's centre on the circle from an unstable member: at the angle of its quartet nearest the circle."""
    if kind != "complex":
        return None
    near = _off(unstable, kind)
    newest = near[int(np.argmin(np.abs(near)))] if near.size else _classify(unstable)[0]
    return complex(np.exp(1j * abs(np.angle(newest))))


def _bracketed(stable, unstable, kind: str) -> bool:
    """Whether the collision's discriminant is resolved at both members (their own multipliers) with opposite signs, the
    stable one's < 0: the secant can start from them. Never for a Krein collision: its centre, taken from an unstable
    member far from it, may pick two other multipliers on a dense circle, whose discriminant has a zero elsewhere."""
    if kind == "complex":
        return False
    d_stable = collision_discriminant(stable.multipliers, kind)
    d_unstable = collision_discriminant(unstable.multipliers, kind)
    return d_stable is not None and d_unstable is not None and d_stable < 0 < d_unstable


def locate_stability_change(
    a, b, solve: Callable[[np.ndarray, float], Orbit] | None, bands: list[tuple[float, float]] | None, k: int | None,
    tighten: Callable[[Orbit], Orbit | None] = _tight, tol: float | None = None, axis: Axis | None = None,
) -> StabilityChange:  # fmt: skip
    """Bisect in the period (or along ``axis``) between members ``a`` and ``b`` that differ by one collision, then find
    the zero of the collision's discriminant (:class:`StabilityChange`).

    The members differ in their pairs off the unit circle
    (:func:`~cosserat_chain.numerics.breather_arclength.instability_counts`; a stable member and an
    unstable one, or two unstable ones with one pair more off the circle on one side): the side
    with fewer is the ``stable`` one of :class:`StabilityChange` (the colliding pair on the circle),
    and the bisection keeps each trial on the side whose counts it shares. Where they differ by
    more than one collision (:func:`locate_stability_changes` splits those first), the first
    kind that differs is located.

    Parameters
    ----------
    a, b : Orbit
        Members of one family (or any orbits with ``y0``, ``period``, ``stable``, ``multipliers``,
        ``nontrivial_multipliers`` and ``monodromy``: the chain's, :mod:`~.breathers`).
    solve : callable(y0, period) -> orbit
        The member of that period from the start ``y0``; raises
        :class:`~cosserat_chain.numerics.shooting.OrbitNotFound` where Newton fails.
    bands : list of (bottom, top)
        The phonon bands the resonances are named from (:func:`nearest_resonance`).
    k : int
        The first rotor's turns per period (Omega = 2 pi k / T).
    tighten : callable(orbit) -> orbit or None
        The same orbit found again, and its monodromy integrated, at :data:`TIGHT_RTOL`.
    tol : float, optional
        The accuracy in Omega wanted: the bisection stops once its bracket is narrower, or, for a
        collision at +1 or -1, once the discriminant is resolved at both ends with opposite signs (the
        secant takes over from there),
        and the secant once its next step is shorter (that step is added to ``accuracy``). None:
        the full :data:`BISECTIONS` and secant iterations (a family's changes).
    axis : Axis, optional
        The coordinate to locate along (:class:`Axis`: a parameter at a fixed frequency, the atlases'
        other axis; ``tol`` is then in its value); ``solve``, ``bands`` and ``k`` are not read with it.
        None: Omega, from them (:func:`omega_axis`).
    """
    axis = omega_axis(solve, k, bands) if axis is None else axis
    ca, cb = _counts(a), _counts(b)
    which = next((i for i in range(len(COUNTED)) if ca[i] != cb[i]), None)
    if which is None:  # the flags differ at the circle's tolerance while the counts agree: by the flags
        stable, unstable = (a, b) if a.stable else (b, a)
        which = int(np.argmax(_counts(unstable)))
    else:
        stable, unstable = (a, b) if ca[which] < cb[which] else (b, a)
    kind = COUNTED[which]
    on = _counts(stable)
    far = unstable
    for _ in range(BISECTIONS):
        if tol is not None and (abs(axis.at(stable) - axis.at(unstable)) <= tol or _bracketed(stable, unstable, kind)):
            break
        try:
            middle = axis.solve(0.5 * (stable.y0 + unstable.y0), 0.5 * (axis.parameter(stable) + axis.parameter(unstable)))
        except OrbitNotFound:  # the bracket found so far stays valid
            break
        if _counts(middle) == on:
            stable = middle
        else:
            unstable = middle
    off = _off(far, kind)
    multiplier = complex(off[int(np.argmax(np.abs(off)))]) if off.size else _classify(far)[0]
    omega_s, omega_u = axis.at(stable), axis.at(unstable)
    moduli_omega = 0.5 * (omega_s + omega_u)
    # The collision's centre from the bisected unstable member: the pair is nearest it there, not at a far member;
    # of its quartets off the circle the one nearest it, which has just left.
    centre = _centre(unstable, kind)
    if kind == "complex" and multiplier.imag < 0:
        multiplier = multiplier.conjugate()
    found = _collision(stable, unstable, kind, centre, axis, tighten, tol or 0.0)
    size = CLUSTER_SIZE[kind]
    if found is None:
        omega, accuracy, method, delta, slope, moduli_accuracy = moduli_omega, None, "moduli", None, None, None
        shooting_omega = math.nan
    else:
        omega, samples, slope, step = found
        delta = max(x.delta for x in samples)
        nearest = min(samples, key=lambda x: abs(x.omega - omega))
        shooting_omega = nearest.omega - nearest.loose / slope
        accuracy = max(x.error for x in samples) / abs(slope) + step
        method = "discriminant"
        # The moduli hide the pair's split sqrt(D) / 2 below the cluster's resolution delta^(1 / m).
        moduli_accuracy = max(4 * delta ** (2 / size) / abs(slope), 0.5 * abs(omega_s - omega_u))
    # The resonance by the multiplier's sector: a Krein collision near -1 is a parametric one too.
    angle = abs(np.angle(multiplier))
    sign = 1 if angle < math.pi / 3 else -1 if angle > 2 * math.pi / 3 else None
    return StabilityChange(
        omega=omega,
        stable_omega=omega_s,
        unstable_omega=omega_u,
        multiplier=multiplier,
        kind=kind,
        resonance=nearest_resonance(axis.bands(omega), axis.omega(omega), multiplier=sign),
        nearest=nearest_resonance(axis.bands(omega), axis.omega(omega)),
        accuracy=accuracy,
        method=method,
        moduli_omega=moduli_omega,
        moduli_accuracy=moduli_accuracy,
        monodromy_error=delta,
        slope=slope,
        shooting_omega=shooting_omega,
    )


def locate_stability_changes(
    a, b, solve: Callable[[np.ndarray, float], Orbit] | None, bands: list[tuple[float, float]] | None, k: int | None,
    tighten: Callable[[Orbit], Orbit | None] = _tight, tol: float | None = None, axis: Axis | None = None,
) -> list[StabilityChange]:  # fmt: skip
    """Every change of stability between members ``a`` and ``b``, in the order from ``a`` to ``b``.

    The members' pairs off the unit circle
    (:func:`~cosserat_chain.numerics.breather_arclength.instability_counts`) tell how many
    collisions lie between them (:func:`~cosserat_chain.numerics.breather_arclength.collisions_between`;
    none where they agree, even if the flags differ only at the circle's tolerance). Where more
    than one does, the bracket is bisected in the period, each half kept where its ends differ,
    until each part holds one (at most :data:`BISECTIONS` deep; a part Newton cannot split is
    located as one); each is located by :func:`locate_stability_change` (along ``axis``: Omega, or a
    parameter at a fixed frequency, the bisection then in the parameter). Two pairs crossing
    between the same two members so give two changes, where a stable/unstable flag or the
    parity of the pairs through +1 (:func:`~cosserat_chain.numerics.breather_arclength.pair_test`)
    give one or none.

    Parameters
    ----------
    a, b, solve, bands, k, tighten, tol, axis
        As :func:`locate_stability_change`.
    """
    axis = omega_axis(solve, k, bands) if axis is None else axis

    def split(a, b, depth: int) -> list:
        count = collisions_between(_counts(a), _counts(b))
        if count == 0 and a.stable == b.stable:
            return []
        if count <= 1 or depth == 0:
            return [(a, b)]
        try:
            middle = axis.solve(0.5 * (a.y0 + b.y0), 0.5 * (axis.parameter(a) + axis.parameter(b)))
        except OrbitNotFound:
            return [(a, b)]
        return split(a, middle, depth - 1) + split(middle, b, depth - 1)

    return [locate_stability_change(x, y, None, None, None, tighten, tol, axis) for x, y in split(a, b, BISECTIONS)]


def roto_breather_family(
    system: System,
    omega: float,
    *,
    to: float | None = None,
    rotor: int | str | None = None,
    partner: int | str | None = None,
    counter: bool = False,
    turns: int = 1,
    coupling: str = "C",
    unfold: str | None = None,
    step: float = 0.02,
    max_step: float = 0.05,
    max_points: int = 300,
    locate: bool = True,
    arclength: bool = False,
    along: tuple[str, float] | None = None,
    branches: bool = False,
    progress: ProgressCallback | None = None,
) -> SystemBreatherFamily:
    """A roto-breather family of ``system`` from the anti-continuum limit at frequency ``omega``.

    Parameters
    ----------
    system : System
        The system at the coupling wanted (its ``coupling`` parameter's value is the target);
        any drive set to 0 (its damping is the unfolding and is set to 0 as well).
    omega : float
        Frequency Omega = 2 pi k / T of the rotor at which the family starts (from the anti-continuum limit).
    to : float, optional
        Follow the family in the period until the frequency reaches ``to`` (default: the start alone).
    rotor : int or str, optional
        The turning coordinate (default the central angle).
    partner : int or str, optional
        A second rotor (a two-site roto-breather), turning with the first, or against it with ``counter``.
    turns : int
        k, turns of the rotor per period.
    coupling : str
        The parameter that couples the sites: continued from 0 (the anti-continuum limit) to its value.
    unfold : str, optional
        The damping parameter (default: the first one the damping depends on).
    step, max_step, max_points
        Of the continuation in the period (in log T).
    locate : bool
        Locate every change of stability along the family by bisection.
    arclength : bool
        Follow the family from ``omega`` to ``to`` by pseudo-arclength instead
        (:func:`~.system_breather_arclength.continue_family`): through folds in Omega, its folds,
        branch points and changes of stability as ``events``.
    along : (str, float), optional
        With ``arclength``: follow the family at the fixed frequency ``omega`` in this parameter
        (the coupling, a geometric one) from the system's value to the value given, instead of in Omega.
    branches : bool
        With ``arclength``: follow the family through each branch point
        (:func:`~.system_breather_arclength.follow_branch`).
    progress : callable(done, total), optional

    Returns
    -------
    SystemBreatherFamily

    Raises
    ------
    BreatherError
        For bad input (a rotor that is not an angle, a coupling that is not a parameter, omega <= 0).
    OrbitNotFound
        If Newton fails at the target coupling.
    """
    unfold = _unfolding_parameter(system, unfold)
    try:
        target_coupling = system.parameter(coupling)
    except ValueError:
        raise BreatherError(
            f"coupling: {system.name} has no parameter {coupling!r}; its parameters are {', '.join(system.parameters)}"
        ) from None
    if to is not None and not (math.isfinite(to) and to > 0):
        raise BreatherError(f"to must be a finite frequency > 0, got {to!r}")
    angles = np.flatnonzero(system.angles)
    if rotor is None:
        if not angles.size:
            raise BreatherError(f"{system.name} has no angle: nothing can turn")
        rotor = int(angles[angles.size // 2])
    rotors = {rotor: turns}
    if partner is not None:
        if _coordinate(system, partner, "partner") == _coordinate(system, rotor, "rotor"):
            raise BreatherError(f"partner must differ from the rotor, got {partner!r} for both")
        rotors[partner] = -turns if counter else turns
    system = system.with_parameters(**{unfold: 0.0})
    start = anti_continuum_orbit(system, float(omega), rotors, coupling)
    k = np.zeros(system.size)
    for i, t in start.turns.items():
        k[i] = t
    alone = system.with_parameters(**{coupling: 0.0})
    first = _at(alone, k, unfold, start.y0, start.period)
    if target_coupling != 0.0:
        first = _continue_coupling(first, system, coupling, target_coupling, k, unfold)
    members = [first]
    message = "the start alone"
    if arclength:
        return _arclength_family(system, start, coupling, first, omega, to, along, branches, counter, partner, turns, unfold, progress)
    if along is not None or branches:
        raise BreatherError("along and branches follow a family by pseudo-arclength: set arclength=True")
    events = []
    if to is not None and to != omega:
        from .system_breather_arclength import continue_family

        period_to = 2 * math.pi * turns / to
        # The kit's driver in the period: its folds (Omega turning) and branch points (a pair through +1 while
        # Omega goes on) are located on the way, each with its accuracy.
        family = continue_family(
            first, "omega", (min(omega, to), max(omega, to)), direction=1.0 if to > omega else -1.0,
            step=step, max_step=max_step, max_points=max_points, progress=progress,
        )  # fmt: skip
        events = [e for e in family.events if e.kind in ("fold", "branch_point")]
        lo, hi = min(first.period, period_to), max(first.period, period_to)
        inside = [o for o in family.orbits if lo <= o.period <= hi]
        members = inside
        message = family.message
        outside = [o for o in family.orbits if not lo <= o.period <= hi]
        if outside and len(family.orbits) >= 2:
            try:
                members.append(_land(family.orbits, period_to, PERIOD, system, k, unfold))
            except OrbitNotFound:
                message += f"; no orbit at Omega = {to:g} itself from the last two members"
    bands = linear_bands(system)
    changes = []
    if locate:
        # Bisection in the period is ill-posed across a fold (both members' periods lie on one side of it): there
        # the fold, with the branch point that comes with it, stands for the change.
        folds = [e.index for e in events if e.kind == "fold"]
        traced = {id(o): i for i, o in enumerate(family.orbits)} if folds else {}
        for a, b in zip(members[:-1], members[1:], strict=True):
            # Members are in the traced order; one landed past the last traced orbit counts as after it.
            first, last = traced.get(id(a), -1), traced.get(id(b), len(traced))
            if not any(first < j <= last for j in folds):
                changes += locate_stability_changes(a, b, lambda y0, period: _at(system, k, unfold, y0, period), bands, turns)
    for event in events:
        # A branch point's pair through +1 is a change of stability too: its discriminant's zero is the same point,
        # found without the singular Newton system that stops the relocation's bisection short.
        same = [
            c for c in changes if event.kind == "branch_point" and c.kind == "+1" and c.accuracy is not None
            and abs(c.omega - event.value) <= c.accuracy + (event.accuracy or 0.0)
        ]  # fmt: skip
        if same:
            event.discriminant = (same[0].omega, same[0].accuracy)
    settings = {"turns": turns, "unfold": unfold, "partner_against": counter if partner is not None else None}
    return SystemBreatherFamily(system, start, coupling, members, bands, changes, message, settings, events=events)


def _arclength_family(system, start, coupling, first, omega, to, along, branches, counter, partner, turns, unfold, progress):
    """:func:`roto_breather_family` with ``arclength``: the family from ``first`` in Omega to ``to``, or in ``along`` at fixed Omega."""
    from .system_breather_arclength import continue_family

    if along is None:
        if to is None or to == omega:
            raise BreatherError(f"arclength needs a frequency to go to (to) other than the start's {omega!r}, got {to!r}")
        name, target, here = "omega", float(to), float(omega)
    else:
        name, target = along
        try:
            here = system.parameter(name)
        except ValueError:
            raise BreatherError(
                f"along: {system.name} has no parameter {name!r}; its parameters are {', '.join(system.parameters)}"
            ) from None
        if not (isinstance(target, float | int) and math.isfinite(target)) or target == here:
            raise BreatherError(f"along: {name} must go to a finite value other than its {here!r}, got {target!r}")
    traced = continue_family(
        first, name, (min(here, target), max(here, target)), direction=1.0 if target > here else -1.0, branches=branches,
        progress=progress,
    )  # fmt: skip
    if name == "omega":
        orbits = traced.orbits
        for event in traced.branch_points:  # each with its pair's discriminant zero, as a natural family's
            if 1 <= event.index < len(orbits):
                event.discriminant = branch_point_discriminant(
                    orbits[event.index - 1], orbits[event.index], lambda y0, period: _at(system, first.turns, unfold, y0, period), turns
                )
    settings = {"turns": turns, "unfold": unfold, "partner_against": counter if partner is not None else None, "arclength": True}
    return SystemBreatherFamily(
        system, start, coupling, traced.orbits, linear_bands(system), [], traced.message, settings, events=traced.events, parameter=name
    )
