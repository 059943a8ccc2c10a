"""Runs whose step count overflows the counters are refused with the chain's fields, not an OverflowError."""

from __future__ import annotations

import pytest

from cosserat_chain.numerics.dynamics import MAX_STEPS, integrate, require_step_count
from cosserat_chain.numerics.relaxation import relax_batch
from cosserat_chain.params import ChainParams


def test_a_relaxation_of_a_stiff_member_names_the_member_and_t_max():
    members = [ChainParams(), ChainParams(E1=1e100)]
    with pytest.raises(ValueError, match=r"member 1 \(params_list\[1\]\): the run would take .* \(t_max = 100\).*E1=1e\+100"):
        relax_batch(members, "nonlinear", [0.1, 0.1], t_max=100.0)


def test_a_graded_chains_factors_are_named():
    params = ChainParams(N=1, m_factors=(1.0, 1e-90, 1.0))
    with pytest.raises(ValueError, match=r"m_factors from 1e-90 to 1; .* shorten t_end"):
        integrate(params, "sine", t_end=10.0)


def test_the_limit_is_the_counters_exact_integers():
    params = ChainParams()
    assert require_step_count(params, MAX_STEPS, 1.0, "t") == MAX_STEPS
    with pytest.raises(ValueError, match="more than 9.01e"):
        require_step_count(params, 2.0 * MAX_STEPS, 1.0, "t")
    with pytest.raises(ValueError):
        require_step_count(params, float("nan"), 1.0, "t")
