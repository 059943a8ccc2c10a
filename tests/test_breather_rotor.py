"""The anti-continuum rotor shared by the chain's and the systems' roto-breathers (experiments.anti_continuum)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.special import ellipk

from cosserat_chain.experiments.anti_continuum import potential_from_torque, rotor_energy, rotor_period, sample_angles


def test_pendulum_torque_integrates_to_its_potential_and_its_turn_to_the_closed_form():
    phi = sample_angles()
    potential = potential_from_torque(-np.sin(phi))
    angles = np.linspace(-7.0, 7.0, 101)
    np.testing.assert_allclose(potential(angles), 1.0 - np.cos(angles), atol=1e-13)
    # One turn of phi'' = -sin phi at energy E > 2 takes 4 K(2 / E) / sqrt(2 E); the inertia scales it by sqrt(J).
    energy = 2.7
    exact = 4.0 / math.sqrt(2.0 * energy) * ellipk(2.0 / energy)
    assert rotor_period(potential, 1.0, energy) == pytest.approx(exact, rel=1e-12)
    assert rotor_period(potential, 4.0, energy) == pytest.approx(2.0 * exact, rel=1e-12)
    assert rotor_energy(potential, 1.0, exact) == pytest.approx(energy, rel=1e-12)


def test_a_turn_too_slow_to_resolve_is_refused():
    potential = potential_from_torque(-np.sin(sample_angles()))
    with pytest.raises(ValueError, match="too slow to resolve"):
        rotor_energy(potential, 1.0, 1e6)
