"""The trace ended where M_c is decided (``continue_in_moment(decided=True)``), against the full turn.

A long clamped chain's turn ends near the chain at rest turned once, where the trace hangs on
round-off (N = 10^5 crawled there); ``critical`` ends it once M_c is decided: the stable branch
from rest ended at a fold, the loaded particle within ``END_ANGLE`` of the turn and |M| fallen to
``END_MOMENT`` of the largest maximum. The ended trace must be the full turn's up to its end, bit
for bit, with every fold the full turn has and the same largest maximum (M_c), for both models,
the paper's chain and random admissible geometries.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from conftest import random_geometries
from cosserat_chain import ChainParams
from cosserat_chain.experiments.critical import critical_point
from cosserat_chain.numerics import continuation
from cosserat_chain.numerics.continuation import continue_in_moment
from cosserat_chain.numerics.kit import BranchEnd

TURN = 2 * math.pi
CHAINS = [ChainParams(N=10), ChainParams(N=100), *random_geometries(2, seed=3)]


def largest_maximum(branch) -> float:
    return max(f.moment for f in branch.folds if f.maximum)


@pytest.mark.parametrize("model", ["nonlinear", "sine"])
@pytest.mark.parametrize("params", CHAINS, ids=lambda p: f"N{p.N}-a{p.a:.3f}")
def test_the_trace_ended_where_m_c_is_decided_is_the_full_turn_up_to_its_end(params, model):
    full = continue_in_moment(params, model, phi0_stop=TURN, phi0_until_unstable=TURN)
    ended = continue_in_moment(params, model, phi0_stop=TURN, phi0_until_unstable=TURN, decided=True)
    assert full.stop == BranchEnd.ANGLE_LIMIT and ended.stop == BranchEnd.DECIDED
    k = ended.moment.size
    assert k < full.moment.size
    for name in ("moment", "phi0", "stable", "critical_eigenvalue"):
        assert np.array_equal(getattr(ended, name), getattr(full, name)[:k]), name
    # Every fold of the turn lies before the end, and M_c, the largest maximum, is the full turn's.
    assert [(f.moment, f.phi0) for f in ended.folds] == [(f.moment, f.phi0) for f in full.folds]
    assert largest_maximum(ended) == largest_maximum(full)
    # Where it ended: within END_ANGLE of the turn, past the stable branch's end, |M| far below M_c.
    assert TURN - continuation.END_ANGLE <= abs(ended.phi0[-1]) < TURN and not ended.stable.all()
    assert abs(ended.moment[-1]) <= continuation.END_MOMENT * largest_maximum(ended)
    assert "M_c is decided" in ended.message and np.all(np.abs(full.moment[k:]) < largest_maximum(full))


def test_a_branch_still_stable_at_the_turn_is_not_ended():
    # A cantilever of the paper's geometry stays stable beyond its first turn (1.41 N rad): M_c is not decided there.
    cantilever = ChainParams(N=5, right_end="free")
    branch = continue_in_moment(cantilever, "nonlinear", phi0_stop=TURN, decided=True)
    assert branch.stable.all() and not branch.folds and branch.stop == BranchEnd.ANGLE_LIMIT


@pytest.mark.parametrize("model", ["nonlinear", "sine"])
def test_critical_ends_a_long_chains_turn_once_m_c_is_decided(model):
    # N = 2000 is near singular at rest (K's softest eigenvalue within ten times its round-off): the nonlinear
    # trace ends short of the turn, eq. (2)'s at its first fold (its closed form bounds every static state's M).
    result = critical_point(ChainParams(N=2000), model, dynamics=False)
    assert result.accurate and result.complete and result.end == "fold"
    assert result.branch.stop == (BranchEnd.DECIDED if model == "nonlinear" else BranchEnd.MAX_FOLDS)
    short = critical_point(ChainParams(N=300), model, dynamics=False)
    assert short.branch.stop == BranchEnd.ANGLE_LIMIT  # resolved at rest: the whole turn, as before
    # M_c on the trend of the paper's geometry (tests/test_critical_scaling.py: N M_c -> 0.64 for eq. (2)).
    if model == "sine":
        assert 2000 * result.critical_moment == pytest.approx(0.64, abs=1e-4)
    else:
        assert result.fold is result.first_fold and result.fold.confirmed
