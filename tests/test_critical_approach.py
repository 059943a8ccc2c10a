"""A chain whose K at rest is beyond double precision: the trace starts from the approach from rest (issue 44 item 2).

At N = 3 10^4 the band factor the trace starts with gives the compliance 33 % off (its bending
modes lost); at N = 10^5 80 %, and the trace from rest crawled at moments of 1e-14, below the
corrector's limit of 1e-11, and turned back at a fold of round-off (M = 1.3e-13). The approach
solves the branch with the angle held at 2^-12 .. 1 rad from the rest response through K's
square root; the trace goes on from there.
"""

from __future__ import annotations

import numpy as np
import pytest

from cosserat_chain import ChainParams
from cosserat_chain.analysis.timoshenko import clamped_central_compliance
from cosserat_chain.experiments.critical import critical_point
from cosserat_chain.numerics import continuation
from cosserat_chain.numerics.continuation import APPROACH_ANGLE, APPROACH_HALVINGS, approach_from_rest, rest_resolved
from cosserat_chain.numerics.newton import solve_rotation_controlled
from cosserat_chain.state import ROW_INDEX

LONG = ChainParams(N=30_000)


def test_the_rest_is_resolved_up_to_n_1e4_and_not_at_3e4():
    assert rest_resolved(ChainParams(N=10**4), "nonlinear")
    assert not rest_resolved(LONG, "nonlinear") and not rest_resolved(LONG, "sine")


@pytest.mark.slow
def test_the_approach_rises_from_the_linear_response_to_one_radian():
    points = approach_from_rest(LONG, "nonlinear")
    angles = np.array([x[ROW_INDEX["phi"], LONG.N] for x, _ in points])
    moments = np.array([m for _, m in points])
    np.testing.assert_allclose(angles, APPROACH_ANGLE * 2.0 ** -np.arange(APPROACH_HALVINGS, -1, -1), rtol=0, atol=1e-15)
    assert np.all(np.diff(moments) > 0)
    # The first angle lies in the linear regime: M = phi_0 / compliance (the exact one), to the stiffening's 1e-3.
    assert moments[0] == pytest.approx(angles[0] / clamped_central_compliance(LONG, nodal=True), rel=1e-3)
    # The last is the rotation-controlled state of its angle, however it is reached (here from the one before
    # an eighth of a radian back, not from the halving's): M is the same to the residual's limit.
    x, m = solve_rotation_controlled(LONG, "nonlinear", 0.875, x0=points[-2][0] * 1.75, moment0=points[-2][1] * 1.75)
    again = solve_rotation_controlled(LONG, "nonlinear", 1.0, x0=x, moment0=m)[1]
    assert again == pytest.approx(moments[-1], rel=1e-7)


def test_an_approach_that_passes_a_maximum_of_m_ends_before_it(monkeypatch):
    # The paper's chain of N = 3 has its fold at phi_0 = 1.04: an approach to 2 rad ends at the last angle below it.
    monkeypatch.setattr(continuation, "APPROACH_ANGLE", 2.0)
    points = approach_from_rest(ChainParams(N=3), "nonlinear")
    angles = [x[ROW_INDEX["phi"], 3] for x, _ in points]
    assert angles[-1] == pytest.approx(1.0) and len(points) == APPROACH_HALVINGS
    branch = continuation.continue_in_moment(ChainParams(N=3), "nonlinear", phi0_stop=2.0, from_approach=True)
    assert branch.approach == APPROACH_HALVINGS and branch.moment[0] == 0.0
    assert branch.folds and branch.folds[0].moment == pytest.approx(0.197495317503289, rel=1e-12)


@pytest.mark.slow
def test_the_nonlinear_m_c_of_n_3e4_from_the_approach_is_the_confirmed_fold():
    """From rest (before) the same fold: 0.0468956686397 (re-solved and confirmed), the compliance 1.1e-5 off."""
    result = critical_point(LONG, "nonlinear")
    assert result.branch.approach == APPROACH_HALVINGS + 1
    assert result.compliance == pytest.approx(clamped_central_compliance(LONG, nodal=True), rel=1e-11)
    fold = result.fold
    assert result.confirmation == "re-solved" and fold.confirmed and result.accurate and fold is result.first_fold
    assert fold.moment == pytest.approx(0.04689566864, rel=1e-9) and fold.phi0 == pytest.approx(3.64368, abs=1e-4)
