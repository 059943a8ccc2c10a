"""The collocation scheme of :mod:`~cosserat_chain.numerics.collocation`: tables, Jacobian, Newton, mesh, multipliers.

Contract
--------
The orbit of eq. (P) of :mod:`~cosserat_chain.numerics.periodic` is sought as a function of the
scaled time tau = t / T on [0, 1]: u(tau) = y(T tau) solves

    u' = T f(u),    u(1) = u(0) + s,    int_0^1 <u - u_ref, u_ref'> dtau = 0,         (C)

s = 2 pi (turns of every particle) on the angles (the rotating angle's phase gain), and the
integral phase condition pins the orbit's phase against a reference orbit u_ref (the guess,
or the previous point of a continuation): of all time shifts of u it keeps the one closest to
u_ref in L2, so it does not go singular where the flow becomes tangent to a section.

Discretisation (de Boor and Swartz; Doedel's AUTO): a mesh 0 = tau_0 < ... < tau_NTST = 1, on
each interval a polynomial of degree NCOL given by its values at NCOL + 1 equally spaced nodes
(the last node of an interval is the first of the next: the profile is continuous), and the
ODE imposed at the NCOL Gauss-Legendre points z_i of each interval:

    sum_l D_il v_jl - h_j T f(sum_l L_il v_jl) = 0,    i = 1..NCOL,  j = 0..NTST-1,

L_il = L_l(z_i), D_il = L_l'(z_i) for the Lagrange polynomials L_l of the nodes on [0, 1] and
h_j = tau_{j+1} - tau_j. The unknowns are the (NTST NCOL + 1) n node values and log T (and M in
a continuation); the equations are these, the boundary condition and the phase condition by
Gauss quadrature. Newton's method solves them with the *sparse* bordered Jacobian (SuperLU):
a collocation block is D_il I - h_j T L_il A(u_ji), A = df/dy from the shooting's right-hand
side with nine coloured variational columns (the force Jacobian is block tridiagonal), so a
step costs O(NTST NCOL) field evaluations and one sparse factorisation, whatever the period.
Gauss collocation is A-stable: the slow passage near a saddle-node ghost needs few intervals.
The mesh is adapted by equidistributing the error monitor h_j |u^(NCOL+1)|^(1/(NCOL+1)), the
(NCOL+1)-th derivative from the jumps of the piecewise constant NCOL-th one (AUTO's ADAPT), so
the points go where the orbit moves fast.

Floquet multipliers: each interval's linearised collocation equations are condensed, by one LU
of the interval's block, to its transfer matrix, x_{j+1} = P_j x_j (x_j the perturbation at mesh
point j); the multipliers are the eigenvalues of P_NTST ... P_1, computed from the factors by the
periodic Schur form (:func:`~cosserat_chain.numerics.floquet.periodic_schur_multipliers`), which
never forms the product, so that the strongly damped multipliers of long orbits keep their digits
(to 1e-170 and below, with their log-moduli) wherever the mesh resolves their modes. (AUTO's FLOWKM,
Fairgrieve and Jepson's pencil of the pairwise-eliminated chain, used here before, loses them below
about 1e-20: Lust 2001.) The trivial multiplier's distance to 1 is its error.

This module knows the equations of motion only through the shooting's system object
(:class:`~cosserat_chain.numerics._System`: ``parameters``, ``nf``, ``load_dof``,
``velocity``, ``params``, ``moment``), so that :mod:`~cosserat_chain.numerics.periodic` can
use it without an import circle; :mod:`~cosserat_chain.numerics.collocation` builds the
public orbits, searches and continuation on it. A user's system enters through its own fields
object in place of :class:`_Fields` (:mod:`~cosserat_chain.numerics.system_collocation`).
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass, replace
from typing import TYPE_CHECKING

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla
from numba import njit, types

from ..errors import CosseratChainError
from ..linalg.eigen import largest_and_nearest
from ..models.base import END_KERNEL_TYPE, FORCE_KERNEL_TYPE
from ..state import ROW_INDEX, pack
from ..state import dof as free_dof
from . import dop853, floquet
from .brent import brentq
from .kit import Evaluation, EvaluationFailed, newton

if TYPE_CHECKING:
    # The scheme serves numerics.periodic, which imports this module: its system class is only named here.
    from .periodic import _System

#: Default number of mesh intervals and of Gauss points per interval (AUTO-07p's NTST, NCOL).
NTST = 40
NCOL = 4
#: Allowed NCOL (AUTO-07p's range).
NCOL_RANGE = (2, 7)
#: Newton tolerance on max |R| (collocation residuals are state increments over an interval).
TOL = 1e-10
#: Mesh adaptations after the first solve (each: a new mesh, the orbit interpolated onto it, Newton again).
ADAPTATIONS = 2
#: The error monitor's floor, as a fraction of its mean: no interval grows without bound where the orbit is slow.
MONITOR_FLOOR = 0.05
#: Coloured variational columns: 3 rows times 3 column classes, plus one never used so that the count is
#: never the shooting's 2 n_free + 1 (which adds the moment's column).
SEEDS = 10
#: Newton keeps its Jacobian's factor while each step divides max |R| by at least 1 / CHORD_RATE.
CHORD_RATE = 0.1
#: SuperLU's column ordering where no nested dissection is given (an interval's own block, a caller's factor of the
#: Jacobian): minimum degree on J + J^T (benchmarks/TIMINGS.md).
PERMUTATION = "MMD_AT_PLUS_A"
#: Nested dissection stops at boxes of at most this many (node, particle) pairs (each 2 x 3 unknowns); smaller
#: leaves fill less (docs/collocation.md, Long chains).
DISSECTION_LEAF = 8
#: SuperLU keeps a diagonal pivot of the dissected system down to this fraction of its column's largest entry
#: (partial pivoting, 1, would move rows across the separators and fill).
PIVOT_THRESHOLD = 0.1
#: Up to this phase-space dimension (2 n_free) the multipliers are all of them, from the dense transfer matrices
#: by the periodic Schur form; above it the leading ones, by Arnoldi on the products of the intervals' sparse
#: transfer maps (docs/collocation.md, Long chains).
ALL_MULTIPLIERS_UP_TO = 240
#: Above :data:`ALL_MULTIPLIERS_UP_TO`: the multipliers asked of each of the two Arnoldi iterations (the largest in
#: modulus; the nearest to :data:`SHIFT`).
LEADING_MULTIPLIERS = 12
#: The shift of the shift-and-invert iteration: the multipliers nearest it are the real ones near +1 (the trivial one,
#: folds and branch points of cycles, the chain's soft overdamped modes, 1 - 1e-5 apart), which Arnoldi on the
#: monodromy itself separates only after hundreds of products.
SHIFT = 1.01
#: ARPACK's relative tolerance on the leading multipliers, and its restarts at most.
ARPACK_TOL = 1e-12
ARPACK_RESTARTS = 20
#: Halvings of a Newton step that does not lower max |R|.
MAX_HALVINGS = 6

#: DOP853 tolerances and step bound of the integration that makes a first profile from a start and a period.
GUESS_RTOL = GUESS_ATOL = 1e-11
GUESS_MAX_STEPS = 10_000_000

_BATCH_SIGNATURE = types.void(
    dop853.RHS_TYPE,
    FORCE_KERNEL_TYPE,
    END_KERNEL_TYPE,
    types.float64[::1],
    types.float64[::1],
    types.int64[::1],
    types.float64[:, ::1],
    types.float64[:, ::1],
)


@njit(_BATCH_SIGNATURE, cache=True, nogil=True, error_model="numpy")
def _batch(rhs, force, end_force, coef, rpar, ipar, points, out):  # pragma: no cover - compiled
    # All the points in one compiled call.
    for p in range(points.shape[0]):
        rhs(force, end_force, 0.0, points[p], coef, rpar, ipar, out[p])


class CollocationError(CosseratChainError, RuntimeError):
    """Newton's method on the collocation system did not converge (the message says what to try)."""


def check_mesh(ntst: int, ncol: int) -> None:
    """Refuse a mesh the scheme cannot use.

    Raises
    ------
    ValueError
        For ntst not an integer >= 2, or ncol not an integer in :data:`NCOL_RANGE`.
    """
    if not (isinstance(ntst, int | np.integer) and not isinstance(ntst, bool) and ntst >= 2):
        raise ValueError(f"ntst must be an integer >= 2 (mesh intervals), got {ntst!r}")
    low, high = NCOL_RANGE
    if not (isinstance(ncol, int | np.integer) and not isinstance(ncol, bool) and low <= ncol <= high):
        raise ValueError(f"ncol must be an integer from {low} to {high} (Gauss points per interval), got {ncol!r}")


@dataclass(frozen=True)
class Scheme:
    """The collocation tables of one NCOL on the reference interval [0, 1].

    Attributes
    ----------
    ncol : int
    nodes : ndarray (ncol + 1,)
        The equally spaced nodes s_l = l / ncol of the Lagrange basis.
    points, weights : ndarray (ncol,)
        Gauss-Legendre points z_i and weights on [0, 1].
    values, slopes : ndarray (ncol, ncol + 1)
        L_l(z_i) and L_l'(z_i).
    top : ndarray (ncol + 1,)
        The (constant) ncol-th derivative of each L_l.
    """

    ncol: int
    nodes: np.ndarray
    points: np.ndarray
    weights: np.ndarray
    values: np.ndarray
    slopes: np.ndarray
    top: np.ndarray

    def basis(self, s: np.ndarray) -> np.ndarray:
        """L_l(s) (k, ncol + 1) at local coordinates ``s`` (k,), as products (monomial coefficients lose digits at ncol = 7)."""
        s = np.atleast_1d(np.asarray(s, dtype=float))
        out = np.ones((s.size, self.ncol + 1))
        for node in range(self.ncol + 1):
            for other in range(self.ncol + 1):
                if other != node:
                    out[:, node] *= (s - self.nodes[other]) / (self.nodes[node] - self.nodes[other])
        return out

    def slope(self, s: np.ndarray) -> np.ndarray:
        """L_l'(s) (k, ncol + 1): the sum over the factors left out of the product."""
        s = np.atleast_1d(np.asarray(s, dtype=float))
        out = np.zeros((s.size, self.ncol + 1))
        nodes = self.nodes
        for node in range(self.ncol + 1):
            for left in range(self.ncol + 1):
                if left == node:
                    continue
                term = np.full(s.size, 1.0 / (nodes[node] - nodes[left]))
                for other in range(self.ncol + 1):
                    if other not in (node, left):
                        term *= (s - nodes[other]) / (nodes[node] - nodes[other])
                out[:, node] += term
        return out


@functools.cache
def scheme(ncol: int) -> Scheme:
    """The tables of :class:`Scheme` for ``ncol`` Gauss points."""
    check_mesh(2, ncol)
    nodes = np.linspace(0.0, 1.0, ncol + 1)
    x, w = np.polynomial.legendre.leggauss(ncol)
    points, weights = 0.5 * (x + 1.0), 0.5 * w
    top = np.array([math.factorial(ncol) / np.prod(nodes[node] - np.delete(nodes, node)) for node in range(ncol + 1)])
    table = Scheme(ncol, nodes, points, weights, np.empty(0), np.empty(0), top)
    return replace(table, values=table.basis(points), slopes=table.slope(points))


class ProfileOrbit(floquet.OrbitMultipliers):
    """What an orbit solved by this scheme derives from its mesh, profile and multipliers (the chain's
    :class:`~cosserat_chain.numerics.collocation.CollocationOrbit` and a user system's
    :class:`~cosserat_chain.numerics.system_collocation.SystemCollocationOrbit`, dataclasses with the fields
    ``mesh``, ``ncol``, ``profile``, ``multipliers`` and ``multiplier_log_moduli``); the multipliers' stability
    from :class:`~cosserat_chain.numerics.floquet.OrbitMultipliers`."""

    mesh: np.ndarray
    ncol: int
    profile: np.ndarray

    @property
    def ntst(self) -> int:
        return self.mesh.size - 1

    @property
    def trivial_multiplier_error(self) -> float:
        """|mu_trivial - 1|: the discretisation's error on the one multiplier known exactly (on long orbits the
        strongly damped multipliers can be worse: ``docs/collocation.md``, Limits)."""
        return float(abs(self.trivial_multiplier - 1.0))

    def states(self, tau: np.ndarray) -> np.ndarray:
        """u at scaled times ``tau`` (k,) in [0, 1] (k, 2n), from the piecewise polynomial."""
        return _interpolate(self.mesh, self.profile, scheme(self.ncol), np.asarray(tau, dtype=float))


class _Fields:
    """f(y), df/dy (on its structural pattern) and df/dM of one system at many points at once."""

    def __init__(self, system: _System):
        params = system.params
        nf = system.nf
        self.nf, self.n = nf, 2 * nf
        self._plain = system.parameters(0)
        self._coloured = system.parameters(SEEDS)
        # ipar = (n, load_dof, ncols, nf, start, stop, row (nf), col (nf), lookup (3 n), neighbours (9 nf)): periodic._rhs's layout.
        ipar = self._coloured[5]
        row, col = ipar[6 : 6 + nf], ipar[6 + nf : 6 + 2 * nf]
        start = 6 + 2 * nf + 3 * params.n_particles
        neighbours = ipar[start : start + 9 * nf].reshape(nf, 9)
        colour = 3 * (col % 3) + row
        #: The particle (array column) of each state component (positions, then velocities).
        self.particle = np.concatenate([col, col]).astype(np.int64)
        # Seeds: position j perturbed in column colour(j); a force row then reads each of its nine
        # neighbours from a different column.
        self._seed = np.zeros((self.n, SEEDS))
        self._seed[np.arange(nf), colour] = 1.0
        i, slot = np.nonzero(neighbours >= 0)
        j = neighbours[i, slot]
        rate = self._coloured[4][1 + nf : 1 + 2 * nf]
        eye = np.arange(nf)
        #: Structural pattern of A: dq'/dv = I, dv'/dv = -rate, dv'/dq from the variational columns.
        self.rows = np.concatenate([eye, nf + eye, nf + i])
        self.cols = np.concatenate([nf + eye, nf + eye, j])
        self._constant = np.concatenate([np.ones(nf), -rate])
        self._read = self.n + (nf + i) * SEEDS + colour[j]
        self.load_dof = system.load_dof
        self.moment_rate = float(self._plain[4][1 + system.load_dof])

    @property
    def nnz(self) -> int:
        return self.rows.size

    def values(self, points: np.ndarray, moment: float) -> np.ndarray:
        """f at ``points`` (P, n) under the moment ``moment``."""
        rhs, kernel, ends, coef, rpar, ipar = self._plain
        rpar[0] = moment
        points = np.ascontiguousarray(points, dtype=float)
        out = np.empty_like(points)
        _batch(rhs, kernel, ends, coef, rpar, ipar, points, out)
        return out

    def jacobian(self, points: np.ndarray, moment: float) -> tuple[np.ndarray, np.ndarray]:
        """f (P, n) and the values of A = df/dy on (:attr:`rows`, :attr:`cols`) (P, nnz) at ``points`` under ``moment``."""
        rhs, kernel, ends, coef, rpar, ipar = self._coloured
        rpar[0] = moment
        count = points.shape[0]
        start = np.empty((count, self.n * (1 + SEEDS)))
        start[:, : self.n] = points
        start[:, self.n :] = self._seed.ravel()
        out = np.empty_like(start)
        _batch(rhs, kernel, ends, coef, rpar, ipar, start, out)
        values = np.empty((count, self.nnz))
        values[:, : 2 * self.nf] = self._constant
        values[:, 2 * self.nf :] = out[:, self._read]
        return out[:, : self.n], values

    def parameter_derivative(self, points: np.ndarray, moment: float) -> np.ndarray:
        """df/dM (P, n) at ``points``: the moment's rate on the loaded angle's velocity, the same at every point."""
        out = np.zeros((points.shape[0], self.n))
        out[:, self.nf + self.load_dof] = self.moment_rate
        return out

    def dense(self, values: np.ndarray) -> np.ndarray:
        """A (P, n, n) from its pattern values (P, nnz)."""
        out = np.zeros((values.shape[0], self.n, self.n))
        np.add.at(out, (slice(None), self.rows, self.cols), values)
        return out


def _interpolate(mesh: np.ndarray, profile: np.ndarray, sch: Scheme, tau: np.ndarray) -> np.ndarray:
    """The piecewise polynomial of node values ``profile`` on ``mesh`` at ``tau`` (k,) -> (k, m)."""
    ntst = mesh.size - 1
    j = np.clip(np.searchsorted(mesh, tau, side="right") - 1, 0, ntst - 1)
    s = (tau - mesh[j]) / (mesh[j + 1] - mesh[j])
    basis = sch.basis(s)  # (k, ncol + 1)
    nodes = j[:, None] * sch.ncol + np.arange(sch.ncol + 1)
    return np.einsum("kl,klm->km", basis, profile[nodes])


def _adapted_mesh(mesh: np.ndarray, profile: np.ndarray, sch: Scheme, ntst: int, floor: float = MONITOR_FLOOR) -> np.ndarray:
    """A mesh of ``ntst`` intervals equidistributing h |u^(ncol+1)|^(1/(ncol+1)) of the current profile (AUTO's ADAPT).

    The monitor is raised to ``floor`` times its mean at least: with ``floor`` = 1 no interval is longer than 2 / ntst.
    """
    h = np.diff(mesh)
    old = h.size
    nodes = np.arange(old)[:, None] * sch.ncol + np.arange(sch.ncol + 1)
    top = np.einsum("l,jlm->jm", sch.top, profile[nodes]) / h[:, None] ** sch.ncol
    # The (ncol+1)-th derivative at each mesh point from the jumps of the ncol-th (periodic: the shift s is constant).
    jump = np.linalg.norm(np.roll(top, -1, axis=0) - top, axis=1) / (0.5 * (h + np.roll(h, -1)))
    monitor = (0.5 * (np.roll(jump, 1) + jump)) ** (1.0 / (sch.ncol + 1))
    monitor = np.maximum(monitor, floor * max(float(np.sum(monitor * h)), np.finfo(float).tiny))
    cumulative = np.concatenate([[0.0], np.cumsum(monitor * h)])
    new = np.interp(np.linspace(0.0, cumulative[-1], ntst + 1), cumulative, mesh)
    new[0], new[-1] = 0.0, 1.0
    return new


def _node_times(mesh: np.ndarray, sch: Scheme) -> np.ndarray:
    """The scaled times of all nodes (ntst ncol + 1,)."""
    h = np.diff(mesh)
    inner = mesh[:-1, None] + h[:, None] * sch.nodes[None, :-1]
    return np.append(inner.ravel(), 1.0)


class _Collocation:
    """The discretised system (C) of one chain and moment on one mesh, with one phase reference.

    ``fields`` (default: the chain's :class:`_Fields` of ``system``) gives f, df/dy on a pattern and df/dM at
    many points (:class:`~cosserat_chain.numerics.system_collocation.SystemFields` for a user's system, whose
    ``system`` then carries the continued parameter's value as ``moment``).

    Unknowns w = (scale * node values (G n), log T[, M]): ``scale`` = 1 / sqrt(G) makes the
    Euclidean norm of the node values the profile's mean square norm, so arclength steps do not
    depend on the mesh; with ``free_moment`` M is the last unknown (a continuation) and the
    Jacobian has its column.
    """

    def __init__(
        self, system: _System, mesh: np.ndarray, ncol: int, shift: np.ndarray, reference: np.ndarray, *, free_moment: bool, fields=None
    ):
        self.system = system
        self.fields = _Fields(system) if fields is None else fields
        self.mesh = np.asarray(mesh, dtype=float)
        self.sch = scheme(ncol)
        self.shift = shift
        self.free_moment = free_moment
        n, ntst = self.fields.n, self.mesh.size - 1
        self.n, self.ntst, self.ncol = n, ntst, ncol
        self.nodes = ntst * ncol + 1
        self.scale = 1.0 / math.sqrt(self.nodes)
        self.h = np.diff(self.mesh)
        self.index = np.arange(ntst)[:, None] * ncol + np.arange(ncol + 1)  # (ntst, ncol + 1) node of (interval, l)
        self.set_reference(reference)
        self._structure()
        self._orders: dict[bool, tuple[np.ndarray, np.ndarray]] = {}

    def set_reference(self, reference: np.ndarray) -> None:
        """The phase condition's reference profile (G, n): its slopes at the Gauss points weigh the condition."""
        self.reference = np.array(reference, dtype=float)
        slope = np.einsum("il,jlm->jim", self.sch.slopes, self.reference[self.index])  # d/ds in local coordinates
        norm = math.sqrt(float(np.sum(self.sch.weights[None, :, None] * slope**2 / self.h[:, None, None])))
        self._slope = slope / norm
        coefficients = np.zeros((self.nodes, self.n))
        weighted = self.sch.weights[None, :, None] * self._slope  # (ntst, ncol, n)
        np.add.at(coefficients, self.index, np.einsum("il,jim->jlm", self.sch.values, weighted))
        self._phase_row = coefficients.ravel()

    def _structure(self) -> None:
        """Row and column indices of the sparse Jacobian, fixed for the mesh (only the values change)."""
        n, ncol, ntst, fields = self.n, self.ncol, self.ntst, self.fields
        point_row = (np.arange(ntst)[:, None] * ncol + np.arange(ncol)) * n  # (ntst, ncol) first row of the point's block
        node_col = self.index * n  # (ntst, ncol + 1)
        # The D I part: (ntst, ncol, ncol + 1, n).
        a = np.arange(n)
        self._d_rows = np.broadcast_to(point_row[:, :, None, None] + a, (ntst, ncol, ncol + 1, n)).ravel()
        self._d_cols = np.broadcast_to(node_col[:, None, :, None] + a, (ntst, ncol, ncol + 1, n)).ravel()
        self._d_vals = np.broadcast_to(self.sch.slopes[None, :, :, None], (ntst, ncol, ncol + 1, n)).ravel()
        # The -h T L A part: (ntst, ncol, ncol + 1, nnz).
        shape = (ntst, ncol, ncol + 1, fields.nnz)
        self._a_rows = np.broadcast_to(point_row[:, :, None, None] + fields.rows, shape).ravel()
        self._a_cols = np.broadcast_to(node_col[:, None, :, None] + fields.cols, shape).ravel()
        rows = ntst * ncol * n
        self.size = self.nodes * n + 1
        self._bc_rows = rows + np.concatenate([a, a])
        self._bc_cols = np.concatenate([(self.nodes - 1) * n + a, a])
        self._bc_vals = np.concatenate([np.ones(n), -np.ones(n)])
        self._col_rows = np.arange(rows)
        self._phase_index = rows + n

    def pack(self, profile: np.ndarray, period: float, moment: float | None = None) -> np.ndarray:
        w = np.append(self.scale * np.asarray(profile).ravel(), math.log(period))
        return np.append(w, moment) if self.free_moment else w

    def unpack(self, w: np.ndarray) -> tuple[np.ndarray, float, float]:
        """(profile (G, n), T, M) at w."""
        profile = w[: self.nodes * self.n].reshape(self.nodes, self.n) / self.scale
        period = math.exp(w[self.nodes * self.n])
        return profile, period, float(w[-1]) if self.free_moment else self.system.moment

    def evaluate(self, w: np.ndarray, jacobian: bool) -> Evaluation:
        """R(w) of (C) and, with ``jacobian``, dR/dw (CSC) and (the field's Jacobian values, T) as data."""
        if not np.all(np.isfinite(w)) or w[self.nodes * self.n] > 700.0:
            raise EvaluationFailed("the collocation unknowns left the finite numbers")
        profile, period, moment = self.unpack(w)
        fields = self.fields
        blocks = profile[self.index]  # (ntst, ncol + 1, n)
        at = np.einsum("il,jlm->jim", self.sch.values, blocks)  # (ntst, ncol, n)
        slope = np.einsum("il,jlm->jim", self.sch.slopes, blocks)
        points = at.reshape(-1, self.n)
        if jacobian:
            f, a_values = fields.jacobian(points, moment)
        else:
            f, a_values = fields.values(points, moment), None
        scaled = (self.h * period)[:, None, None]
        colloc = slope - scaled * f.reshape(self.ntst, self.ncol, self.n)
        bc = profile[-1] - profile[0] - self.shift
        phase = float(
            np.sum(
                self.sch.weights[None, :, None] * (at - np.einsum("il,jlm->jim", self.sch.values, self.reference[self.index])) * self._slope
            )
        )
        residual = np.concatenate([colloc.ravel(), bc, [phase]])
        if not jacobian:
            return Evaluation(residual)
        ht = np.repeat(self.h * period, self.ncol)  # (ntst ncol,) h_j T per point
        a_part = self._a_part(a_values, period)
        rows = self.ntst * self.ncol * self.n
        logt = -(ht[:, None] * f).ravel()
        extra_rows = [self._col_rows, [self._phase_index]]
        extra_cols = [np.full(rows, self.nodes * self.n), [self.nodes * self.n]]
        extra_vals = [logt, [0.0]]
        width = self.size
        if self.free_moment:
            moment_col = -ht[:, None] * fields.parameter_derivative(points, moment)
            extra_rows.append(self._col_rows)
            extra_cols.append(np.full(rows, self.size))
            extra_vals.append(moment_col.ravel())
            width += 1
        data = np.concatenate([self._d_vals, a_part.ravel(), self._bc_vals, self._phase_row, *map(np.ravel, extra_vals)])
        row_idx = np.concatenate(
            [self._d_rows, self._a_rows, self._bc_rows, np.full(self._phase_row.size, self._phase_index), *map(np.ravel, extra_rows)]
        )
        col_idx = np.concatenate([self._d_cols, self._a_cols, self._bc_cols, np.arange(self._phase_row.size), *map(np.ravel, extra_cols)])
        # The node columns carry the unknowns' scale.
        data = np.where(col_idx < self.nodes * self.n, data / self.scale, data)
        matrix = sp.csc_matrix((data, (row_idx, col_idx)), shape=(self.size, width))
        return Evaluation(residual, matrix, (a_values, period))

    def _a_part(self, a_values: np.ndarray, period: float) -> np.ndarray:
        """The entries -h_j T L_il A(u_ji) of the collocation blocks, in the order of the structure's ``_a_rows``."""
        ht = np.repeat(self.h * period, self.ncol)
        return -(ht[:, None] * a_values).reshape(self.ntst, self.ncol, 1, -1) * self.sch.values[None, :, :, None]

    def collocation_matrix(self, a_values: np.ndarray, period: float) -> sp.csr_matrix:
        """The collocation rows of the Jacobian in the node values themselves (unscaled), (ntst ncol n, nodes n)."""
        data = np.concatenate([self._d_vals, self._a_part(a_values, period).ravel()])
        rows = np.concatenate([self._d_rows, self._a_rows])
        cols = np.concatenate([self._d_cols, self._a_cols])
        return sp.csr_matrix((data, (rows, cols)), shape=(self.ntst * self.ncol * self.n, self.nodes * self.n))

    def elimination_order(self, bordered: bool) -> tuple[np.ndarray, np.ndarray]:
        """The Jacobian's rows and columns in a nested-dissection order (with the arclength row and the M column where ``bordered``).

        The unknowns form a grid of (node, particle) pairs: the nodes of one interval are coupled among
        themselves, the intervals only through their mesh points, and a particle only to its neighbours
        (the force Jacobian's band); the boundary condition closes the ring of nodes, and log T (with M)
        and the phase (with the arclength) rows are a thin border. Nodes 0 and last (the ring's closure)
        and the border go last; the rest is split recursively, across a mesh point (a node of all the
        box's particles) or across the particles (the band's width of particles over all the box's nodes),
        whichever separator is smaller, down to boxes of :data:`DISSECTION_LEAF` pairs, each box ordered
        before its separator. The fill of the factor then grows like N log N, not N^2 per mesh point
        (docs/collocation.md, Long chains). Each column is paired with a row whose diagonal entry
        is structurally nonzero: node g > 0 with the collocation point g - 1 (the same interval),
        node 0 with the boundary condition, log T with the phase row, M with the arclength row.
        """
        cached = self._orders.get(bordered)
        if cached is not None:
            return cached
        n, ncol, nodes = self.n, self.ncol, self.nodes
        part = self.fields.particle
        width = max(1, int(np.max(np.abs(part[self.fields.rows] - part[self.fields.cols]), initial=0)))
        count = int(part.max()) + 1
        dofs = [np.flatnonzero(part == p) for p in range(count)]
        pieces: list[np.ndarray] = []

        def box(g0: int, g1: int, p0: int, p1: int) -> None:
            pieces.append((np.arange(g0, g1)[:, None] * n + np.concatenate(dofs[p0:p1])[None, :]).ravel())

        def dissect(g0: int, g1: int, p0: int, p1: int) -> None:
            if g1 <= g0 or p1 <= p0:
                return
            mesh_point = round((g0 + g1) / (2 * ncol)) * ncol
            across_time = g0 < mesh_point < g1 - 1
            across_chain = p1 - p0 >= 2 * width + 1
            if (g1 - g0) * (p1 - p0) <= DISSECTION_LEAF or not (across_time or across_chain):
                box(g0, g1, p0, p1)
            elif across_time and (not across_chain or p1 - p0 <= (g1 - g0) * width):
                dissect(g0, mesh_point, p0, p1)
                dissect(mesh_point + 1, g1, p0, p1)
                box(mesh_point, mesh_point + 1, p0, p1)
            else:
                low = (p0 + p1 - width) // 2
                dissect(g0, g1, p0, low)
                dissect(g0, g1, low + width, p1)
                box(g0, g1, low, low + width)

        dissect(1, nodes - 1, 0, count)
        box(0, 1, 0, count)
        box(nodes - 1, nodes, 0, count)
        border = np.arange(nodes * n, self.size + (1 if bordered else 0))
        cols = np.concatenate([*pieces, border])
        g, d = np.divmod(np.arange(nodes * n), n)
        paired = np.concatenate([np.where(g > 0, (g - 1) * n + d, (nodes - 1) * n + d), border])
        self._orders[bordered] = paired[cols], cols
        return self._orders[bordered]

    def transfers(self, a_values: np.ndarray, period: float) -> np.ndarray:
        """The intervals' transfer matrices P_j (ntst, n, n), x_{j+1} = P_j x_j, of the linearised collocation equations.

        One LU of each interval's own block (well conditioned, an interval being short).
        """
        n, ncol = self.n, self.ncol
        dense = self.fields.dense(a_values).reshape(self.ntst, ncol, n, n)
        eye = np.eye(n)
        out = np.empty((self.ntst, n, n))
        for j in range(self.ntst):
            block = np.empty((ncol, n, ncol + 1, n))
            for node in range(ncol + 1):
                block[:, :, node, :] = (
                    self.sch.slopes[:, node, None, None] * eye - (self.h[j] * period * self.sch.values[:, node])[:, None, None] * dense[j]
                )
            block = block.reshape(ncol * n, (ncol + 1) * n)
            out[j] = np.linalg.solve(block[:, n:], -block[:, :n])[-n:]
        return out

    def floquet(self, a_values: np.ndarray, period: float) -> floquet.Multipliers:
        """The Floquet multipliers of the linearised collocation equations with their log-moduli (module docstring).

        All of them up to 2 n_free = :data:`ALL_MULTIPLIERS_UP_TO`, from the dense transfer matrices by the periodic
        Schur form; above it the leading ones with their error estimates (:meth:`leading`).
        """
        if self.n <= ALL_MULTIPLIERS_UP_TO:
            return floquet.periodic_schur_multipliers(self.transfers(a_values, period))
        return self.leading(a_values, period)

    def multipliers(self, a_values: np.ndarray, period: float) -> np.ndarray:
        """The Floquet multipliers of the linearised collocation equations (module docstring), by decreasing modulus."""
        return self.floquet(a_values, period).values

    def transfer_maps(self, a_values: np.ndarray, period: float) -> _TransferMaps:
        """The intervals' transfer maps x -> P_j x as sparse factors (no dense P_j): :class:`_TransferMaps`."""
        return _TransferMaps(self, a_values, period)

    def leading(self, a_values: np.ndarray, period: float, count: int = LEADING_MULTIPLIERS) -> floquet.Multipliers:
        """The leading multipliers without dense transfer matrices, with their error estimates (docs/collocation.md, Long chains).

        The monodromy P_NTST ... P_1 is applied as the intervals' sparse transfer maps in turn
        (:class:`_TransferMaps`), and ARPACK takes the ``count`` multipliers of largest modulus from
        these products; (M - sigma)^-1 at sigma = :data:`SHIFT` is one solve of the periodic boundary-value
        problem x_{j+1} = P_j x_j, x_NTST - sigma x_0 = b, factored once in the nested-dissection order
        (:class:`_ShiftInvert`), and ARPACK takes the ``count`` multipliers nearest sigma from it. The two sets
        are merged (:func:`~cosserat_chain.linalg.eigen.largest_and_nearest`), by decreasing modulus; each multiplier's error
        estimate is |M v - mu v| of its unit eigenvector v. The trivial multiplier is the one nearest 1, as on the
        dense path.
        """
        n = self.n
        maps = self.transfer_maps(a_values, period)
        inverse = _ShiftInvert(self, a_values, period, SHIFT)
        values, v, _ = largest_and_nearest(maps.apply, inverse.apply, n, SHIFT, count, tol=ARPACK_TOL, restarts=ARPACK_RESTARTS)
        errors = np.linalg.norm(maps.apply(v) - v * values, axis=0)
        with np.errstate(divide="ignore"):
            log_moduli = np.log(np.abs(values))
        return floquet.Multipliers(values, log_moduli, np.angle(values), errors=errors)


class _SparseStep:
    """The Newton step -J^-1 R by SuperLU, with ``border`` (t, w_pred) the arclength row appended; the factor is kept
    while the kit's chord iterations pass the same Jacobian, so a step with a kept Jacobian costs a residual and
    two triangular solves.

    With ``order`` (rows, columns: :meth:`_Collocation.elimination_order`) the system is factored in that
    nested-dissection order, diagonal pivots kept down to :data:`PIVOT_THRESHOLD`, and each solve refined once;
    without it SuperLU orders it by minimum degree on J + J^T (:data:`PERMUTATION`).
    """

    def __init__(self, border: tuple[np.ndarray, np.ndarray] | None = None, order: tuple[np.ndarray, np.ndarray] | None = None):
        self.border = border
        self.order = order
        self.matrix = self.factor = self.permuted = None
        #: Factorisations made, and the entries of the last factor's L + U.
        self.factorizations = 0
        self.fill = 0

    def __call__(self, w: np.ndarray, evaluation: Evaluation, matrix) -> np.ndarray:
        residual = np.asarray(evaluation.residual, dtype=float)
        if self.border is not None:
            t, w_pred = self.border
            residual = np.append(residual, t @ (w - w_pred))
        if matrix is not self.matrix:
            bordered = matrix if self.border is None else sp.vstack([matrix, sp.csr_matrix(self.border[0][None, :])], format="csc")
            try:
                if self.order is None:
                    self.factor = spla.splu(sp.csc_matrix(bordered), permc_spec=PERMUTATION)
                else:
                    rows, cols = self.order
                    self.permuted = sp.csr_matrix(bordered)[rows].tocsc()[:, cols]
                    self.factor = spla.splu(
                        self.permuted, permc_spec="NATURAL", diag_pivot_thresh=PIVOT_THRESHOLD, options={"SymmetricMode": True}
                    )
            except RuntimeError as err:
                raise np.linalg.LinAlgError(f"the collocation Jacobian is singular: {err}") from err
            self.matrix = matrix
            self.factorizations += 1
            self.fill = self.factor.L.nnz + self.factor.U.nnz
        if self.order is None:
            return self.factor.solve(-residual)
        rows, cols = self.order
        rhs = -residual[rows]
        step = self.factor.solve(rhs)
        # One step of iterative refinement makes up for the weaker pivots.
        step += self.factor.solve(rhs - self.permuted @ step)
        out = np.empty_like(residual)
        out[cols] = step
        return out


class _TransferMaps:
    """The monodromy of the linearised collocation equations, x_0 -> P_NTST ... P_1 x_0, as the intervals' maps in turn.

    Interval j's collocation rows [B0 B1] (B0 on its first node, B1 on the other NCOL) give
    x_{j+1} = -(B1^-1 B0 x_j) at the last node: one sparse LU of B1 per interval (a band along the
    chain, ordered by :data:`PERMUTATION`), no dense P_j. :meth:`apply` takes vectors or column
    blocks, real or complex.
    """

    def __init__(self, problem: _Collocation, a_values: np.ndarray, period: float):
        n, ncol = problem.n, problem.ncol
        matrix = problem.collocation_matrix(a_values, period)
        self.size = n
        self._first, self._factors = [], []
        for j in range(problem.ntst):
            block = matrix[j * ncol * n : (j + 1) * ncol * n, j * ncol * n : ((j + 1) * ncol + 1) * n]
            self._first.append(sp.csr_matrix(block[:, :n]))
            self._factors.append(spla.splu(sp.csc_matrix(block[:, n:]), permc_spec=PERMUTATION))
        #: Products applied so far (each NTST sparse solves).
        self.products = 0

    def apply(self, x: np.ndarray) -> np.ndarray:
        """P_NTST ... P_1 x for x (n,) or (n, p)."""
        x = np.asarray(x)
        if np.iscomplexobj(x):
            return self.apply(x.real) + 1j * self.apply(x.imag)
        self.products += 1 if x.ndim == 1 else x.shape[1]
        for first, factor in zip(self._first, self._factors, strict=True):
            x = -factor.solve(np.asarray(first @ x))[-self.size :]
        return x


class _ShiftInvert:
    """(M - sigma)^-1 b for the monodromy M of the linearised collocation equations, without M.

    x_0 = (M - sigma)^-1 b solves the collocation rows on all intervals with the closing rows
    x_NTST - sigma x_0 = b: the Newton system without its border, factored once in the
    nested-dissection order (:meth:`_Collocation.elimination_order`).
    """

    def __init__(self, problem: _Collocation, a_values: np.ndarray, period: float, sigma: float):
        n, nodes = problem.n, problem.nodes
        eye = sp.eye(n, format="csr")
        closing = sp.hstack([-sigma * eye, sp.csr_matrix((n, (nodes - 2) * n)), eye])
        matrix = sp.vstack([problem.collocation_matrix(a_values, period), closing], format="csr")
        rows, cols = problem.elimination_order(False)
        self._rows, self._cols = rows[:-1], cols[:-1]  # without log T and the phase row
        self._factor = spla.splu(
            matrix[self._rows].tocsc()[:, self._cols], permc_spec="NATURAL", diag_pivot_thresh=PIVOT_THRESHOLD,
            options={"SymmetricMode": True},
        )  # fmt: skip
        self._n, self._size = n, nodes * n

    def apply(self, b: np.ndarray) -> np.ndarray:
        b = np.asarray(b)
        if np.iscomplexobj(b):
            return self.apply(b.real) + 1j * self.apply(b.imag)
        rhs = np.zeros(self._size)
        rhs[-self._n :] = b
        out = np.empty(self._size)
        out[self._cols] = self._factor.solve(rhs[self._rows])
        return out[: self._n]


def _trajectory_guess(system: _System, y0: np.ndarray, period: float, mesh: np.ndarray, sch: Scheme, shift: np.ndarray) -> np.ndarray:
    """The node values of the flow from y0 over ``period`` (unwrapped), its mismatch to (C)'s boundary condition spread linearly."""
    rhs, kernel, ends, coef, rpar, ipar = system.parameters(0)
    tau = _node_times(mesh, sch)
    sol = dop853.solve(
        rhs, kernel, coef, rpar, ipar, y0, tau * period, rtol=GUESS_RTOL, atol=GUESS_ATOL, max_steps=GUESS_MAX_STEPS, end_force=ends
    )  # fmt: skip
    if not sol.success:
        raise CollocationError(f"the guess's integration over T={period!r} failed at M={system.moment!r}: {sol.message}")
    profile = sol.y
    mismatch = profile[-1] - profile[0] - shift
    return profile - tau[:, None] * mismatch[None, :]


def _shift(system: _System, particle_turns: np.ndarray) -> np.ndarray:
    angles = np.zeros((3, system.params.n_particles))
    angles[ROW_INDEX["phi"]] = particle_turns
    out = np.zeros(2 * system.nf)
    out[: system.nf] = 2 * math.pi * pack(system.params, angles)
    return out


def _solve(problem: _Collocation, profile: np.ndarray, period: float, *, tol: float, max_iter: int, where: str | None = None):
    """Newton on (C) at fixed M from (profile, period): the correction and its multipliers; ``where`` names the point in
    the failure's message (default the chain's M)."""
    solved = newton(
        problem.evaluate, problem.pack(profile, period), tol=tol, max_iterations=max_iter, divergence=None, damping=MAX_HALVINGS,
        chord=CHORD_RATE, newton_step=_SparseStep(order=problem.elimination_order(False)),
    )  # fmt: skip
    if not solved.converged:
        raise CollocationError(
            f"Newton on the collocation system did not converge at {where or f'M={problem.system.moment!r}'} ({solved.status}, "
            f"{solved.iterations} iterations, max|R| {solved.norm:.3g}); start from an orbit at a nearby {'value' if where else 'moment'}, "
            "or raise ntst (the orbit may move too fast for the mesh)"
        )
    return solved


@dataclass
class Solution:
    """A solved profile of (C): mesh (ntst + 1,), ncol, node values (ntst ncol + 1, 2 n_free) unwrapped, the period,
    the multipliers (by decreasing modulus), max |R|, the Newton iterations of the last solve and ln |mu| of the
    multipliers (in range where the values under- or overflow)."""

    mesh: np.ndarray
    ncol: int
    profile: np.ndarray
    period: float
    multipliers: np.ndarray
    residual: float
    iterations: int
    log_moduli: np.ndarray | None = None


def solve_profile(
    system: _System,
    y0: np.ndarray,
    period: float,
    particle_turns: np.ndarray,
    *,
    ntst: int = NTST,
    ncol: int = NCOL,
    adapt: int = ADAPTATIONS,
    tol: float = TOL,
    max_iter: int = 25,
    profile: np.ndarray | None = None,
    mesh: np.ndarray | None = None,
    shift: np.ndarray | None = None,
    fields=None,
    where: str | None = None,
) -> Solution:
    """Solve (C) from a start y0 (2 n_free,) and period (the flow from y0 over T is the first profile).

    Given ``profile`` on ``mesh`` (an orbit solved before), that profile is interpolated onto the
    new mesh instead. The mesh is first adapted to the guess, then ``adapt`` times to the solution.
    A user's system (:mod:`~cosserat_chain.numerics.system_collocation`) gives its boundary condition's
    ``shift`` (2n,) and its ``fields`` (:class:`_Collocation`) instead of ``particle_turns``, a ``profile``, and
    ``where``: its parameters, named in the message where Newton fails (the chain's is M).

    Raises
    ------
    ValueError
        For a bad ntst, ncol, adapt, tol or period.
    CollocationError
        If Newton's method does not converge.
    """
    check_mesh(ntst, ncol)
    if not (isinstance(adapt, int) and adapt >= 0):
        raise ValueError(f"adapt must be an integer >= 0 (mesh adaptations), got {adapt!r}")
    if not (math.isfinite(tol) and tol > 0):
        raise ValueError(f"tol must be a finite number > 0, got {tol!r}")
    if not (math.isfinite(period) and period > 0):
        raise ValueError(f"the period must be finite and > 0, got {period!r}")
    sch = scheme(ncol)
    shift = _shift(system, particle_turns) if shift is None else shift
    if profile is None:
        mesh = np.linspace(0.0, 1.0, ntst + 1)
        profile = _trajectory_guess(system, y0, period, mesh, sch, shift)
        mesh = _adapted_mesh(mesh, profile, sch, ntst)
        profile = _trajectory_guess(system, y0, period, mesh, sch, shift)
    else:
        old_sch = scheme((profile.shape[0] - 1) // (mesh.size - 1))
        new = _adapted_mesh(mesh, profile, old_sch, ntst) if old_sch.ncol == ncol else np.linspace(0.0, 1.0, ntst + 1)
        profile = _interpolate(mesh, profile, old_sch, _node_times(new, sch))
        mesh = new
    for attempt in range(adapt + 1):
        problem = _Collocation(system, mesh, ncol, shift, profile, free_moment=False, fields=fields)
        solved = _solve(problem, profile, period, tol=tol, max_iter=max_iter, where=where)
        profile, period, _ = problem.unpack(solved.w)
        if attempt < adapt:
            new = _adapted_mesh(mesh, profile, sch, ntst)
            profile = _interpolate(mesh, profile, sch, _node_times(new, sch))
            mesh = new
    a_values, period = solved.evaluation.data
    found = problem.floquet(a_values, period)
    return Solution(mesh, ncol, profile, float(period), found.values, float(solved.norm), solved.iterations, found.log_moduli)


def section_state(
    system: _System, mesh: np.ndarray, ncol: int, profile: np.ndarray, particle_turns: np.ndarray, transversal_min: float
) -> tuple[np.ndarray, np.ndarray | None]:
    """The orbit's start on the loaded angle's section, as the shooting puts it, and its phase plane's normal.

    The start is u(tau) where the loaded angle crosses a multiple of 2 pi with the largest |phi'| / |u'|,
    that angle set to 0 and the other winding angles brought into (-pi, pi]; the normal is None, or, where
    even that crossing has |phi'| / |u'| < ``transversal_min``, the unit flow there (the plane through the
    start normal to the flow, :attr:`~cosserat_chain.numerics.periodic.PeriodicOrbit.phase_normal`).
    """
    dof = system.load_dof
    sch = scheme(ncol)
    ntst = mesh.size - 1

    def angle(tau: np.ndarray) -> np.ndarray:
        return _interpolate(mesh, profile[:, dof : dof + 1], sch, np.atleast_1d(tau))[:, 0]

    fine = np.unique(np.concatenate([np.linspace(0.0, 1.0, 8 * ntst * ncol + 1), mesh]))
    level = np.floor(angle(fine) / (2 * math.pi))
    best, best_slope = profile[0].copy(), -1.0
    for k in np.flatnonzero(level[1:] != level[:-1]):
        target = 2 * math.pi * max(level[k], level[k + 1])
        tau = brentq(lambda t, target=target: float(angle(t)[0] - target), fine[k], fine[k + 1], xtol=1e-15)
        u = _interpolate(mesh, profile, sch, np.array([tau]))[0]
        f = system.velocity(u)
        slope = abs(f[dof]) / np.linalg.norm(f)
        if slope > best_slope:
            best, best_slope = u, slope
    best[dof] -= 2 * math.pi * round(best[dof] / (2 * math.pi))
    params = system.params
    loaded = params.N + system.particle
    for c in np.flatnonzero(particle_turns):
        if c != loaded:
            i = free_dof(params, "phi", int(c) - params.N)
            best[i] -= 2 * math.pi * round(best[i] / (2 * math.pi))
    f = system.velocity(best)
    best[dof] = 0.0
    normal = None if abs(f[dof]) / np.linalg.norm(f) >= transversal_min else f / np.linalg.norm(f)
    return best, normal
