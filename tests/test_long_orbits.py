"""Orbits of long chains (numerics.long_orbits): the monodromy in column blocks, Newton-Krylov shooting, deflated multipliers."""

from __future__ import annotations

import numpy as np
import pytest

from conftest import random_geometries
from cosserat_chain import ChainParams
from cosserat_chain.models import get_model
from cosserat_chain.numerics import long_orbits
from cosserat_chain.numerics.long_orbits import BLOCKS_FROM_N, Monodromy, blocked_shooting, choose_method, leading_multipliers
from cosserat_chain.numerics.periodic import _shooting, _System, _to_y, continue_orbit, find_periodic_orbit, initial_guess

#: Two shootings of one orbit agree to this (Newton stops at closure 1e-9; the integrations are at 1e-11).
AGREE = 1e-8
#: Central differences of the flow with step 1e-5: truncation ~1e-10, the integration's noise 1e-11 / 1e-5.
FD_PRODUCT_TOL = 1e-5

#: (params, model, moment): the paper's chain, a one-particle-each-side chain, two random geometries (1.3 M_c).
CASES = {
    "paper sine N=3": (ChainParams(), "sine", 0.22),
    "nonlinear N=1": (ChainParams(N=1), "nonlinear", 0.5),
    "random sine N=3": (random_geometries(6, seed=3)[1], "sine", 0.40880890655281255),
    "random nonlinear N=4": (random_geometries(6, seed=3)[4], "nonlinear", 0.7922864567040807),
}


@pytest.fixture(scope="module", params=list(CASES))
def three_shootings(request):
    """The same orbit from the same guess by the dense, the blocked and the Newton-Krylov shooting."""
    params, model, moment = CASES[request.param]
    x, v, period = initial_guess(params, model, moment)
    return {
        method: find_periodic_orbit(params, model, moment, guess=(x, v, period), method=method) for method in ("dense", "blocks", "krylov")
    }


def _nearest(reference: np.ndarray, values: np.ndarray) -> np.ndarray:
    return np.array([np.min(np.abs(reference - mu)) for mu in values])


@pytest.mark.parametrize("method", ["blocks", "krylov"])
def test_blocks_and_krylov_shooting_find_the_dense_shootings_orbit_and_multipliers(three_shootings, method):
    dense, other = three_shootings["dense"], three_shootings[method]
    assert other.period == pytest.approx(dense.period, rel=AGREE)
    assert np.max(np.abs(other.x - dense.x)) < AGREE and np.max(np.abs(other.v - dense.v)) < AGREE
    assert other.closure <= 1e-9
    # Each multiplier is one of the dense monodromy's, and none of those larger than the smallest reported is missing.
    assert np.max(_nearest(dense.multipliers, other.multipliers)) < AGREE
    smallest = np.min(np.abs(other.multipliers))
    assert np.max(_nearest(other.multipliers, dense.multipliers[np.abs(dense.multipliers) > smallest + 1e-6]), initial=0) < AGREE
    assert other.stable == dense.stable


@pytest.mark.parametrize("method", ["blocks", "krylov"])
def test_the_trivial_multiplier_equals_one_within_its_reported_error(three_shootings, method):
    orbit = three_shootings[method]
    assert orbit.multiplier_errors.shape == orbit.multipliers.shape
    assert 0 < orbit.trivial_multiplier_error < 1e-8
    assert abs(orbit.trivial_multiplier - 1.0) <= orbit.trivial_multiplier_error
    assert orbit.as_dict()["trivial_multiplier_error"] == orbit.trivial_multiplier_error
    assert three_shootings["dense"].trivial_multiplier_error is None


class _Matrix:
    """A Monodromy stand-in: products with a known matrix."""

    def __init__(self, matrix: np.ndarray):
        self.matrix_ = matrix
        self.size = matrix.shape[0]

    def apply(self, columns: np.ndarray) -> np.ndarray:
        return self.matrix_ @ columns

    def matrix(self) -> np.ndarray:
        return self.matrix_


def _known_matrix() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A non-normal 80 x 80 matrix with known eigenvalues (1 the flow's, two complex pairs and a real one near the circle,
    the rest decaying), its eigenvalues and the eigenvector of 1."""
    rng = np.random.default_rng(4)
    size = 80
    known = np.concatenate(
        [[1.0, 0.95, -0.7], 0.8 * np.exp([0.3j, -0.3j]), 0.5 * np.exp([2.0j, -2.0j]), 0.3 * rng.uniform(-1, 1, size - 7)]
    )
    basis = np.eye(size) + 0.3 * rng.standard_normal((size, size))
    real_basis = basis.astype(complex)
    real_basis[:, 3], real_basis[:, 4] = basis[:, 3] + 1j * basis[:, 4], basis[:, 3] - 1j * basis[:, 4]
    real_basis[:, 5], real_basis[:, 6] = basis[:, 5] + 1j * basis[:, 6], basis[:, 5] - 1j * basis[:, 6]
    return np.real(real_basis @ np.diag(known) @ np.linalg.inv(real_basis)), known, real_basis[:, 0].real


def test_arnoldi_on_products_finds_the_leading_eigenvalues_of_a_non_normal_matrix_with_a_known_flow_direction():
    matrix, known, flow = _known_matrix()
    for form in (False, True):
        values, errors = leading_multipliers(_Matrix(matrix), flow, 6, form=form)
        leading = known[np.argsort(-np.abs(known))][: values.size]
        assert np.max(_nearest(leading, values)) < 1e-9
        assert values[0] == pytest.approx(1.0, abs=1e-12) and errors[0] < 1e-12
        assert np.all(errors < 1e-8)


def test_above_the_dense_threshold_arpack_on_products_of_the_formed_matrix_finds_its_leading_eigenvalues(monkeypatch):
    # Above ALL_MULTIPLIERS_UP_TO the deflated matrix is never formed: ARPACK runs on H M H's products.
    matrix, known, flow = _known_matrix()
    dense, dense_errors = leading_multipliers(matrix, flow, 6)
    monkeypatch.setattr(long_orbits, "ALL_MULTIPLIERS_UP_TO", 20)
    values, errors = leading_multipliers(matrix, flow, 6)
    assert values.size == 7 and dense.size == matrix.shape[0]
    assert np.max(_nearest(known[np.argsort(-np.abs(known))][:7], values)) < 1e-9
    assert np.max(_nearest(dense, values)) < 1e-9
    assert values[0] == pytest.approx(1.0, abs=1e-12) and errors[0] == pytest.approx(dense_errors[0], abs=1e-13)
    assert np.all(errors < 1e-8)


def test_arpack_that_does_not_converge_within_its_restarts_reports_the_multipliers_it_found_with_their_errors(monkeypatch):
    # A symmetric M (its eigenvalue distances bounded by the residuals) whose leading nontrivial eigenvalues crowd within
    # 1e-9 of one another, as a long chain's soft modes do: one restart cannot resolve them.
    rng = np.random.default_rng(5)
    size = 120
    known = np.concatenate([[1.0], 0.999 - 1e-9 * np.arange(30), rng.uniform(-0.9, 0.9, size - 31)])
    rotation = np.linalg.qr(rng.standard_normal((size, size)))[0]
    matrix = rotation @ np.diag(known) @ rotation.T
    monkeypatch.setattr(long_orbits, "ALL_MULTIPLIERS_UP_TO", 20)
    monkeypatch.setattr(long_orbits, "ARPACK_RESTARTS", 1)
    values, errors = leading_multipliers(matrix, rotation[:, 0], 6)
    assert values.size == 7  # the trivial one and six: ARPACK's converged ones, else Arnoldi's Ritz values
    assert values[0] == pytest.approx(1.0, abs=1e-12)
    assert np.all(_nearest(known, values) <= errors + 1e-12)


def test_arnoldi_and_the_formed_monodromy_give_the_same_leading_multipliers_of_an_orbit():
    params, model, moment = random_geometries(6, seed=3)[0], "nonlinear", 0.1238021083297486
    orbit = find_periodic_orbit(params, model, moment, method="dense")
    system = _System(params, get_model(model), moment, 0)
    start = _to_y(params, orbit.x, orbit.v)
    monodromy = Monodromy(system, start, orbit.period, 1e-11, 1e-11)
    values, errors = leading_multipliers(monodromy, system.velocity(start), 6, form=False)
    assert np.max(_nearest(orbit.multipliers, values)) < AGREE
    assert np.all(errors < AGREE)
    assert monodromy.formed is None  # products only


def test_monodromy_products_equal_central_differences_of_the_flow():
    params = ChainParams(N=10)
    system = _System(params, get_model("sine"), 0.3, 0)
    rng = np.random.default_rng(2)
    start = np.concatenate([0.3 * rng.standard_normal(system.nf), 0.1 * rng.standard_normal(system.nf)])
    direction = rng.standard_normal(start.size)
    direction /= np.linalg.norm(direction)
    step = 1e-5
    ahead, _, _ = system.flow(start + step * direction, 1.5, rtol=1e-12, atol=1e-12, variations=False)
    behind, _, _ = system.flow(start - step * direction, 1.5, rtol=1e-12, atol=1e-12, variations=False)
    monodromy = Monodromy(system, start, 1.5, 1e-11, 1e-11)
    product = monodromy.apply(direction)
    assert np.linalg.norm(product - (ahead - behind) / (2 * step)) < FD_PRODUCT_TOL * np.linalg.norm(product)
    # Three columns in one integration are three products, and M formed from blocks holds them.
    block = rng.standard_normal((start.size, 3))
    assert np.allclose(monodromy.apply(block)[:, 0], monodromy.apply(block[:, 0]), atol=1e-9)
    formed = monodromy.matrix(block=16, threads=2)
    assert np.allclose(formed @ direction, product, atol=1e-9)


# A whole branch to the fold: the blocks' Jacobian equal to the dense one (below) and the command's branch by the blocks
# (test_orbit_collocation_cli.py) are the quick tests of the same path.
@pytest.mark.slow
def test_a_continuation_with_the_blocks_ends_at_the_dense_continuations_fold_and_loses_stability_where_it_does(
    paper_sine_orbit, paper_sine_branch
):
    orbit, dense = paper_sine_orbit, paper_sine_branch  # the dense continuation down to M = 0.1 (conftest.py)
    assert choose_method(orbit.params, "auto") == "dense"
    blocks = continue_orbit(orbit, method="blocks", moment_min=0.1)
    assert dense.end == blocks.end == "fold"
    # dPhi_T/dM by differences (|dPhi_T/dM| = 1.2e5 near the fold) moves the steps, not the orbits.
    assert blocks.end_moment == pytest.approx(dense.end_moment, abs=1e-9)
    assert blocks.stability_lost_at == pytest.approx(dense.stability_lost_at, abs=1e-9)
    with pytest.raises(ValueError, match="continue_orbit's method must be auto, dense, blocks or picard"):
        continue_orbit(orbit, method="krylov")


def test_the_blocked_shooting_jacobian_equals_the_variational_one_with_the_moment_column_by_differences(paper_sine_orbit):
    orbit = paper_sine_orbit
    system = _System(orbit.params, get_model("sine"), orbit.moment, 0)
    start = _to_y(orbit.params, orbit.x, orbit.v)
    dense = _shooting(system, orbit.particle_turns, 1e-11, 1e-11)(start, orbit.period, True)
    blocks = blocked_shooting(system, orbit.particle_turns, 1e-11, 1e-11)(start, orbit.period, True)
    for name, exact, other in zip(("residual", "dR/dy0", "dR/dT", "dR/dM", "monodromy"), dense, blocks, strict=True):
        assert np.max(np.abs(other - exact)) <= 1e-8 * max(1.0, np.max(np.abs(exact))), name


def test_auto_method_chooses_the_blocks_from_the_length_where_they_pay():
    assert choose_method(ChainParams(N=BLOCKS_FROM_N - 1), "auto") == "dense"
    assert choose_method(ChainParams(N=BLOCKS_FROM_N), "auto") == "blocks"
    assert choose_method(ChainParams(N=3), "krylov") == "krylov"


@pytest.mark.parametrize(
    ("call", "match"),
    [
        (lambda: find_periodic_orbit(ChainParams(), "sine", 0.22, method="arnoldi"), "method must be one of auto, dense, blocks, krylov"),
        (lambda: leading_multipliers(np.eye(6), np.ones(6), 0), "count must be an integer >= 1"),
        (lambda: leading_multipliers(np.eye(6), np.zeros(6)), "flow must be a finite non-zero vector"),
    ],
)
def test_bad_input_is_refused_with_what_is_allowed(call, match):
    with pytest.raises(ValueError, match=match):
        call()


@pytest.mark.slow
def test_a_two_hundred_and_one_particle_orbit_and_its_leading_multiplier_against_differences_of_the_flow():
    # Strong damping: the sine chain's rotation settles on one stable one-turn orbit (T = 21.125; 141 s of CPU).
    params, model, moment = ChainParams(N=100, gamma_u=1.0, gamma_v=1.0, gamma_phi=1.0), "sine", 0.3
    orbit = find_periodic_orbit(params, model, moment)  # auto: the blocks
    assert orbit.closure <= 1e-9 and orbit.multipliers.size == 2 * 3 * 199
    assert abs(orbit.trivial_multiplier - 1.0) <= orbit.trivial_multiplier_error < 1e-8
    assert orbit.stable
    system = _System(params, get_model(model), moment, 0)
    start = _to_y(params, orbit.x, orbit.v)
    eigenvalues, vectors = np.linalg.eig(Monodromy(system, start, orbit.period, 1e-11, 1e-11).matrix())
    leading = orbit.nontrivial_multipliers[0]
    # The leading nontrivial pair (mu, x) of M: M Re x = Re(mu x), checked by differences of the flow alone.
    index = np.argmin(np.abs(eigenvalues - leading))
    assert abs(eigenvalues[index] - leading) < 1e-8
    x = vectors[:, index] / np.linalg.norm(vectors[:, index])
    step = 1e-5
    ahead, _, _ = system.flow(start + step * x.real, orbit.period, rtol=1e-12, atol=1e-12, variations=False)
    behind, _, _ = system.flow(start - step * x.real, orbit.period, rtol=1e-12, atol=1e-12, variations=False)
    assert np.linalg.norm((ahead - behind) / (2 * step) - (leading * x).real) < FD_PRODUCT_TOL
