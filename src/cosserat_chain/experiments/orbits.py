"""Rotating states as periodic orbits: one orbit, its continuation down in M, and the rotation characteristic.

Contract
--------
:func:`periodic_orbit` finds the rotating state at one moment as a limit cycle
(:func:`~cosserat_chain.numerics.periodic.find_periodic_orbit`) and, with
``down_to``, follows it to smaller moments until it ceases to exist
(:func:`~cosserat_chain.numerics.periodic.continue_orbit`); the result also holds the
static fold M_c (:func:`~cosserat_chain.numerics.continuation.locate_fold`), so the
two edges of the hysteresis loop are side by side: rotation starts going up at M_c,
and stops going down where the orbit ends. Below M_c a run from rest stays static, so the
orbit there is reached from a start given: ``guess`` (an orbit or a state and period, as
:func:`~cosserat_chain.numerics.periodic.find_periodic_orbit` takes), ``start`` (a state,
a stored frame of a run, that the settling run starts from instead of rest) or
``from_above`` (the orbit found at a larger moment and continued down to this one); the
result's ``start`` says which.

:func:`rotation_characteristic` gives the mean angular velocity 2 pi k / T against M
at chosen moments (each orbit seeded by the one at the next larger moment), with the
stability of every orbit and M_c: the rotation characteristic of the hysteresis
picture. Moments where no orbit was found hold NaN.
"""

from __future__ import annotations

import json
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field, replace
from typing import TYPE_CHECKING

import numpy as np

from ..linalg.threads import one_blas_thread
from ..loads import moment_load
from ..models.base import Model, get_model
from ..numerics.collocation import CollocationOrbit, continue_periodic_orbit, find_collocation_orbit
from ..numerics.collocation_core import CollocationError
from ..numerics.continuation import locate_fold
from ..numerics.cycle_curve import locate_cycle_end
from ..numerics.long_orbits import choose_method
from ..numerics.periodic import (
    END_FOLD,
    END_MOMENT_MIN,
    OrbitBranch,
    OrbitError,
    PeriodicOrbit,
    continue_orbit,
    find_periodic_orbit,
    initial_guess,
)
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


def _trivial_errors(branch: OrbitBranch) -> np.ndarray:
    """|mu_trivial - 1| at every orbit of a collocation branch: the multipliers are the collocation's, so this is its
    :attr:`~cosserat_chain.numerics.collocation_core.ProfileOrbit.trivial_multiplier_error`."""
    return np.array([abs(o.trivial_multiplier - 1.0) for o in branch.orbits])


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
    start : dict
        How the orbit was reached: ``method`` ``rest`` (a settled run from rest), ``guess``, ``state``
        (a settled run from a given state) or ``from_above`` (with ``from_moment``, the ``approach``'s end
        and where the orbit lost stability on the way down, if it did); the CLI adds the ``file`` read.
    approach : OrbitBranch or None
        With ``from_above``: the continuation from the larger moment down to this one.
    collocation : CollocationOrbit or None
        With ``method="collocation"``: the collocation solve ``orbit`` was read from, where a
        continuation (``down_to``, :meth:`continued`) starts, so that the orbit is solved once.
    """

    orbit: PeriodicOrbit
    branch: OrbitBranch | None
    static_fold: float
    settings: dict = field(default_factory=dict)
    start: dict = field(default_factory=lambda: {"method": "rest"})
    approach: OrbitBranch | None = None
    collocation: CollocationOrbit | None = field(default=None, repr=False)

    def as_dict(self) -> dict:
        """JSON-ready summary: the orbit, how it was reached, M_c and, with a continuation, where the orbit ends. Moments in the parameters' units; ``moment_scale`` = E1 h^2 divides them into the paper's dimensionless moment (Fig. 2)."""
        out = {**self.orbit.as_dict(), "static_fold": _none_if_nan(self.static_fold), "start": dict(self.start)}
        out.update(self._mesh())
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
                # Period doublings and tori passed on the way (a collocation branch locates them and goes on).
                "events": [
                    {k: v for k, v in event.items() if k != "orbit"} for event in self.branch.events if event["kind"] != "branch_point"
                ],
                "phase_condition": ["section" if o.phase_normal is None else "plane" for o in self.branch.orbits],
            }
            if self.branch.settings.get("method") == "collocation":
                out["continuation"].update(
                    {
                        "end_ntst": self.branch.settings["ntst"],
                        "max_interval": self.settings.get("max_interval"),
                        "trivial_multiplier_error": _trivial_errors(self.branch).tolist(),
                    }
                )
        return out

    def _mesh(self) -> dict:
        """A collocation orbit's method, mesh (``ntst`` intervals of ``ncol`` Gauss points) and trivial multiplier's
        error, the distance to 1 of the one multiplier known exactly (the shooting's form of the orbit, :attr:`orbit`,
        carries none); empty for a shooting's orbit."""
        c = self.collocation
        if c is None:
            return {}
        return {"method": "collocation", "ntst": c.ntst, "ncol": c.ncol, "trivial_multiplier_error": c.trivial_multiplier_error}

    def continued(self, down_to: float, *, period_max: float = 2000.0, progress: ProgressCallback | None = None) -> OrbitResult:
        """This result with its orbit continued down to ``down_to`` (as :func:`periodic_orbit`'s ``down_to``).

        Raises
        ------
        ValueError
            If ``down_to`` is not between 0 and the orbit's moment.
        """
        moment = self.orbit.moment
        if not (math.isfinite(down_to) and 0 <= down_to / moment < 1):
            raise ValueError(f"down_to must lie between 0 and the moment {moment!r} (same sign, smaller), got {down_to!r}")
        branch = _continued(self.collocation or self.orbit, self.settings, abs(down_to), period_max, progress)
        settings = {**self.settings, "down_to": down_to, "period_max": period_max}
        return replace(self, branch=branch, settings=settings)

    def to_dataset(self) -> xr.Dataset:
        """Dataset with the start state (dims ``particle``), the multipliers and, with a
        continuation, the branch (dim ``point``)."""
        import xarray as xr

        o = self.orbit
        particle = np.arange(-o.params.N, o.params.N + 1)
        data = {row: (("particle",), o.x[i]) for i, row in enumerate(ROWS)}
        data.update({f"{row}_dot": (("particle",), o.v[i]) for i, row in enumerate(ROWS)})
        data["particle_turns"] = (("particle",), o.particle_turns, {"long_name": "turns of each particle's angle per period"})
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
            if b.settings.get("method") == "collocation":
                data["branch_trivial_multiplier_error"] = (("point",), _trivial_errors(b))
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
                "start_json": json.dumps(self.start),
                **self._mesh(),
            }
        )
        if "max_interval" in self.settings:
            ds.attrs["max_interval"] = self.settings["max_interval"]
        if self.branch is not None:
            if self.branch.settings.get("method") == "collocation":
                ds.attrs["end_ntst"] = self.branch.settings["ntst"]
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


@one_blas_thread
def periodic_orbit(
    params: ChainParams,
    model: str | Model,
    moment: float,
    *,
    turns: int = 1,
    particle: int = 0,
    down_to: float | None = None,
    period_max: float = 2000.0,
    guess: PeriodicOrbit | tuple | None = None,
    start: tuple[np.ndarray, np.ndarray] | None = None,
    from_above: float | None = None,
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
        The continuations report a diverging period (a homoclinic or SNIC end) beyond this.
    guess : PeriodicOrbit or tuple, optional
        Newton's start, as :func:`~cosserat_chain.numerics.periodic.find_periodic_orbit` takes it.
    start : (x (3, 2N+1), v (3, 2N+1)), optional
        The state the settling run that gives Newton's start begins from, instead of rest
        (a frame of a rotating run: below M_c a run from rest stays static).
    from_above : float, optional
        A larger moment of the same sign (above M_c, where a run from rest rotates): the orbit is
        found there, continued down to ``moment`` (:func:`~cosserat_chain.numerics.periodic.continue_orbit`)
        and solved at ``moment`` from the nearest orbit of that branch. At most one of
        ``guess``, ``start`` and ``from_above``.
    progress : callable(points, max_points), optional
        Reports the continuations' orbits.
    **options
        Passed to :func:`~cosserat_chain.numerics.periodic.find_periodic_orbit` (``tol``, ``rtol``, ``atol``, ``method``, ...);
        with ``method="collocation"`` the mesh :data:`MESH_OPTIONS`: ``ntst`` and ``ncol`` of the orbit's solve
        (:func:`~cosserat_chain.numerics.collocation.find_collocation_orbit`, whose mesh a continuation starts from) and
        ``max_interval`` of the continuations (:func:`~cosserat_chain.numerics.collocation.continue_collocation`).

    Returns
    -------
    OrbitResult

    Raises
    ------
    ValueError
        For bad input, e.g. ``down_to`` not between 0 and ``moment``, ``from_above`` not beyond it,
        more than one of ``guess``, ``start``, ``from_above``, or a mesh option without ``method="collocation"``.
    OrbitError
        If no orbit is found at ``moment``, or the branch followed down from ``from_above`` ends before it.
    """
    model = get_model(model)
    if down_to is not None and not (math.isfinite(down_to) and 0 <= down_to / moment < 1):
        raise ValueError(f"down_to must lie between 0 and the moment {moment!r} (same sign, smaller), got {down_to!r}")
    given = [name for name, value in (("guess", guess), ("start", start), ("from_above", from_above)) if value is not None]
    if len(given) > 1:
        raise ValueError(f"give at most one start of the orbit (guess, start or from_above), got {' and '.join(given)}")
    approach = None
    if from_above is not None:
        solved, approach = _from_above(params, model, moment, from_above, turns, particle, period_max, progress, options)
        how = {"method": "from_above", "from_moment": float(from_above), "approach_points": len(approach.orbits)}
        lost = approach.stability_lost_at
        how["stability_lost_at"] = None if lost is None else float(lost)
    elif start is not None:
        x, v, period = initial_guess(params, model, moment, turns=turns, particle=particle, x0=start[0], v0=start[1])
        solved = _solve(params, model, moment, turns, particle, (x, v, period), options)
        how = {"method": "state"}
    else:
        solved = _solve(params, model, moment, turns, particle, guess, options)
        how = {"method": "rest" if guess is None else "guess"}
    branch = None
    if down_to is not None:
        branch = _continued(solved, options, abs(down_to), period_max, progress)
    settings = {"turns": turns, "down_to": down_to, "period_max": period_max, "from_above": from_above, **options}
    return OrbitResult(
        orbit=_orbit_of(solved), branch=branch, static_fold=_static_fold(params, model, particle), settings=settings, start=how,
        approach=approach, collocation=solved if isinstance(solved, CollocationOrbit) else None,
    )  # fmt: skip


#: The options that set the collocation's mesh: the orbit's intervals and Gauss points, and the continuation's longest interval.
MESH_OPTIONS = ("ntst", "ncol", "max_interval")


def _solve(params, model: Model, moment: float, turns: int, particle: int, guess, options: dict) -> PeriodicOrbit | CollocationOrbit:
    """The orbit at ``moment``: by :func:`~cosserat_chain.numerics.collocation.find_collocation_orbit` where ``options``
    ask for collocation (``method``; its profile, on ``ntst`` intervals of ``ncol`` Gauss points, is where a
    continuation starts, :func:`_continued`), else by :func:`~cosserat_chain.numerics.periodic.find_periodic_orbit`
    with the options."""
    if options.get("method") != "collocation":
        mesh = [f"{k}={options[k]!r}" for k in MESH_OPTIONS if k in options]
        if mesh:
            raise ValueError(
                f"{', '.join(mesh)} set(s) the collocation's mesh: give method='collocation' (got method={options.get('method', 'auto')!r})"
            )
        return find_periodic_orbit(params, model, moment, turns=turns, particle=particle, guess=guess, **options)
    if "segments" in options:
        raise ValueError(
            f"segments applies to the dense and blocks shooting only, got method='collocation' and segments={options['segments']!r} "
            "(collocation takes its multipliers from its intervals' product already)"
        )
    keep = {k: v for k, v in options.items() if k in ("max_iter", "ntst", "ncol")}
    try:
        return find_collocation_orbit(params, model, moment, turns=turns, particle=particle, guess=guess, **keep)
    except CollocationError as err:
        raise OrbitError(str(err)) from err


def _orbit_of(solved: PeriodicOrbit | CollocationOrbit) -> PeriodicOrbit:
    """The :class:`~cosserat_chain.numerics.periodic.PeriodicOrbit` of what :func:`_solve` returned."""
    return solved.periodic_orbit() if isinstance(solved, CollocationOrbit) else solved


def _continued(orbit: PeriodicOrbit | CollocationOrbit, options: dict, moment_min: float, period_max: float, progress) -> OrbitBranch:
    """The orbit (as :func:`_solve` returned it) continued down to ``moment_min``: by collocation where ``options`` ask for it
    (``method``; ``max_interval`` bounds its intervals in time units, :func:`~cosserat_chain.numerics.collocation.continue_collocation`), else by
    :func:`~cosserat_chain.numerics.periodic.continue_orbit` with the options' tolerances and shooting (``dense``,
    ``blocks`` or ``picard``; a ``krylov`` orbit's branch by ``auto``: a continuation needs the monodromy or its dominant subspace).
    A ValueError where the orbit's own period is not below ``period_max``."""
    if not orbit.period < period_max:
        # Else the branch ends at once as a diverging period, a homoclinic or SNIC end claimed where none was followed.
        raise ValueError(
            f"period_max (--period-max) must exceed the period of the orbit the branch starts from: the orbit at "
            f"M = {orbit.moment!r} has T = {orbit.period:.6g}, got period_max = {period_max!r}; give a larger one"
        )
    method = options.get("method", "auto")
    if method == "collocation":
        mesh = {k: v for k, v in options.items() if k == "max_interval"}
        return continue_periodic_orbit(orbit, moment_min=moment_min, period_max=period_max, progress=progress, **mesh)
    keep = {k: v for k, v in options.items() if k in ("tol", "rtol", "atol")}
    shooting = method if method in ("dense", "blocks", "picard") else "auto"
    branch = continue_orbit(orbit, moment_min=moment_min, period_max=period_max, progress=progress, method=shooting, **keep)
    if branch.end == END_FOLD and choose_method(orbit.params, shooting) == "dense":
        return _fold_located(branch)
    return branch


def _fold_located(branch: OrbitBranch) -> OrbitBranch:
    """``branch`` with its fold of cycles located by the augmented shooting system from the orbits around the turn
    (:func:`~cosserat_chain.numerics.cycle_curve.locate_cycle_end`, as the diagram's rows take it): the continuation's
    ``end_moment`` is the parabola through them, 5.0e-7 off on a clamped-pinned N = 3 sine chain whose located fold
    the collocation's branch gave to 5e-11. Unchanged, saying so, where Newton fails."""
    around = sorted(branch.orbits[-3:], key=lambda o: abs(o.moment - branch.end_moment))
    try:
        fold = locate_cycle_end(around, "fold_of_cycles")
    except ValueError as err:
        return replace(
            branch, message=f"{branch.message}; the fold's moment is the parabola through the last three orbits, not located ({err})"
        )
    return replace(
        branch,
        end_moment=float(fold.moment),
        message=f"{branch.message}; located at M = {fold.moment:.12g} by the augmented shooting system",
    )


def _from_above(params, model: Model, moment: float, above: float, turns: int, particle: int, period_max: float, progress, options):
    """(the orbit at ``moment`` as :func:`_solve` returns it, the branch that led there) for :func:`periodic_orbit`'s ``from_above``."""
    if not (math.isfinite(above) and above / moment > 1):
        raise ValueError(f"from_above must be a finite moment beyond {moment!r} (same sign, larger in size), got {above!r}")
    first = _solve(params, model, above, turns, particle, None, options)
    approach = _continued(first, options, abs(moment), period_max, progress)
    if approach.end != END_MOMENT_MIN:
        raise OrbitError(
            f"the {turns}-turn orbit followed down from M = {above!r} ends at M = {approach.end_moment:.10g} "
            f"({approach.end}: {approach.message}), before the moment {moment!r}: this orbit does not reach it "
            "(try another --turns, or a guess from a run at the moment)"
        )
    # The continuation stops at its first orbit past |moment|: Newton at the moment from the nearest one.
    nearest = min(approach.orbits, key=lambda o: abs(o.moment - moment))
    return _solve(params, model, moment, turns, particle, nearest, options), approach


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


@one_blas_thread
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
