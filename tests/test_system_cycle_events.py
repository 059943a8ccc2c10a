"""Period doublings and tori of a user system's orbits (issue 40, item 4): ``shooting.continue_orbits``' events.

A system's branch, in any named parameter, detects and locates them by the package's one mechanism
(``numerics/cycle_events.py``: the circle tests watched at every step, Brent's method in the parameter,
each trial an orbit solved at its value). Checked on a system built so that its multipliers are known
in closed form (a uniformly rotating angle beside linear oscillators, which do not move the orbit but
carry its other multipliers): the torus where a circulatory oscillator's pair crosses the circle, and
no torus where a damped pair inside it turns real (which the shooting's own test, prod(|mu| - 1) over
the complex pairs, took for one); and on AUTO-07p's ``pen`` demo, whose period doubling AUTO locates.
"""

from __future__ import annotations

import cmath
import math
from types import SimpleNamespace

import numpy as np
import pytest
import scipy.sparse as sp

from cosserat_chain.numerics import shooting
from cosserat_chain.numerics.cycle_events import CIRCLE_MULTIPLIER, MOMENT_TOL, circle_events_between
from cosserat_chain.numerics.kit import BranchEnd
from cosserat_chain.systems.base import System

#: AUTO-07p's period doubling of the pen demo's in-phase rotation in I (eps = 0.1; tests/test_system_cycle_curve.py).
AUTO_PERIOD_DOUBLING = 0.17916377626


class RotorOscillators(System):
    """An angle driven round at a constant rate beside a circulatory oscillator, with no coupling:

        phi'' + eps phi' = I,      x'' + cx x' = -kx x - a y,      y'' + cy y' = -ky y + a x.

    The rotation phi' = I / eps with x = y = 0 is an orbit of period T = 2 pi eps / I. Its multipliers are
    1, exp(-eps T) and exp(lambda T) for the oscillator's eigenvalues lambda: with kx = ky = k and cx = cy = c
    the roots of lambda^2 + c lambda + k -+ i a = 0, a pair i sqrt(k) on the axis at a = c sqrt(k) (a torus of
    angle sqrt(k) T); with a = 0, -cx/2 +- sqrt(cx^2/4 - kx) (a pair that turns real at kx = cx^2 / 4) and
    the same of y.
    """

    name = "rotor-oscillators"

    def __init__(self, **parameters):
        super().__init__({"I": 2 * math.pi, "eps": 1.0, "a": 0.2, "cx": 0.2, "cy": 0.2, "kx": 1.5, "ky": 1.5, **parameters})

    @property
    def coordinates(self):
        return ("phi", "x", "y")

    @property
    def angles(self):
        return np.array([True, False, False])

    def forces(self, q):
        p = self.parameters
        return np.array([p["I"], -p["kx"] * q[1] - p["a"] * q[2], -p["ky"] * q[2] + p["a"] * q[1]])

    def force_jacobian(self, q):
        p = self.parameters
        return sp.csr_matrix(np.array([[0.0, 0.0, 0.0], [0.0, -p["kx"], -p["a"]], [0.0, p["a"], -p["ky"]]]))

    def parameter_forces(self, q, name):
        self._check_name(name)
        derivatives = {"I": [1.0, 0.0, 0.0], "a": [0.0, -q[2], q[1]], "kx": [0.0, -q[1], 0.0], "ky": [0.0, 0.0, -q[2]]}
        return np.array(derivatives.get(name, [0.0, 0.0, 0.0]))

    def mass(self):
        return np.ones(3)

    def damping(self):
        p = self.parameters
        return np.array([p["eps"], p["cx"], p["cy"]])


def rotation(**parameters) -> shooting.Orbit:
    system = RotorOscillators(**parameters)
    rate = system.parameter("I") / system.parameter("eps")
    return shooting.find_orbit(system, (np.array([0.0, 0.0, 0.0, rate, 0.0, 0.0]), 2 * math.pi / rate), turns={"phi": 1})


def kinds(branch: shooting.OrbitBranch) -> list[str]:
    return [e.kind for e in branch.events if e.kind in ("period_doubling", "torus")]


def test_the_torus_of_a_circulatory_oscillator_is_located_at_its_closed_form():
    start = rotation()
    branch = shooting.continue_orbits(start, "a", direction=1, limits=(0.0, 0.3), stop_at=())
    c, k, period = 0.2, 1.5, start.period
    assert period == pytest.approx(1.0, abs=1e-12)
    (torus,) = (e for e in branch.events if e.kind == "torus")
    assert kinds(branch) == ["torus"] and torus.located
    assert torus.parameter == pytest.approx(c * math.sqrt(k), abs=1e-8)
    # The pair on the circle at the angle sqrt(k) T; the orbit is the rotation, the parameter set on its system.
    pair = torus.point.nontrivial_multipliers
    assert np.min(np.abs(pair - cmath.exp(1j * math.sqrt(k) * period))) < 1e-8
    assert torus.point.parameter("a") == torus.parameter and torus.point.period == pytest.approx(period, abs=1e-12)
    # It is where the branch's stability changes, between the orbits on either side.
    (lost,) = (e for e in branch.events if e.kind == "stability")
    assert lost.parameter == pytest.approx(torus.parameter, abs=1e-8)
    values = branch.values
    assert values[torus.index - 1] < torus.parameter < values[torus.index]


def test_stop_at_torus_ends_the_branch_at_the_located_torus():
    branch = shooting.continue_orbits(rotation(), "a", direction=1, limits=(0.0, 0.3), stop_at=("torus",))
    assert branch.end == BranchEnd.TORUS and "torus located at a = 0.244948974279" in branch.message
    (torus,) = (e for e in branch.events if e.kind == "torus")
    assert torus.index == len(branch.orbits) - 1 and abs(torus.parameter - 0.2 * math.sqrt(1.5)) < MOMENT_TOL
    # Listed before the loss of stability the kit locates in the same step.
    assert [e.kind for e in branch.events[-2:]] == ["torus", "stability"]


def test_a_pair_inside_the_circle_that_turns_real_is_no_torus():
    """x's pair turns real inside the circle at kx = cx^2 / 4 = 0.09 while y's pair sits 4e-4 inside it: the old test
    prod(|mu| - 1) changed sign there, and its confirmation (a complex pair within 1e-3 of the circle) held."""
    cx, cy = 0.6, 8e-4
    branch = shooting.continue_orbits(
        rotation(a=0.0, cx=cx, cy=cy, kx=0.2), "kx", direction=-1, limits=(0.05, 0.2), step=0.04, min_step=0.04, max_step=0.04, stop_at=()
    )
    assert branch.values.tolist() == pytest.approx([0.2, 0.16, 0.12, 0.08, 0.04], abs=1e-12)
    first, last = branch.orbits[0].nontrivial_multipliers, branch.orbits[-1].nontrivial_multipliers
    near = lambda mu: mu[np.abs(mu) > 0.5]  # noqa: E731 - the multipliers the tests take
    assert np.count_nonzero(np.abs(near(first).imag) > 1e-6) == 4 and np.count_nonzero(np.abs(near(last).imag) > 1e-6) == 2
    # y's pair, exp(-cy T / 2) in modulus, lies within the confirmation's distance of the circle throughout.
    assert 0 < 1.0 - math.exp(-cy / 2) < CIRCLE_MULTIPLIER and np.max(np.abs(last)) < 1.0

    def old_test(mu):
        pairs = mu[mu.imag > 1e-9]
        return np.prod(np.abs(pairs) - 1.0)

    assert old_test(first) * old_test(last) < 0
    assert kinds(branch) == [] and all(o.stable for o in branch.orbits)


def test_the_pen_demo_s_period_doubling_is_auto_s(pen_in_phase_branch):
    """Located by Brent's method in I to MOMENT_TOL: AUTO-07p's printed digits, a multiplier at -1 there."""
    branch = pen_in_phase_branch
    assert branch.end == BranchEnd.PERIOD_DOUBLING and kinds(branch) == ["period_doubling"]
    (event,) = (e for e in branch.events if e.kind == "period_doubling")
    assert event.index == len(branch.orbits) - 1 and event.located and event.parameter == pytest.approx(AUTO_PERIOD_DOUBLING, abs=1e-9)
    assert event.point.parameter("I") == event.parameter
    assert np.min(np.abs(event.point.nontrivial_multipliers + 1.0)) < 1e-8
    assert branch.orbits[event.index].parameter("I") < event.parameter < branch.orbits[event.index - 1].parameter("I")


def pair(p: float) -> SimpleNamespace:
    """An orbit at the parameter value p whose complex pair leaves the unit circle at p = 0.305, at the angle 1."""
    radius = 1.0 + 20.0 * (p - 0.305)
    return SimpleNamespace(p=p, nontrivial_multipliers=np.array([radius * cmath.exp(1j), radius * cmath.exp(-1j)]))


def test_the_locator_takes_any_parameter_and_nothing_between_two_orbits_at_one_value():
    """``value`` names the branch's parameter: the crossing is located in it to MOMENT_TOL; a sign change between two
    orbits at the same value (no interval in the parameter) is not solved for."""
    (event,) = circle_events_between(pair(0.3), pair(0.31), lambda value, a, b: pair(value), value=lambda orbit: orbit.p)
    assert event["kind"] == "torus" and event["located"] and abs(event["moment"] - 0.305) < MOMENT_TOL
    assert event["angle"] == pytest.approx(1.0, abs=1e-12)

    def solve(value, a, b):
        raise AssertionError("no trial may be solved")

    inside, outside = pair(0.3), pair(0.31)
    outside.p = 0.3
    assert circle_events_between(inside, outside, solve, value=lambda orbit: orbit.p) == []
