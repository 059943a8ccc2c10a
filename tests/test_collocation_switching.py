"""Branch switching at a period doubling of a collocation branch on the doubled mesh (issue 40, item 4).

The sine chain at gamma_phi = 0.15 (paper's N = 3 geometry) loses its one-turn orbit at a period doubling
at M = 0.172882426 (``tests/test_collocation_events.py``). At the located event the doubled mesh carries the
orbit run twice; its multipliers are exactly the squares of the one-turn orbit's (the doubled chain of
transfer matrices is the single one repeated); the flip mode changes sign after one period; the doubled
orbits of small amplitude a have period 2 T_PD + O(a^2) and a half-period gap a |x(1/2) - x(0)| + O(a^2);
the family continued away has a period that moves away from 2 T_single; and at the shooting's first doubled
orbit (``cycle_switching.switch_at_period_doubling``, an independent method) both agree.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
import scipy.optimize as so

from collocation_crossings import collocation_crossing
from cosserat_chain import ChainParams
from cosserat_chain.numerics.collocation import continue_collocation, find_collocation_orbit
from cosserat_chain.numerics.collocation_switching import (
    CollocationPeriodDoubling,
    doubled_collocation_orbit,
    flip_mode,
    half_period_gap,
    switch_collocation_at_period_doubling,
)
from cosserat_chain.numerics.collocation_switching import _run_twice as run_twice
from cosserat_chain.numerics.continuation import locate_fold
from cosserat_chain.numerics.cycle_switching import switch_at_period_doubling
from cosserat_chain.numerics.periodic import continue_orbit, find_periodic_orbit
from cycle_ends import shooting_crossing

PARAMS = ChainParams(gamma_phi=0.15)
AMPLITUDES = (1e-3, 2e-3)


@pytest.fixture(scope="module")
def shooting_branch():
    """The shooting's one-turn branch from 1.1 M_c to its first orbit past the period doubling."""
    return shooting_crossing(PARAMS)[0]


@pytest.fixture(scope="module")
def branch():
    """The collocation branch over the period doubling, from the last stable shooting orbit above it to a step below the
    first unstable one (``tests/test_collocation_events.py``'s, computed once for both)."""
    return collocation_crossing(PARAMS)[1]


@pytest.fixture(scope="module")
def event(branch):
    assert [e["kind"] for e in branch.events] == ["period_doubling"]
    return branch.events[0]


@pytest.fixture(scope="module")
def flip(event):
    return flip_mode(event)


def matched_gap(a: np.ndarray, b: np.ndarray) -> float:
    """The largest |a_i - b_pi(i)| of the best one-to-one matching."""
    gap = np.abs(a[:, None] - b[None, :])
    rows, cols = so.linear_sum_assignment(gap)
    return float(gap[rows, cols].max())


def test_at_the_period_doubling_the_doubled_multipliers_are_the_squares(event, flip):
    point = event["orbit"]
    doubled_point, mode = flip
    assert doubled_point.turns == 2 * point.turns and doubled_point.ntst == 2 * point.ntst
    assert doubled_point.period == pytest.approx(2 * point.period, rel=1e-14)
    assert np.array_equal(doubled_point.particle_turns, 2 * point.particle_turns)
    # mu_doubled = mu_single^2: the doubled chain of transfer matrices is the single one repeated (measured 2.2e-12).
    assert matched_gap(doubled_point.multipliers, point.multipliers**2) < 1e-9
    # The -1 became a second +1 beside the trivial one: a double eigenvalue of the pencil, split by the square root of the
    # round-off (measured 3.3e-8).
    assert np.sort(np.abs(doubled_point.multipliers - 1.0))[1] < 1e-6


def test_the_flip_mode_changes_sign_after_one_period(flip):
    doubled_point, mode = flip
    half = mode.shape[0] // 2
    assert np.sqrt(np.mean(np.sum(mode**2, axis=1))) == pytest.approx(1.0, rel=1e-12)
    # x on [0, 1/2], -x on [1/2, 1] (measured 2.8e-14), and x not zero at the start.
    assert np.abs(mode[: half + 1] + mode[half:]).max() < 1e-9
    assert np.abs(mode[0]).max() > 0.1


def test_small_doubled_orbits_tend_to_twice_the_period_and_are_not_the_orbit_run_twice(event, flip):
    point = event["orbit"]
    _, mode = flip
    _, _, shift = run_twice(point)
    family = [doubled_collocation_orbit(event, a, mode=mode) for a in AMPLITUDES]
    offsets = np.array([o.period - 2 * point.period for o in family])
    moments = np.array([o.moment - point.moment for o in family])
    # O(a^2) (measured 7.9e-8 and 3.1e-7 in T, -4.1e-11 and -1.6e-10 in M).
    assert np.all(offsets > 0) and 3.5 < offsets[1] / offsets[0] < 4.5
    assert np.all(moments < 0) and 3.5 < moments[1] / moments[0] < 4.5
    # The state at half the doubled period is the start plus a (x(1/2) - x(0)) = -2 a x(0): the flip mode.
    half = mode.shape[0] // 2
    for a, orbit in zip(AMPLITUDES, family):
        assert orbit.turns == 2 and orbit.residual < 1e-9
        gap = orbit.states(np.array([0.5]))[0] - orbit.profile[0] - shift
        flipped = (mode[half] - mode[0]) * a
        # To O(a) relative (measured 6.5e-7 and 1.5e-6).
        assert np.abs(gap - flipped).max() < 1e-4 * np.abs(flipped).max()
        assert half_period_gap(orbit, shift) == pytest.approx(np.abs(flipped).max(), rel=1e-4)


def test_the_switch_follows_the_doubled_family_away_from_twice_the_single_period(event, branch):
    switch = switch_collocation_at_period_doubling(branch, max_points=3, period_max=200.0)
    assert isinstance(switch, CollocationPeriodDoubling)
    assert switch.point is event["orbit"] and abs(switch.multiplier + 1.0) < 1e-9
    assert switch.side == "below" and switch.coefficient < 0 and switch.doubled.moment < switch.point.moment
    followed = switch.branch
    assert len(followed.orbits) == 3 and np.all(np.diff(followed.moment) < 0)
    assert all(o.turns == 2 and o.trivial_multiplier_error < 1e-6 for o in followed.orbits)
    # The period leaves 2 T_PD as M leaves M_PD, and leaves twice the single orbit's at the same M.
    excess = [o.period - 2 * switch.point.period for o in followed.orbits]
    assert np.all(np.diff(excess) > 0)
    first, last = followed.orbits[0], followed.orbits[-1]
    excess = [o.period - 2 * find_collocation_orbit(PARAMS, "sine", o.moment, guess=switch.point).period for o in (first, last)]
    # Measured 6.3e-4 at M_PD - 4.0e-7 and 1.42e-3 at M_PD - 9.0e-7 (2.4e-3 at M_PD - 1.5e-6, a fourth point).
    assert 0 < 2 * excess[0] < excess[1]
    assert switch.as_dict()["side"] == "below"


@pytest.mark.slow
def test_opposite_amplitudes_start_the_same_doubled_orbit_one_period_apart(event, flip):
    """a and -a: the same orbit (period, moment) started one single period apart (x against -x at the start)."""
    plus = doubled_collocation_orbit(event, 4e-3, mode=flip[1])
    # Through the switch: its predictor, the parabola through the probe at +1e-3, serves -a as well (even in a).
    minus = switch_collocation_at_period_doubling(event, amplitude=-4e-3, follow=False).doubled
    # Measured 4.8e-13 in M and 7e-12 relative in T: the two phases discretised on the same mesh differ by O(a^2).
    assert minus.moment == pytest.approx(plus.moment, abs=1e-11)
    assert minus.period == pytest.approx(plus.period, rel=1e-10)
    # The minus orbit's start is the plus orbit's state at half the doubled period (measured 2.2e-6 of their distance).
    _, _, shift = run_twice(event["orbit"])
    halfway = plus.states(np.array([0.5]))[0] - shift
    assert np.abs(minus.profile[0] - halfway).max() < 1e-4 * np.abs(minus.profile[0] - plus.profile[0]).max()


@pytest.mark.slow
def test_the_doubled_orbit_is_the_shootings_at_the_same_moment(event, shooting_branch):
    shot = switch_at_period_doubling(shooting_branch, follow=False)
    target = shot.doubled
    switch = switch_collocation_at_period_doubling(event, moment_min=target.moment, period_max=200.0, max_points=40)
    assert str(switch.branch.end) == "parameter_limit"
    last = [o for o in switch.branch.orbits if o.moment > target.moment][-1]
    orbit = find_collocation_orbit(PARAMS, "sine", target.moment, turns=2, guess=last, ntst=last.ntst)
    # Measured: period 2.3e-8 relative on the branch's mesh (80 intervals, NCOL = 4), whose fast longitudinal modes
    # are resolved to 3e-4 only; solved again from it with NCOL = 7: period 5.2e-13, multipliers 5.6e-10; the
    # critical one 4.3e-7 on the branch's mesh.
    assert orbit.period == pytest.approx(target.period, rel=1e-7)
    fine = find_collocation_orbit(PARAMS, "sine", target.moment, turns=2, guess=last, ntst=last.ntst, ncol=7)
    assert fine.period == pytest.approx(target.period, rel=1e-9)
    # The shooting's multipliers below 1e-3 are its round-off.
    resolved = lambda mu: mu[np.abs(mu) > 1e-3]  # noqa: E731
    assert matched_gap(resolved(fine.multipliers), resolved(target.multipliers)) < 1e-8
    # The critical one (the flip's square, near +1) already on the branch's mesh.
    assert np.sort(np.abs(orbit.multipliers - 1.0))[1] == pytest.approx(np.sort(np.abs(target.multipliers - 1.0))[1], abs=1e-6)


@pytest.mark.parametrize("kind", ["fold", "torus", "branch_point"])
def test_an_event_that_is_not_a_period_doubling_is_refused(event, kind):
    with pytest.raises(ValueError, match=f"the event is a '{kind}', not a 'period_doubling'"):
        switch_collocation_at_period_doubling({**event, "kind": kind})


def test_bad_starts_and_arguments_are_refused(event, branch):
    with pytest.raises(ValueError, match="not a located period doubling"):
        switch_collocation_at_period_doubling(branch.orbits[0])
    # A branch without the event (the same branch's orbits, events as continue_collocation lists them away from a crossing:
    # none, or only other kinds).
    with pytest.raises(ValueError, match=r"no located period_doubling event \(its events: none\)"):
        switch_collocation_at_period_doubling(dataclasses.replace(branch, events=[]))
    with pytest.raises(ValueError, match=r"no located period_doubling event \(its events: \['torus'\]\)"):
        switch_collocation_at_period_doubling(dataclasses.replace(branch, events=[{**event, "kind": "torus"}]))
    with pytest.raises(ValueError, match="was not located"):
        switch_collocation_at_period_doubling({**event, "located": False})
    with pytest.raises(ValueError, match="offset"):
        switch_collocation_at_period_doubling(event, offset=2.0)
    with pytest.raises(ValueError, match="amplitude"):
        doubled_collocation_orbit(event["orbit"], 0.0)
    with pytest.raises(ValueError, match="amplitude"):
        switch_collocation_at_period_doubling(event, amplitude=float("nan"))
    with pytest.raises(ValueError, match="start must be"):
        switch_collocation_at_period_doubling("event")


@pytest.mark.slow
def test_at_gamma_phi_03_the_doubled_family_is_the_shootings_and_stable():
    """The sine chain at gamma_phi = 0.3 period-doubles above M_c (M = 0.21057, ``tests/test_cycle_switching.py``):
    the collocation's doubled family, continued to the shooting switch's first doubled orbit, is that orbit."""
    params = ChainParams(gamma_phi=0.3)
    shooting = continue_orbit(
        find_periodic_orbit(params, "sine", 1.1 * locate_fold(params, "sine").moment), period_max=100.0, until_unstable=True
    )
    orbits = shooting.orbits
    start = find_collocation_orbit(params, "sine", orbits[-2].moment, guess=orbits[-2])
    branch = continue_collocation(start, moment_min=orbits[-1].moment - 0.5 * (orbits[-2].moment - orbits[-1].moment), period_max=200.0)
    target = switch_at_period_doubling(shooting, follow=False).doubled
    switch = switch_collocation_at_period_doubling(branch, moment_min=target.moment, period_max=200.0, max_points=40)
    assert switch.point.moment == pytest.approx(0.21057, abs=1e-5)
    assert switch.side == "below" and str(switch.branch.end) == "parameter_limit"
    last = [o for o in switch.branch.orbits if o.moment > target.moment][-1]
    orbit = find_collocation_orbit(params, "sine", target.moment, turns=2, guess=last, ntst=last.ntst)
    # Measured: period 1.4e-9 relative, the multipliers near the circle (1 and 0.856) 4.6e-8.
    assert orbit.period == pytest.approx(target.period, rel=1e-7)
    near = lambda mu: mu[np.abs(mu) > 0.5]  # noqa: E731
    assert matched_gap(near(orbit.multipliers), near(target.multipliers)) < 1e-6
    assert orbit.stable and target.stable and not orbits[-1].stable
