"""The switch at a period doubling does not depend on the flip vector's sign (issue 40 item 4: a deterministic switch).

``cycle_switching.flip_vector`` returns the monodromy's eigenvector e for the multiplier -1 with its component of
largest modulus positive, whatever sign LAPACK gives it. On the sine chain at gamma_phi = 0.15 the doubled family's
amplitude along that e turns back at 0.0023, before the normal form's second probe (0.004), where the probes marched
patiently at every scale failed Newton run after Newton run. Both signs start the same doubled orbits (half their period
apart), so the switch gives up a sign after a few halved steps and marches along the other: the switch from either sign
of e reaches the same doubled orbit, and LAPACK's sign changes no bit of it.
"""

from __future__ import annotations

import numpy as np
import pytest
import scipy.linalg as sla

from cosserat_chain import ChainParams
from cosserat_chain.numerics import cycle_switching
from cosserat_chain.numerics.cycle_switching import (
    MIN_STEP,
    PROBE_AMPLITUDES,
    PROBE_SCALES,
    SIGN_STEP,
    flip_vector,
    switch_at_period_doubling,
)
from cosserat_chain.numerics.periodic import OrbitError, find_periodic_orbit
from cycle_ends import shooting_crossing
from test_cycle_switching import half_period_gap

#: LAPACK's eigensolver as scipy gives it, kept before any test replaces it.
EIG = sla.eig
#: The sine chain whose period doubling at M = 0.17288 the switching tests share (tests/cycle_ends.py).
PARAMS = ChainParams(gamma_phi=0.15)


class _Family:
    """A march along one sign of e on a family whose amplitude cannot pass ``turn``; M moves by c a^2 on it."""

    def __init__(self, sign: float, turn: float, log: list):
        self.sign, self.turn, self.log, self.done = sign, turn, log, [(0.0, None)]

    def to(self, amplitude: float, min_step: float = MIN_STEP):
        self.log.append((self.sign, amplitude, min_step))
        if amplitude > self.turn:
            raise OrbitError("the family turns back")
        self.done.append((amplitude, None))
        return amplitude


def test_the_normal_form_marches_along_the_other_sign_where_the_family_turns_before_the_probes():
    c, log = -3.0, []
    turns = {1.0: 0.0023, -1.0: 1.0}  # the sine chain's: along +e the amplitude turns at 0.0023, along -e it does not
    march, probe, coefficient, sign = cycle_switching._normal_form(
        lambda s: _Family(s, turns[s], log), lambda a: c * a * a, signs=(1.0, -1.0)
    )
    assert sign == -1.0 and march.sign == -1.0 and coefficient == pytest.approx(c, rel=1e-12)
    # The full probes along -e, after +e was given up at its second probe with coarse steps only.
    assert probe == PROBE_AMPLITUDES[1]
    assert log == [(1.0, PROBE_AMPLITUDES[0], SIGN_STEP), (1.0, PROBE_AMPLITUDES[1], SIGN_STEP)] + [
        (-1.0, a, SIGN_STEP) for a in PROBE_AMPLITUDES
    ]
    # Where +e serves it is kept, -e never tried.
    log.clear()
    assert cycle_switching._normal_form(lambda s: _Family(s, 1.0, log), lambda a: c * a * a, signs=(1.0, -1.0))[3] == 1.0
    assert {entry[0] for entry in log} == {1.0}


def test_where_both_signs_turn_early_the_probes_shrink_with_patient_steps_on_each_sign():
    c, log = -3.0, []
    turns = {1.0: 0.0005, -1.0: 0.0023}
    _, probe, _, sign = cycle_switching._normal_form(lambda s: _Family(s, turns[s], log), lambda a: c * a * a, signs=(1.0, -1.0))
    # The quick pass fails on both signs, the patient one at the first scale too; at the second scale +e fails, -e serves.
    assert sign == -1.0 and probe == pytest.approx(PROBE_SCALES[1] * PROBE_AMPLITUDES[1])
    small = [PROBE_SCALES[1] * a for a in PROBE_AMPLITUDES]
    assert log == [
        (1.0, PROBE_AMPLITUDES[0], SIGN_STEP), (-1.0, PROBE_AMPLITUDES[0], SIGN_STEP), (-1.0, PROBE_AMPLITUDES[1], SIGN_STEP),
        (1.0, PROBE_AMPLITUDES[0], MIN_STEP), (-1.0, PROBE_AMPLITUDES[0], MIN_STEP), (-1.0, PROBE_AMPLITUDES[1], MIN_STEP),
        (1.0, small[0], MIN_STEP), (1.0, small[1], MIN_STEP), (-1.0, small[0], MIN_STEP), (-1.0, small[1], MIN_STEP),
    ]  # fmt: skip
    with pytest.raises(OrbitError, match="turns back"):
        cycle_switching._normal_form(lambda s: _Family(s, 1e-9, []), lambda a: c * a * a, signs=(1.0, -1.0))


@pytest.fixture(scope="module")
def branch():
    return shooting_crossing(PARAMS)[0]


@pytest.fixture(scope="module")
def switch(branch):
    """The switch with the package's sign of e (along which the family turns at 0.0023)."""
    return switch_at_period_doubling(branch, follow=False)


def negated_eig(matrix):
    """LAPACK's eigenpairs with every eigenvector's sign flipped: as valid an answer as LAPACK's own."""
    values, vectors = EIG(matrix)
    return values, -vectors


def test_the_flip_vector_has_its_largest_component_positive_whatever_lapacks_sign(switch, monkeypatch):
    multiplier, vector = flip_vector(switch.point)
    assert abs(multiplier + 1.0) < 1e-8 and np.linalg.norm(vector) == pytest.approx(1.0, abs=1e-14)
    assert vector[np.argmax(np.abs(vector))] > 0
    monkeypatch.setattr(cycle_switching.sla, "eig", negated_eig)
    again_multiplier, again = flip_vector(switch.point)
    assert again_multiplier == multiplier and np.array_equal(again, vector)


def test_the_switch_from_either_sign_of_the_flip_vector_reaches_the_same_doubled_orbit(branch, switch, monkeypatch):
    own = flip_vector(switch.point)[1]
    # Along the package's e the family turns at 0.0023 < 0.004: the switch marched along -e.
    assert np.array_equal(switch.eigenvector, -own)
    monkeypatch.setattr(cycle_switching, "flip_vector", lambda *a, **k: (lambda r: (r[0], -r[1]))(flip_vector(*a, **k)))
    flipped = switch_at_period_doubling(branch, follow=False)
    assert np.array_equal(flipped.eigenvector, switch.eigenvector)
    for result in (switch, flipped):
        doubled = result.doubled
        # The doubled orbit below M_PD (supercritical), 1e-4 M_PD off as asked, period near 2 T_PD, stable; a genuine orbit
        # of period 2T, not the one-turn orbit twice.
        assert result.side == "below" and doubled.stable and doubled.turns == 2 * result.point.turns
        assert 0.5e-4 < (result.value - doubled.moment) / result.value < 2e-4
        assert doubled.period == pytest.approx(2 * result.point.period, rel=1e-3)
        assert half_period_gap(doubled) > 1e3 * doubled.closure
    assert flipped.doubled.moment == pytest.approx(switch.doubled.moment, abs=1e-12)
    assert flipped.doubled.period == pytest.approx(switch.doubled.period, rel=1e-12)
    assert np.abs(np.sort_complex(flipped.doubled.multipliers) - np.sort_complex(switch.doubled.multipliers)).max() < 1e-9
    # The flip's -1 became 1 - 2 (mu_1^2 - 1) to leading order, mu_1 the one-turn orbit's at the same M (the normal form
    # x -> -(1 + eps) x + x^3; measured 0.01544 against 0.01581).
    single = find_periodic_orbit(PARAMS, "sine", switch.doubled.moment, guess=switch.point).multipliers
    flip = single[np.argmin(np.abs(single + 1.0))]
    second = np.sort(np.abs(switch.doubled.multipliers - 1.0))[1]
    assert second == pytest.approx(2 * (abs(flip) ** 2 - 1), rel=0.1)


def test_the_switch_gives_the_same_bits_whatever_sign_lapack_gives(branch, switch, monkeypatch):
    monkeypatch.setattr(cycle_switching.sla, "eig", negated_eig)
    again = switch_at_period_doubling(branch, follow=False)
    assert np.array_equal(again.eigenvector, switch.eigenvector)
    assert again.amplitude == switch.amplitude and again.coefficient == switch.coefficient
    assert again.doubled.moment == switch.doubled.moment and again.doubled.period == switch.doubled.period
    assert np.array_equal(again.doubled.x, switch.doubled.x) and np.array_equal(again.doubled.v, switch.doubled.v)
    assert np.array_equal(again.doubled.multipliers, switch.doubled.multipliers)


#: AUTO-07p 0.9.2's doubled family (ISW = -1 at its PD, NTST = 200 doubled to 400) at its user point M = 0.17287144382642
#: (benchmarks/auto07p_chain_doubled.py): the period and the flip's square, to their printed digits.
AUTO_MOMENT, AUTO_PERIOD, AUTO_FLIP_SQUARED = 0.17287144382642, 25.739097371, 0.98456


def test_the_doubled_orbit_is_auto07ps_at_its_user_point(switch):
    orbit = find_periodic_orbit(PARAMS, "sine", AUTO_MOMENT, turns=2, guess=switch.doubled)
    # dT/dM is about -2000 this near the period doubling: the period to AUTO's 11 printed digits (measured 3e-10 off).
    assert orbit.period == pytest.approx(AUTO_PERIOD, abs=1e-9)
    second = sorted(orbit.multipliers, key=lambda mu: abs(mu - 1.0))[1]
    assert abs(second - AUTO_FLIP_SQUARED) < 1e-6
