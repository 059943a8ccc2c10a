"""M_c where the trace of the branch is cut short past the first fold: the chain's way on is decided by relaxations.

On this chain (N = 10, a = 0.4166, b = 0.2224, the rest default) the nonlinear branch's stable part from rest ends at a
fold, M = 0.13239, and the corrector stalls further along (step_too_small). Past the fold a slowly loaded chain does not
rotate: it snaps onto a stable state near phi_0 = 1.08 that the trace never reached, and stays at rest on that branch
up to its own fold. Before, ``critical`` reported the first fold as M_c, ``accurate``; the onset is now found past the
traced part (:func:`~cosserat_chain.experiments.critical.onset_past`), and slowly ramped runs of the dynamics, an
independent method, rest just below it and rotate just above.
"""

import json
import math

import numpy as np
import pytest

from cosserat_chain import ChainParams
from cosserat_chain.experiments.critical import critical_point
from cosserat_chain.experiments.simulation import simulate
from cosserat_chain.loads import Schedule

STALLS = ChainParams(N=10, a=0.4166, b=0.2224)


@pytest.fixture(scope="module")
def result():
    return critical_point(STALLS, "nonlinear", dynamics=False)


def test_past_a_cut_short_trace_the_onset_is_the_fold_of_the_branch_the_chain_snaps_onto(result):
    assert result.branch.stop == "step_too_small" and not result.complete
    first = result.first_fold
    assert first.maximum and first.index_before == 0
    assert result.onset == "crossing_fold" and result.snap_through and result.accurate and not result.crossing_unresolved
    # The branch it rests on holds well more than the first fold: M_c is not the first fold's moment.
    assert result.critical_moment > 2.5 * first.moment
    assert result.as_dict()["M_c"] == result.crossing.moment and result.phi0_at_onset == result.crossing.phi0 > first.phi0


@pytest.mark.slow
@pytest.mark.parametrize("factor, rotates", [(0.99, False), (1.01, True)])
def test_a_slowly_ramped_run_rests_below_the_onset_and_rotates_above_it(result, factor, rotates):
    # The load rises from 0 over 1500 time units (the chain's slowest relaxation time is about 50), then is held for 500.
    moment = factor * result.critical_moment
    run = simulate(STALLS, "nonlinear", Schedule.ramp(moment, 1500.0), t_end=2000.0, n_frames=3)
    phi0 = float(run.phi.isel(time=-1).sel(particle=0))
    assert (abs(phi0) > 4 * math.pi) == rotates, phi0
    if not rotates:
        # At rest past the first fold: on the branch it snapped onto, near the onset's angle.
        assert np.isclose(phi0, result.phi0_at_onset, atol=0.2) and phi0 > 2 * result.first_fold.phi0


def test_the_command_decides_m_c_past_the_cut_short_trace_and_exits_0_noting_the_incomplete_branch(tmp_path):
    from typer.testing import CliRunner

    from cosserat_chain.cli import app

    config = tmp_path / "stalls.toml"
    config.write_text("N = 10\na = 0.4166\nb = 0.2224\n")
    result = CliRunner().invoke(app, ["critical", "--model", "nonlinear", "--json", "--config", str(config)])
    assert result.exit_code == 0, result.output
    summary = json.loads(result.stdout)["models"]["nonlinear"]
    assert summary["onset_checked"] is True and summary["branch_complete"] is False
    assert summary["onset"] == "crossing_fold" and summary["M_c"] == pytest.approx(0.371938, abs=1e-6)
    assert "note:" in result.stderr and "step_too_small" in result.stderr
