"""Branch switching where the new family turns before the normal form's probes (issue 40: no false ends).

On the paper's sine chain at gamma_phi = 0.15 the one-turn orbit followed down from M = 0.2 loses its
stability at a period doubling near M_PD = 0.1728824; the doubled family's amplitude along the flip
vector turns at about 0.0023, below the second probe (0.004), and from there Newton found the doubled
orbit half a period on (amplitude -0.0061, the same orbit): ``orbit --switch period-doubling`` failed.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from cosserat_chain import ChainParams
from cosserat_chain.numerics import cycle_switching
from cosserat_chain.numerics.continuation import continue_in_moment
from cosserat_chain.numerics.cycle_switching import PROBE_AMPLITUDES, PROBE_SCALES, hopf_orbit, switch_at_hopf, switch_at_period_doubling
from cosserat_chain.numerics.hopf import hopf_points
from cosserat_chain.numerics.periodic import OrbitError, continue_orbit, find_periodic_orbit
from test_cycle_switching import half_period_gap


class _Family:
    """A march on a family whose amplitude cannot pass ``turn``: the moment moves by c a^2 on it."""

    def __init__(self, turn: float, c: float, log: list):
        self.turn, self.c, self.log, self.done = turn, c, log, [(0.0, None)]

    def to(self, amplitude: float, min_step: float = cycle_switching.MIN_STEP):
        self.log.append(amplitude)
        if amplitude > self.turn:
            raise OrbitError("the family turns back")
        self.done.append((amplitude, None))
        return amplitude  # the "orbit": its distance is c a^2


def test_the_normal_form_takes_smaller_probes_where_the_family_turns_before_them():
    log: list[float] = []
    c = -3.0
    march, probe, coefficient, _ = cycle_switching._normal_form(lambda _: _Family(0.0023, c, log), lambda a: c * a * a)
    assert coefficient == pytest.approx(c, rel=1e-12)
    assert probe == pytest.approx(PROBE_SCALES[1] * PROBE_AMPLITUDES[1])
    assert log[:2] == [PROBE_AMPLITUDES[0], PROBE_AMPLITUDES[1]]  # the first scale: the second probe fails
    with pytest.raises(OrbitError, match="turns back"):  # every scale fails: the last failure, not a made-up value
        cycle_switching._normal_form(lambda _: _Family(1e-9, c, []), lambda a: c * a * a)


@pytest.mark.slow
def test_the_sine_chain_at_gamma_phi_015_switches_onto_its_doubled_family():
    params = ChainParams(gamma_phi=0.15)
    branch = continue_orbit(find_periodic_orbit(params, "sine", 0.2, turns=1), moment_min=0.17, period_max=2000.0)
    switch = switch_at_period_doubling(branch, period_max=2000.0)
    point, doubled = switch.point, switch.doubled
    assert switch.value == pytest.approx(0.1728824269, abs=1e-9)
    assert doubled.turns == 2 * point.turns and switch.side == "below"
    # Near M_PD on the doubled family (below it, as the normal form's sign says), twice the period.
    assert doubled.period == pytest.approx(2 * point.period, rel=1e-3)
    assert 0 < switch.value - doubled.moment < 1e-4 * switch.value and switch.coefficient < 0
    # A genuine orbit of period 2T, not the one-turn orbit twice: O(a) away from its start after T, while closing
    # after 2T; the -1 became a second multiplier near +1 beside the trivial one: 1 - mu = 2 (mu_1^2 - 1) to leading
    # order, mu_1 the one-turn orbit's flip multiplier at the same M (the normal form x -> -(1 + eps) x + x^3; measured
    # 0.01544 against 0.01581).
    assert half_period_gap(doubled) > 1e3 * doubled.closure and half_period_gap(doubled) > 0.1 * switch.amplitude
    near_one = np.sort(np.abs(doubled.multipliers - 1.0))
    single = find_periodic_orbit(params, "sine", doubled.moment, guess=point).multipliers
    flip = single[np.argmin(np.abs(single + 1.0))]
    assert near_one[0] < 1e-8 and near_one[1] == pytest.approx(2 * (abs(flip) ** 2 - 1), rel=0.1)
    assert switch.branch is not None and len(switch.branch.orbits) > 2


@pytest.fixture(scope="module")
def hopf_chain():
    """The N = 2 sine chain and its first Hopf point of positive M (``tests/test_cycle_switching.py``'s)."""
    params = ChainParams(N=2)
    points = hopf_points(params, "sine", continue_in_moment(params, "sine", phi0_stop=2 * math.pi))
    return params, [h for h in points if h.moment > 0]


def test_an_amplitude_below_the_probes_is_reached_back_on_the_same_march(hopf_chain):
    # switch_at_hopf marches to its probes (2e-3, 4e-3) first; an amplitude asked below them is solved on that march
    # (the rule that takes only orbits beyond the last amplitude holds for steps onward, not for one asked back).
    params, points = hopf_chain
    switch = switch_at_hopf(params, "sine", points[0], amplitude=1e-3, follow=False)
    assert switch.amplitude == 1e-3 and switch.branch is None
    again = hopf_orbit(params, "sine", points[0], 1e-3)  # a fresh march straight to it
    assert switch.orbit.moment == pytest.approx(again.moment, abs=1e-9)
    assert switch.orbit.period == pytest.approx(again.period, rel=1e-8)
