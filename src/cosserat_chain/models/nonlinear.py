"""Model (i): nonlinear springs on the exact corner geometry, potential (1).

Every bond has four links (:mod:`cosserat_chain.geometry`); a link of stiffness E
and rest length L0 between corner P0 of particle k and corner P1 of particle k+1
stores P = E (L - L0)^2 / 2 with L = |P1 - P0| (eq. 1). The forces are the exact
gradient: with the link vector D = P1 - P0 and tension T = E (1 - L0/L) D,
particle k receives the force +T and the moment r0 x T, particle k+1 the force
-T and the moment -r1 x T, where r0, r1 are the rotated corner vectors.

The model is conservative and invariant under rigid motions of the whole chain
(when the ends are not clamped). Its Hessian at rest equals the stiffness
matrix K of the linear model (iii), which is how eqs. (2)-(3) are derived.
"""

from __future__ import annotations

import math

import numpy as np
import scipy.sparse as sp
from numba import njit

from ..geometry import bond_links, rotate
from ..params import ChainParams
from ..state import bonded, check_state, scatter_bonds, zero_held
from .base import BATCH_FORCE_SIGNATURE, END_SIGNATURE, FORCE_SIGNATURE, KERNEL_OPTIONS, Model, assemble_bond_blocks
from .linear import max_frequency
from .trig import REDUCTION_LIMIT, sincos

#: Length of a uniform chain's coefficients (a, b, h, E1, E2, h - 2a, d); a graded chain's
#: append E1 of every bond, then E2 of every bond.
GRADED_OFFSET = 7


@njit(inline="always", **KERNEL_OPTIONS)
def _bond(a, b, h, E1, E2, rest1, rest2, c0, s0, c1, s1, du, dv):  # pragma: no cover - compiled
    """Force (fx, fy) and moment m0 on the left particle of a bond, moment m1 on the right one.

    The right particle receives (-fx, -fy). ``a, b, h, E1, E2, rest1, rest2``: the
    coefficients; ``c0, s0, c1, s1``: cos and sin of the two angles; ``du, dv``:
    differences of the displacements (right minus left).
    """
    # Right-hand corners of the left particle: A = R(a, b), B = R(a, -b).
    ax = a * c0 - b * s0
    ay = a * s0 + b * c0
    bx = a * c0 + b * s0
    by = a * s0 - b * c0
    # Left-hand corners of the right particle: C = R(-a, b), D = R(-a, -b).
    cx = -a * c1 - b * s1
    cy = -a * s1 + b * c1
    dx = -a * c1 + b * s1
    dy = -a * s1 - b * c1
    ex = h + du
    ey = dv
    # Tensions T = E (1 - L0/L) (P1 - P0): top A-C, bottom B-D (E1); diagonals A-D, B-C (E2).
    lx = ex + cx - ax
    ly = ey + cy - ay
    t = E1 * (1.0 - rest1 / math.sqrt(lx * lx + ly * ly))
    top_x = t * lx
    top_y = t * ly
    lx = ex + dx - bx
    ly = ey + dy - by
    t = E1 * (1.0 - rest1 / math.sqrt(lx * lx + ly * ly))
    bot_x = t * lx
    bot_y = t * ly
    lx = ex + dx - ax
    ly = ey + dy - ay
    t = E2 * (1.0 - rest2 / math.sqrt(lx * lx + ly * ly))
    ad_x = t * lx
    ad_y = t * ly
    lx = ex + cx - bx
    ly = ey + cy - by
    t = E2 * (1.0 - rest2 / math.sqrt(lx * lx + ly * ly))
    bc_x = t * lx
    bc_y = t * ly
    fx = top_x + bot_x + ad_x + bc_x
    fy = top_y + bot_y + ad_y + bc_y
    m0 = ax * (top_y + ad_y) - ay * (top_x + ad_x) + bx * (bot_y + bc_y) - by * (bot_x + bc_x)
    m1 = -(cx * (top_y + bc_y) - cy * (top_x + bc_x) + dx * (bot_y + ad_y) - dy * (bot_x + ad_x))
    return fx, fy, m0, m1


@njit(FORCE_SIGNATURE, **KERNEL_OPTIONS)
def nonlinear_forces_kernel(x, coef, out, start, stop):  # pragma: no cover - compiled
    a, b, h, E1, E2, rest1, rest2 = coef[0], coef[1], coef[2], coef[3], coef[4], coef[5], coef[6]
    # Column k gets the right half of bond k-1 (-fx, -fy, m1) and the left half of
    # bond k (fx, fy, m0). The loop computes bond k and carries fx, fy, m1 and the
    # sine and cosine of column k+1 to the next iteration (recurrences the
    # vectoriser recognises; it does not recognise a carried -fx, hence fx - fx_prev).
    # Bond start-1 is peeled off rather than guarded by an `if` in the loop, and the
    # slices make every index 0-based: either one alone keeps the loop scalar.
    s0, c0 = sincos(x[2, start - 1])
    s1, c1 = sincos(x[2, start])
    fx_prev, fy_prev, _, m1_prev = _bond(
        a, b, h, E1, E2, rest1, rest2, c0, s0, c1, s1, x[0, start] - x[0, start - 1], x[1, start] - x[1, start - 1]
    )
    s0, c0 = s1, c1
    u = x[0, start:]
    v = x[1, start:]
    phi = x[2, start:]
    out_u = out[0, start:stop]
    out_v = out[1, start:stop]
    out_phi = out[2, start:stop]
    for k in range(stop - start):
        s1, c1 = sincos(phi[k + 1])
        fx, fy, m0, m1 = _bond(a, b, h, E1, E2, rest1, rest2, c0, s0, c1, s1, u[k + 1] - u[k], v[k + 1] - v[k])
        out_u[k] = fx - fx_prev
        out_v[k] = fy - fy_prev
        out_phi[k] = m0 + m1_prev
        fx_prev, fy_prev, m1_prev = fx, fy, m1
        s0, c0 = s1, c1


@njit(FORCE_SIGNATURE, **KERNEL_OPTIONS)
def nonlinear_graded_kernel(x, coef, out, start, stop):  # pragma: no cover - compiled
    a, b, h, rest1, rest2 = coef[0], coef[1], coef[2], coef[5], coef[6]
    # nonlinear_forces_kernel with bond k's E1 and E2 read from the coefficients' tail
    # (GRADED_OFFSET: E1 of every bond, then E2), sliced from bond start-1 so that
    # every index stays 0-based.
    n_bonds = (coef.size - GRADED_OFFSET) // 2
    E1 = coef[GRADED_OFFSET + start - 1 : GRADED_OFFSET + n_bonds]
    E2 = coef[GRADED_OFFSET + n_bonds + start - 1 :]
    s0, c0 = sincos(x[2, start - 1])
    s1, c1 = sincos(x[2, start])
    fx_prev, fy_prev, _, m1_prev = _bond(
        a, b, h, E1[0], E2[0], rest1, rest2, c0, s0, c1, s1, x[0, start] - x[0, start - 1], x[1, start] - x[1, start - 1]
    )
    s0, c0 = s1, c1
    u = x[0, start:]
    v = x[1, start:]
    phi = x[2, start:]
    out_u = out[0, start:stop]
    out_v = out[1, start:stop]
    out_phi = out[2, start:stop]
    for k in range(stop - start):
        s1, c1 = sincos(phi[k + 1])
        fx, fy, m0, m1 = _bond(a, b, h, E1[k + 1], E2[k + 1], rest1, rest2, c0, s0, c1, s1, u[k + 1] - u[k], v[k + 1] - v[k])
        out_u[k] = fx - fx_prev
        out_v[k] = fy - fy_prev
        out_phi[k] = m0 + m1_prev
        fx_prev, fy_prev, m1_prev = fx, fy, m1
        s0, c0 = s1, c1


@njit(inline="always", **KERNEL_OPTIONS)
def _link_stiffness(coef, bond):  # pragma: no cover - compiled
    """(E1, E2) of a bond: the scalars of a uniform chain's coefficients, or the bond's own of a graded chain's."""
    if coef.size == GRADED_OFFSET:
        return coef[3], coef[4]
    n_bonds = (coef.size - GRADED_OFFSET) // 2
    return coef[GRADED_OFFSET + bond], coef[GRADED_OFFSET + n_bonds + bond]


@njit(END_SIGNATURE, **KERNEL_OPTIONS)
def nonlinear_end_kernel(x, coef, out, first, last, ring):  # pragma: no cover - compiled
    a, b, h, rest1, rest2 = coef[0], coef[1], coef[2], coef[5], coef[6]
    n = x.shape[1]
    # Column 0 has bond 0 on its right, column n-1 bond n-2 on its left; a ring's closing
    # bond n-1 joins column n-1 (left) to column 0 (right), a neighbour h further on.
    closing_x = closing_y = closing_m0 = closing_m1 = 0.0
    if ring:
        E1, E2 = _link_stiffness(coef, n - 1)
        s0, c0 = sincos(x[2, n - 1])
        s1, c1 = sincos(x[2, 0])
        closing_x, closing_y, closing_m0, closing_m1 = _bond(
            a, b, h, E1, E2, rest1, rest2, c0, s0, c1, s1, x[0, 0] - x[0, n - 1], x[1, 0] - x[1, n - 1]
        )
    if first:
        E1, E2 = _link_stiffness(coef, 0)
        s0, c0 = sincos(x[2, 0])
        s1, c1 = sincos(x[2, 1])
        fx, fy, m0, _ = _bond(a, b, h, E1, E2, rest1, rest2, c0, s0, c1, s1, x[0, 1] - x[0, 0], x[1, 1] - x[1, 0])
        out[0, 0] = fx - closing_x
        out[1, 0] = fy - closing_y
        out[2, 0] = m0 + closing_m1
    if last:
        E1, E2 = _link_stiffness(coef, n - 2)
        s0, c0 = sincos(x[2, n - 2])
        s1, c1 = sincos(x[2, n - 1])
        fx, fy, _, m1 = _bond(a, b, h, E1, E2, rest1, rest2, c0, s0, c1, s1, x[0, n - 1] - x[0, n - 2], x[1, n - 1] - x[1, n - 2])
        out[0, n - 1] = closing_x - fx
        out[1, n - 1] = closing_y - fy
        out[2, n - 1] = closing_m0 + m1


@njit(BATCH_FORCE_SIGNATURE, **KERNEL_OPTIONS)
def nonlinear_batch_kernel(x, coef, out):  # pragma: no cover - compiled
    n, size = x.shape[1], x.shape[2]
    a, b, h, E1, E2, rest1, rest2 = coef[0], coef[1], coef[2], coef[3], coef[4], coef[5], coef[6]
    # Per member: sine, cosine of the bond's left column and the carried half bond,
    # the same arithmetic as nonlinear_forces_kernel member by member.
    s0, c0 = np.empty(size), np.empty(size)
    fx_prev, fy_prev, m1_prev = np.empty(size), np.empty(size), np.empty(size)
    for i in range(size):
        s0[i], c0[i] = sincos(x[2, 0, i])
    for k in range(n - 1):
        u0, u1, v0, v1, phi1 = x[0, k], x[0, k + 1], x[1, k], x[1, k + 1], x[2, k + 1]
        if k == 0:
            for i in range(size):
                s1, c1 = sincos(phi1[i])
                fx_prev[i], fy_prev[i], _, m1_prev[i] = _bond(
                    a[i], b[i], h[i], E1[i], E2[i], rest1[i], rest2[i], c0[i], s0[i], c1, s1, u1[i] - u0[i], v1[i] - v0[i]
                )
                s0[i], c0[i] = s1, c1
            continue
        out_u, out_v, out_phi = out[0, k], out[1, k], out[2, k]
        for i in range(size):
            s1, c1 = sincos(phi1[i])
            fx, fy, m0, m1 = _bond(a[i], b[i], h[i], E1[i], E2[i], rest1[i], rest2[i], c0[i], s0[i], c1, s1, u1[i] - u0[i], v1[i] - v0[i])
            out_u[i] = fx - fx_prev[i]
            out_v[i] = fy - fy_prev[i]
            out_phi[i] = m0 + m1_prev[i]
            fx_prev[i], fy_prev[i], m1_prev[i] = fx, fy, m1
            s0[i], c0[i] = s1, c1


@njit(cache=True, nogil=True)
def _hessian_blocks(x, h, corners, constants, blocks):  # pragma: no cover - compiled
    """Add every link's Hessian of P = E (L - L0)^2 / 2 to its bond's 6x6 block.

    ``corners[l]``: body-frame corners of link l on the left and the right particle;
    ``constants[k, l]``: its E in bond k and its L0. With D the link vector, e = D / L and
    B = dD/d(u0, v0, phi0, u1, v1, phi1), the block gains B^T G B with
    G = d^2 P / dD^2 = E [(L0/L) e e^T + (1 - L0/L) I], and the corner paths' curvature
    (d^2 D/dphi0^2 = r0, d^2 D/dphi1^2 = -r1) adds T.r0 and -T.r1 with T = E (1 - L0/L) D.
    """
    jac = np.zeros((2, 6))
    jac[0, 0] = -1.0
    jac[1, 1] = -1.0
    jac[0, 3] = 1.0
    jac[1, 4] = 1.0
    for k in range(x.shape[1] - 1):
        c0, s0 = math.cos(x[2, k]), math.sin(x[2, k])
        c1, s1 = math.cos(x[2, k + 1]), math.sin(x[2, k + 1])
        for link in range(corners.shape[0]):
            stiff, rest = constants[k, link, 0], constants[k, link, 1]
            r0x = corners[link, 0, 0] * c0 - corners[link, 0, 1] * s0
            r0y = corners[link, 0, 0] * s0 + corners[link, 0, 1] * c0
            r1x = corners[link, 1, 0] * c1 - corners[link, 1, 1] * s1
            r1y = corners[link, 1, 0] * s1 + corners[link, 1, 1] * c1
            dx = h + x[0, k + 1] - x[0, k] + r1x - r0x
            dy = x[1, k + 1] - x[1, k] + r1y - r0y
            length = math.sqrt(dx * dx + dy * dy)
            ratio = rest / length
            ex, ey = dx / length, dy / length
            gxx = stiff * (ratio * ex * ex + 1.0 - ratio)
            gxy = stiff * ratio * ex * ey
            gyy = stiff * (ratio * ey * ey + 1.0 - ratio)
            jac[0, 2], jac[1, 2] = r0y, -r0x
            jac[0, 5], jac[1, 5] = -r1y, r1x
            for i in range(6):
                gi_x = gxx * jac[0, i] + gxy * jac[1, i]
                gi_y = gxy * jac[0, i] + gyy * jac[1, i]
                for j in range(6):
                    blocks[k, i, j] += gi_x * jac[0, j] + gi_y * jac[1, j]
            tension = stiff * (1.0 - ratio)
            blocks[k, 2, 2] += tension * (dx * r0x + dy * r0y)
            blocks[k, 5, 5] -= tension * (dx * r1x + dy * r1y)


def _links(params: ChainParams, x: np.ndarray):
    """Per link of every bond (a ring's closing bond last): the link, rotated corners r0 (left) and r1 (right), link vector D."""
    u, v, phi = bonded(params, x)
    centre = np.stack([params.h * np.arange(-params.N, -params.N + u.size, dtype=float) + u, v])
    for link in bond_links(params):
        r0 = np.stack(rotate(link.left_corner, phi[:-1]))
        r1 = np.stack(rotate(link.right_corner, phi[1:]))
        yield link, r0, r1, centre[:, 1:] + r1 - centre[:, :-1] - r0


def chain_energy(params: ChainParams, x: np.ndarray) -> float:
    """Potential (1) summed over all links for any (3, 2N+1) state, whatever its ends hold.

    Unlike :meth:`NonlinearModel.energy` it does not check the state against the ends,
    so that invariance under rigid motions of the whole chain can be checked.
    """
    total = 0.0
    for link, _, _, D in _links(params, np.asarray(x, dtype=float)):
        total += np.sum(0.5 * link.stiffness * (np.hypot(D[0], D[1]) - link.rest_length) ** 2)
    return float(total)


def _cross(r: np.ndarray, t: np.ndarray) -> np.ndarray:
    return r[0] * t[1] - r[1] * t[0]


class NonlinearModel(Model):
    """Nonlinear springs model (i), potential (1) on the exact corner geometry; conservative."""

    name = "nonlinear"
    conservative = True
    equation = "eq. (1)"
    rotates = True
    force_kernel = nonlinear_forces_kernel
    end_kernel = nonlinear_end_kernel
    batch_kernel = nonlinear_batch_kernel
    graded_kernel = nonlinear_graded_kernel
    max_angle = REDUCTION_LIMIT

    @staticmethod
    def coefficients(params: ChainParams) -> np.ndarray:
        uniform = np.array([params.a, params.b, params.h, params.E1, params.E2, params.gap, params.d])
        return np.concatenate([uniform, *params.bond_stiffness]) if params.graded_stiffness else uniform

    def energy(self, params: ChainParams, x: np.ndarray) -> float:
        return chain_energy(params, check_state(params, x))

    def bond_energy(self, params: ChainParams, x: np.ndarray) -> np.ndarray:
        """Potential (1) of the four links of every bond, shape (..., n_bonds) for x (..., 3, 2N+1)."""
        x = bonded(params, x)
        du, dv, phi = np.diff(x[..., 0, :], axis=-1), np.diff(x[..., 1, :], axis=-1), x[..., 2, :]
        total = np.zeros(du.shape)
        for link in bond_links(params):
            r0x, r0y = rotate(link.left_corner, phi[..., :-1])
            r1x, r1y = rotate(link.right_corner, phi[..., 1:])
            length = np.hypot(params.h + du + r1x - r0x, dv + r1y - r0y)
            total += 0.5 * link.stiffness * (length - link.rest_length) ** 2
        return total

    def max_frequency(self, params: ChainParams) -> float:
        """The infinite linear chain's bound (:func:`.linear.max_frequency`): the Hessian at rest is eq. (3)'s K.

        A graded chain has no such closed form: the generic bound from the stiffness at rest."""
        return super().max_frequency(params) if params.graded else max_frequency(params)

    def forces(self, params: ChainParams, x: np.ndarray) -> np.ndarray:
        x = check_state(params, x)
        left = np.zeros((3, params.n_bonds))
        right = np.zeros((3, params.n_bonds))
        for link, r0, r1, D in _links(params, x):
            T = link.stiffness * (1.0 - link.rest_length / np.hypot(D[0], D[1])) * D
            left[:2] += T
            left[2] += _cross(r0, T)
            right[:2] -= T
            right[2] -= _cross(r1, T)
        out = scatter_bonds(params, left, right)
        return zero_held(params, out)

    def stiffness(self, params: ChainParams, x: np.ndarray) -> sp.csr_matrix:
        """Exact Hessian of the energy over the free degrees of freedom (symmetric, banded; O(N), compiled)."""
        x = check_state(params, x)
        links = bond_links(params)
        corners = np.array([[link.left_corner, link.right_corner] for link in links])
        # Per bond and link: its stiffness (the bonds of a graded chain differ) and rest length.
        constants = np.empty((params.n_bonds, len(links), 2))
        for index, link in enumerate(links):
            constants[:, index, 0] = link.stiffness
            constants[:, index, 1] = link.rest_length
        blocks = np.zeros((params.n_bonds, 6, 6))
        _hessian_blocks(np.ascontiguousarray(bonded(params, x)), params.h, corners, constants, blocks)
        return assemble_bond_blocks(blocks, params)
