"""Rotating states as periodic orbits by orthogonal collocation (AUTO-07p's scheme).

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
point j); the chain P_j x_j - x_{j+1} = 0 is then eliminated pairwise by QR (the P_j are never
multiplied together) to E x_0 + F x_NTST = 0, and x_NTST = mu x_0 gives the multipliers as the
generalised eigenvalues of the pencil (E, -F) (QZ). This is Fairgrieve and Jepson's method, AUTO's FLOWKM: no product of
badly scaled matrices is formed, so multipliers of 1e-20 and 1e+5 on one orbit come out with
their own accuracy. The trivial multiplier's distance to 1 is its error.

:func:`continue_collocation` follows the orbit in M with the package's one pseudo-arclength
driver (:func:`~cosserat_chain.numerics.kit.continuation`) in (node values, log T, M), the
mesh re-adapted and the phase reference renewed every few points, until the period exceeds
``period_max`` (a homoclinic or SNIC end), M leaves the range, or M turns (a fold of cycles:
located by the driver's secant method on the tangent's M component, and accepted only with a
second multiplier at +1, as issue 40 asks).
"""

from __future__ import annotations

import dataclasses
import functools
import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import scipy.linalg as sla
import scipy.sparse as sp
import scipy.sparse.linalg as spla
from numba import njit, types
from scipy.optimize import brentq

from ..linalg.threads import one_blas_thread
from ..models.base import END_KERNEL_TYPE, FORCE_KERNEL_TYPE, get_model
from ..params import ChainParams
from ..state import ROW_INDEX, check_state, column, pack
from . import dop853, periodic
from .kit import BranchEnd, Evaluation, EvaluationFailed, Event, continuation, newton

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
#: SuperLU's column ordering: minimum degree on J + J^T fills these block-banded systems least (benchmarks/TIMINGS.md).
PERMUTATION = "MMD_AT_PLUS_A"
#: Halvings of a Newton step that does not lower max |R|.
MAX_HALVINGS = 6

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
    # One compiled loop over the points (a Python call per point would cost more than the field).
    for p in range(points.shape[0]):
        rhs(force, end_force, 0.0, points[p], coef, rpar, ipar, out[p])


class CollocationError(periodic.OrbitError):
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
    return dataclasses.replace(table, values=table.basis(points), slopes=table.slope(points))


class _Fields:
    """f(y), df/dy (on its structural pattern) and df/dM of one system at many points at once."""

    def __init__(self, system: periodic._System):
        params = system.params
        nf = system.nf
        self.nf, self.n = nf, 2 * nf
        self._plain = system.parameters(0)
        self._coloured = system.parameters(SEEDS)
        layout = periodic._layout(params)
        row, col = layout[:nf], layout[nf : 2 * nf]
        neighbours = layout[2 * nf + 3 * params.n_particles :].reshape(nf, 9)
        colour = 3 * (col % 3) + row
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

    def dense(self, values: np.ndarray) -> np.ndarray:
        """A (P, n, n) from its pattern values (P, nnz)."""
        out = np.zeros((values.shape[0], self.n, self.n))
        np.add.at(out, (slice(None), self.rows, self.cols), values)
        return out


@dataclass
class CollocationOrbit:
    """A rotating state solved by collocation (module docstring, eq. (C)).

    Attributes
    ----------
    params : ChainParams
    model : str
    moment : float
    turns : int
    particle : int
    period : float
    mesh : ndarray (ntst + 1,)
        tau_0 = 0 < ... < tau_ntst = 1.
    ncol : int
    profile : ndarray (ntst ncol + 1, 2 n_free)
        u at the nodes (unwrapped: the winding angles gain 2 pi times their turns from the first to the last).
    multipliers : ndarray (2 n_free,) complex
        Floquet multipliers by decreasing modulus (the collocation's own monodromy, module docstring).
    residual : float
        max |R| at the solution.
    iterations : int
        Newton iterations of the last solve.
    particle_turns : ndarray (2N+1,) int
    """

    params: ChainParams
    model: str
    moment: float
    turns: int
    particle: int
    period: float
    mesh: np.ndarray
    ncol: int
    profile: np.ndarray
    multipliers: np.ndarray
    residual: float
    iterations: int
    particle_turns: np.ndarray

    @property
    def ntst(self) -> int:
        return self.mesh.size - 1

    @property
    def mean_angular_velocity(self) -> float:
        """2 pi k / T, signed along the moment."""
        return math.copysign(2.0 * math.pi * self.turns / self.period, self.moment)

    @property
    def trivial_multiplier(self) -> complex:
        """The multiplier closest to 1 (along the flow)."""
        return complex(self.multipliers[np.argmin(np.abs(self.multipliers - 1.0))])

    @property
    def trivial_multiplier_error(self) -> float:
        """|mu_trivial - 1|: the multipliers' discretisation error, measured on the one known exactly."""
        return float(abs(self.trivial_multiplier - 1.0))

    @property
    def nontrivial_multipliers(self) -> np.ndarray:
        return np.delete(self.multipliers, np.argmin(np.abs(self.multipliers - 1.0)))

    @property
    def max_multiplier(self) -> float:
        return float(np.max(np.abs(self.nontrivial_multipliers)))

    @property
    def stable(self) -> bool:
        return self.max_multiplier < 1.0

    def states(self, tau: np.ndarray) -> np.ndarray:
        """u at scaled times ``tau`` (k,) in [0, 1] (k, 2 n_free), from the piecewise polynomial."""
        return _interpolate(self.mesh, self.profile, scheme(self.ncol), np.asarray(tau, dtype=float))

    def periodic_orbit(self) -> periodic.PeriodicOrbit:
        """The orbit as a :class:`~cosserat_chain.numerics.periodic.PeriodicOrbit`, started on the loaded angle's section.

        The start is the crossing of phi = 0 (mod 2 pi) by the loaded particle where the flow
        crosses it most steeply; where even there |phi'| / |f| < ``periodic.TRANSVERSAL_MIN``, the
        start carries the plane normal to the flow (``phase_normal``), as the shooting would.
        ``closure`` is the collocation's residual; ``multiplier_errors`` is None (the trivial
        multiplier's distance to 1 is :attr:`trivial_multiplier_error`).
        """
        model = get_model(self.model)
        system = periodic._System(self.params, model, self.moment, self.particle)
        dof = system.load_dof
        y = _section_start(self, dof).copy()
        y[dof] = 0.0
        x, v = periodic._from_y(self.params, y)
        for c in np.flatnonzero(self.particle_turns):
            if c != column(self.params, self.particle):
                x[ROW_INDEX["phi"], c] -= 2 * math.pi * round(x[ROW_INDEX["phi"], c] / (2 * math.pi))
        f = system.velocity(y)
        normal = None if abs(f[dof]) / np.linalg.norm(f) >= periodic.TRANSVERSAL_MIN else f / np.linalg.norm(f)
        return periodic.PeriodicOrbit(
            params=self.params, model=self.model, moment=self.moment, turns=self.turns, particle=self.particle,
            period=self.period, x=x, v=v, multipliers=self.multipliers, closure=self.residual, iterations=self.iterations,
            particle_turns=self.particle_turns, phase_normal=normal,
        )  # fmt: skip

    def as_dict(self) -> dict:
        """JSON-ready summary."""
        return {
            "model": self.model,
            "moment": self.moment,
            "turns": self.turns,
            "particle": self.particle,
            "period": self.period,
            "mean_angular_velocity": self.mean_angular_velocity,
            "ntst": self.ntst,
            "ncol": self.ncol,
            "floquet_multipliers_abs": np.abs(self.multipliers).tolist(),
            "trivial_multiplier": [self.trivial_multiplier.real, self.trivial_multiplier.imag],
            "trivial_multiplier_error": self.trivial_multiplier_error,
            "max_nontrivial_multiplier": self.max_multiplier,
            "stable": self.stable,
            "residual": self.residual,
            "iterations": self.iterations,
        }


def _section_start(orbit: CollocationOrbit, dof: int) -> np.ndarray:
    """u(tau) at the crossing of a multiple of 2 pi by u[dof] where |u[dof]'| / |u'| is largest."""
    sch = scheme(orbit.ncol)
    fine = np.unique(np.concatenate([np.linspace(0.0, 1.0, 8 * orbit.ntst * orbit.ncol + 1), orbit.mesh]))
    angle = _interpolate(orbit.mesh, orbit.profile[:, dof : dof + 1], sch, fine)[:, 0]
    level = np.floor(angle / (2 * math.pi))
    where = np.flatnonzero(level[1:] != level[:-1])
    best, best_slope = None, -1.0
    for k in where:
        target = 2 * math.pi * max(level[k], level[k + 1])

        def offset(t: float, target=target) -> float:
            return float(_interpolate(orbit.mesh, orbit.profile[:, dof : dof + 1], sch, np.array([t]))[0, 0] - target)

        tau = brentq(offset, fine[k], fine[k + 1], xtol=1e-15)
        u = orbit.states(np.array([tau]))[0]
        system = periodic._System(orbit.params, get_model(orbit.model), orbit.moment, orbit.particle)
        f = system.velocity(u)
        slope = abs(f[dof]) / np.linalg.norm(f)
        if slope > best_slope:
            best, best_slope = u, slope
    return orbit.profile[0].copy() if best is None else best


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

    Unknowns w = (scale * node values (G n), log T[, M]): ``scale`` = 1 / sqrt(G) makes the
    Euclidean norm of the node values the profile's mean square norm, so arclength steps do not
    depend on the mesh; with ``free_moment`` M is the last unknown (a continuation) and the
    Jacobian has its column.
    """

    def __init__(
        self, system: periodic._System, mesh: np.ndarray, ncol: int, shift: np.ndarray, reference: np.ndarray, *, free_moment: bool
    ):
        self.system = system
        self.fields = _Fields(system)
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
        a_part = -(ht[:, None] * a_values).reshape(self.ntst, self.ncol, 1, -1) * self.sch.values[None, :, :, None]
        rows = self.ntst * self.ncol * self.n
        logt = -(ht[:, None] * f).ravel()
        extra_rows = [self._col_rows, [self._phase_index]]
        extra_cols = [np.full(rows, self.nodes * self.n), [self.nodes * self.n]]
        extra_vals = [logt, [0.0]]
        width = self.size
        if self.free_moment:
            moment_col = np.zeros((self.ntst * self.ncol, self.n))
            moment_col[:, fields.nf + fields.load_dof] = -ht * fields.moment_rate
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

    def multipliers(self, a_values: np.ndarray, period: float) -> np.ndarray:
        """The Floquet multipliers of the linearised collocation equations (module docstring), by decreasing modulus.

        Each interval's equations give its transfer matrix x_{j+1} = P_j x_j (one LU of the
        interval's own block: well conditioned, an interval being short); the chain
        P_j x_j - x_{j+1} = 0 is then eliminated pairwise by QR, never multiplying the P_j.
        """
        n, ncol = self.n, self.ncol
        dense = self.fields.dense(a_values).reshape(self.ntst, ncol, n, n)
        eye = np.eye(n)
        e_chain = f_chain = None
        for j in range(self.ntst):
            block = np.empty((ncol, n, ncol + 1, n))
            for node in range(ncol + 1):
                block[:, :, node, :] = (
                    self.sch.slopes[:, node, None, None] * eye - (self.h[j] * period * self.sch.values[:, node])[:, None, None] * dense[j]
                )
            block = block.reshape(ncol * n, (ncol + 1) * n)
            transfer = np.linalg.solve(block[:, n:], -block[:, :n])[-n:]
            if e_chain is None:
                e_chain, f_chain = transfer, -eye
                continue
            # Eliminate the shared mesh point x_j from E x_0 + F x_j = 0 and P_j x_j - x_{j+1} = 0.
            q, _ = sla.qr(np.vstack([f_chain, transfer]), mode="full")
            e_chain, f_chain = q[:n, n:].T @ e_chain, -q[n:, n:].T
        mu = sla.eigvals(e_chain, -f_chain)
        mu = mu[np.isfinite(mu)]
        return mu[np.argsort(-np.abs(mu), kind="stable")]


class _SparseStep:
    """The Newton step -J^-1 R by SuperLU, ordered by minimum degree on J + J^T (:data:`PERMUTATION`), with
    ``border`` (t, w_pred) the arclength row appended; the factor is kept while the kit's chord iterations
    pass the same Jacobian, so a step with a kept Jacobian costs a residual and two triangular solves."""

    def __init__(self, border: tuple[np.ndarray, np.ndarray] | None = None):
        self.border = border
        self.matrix = self.factor = None

    def __call__(self, w: np.ndarray, evaluation: Evaluation, matrix) -> np.ndarray:
        residual = np.asarray(evaluation.residual, dtype=float)
        if self.border is not None:
            t, w_pred = self.border
            residual = np.append(residual, t @ (w - w_pred))
        if matrix is not self.matrix:
            bordered = matrix if self.border is None else sp.vstack([matrix, sp.csr_matrix(self.border[0][None, :])], format="csc")
            try:
                self.factor = spla.splu(sp.csc_matrix(bordered), permc_spec=PERMUTATION)
            except RuntimeError as err:
                raise np.linalg.LinAlgError(f"the collocation Jacobian is singular: {err}") from err
            self.matrix = matrix
        return self.factor.solve(-residual)


def _trajectory_guess(
    system: periodic._System, y0: np.ndarray, period: float, mesh: np.ndarray, sch: Scheme, shift: np.ndarray
) -> np.ndarray:
    """The node values of the flow from y0 over ``period`` (unwrapped), its mismatch to (C)'s boundary condition spread linearly."""
    rhs, kernel, ends, coef, rpar, ipar = system.parameters(0)
    tau = _node_times(mesh, sch)
    sol = dop853.solve(
        rhs, kernel, coef, rpar, ipar, y0, tau * period, rtol=periodic.RTOL, atol=periodic.ATOL, max_steps=periodic.MAX_STEPS, end_force=ends
    )  # fmt: skip
    if not sol.success:
        raise CollocationError(f"the guess's integration over T={period!r} failed at M={system.moment!r}: {sol.message}")
    profile = sol.y
    mismatch = profile[-1] - profile[0] - shift
    return profile - tau[:, None] * mismatch[None, :]


def _shift(system: periodic._System, particle_turns: np.ndarray) -> np.ndarray:
    angles = np.zeros((3, system.params.n_particles))
    angles[ROW_INDEX["phi"]] = particle_turns
    out = np.zeros(2 * system.nf)
    out[: system.nf] = 2 * math.pi * pack(system.params, angles)
    return out


def _solve(problem: _Collocation, profile: np.ndarray, period: float, *, tol: float, max_iter: int):
    """Newton on (C) at fixed M from (profile, period): the correction and its multipliers."""
    solved = newton(
        problem.evaluate, problem.pack(profile, period), tol=tol, max_iterations=max_iter, divergence=None, damping=MAX_HALVINGS,
        chord=CHORD_RATE, newton_step=_SparseStep(),
    )  # fmt: skip
    if not solved.converged:
        raise CollocationError(
            f"Newton on the collocation system did not converge at M={problem.system.moment!r} ({solved.status}, "
            f"{solved.iterations} iterations, max|R| {solved.norm:.3g}); start from an orbit at a nearby moment, "
            "or raise ntst (the orbit may move too fast for the mesh)"
        )
    return solved


@one_blas_thread
def solve_collocation(
    system: periodic._System,
    turns: int,
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
) -> CollocationOrbit:
    """The orbit (C) from a start y0 (2 n_free,) and period (the flow from y0 over T is the first profile).

    Given ``profile`` on ``mesh`` (an orbit solved before), that profile is interpolated onto the
    new mesh instead. The mesh is first adapted to the guess, then ``adapt`` times to the solution.

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
    shift = _shift(system, particle_turns)
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
    solved = None
    for attempt in range(adapt + 1):
        problem = _Collocation(system, mesh, ncol, shift, profile, free_moment=False)
        solved = _solve(problem, profile, period, tol=tol, max_iter=max_iter)
        profile, period, _ = problem.unpack(solved.w)
        if attempt < adapt:
            new = _adapted_mesh(mesh, profile, sch, ntst)
            profile = _interpolate(mesh, profile, sch, _node_times(new, sch))
            mesh = new
    a_values, period = solved.evaluation.data
    return CollocationOrbit(
        params=system.params, model=system.model.name, moment=float(system.moment), turns=turns, particle=system.particle,
        period=float(period), mesh=mesh, ncol=ncol, profile=profile, multipliers=problem.multipliers(a_values, period),
        residual=float(solved.norm), iterations=solved.iterations, particle_turns=np.asarray(particle_turns),
    )  # fmt: skip


def find_collocation_orbit(
    params: ChainParams,
    model,
    moment: float,
    *,
    turns: int = 1,
    particle: int = 0,
    guess: periodic.PeriodicOrbit | CollocationOrbit | None = None,
    ntst: int = NTST,
    ncol: int = NCOL,
    adapt: int = ADAPTATIONS,
    tol: float = TOL,
    max_iter: int = 25,
) -> CollocationOrbit:
    """The rotating state at ``moment`` by collocation, eq. (C).

    Parameters
    ----------
    params : ChainParams
    model : str or Model
    moment : float
    turns, particle : int
        As :func:`~cosserat_chain.numerics.periodic.find_periodic_orbit`.
    guess : PeriodicOrbit, CollocationOrbit or (x (3, 2N+1), v (3, 2N+1), T[, particle_turns (2N+1,)]), optional
        An orbit at this or a nearby moment, or a state on it and its period; by default the shooting's settled guess from rest
        (a simulation until the rotation repeats).
    ntst, ncol : int
        Mesh intervals (>= 2) and Gauss points per interval (2..7).
    adapt : int
        Mesh adaptations after the first solve.
    tol : float
        Newton stops when max |R| <= tol.
    max_iter : int

    Returns
    -------
    CollocationOrbit

    Raises
    ------
    ValueError
        For bad mesh sizes, tolerances, moment or turns (naming the field).
    CollocationError
        If Newton's method does not converge.
    """
    model = get_model(model)
    check_mesh(ntst, ncol)
    periodic._check_moment_and_turns(moment, turns)
    periodic.require_orbit_ends(params)
    system = periodic._System(params, model, float(moment), particle)
    if isinstance(guess, CollocationOrbit):
        return solve_collocation(
            system, turns, guess.profile[0], guess.period, guess.particle_turns, ntst=ntst, ncol=ncol, adapt=adapt, tol=tol,
            max_iter=max_iter, profile=guess.profile, mesh=guess.mesh,
        )  # fmt: skip
    if isinstance(guess, periodic.PeriodicOrbit):
        y0, period, particle_turns = periodic._to_y(params, guess.x, guess.v), guess.period, guess.particle_turns
    elif isinstance(guess, tuple) and len(guess) in (3, 4):
        x0, v0, period = guess[:3]
        y0 = periodic._to_y(params, check_state(params, x0, "guess x"), check_state(params, v0, "guess v"))
        particle_turns = (
            periodic._check_particle_turns(params, particle, turns, moment, guess[3])
            if len(guess) == 4
            else periodic._loaded_turns(params, particle, turns, moment)
        )
    elif guess is None:
        x0, v0, period, particle_turns = periodic._settled_guess(
            params, model, moment, turns=turns, particle=particle, x0=None, v0=None, transient_turns=30, t_max=periodic.GUESS_T_MAX
        )
        y0 = periodic._to_y(params, x0, v0)
    else:
        raise ValueError(
            f"guess must be a PeriodicOrbit, a CollocationOrbit, (x, v, T[, particle_turns]) or None, got {type(guess).__name__}"
        )
    return solve_collocation(system, turns, y0, period, particle_turns, ntst=ntst, ncol=ncol, adapt=adapt, tol=tol, max_iter=max_iter)


#: Continuation points between two mesh adaptations (the phase reference is renewed at every point).
REMESH_EVERY = 8
#: A continuation adapts its mesh also once the period has grown by this factor since the last adaptation
#: (1.25 with ``max_interval``, whose intervals then stay within 1.25 times it).
REMESH_GROWTH = 1.5
#: The most intervals a continuation's ``max_interval`` may ask for.
NTST_MAX = 4000
#: A located fold of cycles is confirmed where the second multiplier nearest +1 lies this close to it.
FOLD_MULTIPLIER = 1e-2
#: A branch's message warns where |mu_trivial - 1| exceeds this.
TRIVIAL_WARNING = 1e-6
#: Default bound on the period: beyond it the branch ends as infinite-period (a homoclinic or SNIC end).
PERIOD_MAX = 2000.0


@dataclass
class CollocationBranch:
    """Orbits traced in M by :func:`continue_collocation`.

    Attributes
    ----------
    orbits : list of CollocationOrbit
        In the order traced.
    end : BranchEnd
        ``infinite_period`` (T exceeded ``period_max``), ``parameter_limit`` (M left the range),
        ``fold`` (M turned: a fold of cycles, located and confirmed, :attr:`events`), ``max_points``
        or ``step_too_small``.
    message : str
    adaptations : int
        Mesh adaptations along the way.
    events : list of dict
        ``{"kind", "moment", "located", "orbit"}``: folds of cycles (located by the secant method on
        the tangent's M component, confirmed by a second multiplier at +1) and the sign changes of
        the kit's branch-point test (not located, not confirmed).
    """

    orbits: list[CollocationOrbit]
    end: BranchEnd
    message: str
    adaptations: int = 0
    events: list[dict] = dataclasses.field(default_factory=list)

    @property
    def moment(self) -> np.ndarray:
        return np.array([o.moment for o in self.orbits])

    @property
    def period(self) -> np.ndarray:
        return np.array([o.period for o in self.orbits])

    @property
    def max_multiplier(self) -> np.ndarray:
        return np.array([o.max_multiplier for o in self.orbits])


@dataclass
class _BranchProblem:
    """(C) with M free, for :func:`~cosserat_chain.numerics.kit.continuation` (its ContinuationProblem)."""

    collocation: _Collocation
    template: CollocationOrbit
    moment_range: tuple[float, float]
    period_max: float
    #: The segment ends (for a new mesh) once the period exceeds this.
    remesh_above: float = math.inf
    tol: float = TOL

    def evaluate(self, w: np.ndarray, jacobian: bool) -> Evaluation:
        return self.collocation.evaluate(w, jacobian)

    def correct(self, w: np.ndarray, t: np.ndarray, h: float, jacobian):
        """The kit's chord corrector with the arclength row appended to the sparse system (:class:`_SparseStep`)."""
        border = (t, w + h * t)
        return newton(
            self.evaluate, w + h * t, tol=self.tol, divergence=None, damping=MAX_HALVINGS, chord=CHORD_RATE, newton_step=_SparseStep(border)
        )

    def point(self, w: np.ndarray, evaluation: Evaluation, iterations: int) -> CollocationOrbit:
        profile, period, moment = self.collocation.unpack(w)
        a_values, _ = evaluation.data
        return dataclasses.replace(
            self.template, moment=moment, period=period, mesh=self.collocation.mesh, profile=profile,
            multipliers=self.collocation.multipliers(a_values, period), residual=float(np.max(np.abs(evaluation.residual))),
            iterations=iterations,
        )  # fmt: skip

    def accept(self, previous: CollocationOrbit, candidate: CollocationOrbit) -> bool:
        # AUTO's practice: the phase condition's reference is the last point of the branch.
        self.collocation.set_reference(candidate.profile)
        return True

    def tests(self, point: CollocationOrbit) -> dict[str, float]:
        return {}

    def stop(self, point: CollocationOrbit) -> tuple[BranchEnd, str] | None:
        if point.period > self.period_max:
            return BranchEnd.INFINITE_PERIOD, (
                f"the period reached {point.period:.6g} > period_max={self.period_max:g} at M={point.moment!r}: "
                + BranchEnd.INFINITE_PERIOD.advice
            )
        low, high = self.moment_range
        if not low <= point.moment <= high:
            return BranchEnd.PARAMETER_LIMIT, f"M={point.moment!r} left [{low!r}, {high!r}]: " + BranchEnd.PARAMETER_LIMIT.advice
        if point.period > self.remesh_above:
            return BranchEnd.MAX_POINTS, "the period grew: a new mesh"
        return None

    def locate(self, kind: str, w, t, h, previous, candidate, index: int) -> Event | None:
        """Folds are located by the kit's secant method (None); other sign changes are left where they were seen."""
        return None if kind == "fold" else Event(kind, candidate, candidate.moment, index, None, located=False)

    def confirm(self, kind: str, point: CollocationOrbit) -> bool:
        """A fold of cycles needs a second multiplier at +1 (issue 40's first item): within :data:`FOLD_MULTIPLIER`."""
        if kind != "fold":
            return True
        return bool(np.sort(np.abs(point.multipliers - 1.0))[1] < FOLD_MULTIPLIER)


@one_blas_thread
def continue_collocation(
    orbit: CollocationOrbit,
    *,
    moment_min: float = -math.inf,
    moment_max: float = math.inf,
    period_max: float = PERIOD_MAX,
    direction: float = -1.0,
    step: float = 0.02,
    min_step: float = 1e-7,
    max_step: float = 0.3,
    max_points: int = 400,
    remesh_every: int = REMESH_EVERY,
    ntst: int | None = None,
    max_interval: float | None = None,
    ntst_max: int = NTST_MAX,
    progress: Callable[[int, int], None] | None = None,
) -> CollocationBranch:
    """Follow a collocation orbit in M by pseudo-arclength (module docstring), downwards by default.

    The unknowns are the profile (scaled to its mean square norm), log T (steps of one size while
    T grows without bound towards a homoclinic end) and M. Every ``remesh_every`` points the mesh
    is adapted to the last orbit (and sooner once the period has grown by :data:`REMESH_GROWTH`)
    and the driver restarts there with the tangent interpolated.

    Parameters
    ----------
    orbit : CollocationOrbit
        The start.
    moment_min, moment_max : float
        The range of M.
    period_max : float
        The branch ends as ``infinite_period`` beyond this period.
    direction : float
        -1 towards smaller M, +1 towards larger.
    step, min_step, max_step : float
        Arclength steps of :func:`~cosserat_chain.numerics.kit.continuation`.
    max_points : int
    remesh_every : int
        Points between mesh adaptations (>= 2).
    ntst : int, optional
        Mesh intervals along the branch (default: the start's). Towards a homoclinic end the
        period comes out right on coarse meshes, the strongly damped multipliers do not (an
        interval spanning many damping times damps too little): the message warns where the
        trivial multiplier's error exceeds :data:`TRIVIAL_WARNING`, and a finer mesh cures it.
    max_interval : float, optional
        Longest interval in time units: at each adaptation ntst is raised to 2 T / ``max_interval``
        (at most ``ntst_max``) and the monitor floored at its mean, so that every interval is that
        short. The damped modes then stay resolved and the multipliers right as T grows, at a cost
        that grows with T (the orbit and its period alone need no such bound).
    ntst_max : int
        The most intervals ``max_interval`` may ask for.
    progress : callable(points, max_points), optional

    Returns
    -------
    CollocationBranch

    Raises
    ------
    ValueError
        For a bad range, period_max, direction or remesh_every.
    """
    if not moment_min < moment_max or math.isnan(moment_min) or math.isnan(moment_max):
        raise ValueError(f"moment_min must be < moment_max, got {moment_min!r}, {moment_max!r}")
    if not (math.isfinite(period_max) and period_max > orbit.period):
        raise ValueError(f"period_max must be finite and above the start's period {orbit.period:.6g}, got {period_max!r}")
    if direction not in (-1, 1, -1.0, 1.0):
        raise ValueError(f"direction must be -1 or +1, got {direction!r}")
    if not (isinstance(remesh_every, int) and remesh_every >= 2):
        raise ValueError(f"remesh_every must be an integer >= 2, got {remesh_every!r}")
    if not (isinstance(max_points, int) and max_points >= 1):
        raise ValueError(f"max_points must be an integer >= 1, got {max_points!r}")
    if max_interval is not None and not (math.isfinite(max_interval) and max_interval > 0):
        raise ValueError(f"max_interval must be a finite number > 0 (time units) or None, got {max_interval!r}")
    ntst = orbit.ntst if ntst is None else ntst
    check_mesh(ntst, orbit.ncol)
    system = periodic._System(orbit.params, get_model(orbit.model), orbit.moment, orbit.particle)
    shift = _shift(system, orbit.particle_turns)
    sch = scheme(orbit.ncol)
    orbits, events = [orbit], []
    current, tangent0, adaptations = orbit, None, 0
    end, message = BranchEnd.MAX_POINTS, f"stopped after max_points={max_points} points: " + BranchEnd.MAX_POINTS.advice
    while len(orbits) < max_points:
        if max_interval is None:
            mesh = _adapted_mesh(current.mesh, current.profile, sch, ntst)
        else:
            intervals = min(ntst_max, max(ntst, math.ceil(2.0 * current.period / max_interval)))
            mesh = _adapted_mesh(current.mesh, current.profile, sch, intervals, floor=1.0)
        profile = _interpolate(current.mesh, current.profile, sch, _node_times(mesh, sch))
        if tangent0 is not None:
            nodes = current.profile.shape[0]
            moved = _interpolate(current.mesh, tangent0[:-2].reshape(nodes, -1) * math.sqrt(nodes), sch, _node_times(mesh, sch))
            adaptations += 1
        collocation = _Collocation(system, mesh, orbit.ncol, shift, profile, free_moment=True)
        if tangent0 is not None:
            tangent0 = np.concatenate([collocation.scale * moved.ravel(), tangent0[-2:]])
        growth = REMESH_GROWTH if max_interval is None else 1.25
        problem = _BranchProblem(collocation, current, (moment_min, moment_max), period_max, growth * current.period)
        count = min(remesh_every, max_points - len(orbits) + 1)
        traced = continuation(
            problem, collocation.pack(profile, current.period, current.moment), step=step, min_step=min_step, max_step=max_step,
            max_points=count, direction=direction, tangent0=tangent0, stop_at=("fold",), locate=True,
        )  # fmt: skip
        orbits.extend(traced.points[1:])
        events.extend({"kind": e.kind, "moment": e.parameter, "located": e.located, "orbit": e.point} for e in traced.events)
        if progress is not None:
            progress(len(orbits), max_points)
        if traced.end != BranchEnd.MAX_POINTS or len(traced.points) < 2:
            end, message = traced.end, traced.message
            break
        current = traced.points[-1]
        step = min(max_step, max(min_step, _last_step(traced.points)))
        tangent0 = _secant(collocation, traced.points[-2], traced.points[-1])
    worst = max(orbits, key=lambda o: o.trivial_multiplier_error)
    if worst.trivial_multiplier_error > TRIVIAL_WARNING:
        message += (
            f"; the trivial multiplier is off by {worst.trivial_multiplier_error:.2g} at M={worst.moment!r} (T={worst.period:.6g}): "
            "the multipliers there are not resolved: raise ntst or give max_interval"
        )
    return CollocationBranch(orbits, end, message, adaptations, events)


def _last_step(points: list[CollocationOrbit]) -> float:
    """A restart's first step: a fraction of the last chord's length in the unknowns' scaled norm (log T and M included)."""
    a, b = points[-2], points[-1]
    scale = 1.0 / math.sqrt(b.profile.shape[0])
    chord = np.concatenate([scale * (b.profile - a.profile).ravel(), [math.log(b.period / a.period), b.moment - a.moment]])
    return max(1e-6, float(np.linalg.norm(chord)))


def _secant(collocation: _Collocation, a: CollocationOrbit, b: CollocationOrbit) -> np.ndarray:
    """The unit secant from a to b in the unknowns of ``collocation`` (both on its mesh)."""
    chord = collocation.pack(b.profile, b.period, b.moment) - collocation.pack(a.profile, a.period, a.moment)
    return chord / np.linalg.norm(chord)
