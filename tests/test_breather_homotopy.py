"""From damped to undamped: the paper's driven rotating orbit followed to gamma = 0 at a fixed mean rate
(:mod:`cosserat_chain.numerics.undamping`, :func:`cosserat_chain.experiments.breathers.damped_to_undamped`)."""

from __future__ import annotations

import numpy as np
import pytest

from cosserat_chain.experiments.breathers import damped_to_undamped
from cosserat_chain.numerics.kit import BranchEnd
from cosserat_chain.numerics.periodic import find_periodic_orbit
from cosserat_chain.numerics.undamping import continue_to_undamped
from cosserat_chain.params import ChainParams

#: States of two orbits found by different Newton problems (each closed to 1e-9) agree to this.
STATE_TOL = 1e-8
#: Relative accuracy of the energy balance M Omega = dissipated power (DOP853 at 1e-12, 256 samples).
BALANCE_TOL = 1e-8


def damped(gamma: float, **fields) -> ChainParams:
    return ChainParams(gamma_u=gamma, gamma_v=gamma, gamma_phi=gamma, **fields)


@pytest.mark.parametrize(("model", "moment"), [("nonlinear", 0.21), ("sine", 0.22)])
def test_damped_orbit_followed_to_zero_damping_lands_on_the_anti_continuum_roto_breather(model, moment):
    # The paper's chain (N = 3) with weak damping turns fast, above every band (Omega = 10.5, 10.9).
    orbit = find_periodic_orbit(damped(0.02), model, moment)
    result = damped_to_undamped(orbit)
    end = result.path.undamped
    assert result.path.end == BranchEnd.VALUE and end is not None and end.gamma_scale == 0.0
    assert abs(end.moment) < 1e-9  # an undamped chain's orbit needs no moment
    assert end.period == orbit.period  # the mean rate is held
    assert result.family is not None and result.family.omega == pytest.approx(abs(orbit.mean_angular_velocity), rel=1e-14)
    assert np.max(np.abs(result.landed.x - result.family.x)) < STATE_TOL
    assert np.max(np.abs(result.landed.v - result.family.v)) < STATE_TOL
    assert result.same_orbit and result.family.stable


def test_moment_power_equals_dissipated_power_along_the_homotopy():
    # The paper's nonlinear orbit at M = 0.30 (Omega = 1.3485, inside the longitudinal band): the chain's
    # share of the dissipation grows along the way (M / (s gamma_phi Omega) from 2.22 to 3.3), so M is not s M_0.
    orbit = find_periodic_orbit(damped(0.1), "nonlinear", 0.30)
    path = continue_to_undamped(orbit)
    assert path.end == BranchEnd.VALUE and path.undamped is not None
    ratios = [p.dissipation_ratio for p in path.points[:-1]]
    assert ratios[0] == pytest.approx(2.2246, abs=1e-3) and max(ratios) > 3.0
    for point in path.points[:: max(1, len(path.points) // 6)]:
        if point.gamma_scale == 0.0:
            continue
        assert point.input_power == pytest.approx(point.dissipated_power(), rel=BALANCE_TOL)


def test_sine_model_breaks_the_energy_balance():
    # Eq. (2) has no energy: the same balance fails by far more than its accuracy (here by 0.7 %).
    orbit = find_periodic_orbit(damped(0.02), "sine", 0.22)
    point = continue_to_undamped(orbit, max_points=3).points[-1]
    assert abs(point.input_power / point.dissipated_power() - 1.0) > 1e-3


def test_paper_sine_orbit_at_its_mean_rate_ends_at_a_fold_of_the_damping():
    # M = 0.22, gamma = 0.1 (Omega = 0.662, in the acoustic band): at this mean rate the orbit exists only
    # down to gamma = 0.0906, where s turns back (the kit's fold test, located by the secant method).
    orbit = find_periodic_orbit(damped(0.1), "sine", 0.22)
    path = continue_to_undamped(orbit)
    assert path.end == BranchEnd.FOLD and path.undamped is None
    assert path.fold_scale == pytest.approx(0.90555, abs=1e-4)
    assert min(p.gamma_scale for p in path.points) > path.fold_scale - 1e-3
    assert all(p.gamma_scale > 0.9 for p in path.points)


def test_homotopy_refuses_an_undamped_orbit():
    orbit = find_periodic_orbit(damped(0.02), "sine", 0.22)
    undamped = orbit.__class__(**{**orbit.__dict__, "params": orbit.params.replace(gamma_u=0.0, gamma_v=0.0, gamma_phi=0.0)})
    with pytest.raises(ValueError, match="undamped already"):
        continue_to_undamped(undamped)
    backwards = find_periodic_orbit(damped(0.02), "sine", -0.22)
    with pytest.raises(ValueError, match="M > 0"):
        damped_to_undamped(backwards)
