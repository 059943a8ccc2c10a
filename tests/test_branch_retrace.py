"""A static trace that turns back along itself ends "reversed", incomplete, instead of "returned" as if complete.

The paper's geometry at N = 3000 (nonlinear model) has a cluster of folds and a branch point
near phi_0 = 6.2754, M = 3.6e-4, within the corrector's resolution: the trace turned back
there, passed its folds again in reverse order (each at the same moment and angle to 1e-10,
its index changing the other way) and came back through the rest state, which used to end
the branch "returned" and report it complete. `critical` now ends that chain's trace where M_c is
decided, short of the cluster; the whole turn is traced by ``continue_in_moment(decided=False)``.
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
    import math

    from cosserat_chain import ChainParams
    from cosserat_chain.experiments.critical import max_states
    from cosserat_chain.numerics.continuation import continue_in_moment, moment_response, rest_resolved

    # `critical` ends this chain's trace once M_c is decided, 0.25 rad short of the turn, before the folds' cluster near
    # phi_0 = 6.275 (M ~ 1e-4, a fifth of M_c at most there): complete, with the first fold's M_c re-solved and
    # confirmed, to the residual's round-off limit at this N (2e-10: the corrector's settings move it within that).
    config = tmp_path / "long.toml"
    config.write_text("N = 3000\n")
    out = CliRunner().invoke(app, ["critical", "--model", "nonlinear", "--config", str(config), "--json"])
    assert out.exit_code == 0, out.output
    summary = json.loads(out.stdout)["models"]["nonlinear"]
    assert summary["branch"]["stop"] == "decided" and summary["branch_complete"] is True
    assert summary["M_c"] == pytest.approx(0.0988499823911, rel=3e-9) and summary["accurate"]
    # The whole turn, traced on (decided=False), meets that cluster: within it the trace either turns back along
    # itself, and ends at its first fold passed again the other way, or meets a fold its corrector cannot locate and
    # ends there; either way it says where, and never "returned" as if complete.
    params = ChainParams(N=3000)
    response = moment_response(params, "nonlinear")
    branch = continue_in_moment(
        params, "nonlinear", phi0_stop=16 * 2 * math.pi, phi0_until_unstable=2 * math.pi, max_states=max_states(params),
        response=response, from_approach=not rest_resolved(params, "nonlinear", response=response),
    )  # fmt: skip
    folds = [_fold(f.phi0, f.moment, f.index_before, f.index_after) for f in branch.folds]
    assert branch.folds[0].moment == pytest.approx(0.0988499823911, rel=3e-9)
    if branch.stop == "reversed":
        assert "turned back along itself near phi_0 = 6.27" in branch.message
        assert _retraced(folds) and not _retraced(folds[:-1])
    else:
        assert branch.stop == "step_too_small" and "was not located" in branch.message
        assert "(phi_0 = 6.27" in branch.message and not _retraced(folds)


def test_a_fold_the_corrector_cannot_locate_ends_the_trace_and_keeps_what_was_traced(monkeypatch):
    # A fold whose corrector fails (seen in the drifting crawl of N = 10^4 with another chord
    # setting) used to raise NewtonError out of the trace: every point before it was lost.
    from cosserat_chain import ChainParams
    from cosserat_chain.experiments.critical import critical_point
    from cosserat_chain.numerics.newton import NewtonError

    whole = critical_point(ChainParams(), "nonlinear")
    solved = _StaticBranch._solved

    def failing(self, y, tangent, s, what):
        if what == "fold" and len(self.located_folds) == 1:
            raise NewtonError("the corrector failed (test)", np.zeros(1))
        return solved(self, y, tangent, s, what)

    monkeypatch.setattr(_StaticBranch, "_solved", failing)
    cut = critical_point(ChainParams(), "nonlinear")
    branch = cut.branch
    assert branch.stop == "step_too_small" and not cut.complete
    assert "was not located (the corrector failed (test))" in branch.message and "the branch beyond is not traced" in branch.message
    # The first fold (M_c) is kept as located before; the trace ends at the second, unlocated.
    assert len(branch.folds) == 1 and branch.folds[0].moment == whole.branch.folds[0].moment
    second = whole.branch.folds[1]
    assert branch.phi0[-2] < second.phi0 < branch.phi0[-1] and min(branch.moment[-2:]) > second.moment
    # Past the cut the command checks M_c by relaxations (the chain leaves rest just above it): the incomplete branch is
    # noted, not an error, and M_c is the whole trace's.
    out = CliRunner().invoke(app, ["critical", "--model", "nonlinear", "--json"])
    summary = json.loads(out.stdout)["models"]["nonlinear"]
    assert out.exit_code == 0 and "note:" in out.stderr and "was not located" in out.stderr
    assert summary["onset_checked"] and not summary["branch_complete"] and summary["M_c"] == whole.critical_moment


def test_a_fold_brent_puts_at_the_step_s_start_is_that_point(monkeypatch):
    # Brent's method may return the bracket's end s = 0 (the step's start, whose slope it had
    # from the tangent, not from a solve): at N = 10^5 that raised KeyError after minutes.
    from cosserat_chain import ChainParams
    from cosserat_chain.numerics import continuation

    def at_start(f, a, b, **options):
        f(a)
        return a

    monkeypatch.setattr(continuation, "brentq", at_start)
    branch = continuation.continue_in_moment(ChainParams(), "nonlinear")
    assert branch.folds and all(any(f.moment == m for m in branch.moment) for f in branch.folds)
