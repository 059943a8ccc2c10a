"""A particle's full rotation: model (i)'s held bond potential, its quasi-continuum front and the discrete lattice's."""

from __future__ import annotations

import numpy as np
import pytest

from conftest import ROUND_OFF, random_geometries
from cosserat_chain import ChainParams
from cosserat_chain.analysis.rotation_front import (
    bond_potential,
    discrete_front,
    fourier_content,
    lattice_energy,
    quasi_continuum,
    turn_barrier,
)
from cosserat_chain.models import NONLINEAR

#: Tall, thin particles with weak diagonals: a front about 12 particles wide.
WIDE = ChainParams(a=0.05, b=0.6, E2=0.001)


@pytest.mark.parametrize("params", random_geometries(4, seed=21))
def test_bond_potential_is_model_i_bond_energy_with_centres_held_periodic_and_symmetric(params):
    rng = np.random.default_rng(1)
    angles = rng.uniform(-7, 7, size=(20, 2))
    states = np.zeros((20, 3, 3))
    states[:, 2, :2] = angles
    direct = NONLINEAR.bond_energy(params.replace(N=1), states)[:, 0]
    np.testing.assert_allclose(bond_potential(params, angles[:, 0], angles[:, 1]), direct, rtol=ROUND_OFF, atol=ROUND_OFF)
    a, b = angles.T
    np.testing.assert_allclose(bond_potential(params, b, a), direct, rtol=1e-10, atol=1e-12)
    np.testing.assert_allclose(bond_potential(params, a + 2 * np.pi, b - 4 * np.pi), direct, rtol=1e-10, atol=1e-12)


def test_lattice_gradient_is_the_energys():
    phi = np.array([0.0, 0.4, 1.3, 2.0, 4.1, 6.0])
    _, gradient = lattice_energy(WIDE, phi)
    step = 1e-6
    numeric = [(lattice_energy(WIDE, phi + step * e)[0] - lattice_energy(WIDE, phi - step * e)[0]) / (2 * step) for e in np.eye(phi.size)]
    np.testing.assert_allclose(gradient, numeric, atol=1e-8)


@pytest.mark.parametrize("params", random_geometries(3, seed=4))
def test_quasi_continuum_at_rest_is_the_linear_chains_bending_and_shear(params):
    qc = quasi_continuum(params)
    assert qc.kappa[0] == pytest.approx(2 * params.E1 * params.b**2, rel=1e-6)
    assert qc.tail == pytest.approx(np.sqrt(params.E1 * params.d**2 / (4 * params.E2 * params.h**2)), rel=1e-5)


def test_fourier_content_is_symmetric_and_holds_all_of_v_by_parseval():
    grid = 64
    entries = fourier_content(ChainParams(), grid=grid, count=grid * grid)
    magnitude = {(m, n): c for m, n, c in entries}
    assert magnitude[(0, 1)] == pytest.approx(magnitude[(1, 0)], rel=1e-12)
    assert entries[0][2] >= entries[1][2] >= entries[-1][2]
    angles = 2 * np.pi * np.arange(grid) / grid
    mean_square = np.mean(bond_potential(ChainParams(), angles[:, None], angles[None, :]) ** 2)
    # Each listed pair (m, n), (-m, -n) holds 2 |c_mn|: its share of the mean square is half its square.
    parseval = magnitude[(0, 0)] ** 2 + sum(c**2 / 2 for key, c in magnitude.items() if key != (0, 0))
    assert parseval == pytest.approx(mean_square, rel=1e-9)


def test_wide_front_of_the_lattice_matches_the_quasi_continuum():
    qc = quasi_continuum(WIDE)
    front = discrete_front(WIDE, half_length=60)
    assert front.smooth
    assert front.energy == pytest.approx(qc.front_energy, rel=0.01)
    assert front.width == pytest.approx(qc.width, rel=0.1)
    assert front.peierls_barrier < 1e-3 * front.energy
    # Turning one particle drags its neighbours along: far below the fixed-neighbour barrier.
    barrier = turn_barrier(WIDE, half_length=10, points=24, images=0)
    assert barrier.relaxed < 0.8 * barrier.fixed


def test_narrow_front_slips_into_one_bond_and_a_particle_half_turned_costs_the_single_particle_barrier():
    params = ChainParams()
    front = discrete_front(params, half_length=10)
    assert not front.smooth and front.energy < 1e-12
    barrier = turn_barrier(params, half_length=6, points=32, images=0)
    grid = np.linspace(0, 2 * np.pi, 20001)
    assert barrier.fixed == pytest.approx(2 * bond_potential(params, 0.0, grid).max(), rel=1e-7)
    assert barrier.relaxed <= barrier.fixed + 1e-9
    assert front.energy_site == pytest.approx(barrier.relaxed, rel=1e-6)


@pytest.mark.slow  # the command's whole front, its minimum energy paths included (test_barrier_path.py tests those on their own)
def test_theory_cli_front_reports_the_wide_front_in_json(tmp_path, capsys):
    import json

    from typer.testing import CliRunner

    from cosserat_chain.cli import app
    from cosserat_chain.cli.theory import _print_rotation

    config = tmp_path / "wide.toml"
    config.write_text("a = 0.05\nb = 0.6\nE2 = 0.001\n")
    result = CliRunner().invoke(app, ["theory", "--config", str(config), "--n-list", "4,8", "--front", "--json"])
    assert result.exit_code == 0, result.output
    rotation = json.loads(result.stdout)["rotation"]
    assert rotation["discrete_front"]["smooth"] and rotation["quasi_continuum"]["front_energy"] == pytest.approx(
        quasi_continuum(WIDE).front_energy
    )
    assert rotation["barrier"]["relaxed"] <= rotation["barrier"]["fixed"]
    # The minimum energy path closes the bracket: above the path's top, below the fixed neighbours.
    barrier = rotation["barrier"]
    assert barrier["relaxed"] < barrier["barrier"] < barrier["fixed"] and barrier["saddle"] is None
    best = min(barrier["paths"], key=lambda path: path["barrier"])
    assert barrier["barrier"] == best["barrier"] == max(best["saddles"]) and best["saddle_gradient"] < 1e-10
    _print_rotation(rotation)
    assert f"barrier {barrier['barrier']:.6g}" in capsys.readouterr().out
    assert rotation["free_front"]["smooth"] and rotation["free_front"]["energy"] < rotation["free_front"]["held_energy"]


def test_bad_input_is_refused():
    graded = ChainParams(N=1, E1_factors=(1.0, 2.0))
    with pytest.raises(ValueError, match="E1_factors"):
        bond_potential(graded, 0.0, 0.0)
    with pytest.raises(ValueError, match="half_length"):
        discrete_front(ChainParams(), half_length=1)


def test_lattice_hessian_is_the_gradients_derivative():
    from cosserat_chain.analysis.rotation_front import lattice_hessian

    phi = np.array([0.0, 0.4, 1.3, 2.0, 4.1, 6.0])
    step = 1e-6
    numeric = np.array(
        [(lattice_energy(WIDE, phi + step * e)[1] - lattice_energy(WIDE, phi - step * e)[1]) / (2 * step) for e in np.eye(phi.size)]
    )
    np.testing.assert_allclose(lattice_hessian(WIDE, phi), numeric, atol=1e-8)


@pytest.mark.parametrize(
    ("params", "smooth_path"),
    [(ChainParams(), True), (ChainParams(a=0.05, b=0.3, E2=0.01), True), (ChainParams(a=0.05, b=0.6, E2=0.01), False)],
)
def test_turn_saddle_is_a_first_order_saddle_between_rest_and_the_turned_particle_bracketing_the_barrier(params, smooth_path):
    from cosserat_chain.analysis.rotation_front import lattice_hessian

    barrier = turn_barrier(params, half_length=8, points=32, images=0)
    state = barrier.saddle_state
    free = np.ones(state.size, dtype=bool)
    free[[0, -1]] = False
    hessian = lattice_hessian(params, state)[np.ix_(free, free)]
    assert np.max(np.abs(lattice_energy(params, state)[1][free])) < 1e-10 * np.max(np.abs(hessian))
    assert np.sum(np.linalg.eigvalsh(hessian) < 0) == 1 and barrier.negative_eigenvalues == 1
    # Its two descents: rest, and the particle turned once (zero energy, 2 pi apart).
    first, second, energy = barrier.descents
    assert sorted([round(first / (2 * np.pi)), round(second / (2 * np.pi))]) in ([0, 1], [-1, 0]) and energy < 1e-12
    # The rotation-controlled path's top bounds the barrier from below; the saddle (a path over it) from above.
    assert barrier.relaxed <= barrier.saddle + 1e-9 and barrier.saddle <= barrier.fixed + 1e-9
    if smooth_path:
        assert barrier.saddle == pytest.approx(barrier.relaxed, rel=1e-7)
    else:
        # Wide fronts: the dragged path runs into a metastable state, which the search lists among the others.
        assert barrier.saddle > barrier.relaxed + 0.05 and barrier.others


def test_free_centres_relax_the_front_into_a_stable_minimum_whose_energy_falls_with_the_chains_length():
    from cosserat_chain.analysis.rotation_front import free_front
    from cosserat_chain.models import NONLINEAR
    from cosserat_chain.state import pack

    params = ChainParams(a=0.02, b=0.8, E2=0.01)
    short, longer = free_front(params, half_length=10), free_front(params, half_length=20)
    for front, n in ((short, 10), (longer, 20)):
        chain = params.replace(N=n)
        state = front.state.copy()
        state[2, -1] = 0.0  # the clamped end's 2 pi, as the model stores it
        assert np.max(np.abs(pack(chain, NONLINEAR.forces(chain, state)))) < 1e-8
        assert np.linalg.eigvalsh(NONLINEAR.stiffness(chain, state).toarray())[0] > 0
        assert front.energy == pytest.approx(NONLINEAR.energy(chain, state), rel=1e-12)
        # The held front is admissible, so freeing the centres can only lower the energy: here a lot.
        assert front.smooth and front.energy < 0.8 * front.held_energy and front.displacement > 0.3
    # No intrinsic front: the relaxation grows with the room the clamped ends leave.
    assert longer.energy < 0.8 * short.energy
    # The paper's chain: the front slips into one bond, free centres or not.
    assert free_front(ChainParams(), half_length=6).energy < 1e-12
