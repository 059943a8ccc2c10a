"""Periodic orbits by orthogonal collocation: the scheme's tables, agreement with the shooting, the mesh's
convergence order, an identity the multipliers must satisfy, the continuation to a long period, bad input."""

from __future__ import annotations

import math

import numpy as np
import pytest

from conftest import random_geometries
from cosserat_chain import ChainParams
from cosserat_chain.numerics.collocation import (
    NCOL_RANGE,
    CollocationError,
    check_mesh,
    continue_collocation,
    find_collocation_orbit,
    scheme,
)
from cosserat_chain.numerics.continuation import locate_fold
from cosserat_chain.numerics.periodic import OrbitError, find_periodic_orbit
from cosserat_chain.state import pack, per_dof

#: The N = 1 chain of the issue's long-period case (three particles, the middle one free).
N1 = ChainParams(N=1)
#: A random admissible geometry at N = 2 (the first of conftest's random chains, shortened).
RANDOM2 = random_geometries(1, seed=0)[0].replace(N=2)
#: Shooting tolerances tight enough that its own error stays below the comparison's.
SHOOTING = {"tol": 1e-10, "rtol": 1e-12, "atol": 1e-12}

CASES = [
    pytest.param(N1, "nonlinear", 0.3, id="nonlinear N=1"),
    pytest.param(N1, "sine", 0.5, id="sine N=1"),
    pytest.param(RANDOM2, "sine", 0.8 * RANDOM2.moment_scale, id="sine random N=2"),
]


@pytest.mark.parametrize("ncol", range(NCOL_RANGE[0], NCOL_RANGE[1] + 1))
def test_tables_integrate_and_differentiate_polynomials_of_the_scheme_exactly(ncol):
    sch = scheme(ncol)
    # Gauss-Legendre: exact for degree 2 ncol - 1.
    assert np.sum(sch.weights * sch.points ** (2 * ncol - 1)) == pytest.approx(1.0 / (2 * ncol), rel=1e-13)
    # The Lagrange basis reproduces s^ncol and its derivative at the Gauss points, and its ncol-th derivative.
    assert sch.values @ sch.nodes**ncol == pytest.approx(sch.points**ncol, abs=1e-13)
    assert sch.slopes @ sch.nodes**ncol == pytest.approx(ncol * sch.points ** (ncol - 1), abs=1e-11)
    assert sch.top @ sch.nodes**ncol == pytest.approx(math.factorial(ncol), rel=1e-9)
    assert sch.basis(sch.nodes) == pytest.approx(np.eye(ncol + 1), abs=1e-12)


@pytest.mark.parametrize(("params", "model", "moment"), CASES)
def test_orbit_period_and_multipliers_agree_with_the_shooting(params, model, moment):
    shot = find_periodic_orbit(params, model, moment, **SHOOTING)
    colloc = find_collocation_orbit(params, model, moment, guess=shot)
    assert colloc.period == pytest.approx(shot.period, rel=1e-8)
    assert colloc.trivial_multiplier_error < 1e-8
    # Multipliers carry no labels: compare the sorted moduli and the sorted complex values.
    np.testing.assert_allclose(np.sort(np.abs(colloc.multipliers)), np.sort(np.abs(shot.multipliers)), atol=1e-6)
    orbit = colloc.periodic_orbit()
    assert orbit.phase_normal is None and orbit.x[2, params.N] == 0.0
    np.testing.assert_allclose(orbit.x, shot.x, atol=1e-7)
    np.testing.assert_allclose(orbit.v, shot.v, atol=1e-7)


def test_find_periodic_orbit_by_collocation_from_rest_equals_the_shooting():
    shot = find_periodic_orbit(N1, "nonlinear", 0.3, **SHOOTING)
    colloc = find_periodic_orbit(N1, "nonlinear", 0.3, method="collocation")
    assert colloc.period == pytest.approx(shot.period, rel=1e-8)
    np.testing.assert_allclose(colloc.x, shot.x, atol=1e-7)
    assert colloc.closure < 1e-9 and abs(colloc.trivial_multiplier - 1.0) < 1e-8


def test_period_error_falls_like_h_to_the_power_2_ncol_on_uniform_meshes():
    # Gauss collocation superconverges: h^(2 ncol) at the mesh points and in the period, where a
    # scheme of the polynomials' order alone would give h^(ncol + 1) = h^3.
    reference = find_collocation_orbit(N1, "nonlinear", 0.3, ntst=120, ncol=6)
    errors = [
        abs(find_collocation_orbit(N1, "nonlinear", 0.3, guess=reference, ntst=ntst, ncol=2, adapt=0).period - reference.period)
        for ntst in (16, 32, 64)
    ]
    orders = np.log2(np.array(errors[:-1]) / np.array(errors[1:]))
    assert np.all((orders > 3.6) & (orders < 4.4)), orders


@pytest.mark.parametrize("gamma", [0.1, 1.0])
def test_longitudinal_multipliers_of_the_sine_chain_are_exp_of_minus_half_the_damping_times_the_period(gamma):
    # In eq. (2) u is decoupled, linear and underdamped: its mode gives two multipliers of modulus
    # exp(-gamma_u T / 2m) whatever the rotation does (3e-4 at gamma = 1: no product of the
    # shooting's kind is formed, the pencil gives it to its relative accuracy).
    params = ChainParams(N=1, gamma_u=gamma, gamma_v=gamma, gamma_phi=gamma)
    orbit = find_collocation_orbit(params, "sine", 1.3 * locate_fold(params, "sine").moment)
    expected = math.exp(-gamma * orbit.period / (2 * params.m))
    relative = np.sort(np.abs(np.abs(orbit.multipliers) / expected - 1.0))
    assert relative[1] < 1e-6


@pytest.mark.parametrize(("params", "model", "moment"), [CASES[0], CASES[2]])
def test_product_of_the_multipliers_obeys_liouville(params, model, moment):
    # det(monodromy) = exp(int tr A dt) = exp(-T sum gamma_i / m_i): the damping alone sets the product,
    # down to the strongly damped multipliers (6e-7 on the nonlinear N = 1 orbit) that the trivial one does not test.
    orbit = find_collocation_orbit(params, model, moment)
    rate = np.sum(per_dof(params, params.damping) / pack(params, params.particle_inertia))
    assert np.sum(np.log(np.abs(orbit.multipliers))) == pytest.approx(-orbit.period * rate, rel=1e-7)


@pytest.mark.slow
def test_continuation_follows_the_nonlinear_n1_orbit_to_its_snic_with_the_saddle_node_law():
    # Issue 40: by shooting `orbit --model nonlinear --moment 0.3 --down-to 0.1` on N = 1 ran 30 minutes.
    start = find_collocation_orbit(N1, "nonlinear", 0.3, ntst=80)
    branch = continue_collocation(start, moment_min=0.1, period_max=1000.0)
    assert branch.end == "infinite_period" and branch.period[-1] > 1000.0
    assert np.all(np.diff(branch.moment) < 0) and np.all(np.diff(branch.period) > 0)
    fold = locate_fold(N1, "nonlinear").moment
    assert 0.0 < branch.moment[-1] - fold < 3e-6
    # A saddle-node on the invariant circle: T ~ (M - M_c)^(-1/2) on the last points, so T^-2 is linear
    # in M and vanishes at the static fold, located independently by the statics.
    last = slice(-6, None)
    slope = np.polyfit(np.log(branch.moment[last] - fold), np.log(branch.period[last]), 1)[0]
    assert slope == pytest.approx(-0.5, abs=0.01)
    line = np.polyfit(branch.moment[last], branch.period[last] ** -2.0, 1)
    assert -line[1] / line[0] == pytest.approx(fold, abs=1e-8)
    # Issue 40: the orbit has branch points of cycles (a real multiplier through +1 while M goes on), two pairs,
    # the second pair 5e-4 apart in M; each located with its second multiplier at +1. The shooting's continue_orbit
    # sees the same four, interpolated between its orbits (0.29768, 0.29503, 0.28848, 0.28828).
    points = [event for event in branch.events if event["kind"] == "branch_point"]
    assert [event["located"] for event in points] == [True] * 4
    assert [event["moment"] for event in points] == pytest.approx([0.29768, 0.29503, 0.28848, 0.28828], abs=3e-4)
    for event in points:
        assert np.sort(np.abs(event["orbit"].multipliers - 1.0))[1] < 1e-6
    # A point of period ~100 against the shooting started from it: the period on the branch's mesh; the
    # multipliers (the damped modes over the slow passage) with NCOL = 7 on intervals of a quarter time unit.
    orbit = branch.orbits[int(np.argmin(np.abs(branch.period - 100.0)))]
    shot = find_periodic_orbit(N1, "nonlinear", orbit.moment, guess=orbit.periodic_orbit(), tol=1e-9, rtol=1e-12, atol=1e-12)
    assert orbit.period == pytest.approx(shot.period, rel=1e-7)
    fine = find_collocation_orbit(N1, "nonlinear", orbit.moment, guess=orbit, ntst=400, ncol=7)
    assert fine.period == pytest.approx(shot.period, rel=1e-9)
    np.testing.assert_allclose(np.abs(fine.multipliers[:5]), np.abs(shot.multipliers[:5]), rtol=1e-6)


@pytest.mark.slow
def test_fold_of_cycles_of_the_paper_sine_chain_equals_the_shooting_s(paper_sine_branch):
    # From the shooting's orbit a few points before its fold (the same branch, fewer points to trace).
    near = paper_sine_branch.orbits[-6]
    start = find_collocation_orbit(near.params, "sine", near.moment, guess=near)
    branch = continue_collocation(start, moment_min=0.1)
    assert branch.end == "fold" and paper_sine_branch.end == "fold"
    fold = [event for event in branch.events if event["kind"] == "fold"][-1]
    assert fold["located"] and fold["moment"] == pytest.approx(paper_sine_branch.end_moment, abs=1e-7)
    # The fold's double multiplier at +1: two multipliers near it, the rest well away.
    distance = np.sort(np.abs(fold["orbit"].multipliers - 1.0))
    assert distance[1] < 1e-2 < distance[2]


@pytest.mark.slow
def test_integral_phase_condition_passes_the_sections_false_fold_to_the_real_one():
    # Issue 40 item 1's case: on the N = 2 sine chain at gamma_phi = 0.15 the loaded particle backs up after each
    # turn, and the section phi_0 = 0 gave a false fold at M = 0.18223; the real fold of cycles is at 0.1803666
    # (the augmented shooting system on a phase plane, tests/test_orbit_phase_condition.py).
    chain = ChainParams(N=2, gamma_phi=0.15)
    moment = 1.1 * locate_fold(chain, "sine").moment
    start = find_collocation_orbit(chain, "sine", moment, guess=find_periodic_orbit(chain, "sine", moment))
    branch = continue_collocation(start, moment_min=0.1)
    folds = [event for event in branch.events if event["kind"] == "fold"]
    assert branch.end == "fold" and len(folds) == 1 and folds[0]["located"]
    assert folds[0]["moment"] == pytest.approx(0.1803666, abs=2e-7)
    assert np.all(branch.moment[:-1] > folds[0]["moment"])


@pytest.mark.parametrize(
    ("ntst", "ncol", "match"),
    [(1, 4, "ntst"), (40, 1, "ncol"), (40, 8, "ncol"), (2.5, 4, "ntst"), (40, True, "ncol")],
)
def test_bad_mesh_is_refused_naming_the_field(ntst, ncol, match):
    with pytest.raises(ValueError, match=match):
        check_mesh(ntst, ncol)
    with pytest.raises(ValueError, match=match):
        find_collocation_orbit(N1, "nonlinear", 0.3, ntst=ntst, ncol=ncol)


def test_a_newton_that_does_not_converge_says_what_to_try():
    shot = find_periodic_orbit(N1, "nonlinear", 0.3)
    with pytest.raises(CollocationError, match="did not converge.*raise ntst"):
        find_collocation_orbit(N1, "nonlinear", 0.3, guess=(shot.x, shot.v, 1.3 * shot.period), max_iter=1, adapt=0)
    # Through the shooting's entry point it is the shooting's error.
    with pytest.raises(OrbitError, match="did not converge"):
        find_periodic_orbit(N1, "nonlinear", 0.3, guess=(shot.x, shot.v, 1.3 * shot.period), method="collocation", max_iter=1)


def test_bad_continuation_arguments_are_refused():
    orbit = find_collocation_orbit(N1, "nonlinear", 0.3, ntst=10)
    with pytest.raises(ValueError, match="period_max"):
        continue_collocation(orbit, period_max=1.0)
    with pytest.raises(ValueError, match="remesh_every"):
        continue_collocation(orbit, remesh_every=1)
    with pytest.raises(ValueError, match="moment_min"):
        continue_collocation(orbit, moment_min=0.4, moment_max=0.2)
    with pytest.raises(ValueError, match="adapt"):
        find_collocation_orbit(N1, "nonlinear", 0.3, adapt=-1)
