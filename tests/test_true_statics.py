"""Statics that answer with the state a slowly loaded chain reaches, or say why not (issue 45, items 1, 2, 3 and 6)."""

from __future__ import annotations

import math
import pickle

import numpy as np
import pytest

from conftest import random_geometries
from cosserat_chain import ChainParams, moment_load
from cosserat_chain.numerics.continuation import continue_in_moment
from cosserat_chain.numerics.newton import BranchEndError, Equilibrium, solve_equilibrium

#: Agreement of two solves of one static state, relative to the state's size.
STATE_RTOL = 1e-8


def _stable_point_of_branch(params: ChainParams, model: str) -> tuple[float, np.ndarray]:
    """A point of the continuation's stable branch from rest at 0.8 of its largest moment: (M, x)."""
    branch = continue_in_moment(params, model, max_folds=1, max_points=400)
    stable = np.flatnonzero(branch.stable)
    i = stable[np.argmin(np.abs(branch.moment[stable] - 0.8 * branch.moment[stable].max()))]
    return float(branch.moment[i]), branch.x[i]


@pytest.mark.parametrize("model", ["nonlinear", "sine"])
@pytest.mark.parametrize("n, seed", [(10, 3), (30, 4), (100, 5)])
def test_solve_equilibrium_lands_on_the_continuations_branch_from_rest(n, seed, model):
    params = ChainParams(**{**random_geometries(1, seed=seed)[0].model_dump(), "N": n})
    moment, expected = _stable_point_of_branch(params, model)
    x = solve_equilibrium(params, model, moment_load(moment))
    assert np.max(np.abs(x - expected)) <= STATE_RTOL * max(1.0, np.max(np.abs(expected)))
    assert x.from_rest and x.index == 0 and x.stable


def test_solve_equilibrium_at_n_1000_lands_on_the_branch_from_rest():
    params = ChainParams(**{**random_geometries(1, seed=7)[0].model_dump(), "N": 1000})
    moment, expected = _stable_point_of_branch(params, "nonlinear")
    x = solve_equilibrium(params, "nonlinear", moment_load(moment))
    assert np.max(np.abs(x - expected)) <= STATE_RTOL * max(1.0, np.max(np.abs(expected)))
    assert x.index == 0


def test_the_issues_chain_of_30_is_not_wound():
    """Newton from rest with full steps returned phi_0 = 90.9 rad with 35 negative eigenvalues here."""
    x = solve_equilibrium(ChainParams(N=30), "nonlinear", moment_load(0.1))
    assert x[2, 30] == pytest.approx(0.951, abs=5e-4)
    assert x.index == 0 and x.stable and x.from_rest


def test_sine_state_from_rest_is_the_linear_solve_through_the_sines():
    """Eq. (2) is linear in (u, v, sin phi): the branch from rest is (u, v, sin phi) = M K^-1 e of the linear K."""
    params = ChainParams(N=20, E2=0.7)
    linear = solve_equilibrium(params, "linear", moment_load(1.0))
    moment = 0.6 / np.max(np.abs(linear[2]))  # every particle below pi/2
    x = solve_equilibrium(params, "sine", moment_load(moment))
    assert np.allclose(np.sin(x[2]), moment * linear[2], rtol=0, atol=1e-12)
    assert np.allclose(x[:2], moment * linear[:2], rtol=0, atol=1e-11)


def test_a_load_beyond_the_fold_is_refused_at_the_fold():
    params = ChainParams()
    fold = continue_in_moment(params, "nonlinear", max_folds=1).folds[0]
    with pytest.raises(BranchEndError, match="branch from rest") as caught:
        solve_equilibrium(params, "nonlinear", moment_load(2 * fold.moment))
    assert 2 * fold.moment * caught.value.load_factor == pytest.approx(fold.moment, rel=1e-4)


def test_a_given_start_may_give_an_unstable_state_and_says_so():
    params = ChainParams()
    branch = continue_in_moment(params, "nonlinear", phi0_stop=4.0)
    i = int(np.flatnonzero(~branch.stable)[0]) + 1  # past the fold: an unstable state
    x = solve_equilibrium(params, "nonlinear", moment_load(branch.moment[i]), x0=branch.x[i])
    assert not x.from_rest and x.index == 1 and not x.stable
    assert np.allclose(x, branch.x[i], atol=1e-9)


def test_equilibrium_is_an_array_whose_derived_arrays_are_plain():
    x = solve_equilibrium(ChainParams(), "nonlinear", moment_load(0.05))
    assert isinstance(x, Equilibrium) and x.shape == (3, 7)
    assert type(x + 0.0) is np.ndarray
    assert type(pickle.loads(pickle.dumps(x))) is np.ndarray
    assert x.dynamic is None  # a conservative model: K's verdict is the dynamics'
    assert math.isfinite(x.stability.critical_eigenvalue)
