"""The fixed-step methods: symmetric compositions of damped Verlet sub-steps, as weight tables.

Contract
--------
The equations of motion are, for each row r in (u, v, phi) with inertia m_r
(m, m, j) and viscosity gamma_r,

    m_r q_r'' = F_r(q) + L_r(t) - gamma_r q_r'

with F the model's internal forces and L the loads (eqs. (2)-(3)). One step of
size dt is a symmetric composition of damped velocity-Verlet sub-steps of sizes
c_i dt (coefficients in :class:`Method`), each sub-step being

    damp(h/2) . kick(h/2) . drift(h) . kick(h/2) . damp(h/2)

where ``damp`` is the exact viscous flow v <- v exp(-gamma h / (2 m)) (stable for
any gamma) and ``kick`` uses the forces at the current positions and time. The
composition is time-symmetric, so Verlet is of order 2 and the Yoshida triple
jump of order 4.

The time-step policy sits beside the methods' stability limits: the default step
(:func:`default_time_step`), the refusal of a step beyond the limit (:func:`check_time_step`)
and the hint when a moment spins its particle faster than the step follows (:func:`spin_hint`).

The compiled time loop that runs them is :mod:`.engine`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import cached_property

import numpy as np

from ..loads import Loads
from ..models.base import Model, get_model
from ..params import ChainParams

#: Default time step as a fraction of 1 / omega_max (omega_max: highest linear frequency).
DEFAULT_OMEGA_DT = 0.1


@dataclass(frozen=True)
class Method:
    """A fixed-step method: a symmetric composition of damped Verlet sub-steps.

    Parameters
    ----------
    name : str
    order : int
        Declared global order of accuracy (checked by the test suite).
    weights : tuple of float
        Sub-step sizes as fractions of dt; they sum to 1 and read the same backwards.
    """

    name: str
    order: int
    weights: tuple[float, ...]
    description: str

    @property
    def force_evaluations(self) -> int:
        """Force evaluations per step."""
        return len(self.weights)

    def transfer_matrix(self, omega_dt: float) -> np.ndarray:
        """One undamped step on x'' = -omega^2 x, as the 2x2 map of (x, v/omega)."""
        step = np.eye(2)
        for c in self.weights:
            z = c * omega_dt
            kick = np.array([[1.0, 0.0], [-z / 2, 1.0]])
            drift = np.array([[1.0, z], [0.0, 1.0]])
            step = kick @ drift @ kick @ step
        return step

    @cached_property
    def stability_limit(self) -> float:
        """Largest omega dt for which the undamped harmonic oscillator stays bounded.

        Found from the transfer matrix (stable while |trace| < 2), so it is exact for
        the method's coefficients rather than a quoted constant.
        """
        z = np.linspace(1e-3, 4.0, 4001)
        traces = np.array([abs(np.trace(self.transfer_matrix(zi))) for zi in z])
        first_bad = int(np.argmax(traces >= 2.0))
        lo, hi = z[first_bad - 1], z[first_bad]
        for _ in range(60):
            mid = 0.5 * (lo + hi)
            lo, hi = (mid, hi) if abs(np.trace(self.transfer_matrix(mid))) < 2.0 else (lo, mid)
        return float(lo)


_CBRT2 = 2.0 ** (1.0 / 3.0)
METHODS: dict[str, Method] = {
    "verlet": Method("verlet", 2, (1.0,), "damped velocity Verlet (Strang splitting with exact damping)"),
    "yoshida4": Method(
        "yoshida4",
        4,
        (1.0 / (2.0 - _CBRT2), -_CBRT2 / (2.0 - _CBRT2), 1.0 / (2.0 - _CBRT2)),
        "Yoshida's fourth-order triple jump of the damped Verlet step",
    ),
}


def get_method(name: str | Method) -> Method:
    """The method of that name (a :class:`Method` passes through).

    Raises
    ------
    ValueError
        For an unknown name, listing the known ones.
    """
    if isinstance(name, Method):
        return name
    try:
        return METHODS[name]
    except KeyError:
        raise ValueError(f"method must be one of {sorted(METHODS)}, got {name!r}") from None


# --------------------------------------------------------------------------- time-step policy
def default_time_step(params: ChainParams, model: str | Model = "nonlinear") -> float:
    """0.1 / omega_max: about 60 steps per period of the model's fastest linear mode.

    omega_max is :meth:`Model.max_frequency <cosserat_chain.models.base.Model.max_frequency>`;
    the default model's is that of the three paper models, which share their
    linearisation at rest (eq. 3).
    """
    return DEFAULT_OMEGA_DT / get_model(model).max_frequency(params)


def check_time_step(params: ChainParams, dt: float, method: Method, model: str | Model = "nonlinear") -> None:
    """Refuse a step beyond the method's linear stability limit for ``model`` (default as :func:`default_time_step`).

    Raises
    ------
    ValueError
        If dt is not finite and positive, or dt * omega_max exceeds the limit;
        the message gives the largest stable dt.
    """
    if not (math.isfinite(dt) and dt > 0):
        raise ValueError(f"dt must be a finite number > 0, got {dt!r}")
    omega = get_model(model).max_frequency(params)
    limit = method.stability_limit / omega
    if dt >= limit:
        raise ValueError(
            f"dt={dt!r} is beyond the stability limit of {method.name} for this chain: "
            f"dt must be < {limit:.6g} (omega_max={omega:.6g}); the run would blow up. "
            f"Use a smaller step, e.g. dt={DEFAULT_OMEGA_DT / omega:.3g}."
        )


#: A moment that would turn its particle, at its terminal spin M / gamma_phi, by more than this
#: many radians per step is beyond what the step can follow (about 13 steps a turn).
MAX_SPIN_PER_STEP = 0.5


def spin_hint(params: ChainParams, loads: Loads, dt: float) -> str:
    """Why a run at ``dt`` cannot follow its largest moment, in words, or ``""`` if it can.

    A moment M drives its particle towards the spin M / gamma_phi (the viscous torque
    balancing it): beyond :data:`MAX_SPIN_PER_STEP` radians per step the run no longer
    resolves the rotation, whatever else is right; without rotational damping the spin
    grows without bound.
    """
    moments = [load.schedule.bound() for load in loads if load.row == "phi"]
    largest = max(moments, default=0.0)
    if largest == 0.0:
        return ""
    if params.gamma_phi == 0.0:
        return f"Without rotational damping (gamma_phi = 0) the moment {largest:g} spins its particle up without bound; no time step follows it for long"
    spin = largest / params.gamma_phi
    if spin * dt <= MAX_SPIN_PER_STEP:
        return ""
    return (
        f"The moment {largest:g} spins its particle at up to M / gamma_phi = {spin:.3g} rad per unit time, "
        f"{spin * dt:.3g} rad per step of dt={dt:g}: it is beyond what this step can follow; a smaller load, or "
        f"dt <= {MAX_SPIN_PER_STEP / spin:.3g}"
    )


# --------------------------------------------------------------------------- kernels
def substep_table(weights: np.ndarray, dt, mass: np.ndarray, gamma: np.ndarray) -> np.ndarray:
    """Factors of every sub-step: [s, 0, r] damping exp(-gamma_r h_s / (2 m_r)), [s, 1, r] kick
    h_s / (2 m_r), [s, 2, r] drift h_s, with h_s = weights[s] dt; row S is the empty sub-step.

    Parameters
    ----------
    weights : (S,) sub-step sizes as fractions of dt
    dt : float, or (B,) one step per member
    mass, gamma : (3,), or (B, 3) per member: inertia and viscosity of the rows

    Returns
    -------
    ndarray (S+1, 3, 3), or (S+1, 3, 3, B) for a batch (members innermost)
    """
    single = np.ndim(dt) == 0
    dt = np.atleast_1d(np.asarray(dt, dtype=float))
    mass = np.atleast_2d(np.asarray(mass, dtype=float)).T
    gamma = np.atleast_2d(np.asarray(gamma, dtype=float)).T
    sizes = np.append(np.asarray(weights, dtype=float), 0.0)[:, None, None] * dt[None, None, :]
    table = np.empty((sizes.shape[0], 3, 3, dt.size))
    table[:, 0] = np.exp(-sizes * (gamma / (2.0 * mass))[None])
    table[:, 1] = sizes * (0.5 / mass)[None]
    table[:, 2] = sizes
    return table[..., 0] if single else table
