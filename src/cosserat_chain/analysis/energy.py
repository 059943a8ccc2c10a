"""The energy budget of a run: kinetic, potential, load work, dissipation and their balance.

For the damped, loaded chain (eqs. (2)-(3) with viscosity) the energy balance is

    K(t) + P(t) - W(t) + D(t) = K(t0) + P(t0)

with the kinetic energy K = 1/2 sum (m u'^2 + m v'^2 + j phi'^2) (the paper prints
it without the squares; see ``docs/errata.md``), the potential P of models (i)
and (iii), the work W done by the loads and the energy D dissipated by viscosity.
Its residual, ``balance_error``, measures the integrator's error. The sine model
(eq. 2) has no potential, so its potential and balance are NaN.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..models.base import Model, get_model
from ..params import ChainParams


@dataclass
class EnergyBudget:
    """Energies at the stored frames, each of shape (n_frames,)."""

    kinetic: np.ndarray
    potential: np.ndarray
    load_work: np.ndarray
    dissipated: np.ndarray

    @property
    def balance_error(self) -> np.ndarray:
        """(K + P - W + D) - (K0 + P0); NaN where P is undefined."""
        total = self.kinetic + self.potential - self.load_work + self.dissipated
        return total - total[0]

    def as_dict(self) -> dict[str, np.ndarray]:
        return {
            "kinetic": self.kinetic,
            "potential": self.potential,
            "load_work": self.load_work,
            "dissipated": self.dissipated,
            "balance_error": self.balance_error,
        }


def kinetic_energy(params: ChainParams, v: np.ndarray) -> np.ndarray:
    """1/2 sum m_r v_r^2 for velocities of shape (..., 3, 2N+1)."""
    inertia = params.particle_inertia
    return 0.5 * np.sum(inertia * np.asarray(v) ** 2, axis=(-2, -1))


def potential_energy(params: ChainParams, model: str | Model, x: np.ndarray) -> np.ndarray:
    """Potential energy of every configuration in ``x`` (..., 3, 2N+1); NaN for a non-conservative model."""
    model = get_model(model)
    x = np.asarray(x)
    frames = x.reshape(-1, 3, x.shape[-1])
    if not model.conservative:
        return np.full(frames.shape[0], np.nan).reshape(x.shape[:-2])
    return np.array([model.energy(params, frame) for frame in frames]).reshape(x.shape[:-2])


def energy_budget(params: ChainParams, model: str | Model, trajectory) -> EnergyBudget:
    """Energy budget of a :class:`~cosserat_chain.numerics.dynamics.Trajectory` at its frames."""
    return EnergyBudget(
        kinetic=kinetic_energy(params, trajectory.v),
        potential=potential_energy(params, model, trajectory.x),
        load_work=np.asarray(trajectory.load_work),
        dissipated=np.asarray(trajectory.dissipated),
    )
