"""Corner geometry of Fig. 1."""

from __future__ import annotations

import numpy as np
import pytest

from conftest import random_geometries
from cosserat_chain.geometry import bond_links, corner_positions


@pytest.mark.parametrize("params", random_geometries(3, seed=20))
def test_linked_corners_are_at_rest_length_at_rest(params):
    corners = corner_positions(params, np.zeros((3, params.n_particles)))
    index = {(params.a, params.b): 0, (-params.a, params.b): 1, (-params.a, -params.b): 2, (params.a, -params.b): 3}
    for link in bond_links(params):
        left = corners[:-1, index[link.left_corner]]
        right = corners[1:, index[link.right_corner]]
        np.testing.assert_allclose(np.linalg.norm(right - left, axis=1), link.rest_length, rtol=1e-14)


def test_corners_turn_with_the_particle(paper):
    x = np.zeros((3, paper.n_particles))
    x[2, paper.N] = np.pi / 2
    x[1, paper.N] = 0.1
    corners = corner_positions(paper, x)[paper.N]
    # (a, b) rotated by 90 degrees is (-b, a), shifted by the centre (0, 0.1).
    np.testing.assert_allclose(corners[0], [-paper.b, paper.a + 0.1], atol=1e-15)
