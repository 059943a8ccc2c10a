"""Period doublings and tori on collocation branches (issue 40, item 4): ``continue_collocation``'s events.

Each located event is checked against the shooting's independent location of the same end
(``cycle_curve.locate_cycle_end``: Newton on the shooting map augmented by the critical multiplier's
condition, from the orbits of ``continue_orbit`` around the loss of stability): the same moment, the
critical multiplier at -1 or on the unit circle, a torus's angle the shooting's. The test functions
themselves are checked on multipliers placed by hand, and branches without a crossing report none.
"""

from __future__ import annotations

import cmath
import math

import numpy as np
import pytest

from collocation_crossings import collocation_crossing
from cosserat_chain import ChainParams
from cosserat_chain.numerics.collocation import circle_tests, continue_collocation, critical_multiplier, find_collocation_orbit
from cosserat_chain.numerics.continuation import locate_fold
from cosserat_chain.numerics.cycle_curve import locate_cycle_end
from cosserat_chain.numerics.cycle_events import NEAR_CIRCLE
from cycle_ends import located_end, shooting_crossing

#: The sine chain's one-turn orbit loses its stability at a period doubling at gamma_phi = 0.15 (M = 0.17288,
#: ``tests/test_cycle_switching.py``) and at a torus on the paper's default chain (M = 0.17312, ``tests/test_cycle_curve.py``).
CASES = {"period_doubling": ChainParams(gamma_phi=0.15), "torus": ChainParams()}


def shooting_critical(orbit, kind: str) -> complex:
    """The shooting orbit's multiplier nearest -1, or its complex one (Im > 0) nearest the unit circle."""
    mu = orbit.nontrivial_multipliers
    if kind == "period_doubling":
        return complex(mu[np.argmin(np.abs(mu + 1.0))])
    pairs = mu[mu.imag > 1e-6 * np.abs(mu)]
    return complex(pairs[np.argmin(np.abs(np.abs(pairs) - 1.0))])


@pytest.fixture(scope="module", params=list(CASES))
def crossing(request):
    """(kind, the shooting's located end (``cycle_ends``), the collocation start at the last stable shooting orbit above it, the
    collocation branch from there to a step of the shooting below its first unstable orbit: ``collocation_crossings``, shared with
    ``tests/test_collocation_switching.py``)."""
    kind, params = request.param, CASES[request.param]
    return kind, located_end(params, kind), *collocation_crossing(params)


def test_the_collocation_branch_locates_the_shootings_end_with_its_multiplier_on_the_circle(crossing):
    kind, end, start, branch = crossing
    assert [e["kind"] for e in branch.events] == [kind]
    event = branch.events[0]
    assert event["located"]
    # Measured: 2.8e-10 (period doubling) and 6e-12 (torus) from the shooting's augmented Newton.
    assert event["moment"] == pytest.approx(end.moment, abs=1e-8)
    mu = event["multiplier"]
    assert mu == critical_multiplier(event["orbit"].nontrivial_multipliers, kind)
    if kind == "period_doubling":
        assert abs(mu + 1.0) < 1e-6 and mu.imag == 0.0
        assert "angle" not in event
    else:
        assert abs(abs(mu) - 1.0) < 1e-6 and mu.imag > 0.1
        assert event["angle"] == pytest.approx(cmath.phase(shooting_critical(end, kind)), abs=1e-6)
        assert event["angle"] == pytest.approx(cmath.phase(mu), abs=1e-15)
    # The located orbit is the shooting's: the same period, and the event lies between the orbits where the test turned.
    assert event["orbit"].period == pytest.approx(end.period, rel=1e-7)
    moments = branch.moment
    assert np.any((moments[:-1] > event["moment"]) & (event["moment"] > moments[1:]))
    signs = np.sign([circle_tests(o.nontrivial_multipliers)[kind] for o in branch.orbits])
    assert np.all(signs[moments > event["moment"]] == 1) and np.all(signs[moments < event["moment"]] == -1)


def test_the_shootings_orbit_branch_keeps_the_event(crossing):
    kind, _, _, branch = crossing
    event = branch.events[0]
    converted = branch.orbit_branch().events
    expected = {
        "kind": kind,
        "moment": event["moment"],
        "located": True,
        "multiplier": [event["multiplier"].real, event["multiplier"].imag],
    }
    if kind == "torus":
        expected["angle"] = event["angle"]
    assert converted == [expected]


# The torus case's start in the quick suite; the period-doubling case's, the same claim on the damped chain, with the slow tests.
@pytest.mark.parametrize("crossing", ["torus", pytest.param("period_doubling", marks=pytest.mark.slow)], indirect=True)
def test_a_branch_without_a_crossing_reports_no_event(crossing):
    """The same start followed upwards: stable orbits, every multiplier inside the circle, no event."""
    kind, _, start, _ = crossing
    up = continue_collocation(start, moment_max=start.moment + 0.01, direction=1.0, max_points=3, period_max=200.0)
    assert len(up.orbits) == 3 and np.all(np.diff(up.moment) > 0)
    assert all(o.stable for o in up.orbits)
    assert up.events == [] and up.orbit_branch().events == []


def test_the_test_functions_change_sign_only_where_a_multiplier_crosses_the_circle():
    pair = cmath.rect(0.9, 2.0)
    base = np.array([0.6, pair, pair.conjugate(), 0.3 + 0.1j, 0.3 - 0.1j, -0.3, 1e-9])
    # The multipliers of modulus below NEAR_CIRCLE are left out: the damped real -0.3 would contribute 0.7.
    assert NEAR_CIRCLE > 0.3 + 1e-9
    assert circle_tests(base)["period_doubling"] == pytest.approx(1.6 * abs(pair + 1.0) ** 2, rel=1e-14)
    assert circle_tests(base)["torus"] == pytest.approx(0.1, rel=1e-14)
    assert critical_multiplier(base, "period_doubling") is None
    assert critical_multiplier(base, "torus") == pytest.approx(pair, abs=1e-15)
    # A real multiplier through -1: only the period-doubling test changes sign.
    for inside, outside in ((-0.99, -1.01), (-0.7, -1.4)):
        before, after = circle_tests(np.append(base, inside)), circle_tests(np.append(base, outside))
        assert before["period_doubling"] > 0 > after["period_doubling"]
        assert before["torus"] > 0 and after["torus"] > 0
        assert critical_multiplier(np.append(base, outside), "period_doubling") == outside
    # The pair through the circle: only the torus test changes sign.
    beyond = cmath.rect(1.02, 2.0)
    crossed = circle_tests(np.array([0.6, beyond, beyond.conjugate()]))
    assert crossed["torus"] == pytest.approx(-0.02, rel=1e-12) and crossed["period_doubling"] > 0
    # A pair inside the circle that turns real (two reals near 0.9), or a pair of reals below -1 (both outside,
    # one factor each): no sign change.
    for rest in ([0.92, 0.88], [-1.2, -1.1]):
        split = circle_tests(np.array([0.6, pair, pair.conjugate(), *rest]))
        assert split["torus"] > 0 and split["period_doubling"] > 0


@pytest.mark.slow
def test_the_sine_chain_at_gamma_phi_03_period_doubles_where_the_shooting_says_from_1_1_mc():
    """The paper's sine chain at gamma_phi = 0.3 (period doubling at M = 0.21057 > M_c, ``tests/test_cycle_switching.py``),
    followed by collocation from 1.1 M_c without a guess from the shooting: the first event is the shooting's
    located period doubling; every orbit between two located crossings of -1 has one real multiplier below -1."""
    params = ChainParams(gamma_phi=0.3)
    mc = locate_fold(params, "sine").moment
    branch = continue_collocation(find_collocation_orbit(params, "sine", 1.1 * mc), moment_min=0.2, period_max=200.0)
    doublings = [e for e in branch.events if e["kind"] == "period_doubling"]
    assert doublings and all(e["located"] for e in doublings)
    assert not [e for e in branch.events if e["kind"] == "torus"]
    shooting, index = shooting_crossing(params)
    end = locate_cycle_end(shooting.orbits[index - 1 : index + 1], "period_doubling")
    assert doublings[0]["moment"] == pytest.approx(end.moment, abs=1e-8)
    assert doublings[0]["moment"] == pytest.approx(0.21057, abs=1e-5)
    for e in doublings:
        assert abs(e["multiplier"] + 1.0) < 1e-6
    for orbit in branch.orbits:
        below = sum(1 for mu in orbit.nontrivial_multipliers if abs(mu.imag) <= 1e-6 * abs(mu) and mu.real < -1.0)
        passed = sum(1 for e in doublings if e["moment"] > orbit.moment)
        assert below == passed % 2


@pytest.mark.slow
def test_the_nonlinear_n1_branch_to_its_snic_has_branch_points_and_no_period_doubling_or_torus():
    """Towards the SNIC the damped multipliers are not resolved on 40 intervals (docs/collocation.md, Limits): the
    tests, on the multipliers near the circle only, report no event there; the four branch points stay."""
    start = find_collocation_orbit(ChainParams(N=1), "nonlinear", 0.3)
    branch = continue_collocation(start, moment_min=0.1, period_max=2000.0)
    assert str(branch.end) == "infinite_period"
    assert [e["kind"] for e in branch.events] == ["branch_point"] * 4
    assert math.isfinite(branch.orbits[-1].period) and branch.orbits[-1].period > 2000.0
