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
from cosserat_chain.models.base import get_model
from cosserat_chain.numerics import continuation
from cosserat_chain.numerics.continuation import continue_in_moment
from cosserat_chain.numerics.kit import BranchEnd
from cosserat_chain.numerics.newton import moment_dof
from cosserat_chain.state import pack

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


@pytest.mark.slow
def test_critical_ends_a_long_nonlinear_chains_turn_once_m_c_is_decided():
    # N = 2000 is near singular at rest (K's softest eigenvalue within ten times its round-off): the trace ends
    # short of the turn; N = 300 is resolved at rest and traces the whole turn, as before.
    result = critical_point(ChainParams(N=2000), "nonlinear", dynamics=False)
    assert result.accurate and result.complete and result.end == "fold" and result.branch.stop == BranchEnd.DECIDED
    assert result.fold is result.first_fold and result.fold.confirmed
    assert critical_point(ChainParams(N=300), "nonlinear", dynamics=False).branch.stop == BranchEnd.ANGLE_LIMIT


def test_eq_2s_branch_to_its_first_fold_in_closed_form_is_static_and_meets_the_trace():
    params = ChainParams(N=2000)
    model = get_model("sine")
    result = critical_point(params, model, dynamics=False)
    branch = result.branch
    assert result.accurate and result.complete and result.end == "fold" and branch.stop == BranchEnd.MAX_FOLDS
    # Every closed-form point is a static state under its moment (to round-off of the forces) ...
    for moment, x in zip(branch.moment, branch.x, strict=True):
        residual = model.packed_forces(params, pack(params, x))
        residual[moment_dof(params, 0)] += moment
        assert np.max(np.abs(residual)) < 1e-12
    # ... stable up to the fold by eq. (2)'s theorem (K's inertia counted), index one beyond it.
    assert branch.stable[:-1].all() and not branch.stable[-1]
    fold = result.fold
    assert (fold.index_before, fold.index_after, fold.phi0) == (0, 1, math.pi / 2) and result.onset_particle == 0
    # The trace from rest, stopped at its first fold, finds the same fold to its round-off.
    traced = continue_in_moment(params, model, max_folds=1).folds[0]
    assert traced.moment == pytest.approx(fold.moment, rel=1e-6) and traced.phi0 == pytest.approx(fold.phi0, abs=1e-4)
    assert 2000 * fold.moment == pytest.approx(0.64, abs=1e-4)  # N M_c -> 0.64 (tests/test_critical_scaling.py)
