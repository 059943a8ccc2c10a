"""Graded and disordered chains (issue 14, item 3): per-bond E1, E2 and per-particle m, j.

Checked against independent computations: the compiled graded kernels against the
NumPy twins, the engine's per-column inertia against DOP853 and energy conservation,
and factors all alike against the uniform chain itself.
"""

from __future__ import annotations

import numpy as np
import pytest

from conftest import random_geometries
from cosserat_chain import ChainParams, moment_load
from cosserat_chain.analysis.energy import kinetic_energy, potential_energy
from cosserat_chain.models import get_model
from cosserat_chain.numerics.adaptive import integrate_adaptive
from cosserat_chain.numerics.dynamics import integrate
from cosserat_chain.params import disordered
from cosserat_chain.state import zero_held

ENDS = [{}, {"left_end": "free", "right_end": "pinned"}, {"periodic": True}]


def _state(params, seed=0, scale=0.3):
    x = np.random.default_rng(seed).normal(0.0, scale, (3, params.n_particles))
    return zero_held(params, x)


@pytest.mark.parametrize("ends", ENDS)
@pytest.mark.parametrize("N", [1, 4, 9])
@pytest.mark.parametrize("model", ["nonlinear", "sine", "linear"])
def test_graded_kernels_equal_their_numpy_twins(ends, N, model):
    params = disordered(ChainParams(N=N, **ends), seed=N, spread=0.6)
    assert params.graded_stiffness
    x = _state(params, N)
    twin = get_model(model).forces(params, x)
    assert np.abs(get_model(model).compiled_forces(params, x) - twin).max() <= 1e-13 * np.abs(twin).max()


@pytest.mark.parametrize("model", ["nonlinear", "sine", "linear"])
def test_a_graded_kernel_on_equal_bonds_gives_the_uniform_forces(model):
    """The graded loop itself (not only the folding) on bonds all alike: the uniform kernel's forces to round-off."""
    params = ChainParams(N=6)
    m = get_model(model)
    coef = m.coefficients(params.model_copy(update={"E1_factors": (1.0,) * 12}))
    assert coef.size > m.coefficients(params).size  # the graded layout
    x = _state(params, 3)
    out = np.zeros_like(x)
    type(m).graded_kernel(x, coef, out, 1, x.shape[1] - 1)
    uniform = m.compiled_forces(params, x)
    assert np.allclose(out[:, 1:-1], uniform[:, 1:-1], rtol=0, atol=1e-14 * np.abs(uniform).max())


def test_factors_all_alike_are_the_uniform_chain_to_the_last_bit():
    graded = ChainParams(N=3, E1_factors=[2.0] * 6, m_factors=[1.5] * 7)
    assert graded == ChainParams(N=3, E1=2.0, m=1.5, j=ChainParams(N=3).j) and not graded.graded
    x0 = _state(graded, 1, 0.05)
    a = integrate(graded, "nonlinear", moment_load(0.05, 0), t_end=5.0, x0=x0, n_frames=5)
    b = integrate(ChainParams(N=3, E1=2.0, m=1.5, j=ChainParams(N=3).j), "nonlinear", moment_load(0.05, 0), t_end=5.0, x0=x0, n_frames=5)
    assert np.array_equal(a.x, b.x) and np.array_equal(a.v, b.v)


@pytest.mark.parametrize("ends", ENDS)
@pytest.mark.parametrize("model", ["nonlinear", "linear"])
def test_graded_inertia_conserves_energy_and_agrees_with_dop853(ends, model):
    params = disordered(ChainParams(N=4, gamma_u=0.0, gamma_v=0.0, gamma_phi=0.0, **ends), 7, 0.5, ("E1", "E2", "m", "j"))
    x0 = _state(params, 2, 0.05)
    run = integrate(params, model, moment_load(0.0, 0), t_end=20.0, x0=x0, n_frames=50, method="yoshida4")
    energy = kinetic_energy(params, run.v) + potential_energy(params, model, run.x)
    assert np.ptp(energy) < 5e-6 * energy[0]
    reference = integrate_adaptive(params, model, moment_load(0.0, 0), t_end=20.0, x0=x0, n_frames=50)
    assert np.abs(run.x[-1] - reference.x[-1]).max() < 2e-4
    # A wrong inertia (the uniform particles') is far off: the comparison can fail.
    uniform = params.replace(m_factors=None, j_factors=None)
    other = integrate_adaptive(uniform, model, moment_load(0.0, 0), t_end=20.0, x0=x0, n_frames=50)
    assert np.abs(other.x[-1] - reference.x[-1]).max() > 100 * np.abs(run.x[-1] - reference.x[-1]).max()


def test_the_verlet_error_of_a_graded_chain_falls_like_dt_squared():
    params = disordered(ChainParams(N=5), 3, 0.5, ("E1", "E2", "m", "j"))
    x0 = _state(params, 4, 0.1)
    load = moment_load(0.1, 0)
    reference = integrate_adaptive(params, "sine", load, t_end=10.0, x0=x0, n_frames=2).x[-1]
    errors = [np.abs(integrate(params, "sine", load, t_end=10.0, x0=x0, dt=dt, n_frames=2).x[-1] - reference).max() for dt in (0.02, 0.01)]
    assert 3.5 < errors[0] / errors[1] < 4.5


def test_a_mirror_symmetric_graded_chain_answers_a_central_moment_point_symmetrically():
    factors = np.random.default_rng(5).uniform(0.5, 1.5, 4)
    params = ChainParams(N=4, E1_factors=[*factors, *factors[::-1]], E2_factors=[*factors[::-1], *factors])
    run = integrate(params, "nonlinear", moment_load(0.1, 0), t_end=30.0, n_frames=3)
    u, v, phi = run.x[-1]
    assert np.allclose(u, -u[::-1], atol=1e-12) and np.allclose(v, -v[::-1], atol=1e-12) and np.allclose(phi, phi[::-1], atol=1e-12)


@pytest.mark.parametrize(
    ("changes", "message"),
    [
        ({"E1_factors": [1.0, 2.0]}, "E1_factors must have one value for each of the chain's 6 bonds"),
        ({"m_factors": [1.0] * 6}, "m_factors must have one value for each of the chain's 7 particles"),
        ({"E2_factors": [-1.0] + [1.0] * 5}, "E2_factors[0] must be >= 0"),
        ({"j_factors": [1.0, float("nan")] + [1.0] * 5}, "j_factors[1] must be a finite number"),
        ({"E1_factors": "1,2"}, "E1_factors must be a list of numbers"),
    ],
)
def test_bad_factors_are_refused_naming_the_field(changes, message):
    with pytest.raises(ValueError, match=message.replace("[", r"\[").replace("]", r"\]")):
        ChainParams(N=3, **changes)


def test_disordered_is_reproducible_and_checks_its_input():
    a, b = disordered(ChainParams(N=3), 11, 0.3), disordered(ChainParams(N=3), 11, 0.3)
    assert a == b and max(abs(f - 1) for f in a.E1_factors) <= 0.3
    with pytest.raises(ValueError, match="spread"):
        disordered(ChainParams(), 1, 1.0)
    with pytest.raises(ValueError, match="fields"):
        disordered(ChainParams(), 1, 0.1, ("E3",))
    with pytest.raises(ValueError, match="give E1_factors"):
        a.replace(N=4)


# --------------------------------------------------------------------------- statics and modes
GRADED = [
    disordered(g.replace(N=n), seed, 0.4, ("E1", "E2", "m", "j"))
    for seed, (g, n) in enumerate(zip(random_geometries(3, seed=31), (1, 3, 6)))
]


@pytest.mark.parametrize("params", GRADED, ids=lambda p: f"N{p.N}")
def test_a_graded_static_state_is_the_minimum_of_the_links_energy(params):
    """Newton on the compiled graded kernel against a minimiser of the NumPy link-by-link energy (1)."""
    from scipy.optimize import minimize

    from cosserat_chain.models.nonlinear import chain_energy
    from cosserat_chain.numerics.newton import solve_equilibrium
    from cosserat_chain.state import pack, unpack

    moment = 0.1 * params.E1 * params.h**2
    static = solve_equilibrium(params, "nonlinear", moment_load(moment, 0))
    phi0 = (2, params.N)

    def work(q):
        x = unpack(params, q)
        return chain_energy(params, x) - moment * x[phi0]

    found = minimize(work, np.zeros(pack(params, static).size), method="BFGS", options={"gtol": 1e-11})
    np.testing.assert_allclose(unpack(params, found.x), static, atol=2e-5 * max(1.0, np.abs(static).max()))


@pytest.mark.parametrize("params", GRADED[1:], ids=lambda p: f"N{p.N}")
def test_a_graded_chains_folds_agree_between_methods_and_the_sine_fold_is_one_over_the_compliance(params):
    from cosserat_chain.experiments.critical import critical_point
    from cosserat_chain.numerics.continuation import locate_fold

    nonlinear = critical_point(params, "nonlinear")
    first = locate_fold(params, "nonlinear")
    assert nonlinear.complete and nonlinear.branch.folds[0].moment == pytest.approx(first.moment, rel=1e-10)
    sine = critical_point(params, "sine")
    assert sine.critical_moment * sine.compliance == pytest.approx(1.0, rel=1e-10)
    # The grading moves the fold: the uniform chain of the same geometry has another one.
    uniform = params.model_copy(update={"E1_factors": None, "E2_factors": None, "m_factors": None, "j_factors": None})
    assert abs(locate_fold(uniform, "nonlinear").moment - first.moment) > 1e-4


@pytest.mark.parametrize("params", GRADED[1:], ids=lambda p: f"N{p.N}")
def test_a_graded_chain_started_in_its_lowest_mode_oscillates_at_that_modes_frequency(params):
    """The engine's per-column inertia against the modes' generalised eigenproblem K a = omega^2 M a."""
    from cosserat_chain.analysis.dispersion import finite_modes

    params = params.replace(gamma_u=0.0, gamma_v=0.0, gamma_phi=0.0)
    modes = finite_modes(params, "linear")
    omega = float(np.sqrt(modes.omega2[0].real))
    period = 2 * np.pi / omega
    shape = modes.shapes[0]
    run = integrate(params, "linear", moment_load(0.0), x0=1e-3 * shape, t_end=3 * period, dt=period / 4000, n_frames=3 * 400 + 1)
    inertia = params.particle_inertia
    amplitude = np.einsum("kij,ij,ij->k", run.x, inertia, shape) * 1e3
    np.testing.assert_allclose(amplitude, np.cos(omega * run.time), atol=1e-5)


def test_a_disorder_table_in_a_config_draws_the_chain_of_its_seed(tmp_path):
    from cosserat_chain.io import load_config

    path = tmp_path / "disordered.toml"
    path.write_text('N = 5\nE2 = 0.5\n\n[disorder]\nseed = 4\nspread = 0.25\nfields = ["E1", "m"]\n')
    params, _ = load_config(path)
    assert params == disordered(ChainParams(N=5, E2=0.5), 4, 0.25, ("E1", "m"))
    assert params.E2_factors is None and params.j_factors is None


@pytest.mark.parametrize(
    ("table", "message"),
    [
        ("[disorder]\nseed = 1\n", r"missing key\(s\) \['spread'\]"),
        ("[disorder]\nseed = 1\nspread = 0.1\nsprad = 2\n", r"unknown key\(s\) \['sprad'\]"),
        ("[disorder]\nseed = 1\nspread = 1.5\n", "spread must be a number with 0 <= spread < 1"),
        ("[disorder]\nseed = -1\nspread = 0.1\n", "seed must be an integer >= 0"),
        ('[disorder]\nseed = 1\nspread = 0.1\nfields = "E1"\n', "fields must be a list"),
        ('[disorder]\nseed = 1\nspread = 0.1\nfields = ["E3"]\n', "fields must be a non-empty selection"),
        ("disorder = 3\n", "must be a table"),
        ("E1_factors = [1, 1, 1, 1, 1, 2]\n[disorder]\nseed = 1\nspread = 0.1\n", "also gives \\(E1_factors\\)"),
    ],
)
def test_a_bad_disorder_table_is_refused_naming_the_key(tmp_path, table, message):
    from cosserat_chain.io import load_config

    path = tmp_path / "bad.toml"
    path.write_text("N = 3\n" + table)
    with pytest.raises(ValueError, match=r"\[disorder\] of .*bad.toml.*" + message):
        load_config(path)
