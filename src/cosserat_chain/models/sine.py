"""Model (ii): the sine-Cosserat chain, eq. (2).

Linear in the displacements, with the angles entering only through sin(phi):
the forces are those of the linear model (iii) evaluated at (u, v, sin phi),

    F_sine(u, v, phi) = F_linear(u, v, sin phi).

Eq. (2) is **not** the gradient of any potential: dF_v,k / dphi_k+1 carries a
factor cos(phi_k+1) that dF_phi,k+1 / dv_k lacks, so its Jacobian is not
symmetric away from phi = 0 and no energy exists. The model has no ``energy``;
its stiffness is the non-symmetric Jacobian -dF/dq = K diag(1, 1, cos phi).
At phi = 0 it linearises to the linear model, and it supports full rotations.
"""

from __future__ import annotations

from functools import lru_cache

import numpy as np
import scipy.sparse as sp
from numba import njit
from scipy.linalg import cholesky_banded

from ..linalg import BANDWIDTH, BandMatrix, StiffnessRows, from_upper_bands, upper_bands
from ..params import ChainParams
from ..state import check_state, pack
from .base import FORCE_SIGNATURE, KERNEL_OPTIONS, Model
from .linear import (
    chain_coefficients,
    cosserat_batch,
    cosserat_bond_energy,
    cosserat_bonds,
    cosserat_end_columns,
    cosserat_forces,
    cosserat_graded,
    cosserat_site,
    max_frequency,
    stiffness_matrix,
    stiffness_root,
)
from .trig import sincos


def _chain_rule(params: ChainParams, x: np.ndarray) -> np.ndarray:
    """The diagonal C = diag(1, 1, cos phi) over the free degrees of freedom: dF_sine/dq = dF_linear/dq C."""
    return pack(params, np.vstack([np.ones_like(x[:2]), np.cos(x[2:3])]))


@njit(cache=True, nogil=True)
def _columns_scaled(band, scale):  # pragma: no cover - compiled
    """band's matrix times diag(scale) in band storage: entry t of storage row r holds column r + t - 2B, whose
    factor sits at scale[r + t] (zero outside the matrix). One loop where NumPy's product over a sliding window
    of ``scale`` walked a strided view (benchmarks/TIMINGS.md)."""
    out = np.empty_like(band)
    for r in range(band.shape[0]):
        for t in range(band.shape[1]):
            out[r, t] = band[r, t] * scale[r + t]
    return out


@njit(cache=True, nogil=True)
def _similar_band(columns, scale):  # pragma: no cover - compiled
    """U C U^T in band storage (:class:`~cosserat_chain.linalg.BandMatrix`) from U's columns
    (``columns[k, d] = U[k - B + d, k]``, :func:`_linear_factor_columns`) and C = diag(``scale``).

    The sum of the rank-one terms (U[:, k] c_k) U[:, k]^T for k from the last column down:
    each entry gets its products in the order of SciPy's CSR product ``U @ diags(c) @ U.T``
    (the same bits), in fixed (B + 1) x (B + 1) blocks where that product and its conversion to
    the band took most of the sine model's stability check on a long chain (benchmarks/TIMINGS.md).
    Rows of U before the first are zero columns of ``columns``: their terms add zeros.
    """
    n = columns.shape[0]
    out = np.zeros((n + 2 * BANDWIDTH, 2 * BANDWIDTH + 1))
    for k in range(n - 1, -1, -1):
        for da in range(BANDWIDTH + 1):
            term = columns[k, da] * scale[k]
            row = out[k + da]  # row BANDWIDTH + a of the storage, a = k - BANDWIDTH + da
            for db in range(BANDWIDTH + 1):
                row[BANDWIDTH + db - da] += term * columns[k, db]
    return out


@lru_cache(maxsize=16)
def _linear_factor_bands(params: ChainParams) -> np.ndarray:
    """U with U^T U the linear model's stiffness (banded Cholesky; constant per chain) in LAPACK's upper storage."""
    return cholesky_banded(upper_bands(stiffness_matrix(params)))


@lru_cache(maxsize=16)
def _linear_factor_columns(params: ChainParams) -> np.ndarray:
    """U's columns by rows, ``out[k, d] = U[k - B + d, k]`` (B = :data:`~cosserat_chain.linalg.BANDWIDTH`; zero
    above the matrix and beyond U's band), for :func:`_similar_band`."""
    bands = _linear_factor_bands(params)
    width, n = bands.shape[0] - 1, bands.shape[1]
    if width > BANDWIDTH:
        raise ValueError(f"the linear stiffness has half-bandwidth {width}, more than the chain's {BANDWIDTH}")
    columns = np.zeros((n, BANDWIDTH + 1))
    columns[:, BANDWIDTH - width :] = bands.T
    for k in range(min(BANDWIDTH, n)):
        columns[k, : BANDWIDTH - k] = 0.0  # LAPACK leaves the storage above the matrix's first row unread
    columns.flags.writeable = False
    return columns


@lru_cache(maxsize=16)
def _linear_factor(params: ChainParams) -> sp.csr_matrix:
    """U with U^T U the linear model's stiffness (:func:`_linear_factor_bands`) as a sparse matrix."""
    return from_upper_bands(_linear_factor_bands(params))


@lru_cache(maxsize=16)
def _linear_band(params: ChainParams) -> np.ndarray:
    """The linear model's stiffness in band storage (:class:`~cosserat_chain.linalg.BandMatrix`; constant per chain)."""
    data = BandMatrix.from_sparse(stiffness_matrix(params)).data
    data.flags.writeable = False
    return data


@njit(FORCE_SIGNATURE, **KERNEL_OPTIONS)
def sine_forces_kernel(x, coef, out, start, stop):  # pragma: no cover - compiled
    k_u, k_v, h, bend, couple = coef[0], coef[1], coef[2], coef[3], coef[4]
    # One sine per particle: sin(phi) of the previous and current columns are carried
    # (recurrences the vectoriser recognises); 0-based slices as in the linear kernel.
    s_prev = sincos(x[2, start - 1])[0]
    s_cur = sincos(x[2, start])[0]
    u_prev, u, u_next = x[0, start - 1 : stop - 1], x[0, start:stop], x[0, start + 1 : stop + 1]
    v_prev, v, v_next = x[1, start - 1 : stop - 1], x[1, start:stop], x[1, start + 1 : stop + 1]
    p_next = x[2, start + 1 : stop + 1]
    out_u, out_v, out_phi = out[0, start:stop], out[1, start:stop], out[2, start:stop]
    for k in range(stop - start):
        s_next = sincos(p_next[k])[0]
        out_u[k], out_v[k], out_phi[k] = cosserat_site(
            k_u, k_v, h, bend, couple, u_prev[k], u[k], u_next[k], v_prev[k], v[k], v_next[k], s_prev, s_cur, s_next
        )
        s_prev = s_cur
        s_cur = s_next


# Compiled at its first use (for END_SIGNATURE, by the engine), not at import: the report runs this model's
# chains clamped only, and with an empty cache it cost them its compilation (benchmarks/TIMINGS.md).
@njit(**KERNEL_OPTIONS)
def sine_end_kernel(x, coef, out, first, last, ring):  # pragma: no cover - compiled
    cosserat_end_columns(x, coef, out, first, last, ring, True)


# Compiled at its first use (for FORCE_SIGNATURE, by the engine), not at import: most runs, the report's among
# them, have no graded chain, and with an empty cache it cost them its compilation (benchmarks/TIMINGS.md).
@njit(**KERNEL_OPTIONS)
def sine_graded_kernel(x, coef, out, start, stop):  # pragma: no cover - compiled
    cosserat_graded(x, coef, out, start, stop, True)


@njit(FORCE_SIGNATURE, **KERNEL_OPTIONS)
def sine_bond_kernel(x, coef, out, first, last):  # pragma: no cover - compiled
    cosserat_bonds(x, coef, out, first, last, True)


@njit(**KERNEL_OPTIONS)
def sine_batch_kernel(x, coef, out):  # pragma: no cover - compiled
    phi = x[2]
    sines = np.empty_like(phi)
    for k in range(phi.shape[0]):
        for i in range(phi.shape[1]):
            sines[k, i] = sincos(phi[k, i])[0]
    cosserat_batch(coef, x, sines, out)


class SineModel(Model):
    """Sine-Cosserat model (ii), eq. (2): not conservative (see the module docstring)."""

    name = "sine"
    conservative = False
    equation = "eq. (2)"
    rotates = True
    force_kernel = sine_forces_kernel
    end_kernel = sine_end_kernel
    batch_kernel = sine_batch_kernel
    graded_kernel = sine_graded_kernel
    bond_kernel = sine_bond_kernel

    @staticmethod
    def coefficients(params: ChainParams) -> np.ndarray:
        return chain_coefficients(params)

    def forces(self, params: ChainParams, x: np.ndarray) -> np.ndarray:
        u, v, phi = check_state(params, x)
        return cosserat_forces(params, u, v, np.sin(phi))

    def stiffness(self, params: ChainParams, x: np.ndarray) -> sp.csr_matrix:
        x = check_state(params, x)
        return (stiffness_matrix(params) @ sp.diags(_chain_rule(params, x))).tocsr()

    def stiffness_band(self, params: ChainParams, x: np.ndarray) -> BandMatrix:
        """:meth:`stiffness` K C in band storage: the linear model's band (kept per chain) times C's entry of each
        column, O(N) and without a sparse product (the same values bit for bit: one product an entry either way).

        Raises
        ------
        ValueError
            For a ring (its matrices are not banded).
        """
        linear = _linear_band(params)
        scale = np.zeros(linear.shape[0] + 2 * BANDWIDTH)
        scale[2 * BANDWIDTH : -2 * BANDWIDTH] = _chain_rule(params, check_state(params, x))
        return BandMatrix(_columns_scaled(linear, scale))

    def stiffness_rows(self, params: ChainParams, x: np.ndarray) -> StiffnessRows:
        """K C = A^T (A C) with A the linear model's square-root rows (:func:`~.linear.stiffness_root`) and
        C = diag(1, 1, cos phi): left A's rows, right A C's, and no G.

        Raises
        ------
        ValueError
            For a ring (its matrices are not banded).
        """
        left, starts, before = stiffness_root(params, before=True)
        scale = np.append(_chain_rule(params, check_state(params, x)), np.zeros(BANDWIDTH))
        return StiffnessRows(left, left * scale[starts[:, None] + np.arange(BANDWIDTH + 1)], starts, before, None)

    def symmetric_similar(self, params: ChainParams, x: np.ndarray) -> sp.csr_matrix | None:
        """U C U^T, similar to the stiffness K C (K = U^T U the linear model's, C = diag(1, 1, cos phi)).

        U^-T (U^T U C) U^T = U C U^T: symmetric and banded, with the eigenvalues of the
        non-symmetric stiffness, which are therefore real. By Sylvester's law of inertia
        it has as many negative eigenvalues as C has negative entries: the chain loses
        stability when a particle turns beyond pi/2.
        """
        x = check_state(params, x)
        if params.periodic or params.rigid_modes:
            # The linear stiffness is then singular (rigid motions) or not banded (the
            # ring's corner blocks): no banded factor, and the dense solvers take over.
            return None
        factor = _linear_factor(params)
        return (factor @ sp.diags(_chain_rule(params, x)) @ factor.T).tocsr()

    def symmetric_similar_band(self, params: ChainParams, x: np.ndarray) -> BandMatrix | None:
        """:meth:`symmetric_similar` assembled in band storage, O(N) (the same values bit for bit)."""
        x = check_state(params, x)
        if params.periodic or params.rigid_modes:
            return None
        return BandMatrix(_similar_band(_linear_factor_columns(params), _chain_rule(params, x)))

    def bond_energy(self, params: ChainParams, x: np.ndarray) -> np.ndarray:
        """The linear model's P_bond at (u, v, sin phi), shape (..., 2N) for x (..., 3, 2N+1).

        Eq. (2) has no potential (module docstring); this is the energy whose
        gradient gives its forces in linearised rotations, and it is 2 pi-periodic
        in the angles, as the forces are.
        """
        x = np.asarray(x, dtype=float)
        return cosserat_bond_energy(params, x[..., 0, :], x[..., 1, :], np.sin(x[..., 2, :]))

    def max_frequency(self, params: ChainParams) -> float:
        """The infinite linear chain's bound (:func:`.linear.max_frequency`): eq. (2) linearises to eq. (3) at rest.

        A graded chain has no such closed form: the generic bound from the stiffness at rest."""
        return super().max_frequency(params) if params.graded else max_frequency(params)
