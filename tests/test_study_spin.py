"""A study refuses, before anything runs, a load its relaxations' step cannot follow."""

from __future__ import annotations

import math

import pytest

from cosserat_chain.experiments.study import cell_time_step, spec_from_mapping
from cosserat_chain.numerics.integrators import MAX_SPIN_PER_STEP
from cosserat_chain.params import ChainParams


def _spec(loads, **sweep):
    return {"models": ["sine"], "quantities": ["mean_angular_velocity"], "loads": loads, "parameters": {"a": [0.15, 0.2]}, "sweep": sweep}


def _limit(a: float) -> float:
    """The largest load the default step of the cell a follows: MAX_SPIN_PER_STEP = (M / gamma_phi) dt."""
    params = ChainParams(a=a)
    spec = spec_from_mapping(_spec([0.1]))
    return MAX_SPIN_PER_STEP * params.gamma_phi / cell_time_step(params, "sine", spec)


@pytest.mark.parametrize("load", [1e300, -1e300])
def test_a_load_beyond_any_step_is_refused_naming_the_cells_the_spin_and_the_step(load):
    with pytest.raises(ValueError) as err:
        spec_from_mapping(_spec([0.3, load]))
    text = str(err.value)
    assert "2 impossible parameter combination(s)" in text
    assert "cell a=0.15: sine: The moment 1e+300 spins its particle" in text and "cell a=0.2" in text
    assert "sweep.dt" in text


def test_the_refusal_sits_at_the_spin_the_step_follows():
    limit = min(_limit(0.15), _limit(0.2))
    spec_from_mapping(_spec([0.3, 0.999 * limit]))  # followed: accepted
    with pytest.raises(ValueError, match="beyond what this step can follow"):
        spec_from_mapping(_spec([0.3, 1.001 * limit]))


def test_a_smaller_step_admits_the_load_and_undamped_rotation_is_not_bounded():
    limit = _limit(0.15)
    dt = 0.5 * cell_time_step(ChainParams(a=0.15), "sine", spec_from_mapping(_spec([0.1])))
    spec_from_mapping({**_spec([1.5 * limit]), "parameters": {"a": [0.15]}, "sweep": {"dt": dt}})
    spec_from_mapping({**_spec([1e6]), "fixed": {"gamma_phi": 0.0}})


def test_the_sweeps_upper_bound_is_not_a_load():
    """onset_load's sweep stops at the onset, far below m_max: a large m_max is no spin."""
    spec = spec_from_mapping({"models": ["sine"], "quantities": ["onset_load"], "parameters": {"a": [0.15]}, "sweep": {"m_max": 1e6}})
    assert math.isclose(spec.sweep.m_max, 1e6)
