"""The lower edge of the hysteresis loop in two parameters (issue 13, item 2): ``numerics.cycle_curve``.

Every point of a followed curve is checked against computations that do not use the augmented
system: orbits found on their own by Newton on the shooting map just above and below it (their
Floquet multipliers cross the circle there, as the kind says), the one-parameter continuation
at that value, and the curve followed one way against the same end located at each value.
"""

from __future__ import annotations

import numpy as np
import pytest

from conftest import random_geometries
from cosserat_chain import ChainParams
from cosserat_chain.experiments.coexisting import states_at
from cosserat_chain.experiments.diagram import state_diagram
from cosserat_chain.numerics.cycle_curve import KINDS, continue_cycle_end, locate_cycle_end
from cosserat_chain.numerics.periodic import continue_orbit, find_periodic_orbit
from cycle_ends import around_loss, located_end


def critical(orbit, kind: str) -> complex:
    """The multiplier that crosses the circle at a ``kind`` end: nearest -1, or the complex one nearest the circle."""
    mu = orbit.nontrivial_multipliers
    if kind == "period_doubling":
        return complex(mu[np.argmin(np.abs(mu + 1.0))])
    pairs = mu[np.abs(mu.imag) > 1e-6 * np.abs(mu)]
    return complex(pairs[np.argmin(np.abs(np.abs(pairs) - 1.0))])


def crossing_by_natural_continuation(chain: ChainParams, orbit, moment: float, kind: str, width: float = 2e-5) -> float:
    """The moment where the critical multiplier's modulus is 1, interpolated between orbits found on their own
    at moment (1 +- width) by Newton on the shooting map (no augmented system)."""
    above = find_periodic_orbit(chain, "sine", moment * (1 + width), guess=orbit)
    below = find_periodic_orbit(chain, "sine", moment * (1 - width), guess=above)
    r_above, r_below = abs(critical(above, kind)), abs(critical(below, kind))
    assert r_above < 1.0 < r_below  # stable just above the edge, unstable just below
    assert above.stable
    return above.moment + (1.0 - r_above) * (below.moment - above.moment) / (r_below - r_above)


@pytest.mark.slow
def test_the_torus_end_followed_in_E2_crosses_the_circle_where_it_says():
    params = ChainParams(E2=0.8)
    # Followed over the same range of E2 as ever, each end of it checked (a point in between was a third check of the same).
    curve = continue_cycle_end(located_end(params, "torus"), "torus", "E2", [0.8, 1.0])
    assert curve.complete and list(curve.values) == [0.8, 1.0]
    assert np.all(np.diff(curve.moment) > 0)  # a stiffer diagonal raises the lower edge
    for value, moment, orbit in zip(curve.values, curve.moment, curve.orbits):
        assert abs(abs(critical(orbit, "torus")) - 1.0) < 1e-7
        assert orbit.closure <= 1e-9
        chain = params.replace(E2=float(value))
        # Independent: where the pair's modulus reaches 1 between orbits found on their own (quadratic error ~1e-10).
        assert moment == pytest.approx(crossing_by_natural_continuation(chain, orbit, moment, "torus"), rel=1e-7)


@pytest.mark.slow
def test_the_period_doubling_end_followed_in_the_damping_agrees_with_each_value_on_its_own():
    """Followed from gamma_phi = 0.12 to 0.15, and each value computed on its own by one-parameter
    continuation from 1.1 M_c and then located: the same edge (path independence)."""
    params = ChainParams(gamma_phi=0.12)
    curve = continue_cycle_end(located_end(params, "period_doubling"), "period_doubling", "gamma_phi", [0.12, 0.13, 0.15])
    assert curve.complete
    independent = state_diagram(ChainParams(), "sine", "gamma_phi", [0.12, 0.13, 0.15])
    for moment, orbit, row in zip(curve.moment, curve.orbits, independent.rows):
        assert row.end == "period_doubling" and row.method == "located"
        assert moment == pytest.approx(row.rotation_stops, rel=1e-8)
        assert abs(critical(orbit, "period_doubling") + 1.0) < 1e-5
    chain = params.replace(gamma_phi=0.15)
    assert curve.moment[-1] == pytest.approx(
        crossing_by_natural_continuation(chain, curve.orbits[-1], curve.moment[-1], "period_doubling"), rel=1e-7
    )


def test_the_fold_of_cycles_of_the_two_turn_orbit_followed_in_E2_is_where_the_branch_turns():
    """The sine chain's stable 2-turn orbit (coexisting with the 1-turn one at M = 0.22) is born at a fold
    of cycles near M = 0.2187. Followed to E2 = 1.1, it equals where the one-parameter continuation at
    E2 = 1.1 turns back (a parabola through the orbits around the turn)."""
    found = states_at(ChainParams(), "sine", 0.22, starts=("random",), turns=(2,), random_starts=2)  # the second lands on it
    two_turn = next(f.orbit for f in found.orbits if f.orbit.turns == 2 and f.orbit.stable)
    branch = continue_orbit(two_turn, period_max=200.0)
    assert branch.end == "fold"
    curve = continue_cycle_end(branch.orbits[-2], "fold_of_cycles", "E2", [1.0, 1.05, 1.1])
    assert curve.complete
    assert curve.moment[0] == pytest.approx(branch.end_moment, abs=5e-6)
    chain = ChainParams(E2=1.1)
    again = continue_orbit(find_periodic_orbit(chain, "sine", 1.002 * curve.moment[-1], turns=2, guess=curve.orbits[-1]), step=0.01)
    assert again.end == "fold" and curve.moment[-1] == pytest.approx(again.end_moment, abs=5e-6)
    assert np.all(again.moment >= curve.moment[-1] - 1e-9)  # no orbit of the branch lies below the fold
    # At the fold a second multiplier (beside the trivial one) reaches +1.
    rest = curve.orbits[-1].nontrivial_multipliers
    assert np.min(np.abs(rest - 1.0)) < 1e-3


@pytest.mark.slow
def test_where_the_torus_end_turns_into_a_period_doubling_the_curve_stops_and_the_diagram_computes_the_row_on_its_own():
    """Between E2 = 1.0 (torus) and 1.2 (period doubling) the two ends meet: the torus curve cannot be
    followed to 1.2; with ``follow`` the diagram says so and finds the period doubling there on its own."""
    params = ChainParams()
    curve = continue_cycle_end(located_end(params, "torus"), "torus", "E2", [1.0, 1.2])
    assert not curve.complete and "beyond E2" in curve.message and list(curve.values) == [1.0]
    followed = state_diagram(params, "sine", "E2", [0.8, 1.0, 1.2], follow=True)
    assert [row.method for row in followed.rows] == ["located", "followed", "located"]
    assert [row.end for row in followed.rows] == ["torus", "torus", "period_doubling"]
    assert "could not be followed" in followed.rows[2].message
    # Followed from E2 = 0.8, the same torus end as located at E2 = 1.0 on its own (the curve's first point).
    assert followed.rows[1].rotation_stops == pytest.approx(curve.moment[0], rel=1e-8)
    assert followed.rows[2].rotation_stops < followed.rows[2].static_fold


def test_locating_refines_the_interpolated_loss_of_stability():
    # The period doubling at gamma_phi = 0.15: its branch is the session's (cycle_ends.py), shared with the switching tests.
    stable, unstable = around_loss(ChainParams(gamma_phi=0.15))
    located = locate_cycle_end([stable, unstable], "period_doubling")
    assert abs(critical(located, "period_doubling") + 1.0) < 1e-5
    assert unstable.moment < located.moment < stable.moment


@pytest.mark.parametrize(
    ("kind", "field", "values", "message"),
    [
        ("homoclinic", "E2", [1.0], "kind must be one of"),
        ("torus", "N", [3], "field must be one of"),
        ("torus", "E2", [float("nan")], "finite numbers"),
        ("torus", "E2", [], "finite numbers"),
        ("torus", "a", [-1.0], "not an admissible chain"),
    ],
)
def test_bad_input_is_refused_with_the_field_and_the_value(kind, field, values, message):
    orbit = find_periodic_orbit(ChainParams(), "sine", 0.224)
    with pytest.raises(ValueError, match=message):
        curve = continue_cycle_end(orbit, kind, field, values)
        assert curve is None  # pragma: no cover - the call raises
    assert set(KINDS) == {"fold_of_cycles", "period_doubling", "torus"}


# Chain 6 (a period doubling; the paper chain's torus end is followed above) in the quick suite, chains 2 and 5
# (torus ends, 5 with its stability window) with the slow tests.
@pytest.mark.parametrize("index", [pytest.param(2, marks=pytest.mark.slow), pytest.param(5, marks=pytest.mark.slow), 6])
def test_ends_of_random_chains_followed_in_E2_cross_the_circle_where_they_say(index):
    """Random admissible chains (N = 4, 5) whose rotation ends at a torus or a period doubling (as the
    diagram finds it at the chain's own E2): followed 5 % up in E2, the end agrees with orbits found on
    their own around it, as for the paper's chain. (Chain 5's orbit is unstable in a window, M = 0.649
    to 0.640, between stable orbits: its edge is the window's top.)"""
    params = random_geometries(8, seed=3)[index]
    kind = state_diagram(params, "sine", "E2", [params.E2]).rows[0].end
    assert kind in ("torus", "period_doubling")
    values = [params.E2, 1.05 * params.E2]
    curve = continue_cycle_end(located_end(params, kind), kind, "E2", values)
    assert curve.complete
    for value, moment, orbit in zip(curve.values, curve.moment, curve.orbits):
        chain = params.replace(E2=float(value))
        assert abs(abs(critical(orbit, kind)) - 1.0) < 1e-5
        assert moment == pytest.approx(crossing_by_natural_continuation(chain, orbit, moment, kind), rel=1e-6)
