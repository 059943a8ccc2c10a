"""The three models: energies, gradients, Hessians, compiled kernels and symmetries."""

from __future__ import annotations

import numpy as np
import pytest

from conftest import FD_STEP, FD_TOL, ROUND_OFF, random_geometries, random_state
from cosserat_chain import moment_load
from cosserat_chain.models import LINEAR, NONLINEAR, SINE, available_models, get_model
from cosserat_chain.models.base import no_ends
from cosserat_chain.models.nonlinear import chain_energy
from cosserat_chain.numerics.newton import solve_equilibrium
from cosserat_chain.state import fixed_mask, force_columns, pack, unpack

GEOMETRIES = random_geometries(5, seed=1)
CONSERVATIVE = [NONLINEAR, LINEAR]
ALL = [NONLINEAR, SINE, LINEAR]


def finite_difference_jacobian(fun, params, x):
    """d fun / dq over the free degrees of freedom by central differences."""
    q = pack(params, x)
    columns = []
    for i in range(q.size):
        e = np.zeros_like(q)
        e[i] = FD_STEP
        plus = fun(unpack(params, q + e))
        minus = fun(unpack(params, q - e))
        columns.append((np.atleast_1d(plus) - np.atleast_1d(minus)) / (2 * FD_STEP))
    return np.array(columns).T


def test_registry_lists_the_three_models_and_rejects_unknown_names():
    assert set(available_models()) >= {"nonlinear", "sine", "linear"}
    with pytest.raises(ValueError, match="model must be one of .*'linear'.*got 'cosine'"):
        get_model("cosine")


@pytest.mark.parametrize("model", CONSERVATIVE, ids=lambda m: m.name)
@pytest.mark.parametrize("params", GEOMETRIES[:3])
def test_forces_are_minus_gradient_of_energy(model, params):
    x = random_state(params, 0.2, seed=2)
    gradient = finite_difference_jacobian(lambda y: model.energy(params, y), params, x)[0]
    np.testing.assert_allclose(pack(params, model.forces(params, x)), -gradient, atol=FD_TOL * 10)


@pytest.mark.parametrize("params", GEOMETRIES)
def test_nonlinear_stiffness_at_rest_equals_linear_K(params):
    rest = np.zeros((3, params.n_particles))
    H = NONLINEAR.stiffness(params, rest).toarray()
    K = LINEAR.stiffness(params).toarray()
    assert np.max(np.abs(H - K)) <= ROUND_OFF * np.max(np.abs(K))
    # K is symmetric positive definite: the clamped chain at rest is stable.
    assert np.allclose(K, K.T) and np.linalg.eigvalsh(K).min() > 0


@pytest.mark.parametrize("model", ALL, ids=lambda m: m.name)
@pytest.mark.parametrize("params", GEOMETRIES[:3])
def test_stiffness_is_minus_jacobian_of_forces(model, params):
    x = random_state(params, 0.3, seed=3)
    jac = finite_difference_jacobian(lambda y: pack(params, model.forces(params, y)), params, x)
    np.testing.assert_allclose(model.stiffness(params, x).toarray(), -jac, atol=1e-6)


def test_sine_jacobian_is_not_symmetric_but_nonlinear_hessian_is(paper):
    x = random_state(paper, 0.5, seed=4)
    J = SINE.stiffness(paper, x).toarray()
    H = NONLINEAR.stiffness(paper, x).toarray()
    assert np.max(np.abs(J - J.T)) > 1e-3
    assert np.max(np.abs(H - H.T)) <= ROUND_OFF * np.max(np.abs(H))
    with pytest.raises(TypeError, match="not conservative"):
        SINE.energy(paper, x)


@pytest.mark.parametrize("model", ALL, ids=lambda m: m.name)
@pytest.mark.parametrize("scale", [0.05, 1.0, 40.0])
def test_compiled_kernel_matches_numpy_twin(model, scale):
    params = GEOMETRIES[0].replace(N=6)
    x = random_state(params, scale, seed=5)
    x[:2] = np.clip(x[:2], -0.2 * params.h, 0.2 * params.h)  # large angles, no overlapping corners
    np.testing.assert_allclose(model.compiled_forces(params, x), model.forces(params, x), rtol=1e-11, atol=1e-12)


@pytest.mark.parametrize(
    "ends", [{}, {"left_end": "free", "right_end": "pinned"}, {"periodic": True}], ids=["clamped", "free-pinned", "ring"]
)
@pytest.mark.parametrize("model", ALL, ids=lambda m: m.name)
def test_kernel_on_column_blocks_equals_whole_chain(model, ends):
    params = GEOMETRIES[1].replace(N=8, **ends)
    x = random_state(params, 0.5, seed=6)
    whole = model.compiled_forces(params, x)
    pieces = np.zeros_like(x)
    coef = model.coefficients(params)
    for start, stop in [(1, 4), (4, 5), (5, 12), (12, params.n_particles - 1)]:
        type(model).force_kernel(x, coef, pieces, start, stop)
    first, last = force_columns(params)
    if params.clamped:
        assert model.ends_kernel(params) is no_ends
    else:
        type(model).end_kernel(x, coef, pieces, first == 0, last == params.n_particles, params.periodic)
    pieces[fixed_mask(params)] = 0.0
    np.testing.assert_array_equal(pieces, whole)


def test_sine_model_with_sin_phi_replaced_by_phi_is_the_linear_model():
    params = GEOMETRIES[2]
    x = random_state(params, 0.3, seed=7)
    s = np.clip(x[2], -0.9, 0.9)
    x_lin = np.vstack([x[:2], s])
    x_sine = np.vstack([x[:2], np.arcsin(s)])
    np.testing.assert_allclose(SINE.compiled_forces(params, x_sine), LINEAR.compiled_forces(params, x_lin), atol=ROUND_OFF)


@pytest.mark.parametrize("model", [SINE, LINEAR], ids=lambda m: m.name)
def test_u_decouples_from_v_and_phi(model):
    params = GEOMETRIES[3]
    x = random_state(params, 0.4, seed=8)
    J = model.stiffness(params, x).toarray()
    rows_u = np.arange(0, J.shape[0], 3)
    others = np.setdiff1d(np.arange(J.shape[0]), rows_u)
    assert np.all(J[np.ix_(rows_u, others)] == 0) and np.all(J[np.ix_(others, rows_u)] == 0)
    y = x.copy()
    y[1:] = random_state(params, 0.4, seed=9)[1:]
    np.testing.assert_array_equal(model.compiled_forces(params, x)[0], model.compiled_forces(params, y)[0])


def test_nonlinear_model_couples_u_to_rotation(paper):
    x = np.zeros((3, paper.n_particles))
    x[2, 3] = 0.5
    assert np.max(np.abs(NONLINEAR.forces(paper, x)[0])) > 1e-3


@pytest.mark.parametrize("model", ALL, ids=lambda m: m.name)
def test_response_to_central_moment_is_mirror_symmetric(model, paper):
    x = solve_equilibrium(paper, model, moment_load(0.1))
    u, v, phi = x
    np.testing.assert_allclose(v, -v[::-1], atol=1e-13)
    np.testing.assert_allclose(phi, phi[::-1], atol=1e-13)
    np.testing.assert_allclose(u, -u[::-1], atol=1e-13)
    assert phi[paper.N] > 0


@pytest.mark.parametrize(
    ("model", "order"),
    # Nonlinear: u is even in M (mirror y -> -y), so u ~ M^2 appears at first relative order.
    # Sine: its statics are odd in M and sin(phi) = phi - phi^3/6, so the difference is O(M^2).
    [(NONLINEAR, 1), (SINE, 2)],
    ids=["nonlinear", "sine"],
)
def test_static_response_agrees_with_linear_as_moment_vanishes(model, order, paper):
    moments = np.array([4e-3, 2e-3, 1e-3, 5e-4])
    diffs = []
    for M in moments:
        lin = solve_equilibrium(paper, LINEAR, moment_load(M))
        other = solve_equilibrium(paper, model, moment_load(M))
        diffs.append(np.max(np.abs(other - lin)) / np.max(np.abs(lin)))
    diffs = np.array(diffs)
    ratios = diffs[:-1] / diffs[1:]
    np.testing.assert_allclose(ratios, 2.0**order, rtol=0.05)  # relative difference ~ M^order


@pytest.mark.parametrize("params", GEOMETRIES[:3])
def test_nonlinear_energy_is_invariant_under_rigid_motions(params):
    rng = np.random.default_rng(10)
    x = rng.normal(scale=0.05, size=(3, params.n_particles))  # ends free: no clamp in chain_energy
    X = params.h * np.arange(-params.N, params.N + 1) + x[0]
    Y = x[1]
    theta, tx, ty = 0.7, 0.3, -1.1
    moved = np.array(
        [
            np.cos(theta) * X - np.sin(theta) * Y + tx - params.h * np.arange(-params.N, params.N + 1),
            np.sin(theta) * X + np.cos(theta) * Y + ty,
            x[2] + theta,
        ]
    )
    energy = chain_energy(params, x)
    assert energy > 0
    assert chain_energy(params, moved) == pytest.approx(energy, rel=1e-12)
    assert chain_energy(params, moved + np.array([[0.0], [0.0], [2 * np.pi]])) == pytest.approx(energy, rel=1e-12)
