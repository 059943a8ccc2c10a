"""Period doublings and tori located on the shooting's branches (issue 40, item 4): ``continue_orbit``'s events.

Every route (dense, blocks, Newton-Picard) locates the end where the sine chain's one-turn orbit loses
its stability, by Brent's method in M on the circle tests with each trial re-solved
(``numerics/cycle_events.py``). The located moment is checked against independent locations of the
same end: the shooting's augmented Newton (``cycle_curve.locate_cycle_end``, ``tests/cycle_ends.py``),
AUTO-07p's torus end (docs/state-diagram.md) and the collocation's located event; the critical
multiplier at the located orbit lies on -1 or on the unit circle. The locator itself is checked on
multipliers given in closed form, where the crossing is known exactly and a sign change that is no
crossing must not be reported.
"""

from __future__ import annotations

import cmath
import json
import math
from types import SimpleNamespace

import numpy as np
import pytest

from collocation_crossings import collocation_crossing
from cosserat_chain import ChainParams
from cosserat_chain.numerics.cycle_curve import torus_angle
from cosserat_chain.numerics.cycle_events import MOMENT_TOL, SPLITS, circle_counts, circle_tests, locate_circle_events
from cosserat_chain.numerics.periodic import OrbitError, continue_orbit
from cycle_ends import located_end, shooting_crossing

#: The sine chain's one-turn orbit from 1.1 M_c loses its stability at a period doubling at gamma_phi = 0.15 and at a
#: torus on the paper's default chain (N = 3; ``tests/test_collocation_events.py``).
CASES = {"period_doubling": ChainParams(gamma_phi=0.15), "torus": ChainParams()}
#: AUTO-07p 0.9.2's torus end of the paper's chain from its one-parameter run (docs/state-diagram.md, EPSL = EPSU = 1e-8).
AUTO_TORUS = 0.17312446607
#: Agreement asked of two locations of one end in M (measured: 2e-14 to 3e-12 against the augmented Newton, 1.2e-11
#: against AUTO's printed digits, 2.8e-10 against the collocation's period doubling).
MOMENT_AGREEMENT = 1e-9
#: The critical multiplier at a located orbit lies this near -1 or the unit circle (measured: 7e-13 dense, 3e-9 picard).
ON_CIRCLE = 1e-7


def critical_distance(kind: str, multiplier: list[float]) -> float:
    mu = complex(*multiplier)
    return abs(mu + 1.0) if kind == "period_doubling" else abs(abs(mu) - 1.0)


@pytest.fixture(scope="module", params=list(CASES))
def crossing(request):
    """(kind, the dense branch to its first unstable orbit and that orbit's index: ``cycle_ends``, shared)."""
    kind = request.param
    return kind, *shooting_crossing(CASES[kind])


def test_the_dense_branch_locates_the_augmented_newtons_end_with_its_multiplier_on_the_circle(crossing):
    kind, branch, index = crossing
    (event,) = branch.events
    assert event["kind"] == kind and event["located"] and event["accuracy"] == MOMENT_TOL
    end = located_end(CASES[kind], kind)
    assert event["moment"] == pytest.approx(end.moment, abs=MOMENT_AGREEMENT)
    # Between the last stable and the first unstable orbit, and the branch's stability is lost exactly there.
    assert branch.orbits[index].moment < event["moment"] < branch.orbits[index - 1].moment
    assert branch.stability_lost_at == event["moment"]
    assert critical_distance(kind, event["multiplier"]) < ON_CIRCLE
    orbit = event["orbit"]
    assert orbit.moment == event["moment"] and orbit.period == pytest.approx(end.period, rel=1e-8)
    if kind == "torus":
        assert event["angle"] == pytest.approx(torus_angle(end), abs=1e-8)
        assert event["moment"] == pytest.approx(AUTO_TORUS, abs=MOMENT_AGREEMENT)
    else:
        assert event["multiplier"][1] == 0.0 and "angle" not in event
    # The CLI's JSON takes the event as it is, the orbit left out (experiments/orbits.py).
    assert json.loads(json.dumps({k: v for k, v in event.items() if k != "orbit"}))["moment"] == event["moment"]


@pytest.mark.parametrize("method", ["blocks", "picard"])
def test_blocks_and_newton_picard_locate_the_dense_event(crossing, method):
    """From the dense branch's last stable orbit, so that each branch is two orbits, the event between them; picard sees
    only the multipliers above rho."""
    kind, branch, index = crossing
    other = continue_orbit(branch.orbits[index - 1], period_max=100.0, until_unstable=True, method=method)
    (event,) = other.events
    assert event["kind"] == kind and event["located"]
    assert event["moment"] == pytest.approx(branch.events[0]["moment"], abs=MOMENT_AGREEMENT)
    assert critical_distance(kind, event["multiplier"]) < ON_CIRCLE
    assert other.stability_lost_at == event["moment"]


@pytest.mark.slow
def test_the_shootings_event_is_the_collocations(crossing):
    kind, branch, _ = crossing
    _, collocated = collocation_crossing(CASES[kind])
    (event,) = [e for e in collocated.events if e["kind"] == kind]
    assert branch.events[0]["moment"] == pytest.approx(event["moment"], abs=MOMENT_AGREEMENT)


# The locator on multipliers in closed form: orbits are (moment, nontrivial multipliers), `solve` gives them exactly.
M_CROSS = 0.2
ANGLE = 2.0


def orbit(moment: float, multipliers) -> SimpleNamespace:
    return SimpleNamespace(moment=moment, nontrivial_multipliers=np.asarray(multipliers, dtype=complex))


def flip(moment: float) -> SimpleNamespace:
    """A real multiplier -1 - 3 (M_CROSS - M) - (M_CROSS - M)^2 beside a damped pair and a damped real one."""
    d = M_CROSS - moment
    return orbit(moment, [-1.0 - 3.0 * d - d * d, 0.6 * cmath.exp(1j), 0.6 * cmath.exp(-1j), 0.7])


def torus(moment: float) -> SimpleNamespace:
    """A pair of modulus exp(2 (M_CROSS - M)) at the angle ANGLE beside a damped real one."""
    r = math.exp(2.0 * (M_CROSS - moment))
    return orbit(moment, [r * cmath.exp(1j * ANGLE), r * cmath.exp(-1j * ANGLE), -0.8])


def exactly(family):
    return lambda moment, a, b: family(moment)


@pytest.mark.parametrize("family", [flip, torus])
def test_a_crossing_given_in_closed_form_is_located_to_the_tolerance(family):
    kind = "period_doubling" if family is flip else "torus"
    orbits = [family(m) for m in (0.26, 0.23, 0.21, 0.185, 0.16)]
    ((index, event),) = locate_circle_events(orbits, exactly(family))
    assert index == 3 and event["kind"] == kind and event["located"]
    assert event["moment"] == pytest.approx(M_CROSS, abs=MOMENT_TOL)
    assert critical_distance(kind, event["multiplier"]) < 3.1 * MOMENT_TOL  # |d mu / dM| <= 3 at the crossing
    assert event["orbit"].moment == event["moment"]
    if kind == "torus":
        assert event["angle"] == pytest.approx(ANGLE, abs=1e-15)


def test_a_pair_outside_the_circle_turning_real_is_no_torus():
    """The torus test's sign flips where a pair outside the circle meets on the real axis (at M = 0.2): no event."""

    def colliding(moment: float) -> SimpleNamespace:
        d = moment - M_CROSS
        split = 1.2 * cmath.exp(1j * math.sqrt(d)) if d > 0 else 1.2 + math.sqrt(-d)
        pair = [split, split.conjugate()] if d > 0 else [split, 1.44 / split]
        return orbit(moment, [*pair, 0.6])

    orbits = [colliding(m) for m in (0.23, 0.21, 0.19)]
    signs = [np.sign(np.prod(1.0 - np.abs(o.nontrivial_multipliers[o.nontrivial_multipliers.imag > 1e-6]))) for o in orbits]
    assert signs[1] != signs[2]  # the test does flip
    assert locate_circle_events(orbits, exactly(colliding)) == []


def test_an_event_whose_trials_cannot_be_solved_is_reported_unlocated_at_the_orbit_past_it():
    def fails(moment, a, b):
        raise OrbitError(f"no convergence at M={moment}")

    ((index, event),) = locate_circle_events([flip(0.23), flip(0.18)], fails)
    assert index == 1 and event["moment"] == 0.18 and not event["located"] and "accuracy" not in event


def test_two_events_in_one_step_come_in_the_order_of_the_tests_and_none_without_a_sign_change():
    def both(moment: float) -> SimpleNamespace:
        return orbit(moment, [*flip(moment).nontrivial_multipliers[:1], *torus(moment - 0.01).nontrivial_multipliers[:2]])

    found = locate_circle_events([both(0.23), both(0.17)], exactly(both))
    assert [(i, e["kind"]) for i, e in found] == [(1, "period_doubling"), (1, "torus")]
    assert [e["moment"] for _, e in found] == pytest.approx([M_CROSS, M_CROSS + 0.01], abs=MOMENT_TOL)
    assert locate_circle_events([flip(0.26), flip(0.23)], exactly(flip)) == []


@pytest.mark.parametrize("kind", ["period_doubling", "torus"])
def test_two_crossings_of_one_kind_in_one_step_are_separated_and_both_located(kind):
    """Two multipliers cross at M = 0.2 and 0.203 between orbits at 0.23 and 0.16: the test's sign is the same at both
    ends (two factors flipped), the counts of multipliers outside the circle differ by two."""

    def two(moment: float) -> SimpleNamespace:
        if kind == "period_doubling":  # the real multipliers of two flips
            return orbit(moment, [flip(moment).nontrivial_multipliers[0], flip(moment - 0.003).nontrivial_multipliers[0], 0.7])
        second = torus(moment - 0.003).nontrivial_multipliers[:2] * np.exp([0.5j, -0.5j])  # the second pair at another angle
        return orbit(moment, [*torus(moment).nontrivial_multipliers[:2], *second, -0.8])

    ends = [two(0.23), two(0.16)]
    assert circle_tests(ends[0].nontrivial_multipliers)[kind] * circle_tests(ends[1].nontrivial_multipliers)[kind] > 0
    assert np.subtract(circle_counts(ends[1].nontrivial_multipliers), circle_counts(ends[0].nontrivial_multipliers)).max() == 2
    found = locate_circle_events(ends, exactly(two))
    assert [(i, e["kind"], e["located"]) for i, e in found] == [(1, kind, True)] * 2
    assert [e["moment"] for _, e in found] == pytest.approx([M_CROSS + 0.003, M_CROSS], abs=MOMENT_TOL)
    # Without the halvings neither is seen; a step with one crossing is not halved (every trial is Brent's).
    assert locate_circle_events(ends, exactly(two), splits=0) == []
    family = flip if kind == "period_doubling" else torus
    runs = []
    for splits in (0, SPLITS):
        trials = []

        def counted(moment, a, b, trials=trials):
            trials.append(moment)
            return family(moment)

        ((_, event),) = locate_circle_events([family(0.23), family(0.17)], counted, splits=splits)
        runs.append((trials, event["moment"]))
    assert runs[0] == runs[1]
