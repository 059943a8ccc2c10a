"""The cusp of cycles on a fold-of-cycles curve (issue 40, item 4): ``numerics.cycle_curve``.

The N = 2 sine chain's fold of cycles (the lower edge of its hysteresis at gamma_phi = 0.15),
followed up in gamma_phi, turns back at gamma_phi = 0.51403582665: there it meets a second fold
of the same orbit branch and both vanish. The cusp is checked against what does not use the
pseudo-arclength that locates it: the two folds solved at values below it by natural steps from
either branch (their moments part like the distance to the cusp to the power 3/2, the cusp's
normal form), and the one-parameter continuations in M on either side (a fold near the cusp's
moment below it, none above).
"""

from __future__ import annotations

import json
import math
from types import SimpleNamespace

import numpy as np
import pytest

from cosserat_chain import ChainParams
from cosserat_chain.numerics.continuation import locate_fold
from cosserat_chain.numerics.cycle_curve import CUSP_LABELS, KINDS, Codim2Point, continue_cycle_end
from cosserat_chain.numerics.periodic import continue_orbit, find_periodic_orbit

#: Distances below the cusp (in gamma_phi) at which the two folds are solved, each four times the one before.
DISTANCES = (1e-4, 4e-4, 1.6e-3)


@pytest.fixture(scope="module")
def curve():
    """The N = 2 chain's fold of cycles followed from gamma_phi = 0.15 towards 0.52, beyond its cusp."""
    chain = ChainParams(N=2, gamma_phi=0.15)
    branch = continue_orbit(find_periodic_orbit(chain, "sine", 1.05 * locate_fold(chain, "sine").moment), period_max=200.0)
    assert branch.end == "fold"
    return continue_cycle_end(branch.orbits[-2], "fold_of_cycles", "gamma_phi", [0.15, 0.3, 0.5, 0.52])


@pytest.fixture(scope="module")
def cusp(curve):
    return curve.points[-1]


@pytest.mark.slow
def test_the_fold_of_cycles_curve_turns_back_in_the_damping_at_a_named_cusp(curve, cusp):
    assert not curve.complete and list(curve.values) == [0.15, 0.3, 0.5]
    assert cusp.kind == "cusp" and cusp.label == "CP" and cusp.name == "cusp"
    assert "cusp (CP)" in curve.message and "turns back in gamma_phi" in curve.message
    assert cusp.value == pytest.approx(0.51403582665, abs=1e-9)
    assert cusp.moment == pytest.approx(0.47459877, abs=1e-7)
    assert 0 < cusp.uncertainty < 1e-8
    # The curve's tangent has neither a p- nor an M-component there: its projection on (p, M) has a cusp.
    assert abs(cusp.test) < 1e-6 and abs(cusp.tangent_moment) < 1e-6
    # A fold of cycles still: a second multiplier at +1 beside the trivial one.
    assert np.sort(np.abs(cusp.orbit.multipliers - 1.0))[1] < 1e-3
    # The two branches of the bracket lie below the cusp in gamma_phi (it is the largest value on the curve).
    (value_a, orbit_a), (value_b, orbit_b) = cusp.branches
    assert max(value_a, value_b) <= cusp.value + cusp.uncertainty
    assert min(value_a, value_b) > 0.5
    assert orbit_a.moment != orbit_b.moment
    summary = json.loads(json.dumps(curve.as_dict()))["codim2"][-1]
    assert summary["label"] == "CP" and len(summary["branches"]) == 2


@pytest.mark.slow
def test_below_the_cusp_the_two_folds_part_like_the_distance_to_the_power_three_halves(curve, cusp):
    """Each fold followed by natural steps (no arclength) from its own branch's orbit to cusp - delta."""
    moments = []
    for value, orbit in cusp.branches:
        followed = continue_cycle_end(orbit, "fold_of_cycles", "gamma_phi", [value, *(cusp.value - d for d in DISTANCES)])
        assert followed.complete
        moments.append(followed.moment[1:])
    gap = np.abs(moments[0] - moments[1])
    exponents = np.diff(np.log(gap)) / math.log(4.0)
    assert np.all(np.abs(exponents - 1.5) < 0.01), exponents  # a cusp value 2e-6 off fails this
    # Both meet the cusp's moment as the distance shrinks (M moves about as fast as gamma_phi along the curve).
    assert np.all(np.abs(np.array(moments) - cusp.moment) <= 2.0 * np.array(DISTANCES))


@pytest.mark.slow
def test_one_parameter_continuations_in_the_moment_find_the_fold_below_the_cusp_and_none_above(curve, cusp):
    delta = 4e-3
    folds = {}
    for value, orbit in cusp.branches:
        folds[orbit.moment] = continue_cycle_end(orbit, "fold_of_cycles", "gamma_phi", [value, cusp.value - delta]).moment[-1]
    lower = min(folds.values())
    below = continue_orbit(find_periodic_orbit(ChainParams(N=2, gamma_phi=cusp.value - delta), "sine", 0.6), period_max=200.0)
    # The branch down from M = 0.6 turns at the lower of the two folds (8e-5 apart): none of its orbits lies
    # below it, the nearest within a step. Its own estimate of the turn (a parabola through the orbits around
    # it) is coarse here, where the fold's quadratic coefficient is nearly zero: 1.4e-4 below.
    assert below.end == "fold" and below.end_moment == pytest.approx(lower, abs=3e-4)
    assert lower - 1e-9 <= np.min(below.moment) < lower + 1e-4
    above = continue_orbit(find_periodic_orbit(ChainParams(N=2, gamma_phi=cusp.value + delta), "sine", 0.6), period_max=200.0)
    # Above the cusp the branch passes its moment without turning: its next end lies far below.
    assert above.end_moment < cusp.moment - 0.05
    assert np.all(np.diff(above.moment[above.moment > cusp.moment - 0.05]) < 0)


def test_a_cusp_is_named_and_serialised_with_its_branches():
    orbit = SimpleNamespace(moment=0.47, period=6.67)
    extra = {"branches": ((0.5139, orbit), (0.5138, orbit)), "tangent_moment": 0.0, "branch_moments": (0.47, 0.47)}
    point = Codim2Point("cusp", CUSP_LABELS["cusp"], 0.514, 0.47, 6.67, orbit, 1e-9, 1e-9, **extra)
    assert point.name == "cusp" and point.label == "CP"
    summary = json.loads(json.dumps(point.as_dict()))
    assert summary["branches"] == [{"value": 0.5139, "moment": 0.47, "period": 6.67}, {"value": 0.5138, "moment": 0.47, "period": 6.67}]


def test_a_cusp_is_no_kind_of_end_to_follow():
    with pytest.raises(ValueError, match="kind must be one of " + ", ".join(KINDS) + ", got 'cusp'"):
        continue_cycle_end(None, "cusp", "gamma_phi", [0.5])
