"""Graded and disordered chains (issue 14, item 3): per-bond E1, E2 and per-particle m, j.

Checked against independent computations: the compiled graded kernels against the
NumPy twins, the engine's per-column inertia against DOP853 and energy conservation,
and factors all alike against the uniform chain itself.
"""

from __future__ import annotations

import numpy as np
import pytest

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
