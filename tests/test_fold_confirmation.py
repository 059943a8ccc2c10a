"""Folds of a long chain confirmed by a second trace of the branch (``critical_point``).

Where K's softest eigenvalue at rest is near its round-off (a long clamped chain), a fold
that only one trace passes is round-off, not the branch's: each fold says whether a
second trace with other steps passed it too, and ``critical`` exits ``inaccurate`` where
the onset's fold is not confirmed.
"""

from __future__ import annotations

import json
import math
from dataclasses import replace

import numpy as np
import pytest
from typer.testing import CliRunner

from cosserat_chain import ChainParams
from cosserat_chain.cli import app
from cosserat_chain.cli.common import EXIT_CODES
from cosserat_chain.experiments import critical
from cosserat_chain.experiments.critical import CONFIRM_MOMENT_RTOL, CONFIRM_PHI0_ATOL, confirm_folds, critical_point
from cosserat_chain.linalg import smallest_eigenvalue
from cosserat_chain.models.base import get_model
from cosserat_chain.status import Status

runner = CliRunner()
#: The chain whose branch has two maxima and a minimum between them (tests/test_statics.py).
TWO_MAXIMA = ChainParams(N=10, a=0.3, b=0.1, E1=2.0, E2=0.3)


def test_a_short_chain_is_traced_once_and_its_folds_are_not_marked():
    result = critical_point(TWO_MAXIMA, "nonlinear")
    assert result.confirmation == "once" and result.accurate
    assert all(f.confirmed is None for f in result.branch.folds)
    # Each fold carries the change of stability: the index of K changes by one at it.
    first, minimum, largest = result.branch.folds[:3]
    assert (first.index_before, first.index_after) == (0, 1)
    assert (minimum.index_before, minimum.index_after) == (1, 0)
    assert (largest.index_before, largest.index_after) == (0, 1)
    for f in result.branch.folds:
        assert abs(f.index_after - f.index_before) == 1
    summary = result.as_dict()
    assert summary["folds"][0] == {
        "moment": first.moment, "phi0": first.phi0, "maximum": True, "index_before": 0, "index_after": 1, "confirmed": None,
        "discrepancy": None,
    }  # fmt: skip
    assert summary["accurate"] is True and summary["confirmation"] == "once"


def test_a_second_trace_with_other_steps_passes_the_same_folds(monkeypatch):
    # Every chain traced twice: the branch's real folds are passed by both traces.
    monkeypatch.setattr(critical, "CONFIRM_MARGIN", math.inf)
    once = critical_point(TWO_MAXIMA, "nonlinear", max_points=5000)
    seen = []
    result = critical_point(TWO_MAXIMA, "nonlinear", progress=lambda done, total: seen.append((done, total)))
    assert result.confirmation == "twice" and result.accurate
    assert [f.confirmed for f in result.branch.folds] == [True] * len(result.branch.folds)
    assert max(f.discrepancy for f in result.branch.folds) < 1e-10
    # Confirming changes nothing else: the same folds as a single trace (the first trace is the same).
    assert [(f.moment, f.phi0) for f in result.branch.folds] == [(f.moment, f.phi0) for f in once.branch.folds]
    assert result.critical_moment == once.critical_moment and result.first_fold.confirmed
    # The progress runs over both traces on one scale, to its end.
    totals = {total for _, total in seen}
    assert totals == {4 * math.pi} and max(done for done, _ in seen) == pytest.approx(4 * math.pi)
    assert all(b >= a for (a, _), (b, _) in zip(seen, seen[1:]))


def test_confirm_folds_matches_kind_moment_and_angle_within_the_tolerances():
    branch = critical_point(TWO_MAXIMA, "nonlinear").branch
    first = branch.folds[0]
    scale = max(abs(branch.moment))
    near = replace(first, moment=first.moment + 0.5 * CONFIRM_MOMENT_RTOL * scale, phi0=first.phi0 - 0.5 * CONFIRM_PHI0_ATOL)
    assert confirm_folds(branch, [near])[0].confirmed
    assert not confirm_folds(branch, [replace(first, moment=first.moment + 2 * CONFIRM_MOMENT_RTOL * scale)])[0].confirmed
    assert not confirm_folds(branch, [replace(first, phi0=first.phi0 + 2 * CONFIRM_PHI0_ATOL)])[0].confirmed
    assert not confirm_folds(branch, [replace(first, maximum=False)])[0].confirmed  # a minimum is another fold
    assert [f.confirmed for f in confirm_folds(branch, [])] == [False] * len(branch.folds)
    # The folds keep everything else.
    assert confirm_folds(branch, [near])[0].x is first.x and confirm_folds(branch, [near])[0].index_after == first.index_after


def _second_trace_moved(monkeypatch, shift: float = 1e-6):
    """Every chain traced twice, and the second trace's folds moved by ``shift`` in M (as round-off's folds move)."""
    monkeypatch.setattr(critical, "CONFIRM_MARGIN", math.inf)
    original = critical.continue_in_moment

    def traced(params, model, **kwargs):
        branch = original(params, model, **kwargs)
        if kwargs.get("step") is not None:
            branch.folds = [replace(f, moment=f.moment + shift) for f in branch.folds]
        return branch

    monkeypatch.setattr(critical, "continue_in_moment", traced)


def test_an_onset_fold_the_second_trace_does_not_pass_makes_the_result_inaccurate(monkeypatch):
    _second_trace_moved(monkeypatch)
    result = critical_point(ChainParams(), "nonlinear")
    assert result.confirmation == "twice"
    assert result.fold.confirmed is False and not result.accurate
    assert result.fold.discrepancy == pytest.approx(1e-6, rel=1e-6)
    assert result.to_dataset().attrs["accurate"] == 0


def test_critical_exits_inaccurate_and_still_prints_and_writes_an_unconfirmed_fold(monkeypatch, tmp_path):
    _second_trace_moved(monkeypatch)
    out = tmp_path / "critical.nc"
    result = runner.invoke(app, ["critical", "--model", "nonlinear", "--json", "--out", str(out)])
    assert result.exit_code == EXIT_CODES[Status.INACCURATE] == 5, result.output
    summary = json.loads(result.stdout.splitlines()[0])["models"]["nonlinear"]
    assert summary["accurate"] is False and summary["folds"][0]["confirmed"] is False
    assert "second trace" in result.output and "differ by up to 1e-06" in result.output and out.exists()


def test_a_failed_second_trace_leaves_the_folds_unconfirmed_and_says_why(monkeypatch):
    monkeypatch.setattr(critical, "CONFIRM_MARGIN", math.inf)
    original = critical.continue_in_moment

    def traced(params, model, **kwargs):
        if kwargs.get("step") is not None:
            raise critical.NewtonError("the corrector failed at arclength 0.1 from M=0.05", None)
        return original(params, model, **kwargs)

    monkeypatch.setattr(critical, "continue_in_moment", traced)
    result = critical_point(ChainParams(), "nonlinear")  # eq. (2)'s folds are confirmed by their closed form, not traced twice
    assert result.confirmation.startswith("the second trace failed: the corrector failed")
    assert not result.accurate and all(f.confirmed is False and f.discrepancy == math.inf for f in result.branch.folds)
    assert result.as_dict()["folds"][0]["discrepancy"] is None  # JSON has no inf


def test_a_chain_is_traced_twice_where_its_softest_eigenvalue_at_rest_nears_its_round_off():
    # The paper's geometry: K's softest eigenvalue (its bending mode, ~N^-4) over its
    # round-off is 18.5 at N = 1000 and 1.2 at N = 2000 (docs/statics.md).
    for N, expected in ((3, False), (1000, False), (2000, True)):
        params = ChainParams(N=N)
        value, resolution = smallest_eigenvalue(get_model("nonlinear").symmetric_similar(params, np.zeros((3, params.n_particles))))
        assert critical.near_singular_at_rest(params, get_model("nonlinear")) is expected
        assert (value < critical.CONFIRM_MARGIN * resolution) is expected
    # A ring and a model without a banded similar run the dense statics at small N: never twice.
    assert not critical.near_singular_at_rest(ChainParams(N=3, periodic=True), get_model("nonlinear"))


@pytest.mark.slow
def test_the_first_fold_of_a_long_chain_is_confirmed_by_the_second_trace():
    # N = 1500: K's softest eigenvalue at rest within ten times its round-off, so the branch
    # is traced twice; its first fold is the branch's, passed by both traces.
    result = critical_point(ChainParams(N=1500), "nonlinear")
    assert result.confirmation == "twice" and result.accurate
    assert result.first_fold.confirmed and result.fold.confirmed
