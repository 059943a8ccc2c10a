"""The interface every chain model offers, and the registry of models by name.

Contract
--------
A model turns a configuration ``x`` (3, 2N+1) into the internal generalised forces
on the particles (the right-hand sides of eqs. (2)-(3) without loads and
viscosity). Every model provides

* ``force_kernel``: a compiled function with signature :data:`FORCE_SIGNATURE`,
  ``kernel(x, coef, out, start, stop)``, that overwrites ``out[:, start:stop]``
  with the forces on the interior columns start..stop-1 (1 <= start < stop <= 2N),
  each with a neighbour on either side. It reads only columns start-1..stop, so
  disjoint column ranges can be computed by different threads. Its loops over
  columns must vectorise (no branch in a loop body, 0-based slices, each bond
  computed once: carried to the next column or kept in scratch, :func:`stack_floats`).
* ``end_kernel`` (optional: a model without it runs clamped chains only):
  signature :data:`END_SIGNATURE`, ``kernel(x, coef, out, first, last, ring)``,
  overwrites the forces on column 0 (if ``first``) and column 2N (if ``last``).
  Column 0 has a bond on its right only and column 2N on its left only, unless
  ``ring``: then column 2N is bonded to column 0 as to a neighbour h further on.
  A kernel of its own, not a branch of ``force_kernel``: end code in the chain
  kernel, even never run, cost the paper's clamped chain 10 % of its step.
  Neither kernel knows which degrees of freedom the ends hold fixed: the engine
  zeroes their forces (:func:`cosserat_chain.state.held`).
* ``batch_kernel``: the interior forces for a batch of B chains stored
  batch-innermost, signature :data:`BATCH_FORCE_SIGNATURE`, ``kernel(x, coef, out)``
  with x and out (3, 2N+1, B) and coef (c, B), one column of coefficients per
  member; it overwrites columns 1..2N-1 of every member. Its innermost loop runs
  over the members, so a batch of short chains fills the SIMD lanes. Member b's
  forces must equal ``force_kernel`` on member b to the last bit: both call the
  same inline per-bond (or per-particle) function. (A batch's end columns come from
  ``end_kernel``, member by member: the same code, so the same bits.)
* ``graded_kernel`` (optional: a model without it runs uniform chains only): the
  interior forces of a chain whose bonds differ (``ChainParams.E1_factors``,
  ``E2_factors``), signature :data:`FORCE_SIGNATURE`, reading the per-bond
  coefficients that ``coefficients`` appends for such a chain. A kernel of its
  own, so that the uniform chain's loop reads no per-bond array; ``end_kernel``
  reads either layout (the end columns are not the hot loop). A graded chain runs
  as a batch of one (:func:`cosserat_chain.numerics.engine.split`).
* ``bond_kernel`` (optional): every bond's forces and their exact Jacobian, signature
  :data:`FORCE_SIGNATURE`, ``kernel(x, coef, out, first, last)``, overwriting
  ``out[:, first:last]`` (:data:`BOND_ROWS` rows) for the bonds first..last-1 of an open chain
  (bond k joins columns k and k+1): rows 0-3 the bond's (fx, fy) on its left particle (the
  right one gets minus them) and its moments m0 on the left, m1 on the right particle; rows
  4 + 6 r + c the derivative of force r by degree of freedom c, both over (u_k, v_k, phi_k,
  u_k+1, v_k+1, phi_k+1). It reads either layout of ``coef`` (uniform or graded). The
  periodic orbits' variational equations take it; a model without it gets their Jacobian
  by coloured finite differences of ``force_kernel``.
* ``coefficients(params)``: the flat float64 array ``coef`` the kernel reads.
* ``forces(params, x)``: a NumPy twin of the kernel (zero at the degrees of
  freedom the ends hold fixed), tested against it.
* ``stiffness(params, x)``: the sparse matrix -dF/dq over the free degrees of
  freedom (ordering in :mod:`cosserat_chain.state`). For conservative models it
  is the Hessian of the energy, symmetric.
* ``energy(params, x)`` (conservative models only): the potential energy.
* ``bond_energy(params, x)``: the energy stored in every bond, for any number of
  configurations (the diagnostics' energy localization measures); optional.
* ``max_frequency(params)``: an upper bound for the highest angular frequency of
  the chain linearised at rest, which sets the default time step and the
  stability check of the fixed-step integrators. The generic one works from
  ``stiffness``; a model with a closed-form bound overrides it.
* ``rotates``: whether the model supports full rotations (forces 2 pi-periodic in
  every angle), which the rotation experiments and the CLI's choices ask.

Numerical methods receive a :class:`Model` and never import a concrete one;
adding a model means one module and one :func:`register_model` call
(``docs/adding-a-model.md``).
"""

from __future__ import annotations

import math
import warnings
from abc import ABC, abstractmethod
from collections.abc import Callable
from functools import lru_cache
from typing import ClassVar

import numpy as np
import scipy.sparse as sp
from llvmlite import ir
from numba import njit, types
from numba.core.errors import NumbaExperimentalFeatureWarning
from numba.extending import intrinsic

from ..linalg import BANDWIDTH, BandMatrix, StiffnessRows, largest_eigenvalue_bound
from ..linalg.band import scatter_add, scatter_signed
from ..memory import FLOAT, require
from ..params import ChainParams
from ..state import _free, check_state, force_columns, n_free, pack, unpack, zero_held

# The compiled integrators take the force kernels as first-class functions (one compiled
# integrator serves every model); Numba calls that feature experimental at each dispatch, a note
# for its own developers that would otherwise reach every user's terminal.
warnings.filterwarnings("ignore", message="First-class function type feature is experimental", category=NumbaExperimentalFeatureWarning)

#: Signature of every compiled force kernel: (x, coef, out, start, stop) -> None.
FORCE_SIGNATURE = types.void(types.float64[:, ::1], types.float64[::1], types.float64[:, ::1], types.int64, types.int64)
#: Rows of a bond kernel's output per bond: four forces, then the 6x6 Jacobian row by row (module docstring).
BOND_ROWS = 40
#: Signature of the end kernels: (x, coef, out, first, last, ring) -> None.
END_SIGNATURE = types.void(types.float64[:, ::1], types.float64[::1], types.float64[:, ::1], types.boolean, types.boolean, types.boolean)
END_KERNEL_TYPE = types.FunctionType(END_SIGNATURE)
#: The first-class function type compiled integrators take, so that one compiled
#: (and cached) integrator serves every model.
FORCE_KERNEL_TYPE = types.FunctionType(FORCE_SIGNATURE)
#: Signature of every compiled batch force kernel: (x, coef, out) -> None, batch innermost.
BATCH_FORCE_SIGNATURE = types.void(types.float64[:, :, ::1], types.float64[:, ::1], types.float64[:, :, ::1])
BATCH_FORCE_KERNEL_TYPE = types.FunctionType(BATCH_FORCE_SIGNATURE)
#: Numba options of the compiled hot loops (force kernels, integrators).
#: ``error_model="numpy"``: a division by zero gives inf or nan instead of raising,
#: which keeps a test and a branch out of every division. ``fastmath={"contract"}``
#: and no other flag: ``a * b + c`` may become one fused multiply-add (one rounding
#: instead of two), as gcc compiles C by default at ``-O3 -march=native``
#: (the gain on the nonlinear kernel: benchmarks/TIMINGS.md). No reassociation (sums keep their order) and no
#: nnan/ninf (they would delete the finiteness checks).
KERNEL_OPTIONS = {"cache": True, "nogil": True, "error_model": "numpy", "fastmath": {"contract"}}
#: float64 lanes of the widest SIMD registers (AVX-512) a kernel's vector loop fills: a loop
#: whose trip count is a multiple of it leaves nothing to its scalar remainder loop.
LANES = 8


@njit(inline="always", **KERNEL_OPTIONS)
def put_six(work, width, row, i, a0, a1, a2, a3, a4, a5):  # pragma: no cover - compiled
    """Rows row..row+5 of column i of a bond kernel's block scratch ``work`` (rows of ``width``), one by one.

    A bond kernel computes a block of bonds into scratch and copies its rows out: writing the
    output directly, or through a tuple indexed in a loop, kept its loop scalar (the output and
    the state are arrays the vectoriser cannot tell apart).
    """
    work[row * width + i] = a0
    work[(row + 1) * width + i] = a1
    work[(row + 2) * width + i] = a2
    work[(row + 3) * width + i] = a3
    work[(row + 4) * width + i] = a4
    work[(row + 5) * width + i] = a5


#: Bonds per block of the bond kernels: a block's 40 rows and its angles stay in the L1 cache (21 KB).
BOND_BLOCK = 64


@intrinsic
def stack_floats(typingctx, size):  # pragma: no cover - compiled
    """Pointer to ``size`` (a literal) float64 on the calling compiled function's stack, 64-byte aligned, not initialised.

    A kernel's scratch (``numba.carray(stack_floats(n), shape)``): ``np.empty``
    would allocate from the heap on every call, and scratch among the kernel's arguments
    would change :data:`FORCE_SIGNATURE`. The values live until the function returns.
    """
    if not isinstance(size, types.IntegerLiteral):
        return None
    slots = ir.ArrayType(ir.DoubleType(), size.literal_value)

    def codegen(context, builder, signature, args):
        # In the entry block, as every alloca: it then takes its stack once per call, not per loop turn.
        with builder.goto_entry_block():
            slot = builder.alloca(slots)
        slot.align = 64
        return builder.bitcast(slot, ir.DoubleType().as_pointer())

    return types.CPointer(types.float64)(size), codegen


#: Relative asymmetry of M^-1/2 K M^-1/2 below which the generic max_frequency takes K as
#: symmetric: a Hessian assembled from per-link terms is symmetric only to round-off.
_SYMMETRY_RTOL = 1e-10
#: Width of the generic max_frequency's final bracket on lambda_max, relative to the
#: Gershgorin bound: some 34 bisection steps, far below what a time step needs.
_BISECTION_RTOL = 1e-10


class Model(ABC):
    """A discrete chain model (see the module docstring for the contract)."""

    name: ClassVar[str]
    #: Whether the forces are minus the gradient of :meth:`energy`.
    conservative: ClassVar[bool]
    #: Paper reference, e.g. "eq. (2)".
    equation: ClassVar[str]
    #: Whether the model supports full rotations: its forces are 2 pi-periodic in every
    #: angle, so a particle can turn steadily (models (i) and (ii); the linear model (iii)
    #: only holds small angles). Rotation experiments and the CLI's choices ask it.
    rotates: ClassVar[bool]
    force_kernel: ClassVar[Callable[..., None]]
    #: The forces on the end columns (module docstring); None: clamped chains only.
    end_kernel: ClassVar[Callable[..., None] | None] = None
    batch_kernel: ClassVar[Callable[..., None]]
    #: The interior forces of a chain graded in its bonds (module docstring); None: uniform chains only.
    graded_kernel: ClassVar[Callable[..., None] | None] = None
    #: Every bond's forces and their exact Jacobian (module docstring); None: finite differences where a Jacobian is wanted.
    bond_kernel: ClassVar[Callable[..., None] | None] = None
    #: Largest |phi| at which the kernels of a model that does not rotate are accurate; the
    #: engine stops a run beyond it. A rotating model needs none: the engine keeps its angles
    #: below :data:`.trig.WRAP_ANGLE` by whole turns (``numerics.engine``).
    max_angle: ClassVar[float] = math.inf

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

    def stiffness_band(self, params: ChainParams, x: np.ndarray) -> BandMatrix:
        """:meth:`stiffness` in band storage (:class:`~cosserat_chain.linalg.BandMatrix`), for the O(N) statics.

        By default the band of :meth:`stiffness`; a model that has its bonds' sums
        overrides it with :func:`assemble_bond_sums` (no CSR matrix between).

        Raises
        ------
        ValueError
            For a ring (its matrices are not banded).
        """
        return BandMatrix.from_sparse(self.stiffness(params, x))

    def stiffness_rows(self, params: ChainParams, x: np.ndarray) -> StiffnessRows | None:
        """K = L^T R + G over the free degrees of freedom as rows (:class:`~cosserat_chain.linalg.StiffnessRows`), for
        :class:`~cosserat_chain.linalg.MixedFactor`, or None where the model has no such form (the default).

        A model whose K is a sum of rank-one terms gives them so that a long chain's soft modes survive
        the solves (:mod:`cosserat_chain.linalg.mixed`).
        """
        return None

    def energy(self, params: ChainParams, x: np.ndarray) -> float:
        """Potential energy at ``x``.

        Raises
        ------
        TypeError
            For a model that is not conservative.
        """
        raise TypeError(f"the {self.name} model ({self.equation}) is not conservative: it has no potential energy")

    def symmetric_similar(self, params: ChainParams, x: np.ndarray) -> sp.csr_matrix | None:
        """A symmetric banded matrix similar to :meth:`stiffness` at ``x`` (the same eigenvalues), or None.

        For a conservative model the stiffness itself (the Hessian of the energy). A
        model whose stiffness is a symmetric positive definite matrix times a positive
        or negative diagonal (eq. (2)) returns the symmetric similar matrix of that
        product. The statics take stability and folds from its smallest eigenvalue in
        O(N) (:mod:`cosserat_chain.numerics.stability`); None sends them to dense solvers.
        """
        return self.stiffness(params, x) if self.conservative else None

    def symmetric_similar_band(self, params: ChainParams, x: np.ndarray) -> BandMatrix | None:
        """:meth:`symmetric_similar` in band storage, or None where it is None (the statics' stability reads this).

        By default :meth:`stiffness_band` for a conservative model whose similar is its stiffness,
        else the band of :meth:`symmetric_similar`; a model with a banded similar of its own
        assembles it there (no sparse product between).

        Raises
        ------
        ValueError
            For a ring (its matrices are not banded).
        """
        if self.conservative and type(self).symmetric_similar is Model.symmetric_similar:
            return self.stiffness_band(params, x)
        similar = self.symmetric_similar(params, x)
        return None if similar is None else BandMatrix.from_sparse(similar)

    def bond_energy(self, params: ChainParams, x: np.ndarray) -> np.ndarray:
        """Energy stored in every bond, for any number of configurations.

        Parameters
        ----------
        params : ChainParams
        x : ndarray, shape (..., 3, 2N+1)
            Configurations, any leading shape (not checked: a whole run at once).

        Returns
        -------
        ndarray, shape (..., 2N)
            Bond k joins columns k and k+1.

        Raises
        ------
        NotImplementedError
            For a model that does not define its energy bond by bond (the
            diagnostics then leave their energy measures NaN).
        """
        raise NotImplementedError(f"the {self.name} model ({self.equation}) defines no bond energy")

    def max_frequency(self, params: ChainParams) -> float:
        """Upper bound for the highest angular frequency of the clamped chain linearised at rest.

        The generic bound, from :meth:`stiffness` at rest K and the inertia M: the
        eigenvalues omega^2 of M^-1 K are those of A = M^-1/2 K M^-1/2. For a
        symmetric K, lambda_max of A by bisection between its largest diagonal entry
        and the Gershgorin bound (the largest absolute row sum): sigma I - A is
        positive definite exactly when sigma > lambda_max, which a banded Cholesky
        factorisation tells. Bonds between neighbours give A a bandwidth of at most
        5, so each step costs O(N), with no dense matrix; the upper end of the final
        bracket is returned, above lambda_max by at most 1e-10 of the Gershgorin
        bound. For a non-symmetric K, and for a ring (whose K is not banded), the
        Gershgorin bound on the spectral radius.
        A model with a closed-form bound independent of N overrides this.

        The bound is kept per model and chain (the 64 latest): a chain of 10^4
        particles takes some 30 banded factorisations (benchmarks/TIMINGS.md), which repeated runs of the
        same chain (a benchmark, a sweep of loads) would otherwise pay every time.

        Returns
        -------
        float
            omega_max = sqrt(lambda_max) in 1/time units (0 if no eigenvalue is positive).
        """
        return _cached_max_frequency(self, params)

    def _generic_max_frequency(self, params: ChainParams) -> float:
        """The computation of :meth:`max_frequency` (uncached)."""
        n = params.n_particles
        # The first computation of the chain's size in most runs (the default time step):
        # refuse here, with the number, a chain that cannot fit (the stiffness, its bands
        # and the factor's copies, about 50 values a degree of freedom).
        require(50 * FLOAT * 3 * n, f"the stiffness of {n} particles (N={params.N})", "simulate a shorter chain")
        scale = sp.diags(1.0 / np.sqrt(pack(params, params.particle_inertia)))
        dynamical = (scale @ sp.csr_matrix(self.stiffness(params, np.zeros((3, n)))) @ scale).tocsr()
        gershgorin = float(abs(dynamical).sum(axis=1).max())
        # A ring's corner blocks would make the band as wide as the chain: its Gershgorin bound instead.
        if params.periodic or abs(dynamical - dynamical.T).max() > _SYMMETRY_RTOL * gershgorin:
            return math.sqrt(gershgorin)
        return math.sqrt(max(0.0, largest_eigenvalue_bound(dynamical, _BISECTION_RTOL)))

    def compiled_forces(self, params: ChainParams, x: np.ndarray) -> np.ndarray:
        """Forces from the compiled kernel, same layout as :meth:`forces`."""
        return self._kernel_forces(params, check_state(params, x))

    def packed_forces(self, params: ChainParams, q: np.ndarray) -> np.ndarray:
        """``pack(compiled_forces(unpack(q)))``: the forces on the free degrees of freedom ``q`` (length n_free).

        The state is built here from a vector, so it is not validated again (the
        continuation's corrector evaluates this some seven times a point: the check was
        a quarter of a residual's cost at N = 1000); a non-finite ``q`` gives non-finite
        forces, which the caller's convergence test rejects.
        """
        return pack(params, self._kernel_forces(params, unpack(params, q), held=False))

    def _kernel_forces(self, params: ChainParams, x: np.ndarray, *, held: bool = True) -> np.ndarray:
        """:meth:`compiled_forces` of a valid C-contiguous state (``held=False``: the held
        degrees of freedom's entries left as computed, for :func:`~cosserat_chain.state.pack` to drop)."""
        out = np.zeros_like(x)
        coef = self.coefficients(params)
        force, ends = self.chain_kernels(params)
        force(x, coef, out, 1, x.shape[1] - 1)
        start, stop = force_columns(params)
        if start == 0 or stop == x.shape[1]:
            ends(x, coef, out, start == 0, stop == x.shape[1], params.periodic)
        if held:
            zero_held(params, out)
        return out

    def chain_kernels(self, params: ChainParams) -> tuple[Callable[..., None], Callable[..., None]]:
        """The (interior, end) kernels a single run of ``params`` takes with ``coefficients(params)``.

        Raises
        ------
        ValueError
            For a chain graded in its bonds and a model without ``graded_kernel``, or
            other ends and a model without ``end_kernel``.
        """
        ends = self.ends_kernel(params)
        if not params.graded_stiffness:
            return type(self).force_kernel, ends
        if type(self).graded_kernel is None:
            raise ValueError(
                f"the {self.name} model has no graded_kernel: it runs chains whose bonds are alike only (E1_factors, E2_factors)"
            )
        return type(self).graded_kernel, ends

    def ends_kernel(self, params: ChainParams) -> Callable[..., None]:
        """The end kernel for ``params`` (a compiled no-op for a clamped chain).

        Raises
        ------
        ValueError
            For a chain with other ends and a model that has no ``end_kernel``.
        """
        if params.clamped:
            return no_ends
        if type(self).end_kernel is None:
            raise ValueError(f"the {self.name} model has no end_kernel: it runs clamped chains only, got {params.describe_ends()}")
        return type(self).end_kernel

    def __repr__(self) -> str:
        return f"<model {self.name!r}: {self.equation}>"


@njit(END_SIGNATURE, cache=True, nogil=True)
def no_ends(x, coef, out, first, last, ring):  # pragma: no cover - compiled
    """The end kernel of a clamped chain: its end columns do not move."""


@njit(FORCE_SIGNATURE, cache=True, nogil=True)
def no_chain_forces(x, coef, out, start, stop):  # pragma: no cover - compiled
    """Fills the chain-kernel slot of a compiled loop that runs a batch: the loop never calls it.

    A slot's kernel is compiled when it is handed over; a stub there instead of the model's
    kernel spares the compilation of a kernel the run does not use.
    """


@njit(BATCH_FORCE_SIGNATURE, cache=True, nogil=True)
def no_batch_forces(x, coef, out):  # pragma: no cover - compiled
    """Fills the batch-kernel slot of a compiled loop that runs one chain: the loop never calls it (:func:`no_chain_forces`)."""


#: Names the command line keeps for itself (``--model all``).
RESERVED_NAMES = ("all",)
#: Class attributes of the contract that have no default: checked at registration, so that
#: a model lacking one fails there rather than in the middle of a run.
_REQUIRED = ("name", "conservative", "equation", "rotates", "force_kernel", "batch_kernel")

_REGISTRY: dict[str, Model] = {}


def register_model(model: Model) -> Model:
    """Make ``model`` available to :func:`get_model` (and the CLI's ``--model``) under ``model.name``.

    Returns
    -------
    Model
        ``model`` itself, so that a module can write ``TOY = register_model(ToyModel())``.

    Raises
    ------
    TypeError
        If ``model`` is not a :class:`Model` or lacks a class attribute of the contract.
    ValueError
        If the name is reserved (:data:`RESERVED_NAMES`) or another model holds it
        (:func:`unregister_model` that one first).
    """
    if not isinstance(model, Model):
        raise TypeError(f"model must be an instance of a Model subclass, got {type(model).__name__}")
    missing = [attribute for attribute in _REQUIRED if not hasattr(model, attribute)]
    if missing:
        raise TypeError(f"{type(model).__name__} lacks the class attribute(s) {', '.join(missing)} of the model contract (models/base.py)")
    if model.name in RESERVED_NAMES:
        raise ValueError(f"model name {model.name!r} is reserved (the CLI's --model {model.name}); choose another name")
    if _REGISTRY.get(model.name, model) is not model:
        raise ValueError(
            f"a model named {model.name!r} is already registered ({_REGISTRY[model.name]!r}); unregister_model({model.name!r}) first"
        )
    _REGISTRY[model.name] = model
    return model


def unregister_model(name: str) -> Model:
    """Remove the model registered as ``name`` and return it (e.g. a model a test registered).

    Raises
    ------
    ValueError
        For a name that is not registered, listing the registered ones.
    """
    try:
        return _REGISTRY.pop(name)
    except KeyError:
        raise ValueError(f"model must be one of {sorted(_REGISTRY)} to be unregistered, got {name!r}") from None


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


@lru_cache(maxsize=32)
def _bond_block_pattern(n_particles: int, left: str, right: str, ring: bool) -> tuple[np.ndarray, ...]:
    """Where each entry of the per-bond 6x6 blocks lands in the CSR data of the assembled matrix.

    Returns ``keep`` (flat block entries on free degrees of freedom), ``position``
    (their index in the CSR data, duplicates summed there), ``indices``, ``indptr``
    and ``diagonal`` (data index of every diagonal entry). The pattern depends only on
    the chain's length and ends, so it is built once and every assembly is one ``bincount``.
    """
    n_bonds = n_particles if ring else n_particles - 1
    free = _free(n_particles, left, right)
    # Matrix index of every degree of freedom (3 column + row), -1 where an end holds it fixed.
    number = np.full(3 * n_particles, -1, dtype=np.int64)
    number[free] = np.arange(free.size)
    cols = np.arange(n_bonds)
    dofs = np.concatenate([3 * cols[:, None] + np.arange(3), 3 * ((cols[:, None] + 1) % n_particles) + np.arange(3)], axis=1)
    local = number[dofs]
    rows = np.broadcast_to(local[:, :, None], (n_bonds, 6, 6)).reshape(-1)
    columns = np.broadcast_to(local[:, None, :], (n_bonds, 6, 6)).reshape(-1)
    keep = np.flatnonzero((rows >= 0) & (columns >= 0))
    size = free.size
    # Sorting by (row, column) and numbering the distinct pairs gives the CSR order.
    key = rows[keep].astype(np.int64) * size + columns[keep]
    unique, position = np.unique(key, return_inverse=True)
    indices = (unique % size).astype(np.int32)
    indptr = np.searchsorted(unique // size, np.arange(size + 1)).astype(np.int32)
    diagonal = np.searchsorted(unique, np.arange(size, dtype=np.int64) * (size + 1))
    for array in (keep, position, indices, indptr, diagonal):
        array.flags.writeable = False
    return keep, position, indices, indptr, diagonal


def assemble_bond_blocks(blocks: np.ndarray, params: ChainParams, diagonal: np.ndarray | None = None) -> sp.csr_matrix:
    """Sparse matrix over the free degrees of freedom from per-bond 6x6 blocks.

    Parameters
    ----------
    blocks : ndarray, shape (n_bonds, 6, 6)
        Block of bond k (array columns k and k+1, or 2N and 0 for a ring's closing bond)
        over (u_k, v_k, phi_k, u_k+1, v_k+1, phi_k+1).
    params : ChainParams
        The chain: its length and its ends.
    diagonal : ndarray, shape (3, 2N+1), optional
        Extra per-degree-of-freedom diagonal terms.

    Returns
    -------
    scipy.sparse.csr_matrix
        Entries on degrees of freedom the ends hold fixed are dropped; O(N), one
        compiled scatter on a cached pattern (:func:`_bond_block_pattern`, :func:`~cosserat_chain.linalg.band.scatter_add`).
    """
    left, right = params.ends
    keep, position, indices, indptr, diagonal_at = _bond_block_pattern(params.n_particles, left, right, params.periodic)
    data = np.zeros(indices.size)
    scatter_add(np.ascontiguousarray(blocks, dtype=float).reshape(-1), keep, position, data)
    if diagonal is not None:
        data[diagonal_at] += pack(params, diagonal)
    size = indptr.size - 1
    # Copies of the shared pattern: scipy may sort or prune a matrix's indices in place.
    return sp.csr_matrix((data, indices.copy(), indptr.copy()), shape=(size, size))


#: The ten numbers that make a bond's 6x6 Hessian block when its energy depends on the
#: translations only through their difference (every model here): with
#: P(u1 - u0, v1 - v0, phi0, phi1), the translations' 2x2 blocks are +-S (S = d^2P/dD^2,
#: "uu", "uv", "vv"), the couplings of a translation with phi_0 or phi_1 are +- their
#: d^2P/dD dphi ("u_phi0" = d^2P/du1 dphi0, ...; minus on the left particle's rows), and the
#: rotations' three entries stand alone.
BOND_SUMS = ("uu", "uv", "vv", "u_phi0", "v_phi0", "u_phi1", "v_phi1", "phi0_phi0", "phi1_phi1", "phi0_phi1")


def _bond_sum_entries() -> tuple[np.ndarray, np.ndarray]:
    """For each entry (a, b) of a bond's block: which of :data:`BOND_SUMS` it is and its sign (6x6 each)."""
    which, sign = np.zeros((6, 6), dtype=np.int64), np.zeros((6, 6))
    for i, sign_i in ((0, -1.0), (3, 1.0)):  # the left particle's translations, the right one's
        for j, sign_j in ((0, -1.0), (3, 1.0)):
            for a, b, name in ((0, 0, "uu"), (0, 1, "uv"), (1, 0, "uv"), (1, 1, "vv")):
                which[i + a, j + b], sign[i + a, j + b] = BOND_SUMS.index(name), sign_i * sign_j
        for a, row in ((0, "u"), (1, "v")):
            for rotation, name in ((2, f"{row}_phi0"), (5, f"{row}_phi1")):
                which[i + a, rotation] = which[rotation, i + a] = BOND_SUMS.index(name)
                sign[i + a, rotation] = sign[rotation, i + a] = sign_i
    for a, b, name in ((2, 2, "phi0_phi0"), (5, 5, "phi1_phi1"), (2, 5, "phi0_phi1"), (5, 2, "phi0_phi1")):
        which[a, b], sign[a, b] = BOND_SUMS.index(name), 1.0
    return which, sign


@lru_cache(maxsize=32)
def _bond_sum_pattern(n_particles: int, left: str, right: str, ring: bool, band: bool) -> tuple[np.ndarray, ...]:
    """:func:`_bond_block_pattern` read from the bonds' sums: (source, sign, position) of every kept entry.

    ``source`` indexes the flattened sums (10, n_bonds), ``sign`` is +-1, ``position`` the
    entry's index in the CSR data or, with ``band``, in the flattened
    :class:`~cosserat_chain.linalg.BandMatrix` storage. The entries keep the block pattern's
    order, so that every matrix entry sums its terms in the same order as from the blocks.
    """
    keep, position, indices, indptr, _ = _bond_block_pattern(n_particles, left, right, ring)
    n_bonds = n_particles if ring else n_particles - 1
    which, sign = _bond_sum_entries()
    bond, entry = np.divmod(keep, 36)
    source = which.reshape(-1)[entry] * n_bonds + bond
    if band:
        rows = np.repeat(np.arange(indptr.size - 1), np.diff(indptr))[position]
        position = (BANDWIDTH + rows) * (2 * BANDWIDTH + 1) + BANDWIDTH + indices[position] - rows
    out = (source, sign.reshape(-1)[entry], position)
    for array in out:
        array.flags.writeable = False
    return out


def assemble_bond_sums(sums: np.ndarray, params: ChainParams, *, band: bool = False) -> sp.csr_matrix | BandMatrix:
    """The matrix over the free degrees of freedom from every bond's :data:`BOND_SUMS`, O(N).

    Parameters
    ----------
    sums : ndarray, shape (10, n_bonds)
        Bond k's sums in the order of :data:`BOND_SUMS`.
    params : ChainParams
    band : bool
        Return :class:`~cosserat_chain.linalg.BandMatrix` storage instead of CSR (the same
        values, bit for bit: both sum each entry's terms in the same order), for the O(N)
        statics, with no CSR matrix between.

    Raises
    ------
    ValueError
        With ``band`` for a ring, whose closing bond lies outside the band.
    """
    if band and params.periodic:
        raise ValueError("a ring's matrices are not banded (its closing bond couples the first and the last particle)")
    left, right = params.ends
    source, sign, position = _bond_sum_pattern(params.n_particles, left, right, params.periodic, band)
    values = np.ascontiguousarray(sums, dtype=float).reshape(-1)
    size = n_free(params)
    if band:
        data = np.zeros((size + 2 * BANDWIDTH, 2 * BANDWIDTH + 1))
        scatter_signed(values, source, sign, position, data.reshape(-1))
        return BandMatrix(data)
    _, _, indices, indptr, _ = _bond_block_pattern(params.n_particles, left, right, params.periodic)
    data = np.zeros(indices.size)
    scatter_signed(values, source, sign, position, data)
    # Copies of the shared pattern: scipy may sort or prune a matrix's indices in place.
    return sp.csr_matrix((data, indices.copy(), indptr.copy()), shape=(size, size))


@lru_cache(maxsize=64)
def _cached_max_frequency(model: Model, params: ChainParams) -> float:
    """:meth:`Model.max_frequency` cached by model (the registry's instance) and (hashable, frozen) parameters."""
    return model._generic_max_frequency(params)
