"""Codimension-two points on the two-parameter curves of the rotating orbit's ends (issue 40 item 4):
``numerics.cycle_curve``'s test functions and their located zeros.

On the paper's chain (N = 3 sine, E2 varied) the torus end's critical pair turns through the angle
2 pi / 3 (a 1:3 resonance) between E2 = 0.9 and 0.95, and through pi near E2 = 1.1336 where it meets
the period-doubling end (a 1:2 resonance): located from the torus curve (its pair turning real) and
from the period-doubling curve (a second multiplier reaching -1), two different augmented systems,
the two agree.
"""

from __future__ import annotations

import math
from types import SimpleNamespace

import numpy as np
import pytest

from cosserat_chain import ChainParams
from cosserat_chain.numerics.cycle_curve import AUTO_LABELS, CODIM2, Codim2Point, _codim2_tests, continue_cycle_end
from cycle_ends import located_end


def pair_of(orbit) -> complex:
    """The complex multiplier nearest the unit circle, positive imaginary part."""
    mu = orbit.nontrivial_multipliers
    pairs = mu[mu.imag > 1e-6 * np.abs(mu)]
    return complex(pairs[np.argmin(np.abs(np.abs(pairs) - 1.0))])


def test_the_test_functions_vanish_at_their_points_and_change_sign_across_them():
    """Each test function on multipliers built to sit on either side of its point (no orbit needed)."""

    def orbit(*mu):
        every = np.array([1.0, *mu], dtype=complex)
        return SimpleNamespace(multipliers=every, nontrivial_multipliers=every[1:])

    def torus(theta):
        pair = complex(np.exp(1j * theta))
        return orbit(pair, pair.conjugate(), 0.3), pair

    for angle, name in ((2 * math.pi / 3, "resonance_1_3"), (math.pi / 2, "resonance_1_4")):
        below, above = (_codim2_tests("torus", *torus(angle + d))[name] for d in (-1e-3, 1e-3))
        assert below * above < 0 and abs(_codim2_tests("torus", *torus(angle))[name]) < 1e-15
    # The torus's pair turning real at -1 or +1 ends the curve: the test reaches zero from one side.
    assert _codim2_tests("torus", *torus(math.pi - 1e-3))["resonance_1_2"] > 0
    assert _codim2_tests("torus", *torus(1e-3))["resonance_1_1"] < 0
    # On a period doubling (a multiplier at -1): a second one through -1, or a real one through +1.
    inside, outside = orbit(-1.0, -0.99, 0.3 + 0.2j, 0.3 - 0.2j), orbit(-1.0, -1.01, 0.3 + 0.2j, 0.3 - 0.2j)
    assert _codim2_tests("period_doubling", inside, None)["resonance_1_2"] == pytest.approx(0.01)
    assert _codim2_tests("period_doubling", outside, None)["resonance_1_2"] == pytest.approx(-0.01)
    flip_below, flip_above = orbit(-1.0, 0.99, 0.2), orbit(-1.0, 1.01, 0.2)
    assert _codim2_tests("period_doubling", flip_below, None)["fold_flip"] == pytest.approx(-0.01)
    assert _codim2_tests("period_doubling", flip_above, None)["fold_flip"] == pytest.approx(0.01)
    # On a fold (a second multiplier at +1): a real one through -1; a complex pair near -1 changes nothing.
    fold = [_codim2_tests("fold_of_cycles", orbit(1.0, mu, -0.9 + 0.1j, -0.9 - 0.1j), None)["fold_flip"] for mu in (-0.99, -1.01)]
    assert fold[0] * fold[1] < 0
    assert set(AUTO_LABELS) == {name for names in CODIM2.values() for name in names}


def test_the_torus_end_of_the_paper_s_chain_passes_a_1_to_3_resonance():
    """Followed from E2 = 0.9 to 0.95, the torus end's pair turns through 2 pi / 3: located to the test's tolerance,
    with the pair on the circle at exactly that angle, between the followed values' angles."""
    curve = continue_cycle_end(located_end(ChainParams(E2=0.9), "torus"), "torus", "E2", [0.9, 0.95])
    assert curve.complete
    (point,) = curve.points
    assert isinstance(point, Codim2Point) and (point.kind, point.label, point.name) == ("resonance_1_3", "R3", "1:3 resonance")
    assert 0.9 < point.value < 0.95 and point.uncertainty < 1e-9
    mu = pair_of(point.orbit)
    assert abs(abs(mu) - 1.0) < 1e-8  # still a torus end
    assert np.angle(mu) == pytest.approx(2 * math.pi / 3, abs=1e-8) and point.angle == pytest.approx(np.angle(mu), abs=1e-12)
    # Independently of the located point: the followed ends' angles lie on either side of 2 pi / 3.
    angles = [np.angle(pair_of(orbit)) for orbit in curve.orbits]
    assert angles[0] < 2 * math.pi / 3 < angles[1]
    assert point.moment == pytest.approx(0.170201521, abs=1e-8)
    # AUTO-07p's torus curve of the same chain (docs/state-diagram.md): its pair's angle, printed to 6 digits,
    # passes 2 pi / 3 at E2 = 0.9213118 (interpolated between its points 0.003 apart).
    assert point.value == pytest.approx(0.9213118, abs=5e-6)
    assert curve.as_dict()["codim2"][0]["label"] == "R3"


@pytest.mark.slow
def test_the_1_to_2_resonance_where_the_torus_end_becomes_a_period_doubling_is_the_same_from_either_curve():
    """The torus curve (from E2 = 1.0 up) ends where its pair turns real at -1; the period-doubling curve (from
    1.2 down) stops where its second real negative multiplier reaches -1. Both stop there and say so, and the
    two points agree within their stated uncertainties."""
    params = ChainParams()
    torus = continue_cycle_end(located_end(params.replace(E2=1.0), "torus"), "torus", "E2", [1.0, 1.13, 1.2])
    flip = continue_cycle_end(located_end(params.replace(E2=1.2), "period_doubling"), "period_doubling", "E2", [1.2, 1.14, 1.13])
    assert not torus.complete and not flip.complete
    for curve in (torus, flip):
        assert "1:2 resonance (R2)" in curve.message
        assert curve.points[-1].kind == "resonance_1_2"
    a, b = torus.points[-1], flip.points[-1]
    assert abs(a.value - b.value) <= a.uncertainty + b.uncertainty + 1e-10
    assert a.value == pytest.approx(1.1336439615, abs=1e-9) and a.moment == pytest.approx(b.moment, abs=1e-9)
    # AUTO-07p's two-parameter run of the torus point (ISW = 2) reports its branch point there at
    # E2 = 1.1336440222, M = 0.17753002649, period 11.723242759 (located to its EPSS).
    assert a.value == pytest.approx(1.1336440222, abs=1e-7) and a.moment == pytest.approx(0.17753002649, abs=1e-8)
    assert a.period == pytest.approx(11.723242759, rel=1e-7)
    assert a.angle == pytest.approx(math.pi, abs=1e-4)
    # Two multipliers at -1 (a Jordan block: each within sqrt(round-off), their sum and product to round-off).
    for point in (a, b):
        mu = point.orbit.nontrivial_multipliers
        pair = mu[np.argsort(np.abs(mu + 1.0))[:2]]
        assert np.all(np.abs(pair + 1.0) < 1e-4)
        assert abs(np.sum(pair).real + 2.0) < 1e-8 and abs(np.prod(pair).real - 1.0) < 1e-8
        assert np.max(np.abs(np.delete(mu, np.argsort(np.abs(mu + 1.0))[:2]))) < 0.6  # the rest well inside


@pytest.mark.slow
def test_the_torus_end_followed_down_from_0_8_passes_a_1_to_4_resonance():
    curve = continue_cycle_end(located_end(ChainParams(E2=0.8), "torus"), "torus", "E2", [0.8, 0.7])
    (point,) = curve.points
    assert (point.kind, point.label) == ("resonance_1_4", "R4") and 0.7 < point.value < 0.8
    assert np.angle(pair_of(point.orbit)) == pytest.approx(math.pi / 2, abs=1e-8) and point.uncertainty < 1e-8
    # AUTO-07p's torus curve: its printed pair passes pi / 2 at E2 = 0.7280999 (interpolated, 6 digits).
    assert point.value == pytest.approx(0.7280999, abs=5e-6)


def test_the_secant_finds_a_zero_between_points_and_refuses_a_stop_that_is_not_one():
    """``_locate_codim2`` on a curve made up from the angle theta(p) of a pair on the circle (no orbit): the 1:3
    resonance at theta = 2 pi / 3 between two points, to the tolerance; the 1:2 resonance at the end of a curve
    that reaches theta = pi at p = 1; and a curve that stops at p = 0.9 for another reason (no solution beyond)
    while theta is still 0.3 from pi: not reported."""
    from cosserat_chain.numerics.cycle_curve import _locate_codim2

    def entry(p: float, theta) -> tuple:
        pair = complex(np.exp(1j * theta(p)))
        orbit = SimpleNamespace(moment=0.1 + p, period=1.0, multipliers=np.array([1.0, pair, pair.conjugate(), 0.3]))
        return (p, np.array([p]), orbit, 0, pair)

    def curve(theta, stop: float):
        return lambda p, guess, pair: entry(p, theta) if p <= stop else None

    line = lambda p: 2.0 + p  # noqa: E731 - theta(p), through 2 pi / 3 at p = 2 pi / 3 - 2
    zero = 2 * math.pi / 3 - 2.0
    point = _locate_codim2("torus", "resonance_1_3", curve(line, 1.0), [entry(0.0, line)], entry(0.2, line), 0.2)
    assert point.label == "R3" and abs(point.value - zero) <= max(point.uncertainty, 1e-12) and point.uncertainty < 1e-9
    ending = lambda p: math.pi - 0.5 * math.sqrt(max(1.0 - p, 0.0))  # noqa: E731 - reaches pi at p = 1 like a square root
    point = _locate_codim2("torus", "resonance_1_2", curve(ending, 1.0), [entry(0.9, ending), entry(0.95, ending)], None, 1.5)
    assert point.kind == "resonance_1_2" and abs(point.value - 1.0) <= point.uncertainty < 1e-6
    assert _locate_codim2("torus", "resonance_1_2", curve(line, 0.9), [entry(0.85, line), entry(0.88, line)], None, 1.5) is None
