"""What the report's speed-ups kept bitwise: the nonlinear bond energies, and a shooting's parameters built once."""

import numpy as np

from cosserat_chain.geometry import rotate
from cosserat_chain.models.base import get_model
from cosserat_chain.models.nonlinear import bond_links, bonded
from cosserat_chain.numerics.periodic import _System
from cosserat_chain.params import ChainParams


def _reference_bond_energy(params: ChainParams, x: np.ndarray) -> np.ndarray:
    """Potential (1) of the four links of every bond, each corner rotated by geometry.rotate."""
    x = bonded(params, x)
    du, dv, phi = np.diff(x[..., 0, :], axis=-1), np.diff(x[..., 1, :], axis=-1), x[..., 2, :]
    total = np.zeros(du.shape)
    for link in bond_links(params):
        r0x, r0y = rotate(link.left_corner, phi[..., :-1])
        r1x, r1y = rotate(link.right_corner, phi[..., 1:])
        length = np.hypot(params.h + du + r1x - r0x, dv + r1y - r0y)
        total += 0.5 * link.stiffness * (length - link.rest_length) ** 2
    return total


def test_nonlinear_bond_energy_is_bitwise_the_per_link_rotation():
    params = ChainParams(N=4, b=0.3)
    x = np.random.default_rng(2).standard_normal((50, 3, params.n_particles))
    x[..., 2, :] *= 7.0  # angles over several turns
    energy = get_model("nonlinear").bond_energy(params, x)
    np.testing.assert_array_equal(energy, _reference_bond_energy(params, x))
    assert energy.shape == (50, params.n_bonds)


def test_shooting_parameters_are_copies_with_the_moment():
    """The parameters are built once per chain and model; each caller gets its own arrays, with its own moment."""
    params = ChainParams()
    first = _System(params, get_model("sine"), 0.2, 0).parameters(0)
    first[4][:] = -1.0  # a caller that changes its rpar (the undamping homotopy scales it)
    first[5][:] = -1
    second = _System(params, get_model("sine"), 0.3, 0).parameters(0)
    assert second[4][0] == 0.3
    assert np.all(second[4][1:] > 0)
    assert np.all(second[5][:4] >= 0)
    fresh = _System(params.replace(gamma_phi=0.4), get_model("sine"), 0.3, 0).parameters(0)
    assert not np.array_equal(fresh[4], second[4])  # another chain's damping: not the cached chain's
