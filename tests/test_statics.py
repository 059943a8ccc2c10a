"""Direct statics: Newton under load and rotation control, continuation, folds, compliance, stability."""

from __future__ import annotations

import math

import numpy as np
import pytest
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from conftest import ROUND_OFF, random_geometries
from cosserat_chain import ChainParams, moment_load
from cosserat_chain.experiments.critical import critical_point
from cosserat_chain.io import read_dataset, write_dataset
from cosserat_chain.models.base import get_model
from cosserat_chain.models.linear import stiffness_matrix
from cosserat_chain.numerics.continuation import STEP, compliance, continue_in_moment, locate_fold, moment_slope, rotation_branch
from cosserat_chain.numerics.newton import moment_dof, solve_equilibrium, solve_rotation_controlled
from cosserat_chain.numerics.relaxation import relax
from cosserat_chain.numerics.stability import static_stability
from cosserat_chain.state import n_free, unpack
from static_onsets import TWO_MAXIMA, nonlinear_critical

#: M_c must be located to this relative accuracy (the issue asks for 1e-10).
FOLD_RTOL = 1e-10
ROTATING_MODELS = ["nonlinear", "sine"]


def linear_rotation_response(params: ChainParams, particle: int = 0) -> np.ndarray:
    """(u, v, phi) of every particle for a unit moment on ``particle``: K^-1 e (linear statics)."""
    e = np.zeros(n_free(params))
    e[moment_dof(params, particle)] = 1.0
    return unpack(params, spla.spsolve(stiffness_matrix(params).tocsc(), e))


@pytest.mark.parametrize("params", [ChainParams(), *random_geometries(4, seed=3)], ids=lambda p: f"N{p.N}_a{p.a:.2f}")
def test_sine_critical_moment_is_inverse_largest_linear_rotation_compliance(params):
    # The sine model's statics are the linear ones in (u, v, sin phi): sin phi_k = c_k M,
    # so the branch ends where the largest |c_k| makes |sin phi_k| = 1.
    if params.E2 == 0:
        pytest.skip("without diagonal links the rotations do not couple")
    rotations = linear_rotation_response(params)[2]
    fold = locate_fold(params, "sine")
    assert fold.moment == pytest.approx(1.0 / np.max(np.abs(rotations)), rel=FOLD_RTOL)
    assert fold.phi0 == pytest.approx(math.pi / 2, rel=FOLD_RTOL)


def test_linear_branch_is_a_straight_line_with_the_compliance_as_slope_and_no_fold(paper):
    c = linear_rotation_response(paper)[2, paper.N]
    branch = continue_in_moment(paper, "linear", phi0_stop=2 * math.pi)
    assert compliance(paper, "linear") == pytest.approx(c, rel=ROUND_OFF)
    np.testing.assert_allclose(branch.phi0[1:] / branch.moment[1:], c, rtol=1e-10)
    assert branch.phi0[-1] >= 2 * math.pi
    assert branch.folds == [] and branch.stable.all()
    assert locate_fold(paper, "linear") is None


def test_every_model_has_the_linear_compliance_at_rest(paper):
    values = [compliance(paper, model) for model in ("nonlinear", "sine", "linear")]
    np.testing.assert_allclose(values, values[2], rtol=ROUND_OFF)


def test_nonlinear_branch_slope_at_zero_is_the_linear_compliance_with_cubic_error(paper):
    # M(phi_0) is odd (mirror symmetry), so phi_0 / M - c = O(phi_0^2): halving phi_0 divides the error by 4.
    c = compliance(paper, "linear")
    errors = []
    for angle in (0.02, 0.01, 0.005):
        _, moment = solve_rotation_controlled(paper, "nonlinear", angle)
        errors.append(abs(angle / moment - c))
    orders = np.log2(np.array(errors[:-1]) / np.array(errors[1:]))
    np.testing.assert_allclose(orders, 2.0, atol=0.05)


@pytest.mark.parametrize("model", ROTATING_MODELS)
def test_rotation_control_agrees_with_load_control_below_the_fold(paper, model):
    for angle in (0.3, 0.8):
        x_rot, moment = solve_rotation_controlled(paper, model, angle)
        x_load = solve_equilibrium(paper, model, moment_load(moment))
        np.testing.assert_allclose(x_load, x_rot, atol=1e-10)


@pytest.mark.parametrize("model", ROTATING_MODELS)
def test_fold_is_the_maximum_of_the_characteristic_where_K_is_singular(paper, model):
    fold = locate_fold(paper, model)
    branch = rotation_branch(paper, model, np.linspace(0.0, math.pi, 181))
    assert np.all(branch.moment <= fold.moment * (1 + ROUND_OFF))
    assert abs(moment_slope(paper, model, fold.x)) < 1e-12
    # Independent check: K has a zero eigenvalue at the fold and not at nearby states.
    assert abs(static_stability(paper, model, fold.x).critical_eigenvalue) < 1e-9
    near, _ = solve_rotation_controlled(paper, model, fold.phi0 - 0.05, x0=fold.x, moment0=fold.moment)
    assert static_stability(paper, model, near).critical_eigenvalue > 1e-4


@pytest.mark.parametrize("model", ROTATING_MODELS)
def test_continuation_passes_the_folds_and_agrees_with_rotation_control(paper, model):
    branch = continue_in_moment(paper, model, phi0_stop=2 * math.pi)
    fold = locate_fold(paper, model)
    # A full turn passes a maximum and a minimum of M; by the symmetry phi -> phi + pi of the
    # rectangle and M -> -M they are +-M_c.
    assert len(branch.folds) == 2
    assert branch.folds[0].moment == pytest.approx(fold.moment, rel=FOLD_RTOL)
    assert branch.folds[1].moment == pytest.approx(-fold.moment, rel=FOLD_RTOL)
    # Every continuation point lies on the rotation-controlled characteristic.
    for i in range(0, len(branch.moment), 7):
        _, moment = solve_rotation_controlled(paper, model, branch.phi0[i], x0=branch.x[i], moment0=branch.moment[i])
        assert moment == pytest.approx(branch.moment[i], abs=1e-10)


@pytest.mark.parametrize("model", ROTATING_MODELS)
def test_branch_is_stable_up_to_the_fold_and_unstable_after(paper, model):
    branch = continue_in_moment(paper, model, phi0_stop=2 * math.pi)
    first, second = branch.folds
    before = branch.phi0 < first.phi0 - 1e-3
    between = (branch.phi0 > first.phi0 + 1e-3) & (branch.phi0 < second.phi0 - 1e-3)
    assert branch.stable[before].all() and before.sum() > 3
    assert not branch.stable[between].any() and between.sum() > 3


@pytest.mark.parametrize("model", ROTATING_MODELS)
def test_critical_eigenvalue_vanishes_like_sqrt_of_distance_to_the_fold(paper, model):
    fold = locate_fold(paper, model)
    distances, eigenvalues = [], []
    for offset in (4e-2, 2e-2, 1e-2, 5e-3):
        x, moment = solve_rotation_controlled(paper, model, fold.phi0 - offset, x0=fold.x, moment0=fold.moment)
        distances.append(fold.moment - moment)
        eigenvalues.append(static_stability(paper, model, x).critical_eigenvalue)
    slope = np.polyfit(np.log(distances), np.log(eigenvalues), 1)[0]
    assert slope == pytest.approx(0.5, abs=0.02)


def test_sine_model_stability_uses_the_damped_dynamics(paper):
    # Below the fold the damped linearisation decays; beyond it one real eigenvalue is positive.
    below, _ = solve_rotation_controlled(paper, "sine", 1.0)
    beyond, _ = solve_rotation_controlled(paper, "sine", 2.0)
    assert static_stability(paper, "sine", below, dense=True).spectral_abscissa < 0
    assert static_stability(paper, "sine", beyond, dense=True).spectral_abscissa > 0
    assert not static_stability(paper, "sine", beyond).stable and static_stability(paper, "sine", below).stable


def test_critical_point_result_round_trips_to_a_dataset(paper, tmp_path):
    result = nonlinear_critical(paper)
    ds = read_dataset(write_dataset(result.to_dataset(), tmp_path / "critical.nc"))
    assert float(ds.M_c) == result.critical_moment
    assert ds.attrs["model"] == "nonlinear" and "params_json" in ds.attrs
    np.testing.assert_array_equal(ds.phi0.values, result.branch.phi0)
    summary = result.as_dict()
    assert summary["compliance"] == pytest.approx(compliance(paper, "linear"), rel=ROUND_OFF)
    assert critical_point(paper, "linear").as_dict()["M_c"] is None


def test_statics_reject_a_clamped_loaded_particle(paper):
    with pytest.raises(ValueError, match=r"is held fixed by the right end \(clamped\)"):
        solve_rotation_controlled(paper, "nonlinear", 0.1, particle=paper.N)
    with pytest.raises(ValueError, match="min_step <= step <= max_step"):
        continue_in_moment(paper, "linear", step=-1.0)


@pytest.mark.parametrize("model", ["nonlinear", "sine", "linear"])
@pytest.mark.parametrize("N", [1, 2, 5, 20])
def test_banded_stability_equals_the_dense_reference_on_random_chains(N, model):
    rng = np.random.default_rng(N)
    for _ in range(3):
        params = ChainParams(N=N, a=rng.uniform(0.1, 0.45), b=rng.uniform(0.05, 0.5), E1=rng.uniform(0.3, 3), E2=rng.uniform(0.3, 3))
        # K(x) is the stiffness at any state, equilibrium or not: rotated states of
        # growing angle give definite and indefinite ones (for eq. (2): angles beyond pi/2).
        for angle in (0.1, 1.0, 2.5):
            x = np.zeros((3, params.n_particles))
            x[:, 1:-1] = angle * rng.uniform(-1, 1, (3, params.n_particles - 2)) * np.array([[0.1], [0.1], [1.0]])
            dense = static_stability(params, model, x, dense=True)
            banded = static_stability(params, model, x)
            assert banded.stable == dense.stable
            assert banded.critical_eigenvalue == pytest.approx(dense.critical_eigenvalue, rel=1e-9, abs=1e-12)


def test_rotation_controlled_newton_reaches_the_round_off_floor_of_a_long_chain():
    from cosserat_chain.models.base import get_model
    from cosserat_chain.numerics.newton import round_off_floor
    from cosserat_chain.state import pack

    # An absolute 1e-14 is below the round-off of these forces: the floor is what can be asked.
    params = ChainParams(N=1000)
    x, moment = solve_rotation_controlled(params, "nonlinear", 1.0, tol=1e-14)
    model = get_model("nonlinear")
    residual = pack(params, model.forces(params, x))
    residual[3 * (params.N - 1) + 2] += moment
    floor = round_off_floor(model.stiffness(params, x), x)
    assert 1e-14 < floor < 1e-10 and np.max(np.abs(residual)) <= floor


@pytest.mark.slow
def test_the_long_turn_takes_the_same_path_whatever_the_steps():
    # N = 1000 passes 40 folds over the turn. Its corrector once jumped by 1.2 with a step of
    # 0.19 (a correction within a tenth of the state's size was allowed) onto a closed loop
    # of the branch, went round it twice and left it where round-off decided: the folds
    # after the jump changed with the steps. A jump is now a correction beyond the step and
    # beyond JUMP of the state's size, and the default steps and steps 0.8 as long pass the same folds.
    from cosserat_chain.numerics.continuation import MAX_STEP_FACTOR

    params = ChainParams(N=1000)
    default = STEP * math.sqrt(n_free(params) / 15)
    branches = [continue_in_moment(params, "nonlinear", step=f * default, max_step=f * MAX_STEP_FACTOR * default) for f in (1.0, 0.8)]
    assert all(b.complete for b in branches) and len(branches[0].folds) == len(branches[1].folds) >= 40
    # K's condition number is 5e12 here: most folds agree to 1e-12, the worst to 2e-9 (M) and 5e-9 (phi_0).
    for one, other in zip(*(b.folds for b in branches)):
        assert one.maximum == other.maximum and one.moment == pytest.approx(other.moment, rel=2e-8)
        assert one.phi0 == pytest.approx(other.phi0, abs=1e-7)
    states = np.array([f.x.ravel() for f in branches[0].folds])
    apart = np.max(np.abs(states[:, None] - states[None]), axis=2) + np.eye(len(states))
    assert apart.min() > 1e-3  # no fold passed twice: no loop gone round again


def test_a_branch_with_two_maxima_reports_both_with_the_stability_between():
    # The example: a small maximum of M near phi_0 = 1.0003, a minimum just after
    # it, and the largest maximum near 2.04. The chain snaps through at the first and
    # rotates only above the largest.
    params = TWO_MAXIMA
    result = nonlinear_critical(params)
    first, minimum, largest = result.branch.folds[:3]
    assert (first.maximum, minimum.maximum, largest.maximum) == (True, False, True)
    assert first.phi0 == pytest.approx(1.0003, abs=1e-3) and largest.phi0 == pytest.approx(2.04, abs=0.01)
    assert minimum.moment < first.moment < largest.moment
    assert result.first_fold is first and result.fold is largest and result.critical_moment == largest.moment
    summary = result.as_dict()
    assert summary["snap_through"] and summary["first_fold"] == {"moment": first.moment, "phi0": first.phi0}
    # Stable from rest to the first maximum, unstable between it and the minimum, stable
    # again up to the largest maximum.
    branch = result.branch
    along = np.arange(branch.moment.size)
    for lo, hi, stable in ((0.0, first.phi0, True), (first.phi0, minimum.phi0, False), (minimum.phi0, largest.phi0, True)):
        inside = (branch.phi0 > lo + 1e-6) & (branch.phi0 < hi - 1e-6) & (along < np.argmax(branch.phi0 > largest.phi0))
        assert inside.any() and np.all(branch.stable[inside] == stable), (lo, hi)
    # Each fold, located along the arclength, is the root of dM/dphi_0 that locate_fold finds.
    for fold in (first, minimum, largest):
        alone = locate_fold(params, "nonlinear", bracket=(fold.phi0 - 2e-3, fold.phi0 + 2e-3), seed=(fold.x, fold.moment))
        assert alone.moment == pytest.approx(fold.moment, abs=1e-10) and alone.phi0 == pytest.approx(fold.phi0, abs=1e-8)


@pytest.mark.parametrize("N", [20, 60])
def test_critical_on_a_longer_chain_finds_the_sine_fold_and_agrees_with_locate_fold(N):
    # No tolerance tuned by hand: the round-off floor lets Newton converge where an
    # absolute 1e-14 could not (from N of about 20), and the banded stability keeps it O(N).
    params = ChainParams(N=N)
    sine = critical_point(params, "sine")
    rotations = linear_rotation_response(params)[2]
    assert sine.critical_moment == pytest.approx(1.0 / np.max(np.abs(rotations)), rel=1e-10)
    assert sine.phi0_at_fold == pytest.approx(math.pi / 2, rel=1e-10)
    if N == 20:
        nonlinear = critical_point(params, "nonlinear")
        fold = nonlinear.fold
        alone = locate_fold(params, "nonlinear", bracket=(fold.phi0 - 1e-2, fold.phi0 + 1e-2), seed=(fold.x, fold.moment))
        assert alone.moment == pytest.approx(fold.moment, abs=1e-10) and alone.phi0 == pytest.approx(fold.phi0, abs=1e-8)
        # On this chain the first fold is the onset of rotation: no snap-through.
        assert nonlinear.first_fold is fold and not nonlinear.as_dict()["snap_through"]


def test_locate_fold_finds_the_fold_of_a_chain_whose_branch_turns_back_in_phi0():
    # N = 50: after its first fold the branch turns back in phi_0, and a scan in phi_0
    # found no sign change of dM/dphi_0 (it returned None). The continuation's fold equals
    # the root of dM/dphi_0 on the rotation-controlled branch.
    params = ChainParams(N=50)
    fold = locate_fold(params, "nonlinear")
    assert fold is not None and fold.maximum
    alone = locate_fold(params, "nonlinear", bracket=(fold.phi0 - 1e-2, fold.phi0 + 1e-2), seed=(fold.x, fold.moment))
    assert alone.moment == pytest.approx(fold.moment, abs=1e-10) and alone.phi0 == pytest.approx(fold.phi0, abs=1e-8)
    assert abs(static_stability(params, "nonlinear", fold.x).critical_eigenvalue) < 1e-9  # K is singular there


@pytest.mark.parametrize(
    "params", random_geometries(6, seed=12) + [ChainParams(N=10, a=0.3, b=0.1, E1=2.0, E2=0.3)], ids=lambda p: f"N{p.N}_a{p.a:.2f}"
)
def test_adaptive_steps_find_the_folds_that_short_fixed_steps_find(params):
    # The step grows where the branch is straight; it must not pass a fold that steps
    # a quarter of the default long, never growing, find (the last chain has a pair of
    # folds within 0.015 rad of phi_0).
    adaptive = continue_in_moment(params, "nonlinear", phi0_stop=math.pi)
    short = STEP * math.sqrt(n_free(params) / 15) / 4
    fine = continue_in_moment(params, "nonlinear", phi0_stop=math.pi, step=short, max_step=short, max_points=20000)
    assert adaptive.stop == fine.stop and adaptive.stop in ("phi0_stop", "step_too_small")
    if adaptive.stop == "step_too_small":
        # One of these chains (N = 4, a = 0.21) reaches a state where a diagonal link's
        # length vanishes: the energy (1) has a cone there and the branch no smooth
        # continuation. Before the corrector refused jumps it leapt 1.6 across it onto
        # an earlier part of the branch and came back to rest. The traced part is kept.
        for branch in (adaptive, fine):
            assert not branch.complete and "not smooth" in branch.message
            assert _shortest_link(params, branch.x[-1]) < 1e-3 < _shortest_link(params, branch.x[0])
        chords = np.linalg.norm(np.diff(adaptive.x.reshape(adaptive.moment.size, -1), axis=0), axis=1)
        assert np.max(chords) < 0.5
    assert [f.maximum for f in adaptive.folds] == [f.maximum for f in fine.folds]
    for a, f in zip(adaptive.folds, fine.folds, strict=True):
        assert a.moment == pytest.approx(f.moment, abs=1e-10) and a.phi0 == pytest.approx(f.phi0, abs=1e-7)
    assert adaptive.moment.size < fine.moment.size


def _shortest_link(params: ChainParams, x: np.ndarray) -> float:
    from cosserat_chain.geometry import bond_links, particle_positions, rotate

    centre = np.stack([particle_positions(params) + x[0], x[1]])
    lengths = []
    for link in bond_links(params):
        r0, r1 = np.stack(rotate(link.left_corner, x[2, :-1])), np.stack(rotate(link.right_corner, x[2, 1:]))
        lengths.append(np.hypot(*(centre[:, 1:] + r1 - centre[:, :-1] - r0)).min())
    return float(min(lengths))


def test_a_branch_cut_short_by_its_point_budget_says_so(paper):
    branch = continue_in_moment(paper, "nonlinear", max_points=10)
    assert branch.stop == "max_points" and not branch.complete and branch.moment.size == 10
    assert continue_in_moment(paper, "nonlinear", max_folds=1).stop == "max_folds"
    result = critical_point(paper, "sine", max_points=10)
    assert not result.complete and result.as_dict()["branch_complete"] is False
    # A long step passes M = 0 at phi_0 = pi (the sine model's forces vanish there): that
    # is not the rest state, and the turn goes on to its minimum of M at 3 pi / 2.
    long = critical_point(ChainParams(N=100), "sine")
    assert long.branch.stop == "phi0_stop" and [f.maximum for f in long.branch.folds] == [True, False]
    assert long.branch.folds[1].phi0 == pytest.approx(3 * math.pi / 2, rel=1e-9)


@pytest.mark.parametrize("model", ROTATING_MODELS)
def test_the_stability_guess_changes_the_cost_not_the_result(model):
    rng = np.random.default_rng(7)
    for N in (2, 20, 200):
        params = ChainParams(N=N, a=rng.uniform(0.1, 0.45), b=rng.uniform(0.05, 0.5), E1=rng.uniform(0.3, 3), E2=rng.uniform(0.3, 3))
        for angle in (0.3, 2.0):
            x = np.zeros((3, params.n_particles))
            x[:, 1:-1] = angle * rng.uniform(-1, 1, (3, params.n_particles - 2)) * np.array([[0.1], [0.1], [1.0]])
            plain = static_stability(params, model, x)
            for guess in (plain.critical_eigenvalue * 1.3, -plain.critical_eigenvalue, 0.0, 5.0):
                guided = static_stability(params, model, x, guess=guess)
                assert guided.index == plain.index and guided.stable == plain.stable
                assert guided.critical_eigenvalue == pytest.approx(plain.critical_eigenvalue, rel=1e-9, abs=1e-12)


def test_the_bordered_and_rotation_controlled_jacobians_and_the_bordered_solve_equal_their_dense_definitions():
    from cosserat_chain.linalg import bordered_jacobian, bordered_solve, rotation_controlled_jacobian
    from cosserat_chain.models.base import get_model

    rng = np.random.default_rng(3)
    for params in (ChainParams(N=1), ChainParams(N=2), *random_geometries(3, seed=9)):
        x = np.zeros((3, params.n_particles))
        x[:, 1:-1] = rng.normal(size=(3, params.n_particles - 2))
        for model in ("nonlinear", "sine"):
            stiffness = get_model(model).stiffness(params, x)
            n = stiffness.shape[0]
            for dof in {0, n // 2, n - 1}:
                row = rng.normal(size=n + 1)
                dense = np.zeros((n + 1, n + 1))
                dense[:n, :n] = -stiffness.toarray()
                dense[dof, n] = 1.0
                dense[n] = row
                assert np.array_equal(bordered_jacobian(stiffness, dof, row).toarray(), dense)
                # The compiled banded elimination solves the same system as a dense LU.
                rhs = rng.normal(size=n + 1)
                exact = np.linalg.solve(dense, rhs)
                bound = 1e3 * np.finfo(float).eps * np.linalg.cond(dense) * np.max(np.abs(exact))
                assert np.max(np.abs(bordered_solve(stiffness, dof, row, rhs) - exact)) <= bound
                replaced = -stiffness.toarray()
                replaced[:, dof] = 0.0
                replaced[dof, dof] = 1.0
                assert np.array_equal(rotation_controlled_jacobian(stiffness, dof).toarray(), replaced)


def test_a_snap_through_names_the_stable_state_that_the_damped_chain_reaches():
    params = TWO_MAXIMA
    result = nonlinear_critical(params)
    first, target = result.first_fold, result.snap_to
    assert target is not None and target.moment == first.moment
    minimum = result.branch.folds[1]
    # Beyond the minimum of M, on the stable segment up to the largest maximum, holding the first fold's moment.
    assert minimum.phi0 < target.phi0 < result.fold.phi0 and static_stability(params, "nonlinear", target.x).stable
    residual = get_model("nonlinear").forces(params, target.x)
    residual[2, params.N] += first.moment
    assert np.max(np.abs(residual[:, 1:-1])) < 1e-10
    # The damped dynamics pushed just past the fold come to rest there (M a little above
    # the fold's: at the fold itself the drift away is too slow to finish).
    # The branch is steep in phi_0 there, so compare with its state at the pushed moment.
    pushed = first.moment * (1 + 1e-5)
    step = relax(params, "nonlinear", pushed, x0=first.x)
    nearby = solve_equilibrium(params, "nonlinear", moment_load(pushed), x0=target.x)
    assert step.status == "static" and np.max(np.abs(step.x - nearby)) < 1e-6
    assert abs(nearby[2, params.N] - target.phi0) < 0.01 < target.phi0 - first.phi0
    assert result.as_dict()["snap_to"] == {"moment": target.moment, "phi0": target.phi0}
    assert nonlinear_critical(ChainParams()).snap_to is None  # the paper's chain: no snap-through


def test_the_first_folds_of_a_thousand_particle_pairs_chain_need_no_tuned_tolerance():
    # N = 1000 (2001 particles), default settings: the sine fold is 1/(largest linear
    # rotation compliance) at phi_0 = pi/2, the nonlinear one the root of dM/dphi_0 that
    # locate_fold finds in a bracket around it.
    params = ChainParams(N=1000)
    sine = continue_in_moment(params, "sine", max_folds=1)
    rotations = linear_rotation_response(params)[2]
    # Both sides rest on solves with K, whose condition number is 5e12 here: two independent
    # factorisations of it agree to 1.5e-7 (docs/continuum.md), so that is what can be asked.
    assert sine.stop == "max_folds" and sine.folds[0].moment == pytest.approx(1.0 / np.max(np.abs(rotations)), rel=1e-6)
    assert sine.folds[0].phi0 == pytest.approx(math.pi / 2, rel=1e-10)
    nonlinear = continue_in_moment(params, "nonlinear", max_folds=1).folds[0]
    alone = locate_fold(params, "nonlinear", bracket=(nonlinear.phi0 - 1e-3, nonlinear.phi0 + 1e-3), seed=(nonlinear.x, nonlinear.moment))
    assert nonlinear.maximum and alone.moment == pytest.approx(nonlinear.moment, rel=FOLD_RTOL)


def test_the_bordered_solve_falls_back_to_pivoting_at_a_zero_pivot():
    from cosserat_chain.linalg import bordered_solve

    # A zero pivot in the natural order (no pivoting) falls back to SuperLU's pivoting.
    singular_start = sp.csr_matrix(np.array([[0.0, 1.0, 0.0], [1.0, 0.0, 1.0], [0.0, 1.0, 2.0]]))
    row, rhs = np.array([1.0, 2.0, 3.0, 4.0]), np.array([1.0, -1.0, 2.0, 0.5])
    dense = np.zeros((4, 4))
    dense[:3, :3] = -singular_start.toarray()
    dense[0, 3] = 1.0
    dense[3] = row
    assert np.allclose(bordered_solve(singular_start, 0, row, rhs), np.linalg.solve(dense, rhs), rtol=1e-12, atol=1e-12)


def test_a_chord_through_rest_is_told_from_one_through_a_half_turn():
    from cosserat_chain.numerics.continuation import _passes_rest

    params = ChainParams(N=2)
    before, after = np.zeros((3, params.n_particles)), np.zeros((3, params.n_particles))
    before[:, 1:-1], after[:, 1:-1] = 0.01, -0.01  # M from +1 to -1 through rest
    assert _passes_rest(before, after, 1.0, -1.0)
    assert not _passes_rest(before, after + 0.05, 1.0, -1.0)  # passes beside it
    # A long chord from phi_0 = -0.2 to 6.5 crosses M = 0 at phi_0 = 3.15, within half its
    # length of rest but with the loaded particle half a turn round (the sine model's
    # forces vanish at phi = pi): not the rest state.
    before, after = np.zeros((3, params.n_particles)), np.zeros((3, params.n_particles))
    before[2, params.N], after[2, params.N] = -0.2, 6.5
    assert np.linalg.norm(0.5 * (before + after)) <= 0.5 * np.linalg.norm(after - before)
    assert not _passes_rest(before, after, 0.3, -0.3)


def test_statics_figures_plot_the_dimensionless_moment_M_over_E1_h2():
    """Fig. 2 for a chain with E1 = 2 and h = 1.5: the fold sits at M_c / (E1 h^2) on an axis that says so."""
    import matplotlib

    matplotlib.use("Agg")
    from cosserat_chain.plots.statics import critical_against_length, figure2

    chain = ChainParams(E1=2.0, h=1.5, a=0.3, b=0.3)
    result = critical_point(chain, "sine")
    assert result.as_dict()["M_c_dimensionless"] == pytest.approx(result.critical_moment / (2.0 * 1.5**2), rel=1e-15)
    left, right = figure2({"sine": result}).axes
    assert "E_1 h^2" in left.get_xlabel() and "E_1 h^2" in right.get_ylabel()
    fold = result.fold
    markers = [line for line in right.lines if line.get_marker() == "o"]
    assert any(np.isclose(line.get_ydata()[0], fold.moment / chain.moment_scale, rtol=1e-12) for line in markers)
    (moment_axis, _) = critical_against_length({"sine": [result]}).axes
    assert moment_axis.lines[0].get_ydata()[0] == pytest.approx(chain.N * result.critical_moment / chain.moment_scale)


def test_a_continuation_point_assembles_the_stiffness_once_per_solve_and_counts_the_index_only_when_unstable(monkeypatch):
    # The O(N) cost of a point is a fixed number of banded passes: one assembly of K per
    # converged point (whose tangent and stability reuse it) and per Newton iteration that
    # factors anew, one banded factor each (the chord iterations reuse the last one), and
    # the inertia count at zero only where the smallest eigenvalue is not certified
    # positive (its own factor otherwise comes free with the eigenvalue). An assembly is
    # either storage of K (CSR or band): each is counted.
    from cosserat_chain.models.base import Model
    from cosserat_chain.models.nonlinear import NonlinearModel
    from cosserat_chain.numerics import continuation, stability

    calls = {"stiffness": 0, "similar": 0, "solve": 0, "count": 0}

    def counted(name, function):
        def wrapper(*args, **kwargs):
            calls[name] += 1
            return function(*args, **kwargs)

        return wrapper

    monkeypatch.setattr(NonlinearModel, "stiffness", counted("stiffness", NonlinearModel.stiffness))
    monkeypatch.setattr(NonlinearModel, "stiffness_band", counted("stiffness", NonlinearModel.stiffness_band))
    monkeypatch.setattr(Model, "symmetric_similar_band", counted("similar", Model.symmetric_similar_band))
    monkeypatch.setattr(continuation, "BorderedFactor", counted("solve", continuation.BorderedFactor))
    monkeypatch.setattr(stability, "negative_count", counted("count", stability.negative_count))
    brentq = continuation.brentq

    def counted_search(function, *args, **kwargs):
        return brentq(counted("located", function), *args, **kwargs)

    calls["located"] = 0
    monkeypatch.setattr(continuation, "brentq", counted_search)
    model = get_model("nonlinear")
    for params in (ChainParams(N=10), ChainParams(N=100)):
        calls.update(dict.fromkeys(calls, 0))
        branch = continue_in_moment(params, model, max_folds=1)
        points = branch.moment.size
        # The rest state's stability assembles its own (no corrector ran there), and so does the
        # response at rest that sizes the largest step; nothing else does.
        assert calls["similar"] == 1 and calls["stiffness"] <= calls["solve"] + 2
        assert calls["solve"] <= 8 * points  # a few Newton iterations and the tangent a point
        # The chord iterations assemble nothing; locating the fold is a full Newton solve (a few
        # assemblies) and a tangent at each point of its search.
        assert calls["stiffness"] <= 3 * points + 8 * calls["located"]
        # Unstable states only: the traced ones, and the ends of steps from a stable point
        # across the fold or a crossing, retaken shorter (each halved, from the longest step
        # down to refine_step, 2e-4; twice: the falling eigenvalue's and the crossing's).
        longest = continuation.largest_step(params, model, 0)
        halvings = int(np.ceil(np.log2(longest / 2e-4)))
        assert calls["count"] <= np.count_nonzero(~branch.stable) + 2 + 2 * halvings, calls
        assert branch.folds and branch.folds[0].maximum


def test_an_eigenvalue_within_its_round_off_keeps_the_decided_stability_along_a_branch():
    # A clamped-free chain of N = 1000: its free arm's softest eigenvalue (N^-4, 6e-14) lies
    # below the resolution of the critical eigenvalue (1.4e-13) and comes out at -6e-15 at
    # some points. Its sign is noise: the branch keeps the stability decided at rest.
    params = ChainParams(N=1000, left_end="clamped", right_end="free")
    branch = continue_in_moment(params, "nonlinear", max_points=60)
    resolution = static_stability(params, "nonlinear", branch.x[0]).resolution
    assert np.all(np.abs(branch.critical_eigenvalue) <= resolution)
    assert np.any(branch.critical_eigenvalue < 0)  # the noise the rule is for
    assert branch.stable.all() and not branch.branch_points


def test_a_matrix_wider_than_the_chains_band_is_refused_by_the_band_kernels_and_solved_without_them():
    # The compiled band kernels take the chain's half-bandwidth (5) as a constant: a wider
    # matrix (a ring's corner blocks) is no band for them. The stability's lower band says so by
    # name; the bordered factor falls back to the sparse solve and still solves it exactly.
    from cosserat_chain.linalg import BANDWIDTH, BorderedFactor, band_storage, bordered_jacobian

    rng = np.random.default_rng(3)
    n = 20
    wide = sp.diags(
        [np.full(n, 10.0), np.full(n - BANDWIDTH - 1, 0.5), np.full(n - BANDWIDTH - 1, 0.5)], [0, BANDWIDTH + 1, -BANDWIDTH - 1]
    ).tocsr()
    for matrix in (wide, wide.toarray()):
        with pytest.raises(ValueError, match=f"half-bandwidth {BANDWIDTH + 1}, more than the chain's {BANDWIDTH}"):
            band_storage(matrix)
    row, rhs = rng.standard_normal(n + 1), rng.standard_normal(n + 1)
    solution = BorderedFactor(wide, 4).solve(row, rhs)
    assert np.max(np.abs(bordered_jacobian(wide, 4, row) @ solution - rhs)) < 1e-12
    banded = sp.diags([np.full(n, 10.0), np.full(n - BANDWIDTH, 0.5), np.full(n - BANDWIDTH, 0.5)], [0, BANDWIDTH, -BANDWIDTH]).tocsr()
    assert BorderedFactor(banded, 4)._ok and not BorderedFactor(wide, 4)._ok


@pytest.mark.parametrize(
    "chain",
    [
        dict(N=20, right_end="pinned"),  # the paper's geometry, clamped-pinned
        dict(N=25, a=0.10518722914678214, b=0.3652158378015968, E1=2.109973577076706, E2=1.5859087091011652, left_end="pinned"),
    ],
)
def test_a_turn_of_m_without_one_crossing_is_refined_and_the_turn_is_mirror_symmetric(chain):
    # Each chain once took a step across a fold of M with the same index at both ends
    # (N = 20: 1 and 1 across a minimum where short steps find 1 before it and 2 after):
    # the fold's corrector found no point between them and critical raised NewtonError. A
    # turn of M without exactly one crossing now refines the step like a crossing
    # without a turn, and the index changes by one at every fold. Mirrored about the chain's axis (v, phi -> -v, -phi) the
    # branch maps onto itself with M -> -M and phi_0 -> 2 pi - phi_0 (angles mod 2 pi): the
    # folds of the second half of the turn, traced and located on their own, are those of
    # the first half mirrored.
    result = critical_point(ChainParams(**chain), "nonlinear")
    branch = result.branch
    assert result.complete and branch.stop == "phi0_stop"
    folds = np.array([(f.moment, f.phi0) for f in branch.folds])
    assert len(folds) >= 8 and len(folds) % 2 == 0
    mirrored = np.column_stack([-folds[:, 0], 2 * math.pi - folds[:, 1]])
    distance = np.max(np.abs(folds[:, None, :] - mirrored[None, :, :]), axis=2)
    assert np.all(distance.min(axis=1) < 1e-8), distance.min(axis=1)
    # Maxima and minima of M alternate along the branch.
    maxima = np.array([f.maximum for f in branch.folds])
    assert np.all(maxima[1:] != maxima[:-1])


@pytest.mark.parametrize("n", [0, 1, 7, 8, 9, 1001])
def test_the_continuations_dot_product_and_norm_agree_with_an_exact_sum(n):
    # Compiled on the calling thread (OpenBLAS's ddot threads long vectors); eight partial
    # sums and a tail: every length modulo 8 and the empty vector.
    import math

    from cosserat_chain.linalg import dot, euclidean_norm

    rng = np.random.default_rng(n)
    a, b = rng.standard_normal(n), rng.standard_normal(n)
    exact = math.fsum(a * b)
    assert abs(dot(a, b) - exact) <= 4 * n * np.finfo(float).eps * np.sum(np.abs(a * b))
    assert euclidean_norm(a) == pytest.approx(math.sqrt(math.fsum(a * a)), rel=1e-14, abs=0.0)
    assert dot(a, a) >= 0.0 and (n > 0 or dot(a, b) == 0.0)


def test_the_largest_step_follows_the_branchs_length_per_radian_so_the_points_do_not_grow_with_N():
    # The sine model's u and v grow like N^2 M: with the largest step capped at 20 first
    # steps, every step of its turn hit the cap (N = 1000: 1015 points, N = 3000: 2782, and
    # N = 10^4 crawled). The cap is the arclength over which phi_0 turns by 2 PHI0_STEP along
    # the tangent at rest (here from a dense solve), so the turn limits size the steps.
    from cosserat_chain.numerics import continuation

    model = get_model("sine")
    params = ChainParams(N=100)
    e = np.zeros(n_free(params))
    e[moment_dof(params, 0)] = 1.0
    response = np.linalg.solve(stiffness_matrix(params).toarray(), e)
    per_radian = np.linalg.norm(response) / response[moment_dof(params, 0)]
    assert continuation.largest_step(params, model, 0) == pytest.approx(2 * continuation.PHI0_STEP * per_radian, rel=1e-10)
    assert continuation.largest_step(ChainParams(), model, 0) == continuation.MAX_STEP_FACTOR * STEP  # short chains: as before
    points = {}
    # Three times the particles: 168 and 200 points (the old cap: 629 and 2955).
    for N in (100, 300):
        params = ChainParams(N=N)
        branch = continue_in_moment(params, model)
        points[N] = branch.moment.size
        assert branch.stop == "phi0_stop"
        assert [f.phi0 for f in branch.folds] == pytest.approx([math.pi / 2, 3 * math.pi / 2], abs=1e-8)
        assert branch.folds[0].moment == pytest.approx(1 / compliance(params, "linear"), rel=1e-8)
    assert points[300] < 1.3 * points[100], points
