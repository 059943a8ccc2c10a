"""The unequal pendulum pairs' homoclinic ends after the branch stop at a lost trivial multiplier (issue 40 item 3).

Since the shooting branch ends where its monodromy loses the trivial multiplier (||M|| ~ 1e9), the last orbits of
seeds 1 and 2 (``tests/test_homoclinic_unequal.py``) were thought to stay 0.33 and 5.4 from the saddle. They pass it
within 0.004 and 0.002: ``homoclinic_from_orbit`` measured the passage on a whole period integrated again from the
orbit's slowest point, which carries that point's round-off times ||M||; it now reads the passage off the one period
integrated from y0, wrapped by the turns. Where the solve is refused all the same, the fit of the period's growth that
remains must carry an uncertainty that covers AUTO-07p's end (its spread alone did not: 7.9e-8 against an error of
2.1e-7 on seed 1).
"""

from __future__ import annotations

import math
from types import SimpleNamespace

import numpy as np
import pytest

from conftest import SYSTEMS_CACHE
from cosserat_chain.experiments import system_diagram as module
from cosserat_chain.experiments.system_diagram import system_diagram
from cosserat_chain.numerics.equilibria import find_equilibrium
from cosserat_chain.numerics.homoclinic import HomoclinicError, homoclinic_from_orbit, rest
from cosserat_chain.numerics.shooting import states
from test_homoclinic_unequal import ASKED, TURNS, unequal_pair

SEED1 = {"k": 0.305, "a": 0.194, "mu": 0.802, "w": 1.459, "r": 0.949, "coupling": "sine"}
SEED2 = {"k": 0.205, "a": 0.116, "mu": 1.74, "w": 0.774, "r": 1.18}
#: AUTO-07p's ends (tests/test_homoclinic_unequal.py: NTST = 100 and 200, NCOL = 4, 11 digits).
SEED1_END, SEED2_END = 0.27968300176, 0.13311167554


@pytest.fixture(autouse=True)
def _cache(monkeypatch):
    """The compiled systems go to the tests' cache folder, not the user's."""
    monkeypatch.setenv("COSSERAT_CHAIN_CACHE", str(SYSTEMS_CACHE))


def test_the_last_orbit_before_the_lost_trivial_multiplier_passes_the_saddle_closely_and_its_loop_is_solved():
    """Seed 1's last orbit of the continuation (T = 19.33, ||M|| = 7e8, where the branch ends at a lost trivial
    multiplier) passes 0.004 from the saddle with both pendula up; the loop is solved from it to the asked accuracy,
    AUTO-07p's end within it (before the fix: refused, 'no nearer than 0.333')."""
    current = 0.27968572324885094
    system = unequal_pair(I=current, **SEED1)
    y0 = np.array([0.5259807752193988, 0.42237678775286674, 1.636750865355549, 2.7756804140659335])
    orbit = SimpleNamespace(system=system, y0=y0, period=19.334934609499708)
    path = states(system, y0, np.linspace(0.0, orbit.period, 2001))
    slowest = path[int(np.argmin([np.linalg.norm(system.vector_field(y)) for y in path]))]
    saddle = rest(system, find_equilibrium(system, slowest[:2], tol=1e-13, descent=False).q, 0)
    assert np.sum(saddle.eigenvalues.real > 0) == 2
    assert np.min(np.linalg.norm(path - saddle.y, axis=1)) < 0.005
    # Two rungs keep the test quick (the default ladder goes on to 1e-6, where this pair's Newton stops at 1e-4).
    end = homoclinic_from_orbit(orbit, turns=TURNS, parameter="I", ladder=(1e-2, 1e-3))
    assert end.accuracy <= ASKED and abs(end.value - SEED1_END) <= end.accuracy
    assert np.allclose(end.rest.q, saddle.q, atol=1e-5)


@pytest.mark.slow
@pytest.mark.parametrize(("parameters", "auto"), [pytest.param(SEED1, SEED1_END, id="seed1"), pytest.param(SEED2, SEED2_END, id="seed2")])
def test_a_fitted_end_that_remains_covers_auto07p_within_its_uncertainty(monkeypatch, parameters, auto):
    """With both solves refused, the row keeps the fit of the period's growth: AUTO-07p's end lies within its stated
    uncertainty (the fits' spread alone, 7.9e-8 and 3.1e-7, did not cover errors of 2.1e-7 and 5.1e-7)."""

    def refuse(*args, **kwargs):
        raise HomoclinicError("refused by the test")

    monkeypatch.setattr(module, "homoclinic_from_orbit", refuse)
    monkeypatch.setattr(module, "homoclinic_end", refuse)
    pair = unequal_pair(**parameters)
    (row,) = system_diagram(pair, "a", [pair.parameter("a")], "I").rows
    assert (row.end, row.method) == ("homoclinic", "fitted"), row.message
    assert math.isfinite(row.accuracy) and abs(row.stops - auto) <= row.accuracy
