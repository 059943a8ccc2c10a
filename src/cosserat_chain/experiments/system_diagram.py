"""Both edges of the hysteresis loop of a user's system against one of its parameters (``diagram --system``).

Contract
--------
For each value of the parameter ``vary`` of a :class:`~cosserat_chain.systems.base.System`,
:func:`system_diagram` gives, in the parameter ``drive`` (the chain's moment: a bias current,
a torque):

* ``starts``: where the equilibrium Newton reaches from ``start`` folds when it is continued up
  in the drive (:func:`~cosserat_chain.numerics.equilibria.continue_equilibria`): a slowly rising
  drive starts the rotation there;
* ``stops``: where a slowly falling drive stops it. A rotation found by a settling run a tenth
  of the fold beyond it (turning as ``turns`` says) is continued down in the drive
  (:func:`~cosserat_chain.numerics.shooting.continue_orbits`) until it ends;
* ``end``: ``fold_of_cycles`` (the continuation's fold, confirmed by a second multiplier at
  +1), ``homoclinic`` (the period diverges below the fold: the orbit grows into a loop through
  the saddle past the fold), ``snic`` (the period diverges at the fold itself: a saddle-node on
  the invariant circle, no hysteresis), else the continuation's own end (``max_points``,
  ``parameter_limit``, ...: the rotation was not followed to its end); None where no edge was
  found (``message`` says why);
* ``stops_method`` and ``stops_uncertainty`` (the accuracy): ``solved`` for a homoclinic end
  solved as a boundary-value problem (projection boundary conditions): first from the loop the
  continuation's longest orbits nearly are, in turn (:func:`~cosserat_chain.numerics.homoclinic.branch_end_orbits`),
  through the saddle the orbit lingers at
  (:func:`~cosserat_chain.numerics.homoclinic.homoclinic_from_orbit`: any saddle with real
  unstable eigenvalues, on whichever static branch), else
  (:func:`~cosserat_chain.numerics.homoclinic.homoclinic_end`) in the bracket between the last orbit
  and the fit of its period's growth, the saddle followed along the static branch past the fold;
  its accuracy the one the solve reports; ``fitted`` where both fail (the fit of the period's
  growth, p = p* + c exp(-s T), is kept, ``reason`` says why it was not solved, and its
  uncertainty is the fit's own: the distance between the fits over the last half and the whole
  span of periods, or its reach beyond the last orbit where larger,
  :func:`~cosserat_chain.numerics.shooting.continue_orbits`); ``located`` for a fold of cycles (the continuation's event, located by the
  kit to its corrector's tolerance; no accuracy estimated); ``static_fold`` for a SNIC (the end
  is the equilibrium's fold, ``starts``; every orbit lies above it and the fold's centre
  manifold falls back into the shifted fold, :func:`~cosserat_chain.numerics.homoclinic.fold_turns_over`);
  ``upper_bound`` where the period passed ``period_max`` above the fold but that manifold turns
  over (near the codimension-two point: the end is a homoclinic one just below the fold, which
  bounds it; ``reason`` says so); ``last_orbit`` where the continuation stopped for
  another reason, or its period diverged with no fit and no solved loop (the last orbit's value, not an end);
* ``open``: whether the loop is open, stops below starts (None where the end is not known);
* ``warning``: where the followed orbit loses stability before its end (a falling drive then
  leaves it for a state not followed: the end reported is the unstable continuation's), and
  where a run started just below a fold of cycles from the fold's orbit keeps rotating
  (``below_edge`` ``rotating``: the fold ends one orbit, not the rotation; the chain's diagram
  follows the next orbit, here the row only says so); ``below_edge`` is ``rest`` where that run
  comes to rest (the fold is the edge of rotation).

Across the rows, ``snic_point`` is where the homoclinic end meets the static fold (between a
homoclinic row and a SNIC row next to it): solved by the augmented system
(:func:`~cosserat_chain.numerics.homoclinic.locate_snic_point`, ``method`` ``solved``, with its
``accuracy`` and the drive there), or ``not_located`` with the reason. Nothing is extrapolated.

With ``codim2``, ``codim2_between`` follows a two-parameter curve between each two neighbouring rows
(:func:`~cosserat_chain.numerics.cycle_curve.continue_cycle_end` on the system's orbit): the row's
``curve``, the located period doubling or torus where its orbit loses stability, else its located fold
of cycles, from its value to the next row's (from the second row back where the first has none), in
(``vary``, ``drive``); each entry lists the codimension-two points located on the way (1:1 ... 1:4
resonances, fold-flip, fold-torus, the cusp of a fold curve), the drive the curve reaches at the other value (``reaches``: where the other row's
own curve of the same kind lies, to Newton's tolerance) and where and why it stopped.
"""

from __future__ import annotations

import json
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np

from ..linalg.threads import one_blas_thread
from ..numerics.cycle_curve import KINDS, continue_cycle_end
from ..numerics.equilibria import EquilibriumNotFound, continue_equilibria, find_equilibrium
from ..numerics.homoclinic import (
    HomoclinicError,
    branch_end_orbits,
    fold_turns_over,
    homoclinic_end,
    homoclinic_from_orbit,
    locate_snic_point,
)
from ..numerics.kit import BranchEnd, EvaluationFailed
from ..numerics.shooting import OrbitNotFound, continue_orbits, find_orbit, flow, settled_guess, states, turns_vector
from ..systems.base import System

if TYPE_CHECKING:
    import xarray as xr

#: Where the rotation is first sought: this fraction of the fold's size beyond the fold (no equilibrium is left there).
BEYOND_FOLD = 0.1
#: Default period beyond which the period counts as diverging.
PERIOD_MAX = 100.0
#: The bracket of a homoclinic end reaches at least this far (relative) below the fit of the period's growth, and at
#: least ten times the fit's spread (the chain's diagram's rule); widened by :data:`WIDEN` where the manifold's fate
#: does not change across it, at most :data:`WIDENINGS` times.
BRACKET_RTOL = 1e-4
WIDEN = 30.0
WIDENINGS = 3
#: A diverging period whose last orbit lies at or above the fold (this close, relative) ends at the fold: a SNIC.
#: Below the fold the orbit exists where no SNIC's can, so a last orbit below it is a homoclinic end's.
SNIC_RTOL = 1e-9
#: A run just below a fold of cycles starts this far (relative) below it from the fold's orbit, lasts
#: :data:`BELOW_PERIODS` of its periods and is then watched for :data:`WINDOW_PERIODS` more.
BELOW_FOLD = 1e-2
BELOW_PERIODS = 300
WINDOW_PERIODS = 20
#: Velocities below this at the end of that run: the system came to rest.
REST_VELOCITY = 1e-4
#: How ``stops`` was found (module docstring).
METHODS = ("solved", "fitted", "located", "static_fold", "upper_bound", "last_orbit")


@dataclass
class SystemDiagramRow:
    """One value of the varied parameter (module docstring for the fields)."""

    value: float
    starts: float | None = None
    stops: float | None = None
    end: str | None = None
    method: str | None = None
    accuracy: float | None = None
    open: bool | None = None
    message: str = ""
    reason: str = ""
    warning: str = ""
    below: str | None = None
    stability_lost: float | None = None
    homoclinic: dict[str, Any] | None = None
    events: list[dict[str, Any]] = field(default_factory=list)
    #: The kind of the row's two-parameter curve (``codim2``): the located period doubling or torus where the orbit
    #: loses stability, else its located fold of cycles; None where there is none.
    curve: str | None = None
    #: The orbit there (where that curve starts), not in the output.
    curve_orbit: Any = field(default=None, repr=False)
    #: The fold's coordinates (where the SNIC point's augmented system starts), not in the output.
    fold_q: np.ndarray | None = field(default=None, repr=False)

    def as_dict(self) -> dict[str, Any]:
        return {
            "value": self.value,
            "starts": self.starts,
            "stops": self.stops,
            "end": self.end,
            "stops_method": self.method,
            "stops_uncertainty": self.accuracy,
            "open": self.open,
            "message": self.message,
            "reason": self.reason or None,
            "warning": self.warning or None,
            "below_edge": self.below,
            "stability_lost": self.stability_lost,
            "homoclinic": self.homoclinic,
            "curve": self.curve,
            "events": self.events,
        }


@dataclass
class SystemDiagram:
    """Rows of :func:`system_diagram`, one per value of ``vary``, and the SNIC point between them."""

    system: System
    vary: str
    drive: str
    turns: dict[str, int]
    rows: list[SystemDiagramRow] = field(default_factory=list)
    snic_point: dict[str, Any] | None = None
    #: The curves between the rows (module docstring), None where they were not asked for.
    codim2_between: list[dict[str, Any]] | None = None

    def as_dict(self) -> dict[str, Any]:
        """The ``diagram --system --json`` object (with the system's description)."""
        return {
            **self.system.describe(),
            "vary": self.vary,
            "drive": self.drive,
            "turns": self.turns,
            "snic_point": self.snic_point,
            "codim2_between": self.codim2_between,
            "rows": [row.as_dict() for row in self.rows],
        }

    def to_dataset(self) -> xr.Dataset:
        """Dataset over ``value``; the SNIC point and each row's messages in the attributes (as JSON)."""
        import xarray as xr

        def column(name):
            return np.array([np.nan if getattr(row, name) is None else float(getattr(row, name)) for row in self.rows])

        def text(name, missing):
            return np.array([getattr(row, name) or missing for row in self.rows], dtype=object)

        ds = xr.Dataset(
            {
                "starts": ("value", column("starts"), {"long_name": f"{self.drive} where the equilibrium folds (rotation starts, rising {self.drive})"}),
                "stops": ("value", column("stops"), {"long_name": f"{self.drive} where the rotation ends (falling {self.drive}; NaN: not found)"}),
                "stops_uncertainty": ("value", column("accuracy"), {"long_name": "accuracy of stops: a solved end's, or a fitted one's own uncertainty (stops_method fitted; NaN: not estimated)"}),
                "stops_method": ("value", text("method", "none"), {"long_name": "how stops was found: " + ", ".join(METHODS) + " or none"}),
                "open": ("value", np.array([bool(row.open) for row in self.rows]), {"long_name": "1 if the hysteresis loop is open (the rotation stops below where it starts), 0 if not or unknown"}),
                "end": ("value", text("end", "failed"), {"long_name": "how the continued rotation ended"}),
                "below_edge": ("value", text("below", "not_checked"), {"long_name": "a run just below a fold of cycles: rest, rotating, not_converged or not_checked"}),
            },
            coords={"value": ("value", np.array([row.value for row in self.rows]), {"long_name": f"the varied parameter {self.vary}"})},
        )  # fmt: skip
        ds.attrs.update(
            {
                "experiment": "system_diagram",
                "title": f"Hysteresis loop of the system {self.system.name}",
                "varied": self.vary,
                "drive": self.drive,
                "snic_point_json": json.dumps(self.snic_point),
                "codim2_between_json": json.dumps(self.codim2_between),
                "rows_json": json.dumps([{k: v for k, v in row.as_dict().items() if k != "events"} for row in self.rows], default=float),
            }
        )
        return ds


@one_blas_thread
def system_diagram(
    system: System,
    vary: str,
    values: Sequence[float],
    drive: str,
    *,
    turns: dict[str, int] | None = None,
    start: np.ndarray | None = None,
    period_max: float = PERIOD_MAX,
    codim2: bool = False,
    progress: Callable[[int, int], None] | None = None,
) -> SystemDiagram:
    """Both edges of the hysteresis loop in ``drive`` at each of ``values`` of ``vary`` (module docstring).

    Parameters
    ----------
    system : System
    vary, drive : str
        Two different parameters of the system.
    values : sequence of float
    turns : mapping coordinate -> int, optional
        The rotation followed: turns of each angle per period (default every angle once, in phase).
    start : ndarray (n,), optional
        Where Newton starts for the equilibrium (default q = 0).
    period_max : float
        A period beyond this counts as diverging (a homoclinic or SNIC end).
    codim2 : bool
        Follow each row's curve to the next value and list the codimension-two points on the way
        (:attr:`SystemDiagram.codim2_between`, module docstring).
    progress : callable(done, total), optional

    Raises
    ------
    ValueError
        For bad input, naming it (a parameter the system lacks, equal ``vary`` and ``drive``,
        a value that is not finite, turns of a coordinate that is not an angle).
    """
    system.parameter(vary)
    system.parameter(drive)
    if drive == vary:
        raise ValueError(f"drive and vary must be different parameters, got {drive!r} for both")
    values = [float(v) for v in values]
    if not values or not all(math.isfinite(v) for v in values):
        raise ValueError(f"values must be finite numbers, at least one, got {values!r}")
    if not (isinstance(period_max, int | float) and math.isfinite(period_max) and period_max > 0):
        raise ValueError(f"period_max must be a finite number > 0, got {period_max!r}")
    if not isinstance(codim2, bool):
        raise ValueError(f"codim2 must be True or False, got {codim2!r}")
    if turns is None:
        turns = {name: 1 for name, angle in zip(system.coordinates, system.angles, strict=True) if angle}
    k = turns_vector(system, turns)
    if not np.any(k):
        raise ValueError(f"turns must turn at least one angle of {system.name}, got {turns!r}")
    q0 = np.zeros(system.size) if start is None else system.check_state(np.asarray(start, dtype=float), "start")
    diagram = SystemDiagram(system, vary, drive, {name: int(n) for name, n in turns.items()})
    for i, value in enumerate(values):
        if progress is not None:
            progress(i, len(values))
        diagram.rows.append(_row(system.with_parameters(**{vary: value}), vary, value, drive, k, q0, period_max))
    diagram.snic_point = _snic_point(diagram, k)
    if codim2:
        diagram.codim2_between = _codim2_between(diagram)
    if progress is not None:
        progress(len(values), len(values))
    return diagram


def _row(system: System, vary: str, value: float, drive: str, k: np.ndarray, q0: np.ndarray, period_max: float) -> SystemDiagramRow:
    """One value's row: the equilibrium's first fold in ``drive`` and the end of the rotation followed down from beyond it."""
    row = SystemDiagramRow(value)
    try:
        statics = continue_equilibria(find_equilibrium(system, q0), drive, direction=1.0)
    except EquilibriumNotFound as err:
        row.message = str(err)
        return row
    folds = [e for e in statics.events if e.kind == "fold" and e.located]
    if not folds:
        row.message = f"the equilibrium has no fold in {drive}: {statics.message}"
        return row
    onset = float(folds[0].parameter)
    row.starts, row.fold_q = onset, np.array(folds[0].point.q, dtype=float)
    beyond = system.with_parameters(**{drive: onset + BEYOND_FOLD * max(abs(onset), 1e-3)})
    forces, damping = beyond.forces(q0), beyond.damping()
    # The terminal spin of a driven pendulum, drive over damping: a start that turns.
    drift = np.where(beyond.angles & (damping > 0), forces / np.where(damping > 0, damping, 1.0), 0.0)
    first = int(np.flatnonzero(k)[0])
    try:
        guess = settled_guess(beyond, np.concatenate([q0, drift]), coordinate=first, turns=abs(int(k[first])))
        branch = continue_orbits(find_orbit(beyond, guess, turns=k), drive, direction=-1.0, period_max=period_max)
    except (OrbitNotFound, EvaluationFailed, ValueError) as err:
        row.message = f"no rotation followed from {drive} = {beyond.parameter(drive):.6g}: {err}"
        return row
    row.events = branch.as_dict()["events"]
    row.message = branch.message
    _stability_warning(row, branch, drive)
    last = float(branch.values[-1])
    if branch.end == BranchEnd.FOLD:
        fold = next((e for e in reversed(branch.events) if e.kind == "fold" and e.located), None)
        row.stops = last if fold is None else float(fold.parameter)
        row.end, row.method = "fold_of_cycles", "located"
        if fold is not None:
            _below_fold(row, fold.point, drive, first)
            if row.curve is None:
                row.curve, row.curve_orbit = "fold_of_cycles", fold.point
    elif branch.end == BranchEnd.INFINITE_PERIOD or branch.end_value is not None:
        if last >= onset - SNIC_RTOL * max(1.0, abs(onset)):
            # The continuation's note fits a homoclinic end's growth, which a SNIC's is not.
            row.message = row.message.split("; the period grows like a homoclinic")[0]
            _snic_or_near(row, system, vary, drive, k, onset, period_max)
        else:
            row.end = "homoclinic"
            _homoclinic(row, system, drive, k, first, branch, last)
    else:
        row.stops, row.end, row.method = last, str(branch.end), "last_orbit"
    if row.method == "upper_bound":
        row.open = None
    elif row.end in ("fold_of_cycles", "homoclinic", "snic"):
        row.open = bool(row.stops < onset - 1e-9 * max(1.0, abs(onset)))
    return row


def _snic_or_near(row: SystemDiagramRow, system: System, vary: str, drive: str, k: np.ndarray, onset: float, period_max: float) -> None:
    """Every orbit lies above the fold: a SNIC where the fold's centre manifold falls back into the shifted fold; where
    it turns over instead, a rotation exists at the fold and ends below it (near the codimension-two point the period
    passes period_max above the fold on the way): the end is then only bounded by the fold, and the row says so."""
    turns = {system.coordinates[i]: int(n) for i, n in enumerate(k) if n}
    try:
        over = fold_turns_over(system.with_parameters(**{drive: onset}), row.fold_q, turns=turns, name=vary, moment=drive)
    except (HomoclinicError, EvaluationFailed) as err:
        row.stops, row.end, row.method = onset, "snic", "static_fold"
        row.message += (
            f"; every orbit lies above the fold at {drive} = {onset:.12g}: the period diverges there (a SNIC; not confirmed: {err})"
        )
        return
    if not over:
        row.stops, row.end, row.method = onset, "snic", "static_fold"
        row.message += (
            f"; every orbit lies above the fold at {drive} = {onset:.12g} and the fold's centre manifold falls back into the "
            "shifted fold: the period diverges at the fold itself (a SNIC)"
        )
        return
    row.stops, row.end, row.method = onset, "homoclinic", "upper_bound"
    row.reason = (
        f"the period passed period_max = {period_max:g} above the fold, but the fold's centre manifold turns over: a rotation "
        f"exists at the fold, so it ends at a homoclinic loop below {drive} = {onset:.12g} (near the point where the homoclinic "
        "end becomes a SNIC); raise period_max to follow it there"
    )
    row.message += "; " + row.reason


def _stability_warning(row: SystemDiagramRow, branch, drive: str) -> None:
    """Warn where the followed orbit is (or becomes) unstable before its end: a falling drive leaves it there."""
    stable = [o.stable for o in branch.orbits]
    if all(stable):
        return
    index = stable.index(False)
    kinds = sorted({e.kind for e in branch.events if e.kind in ("period_doubling", "torus", "fold", "branch_point")})
    values = branch.values
    # The located change of stability between the last stable orbit and the first unstable one (else that orbit's value).
    span = sorted(values[max(index - 1, 0) : index + 1])
    lost = next((e.parameter for e in branch.events if e.kind == "stability" and e.located and span[0] <= e.parameter <= span[-1]), None)
    row.stability_lost = float(values[index] if index == 0 or lost is None else lost)
    if index > 0:
        loss = next(
            (e for e in branch.events if e.kind in ("period_doubling", "torus") and e.located and span[0] <= e.parameter <= span[-1]), None
        )
        if loss is not None:
            row.curve, row.curve_orbit = loss.kind, loss.point
    where = "is unstable where it was found" if index == 0 else f"loses stability at {drive} = {row.stability_lost:.10g}"
    how = f" ({', '.join(kinds)} on the way)" if kinds else ""
    row.warning = (
        f"the followed orbit {where}{how}: a slowly falling {drive} leaves it there for a state not followed here, so the "
        "end reported is that of the orbit continued through its unstable part"
    )


def _homoclinic(row: SystemDiagramRow, system: System, drive: str, k: np.ndarray, winding: int, branch, last: float) -> None:
    """Solve the homoclinic end: from the loop the longest orbits nearly are (in turn), else in the bracket between the fit
    and the last orbit with the static branch's saddle past the fold; keep the fit, saying why and with its own uncertainty, where
    both fail (the last orbit's value, where there is no fit)."""
    spread = branch.end_uncertainty if branch.end_uncertainty is not None and math.isfinite(branch.end_uncertainty) else 0.0
    # A fit is reported only with its own uncertainty; without one the end is bounded by the last orbit alone.
    fitted = branch.end_value is not None and spread > 0
    fit = float(branch.end_value) if branch.end_value is not None else last
    reach = max(10.0 * spread, BRACKET_RTOL * max(abs(fit), 1e-3), 2.0 * abs(last - fit))
    turns = {system.coordinates[i]: int(n) for i, n in enumerate(k) if n}
    errors: list[str] = []
    orbit = None
    for candidate in branch_end_orbits(branch):
        try:
            # Through the saddle the orbit lingers at, which need not be the static branch's past the fold (an unequal
            # pendulum pair's in-phase rotation ends at the saddle with both pendula up).
            orbit = homoclinic_from_orbit(candidate, turns=turns, parameter=drive, value=fit)
            break
        except HomoclinicError as err:
            errors.append(f"from the orbit of period {candidate.period:.6g}: {err}")
    if orbit is None:
        error: Exception | None = None
        try:
            saddle = _saddle(system, drive, row.fold_q, float(row.starts), last, winding)
            for _ in range(WIDENINGS + 1):
                try:
                    orbit = homoclinic_end(
                        system.with_parameters(**{drive: last}), saddle, turns=turns, bracket=(fit - reach, last), parameter=drive
                    )
                    break
                except HomoclinicError as err:
                    error = err
                    reach *= WIDEN
        except (HomoclinicError, EquilibriumNotFound, EvaluationFailed, ValueError) as err:
            error = err
        if orbit is None:
            errors.append(f"in a bracket from the static branch's saddle past the fold: {error}")
    quoted = f"the fit of the period's growth gave {fit:.10g} +- {spread:.2g}"
    if orbit is None:
        row.reason = "the boundary-value problem was not solved: " + "; ".join(errors)
        if fitted:
            row.stops, row.method, row.accuracy = fit, "fitted", spread
            row.message += (
                f"; homoclinic end fitted from the period's growth, not solved ({'; '.join(errors)}): {drive} = {fit:.10g} "
                f"+- {spread:.2g}, fitted (the fit's own uncertainty)"
            )
        else:
            row.stops, row.method, row.accuracy = last, "last_orbit", None
            row.message += (
                f"; homoclinic end not solved ({'; '.join(errors)}) and its fit has no uncertainty: the last orbit's {drive} bounds it"
            )
        return
    row.stops, row.method, row.accuracy = float(orbit.value), "solved", float(orbit.accuracy)
    row.homoclinic = orbit.as_dict()
    off = abs(fit - orbit.value)
    row.message = (
        f"the orbit ends at a loop homoclinic to the saddle at {drive} = {orbit.value:.13g} +- {orbit.accuracy:.1g}, solved by "
        f"projection boundary conditions ({quoted}{', off by ' + format(off, '.2g') if off > spread else ''})"
    )


def _saddle(system: System, drive: str, fold_q: np.ndarray, onset: float, target: float, winding: int) -> np.ndarray:
    """The equilibrium past the fold at ``drive`` = ``target``: the static branch followed from the fold, its
    coordinate along the fold's null vector (oriented so the winding angle grows) prescribed, down to ``target``."""
    at_fold = system.with_parameters(**{drive: onset})
    _, _, vt = np.linalg.svd(at_fold.force_jacobian(fold_q).toarray())
    v = vt[-1] if vt[-1][winding] >= 0 else -vt[-1]
    q, p, s, ds = fold_q.copy(), onset, 0.0, 0.02
    while s < 2 * math.pi:
        solved = _on_branch(system, drive, fold_q, v, s + ds, q + ds * v, p)
        if solved is None:
            ds *= 0.5
            if ds < 1e-6:
                break
            continue
        q_new, p_new = solved
        if p_new <= target:
            w = (p - target) / (p - p_new)
            return find_equilibrium(system.with_parameters(**{drive: target}), q + w * (q_new - q), tol=1e-13, descent=False).q
        q, p, s, ds = q_new, p_new, s + ds, min(1.5 * ds, 0.2)
    raise HomoclinicError(
        f"the static branch past the fold at {drive} = {onset:.10g} does not fall back to {drive} = {target:.10g}: no saddle found there"
    )


def _on_branch(system: System, drive: str, fold_q: np.ndarray, v: np.ndarray, s: float, q: np.ndarray, p: float):
    """Newton on F(q; p) = 0, v . (q - q_fold) = s in (q, p); None where it does not converge."""
    n = q.size
    for _ in range(30):
        at = system.with_parameters(**{drive: p})
        residual = np.append(at.forces(q), v @ (q - fold_q) - s)
        if np.max(np.abs(residual)) < 1e-12:
            return q, p
        big = np.zeros((n + 1, n + 1))
        big[:n, :n] = at.force_jacobian(q).toarray()
        big[:n, n] = at.parameter_forces(q, drive)
        big[n, :n] = v
        try:
            step = np.linalg.solve(big, -residual)
        except np.linalg.LinAlgError:
            return None
        q, p = q + step[:n], p + step[n]
        if not np.all(np.isfinite(q)) or abs(step[n]) > 1e3:
            return None
    return None


def _below_fold(row: SystemDiagramRow, orbit, drive: str, winding: int) -> None:
    """A run from the fold's orbit just below the fold: does the system rest there (the fold is the edge of rotation),
    or keep rotating (on an orbit not followed: warn)?"""
    below = orbit.system.with_parameters(**{drive: row.stops - BELOW_FOLD * max(abs(row.stops), 1e-3)})
    try:
        y = flow(below, orbit.y0, BELOW_PERIODS * orbit.period, variations=False)[0]
        window = states(below, y, np.linspace(0.0, WINDOW_PERIODS * orbit.period, 401), rtol=1e-10, atol=1e-10)
    except EvaluationFailed as err:
        row.below = "not_converged"
        row.message += f"; a run below the fold of cycles failed ({err})"
        return
    n = below.size
    gain = abs(window[-1, winding] - window[0, winding])
    where = f"{drive} = {below.parameter(drive):.10g}"
    if gain >= 2 * math.pi:
        row.below = "rotating"
        warning = (
            f"below the fold of cycles a run from its orbit at {where} keeps rotating (mean rate "
            f"{gain / (WINDOW_PERIODS * orbit.period):.6g}): the fold ends one orbit, not the rotation, which goes on on a "
            "coexisting orbit not followed here (hysteresis may continue below)"
        )
        row.warning = f"{row.warning}; {warning}" if row.warning else warning
    elif np.max(np.abs(window[:, n:])) < REST_VELOCITY:
        row.below = "rest"
        row.message += f"; a run from the fold's orbit at {where} comes to rest: the fold is the edge of rotation"
    else:
        row.below = "not_converged"
        row.message += f"; a run from the fold's orbit at {where} has neither settled nor kept turning"


def _codim2_between(diagram: SystemDiagram) -> list[dict[str, Any]]:
    """Each two neighbouring rows' entry: the first row's curve (else the second's) followed to the other value (module docstring)."""
    vary, drive, out = diagram.vary, diagram.drive, []
    for before, after in zip(diagram.rows, diagram.rows[1:]):
        entry: dict[str, Any] = {
            "between": [before.value, after.value], "curves": [before.curve, after.curve], "followed": None, "from": None,
            "complete": None, "points": [], "reaches": None, "message": "",
        }  # fmt: skip
        start, target = (before, after) if before.curve in KINDS else (after, before)
        if start.curve not in KINDS:
            entry["message"] = f"not followed: neither row's orbit has a located period doubling, torus or fold of cycles in {drive}"
            out.append(entry)
            continue
        entry["followed"], entry["from"] = start.curve, start.value
        try:
            curve = continue_cycle_end(start.curve_orbit, start.curve, vary, [start.value, target.value], parameter=drive)
        except (ValueError, EvaluationFailed) as err:
            entry["message"] = f"the {start.curve} was not followed from {vary} = {start.value:g} ({err})"
            out.append(entry)
            continue
        entry["complete"] = curve.complete
        entry["points"] = [
            {"name": p.name, "kind": p.kind, "label": p.label, "value": p.value, "accuracy": p.uncertainty,
             "drive": p.moment, "period": p.period, "angle": p.angle}
            for p in curve.points
        ]  # fmt: skip
        if curve.complete:
            entry["reaches"] = float(curve.moment[-1])
            entry["message"] = (
                f"the {start.curve} curve followed from {vary} = {start.value:g} reaches {target.value:g} at {drive} = {curve.moment[-1]:.10g}"
            )
        else:
            entry["message"] = curve.message
        out.append(entry)
    return out


def _snic_point(diagram: SystemDiagram, k: np.ndarray) -> dict[str, Any] | None:
    """The codimension-two point between the first homoclinic row and the SNIC row next to it (module docstring)."""
    rows = diagram.rows
    pair = next(((a, b) for a, b in zip(rows, rows[1:]) if {a.end, b.end} == {"homoclinic", "snic"}), None)
    if pair is None:
        return None
    between = [pair[0].value, pair[1].value]
    snic = pair[0] if pair[0].end == "snic" else pair[1]
    turns = {diagram.system.coordinates[i]: int(n) for i, n in enumerate(k) if n}
    system = diagram.system.with_parameters(**{diagram.vary: snic.value, diagram.drive: snic.starts})
    try:
        point = locate_snic_point(system, snic.fold_q, name=diagram.vary, bracket=tuple(between), turns=turns, moment=diagram.drive)
    except (HomoclinicError, EvaluationFailed, ValueError) as err:
        return {"value": None, "accuracy": None, "drive": None, "between": between, "method": "not_located", "reason": str(err)}
    return {
        "value": float(point.value),
        "accuracy": float(point.accuracy),
        "drive": float(point.moment),
        "between": between,
        "method": "solved",
        "solver": "augmented_system",
    }
