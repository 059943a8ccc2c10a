"""All three models agree at small load (issue 17, item 1): the slope, the sine identity, the range, the mechanism."""

from __future__ import annotations

import math

import numpy as np
import pytest
import scipy.optimize as so

from conftest import random_geometries
from cosserat_chain import ChainParams, moment_load
from cosserat_chain.analysis.agreement import agreement_range, errors_against, static_deviation
from cosserat_chain.numerics.continuation import compliance, rotation_branch
from cosserat_chain.numerics.newton import solve_equilibrium

#: The chains of the issue's measurements, with the nonlinear model's deviation from the
#: linear one at the linear angle 0.1, as quoted there (percent, rounded as quoted).
QUOTED = [
    (ChainParams(), -0.56),
    (ChainParams(N=4, a=0.5, b=0.4, h=2, E1=0.7, E2=1.3), -1.7),
    (ChainParams(N=10, a=0.3, b=0.1, E1=2, E2=0.3), -13.0),
    (ChainParams(N=50, a=0.25, b=0.15, E2=2), -45.0),
]
#: Relative agreement of two exact computations by different routes (Newton to 1e-12).
SOLVER = 1e-9


def _on_rotation_branch(params, model, phi0):
    """M at the model's own angle phi0, from the rotation-controlled branch (an independent route)."""
    angles = np.linspace(0.0, phi0, 9)[1:]
    return float(rotation_branch(params, model, angles).moment[-1])


@pytest.mark.parametrize("N", [1, 2, 5, 12])
def test_the_sine_deviation_is_arcsin_p_over_p_on_every_chain(N):
    """sin phi_0 = c M exactly (the sine model's statics are the linear one's in sin phi), so phi_0 / (c M) - 1 = p^2/6 + O(p^4).
    One random geometry a chain length (seeded by N: four geometries over the four cases)."""
    p = np.array([1e-3, 0.01, 0.1, 0.5, 0.9])
    for params in random_geometries(1, seed=N):
        params = params.model_copy(update={"N": N})
        deviation = static_deviation(params, "sine", p)
        np.testing.assert_allclose(1.0 + deviation, np.arcsin(p) / p, rtol=SOLVER)
        # The leading term phi_0^2 / 6 and the next, 3 p^4 / 40 (the third, 5 p^6 / 112, is below 1e-4 of them).
        np.testing.assert_allclose(deviation[:3], p[:3] ** 2 / 6 * (1 + 0.45 * p[:3] ** 2), rtol=1e-4)
        # The range within 1 % is the same for every chain: arcsin(p) / p = 1.01.
        edge = so.brentq(lambda q: math.asin(q) / q - 1.01, 0.01, 1.0, xtol=1e-15)
        assert agreement_range(params, "sine", tolerance=0.01).phi0_linear == pytest.approx(edge, rel=SOLVER)


def test_every_model_leaves_the_common_tangent_at_second_order():
    """The same slope at rest: the deviation vanishes like p^2 for every model (a slope error would leave it O(1))."""
    for params in random_geometries(3, seed=7):
        slopes = [compliance(params, m) for m in ("nonlinear", "sine", "linear")]
        np.testing.assert_allclose(slopes, slopes[0], rtol=1e-12)
        p = np.array([4e-3, 2e-3])
        for model in ("nonlinear", "sine"):
            deviation = static_deviation(params, model, p)
            assert abs(deviation[0]) < 1e-3
            assert deviation[0] / deviation[1] == pytest.approx(4.0, rel=1e-2)
        np.testing.assert_allclose(static_deviation(params, "linear", p), 0.0, atol=1e-10)


@pytest.mark.parametrize(("params", "quoted"), QUOTED, ids=["paper", "N4", "N10", "N50"])
def test_the_quoted_deviations_at_a_linear_angle_of_0_1(params, quoted):
    deviation = float(static_deviation(params, "nonlinear", [0.1])[0])
    assert float(f"{100 * deviation:.2g}") == quoted
    # Load control and rotation control give the same static state: at its angle the
    # rotation-controlled branch holds exactly the load 0.1 / c.
    c = compliance(params, "nonlinear")
    assert _on_rotation_branch(params, "nonlinear", 0.1 * (1 + deviation)) == pytest.approx(0.1 / c, rel=SOLVER)


def test_the_long_chain_already_deviates_by_5_percent_at_a_linear_angle_of_0_01():
    params = QUOTED[-1][0]
    assert float(f"{100 * static_deviation(params, 'nonlinear', [0.01])[0]:.2g}") == -4.9


@pytest.mark.parametrize(("params", "_"), QUOTED[:3], ids=["paper", "N4", "N10"])
def test_the_agreement_range_ends_where_the_branch_leaves_the_tolerance(params, _):
    tolerance = 0.01
    edge = agreement_range(params, "nonlinear", tolerance=tolerance)
    assert edge.bound == "tolerance"
    assert edge.phi0_linear == pytest.approx(edge.compliance * edge.moment, rel=1e-15)
    # The rotation-controlled branch at the edge's angle holds the edge's load, and the
    # deviation there is the tolerance (stiffer: below the linear angle).
    moment = _on_rotation_branch(params, "nonlinear", edge.phi0)
    assert moment == pytest.approx(edge.moment, rel=SOLVER)
    assert edge.phi0 / (edge.compliance * moment) - 1.0 == pytest.approx(-tolerance, rel=1e-7)
    # Within the range the models agree, just beyond it they do not.
    half, inside, beyond = np.abs(static_deviation(params, "nonlinear", edge.phi0_linear * np.array([0.5, 0.99, 1.01])))
    assert half < inside < tolerance < beyond


def test_a_tolerance_beyond_the_fold_ends_the_range_at_the_fold():
    params = ChainParams()
    edge = agreement_range(params, "sine", tolerance=0.9)
    # arcsin(1) / 1 - 1 = pi/2 - 1 = 0.571 < 0.9: the sine branch ends first, at sin phi_0 = 1.
    assert edge.bound == "fold"
    assert edge.phi0 == pytest.approx(math.pi / 2, rel=1e-9)
    assert edge.deviation == pytest.approx(math.pi / 2 - 1, rel=1e-9)
    assert agreement_range(params, "linear").bound == "end"


def test_the_stiffening_grows_with_the_transverse_displacements():
    """kappa = deviation / p^2 against (v_max / (b phi_0))^2 of the linear solution: proportional on long chains, and
    positive (softer) at N = 1, where the loaded particle's v vanishes by symmetry."""
    p = 3e-3
    ratios = {}
    for N in (1, 10, 20, 50):
        params = ChainParams(N=N)
        c = compliance(params, "linear")
        v = np.max(np.abs(solve_equilibrium(params, "linear", moment_load(p / c))[1])) / p
        kappa = float(static_deviation(params, "nonlinear", [p])[0]) / p**2
        ratios[N] = (kappa, v / params.b)
    assert ratios[1][1] < 1e-12 and ratios[1][0] > 0
    scaled = [ratios[N][0] / ratios[N][1] ** 2 for N in (10, 20, 50)]
    assert all(k < 0 for k in scaled)
    np.testing.assert_allclose(scaled, scaled[-1], rtol=0.02)
    # kappa itself grows like N^2 (v_max like N): a factor 25 from N = 10 to 50.
    assert ratios[50][0] / ratios[10][0] == pytest.approx(25.0, rel=0.1)


def test_the_sine_error_exceeds_the_linear_one_except_on_the_shortest_chain():
    """The paper: the error of model (2) exceeds that of (3), against model (1). At N = 1 the nonlinear chain is softer
    than the linear one, by more than half the sine model's excess, and the sine model is the closer of the two."""
    p = [0.05, 0.1]
    for N, sine_worse in ((1, False), (3, True), (10, True)):
        errors = errors_against(ChainParams(N=N), "nonlinear", ["sine", "linear"], p)
        assert np.all((np.abs(errors["sine"]) > np.abs(errors["linear"])) == sine_worse), N
    assert static_deviation(ChainParams(N=1), "nonlinear", [0.1])[0] > 0


def test_bad_input_is_refused():
    params = ChainParams()
    with pytest.raises(ValueError, match="tolerance"):
        agreement_range(params, "nonlinear", tolerance=0.0)
    with pytest.raises(ValueError, match="phi0_linear"):
        static_deviation(params, "nonlinear", [0.0])
    # Beyond the nonlinear fold (M_c = 0.1975, c = 4.90: linear angle 0.968) there is no static state.
    with pytest.raises(ValueError, match="beyond the first fold"):
        static_deviation(params, "nonlinear", [1.2])
