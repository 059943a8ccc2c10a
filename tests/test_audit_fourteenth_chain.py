"""Fourteenth session's outside audit of the chain: cases not in the other tests (H14aud).

A fold that ends the stable branch from rest is M_c only where the slowly loaded chain leaves rest there. The pinned-clamped
chain below folds at M = 1.2757 on the traced branch from rest (traced over its whole turn, no other stable part on it),
but the chain snaps onto a stable state of a branch the trace never reaches and rests there up to M = 8.8989: ramped runs
(load 0 -> M over 3000 time units, then held) rest at 1.01 times the first fold and at 0.99 times the second, and rotate
at 1.01 times the second (the audit's independent corner-spring energy, SymPy, holds the second fold at the same moment
to 5e-14 with the angle held).
"""

from __future__ import annotations

import numpy as np
import pytest
from typer.testing import CliRunner

from cosserat_chain import ChainParams, Schedule, moment_load
from cosserat_chain.cli import app
from cosserat_chain.experiments.critical import critical_point
from cosserat_chain.numerics.dynamics import integrate

#: Found by ramped runs against ``critical`` on random geometries (seed 3, case 14 of the audit's search, rounded).
SNAPPING = ChainParams(N=6, h=1.6, a=0.69, b=0.83, E1=2.3, E2=2.5, left_end="pinned")
LOADED = 3
FIRST_FOLD = 1.275699275431419


def _ramped(params: ChainParams, moment: float, particle: int) -> tuple[float, float]:
    """Largest |velocity| at the end and largest |phi| of a run with the load ramped 0 -> ``moment`` then held."""
    run = integrate(params, "nonlinear", moment_load(Schedule.ramp(moment, duration=3000.0), particle), t_end=5000.0, n_frames=11)
    return float(np.max(np.abs(run.v[-1]))), float(np.max(np.abs(run.x[:, 2])))


def test_a_fold_the_chain_snaps_past_onto_an_untraced_branch_is_not_mc():
    result = critical_point(SNAPPING, "nonlinear", particle=LOADED)
    assert result.complete and result.first_fold.moment == pytest.approx(FIRST_FOLD, rel=1e-9)
    # The chain rests just above the first fold: it is not where rotation starts.
    speed, turned = _ramped(SNAPPING, 1.01 * FIRST_FOLD, LOADED)
    assert speed < 1e-10 and turned < 1.0
    mc = result.critical_moment
    assert result.onset == "crossing_fold" and result.onset_checked and result.accurate
    assert mc == pytest.approx(8.898909901207288, rel=1e-6)
    speed, turned = _ramped(SNAPPING, 0.99 * mc, LOADED)
    assert speed < 1e-10 and turned < np.pi
    speed, turned = _ramped(SNAPPING, 1.01 * mc, LOADED)
    assert turned > 100.0


#: A graded chain whose trace stalls past its first fold: the chain snaps onto a stable branch that turns back in the loaded
#: angle at phi_0 = 1.2166 before its maximum of M (an independent load-stepped Newton on the SymPy energy holds it up to
#: 0.979 x 1.76631, none at 0.980 x). Followed with the angle held, the solve past the turn landed on another branch
#: (the other angles jumped by 3.4 rad, K indefinite there) and gave a fold at M = 1.76631 'accurate', where ramped runs
#: rotate at 0.99 of it (seed 3, case 28 of the audit's search). Followed to its own fold (M = 1.72982, phi_0 = 1.21754),
#: a relaxation at 1.001 x rests on one more branch, whose fold at 1.73512 is M_c; a ramped run at 0.999 x that rotates
#: (the snap's outcome between two folds 0.3 % apart depends on how the load rises).
JUMPING = ChainParams(
    N=2, h=1.252282550275866, a=0.5267697532522171, b=0.6886228434911934, E1=0.35806222884063343, E2=2.091060859133559,
    E1_factors=(0.6394398442798155, 1.2949614442024902, 1.4591659710394005, 1.020240694893079),
    E2_factors=(0.8835203933302729, 1.0098869655687766, 1.3292926338282425, 1.2467434606177825),
)  # fmt: skip


def test_a_crossing_branch_followed_past_its_turn_in_the_angle_is_not_a_fold_of_mc():
    jumped = 1.7663149471747406
    speed, turned = _ramped(JUMPING, 0.99 * jumped, -1)
    assert turned > 100.0  # the chain rotates below the old M_c
    result = critical_point(JUMPING, "nonlinear", particle=-1)
    # The followed branch's own fold (the reference: between 0.979 and 0.980 x 1.76631), where a relaxation at 1.001 x
    # rests on one more branch, whose fold at 1.73512 is M_c; the jump's 1.76631 is gone.
    assert result.critical_moment < 0.99 * jumped and result.crossing.moment == pytest.approx(1.7351194, rel=1e-6)
    speed, turned = _ramped(JUMPING, 0.99 * result.critical_moment, -1)
    assert speed < 1e-10 and turned < np.pi


def test_a_loop_of_symbolic_links_given_as_a_run_is_refused_naming_it(tmp_path):
    """``export``, ``draw`` and ``simulate --x0`` read a run through io.read_dataset: a loop of links raised OSError there
    (exit 1 with a traceback); now exit 2 naming the path and why."""
    (tmp_path / "a").symlink_to(tmp_path / "b")
    (tmp_path / "b").symlink_to(tmp_path / "a")
    result = CliRunner().invoke(app, ["export", str(tmp_path / "a"), "--to", "csv", "--out", str(tmp_path / "x.csv")])
    assert result.exit_code == 2, result.output
    assert "cannot be read: Too many levels of symbolic links" in result.output and str(tmp_path / "a") in result.output
    assert not (tmp_path / "x.csv").exists()


def test_diagram_on_a_chain_too_long_is_refused_by_its_estimate_before_any_array(tmp_path):
    """``diagram`` indexed the chain's degrees of freedom (the fold curve's moment_dof) before any memory check: N = 10^9
    failed at a 44.7 GiB allocation (N = 3 x 10^8 would have taken 7 GB); now critical's estimate refuses it first."""
    config = tmp_path / "huge.toml"
    config.write_text("N = 1000000000\n")
    result = CliRunner().invoke(app, ["diagram", "--vary", "E2", "--values", "0.5", "--config", str(config)])
    assert result.exit_code == 2, result.output
    assert "not enough memory: diagram on 2000000001 particles (N=1000000000) needs about" in result.output
