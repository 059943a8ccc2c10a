"""The interface every chain model offers, and the registry of models by name.

Contract
--------
A model turns a configuration ``x`` (3, 2N+1) into the internal generalised forces
on the particles (the right-hand sides of eqs. (2)-(3) without loads and
viscosity). Every model provides

* ``force_kernel``: a compiled function with signature :data:`FORCE_SIGNATURE`,
  ``kernel(x, coef, out, start, stop)``, that overwrites ``out[:, start:stop]``
  with the forces on columns start..stop-1 (1 <= start < stop <= 2N). It reads
  only columns start-1..stop, so disjoint column ranges can be computed by
  different threads. The compiled integrators call models only through it.
* ``coefficients(params)``: the flat float64 array ``coef`` the kernel reads.
* ``forces(params, x)``: a NumPy twin of the kernel (clamped columns zero),
  tested against it.
* ``stiffness(params, x)``: the sparse matrix -dF/dq over the free degrees of
  freedom (ordering in :mod:`cosserat_chain.state`). For conservative models it
  is the Hessian of the energy, symmetric.
* ``energy(params, x)`` (conservative models only): the potential energy.

Numerical methods receive a :class:`Model` and never import a concrete one;
adding a model means one module and one :func:`register_model` call.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from collections.abc import Callable
from typing import ClassVar

import numpy as np
import scipy.sparse as sp
from numba import types

from ..params import ChainParams
from ..state import check_state

#: Signature of every compiled force kernel: (x, coef, out, start, stop) -> None.
FORCE_SIGNATURE = types.void(types.float64[:, ::1], types.float64[::1], types.float64[:, ::1], types.int64, types.int64)
#: The first-class function type compiled integrators take, so that one compiled
#: (and cached) integrator serves every model.
FORCE_KERNEL_TYPE = types.FunctionType(FORCE_SIGNATURE)
#: Numba options of the compiled hot loops (force kernels, integrators).
#: ``error_model="numpy"``: a division by zero gives inf or nan instead of raising,
#: which keeps a test and a branch out of every division. ``fastmath={"contract"}``
#: and no other flag: ``a * b + c`` may become one fused multiply-add (one rounding
#: instead of two), as gcc compiles C by default at ``-O3 -march=native``; about
#: +25 % on the nonlinear kernel. No reassociation (sums keep their order) and no
#: nnan/ninf (they would delete the finiteness checks).
KERNEL_OPTIONS = {"cache": True, "nogil": True, "error_model": "numpy", "fastmath": {"contract"}}


class Model(ABC):
    """A discrete chain model (see the module docstring for the contract)."""

    name: ClassVar[str]
    #: Whether the forces are minus the gradient of :meth:`energy`.
    conservative: ClassVar[bool]
    #: Paper reference, e.g. "eq. (2)".
    equation: ClassVar[str]
    force_kernel: ClassVar[Callable[..., None]]

    @staticmethod
    @abstractmethod
    def coefficients(params: ChainParams) -> np.ndarray:
        """Flat float64 array of the coefficients ``force_kernel`` reads."""

    @abstractmethod
    def forces(self, params: ChainParams, x: np.ndarray) -> np.ndarray:
        """Internal generalised forces (3, 2N+1) at ``x``; NumPy twin of the kernel."""

    @abstractmethod
    def stiffness(self, params: ChainParams, x: np.ndarray) -> sp.csr_matrix:
        """-dF/dq over the free degrees of freedom at ``x``, shape (3(2N-1), 3(2N-1))."""

    def energy(self, params: ChainParams, x: np.ndarray) -> float:
        """Potential energy at ``x``.

        Raises
        ------
        TypeError
            For a model that is not conservative.
        """
        raise TypeError(f"the {self.name} model ({self.equation}) is not conservative: it has no potential energy")

    def compiled_forces(self, params: ChainParams, x: np.ndarray) -> np.ndarray:
        """Forces from the compiled kernel, same layout as :meth:`forces`."""
        x = check_state(params, x)
        out = np.zeros_like(x)
        type(self).force_kernel(x, self.coefficients(params), out, 1, x.shape[1] - 1)
        return out

    def __repr__(self) -> str:
        return f"<model {self.name!r}: {self.equation}>"


_REGISTRY: dict[str, Model] = {}


def register_model(model: Model) -> Model:
    """Make ``model`` available to :func:`get_model` under ``model.name``."""
    _REGISTRY[model.name] = model
    return model


def get_model(model: str | Model) -> Model:
    """The registered model of that name (a :class:`Model` passes through).

    Raises
    ------
    ValueError
        For an unknown name, listing the known ones.
    """
    if isinstance(model, Model):
        return model
    try:
        return _REGISTRY[model]
    except KeyError:
        raise ValueError(f"model must be one of {sorted(_REGISTRY)}, got {model!r}") from None


def available_models() -> tuple[str, ...]:
    """Names of the registered models, in registration order."""
    return tuple(_REGISTRY)


def assemble_bond_blocks(blocks: np.ndarray, n_particles: int, diagonal: np.ndarray | None = None) -> sp.csr_matrix:
    """Sparse matrix over the free degrees of freedom from per-bond 6x6 blocks.

    Parameters
    ----------
    blocks : ndarray, shape (n_particles - 1, 6, 6)
        Block of bond k (particles k, k+1 as array columns) over
        (u_k, v_k, phi_k, u_k+1, v_k+1, phi_k+1).
    n_particles : int
    diagonal : ndarray, shape (3, n_particles), optional
        Extra per-degree-of-freedom diagonal terms.

    Returns
    -------
    scipy.sparse.csr_matrix
        Entries on clamped degrees of freedom are dropped.
    """
    n_bonds = n_particles - 1
    cols = np.arange(n_bonds)
    # Global free index 3 (column - 1) + row, or -1 for the clamped columns.
    local = np.concatenate([3 * (cols[:, None] - 1) + np.arange(3), 3 * cols[:, None] + np.arange(3)], axis=1)
    local[:, :3][cols == 0] = -1
    local[:, 3:][cols + 1 == n_particles - 1] = -1
    rows = np.broadcast_to(local[:, :, None], blocks.shape)
    columns = np.broadcast_to(local[:, None, :], blocks.shape)
    keep = (rows >= 0) & (columns >= 0)
    size = 3 * (n_particles - 2)
    matrix = sp.coo_matrix((blocks[keep], (rows[keep], columns[keep])), shape=(size, size))
    if diagonal is not None:
        matrix = matrix + sp.diags(np.ascontiguousarray(diagonal[:, 1:-1].T).reshape(-1))
    return matrix.tocsr()
