"""The existence map of a user system's roto-breathers: an atlas over the frequency Omega and one of its parameters.

Contract
--------
:func:`system_breather_atlas` computes, on the grid of frequencies ``omegas`` and values of
one parameter of a :class:`~cosserat_chain.systems.base.System` (its coupling ``C``, an
on-site strength, a mass), the roto-breather of the undamped system at each point: one rotor,
or two (a ``partner`` turning with it, in phase, or against it with ``counter``). As the
chain's atlas (:mod:`~.breather_atlas`), every point starts Newton
(:func:`~cosserat_chain.numerics.shooting.find_orbit`, the damping parameter as the unfolding
unknown) from, in this order,

1. the secant through the two orbits before it at the same parameter value (continuation in Omega),
2. the secant through the two orbits at the same Omega and the previous values (in the parameter),
3. the anti-continuum limit continued in the coupling from 0 to its value at that point
   (:func:`~.system_breathers.roto_breather_family`),

and ``source`` records which converged. At each orbit, from
:data:`~.breathers.TAIL_SAMPLES` states over its period (:func:`system_orbit_localization`):

* **stability**: the largest modulus of the multipliers other than the pair at +1;
* **localization**: the participation ratio of the coordinates' mean kinetic energies
  K_i = <m_i v_i^2> / 2 (a user system need not split its energy by site; 1 for a lone rotor,
  about 2 for a pair), the largest |q| of the coordinates that do not turn, and the
  localization length xi (:func:`~.breather_atlas.localization_length`) of the largest
  oscillation (half the range over the period) of the sites d = 1, 2, ... from the first
  rotor, a site being a lattice's site (:class:`~cosserat_chain.systems.lattice.LatticeSystem`,
  the distance around a ring the shorter way) or a coordinate of any other system;
* **checks**: the orbit's return modulo 2 pi by a separate integration of its state
  (``return_error``) and the spread of its energy (``energy_drift``, NaN without an energy);
* **the bands** of the linear system about rest at each value
  (:func:`~.system_breathers.linear_bands`) and the harmonics of Omega inside them.

:meth:`SystemBreatherAtlas.locate_changes` locates the changes of stability between neighbours along
Omega and along the parameter as the chain's atlas does (:class:`~.breather_atlas.AtlasChange`), each by
:func:`~.system_breathers.locate_stability_changes` (along the parameter at the neighbours' frequency,
:func:`~.system_breathers.parameter_axis`).
:meth:`SystemBreatherAtlas.to_dataset` writes it all to one self-describing Dataset.
"""

from __future__ import annotations

import json
import math
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from functools import partial
from typing import TYPE_CHECKING

import numpy as np

from ..numerics.shooting import Orbit, OrbitNotFound, find_orbit
from ..systems.base import System
from ..systems.lattice import LatticeSystem
from .breather_atlas import (
    ATLAS_MAX_ITER,
    LOCATE_TOL,
    SOURCES,
    AtlasChange,
    AtlasPoint,
    change_variables,
    check_along,
    check_locate_tol,
    localization_entries,
    localization_length,
    locate_atlas_changes,
    one_family,
)
from .breathers import TAIL_SAMPLES
from .lifetimes import check_lifetime_run, lifetime_variables, measure_point_lifetimes
from .simulation import system_attributes
from .system_breathers import (
    BreatherError,
    _at,
    _coordinate,
    _unfolding_parameter,
    harmonics_in_bands,
    linear_bands,
    locate_stability_changes,
    orbit_energy,
    parameter_axis,
    roto_breather_family,
    system_lifetime,
)

if TYPE_CHECKING:  # xarray is imported where a Dataset is built
    import xarray as xr

ProgressCallback = Callable[[int, int], None]


def _sites(system: System) -> tuple[np.ndarray, int, bool]:
    """Each coordinate's site, the number of sites, and whether they close in a ring."""
    if isinstance(system, LatticeSystem):
        return np.repeat(np.arange(system.sites), len(system.dofs)), system.sites, system.boundary == "periodic"
    return np.arange(system.size), system.size, False


@dataclass(frozen=True)
class SystemLocalization:
    """How localized a user system's roto-breather is (module docstring)."""

    participation_ratio: float
    amplitude: float
    site_amplitudes: np.ndarray
    length: float
    energy_drift: float
    return_error: float

    def as_dict(self) -> dict:
        """The measures in an atlas point's JSON (:func:`~.breather_atlas.localization_entries`)."""
        return localization_entries(self, {"amplitude_of_others": self.amplitude})


def system_orbit_localization(orbit: Orbit, rotor: int) -> SystemLocalization:
    """:class:`SystemLocalization` of ``orbit`` (``rotor``: the first turning coordinate) from :data:`~.breathers.TAIL_SAMPLES` states."""
    system = orbit.system
    n = system.size
    y = orbit.trajectory(orbit.period * np.arange(1, TAIL_SAMPLES + 1) / TAIL_SAMPLES)
    q, v = y[:, :n], y[:, n:]
    kinetic = 0.5 * np.mean(system.mass()[None] * v**2, axis=0)
    ratio = float(kinetic.sum() ** 2 / np.sum(kinetic**2)) if np.any(kinetic > 0) else math.nan
    turning = orbit.turns != 0
    amplitude = float(np.max(np.abs(q[:, ~turning]), initial=0.0))
    swing = 0.5 * (q.max(axis=0) - q.min(axis=0))
    swing[turning] = 0.0
    site, count, ring = _sites(system)
    distance = np.abs(site - site[rotor])
    if ring:
        distance = np.minimum(distance, count - distance)
    reach = int(distance.max(initial=0))
    per_distance = np.array([float(np.max(swing[distance == d], initial=0.0)) for d in range(1, reach + 1)])
    drift = math.nan
    start = orbit_energy(orbit)
    if start is not None:
        energies = np.array([system.energy(qk) + 0.5 * np.sum(system.mass() * vk**2) for qk, vk in zip(q, v, strict=True)])
        drift = float(np.max(np.abs(energies - start)) / max(1.0, abs(start)))
    back = float(np.max(np.abs(y[-1] - orbit.y0 - np.concatenate([2 * math.pi * orbit.turns, np.zeros(n)]))))
    return SystemLocalization(ratio, amplitude, per_distance, localization_length(per_distance), drift, back)


@dataclass
class SystemAtlasPoint(AtlasPoint):
    """One point of a system's atlas (:class:`~.breather_atlas.AtlasPoint`): an :class:`~cosserat_chain.numerics.shooting.Orbit`
    and its :class:`SystemLocalization`."""

    def energy(self) -> float | None:
        """The orbit's total energy (:func:`~.system_breathers.orbit_energy`; None for a system without one)."""
        return orbit_energy(self.orbit)


@dataclass
class SystemBreatherAtlas:
    """Roto-breathers of a system over (parameter value, Omega): ``points[j][i]`` at ``values[j]``, ``omegas[i]``.

    Attributes
    ----------
    system : System
        The undamped system (the parameter aside).
    field : str
        The parameter varied.
    values, omegas : ndarray
    points : list of list of SystemAtlasPoint
    rotors : dict
        Coordinate index -> signed turns per period.
    settings : dict
    """

    system: System
    field: str
    values: np.ndarray
    omegas: np.ndarray
    points: list[list[SystemAtlasPoint]]
    rotors: dict[int, int]
    settings: dict = field(default_factory=dict)
    #: From :meth:`locate_changes` (None: not located).
    changes: list[AtlasChange] | None = None

    def locate_changes(
        self, tol: float = LOCATE_TOL, progress: Callable[[int, int], None] | None = None, every: bool = False,
        along: str | tuple[str, ...] | None = None,
    ) -> None:  # fmt: skip
        """Locate every change of stability between neighbours of opposite stability, with ``every`` between any whose pairs
        off the circle differ (:func:`~.breather_atlas.locate_atlas_changes`), along Omega and along the parameter
        (``along``: ``omega``, the parameter's name, or both for None), to ``tol`` in each, by
        :func:`~.system_breathers.locate_stability_changes` (along the parameter on
        :func:`~.system_breathers.parameter_axis`: the orbits at the neighbours' period on the system with the parameter's
        value, bisected and placed in it); kept in :attr:`changes`, :meth:`as_dict`, :meth:`to_dataset` and the settings
        (the parameter's neighbours neither joined by the atlas's continuation nor found of one family by
        :func:`~.breather_atlas.one_family` are left unlocated).

        Raises
        ------
        ValueError
            For a tolerance :func:`~.breather_atlas.check_locate_tol` refuses, or axes :func:`~.breather_atlas.check_along`
            refuses.
        """
        tol = check_locate_tol(tol)
        axes = check_along(along, self.field)
        k = np.zeros(self.system.size)
        for i, t in self.rotors.items():
            k[i] = t
        first = next(iter(self.rotors.values()))
        unfold = self.settings["unfold"]

        def locate(axis: str, j: int, i: int, a: Orbit, b: Orbit, traced: bool) -> list | None:
            if axis == "omega":
                here = self.system_at(self.values[j])
                return locate_stability_changes(a, b, partial(_at, here, k, unfold), linear_bands(here), first, tol=tol)

            def solve(y0: np.ndarray, value: float) -> Orbit:
                return _at(self.system_at(value), k, unfold, y0, a.period)

            value = partial(_parameter_value, self.field)
            if not (traced or one_family(a, b, solve, value)):
                return None
            line = parameter_axis(value, solve, lambda v: linear_bands(self.system_at(v)), float(self.omegas[i]))
            return locate_stability_changes(a, b, None, None, None, tol=tol, axis=line)

        self.changes, skipped = locate_atlas_changes(self.points, self.values, self.omegas, axes, locate, progress, every)
        self.settings["locate"] = {"tol": tol, "every": every, "along": list(axes), "not_one_family": skipped}

    def measure_lifetimes(
        self, max_periods: int, *, perturbation: float = 1e-8, threshold: float = 1e-2, progress: Callable[[int, int], None] | None = None
    ) -> None:
        """Run every point's orbit from its perturbed velocities on the system's flow (:func:`~.system_breathers.system_lifetime`)
        and keep the lifetimes with the points: in :meth:`as_dict`, :meth:`to_dataset` and the settings.

        Raises
        ------
        ValueError
            As :func:`~.system_breathers.system_lifetime` does (before any run).
        """
        check_lifetime_run(perturbation, threshold, max_periods)
        run = partial(system_lifetime, perturbation=perturbation, threshold=threshold, max_periods=max_periods)
        measure_point_lifetimes(self.points, run, progress)
        self.settings["lifetime"] = {"max_periods": max_periods, "perturbation": perturbation, "threshold": threshold}

    def system_at(self, value: float) -> System:
        return self.system.with_parameters(**{self.field: float(value)})

    def grid(self, name: str) -> np.ndarray:
        """A measure over (value, omega) from :meth:`SystemAtlasPoint.as_dict` (NaN where no orbit)."""
        out = np.full((self.values.size, self.omegas.size), np.nan)
        for j, row in enumerate(self.points):
            for i, point in enumerate(row):
                length = name == "localization_length" and point.localization is not None
                item = point.localization.length if length else point.as_dict().get(name)
                if item is not None:
                    out[j, i] = float(item)
        return out

    def bands(self) -> list[list[tuple[float, float]]]:
        """The phonon bands about rest at each value (:func:`~.system_breathers.linear_bands`)."""
        return [linear_bands(self.system_at(value)) for value in self.values]

    def as_dict(self) -> dict:
        bands = self.bands()
        return {
            **self.system.describe(),
            "field": self.field,
            "values": self.values.tolist(),
            "omegas": self.omegas.tolist(),
            "rotors": {self.system.coordinates[i]: k for i, k in self.rotors.items()},
            "bands": [[list(b) for b in row] for row in bands],
            "points": [[p.as_dict() for p in row] for row in self.points],
            "harmonics_in_bands": [
                [[{"harmonic": n, "band": b} for n, b in harmonics_in_bands(bands[j], float(w))] for w in self.omegas]
                for j in range(self.values.size)
            ],
            "settings": self.settings,
            "stability_changes": None if self.changes is None else [c.as_dict() for c in self.changes],
        }

    def to_dataset(self, reference: str | None = None) -> xr.Dataset:
        """Dataset over (value, omega): every measure, the start of each orbit, the bands (NaN-padded); the system in the attributes.

        Parameters
        ----------
        reference : str, optional
            How the system was named (``takeno_peyrard``, ``my_lattice.py:build``), kept as ``system_reference``.
        """
        import xarray as xr

        dims = ("value", "omega")
        measures = {
            "energy": "total energy of the orbit (NaN: no orbit, or the system has no energy function)",
            "max_multiplier": "largest modulus of the Floquet multipliers other than the pair at +1",
            "unfolding": f"the unfolding damping {self.settings.get('unfold')} at the solution (0 for an orbit of the undamped system)",
            "closure": "max |Phi_T(y0) - y0 - 2 pi k| of the converged orbit",
            "iterations": "Newton iterations",
            "participation_ratio": "(sum K_i)^2 / sum K_i^2 of the coordinates' mean kinetic energies",
            "localization_length": "decay length of the others' oscillation in sites from the first rotor (inf: no decay)",
            "amplitude_of_others": "largest |q| over a period of the coordinates that do not turn",
            "energy_drift": "max |E(t) - E(0)| / max(1, |E(0)|) along the orbit",
            "return_error": "max |y(T) - y(0) - 2 pi k| by a separate integration of the state",
            "cpu_s": "CPU time of the point in seconds (Newton from every start tried, multipliers, checks)",
        }
        data = {name: (dims, self.grid(name), {"long_name": long}) for name, long in measures.items()}
        for name, long in (
            ("exists", "a roto-breather was found (Newton converged)"),
            ("stable", "every nontrivial multiplier on the unit circle"),
        ):
            data[name] = (dims, np.nan_to_num(self.grid(name)).astype(np.int8), {"long_name": long})
        sources = np.array([[SOURCES.index(p.source) for p in row] for row in self.points], dtype=np.int8)
        data["source"] = (dims, sources, {"long_name": "where Newton started", "flag_values": np.arange(len(SOURCES), dtype=np.int8),
                                          "flag_meanings": " ".join(SOURCES)})  # fmt: skip
        starts = np.full((*sources.shape, 2 * self.system.size), np.nan)
        for j, row in enumerate(self.points):
            for i, p in enumerate(row):
                if p.orbit is not None:
                    starts[j, i] = p.orbit.y0
        n = self.system.size
        data["q0"] = ((*dims, "coordinate"), starts[..., :n], {"long_name": "start of the orbit: coordinates"})
        data["v0"] = ((*dims, "coordinate"), starts[..., n:], {"long_name": "start of the orbit: velocities"})
        bands = self.bands()
        width = max((len(b) for b in bands), default=0)
        edges = np.full((self.values.size, width, 2), np.nan)
        for j, row in enumerate(bands):
            edges[j, : len(row)] = row
        data["band_edge"] = (("value", "band", "edge"), edges, {"long_name": "edges of the phonon bands about rest (NaN: fewer bands)"})
        coords = {
            "value": ("value", self.values, {"long_name": f"system parameter {self.field}"}),
            "omega": ("omega", self.omegas, {"long_name": "mean angular velocity Omega = 2 pi k / T of the first rotor"}),
            "coordinate": ("coordinate", list(self.system.coordinates)),
            "band": ("band", np.arange(width)),
            "edge": ("edge", ["bottom", "top"]),
        }
        if "lifetime" in self.settings:
            data.update(lifetime_variables(self.points, dims))
        if self.changes is not None:
            units, field_name = "rad per time unit of the system", f"system parameter {self.field}"
            data.update(change_variables(self.changes, units, "the system's", field_name, self.field))
        ds = xr.Dataset(data, coords=coords)
        ds.attrs.update(system_attributes(self.system, reference))
        ds.attrs.update(
            {
                "experiment": "system_roto_breather_atlas",
                "title": f"Roto-breather atlas of the system {self.system.name} over Omega and {self.field}",
                "field": self.field,
                "rotors_json": json.dumps({self.system.coordinates[i]: k for i, k in self.rotors.items()}),
                "settings_json": json.dumps(self.settings),
            }
        )
        return ds


def _parameter_value(name: str, orbit: Orbit) -> float:
    """The parameter's value on ``orbit``'s system."""
    return float(orbit.parameter(name))


def _secant(a: Orbit | None, b: Orbit | None, r: float) -> np.ndarray | None:
    """The state b + r (b - a) (b alone without a), or None without b."""
    if b is None:
        return None
    return b.y0 if a is None else b.y0 + r * (b.y0 - a.y0)


def system_breather_atlas(
    system: System,
    omegas: np.ndarray | list[float],
    field: str,
    values: np.ndarray | list[float],
    *,
    rotor: int | str | None = None,
    partner: int | str | None = None,
    counter: bool = False,
    turns: int = 1,
    coupling: str = "C",
    unfold: str | None = None,
    progress: ProgressCallback | None = None,
) -> SystemBreatherAtlas:
    """Roto-breathers of ``system`` over the grid ``values`` of ``field`` x ``omegas`` (module docstring).

    Parameters
    ----------
    system : System
        Undriven; its damping parameter is set to 0 (it is the unfolding unknown).
    omegas : sequence of float
        Frequencies > 0 of the first rotor, followed in this order (start where the anti-continuum
        limit converges, e.g. above the band).
    field : str
        The parameter varied (the coupling itself, or any other but the damping).
    values : sequence of float
        Its values, followed in this order.
    rotor, partner, counter, turns, coupling, unfold
        As :func:`~.system_breathers.roto_breather_family`.
    progress : callable(done, total), optional
        Called after each point.

    Returns
    -------
    SystemBreatherAtlas

    Raises
    ------
    BreatherError
        For a field that is not a parameter (or is the damping), values or frequencies not finite
        (frequencies not > 0), a rotor or partner that is not an angle.
    """
    unfold = _unfolding_parameter(system, unfold)
    if field not in system.parameters or field == unfold:
        allowed = ", ".join(p for p in system.parameters if p != unfold)
        raise BreatherError(f"field must be a parameter of {system.name} other than its damping {unfold!r} ({allowed}), got {field!r}")
    if coupling not in system.parameters:
        raise BreatherError(f"coupling: {system.name} has no parameter {coupling!r}; its parameters are {', '.join(system.parameters)}")
    omegas = np.asarray(omegas, dtype=float)
    values = np.asarray(values, dtype=float)
    if omegas.ndim != 1 or omegas.size == 0 or not np.all(np.isfinite(omegas)) or np.any(omegas <= 0):
        raise BreatherError(f"omegas must be one or more finite frequencies > 0, got {omegas.tolist()!r}")
    if values.ndim != 1 or values.size == 0 or not np.all(np.isfinite(values)):
        raise BreatherError(f"values of {field} must be one or more finite numbers, got {values.tolist()!r}")
    system = system.with_parameters(**{unfold: 0.0})
    if rotor is None:
        angles = np.flatnonzero(system.angles)
        if not angles.size:
            raise BreatherError(f"{system.name} has no angle: nothing can turn")
        rotor = int(angles[angles.size // 2])
    first = _coordinate(system, rotor, "rotor")
    rotors = {first: turns}
    if partner is not None:
        other = _coordinate(system, partner, "partner")
        if other == first:
            raise BreatherError(f"partner must differ from the rotor, got {partner!r} for both")
        rotors[other] = -turns if counter else turns
    k = np.zeros(system.size)
    for i, t in rotors.items():
        k[i] = t
    found: list[list[Orbit | None]] = [[None] * omegas.size for _ in values]
    points: list[list[SystemAtlasPoint]] = []
    for j, value in enumerate(values):
        here = system.with_parameters(**{field: float(value)})
        row = []
        for i, omega in enumerate(omegas):
            started = time.process_time()
            period = 2 * math.pi * turns / omega
            starts = []
            if i >= 1 and found[j][i - 1] is not None:
                before, earlier = found[j][i - 1], found[j][i - 2] if i >= 2 else None
                r = 0.0 if earlier is None else (omega - omegas[i - 1]) / (omegas[i - 1] - omegas[i - 2])
                starts.append(("omega", _secant(earlier, before, r)))
            if j >= 1 and found[j - 1][i] is not None:
                last, first_ = found[j - 1][i], found[j - 2][i] if j >= 2 else None
                r = 0.0 if first_ is None else (value - values[j - 1]) / (values[j - 1] - values[j - 2])
                starts.append(("field", _secant(first_, last, r)))
            starts.append(("anti_continuum", None))
            point = SystemAtlasPoint(float(omega), float(value), "none")
            messages = []
            for source, guess in starts:
                try:
                    if guess is None:
                        orbit = roto_breather_family(
                            here, float(omega), rotor=first, partner=None if partner is None else list(rotors)[1], counter=counter,
                            turns=turns, coupling=coupling, unfold=unfold, locate=False,
                        ).orbits[0]  # fmt: skip
                    else:
                        orbit = find_orbit(here, (guess, period), turns=k, unfold=unfold, max_iterations=ATLAS_MAX_ITER)
                except (OrbitNotFound, BreatherError) as err:
                    messages.append(f"from {source}: {err}")
                    continue
                found[j][i] = orbit
                point = SystemAtlasPoint(float(omega), float(value), source, orbit, system_orbit_localization(orbit, first))
                break
            point.message = "; ".join(messages) if point.orbit is None else ""
            point.cpu_s = time.process_time() - started
            row.append(point)
            if progress is not None:
                progress(j * omegas.size + i + 1, values.size * omegas.size)
        points.append(row)
    settings = {"turns": turns, "coupling": coupling, "unfold": unfold, "partner_against": counter if partner is not None else None}
    return SystemBreatherAtlas(system, field, values, omegas, points, rotors, settings)
