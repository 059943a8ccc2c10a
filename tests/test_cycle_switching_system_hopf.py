"""Orbits born at a user system's Hopf point (issue 40 item 4): ``cycle_switching.system_hopf_orbit``.

The follower-force rotor of ``tests/follower_rotor_system.py`` (a Stuart-Landau normal form in second-order form)
has its Hopf point at a0 = c sqrt(kk) and, beyond it, the circle of radius R with a0 - c sqrt(kk) = b R^2 and period
2 pi / sqrt(kk) at every amplitude: the orbit started along the crossing eigenvector must be that circle, exactly.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from cosserat_chain.numerics.cycle_switching import system_hopf_orbit
from cosserat_chain.numerics.equilibria import continue_equilibria, find_equilibrium
from cosserat_chain.numerics.shooting import CLOSURE_TOL
from follower_rotor_system import HOPF, PERIOD, ROTOR


@pytest.fixture(scope="module")
def hopf():
    """The equilibrium q = 0 followed up in a0 from 0.2 to its located Hopf point."""
    namespace: dict = {}
    exec(ROTOR, namespace)
    system = namespace["build"](a0=0.2)
    branch = continue_equilibria(find_equilibrium(system, np.zeros(2)), "a0", direction=1, stop_at=("hopf",), limits=(0.0, 0.4))
    (event,) = [e for e in branch.events if e.kind == "hopf"]
    assert event.located and event.parameter == pytest.approx(HOPF, abs=1e-9)
    return event.point


@pytest.mark.parametrize("amplitude", [4e-3, 4e-2])
def test_the_orbit_born_at_a_systems_hopf_point_is_the_closed_form_circle(hopf, amplitude):
    orbit = system_hopf_orbit(hopf, "a0", amplitude)
    radius = math.hypot(*orbit.q0)
    assert not orbit.turns.any() and orbit.closure <= 1e-9
    assert orbit.period == pytest.approx(PERIOD, abs=1e-8)
    # On the circle: a0 - a0_H = b R^2, and the speed R sqrt(kk) along it; the amplitude is e . (y0 - y_H), |e| = 1.
    # a0 to Newton's closure tolerance over its leverage on the closure, about T R per unit of a0.
    assert orbit.parameter("a0") - HOPF == pytest.approx(radius**2, abs=2 * CLOSURE_TOL / (PERIOD * radius))
    assert np.hypot(*orbit.v0) == pytest.approx(radius * math.sqrt(1.5), rel=1e-8)
    assert radius * math.sqrt(1 + 1.5) >= amplitude * (1 - 1e-9)
    assert orbit.stable  # supercritical: the circle inherits the stability the equilibrium lost


def test_an_equilibrium_off_its_hopf_point_or_a_bad_amplitude_is_refused(hopf):
    with pytest.raises(ValueError, match="amplitude must be a finite number > 0"):
        system_hopf_orbit(hopf, "a0", 0.0)
    off = find_equilibrium(hopf.system.with_parameters(a0=0.2), np.zeros(2))
    with pytest.raises(ValueError, match="not a located Hopf point"):
        system_hopf_orbit(off, "a0", 1e-2)


def test_a_subcritical_hopf_points_unstable_circles_which_no_settling_run_reaches():
    """With b < 0 the circles lie below the Hopf point (a0 - a0_H = b R^2 < 0) and are unstable: only the Hopf start
    reaches them."""
    namespace: dict = {}
    exec(ROTOR, namespace)
    system = namespace["build"](a0=0.2, b=-1.0)
    branch = continue_equilibria(find_equilibrium(system, np.zeros(2)), "a0", direction=1, stop_at=("hopf",), limits=(0.0, 0.4))
    (event,) = [e for e in branch.events if e.kind == "hopf"]
    orbit = system_hopf_orbit(event.point, "a0", 4e-2)
    radius = math.hypot(*orbit.q0)
    assert orbit.period == pytest.approx(PERIOD, abs=1e-8) and not orbit.stable
    assert orbit.parameter("a0") - HOPF == pytest.approx(-(radius**2), abs=2 * CLOSURE_TOL / (PERIOD * radius))
