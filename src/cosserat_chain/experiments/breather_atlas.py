"""The existence map of roto-breathers: an atlas over the frequency Omega and a field of the chain (its geometry).

Contract
--------
:func:`breather_atlas` computes, on the grid of frequencies ``omegas`` and values of one
field of :class:`~cosserat_chain.params.ChainParams` (``a``, ``b``, ``h``: the geometry;
``E1``, ``E2``: the stiffnesses), the one-site roto-breather of the undamped, unloaded chain
at each point, by Newton on the unfolded shooting map
(:func:`~cosserat_chain.numerics.long_breathers.find_breather_orbit`, the monodromy in
column blocks from N = 50; the cost of a family is in docs/roto-breathers.md). The families
are continued in both directions: every point starts Newton from, in this order,

1. the secant through the two orbits before it at the same field value (continuation in
   Omega, the last orbit's Newton Jacobian kept for the first steps),
2. the secant through the two orbits at the same Omega and the previous field values
   (continuation in the field),
3. the anti-continuum rotor (:func:`~.breathers.anti_continuum_state`),

and ``exists`` is whether one of them converged (``source`` says which). At each orbit:

* **stability**: the largest modulus of the Floquet multipliers other than the Hamiltonian
  pair at +1 (the flow and the family), stable where it is 1 to
  :data:`~cosserat_chain.numerics.periodic.HAMILTONIAN_CIRCLE_TOL`;
* **localization** (:func:`orbit_localization`, over :data:`~.breathers.TAIL_SAMPLES`
  times of a period): the participation ratio PR = (sum e_k)^2 / sum e_k^2 of the particles'
  energies e_k (kinetic plus half of each bond's:
  :func:`~cosserat_chain.analysis.diagnostics.particle_energies`, the sine model's bonds
  with the linear bond energy at sin phi), averaged over the samples as the localization
  diagnostics average it over a run; the largest |phi|, |u| / h, |v| / h of the particles
  that do not turn against the diagnostics' :data:`~cosserat_chain.analysis.diagnostics.THRESHOLDS`
  (``localized``: every one within); the localization length xi, from a least-squares
  fit of log A_d = c - d / xi to the largest oscillation A_d (half the range over the period
  of u / h, v / h or phi) of the particles d sites from the rotor (:func:`localization_length`);
  and the static displacement, the largest mean |u| / h, |v| / h of the others (a zero-frequency
  deformation, which a chain with an acoustic band does not localize);
* **checks**: the closure of the orbit under a separate integration of the state alone
  (its return modulo 2 pi after one period, ``return_error``) and the spread of the energy
  along it (``energy_drift``; NaN for the sine model, which has no energy);
* **the bands**: the band edges of the infinite linear chain at each field value
  (:func:`~.breathers.band_edges`; a graded chain's from its finite modes; the bands the rotation drives:
  :func:`~.breathers.coupled_bands`) and the frequencies edge / n at which the n-th harmonic
  meets them, the lines the map is drawn against.

:meth:`BreatherAtlas.locate_changes` then locates, between neighbours along Omega of one family
(a point continued from the one before it) and between neighbours along the field at one Omega
(of one family: joined by the atlas's continuation, :func:`traced_families`, or by Newton from one
to the other, :func:`one_family`) of opposite stability (with ``every``, also two unstable ones
whose multiplier pairs off the unit circle differ:
:func:`~cosserat_chain.numerics.breather_arclength.instability_counts`), every change of
stability between them, with the families' one mechanism (:func:`~.breathers.located_changes`,
:func:`~.system_breathers.locate_stability_changes`: the zero of the colliding pair's
discriminant, its accuracy measured against the orbits found again at a tight tolerance; along
the field on :func:`~.system_breathers.parameter_axis`, bisected and placed in the field's value)
to an accuracy the caller asks for (:data:`LOCATE_TOL` by default, in Omega or in the field):
:class:`AtlasChange`, shared by the user systems' atlas (:mod:`~.system_breather_atlas`).

:meth:`BreatherAtlas.to_dataset` writes it all to one self-describing Dataset.
"""

from __future__ import annotations

import json
import math
import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from functools import partial
from typing import TYPE_CHECKING

import numpy as np

from ..analysis.diagnostics import THRESHOLDS, participation_ratio, particle_energies
from ..loads import moment_load
from ..models.base import Model, get_model
from ..numerics.breather_arclength import collisions_between, instability_counts
from ..numerics.long_breathers import SolvedBreather, find_breather_orbit
from ..numerics.periodic import HamiltonianOrbit, OrbitError, require_undamped
from ..numerics.shooting import Orbit, OrbitNotFound
from ..params import ChainParams
from ..state import ROW_INDEX, ROWS, column
from .breathers import (
    ATLAS_FIELDS,
    BAND_SOURCES,
    MAX_HARMONIC,
    TAIL_SAMPLES,
    _Member,
    _solvers,
    band_edges,
    chain_at,
    combination_resonances,
    coupled_bands,
    harmonics_in_bands,
    lifetime,
    localized_mode_summary,
    located_changes,
    rotors_start,
)
from .lifetimes import Lifetime, check_lifetime_run, lifetime_variables, measure_point_lifetimes
from .simulation import run_attributes
from .system_breathers import StabilityChange, locate_stability_changes, parameter_axis

if TYPE_CHECKING:  # xarray is imported where a Dataset is built
    import xarray as xr

    from .system_breather_atlas import SystemLocalization

ProgressCallback = Callable[[float, float], None]

#: Where each point's Newton started (``source``): none converged, continued in Omega, in the field, the anti-continuum rotor.
SOURCES = ("none", "omega", "field", "anti_continuum")
#: Newton iterations allowed from each start (a start that needs more is left for the next one).
ATLAS_MAX_ITER = 25
#: Newton from each start must divide the closure by this every two steps, else the next start is tried.
ATLAS_CONTRACTION = 0.9
#: Amplitudes below this are integration noise, not a tail: :func:`localization_length` fits only above it.
AMPLITUDE_FLOOR = 1e-9
#: The accuracy in Omega (and in the field, along it) to which an atlas locates its changes of stability by default (:meth:`BreatherAtlas.locate_changes`):
#: looser than a family's, which is the cost of the secant's last steps and the bisections below it.
LOCATE_TOL = 1e-6
#: The largest accuracy in Omega an atlas's changes may be asked for.
LOCATE_TOL_MAX = 0.01
#: How each located change was placed (:attr:`AtlasChange.placed_by`), and its kinds, as the Dataset's flags.
PLACED_BY = ("discriminant", "moduli", "bracket")
CHANGE_KINDS = ("+1", "-1", "complex")


def check_locate_tol(tol: float) -> float:
    """``tol`` as a float; ValueError naming ``locate_tol`` unless 0 < tol <= :data:`LOCATE_TOL_MAX`."""
    if isinstance(tol, bool) or not isinstance(tol, (int, float)) or not (math.isfinite(tol) and 0 < tol <= LOCATE_TOL_MAX):
        raise ValueError(f"locate_tol must be an accuracy in Omega (and in the field along it) > 0 and <= {LOCATE_TOL_MAX:g}, got {tol!r}")
    return float(tol)


def check_along(along, field_name: str) -> tuple[str, ...]:
    """The axes to locate along, in the order ``omega``, ``field_name`` (both for None); ValueError naming ``along`` for
    anything else, or none."""
    allowed = ("omega", field_name)
    if along is None:
        return allowed
    names = (along,) if isinstance(along, str) else tuple(along)
    if not names or any(name not in allowed for name in names):
        raise ValueError(f"along must name one or both of the atlas's axes {', '.join(allowed)}, got {along!r}")
    return tuple(name for name in allowed if name in names)


@dataclass(frozen=True)
class AtlasChange:
    """A change of stability located between two neighbours of an atlas: along Omega (one field value) or along the field
    (one Omega).

    Attributes
    ----------
    row : int
        The index of the first neighbour's field value (``values[row]``).
    value : float
        The field value of the change: the row's along Omega, the located one along the field.
    between : (int, int)
        The indices of the two neighbours along the axis: in ``omegas``, or in ``values``.
    change : StabilityChange
        :class:`~.system_breathers.StabilityChange`: ``omega``, its ``accuracy``, ``kind``, ``method``; along the field
        those are in the field's value (:class:`~.system_breathers.Axis`).
    axis : str
        ``omega``, or the field's name.
    column : int, optional
        Along the field: the index in ``omegas`` of both neighbours.
    frequency : float, optional
        Along the field: their Omega.
    """

    row: int
    value: float
    between: tuple[int, int]
    change: StabilityChange
    axis: str = "omega"
    column: int | None = None
    frequency: float | None = None

    @property
    def omega(self) -> float:
        """The Omega of the change: located along Omega, the neighbours' along the field."""
        return self.change.omega if self.axis == "omega" else float(self.frequency)

    @property
    def placed_by(self) -> str:
        """``discriminant`` (its zero, with a measured accuracy), ``moduli`` (the bisection on the moduli, with the
        moduli's accuracy) or ``bracket`` (that bisection without a measured slope: half its bracket)."""
        if self.change.accuracy is not None:
            return "discriminant"
        return "moduli" if self.change.moduli_accuracy is not None else "bracket"

    @property
    def accuracy(self) -> float:
        """The change's accuracy along its axis (in Omega, or in the field) as :attr:`placed_by` gives it."""
        c = self.change
        if c.accuracy is not None:
            return float(c.accuracy)
        return float(c.moduli_accuracy if c.moduli_accuracy is not None else 0.5 * abs(c.stable_omega - c.unstable_omega))

    def as_dict(self) -> dict:
        """JSON-ready; along the field the change's coordinates are named ``value``, ``stable_value``, ... and ``omega`` is
        the neighbours' Omega."""
        change = self.change.as_dict()
        if self.axis == "omega":
            return {"axis": "omega", "value": self.value, "between": list(self.between), **change, "accuracy": self.accuracy,
                    "placed_by": self.placed_by}  # fmt: skip
        renamed = {key.replace("omega", "value"): item for key, item in change.items()}
        return {"axis": self.axis, "omega": self.omega, "column": self.column, "between": list(self.between), **renamed,
                "accuracy": self.accuracy, "placed_by": self.placed_by}  # fmt: skip


def to_locate(points: list[list], every: bool = False, axis: str = "omega") -> list[tuple[int, int]]:
    """(row, i) of neighbours of opposite stability, and with ``every`` also two unstable ones whose pairs off the unit
    circle differ (a second pair leaving or a pair coming back while another stays off): along Omega points[row][i],
    points[row][i + 1] of one family (the second continued from the first in Omega); along the field (any other ``axis``)
    points[row][i], points[row + 1][i] (whether they are of one family is for the locate to check)."""
    out = []
    along_omega = axis == "omega"
    for j in range(len(points) - (0 if along_omega else 1)):
        for i in range(len(points[j]) - (1 if along_omega else 0)):
            a, b = (points[j][i], points[j][i + 1]) if along_omega else (points[j][i], points[j + 1][i])
            if a.orbit is None or b.orbit is None or (along_omega and b.source != "omega"):
                continue
            counts = instability_counts(a.orbit.nontrivial_multipliers), instability_counts(b.orbit.nontrivial_multipliers)
            if a.orbit.stable != b.orbit.stable or (every and collisions_between(*counts)):
                out.append((j, i))
    return out


#: Along the field, two neighbours the atlas's continuation does not join are of one family where Newton from the first's
#: state at the second's value lands on the second to this (max-norm of the start's difference).
ONE_FAMILY_TOL = 1e-6


def traced_families(points: list[list]) -> np.ndarray:
    """(value, omega) labels of the families as the atlas traced them: two points share one where a chain of continuations
    joins them (a point continued in Omega from the one before it, in the field from the one at the previous value); -1
    where no orbit was found."""
    rows, columns = len(points), len(points[0]) if points else 0
    parent = list(range(rows * columns))

    def root(n: int) -> int:
        while parent[n] != n:
            parent[n] = parent[parent[n]]
            n = parent[n]
        return n

    for j in range(rows):
        for i in range(columns):
            source = points[j][i].source
            if source in ("omega", "field"):
                parent[root(j * columns + i)] = root(j * columns + i - 1 if source == "omega" else (j - 1) * columns + i)
    return np.array([[root(j * columns + i) if points[j][i].orbit is not None else -1 for i in range(columns)] for j in range(rows)])


def one_family(a, b, solve: Callable[[np.ndarray, float], object], value: Callable[[object], float]) -> bool:
    """Whether members ``a`` and ``b`` (at two values of a field, one Omega) are of one family: Newton from ``a``'s state at
    ``b``'s value (``solve(y0, value)``) lands on ``b`` to :data:`ONE_FAMILY_TOL`."""
    try:
        landed = solve(a.y0, value(b))
    except OrbitNotFound:
        return False
    return bool(np.max(np.abs(landed.y0 - b.y0)) <= ONE_FAMILY_TOL)


def locate_atlas_changes(
    points: list[list], values: np.ndarray, omegas: np.ndarray, axes: tuple[str, ...],
    locate: Callable[[str, int, int, object, object, bool], list[StabilityChange] | None],
    progress: Callable[[int, int], None] | None = None, every: bool = False,
) -> tuple[list[AtlasChange], list[dict]]:  # fmt: skip
    """Every change of stability between the neighbours :func:`to_locate` gives along each of ``axes`` (with ``every``),
    ``locate(axis, row, i, a, b, traced)`` the located changes between orbits ``a`` and ``b`` (each collision between them,
    as their pairs off the circle count them; ``traced``: the atlas's continuation joins them, :func:`traced_families`),
    None where they are not of one family; ``progress(done, total)`` after each pair.

    Returns
    -------
    (changes, skipped)
        The changes along Omega, then along the field; the pairs not of one family (``axis``, ``row``, ``column``).
    """
    pairs = [(axis, j, i) for axis in axes for j, i in to_locate(points, every, axis)]
    families = traced_families(points)
    out, skipped = [], []
    for n, (axis, j, i) in enumerate(pairs):
        second = (j, i + 1) if axis == "omega" else (j + 1, i)
        located = locate(axis, j, i, points[j][i].orbit, points[second[0]][second[1]].orbit, bool(families[j, i] == families[second]))
        if located is None:
            skipped.append({"axis": axis, "row": j, "column": i})
        for change in located or []:
            if axis == "omega":
                out.append(AtlasChange(j, float(values[j]), (i, i + 1), change))
            else:
                out.append(AtlasChange(j, float(change.omega), (j, j + 1), change, axis, i, float(omegas[i])))
        if progress is not None:
            progress(n + 1, len(pairs))
    return out, skipped


def change_variables(changes: list[AtlasChange], omega_units: str, value_units: str, field_name: str, field: str) -> dict:
    """The located changes as Dataset variables over a dimension ``change`` (empty where none), their units and meanings:
    each change's point (value, omega), its axis (``omega`` or the field ``field``), and its accuracy and bracket in the
    axis's units (NaN in the other's)."""
    kinds = {"flag_values": np.arange(len(CHANGE_KINDS), dtype=np.int8), "flag_meanings": "plus_one minus_one complex"}
    placed = {"flag_values": np.arange(len(PLACED_BY), dtype=np.int8), "flag_meanings": " ".join(PLACED_BY)}
    axes = {"flag_values": np.arange(2, dtype=np.int8), "flag_meanings": f"omega {field}"}

    def on(axis_is_omega: bool, get: Callable[[AtlasChange], float]) -> Callable[[AtlasChange], float]:
        return lambda c: get(c) if (c.axis == "omega") == axis_is_omega else math.nan

    table = (
        ("axis", lambda c: 0 if c.axis == "omega" else 1, np.int8, "1", "the axis the change was located along", axes),
        ("value", lambda c: c.value, float, value_units, f"{field_name} of the change (located along {field})", {}),
        ("omega", lambda c: c.omega, float, omega_units, "Omega of the change (located along omega)", {}),
        ("accuracy", on(True, lambda c: c.accuracy), float, omega_units,
         "accuracy of change_omega along omega (change_placed_by says how it was measured)", {}),
        ("value_accuracy", on(False, lambda c: c.accuracy), float, value_units,
         f"accuracy of change_value along {field} (change_placed_by says how it was measured)", {}),
        ("stable_omega", on(True, lambda c: c.change.stable_omega), float, omega_units, "bracket's end with fewer pairs off the unit circle", {}),
        ("unstable_omega", on(True, lambda c: c.change.unstable_omega), float, omega_units, "bracket's end with the colliding pair off it", {}),
        ("stable_value", on(False, lambda c: c.change.stable_omega), float, value_units, "bracket's end with fewer pairs off the unit circle", {}),
        ("unstable_value", on(False, lambda c: c.change.unstable_omega), float, value_units, "bracket's end with the colliding pair off it", {}),
        ("between", lambda c: c.between[0], np.int32, "1", "index of the first neighbour along the axis, in omega or in value (the other: the next)", {}),
        ("at", lambda c: c.row if c.axis == "omega" else c.column, np.int32, "1", "index of both neighbours across the axis, in value or in omega", {}),
        ("kind", lambda c: CHANGE_KINDS.index(c.change.kind), np.int8, "1", "where the pair meets: +1, -1, off the real axis", kinds),
        ("placed_by", lambda c: PLACED_BY.index(c.placed_by), np.int8, "1", "how the change was placed", placed),
    )  # fmt: skip
    return {
        f"change_{name}": (("change",), np.array([get(c) for c in changes], dtype=dtype), {"units": units, "long_name": long, **extra})
        for name, get, dtype, units, long, extra in table
    }


def localization_length(amplitudes: np.ndarray) -> float:
    """The decay length xi of amplitudes A_d ~ exp(-d / xi), d = 1, 2, ... sites from the rotor.

    A least-squares fit of log A_d over the A_d above :data:`AMPLITUDE_FLOOR` (a tail that
    falls under the integration's noise is fitted only where it is resolved).

    Parameters
    ----------
    amplitudes : ndarray (D,)
        A_1, ..., A_D.

    Returns
    -------
    float
        xi in sites; inf where the tail does not decay, NaN with fewer than two resolved sites.
    """
    amplitudes = np.asarray(amplitudes, dtype=float)
    d = np.arange(1, amplitudes.size + 1)
    resolved = amplitudes > AMPLITUDE_FLOOR
    if np.count_nonzero(resolved) < 2:
        return math.nan
    slope = np.polyfit(d[resolved], np.log(amplitudes[resolved]), 1)[0]
    # A flat tail fits a slope of round-off size: a length of 1e9 sites or more is no decay.
    return math.inf if slope > -1e-9 else float(-1.0 / slope)


@dataclass(frozen=True)
class Localization:
    """How localized a roto-breather is (module docstring).

    Attributes
    ----------
    participation_ratio : float
        Mean over a period of (sum e_k)^2 / sum e_k^2 of the particles' energies.
    amplitudes : dict
        The largest |phi| (rad), |u| / h, |v| / h of the particles that do not turn (names of
        :data:`~cosserat_chain.analysis.diagnostics.THRESHOLDS`).
    site_amplitudes : ndarray (N,)
        A_d, the largest half-range (max - min) / 2 over the period of u / h, v / h, phi of the
        particles d = 1..N sites from the rotor: their oscillation about their mean position.
    length : float
        :func:`localization_length` of ``site_amplitudes``.
    static_displacement : float
        The largest |mean over the period| of u / h and v / h of the particles that do not turn:
        the chain's static deformation by the rotor (the nonlinear model's turning corners pull
        its neighbours in on average, a strain that a clamped chain spreads over its whole
        length, falling linearly to the ends: zero frequency, in the longitudinal band).
    energy_drift : float
        max |E(t) - E(0)| / max(1, |E(0)|) over the samples (NaN without an energy).
    return_error : float
        max |x(T) - x(0) - 2 pi k e_phi|, |v(T) - v(0)|: the orbit closed by an integration of its state alone.
    """

    participation_ratio: float
    amplitudes: dict
    site_amplitudes: np.ndarray
    length: float
    energy_drift: float
    return_error: float
    static_displacement: float = 0.0

    @property
    def localized(self) -> bool:
        """Every amplitude of the others within its threshold (the diagnostics' ``localized_rotation``)."""
        return all(self.amplitudes[name] <= THRESHOLDS[name] for name in THRESHOLDS)

    def as_dict(self) -> dict:
        """The measures in an atlas point's JSON (:func:`localization_entries`)."""
        return localization_entries(
            self, {"amplitudes_of_others": self.amplitudes, "static_displacement": self.static_displacement, "localized": self.localized}
        )


def localization_entries(localization, amplitudes: dict) -> dict:
    """The JSON of a chain's or a system's localization: its ratio and length, ``amplitudes`` (the others'), its checks."""
    return {
        "participation_ratio": localization.participation_ratio,
        "localization_length": None if not math.isfinite(localization.length) else localization.length,
        **amplitudes,
        "energy_drift": None if not math.isfinite(localization.energy_drift) else localization.energy_drift,
        "return_error": localization.return_error,
    }


def orbit_localization(orbit: HamiltonianOrbit) -> Localization:
    """:class:`Localization` of ``orbit`` from :data:`~.breathers.TAIL_SAMPLES` states over its period."""
    params = orbit.params
    x, v = orbit.trajectory(orbit.period * np.arange(1, TAIL_SAMPLES + 1) / TAIL_SAMPLES)
    energies = particle_energies(params, orbit.model, x, v)
    ratio = float(np.nanmean(participation_ratio(energies)))
    scale = np.array([params.h, params.h, 1.0])[None, :, None]
    size = np.abs(x) / scale
    turning = np.flatnonzero(orbit.particle_turns)
    others = np.delete(size, turning, axis=2)
    names = {"u_over_h": ROW_INDEX["u"], "v_over_h": ROW_INDEX["v"], "phi": ROW_INDEX["phi"]}
    amplitudes = {name: float(np.max(others[:, row], initial=0.0)) for name, row in names.items()}
    signed = x / scale
    swing = 0.5 * (signed.max(axis=0) - signed.min(axis=0))  # (3, 2N+1): the oscillation about the mean
    per_particle = np.max(swing, axis=0)
    per_particle[turning] = 0.0
    rotor = column(params, orbit.particle)
    n = params.n_particles
    site = np.array([max(per_particle[c] for c in (rotor - d, rotor + d) if 0 <= c < n) for d in range(1, params.N + 1)])
    static = np.delete(np.abs(signed.mean(axis=0)[: ROW_INDEX["phi"]]), turning, axis=1)
    drift = math.nan
    if orbit.energy is not None:
        drift = float(np.max(np.abs(energies.sum(axis=1) - orbit.energy)) / max(1.0, abs(orbit.energy)))
    shift = np.zeros_like(orbit.x)
    shift[ROW_INDEX["phi"]] = 2 * math.pi * orbit.particle_turns
    back = float(max(np.max(np.abs(x[-1] - orbit.x - shift)), np.max(np.abs(v[-1] - orbit.v))))
    return Localization(ratio, amplitudes, site, localization_length(site), drift, back, float(np.max(static, initial=0.0)))


@dataclass
class AtlasPoint:
    """One point of an atlas, of the chain or (:class:`~.system_breather_atlas.SystemAtlasPoint`) of a user system.

    The orbit (None where none was found) and what was measured on it: ``localization`` a
    :class:`Localization` (of a system's orbit, a
    :class:`~.system_breather_atlas.SystemLocalization`: both give their JSON by ``as_dict``).
    """

    omega: float
    value: float
    source: str
    orbit: HamiltonianOrbit | Orbit | None = None
    localization: Localization | SystemLocalization | None = None
    cpu_s: float = 0.0
    message: str = ""
    #: From the atlas's ``measure_lifetimes`` (None: not run).
    lifetime: Lifetime | None = None

    @property
    def exists(self) -> bool:
        return self.orbit is not None

    def energy(self) -> float | None:
        """The orbit's total energy (None for a model without one)."""
        return self.orbit.energy

    def as_dict(self) -> dict:
        out = {"omega": self.omega, "value": self.value, "exists": self.exists, "source": self.source, "cpu_s": self.cpu_s}
        if self.orbit is None:
            return {**out, "message": self.message}
        o = self.orbit
        if self.lifetime is not None:
            out["lifetime"] = self.lifetime.as_dict()
        return {
            **out,
            "energy": self.energy(),
            "max_multiplier": o.max_multiplier,
            "stable": bool(o.stable),
            "unfolding": o.unfolding,
            "closure": o.closure,
            "iterations": o.iterations,
            **self.localization.as_dict(),
        }


@dataclass
class BreatherAtlas:
    """Roto-breathers over (field value, Omega): ``points[j][i]`` at ``values[j]``, ``omegas[i]``.

    Attributes
    ----------
    params : ChainParams
        The chain at the first value (the field aside).
    model : str
    field : str
    values, omegas : ndarray
    points : list of list of AtlasPoint
    bands : tuple of str
        The bands the rotation drives (at the first value).
    settings : dict
    """

    params: ChainParams
    model: str
    field: str
    values: np.ndarray
    omegas: np.ndarray
    points: list[list[AtlasPoint]]
    bands: tuple[str, ...]
    settings: dict = field(default_factory=dict)
    #: From :meth:`locate_changes` (None: not located).
    changes: list[AtlasChange] | None = None

    def params_at(self, value: float) -> ChainParams:
        return chain_at(self.params, self.field, value)

    def locate_changes(
        self, tol: float = LOCATE_TOL, progress: Callable[[int, int], None] | None = None, every: bool = False,
        along: str | tuple[str, ...] | None = None,
    ) -> None:  # fmt: skip
        """Locate every change of stability between neighbours of opposite stability, with ``every`` between any whose pairs
        off the circle differ (:func:`locate_atlas_changes`), along Omega and along the field (``along``: ``omega``, the
        field's name, or both for None), to ``tol`` in each; kept in :attr:`changes`, :meth:`as_dict`, :meth:`to_dataset`
        and the settings (the field's neighbours neither joined by the atlas's continuation, :func:`traced_families`, nor
        found of one family by :func:`one_family` are left unlocated).

        Along Omega by :func:`~.breathers.located_changes`; along the field the same mechanism
        (:func:`~.system_breathers.locate_stability_changes`) on :func:`~.system_breathers.parameter_axis`: the
        members at the neighbours' Omega on the chain with the field's value (:func:`~.breathers.chain_at`), bisected and
        placed in the value, the resonances named from the bands there.

        Raises
        ------
        ValueError
            For a tolerance :func:`check_locate_tol` refuses, or axes :func:`check_along` refuses.
        """
        tol = check_locate_tol(tol)
        axes = check_along(along, self.field)

        def locate(axis: str, j: int, i: int, a: HamiltonianOrbit, b: HamiltonianOrbit, traced: bool) -> list | None:
            if axis == "omega":
                return located_changes([a, b], self.bands, tol)
            solve, tighten = _solvers(a, self.field)
            first, second = _Member(a), _Member(b)
            value = partial(_member_value, self.field)
            if not (traced or one_family(first, second, solve, value)):
                return None
            line = parameter_axis(value, solve, partial(_band_edges, self.params, self.field, self.bands), a.omega)
            return locate_stability_changes(first, second, None, None, None, tighten, tol, axis=line)

        self.changes, skipped = locate_atlas_changes(self.points, self.values, self.omegas, axes, locate, progress, every)
        self.settings["locate"] = {"tol": tol, "every": every, "along": list(axes), "not_one_family": skipped}

    def measure_lifetimes(
        self, max_periods: int, *, perturbation: float = 1e-8, threshold: float = 1e-2, progress: Callable[[int, int], None] | None = None
    ) -> None:
        """Run every point's orbit from its perturbed velocities (:func:`~.breathers.lifetime`) and keep the lifetimes
        with the points (:attr:`AtlasPoint.lifetime`): in :meth:`as_dict`, :meth:`to_dataset` and the settings.

        Raises
        ------
        ValueError
            As :func:`~.breathers.lifetime` does (before any run).
        """
        check_lifetime_run(perturbation, threshold, max_periods)
        run = partial(lifetime, perturbation=perturbation, threshold=threshold, max_periods=max_periods)
        measure_point_lifetimes(self.points, run, progress)
        self.settings["lifetime"] = {"max_periods": max_periods, "perturbation": perturbation, "threshold": threshold}

    def grid(self, name: str) -> np.ndarray:
        """A measure over (value, omega) from :meth:`AtlasPoint.as_dict` (NaN where no orbit)."""
        out = np.full((self.values.size, self.omegas.size), np.nan)
        for j, row in enumerate(self.points):
            for i, point in enumerate(row):
                # The JSON has no infinity: an undecaying tail's length is taken from the measure itself.
                length = name == "localization_length" and point.localization is not None
                item = point.localization.length if length else point.as_dict().get(name)
                if item is not None:
                    out[j, i] = float(item)
        return out

    def band_edges(self) -> np.ndarray:
        """(value, band, edge) the bottom and top of each driven band at each field value (:func:`~.breathers.band_edges`)."""
        out = np.zeros((self.values.size, len(self.bands), 2))
        for j, value in enumerate(self.values):
            edges = band_edges(self.params_at(value))
            for b, band in enumerate(self.bands):
                out[j, b] = edges[band]
        return out

    def localized_modes(self) -> list[list[dict]]:
        """Per field value, a graded chain's localized modes with their share on the rotors' core (:func:`~.breathers.localized_mode_summary`)."""
        rotors = (self.settings.get("particle", 0), *(int(k) for k in self.settings.get("partners", {})))
        return [localized_mode_summary(self.params_at(value), rotors) for value in self.values]

    def resonance_omegas(self) -> np.ndarray:
        """(value, band, edge, harmonic): Omega = edge / n, where the n-th harmonic meets the edge."""
        return self.band_edges()[..., None] / np.arange(1, MAX_HARMONIC + 1)

    def as_dict(self) -> dict:
        return {
            "model": self.model,
            "field": self.field,
            "values": self.values.tolist(),
            "omegas": self.omegas.tolist(),
            "bands": list(self.bands),
            "bands_from": BAND_SOURCES[self.params.graded],
            "band_edges": {band: self.band_edges()[:, b].tolist() for b, band in enumerate(self.bands)},
            "localized_modes": self.localized_modes(),
            "thresholds": THRESHOLDS,
            "points": [[p.as_dict() for p in row] for row in self.points],
            "resonances": atlas_resonances(self),
            "settings": self.settings,
            "stability_changes": None if self.changes is None else [c.as_dict() for c in self.changes],
        }

    def to_dataset(self) -> xr.Dataset:
        """Dataset over (value, omega) with the bands and their harmonics; parameters, model, version, units in the attributes."""
        import xarray as xr

        dims = ("value", "omega")
        measures = {
            "energy": ("1", "total energy of the orbit (NaN: no orbit, or the model has no energy)"),
            "max_multiplier": ("1", "largest modulus of the Floquet multipliers other than the Hamiltonian pair at +1"),
            "unfolding": ("1", "unfolding damping rate eps at the solution (0 up to Newton's tolerance)"),
            "closure": ("1", "max |Phi_T(y0) - y0 - 2 pi k e_phi| of the converged orbit"),
            "iterations": ("1", "Newton iterations"),
            "participation_ratio": ("1", "(sum e_k)^2 / sum e_k^2 of the particles' energies, mean over a period"),
            "localization_length": ("1", "decay length of the others' oscillation about their mean, in sites (inf: no decay)"),
            "static_displacement": ("1", "largest |mean u| / h, |mean v| / h over a period of the particles that do not turn"),
            "energy_drift": ("1", "max |E(t) - E(0)| / max(1, |E(0)|) along the orbit"),
            "return_error": ("1", "max |state(T) - state(0) - 2 pi k e_phi| by a separate integration of the state"),
            "cpu_s": ("s", "CPU time of the point (Newton from every start tried, multipliers, checks)"),
        }
        data = {name: (dims, self.grid(name), {"units": units, "long_name": long}) for name, (units, long) in measures.items()}
        data["exists"] = (
            dims,
            self.grid("exists").astype(np.int8),
            {"units": "1", "long_name": "a roto-breather was found (Newton converged)"},
        )
        data["stable"] = (
            dims,
            np.nan_to_num(self.grid("stable")).astype(np.int8),
            {"units": "1", "long_name": "every nontrivial multiplier on the unit circle"},
        )
        data["localized"] = (dims, np.nan_to_num(self.grid("localized")).astype(np.int8),
                             {"units": "1", "long_name": "every amplitude of the others within the localization diagnostics' threshold"})  # fmt: skip
        sources = np.array([[SOURCES.index(p.source) for p in row] for row in self.points], dtype=np.int8)
        data["source"] = (dims, sources, {"units": "1", "long_name": "where Newton started", "flag_values": np.arange(len(SOURCES), dtype=np.int8),
                                          "flag_meanings": " ".join(SOURCES)})  # fmt: skip
        for name in THRESHOLDS:
            unit = "rad" if name == "phi" else "1"
            values = np.full(sources.shape, np.nan)
            for j, row in enumerate(self.points):
                for i, p in enumerate(row):
                    if p.localization is not None:
                        values[j, i] = p.localization.amplitudes[name]
            data[f"amplitude_{name}"] = (dims, values, {"units": unit, "long_name": f"largest {name} of the particles that do not turn",
                                                        "threshold": THRESHOLDS[name]})  # fmt: skip
        states = np.full((2, len(ROWS), *sources.shape, self.params.n_particles), np.nan)
        for j, row in enumerate(self.points):
            for i, p in enumerate(row):
                if p.orbit is not None:
                    states[:, :, j, i] = p.orbit.x, p.orbit.v
        for r, name in enumerate(ROWS):
            unit = "rad" if name == "phi" else "1"
            data[name] = (
                (*dims, "particle"),
                states[0, r],
                {"units": unit, "long_name": f"{name} of the orbit's start (section phi_rotor = 0)"},
            )
            data[f"{name}_dot"] = ((*dims, "particle"), states[1, r],
                                   {"units": f"{unit} s-1" if unit == "rad" else "s-1", "long_name": f"rate of {name} at the orbit's start"})  # fmt: skip
        resonant = atlas_resonances(self)
        for name, long in (
            ("harmonics_in_bands", "harmonics n Omega (n <= 6) inside a driven band"),
            ("combination_resonances", "pairs of driven bands whose frequencies sum to a harmonic n Omega (n <= 6)"),
        ):
            counts = np.array([len(r[name]) for r in resonant], dtype=np.int16).reshape(sources.shape)
            data[name] = (dims, counts, {"units": "1", "long_name": long})
        edges = self.band_edges()
        data["band_edge"] = (("value", "band", "edge"), edges, {"units": "rad s-1", "long_name": "band edges of the infinite linear chain"})
        data["resonance_omega"] = (("value", "band", "edge", "harmonic"), self.resonance_omegas(),
                                   {"units": "rad s-1", "long_name": "Omega at which the n-th harmonic meets the band edge"})  # fmt: skip
        coords = {
            "value": ("value", self.values, {"long_name": f"chain field {self.field}"}),
            "omega": ("omega", self.omegas, {"units": "rad s-1", "long_name": "mean angular velocity Omega of the rotating particle"}),
            "band": ("band", list(self.bands)),
            "edge": ("edge", ["bottom", "top"]),
            "harmonic": ("harmonic", np.arange(1, MAX_HARMONIC + 1)),
            "particle": ("particle", np.arange(-self.params.N, self.params.N + 1)),
        }
        if "lifetime" in self.settings:
            data.update(lifetime_variables(self.points, dims))
        if self.changes is not None:
            value_units = "length (units of the parameters' h)" if self.field in ("a", "b", "h") else "stiffness (units of E1)"
            data.update(change_variables(self.changes, "rad s-1", value_units, f"chain field {self.field}", self.field))
        ds = xr.Dataset(data, coords=coords)
        model = get_model(self.model)
        ds.attrs.update(run_attributes(self.params, model, moment_load(0.0, self.settings.get("particle", 0))))
        ds.attrs.update(
            {
                "experiment": "roto_breather_atlas",
                "field": self.field,
                "field_units": "length (units of the parameters' h)" if self.field in ("a", "b", "h") else "stiffness (units of E1)",
                "units": "time: the parameters' units (m = 1, E1 = 1 give the paper's); angles: rad",
                "bands": ", ".join(self.bands),
                "bands_from": BAND_SOURCES[self.params.graded],
                "localized_modes_json": json.dumps(self.localized_modes()),
                "thresholds_json": json.dumps(THRESHOLDS),
                "settings_json": json.dumps(self.settings),
            }
        )
        return ds


def _member_value(field_name: str, member) -> float:
    """The field's value on a chain's member (:class:`~.breathers._Member`)."""
    return float(getattr(member.orbit.params, field_name))


def _band_edges(params: ChainParams, field_name: str, bands: tuple[str, ...], value: float) -> list[tuple[float, float]]:
    """The driven bands' (bottom, top) on the chain with the field at ``value`` (the resonances are named from them)."""
    edges = band_edges(chain_at(params, field_name, value))
    return [tuple(edges[name]) for name in bands]


def _secant(a: HamiltonianOrbit | None, b: HamiltonianOrbit | None, r: float) -> tuple[np.ndarray, np.ndarray] | None:
    """The state b + r (b - a) (b alone without a), or None without b."""
    if b is None:
        return None
    if a is None:
        return b.x, b.v
    return b.x + r * (b.x - a.x), b.v + r * (b.v - a.v)


def breather_atlas(
    params: ChainParams,
    model: str | Model,
    omegas: np.ndarray | list[float],
    field: str,
    values: np.ndarray | list[float],
    *,
    turns: int = 1,
    particle: int = 0,
    method: str = "auto",
    partners: Mapping[int, int] | None = None,
    progress: ProgressCallback | None = None,
) -> BreatherAtlas:
    """Roto-breathers over the grid ``values`` x ``omegas`` (module docstring): one-site, or multi-site with ``partners``.

    Parameters
    ----------
    params : ChainParams
        Undamped; ``field`` is replaced by each of ``values`` (:func:`chain_at`: the inertia
        follows a and b where it is their default).
    model : str or Model
        ``sine`` or ``nonlinear``.
    omegas : sequence of float
        Frequencies > 0, followed in this order (a family is continued from one to the next:
        start where the anti-continuum rotor converges, above the bands).
    field : str
        One of :data:`ATLAS_FIELDS`.
    values : sequence of float
        Its values, followed in this order.
    turns, particle
        The rotor's turns per period and its particle.
    method : {"auto", "dense", "blocks"}
        Of :func:`~cosserat_chain.numerics.long_breathers.find_breather_orbit`.
    partners : {particle: signed turns}, optional
        More rotors (:func:`~.breathers.rotors_start`): ``{1: turns}`` turns particle 1 with the
        first rotor (in phase), ``{1: -turns}`` against it (out of phase).
    progress : callable(done, total), optional
        Called after each point.

    Returns
    -------
    BreatherAtlas

    Raises
    ------
    ValueError
        For a damped chain, a field not in :data:`ATLAS_FIELDS`, values the chain refuses, or
        frequencies not finite and > 0.
    """
    model = get_model(model)
    require_undamped(params)
    if field not in ATLAS_FIELDS:
        raise ValueError(f"field must be one of {', '.join(ATLAS_FIELDS)} (the geometry or a stiffness), got {field!r}")
    omegas = np.asarray(omegas, dtype=float)
    values = np.asarray(values, dtype=float)
    if omegas.ndim != 1 or omegas.size == 0 or not np.all(np.isfinite(omegas)) or np.any(omegas <= 0):
        raise ValueError(f"omegas must be one or more finite frequencies > 0, got {omegas.tolist()!r}")
    if values.ndim != 1 or values.size == 0 or not np.all(np.isfinite(values)):
        raise ValueError(f"values of {field} must be one or more finite numbers, got {values.tolist()!r}")
    chains = []
    for value in values:
        try:
            chains.append(chain_at(params, field, value))
        except ValueError as err:  # pydantic's ValidationError: its messages without the framework's wording
            reasons = [e["msg"].removeprefix("Value error, ") for e in err.errors()] if hasattr(err, "errors") else [str(err)]
            raise ValueError(f"values of {field}: the chain refuses {field}={float(value)!r}: {'; '.join(reasons)}") from None
    partners = dict(partners or {})
    particle_turns = rotors_start(chains[0], model, float(omegas[0]), turns=turns, particle=particle, partners=partners)[3]
    found: list[list[SolvedBreather | None]] = [[None] * omegas.size for _ in values]
    points: list[list[AtlasPoint]] = []
    total = values.size * omegas.size
    for j, chain in enumerate(chains):
        row = []
        for i, omega in enumerate(omegas):
            started = time.process_time()
            starts = []
            before = found[j][i - 1] if i >= 1 else None
            if before is not None:
                earlier = found[j][i - 2] if i >= 2 else None
                r = 0.0 if earlier is None else (omega - before.orbit.omega) / (before.orbit.omega - earlier.orbit.omega)
                starts.append(("omega", _secant(None if earlier is None else earlier.orbit, before.orbit, r), before.jacobian))
            last = found[j - 1][i] if j >= 1 else None
            if last is not None:
                first = found[j - 2][i] if j >= 2 else None
                r = 0.0 if first is None else (values[j] - values[j - 1]) / (values[j - 1] - values[j - 2])
                starts.append(("field", _secant(None if first is None else first.orbit, last.orbit, r), last.jacobian))
            starts.append(
                ("anti_continuum", rotors_start(chain, model, float(omega), turns=turns, particle=particle, partners=partners)[:2], None)
            )
            point = AtlasPoint(float(omega), float(values[j]), "none")
            messages = []
            for source, guess, jacobian in starts:
                try:
                    solved = find_breather_orbit(
                        chain, model, float(omega), guess, method=method, turns=turns, particle=particle, particle_turns=particle_turns,
                        max_iter=ATLAS_MAX_ITER, jacobian0=jacobian, contraction=ATLAS_CONTRACTION,
                    )  # fmt: skip
                except OrbitError as err:
                    messages.append(f"from {source}: {err}")
                    continue
                found[j][i] = solved
                point = AtlasPoint(float(omega), float(values[j]), source, solved.orbit, orbit_localization(solved.orbit))
                break
            point.message = "; ".join(messages) if point.orbit is None else ""
            point.cpu_s = time.process_time() - started
            row.append(point)
            if progress is not None:
                progress(j * omegas.size + i + 1, total)
        points.append(row)
    settings = {"model": model.name, "field": field, "turns": turns, "particle": particle, "method": method}
    if partners:
        settings["partners"] = {str(k): t for k, t in partners.items()}
    return BreatherAtlas(params, model.name, field, values, omegas, points, coupled_bands(params, model, particle), settings)


def atlas_resonances(atlas: BreatherAtlas) -> list[dict]:
    """Per point: the harmonics inside a driven band and the phonon pairs summing to a harmonic (JSON-ready)."""
    out = []
    for value in atlas.values:
        chain = atlas.params_at(value)
        for omega in atlas.omegas:
            out.append({
                "value": float(value),
                "omega": float(omega),
                "harmonics_in_bands": [{"harmonic": n, "band": b} for n, b in harmonics_in_bands(chain, float(omega), bands=atlas.bands)],
                "combination_resonances": [{"harmonic": n, "bands": [a, b]} for n, a, b in combination_resonances(chain, float(omega), bands=atlas.bands)],
            })  # fmt: skip
    return out
