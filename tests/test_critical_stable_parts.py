"""M_c is where the highest stable part of the branch ends, not a maximum approached on an unstable part.

A short nonlinear chain (found by an outside audit) snaps through at its first fold onto a later
stable part of the branch; that part ends at a branch point, M = 2.8474, before the branch's
largest maximum, M = 2.8634, which is approached with one negative eigenvalue of K. The damped
dynamics decide which is the onset of rotation: the chain stays at rest just below the branch
point and rotates just above it, below the maximum.
"""

from __future__ import annotations

import numpy as np
import pytest

from cosserat_chain.experiments.critical import critical_point
from cosserat_chain.loads import moment_load
from cosserat_chain.numerics.newton import solve_equilibrium
from cosserat_chain.numerics.relaxation import relax
from cosserat_chain.numerics.stability import static_stability
from cosserat_chain.params import ChainParams

AUDIT_CHAIN = ChainParams(N=2, a=0.3322182094875878, b=0.4917337074310625, E1=1.639467623071645, E2=2.649938651532578)


@pytest.fixture(scope="module")
def audit_result():
    return critical_point(AUDIT_CHAIN, "nonlinear")


def test_the_onset_is_the_branch_point_ending_the_later_stable_part(audit_result):
    r = audit_result
    point = r.branch_point
    assert r.onset == "branch_point" and r.critical_moment == point.moment
    assert point.index_before == 0 < point.index_after and point.located
    # The branch's largest maximum lies higher, approached with K indefinite: not where the chain leaves.
    assert r.fold.maximum and r.fold.index_before == 1 and r.fold.moment > point.moment + 1e-2
    # The stable branch from rest ends earlier at its first fold: a snap-through onto the later stable part.
    assert r.end == "fold" and r.snap_through and r.first_fold.moment < point.moment
    assert r.first_fold.index_before == 0
    assert static_stability(AUDIT_CHAIN, "nonlinear", r.snap_to.x).stable
    assert r.snap_to.phi0 > r.first_fold.phi0
    as_json = r.as_dict()
    assert as_json["M_c"] == point.moment and as_json["onset"] == "branch_point" and as_json["end"] == "fold"
    assert as_json["snap_through"] and as_json["largest_fold"]["moment"] == r.fold.moment


def test_the_chain_rests_below_the_branch_point_and_rotates_above_it_below_the_maximum(audit_result):
    point = audit_result.branch_point
    i = point.after_point
    assert audit_result.branch.stable[i] and not audit_result.branch.stable[i + 1]
    below = solve_equilibrium(AUDIT_CHAIN, "nonlinear", moment_load(0.995 * point.moment), x0=audit_result.branch.x[i])
    rest = relax(AUDIT_CHAIN, "nonlinear", 0.998 * point.moment, x0=below)
    assert rest.status.value == "static" and abs(rest.x[2, AUDIT_CHAIN.N] - point.phi0) < 0.1
    above = 1.001 * point.moment
    assert above < audit_result.fold.moment
    assert relax(AUDIT_CHAIN, "nonlinear", above, x0=rest.x).status.value == "rotating"


def test_no_stable_part_ends_higher_than_the_onset(audit_result):
    """Every maximum approached with index 0 and every branch point left with index 0 holds at most M_c."""
    r = audit_result
    ends = [f.moment for f in r.branch.folds if f.maximum and f.index_before == 0]
    ends += [q.moment for q in r.branch.branch_points if q.index_before == 0 < q.index_after]
    assert max(ends) == r.critical_moment
    # The traced points' moments on stable parts never exceed M_c (to the located points' accuracy).
    assert np.max(r.branch.moment[r.branch.stable]) <= r.critical_moment * (1 + 1e-9)
