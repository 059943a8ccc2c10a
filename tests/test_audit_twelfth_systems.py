"""The twelfth outside audit of the orbit kit on user systems that no other test holds (H12audB).

Each system is written here by hand; each number is checked against a closed form or an independent
computation. The tests marked as defects fail on the code before their fix.
"""

from __future__ import annotations

import math

import numpy as np

from cosserat_chain.numerics.equilibria import continue_equilibria, find_equilibrium
from cosserat_chain.numerics.kit import BranchEnd
from cosserat_chain.numerics.shooting import continue_orbits, find_orbit
from cosserat_chain.systems.base import System
from follower_rotor_system import rotor_class

FollowerRotor = rotor_class()


def _hopf(system: System) -> float:
    p = system.parameters
    return p["c"] * math.sqrt(p["kk"])


def _circle(system: System) -> tuple[np.ndarray, float]:
    """The closed-form orbit's start (R, 0, 0, R w) and period."""
    p = system.parameters
    w = math.sqrt(p["kk"])
    radius = math.sqrt((p["a0"] - _hopf(system)) / p["b"])
    return np.array([radius, 0.0, 0.0, radius * w]), 2 * math.pi / w


def test_a_hopf_point_of_a_circulatory_system_is_located_at_its_closed_form():
    """The rest state's branch in a0 meets one Hopf point, at c sqrt(kk); no fold, no branch point."""
    system = FollowerRotor(a0=0.1)
    branch = continue_equilibria(find_equilibrium(system, np.zeros(2)), "a0", limits=(0.0, 0.5), stop_at=())
    assert [e.kind for e in branch.events] == ["hopf"]
    assert abs(branch.events[0].parameter - _hopf(system)) < 1e-8


def test_the_orbits_born_at_the_hopf_point_have_the_closed_form_radius_period_and_multipliers():
    """Shooting from 5 % off the circle returns the circle to Newton's tolerance; the multipliers equal
    those of a monodromy by central differences of SciPy's DOP853 (rtol 1e-12), an independent computation."""
    from scipy.integrate import solve_ivp

    system = FollowerRotor(a0=0.3)
    start, period = _circle(system)
    orbit = find_orbit(system, (1.05 * start, 1.01 * period))
    assert abs(orbit.period - period) < 1e-9
    assert abs(np.hypot(*orbit.q0) - start[0]) < 1e-9
    h, columns = 1e-6, []
    for e in np.eye(4):
        ends = [
            solve_ivp(
                lambda t, y: system.vector_field(y), (0, orbit.period), orbit.y0 + s * h * e, method="DOP853", rtol=1e-12, atol=1e-12
            ).y[:, -1]
            for s in (1, -1)
        ]
        columns.append((ends[0] - ends[1]) / (2 * h))
    reference = np.sort_complex(np.linalg.eigvals(np.array(columns).T))
    assert np.max(np.abs(np.sort_complex(orbit.multipliers) - reference)) < 1e-6


def test_an_orbit_shrinking_onto_its_hopf_point_ends_there_not_at_a_fold_of_cycles():
    """Defect: followed down in a0, the family shrinks onto q = 0 at the Hopf point, where a0 turns
    (a0 - a0_H ~ R^2) and the equilibrium's pair exp(+-i w T) sits at +1. The continuation reported a
    located ``fold`` (a fold of cycles) and a ``branch_point`` there and went on, back up the same family
    phase-shifted by half a period, to max_points. It now ends at the Hopf point, naming it."""
    system = FollowerRotor(a0=0.27)  # radius 0.16, five orbits to the Hopf point at 0.2449
    orbit = find_orbit(system, _circle(system))
    branch = continue_orbits(orbit, "a0", direction=-1, stop_at=(), max_points=40)
    assert branch.end == BranchEnd.HOPF, branch.message
    assert not [e for e in branch.events if e.kind in ("fold", "branch_point")]
    assert "Hopf point" in branch.message
    assert abs(branch.values[-1] - _hopf(system)) < 0.02
    assert np.all(np.abs(branch.periods - _circle(system)[1]) < 1e-7)


def _retrapping(alpha: float, low: float, high: float) -> float:
    """The damped driven pendulum's retrapping torque I_r(alpha), independently: the saddle's unstable
    manifold (SciPy's DOP853 at rtol 1e-13) reaches the next saddle at I_r; above, it goes over the top
    (the pendulum rotates), below, it falls back (its rate comes to zero first). Bisected to 1e-12."""
    from scipy.integrate import solve_ivp

    def rotates(torque: float) -> bool:
        saddle = math.pi - math.asin(torque)
        rate = 0.5 * (-alpha + math.sqrt(alpha**2 + 4 * math.cos(math.asin(torque))))

        def back(t, y):
            return y[1]

        def over(t, y):
            return y[0] - saddle - 2 * math.pi - 0.5

        back.terminal, back.direction, over.terminal = True, -1, True
        run = solve_ivp(
            lambda t, y: [y[1], torque - math.sin(y[0]) - alpha * y[1]],
            (0, 1e3),
            [saddle + 1e-8, rate * 1e-8],
            method="DOP853",
            events=[back, over],
            rtol=1e-13,
            atol=1e-15,
        )
        return run.t_events[1].size > 0

    while high - low > 1e-12:
        middle = 0.5 * (low + high)
        low, high = (low, middle) if rotates(middle) else (middle, high)
    return 0.5 * (low + high)


def test_a_fitted_homoclinic_end_lies_within_its_stated_uncertainty():
    """Defect: the end fitted from the period's growth was the fit over the widest span of periods, with its
    distance from the fit over half that span as the uncertainty; the wide fit is the worse one (its orbits of
    shorter period follow the exponential law less closely), and was off by more than the stated uncertainty:
    1.5e-9 against +- 1.1e-9 on this pair's in-phase rotation, 1.8e-7 against 1.1e-7 on an unequal pendulum pair against
    AUTO-07p. The narrow fit is now the value, the wide one's distance from it the uncertainty."""
    from cosserat_chain.systems.lattice import LatticeSystem

    # Two pendula with a Josephson (sine) bond: their in-phase rotation is the single pendulum's.
    pair = LatticeSystem(
        sites=2,
        site_energy="1 - cos(phi) - I*phi",
        bond_energy="kappa*(1 - cos(phi_r - phi_l))",
        damping="alpha",
        parameters={"I": 0.5, "alpha": 0.1, "kappa": 0.2},
        name="sine-pair",
    )
    orbit = find_orbit(pair, (np.array([0.0, 0.0, 5.0, 5.0]), 1.25), turns={"phi_0": 1, "phi_1": 1})
    branch = continue_orbits(orbit, "I", direction=-1, stop_at=())
    reference = _retrapping(0.1, 0.12, 0.135)
    assert abs(reference - 4 * 0.1 / math.pi) < 0.01
    assert branch.end_value is not None and branch.end_uncertainty is not None, branch.message
    assert abs(branch.end_value - reference) <= branch.end_uncertainty, (branch.end_value, reference, branch.end_uncertainty)
