"""Model (iii): the standard linear Cosserat chain, eq. (3), with coefficients derived from the geometry.

The forces are F = -K q with the constant stiffness matrix K of the bond energy

    P_bond = k_u/2 (u_k+1 - u_k)^2 + E1 b^2 (phi_k+1 - phi_k)^2
             + k_v/2 (v_k+1 - v_k - h (phi_k + phi_k+1)/2)^2,

which is the second-order expansion of the nonlinear potential (1) at rest.
Written per particle this is eq. (3) with the coupling 4 (h^2/d^2) E2 of eq. (2)
(the printed eq. (3) lacks the factor 4, which makes it non-symmetric; see
``docs/errata.md``):

    F_u   = k_u (u_k+1 - 2 u_k + u_k-1)
    F_v   = k_v (v_k+1 - 2 v_k + v_k-1 - h (phi_k+1 - phi_k-1) / 2)
    F_phi = 2 b^2 [D1 (phi_k+1 - 2 phi_k + phi_k-1) + D2 ((v_k+1 - v_k-1) / (2h) - phi_k)]
"""

from __future__ import annotations

from functools import lru_cache

import numpy as np
import scipy.sparse as sp
from numba import njit

from ..linalg import RootFactor
from ..params import ChainParams
from ..state import bonded, check_state, free_index, n_free, scatter_bonds, zero_held
from .base import BOND_BLOCK, FORCE_SIGNATURE, KERNEL_OPTIONS, Model, assemble_bond_blocks, put_six
from .trig import sincos


def cosserat_coefficients(params: ChainParams) -> np.ndarray:
    """Coefficients (k_u, k_v, h, 2 b^2 D1, 2 b^2 D2) of eqs. (2)-(3), derived from the geometry."""
    two_b2 = 2.0 * params.b**2
    return np.array([params.k_u, params.k_v, params.h, two_b2 * params.D1, two_b2 * params.D2])


#: Length of a uniform chain's coefficients (k_u, k_v, h, bend, couple); a graded chain's append
#: k_u, k_v, bend and couple of every bond, in that order (:func:`chain_coefficients`).
GRADED_OFFSET = 5


def bond_coefficients(params: ChainParams) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(k_u, k_v, 2 b^2 D1, 2 b^2 D2) of every bond, arrays (n_bonds,): the coefficients of
    :func:`cosserat_coefficients` with the bond's own E1 and E2 (linear in them)."""
    E1, E2 = params.bond_stiffness
    d2 = params.d**2
    two_b2 = 2.0 * params.b**2
    k_u = 2.0 * (E1 + params.gap**2 / d2 * E2)
    k_v = 8.0 * params.b**2 / d2 * E2
    return k_u, k_v, two_b2 * (E1 - params.h**2 / d2 * E2), two_b2 * (4.0 * params.h**2 / d2 * E2)


def chain_coefficients(params: ChainParams) -> np.ndarray:
    """The kernels' ``coef``: :func:`cosserat_coefficients`, and for a chain graded in its bonds every bond's after them."""
    uniform = cosserat_coefficients(params)
    return np.concatenate([uniform, *bond_coefficients(params)]) if params.graded_stiffness else uniform


@njit(inline="always", **KERNEL_OPTIONS)
def cosserat_site(k_u, k_v, h, bend, couple, u_prev, u, u_next, v_prev, v, v_next, a_prev, a, a_next):  # pragma: no cover - compiled
    """Forces (F_u, F_v, F_phi) of eqs. (2)-(3) on one particle from its neighbours.

    ``a_prev, a, a_next`` stand for the angles (eq. 3) or their sines (eq. 2);
    ``bend`` = 2 b^2 D1, ``couple`` = 2 b^2 D2.
    """
    f_u = k_u * (u_next - 2.0 * u + u_prev)
    f_v = k_v * (v_next - 2.0 * v + v_prev - 0.5 * h * (a_next - a_prev))
    f_phi = bend * (a_next - 2.0 * a + a_prev) + couple * ((v_next - v_prev) / (2.0 * h) - a)
    return f_u, f_v, f_phi


@njit(inline="always", **KERNEL_OPTIONS)
def cosserat_bond(k_u, k_v, h, bend, couple, du, dv, a0, a1):  # pragma: no cover - compiled
    """One bond's forces: (F_u, F_v) on its left particle (the right one gets minus them), F_phi on each.

    The gradient of P_bond (module docstring), with 2 E1 b^2 = bend + couple / 4 and
    k_v h / 2 = couple / (2 h); the forces of an end particle, which has one bond.
    """
    shear = dv - 0.5 * h * (a0 + a1)
    twist = (bend + 0.25 * couple) * (a1 - a0)
    lever = couple / (2.0 * h) * shear
    return k_u * du, k_v * shear, twist + lever, lever - twist


@njit(inline="always", **KERNEL_OPTIONS)
def cosserat_end(
    k_u, k_v, h, bend, couple, u_prev, u, u_next, v_prev, v, v_next, a_prev, a, a_next, side, ring
):  # pragma: no cover - compiled
    """Forces on an end column: eqs. (2)-(3) with both neighbours for a ring, else its one bond's.

    ``side`` 0 for column 0 (its bond on the right: the ``next`` values), 1 for the
    last column (its bond on the left: the ``prev`` values).
    """
    if ring:
        return cosserat_site(k_u, k_v, h, bend, couple, u_prev, u, u_next, v_prev, v, v_next, a_prev, a, a_next)
    if side == 0:
        f_u, f_v, f_phi, _ = cosserat_bond(k_u, k_v, h, bend, couple, u_next - u, v_next - v, a, a_next)
        return f_u, f_v, f_phi
    f_u, f_v, _, f_phi = cosserat_bond(k_u, k_v, h, bend, couple, u - u_prev, v - v_prev, a_prev, a)
    return -f_u, -f_v, f_phi


@njit(inline="always", **KERNEL_OPTIONS)
def cosserat_graded(x, coef, out, start, stop, sine):  # pragma: no cover - compiled
    """Eqs. (2)-(3) on columns start..stop-1 bond by bond, each bond with its own coefficients.

    ``sine``: a constant of the caller, the angles enter as sin phi (eq. 2) or phi
    (eq. 3). Bond k's (k_u, k_v, bend, couple) come from the coefficients' tail
    (:func:`chain_coefficients`), sliced from bond start-1 so that every index is
    0-based; the bond's forces are carried to the next column, as in the nonlinear kernel.
    """
    h = coef[2]
    n_bonds = (coef.size - GRADED_OFFSET) // 4
    first = GRADED_OFFSET + start - 1
    k_u = coef[first : GRADED_OFFSET + n_bonds]
    k_v = coef[first + n_bonds : GRADED_OFFSET + 2 * n_bonds]
    bend = coef[first + 2 * n_bonds : GRADED_OFFSET + 3 * n_bonds]
    couple = coef[first + 3 * n_bonds :]
    u, v, phi = x[0, start - 1 :], x[1, start - 1 :], x[2, start - 1 :]
    a0 = sincos(phi[0])[0] if sine else phi[0]
    a1 = sincos(phi[1])[0] if sine else phi[1]
    fu_prev, fv_prev, _, p_prev = cosserat_bond(k_u[0], k_v[0], h, bend[0], couple[0], u[1] - u[0], v[1] - v[0], a0, a1)
    a0 = a1
    out_u, out_v, out_phi = out[0, start:stop], out[1, start:stop], out[2, start:stop]
    for k in range(stop - start):
        a1 = sincos(phi[k + 2])[0] if sine else phi[k + 2]
        fu, fv, p0, p1 = cosserat_bond(
            k_u[k + 1], k_v[k + 1], h, bend[k + 1], couple[k + 1], u[k + 2] - u[k + 1], v[k + 2] - v[k + 1], a0, a1
        )
        out_u[k] = fu - fu_prev
        out_v[k] = fv - fv_prev
        out_phi[k] = p0 + p_prev
        fu_prev, fv_prev, p_prev = fu, fv, p1
        a0 = a1


@njit(inline="always", **KERNEL_OPTIONS)
def cosserat_end_columns(x, coef, out, first, last, ring, sine):  # pragma: no cover - compiled
    """The end columns of eqs. (2)-(3) (``sine`` as in :func:`cosserat_graded`), for either layout of ``coef``.

    A uniform chain's by :func:`cosserat_end` (a ring's seam by the interior formula, so
    its bits are the interior's); a graded chain's from its one or two bonds, each with
    its own coefficients (a ring's closing bond n-1 joins column n-1 to column 0).
    """
    n = x.shape[1]
    graded = coef.size > GRADED_OFFSET
    n_bonds = (coef.size - GRADED_OFFSET) // 4
    for side in range(2):
        if not ((side == 0 and first) or (side == 1 and last)):
            continue
        c = 0 if side == 0 else n - 1
        i, j = (c - 1) % n, (c + 1) % n
        a_i = sincos(x[2, i])[0] if sine else x[2, i]
        a_c = sincos(x[2, c])[0] if sine else x[2, c]
        a_j = sincos(x[2, j])[0] if sine else x[2, j]
        if not graded:
            out[0, c], out[1, c], out[2, c] = cosserat_end(
                coef[0], coef[1], coef[2], coef[3], coef[4], x[0, i], x[0, c], x[0, j], x[1, i], x[1, c], x[1, j],
                a_i, a_c, a_j, side, ring,
            )  # fmt: skip
            continue
        f_u = f_v = f_phi = 0.0
        if ring or side == 0:  # the bond on the right: c to j (bond c, or the closing bond n-1 from the last column)
            b = c
            fu, fv, p0, _ = cosserat_bond(
                coef[GRADED_OFFSET + b], coef[GRADED_OFFSET + n_bonds + b], coef[2], coef[GRADED_OFFSET + 2 * n_bonds + b],
                coef[GRADED_OFFSET + 3 * n_bonds + b], x[0, j] - x[0, c], x[1, j] - x[1, c], a_c, a_j,
            )  # fmt: skip
            f_u, f_v, f_phi = fu, fv, p0
        if ring or side == 1:  # the bond on the left: i to c (bond i)
            b = i
            fu, fv, _, p1 = cosserat_bond(
                coef[GRADED_OFFSET + b], coef[GRADED_OFFSET + n_bonds + b], coef[2], coef[GRADED_OFFSET + 2 * n_bonds + b],
                coef[GRADED_OFFSET + 3 * n_bonds + b], x[0, c] - x[0, i], x[1, c] - x[1, i], a_i, a_c,
            )  # fmt: skip
            f_u, f_v, f_phi = f_u - fu, f_v - fv, f_phi + p1
        out[0, c], out[1, c], out[2, c] = f_u, f_v, f_phi


@njit(inline="always", **KERNEL_OPTIONS)
def _cosserat_bond_rows(k_u, k_v, h, bend, couple, x, work, start, i):  # pragma: no cover - compiled
    """Bond start + i's 40 rows (the bond kernel's layout) into column i of the block's scratch ``work``,
    whose rows 40 and 41 hold the block's angles a (phi or sin phi) and da/dphi."""
    width = BOND_BLOCK
    one = np.uint64(1)
    k = start + i
    a0, a1 = work[40 * width + i], work[40 * width + i + one]
    da0, da1 = work[41 * width + 1 + i], work[41 * width + 1 + i + one]
    fx, fy, m0, m1 = cosserat_bond(k_u, k_v, h, bend, couple, x[0, k + one] - x[0, k], x[1, k + one] - x[1, k], a0, a1)
    work[i] = fx
    work[width + i] = fy
    work[2 * width + i] = m0
    work[3 * width + i] = m1
    twist = bend + 0.25 * couple
    lever = couple / (2.0 * h)
    shear0, shear1 = -0.5 * h * da0, -0.5 * h * da1  # ds/dphi0, ds/dphi1
    # Rows of the left particle's (fx, fy, m0), then the right one's (-fx, -fy, m1), over
    # (u0, v0, phi0, u1, v1, phi1).
    put_six(work, width, 4, i, -k_u, 0.0, 0.0, k_u, 0.0, 0.0)
    put_six(work, width, 10, i, 0.0, -k_v, k_v * shear0, 0.0, k_v, k_v * shear1)
    put_six(work, width, 16, i, 0.0, -lever, -twist * da0 + lever * shear0, 0.0, lever, twist * da1 + lever * shear1)
    put_six(work, width, 22, i, k_u, 0.0, 0.0, -k_u, 0.0, 0.0)
    put_six(work, width, 28, i, 0.0, k_v, -k_v * shear0, 0.0, -k_v, -k_v * shear1)
    put_six(work, width, 34, i, 0.0, -lever, twist * da0 + lever * shear0, 0.0, lever, -twist * da1 + lever * shear1)


@njit(inline="always", **KERNEL_OPTIONS)
def cosserat_bonds(x, coef, out, first, last, sine):  # pragma: no cover - compiled
    """Bonds first..last-1 of eqs. (2)-(3) with their exact Jacobian (the bond kernel's layout,
    :data:`~.base.BOND_ROWS`), ``sine`` as in :func:`cosserat_graded`, for either layout of ``coef``.

    The bond's forces (:func:`cosserat_bond`) are linear in (du, dv, a0, a1), with a = sin phi
    (eq. 2, da/dphi = cos phi) or phi (eq. 3); with T = bend + couple / 4 and
    L = couple / (2 h): fx = k_u du, fy = k_v s, m0 = T (a1 - a0) + L s, m1 = L s - T (a1 - a0),
    s = dv - h (a0 + a1) / 2. In blocks of :data:`~.base.BOND_BLOCK` bonds through scratch, the
    coefficients read from arrays (a uniform chain's from blocks of equal values), as the nonlinear
    model's bond kernel (SIMD across bonds).
    """
    graded = coef.size > GRADED_OFFSET
    n_bonds = (coef.size - GRADED_OFFSET) // 4
    h = coef[2]
    width = BOND_BLOCK
    work = np.empty(42 * width + 2)
    # A uniform chain's coefficients as blocks of equal values: one loop for both layouts (a second
    # copy of the inlined bond for the uniform chain doubled the compile).
    uniform = np.empty((4, width))
    for i in range(width):
        uniform[0, i] = coef[0]
        uniform[1, i] = coef[1]
        uniform[2, i] = coef[3]
        uniform[3, i] = coef[4]
    one = np.uint64(1)
    for begin in range(first, last, width):
        start = np.uint64(begin)
        m = np.uint64(min(width, last - begin))
        for i in range(m + one):
            phi = x[2, start + i]
            s, c = sincos(phi)
            work[40 * width + i] = s if sine else phi
            work[41 * width + 1 + i] = c if sine else 1.0
        k_u = coef[GRADED_OFFSET + begin :] if graded else uniform[0]
        k_v = coef[GRADED_OFFSET + n_bonds + begin :] if graded else uniform[1]
        bend = coef[GRADED_OFFSET + 2 * n_bonds + begin :] if graded else uniform[2]
        couple = coef[GRADED_OFFSET + 3 * n_bonds + begin :] if graded else uniform[3]
        for i in range(m):
            _cosserat_bond_rows(k_u[i], k_v[i], h, bend[i], couple[i], x, work, start, i)
        for row in range(40):
            for i in range(m):
                out[row, start + i] = work[row * width + i]


# Compiled at its first use (for FORCE_SIGNATURE), not at import: the report follows no orbit of this model,
# and with an empty cache it cost it its compilation (benchmarks/TIMINGS.md).
@njit(**KERNEL_OPTIONS)
def linear_bond_kernel(x, coef, out, first, last):  # pragma: no cover - compiled
    cosserat_bonds(x, coef, out, first, last, False)


# Compiled at its first use (for FORCE_SIGNATURE, by the engine), not at import: most runs, the report's among
# them, have no graded chain, and with an empty cache it cost them its compilation (benchmarks/TIMINGS.md).
@njit(**KERNEL_OPTIONS)
def linear_graded_kernel(x, coef, out, start, stop):  # pragma: no cover - compiled
    cosserat_graded(x, coef, out, start, stop, False)


@njit(FORCE_SIGNATURE, **KERNEL_OPTIONS)
def linear_forces_kernel(x, coef, out, start, stop):  # pragma: no cover - compiled
    k_u, k_v, h, bend, couple = coef[0], coef[1], coef[2], coef[3], coef[4]
    # 0-based slices for the three neighbours: no wrap-around arithmetic in the loop.
    m = stop - start
    u_prev, u, u_next = x[0, start - 1 : stop - 1], x[0, start:stop], x[0, start + 1 : stop + 1]
    v_prev, v, v_next = x[1, start - 1 : stop - 1], x[1, start:stop], x[1, start + 1 : stop + 1]
    p_prev, p, p_next = x[2, start - 1 : stop - 1], x[2, start:stop], x[2, start + 1 : stop + 1]
    out_u, out_v, out_phi = out[0, start:stop], out[1, start:stop], out[2, start:stop]
    for k in range(m):
        out_u[k], out_v[k], out_phi[k] = cosserat_site(
            k_u, k_v, h, bend, couple, u_prev[k], u[k], u_next[k], v_prev[k], v[k], v_next[k], p_prev[k], p[k], p_next[k]
        )


# Compiled at its first use (for END_SIGNATURE, by the engine), not at import: the report runs this model's
# chains clamped only, and with an empty cache it cost them its compilation (benchmarks/TIMINGS.md).
@njit(**KERNEL_OPTIONS)
def linear_end_kernel(x, coef, out, first, last, ring):  # pragma: no cover - compiled
    cosserat_end_columns(x, coef, out, first, last, ring, False)


@njit(inline="always", **KERNEL_OPTIONS)
def cosserat_batch(coef, x, angle, out):  # pragma: no cover - compiled
    """Eqs. (2)-(3) for a batch (3, n, B) with ``angle`` (n, B) standing for phi or sin phi."""
    n, size = x.shape[1], x.shape[2]
    k_u, k_v, h, bend, couple = coef[0], coef[1], coef[2], coef[3], coef[4]
    for k in range(1, n - 1):
        u_prev, u, u_next = x[0, k - 1], x[0, k], x[0, k + 1]
        v_prev, v, v_next = x[1, k - 1], x[1, k], x[1, k + 1]
        a_prev, a, a_next = angle[k - 1], angle[k], angle[k + 1]
        out_u, out_v, out_phi = out[0, k], out[1, k], out[2, k]
        for i in range(size):
            out_u[i], out_v[i], out_phi[i] = cosserat_site(
                k_u[i], k_v[i], h[i], bend[i], couple[i], u_prev[i], u[i], u_next[i], v_prev[i], v[i], v_next[i], a_prev[i], a[i], a_next[i]
            )


@njit(**KERNEL_OPTIONS)
def linear_batch_kernel(x, coef, out):  # pragma: no cover - compiled
    cosserat_batch(coef, x, x[2], out)


def cosserat_forces(params: ChainParams, u: np.ndarray, v: np.ndarray, angle: np.ndarray) -> np.ndarray:
    """Right-hand side of eqs. (2)-(3) with ``angle`` standing for phi (eq. 3) or sin phi (eq. 2).

    Shapes (2N+1,) each; returns (3, 2N+1), bond by bond (:func:`cosserat_bond`), zero
    at the degrees of freedom the ends hold fixed.
    """
    k_u, k_v, bend, couple = bond_coefficients(params)
    h = params.h
    u, v, angle = bonded(params, np.stack([u, v, angle]))
    du, dv = np.diff(u), np.diff(v)
    shear = dv - 0.5 * h * (angle[1:] + angle[:-1])
    twist = (bend + 0.25 * couple) * np.diff(angle)
    lever = couple / (2.0 * h) * shear
    left = np.stack([k_u * du, k_v * shear, twist + lever])
    right = np.stack([-k_u * du, -k_v * shear, lever - twist])
    out = scatter_bonds(params, left, right)
    return zero_held(params, out)


def cosserat_bond_energy(params: ChainParams, u: np.ndarray, v: np.ndarray, angle: np.ndarray) -> np.ndarray:
    """P_bond of every bond (module docstring) with ``angle`` standing for phi (eq. 3) or sin phi (eq. 2).

    Shapes (..., 2N+1) each; returns (..., n_bonds), bond k joining columns k and k+1
    (a ring's closing bond last).
    """
    u, v, angle = (bonded(params, a) for a in (u, v, angle))
    shear = np.diff(v, axis=-1) - 0.5 * params.h * (angle[..., 1:] + angle[..., :-1])
    k_u, k_v, _, _ = bond_coefficients(params)
    E1 = params.bond_stiffness[0]
    return 0.5 * k_u * np.diff(u, axis=-1) ** 2 + E1 * params.b**2 * np.diff(angle, axis=-1) ** 2 + 0.5 * k_v * shear**2


def bond_stiffness_blocks(params: ChainParams) -> np.ndarray:
    """Hessian (n_bonds, 6, 6) of every bond's P_bond over (u_k, v_k, phi_k, u_k+1, v_k+1, phi_k+1)."""
    g_u = np.array([-1.0, 0, 0, 1, 0, 0])
    g_phi = np.array([0, 0, -1.0, 0, 0, 1])
    g_shear = np.array([0, -1.0, -params.h / 2, 0, 1, -params.h / 2])
    k_u, k_v, _, _ = bond_coefficients(params)
    E1 = params.bond_stiffness[0]
    return (
        k_u[:, None, None] * np.outer(g_u, g_u)
        + (2 * E1 * params.b**2)[:, None, None] * np.outer(g_phi, g_phi)
        + k_v[:, None, None] * np.outer(g_shear, g_shear)
    )


def stiffness_root(params: ChainParams, *, before: bool = False) -> tuple[np.ndarray, ...]:
    """The rows of A with K = A^T A over the free degrees of freedom (an open chain), for :class:`~cosserat_chain.linalg.RootFactor`.

    P_bond is a sum of three squares (module docstring): each bond gives the rows sqrt(k_u) g_u,
    sqrt(2 E1 b^2) g_phi and sqrt(k_v) g_shear over its six degrees of freedom
    (:func:`bond_stiffness_blocks`), so that K, the sum of their outer products, is A^T A. Returns
    ``values`` (rows, 6), row i's entries from its first free column ``starts[i]`` on (the held degrees
    of freedom dropped), and with ``before`` the rows' places in the mixed form (:func:`free_bond_rows`).

    Raises
    ------
    ValueError
        For a ring, whose first and last bonds wrap around the band.
    """
    if params.periodic:
        raise ValueError("a ring's stiffness has no banded square root (its first and last bonds wrap around the band)")
    k_u, k_v, _, _ = bond_coefficients(params)
    E1 = params.bond_stiffness[0]
    bonds = params.n_particles - 1
    shape = np.array([[-1.0, 0, 0, 1, 0, 0], [0, 0, -1.0, 0, 0, 1], [0, -1.0, -params.h / 2, 0, 1, -params.h / 2]])
    weights = np.sqrt(np.stack(np.broadcast_arrays(k_u, 2 * E1 * params.b**2, k_v), axis=-1) * np.ones((bonds, 1)))
    values, starts, placed = free_bond_rows(params, (weights[:, :, None] * shape).reshape(3 * bonds, 6))
    return (values, starts, placed) if before else (values, starts)


def free_bond_rows(params: ChainParams, rows: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Rows over each bond's six degrees of freedom (u_k, v_k, phi_k, u_k+1, v_k+1, phi_k+1), the same number for
    every bond and in bond order, as rows over the free degrees of freedom (:class:`~cosserat_chain.linalg.RootFactor`'s
    form): ``values`` (rows, 6) from each row's first free column ``starts`` on, the held degrees of freedom dropped,
    and ``before``, the number of free degrees of freedom of the particles up to each row's bond's left one (where
    :class:`~cosserat_chain.linalg.MixedFactor` puts the row's multiplier). Rows without a free column are left out.

    Raises
    ------
    ValueError
        For a ring, whose first and last bonds wrap around the band.
    """
    if params.periodic:
        raise ValueError("a ring's stiffness has no banded square root (its first and last bonds wrap around the band)")
    source, target, starts, before = _free_bond_layout(params, rows.shape[0] // (params.n_particles - 1))
    values = np.zeros((starts.size, 6))
    values.reshape(-1)[target] = rows.reshape(-1)[source]
    return values, starts, before


@lru_cache(maxsize=16)
def _free_bond_layout(params: ChainParams, per_bond: int) -> tuple[np.ndarray, ...]:
    """Where :func:`free_bond_rows` puts each entry (constant per chain): the flat indices of the entries read
    (``source``) and written (``target``), and the rows' ``starts`` and ``before``."""
    bonds = params.n_particles - 1
    position = np.full(3 * params.n_particles, -1)
    position[free_index(params)] = np.arange(n_free(params))
    window = np.repeat(position[3 * np.arange(bonds)[:, None] + np.arange(6)], per_bond, axis=0)  # free position or -1
    kept = np.flatnonzero(np.any(window >= 0, axis=1))
    before = np.searchsorted(free_index(params), 3 * (kept // per_bond) + 3)
    window = window[kept]
    starts = np.where(window >= 0, window, np.iinfo(np.int64).max).min(axis=1)
    offsets = np.where(window >= 0, window - starts[:, None], -1)
    row, column = np.nonzero(offsets >= 0)
    out = (kept[row] * 6 + column, row * 6 + offsets[row, column], starts, before)
    for array in out:
        array.flags.writeable = False
    return out


def rest_solve(params: ChainParams, rhs: np.ndarray) -> np.ndarray:
    """K^-1 ``rhs`` (packed free degrees of freedom) with K of eq. (3), every model's K at rest, through its square root.

    :func:`stiffness_root`'s rows reduced by Givens rotations (:class:`~cosserat_chain.linalg.RootFactor`):
    a factor of K's rounded entries loses a clamped chain's bending modes, whose eigenvalue falls
    like N^-4 (its compliance 0.15 % off at N = 10^4, 33 % at 3 10^4, 80 % at 10^5 by the band LU;
    refined in extended precision, 1.1e-5 and 55 % off at the last two), where R keeps them
    (docs/statics.md: 1.8e-14 from the closed form at N = 10^5).

    Raises
    ------
    ValueError
        For a ring (no banded square root), or where K is singular (a chain free to move rigidly).
    """
    x = RootFactor(*stiffness_root(params), n_free(params)).solve(rhs)
    if not np.all(np.isfinite(x)):
        raise ValueError("the stiffness at rest is singular: the chain can move rigidly")
    return x


def stiffness_matrix(params: ChainParams) -> sp.csr_matrix:
    """The constant stiffness matrix K of eq. (3) over the free degrees of freedom (symmetric; banded for an open chain)."""
    return assemble_bond_blocks(np.ascontiguousarray(bond_stiffness_blocks(params)), params)


class LinearModel(Model):
    """Standard linear Cosserat model (iii), eq. (3) with geometry-derived coefficients; conservative."""

    name = "linear"
    conservative = True
    equation = "eq. (3)"
    # Quadratic in phi: a model of small rotations, not periodic in them.
    rotates = False
    force_kernel = linear_forces_kernel
    end_kernel = linear_end_kernel
    batch_kernel = linear_batch_kernel
    graded_kernel = linear_graded_kernel
    bond_kernel = linear_bond_kernel

    @staticmethod
    def coefficients(params: ChainParams) -> np.ndarray:
        return chain_coefficients(params)

    def forces(self, params: ChainParams, x: np.ndarray) -> np.ndarray:
        u, v, phi = check_state(params, x)
        return cosserat_forces(params, u, v, phi)

    def stiffness(self, params: ChainParams, x: np.ndarray | None = None) -> sp.csr_matrix:
        return stiffness_matrix(params)

    def energy(self, params: ChainParams, x: np.ndarray) -> float:
        return float(np.sum(self.bond_energy(params, check_state(params, x))))

    def bond_energy(self, params: ChainParams, x: np.ndarray) -> np.ndarray:
        """P_bond of every bond (module docstring), shape (..., n_bonds) for x (..., 3, 2N+1)."""
        x = np.asarray(x, dtype=float)
        return cosserat_bond_energy(params, x[..., 0, :], x[..., 1, :], x[..., 2, :])

    def max_frequency(self, params: ChainParams) -> float:
        """The infinite chain's bound :func:`max_frequency` (independent of N, cheap); a graded chain's generic one."""
        return super().max_frequency(params) if params.graded else max_frequency(params)


def bloch_stiffness(params: ChainParams, q: np.ndarray) -> np.ndarray:
    """Stiffness of the infinite chain for the wave exp(i q k), shape (len(q), 3, 3), Hermitian.

    Rows and columns (u, v, phi); ``q`` is the wavenumber per particle in [0, pi].
    """
    k_u, k_v, h, bend, couple = cosserat_coefficients(params)
    q = np.atleast_1d(np.asarray(q, dtype=float))
    s2 = 4.0 * np.sin(q / 2) ** 2
    out = np.zeros((q.size, 3, 3), dtype=complex)
    out[:, 0, 0] = k_u * s2
    out[:, 1, 1] = k_v * s2
    out[:, 1, 2] = 1j * k_v * h * np.sin(q)
    out[:, 2, 1] = -1j * couple / h * np.sin(q)
    out[:, 2, 2] = bend * s2 + couple
    return out


@lru_cache(maxsize=64)
def max_frequency(params: ChainParams) -> float:
    """Highest angular frequency of the infinite linear chain, an upper bound for any finite clamped one.

    The clamped chain's stiffness is a principal block of the infinite chain's, so
    its frequencies lie inside the infinite chain's bands. Kept per chain (the 64
    latest, as :meth:`.base.Model.max_frequency`): 513 eigenvalue problems, which every
    run would pay again for its time step's stability check (benchmarks/TIMINGS.md).
    """
    q = np.linspace(0.0, np.pi, 513)
    scale = 1.0 / np.sqrt(np.array(params.inertia))
    dynamical = bloch_stiffness(params, q) * scale[:, None] * scale[None, :]
    return float(np.sqrt(np.max(np.linalg.eigvalsh(dynamical))))
