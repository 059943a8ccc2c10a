"""The answer to the paper's open problem, in sentences with numbers, for a report section."""

from __future__ import annotations

import json

import pytest

from cosserat_chain import ChainParams
from cosserat_chain.analysis.which_continuum import answer


def test_answer_for_the_paper_chain_states_the_orders_and_that_no_continuum_carries_a_full_rotation():
    result = answer(n_values=(20, 40, 80))
    small, bending, rotation = result.lines()
    assert result.beam.order("timoshenko") == pytest.approx(2.0, abs=0.05) and "order 2.0" in small
    assert result.bending.order("moment") == pytest.approx(2.0, abs=0.05) and "orders 2.0" in bending
    assert not result.front.smooth and "no continuum" in rotation and f"{result.barrier.fixed:.4g}" in rotation
    assert json.loads(json.dumps(result.as_dict()))["answer"] == result.lines()


def test_answer_takes_any_ends_of_the_given_geometry():
    result = answer(ChainParams(left_end="pinned", right_end="free", b=0.3), n_values=(10, 20, 40))
    assert result.beam.paper[0] == result.beam.paper[0]  # eq. (11) applies: the small deformations are the clamped chain's
    assert result.bending.N.tolist() == [10, 20, 40]
