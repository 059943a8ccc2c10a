"""The state diagram's rows reuse what a neighbouring row already knows, and only that (issue 44 item 1)."""

from __future__ import annotations

import pytest

from cosserat_chain import ChainParams
from cosserat_chain.experiments import diagram
from cosserat_chain.experiments.critical import critical_point
from static_onsets import nonlinear_critical

CANTILEVER = ChainParams(right_end="free")


@pytest.fixture
def counted_onsets(monkeypatch):
    """The rows' static onsets computed, with the lower edges left out (each row's orbit is not wanted here)."""
    calls = []
    onset = diagram._static_onset

    def counting(chain, *args):
        calls.append(chain)
        return onset(chain, *args)

    monkeypatch.setattr(diagram, "_static_onset", counting)
    monkeypatch.setattr(diagram, "_lower_edge", lambda *args: diagram._Edge(None, "not_found", "not computed here"))
    return calls


def test_along_the_damping_the_branch_from_rest_is_computed_once_and_every_row_keeps_its_branch_point(counted_onsets):
    """The nonlinear cantilever's stable branch ends at a branch point before its fold: every row's M_c is it."""
    result = diagram.state_diagram(CANTILEVER, "nonlinear", "gamma_phi", [0.1, 0.2, 0.3])
    reference = nonlinear_critical(CANTILEVER)
    assert len(counted_onsets) == 1
    for row in result.rows:
        assert row.static_fold == pytest.approx(reference.critical_moment, rel=1e-9)
        assert "branch point" in row.message


def test_along_a_field_the_statics_read_every_row_has_its_own_onset(counted_onsets):
    """On the paper's chain (its folds 0.1975 at E2 = 1.0 and 0.2060 at 1.1: no branch point needed for this claim)."""
    paper = ChainParams()
    result = diagram.state_diagram(paper, "nonlinear", "E2", [1.0, 1.1])
    assert [chain.E2 for chain in counted_onsets] == [1.0, 1.1]
    assert result.rows[1].static_fold == pytest.approx(critical_point(paper.replace(E2=1.1), "nonlinear").critical_moment, rel=1e-9)
    assert result.rows[0].static_fold != result.rows[1].static_fold
