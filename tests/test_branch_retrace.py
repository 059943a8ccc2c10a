"""A static trace that turns back along itself ends "reversed", incomplete, instead of "returned" as if complete.

The paper's geometry at N = 3000 (nonlinear model) has a cluster of folds and a branch point
near phi_0 = 6.2754, M = 3.6e-4, within the corrector's resolution: the trace turned back
there, passed its folds again in reverse order (each at the same moment and angle to 1e-10,
its index changing the other way) and came back through the rest state, which used to end
the branch "returned" and report it complete.
"""

from __future__ import annotations

import json

import numpy as np
import pytest
from typer.testing import CliRunner

from cosserat_chain.cli import app
from cosserat_chain.numerics.continuation import Fold, _StaticBranch


def _fold(phi0, moment, before, after):
    return Fold(moment=moment, phi0=phi0, x=np.zeros((3, 3)), index_before=before, index_after=after)


def _retraced(folds) -> str:
    branch = _StaticBranch.__new__(_StaticBranch)
    branch.located_folds, branch.reversal = [], ""
    for fold in folds:
        branch._check_retrace(fold)
        branch.located_folds.append(fold)
    return branch.reversal


def test_a_fold_passed_again_the_other_way_is_a_retrace_an_adjacent_pair_is_not():
    first, second = _fold(3.6, 0.0988, 0, 1), _fold(6.2734, 5.35e-4, 1, 0)
    turn = _fold(6.2753, 5.49e-4, 0, 1)
    # A small maximum and minimum of M side by side: a real pair, not a retrace.
    assert _retraced([first, second, turn, _fold(6.2753 + 1e-10, 5.49e-4 * (1 + 1e-9), 1, 0)]) == ""
    # The second fold passed again, the other way, after another one: the trace is going back.
    message = _retraced([first, second, turn, _fold(6.2755, 3.6e-4, 1, 0), _fold(6.2734 + 5e-11, 5.35e-4 * (1 - 5e-11), 0, 1)])
    assert "turned back along itself near phi_0 = 6.2755" in message and "6.2734" in message
    # The same fold the same way (a branch traced twice) or another moment is not the retrace.
    assert _retraced([first, second, turn, _fold(6.2734, 5.35e-4, 1, 0)]) == ""
    assert _retraced([first, second, turn, _fold(6.2734, 5.36e-4, 0, 1)]) == ""


@pytest.mark.slow
def test_the_long_chain_that_turns_back_is_reported_incomplete_with_where(tmp_path):
    config = tmp_path / "long.toml"
    config.write_text("N = 3000\n")
    out = CliRunner().invoke(app, ["critical", "--model", "nonlinear", "--config", str(config), "--json"])
    assert out.exit_code == 3, out.output
    assert "turned back along itself near phi_0 = 6.27" in out.stderr and "largest maximum of the traced part" in out.stderr
    summary = json.loads(out.stdout)["models"]["nonlinear"]
    assert summary["branch"]["stop"] == "reversed" and summary["branch_complete"] is False
    # M_c, from the part traced before the turn, is the first fold's, re-solved and confirmed.
    assert summary["M_c"] == pytest.approx(0.0988499823911, rel=1e-10) and summary["accurate"]
    # The trace ends at its first fold passed again the other way: the last one, not before.
    folds = [_fold(f["phi0"], f["M"] if "M" in f else f["moment"], f["index_before"], f["index_after"]) for f in summary["folds"]]
    assert _retraced(folds) and not _retraced(folds[:-1])
