"""The chain's branch searches a step that holds a fold of cycles in its halves, by the user systems' mechanism.

Across a fold the moment turns, so Brent's method in M between the two orbits of the step that holds it has no
bracket: a period doubling or torus in that step was reported unlocated (issue 40 item 4; the driven-end chain of
``tests/test_system_cycle_events_fold.py`` found it on a system's branch). ``periodic.continue_orbit`` now has the kit
locate the fold where a circle test also changes sign in its step, and searches the step in its two halves on either
side of the fold with ``cycle_events.steps``, the function a system's branch uses.

The chain's own steps across a fold are short (its multipliers move like the root of the distance in M there, and
the step is retaken shorter where they move far), so no chain searched (the paper's chain and random geometries,
N = 1-3, sine and nonlinear) had a period doubling in its fold's step. The step here is made of the paper's sine
chain at gamma_phi = 0.15: from its last orbit above the period doubling to its last orbit, past the fold; the fold
is the kit's, located as the continuation locates it. AUTO-07p 0.9.2 on the same chain from M = 0.1735
(``benchmarks/auto07p_chain_fold_step.py``, NTST = 200, DSMAX = 1e-3) labels the PD at M = 0.17288242687 and the LP
at 0.17073193979.
"""

from __future__ import annotations

from functools import partial

import numpy as np
import pytest

from cosserat_chain import ChainParams
from cosserat_chain.numerics import kit, periodic
from cosserat_chain.numerics.cycle_events import locate_circle_events, steps
from cosserat_chain.numerics.periodic import continue_orbit, find_periodic_orbit

#: AUTO-07p's labels on the branch (printed digits; the fold's period 13.766022526).
AUTO_PD, AUTO_PD_PERIOD, AUTO_LP = 0.17288242687, 12.85836551, 0.17073193979


def test_only_the_step_that_holds_a_fold_is_split_at_it():
    orbits = ["o0", "o1", "o2", "o3"]
    assert steps(orbits) == [(1, "o0", "o1"), (2, "o1", "o2"), (3, "o2", "o3")]
    assert steps(orbits, {2: "fold"}) == [(1, "o0", "o1"), (2, "o1", "fold"), (2, "fold", "o2"), (3, "o2", "o3")]


@pytest.fixture(scope="module")
def traced():
    """The branch from M = 0.2 to its fold, and the fold as the continuation's kit locates it (told to locate it)."""
    runs = []

    def spy(*args, **kwargs):
        runs.append(kit.continuation(*args, **kwargs))
        return runs[-1]

    own = periodic._OrbitBranchProblem.locate
    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(periodic, "continuation", spy)
        patch.setattr(periodic._OrbitBranchProblem, "locate", lambda self, kind, *rest: None if kind == "fold" else own(self, kind, *rest))
        branch = continue_orbit(find_periodic_orbit(ChainParams(gamma_phi=0.15), "sine", 0.2), period_max=2000.0)
    (fold,) = [e.point for e in runs[-1].events if e.kind == "fold" and e.located]
    return branch, fold


def test_the_fold_is_located_where_auto07p_labels_it_and_ends_the_branch(traced):
    branch, fold = traced
    assert branch.end == "fold" and branch.end_moment == fold.moment
    # The kit's fold to 1.4e-11 (the parabola through the last three orbits, the end without a located fold, 6e-9).
    assert fold.moment == pytest.approx(AUTO_LP, abs=5e-11)
    assert np.min(np.abs(fold.nontrivial_multipliers - 1.0)) < 1e-4


def test_a_step_over_a_period_doubling_and_the_fold_locates_it_at_auto07ps_value(traced):
    branch, fold = traced
    (event,) = [e for e in branch.events if e["kind"] == "period_doubling"]
    before = [o for o in branch.orbits if o.moment > event["moment"]][-1]
    after = branch.orbits[-1]
    assert after.moment > fold.moment and before.moment > event["moment"] > fold.moment
    solve = partial(
        periodic._orbit_between, method="dense", segments=None, tol=periodic.CLOSURE_TOL, rtol=periodic.RTOL, atol=periodic.ATOL
    )
    ((index, doubling),) = locate_circle_events([before, after], solve, folds={1: fold})
    assert index == 1 and doubling["kind"] == "period_doubling" and doubling["located"]
    assert doubling["moment"] == pytest.approx(AUTO_PD, abs=2e-11) and doubling["moment"] == pytest.approx(event["moment"], abs=1e-10)
    assert doubling["orbit"].period == pytest.approx(AUTO_PD_PERIOD, abs=1e-8)
    assert abs(doubling["multiplier"][0] + 1.0) < 1e-8


def test_the_continuation_asks_the_kit_to_locate_a_fold_only_where_a_circle_test_turns_in_its_step(traced):
    branch, fold = traced
    (event,) = [e for e in branch.events if e["kind"] == "period_doubling"]
    index = next(i for i, o in enumerate(branch.orbits) if o.moment < event["moment"])
    problem = periodic._OrbitBranchProblem.__new__(periodic._OrbitBranchProblem)
    problem.method = "dense"
    crossing = branch.orbits[index - 1 : index + 1]
    assert problem.locate("fold", None, None, 0.1, *crossing, index) is None
    unlocated = problem.locate("fold", None, None, 0.1, *branch.orbits[-2:], len(branch.orbits) - 1)
    assert not unlocated.located and unlocated.point is branch.orbits[-1] and unlocated.parameter == branch.orbits[-1].moment
    assert problem.locate("branch_point", None, None, 0.1, *crossing, index).located is False
