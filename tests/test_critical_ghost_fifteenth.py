"""The fold's normal form that decides how ``critical`` checks the chain's fate just above the fold (H15crit).

Above a saddle-node fold the damped chain crawls through the fold's ghost, gamma s' = mu - beta s^2 along K's null
vector, in the time pi gamma / sqrt(-mu beta) and always the way of mu's sign (:func:`critical.ghost_passage`). So one
relaxation, started on that side, decides what two decided, and where the ghost outlasts the relaxation's ``t_max`` none
is run: the check is then undecided, never read as "the chain leaves rest".
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from cosserat_chain import ChainParams, moment_load
from cosserat_chain.experiments import critical
from cosserat_chain.experiments.critical import critical_point, ghost_passage
from cosserat_chain.models.base import get_model
from cosserat_chain.numerics import relaxation
from cosserat_chain.numerics.dynamics import integrate
from cosserat_chain.numerics.stability import static_stability
from cosserat_chain.state import n_free, pack, unpack
from cosserat_chain.status import Status

MODEL = get_model("nonlinear")


def _fold_and_mode(params: ChainParams, result=None):
    """The first fold of the branch from rest (``result``'s, else computed) and K's unit null vector there."""
    fold = (result or critical_point(params, MODEL, dynamics=False)).first_fold
    mode = np.zeros(n_free(params))
    static_stability(params, MODEL, fold.x, start=mode)
    return fold, mode / np.linalg.norm(mode)


@pytest.mark.parametrize("n", [3, 10])
def test_the_ghost_runs_towards_the_traced_branch_past_the_fold(n):
    """The normal form's flow (mu's sign) points along the null vector to the unstable branch the trace follows past the
    fold: the traced branch's first unstable point lies on that side (N = 3 and N = 10 have opposite signs)."""
    params = ChainParams(N=n)
    result = critical_point(params, MODEL, dynamics=False)
    fold, mode = _fold_and_mode(params, result)
    time, flow = ghost_passage(params, MODEL, fold, mode, 1.001 * fold.moment)
    assert math.isfinite(time) and time > 0
    past = int(np.flatnonzero(~result.branch.stable)[0])
    side = float(pack(params, result.branch.x[past] - fold.x) @ mode)
    assert np.sign(side) == flow
    assert {3: -1.0, 10: 1.0}[n] == flow  # both signs are exercised


def test_the_ghost_passage_takes_the_normal_forms_time():
    """The chain's passage through the ghost, started upstream on the null vector, between s = -0.05 and +0.05, at 1e-4
    and 1e-5 above the fold (paper's chain): the normal form's time there is pi gamma / sqrt(-mu beta) less a part that
    does not depend on the excess, so the two passages differ by the difference of the predicted ones (measured 243.97
    against 244.14); a wrong gamma, mu or beta, or the wrong power of the excess, fails."""
    params = ChainParams(N=3)
    fold, mode = _fold_and_mode(params)
    passages, ghosts = [], []
    for excess in (1e-4, 1e-5):
        moment = (1 + excess) * fold.moment
        ghost, flow = ghost_passage(params, MODEL, fold, mode, moment)
        run = integrate(params, MODEL, moment_load(moment, 0), t_end=800.0, n_frames=8001, x0=fold.x - flow * 0.1 * unpack(params, mode))
        s = np.array([flow * pack(params, x - fold.x) @ mode for x in run.x])
        passages.append(run.time[np.argmax(s > 0.05)] - run.time[np.argmax(s > -0.05)])
        ghosts.append(ghost)
    assert passages[1] - passages[0] == pytest.approx(ghosts[1] - ghosts[0], rel=0.01)


def test_relaxations_that_decide_nothing_leave_the_traced_fold_unchecked(monkeypatch):
    """A relaxation that neither rests nor rotates within t_max is not 'the chain leaves rest': past the fold of a whole
    trace M_c stays the traced fold, accurate, without onset_checked (it was reported checked)."""
    params = ChainParams(N=3)
    checked = critical_point(params, MODEL, dynamics=False)
    assert checked.onset_checked and checked.onset == "fold"

    def undecided(params, model, moment, **kwargs):
        x = kwargs["x0"]
        return relaxation.RelaxationStep(Status.NOT_CONVERGED, x, 0 * x, 20000.0, 1.0, 1.0, 0.0, np.full(x.shape[1], np.nan), "")

    monkeypatch.setattr(relaxation, "relax", undecided)
    result = critical_point(params, MODEL, dynamics=False)
    assert result.critical_moment == checked.critical_moment and result.onset == "fold"
    assert not result.onset_checked and not result.crossing_unresolved and result.accurate


@pytest.mark.slow
def test_a_long_chains_fold_whose_ghost_outlasts_the_relaxation_is_left_unchecked():
    """N = 1000 on the paper's geometry: the fold's null vector is the long chain's slow bending (its loaded angle
    component 0.025) and the ghost takes 2.8e5 at 1.001 M_f, against relax's t_max of 20000 (two relaxations of that
    length had turned the loaded particle by 0.006 turn and were read as 'leaves rest'): none is run, M_c is the traced
    fold, not onset_checked."""
    params = ChainParams(N=1000)
    result = critical_point(params, MODEL, dynamics=False)
    fold, mode = _fold_and_mode(params, result)
    time, _ = ghost_passage(params, MODEL, fold, mode, critical.CROSSING_EXCESS * fold.moment)
    assert time / 2 > relaxation.RelaxSettings().t_max
    assert result.critical_moment == pytest.approx(0.1375458753980464, rel=1e-12)
    assert result.onset == "fold" and result.accurate and not result.onset_checked and not result.crossing_unresolved
