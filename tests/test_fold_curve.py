"""The static fold followed in a parameter (issue 13, item 1): ``numerics.fold_curve.continue_fold``.

Checked against independent fold searches at every value (``locate_fold``: Brent's
method on dM/dphi_0 of the rotation-controlled branch), on the paper's chain, random
admissible chains and a long chain; Newton's quadratic convergence; a field the statics
do not read; a fold that ends in a cusp; and bad input.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from conftest import random_geometries
from cosserat_chain import ChainParams
from cosserat_chain.numerics.continuation import continue_in_moment, locate_fold
from cosserat_chain.numerics.fold_curve import STATIC_INDEPENDENT, continue_fold

FOLD_AGREEMENT = 1e-10


def independent_fold(params: ChainParams, model: str) -> float:
    return locate_fold(params, model, phi0_max=2 * math.pi).moment


@pytest.mark.parametrize("model", ["nonlinear", "sine"])
@pytest.mark.parametrize(
    ("field", "factors"), [("E2", (1.0, 0.8, 0.6)), ("b", (1.0, 1.1, 1.2)), ("h", (1.0, 0.95, 0.9)), ("E1", (1.0, 1.5, 2.0))]
)
def test_the_followed_fold_equals_an_independent_search_at_every_value(model, field, factors):
    params = ChainParams()
    values = [getattr(params, field) * f for f in factors]
    curve = continue_fold(params, model, field, values)
    assert curve.complete and np.array_equal(curve.values, values)
    for value, moment in zip(values, curve.moment):
        assert moment == pytest.approx(independent_fold(params.replace(**{field: value}), model), abs=FOLD_AGREEMENT)
    assert np.all(curve.iterations[1:] <= 5)  # Newton on the extended system converges quadratically


@pytest.mark.parametrize("params", random_geometries(4, seed=31), ids=lambda p: f"N{p.N}")
def test_on_random_chains_the_fold_moves_as_independent_searches_say(params):
    values = params.a * np.array([1.0, 0.97, 0.94])
    curve = continue_fold(params, "nonlinear", "a", values)
    assert curve.complete
    for value, moment, state in zip(values, curve.moment, curve.x):
        chain = params.replace(a=value)
        assert moment == pytest.approx(independent_fold(chain, "nonlinear"), abs=FOLD_AGREEMENT)
        # The state is an equilibrium under M_c and K is singular there.
        from cosserat_chain.models import NONLINEAR

        force = NONLINEAR.forces(chain, state)
        force[2, chain.N] += moment
        assert np.abs(force).max() < 1e-10
        assert np.abs(np.linalg.eigvalsh(NONLINEAR.stiffness(chain, state).toarray())).min() < 1e-8


def test_a_long_chain_is_followed_in_a_few_newton_steps():
    params = ChainParams(N=100)
    curve = continue_fold(params, "nonlinear", "E2", [1.0, 1.05, 1.1])
    assert curve.complete and np.all(curve.iterations[1:] <= 5)
    assert curve.moment[-1] == pytest.approx(independent_fold(params.replace(E2=1.1), "nonlinear"), abs=FOLD_AGREEMENT)


@pytest.mark.parametrize("field", STATIC_INDEPENDENT)
def test_inertia_and_viscosity_do_not_move_the_fold(field):
    params = ChainParams()
    curve = continue_fold(params, "nonlinear", field, [0.05, 0.2, 3.0])
    assert curve.independent and curve.complete
    np.testing.assert_allclose(curve.moment, independent_fold(params, "nonlinear"), rtol=0, atol=1e-13)


def test_a_fold_that_meets_another_one_ends_and_says_where():
    # M(phi_0) of this chain has a maximum at phi_0 = 1.0003 and a minimum 0.017 rad later
    # (docs/statics.md); lowering E2 brings them together until both vanish.
    params = ChainParams(N=10, a=0.3, b=0.1, E1=2.0, E2=0.3)
    curve = continue_fold(params, "nonlinear", "E2", np.linspace(0.3, 0.28, 5))
    assert not curve.complete and "ends there" in curve.message
    last = float(curve.message.split("beyond E2 = ")[1].split(" ")[0])
    assert 0.28 < last < 0.3
    # Past the end the branch's first maximum is elsewhere: the pair near phi_0 = 1 is gone.
    beyond = continue_in_moment(params.replace(E2=0.28), "nonlinear", max_folds=1).folds[0]
    assert abs(beyond.phi0 - curve.phi0[0]) > 0.5


def test_bad_input_is_refused_naming_the_field_and_the_value():
    params = ChainParams()
    with pytest.raises(ValueError, match="field must be one of E1, E2"):
        continue_fold(params, "nonlinear", "N", [3, 4])
    with pytest.raises(ValueError, match="values of E2 must be one or more finite numbers"):
        continue_fold(params, "nonlinear", "E2", [1.0, float("nan")])
    with pytest.raises(ValueError, match=r"a = 0.6 is not an admissible chain.*a must satisfy 0 < a < h/2"):
        continue_fold(params, "nonlinear", "a", [0.2, 0.6])
    with pytest.raises(ValueError, match="no fold"):
        continue_fold(params, "linear", "E2", [1.0, 1.1])
    with pytest.raises(ValueError, match="can move rigidly"):
        continue_fold(ChainParams(left_end="free", right_end="free"), "nonlinear", "E2", [1.0])


def test_where_the_fold_meets_another_the_turn_of_the_curve_is_located_between_two_and_no_fold():
    # The same pair of folds near phi_0 = 1 (test above): the curve of the maximum turns back in
    # E2 where it meets the minimum. Just above the located turn the branch from rest still has
    # its first maximum there; just below, that pair is gone.
    params = ChainParams(N=10, a=0.3, b=0.1, E1=2.0, E2=0.3)
    curve = continue_fold(params, "nonlinear", "E2", [0.3, 0.29])
    turn = float(curve.message.split("beyond E2 = ")[1].split(" ")[0])
    above = continue_in_moment(params.replace(E2=turn + 2e-5), "nonlinear", max_folds=1).folds[0]
    below = continue_in_moment(params.replace(E2=turn - 2e-5), "nonlinear", max_folds=1).folds[0]
    assert abs(above.phi0 - curve.phi0[0]) < 0.05 and abs(below.phi0 - curve.phi0[0]) > 0.5


def test_values_in_any_order_are_followed_there_and_back():
    params = ChainParams(N=6)
    values = [1.0, 0.7, 1.3, 1.0]
    curve = continue_fold(params, "nonlinear", "E2", values)
    assert curve.complete and np.array_equal(curve.values, values)
    assert curve.moment[-1] == pytest.approx(curve.moment[0], abs=1e-13)
    for value, moment in zip(values[1:3], curve.moment[1:3]):
        assert moment == pytest.approx(independent_fold(params.replace(E2=value), "nonlinear"), abs=FOLD_AGREEMENT)


def test_a_fold_that_is_nearly_not_simple_is_still_followed_to_the_value():
    # The N = 3 cantilever's first fold (phi_0 = 4.84, near 3 pi / 2): its null vector turns 10^5
    # times faster than E2 moves, the extended system is nearly singular and the curve's tangent
    # shows turns that are not there; the fold at the value is regular.
    params = ChainParams(right_end="free")
    curve = continue_fold(params, "nonlinear", "E2", [1.0, 1.1])
    assert curve.complete
    assert curve.moment[-1] == pytest.approx(independent_fold(params.replace(E2=1.1), "nonlinear"), abs=FOLD_AGREEMENT)
