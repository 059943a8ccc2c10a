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

The compiled time loop that runs them is :mod:`.engine`.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import numpy as np


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
