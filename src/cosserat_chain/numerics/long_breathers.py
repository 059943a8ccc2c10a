"""Hamiltonian rotating orbits (roto-breathers) of long chains: the unfolded shooting with the monodromy in column blocks.

Contract
--------
:func:`~.periodic.find_hamiltonian_orbit` integrates the monodromy in one piece, with the
unfolding's derivative as one more variational column; its time and memory grow like N^2
per unit time (docs/roto-breathers.md, cost of a family). Here the same Newton
system,

    Phi_T^eps(y0) - y0 - 2 pi k e_phi = 0,  unknowns (y0 without phi_rotor, eps),
    Jacobian [(M - I) without the phi column, dPhi_T/deps],

takes M from column blocks (:class:`~.long_orbits.Monodromy`, the blocks on parallel
threads, with the memory of M alone) and dPhi_T/deps from fourth-order central differences
of four state-only flows (the blocks' columns are the identity's alone: the unfolding's
column exists only in the one-piece integration). Newton keeps its Jacobian while each step
divides the closure tenfold (chord iterations, :data:`~.long_orbits.CHORD_RATE`), and a
continuation hands the last orbit's Jacobian to the next one (``jacobian0``), so an orbit of
a family costs about one M, the one formed at the solution for its Floquet multipliers
(:func:`~.long_orbits.leading_multipliers`: all of them up to 2 n_free =
:data:`~.long_orbits.ALL_MULTIPLIERS_UP_TO`, then the leading ones).

:func:`find_breather_orbit` chooses between the two by ``method`` (``"auto"``: the blocks
from N = :data:`~.long_orbits.BLOCKS_FROM_N`) and returns the orbit with the Jacobian at the
solution (:class:`SolvedBreather`), which the next orbit of a family starts from.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

import numpy as np

from ..models.base import Model
from ..params import ChainParams
from ..state import check_state
from . import dop853, long_orbits
from .kit import Evaluation, EvaluationFailed, newton
from .periodic import (
    ATOL,
    CLOSURE_TOL,
    MAX_HALVINGS,
    MAX_STEPS,
    RTOL,
    HamiltonianOrbit,
    OrbitError,
    PeriodicOrbit,
    _no_hamiltonian_convergence,
    _orbit_from,
    _System,
    _to_y,
    _UndampedSystem,
    find_hamiltonian_orbit,
    hamiltonian_energy,
    hamiltonian_setup,
)

#: Step of the fourth-order central differences of the flow in the unfolding eps (a rate: 1/time).
EPS_STEP = 1e-5
#: A Newton trial state farther than this times max(1, max |y0|) from the start (max norm) is refused unintegrated.
REACH = 4.0
#: A trial's flow may take this many times the DOP853 steps of the start's (plus STEPS_SLACK), else it is refused.
STEPS_FACTOR = 50
STEPS_SLACK = 1000


@dataclass
class SolvedBreather:
    """A Hamiltonian orbit with the Newton Jacobian at it (None for the dense method), for the next orbit of a family."""

    orbit: HamiltonianOrbit
    jacobian: np.ndarray | None = None


def _eps_derivative(system: _UndampedSystem, y0: np.ndarray, period: float, rtol: float, atol: float) -> np.ndarray:
    """dPhi_T/deps (2 n_free,) by the fourth-order central difference with :data:`EPS_STEP`."""
    near, far = (
        [
            dataclasses.replace(system, eps=system.eps + sign * reach * EPS_STEP).flow(y0, period, rtol=rtol, atol=atol, variations=False)
            for sign in (1.0, -1.0)
        ]
        for reach in (1.0, 2.0)
    )
    return (8.0 * (near[0][0] - near[1][0]) - (far[0][0] - far[1][0])) / (12.0 * EPS_STEP)


def find_long_hamiltonian_orbit(
    params: ChainParams,
    model: str | Model,
    omega: float,
    guess: PeriodicOrbit | tuple,
    *,
    turns: int = 1,
    particle: int = 0,
    particle_turns: np.ndarray | None = None,
    tol: float = CLOSURE_TOL,
    max_iter: int = 25,
    rtol: float = RTOL,
    atol: float = ATOL,
    jacobian0: np.ndarray | None = None,
    contraction: float | None = None,
    threads: int | None = None,
) -> SolvedBreather:
    """:func:`~.periodic.find_hamiltonian_orbit` with the monodromy from column blocks (module docstring).

    Parameters
    ----------
    params, model, omega, guess, turns, particle, particle_turns, tol, max_iter, rtol, atol
        As :func:`~.periodic.find_hamiltonian_orbit`.
    jacobian0 : ndarray (2 n_free, 2 n_free), optional
        The Newton Jacobian of a nearby orbit (:attr:`SolvedBreather.jacobian`): the first
        steps use it, and M is formed only where they stop converging fast, and at the solution.
    contraction : float, optional
        Give up unless the closure falls by this factor every two steps (:func:`~.kit.newton`):
        a start outside Newton's basin then costs a few steps, not ``max_iter`` monodromies.
    threads : int, optional
        Threads the blocks run on (default :data:`~.long_orbits.THREADS`).

    Returns
    -------
    SolvedBreather
        The orbit (``multiplier_errors`` holds the multipliers' error estimates) and the Jacobian there.

    Raises
    ------
    ValueError
        As :func:`~.periodic.find_hamiltonian_orbit`, and for a ``jacobian0`` of the wrong shape.
    OrbitError
        If Newton's method does not converge.
    """
    model, particle_turns = hamiltonian_setup(params, model, omega, guess, turns, particle, particle_turns, tol, rtol, atol)
    x0, v0 = (guess.x, guess.v) if isinstance(guess, PeriodicOrbit) else guess
    period = 2.0 * math.pi * turns / float(omega)
    base = _System(params, model, 0.0, particle)
    y0 = _to_y(params, check_state(params, x0, "guess x"), check_state(params, v0, "guess v"))
    y0[base.load_dof] = 0.0
    keep = np.arange(len(y0)) != base.load_dof
    if jacobian0 is not None and np.shape(jacobian0) != (len(y0), len(y0)):
        raise ValueError(f"jacobian0 must be ({len(y0)}, {len(y0)}) (the Newton Jacobian of this chain's orbit), got {np.shape(jacobian0)}")
    shift = long_orbits._shift(base, particle_turns)
    identity = np.eye(len(y0))[:, keep]

    reach = REACH * max(1.0, float(np.max(np.abs(y0))))
    budget: list[int] = []  # the trials' step budget, set by the first flow (the start's)

    def closure(w: np.ndarray, jacobian: bool) -> Evaluation:
        y = np.zeros(len(keep))
        y[keep] = w[:-1]
        if np.max(np.abs(y - y0)) > reach:
            # A step from a poor Jacobian can throw the chain into a violent motion that DOP853 follows for
            # minutes at N = 50: refused as a worse closure (halved), without integrating.
            raise EvaluationFailed(f"the trial state moved {np.max(np.abs(y - y0)):.3g} from the start (more than {reach:.3g})")
        system = _UndampedSystem(params, model, 0.0, particle, float(w[-1]))
        rhs, kernel, ends, coef, rpar, ipar = system.parameters(0)
        times = np.array([0.0, period])
        sol = dop853.solve(
            rhs, kernel, coef, rpar, ipar, y, times, rtol=rtol, atol=atol, max_steps=budget[0] if budget else MAX_STEPS, end_force=ends
        )
        if not sol.success:
            # A step far off the orbit can make the flow run away (or turn violent, taking minutes) before T:
            # refused as a worse closure (halved).
            raise EvaluationFailed(f"the flow of a Newton trial over T={period!r} failed: {sol.message}")
        if not budget:
            budget.append(STEPS_FACTOR * sol.steps + STEPS_SLACK)
        end = sol.y[-1]
        monodromy = long_orbits.Monodromy(system, y, period, rtol, atol)

        def matrix() -> np.ndarray:
            mono = monodromy.matrix(threads=threads)
            return np.column_stack([mono[:, keep] - identity, _eps_derivative(system, y, period, rtol, atol)])

        # M is formed only where Newton asks for a fresh Jacobian (chord iterations, and at the solution).
        return Evaluation(end - y - shift, matrix, monodromy)

    w0 = np.append(y0[keep], 0.0)
    solved = newton(
        closure, w0, tol=tol, max_iterations=max_iter, divergence=None, chord=long_orbits.CHORD_RATE, jacobian0=jacobian0,
        damping=MAX_HALVINGS, contraction=contraction,
    )  # fmt: skip
    if not solved.converged:
        raise OrbitError(_no_hamiltonian_convergence(omega, turns, solved.iterations, solved.norm))
    y0[keep] = solved.w[:-1]
    try:
        jacobian = solved.evaluation.matrix()
        multipliers, errors = long_orbits.leading_multipliers(solved.evaluation.data.formed, base.velocity(y0))
    except EvaluationFailed as err:
        raise OrbitError(f"the monodromy at the orbit failed: {err}") from err
    orbit = _orbit_from(base, turns, y0, period, multipliers, solved.norm, solved.iterations, particle_turns, None, errors)
    fields = {name: getattr(orbit, name) for name in PeriodicOrbit.__dataclass_fields__}
    energy = hamiltonian_energy(params, model, orbit.x, orbit.v)
    return SolvedBreather(HamiltonianOrbit(**fields, unfolding=float(solved.w[-1]), energy=energy), jacobian)


def find_breather_orbit(
    params: ChainParams,
    model: str | Model,
    omega: float,
    guess: PeriodicOrbit | tuple,
    *,
    method: str = "auto",
    turns: int = 1,
    particle: int = 0,
    particle_turns: np.ndarray | None = None,
    max_iter: int = 25,
    jacobian0: np.ndarray | None = None,
    contraction: float | None = None,
) -> SolvedBreather:
    """A Hamiltonian orbit by the dense shooting or the blocks (``method``: ``"auto"``, ``"dense"``, ``"blocks"``).

    ``"auto"`` takes the blocks from N = :data:`~.long_orbits.BLOCKS_FROM_N`; ``jacobian0`` and
    ``contraction`` serve the blocks only (the dense method forms M at every step, cheaply).

    Raises
    ------
    ValueError
        For a method not in auto, dense, blocks, and as the solvers.
    OrbitError
        If Newton's method does not converge.
    """
    chosen = long_orbits.choose_method(params, method)
    if chosen == "krylov":
        raise ValueError("method must be auto, dense or blocks (a roto-breather's stability needs the monodromy formed), got 'krylov'")
    if chosen == "dense":
        orbit = find_hamiltonian_orbit(
            params, model, omega, guess, turns=turns, particle=particle, particle_turns=particle_turns, max_iter=max_iter
        )
        return SolvedBreather(orbit)
    return find_long_hamiltonian_orbit(
        params, model, omega, guess, turns=turns, particle=particle, particle_turns=particle_turns, max_iter=max_iter,
        jacobian0=jacobian0, contraction=contraction,
    )  # fmt: skip
