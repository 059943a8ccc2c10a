"""The models' bond kernels: every bond's forces and their exact Jacobian.

Assembled over the chain, the bonds' forces must equal the model's forces and minus their
Jacobian the model's stiffness (an independent code path: the nonlinear model's Hessian sums,
the linear model's K, the sine model's K C), to round-off, for random admissible geometries,
states of large rotation, every kind of end and chains graded in their bonds.
"""

from __future__ import annotations

import numpy as np
import pytest

from conftest import random_geometries, random_state
from cosserat_chain.models import get_model
from cosserat_chain.models.base import BOND_ROWS, assemble_bond_blocks

ENDS = [("clamped", "clamped"), ("pinned", "free"), ("free", "clamped"), ("pinned", "pinned")]


def _bonds(model, params, x):
    out = np.full((BOND_ROWS, params.n_bonds), np.nan)
    type(model).bond_kernel(np.ascontiguousarray(x), model.coefficients(params), out, 0, params.n_bonds)
    return out


@pytest.mark.parametrize("model", ["nonlinear", "sine", "linear"])
@pytest.mark.parametrize("index", range(4))
@pytest.mark.parametrize("graded", [False, True])
def test_bond_kernel_assembles_to_the_models_forces_and_stiffness(model, index, graded):
    m = get_model(model)
    rng = np.random.default_rng(index)
    left, right = ENDS[index]
    params = random_geometries(4, seed=31)[index].replace(left_end=left, right_end=right)
    if graded:
        params = params.replace(
            E1_factors=tuple(rng.uniform(0.5, 1.5, params.n_bonds)), E2_factors=tuple(rng.uniform(0.5, 1.5, params.n_bonds))
        )
    x = random_state(params, 0.3, seed=index)
    x[2] *= 8.0  # angles of several radians: the sines and cosines matter
    bonds = _bonds(m, params, x)
    forces = np.zeros((3, params.n_particles))
    forces[:, :-1] += bonds[:3]
    forces[:2, 1:] -= bonds[:2]
    forces[2, 1:] += bonds[3]
    expected = m.forces(params, x)
    free = expected != 0.0
    assert np.abs(forces[free] - expected[free]).max() <= 1e-13 * np.abs(expected).max()
    jacobian = bonds[4:].T.reshape(params.n_bonds, 6, 6)
    stiffness = m.stiffness(params, x).toarray()
    assert np.abs(assemble_bond_blocks(-jacobian, params).toarray() - stiffness).max() <= 1e-13 * np.abs(stiffness).max()


@pytest.mark.parametrize("model", ["nonlinear", "sine", "linear"])
def test_bond_kernel_jacobian_equals_differences_of_its_forces(model):
    """The Jacobian rows against central differences of the same kernel's force rows, bond by bond."""
    m = get_model(model)
    params = random_geometries(1, seed=5)[0].replace(N=2)
    x = random_state(params, 0.2, seed=1) + np.array([[0.0], [0.0], [2.0]])
    bonds = _bonds(m, params, x)
    step = 1e-6
    for k in range(params.n_bonds):
        for c in range(6):
            plus, minus = x.copy(), x.copy()
            plus[c % 3, k + c // 3] += step
            minus[c % 3, k + c // 3] -= step
            difference = (_bonds(m, params, plus)[:4, k] - _bonds(m, params, minus)[:4, k]) / (2 * step)
            # Rows of (fx, fy, m0) on the left particle and (-fx, -fy, m1) on the right one.
            rows = np.array([difference[0], difference[1], difference[2], -difference[0], -difference[1], difference[3]])
            assert np.allclose(bonds[4 + c :: 6, k][:6], rows, rtol=1e-7, atol=1e-7 * np.abs(bonds[4:, k]).max())
