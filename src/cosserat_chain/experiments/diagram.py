"""The map of static and rotating states against one parameter: both edges of the hysteresis loop.

Contract
--------
For each value of one field of the chain, :func:`state_diagram` gives

* ``static_fold``: M_c, where the static branch from rest ends (the upper edge of the
  loop: a slowly rising load makes the particle rotate above it), followed through the
  values by continuation of the fold itself (:func:`~cosserat_chain.numerics.fold_curve.continue_fold`),
  or the branch point where the stable branch ends before its fold (a cantilever under the
  nonlinear model; ``message`` says so): every row's M_c is ``critical``'s, the followed fold where it is that,
  else ``critical``'s with ``message`` saying why (a branch point or a cusp's pair of folds before the followed
  fold, or a snap past it onto a branch the chain rests on);
* ``rotation_stops``: where a slowly falling load stops the rotation (the lower edge):
  the rotating state, found as a periodic orbit just above M_c and continued down in M
  (:func:`~cosserat_chain.numerics.periodic.continue_orbit`), ceases to be stable or
  ceases to exist there;
* ``end``: how it stops, from the orbit's Floquet multipliers and the continuation's end:
  ``fold_of_cycles`` (a real multiplier through +1 and M turning back: the stable orbit
  meets an unstable one), ``branch_point_of_cycles`` (a real multiplier through +1 while M
  goes on falling: another branch of orbits crosses this one, as where the chain's mirror
  symmetry breaks), ``period_doubling`` (a real multiplier through -1), ``torus``
  (a complex pair through the unit circle), ``homoclinic`` (the period grows without
  bound below M_c) or ``snic`` (the period grows without bound at M_c itself: a
  saddle-node on the invariant circle, no hysteresis), ``not_found`` when no rotating
  orbit was found or the continuation failed (``message`` says why);
* ``rotation_starts``: how a slowly rising load starts the rotation at M_c: ``snic`` (the
  orbit is born on the static fold with an infinitely long period), ``jump`` (onto a rotating
  state that exists there already: the loop is open), None where the lower edge is unknown;
* ``method``: how ``rotation_stops`` was found: ``located`` (a fold of cycles, period
  doubling or torus first bracketed by the one-parameter continuation, then solved exactly
  at that value: a fold by Newton on the augmented shooting system of
  :mod:`~cosserat_chain.numerics.cycle_curve`, a period doubling or torus by the one
  mechanism of :mod:`~cosserat_chain.numerics.cycle_events`), ``followed`` (with
  ``follow``: the same system continued from the value before, the curve of the lower edge
  in (M, p)), ``solved`` (a homoclinic end: the loop from the saddle back to it shifted by
  2 pi, a boundary-value problem with projection boundary conditions,
  :func:`~cosserat_chain.numerics.homoclinic.chain_homoclinic_end`), ``fitted`` (a homoclinic
  end the boundary-value problem did not solve: the fit of the period's growth, ``message`` says
  why), ``one_parameter`` (read from the continuation alone: SNIC ends, or where the end could
  not be located, ``message`` says);
* ``rotation_stops_uncertainty``: for a solved homoclinic end its accuracy (the change over the
  last step of the boundary conditions' distance to the saddle); for one left fitted to the
  period's growth (T ~ -log(M - M_h)), three times the difference between the fit to the last
  orbits and the fit to the last four alone (:data:`FIT_SAFETY`; ``rotation_stops`` carries
  only the digits it leaves); None for every other end, a computed point (located, followed, a SNIC at M_c);
* ``hysteresis``: whether the loop is open, rotation_stops < M_c: between the two edges the
  particle can rest or rotate; None (unknown) where the followed orbit loses stability above
  M_c (no static state exists there: the rotation goes on in a state not followed);
* ``moment_scale``: E1 h^2 of that row's chain, and both edges divided by it
  (``..._dimensionless``), the paper's dimensionless moment of Fig. 2 (the varied field
  may be E1 or h, so the unit is per row).

Across the rows, ``snic_point`` is where the homoclinic end meets the static fold and becomes a
SNIC (between a homoclinic row and a SNIC row next to it): solved by the augmented system
(:func:`~cosserat_chain.numerics.homoclinic.chain_snic_point`, ``method`` ``solved`` with its
``accuracy``); where that fails, extrapolated from two homoclinic rows (``method``
``extrapolated``, no accuracy, ``reason`` the solve's error).

With ``codim2``, ``codim2_between`` says what lies between each two neighbouring rows whose ends differ (a torus
end at one value, a period doubling at the next): the first row's end (else the second's) followed towards the other
row's value by :func:`~cosserat_chain.numerics.cycle_curve.continue_cycle_end`, with the codimension-two points it
located on the way (named, each value with its accuracy) and where and why the curve stopped; a homoclinic, SNIC or
branch-point end is not followed, and the entry says so.

A diverging period is told apart by its growth over the last orbits before ``period_max``:
like (M - M_c)^(-1/2) at a SNIC (T^-2 extrapolated to zero lands on M_c), like -log(M - M_h)
at a homoclinic end (M_h from the best fit). Limits: one rotating orbit is followed, the
first stable one with 1, 2, ... ``turns`` turns a period just above M_c (``not_found`` if
none is: the rotation there may be irregular, as the nonlinear chain's at the default
damping). Below a fold of cycles (below M_c) a run from the fold's orbit tells whether the
chain rests there (``below_edge`` ``rest``: the fold is the edge of rotation) or keeps rotating;
then the stable orbit it settles on is followed down in its turn (:data:`MAX_ORBITS` orbits in
all, ``followed_orbits``), or the row warns (``warning``) that the fold ends one orbit, not the
rotation. Other coexisting orbits and irregular rotation are not searched here
(:func:`~cosserat_chain.experiments.coexisting.states_at` lists them at one moment: the sine
chain at M = 0.22 has a stable 2-turn orbit beside the 1-turn one a run from rest reaches).
"""

from __future__ import annotations

import json
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np

from ..linalg.threads import one_blas_thread
from ..memory import require
from ..models.base import get_model
from ..numerics.cycle_curve import KINDS, continue_cycle_end, locate_circle_event, locate_cycle_end, torus_angle
from ..numerics.cycle_events import CIRCLE_KINDS
from ..numerics.dynamics import IntegrationError
from ..numerics.fold_curve import continue_fold
from ..numerics.homoclinic import HomoclinicError, chain_homoclinic_end, chain_snic_point
from ..numerics.periodic import OrbitError, PeriodicOrbit, continue_orbit, find_periodic_orbit, initial_guess
from ..numerics.relaxation import relax
from ..params import ChainParams
from ..state import column
from .critical import critical_memory, critical_point

if TYPE_CHECKING:
    import xarray as xr

#: How the rotation can stop going down (module docstring).
ENDS = ("fold_of_cycles", "branch_point_of_cycles", "period_doubling", "torus", "homoclinic", "snic", "not_found")
#: The rotating orbit is first sought at this multiple of M_c, above the static fold.
START_FACTOR = 1.1
#: A diverging period whose end extrapolates this close to M_c (relative) ends at the static
#: fold: a SNIC (measured: 2e-5 for the paper's sine chain with gamma_phi = 0.5).
SNIC_RTOL = 1e-3
#: Orbits near a diverging period that the end's extrapolations use.
TAIL = 6
#: Fewest orbits a diverging period is read from (the quadratic fit of T^-2 needs more than three).
MIN_TAIL = 4
#: Orbits of a continuation that crept to a halt that tell a homoclinic approach (:func:`_approach`).
APPROACH_POINTS = 12
#: A homoclinic M_h fitted further below the last orbit's M than this (relative) is an
#: extrapolation too far to report (the weakly damped pendulum's: 1.2e-4 at gamma_phi = 0.01).
APPROACH_RTOL = 1e-3
#: Least relative step in T between the orbits :func:`_approach` takes (the last ones of a crawl are thinned out).
APPROACH_SPACING = 1e-3
#: Default period beyond which the period counts as diverging (each orbit near it costs an
#: integration of that length with its monodromy: benchmarks/TIMINGS.md).
PERIOD_MAX = 100.0
#: A fitted homoclinic end's uncertainty is this times the difference between the fits to the last TAIL (or
#: APPROACH_POINTS) orbits and to the last MIN_TAIL: the pendulum's true error (an independent bisection on the
#: saddle's unstable manifold) was 2.1 times that difference at gamma_phi = 0.02, 1.2 times at 0.05. It is a
#: heuristic: where the continuation crawls to a halt far from the divergence (the N = 1 chain at gamma_phi = 0.02
#: since its Jacobian is exact) the fit is off by 12 times it; the end is then solved (:func:`_solved`).
FIT_SAFETY = 3.0
#: A fitted homoclinic end's bracket for the solve reaches at least this far (relative) below the fit.
BRACKET_RTOL = 1e-4
#: How close (relative to max(|M|, 1)) ``critical``'s M_c must lie to the fold curve's fold for the row to keep the
#: followed fold: both are Newton-solved folds, equal to round-off when they are the same fold.
FOLD_MATCH = 1e-8
#: A fold of cycles is checked by a run this far (relative) below it: close enough to stay near the fold's orbit,
#: far enough that its ghost does not hold the run for long (the N = 2 sine chain at gamma_phi = 0.2: 116 turns near
#: its fold's rate at 1e-3 below, 4 turns at 1e-2).
BELOW_FOLD = 1e-2
#: The run below a fold lasts at most this many of the fold orbit's periods (the light N = 2 chain settles on its
#: next orbit within 100, the paper's N = 2 chain at gamma_phi = 0.15 rests within 60); longer, it is ``not_converged``.
BELOW_PERIODS = 500
#: Orbits a row follows in turn where the rotation goes on below a fold of cycles.
MAX_ORBITS = 3
#: An imaginary part of the leading multiplier above this (relative to its modulus) is a complex pair.
COMPLEX_RTOL = 1e-6
#: Settings of the continuation that brackets a row's end (:func:`_edge_from`): the integration's tolerances, the
#: orbits' closure and the first arclength step. Where the end is then located (:func:`_located`), it is solved at the
#: package's full tolerances from the orbits around it, so the edge is the same to the solve's accuracy
#: (benchmarks/TIMINGS.md); the multipliers, accurate to about 1e-7, still tell where stability is lost.
SCOUT = {"rtol": 1e-8, "atol": 1e-8, "tol": 1e-6, "step": 0.2}


@dataclass
class DiagramRow:
    """One value of the varied field (module docstring for the fields)."""

    value: float
    static_fold: float | None
    phi0_at_fold: float | None
    rotation_stops: float | None
    end: str
    hysteresis: bool | None
    message: str = ""
    moment_scale: float = 1.0
    method: str = "one_parameter"
    uncertainty: float | None = None
    below: str | None = None
    followed: list[dict[str, Any]] = field(default_factory=list)
    warning: str = ""

    @property
    def rotation_continues_below(self) -> bool | None:
        """Whether a run just below a fold-of-cycles edge keeps rotating (the edge is then not the end of rotation);
        None where it was not checked (other ends) or did not settle."""
        return {"rest": False, "rotating": True}.get(self.below)

    @property
    def rotation_starts(self) -> str | None:
        """How a slowly rising load starts the rotation at M_c: ``snic`` (with an infinitely long period,
        the orbit born on the static fold), ``jump`` (onto a rotating state that already exists there: the
        loop is open), None where the lower edge is not known."""
        if self.end == "snic":
            return "snic"
        return "jump" if self.hysteresis else None

    def dimensionless(self, moment: float | None) -> float | None:
        """``moment`` in units of this row's E1 h^2 (the paper's dimensionless moment; E1 or h may be the varied field)."""
        return None if moment is None else moment / self.moment_scale

    def as_dict(self) -> dict[str, Any]:
        return {
            "value": self.value,
            "static_fold": self.static_fold,
            "phi0_at_fold": self.phi0_at_fold,
            "rotation_stops": self.rotation_stops,
            "end": self.end,
            "hysteresis": self.hysteresis,
            "rotation_starts": self.rotation_starts,
            "message": self.message,
            "moment_scale": self.moment_scale,
            "method": self.method,
            "rotation_stops_uncertainty": self.uncertainty,
            "below_edge": self.below,
            "rotation_continues_below": self.rotation_continues_below,
            "followed_orbits": self.followed,
            "warning": self.warning or None,
            "static_fold_dimensionless": self.dimensionless(self.static_fold),
            "rotation_stops_dimensionless": self.dimensionless(self.rotation_stops),
        }


@dataclass
class StateDiagram:
    """Rows of :func:`state_diagram`, one per value of ``field``."""

    params: ChainParams
    model: str
    field: str
    turns: int
    rows: list[DiagramRow] = field(default_factory=list)
    independent: bool = False
    #: The SNIC point solved by :func:`state_diagram` (:attr:`snic_point`'s form), None where it was not.
    solved_snic: dict[str, Any] | None = None
    #: Why it was not solved, where rows with a homoclinic end next to a SNIC have one.
    snic_failure: str = ""
    #: What lies between each two neighbouring rows with different ends (:func:`_codim2_between`'s entries),
    #: None where it was not asked for (``codim2`` of :func:`state_diagram`).
    codim2_between: list[dict[str, Any]] | None = None

    @property
    def snic_point(self) -> dict[str, Any] | None:
        """Where the homoclinic end meets the static fold and becomes a SNIC, between two rows (None without such rows).

        Solved where :func:`state_diagram` could (:attr:`solved_snic`): ``{"value": p*, "accuracy": ...,
        "moment": M_c there, "between": [p_h, p_snic], "method": "solved", "solver": "augmented_system"}``,
        the codimension-two point by :func:`~cosserat_chain.numerics.homoclinic.chain_snic_point` between the
        first homoclinic row and the SNIC row next to it. Otherwise (``reason`` says why: the solve's error,
        or rows made without it) the fallback of :meth:`extrapolated_snic_point`, ``method`` ``extrapolated``
        with no accuracy, or ``not_located`` (``value`` None) where it cannot be extrapolated either.
        """
        if self.solved_snic is not None:
            return dict(self.solved_snic)
        pair = _snic_pair(self.rows)
        if pair is None:
            return None
        reason = self.snic_failure or "not solved: the rows were not computed by state_diagram"
        point = self.extrapolated_snic_point()
        if point is None:
            between = [pair[0].value, pair[1].value]
            return {"value": None, "accuracy": None, "between": between, "method": "not_located", "reason": reason}
        return {**point, "accuracy": None, "reason": reason}

    def extrapolated_snic_point(self) -> dict[str, Any] | None:
        """The SNIC point extrapolated from two homoclinic rows before a SNIC row (the fallback of :attr:`snic_point`).

        Near that point (a saddle-node homoclinic orbit, codimension two) the gap closes
        quadratically, (M_c - M_h) / M_c ~ (p* - p)^2, so sqrt of the gap is linear in the
        parameter p: the last two homoclinic rows before a SNIC row (in the order given)
        extrapolate it to zero at p*. Returns ``{"value": p*, "between": [p_h, p_snic],
        "from": [p_h1, p_h2], "method": "extrapolated"}``, or None without such rows or when p* falls
        outside (p_h, p_snic] (the rows are then too far from the point to locate it). The
        one-particle pendulum gives alpha* = 1.1939 against the solved 1.19305 (alpha = gamma_phi / sqrt(j M_c); tested).
        """
        for i in range(2, len(self.rows)):
            first, second, snic = self.rows[i - 2], self.rows[i - 1], self.rows[i]
            if not (first.end == second.end == "homoclinic" and snic.end == "snic"):
                continue
            gaps = [math.sqrt(max(0.0, 1.0 - row.rotation_stops / row.static_fold)) for row in (first, second)]
            if gaps[0] == gaps[1]:
                return None
            # The line through the two (value, sqrt(gap)) points, where it reaches zero.
            root = second.value - gaps[1] * (second.value - first.value) / (gaps[1] - gaps[0])
            lo, hi = sorted((second.value, snic.value))
            if not (lo < root <= hi):
                return None
            return {
                "value": float(root),
                "between": [second.value, snic.value],
                "from": [first.value, second.value],
                "method": "extrapolated",
            }
        return None

    def as_dict(self) -> dict[str, Any]:
        """The ``diagram --json`` object."""
        return {
            "model": self.model,
            "parameter": self.field,
            "turns": self.turns,
            "snic_point": self.snic_point,
            "static_fold_independent_of_parameter": self.independent,
            "rows": [row.as_dict() for row in self.rows],
            "codim2_between": self.codim2_between,
        }

    def to_dataset(self) -> xr.Dataset:
        """Dataset over ``value`` with the parameters and the model in the attributes."""
        import xarray as xr

        from ..loads import Loads
        from .simulation import run_attributes

        def column(name):
            return np.array([np.nan if getattr(row, name) is None else float(getattr(row, name)) for row in self.rows])

        ds = xr.Dataset(
            {
                "static_fold": (("value",), column("static_fold"), {"long_name": "M_c, the end of the static branch from rest"}),
                "phi0_at_fold": (("value",), column("phi0_at_fold"), {"long_name": "phi_0 at the static fold"}),
                "rotation_stops": (("value",), column("rotation_stops"), {"long_name": "moment at which a falling load stops the rotation"}),
                "end": (("value",), np.array([row.end for row in self.rows], dtype=str), {"long_name": "how the rotation stops"}),
                "hysteresis": (("value",), np.array([-1 if row.hysteresis is None else int(row.hysteresis) for row in self.rows], dtype=np.int8),
                               {"long_name": "1: open loop (rotation_stops < static_fold), 0: closed, -1: unknown"}),
                "rotation_starts": (("value",), np.array([row.rotation_starts or "unknown" for row in self.rows], dtype=str),
                                    {"long_name": "how a rising load starts the rotation at M_c: snic, jump or unknown"}),
                "method": (("value",), np.array([row.method for row in self.rows], dtype=str),
                           {"long_name": "how rotation_stops was found: followed, located, solved, fitted or one_parameter"}),
                "rotation_stops_uncertainty": (("value",), column("uncertainty"),
                                               {"long_name": "accuracy of a homoclinic rotation_stops, solved or fitted (NaN: another computed point)"}),
                "moment_scale": (("value",), column("moment_scale"), {"long_name": "E1 h^2, the unit of the dimensionless moment M / (E1 h^2)"}),
                "below_edge": (("value",), np.array([row.below or "not_checked" for row in self.rows], dtype=str),
                               {"long_name": "a run just below a fold-of-cycles edge: rest, rotating (the edge is not the end of rotation), not_converged or not_checked"}),
            },
            # The value's units are the varied field's: io.describe reads them from the attribute "parameter".
            coords={"value": ("value", np.array([row.value for row in self.rows]))},
        )  # fmt: skip
        ds.attrs.update(run_attributes(self.params, get_model(self.model), Loads()))
        ds.attrs.update({"experiment": "state_diagram", "parameter": self.field, "turns": self.turns,
                         "static_fold_independent_of_parameter": int(self.independent),
                         "snic_point_json": json.dumps(self.snic_point),
                         "codim2_between_json": json.dumps(self.codim2_between)})  # fmt: skip
        return ds


@dataclass
class _Edge:
    """Where one chain's rotation stops (:class:`DiagramRow`'s fields) and the orbit next to it that a
    curve of that end starts from (None where the end cannot be followed)."""

    stops: float | None
    end: str
    message: str
    orbit: PeriodicOrbit | None = None
    method: str = "one_parameter"
    uncertainty: float | None = None
    below: str | None = None
    followed: list[dict[str, Any]] = field(default_factory=list)
    warning: str = ""
    first: PeriodicOrbit | None = None


def _snic_pair(rows: Sequence[DiagramRow]) -> tuple[DiagramRow, DiagramRow] | None:
    """The first two neighbouring rows of which one ends homoclinic and the other at a SNIC (the SNIC point lies between)."""
    for before, after in zip(rows, rows[1:]):
        if {before.end, after.end} == {"homoclinic", "snic"}:
            return before, after
    return None


def _solve_snic(diagram: StateDiagram, params: ChainParams, model, particle: int) -> None:
    """Set ``diagram.solved_snic`` to the codimension-two point between its homoclinic and SNIC rows, solved by the
    augmented system (:func:`~cosserat_chain.numerics.homoclinic.chain_snic_point`), or ``snic_failure`` to why not."""
    pair = _snic_pair(diagram.rows)
    if pair is None:
        return
    homoclinic = pair[0] if pair[0].end == "homoclinic" else pair[1]
    between = [pair[0].value, pair[1].value]
    chain = params.replace(**{diagram.field: homoclinic.value})
    try:
        point = chain_snic_point(chain, model, name=diagram.field, bracket=tuple(between), particle=particle)
    except (HomoclinicError, ValueError) as err:
        diagram.snic_failure = f"the augmented system did not solve it ({err})"
        return
    diagram.solved_snic = {
        "value": float(point.value),
        "accuracy": float(point.accuracy),
        "moment": float(point.moment),
        "between": between,
        "method": "solved",
        "solver": "augmented_system",
    }


def _first_stable(
    chain: ChainParams, model, moment: float, turns: int, particle: int, state=None
) -> tuple[PeriodicOrbit | None, list[str]]:
    """The first stable orbit at ``moment`` with 1, 2, ... ``turns`` turns a period (settled from rest, or from
    ``state`` = (x, v)), and what each try gave."""
    orbit, tried = None, []
    for k in range(1, turns + 1):
        try:
            guess = None if state is None else initial_guess(chain, model, moment, turns=k, particle=particle, x0=state[0], v0=state[1])
            candidate = find_periodic_orbit(chain, model, moment, turns=k, particle=particle, guess=guess)
        except OrbitError:
            tried.append(f"{k} turn(s): none found")
            continue
        if candidate.stable:
            orbit = candidate
            break
        tried.append(f"{k} turn(s): unstable (largest multiplier {candidate.max_multiplier:.4g})")
    return orbit, tried


def _lower_edge(chain: ChainParams, model, moment_c: float, turns: int, particle: int, period_max: float, field_name: str) -> _Edge:
    """The lower edge of one chain by one-parameter continuation in M, located exactly by the augmented
    shooting system where it is a fold of cycles, a period doubling or a torus (``field_name``: the
    varied field, which the messages name)."""
    start = START_FACTOR * moment_c
    orbit, tried = _first_stable(chain, model, start, turns, particle)
    if orbit is None:
        return _Edge(
            None,
            "not_found",
            (
                f"no stable periodic orbit at M = {start:.6g} with 1 to {turns} turns a period ({'; '.join(tried)}): "
                "the rotation there may be modulated or irregular (simulate or rotate show it)"
            ),
        )
    return _edge_of(orbit, chain, model, moment_c, particle, period_max, field_name)


def _edge_of(orbit: PeriodicOrbit, chain: ChainParams, model, moment_c: float, particle: int, period_max: float, field_name: str) -> _Edge:
    """Where the stable ``orbit`` ends going down in M (:func:`_lower_edge`), the orbit kept as ``first``."""
    edge = _edge_from(orbit, chain, model, moment_c, particle, period_max, field_name)
    edge.first = orbit
    return edge


def _edge_from(
    orbit: PeriodicOrbit, chain: ChainParams, model, moment_c: float, particle: int, period_max: float, field_name: str
) -> _Edge:
    """:func:`_edge_of` without the orbit kept.

    The continuation first runs with :data:`SCOUT`'s looser tolerances: it only brackets the end, which :func:`_located`
    then locates at full accuracy from the orbits around it, or the projection boundary conditions
    solve (a homoclinic end: the loop in the bracket of the scouting branch's fit, the same M_h as from the accurate
    branch's to far below its accuracy; the message quotes the scouting fit), and a SNIC end is M_c itself.
    Every other end is read from the branch's own orbits (a fitted homoclinic end the solve did not find, the
    one-parameter estimate where the location fails, a continuation that ended otherwise): that branch is traced
    again at full accuracy, so that such an edge is what the accurate continuation gives.
    """
    edge = _edge_of_branch(
        orbit, continue_orbit(orbit, moment_min=0.0, period_max=period_max, until_unstable=True, **SCOUT),
        chain, model, moment_c, particle, period_max, field_name,
    )  # fmt: skip
    if edge.method in ("located", "solved") or edge.end == "snic":
        return edge
    branch = continue_orbit(orbit, moment_min=0.0, period_max=period_max, until_unstable=True)
    return _edge_of_branch(orbit, branch, chain, model, moment_c, particle, period_max, field_name)


def _edge_of_branch(
    orbit: PeriodicOrbit, branch, chain: ChainParams, model, moment_c: float, particle: int, period_max: float, field_name: str
) -> _Edge:
    """Where the rotation stops, read from ``branch``, the continuation of the stable ``orbit`` down in M."""
    start = orbit.moment
    lost = branch.stability_lost_at
    if lost is not None:
        index = int(np.argmin(branch.stable))
        first_unstable = branch.orbits[index]
        leading = first_unstable.nontrivial_multipliers[np.argmax(np.abs(first_unstable.nontrivial_multipliers))]
        if abs(leading.imag) > COMPLEX_RTOL * abs(leading):
            end = "torus"
        elif leading.real < 0:
            end = "period_doubling"
        else:
            # Through +1: a fold of cycles only where M turns there (the continuation's fold), else a branch point.
            end = "fold_of_cycles" if branch.end == "fold" else "branch_point_of_cycles"
        around = branch.orbits[index - 1 : index + 1]
        message = f"the orbit loses stability at M = {lost:.6g} (leading multiplier {leading:.4g}, interpolated)" + _phase_note(branch)
        return _located(_Edge(float(lost), end, message), around, field_name)
    if branch.end == "fold":
        around = sorted(branch.orbits[-3:], key=lambda o: abs(o.moment - branch.end_moment))
        return _located(_Edge(float(branch.end_moment), "fold_of_cycles", branch.message), around, field_name)
    if branch.end == "infinite_period":
        if len(branch.orbits) < MIN_TAIL:
            return _Edge(
                None,
                "not_found",
                (
                    f"the period exceeded period_max = {period_max:g} within {len(branch.orbits)} orbits of the start at "
                    f"M = {start:.6g} (periods {', '.join(f'{t:.4g}' for t in branch.period)}): too few to tell how it "
                    "diverges (try a larger period_max)"
                ),
            )
        stops, end, message, uncertainty = _diverging(branch.moment[-TAIL:], branch.period[-TAIL:], moment_c)
        return _solved(_Edge(stops, end, message, uncertainty=uncertainty), chain, model, particle, float(branch.moment[-1]))
    tail = _approach(np.asarray(branch.moment), np.asarray(branch.period)) if branch.end in ("step_too_small", "max_points") else None
    if tail is not None:
        # The continuation crawled to a halt with the period still growing: near a homoclinic
        # orbit T grows only like -log(M - M_h) / lambda (the weakly damped pendulum: T = 4.03
        # at M - M_h = 1e-8), so no period cap is ever reached; the growth locates M_h.
        stops, end, message, uncertainty = _diverging(*tail, moment_c)
        last = abs(float(branch.moment[-1]))
        # The rotation exists down to the last orbit: M_h lies between the fit and it.
        if end == "snic" or 0.0 <= last - abs(stops) <= APPROACH_RTOL * last:
            fitted = _Edge(
                stops,
                end,
                f"{message}; the continuation stopped by {branch.end} at M = {branch.moment[-1]:.10g}, the bound above M_h",
                uncertainty=uncertainty,
            )
            return _solved(fitted, chain, model, particle, float(branch.moment[-1]))
    return _Edge(None, "not_found", f"the orbit's continuation ended by {branch.end}: {branch.message}")


def _below_fold(
    edge: _Edge, chain: ChainParams, model, moment_c: float, turns: int, particle: int, period_max: float, field_name: str
) -> _Edge:
    """Whether the rotation goes on below a fold of cycles, and where it stops if it does (module docstring).

    A run starts at (1 - :data:`BELOW_FOLD`) times the fold's moment from the fold's orbit
    (:func:`~cosserat_chain.numerics.relaxation.relax`, the protocol's test of rest or steady rotation). Where it
    keeps rotating, the first stable orbit of 1 to ``turns`` turns settled from where it went is followed down in
    turn, up to :data:`MAX_ORBITS` orbits in all; the returned edge is the last orbit's, with ``below`` (``rest``,
    ``rotating`` or ``not_converged``), ``followed`` (each orbit: turns, rate, moment it was found at, end, where)
    and a ``warning`` where a run below the reported edge still rotates.
    """
    followed = [_followed_entry(edge)]
    while edge.end == "fold_of_cycles" and edge.orbit is not None and edge.stops is not None and edge.stops < moment_c:
        below = edge.stops * (1.0 - BELOW_FOLD)
        try:
            run = relax(chain, model, below, particle=particle, x0=edge.orbit.x, v0=edge.orbit.v, t_max=BELOW_PERIODS * edge.orbit.period)
        except IntegrationError as err:
            edge.below, edge.message = "not_converged", edge.message + f"; a run below the fold at M = {below:.8g} failed ({err})"
            break
        rate = float(run.angular_velocity[column(chain, particle)]) if run.status == "rotating" else 0.0
        edge.below = "rest" if run.status == "static" else ("rotating" if run.status == "rotating" else "not_converged")
        followed[-1]["below"] = edge.below
        if edge.below == "rest":
            edge.message += f"; a run from the fold's orbit at M = {below:.8g} comes to rest: the fold is the edge of rotation"
            break
        what = f"keeps rotating (mean rate {rate:.6g})" if edge.below == "rotating" else f"has not settled ({run.message})"
        edge.warning = (
            f"below the fold of cycles at M = {edge.stops:.8g} a run from its orbit at M = {below:.8g} {what}: "
            "the fold ends one orbit, not the rotation"
        )
        if edge.below != "rotating" or len(followed) >= MAX_ORBITS:
            edge.message += "; " + edge.warning
            break
        orbit, tried = _first_stable(chain, model, below, turns, particle, state=(run.x, run.v))
        if orbit is None:
            edge.message += f"; {edge.warning}; no stable orbit found there ({'; '.join(tried)})"
            break
        previous = edge
        edge = _edge_of(orbit, chain, model, moment_c, particle, period_max, field_name)
        edge.message = (
            f"the {previous.orbit.turns}-turn orbit ends at a fold of cycles at M = {previous.stops:.8g}, where the chain "
            f"goes on to a {orbit.turns}-turn orbit (mean rate {orbit.mean_angular_velocity:.6g}), followed from there: {edge.message}"
        )
        followed.append(_followed_entry(edge))
    edge.followed = followed
    if edge.below != "rotating":
        edge.warning = ""
    return edge


def _followed_entry(edge: _Edge) -> dict[str, Any]:
    """One orbit of a row's ``followed_orbits``: its turns and rate where it was found, its end, where, and what a run
    below a fold of cycles does (``below``: None where not checked)."""
    entry: dict[str, Any] = {"turns": None, "found_at": None, "mean_angular_velocity": None}
    if edge.first is not None:
        orbit = edge.first
        entry = {"turns": orbit.turns, "found_at": float(orbit.moment), "mean_angular_velocity": float(orbit.mean_angular_velocity)}
    return {**entry, "end": edge.end, "rotation_stops": edge.stops, "below": None}


def _solved(edge: _Edge, chain: ChainParams, model, particle: int, last: float) -> _Edge:
    """A fitted homoclinic end replaced by the solved loop (:func:`~cosserat_chain.numerics.homoclinic.chain_homoclinic_end`:
    projection boundary conditions, with its accuracy); where that fails, the fit is kept and the message says why."""
    if edge.end != "homoclinic" or edge.stops is None:
        return edge
    if edge.uncertainty is None:
        edge.method = "fitted"
        return edge
    # The fit's uncertainty can be too small by more than a factor of ten (the N = 1 chain at gamma_phi = 0.02, whose
    # continuation crawls to a halt at a period of 4.4, far from diverging: 1.2e-8 against an error of 1.5e-7): the
    # bracket reaches at least BRACKET_RTOL below it; its bisection costs a few manifold runs more.
    reach = max(10.0 * edge.uncertainty, BRACKET_RTOL * abs(edge.stops))
    try:
        orbit = chain_homoclinic_end(chain, model, bracket=(edge.stops - reach, last), particle=particle)
    except (HomoclinicError, OrbitError) as err:  # an integration along a loop that ran away ends the solve too
        # The fit stays, labelled so, with its own uncertainty (FIT_SAFETY times the spread of the fits).
        edge.message += f"; not solved ({err}): M_h = {edge.stops:.10g} +- {edge.uncertainty:.2g}, fitted (the fit's own uncertainty)"
        edge.method = "fitted"
        return edge
    off = abs(edge.stops - orbit.value)
    fit = f"the fit of the period's growth gave {edge.stops:.10g} +- {edge.uncertainty:.2g}" + (
        f", off by {off:.2g}: its spread understated its error" if off > edge.uncertainty else ""
    )
    message = (
        f"the orbit ends at a loop homoclinic to the saddle at M_h = {orbit.value:.12g} +- {orbit.accuracy:.1g}, solved by "
        f"projection boundary conditions ({fit})"
    )
    return _Edge(orbit.value, "homoclinic", message, method="solved", uncertainty=orbit.accuracy)


def _phase_note(branch) -> str:
    """Says where the continuation left the section phi_0 = 0 for a phase plane (empty where it did not)."""
    index = next((i for i, o in enumerate(branch.orbits) if o.phase_normal is not None), None)
    if index is None:
        return ""
    # The plane passes through the last orbit on the section (the first one, if the start had a plane).
    switched = branch.orbits[max(index - 1, 0)].moment
    return f"; the flow became tangent to the section phi_0 = 0 near M = {switched:.6g}: the orbit was continued on the phase plane normal to the flow"


def _located(edge: _Edge, around: Sequence[PeriodicOrbit], field_name: str) -> _Edge:
    """``edge`` located at full tolerances at its own chain from the orbits ``around`` it (the one-parameter estimate
    interpolates the multipliers between two orbits: 3e-5 off for the paper's chain's period doubling at gamma_phi =
    0.12); unchanged, saying so, where that fails. A period doubling or a torus is the scouting branch's event found
    again by the one mechanism (:func:`~cosserat_chain.numerics.cycle_curve.locate_circle_event`: Brent's method in M
    on its test function between the last stable and the first unstable orbit, solved again at full tolerances); a
    fold of cycles is solved by Newton on the augmented shooting system, and a branch point of cycles by the fold's
    system (the shooting Jacobian is singular at both)."""
    try:
        if edge.end in CIRCLE_KINDS:
            edge.orbit = locate_circle_event(around, edge.end, field_name=field_name, resolve=True)
            how = "Brent's method on its test function (cycle_events)"
        else:
            kind = "fold_of_cycles" if edge.end == "branch_point_of_cycles" else edge.end
            edge.orbit = locate_cycle_end(around, kind, field_name=field_name)
            how = "the augmented shooting system"
    except ValueError as err:
        edge.message += f"; not located exactly ({err})"
        return edge
    edge.stops, edge.method = float(edge.orbit.moment), "located"
    edge.message += f"; located at M = {edge.stops:.8g} by {how}"
    return edge


def _approach(moment: np.ndarray, period: np.ndarray) -> tuple[np.ndarray, np.ndarray] | None:
    """The branch's last orbits if they approach a limit moment with a growing period, else None.

    Taken: the last APPROACH_POINTS orbits of distinct M, each period at least APPROACH_SPACING
    (relative) below the next one kept (a crawl of the last steps, whose periods differ by 1e-6, is
    thinned out: its dT/dM is the local slope, not the approach). An approach: |M| falls and T
    rises from each to the next, ever faster against M (|dT/dM| larger over the second
    half of them than over the first), as -log(M - M_h) does; :func:`_diverging` then fits
    M_h, which is kept only within APPROACH_RTOL of the last orbit's M below it.
    """
    distinct = np.flatnonzero(np.abs(np.diff(moment)) > 1e-14 * np.abs(moment[1:])) + 1
    spaced: list[int] = []
    for index in distinct[::-1]:
        if not spaced or period[index] <= period[spaced[-1]] * (1.0 - APPROACH_SPACING):
            spaced.append(int(index))
    keep = np.array(spaced[:APPROACH_POINTS][::-1], dtype=int)
    if keep.size < APPROACH_POINTS:
        return None
    m, t = np.abs(moment[keep]), period[keep]
    half = APPROACH_POINTS // 2
    slope_first = (t[half - 1] - t[0]) / (m[0] - m[half - 1])
    slope_last = (t[-1] - t[half]) / (m[half] - m[-1])
    if not (np.all(np.diff(m) < 0) and np.all(np.diff(t) > 0) and slope_last > slope_first):
        return None
    return moment[keep], t


def _diverging(moment: np.ndarray, period: np.ndarray, moment_c: float) -> tuple[float, str, str, float | None]:
    """Where and how a diverging period ends: SNIC at M_c, or homoclinic below it; and the uncertainty of a fitted M_h.

    At a SNIC T ~ (M - M_c)^(-1/2), so T^-2 is linear in M and vanishes at M_c; at a
    homoclinic end T ~ -log(M - M_h) / lambda. The first is tested by the linear
    extrapolation of T^-2 (the end is then M_c itself, computed: no uncertainty is given);
    otherwise M_h is where the fit of T against log(M - M_h) is best, and its uncertainty
    FIT_SAFETY times the difference from the same fit to the last MIN_TAIL orbits alone.
    """
    import scipy.optimize as so

    # T^-2 = c (M - M_c) (1 + O(M - M_c)): a quadratic through the last orbits, its root
    # nearest them (a straight line extrapolated to 7e-4 of M_c from periods up to 100).
    # In M centred on the last orbit and scaled by the spread (a tail that crept to a halt
    # spans 1e-10: polyfit in M itself would be ill-conditioned).
    width = float(np.ptp(moment)) or 1.0
    roots = np.roots(np.polyfit((moment - moment[-1]) / width, period**-2.0, 2))
    real = roots[np.abs(roots.imag) <= 1e-12 * np.abs(roots)].real * width + moment[-1]
    at = float(real[np.argmin(np.abs(real - moment[-1]))]) if real.size else math.inf
    if abs(at - moment_c) <= SNIC_RTOL * abs(moment_c):
        message = f"the period diverges like (M - M_c)^(-1/2) at M_c = {moment_c:.6g} (T^-2 extrapolates to {at:.6g})"
        return float(moment_c), "snic", message, None

    def fit(moment: np.ndarray, period: np.ndarray) -> float:
        span = float(np.ptp(moment))
        nearest = float(np.min(np.abs(moment)))

        def misfit(m_h: float) -> float:
            logs = np.log(np.abs(moment) - m_h)
            return float(np.sum((period - np.polyval(np.polyfit(logs, period, 1), logs)) ** 2))

        best = so.minimize_scalar(misfit, bounds=(nearest - 20.0 * span, nearest - 1e-9 * max(span, 1e-12)), method="bounded")
        return float(np.sign(moment[-1]) * best.x)

    m_h = fit(moment, period)
    near = fit(moment[-MIN_TAIL:], period[-MIN_TAIL:]) if moment.size > MIN_TAIL else None
    uncertainty = None if near is None else FIT_SAFETY * abs(m_h - near)
    spread = "" if uncertainty is None else f" +- {uncertainty:.1g}"
    return (
        m_h,
        "homoclinic",
        f"the period diverges like -log(M - M_h) at M_h = {m_h:.6g}{spread} (a fit to the last {moment.size} orbits, not a computed point)",
        uncertainty,
    )


def _static_onset(chain: ChainParams, model, particle: int, fold: float, phi0: float) -> tuple[float, float, str]:
    """(M_c, phi_0 there, a note): ``critical``'s M_c, the one definition of the onset of rotation; the fold curve's
    fold where it is that M_c, else a note says what M_c is instead.

    The stable branch from rest may end before the followed fold at a branch point (K singular while M still rises:
    the nonlinear cantilever's at M = 0.08198, phi_0 = 4.23, before its fold at 0.08375); a cusp may have put a pair
    of folds before it (the nonlinear N = 1 chain between E2 = 1.0 and 1.1: folds at M = 0.26472 and 0.26027, then
    the followed one at 0.26289); or the chain may snap past the followed fold onto a branch the trace does not follow
    and leave rest only at that branch's fold (tests/test_audit_fourteenth_chain.py: 8.898910 past the first fold
    1.275699)."""
    onset = critical_point(chain, model, particle=particle, dynamics=False)
    moment, angle = onset.critical_moment, onset.phi0_at_onset
    if moment is None or angle is None:
        raise ValueError(f"the stable branch from rest of this row has no onset of rotation ({onset.end})")
    if abs(moment - fold) <= FOLD_MATCH * max(abs(fold), 1.0):
        return fold, phi0, ""
    if onset.onset == "branch_point":
        why = f"the stable branch from rest ends at a branch point at M = {moment:.6g} (phi_0 = {angle:.4g}), before the fold at {fold:.6g}"
    elif onset.onset == "crossing_fold":
        why = (
            f"the chain snaps past the fold at M = {fold:.6g} onto a branch it rests on until that branch's fold at M = {moment:.6g} "
            f"(phi_0 = {angle:.4g})"
        )
    else:
        why = f"the fold curve followed the fold at M = {fold:.6g} (phi_0 = {phi0:.4g}), but the branch from rest ends at the fold at M = {moment:.6g} (phi_0 = {angle:.4g})"
    bound = " (a lower bound: critical did not follow the branch the chain lands on to its end)" if onset.crossing_unresolved else ""
    return float(moment), float(angle), f"{why}: M_c is critical's ({onset.onset}){bound}; "


def _followed(previous: tuple[float, _Edge] | None, field_name: str, value: float) -> _Edge | None:
    """The previous row's end followed to ``value`` (None where it cannot be; an edge without an orbit, whose
    message says why, where the curve stopped: the row is then computed on its own)."""
    if previous is None or previous[1].orbit is None or previous[1].end not in KINDS:
        return None
    before, edge = previous
    try:
        curve = continue_cycle_end(edge.orbit, edge.end, field_name, [before, value])
    except ValueError as err:
        return _Edge(None, "not_found", f"the {edge.end} end was not followed from {field_name} = {before:g} ({err})")
    if not curve.complete:
        return _Edge(None, "not_found", curve.message)
    message = f"the {edge.end} end followed from {field_name} = {before:g} by the augmented shooting system"
    return _Edge(float(curve.moment[-1]), edge.end, message, curve.orbits[-1], "followed")


#: Why an end cannot be followed in the field by :func:`~cosserat_chain.numerics.cycle_curve.continue_cycle_end`.
UNFOLLOWED = {
    "homoclinic": "a homoclinic end cannot be followed by the augmented shooting system (numerics.cycle_curve: with single "
    "shooting the orbit's passage near the saddle makes Newton fail at the first step)",
    "snic": "a SNIC end lies on the static fold, not on a curve of cycles (snic_point: where it meets a homoclinic end)",
    "branch_point_of_cycles": "a branch point of cycles is not followed in a second parameter",
    "not_found": "no end was found there",
}


#: The strong resonances two neighbouring torus rows can straddle, by the angle of the pair on the circle (the 1:1 and
#: 1:2 ones, at 0 and pi, end a torus curve: they lie between a torus row and a row of another end).
TORUS_RESONANCES = {"resonance_1_3": 2 * math.pi / 3, "resonance_1_4": math.pi / 2}


def _torus_angles(edges: Sequence[_Edge | None]) -> list[float] | None:
    """The torus pair's angles at two rows' ends, or None where an end's orbit is missing or has no complex pair."""
    try:
        return [torus_angle(edge.orbit) for edge in edges if edge is not None and edge.orbit is not None] or None
    except OrbitError:
        return None


def _straddled(edges: Sequence[_Edge | None]) -> tuple[list[float] | None, list[str]]:
    """Two torus rows' angles and the resonances of :data:`TORUS_RESONANCES` between them (their cos theta on either side)."""
    angles = _torus_angles(edges)
    if angles is None or len(angles) != 2:
        return angles, []
    return angles, [name for name, angle in TORUS_RESONANCES.items() if (angles[0] - angle) * (angles[1] - angle) < 0]


def _codim2_between(rows: Sequence[DiagramRow], edges: Sequence[_Edge | None], field_name: str) -> list[dict[str, Any]]:
    """What lies between each two neighbouring rows whose ends differ, or which both end at a torus with the pair's
    angles on either side of a strong resonance (:data:`TORUS_RESONANCES`): one entry per such pair (module docstring).

    The first row's end (or, where it cannot be followed, the second's, towards the first) is followed from its row
    to the other's value by :func:`~cosserat_chain.numerics.cycle_curve.continue_cycle_end`: ``points`` are the
    codimension-two points it located on the way (name, AUTO-07p's label, value, its accuracy, M, period), and
    ``message`` says where and why the curve stopped (its own words: Newton failed on halved steps, another
    multiplier left the circle), or that it reached the other row. Where neither end can be followed,
    ``followed`` is None and ``message`` says why (:data:`UNFOLLOWED`). Between two torus rows ``angles`` are their
    pairs' angles and ``straddles`` the resonances between them (empty, and ``angles`` None, for rows of different ends).
    """
    out = []
    for i in range(1, len(rows)):
        before, after = rows[i - 1], rows[i]
        angles, straddles = _straddled(edges[i - 1 : i + 1]) if before.end == after.end == "torus" else (None, [])
        if before.end == after.end and not straddles:
            continue
        entry: dict[str, Any] = {
            "between": [before.value, after.value], "ends": [before.end, after.end],
            "followed": None, "from": None, "complete": None, "points": [], "message": "",
            "angles": angles if straddles else None, "straddles": straddles,
        }  # fmt: skip
        why = []
        for start, target, edge in ((before, after, edges[i - 1]), (after, before, edges[i])):
            if start.end not in KINDS or edge is None or edge.orbit is None:
                reason = UNFOLLOWED.get(start.end, "its end was not located exactly (no orbit at the end to start from)")
                why.append(f"the {start.end} end at {field_name} = {start.value:g}: {reason}")
                continue
            entry["followed"], entry["from"] = start.end, start.value
            try:
                curve = continue_cycle_end(edge.orbit, start.end, field_name, [start.value, target.value])
            except (ValueError, OrbitError) as err:
                entry["message"] = f"the {start.end} end was not followed from {field_name} = {start.value:g} ({err})"
                break
            entry["complete"] = curve.complete
            entry["points"] = [
                {"name": p.name, "kind": p.kind, "label": p.label, "value": p.value, "accuracy": p.uncertainty,
                 "moment": p.moment, "period": p.period, "angle": p.angle}
                for p in curve.points
            ]  # fmt: skip
            entry["message"] = curve.message or (
                f"the {start.end} end followed from {field_name} = {start.value:g} reaches {target.value:g} at "
                f"M = {curve.moment[-1]:.8g}, where the row's end is {target.end}: the two rows end different orbits"
                if start.end != target.end
                else _straddle_message(start, target, field_name, straddles, curve)
            )
            break
        if entry["followed"] is None:
            entry["message"] = "not followed: " + "; ".join(why)
        elif why:
            entry["message"] = f"{why[0]}, so the other end was followed: {entry['message']}"
        out.append(entry)
    return out


def _straddle_message(start: DiagramRow, target: DiagramRow, field_name: str, straddles: list[str], curve) -> str:
    """What following a torus end between two torus rows found: each resonance their angles straddle, located or not."""
    located = {point.kind: point for point in curve.points}
    said = []
    for name in straddles:
        point = located.get(name)
        words = f"{name.removeprefix('resonance_').replace('_', ':')} resonance"
        if point is None:
            said.append(f"the {words} its angles straddle was not located")
        else:
            said.append(f"its pair passes the {words} ({point.label}) at {field_name} = {point.value:.10g} +- {point.uncertainty:.2g}")
    return f"the torus end followed from {field_name} = {start.value:g} reaches {target.value:g}: " + "; ".join(said)


@one_blas_thread
def state_diagram(
    params: ChainParams,
    model: str,
    field_name: str,
    values: Sequence[float],
    *,
    turns: int = 3,
    particle: int = 0,
    period_max: float = PERIOD_MAX,
    follow: bool = False,
    codim2: bool = False,
    progress: Callable[[float, float], None] | None = None,
) -> StateDiagram:
    """Both edges of the hysteresis loop at each value of ``field_name`` (module docstring).

    Parameters
    ----------
    params : ChainParams
    model : {"nonlinear", "sine"}
    field_name : str
        A number of the chain (:data:`~cosserat_chain.numerics.fold_curve.FIELDS`).
    values : sequence of float
        In the order to follow the fold through them.
    turns : int
        The rotating orbit followed is the first stable one with 1, 2, ... ``turns`` turns
        of the loaded particle a period (rotating states of the paper's chain can repeat
        only after 2 or 3).
    period_max : float
        A period beyond this is a diverging one (homoclinic or SNIC end).
    follow : bool
        Follow each end from the value before by the augmented shooting system
        (:func:`~cosserat_chain.numerics.cycle_curve.continue_cycle_end`), the curve of the
        lower edge in (M, p); False computes every row on its own by one-parameter
        continuation in M (each then located exactly).
    codim2 : bool
        Between each two neighbouring rows whose ends differ, follow one row's end towards the other's value and
        report the codimension-two points located on the way, or where and why the curve stopped
        (:attr:`StateDiagram.codim2_between`, :func:`_codim2_between`; several times a row's cost).
    progress : callable(done, total), optional

    Raises
    ------
    ValueError
        For bad input (the field, a value, a model that does not rotate, a chain that
        can move rigidly), or a first value without a static fold.
    """
    model = get_model(model)
    if not model.rotates:
        raise ValueError(f"the {model.name} model does not rotate ({model.equation}): the diagram needs nonlinear or sine")
    if not (isinstance(turns, int) and not isinstance(turns, bool) and turns >= 1):
        raise ValueError(f"turns must be an integer >= 1, got {turns!r}")
    if not (math.isfinite(period_max) and period_max > 0):
        raise ValueError(f"period_max must be a finite number > 0, got {period_max!r}")
    if not isinstance(codim2, bool):
        raise ValueError(f"codim2 must be True or False, got {codim2!r}")
    # Each value's branch is traced as by critical: its least memory is checked before the fold curve indexes the chain.
    require(
        critical_memory(params, model, near_singular=True),
        f"diagram on {params.n_particles} particles (N={params.N})",
        "a shorter chain (N)",
    )
    curve = continue_fold(params, model, field_name, values)
    diagram = StateDiagram(params=params, model=model.name, field=field_name, turns=turns, independent=curve.independent)
    total = len(values)
    previous: tuple[float, _Edge] | None = None
    # Along a field the statics do not read (curve.independent: damping, mass, inertia) every row's branch
    # from rest is the same, so where it ends is computed once.
    onset: tuple[float, float, str] | None = None
    edges: list[_Edge | None] = []
    for index, value in enumerate(np.asarray(values, dtype=float)):
        if progress is not None:
            progress(index, total)
        reached = np.flatnonzero(curve.values == value)
        chain = params.replace(**{field_name: float(value)})
        if reached.size == 0:
            diagram.rows.append(DiagramRow(float(value), None, None, None, "not_found", None, curve.message, chain.moment_scale))
            edges.append(None)
            previous = None
            continue
        if onset is None or not curve.independent:
            onset = _static_onset(chain, model, particle, float(curve.moment[reached[0]]), float(curve.phi0[reached[0]]))
        moment_c, phi0_c, branch_note = onset
        edge = _followed(previous, field_name, float(value)) if follow else None
        if edge is None or edge.orbit is None:
            note = "" if edge is None else edge.message + "; "
            edge = _lower_edge(chain, model, moment_c, turns, particle, period_max, field_name)
            edge.message = note + edge.message
        edge = _below_fold(edge, chain, model, moment_c, turns, particle, period_max, field_name)
        edge.message = branch_note + edge.message
        previous = (float(value), edge)
        stops, message = edge.stops, edge.message
        hysteresis = None if stops is None else bool(stops < moment_c * (1.0 - SNIC_RTOL))
        if stops is not None and stops > moment_c * (1.0 + SNIC_RTOL):
            # Above M_c no static state exists: the chain rotates on in a state not followed here
            # (the sine chain at gamma_phi = 0.3: a period doubling at 0.2105 > M_c = 0.2040).
            hysteresis = None
            message += (
                f"; this is above M_c = {moment_c:.6g}, where no static state exists: the rotation goes on in another "
                "state (not followed), so where it stops and whether the loop is open are not known"
            )
        diagram.rows.append(
            DiagramRow(float(value), moment_c, phi0_c, stops, edge.end, hysteresis, message,
                       chain.moment_scale, edge.method, edge.uncertainty, edge.below, edge.followed, edge.warning)
        )  # fmt: skip
        edges.append(edge)
    _solve_snic(diagram, params, model, particle)
    if codim2:
        diagram.codim2_between = _codim2_between(diagram.rows, edges, field_name)
    if progress is not None:
        progress(total, total)
    return diagram
