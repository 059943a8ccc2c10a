"""Periodic orbits of any system: shooting, Floquet multipliers, and continuation in any parameter.

Contract
--------
For a :class:`~cosserat_chain.systems.base.System` M q'' = F(q; p) - C q' with state
y = (q, q') (2n), a periodic orbit of period T that turns k_i times in each angle i is a
solution of

    Phi_T(y0) - y0 - 2 pi k = 0,        f(y_ref) . (y0 - y_ref) = 0,          (O)

where Phi_t is the flow, k (2n,) holds the turns on the angle coordinates (zero on the
velocities and the other coordinates), and the second equation (a Poincare plane through
a reference point y_ref, normal to the flow there) fixes the phase. Unlike a section on one
coordinate, the plane is transversal wherever the reference orbit is, however a particle
backs up during a turn, so a continuation cannot stop at a section's false fold.

* :func:`flow` integrates the flow with its variational equations (the monodromy
  dPhi_T/dy0 and dPhi_T/dp of any named parameter p), by the package's compiled DOP853
  on a compiled system (:class:`~cosserat_chain.systems.base.FlowKernels`), otherwise by
  SciPy's DOP853 on the system's Python forces.
* :func:`find_orbit` solves (O) by Newton (:func:`cosserat_chain.numerics.kit.newton`)
  in (y0, T); the Floquet multipliers are the eigenvalues of the monodromy M, or above
  ||M|| = :data:`SEGMENTED_FROM` those of the periodic Schur form of its segments
  (:func:`orbit_multipliers`). Newton stops at max |R| <= tol or at the closure's noise floor,
  :data:`NOISE_ULPS` eps ||M|| |y0|, where that is larger (a long orbit next to a saddle).
* :func:`continue_orbits` follows the orbit in any parameter with the one
  pseudo-arclength driver (:func:`cosserat_chain.numerics.kit.continuation`), in
  (y0, log T, p); it locates folds of cycles (confirmed by a second multiplier at +1, or a
  double one split symmetrically about +1 by the monodromy's errors: :func:`second_multiplier_at_one`)
  and branch points, period doublings (a multiplier at -1) and tori (a complex pair on the
  unit circle) by the package's one mechanism for them (:mod:`~.cycle_events`: its test
  functions watched at every step, Brent's method in p, each trial an orbit solved at its
  p), and ends where the period diverges, with the end fitted from the
  period's growth, its uncertainty the fits' spread or its reach beyond the last orbit where
  larger (``end_method`` ``fitted``;
  :func:`~cosserat_chain.numerics.homoclinic.solve_branch_end` solves it), where the monodromy
  no longer shows the trivial multiplier within :data:`TRIVIAL_LOST` of +1 (single shooting's
  accuracy exhausted, the period growing on), or where an oscillation
  shrinks onto an equilibrium at a Hopf point (there the parameter turns too, with the
  equilibrium's pair at +1, but no fold of cycles is reported).
* A conservative system's orbits come in families: ``unfold=`` names a damping parameter
  that replaces the period as unknown (:class:`_Shooting`), so an orbit is found at a given
  period and the family is continued in the period or any other parameter.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field

import numpy as np

from ..errors import CosseratChainError
from ..linalg.threads import one_blas_thread
from ..models.base import no_ends
from ..systems.base import System, SystemDefinitionError
from . import cycle_events, dop853
from .brent import brentq
from .equilibria import EquilibriumNotFound, find_equilibrium
from .floquet import periodic_schur_multipliers
from .kit import BranchEnd, Continuation, Evaluation, EvaluationFailed, Event, continuation, newton

#: Tolerances of the shooting integrations.
RTOL = 1e-11
ATOL = 1e-11
#: Newton tolerance on max |R| of (O).
CLOSURE_TOL = 1e-9
#: Units of round-off in y0 that the closure resolves: y(T) moves by up to ||M|| times a change of y0, so max |R| cannot
#: be resolved below NOISE_ULPS eps ||M||_inf max(1, |y0|_inf) (:meth:`_Shooting.converged`); a long orbit near a
#: homoclinic loop (||M|| ~ 1e7 at T = 26 next to a saddle-focus) has its noise floor above CLOSURE_TOL.
NOISE_ULPS = 8.0
#: Above this ||M||_inf the eigenvalues of the formed monodromy carry errors up to O(1) (the trivial multiplier 6e-3
#: off 1 at T = 27 next to a saddle-focus, a fold's second one lost): the multipliers come instead from the periodic
#: Schur form of the period's segment matrices (:func:`orbit_multipliers`), each segment growing about SEGMENT_GROWTH.
SEGMENTED_FROM = 1e4
SEGMENT_GROWTH = 1e2
#: Two multipliers are a double one at +1 split by errors where their mean lies within this fraction of their half-split
#: from +1 (a split is symmetric about the block's trace; a real second multiplier at 1 + s beside the trivial one is not).
SPLIT_SYMMETRY = 0.25
#: A continuation ends where the multiplier nearest +1 (the trivial one) lies further from it than this: the monodromy
#: is too inaccurate to follow or test (near a fold its double multiplier may split by 0.7 and still be followed).
TRIVIAL_LOST = 0.5
#: Most DOP853 steps over one period, and per unit of time: a Newton trial that runs into a stiff or
#: blowing-up state fails in seconds instead of grinding through MAX_STEPS (a roto-breather's trial
#: below the band did).
MAX_STEPS = 10_000_000
STEPS_PER_TIME = 100_000
#: A multiplier within the square root of this of +1 confirms a located fold or branch point of cycles (a period
#: doubling's or torus's is confirmed by :func:`~.cycle_events.on_circle`).
CONFIRM_TOL = 1e-3
#: Largest |mu| - 1 of a conservative orbit's multiplier that still counts as on the unit circle: the
#: monodromy is accurate to about 1e-9, and a colliding pair splits like the square root of that.
CIRCLE_TOL = 1e-6
#: An oscillation within this (relative to the state's size) of an equilibrium with a pair of eigenvalues
#: within this (relative) of +-2 pi i / T has shrunk onto the equilibrium at a Hopf point.
HOPF_COLLAPSE = 1e-2


class OrbitNotFound(CosseratChainError, RuntimeError):
    """Newton's method on (O) did not converge."""


def flow(
    system: System, y0: np.ndarray, period: float, *, variations: bool, parameter: str | None = None, rtol: float = RTOL, atol: float = ATOL
):
    """y(T) from y0 and, with ``variations``, the monodromy dy(T)/dy0 (2n, 2n) and dy(T)/dp (2n,).

    Raises
    ------
    EvaluationFailed
        If the integration cannot finish: a blow-up, or more than MAX_STEPS steps or
        STEPS_PER_TIME steps per unit of time (whichever is fewer).
    """
    size = 2 * system.size
    ncols = size + 1 if variations else 0
    start = np.asarray(y0, dtype=float)
    if variations:
        start = np.concatenate([start, np.hstack([np.eye(size), np.zeros((size, 1))]).ravel()])
    end = _integrate(system, start, np.array([0.0, period]), ncols, parameter if variations else None, rtol, atol)[-1]
    if not variations:
        return end[:size], None, None
    cols = end[size:].reshape(size, ncols)
    return end[:size], cols[:, :size], cols[:, size]


def states(system: System, y0: np.ndarray, times: np.ndarray, *, rtol: float = RTOL, atol: float = ATOL) -> np.ndarray:
    """The states y (len(times), 2n) at ``times`` (increasing, from ``times[0]`` where y = y0), in one integration.

    Raises
    ------
    EvaluationFailed
        As :func:`flow`.
    """
    return _integrate(system, np.asarray(y0, dtype=float), np.asarray(times, dtype=float), 0, None, rtol, atol)


def _integrate(system: System, start: np.ndarray, times: np.ndarray, ncols: int, parameter: str | None, rtol: float, atol: float):
    """The state (with ``ncols`` variational columns, the last one dy/d``parameter``) at every time of ``times``:
    the package's compiled DOP853 on a compiled system, SciPy's otherwise."""
    n = system.size
    inverse = 1.0 / system.mass()
    rate = system.damping() * inverse
    if parameter is not None:
        d_inverse, d_rate = system.parameter_mass_damping(parameter)
    else:
        d_inverse = d_rate = np.zeros(n)
    span = float(times[-1] - times[0])
    kernels = system.flow_kernels()
    if kernels is None:
        return _scipy_integrate(system, start, times, ncols > 0, parameter, inverse, rate, d_inverse, d_rate, rtol, atol)
    index = kernels.parameter_index[parameter] if parameter is not None else -1
    ipar = np.array([*kernels.head, ncols, index], dtype=np.int64)
    rpar = np.concatenate([inverse, rate, d_inverse, d_rate])
    sol = dop853.solve(
        kernels.rhs,
        _no_force,
        kernels.coef,
        rpar,
        ipar,
        start,
        times,
        rtol=rtol,
        atol=atol,
        max_steps=min(MAX_STEPS, int(STEPS_PER_TIME * (1.0 + span))),
        end_force=no_ends,
    )
    if not sol.success:
        raise EvaluationFailed(f"the flow of {system.name} over T={span:.10g} failed: {sol.message}")
    return sol.y


def _scipy_integrate(system, start, times, variations, parameter, inverse, rate, d_inverse, d_rate, rtol, atol):
    from scipy.integrate import solve_ivp

    n = system.size

    def field(t, z):
        q, v = z[:n], z[n : 2 * n]
        f = system.forces(q)
        out = np.empty_like(z)
        out[:n] = v
        out[n : 2 * n] = inverse * f - rate * v
        if variations:
            cols = z[2 * n :].reshape(2 * n, 2 * n + 1)
            d = np.empty_like(cols)
            d[:n] = cols[n:]
            d[n:] = inverse[:, None] * (system.force_jacobian(q) @ cols[:n]) - rate[:, None] * cols[n:]
            if parameter is not None:
                d[n:, -1] += inverse * system.parameter_forces(q, parameter) + d_inverse * f - d_rate * v
            out[2 * n :] = d.ravel()
        return out

    sol = solve_ivp(field, (times[0], times[-1]), start, method="DOP853", t_eval=times, rtol=rtol, atol=atol)
    if not sol.success or not np.all(np.isfinite(sol.y)):
        raise EvaluationFailed(f"the flow of {system.name} over T={times[-1] - times[0]:.10g} failed: {sol.message}")
    return sol.y.T


def _no_force_impl(x, coef, out, start, stop):  # pragma: no cover - compiled
    pass


def _compiled_no_force():
    from numba import njit

    from ..models.base import FORCE_SIGNATURE

    return njit(FORCE_SIGNATURE, cache=True, nogil=True)(_no_force_impl)


_no_force = _compiled_no_force()


def turns_vector(system: System, turns: Mapping[str | int, int] | np.ndarray | None) -> np.ndarray:
    """The turns per period of every coordinate (n,) from a mapping name-or-index -> k, checked against the angles."""
    k = np.zeros(system.size)
    if turns is None:
        return k
    if isinstance(turns, Mapping):
        names = system.coordinates
        for key, value in turns.items():
            i = names.index(key) if isinstance(key, str) and key in names else key
            if not (isinstance(i, int | np.integer) and 0 <= i < system.size):
                raise ValueError(f"turns: {key!r} is not a coordinate of {system.name} (coordinates {', '.join(names)})")
            k[i] = value
    else:
        k = np.asarray(turns, dtype=float)
        if k.shape != (system.size,):
            raise ValueError(f"turns must have shape ({system.size},), got {k.shape}")
    if np.any(k != np.round(k)):
        raise ValueError(f"turns must be whole numbers, got {k}")
    bad = np.flatnonzero((k != 0) & ~system.angles)
    if bad.size:
        raise ValueError(f"turns on {system.coordinates[bad[0]]!r}, which is not an angle of {system.name}: only angles can turn")
    return k


#: Round-off allowed in F(q + 2 pi k) - F(q), relative to the largest force there, for turns k the forces are periodic in.
PERIODIC_RTOL = 1e-9


def require_periodic_turns(system: System, q: np.ndarray, turns: np.ndarray) -> None:
    """Refuse turns the forces are not 2 pi periodic in: F(q + 2 pi k) must equal F(q) (checked at ``q``).

    Only then is a state that gains 2 pi k in a period the same state again, and (O) an orbit: a
    lattice bonded by k/2 (phi_r - phi_l)^2 turns its angles together, never one alone.

    Raises
    ------
    SystemDefinitionError
        Naming the turning coordinates and how far the forces move.
    """
    if not np.any(turns):
        return
    q = np.where(system.angles, np.mod(q, 2 * math.pi), q)  # whole turns of a long run left out: round-off stays small
    before, after = system.forces(q), system.forces(q + 2 * math.pi * turns)
    moved = float(np.max(np.abs(after - before)))
    if moved > PERIODIC_RTOL * max(1.0, float(np.max(np.abs(before)))):
        turning = ", ".join(f"{system.coordinates[i]} {int(turns[i]):+d}" for i in np.flatnonzero(turns))
        raise SystemDefinitionError(
            f"turns {turning}: the forces of {system.name} are not 2 pi periodic in these turns (F moves by up to "
            f"{moved:.3g} when they are made), so no orbit turning so closes; turn the coordinates whose differences "
            "the forces depend on together, or write the coupling periodic (e.g. 1 - cos(phi_r - phi_l))"
        )


@dataclass
class Orbit:
    """A periodic orbit of a system: its start y0 = (q0, v0) on the phase plane, period, turns and Floquet multipliers."""

    system: System
    y0: np.ndarray
    period: float
    turns: np.ndarray
    multipliers: np.ndarray
    closure: float
    iterations: int
    monodromy: np.ndarray = field(repr=False)
    #: The damping parameter that unfolded a conservative orbit (None for a dissipative one).
    unfold: str | None = None

    @property
    def unfolding(self) -> float | None:
        """The unfolding parameter's value at the orbit: zero to the closure's accuracy (None without one)."""
        return None if self.unfold is None else self.system.parameter(self.unfold)

    @property
    def q0(self) -> np.ndarray:
        return self.y0[: self.system.size]

    @property
    def v0(self) -> np.ndarray:
        return self.y0[self.system.size :]

    def parameter(self, name: str) -> float:
        return self.system.parameter(name)

    @property
    def nontrivial_multipliers(self) -> np.ndarray:
        """The multipliers without the one closest to +1 (the flow direction), and for a conservative
        orbit without the second one there (the energy's)."""
        mu = self.multipliers
        for _ in range(1 if self.unfold is None else 2):
            mu = np.delete(mu, int(np.argmin(np.abs(mu - 1.0))))
        return mu

    @property
    def max_multiplier(self) -> float:
        return float(np.max(np.abs(self.nontrivial_multipliers), initial=0.0))

    @property
    def stable(self) -> bool:
        """All nontrivial multipliers inside the unit circle (on it, within CIRCLE_TOL, for a conservative orbit)."""
        return self.max_multiplier < (1.0 if self.unfold is None else 1.0 + CIRCLE_TOL)

    def trajectory(self, times: np.ndarray, *, rtol: float = RTOL, atol: float = ATOL) -> np.ndarray:
        """States y (len(times), 2n) along the orbit at ``times`` (increasing, from 0), in one integration from y0."""
        times = np.asarray(times, dtype=float)
        if times.size and times[0] == 0.0:
            return states(self.system, self.y0, times, rtol=rtol, atol=atol)
        return states(self.system, self.y0, np.concatenate([[0.0], times]), rtol=rtol, atol=atol)[1:]

    def as_dict(self) -> dict:
        return {
            **self.system.describe(),
            "period": self.period,
            "turns": self.turns.tolist(),
            "q0": self.q0.tolist(),
            "v0": self.v0.tolist(),
            "multipliers_abs": np.abs(self.multipliers).tolist(),
            "max_multiplier": self.max_multiplier,
            "stable": self.stable,
            "closure": self.closure,
        }


#: The name under which the period is an unknown or the continued variable (as log T).
PERIOD = "period"
#: Along :func:`continue_orbits`, a trial period more than this many times the last orbit's (or less than its inverse)
#: is not integrated: a Newton iterate thrown far off (a T of 10^7 next to orbits of T = 7, a million periods'
#: integration) fails at once instead, and the continuation shortens its step.
PERIOD_JUMP = 16.0


class _Shooting:
    """Equations (O) of one system, turns and phase plane, in the unknowns w = (y0, *unknowns).

    Each entry of ``unknowns`` is :data:`PERIOD` (w holds log T) or a parameter of the system.
    The period is an unknown of a dissipative orbit. A conservative system's orbits come in
    families along which the period varies, and each is found at a fixed period with an
    unfolding parameter unknown instead: a damping that makes every orbit but the undamped
    one lose energy, so Newton returns it at zero (Munoz-Almaraz et al., Physica D 181, 2003).
    """

    def __init__(self, system: System, turns: np.ndarray, reference: np.ndarray, period: float, unknowns: tuple[str, ...], tol, rtol, atol):
        self.system, self.period, self.unknowns, self.tol, self.rtol, self.atol = system, period, unknowns, tol, rtol, atol
        self.last_period: float | None = None  # set by a continuation (set_reference): the scale of PERIOD_JUMP
        #: ||M||_inf of the last monodromy computed, and the last y0 evaluated (:meth:`converged`'s noise floor).
        self.growth, self.current = 1.0, np.asarray(reference, dtype=float)
        for name in unknowns:
            if name != PERIOD:
                system.parameter(name)
        n = system.size
        require_periodic_turns(system, np.asarray(reference, dtype=float)[:n], turns)
        self.shift = np.concatenate([2 * math.pi * turns, np.zeros(n)])
        self.turns = turns
        self.set_reference(reference)

    def set_reference(self, reference: np.ndarray, period: float | None = None) -> None:
        """The phase plane through ``reference``; ``period``: the orbit's there, the scale of :data:`PERIOD_JUMP`."""
        self.reference = np.array(reference, dtype=float)
        self.normal = self.system.vector_field(self.reference)
        if period is not None:
            self.last_period = period

    def floor(self, y0: np.ndarray, monodromy: np.ndarray | None) -> float:
        """The smallest max |R| the closure resolves at y0: :data:`NOISE_ULPS` units of round-off of y0 carried by the
        monodromy (the last one computed where this evaluation has none)."""
        if monodromy is not None:
            self.growth = float(np.linalg.norm(monodromy, np.inf))
        return NOISE_ULPS * np.finfo(float).eps * self.growth * max(1.0, float(np.max(np.abs(y0))))

    def converged(self, evaluation: Evaluation, norm: float) -> bool:
        """Newton's test: max |R| <= tol, or the closure's noise floor (:meth:`floor`) where that is larger: a long
        orbit's R cannot fall below it, and Newton would otherwise grind in the noise and the continuation give up."""
        return norm <= max(self.tol, self.floor(self.current, evaluation.data))

    def pack(self, orbit: Orbit) -> np.ndarray:
        extra = [math.log(orbit.period) if u == PERIOD else orbit.system.parameter(u) for u in self.unknowns]
        return np.concatenate([orbit.y0, extra])

    def split(self, w: np.ndarray) -> tuple[np.ndarray, float, System]:
        size = 2 * self.system.size
        period, values = self.period, {}
        for i, name in enumerate(self.unknowns):
            if name == PERIOD:
                if not (math.isfinite(w[size + i]) and -50 < w[size + i] < 50):
                    raise EvaluationFailed(f"log T = {w[size + i]!r} out of range")
                period = math.exp(w[size + i])
                if self.last_period is not None and not self.last_period / PERIOD_JUMP <= period <= self.last_period * PERIOD_JUMP:
                    raise EvaluationFailed(
                        f"T = {period:.6g} is more than {PERIOD_JUMP:g} times off the last orbit's {self.last_period:.6g}"
                    )
            else:
                values[name] = float(w[size + i])
        return w[:size], period, self.system.with_parameters(**values) if values else self.system

    def evaluate(self, w: np.ndarray, jacobian: bool) -> Evaluation:
        size = 2 * self.system.size
        y0, period, system = self.split(w)
        self.current = y0
        names = [u for u in self.unknowns if u != PERIOD]
        first = names[0] if (jacobian and names) else None
        end, mono, d_first = flow(system, y0, period, variations=jacobian, parameter=first, rtol=self.rtol, atol=self.atol)
        residual = np.append(end - y0 - self.shift, self.normal @ (y0 - self.reference))
        if not jacobian:
            return Evaluation(residual)
        derivative = {first: d_first} if first else {}
        for name in names[1:]:
            derivative[name] = flow(system, y0, period, variations=True, parameter=name, rtol=self.rtol, atol=self.atol)[2]
        cols = [mono - np.eye(size)]
        for name in self.unknowns:
            cols.append((period * system.vector_field(end))[:, None] if name == PERIOD else derivative[name][:, None])
        top = np.hstack(cols)
        bottom = np.concatenate([self.normal, np.zeros(top.shape[1] - size)])
        return Evaluation(residual, np.vstack([top, bottom]), mono)

    def orbit(self, w: np.ndarray, ev: Evaluation, iterations: int) -> Orbit:
        y0, period, system = self.split(w)
        return Orbit(
            system=system,
            y0=y0.copy(),
            period=period,
            turns=self.turns,
            multipliers=orbit_multipliers(system, y0, period, ev.data, rtol=self.rtol, atol=self.atol),
            closure=float(np.max(np.abs(ev.residual[:-1]))),
            iterations=iterations,
            monodromy=ev.data,
        )


def orbit_multipliers(
    system: System, y0: np.ndarray, period: float, monodromy: np.ndarray, *, rtol: float = RTOL, atol: float = ATOL
) -> np.ndarray:
    """The Floquet multipliers of the orbit from y0: the eigenvalues of ``monodromy`` up to ||M||_inf =
    :data:`SEGMENTED_FROM`, above it those of the periodic Schur form of m segment matrices (the flow's variations over
    T / m each, m = log ||M|| / log :data:`SEGMENT_GROWTH` rounded up), which keeps the multipliers near the unit circle
    accurate however large the others are (:func:`~.floquet.periodic_schur_multipliers`)."""
    growth = float(np.linalg.norm(monodromy, np.inf))
    if not growth > SEGMENTED_FROM:
        return np.linalg.eigvals(monodromy)
    count = math.ceil(math.log(growth) / math.log(SEGMENT_GROWTH))
    y, segments = np.asarray(y0, dtype=float), []
    for _ in range(count):
        y, segment, _ = flow(system, y, period / count, variations=True, rtol=rtol, atol=atol)
        segments.append(segment)
    return periodic_schur_multipliers(segments).values


def read_guess(system: System, guess, turns, orbits: tuple[type, ...]) -> tuple[np.ndarray, float, np.ndarray]:
    """(y0, T, turns vector) of a guess: an orbit of one of the types ``orbits`` (its turns unless ``turns`` is given)
    or a pair (y0, T) with ``turns``; y0 must be 2n finite numbers and T finite and > 0 (ValueError otherwise)."""
    if isinstance(guess, orbits):
        y0, period, k = guess.y0, guess.period, guess.turns if turns is None else turns_vector(system, turns)
    else:
        y0, period = guess
        k = turns_vector(system, turns)
    y0 = np.asarray(y0, dtype=float)
    if y0.shape != (2 * system.size,) or not np.all(np.isfinite(y0)):
        raise ValueError(f"the guessed state must be 2n = {2 * system.size} finite numbers, got shape {y0.shape}")
    if not (math.isfinite(period) and period > 0):
        raise ValueError(f"the guessed period must be finite and > 0, got {period!r}")
    return y0, period, k


@one_blas_thread
def find_orbit(
    system: System,
    guess: tuple[np.ndarray, float] | Orbit,
    *,
    turns: Mapping[str | int, int] | np.ndarray | None = None,
    tol: float = CLOSURE_TOL,
    max_iterations: int = 25,
    rtol: float = RTOL,
    atol: float = ATOL,
    unfold: str | None = None,
) -> Orbit:
    """The periodic orbit near ``guess``, by Newton on (O).

    Parameters
    ----------
    system : System
    guess : (y0 (2n,), T) or Orbit
        A state on or near the orbit and its period (e.g. from :func:`settled_guess`).
    turns : mapping coordinate (name or index) -> k, or (n,) array
        Turns per period of the angles (a rotation); none for an oscillation.
    tol : float
        Newton stops when max |R| <= tol.
    unfold : str, optional
        For a conservative system (no damping at the orbit): the period is kept at the guess's and
        this damping parameter is the unknown instead (the unfolding of :class:`_Shooting`); it is
        returned at zero to the closure's accuracy, and :attr:`Orbit.unfolding` says how near.

    Raises
    ------
    OrbitNotFound
        If Newton does not converge (a guess from a nearby parameter or a settled simulation helps).
    """
    y0, period, k = read_guess(system, guess, turns, (Orbit,))
    unknowns = (PERIOD,) if unfold is None else (unfold,)
    shooting = _Shooting(system, k, y0, period, unknowns, tol, rtol, atol)
    start = np.append(y0, math.log(period) if unfold is None else system.parameter(unfold))
    corrected = newton(shooting.evaluate, start, converged=shooting.converged, max_iterations=max_iterations)
    if not corrected.converged:
        raise OrbitNotFound(
            f"Newton on the periodic orbit of {system.name} {corrected.status} after {corrected.iterations} iterations "
            f"(max|R| = {corrected.norm:.3g}); start from a settled simulation (settled_guess) or a nearby parameter's orbit"
        )
    orbit = shooting.orbit(corrected.w, corrected.evaluation, corrected.iterations)
    orbit.unfold = unfold
    return orbit


#: Upward crossings of its mean after the first among which :func:`settled_guess` seeks an oscillation's return.
OSCILLATION_CROSSINGS = 4


def settled_guess(
    system: System,
    y0: np.ndarray,
    *,
    coordinate: str | int,
    turns: int = 1,
    transient: float = 200.0,
    window: float = 200.0,
    samples: int = 4000,
) -> tuple[np.ndarray, float]:
    """A start for :func:`find_orbit` from a simulation: after ``transient``, the state where
    ``coordinate`` crosses a multiple of 2 pi and the time it takes to gain 2 pi ``turns`` more.

    With ``turns`` 0 (an oscillation, no angle turning): the state where ``coordinate`` crosses
    its mean over the window upwards, and the time to the first later upward crossing (among the
    next :data:`OSCILLATION_CROSSINGS`) whose state lies within ten times the nearest one's distance
    of it: the period also where the oscillation crosses its mean more than once a period.

    Raises
    ------
    OrbitNotFound
        If the coordinate does not turn ``turns`` times within ``window`` (does not oscillate, for
        ``turns`` 0).
    """
    i = system.coordinates.index(coordinate) if isinstance(coordinate, str) else int(coordinate)
    y = flow(system, np.asarray(y0, dtype=float), transient, variations=False)[0]
    times = np.linspace(0.0, window, samples)
    sampled = states(system, y, times, rtol=1e-10, atol=1e-10)
    if turns == 0:
        value = sampled[:, i]
        above = value > value.mean()
        ups = np.flatnonzero(~above[:-1] & above[1:]) + 1
        if ups.size < 2:
            raise OrbitNotFound(
                f"{system.coordinates[i]} did not oscillate about its mean in a window of {window:g} after a transient of {transient:g}"
            )
        later = ups[1 : OSCILLATION_CROSSINGS + 1]
        distance = np.linalg.norm(sampled[later] - sampled[ups[0]], axis=1)
        b = later[np.flatnonzero(distance <= 10.0 * distance.min() + 1e-9)[0]]
        return sampled[ups[0]].copy(), float(times[b] - times[ups[0]])
    angle = sampled[:, i]
    level = np.floor(angle / (2 * math.pi))
    crossings = np.flatnonzero(np.diff(level) != 0)
    if crossings.size < turns + 1:
        raise OrbitNotFound(
            f"{system.coordinates[i]} did not turn {turns} times in a window of {window:g} after a transient of {transient:g}"
        )
    a, b = crossings[0], crossings[turns]
    start = sampled[a + 1].copy()
    # Whole turns are dropped from the angles: the orbit is the same, the numbers small.
    angles = np.flatnonzero(system.angles)
    start[angles] -= 2 * math.pi * np.floor(start[angles] / (2 * math.pi))
    return start, float(times[b + 1] - times[a + 1])


@dataclass
class OrbitBranch:
    """Orbits continued in one parameter, with their located events and how the branch ended."""

    parameter: str
    orbits: list[Orbit]
    events: list
    end: BranchEnd
    message: str
    end_value: float | None = None
    end_uncertainty: float | None = None
    #: How ``end_value`` was found: ``fitted`` (the period's growth) or ``solved`` (a homoclinic loop's boundary-value
    #: problem, :func:`~cosserat_chain.numerics.homoclinic.solve_branch_end`); None where there is no end value.
    end_method: str | None = None

    @property
    def values(self) -> np.ndarray:
        return np.array([o.period if self.parameter == PERIOD else o.parameter(self.parameter) for o in self.orbits])

    @property
    def periods(self) -> np.ndarray:
        return np.array([o.period for o in self.orbits])

    def as_dict(self) -> dict:
        return {
            "parameter": self.parameter,
            "values": self.values.tolist(),
            "periods": self.periods.tolist(),
            "max_multiplier": [o.max_multiplier for o in self.orbits],
            "events": [{"kind": e.kind, "value": e.parameter, "period": e.point.period if e.located else None} for e in self.events],
            "end": str(self.end),
            "message": self.message,
            "end_value": self.end_value,
            "end_uncertainty": self.end_uncertainty,
            # A fit of the period's growth unless a homoclinic solve replaced it (homoclinic.solve_branch_end).
            "end_method": None if self.end_value is None else (self.end_method or "fitted"),
        }


class _OrbitProblem:
    """(O) with the parameter unknown, for :func:`cosserat_chain.numerics.kit.continuation`."""

    def __init__(
        self,
        shooting: _Shooting,
        period_max: float,
        limits: tuple[float, float],
        until_unstable: bool,
        start_stable: bool,
        unfold: str | None,
        stop_at: tuple[str, ...] = (),
    ):
        self.shooting, self.tol, self.unfold = shooting, shooting.tol, unfold
        self.parameter_name = shooting.unknowns[-1]
        self.period_max, self.limits, self.until_unstable, self.start_stable = period_max, limits, until_unstable, start_stable
        #: The located point where an oscillation shrank onto an equilibrium (a Hopf point), the branch's end.
        self.collapsed: Orbit | None = None
        #: The period doublings and tori that end the branch once found (:meth:`stop`).
        self.stop_at = tuple(kind for kind in stop_at if kind in cycle_events.CIRCLE_KINDS)
        #: The last step accepted (previous, candidate), and the period doublings and tori found over each step by
        #: :meth:`stop`, keyed by the two orbits' ids (reused by :meth:`circle_events`).
        self.step: tuple[Orbit, Orbit] | None = None
        #: The last orbit :meth:`stop` saw (the previous one where a step was accepted without :meth:`accept`).
        self.last: Orbit | None = None
        self.found: dict[tuple[int, int], list[dict]] = {}

    def evaluate(self, w, jacobian):
        return self.shooting.evaluate(w, jacobian)

    def converged(self, evaluation: Evaluation, norm: float) -> bool:
        return self.shooting.converged(evaluation, norm)

    def point(self, w, ev, iterations) -> Orbit:
        orbit = self.shooting.orbit(w, ev, iterations)
        orbit.unfold = self.unfold
        return orbit

    def accept(self, previous: Orbit, candidate: Orbit) -> bool:
        # The next phase plane passes through the orbit just found.
        self.shooting.set_reference(candidate.y0, candidate.period)
        self.step = (previous, candidate)
        return True

    def tests(self, orbit: Orbit) -> dict[str, float]:
        # Period doublings and tori are the circle tests' (:meth:`circle_events`); a conservative orbit's multipliers
        # lie on the circle up to round-off, and only leaving it counts.
        return {"stability": 1.0 if orbit.stable else -1.0}

    def value(self, orbit: Orbit) -> float:
        """The continued parameter's value at ``orbit``."""
        name = self.shooting.unknowns[-1]
        return orbit.period if name == PERIOD else orbit.parameter(name)

    def solve(self, value: float, a: Orbit, b: Orbit) -> Orbit:
        """The orbit at the continued parameter's ``value`` between the orbits a and b: Newton on (O) from the orbit
        interpolated linearly in the parameter (y0 and log T), on the phase plane through that start."""
        theta = (value - self.value(a)) / (self.value(b) - self.value(a))
        start = (1.0 - theta) * a.y0 + theta * b.y0
        period = math.exp((1.0 - theta) * math.log(a.period) + theta * math.log(b.period))
        system = a.system.with_parameters(**{self.shooting.unknowns[-1]: value})
        shooting = self.shooting
        return find_orbit(system, (start, period), turns=a.turns, tol=shooting.tol, rtol=shooting.rtol, atol=shooting.atol)

    def circle_events(self, a: Orbit, b: Orbit) -> list[dict]:
        """The period doublings and tori between the consecutive orbits a and b (:func:`~.cycle_events.circle_events_between`,
        Brent's method in the parameter); none for a conservative family, whose multipliers lie on the circle."""
        key = (id(a), id(b))
        if key not in self.found:
            dissipative = a.unfold is None and self.shooting.unknowns[-1] != PERIOD
            self.found[key] = cycle_events.circle_events_between(a, b, self.solve, value=self.value) if dissipative else []
        return self.found[key]

    def confirm(self, kind: str, orbit: Orbit) -> bool:
        if kind in ("fold", "branch_point") and orbit.unfold is None and _shrunk_onto_equilibrium(orbit):
            # The parameter turns at a Hopf point too (p - p_H ~ amplitude^2), with the equilibrium's pair
            # exp(+-i omega T) at +1: no fold of cycles, the end of the family.
            self.collapsed = orbit
            return False
        if kind == "fold" or (kind == "branch_point" and orbit.unfold is None):
            # A branch point of cycles has a second multiplier at +1, as a fold (the parameter does not turn there:
            # the kit's test is the sign of det [dR/dw; t], which a fold leaves alone).
            return second_multiplier_at_one(orbit.multipliers)
        return True

    def stop(self, orbit: Orbit):
        name = self.shooting.unknowns[-1]
        value = orbit.period if name == PERIOD else orbit.parameter(name)
        if self.collapsed is not None:
            at = self.collapsed.period if name == PERIOD else self.collapsed.parameter(name)
            return (
                BranchEnd.HOPF,
                f"the orbit shrank onto an equilibrium at a Hopf point near {name} = {at:.10g} (period {self.collapsed.period:.10g}): "
                "the family ends there; equilibria.continue_equilibria locates the Hopf point itself",
            )
        previous = self.step[0] if self.step is not None and self.step[1] is orbit else self.last
        self.last = orbit
        if self.stop_at and previous is not None:
            ending = next((e for e in self.circle_events(previous, orbit) if e["kind"] in self.stop_at), None)
            if ending is not None:
                where = "located at" if ending["located"] else "passed before"
                kind = BranchEnd(ending["kind"])
                return kind, f"{ending['kind'].replace('_', ' ')} {where} {name} = {ending['moment']:.12g}: {kind.advice}"
        lost = _trivial_distance(orbit.multipliers)
        if orbit.unfold is None and lost > TRIVIAL_LOST:
            # The trivial multiplier is 1 for every orbit: a monodromy that no longer shows it is too inaccurate to
            # continue on or to test (near a saddle-focus at T ~ 32 single shooting's y0 carries the closure's noise).
            return (
                BranchEnd.INFINITE_PERIOD,
                f"the shooting's accuracy is exhausted at {name} = {value:.12g}, T = {orbit.period:.8g}: the multiplier nearest +1 is "
                f"{lost:.2g} from it (||M|| = {np.linalg.norm(orbit.monodromy, np.inf):.2g}); the period grows on",
            )
        if orbit.period > self.period_max:
            return (
                BranchEnd.INFINITE_PERIOD,
                f"the period exceeded period_max={self.period_max:g} at {name} = {value:.12g}: it diverges",
            )
        if not self.limits[0] <= value <= self.limits[1]:
            return BranchEnd.PARAMETER_LIMIT, f"{name} = {value:.12g} left [{self.limits[0]:g}, {self.limits[1]:g}]"
        if self.until_unstable and self.start_stable and not orbit.stable:
            return BranchEnd.UNSTABLE, f"stability lost near {name} = {value:.12g}"
        return None


def _split_double(multipliers: np.ndarray) -> float:
    """The distance from +1 of the mean of the two multipliers nearest it, less the half-split s squared (the mean's own
    error), where they are a double multiplier at +1 split by the monodromy's errors (a Jordan block at a fold of cycles
    splits into 1 +- s, real or a complex pair, about its trace): the mean lies within :data:`SPLIT_SYMMETRY` s of +1;
    infinite otherwise."""
    mu = np.asarray(multipliers, dtype=complex)
    if mu.size < 2:
        return math.inf
    first, second = mu[np.argsort(np.abs(mu - 1.0))[:2]]
    mean, half = 0.5 * (first + second), 0.5 * abs(first - second)
    # An error e splits the block by sqrt(e) and moves its mean by O(e), the half-split squared.
    return max(0.0, float(abs(mean - 1.0)) - half**2) if abs(mean - 1.0) <= SPLIT_SYMMETRY * half else math.inf


def _trivial_distance(multipliers: np.ndarray) -> float:
    """How far the trivial multiplier lies from +1: the nearest one's distance, or the split double one's
    (:func:`_split_double`) where smaller."""
    mu = np.asarray(multipliers, dtype=complex)
    nearest = float(np.min(np.abs(mu - 1.0), initial=math.inf))
    return min(nearest, _split_double(mu))


def second_multiplier_at_one(multipliers: np.ndarray) -> bool:
    """Whether a second multiplier lies at +1 beside the trivial one (a fold or branch point of cycles): the second
    nearest +1 within the square root of :data:`CONFIRM_TOL`, or the two nearest a double multiplier split about +1
    (:func:`_split_double`) whose mean is.

    The double multiplier is a Jordan block, which an error e of the monodromy splits by about sqrt(e); next to a
    saddle-focus the long orbit's monodromy carries errors that split it into 1 +- 0.18i (T = 27, ||M|| ~ 2e5) while
    the mean, the block's trace, stays within 0.02 of 1."""
    mu = np.asarray(multipliers, dtype=complex)
    if mu.size < 2:
        return False
    second = mu[np.argsort(np.abs(mu - 1.0))[1]]
    return bool(abs(second - 1.0) < CONFIRM_TOL**0.5 or _split_double(mu) < CONFIRM_TOL**0.5)


def _shrunk_onto_equilibrium(orbit: Orbit) -> bool:
    """Whether an oscillation (no turns) lies within :data:`HOPF_COLLAPSE` of an equilibrium whose dynamics has
    a pair of eigenvalues at +-2 pi i / T: the orbit has shrunk onto it at a Hopf point."""
    if np.any(orbit.turns):
        return False
    try:
        rest = find_equilibrium(orbit.system, orbit.q0)
    except EquilibriumNotFound:
        return False
    scale = max(1.0, float(np.linalg.norm(rest.q)))
    if rest.eigenvalues is None or np.linalg.norm(orbit.y0 - np.append(rest.q, np.zeros(orbit.system.size))) > HOPF_COLLAPSE * scale:
        return False
    omega = 2 * math.pi / orbit.period
    return bool(np.min(np.abs(rest.eigenvalues - 1j * omega)) < HOPF_COLLAPSE * omega)


@one_blas_thread
def continue_orbits(
    orbit: Orbit,
    parameter: str,
    *,
    direction: float = -1.0,
    limits: tuple[float, float] = (-math.inf, math.inf),
    period_max: float = 1000.0,
    step: float = 0.05,
    min_step: float = 1e-6,
    max_step: float = 0.5,
    max_points: int = 300,
    stop_at: tuple[str, ...] = ("fold",),
    until_unstable: bool = False,
    tol: float = CLOSURE_TOL,
    rtol: float = RTOL,
    atol: float = ATOL,
    progress: Callable[[int, int], None] | None = None,
) -> OrbitBranch:
    """Follow ``orbit`` in the named ``parameter`` (pseudo-arclength in (y0, log T, p)).

    Parameters
    ----------
    orbit : Orbit
        Start (from :func:`find_orbit`).
    parameter : str
        Any parameter of the orbit's system, or ``"period"`` (a family of a conservative system
        in its period, with ``unfold``).
    direction : float
        Start towards smaller (-1) or larger (+1) values.
    limits : (float, float)
        Stop when the parameter (or the period) leaves this range.
    period_max : float
        Stop when the period exceeds it; the end is then fitted from the period's growth.
    stop_at : tuple of str
        Events that end the branch (``fold``, ``period_doubling``, ``torus``, ``branch_point``).

    Returns
    -------
    OrbitBranch
        Events located on the way are confirmed by their multipliers (a fold of cycles needs a
        second multiplier at +1). Period doublings and tori are :mod:`~.cycle_events`': located by
        Brent's method in the parameter to :data:`~.cycle_events.MOMENT_TOL` where a circle test
        changes sign, kept with the critical multiplier within :data:`~.cycle_events.CIRCLE_MULTIPLIER`
        of -1 or of the unit circle (a pair inside the circle that turns real is no torus); where
        Brent's trials cannot be solved the event is the orbit after the sign change, unlocated.
    """
    system = orbit.system
    unfold = getattr(orbit, "unfold", None)
    if parameter == PERIOD and unfold is None:
        raise ValueError("continuing in the period needs an orbit found with unfold= (a conservative family)")
    if parameter != PERIOD:
        system.parameter(parameter)
    unknowns = (PERIOD if unfold is None else unfold, parameter)
    shooting = _Shooting(system, orbit.turns, orbit.y0, orbit.period, unknowns, tol, rtol, atol)
    shooting.set_reference(orbit.y0, orbit.period)
    problem = _OrbitProblem(shooting, period_max, limits, until_unstable, orbit.stable, unfold, stop_at)
    w0 = shooting.pack(orbit)
    traced: Continuation = continuation(
        problem,
        w0,
        step=step,
        min_step=min_step,
        max_step=max_step,
        max_points=max_points,
        direction=direction,
        stop_at=stop_at,
        progress=progress,
    )
    branch = OrbitBranch(parameter, traced.points, _with_circle_events(problem, traced), traced.end, traced.message)
    growing = len(branch.orbits) >= 4 and branch.periods[-1] > 2 * min(branch.periods)
    if traced.end == BranchEnd.INFINITE_PERIOD or (traced.end == BranchEnd.STEP_TOO_SMALL and growing):
        branch.end_value, branch.end_uncertainty = _fitted_end(branch)
        if branch.end_value is not None:
            branch.end_method = "fitted"
            branch.message += (
                f"; the period grows like a homoclinic end's: fitted end {parameter} = {branch.end_value:.10g} "
                + ("" if branch.end_uncertainty is None else f"+- {branch.end_uncertainty:.2g} ")
                + "(a fit of p = p* + c exp(-s T), not a computed point)"
            )
    return branch


def _with_circle_events(problem: _OrbitProblem, traced: Continuation) -> list[Event]:
    """The kit's events of ``traced`` and the period doublings and tori between its consecutive orbits
    (:meth:`_OrbitProblem.circle_events`, those :meth:`~_OrbitProblem.stop` found reused), in the order of the branch
    (within a step the period doublings and tori first: the loss of stability the kit locates at one is listed after it).

    Across a step that holds a located fold the parameter turns: Brent's method in it has no bracket there, so such a
    step is searched in its two halves, from the orbit before to the fold's and from the fold's to the orbit after
    (:func:`~.cycle_events.steps`, as on the chain's branch)."""
    folds = {e.index: e.point for e in traced.events if e.kind == "fold" and e.located}
    found = [
        Event(e["kind"], e["orbit"] if e["located"] else b, e["moment"], i, None, located=e["located"])
        for i, a, b in cycle_events.steps(traced.points, folds)
        for e in problem.circle_events(a, b)
    ]
    return sorted([*found, *traced.events], key=lambda event: event.index)


def _fitted_end(branch: OrbitBranch) -> tuple[float | None, float | None]:
    """Where the period diverges, from the last orbits: p = p* + c exp(-s T) (a homoclinic end)
    fitted through three orbits spread over the last half span of periods. Its uncertainty is the
    larger of its distance from the same fit over the whole span (the orbits of shorter periods are
    further from the law, so the narrower fit is the nearer one) and the distance it extrapolates
    beyond the last orbit: the law holds only asymptotically, and the spread alone understated the error (the unequal
    pairs' fits lay 2.1e-7 and 5.1e-7 from AUTO-07p's ends with spreads of 7.9e-8 and 3.1e-7, 2.9e-6
    and 1.1e-6 beyond their last orbits)."""
    values, periods = branch.values, branch.periods
    if len(values) < 4:
        return None, None

    def spread(span: float) -> tuple[np.ndarray, np.ndarray]:
        picks = [int(np.argmin(np.abs(periods - (periods[-1] - f * span)))) for f in (1.0, 0.5, 0.0)]
        return values[picks], periods[picks]

    def fit(v: np.ndarray, t: np.ndarray) -> float:
        t = t - t[0]
        ratio = (v[2] - v[1]) / (v[1] - v[0])

        def mismatch(rate: float) -> float:
            e = np.exp(-rate * t)
            return (e[2] - e[1]) / (e[1] - e[0]) - ratio

        try:
            rate = brentq(mismatch, 1e-9, 50.0 / max(t[2], 1e-12))
        except ValueError:
            return float(v[2])
        e = np.exp(-rate * t)
        scale = (v[2] - v[1]) / (e[2] - e[1])
        return float(v[2] - scale * e[2])

    span = min(6.0, 0.5 * (periods[-1] - np.min(periods)))
    # Orbits picked twice (a short span) make the ratios 0/0: that fit is not finite, and neither is its spread.
    with np.errstate(divide="ignore", invalid="ignore"):
        wide, narrow = fit(*spread(span)), fit(*spread(0.5 * span))
    if not math.isfinite(narrow):
        return (wide, None) if math.isfinite(wide) else (None, None)
    return narrow, max(abs(wide - narrow), abs(values[-1] - narrow)) if math.isfinite(wide) else None
