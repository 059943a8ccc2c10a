"""Coexisting states at one moment: the static states, the rotating orbits and irregular rotation, from several starts.

Contract
--------
Under a constant moment M on the loaded particle (eqs. (1)-(3) with viscosity) the
chain can end in more than one state, and which one depends on where it starts.
:func:`states_at` lists, at one M,

* ``static``: every static state F(x) + M e = 0 on the branch from rest traced over
  one full turn of the loaded particle
  (:func:`~cosserat_chain.numerics.continuation.continue_in_moment`; for a model that
  does not rotate, the branch is a line and its one state is solved from rest): each
  crossing of M between two traced points is solved by Newton (load control,
  :func:`~cosserat_chain.numerics.newton.solve_equilibrium`, from the interpolated
  state; rotation control and Brent in phi_0 where that fails), with its residual
  and its stability: K's inertia, the *stiffness index*
  (:func:`~cosserat_chain.numerics.stability.static_stability`), and the verdict of the
  damped dynamics, its unstable eigenvalues
  (:func:`~cosserat_chain.numerics.stability.dynamic_stability`): for eq. (2) they differ
  (the sine chain's unstable branch at N = 2 has stiffness index 1 and three unstable
  eigenvalues between its Hopf points).
  A static state that a long run reaches off that branch is added (``on_branch``
  false).
* ``hopf``: the Hopf points of that branch
  (:func:`~cosserat_chain.numerics.hopf.hopf_points`; a conservative model has none), searched
  where the damped dynamics' eigenvalues are dense (:data:`~cosserat_chain.numerics.stability.DENSE_LIMIT`:
  N up to about 33 with clamped ends; the search takes them at every traced point) and None
  beyond, where ``hopf_points`` can be called on the branch directly.
* ``orbits``: periodic orbits, eq. (P) of :mod:`cosserat_chain.numerics.periodic`,
  found by shooting (:func:`~cosserat_chain.numerics.periodic.find_periodic_orbit`)
  with k = 1, 2, 3 (``turns``) turns a period from rest, and from the end of every
  long run that settled on a rotation repeating after k turns; each with its period,
  turns, mean rate 2 pi k / T and Floquet multipliers. An orbit found with k turns
  that closes after k / d of them is reported with its least number of turns; an
  orbit found twice (the same turns and period, the start of one on the other) once,
  with every start that found it.
* ``irregular``: long runs that rotate without repeating after up to ``2 max(turns)``
  turns: the rates over windows of ``window_turns`` whole turns in the run's second
  half (min, max, mean). Windows of whole turns, not of a fixed time: over a fixed
  time window a periodic rotation's rate varies with the phase at which the window
  starts and ends (for the paper's sine chain at M = 0.22 by +-0.008 over 500 time
  units, docs/periodic-orbits.md), which is no modulation.
* ``runs``: for every start (rest, each static state perturbed both ways, seeded random
  states), what a run of ``t_long`` from it reached.
* ``from_rest``: what the relaxation protocol from rest (:func:`~cosserat_chain.numerics.relaxation.relax`,
  the paper's Section 4 step) reaches: its own verdict (``static``, ``rotating``,
  ``not_converged``) and the listed state its end state settles on.

The long runs are the package's fixed-step integrator (Yoshida-4, the default step)
following the loaded particle's turns (:class:`~cosserat_chain.numerics.dynamics.TurnWatch`).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ..linalg.threads import one_blas_thread
from ..loads import moment_load
from ..models.base import Model, get_model
from ..numerics.brent import brentq
from ..numerics.continuation import continue_in_moment
from ..numerics.dynamics import TurnWatch, integrate
from ..numerics.hopf import HopfPoint, hopf_points
from ..numerics.newton import NewtonError, moment_dof, solve_equilibrium, solve_rotation_controlled
from ..numerics.periodic import OrbitError, PeriodicOrbit, find_periodic_orbit, initial_guess
from ..numerics.relaxation import relax
from ..numerics.stability import DENSE_LIMIT, DynamicStability, Stability, dynamic_stability, static_stability
from ..params import ChainParams
from ..state import ROW_INDEX, column, fixed_mask, n_free, pack, require_held, zeros
from ..status import Status

ProgressCallback = Callable[[float, float], None]

#: The kinds of start :func:`states_at` takes (module docstring).
STARTS = ("rest", "static", "random")
#: Default time of each long run (a few seconds for the paper's chain: its 7 particles
#: run at about 3e7 particle-steps per second).
T_LONG = 5000.0
#: Default number of seeded random starts.
RANDOM_STARTS = 8
#: Size of the perturbation of a static state (largest component), both signs.
PERTURBATION = 1e-2
#: Turns per window of an irregular rotation's rates.
WINDOW_TURNS = 12
#: Spans of k turns that agree to this (relative) repeat after k turns: the turn times are
#: interpolated within a step, measured 3e-6 relative on a periodic orbit (Yoshida-4, default step).
SPAN_RTOL = 1e-4
#: A run whose velocities fell below this has come to rest (its end is then solved by Newton).
REST_SPEED = 1e-6
#: Two static states, or the starts of two orbits on the section phi_0 = 0, closer than this are one.
STATE_ATOL = 1e-6
#: Two orbits whose periods differ by less than this (relative) may be one (their states decide).
PERIOD_RTOL = 1e-6
#: Turns kept of each long run (its second half is analysed).
KEEP_TURNS = 4096
#: Samples per turn of an orbit where its crossings of the section are bracketed.
SAMPLES_PER_TURN = 64


@dataclass
class StaticState:
    """One static state at M.

    Attributes
    ----------
    x : ndarray (3, 2N+1)
    phi0 : float
        Angle of the loaded particle (rad).
    residual : float
        max |F(x) + M e| over the free degrees of freedom.
    stability : Stability
        From K: its critical eigenvalue and inertia (``index``, the stiffness index).
    dynamics : DynamicStability
        From the eigenvalues of the damped dynamics: the verdict (``stable`` and the JSON's
        ``stable`` are this one's) and the unstable eigenvalues.
    on_branch : bool
        On the traced full-turn branch from rest (False: reached by a long run off it).
    found_from : list of str
        The starts whose runs ended here.
    """

    x: np.ndarray
    phi0: float
    residual: float
    stability: Stability
    dynamics: DynamicStability
    on_branch: bool = True
    found_from: list[str] = field(default_factory=list)

    @property
    def stable(self) -> bool:
        """Dynamically stable (the damped dynamics' verdict)."""
        return self.dynamics.stable

    def as_dict(self) -> dict[str, Any]:
        d = self.dynamics
        return {
            "phi0": self.phi0,
            "residual": self.residual,
            "stable": d.stable,
            "dynamically_stable": d.stable,
            "unstable_eigenvalues": d.unstable_eigenvalues,
            "unstable_real": d.unstable_real,
            "unstable_pairs": d.unstable_pairs,
            "unstable": [[z.real, z.imag] for z in d.rightmost[: d.unstable_eigenvalues]],
            "stiffness_index": self.stability.index,
            "critical_eigenvalue": self.stability.critical_eigenvalue,
            "on_branch": self.on_branch,
            "found_from": self.found_from,
        }


@dataclass
class FoundOrbit:
    """A periodic orbit at M and the starts that found it."""

    orbit: PeriodicOrbit
    found_from: list[str] = field(default_factory=list)

    def as_dict(self) -> dict[str, Any]:
        o = self.orbit
        return {
            "turns": o.turns,
            "period": o.period,
            "mean_angular_velocity": o.mean_angular_velocity,
            "max_nontrivial_multiplier": o.max_multiplier,
            "floquet_multipliers_abs": np.abs(o.multipliers).tolist(),
            "stable": o.stable,
            "closure": o.closure,
            "found_from": self.found_from,
        }


@dataclass
class IrregularRotation:
    """A long run that rotates without repeating after up to ``max_turns`` turns.

    Attributes
    ----------
    rate_mean, rate_min, rate_max : float
        Mean angular velocity of the loaded particle over windows of ``window_turns``
        whole turns in the run's second half: their mean, least and largest.
    window_turns : int
    turns : int
        Turns in the analysed half.
    max_turns : int
        No span of 1..max_turns turns repeated to :data:`SPAN_RTOL`.
    found_from : list of str
    """

    rate_mean: float
    rate_min: float
    rate_max: float
    window_turns: int
    turns: int
    max_turns: int
    found_from: list[str] = field(default_factory=list)

    def as_dict(self) -> dict[str, Any]:
        return {
            "rate_mean": self.rate_mean,
            "rate_min": self.rate_min,
            "rate_max": self.rate_max,
            "window_turns": self.window_turns,
            "turns": self.turns,
            "max_turns": self.max_turns,
            "found_from": self.found_from,
        }


@dataclass
class Run:
    """What the long run from one start reached: ``reached`` is ``static``, ``orbit``, ``irregular`` or ``not_settled``, ``index`` its entry in that list."""

    start: str
    reached: str
    index: int | None
    message: str = ""

    def as_dict(self) -> dict[str, Any]:
        return {"start": self.start, "reached": self.reached, "index": self.index, "message": self.message}


@dataclass
class CoexistingStates:
    """The states at one moment (module docstring).

    ``from_rest`` is a :class:`Run` of the relaxation protocol from rest; ``relaxation``
    its step's status, time and mean angular velocity of the loaded particle.
    """

    params: ChainParams
    model: str
    moment: float
    particle: int
    static: list[StaticState]
    orbits: list[FoundOrbit]
    irregular: list[IrregularRotation]
    runs: list[Run]
    from_rest: Run
    relaxation: dict[str, Any]
    settings: dict[str, Any] = field(default_factory=dict)
    status: Status = Status.COMPLETED
    hopf: list[HopfPoint] | None = field(default_factory=list)

    @property
    def stable_states(self) -> int:
        """Dynamically stable static states plus stable orbits: the attractors found besides irregular rotation."""
        return sum(s.stable for s in self.static) + sum(o.orbit.stable for o in self.orbits)

    def as_dict(self) -> dict[str, Any]:
        """JSON-ready summary. Moments in the parameters' units; ``moment_scale`` = E1 h^2 divides them into the paper's dimensionless moment (Fig. 2)."""
        return {
            "model": self.model,
            "moment": self.moment,
            "moment_scale": self.params.moment_scale,
            "particle": self.particle,
            "static": [s.as_dict() for s in self.static],
            "hopf_points": None if self.hopf is None else [h.as_dict() for h in self.hopf],
            "orbits": [o.as_dict() for o in self.orbits],
            "irregular": [r.as_dict() for r in self.irregular],
            "runs": [r.as_dict() for r in self.runs],
            "from_rest": {**self.from_rest.as_dict(), "relaxation": self.relaxation},
            "settings": self.settings,
            "status": str(self.status),
        }


def _wrap(angles: np.ndarray) -> np.ndarray:
    """Angles reduced to [-pi, pi): the rotating models are 2 pi periodic in every angle (Section 4)."""
    return (angles + math.pi) % (2 * math.pi) - math.pi


def _distance(a: np.ndarray, b: np.ndarray) -> float:
    """Largest difference of two states (3, 2N+1), or states stacked with their velocities (6, 2N+1), angles modulo 2 pi."""
    d = a - b
    d[ROW_INDEX["phi"]] = _wrap(d[ROW_INDEX["phi"]])
    return float(np.max(np.abs(d)))


def _wrapped(x: np.ndarray) -> np.ndarray:
    """A copy of the configuration x (3, 2N+1) with its angles in [-pi, pi)."""
    x = x.copy()
    x[ROW_INDEX["phi"]] = _wrap(x[ROW_INDEX["phi"]])
    return x


def _residual(params: ChainParams, model: Model, x: np.ndarray, moment: float, particle: int) -> float:
    r = pack(params, model.compiled_forces(params, x))
    r[moment_dof(params, particle)] += moment
    return float(np.max(np.abs(r))) if r.size else 0.0


def _static_states(params: ChainParams, model: Model, moment: float, particle: int) -> tuple[list[StaticState], list[HopfPoint] | None]:
    """The static states at ``moment`` on the branch from rest (over one full turn for a rotating model), and the
    branch's Hopf points (none for a conservative model: with damping its unstable eigenvalues are K's negative ones;
    None where not searched, beyond the dense limit: module docstring)."""
    col = column(params, particle)
    hopf: list[HopfPoint] | None = []
    if not model.rotates:
        x = solve_equilibrium(params, model, moment_load(moment, particle))
        states = [x]
    else:
        branch = continue_in_moment(params, model, particle=particle, phi0_stop=2 * math.pi)
        if not model.conservative:
            hopf = hopf_points(params, model, branch) if 2 * n_free(params) <= DENSE_LIMIT else None
        states = []
        m = branch.moment - moment
        for i in range(len(m) - 1):
            if m[i] == 0.0 and i > 0:
                continue  # counted as the end of the previous interval
            if not (m[i] * m[i + 1] < 0 or m[i + 1] == 0.0 or (i == 0 and m[0] == 0.0)):
                continue
            if i == 0 and m[0] == 0.0:
                states.append(branch.x[0])
                continue
            states.append(_solve_crossing(params, model, moment, particle, branch, i))
    out: list[StaticState] = []
    for x in states:
        if any(_distance(x, s.x) < STATE_ATOL for s in out):
            continue
        residual = _residual(params, model, x, moment, particle)
        checks = static_stability(params, model, x), dynamic_stability(params, model, x)
        out.append(StaticState(x, float(x[ROW_INDEX["phi"], col]), residual, *checks))
    return out, hopf


def _solve_crossing(params: ChainParams, model: Model, moment: float, particle: int, branch, i: int) -> np.ndarray:
    """The static state at ``moment`` between the traced points i and i + 1 of ``branch``."""
    col = column(params, particle)
    m0, m1 = branch.moment[i], branch.moment[i + 1]
    w = (moment - m0) / (m1 - m0)
    guess = (1 - w) * branch.x[i] + w * branch.x[i + 1]
    low, high = sorted((branch.phi0[i], branch.phi0[i + 1]))
    margin = 0.5 * (high - low) + 1e-9
    try:
        x = solve_equilibrium(params, model, moment_load(moment, particle), x0=guess, tol=1e-13)
        # Load control converges to the state between the two points unless the branch bends there (near a fold).
        if low - margin <= x[ROW_INDEX["phi"], col] <= high + margin and np.max(np.abs(x - guess)) < 0.5:
            return x
    except NewtonError:
        pass

    def excess(phi0: float) -> float:
        nearest = branch.x[i] if abs(phi0 - branch.phi0[i]) < abs(phi0 - branch.phi0[i + 1]) else branch.x[i + 1]
        return solve_rotation_controlled(params, model, phi0, particle=particle, x0=nearest, moment0=moment, tol=1e-13)[1] - moment

    phi = brentq(excess, branch.phi0[i], branch.phi0[i + 1], xtol=1e-15, rtol=4 * np.finfo(float).eps)
    return solve_rotation_controlled(params, model, phi, particle=particle, x0=guess, moment0=moment, tol=1e-13)[0]


def _section_states(orbit: PeriodicOrbit) -> list[np.ndarray]:
    """The orbit's states (x, v stacked (6, 2N+1)) at its k crossings of phi_0 = 0 mod 2 pi, phi_0 reduced to 0."""
    col = column(orbit.params, orbit.particle)
    sign = math.copysign(1.0, orbit.moment)
    out = [np.concatenate([orbit.x, orbit.v])]
    if orbit.turns == 1:
        return out
    times = np.linspace(0.0, orbit.period, SAMPLES_PER_TURN * orbit.turns + 1)[1:]
    phi = sign * orbit.trajectory(times)[0][:, ROW_INDEX["phi"], col]

    def state(t: float) -> tuple[np.ndarray, np.ndarray]:
        x, v = orbit.trajectory(np.array([t]))
        return x[0], v[0]

    def past(t: float, target: float) -> float:
        return sign * state(t)[0][ROW_INDEX["phi"], col] - target if t > 0 else -target

    for j in range(1, orbit.turns):
        target = 2 * math.pi * j
        after = int(np.argmax(phi >= target))
        t_low = 0.0 if after == 0 else times[after - 1]
        t = brentq(lambda s, target=target: past(s, target), t_low, times[after], xtol=1e-13)
        x, v = state(t)
        x = x.copy()
        x[ROW_INDEX["phi"], col] -= sign * target
        out.append(np.concatenate([x, v]))
    return out


def _least_turns(orbit: PeriodicOrbit) -> PeriodicOrbit:
    """The orbit with its least number of turns a period (a k-turn orbit may be a j-turn one run k / j times)."""
    k = orbit.turns
    col = column(orbit.params, orbit.particle)
    for j in range(1, k):
        if k % j:
            continue
        x, v = orbit.trajectory(np.array([orbit.period * j / k]))
        shifted = x[0].copy()
        shifted[ROW_INDEX["phi"], col] -= math.copysign(2 * math.pi * j, orbit.moment)
        if max(_distance(shifted, orbit.x), np.max(np.abs(v[0] - orbit.v))) < 1e3 * STATE_ATOL:
            try:
                return find_periodic_orbit(orbit.params, orbit.model, orbit.moment, turns=j, particle=orbit.particle,
                                           guess=(orbit.x, orbit.v, orbit.period * j / k))  # fmt: skip
            except OrbitError:
                return orbit
    return orbit


class _Catalogue:
    """The states found so far, each found once."""

    def __init__(self, static: list[StaticState]):
        self.static = static
        self.orbits: list[FoundOrbit] = []
        self.irregular: list[IrregularRotation] = []
        self._sections: list[list[np.ndarray]] = []

    def add_static(self, params: ChainParams, model: Model, x: np.ndarray, moment: float, particle: int, start: str) -> int:
        for i, s in enumerate(self.static):
            if _distance(x, s.x) < 1e3 * STATE_ATOL:
                s.found_from.append(start)
                return i
        x = _wrapped(x) if model.rotates else x
        phi0 = float(x[ROW_INDEX["phi"], column(params, particle)])
        residual = _residual(params, model, x, moment, particle)
        checks = static_stability(params, model, x), dynamic_stability(params, model, x)
        self.static.append(StaticState(x, phi0, residual, *checks, on_branch=False, found_from=[start]))
        return len(self.static) - 1

    def add_orbit(self, orbit: PeriodicOrbit, start: str) -> int:
        orbit = _least_turns(orbit)
        start_state = np.concatenate([orbit.x, orbit.v])
        for i, found in enumerate(self.orbits):
            other = found.orbit
            if other.turns != orbit.turns or abs(other.period - orbit.period) > PERIOD_RTOL * other.period:
                continue
            if any(_distance(start_state, s) < 1e3 * STATE_ATOL for s in self._sections[i]):
                if start not in found.found_from:
                    found.found_from.append(start)
                return i
        self.orbits.append(FoundOrbit(orbit, [start]))
        self._sections.append(_section_states(orbit))
        return len(self.orbits) - 1

    def add_irregular(self, rotation: IrregularRotation, start: str) -> int:
        for i, other in enumerate(self.irregular):
            # One chaotic state seen from two starts: the same windows, rates overlapping.
            if other.window_turns == rotation.window_turns and rotation.rate_min <= other.rate_max and other.rate_min <= rotation.rate_max:
                other.found_from.append(start)
                return i
        rotation.found_from.append(start)
        self.irregular.append(rotation)
        return len(self.irregular) - 1


def _shooting_guess(params: ChainParams, model: Model, moment: float, turns: int, particle: int, x: np.ndarray, v: np.ndarray):
    """A start for the shooting with ``turns`` turns from a run's end: on the section phi_0 = 0, every angle in [-pi, pi)."""
    x0, v0, period = initial_guess(params, model, moment, turns=turns, particle=particle, x0=x, v0=v, transient_turns=turns)
    return _wrapped(x0), v0, period


def _follow(
    params: ChainParams,
    model: Model,
    moment: float,
    particle: int,
    x0: np.ndarray,
    v0: np.ndarray,
    start: str,
    catalogue: _Catalogue,
    *,
    t_long: float,
    max_turns: int,
    window_turns: int,
) -> Run:
    """Run ``t_long`` from (x0, v0) and name what the run reached (adding it to the catalogue)."""
    sign = math.copysign(1.0, moment) if moment else 1.0
    run = integrate(
        params, model, moment_load(moment, particle), t_end=t_long, x0=x0, v0=v0, method="yoshida4", n_frames=2, throw=True,
        turns=TurnWatch(particle, sign, keep=KEEP_TURNS),
    )  # fmt: skip
    x, v = run.x[-1], run.v[-1]
    times = run.turns.times[run.turns.times > 0.5 * t_long]
    if times.size < max(4 * max_turns + 1, window_turns + 2):
        if float(np.max(np.abs(v))) < REST_SPEED:
            try:
                x = solve_equilibrium(params, model, moment_load(moment, particle), x0=x, tol=1e-13)
            except NewtonError:
                return Run(start, "not_settled", None, "at rest, but Newton did not converge from the run's end")
            return Run(start, "static", catalogue.add_static(params, model, x, moment, particle, start))
        return Run(
            start,
            "not_settled",
            None,
            f"{times.size} turns in the second half of the run and still moving: a slow transient (try a longer t_long)",
        )
    for k in range(1, 2 * max_turns + 1):
        spans = times[k:] - times[:-k]
        if np.ptp(spans) <= SPAN_RTOL * float(np.mean(spans)):
            try:
                guess = _shooting_guess(params, model, moment, k, particle, x, v)
                orbit = find_periodic_orbit(params, model, moment, turns=k, particle=particle, guess=guess)
            except OrbitError as err:
                return Run(start, "not_settled", None, f"repeats after {k} turns, but shooting failed: {err}")
            return Run(start, "orbit", catalogue.add_orbit(orbit, start))
    rates = sign * 2 * math.pi * window_turns / (times[window_turns:] - times[:-window_turns])
    rotation = IrregularRotation(
        float(np.mean(rates)), float(np.min(rates)), float(np.max(rates)), window_turns, int(times.size), 2 * max_turns
    )
    index = catalogue.add_irregular(rotation, start)
    # Unstable orbits embedded in the irregular rotation (the shooting converges to them from nearby).
    for k in range(1, max_turns + 1):
        try:
            guess = _shooting_guess(params, model, moment, k, particle, x, v)
            catalogue.add_orbit(
                find_periodic_orbit(params, model, moment, turns=k, particle=particle, guess=guess),
                f"{start}: shooting from its end, {k} turn(s)",
            )
        except OrbitError:
            continue
    return Run(start, "irregular", index)


def _random_start(params: ChainParams, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """Angles uniform in (-pi, pi), displacements of 0.1 h and velocities of 1 (normal), the held ones zero."""
    x = zeros(params)
    x[:2] = 0.1 * params.h * rng.standard_normal(x[:2].shape)
    x[ROW_INDEX["phi"]] = rng.uniform(-math.pi, math.pi, params.n_particles)
    v = rng.standard_normal(x.shape)
    held = fixed_mask(params)
    x[held], v[held] = 0.0, 0.0
    return x, v


@one_blas_thread
def states_at(
    params: ChainParams,
    model: str | Model,
    moment: float,
    *,
    particle: int = 0,
    starts: Sequence[str] = STARTS,
    turns: Sequence[int] = (1, 2, 3),
    random_starts: int = RANDOM_STARTS,
    seed: int = 0,
    perturbation: float = PERTURBATION,
    t_long: float = T_LONG,
    window_turns: int = WINDOW_TURNS,
    progress: ProgressCallback | None = None,
) -> CoexistingStates:
    """The static states, periodic orbits and irregular rotations at ``moment``, and which one the protocol from rest reaches.

    Parameters
    ----------
    params : ChainParams
        A chain held against rigid motion (a clamped end or two pinned ones): its static states are traced.
    model : str or Model
        A model that does not rotate (linear) gets its one static state and no orbit.
    moment : float
        Constant moment M on ``particle`` (the static branch is traced towards increasing M).
    particle : int
    starts : sequence of {"rest", "static", "random"}
        Long runs from rest, from every static state perturbed by +-``perturbation``
        (a seeded random direction), and from ``random_starts`` seeded random states.
    turns : sequence of int >= 1
        Shooting from rest with each number of turns a period; the long runs look for
        repetition after up to 2 max(turns) turns and shoot with it.
    random_starts, seed : int
    perturbation : float
        Largest component of a static state's perturbation.
    t_long : float
        Length of each long run (its second half is analysed).
    window_turns : int
        Turns per window of an irregular rotation's rates.
    progress : callable(done, total), optional

    Returns
    -------
    CoexistingStates

    Raises
    ------
    ValueError
        For a non-finite moment, an unknown start, turns < 1, a non-positive t_long,
        perturbation, or window, a negative random_starts, or a chain that can move
        rigidly (:func:`~cosserat_chain.state.require_held`).
    """
    model = get_model(model)
    if not (isinstance(moment, int | float) and math.isfinite(moment)):
        raise ValueError(f"moment must be a finite number, got {moment!r}")
    moment = float(moment)
    unknown = [s for s in starts if s not in STARTS]
    if unknown:
        raise ValueError(f"starts must be among {', '.join(STARTS)}, got {unknown[0]!r}")
    if not turns or not all(isinstance(k, int) and not isinstance(k, bool) and k >= 1 for k in turns):
        raise ValueError(f"turns must be integers >= 1 (turns of the loaded particle per period), got {turns!r}")
    for name, value in (("t_long", t_long), ("perturbation", perturbation)):
        if not (isinstance(value, int | float) and math.isfinite(value) and value > 0):
            raise ValueError(f"{name} must be a finite number > 0, got {value!r}")
    if not (isinstance(window_turns, int) and window_turns >= 1):
        raise ValueError(f"window_turns must be an integer >= 1, got {window_turns!r}")
    if not (isinstance(random_starts, int) and random_starts >= 0):
        raise ValueError(f"random_starts must be an integer >= 0, got {random_starts!r}")
    column(params, particle)
    # The static states on the branch from rest need the chain held against rigid motion.
    require_held(params)
    settings = {"starts": list(starts), "turns": list(turns), "random_starts": random_starts, "seed": seed,
                "perturbation": perturbation, "t_long": t_long, "window_turns": window_turns}  # fmt: skip
    static, hopf = _static_states(params, model, moment, particle)
    catalogue = _Catalogue(static)
    rng = np.random.default_rng(seed)
    plan: list[tuple[str, np.ndarray, np.ndarray]] = []
    if model.rotates:
        if "static" in starts:
            for i, s in enumerate(list(catalogue.static)):
                direction = rng.standard_normal(s.x.shape)
                direction[fixed_mask(params)] = 0.0
                direction *= perturbation / np.max(np.abs(direction))
                plan += [
                    (f"static {i} + perturbation", s.x + direction, zeros(params)),
                    (f"static {i} - perturbation", s.x - direction, zeros(params)),
                ]
        if "random" in starts:
            plan += [(f"random {j}", *_random_start(params, rng)) for j in range(random_starts)]
    shots = list(turns) if model.rotates and moment != 0.0 else []
    total = 1 + len(shots) + len(plan)
    done = 0

    def tick() -> None:
        nonlocal done
        done += 1
        if progress is not None:
            progress(done, total)

    # The protocol from rest (Section 4): one relaxation step, then its end followed until it settles.
    step = relax(params, model, moment, particle=particle)
    relaxation = {"status": str(step.status), "time": step.time, "turns": step.turns, "message": step.message,
                  "mean_angular_velocity": float(step.angular_velocity[column(params, particle)])}  # fmt: skip
    if step.status == Status.STATIC:
        x = solve_equilibrium(params, model, moment_load(moment, particle), x0=step.x, tol=1e-13)
        from_rest = Run("rest", "static", catalogue.add_static(params, model, x, moment, particle, "rest"))
    elif model.rotates:
        from_rest = _follow(params, model, moment, particle, step.x, step.v, "rest", catalogue, t_long=t_long,
                            max_turns=max(turns), window_turns=window_turns)  # fmt: skip
    else:
        from_rest = Run("rest", "not_settled", None, step.message)
    runs = [from_rest] if "rest" in starts else []
    tick()
    for k in shots:
        try:
            catalogue.add_orbit(find_periodic_orbit(params, model, moment, turns=k, particle=particle), f"shooting from rest, {k} turn(s)")
        except OrbitError:
            pass
        tick()
    for name, x0, v0 in plan:
        runs.append(
            _follow(
                params, model, moment, particle, x0, v0, name, catalogue, t_long=t_long, max_turns=max(turns), window_turns=window_turns
            )
        )
        tick()
    return CoexistingStates(
        params=params,
        model=model.name,
        moment=moment,
        particle=particle,
        static=catalogue.static,
        orbits=catalogue.orbits,
        irregular=catalogue.irregular,
        runs=runs,
        from_rest=from_rest,
        relaxation=relaxation,
        settings=settings,
        hopf=hopf,
    )
