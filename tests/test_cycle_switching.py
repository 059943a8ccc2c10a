"""Branch switching at a period doubling and at Hopf points (issue 40, item 4): ``numerics.cycle_switching``.

The nonlinear paper chain at gamma_phi = 0.2 loses its one-turn orbit at a period doubling near
M = 0.19665 (``tests/test_periodic_jacobian.py``). The doubled orbit must behave as the normal form
says where its amplitude a vanishes (period 2 T_PD + O(a^2), M_PD + O(a^2), multipliers the squares
of the one-turn orbit's + O(a^2)), be a genuine orbit of period 2T (not the one-turn orbit traversed
twice), and be the orbit a simulation settles on below the period doubling.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest
import scipy.optimize as so

from cosserat_chain import ChainParams
from cosserat_chain.loads import moment_load
from cosserat_chain.numerics.continuation import continue_in_moment, locate_fold
from cosserat_chain.numerics.cycle_curve import locate_circle_event
from cosserat_chain.numerics.cycle_switching import (
    PeriodDoubling,
    doubled_orbit,
    flip_vector,
    hopf_orbit,
    hopf_vector,
    switch_at_hopf,
    switch_at_period_doubling,
)
from cosserat_chain.numerics.dynamics import integrate
from cosserat_chain.numerics.hopf import hopf_points
from cosserat_chain.numerics.integrators import default_time_step
from cosserat_chain.numerics.periodic import OrbitError, continue_orbit, find_periodic_orbit, initial_guess
from cycle_ends import shooting_crossing

PARAMS = ChainParams(gamma_phi=0.2)
AMPLITUDES = (1e-3, 2e-3, 4e-3)


@pytest.fixture(scope="module")
def branch():
    """The one-turn orbit followed down from 0.1975 (0.4 % above the period doubling) to its first unstable orbit
    (below it)."""
    return continue_orbit(find_periodic_orbit(PARAMS, "nonlinear", 0.1975), period_max=100.0, until_unstable=True)


@pytest.fixture(scope="module")
def switch(branch) -> PeriodDoubling:
    return switch_at_period_doubling(branch, max_points=4, period_max=100.0)


@pytest.fixture(scope="module")
def family(switch):
    """Doubled orbits of small amplitudes at the located period doubling."""
    return [doubled_orbit(switch.point, a, eigenvector=switch.eigenvector) for a in AMPLITUDES]


def half_period_gap(orbit) -> float:
    """max |state at T/2 - start| with the loaded angle's half of the turns taken off: zero for an orbit of period T/2."""
    x, v = orbit.trajectory(np.array([orbit.period / 2]))
    x = x[0] - 2 * math.pi * (orbit.particle_turns // 2)[None, :] * np.array([[0], [0], [1]])
    return float(max(np.abs(x - orbit.x).max(), np.abs(v[0] - orbit.v).max()))


def test_the_switch_starts_at_the_located_period_doubling(switch, branch):
    point = switch.point
    assert point.moment == pytest.approx(0.19665, abs=1e-5)
    # The branch's own event (cycle_events: Brent's method in M and one secant step), its multiplier on -1 to the
    # orbit's accuracy (1.5e-12; Brent's root alone 1.7e-8 off, the augmented Newton's 2.5e-11).
    (event,) = [e for e in branch.events if e["kind"] == "period_doubling"]
    assert point is event["orbit"] and event["moment"] == point.moment
    assert abs(switch.multiplier + 1.0) < 1e-10
    with pytest.raises(ValueError, match="kind must be one of"):
        locate_circle_event(branch.orbits[-2:], "fold_of_cycles")
    with pytest.raises(ValueError, match=r"could not be located at E1 = .*: it needs the two orbits of a branch around it"):
        locate_circle_event(branch.orbits[-1:], "period_doubling")
    # Between the last stable and the first unstable one-turn orbit of the branch.
    assert branch.orbits[-1].moment < point.moment < branch.orbits[-2].moment
    # The eigenvector is the monodromy's for -1: flip_vector of the same orbit gives it again.
    again = flip_vector(point)[1]
    assert min(np.abs(again - switch.eigenvector).max(), np.abs(again + switch.eigenvector).max()) < 1e-6


def test_the_doubled_orbit_tends_to_twice_the_period_and_the_moment_of_the_period_doubling(switch, family):
    point = switch.point
    period = np.array([o.period for o in family])
    moment = np.array([o.moment for o in family])
    a = np.array(AMPLITUDES)
    for orbit in family:
        assert orbit.turns == 2 and np.array_equal(orbit.particle_turns, 2 * point.particle_turns)
        assert orbit.closure <= 1e-9
    # O(a^2): doubling a multiplies the offsets by about 4 ...
    for offset in (period - 2 * point.period, moment - point.moment):
        ratios = offset[1:] / offset[:-1]
        assert np.all((3.5 < ratios) & (ratios < 4.5)), ratios
    # ... and the limit a -> 0 of T = T0 + p a^2 + q a^3 through the three is 2 T_PD to the located accuracy.
    limit = np.linalg.solve(np.column_stack([np.ones(3), a**2, a**3]), period)[0]
    assert limit == pytest.approx(2 * point.period, rel=1e-8)
    assert np.linalg.solve(np.column_stack([np.ones(3), a**2, a**3]), moment)[0] == pytest.approx(point.moment, abs=1e-9)
    # The normal form's coefficient c of M - M_PD = c a^2 (the switch's secant) agrees with these orbits.
    assert (moment[0] - point.moment) / a[0] ** 2 == pytest.approx(switch.coefficient, rel=0.1)


def test_the_doubled_orbits_multipliers_are_the_squares_of_the_one_turn_orbits(switch, family):
    squares = switch.point.multipliers**2
    distances = []
    for orbit in family:
        gap = np.abs(squares[:, None] - orbit.multipliers[None, :])
        rows, cols = so.linear_sum_assignment(gap)
        distances.append(gap[rows, cols].max())
        # The -1 became a second multiplier near +1 beside the trivial one, but not +1 itself: no double cover.
        near_one = np.sort(np.abs(orbit.multipliers - 1.0))
        assert near_one[0] < 1e-8 and 1e-6 < near_one[1] < 1e-2
    distances = np.array(distances)
    assert distances[0] < 1e-3
    assert np.all((3.0 < distances[1:] / distances[:-1]) & (distances[1:] / distances[:-1] < 5.0)), distances


def test_the_doubled_orbit_is_a_genuine_orbit_of_twice_the_period(switch, family):
    # At T/2 the doubled orbit is O(a) away from its start (y_PD + a e against y_PD - a e, each moved back onto the
    # section along the flow): not the one-turn orbit twice.
    gaps = np.array([half_period_gap(orbit) for orbit in family])
    for a, gap, orbit in zip(AMPLITUDES, gaps, family):
        assert 1e3 * orbit.closure < a < gap
    assert np.all((1.8 < gaps[1:] / gaps[:-1]) & (gaps[1:] / gaps[:-1] < 2.2)), gaps
    # The one-turn orbit itself closes after half the period (the check's own control).
    point = switch.point
    doubled_point = dataclasses.replace(point, turns=2, period=2 * point.period, particle_turns=2 * point.particle_turns)
    assert half_period_gap(doubled_point) < 1e-7


def test_the_doubled_family_lies_below_and_takes_over_the_stability(switch, branch):
    point, doubled = switch.point, switch.doubled
    assert switch.side == "below" and switch.coefficient < 0  # a supercritical flip of an orbit that loses stability downwards
    # About the default relative distance MOMENT_OFFSET = 1e-4 from the period doubling (the normal form's amplitude).
    assert doubled.moment < point.moment and 0.5e-4 < (point.moment - doubled.moment) / point.moment < 2e-4
    assert doubled.stable and not branch.orbits[-1].stable
    assert doubled.period == pytest.approx(2 * point.period, rel=1e-2)
    # Followed down in M: every orbit of the family has two turns, a period near 2T, and stays stable near the switch.
    followed = switch.branch
    assert followed is not None and len(followed.orbits) >= 3
    assert np.all(np.diff(followed.moment) < 0)
    assert all(o.turns == 2 and o.stable for o in followed.orbits)
    assert np.allclose(followed.period, 2 * point.period, rtol=1e-2)
    assert switch.as_dict()["side"] == "below"


def test_a_located_orbit_switches_as_its_branch_does(switch):
    again = switch_at_period_doubling(switch.point, follow=False)
    assert again.branch is None
    assert again.doubled.moment == pytest.approx(switch.doubled.moment, abs=1e-10)
    assert again.doubled.period == pytest.approx(switch.doubled.period, abs=1e-8)


def test_bad_input_is_refused_with_the_value(switch, branch):
    with pytest.raises(ValueError, match="amplitude must be a finite non-zero"):
        doubled_orbit(switch.point, 0.0, eigenvector=switch.eigenvector)
    with pytest.raises(ValueError, match="amplitude must be a finite non-zero"):
        doubled_orbit(switch.point, float("nan"), eigenvector=switch.eigenvector)
    with pytest.raises(ValueError, match="offset must be a number in"):
        switch_at_period_doubling(switch.point, offset=2.0)
    with pytest.raises(ValueError, match="no real Floquet multiplier passes -1"):
        switch_at_period_doubling(dataclasses.replace(branch, orbits=branch.orbits[:2]))
    with pytest.raises(ValueError, match="start must be a PeriodicOrbit or an OrbitBranch"):
        switch_at_period_doubling("orbit")


def test_a_simulation_below_the_period_doubling_settles_on_the_doubled_orbit(switch):
    """Independent of the switch: a run (Yoshida-4) from the one-turn orbit's state at the period doubling, at the
    moment of the last doubled orbit followed, leaves the now unstable one-turn orbit for the doubled one."""
    doubled, point = switch.branch.orbits[-1], switch.point
    loads = moment_load(doubled.moment, point.particle).validate(PARAMS)
    run = integrate(
        PARAMS, "nonlinear", loads, t0=0.0, t_end=100 * doubled.period, dt=default_time_step(PARAMS, "nonlinear"), x0=point.x,
        v0=point.v, method="yoshida4", n_frames=2,
    )  # fmt: skip
    guess = initial_guess(PARAMS, "nonlinear", doubled.moment, turns=2, x0=run.x[-1], v0=run.v[-1])
    assert guess[2] == pytest.approx(doubled.period, rel=1e-4)  # the simulation's own two turns
    simulated = find_periodic_orbit(PARAMS, "nonlinear", doubled.moment, turns=2, guess=guess)
    assert simulated.period == pytest.approx(doubled.period, rel=1e-9)
    assert simulated.max_multiplier == pytest.approx(doubled.max_multiplier, abs=1e-6)
    assert doubled.max_multiplier < 1.0


@pytest.mark.slow  # a second damping of the sine chain's switch: at gamma_phi = 0.15 it is tested quickly below
def test_the_sine_chain_above_its_static_fold_doubles_its_period_at_gamma_phi_03():
    """The sine chain at gamma_phi = 0.3 period-doubles at M = 0.2105 > M_c (``tests/test_diagram.py``): the
    doubled orbit is stable below it, where the one-turn orbit is not."""
    params = ChainParams(gamma_phi=0.3)
    one_turn = find_periodic_orbit(params, "sine", 1.1 * locate_fold(params, "sine").moment)
    branch = continue_orbit(one_turn, period_max=100.0, until_unstable=True)
    switch = switch_at_period_doubling(branch, max_points=5)
    assert switch.point.moment == pytest.approx(0.21057, abs=1e-5)
    assert switch.side == "below" and switch.doubled.stable and not branch.orbits[-1].stable
    assert switch.doubled.period == pytest.approx(2 * switch.point.period, rel=1e-2)
    assert half_period_gap(switch.doubled) > 1e3 * switch.doubled.closure


def test_an_orbit_without_a_real_negative_multiplier_has_no_flip_vector(switch):
    orbit = dataclasses.replace(switch.point, multipliers=np.array([1.0 + 0j]))
    # The multipliers are recomputed from the monodromy: the located orbit has its -1 whatever it carries.
    assert abs(flip_vector(orbit)[0] + 1.0) < 1e-8
    with pytest.raises(OrbitError, match="no real negative Floquet multiplier"):
        flip_vector(dataclasses.replace(switch.point, period=1e-3))


def test_the_pen_demo_doubles_into_out_of_phase_rotations_with_auto07p_s_branch_point(pen_in_phase_branch):
    """AUTO-07p's demo ``pen`` (two coupled pendula): the in-phase rotation period-doubles at I = 0.17916377626
    (``tests/test_systems.py``), and its second run follows the bifurcating branch of out-of-phase rotations,
    on which AUTO's regression output (``test/hyper.all``) prints a branch point at I = 3.31445E-01 with period
    9.72615E+00 (a multiplier through +1). The switch gives the same branch: subcritical here (the doubled
    orbits lie above the period doubling, unstable), up to a fold of cycles and back down through that point."""
    switch = switch_at_period_doubling(pen_in_phase_branch, stop_at=(), limits=(0.179, 1.0), max_points=80)
    assert switch.parameter == "I" and switch.value == pytest.approx(0.17916377626, abs=1e-9)
    # AUTO's first run prints PERIOD 3.70528E+00 there: its collocation's periods lie ~8e-6 off the shooting's.
    assert switch.point.period == pytest.approx(3.70528, abs=1e-5)
    # The flip is out of phase: the eigenvector moves the two pendula against each other.
    e = switch.eigenvector
    assert np.allclose(e[0], -e[1], atol=1e-8) and np.allclose(e[2], -e[3], atol=1e-8)
    doubled = switch.doubled
    assert switch.side == "above" and switch.coefficient > 0 and not doubled.stable
    assert np.array_equal(doubled.turns, [2, 2]) and doubled.period == pytest.approx(2 * switch.point.period, rel=1e-3)
    assert abs(doubled.q0[0] - doubled.q0[1]) > 1e-2  # out of phase, no longer on phi_1 = phi_2
    folds = [e for e in switch.branch.events if e.kind == "fold" and e.located]
    assert folds and folds[0].parameter > 0.39
    crossing = next(e for e in switch.branch.events if e.located and e.kind == "stability" and e.parameter < folds[0].parameter - 1e-3)
    assert crossing.parameter == pytest.approx(0.331445, abs=5e-7)
    assert crossing.point.period == pytest.approx(9.72615, abs=1e-5)
    assert np.min(np.abs(crossing.point.nontrivial_multipliers - 1.0)) < 1e-5


def test_where_the_flip_vector_nearly_follows_the_branch_the_switch_still_finds_the_doubled_orbit():
    """On the sine chain at gamma_phi = 0.15 (period doubling at M = 0.17288, ``tests/test_cycle_curve.py``) the
    amplitude condition along e alone also meets the one-turn orbit traversed twice, at a distance O(a), and
    Newton went there (M - M_PD linear in a, the squared flip multiplier 1 + 9.5 a): the doubled orbits found
    have M - M_PD quadratic in a, a multiplier 1 - O(a^2) and do not close after half their period.

    The family bends within a few 1e-3 (its amplitude along e turns at 0.0023), so M - M_PD = c a^2 + d a^3 with
    d a / c about 0.2 at a = 1e-3: the ratio of the offsets at 2a and a is 4 (1 + d a / c) to first order, 3.5 for one
    sign of e and 6.3 for the other, and the eigenvector's sign is LAPACK's. Both signs are taken: the even part of
    M - M_PD in a quadruples with a doubled, the odd part grows eightfold; the double cover's offsets are odd in a."""
    # The shooting's branch of the collocation tests (tests/collocation_crossings.py), computed once a session.
    switch = switch_at_period_doubling(shooting_crossing(ChainParams(gamma_phi=0.15))[0], follow=False)
    point = switch.point
    assert point.moment == pytest.approx(0.17288, abs=1e-5)
    amplitudes = (5e-4, 1e-3)
    family = {(a, sign): doubled_orbit(point, sign * a, eigenvector=switch.eigenvector) for a in amplitudes for sign in (1, -1)}
    offsets = {key: o.moment - point.moment for key, o in family.items()}
    assert all(offset < 0 for offset in offsets.values())
    even = [offsets[a, 1] + offsets[a, -1] for a in amplitudes]
    odd = [offsets[a, 1] - offsets[a, -1] for a in amplitudes]
    assert 3.5 < even[1] / even[0] < 4.5 and 6.0 < odd[1] / odd[0] < 10.0
    for (a, _), orbit in family.items():
        second = np.sort(np.abs(orbit.multipliers - 1.0))[1]
        assert 1e-7 < second < 1e3 * a**2
        assert half_period_gap(orbit) > a
    assert switch.side == "below" and switch.doubled.stable


@pytest.fixture(scope="module")
def hopf_chain():
    """The sine chain at N = 2 (paper's geometry) and the Hopf points of positive M on its unstable branch
    (``tests/test_dynamic_stability.py``: phi_0 = 1.6575 and 2.4380)."""
    params = ChainParams(N=2)
    points = hopf_points(params, "sine", continue_in_moment(params, "sine", phi0_stop=2 * math.pi))
    return params, [h for h in points if h.moment > 0]


def linear_multipliers(params, point) -> np.ndarray:
    """exp(lambda 2 pi / omega) over the eigenvalues lambda of the damped dynamics linearised at the Hopf point."""
    system, state, _, _ = hopf_vector(params, "sine", point)
    n = system.size
    jacobian = system.force_jacobian(state[:n]).toarray() / system.mass()[:, None]
    matrix = np.block([[np.zeros((n, n)), np.eye(n)], [jacobian, -np.diag(system.damping() / system.mass())]])
    return np.exp(np.linalg.eigvals(matrix) * 2 * math.pi / point.frequency)


@pytest.mark.parametrize("which", [0, 1])
def test_orbits_born_at_a_hopf_point_have_its_period_and_grow_like_the_root_of_the_moment(hopf_chain, which):
    params, points = hopf_chain
    point = points[which]
    assert point.phi0 == pytest.approx((1.6575078516528, 2.4380368033649)[which], abs=1e-9)
    period = 2 * math.pi / point.frequency
    a = np.array(AMPLITUDES)
    family = [hopf_orbit(params, "sine", point, x) for x in a]
    for x, orbit in zip(a, family):
        # Non-rotating: no turns, the loaded angle swings about the Hopf state's by about the amplitude.
        assert orbit.turns == 0 and not orbit.particle_turns.any() and orbit.closure <= 1e-9
        angles, _ = orbit.trajectory(np.linspace(0.0, orbit.period, 41)[1:])
        swing = angles[:, 2, params.N] - point.phi0
        assert 0.3 * x < swing.max() < 3 * x and 0.3 * x < -swing.min() < 3 * x
    periods = np.array([o.period for o in family])
    offsets = np.array([o.moment - point.moment for o in family])
    # a ~ sqrt(|M - M_H|): M - M_H quadruples with a doubled ...
    assert np.all((3.5 < offsets[1:] / offsets[:-1]) & (offsets[1:] / offsets[:-1] < 4.5)), offsets
    # ... and the period tends to 2 pi / omega (T = T0 + p a^2 + q a^3 through the three).
    limit = np.linalg.solve(np.column_stack([np.ones(3), a**2, a**3]), periods)[0]
    assert limit == pytest.approx(period, rel=1e-8)
    # Floquet multipliers: exp(lambda T) of the static state's eigenvalues to O(a^2) (independent: the statics'
    # linearisation), the crossing pair's two now the trivial +1 and one 1 - O(a^2).
    expected = linear_multipliers(params, point)
    for x, orbit in zip(a, family):
        mu = orbit.multipliers[np.abs(orbit.multipliers) > 1e-3]
        gap = np.abs(mu[:, None] - expected[None, :]) / np.maximum(1.0, np.abs(mu[:, None]))
        rows, cols = so.linear_sum_assignment(gap)
        assert gap[rows, cols].max() < 50 * x**2


def test_the_switch_at_a_hopf_point_continues_the_family_down(hopf_chain):
    params, points = hopf_chain
    switch = switch_at_hopf(params, "sine", points[0], max_points=5, period_max=100.0)
    assert switch.side == "below" and switch.coefficient < 0
    assert abs(switch.eigenvalue - 1j * points[0].frequency) < 1e-9
    assert 0.5e-4 < (points[0].moment - switch.orbit.moment) / points[0].moment < 2e-4
    # The saddle's unstable real eigenvalue stays: the orbits are unstable, their leading multiplier exp(lambda T).
    assert not switch.orbit.stable and switch.orbit.max_multiplier == pytest.approx(4.18, abs=0.05)
    branch = switch.branch
    assert len(branch.orbits) == 5 and np.all(np.diff(branch.moment) < 0)
    assert all(o.turns == 0 for o in branch.orbits)
    assert np.all(np.diff(branch.period) > 0)  # the period grows away from the Hopf point
    assert switch.as_dict()["side"] == "below"


def test_a_hopf_point_not_located_or_a_bad_amplitude_is_refused(hopf_chain):
    params, points = hopf_chain
    with pytest.raises(ValueError, match="located HopfPoint"):
        hopf_orbit(params, "sine", dataclasses.replace(points[0], located=False), 1e-3)
    with pytest.raises(ValueError, match="amplitude must be a finite number > 0"):
        hopf_orbit(params, "sine", points[0], -1e-3)
    with pytest.raises(ValueError, match="offset must be a number in"):
        switch_at_hopf(params, "sine", points[0], offset=0.0)
