"""A fourth model is one class and one registry line: a toy model runs through every layer.

The toy is three uncoupled chains of linear springs (u, v and phi each its own
discrete Laplacian), so everything it does has a closed form: the static state,
the compliance, the modes, the whole damped trajectory. It is registered here,
after the package and the CLI were imported, and leaves ``max_frequency`` and
``bond_energy`` to the base class.
"""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
import scipy.linalg as sla
import scipy.sparse as sp
from numba import njit
from typer.testing import CliRunner

from conftest import ROUND_OFF
from cosserat_chain import ChainParams, moment_load
from cosserat_chain.analysis.diagnostics import StreamingDiagnostics, bond_energies
from cosserat_chain.analysis.dispersion import finite_modes
from cosserat_chain.cli import app
from cosserat_chain.experiments.critical import critical_point
from cosserat_chain.models import LINEAR, Model, available_models, get_model, register_model, unregister_model
from cosserat_chain.models.base import BATCH_FORCE_SIGNATURE, FORCE_SIGNATURE, KERNEL_OPTIONS
from cosserat_chain.models.linear import max_frequency as bloch_bound
from cosserat_chain.numerics.continuation import compliance
from cosserat_chain.numerics.dynamics import check_time_step, default_time_step, integrate
from cosserat_chain.numerics.integrators import get_method
from cosserat_chain.numerics.newton import solve_equilibrium
from cosserat_chain.numerics.relaxation import relax
from cosserat_chain.state import check_state

runner = CliRunner()
#: The generic max_frequency's bisection stops within 1e-10 of the Gershgorin bound above lambda_max.
BISECTION_TOL = 1e-9


@njit(inline="always", **KERNEL_OPTIONS)
def _springs(k_u, k_v, k_phi, u_prev, u, u_next, v_prev, v, v_next, p_prev, p, p_next):  # pragma: no cover - compiled
    return k_u * (u_next - 2.0 * u + u_prev), k_v * (v_next - 2.0 * v + v_prev), k_phi * (p_next - 2.0 * p + p_prev)


@njit(FORCE_SIGNATURE, **KERNEL_OPTIONS)
def toy_forces_kernel(x, coef, out, start, stop):  # pragma: no cover - compiled
    k_u, k_v, k_phi = coef[0], coef[1], coef[2]
    u_prev, u, u_next = x[0, start - 1 : stop - 1], x[0, start:stop], x[0, start + 1 : stop + 1]
    v_prev, v, v_next = x[1, start - 1 : stop - 1], x[1, start:stop], x[1, start + 1 : stop + 1]
    p_prev, p, p_next = x[2, start - 1 : stop - 1], x[2, start:stop], x[2, start + 1 : stop + 1]
    out_u, out_v, out_phi = out[0, start:stop], out[1, start:stop], out[2, start:stop]
    for k in range(stop - start):
        out_u[k], out_v[k], out_phi[k] = _springs(
            k_u, k_v, k_phi, u_prev[k], u[k], u_next[k], v_prev[k], v[k], v_next[k], p_prev[k], p[k], p_next[k]
        )


@njit(BATCH_FORCE_SIGNATURE, **KERNEL_OPTIONS)
def toy_batch_kernel(x, coef, out):  # pragma: no cover - compiled
    n, size = x.shape[1], x.shape[2]
    k_u, k_v, k_phi = coef[0], coef[1], coef[2]
    for k in range(1, n - 1):
        u_prev, u, u_next = x[0, k - 1], x[0, k], x[0, k + 1]
        v_prev, v, v_next = x[1, k - 1], x[1, k], x[1, k + 1]
        p_prev, p, p_next = x[2, k - 1], x[2, k], x[2, k + 1]
        out_u, out_v, out_phi = out[0, k], out[1, k], out[2, k]
        for i in range(size):
            out_u[i], out_v[i], out_phi[i] = _springs(
                k_u[i], k_v[i], k_phi[i], u_prev[i], u[i], u_next[i], v_prev[i], v[i], v_next[i], p_prev[i], p[i], p_next[i]
            )


def toy_coefficients(params: ChainParams) -> np.ndarray:
    """Spring constants (k_u, k_v, k_phi): the linear model's k_u, k_v and a torsion spring 2 E1 b^2."""
    return np.array([params.k_u, params.k_v, 2.0 * params.E1 * params.b**2])


class SpringsModel(Model):
    """Three uncoupled spring chains: P = sum over bonds of k_r / 2 (x_r,k+1 - x_r,k)^2."""

    name = "toy"
    conservative = True
    equation = "uncoupled springs"
    rotates = False
    force_kernel = toy_forces_kernel
    batch_kernel = toy_batch_kernel

    @staticmethod
    def coefficients(params: ChainParams) -> np.ndarray:
        return toy_coefficients(params)

    def forces(self, params: ChainParams, x: np.ndarray) -> np.ndarray:
        x = check_state(params, x)
        out = np.zeros_like(x)
        out[:, 1:-1] = toy_coefficients(params)[:, None] * (x[:, 2:] - 2.0 * x[:, 1:-1] + x[:, :-2])
        return out

    def stiffness(self, params: ChainParams, x: np.ndarray) -> sp.csr_matrix:
        # Free degrees of freedom particle by particle, (u, v, phi) within each.
        return sp.kron(laplacian(params.n_particles - 2), sp.diags(toy_coefficients(params))).tocsr()

    def energy(self, params: ChainParams, x: np.ndarray) -> float:
        x = check_state(params, x)
        return float(0.5 * np.sum(toy_coefficients(params)[:, None] * np.diff(x, axis=1) ** 2))


def laplacian(size: int) -> sp.csr_matrix:
    """tridiag(-1, 2, -1) of the clamped chain, shape (size, size)."""
    return sp.diags([-np.ones(size - 1), 2.0 * np.ones(size), -np.ones(size - 1)], [-1, 0, 1]).tocsr()


def laplacian_eigenvalues(size: int) -> np.ndarray:
    """4 sin^2(j pi / (2 (size + 1))), j = 1..size: the spectrum of :func:`laplacian`."""
    return 4.0 * np.sin(np.arange(1, size + 1) * np.pi / (2 * (size + 1))) ** 2


def tent(params: ChainParams, moment: float) -> np.ndarray:
    """The toy's static state under ``moment`` on particle 0: phi_k = M (N - |k|) / (2 k_phi), u = v = 0."""
    x = np.zeros((3, params.n_particles))
    x[2] = moment * (params.N - np.abs(np.arange(-params.N, params.N + 1))) / (2.0 * toy_coefficients(params)[2])
    return x


def exact_trajectory(params: ChainParams, moment: float, t: float) -> tuple[np.ndarray, np.ndarray]:
    """State and velocity at ``t`` of the damped toy chain started at rest: M q'' = -K q + L - Gamma q'."""
    n = 3 * (params.n_particles - 2)
    mass = np.tile(params.inertia, params.n_particles - 2)
    gamma = np.tile(params.damping, params.n_particles - 2)
    K = TOY.stiffness(params, np.zeros((3, params.n_particles))).toarray()
    load = np.zeros(n)
    load[3 * (params.N - 1) + 2] = moment
    # The affine system z' = A z + b as a linear one in (z, 1): z(t) = expm(t A_aug) (0, 1).
    augmented = np.zeros((2 * n + 1, 2 * n + 1))
    augmented[:n, n : 2 * n] = np.eye(n)
    augmented[n : 2 * n, :n] = -K / mass[:, None]
    augmented[n : 2 * n, n : 2 * n] = -np.diag(gamma / mass)
    augmented[n : 2 * n, -1] = load / mass
    z = sla.expm(t * augmented)[:, -1]
    x, v = np.zeros((3, params.n_particles)), np.zeros((3, params.n_particles))
    x[:, 1:-1] = z[:n].reshape(-1, 3).T
    v[:, 1:-1] = z[n : 2 * n].reshape(-1, 3).T
    return x, v


TOY = SpringsModel()
PARAMS = ChainParams()


@pytest.fixture(autouse=True)
def toy():
    """Register the toy for one test (after the CLI was built) and take it out again."""
    register_model(TOY)
    yield TOY
    unregister_model(TOY.name)


def test_the_toy_is_registered_after_the_cli_was_imported_and_removed_afterwards(toy):
    assert available_models()[-1] == "toy" and get_model("toy") is toy
    unregister_model("toy")
    assert "toy" not in available_models()
    with pytest.raises(ValueError, match="model must be one of .*got 'toy'"):
        get_model("toy")
    register_model(toy)  # for the fixture's clean-up


def test_registry_refuses_a_taken_or_reserved_name_and_an_incomplete_model(toy):
    assert register_model(toy) is toy  # registering the same object again changes nothing
    with pytest.raises(ValueError, match="'toy' is already registered.*unregister_model"):
        register_model(SpringsModel())
    with pytest.raises(ValueError, match="'all' is reserved"):
        register_model(type("AllModel", (SpringsModel,), {"name": "all"})())
    with pytest.raises(TypeError, match="Unsure lacks the class attribute.*rotates"):
        register_model(Unsure())
    with pytest.raises(ValueError, match="to be unregistered, got 'nothing'"):
        unregister_model("nothing")


class Unsure(Model):
    """The toy but for ``rotates``, which it does not say."""

    name = "unsure"
    conservative = True
    equation = "uncoupled springs"
    force_kernel = toy_forces_kernel
    batch_kernel = toy_batch_kernel
    coefficients = staticmethod(toy_coefficients)
    forces = SpringsModel.forces
    stiffness = SpringsModel.stiffness


def test_compiled_kernels_are_the_numpy_forces_and_the_batch_kernel_is_bitwise_the_single_one():
    rng = np.random.default_rng(4)
    x = np.zeros((3, PARAMS.n_particles))
    x[:, 1:-1] = rng.standard_normal((3, PARAMS.n_particles - 2))
    np.testing.assert_allclose(TOY.compiled_forces(PARAMS, x), TOY.forces(PARAMS, x), rtol=0, atol=ROUND_OFF)
    members = [PARAMS, PARAMS.replace(E1=2.0), PARAMS.replace(b=0.3, E2=0.0)]
    batch_x = np.zeros((3, PARAMS.n_particles, len(members)))
    batch_x[:, 1:-1] = rng.standard_normal((3, PARAMS.n_particles - 2, len(members)))
    coef = np.ascontiguousarray(np.array([TOY.coefficients(p) for p in members]).T)
    batch_out = np.zeros_like(batch_x)
    toy_batch_kernel(batch_x, coef, batch_out)
    for b in range(len(members)):
        single = np.zeros((3, PARAMS.n_particles))
        toy_forces_kernel(np.ascontiguousarray(batch_x[..., b]), np.ascontiguousarray(coef[:, b]), single, 1, PARAMS.n_particles - 1)
        assert np.array_equal(batch_out[..., b], single)


def test_generic_max_frequency_is_the_toys_highest_mode_and_sets_the_time_step():
    size = PARAMS.n_particles - 2
    exact = math.sqrt(np.max(toy_coefficients(PARAMS) / np.array(PARAMS.inertia)) * laplacian_eigenvalues(size).max())
    omega = TOY.max_frequency(PARAMS)
    assert exact * (1 - ROUND_OFF) <= omega <= exact * (1 + BISECTION_TOL)
    assert default_time_step(PARAMS, "toy") == pytest.approx(0.1 / omega, rel=ROUND_OFF)
    verlet = get_method("verlet")
    check_time_step(PARAMS, 0.99 * verlet.stability_limit / omega, verlet, TOY)
    with pytest.raises(ValueError, match=f"stability limit of verlet.*omega_max={omega:.6g}"):
        check_time_step(PARAMS, 1.01 * verlet.stability_limit / omega, verlet, "toy")


def test_generic_max_frequency_bounds_the_linear_chain_within_a_few_percent_at_n50():
    params = ChainParams(N=50)
    K = LINEAR.stiffness(params).toarray()
    scale = 1.0 / np.sqrt(np.tile(params.inertia, params.n_particles - 2))
    exact = math.sqrt(np.linalg.eigvalsh(scale[:, None] * K * scale[None, :]).max())
    generic = Model.max_frequency(LINEAR, params)
    assert exact * (1 - ROUND_OFF) <= generic <= 1.03 * exact
    # The infinite chain's bound that the paper's models use lies above both.
    assert generic <= bloch_bound(params) * (1 + ROUND_OFF) and LINEAR.max_frequency(params) == bloch_bound(params)


def test_integrate_follows_the_exact_damped_trajectory():
    moment, t_end = 0.05, 20.0
    dt = default_time_step(PARAMS, TOY)
    run = integrate(PARAMS, "toy", moment_load(moment), t_end=t_end, dt=dt, method="yoshida4", n_frames=2)
    assert run.ok, run.message
    x, v = exact_trajectory(PARAMS, moment, t_end)
    assert np.max(np.abs(run.x[-1] - x)) <= 1e-6 * np.max(np.abs(x))
    assert np.max(np.abs(run.v[-1] - v)) <= 1e-6 * np.max(np.abs(x))


def test_relax_comes_to_rest_in_the_toys_static_state():
    step = relax(PARAMS, "toy", 0.05, dt=default_time_step(PARAMS, TOY))
    assert step.status == "static", step.message
    np.testing.assert_allclose(step.x, tent(PARAMS, 0.05), rtol=0, atol=1e-8)


def test_statics_solve_the_toys_green_function():
    moment = 0.05
    x = solve_equilibrium(PARAMS, "toy", moment_load(moment))
    np.testing.assert_allclose(x, tent(PARAMS, moment), rtol=0, atol=ROUND_OFF)
    c = PARAMS.N / (2.0 * toy_coefficients(PARAMS)[2])  # phi_0 / M at the centre
    assert compliance(PARAMS, "toy") == pytest.approx(c, rel=ROUND_OFF)
    result = critical_point(PARAMS, "toy")
    assert result.fold is None and result.compliance == pytest.approx(c, rel=ROUND_OFF)
    branch = result.branch
    assert branch.phi0.max() >= 2 * math.pi * (1 - 1e-9)
    np.testing.assert_allclose(branch.moment, branch.phi0 / c, rtol=1e-9, atol=1e-12)


def test_finite_modes_are_the_three_spring_chains_spectra():
    modes = finite_modes(PARAMS, "toy")
    laplace = laplacian_eigenvalues(PARAMS.n_particles - 2)
    expected = np.sort(np.concatenate([k / m * laplace for k, m in zip(toy_coefficients(PARAMS), PARAMS.inertia)]))
    assert modes.model == "toy" and modes.stable
    np.testing.assert_allclose(modes.omega2.real, expected, rtol=1e-10)
    assert np.all(modes.omega2.imag == 0)


def test_diagnostics_without_bond_energies_keep_the_turns_and_leave_the_energy_measures_nan():
    x = np.zeros((3, 3, PARAMS.n_particles))
    x[1:, 2, PARAMS.N] = [1.0, 2.0 * math.pi + 0.1]  # the loaded particle makes one turn
    with pytest.raises(NotImplementedError, match="toy model .* defines no bond energy"):
        bond_energies(PARAMS, "toy", x)
    diagnostics = StreamingDiagnostics(PARAMS, "toy", 0, x[0], np.zeros_like(x[0]))
    diagnostics.update(np.array([0.0, 1.0, 2.0]), x, np.zeros_like(x))
    assert not diagnostics.has_energy and diagnostics.turns_completed == 1
    assert math.isnan(diagnostics.participation_ratio) and np.all(np.isnan(diagnostics.mean_energy_share))


def test_cli_offers_the_toy_where_it_applies_and_simulates_it():
    result = runner.invoke(app, ["simulate", "--model", "toy", "--moment", "0.02", "--t-end", "600", "--json"])
    assert result.exit_code == 0, result.output
    data = json.loads(result.stdout)
    assert data["model"] == "toy" and data["status"] == "completed"
    np.testing.assert_allclose(data["final"]["phi"], tent(PARAMS, 0.02)[2], rtol=0, atol=1e-8)
    rejected = runner.invoke(app, ["rotate", "--model", "toy", "--moment", "0.3"])
    assert rejected.exit_code == 2 and "'toy' is not one of 'nonlinear', 'sine'" in rejected.output


def test_cli_refuses_the_toy_once_unregistered(toy):
    unregister_model("toy")
    try:
        result = runner.invoke(app, ["simulate", "--model", "toy", "--t-end", "1"])
        assert result.exit_code == 2 and "'toy' is not one of" in result.output and "'nonlinear'" in result.output
    finally:
        register_model(toy)


def test_plots_fall_back_to_the_colour_cycle_and_the_models_equation():
    import matplotlib.pyplot as plt

    from cosserat_chain.plots.statics import MODEL_COLORS, model_color, model_label

    cycle = plt.rcParams["axes.prop_cycle"].by_key()["color"]
    assert model_color("toy") == cycle[len(MODEL_COLORS)] and model_color("toy") not in MODEL_COLORS.values()
    assert model_label("toy") == "toy, uncoupled springs" and model_label("sine") == "sine-Cosserat (2)"
    assert model_label("from elsewhere") == "from elsewhere" and model_color("from elsewhere") == cycle[len(MODEL_COLORS) + 1]


def test_the_paper_models_say_whether_they_rotate():
    assert [get_model(name).rotates for name in ("nonlinear", "sine", "linear")] == [True, True, False]
    assert TOY.rotates is False
