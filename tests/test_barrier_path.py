"""The turn's minimum energy path: the climbing-image string method and P-RFO on Mueller-Brown and on the held lattice."""

from __future__ import annotations

import numpy as np
import pytest

from cosserat_chain import ChainParams
from cosserat_chain.analysis.rotation_front import bond_potential, lattice_energy, lattice_hessian, turn_barrier
from cosserat_chain.numerics.mep import saddle_search, string_method

# The Mueller-Brown potential (Theor. Chim. Acta 53, 75, 1979): three minima, two saddles.
_A = np.array([-200.0, -100.0, -170.0, 15.0])
_a = np.array([-1.0, -1.0, -6.5, 0.7])
_b = np.array([0.0, 0.0, 11.0, 0.6])
_c = np.array([-10.0, -10.0, -6.5, 0.7])
_x0 = np.array([1.0, 0.0, -0.5, -1.0])
_y0 = np.array([0.0, 0.5, 1.5, 1.0])


def _terms(points):
    x, y = points[..., 0:1] - _x0, points[..., 1:2] - _y0
    return _A * np.exp(_a * x * x + _b * x * y + _c * y * y), 2 * _a * x + _b * y, _b * x + 2 * _c * y


def mueller_brown(points):
    """Energies (M,) and gradients (M, 2) at points (M, 2)."""
    t, fx, fy = _terms(points)
    return t.sum(-1), np.stack([(t * fx).sum(-1), (t * fy).sum(-1)], axis=-1)


def mueller_brown_hessian(point):
    """Gradient (2,) and Hessian (2, 2) at one point."""
    t, fx, fy = _terms(point)
    off = (t * (fx * fy + _b)).sum()
    hessian = np.array([[(t * (fx * fx + 2 * _a)).sum(), off], [off, (t * (fy * fy + 2 * _c)).sum()]])
    return np.array([(t * fx).sum(), (t * fy).sum()]), hessian


# Minima A and B and the two saddles on the path between them (refined here to 1e-12 from the tabulated ones).
MINIMUM_A, MINIMUM_B = (-0.558224, 1.441726), (0.623499, 0.028038)
SADDLE_1, ENERGY_1 = (-0.822002, 0.624313), -40.664844
SADDLE_2, ENERGY_2 = (0.212487, 0.292988), -72.248940


@pytest.mark.parametrize("images", [21, 42])
def test_climbing_string_on_mueller_brown_finds_the_tabulated_saddles_and_the_middle_minimum(images):
    path = string_method(mueller_brown, np.array([MINIMUM_A, MINIMUM_B]), step=1e-4, images=images, tolerance=1e-3)
    assert path.converged and path.climbing == path.top
    # Two tops: the higher (the climbing image, on its saddle to the tolerance) and the lower.
    tops = path.maxima()
    assert len(tops) == 2 and path.images[tops[0], 0] < path.images[tops[1], 0]
    np.testing.assert_allclose(path.images[path.climbing], SADDLE_1, atol=1e-4)
    found = []
    for top in tops:
        saddle = saddle_search(mueller_brown_hessian, path.images[top], tolerance=1e-12)
        assert saddle.converged and saddle.negative == 1
        found.append((saddle.x, float(mueller_brown(saddle.x[None])[0][0])))
    np.testing.assert_allclose(found[0][0], SADDLE_1, atol=2e-6)
    np.testing.assert_allclose(found[1][0], SADDLE_2, atol=2e-6)
    assert found[0][1] == pytest.approx(ENERGY_1, abs=2e-6) and found[1][1] == pytest.approx(ENERGY_2, abs=2e-6)
    # Between the two tops the path dips into the third minimum (-0.050, 0.467), E = -80.77.
    valley = path.images[tops[0] : tops[1] + 1][np.argmin(path.energies[tops[0] : tops[1] + 1])]
    np.testing.assert_allclose(valley, (-0.050, 0.467), atol=0.05)


def test_string_without_climbing_stays_below_the_saddle_and_bad_input_is_refused():
    path = string_method(mueller_brown, np.array([MINIMUM_A, MINIMUM_B]), step=1e-4, images=11, climb=False, tolerance=1e-2)
    assert path.converged and path.climbing == -1 and path.energies.max() < ENERGY_1
    with pytest.raises(ValueError, match="images"):
        string_method(mueller_brown, np.array([MINIMUM_A, MINIMUM_B]), step=1e-4, images=2)
    with pytest.raises(ValueError, match="step"):
        string_method(mueller_brown, np.array([MINIMUM_A, MINIMUM_B]), step=0.0, images=5)
    with pytest.raises(ValueError, match="path"):
        string_method(mueller_brown, np.zeros(3), step=1e-4)
    with pytest.raises(ValueError, match="images"):
        turn_barrier(ChainParams(), half_length=2, images=2)


def test_one_particle_between_fixed_neighbours_turns_over_twice_the_bond_potentials_top():
    params = ChainParams(a=0.05, b=0.3, E2=0.01)
    barrier = turn_barrier(params, half_length=1, points=16, images=12)
    grid = np.linspace(0, 2 * np.pi, 20001)
    assert barrier.barrier == pytest.approx(2 * bond_potential(params, 0.0, grid).max(), rel=1e-7)
    assert barrier.barrier == pytest.approx(barrier.fixed, rel=1e-12)


def _check_top(params, path):
    """The path's top: zero gradient, one negative eigenvalue over the free particles."""
    free = np.ones(path.state.size, dtype=bool)
    free[[0, -1]] = False
    hessian = lattice_hessian(params, path.state)[np.ix_(free, free)]
    assert np.max(np.abs(lattice_energy(params, path.state)[1][free])) < 1e-10 * np.max(np.abs(hessian))
    assert np.sum(np.linalg.eigvalsh(hessian) < 0) == 1
    assert path.minima[0] < 1e-12 and path.minima[-1] < 1e-12
    assert np.isclose(path.images[0], 0).all() and path.images[-1][path.state.size // 2] == pytest.approx(2 * np.pi)


@pytest.mark.parametrize("params", [ChainParams(), ChainParams(a=0.05, b=0.3, E2=0.01)])
def test_where_the_rotation_controlled_path_is_continuous_the_minimum_energy_path_closes_the_bracket(params):
    barrier = turn_barrier(params, half_length=6, points=24, images=16)
    assert {path.start for path in barrier.paths} == {"rotation-controlled", "one-sided"}
    for path in barrier.paths:
        _check_top(params, path)
        assert len(path.saddles) == 1
    assert barrier.barrier == pytest.approx(barrier.relaxed, rel=1e-7)
    assert barrier.barrier == pytest.approx(barrier.saddle, rel=1e-7)


@pytest.mark.slow
def test_wide_front_turns_through_a_lower_one_sided_saddle_inside_the_bracket():
    params = ChainParams(a=0.05, b=0.6, E2=0.01)
    barrier = turn_barrier(params, half_length=8, points=24, images=24)
    paths = {path.start: path for path in barrier.paths}
    # The mirror-symmetric path keeps its symmetry: its top is the former upper bound.
    assert paths["rotation-controlled"].barrier == pytest.approx(barrier.saddle, rel=1e-9)
    one_sided = paths["one-sided"]
    _check_top(params, one_sided)
    # It passes a metastable front (the particle slipped past one side, dragging the other).
    assert len(one_sided.minima) >= 3 and 0.5 < max(one_sided.minima) < barrier.relaxed
    assert barrier.barrier == one_sided.barrier
    assert barrier.relaxed < barrier.barrier < barrier.saddle - 0.03


@pytest.mark.slow
@pytest.mark.parametrize(
    ("a", "b", "E2", "expected", "double"),
    # The images are doubled on the two rows where that costs least (the two widest fronts' 96-image
    # paths took three quarters of this test's time; their convergence is in docs/which-continuum.md).
    [(0.05, 0.6, 0.01, 0.7718, True), (0.05, 0.6, 0.001, 0.7214, True), (0.02, 0.8, 0.01, 1.1039, False), (0.02, 0.8, 0.001, 1.0237, False)],
)
def test_wide_fronts_barrier_of_the_held_lattice_lies_in_the_bracket_and_does_not_move_when_the_images_double(a, b, E2, expected, double):
    params = ChainParams(a=a, b=b, E2=E2)
    coarse = turn_barrier(params, half_length=30, points=32, images=48)
    assert coarse.relaxed < coarse.barrier < coarse.fixed
    if np.isfinite(coarse.saddle):
        assert coarse.barrier < coarse.saddle
    assert coarse.barrier == pytest.approx(expected, abs=5e-5)
    best = min(coarse.paths, key=lambda path: path.barrier)
    _check_top(params, best)
    assert len(best.minima) >= 3  # a metastable state on the way: the front, or the particle half-turned
    if double:
        fine = turn_barrier(params, half_length=30, points=32, images=96)
        assert fine.barrier == pytest.approx(coarse.barrier, rel=1e-10)
