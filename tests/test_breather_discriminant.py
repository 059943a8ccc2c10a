"""The collision discriminant of :mod:`cosserat_chain.numerics.breather_arclength` on matrices whose multipliers are known.

At a collision of m multipliers (a Jordan block) an error delta of the matrix moves each of them by delta^(1/m), while
the cluster's symmetric functions, and so the discriminant, move by O(delta): the reason a change of stability is
located on it rather than on the multipliers' moduli.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
import scipy.linalg as sla

from cosserat_chain.numerics.breather_arclength import collision_discriminant


def rotation(theta: float) -> np.ndarray:
    return np.array([[math.cos(theta), -math.sin(theta)], [math.sin(theta), math.cos(theta)]])


def with_hamiltonian_pair(block: np.ndarray, far: float = 2.0) -> np.ndarray:
    """The Hamiltonian pair at +1 (a Jordan block), ``block`` and a pair of phonons far from +1 and -1 (angle ``far``)."""
    return sla.block_diag(np.array([[1.0, 3.0], [0.0, 1.0]]), block, rotation(far))


@pytest.mark.parametrize("theta", [0.01, 0.3, 0.6])
def test_a_pair_on_the_circle_and_a_real_pair_at_plus_one(theta):
    """D = -4 sin^2 theta for the pair e^(+-i theta), 4 sinh^2 lambda for e^(+-lambda): the sign tells them apart."""
    assert collision_discriminant(np.linalg.eigvals(with_hamiltonian_pair(rotation(theta))), "+1") == pytest.approx(
        -4 * math.sin(theta) ** 2, rel=1e-9, abs=1e-14
    )
    real = np.diag([math.exp(theta), math.exp(-theta)])
    assert collision_discriminant(np.linalg.eigvals(with_hamiltonian_pair(real)), "+1") == pytest.approx(
        4 * math.sinh(theta) ** 2, rel=1e-9
    )


def test_at_minus_one_and_a_krein_collision():
    """At -1: D = -4 sin^2 of the angle from -1, 4 sinh^2 for -e^(+-lambda). Off the axis: two pairs at angles 1 +- d on
    the circle give -4 sin^2 d; a quartet r e^(+-i), e^(+-i) / r gives (r - 1/r)^2."""
    assert collision_discriminant(np.linalg.eigvals(-rotation(0.2)), "-1") == pytest.approx(-4 * math.sin(0.2) ** 2, rel=1e-9)
    assert collision_discriminant(np.array([-math.exp(0.2), -math.exp(-0.2)]), "-1") == pytest.approx(4 * math.sinh(0.2) ** 2)
    centre = complex(np.exp(1j))
    on = np.exp(1j * np.array([1.01, -1.01, 0.99, -0.99]))
    assert collision_discriminant(on, "complex", centre) == pytest.approx(-4 * math.sin(0.01) ** 2, rel=1e-9)
    r = 1.05
    off = np.array([r, 1 / r, r, 1 / r]) * np.exp(1j * np.array([1, 1, -1, -1]))
    assert collision_discriminant(off, "complex", centre) == pytest.approx((r - 1 / r) ** 2, rel=1e-9)


def test_a_perturbed_four_fold_collision_moves_the_multipliers_by_the_fourth_root_and_the_discriminant_linearly():
    """A 4 x 4 Jordan block at +1 (the Hamiltonian pair and a pair at the collision), perturbed by delta in one corner:
    its multipliers move by delta^(1/4) (1e-3 for 1e-12), the discriminant by about delta."""
    block = np.eye(4) + np.diag(np.ones(3), 1)
    matrix = sla.block_diag(block, rotation(2.0))
    for delta in (1e-12, 1e-8):
        perturbed = matrix.copy()
        perturbed[3, 0] += delta
        mu = np.linalg.eigvals(perturbed)
        moved = np.sort(np.abs(mu - 1.0))[:4]
        assert moved == pytest.approx(delta**0.25, rel=0.05)
        assert abs(collision_discriminant(mu, "+1")) < 100 * delta


def test_an_unresolved_cluster_and_bad_input():
    """A phonon pair as near +1 as the cluster leaves it unresolved (None); a bad kind or a Krein collision without its
    centre is a ValueError naming what is allowed."""
    crowded = np.linalg.eigvals(with_hamiltonian_pair(rotation(0.3), far=0.35))
    assert collision_discriminant(crowded, "+1") is None
    assert collision_discriminant(np.ones(3), "+1") is None  # fewer multipliers than the cluster holds
    with pytest.raises(ValueError, match="kind must be one of"):
        collision_discriminant(np.ones(4), "+2")
    with pytest.raises(ValueError, match="centre"):
        collision_discriminant(np.ones(4), "complex")
