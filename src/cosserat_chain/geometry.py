"""Corners of the particles and the four links of every bond (paper, Section 2 and Fig. 1).

Particle k has its centre at (k h + u_k, v_k) and is the rectangle with corners
(+-a, +-b) rotated by phi_k about the centre. Between particles k and k+1
there are four links, each joining a right-hand corner of k to a left-hand
corner of k+1:

===========  ================  ==================  =========  ============
link         corner on k       corner on k+1       stiffness  rest length
===========  ================  ==================  =========  ============
top          (a, b)            (-a, b)             E1         h - 2a
bottom       (a, -b)           (-a, -b)            E1         h - 2a
diagonal 1   (a, b)            (-a, -b)            E2         d
diagonal 2   (a, -b)           (-a, b)             E2         d
===========  ================  ==================  =========  ============
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .params import ChainParams


@dataclass(frozen=True)
class Link:
    """One spring of a bond: corners (in the particles' body frames), stiffness and rest length."""

    name: str
    left_corner: tuple[float, float]
    right_corner: tuple[float, float]
    stiffness: float | np.ndarray
    rest_length: float


def bond_links(params: ChainParams) -> tuple[Link, ...]:
    """The four links between particle k (left) and k+1 (right), in the table's order.

    A link's ``stiffness`` is a float, or for a chain graded in its bonds an array
    (n_bonds,): that link's stiffness in every bond.
    """
    a, b = params.a, params.b
    E1, E2 = params.bond_stiffness if params.graded_stiffness else (params.E1, params.E2)
    return (
        Link("top", (a, b), (-a, b), E1, params.gap),
        Link("bottom", (a, -b), (-a, -b), E1, params.gap),
        Link("diagonal_1", (a, b), (-a, -b), E2, params.d),
        Link("diagonal_2", (a, -b), (-a, b), E2, params.d),
    )


def particle_positions(params: ChainParams) -> np.ndarray:
    """Rest positions x_k = k h of the centres, k = -N..N, shape (2N+1,)."""
    return params.h * np.arange(-params.N, params.N + 1, dtype=float)


def rotate(corner: tuple[float, float], phi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Body-frame corner (cx, cy) rotated by the angles ``phi`` (any shape)."""
    c, s = np.cos(phi), np.sin(phi)
    cx, cy = corner
    return cx * c - cy * s, cx * s + cy * c


def corner_positions(params: ChainParams, x: np.ndarray) -> np.ndarray:
    """Positions of the four corners of every particle in the deformed state.

    Parameters
    ----------
    params : ChainParams
    x : ndarray, shape (3, 2N+1)
        Rows u, v, phi.

    Returns
    -------
    ndarray, shape (2N+1, 4, 2)
        Corners in the order (a, b), (-a, b), (-a, -b), (a, -b) (counter-clockwise), as (X, Y).
    """
    u, v, phi = x
    centre_x = particle_positions(params) + u
    out = np.empty((x.shape[1], 4, 2))
    for i, corner in enumerate(((params.a, params.b), (-params.a, params.b), (-params.a, -params.b), (params.a, -params.b))):
        rx, ry = rotate(corner, phi)
        out[:, i, 0] = centre_x + rx
        out[:, i, 1] = v + ry
    return out
