"""Folds of a long chain confirmed by a re-solve near each fold (``critical_point``).

Where K's softest eigenvalue at rest is near its round-off (a long clamped chain), a fold
the trace passes may be round-off, not the branch's: each fold that decides M_c says whether
a re-solve on the rotation-controlled branch found it too, and ``critical`` exits
``inaccurate`` where the onset's fold is not confirmed.
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
from cosserat_chain.experiments.critical import CONFIRM_MOMENT_RTOL, CONFIRM_PHI0_ATOL, confirm_folds, critical_point, resolve_fold
from cosserat_chain.linalg import smallest_eigenvalue
from cosserat_chain.models.base import get_model
from cosserat_chain.status import Status
from static_onsets import TWO_MAXIMA, nonlinear_critical

runner = CliRunner()


def test_a_short_chain_is_traced_once_and_its_folds_are_not_marked():
    result = nonlinear_critical(TWO_MAXIMA)
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


def test_the_folds_that_decide_m_c_are_found_again_by_their_re_solve(monkeypatch):
    # Every chain re-solved: the first fold and the larger maximum after it (M_c) are found again.
    monkeypatch.setattr(critical, "CONFIRM_MARGIN", math.inf)
    once = critical_point(TWO_MAXIMA, "nonlinear", max_points=5000)
    seen = []
    result = critical_point(TWO_MAXIMA, "nonlinear", progress=lambda done, total: seen.append((done, total)))
    assert result.confirmation == "re-solved" and result.accurate
    deciding = [f for f in result.branch.folds if f.confirmed is not None]
    assert deciding == [result.first_fold, result.fold] and result.fold is not result.first_fold
    assert all(f.confirmed for f in deciding) and max(f.discrepancy for f in deciding) < 1e-10
    # The other folds (the minimum between the maxima, the mirrored ones) are not re-solved.
    assert all(f.confirmed is None and f.discrepancy is None for f in result.branch.folds if f not in deciding)
    # Confirming changes nothing else: the same folds as a single trace (the trace is the same).
    assert [(f.moment, f.phi0) for f in result.branch.folds] == [(f.moment, f.phi0) for f in once.branch.folds]
    assert result.critical_moment == once.critical_moment
    # One trace: the progress runs over one turn, to its end.
    totals = {total for _, total in seen}
    assert totals == {2 * math.pi} and max(done for done, _ in seen) == pytest.approx(2 * math.pi)
    assert all(b >= a for (a, _), (b, _) in zip(seen, seen[1:]))


def test_the_re_solve_finds_a_fold_where_m_is_stationary_and_no_fold_elsewhere_on_the_branch():
    # The re-solve's root of dM/dphi_0 is the traced fold's; a point of the branch where M still
    # rises, dressed up as a fold, has no root of dM/dphi_0 within the tolerance: not found.
    branch = nonlinear_critical(TWO_MAXIMA).branch
    first = branch.folds[0]
    found = resolve_fold(TWO_MAXIMA, get_model("nonlinear"), first)
    assert found is not None and found.maximum
    assert abs(found.moment - first.moment) < 1e-12 and abs(found.phi0 - first.phi0) < 1e-8
    rising = int(np.argmax(branch.phi0 > 0.5 * first.phi0))
    fake = replace(first, moment=float(branch.moment[rising]), phi0=float(branch.phi0[rising]), x=branch.x[rising])
    assert resolve_fold(TWO_MAXIMA, get_model("nonlinear"), fake) is None
    # A maximum is not a minimum: the same fold asked for as a minimum is not found.
    assert resolve_fold(TWO_MAXIMA, get_model("nonlinear"), replace(first, maximum=False)) is None


def test_confirm_folds_matches_kind_moment_and_angle_within_the_tolerances():
    branch = nonlinear_critical(TWO_MAXIMA).branch
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


def test_the_re_solve_narrows_its_bracket_where_phi0_turns_back_next_to_the_fold(monkeypatch):
    # phi_0 can turn back within the bracket (two folds of N = 1000, 1e-6 rad beyond them): no state
    # there, the solve fails, and a narrower bracket finds the fold; failing everywhere, none is found.
    first = nonlinear_critical(TWO_MAXIMA).branch.folds[0]
    original = critical.solve_rotation_controlled

    def reachable(params, model, angle, **kwargs):
        if abs(angle - first.phi0) > 2e-6:
            raise critical.NewtonError(f"no state at phi0={angle}", None)
        return original(params, model, angle, **kwargs)

    monkeypatch.setattr(critical, "solve_rotation_controlled", reachable)
    found = resolve_fold(TWO_MAXIMA, get_model("nonlinear"), first)
    assert found is not None and abs(found.moment - first.moment) < 1e-12 and abs(found.phi0 - first.phi0) < 1e-9
    monkeypatch.setattr(critical, "CONFIRM_NARROWING", np.array([1.0, 0.5]))
    assert resolve_fold(TWO_MAXIMA, get_model("nonlinear"), first) is None


def _re_solve_moved(monkeypatch, shift: float = 1e-6):
    """Every chain re-solved, and the re-solved folds moved by ``shift`` in M (as round-off's folds move)."""
    monkeypatch.setattr(critical, "CONFIRM_MARGIN", math.inf)
    original = critical.resolve_fold

    def moved(*args, **kwargs):
        found = original(*args, **kwargs)
        return None if found is None else replace(found, moment=found.moment + shift)

    monkeypatch.setattr(critical, "resolve_fold", moved)


def test_an_onset_fold_the_re_solve_does_not_find_makes_the_result_inaccurate(monkeypatch):
    _re_solve_moved(monkeypatch)
    result = critical_point(ChainParams(), "nonlinear")
    assert result.confirmation == "re-solved"
    assert result.fold.confirmed is False and not result.accurate
    assert result.fold.discrepancy == pytest.approx(1e-6, rel=1e-6)
    assert result.to_dataset().attrs["accurate"] == 0


def test_critical_exits_inaccurate_and_still_prints_and_writes_an_unconfirmed_fold(monkeypatch, tmp_path):
    _re_solve_moved(monkeypatch)
    out = tmp_path / "critical.nc"
    result = runner.invoke(app, ["critical", "--model", "nonlinear", "--json", "--out", str(out)])
    assert result.exit_code == EXIT_CODES[Status.INACCURATE] == 5, result.output
    summary = json.loads(result.stdout.splitlines()[0])["models"]["nonlinear"]
    assert summary["accurate"] is False and summary["folds"][0]["confirmed"] is False
    assert "re-solve" in result.output and "differ by up to 1e-06" in result.output and out.exists()


def test_a_failed_re_solve_leaves_the_fold_unconfirmed(monkeypatch):
    monkeypatch.setattr(critical, "CONFIRM_MARGIN", math.inf)

    def failing(*args, **kwargs):
        raise critical.NewtonError("not converged", None)

    monkeypatch.setattr(critical, "solve_rotation_controlled", failing)
    result = critical_point(ChainParams(), "nonlinear")  # eq. (2)'s folds are confirmed by their closed form, not re-solved
    assert result.confirmation == "re-solved" and not result.accurate
    assert result.first_fold.confirmed is False and result.first_fold.discrepancy == math.inf
    assert result.as_dict()["folds"][0]["discrepancy"] is None  # JSON has no inf


def test_folds_are_re_solved_where_the_softest_eigenvalue_at_rest_nears_its_round_off():
    # The paper's geometry: K's softest eigenvalue (its bending mode, ~N^-4) over its
    # round-off is 18.5 at N = 1000 and 1.2 at N = 2000 (docs/statics.md).
    for N, expected in ((3, False), (1000, False), (2000, True)):
        params = ChainParams(N=N)
        value, resolution = smallest_eigenvalue(get_model("nonlinear").symmetric_similar(params, np.zeros((3, params.n_particles))))
        assert critical.near_singular_at_rest(params, get_model("nonlinear")) is expected
        assert (value < critical.CONFIRM_MARGIN * resolution) is expected
    # A ring and a model without a banded similar run the dense statics at small N: never re-solved.
    assert not critical.near_singular_at_rest(ChainParams(N=3, periodic=True), get_model("nonlinear"))


@pytest.mark.slow
def test_the_first_fold_of_a_long_chain_is_confirmed_by_its_re_solve():
    # N = 1500: K's softest eigenvalue at rest within ten times its round-off, so the folds that
    # decide M_c are re-solved; the first fold is the branch's, found again.
    result = critical_point(ChainParams(N=1500), "nonlinear")
    assert result.confirmation == "re-solved" and result.accurate
    assert result.first_fold.confirmed and result.fold.confirmed
