"""Rotating states as periodic orbits: one orbit, its continuation down in M, and the rotation characteristic.

Contract
--------
:func:`periodic_orbit` finds the rotating state at one moment as a limit cycle
(:func:`~cosserat_chain.numerics.periodic.find_periodic_orbit`) and, with
``down_to``, follows it to smaller moments until it ceases to exist
(:func:`~cosserat_chain.numerics.periodic.continue_orbit`); the result also holds the
static fold M_c (:func:`~cosserat_chain.numerics.continuation.locate_fold`), so the
two edges of the hysteresis loop are side by side: rotation starts going up at M_c,
and stops going down where the orbit ends.

:func:`rotation_characteristic` gives the mean angular velocity 2 pi k / T against M
at chosen moments (each orbit seeded by the one at the next larger moment), with the
stability of every orbit and M_c: the rotation characteristic of the hysteresis
picture. Moments where no orbit was found hold NaN.
"""

from __future__ import annotations

import json
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np

from ..loads import moment_load
from ..models.base import Model, get_model
from ..numerics.continuation import locate_fold
from ..numerics.periodic import OrbitBranch, OrbitError, PeriodicOrbit, continue_orbit, find_periodic_orbit
from ..params import ChainParams
from ..state import ROWS
from .simulation import run_attributes

if TYPE_CHECKING:  # xarray is imported where a Dataset is built or read: commands without file output start without it
    import xarray as xr

ProgressCallback = Callable[[float, float], None]


def _static_fold(params: ChainParams, model: Model, particle: int) -> float:
    if params.rigid_modes:
        # A chain that can spin about a pin has no static state under a moment: no fold (NaN).
        return math.nan
    fold = locate_fold(params, model, particle=particle)
    return math.nan if fold is None else float(fold.moment)


def _none_if_nan(value: float) -> float | None:
    return None if not math.isfinite(value) else float(value)


@dataclass
class OrbitResult:
    """One periodic orbit and, optionally, its continuation down in M.

    Attributes
    ----------
    orbit : PeriodicOrbit
        The orbit at the requested moment.
    branch : OrbitBranch or None
        The continuation (with ``down_to``).
    static_fold : float
        M_c of the static branch (NaN if it has none, as a chain that spins about a pin has no static state).
    """

    orbit: PeriodicOrbit
    branch: OrbitBranch | None
    static_fold: float
    settings: dict = field(default_factory=dict)

    def as_dict(self) -> dict:
        """JSON-ready summary: the orbit, M_c and, with a continuation, where the orbit ends. Moments in the parameters' units; ``moment_scale`` = E1 h^2 divides them into the paper's dimensionless moment (Fig. 2)."""
        out = {**self.orbit.as_dict(), "static_fold": _none_if_nan(self.static_fold)}
        if self.branch is not None:
            out["continuation"] = {
                "end": self.branch.end,
                "end_moment": self.branch.end_moment,
                "end_period": self.branch.orbits[-1].period,
                "stability_lost_at": self.branch.stability_lost_at,
                "message": self.branch.message,
                "moment": self.branch.moment.tolist(),
                "period": self.branch.period.tolist(),
                "mean_angular_velocity": self.branch.mean_angular_velocity.tolist(),
                "stable": self.branch.stable.tolist(),
                "branch_points": [event["moment"] for event in self.branch.events if event["kind"] == "branch_point"],
                "phase_condition": ["section" if o.phase_normal is None else "plane" for o in self.branch.orbits],
            }
        return out

    def to_dataset(self) -> xr.Dataset:
        """Dataset with the start state (dims ``particle``), the multipliers and, with a
        continuation, the branch (dim ``point``)."""
        import xarray as xr

        o = self.orbit
        particle = np.arange(-o.params.N, o.params.N + 1)
        data = {row: (("particle",), o.x[i]) for i, row in enumerate(ROWS)}
        data.update({f"{row}_dot": (("particle",), o.v[i]) for i, row in enumerate(ROWS)})
        data["multiplier_real"] = (("multiplier",), o.multipliers.real)
        data["multiplier_imag"] = (("multiplier",), o.multipliers.imag)
        coords = {"particle": particle, "multiplier": np.arange(len(o.multipliers))}
        if self.branch is not None:
            b = self.branch
            data["branch_moment"] = (("point",), b.moment)
            data["branch_period"] = (("point",), b.period)
            data["branch_mean_angular_velocity"] = (("point",), b.mean_angular_velocity)
            data["branch_max_multiplier"] = (("point",), b.max_multiplier)
            data["branch_stable"] = (("point",), b.stable.astype(np.int8))
            coords["point"] = np.arange(len(b.orbits))
        ds = xr.Dataset(data, coords=coords)
        ds.attrs.update(run_attributes(o.params, get_model(o.model), moment_load(o.moment, o.particle)))
        ds.attrs.update(
            {
                "experiment": "periodic_orbit",
                "moment": o.moment,
                "turns": o.turns,
                "loaded_particle": o.particle,
                "period": o.period,
                "mean_angular_velocity": o.mean_angular_velocity,
                "stable": int(o.stable),
                "closure": o.closure,
                "static_fold": self.static_fold,
                "settings_json": json.dumps(self.settings),
            }
        )
        if self.branch is not None:
            lost = self.branch.stability_lost_at
            ds.attrs.update(
                {
                    "end": self.branch.end,
                    "end_moment": self.branch.end_moment,
                    "end_message": self.branch.message,
                    "stability_lost_at": math.nan if lost is None else lost,
                }
            )
        return ds


def periodic_orbit(
    params: ChainParams,
    model: str | Model,
    moment: float,
    *,
    turns: int = 1,
    particle: int = 0,
    down_to: float | None = None,
    period_max: float = 2000.0,
    progress: ProgressCallback | None = None,
    **options,
) -> OrbitResult:
    """The rotating state at ``moment`` as a periodic orbit, optionally continued down to ``down_to``.

    Parameters
    ----------
    params : ChainParams
    model : str or Model
        ``nonlinear`` or ``sine`` (the linear model does not rotate).
    moment : float
    turns : int
        Turns of the loaded particle per period.
    particle : int
    down_to : float, optional
        Continue the orbit towards smaller |M|, stopping at this moment if it still exists there.
    period_max : float
        The continuation reports a diverging period (homoclinic end) beyond this.
    progress : callable(points, max_points), optional
    **options
        Passed to :func:`~cosserat_chain.numerics.periodic.find_periodic_orbit` (``tol``, ``rtol``, ``atol``, ...).

    Returns
    -------
    OrbitResult

    Raises
    ------
    ValueError
        For bad input, e.g. ``down_to`` not between 0 and ``moment``.
    OrbitError
        If no orbit is found at ``moment``.
    """
    model = get_model(model)
    if down_to is not None and not (math.isfinite(down_to) and 0 <= down_to / moment < 1):
        raise ValueError(f"down_to must lie between 0 and the moment {moment!r} (same sign, smaller), got {down_to!r}")
    orbit = find_periodic_orbit(params, model, moment, turns=turns, particle=particle, **options)
    branch = None
    if down_to is not None:
        keep = {k: v for k, v in options.items() if k in ("tol", "rtol", "atol")}
        branch = continue_orbit(orbit, moment_min=abs(down_to), period_max=period_max, progress=progress, **keep)
    settings = {"turns": turns, "down_to": down_to, "period_max": period_max, **options}
    return OrbitResult(orbit=orbit, branch=branch, static_fold=_static_fold(params, model, particle), settings=settings)


@dataclass
class RotationCharacteristic:
    """Mean angular velocity of the rotating state against M, from periodic orbits.

    Attributes
    ----------
    moment : ndarray (k,)
        Moments, in decreasing |M| (the order they were computed).
    period, mean_angular_velocity, max_multiplier : ndarray (k,)
        NaN where no orbit was found.
    stable : ndarray of bool (k,)
    static_fold : float
        M_c: the static branch ends there (rotation starts going up).
    """

    params: ChainParams
    model: str
    turns: int
    particle: int
    moment: np.ndarray
    period: np.ndarray
    mean_angular_velocity: np.ndarray
    max_multiplier: np.ndarray
    stable: np.ndarray
    static_fold: float
    orbits: list[PeriodicOrbit | None] = field(default_factory=list)

    @property
    def found(self) -> np.ndarray:
        """Where an orbit was found."""
        return np.isfinite(self.period)

    def as_dict(self) -> dict:
        """JSON-ready table (null where no orbit was found). Moments in the parameters' units; ``moment_scale`` = E1 h^2 divides them into the paper's dimensionless moment (Fig. 2)."""
        return {
            "model": self.model,
            "turns": self.turns,
            "particle": self.particle,
            "moment": self.moment.tolist(),
            "moment_scale": self.params.moment_scale,
            "period": [_none_if_nan(x) for x in self.period],
            "mean_angular_velocity": [_none_if_nan(x) for x in self.mean_angular_velocity],
            "max_nontrivial_multiplier": [_none_if_nan(x) for x in self.max_multiplier],
            "stable": self.stable.tolist(),
            "static_fold": _none_if_nan(self.static_fold),
        }

    def to_dataset(self) -> xr.Dataset:
        """Dataset with dimension ``point`` and the parameters in the attributes."""
        import xarray as xr

        ds = xr.Dataset(
            {
                "period": (("point",), self.period),
                "mean_angular_velocity": (("point",), self.mean_angular_velocity),
                "max_multiplier": (("point",), self.max_multiplier),
                "stable": (("point",), self.stable.astype(np.int8)),
            },
            coords={"point": np.arange(len(self.moment)), "moment": ("point", self.moment)},
        )
        ds["mean_angular_velocity"].attrs["long_name"] = "2 pi k / T of the periodic orbit (NaN: none found)"
        ds.attrs.update(run_attributes(self.params, get_model(self.model), moment_load(0.0, self.particle)))
        ds.attrs.update(
            {
                "experiment": "rotation_characteristic",
                "turns": self.turns,
                "loaded_particle": self.particle,
                "static_fold": self.static_fold,
            }
        )
        return ds


def rotation_characteristic(
    params: ChainParams,
    model: str | Model,
    moments: Sequence[float],
    *,
    turns: int = 1,
    particle: int = 0,
    progress: ProgressCallback | None = None,
    **options,
) -> RotationCharacteristic:
    """Mean angular velocity 2 pi k / T of the periodic orbit at each moment, and M_c.

    The moments are visited in decreasing |M|; each orbit starts from the one found
    at the previous moment (the first from a simulation), so the curve follows one
    branch of orbits down towards its end. Below the end (or where Newton fails) the
    entries are NaN and the next moment starts again from the last orbit found.

    Parameters
    ----------
    params : ChainParams
    model : str or Model
    moments : sequence of float
        Moments of one sign, non-zero.
    turns, particle
        As for :func:`periodic_orbit`.
    progress : callable(done, total), optional
    **options
        Passed to :func:`~cosserat_chain.numerics.periodic.find_periodic_orbit`.

    Returns
    -------
    RotationCharacteristic

    Raises
    ------
    ValueError
        If ``moments`` is empty, mixes signs or holds zero or a non-finite value.
    """
    model = get_model(model)
    values = np.asarray(moments, dtype=float)
    if values.ndim != 1 or values.size == 0 or not np.all(np.isfinite(values)) or np.any(values == 0):
        raise ValueError(f"moments must be a non-empty list of finite non-zero moments, got {moments!r}")
    if not (np.all(values > 0) or np.all(values < 0)):
        raise ValueError(f"moments must all have the same sign, got {moments!r}")
    values = values[np.argsort(-np.abs(values), kind="stable")]
    orbits: list[PeriodicOrbit | None] = []
    last: PeriodicOrbit | None = None
    for i, moment in enumerate(values):
        try:
            orbit = find_periodic_orbit(params, model, float(moment), turns=turns, particle=particle, guess=last, **options)
        except OrbitError:
            orbit = None
        orbits.append(orbit)
        last = orbit or last
        if progress is not None:
            progress(i + 1, len(values))

    def column(attr: str) -> np.ndarray:
        return np.array([math.nan if o is None else float(getattr(o, attr)) for o in orbits])

    return RotationCharacteristic(
        params=params,
        model=model.name,
        turns=turns,
        particle=particle,
        moment=values,
        period=column("period"),
        mean_angular_velocity=column("mean_angular_velocity"),
        max_multiplier=column("max_multiplier"),
        stable=np.array([o is not None and o.stable for o in orbits]),
        static_fold=_static_fold(params, model, particle),
        orbits=orbits,
    )
