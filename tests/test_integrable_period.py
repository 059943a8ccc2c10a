"""Orbits refuse, before integrating, a period their integrator cannot cover (a chain many decades stiff)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from cosserat_chain.models.base import get_model
from cosserat_chain.numerics.periodic import (
    DOP853_STABLE_STEP,
    MAX_STEPS,
    find_hamiltonian_orbit,
    find_periodic_orbit,
    require_integrable_period,
)
from cosserat_chain.params import ChainParams


@pytest.mark.parametrize("model", ["sine", "nonlinear"])
def test_the_refusal_sits_at_max_steps_of_the_fastest_mode(model):
    params = ChainParams(N=2)
    omega = get_model(model).max_frequency(params)
    edge = MAX_STEPS * DOP853_STABLE_STEP / omega
    require_integrable_period(params, get_model(model), 0.99 * edge)
    with pytest.raises(ValueError, match=r"one period T = .* takes at least 1\.01e\+07 integration steps"):
        require_integrable_period(params, get_model(model), 1.01 * edge)


def test_a_graded_chain_decades_apart_is_refused_naming_its_factors():
    params = ChainParams(N=1, m_factors=(1.0, 1e-90, 1.0), gamma_u=0.0, gamma_v=0.0, gamma_phi=0.0)
    zero = np.zeros((3, 3))
    with pytest.raises(ValueError, match="their factors") as err:
        find_hamiltonian_orbit(params, "sine", 2.0, (zero, zero))
    steps = float(str(err.value).split("at least ")[1].split(" ")[0])
    # T omega_max / 6 with omega_max of the light particle: sqrt(stiffness / 1e-90) ~ 1e45
    assert 1e44 < steps < 1e46
    with pytest.raises(ValueError, match="their factors"):
        find_periodic_orbit(params.model_copy(update={"gamma_phi": 0.1}), "sine", 0.3, guess=(zero, zero, 2 * math.pi))
