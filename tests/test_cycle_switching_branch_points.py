"""Branch switching at branch points of cycles (issue 40 item 4): ``numerics.cycle_branch_points``.

The nonlinear N = 1 chain's one-turn orbit has two branch points (a real multiplier through +1 at
M = 0.29772 and back at 0.29500 while M goes on falling, ``tests/test_orbit_phase_condition.py``):
both break the chain's mirror symmetry. The switched orbits are checked by an integrator other than
the shooting's (SciPy's), against the chain's symmetry (the mirror image of a new orbit is an orbit
too, the old one is its own) and, for the stable family, by a long run from a perturbed start. A user
system's switch is checked against AUTO-07p's: the ``pen`` demo's third run follows the branch that
crosses the out-of-phase family at its branch point I = 0.331445.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from cosserat_chain import ChainParams
from cosserat_chain.numerics import shooting
from cosserat_chain.numerics.cycle_branch_points import BranchSwitch, mirror, switch_at_branch_point
from cosserat_chain.numerics.cycle_switching import switch_at_period_doubling
from cosserat_chain.numerics.periodic import _System, _to_y, continue_orbit, find_periodic_orbit
from cosserat_chain.systems.pen import pen

CHAIN = ChainParams(N=1)


@pytest.fixture(scope="module")
def branch():
    """The one-turn orbit of the nonlinear N = 1 chain followed from M = 0.3 past its two branch points."""
    return continue_orbit(find_periodic_orbit(CHAIN, "nonlinear", 0.3), moment_min=0.294)


@pytest.fixture(scope="module")
def switches(branch):
    return [switch_at_branch_point(branch, index=i, follow=False) for i in (0, 1)]


def flowed(orbit, y0: np.ndarray, time: float, tol: float = 1e-12) -> np.ndarray:
    """The chain's state after ``time`` from y0 by SciPy's DOP853 (not the shooting's integrator)."""
    system = _System(orbit.params, _model(orbit), orbit.moment, orbit.particle)
    sol = solve_ivp(system.rhs(0), (0.0, time), y0, method="DOP853", rtol=tol, atol=tol)
    assert sol.success
    return sol.y[:, -1]


def _model(orbit):
    from cosserat_chain.models.base import get_model

    return get_model(orbit.model)


def shift(orbit, periods: int = 1) -> np.ndarray:
    """The change of y over ``periods`` periods: 2 pi times each particle's turns in its angle."""
    turned = np.zeros((3, orbit.params.n_particles))
    turned[2] = 2 * math.pi * periods * orbit.particle_turns
    return _to_y(orbit.params, turned, np.zeros_like(turned))


def closure(orbit, y0: np.ndarray) -> float:
    """max |y(T) - y0 - 2 pi k| of the orbit's period and turns from y0."""
    return float(np.max(np.abs(flowed(orbit, y0, orbit.period) - y0 - shift(orbit))))


def test_both_branch_points_break_the_mirror_symmetry_and_the_new_orbits_close_by_another_integrator(branch, switches):
    for switch, moment in zip(switches, (0.29772, 0.29500)):
        assert isinstance(switch, BranchSwitch) and switch.kind == "mirror_symmetry_breaking" and switch.parameter == "M"
        assert switch.value == pytest.approx(moment, abs=3e-5)
        # The located point: a second multiplier at +1, and the old orbit is its own mirror image. Its antisymmetric
        # part is round-off amplified by the branch point's near-singular Jacobian (the symmetry-breaking direction is
        # its null vector): 1e-9 to 5e-9 with the engine's rounding of the start (the frame-independent kick-drift's
        # gives 5.2e-9), six orders below the new orbit's asymmetry (above 1e-2, checked below).
        assert abs(switch.multiplier - 1.0) < 1e-6
        s = mirror(CHAIN)
        old = _to_y(CHAIN, switch.point.x, switch.point.v)
        assert np.max(np.abs(s @ old - old)) < 1e-8
        # The new orbit: same turns, near the point, solves the periodic problem by SciPy's integrator, is not
        # symmetric, and its mirror image is an orbit too (at the same M and T).
        new = switch.orbit
        y0 = _to_y(CHAIN, new.x, new.v)
        assert new.turns == switch.point.turns and abs(new.moment - switch.value) < 1e-3
        assert closure(new, y0) < 1e-7 and closure(new, s @ y0) < 1e-7
        assert np.max(np.abs(s @ y0 - y0)) > 1e-2
        # The directions at the point: the old branch's symmetric, the new family's antisymmetric, orthogonal.
        assert abs(switch.along @ switch.direction) < 1e-8


@pytest.mark.slow
def test_the_family_from_the_lower_branch_point_is_stable_and_a_run_from_near_it_keeps_its_asymmetry(switches):
    """Between the two branch points the symmetric orbit is unstable; the asymmetric family born at the lower one
    lies above it and is stable (largest multiplier 0.989): a run from its orbit perturbed by 1e-4 comes back
    towards it over 150 periods (to its section, as 0.989^150 = 0.19), and not to its mirror image."""
    switch = switches[1]
    new = switch.orbit
    assert switch.side == "above" and new.stable and new.max_multiplier < 0.99
    y0 = _to_y(CHAIN, new.x, new.v)
    s = mirror(CHAIN)
    system = _System(CHAIN, _model(new), new.moment, new.particle)
    dof = system.load_dof

    def off_orbit(y: np.ndarray) -> np.ndarray:
        """Where a run from y next crosses the orbit's section (its start's loaded angle, mod 2 pi), less the start."""
        y = y.copy()
        y[dof] -= 2 * math.pi * math.floor((y[dof] - y0[dof]) / (2 * math.pi))

        def section(t, z):
            return z[dof] - y0[dof] - 2 * math.pi

        section.terminal, section.direction = True, 1.0
        sol = solve_ivp(system.rhs(0), (0.0, new.period), y, method="DOP853", rtol=1e-11, atol=1e-11, events=section)
        assert sol.status == 1
        return sol.y_events[0][0] - shift(new) - y0

    start = y0 + 1e-4 * np.random.default_rng(4).standard_normal(y0.size)
    later = flowed(new, start, 150 * new.period, tol=1e-9) - shift(new, 150)
    before, after = np.max(np.abs(off_orbit(start))), np.max(np.abs(off_orbit(later)))
    assert after < 0.4 * before
    assert np.max(np.abs(s @ y0 - y0)) > 100 * before  # its mirror image (and the symmetric orbit) lie far off


def test_the_asymmetric_family_rises_over_a_fold_of_cycles_and_comes_back_to_the_other_branch_point(switches):
    """Born above the upper branch point, the family is followed up (continue_family: through its folds), turns at
    a fold of cycles near M = 0.3395 and comes back down to the symmetric branch at the lower branch point: its
    asymmetry falls towards zero there. The two branch points are joined by one family of asymmetric orbits."""
    switch = switch_at_branch_point(switches[0].point, max_points=60)
    assert switch.side == "above"
    family = switch.branch
    folds = [e["moment"] for e in family.events if e["kind"] == "fold"]
    assert len(folds) == 1 and 0.339 < folds[0] < 0.340
    s = mirror(CHAIN)
    asymmetry = np.array([np.max(np.abs((s - np.eye(s.shape[0])) @ _to_y(CHAIN, o.x, o.v))) for o in family.orbits])
    moments = np.array([o.moment for o in family.orbits])
    top = int(np.argmax(moments))
    closest = top + int(np.argmin(asymmetry[top:]))
    assert abs(moments[closest] - switches[1].value) < 1e-3 and asymmetry[closest] < 0.03
    assert family.orbits[closest].stable  # the lower point's family is the stable one


def test_the_orbit_at_a_symmetry_breaking_point_switches_without_its_branch(switches):
    alone = switch_at_branch_point(switches[0].point, follow=False)
    assert alone.kind == "mirror_symmetry_breaking"
    assert alone.orbit.moment == pytest.approx(switches[0].orbit.moment, abs=1e-6)


@pytest.mark.parametrize(
    "options, message",
    [
        ({"offset": 0.0}, "offset must be"),
        ({"amplitude": math.nan}, "amplitude must be"),
        ({"index": 2}, "has 2 branch point"),
        ({"index": -1}, "index must be"),
        ({"parameter": "gamma_phi"}, "lies in the moment M"),
    ],
)
def test_bad_input_is_refused_with_the_field_and_the_value(branch, options, message):
    with pytest.raises(ValueError, match=message):
        switch_at_branch_point(branch, follow=False, **options)


def test_an_orbit_without_a_second_multiplier_at_plus_one_is_not_a_branch_point(branch):
    with pytest.raises(ValueError, match="not a branch point of cycles"):
        switch_at_branch_point(branch.orbits[0], follow=False)


@pytest.mark.slow
def test_the_pen_demo_s_branch_point_switches_onto_auto07p_s_third_run(pen_in_phase_branch):
    """AUTO-07p's ``pen``: its second run (the out-of-phase family from the period doubling) prints a branch point
    at I = 3.31445E-01, period 9.72615E+00; its third run switches there (ISW = -1) and follows the crossing
    branch down to a homoclinic end near I = 0.15995 (period 30 at I = 0.1599536). AUTO-07p 0.9.2 (Debian),
    the demo's constants files, NTST = 30, NCOL = 4: points of that run at I = 0.28556823916 (period
    10.935861510) and 0.17519654660 (period 13.893092703). The switch here gives the same branch."""
    system = pen()
    doubled = switch_at_period_doubling(pen_in_phase_branch, stop_at=("branch_point",), limits=(0.179, 1.0), max_points=80).branch
    switch = switch_at_branch_point(doubled, stop_at=(), limits=(0.1, 1.0), max_points=200, period_max=30.0)
    # AUTO's b.pen: BP at I = 0.33144454208, period 9.7261478586; its collocation (NTST = 30) is off by about the
    # same as its period (4e-7 relative): the point here, refined on the old family, is at 0.3314452407 (secant on
    # the crossing multiplier, to 1e-10).
    assert switch.kind == "branch_point" and switch.value == pytest.approx(0.3314452407, abs=1e-9)
    assert switch.value == pytest.approx(0.33144454208, rel=3e-6) and switch.point.period == pytest.approx(9.7261478586, rel=1e-6)
    assert switch.side == "below"
    values, orbits = switch.branch.values, switch.branch.orbits
    # Down in I while the period grows to 20; beyond, I wiggles by 1e-7 about its homoclinic end, as AUTO's does
    # (0.15995229 at period 22.9, 0.15995362 at 30).
    rising = switch.branch.periods < 20.0
    assert np.all(np.diff(values[rising]) < 0) and values[-1] == pytest.approx(0.159953, abs=2e-6)
    for value, period in ((0.28556823916, 10.935861510), (0.17519654660, 13.893092703)):
        orbit = orbits[int(np.argmin(np.abs(values - value)))]
        for step in np.linspace(orbit.parameter("I"), value, 21)[1:]:
            orbit = shooting.find_orbit(system.with_parameters(I=float(step)), orbit)
        assert orbit.period == pytest.approx(period, rel=1e-6)
        # The old family is symmetric under swapping the pendula and half a period (the velocities after T / 2 are
        # the start's swapped); the new one is not.
        half = shooting.flow(orbit.system, orbit.y0, orbit.period / 2, variations=False, rtol=1e-11, atol=1e-11)[0]
        assert np.max(np.abs(half[[3, 2]] - orbit.y0[[2, 3]])) > 1e-2
    old = switch.point
    half = shooting.flow(old.system, old.y0, old.period / 2, variations=False, rtol=1e-11, atol=1e-11)[0]
    # The point lies on the old family: at fixed I the two families are sqrt(|I - I_BP| / c) apart there, so the
    # shooting's tolerance leaves it about 1e-4 off the symmetric orbit (the kit's event point lay 2e-3 off).
    assert np.max(np.abs(half[[3, 2]] - old.y0[[2, 3]])) < 3e-4
