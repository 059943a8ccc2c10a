"""Rotating states as periodic orbits: shooting, Floquet multipliers and continuation in the moment.

Contract
--------
Above the critical moment the loaded particle turns without end while the rest of
the chain oscillates (Section 4). Because every model used for rotation is 2 pi
periodic in each angle, a steady rotation is a *limit cycle*: after a period T the
angle phi_0 of the loaded particle has advanced by 2 pi k (k turns) and every other
coordinate and every velocity has returned,

    Phi_T(y0) = y0 + 2 pi k e_phi0,                                    (P)

where y = (q, q') holds the free degrees of freedom and their velocities (ordering
of :mod:`cosserat_chain.state`) and Phi_t is the flow of the damped equations of
motion (1)-(3) under a constant moment M on the loaded particle. Any open chain held
against translation works (clamped, pinned and free ends, not two free ones, not a
ring): other angles may wind too (a cantilever's free arm, a chain spinning about its
pin), and (P) then shifts each by 2 pi times its turns (:attr:`PeriodicOrbit.particle_turns`).

* :func:`find_periodic_orbit` solves (P) by Newton's method on the shooting map.
  The unknowns are the state on the Poincare section phi_0 = 0 (phi_0 is fixed,
  which removes the phase freedom along the orbit) and the period T. The section
  serves only where the flow crosses it transversally: a loaded particle that backs up
  after each turn crosses phi_0 = 0 three times a period, and where two crossings merge
  the section's Newton system is singular although the orbit is regular (the N = 2 sine
  chain at gamma_phi = 0.15 gave a false fold of cycles at M = 0.18223 so). Where the
  cosine of the angle between the flow and the section's normal, |phi_0'| / |f(y0)|, is
  small (:data:`TRANSVERSAL_MIN`) the phase condition is instead the plane through the
  start normal to the flow there, f(y_ref) . (y0 - y_ref) = 0 (as
  :mod:`~cosserat_chain.numerics.shooting` for any system), with the whole state unknown;
  :attr:`PeriodicOrbit.phase_normal` records which. The Jacobian
  is exact up to the integration tolerance: the monodromy matrix dPhi_T/dy0 comes
  from the variational equations Phi' = A(t) Phi, A = [[0, I], [M^-1 dF/dq, -M^-1 Gamma]],
  integrated together with the state by the package's compiled DOP853
  (:mod:`cosserat_chain.numerics.dop853`) on a compiled right-hand side; the
  force Jacobian dF/dq inside it is exact, bond by bond from the model's bond kernel
  (:mod:`cosserat_chain.models.base`), or, for a model without one, formed by fourth-order
  central differences of its compiled force kernel, coloured so that it costs 36 force
  evaluations whatever N (a column's forces depend only on its two neighbours).
* The Floquet multipliers are the eigenvalues of the monodromy matrix. One equals 1
  (the flow direction); the orbit is stable iff all the others lie inside the unit
  circle.
* :func:`continue_orbit` follows the orbit in M by pseudo-arclength continuation in
  (y0, log T, M), downwards until it ceases to exist: at a fold of limit cycles
  (M turns back, the period stays finite) or where the period diverges (a
  homoclinic end; at the static fold M_c it is the saddle-node on the invariant
  circle, with T ~ (M - M_c)^(-1/2)). Using log T as the unknown keeps steps of the
  same size while T grows without bound. The phase condition is re-chosen along the
  way where the flow turns towards tangency with it (:data:`TRANSVERSAL_DROP`), and a
  turn of M counts as a fold of cycles only where a real Floquet multiplier crosses +1
  between the orbits around it; a multiplier through +1 where M does not turn is a branch
  point of cycles (:attr:`OrbitBranch.events`), and the branch goes on through it. Period
  doublings (a real multiplier through -1) and tori (a complex pair through the unit circle)
  are located in M between the orbits where their test functions turn, each trial orbit
  re-solved by the branch's own method (:mod:`~cosserat_chain.numerics.cycle_events`).
"""

from __future__ import annotations

import dataclasses
import math
import warnings
from collections.abc import Callable
from dataclasses import dataclass, field
from functools import lru_cache, partial

import numpy as np
import scipy.linalg as sla
from numba import njit

from ..errors import CosseratChainError
from ..linalg.threads import one_blas_thread
from ..loads import moment_load
from ..memory import FLOAT, require
from ..models.base import BOND_BLOCK, BOND_ROWS, END_KERNEL_TYPE, FORCE_KERNEL_TYPE, Model, get_model, no_ends
from ..params import ChainParams
from ..state import ROW_INDEX, check_state, column, force_columns, free_index, held, n_free, pack, per_dof, unpack, zeros
from ..state import dof as free_dof
from ..status import Status
from . import collocation_core, cycle_events, dop853, floquet, long_orbits, newton_picard, shooting
from .addresses import entry
from .dynamics import TurnWatch, integrate
from .integrators import default_time_step
from .kit import BranchEnd, Correction, Evaluation, EvaluationFailed, Event, continuation, newton

#: Step of the fourth-order central differences of the force kernel: dF/dq is then accurate
#: to ~5e-13 of |K| against the nonlinear model's exact stiffness at displacements of 0.1,
#: 2e-10 at 0.3 (truncation, step^4), with round-off (eps / step) near 1e-12. Second-order
#: differences reach only ~1e-9, and their round-off, rough from one evaluation to the next,
#: ruled DOP853's steps: near the nonlinear chain's period doubling (monodromy entries ~5e3)
#: 16763 steps at rtol = 1e-11 against 273 with these (the state alone: 214).
FD_STEP = 2.5e-4
#: Default tolerances of the shooting integrations (DOP853).
RTOL = 1e-11
ATOL = 1e-11
#: Default Newton tolerance on the closure max |Phi_T(y0) - y0 - 2 pi k e_phi0|.
CLOSURE_TOL = 1e-9
#: The section phi_particle = const fixes the phase only where the flow crosses it with
#: |phi'| / |f(y0)| at least this (the cosine of the angle between the flow and the section's
#: normal): 0.41 on the N = 2 sine chain's orbit at 1.1 M_c, 0.02 one step before its false fold.
TRANSVERSAL_MIN = 0.05
#: :func:`continue_orbit` re-chooses the phase condition (the plane through the orbit normal to the
#: flow) where that cosine has fallen below this fraction of its value where the condition was chosen.
TRANSVERSAL_DROP = 0.25
#: Newton iterations of one continuation step before the step is halved.
MAX_CORRECTOR_ITERATIONS = 10
#: Farthest a Floquet multiplier near the unit circle may move in the complex plane over one
#: continuation step (:func:`continue_orbit` retakes a longer one shorter, so that no window of
#: instability hides between two stable orbits).
MAX_MULTIPLIER_MOTION = 0.1
#: Multipliers whose modulus lies in this range at either end of a step count as near the circle.
MULTIPLIER_WATCH = (0.9, 1.2)
#: A dense continuation's orbit whose trivial multiplier (1 exactly) comes out farther than shooting.TRIVIAL_LOST from +1,
#: or whose multiplier nearest +1 has its eigenvector off the flow f(y0) (cosine below ALONG_FLOW: the trivial one has
#: drifted past another), ends the branch, the shooting's accuracy exhausted: next to a saddle (||M|| ~ 1e6 at T = 10
#: on the N = 1 sine chain) the monodromy's eigenvalue along the flow drifts to 2.03 (formed or from the segments' periodic
#: Schur form alike), and once it passes the damped pair 0.25 +- 0.54i it reads as a real multiplier through +1: a false
#: fold of cycles.
ALONG_FLOW = 0.9
#: Newton reuses its Jacobian while each step divides the closure by at least 1 / NEWTON_RATE.
NEWTON_RATE = 0.1
#: The continuation's step grows after a correction in at most EASY_ITERATIONS, shrinks after HARD_ITERATIONS or more.
EASY_ITERATIONS, HARD_ITERATIONS = 5, 8
#: Step halvings of a Newton step that makes the closure worse.
MAX_HALVINGS = 6
#: Most DOP853 steps (accepted and rejected) over one period.
MAX_STEPS = 10_000_000
#: Time simulated per call while looking for a settled rotation.
GUESS_CHUNK = 200.0
#: Longest simulation from rest for the default guess.
GUESS_T_MAX = 20000.0
#: The simulated rotation has settled when two consecutive spans of k turns agree to this.
SETTLE_RTOL = 1e-3
#: Further settled runs continuing the default guess of ``method="picard"`` (each a few turns): the period of a long
#: chain still drifts where two turns agree to SETTLE_RTOL, and from there Newton-Picard's first steps leave the linear
#: range (N = 500 stalled at closure 8.4e-3; from the guess continued so, it converged: docs/periodic-orbits.md).
PICARD_SETTLE = 100

ProgressCallback = Callable[[float, float], None]


@njit(inline="always", cache=True, nogil=True, error_model="numpy")
def _unpack_layout(ipar):  # pragma: no cover - compiled
    """ipar = (n, load_dof, ncols, nf, start, stop, row (nf), col (nf), lookup (3 n), neighbours (9 nf)[, 1
    for the Hamiltonian unfolding of _UndampedSystem]), as _System.parameters lays it out: [start, stop)
    the columns that move, (row[i], col[i]) the place of free degree of freedom i in x (no division in
    the loops: benchmarks/TIMINGS.md), lookup[3 column + row] the free index (-1 where an end holds it),
    neighbours[9 i + 3 o + r] the free index of row r of column col[i] - 1 + o (-1 where there is none)."""
    n, nf = ipar[0], ipar[3]
    row = ipar[6 : 6 + nf]
    col = ipar[6 + nf : 6 + 2 * nf]
    lookup = ipar[6 + 2 * nf : 6 + 2 * nf + 3 * n]
    neighbours = ipar[6 + 2 * nf + 3 * n : 6 + 11 * nf + 3 * n]
    return n, ipar[1], ipar[2], nf, ipar[4], ipar[5], row, col, lookup, neighbours


@njit(inline="always", cache=True, nogil=True, error_model="numpy")
def _state_of(y, nf, n, row, col):  # pragma: no cover - compiled
    x = np.zeros((3, n))
    for i in range(nf):
        x[row[i], col[i]] = y[i]
    return x


@njit(inline="always", cache=True, nogil=True, error_model="numpy")
def _accelerations(y, dy, f, rpar, nf, load_dof, row, col):  # pragma: no cover - compiled
    # rpar = (M, 1/mass (nf), gamma/mass (nf)).
    moment = rpar[0]
    inv_mass = rpar[1 : 1 + nf]
    damping_rate = rpar[1 + nf : 1 + 2 * nf]
    for i in range(nf):
        dy[i] = y[nf + i]
        load = moment if i == load_dof else 0.0
        dy[nf + i] = (f[row[i], col[i]] + load) * inv_mass[i] - damping_rate[i] * y[nf + i]


@njit(inline="always", cache=True, nogil=True, error_model="numpy")
def _variations(y, dy, jacobian, rpar, ipar, n, nf, ncols, load_dof, neighbours):  # pragma: no cover - compiled
    """The variational equations Phi' = A Phi with dF/dq given as ``jacobian`` (9 nf): the derivative of
    free degree of freedom i's force by (u, v, phi) of its column's left neighbour, itself and its right
    neighbour at 9 i + 3 o + r (block tridiagonal: a column's forces read only its two neighbours), so the
    product costs O(nf ncols), not the O(nf^2 ncols) of a dense one (benchmarks/TIMINGS.md). Phi is read
    and written at flat offsets, no row views: with few columns (a Krylov product) the views' set-up
    cost more than the arithmetic."""
    inv_mass = rpar[1 : 1 + nf]
    damping_rate = rpar[1 + nf : 1 + 2 * nf]
    base = 2 * nf
    velocities = base + nf * ncols
    for index in range(nf * ncols):
        dy[base + index] = y[velocities + index]
    for i in range(nf):
        out = velocities + i * ncols
        rate = damping_rate[i]
        for k in range(ncols):
            dy[out + k] = -rate * y[out + k]
        for slot in range(9):
            j = neighbours[9 * i + slot]
            if j < 0:
                continue
            weight = jacobian[9 * i + slot] * inv_mass[i]
            column = base + j * ncols
            for k in range(ncols):
                dy[out + k] += weight * y[column + k]
    if ncols == 2 * nf + 1:
        last = ncols - 1
        if ipar.size > 6 + 11 * nf + 3 * n:
            # The last column is dy/deps of the Hamiltonian unfolding (a uniform damping rate
            # eps on every velocity, ipar's extra entry): d(-eps v)/deps = -v.
            for i in range(nf):
                dy[velocities + i * ncols + last] -= y[nf + i]
        else:
            # The last column is dy/dM: the moment enters the loaded particle's equation.
            dy[velocities + load_dof * ncols + last] += inv_mass[load_dof]


@njit(dop853.RHS_SIGNATURE, cache=True, nogil=True, error_model="numpy")
def _state_rhs(force, end_force, t, y, coef, rpar, ipar, dy):  # pragma: no cover - compiled
    # :func:`_rhs` without variational columns (ncols = 0), the same arithmetic: compiled apart, so that a
    # program whose models all have a bond kernel (the report) never compiles _rhs's force differences.
    n, load_dof, ncols, nf, start, stop, row, col, lookup, neighbours = _unpack_layout(ipar)
    x = _state_of(y, nf, n, row, col)
    f = np.zeros((3, n))
    force(x, coef, f, 1, n - 1)
    if start == 0 or stop == n:
        end_force(x, coef, f, start == 0, stop == n, False)
    _accelerations(y, dy, f, rpar, nf, load_dof, row, col)


# Compiled at its first use (addresses.entry compiles dop853.RHS_SIGNATURE exactly): only a model without a bond
# kernel integrates variational columns with it.
@njit(cache=True, nogil=True, error_model="numpy")
def _rhs(force, end_force, t, y, coef, rpar, ipar, dy):  # pragma: no cover - compiled
    # Autonomous: t is not read. The forces from the model's chain and end kernels; with
    # variational columns, dF/dq by fourth-order central differences of them, (8 (F(q + h) -
    # F(q - h)) - (F(q + 2h) - F(q - 2h))) / 12h, for a model without a bond kernel.
    n, load_dof, ncols, nf, start, stop, row, col, lookup, neighbours = _unpack_layout(ipar)
    ends = start == 0 or stop == n
    x = _state_of(y, nf, n, row, col)
    f = np.zeros((3, n))
    force(x, coef, f, 1, n - 1)
    if ends:
        end_force(x, coef, f, start == 0, stop == n, False)
    _accelerations(y, dy, f, rpar, nf, load_dof, row, col)
    if ncols == 0:
        return
    # Coloured: perturbing row r of every third moving column at once is exact because a
    # column's forces read only its two neighbours (an end column's only its one).
    jacobian = np.zeros(9 * nf)
    xp = np.empty_like(x)
    xm = np.empty_like(x)
    fp = np.zeros((3, n))
    fm = np.zeros((3, n))
    diff = np.empty((3, n))
    for r in range(3):
        for color in range(3):
            diff[:] = 0.0
            for far in range(2):
                offset = (1.0 + far) * FD_STEP
                weight = -1.0 if far else 8.0
                for rr in range(3):  # loops: a slice assignment compiles numba's shape-mismatch message
                    for c in range(n):
                        xp[rr, c] = x[rr, c]
                        xm[rr, c] = x[rr, c]
                for c in range(start + color, stop, 3):
                    if lookup[3 * c + r] >= 0:
                        xp[r, c] += offset
                        xm[r, c] -= offset
                force(xp, coef, fp, 1, n - 1)
                force(xm, coef, fm, 1, n - 1)
                if ends:
                    end_force(xp, coef, fp, start == 0, stop == n, False)
                    end_force(xm, coef, fm, start == 0, stop == n, False)
                for c in range(start, stop):
                    for rr in range(3):
                        diff[rr, c] += weight * (fp[rr, c] - fm[rr, c])
            for c in range(start, stop):
                for p in range(max(c - 1, start), min(c + 2, stop)):
                    if (p - start) % 3 != color or lookup[3 * p + r] < 0:
                        continue
                    for rr in range(3):
                        i = lookup[3 * c + rr]
                        if i >= 0:
                            jacobian[9 * i + 3 * (p - c + 1) + r] = diff[rr, c] / (12.0 * FD_STEP)
    _variations(y, dy, jacobian, rpar, ipar, n, nf, ncols, load_dof, neighbours)


@njit(dop853.RHS_SIGNATURE, cache=True, nogil=True, error_model="numpy")
def _bond_rhs(bond_force, end_force, t, y, coef, rpar, ipar, dy):  # pragma: no cover - compiled
    # _rhs for a model with a bond kernel (``bond_force``; ``end_force`` is not read): the forces
    # and their exact Jacobian bond by bond. Row r of column c takes the left half of bond c and the
    # right half of bond c - 1 (models.base: the bond kernel's rows). The bonds come a block at a time
    # and their columns are read at once, while the block's rows are in the L1 cache (read column by
    # column from the whole array, each value a cache miss: they cost more than the bonds themselves).
    n, load_dof, ncols, nf, start, stop, row, col, lookup, neighbours = _unpack_layout(ipar)
    x = _state_of(y, nf, n, row, col)
    bonds = np.empty((BOND_ROWS, n - 1))
    f = np.zeros((3, n))
    jacobian = np.zeros(9 * nf)
    for begin in range(0, n - 1, BOND_BLOCK):
        end = min(begin + BOND_BLOCK, n - 1)
        bond_force(x, coef, bonds, begin, end)
        for c in range(begin, end + 1 if end == n - 1 else end):
            for r in range(3):
                if c < n - 1:  # bond c: the left particle's force r, by columns c, c + 1 (slots 3 to 8)
                    f[r, c] += bonds[r, c]
                if c > 0:  # bond c - 1: the right particle's (-fx, -fy, m1)
                    f[r, c] += bonds[3, c - 1] if r == 2 else -bonds[r, c - 1]
                i = lookup[3 * c + r]
                if ncols == 0 or i < 0:
                    continue
                if c < n - 1:
                    for k in range(6):
                        jacobian[9 * i + 3 + k] += bonds[4 + 6 * r + k, c]
                if c > 0:  # by columns c - 1, c (slots 0 to 5)
                    for k in range(6):
                        jacobian[9 * i + k] += bonds[4 + 6 * (3 + r) + k, c - 1]
    _accelerations(y, dy, f, rpar, nf, load_dof, row, col)
    if ncols == 0:
        return
    _variations(y, dy, jacobian, rpar, ipar, n, nf, ncols, load_dof, neighbours)


def require_orbit_ends(params: ChainParams) -> None:
    """Refuse the chains the shooting cannot take: a ring, and a chain free to translate.

    Any open chain held against translation works: clamped, pinned and free ends in any
    combination but free-free. A pinned end with a free one may spin about the pin (the
    nonlinear chain then turns as a whole: every angle winds, :attr:`PeriodicOrbit.particle_turns`).

    Raises
    ------
    ValueError
        For ``periodic = True`` or two free ends, naming why.
    """
    if params.periodic:
        raise ValueError(
            "the periodic-orbit solver needs an open chain (left_end, right_end), got a ring: its closing bond couples "
            "particle N to particle -N, so the force Jacobian is not block tridiagonal and the shooting's coloured "
            "differences and band product do not hold"
        )
    if params.left_end == params.right_end == "free":
        raise ValueError(
            "the periodic-orbit solver needs a chain held against translation, got free ends: every orbit then comes with "
            "the copies translated by any distance (two more Floquet multipliers equal 1), so the shooting's Newton system "
            "is singular; pin or clamp one end (left_end, right_end)"
        )


def _layout(params: ChainParams) -> np.ndarray:
    """The tail of :func:`_rhs`'s ipar: row, col (nf each), lookup (3 n) and neighbours (9 nf) of the free degrees of freedom."""
    position = free_index(params)
    n = params.n_particles
    lookup = np.full(3 * n + 6, -1, dtype=np.int64)  # three columns of -1 either side: the neighbours beyond the ends
    lookup[3 + position] = np.arange(position.size)
    col = position // 3
    neighbours = lookup[3 * col[:, None] + np.arange(9)]
    return np.concatenate([position % 3, col, lookup[3:-3], neighbours.ravel()])


@lru_cache(maxsize=64)
def _parameters(params: ChainParams, model: Model, particle: int, ncols: int):
    """:meth:`_System.parameters` at M = 0, built once per chain, model, loaded particle and column count: a
    continuation evaluates the same chain at many moments (the callers get copies of the arrays)."""
    mass = pack(params, params.particle_inertia)
    gamma = per_dof(params, params.damping)
    rpar = np.concatenate([[0.0], 1.0 / mass, gamma / mass])
    head = [params.n_particles, free_dof(params, "phi", particle), ncols, n_free(params), *force_columns(params)]
    ipar = np.concatenate([head, _layout(params)]).astype(np.int64)
    coef = model.coefficients(params)
    bonds = type(model).bond_kernel
    if ncols and bonds is not None:
        return _bond_rhs, bonds, no_ends, coef, rpar, ipar
    kernel, ends = model.chain_kernels(params)
    return (_rhs if ncols else _state_rhs), kernel, ends, coef, rpar, ipar


class OrbitError(CosseratChainError, RuntimeError):
    """Newton's method on the shooting map did not converge (the message says what to try)."""


@dataclass(frozen=True)
class _System:
    """The equations of motion of one chain, model and moment in the layout of :func:`_rhs`."""

    params: ChainParams
    model: Model
    moment: float
    particle: int

    def __post_init__(self) -> None:
        require_orbit_ends(self.params)

    @property
    def nf(self) -> int:
        return n_free(self.params)

    @property
    def load_dof(self) -> int:
        return free_dof(self.params, "phi", self.particle)

    def parameters(self, ncols: int):
        """The right-hand side, its force and end kernels, their coefficients, rpar and ipar with ``ncols`` variational columns.

        :func:`_bond_rhs` with the model's bond kernel where there are variational columns and the
        model has one (an exact force Jacobian), else :func:`_rhs` with its chain kernels
        (:func:`_state_rhs` without variational columns).
        """
        try:
            built = _parameters(self.params, self.model, self.particle, ncols)
        except TypeError:  # a chain or model that cannot be hashed is built anew each time
            built = _parameters.__wrapped__(self.params, self.model, self.particle, ncols)
        rhs, kernel, ends, coef, rpar, ipar = built
        rpar = rpar.copy()
        rpar[0] = self.moment
        return rhs, kernel, ends, coef.copy(), rpar, ipar.copy()

    def rhs(self, ncols: int):
        """The right-hand side f(t, y) with ``ncols`` variational columns, for Python callers."""
        rhs, kernel, ends, coef, rpar, ipar = self.parameters(ncols)
        # The kernels by their addresses (addresses.entry): a call then skips Numba's look-up of each.
        kernel, ends = entry(kernel, FORCE_KERNEL_TYPE), entry(ends, END_KERNEL_TYPE)

        def f(t: float, y: np.ndarray) -> np.ndarray:
            dy = np.empty_like(y)
            rhs(kernel, ends, t, y, coef, rpar, ipar, dy)
            return dy

        return f

    def flow(self, y0: np.ndarray, period: float, *, rtol: float, atol: float, variations: bool):
        """State after ``period`` and, with ``variations``, dPhi_T/dy0 (2nf, 2nf) and dPhi_T/dM (2nf,)."""
        size = 2 * self.nf
        ncols = size + 1 if variations else 0
        if variations:
            # DOP853 holds about 16 copies of its state (stages, error estimate, the step's ends).
            require(
                16 * FLOAT * size * (size + 2),
                f"the monodromy flow of {size} phase-space dimensions ({self.params.n_particles} particles, N={self.params.N})",
                "periodic orbits of a shorter chain (the monodromy matrix is dense: its memory grows like N^2)",
            )
        start = np.concatenate([y0, np.hstack([np.eye(size), np.zeros((size, 1))]).ravel() if variations else []])
        rhs, kernel, ends, coef, rpar, ipar = self.parameters(ncols)
        sol = dop853.solve(
            rhs, kernel, coef, rpar, ipar, start, np.array([0.0, period]), rtol=rtol, atol=atol, max_steps=MAX_STEPS, end_force=ends
        )
        if not sol.success:
            raise OrbitError(f"integration over T={period!r} failed at M={self.moment!r}: {sol.message}")
        end = sol.y[-1]
        if not variations:
            return end[:size], None, None
        phi = end[size:].reshape(size, ncols)
        return end[:size], phi[:, :size], phi[:, size]

    def segment_jacobians(self, y0: np.ndarray, period: float, segments: int, *, rtol: float, atol: float) -> np.ndarray:
        """The flow's Jacobians over ``segments`` equal pieces of [0, period] from y0 (segments, 2nf, 2nf), each from the identity.

        Their product, the last on the left, is the monodromy; kept apart, their strongly damped
        directions keep their digits (:mod:`~.floquet`). The state is carried from piece to piece.
        """
        size = 2 * self.nf
        out = np.empty((segments, size, size))
        y = np.asarray(y0, dtype=float)
        for k in range(segments):
            y, out[k], _ = self.flow(y, period / segments, rtol=rtol, atol=atol, variations=True)
        return out

    def velocity(self, y: np.ndarray) -> np.ndarray:
        """The vector field f(y) (2nf,)."""
        return self.rhs(0)(0.0, y)


@dataclass(frozen=True)
class _Phase:
    """The shooting's phase condition through the start ``reference`` (2nf,).

    ``normal`` None: the section phi_particle = reference[dof] (the loaded angle is not an
    unknown); otherwise the plane normal . (y0 - reference) = 0, ``normal`` a unit vector of the
    state space, with every component of y0 unknown and the plane as one more equation.
    """

    reference: np.ndarray
    dof: int
    normal: np.ndarray | None = None

    @property
    def keep(self) -> np.ndarray:
        """The components of y0 that are unknowns (bool, 2nf)."""
        keep = np.ones(self.reference.size, dtype=bool)
        if self.normal is None:
            keep[self.dof] = False
        return keep

    @property
    def head(self) -> int:
        """How many unknowns y0 contributes."""
        return self.reference.size - (self.normal is None)

    def state(self, head: np.ndarray) -> np.ndarray:
        """y0 from its unknowns."""
        if self.normal is not None:
            return np.array(head, dtype=float)
        y0 = np.empty(self.reference.size)
        y0[self.keep] = head
        y0[self.dof] = self.reference[self.dof]
        return y0

    def residual(self, y0: np.ndarray) -> np.ndarray:
        """The phase equation's residual (none for the section, which holds by construction)."""
        return np.empty(0) if self.normal is None else np.array([self.normal @ (y0 - self.reference)])

    def rows(self, width: int) -> np.ndarray:
        """Its Jacobian rows over the unknowns (y0's first, then ``width - head`` others)."""
        if self.normal is None:
            return np.empty((0, width))
        return np.concatenate([self.normal, np.zeros(width - self.normal.size)])[None, :]

    def crossing(self, system: _System, y0: np.ndarray) -> float:
        """The cosine of the angle between the flow at y0 and the condition's normal (signed)."""
        f = system.velocity(y0)
        along = f[self.dof] if self.normal is None else float(self.normal @ f)
        return float(along / np.linalg.norm(f))


def _plane(system: _System, y0: np.ndarray) -> _Phase:
    """The plane through y0 normal to the flow there."""
    f = system.velocity(y0)
    return _Phase(np.array(y0, dtype=float), system.load_dof, f / np.linalg.norm(f))


def _phase_for(system: _System, y0: np.ndarray, normal: np.ndarray | None = None) -> _Phase:
    """The phase condition through y0: the plane of ``normal`` if given, else the section on the loaded angle
    where the flow crosses it transversally (:data:`TRANSVERSAL_MIN`), else the plane normal to the flow."""
    if normal is not None:
        return _Phase(np.array(y0, dtype=float), system.load_dof, np.asarray(normal, dtype=float))
    section = _Phase(np.array(y0, dtype=float), system.load_dof)
    return section if abs(section.crossing(system, y0)) >= TRANSVERSAL_MIN else _plane(system, y0)


@dataclass
class PeriodicOrbit(floquet.OrbitMultipliers):
    """A rotating state as a limit cycle (see the module docstring, eq. (P)).

    Attributes
    ----------
    params : ChainParams
    model : str
    moment : float
        Constant moment M on the loaded particle.
    turns : int
        k: the loaded particle turns k times per period.
    particle : int
        The loaded particle.
    period : float
        T.
    x, v : ndarray (3, 2N+1)
        The state where the orbit starts: on the section phi_0 = 0 (``phase_normal`` None), or
        where the flow is nearly tangent to that section, on the plane ``phase_normal`` . (y -
        y_start) = 0 (the loaded angle is then anywhere).
    multipliers : ndarray (2 n_free,) complex
        Floquet multipliers (eigenvalues of the monodromy matrix), by decreasing modulus.
    closure : float
        max |Phi_T(y0) - y0 - 2 pi k e_phi0| of the converged orbit.
    iterations : int
        Newton iterations used.
    particle_turns : ndarray (2N+1,) int
        Signed turns of every particle's angle per period (the loaded particle's is
        +-``turns``; others wind when the whole chain spins about a pin). Default: the
        loaded particle's alone.
    phase_normal : ndarray (2 n_free,) or None
        The unit normal of the phase plane through the start, None for the section on the
        loaded angle (module docstring); a continuation or a guess from this orbit keeps it.
    multiplier_errors : ndarray (k,) or None
        Error estimates of ``multipliers`` (residual norms: :mod:`~.long_orbits` for the blocks
        and Krylov methods, :mod:`~.newton_picard` for ``picard``, whose multipliers above its
        rho are certified where |mu| less its residual exceeds rho); where not all are computed,
        ``multipliers`` are the k leading ones only.
    multiplier_log_moduli : ndarray (2 n_free,) or None
        ln |mu| of each multiplier where they came from the segments' product (``segments`` of
        :func:`find_periodic_orbit`, or collocation): in range where the value under- or overflows.
    """

    params: ChainParams
    model: str
    moment: float
    turns: int
    particle: int
    period: float
    x: np.ndarray
    v: np.ndarray
    multipliers: np.ndarray
    closure: float
    iterations: int
    particle_turns: np.ndarray | None = None
    phase_normal: np.ndarray | None = None
    multiplier_errors: np.ndarray | None = None
    multiplier_log_moduli: np.ndarray | None = None

    def __post_init__(self) -> None:
        if self.particle_turns is None:
            self.particle_turns = _loaded_turns(self.params, self.particle, self.turns, self.moment)

    @property
    def mean_angular_velocity(self) -> float:
        """2 pi k / T, signed along the moment."""
        return math.copysign(2.0 * math.pi * self.turns / self.period, self.moment)

    @property
    def trivial_multiplier_error(self) -> float | None:
        """The trivial multiplier's error estimate (:attr:`multiplier_errors`); None where not estimated."""
        if self.multiplier_errors is None:
            return None
        return float(self.multiplier_errors[self.trivial_index])

    def trajectory(self, times: np.ndarray, *, rtol: float = RTOL, atol: float = ATOL) -> tuple[np.ndarray, np.ndarray]:
        """The states along the orbit at ``times`` (k,) > 0 after its start (x, v), by the shooting's DOP853.

        Returns
        -------
        x, v : ndarray (k, 3, 2N+1)
            Unwrapped: phi_0 has advanced by 2 pi k at ``times = period`` (eq. (P)).
        """
        times = np.asarray(times, dtype=float)
        system = _System(self.params, get_model(self.model), self.moment, self.particle)
        rhs, kernel, ends, coef, rpar, ipar = system.parameters(0)
        start = _to_y(self.params, self.x, self.v)
        sol = dop853.solve(
            rhs, kernel, coef, rpar, ipar, start, np.concatenate([[0.0], times]), rtol=rtol, atol=atol, max_steps=MAX_STEPS, end_force=ends
        )
        if not sol.success:
            raise OrbitError(f"integration along the orbit failed at M={self.moment!r}: {sol.message}")
        states = [_from_y(self.params, y) for y in sol.y[1:]]
        return np.array([s[0] for s in states]), np.array([s[1] for s in states])

    def as_dict(self) -> dict:
        """JSON-ready summary. Moments in the parameters' units; ``moment_scale`` = E1 h^2 divides them into the paper's dimensionless moment (Fig. 2).

        ``floquet_multipliers_log10_abs`` (log10 |mu|, in range below 1e-308) where the multipliers came from the
        segments' product (:attr:`multiplier_log_moduli`).
        """
        out = {
            "model": self.model,
            "moment": self.moment,
            "moment_scale": self.params.moment_scale,
            "turns": self.turns,
            "particle": self.particle,
            "particle_turns": [int(k) for k in self.particle_turns],
            "period": self.period,
            "mean_angular_velocity": self.mean_angular_velocity,
            "floquet_multipliers_abs": np.abs(self.multipliers).tolist(),
            "trivial_multiplier": [self.trivial_multiplier.real, self.trivial_multiplier.imag],
            "max_nontrivial_multiplier": self.max_multiplier,
            "stable": self.stable,
            "closure": self.closure,
            "iterations": self.iterations,
            "phase_condition": "section" if self.phase_normal is None else "plane",
            "trivial_multiplier_error": self.trivial_multiplier_error,
        }
        if self.multiplier_log_moduli is not None:
            out["floquet_multipliers_log10_abs"] = (self.multiplier_log_moduli / math.log(10.0)).tolist()
        return out


#: Most turns of the loaded particle a period: the paper's chain repeats after 1 to 3; a period of many
#: turns is a quasi-periodic or chaotic rotation, and its settling run grows with the turns.
MAX_TURNS = 1000


def _check_moment_and_turns(moment: float, turns: int) -> None:
    if not (math.isfinite(moment) and moment != 0):
        raise ValueError(f"moment must be finite and non-zero (a rotating state needs a load), got {moment!r}")
    if not (isinstance(turns, int) and not isinstance(turns, bool) and 1 <= turns <= MAX_TURNS):
        raise ValueError(f"turns must be an integer from 1 to {MAX_TURNS} (turns of the loaded particle per period), got {turns!r}")


def _loaded_turns(params: ChainParams, particle: int, turns: int, moment: float) -> np.ndarray:
    """Turns per period of every particle when the loaded one alone winds: +-turns there, 0 elsewhere."""
    out = np.zeros(params.n_particles, dtype=np.int64)
    out[column(params, particle)] = int(math.copysign(turns, moment))
    return out


def _check_particle_turns(params: ChainParams, particle: int, turns: int, moment: float, particle_turns) -> np.ndarray:
    out = np.asarray(particle_turns)
    expected = int(math.copysign(turns, moment))
    if out.shape != (params.n_particles,) or out.dtype.kind not in "iu" or out[column(params, particle)] != expected:
        raise ValueError(
            f"particle_turns must be {params.n_particles} integers (turns per period of every particle) with "
            f"{expected} at the loaded particle {particle}, got {particle_turns!r}"
        )
    held_phi = [c for row, c in held(params) if row == ROW_INDEX["phi"]]
    if np.any(out[held_phi] != 0):
        raise ValueError(f"particle_turns must be 0 where an end holds the angle (clamped), got {particle_turns!r}")
    return out.astype(np.int64)


def _to_y(params: ChainParams, x: np.ndarray, v: np.ndarray) -> np.ndarray:
    return np.concatenate([pack(params, x), pack(params, v)])


def _from_y(params: ChainParams, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    nf = n_free(params)
    return unpack(params, y[:nf]), unpack(params, y[nf:])


def initial_guess(
    params: ChainParams,
    model: str | Model,
    moment: float,
    *,
    turns: int = 1,
    particle: int = 0,
    x0: np.ndarray | None = None,
    v0: np.ndarray | None = None,
    transient_turns: int = 30,
    t_max: float = GUESS_T_MAX,
) -> tuple[np.ndarray, np.ndarray, float]:
    """A state on the section phi_0 = 0 and a period, from a simulation that has settled.

    Integrates (fixed-step Yoshida-4) from (x0, v0) (default rest) until two consecutive
    spans of ``turns`` turns take the same time to ``SETTLE_RTOL`` or the loaded particle
    has made ``transient_turns + turns`` turns, and returns the state at the last crossing of
    phi_0 = 0 mod 2 pi (phi_0 reduced to 0) and the time of the last ``turns`` turns.

    Raises
    ------
    OrbitError
        If the particle has not made that many turns by ``t_max`` (no rotation).
    """
    return _settled_guess(
        params, model, moment, turns=turns, particle=particle, x0=x0, v0=v0, transient_turns=transient_turns, t_max=t_max
    )[:3]


def _settled_guess(
    params: ChainParams,
    model: str | Model,
    moment: float,
    *,
    turns: int,
    particle: int,
    x0: np.ndarray | None,
    v0: np.ndarray | None,
    transient_turns: int,
    t_max: float,
) -> tuple[np.ndarray, np.ndarray, float, np.ndarray]:
    """:func:`initial_guess` and the turns every particle made over the last ``turns`` turns (PeriodicOrbit.particle_turns).

    The angles of the other particles that wound are reduced to (-pi, pi] on the section.
    """
    model = get_model(model)
    _check_moment_and_turns(moment, turns)
    system = _System(params, model, float(moment), particle)
    x = zeros(params) if x0 is None else check_state(params, x0, "x0")
    v = zeros(params) if v0 is None else check_state(params, v0, "v0")
    dof = system.load_dof
    col = column(params, particle)
    loads = moment_load(float(moment), particle).validate(params)
    sign = math.copysign(1.0, moment)
    wanted = transient_turns + turns

    # Turns count from the multiple of 2 pi at or behind the start, one run per turn,
    # each stopping at the step that completes it.
    phi = x[ROW_INDEX["phi"], col]
    watch = TurnWatch(particle, sign, phi_start=sign * 2 * math.pi * math.floor(sign * phi / (2 * math.pi)), keep=1, stop_after=1)
    # The default step once (integrate would compute it again for every turn); it lies far
    # inside the stability limit, so it needs no check either.
    dt = default_time_step(params, model)
    times: list[float] = []
    angles: list[np.ndarray] = []
    state = None
    elapsed = 0.0
    while elapsed < t_max and len(times) < wanted + 1 and not _settled(times, turns):
        run = integrate(
            params, model, loads, t0=elapsed, t_end=min(elapsed + GUESS_CHUNK, t_max), dt=dt, check_stability=False, x0=x, v0=v,
            method="yoshida4", n_frames=2, throw=True, turns=watch,
        )  # fmt: skip
        x, v = run.x[-1], run.v[-1]
        elapsed = float(run.time[-1])
        if run.turns.made > watch.made:
            times.append(float(run.turns.times[-1]))
            angles.append(x[ROW_INDEX["phi"]].copy())
            state = _to_y(params, x, v)
        watch = run.turns.following(stop_after=run.turns.made + 1)
    if len(times) < turns + 1:
        raise OrbitError(
            f"the loaded particle made {len(times)} turns by t={elapsed:g} at M={moment!r}: no rotating state reached from "
            "this start; start above the static fold M_c, or give a guess (an orbit at a nearby moment)"
        )
    state[dof] = 0.0
    x, v = _from_y(params, state)
    # Whole turns of every angle over the last span (a chain that spins about a pin winds as a whole).
    particle_turns = np.rint((angles[-1] - angles[-1 - turns]) / (2 * math.pi)).astype(np.int64)
    particle_turns[col] = int(math.copysign(turns, moment))
    for c in np.flatnonzero(particle_turns):
        if c != col:
            x[ROW_INDEX["phi"], c] -= 2 * math.pi * round(x[ROW_INDEX["phi"], c] / (2 * math.pi))
    return x, v, times[-1] - times[-1 - turns], particle_turns


def _settled(times: list[float], turns: int) -> bool:
    """Whether the last two spans of ``turns`` turns took the same time to SETTLE_RTOL."""
    if len(times) < 2 * turns + 1:
        return False
    last, before = times[-1] - times[-1 - turns], times[-1 - turns] - times[-1 - 2 * turns]
    return abs(last - before) <= SETTLE_RTOL * last


def _shooting(system: _System, particle_turns: np.ndarray, rtol: float, atol: float, *, consistent: bool = False):
    """The residual of (P) at (y0, T) and, with ``variations``, its derivatives.

    ``particle_turns`` (2N+1,): turns per period of every particle's angle (eq. (P) with
    2 pi times them on every angle). Returns (R, dR/dy0, dR/dT, dR/dM, monodromy); the
    last four are None without ``variations`` (a state-only integration, about ten times cheaper).
    With ``variations`` R comes from the integration with the variational equations (its steps, under
    error control on every column, are the shorter and its end the more accurate), or with ``consistent``
    from the state's own integration, as without them (a continuation's corrector: next to a saddle the
    two ends differ by more than the closure asked, and an iterate passed on one failed on the other at
    the same y0: 400 orbits crawled from T = 6.1 to 6.85 on the N = 1 sine chain).
    """
    shift = np.zeros(2 * system.nf)
    angles = zeros(system.params)
    angles[ROW_INDEX["phi"]] = particle_turns
    shift[: system.nf] = 2 * math.pi * pack(system.params, angles)

    def evaluate(y0: np.ndarray, period: float, variations: bool = True):
        if variations and not consistent:
            end, mono, d_moment = system.flow(y0, period, rtol=rtol, atol=atol, variations=True)
        else:
            end = system.flow(y0, period, rtol=rtol, atol=atol, variations=False)[0]
        residual = end - y0 - shift
        if not variations:
            return residual, None, None, None, None
        if consistent:
            _, mono, d_moment = system.flow(y0, period, rtol=rtol, atol=atol, variations=True)
        return residual, mono - np.eye(len(y0)), system.velocity(end), d_moment, mono

    return evaluate


#: A bound on h |lambda| for DOP853's steps on the fastest mode, above the extent of its stability
#: domain (about 6 along the negative real axis, less along the imaginary one): T omega_max / this
#: bounds the steps of one period from below.
DOP853_STABLE_STEP = 6.0


def require_integrable_period(params: ChainParams, model: Model, period: float) -> None:
    """Refuse a period that DOP853 cannot integrate within :data:`MAX_STEPS` steps.

    The chain's fastest mode omega_max (:meth:`Model.max_frequency`, the factors of a graded
    chain included) bounds the step from above by :data:`DOP853_STABLE_STEP` / omega_max, so one
    period takes at least T omega_max / DOP853_STABLE_STEP steps; a chain whose stiffness and
    inertia are many decades apart (a mass factor of 1e-90) would otherwise grind through
    ``MAX_STEPS`` steps per integration, many times over, before failing.

    Raises
    ------
    ValueError
        Naming the period, omega_max and the steps, where they exceed :data:`MAX_STEPS`.
    """
    omega = model.max_frequency(params)
    steps = period * omega / DOP853_STABLE_STEP
    if not steps <= MAX_STEPS:  # also NaN
        graded = ", their factors" if params.graded else ""
        raise ValueError(
            f"one period T = {period:.6g} of this chain takes at least {steps:.3g} integration steps (its fastest mode "
            f"omega_max = {omega:.3g}, from E1, E2, m, j{graded}), more than {MAX_STEPS:.0e}: the model is dimensionless, "
            "so scale stiffnesses and inertias to within a few decades of each other"
        )


@one_blas_thread
def _check_segments(params: ChainParams, segments: int | None, method: str) -> None:
    """Refuse ``segments`` that are not a positive integer, that ``method`` cannot take, or whose matrices do not fit in memory.

    Raises
    ------
    ValueError
        For segments < 1 or not an integer, or a method other than the dense and blocks shooting.
    MemoryEstimateError
        Where the segments' Jacobians do not fit in the free memory.
    """
    if segments is None:
        return
    if not (isinstance(segments, (int, np.integer)) and not isinstance(segments, bool) and segments >= 1):
        raise ValueError(f"segments must be an integer >= 1 (pieces of the period), got {segments!r}")
    if method not in ("dense", "blocks"):
        raise ValueError(
            f"segments applies to the dense and blocks shooting only, got method={method!r} "
            "(collocation takes its multipliers from its intervals' product already; krylov forms no matrices)"
        )
    size = 2 * n_free(params)
    require(
        segments * size * size * FLOAT, f"{segments} segment Jacobians of {size} x {size}",
        "fewer segments (--segments: 16 to 64 keep the smallest multipliers to round-off)",
    )  # fmt: skip


def _along_flow(mono: np.ndarray, multiplier: complex, flow: np.ndarray) -> float:
    """|cos| of the angle between the flow f(y0) and the eigenvector of ``mono`` for ``multiplier`` (the one taken for
    the trivial one), by two steps of inverse iteration from a fixed start (not the flow, which may lack the component
    sought): 1 for the true trivial multiplier."""
    shift = complex(multiplier) * (1.0 + 1e-12) + 1e-14  # off the eigenvalue by round-off's order: a regular solve
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", sla.LinAlgWarning)  # exactly singular: the solve's infinities say so below
        lu = sla.lu_factor(mono - shift * np.eye(len(flow)))
    vector = np.random.default_rng(0).standard_normal(len(flow)).astype(complex)
    for _ in range(2):
        with np.errstate(all="ignore"):
            vector = sla.lu_solve(lu, vector)
        if not np.all(np.isfinite(vector)) or not np.any(vector):
            return 1.0  # exactly singular there
        vector /= np.linalg.norm(vector)
    return float(abs(np.vdot(vector, flow)) / np.linalg.norm(flow))


def _multipliers(
    system: _System, y0: np.ndarray, period: float, mono: np.ndarray | None, method: str, segments: int | None, rtol: float, atol: float
) -> tuple[np.ndarray, np.ndarray | None, np.ndarray | None]:
    """The Floquet multipliers of the orbit from y0 (by decreasing modulus), their errors and log-moduli (None where not computed).

    ``dense``: the eigenvalues of the formed monodromy ``mono``, or with ``segments`` the periodic
    Schur form of the pieces' Jacobians (:meth:`_System.segment_jacobians`); ``blocks``:
    :func:`~.long_orbits.orbit_multipliers` (the trivial one deflated, with its error; with
    ``segments`` from the pieces' matrices assembled from column blocks).
    """
    if method == "blocks":
        return long_orbits.orbit_multipliers(system, y0, period, mono, segments, rtol=rtol, atol=atol)
    if segments is None:
        values = sla.eigvals(mono)
        return values[np.argsort(-np.abs(values), kind="stable")], None, None
    found = floquet.periodic_schur_multipliers(system.segment_jacobians(y0, period, segments, rtol=rtol, atol=atol))
    return found.values, None, found.log_moduli


def find_periodic_orbit(
    params: ChainParams,
    model: str | Model,
    moment: float,
    *,
    turns: int = 1,
    particle: int = 0,
    guess: PeriodicOrbit | tuple | None = None,
    tol: float = CLOSURE_TOL,
    max_iter: int = 25,
    rtol: float = RTOL,
    atol: float = ATOL,
    transient_turns: int = 30,
    method: str = "auto",
    segments: int | None = None,
    rho: float | None = None,
    guard: int | None = None,
) -> PeriodicOrbit:
    """The rotating state at ``moment`` as a limit cycle, by Newton on the shooting map (P).

    Parameters
    ----------
    params : ChainParams
    model : str or Model
        A model that is 2 pi periodic in the angles (``nonlinear``, ``sine``).
    moment : float
        Constant moment M on the loaded particle (non-zero).
    turns : int
        k >= 1, turns of the loaded particle per period; rotating states of the
        paper's chain at larger loads repeat only after 2 or 3 turns.
    particle : int
        The loaded particle.
    guess : PeriodicOrbit or (x (3, 2N+1), v (3, 2N+1), T[, particle_turns (2N+1,)]), optional
        Start of Newton's method (an orbit at a nearby moment); by default
        :func:`initial_guess` from rest (for ``method="picard"`` continued by :data:`PICARD_SETTLE`
        further settled runs), which also counts the turns every particle
        makes a period (the whole chain winds when it spins about a pin). A tuple
        without ``particle_turns``, or an orbit with other turns, winds the loaded
        particle alone. A guessed orbit on a phase plane (:attr:`PeriodicOrbit.phase_normal`)
        keeps its plane; any other guess is put on the section phi_0 = 0, or, where the flow
        is nearly tangent to it there (:data:`TRANSVERSAL_MIN`), on the plane through it
        normal to the flow.
    tol : float
        Newton stops when max |Phi_T(y0) - y0 - 2 pi k e_phi0| <= tol.
    max_iter : int
    rtol, atol : float
        Tolerances of the DOP853 integrations of the state and its variations.
    transient_turns : int
        Turns simulated before the default guess is taken.
    method : {"auto", "dense", "blocks", "krylov", "picard", "collocation"}
        ``dense``: the monodromy matrix integrated in one piece; ``blocks``: assembled from
        column blocks integrated on parallel threads, with the memory of M alone (all
        multipliers up to 2 n_free = 2500, the leading ones above); ``krylov``: never formed,
        Newton-Krylov shooting with the leading multipliers by Arnoldi (:mod:`~.long_orbits`);
        ``picard``: Newton-Picard shooting, the multipliers above ``newton_picard.RHO`` with their
        residuals (:mod:`~.newton_picard`); ``auto``: ``blocks`` from N = ``long_orbits.BLOCKS_FROM_N`` on, else ``dense``;
        ``collocation``: orthogonal collocation with its default mesh (:mod:`~.collocation_core`; ``tol``,
        ``rtol`` and ``atol`` do not apply), the start put on the section afterwards.
    segments : int, optional
        With the dense or the blocks method (the blocks integrated piece by piece,
        :func:`~.long_orbits.orbit_multipliers`; above 2 n_free = 2500 the leading ones only, with a
        warning): the multipliers from the Jacobians of this many equal pieces of the
        converged orbit (the variational equations integrated from the identity on each: one more
        integration of the monodromy's cost), by the periodic Schur form of their product
        (:func:`~.floquet.periodic_schur_multipliers`), with their log-moduli. The eigenvalues of
        the formed monodromy (the default) lose every multiplier below about 1e-16 times the
        largest; these keep them wherever each piece's own decay stays within the integration's
        tolerance (docs/periodic-orbits.md, Multipliers of long, strongly damped orbits).
    rho, guard : float, int, optional
        With ``method="picard"`` only: the modulus above which multipliers are Newton's (the
        rest Picard's; default ``newton_picard.RHO``) and the basis columns kept beyond them
        (default ``newton_picard.GUARD``); :func:`~.newton_picard.check_options` says what is allowed.

    Returns
    -------
    PeriodicOrbit

    Raises
    ------
    ValueError
        For an unknown method, a zero or non-finite moment, turns < 1 or a bad guess, and for a ring or a
        chain with two free ends (:func:`require_orbit_ends` says why).
    OrbitError
        If Newton's method does not converge (try a guess from a nearby moment, another
        ``turns``, or the rotation may be chaotic).
    """
    model = get_model(model)
    _check_moment_and_turns(moment, turns)
    for name, value in (("tol", tol), ("rtol", rtol), ("atol", atol)):
        if not (math.isfinite(value) and value > 0):
            raise ValueError(f"{name} must be a finite number > 0, got {value!r}")
    require_orbit_ends(params)
    collocating = method == "collocation"
    method = "dense" if collocating else long_orbits.choose_method(params, method)
    _check_segments(params, segments, "collocation" if collocating else method)
    if (rho is not None or guard is not None) and method != "picard":
        raise ValueError(f"rho and guard apply to method='picard' only, got method={method!r}")
    if method == "picard":
        newton_picard.check_options(
            newton_picard.RHO if rho is None else rho, newton_picard.GUARD if guard is None else guard, 2 * n_free(params)
        )  # fmt: skip
    particle_turns = _loaded_turns(params, particle, turns, moment)
    if guess is None:
        x0, v0, period, particle_turns = _settled_guess(
            params, model, moment, turns=turns, particle=particle, x0=None, v0=None, transient_turns=transient_turns, t_max=GUESS_T_MAX
        )
        for _ in range(PICARD_SETTLE if method == "picard" else 0):
            x0, v0, period, particle_turns = _settled_guess(
                params, model, moment, turns=turns, particle=particle, x0=x0, v0=v0, transient_turns=transient_turns, t_max=GUESS_T_MAX
            )
    elif isinstance(guess, PeriodicOrbit):
        x0, v0, period = guess.x, guess.v, guess.period
        if guess.particle_turns[column(params, particle)] == particle_turns[column(params, particle)]:
            particle_turns = guess.particle_turns
    elif len(guess) == 4:
        x0, v0, period = guess[:3]
        particle_turns = _check_particle_turns(params, particle, turns, moment, guess[3])
    else:
        x0, v0, period = guess
    if not (math.isfinite(period) and period > 0):
        raise ValueError(f"the guessed period must be finite and > 0, got {period!r}")
    require_integrable_period(params, model, period)
    system = _System(params, model, float(moment), particle)
    y0 = _to_y(params, check_state(params, x0, "guess x"), check_state(params, v0, "guess v"))
    # A guessed orbit on a phase plane keeps its plane; any other guess is put on phi_0 = 0.
    normal = guess.phase_normal if isinstance(guess, PeriodicOrbit) else None
    if normal is None:
        y0[system.load_dof] = 0.0
    phase = _phase_for(system, y0, normal)
    if collocating:
        try:
            solved = collocation_core.solve_profile(system, y0, period, particle_turns, max_iter=max_iter)
        except collocation_core.CollocationError as err:
            raise OrbitError(str(err)) from err
        y0, normal = collocation_core.section_state(system, solved.mesh, solved.ncol, solved.profile, particle_turns, TRANSVERSAL_MIN)
        return _orbit_from(
            system, turns, y0, solved.period, solved.multipliers, solved.residual, solved.iterations, particle_turns, normal,
            multiplier_log_moduli=solved.log_moduli,
        )  # fmt: skip
    if method != "dense":
        return _long_orbit(
            system, turns, y0, period, particle_turns, phase, method, tol=tol, max_iter=max_iter, rtol=rtol, atol=atol, segments=segments,
            picard={"rho": rho, "guard": guard},
        )  # fmt: skip
    evaluate = _shooting(system, particle_turns, rtol, atol)
    keep = phase.keep

    def closure(w: np.ndarray, jacobian: bool) -> Evaluation:
        """(P) and the phase condition at w = (y0's unknowns, T) and, with ``jacobian``, their Jacobian and the monodromy (``data``)."""
        if not w[-1] > 0:
            raise EvaluationFailed(f"the period must stay > 0, got {w[-1]!r}")
        y = phase.state(w[:-1])
        residual, jac_y, jac_t, _, mono = evaluate(y, w[-1], jacobian)
        residual = np.append(residual, phase.residual(y))
        if jac_y is None:
            return Evaluation(residual, None, mono)
        return Evaluation(residual, np.vstack([np.column_stack([jac_y[:, keep], jac_t]), phase.rows(len(w))]), mono)

    # Newton with the Jacobian reused while it still converges fast (chord): a step costs one
    # state-only integration, and the variational equations are integrated again only
    # when the closure falls by less than NEWTON_RATE, or at the end for the multipliers;
    # a step that makes the closure worse is halved (a rough guess far from the orbit).
    solved = newton(
        closure, np.append(y0[keep], period), tol=tol, max_iterations=max_iter, divergence=None, chord=NEWTON_RATE, damping=MAX_HALVINGS
    )
    if not solved.converged:
        raise OrbitError(_no_convergence(moment, turns, solved.iterations, solved.norm))
    y0 = phase.state(solved.w[:-1])
    multipliers, _, logs = _multipliers(system, y0, solved.w[-1], solved.evaluation.data, "dense", segments, rtol, atol)
    return _orbit_from(
        system, turns, y0, solved.w[-1], multipliers, solved.norm, solved.iterations, particle_turns, phase.normal,
        multiplier_log_moduli=logs,
    )  # fmt: skip


def _long_orbit(
    system, turns, y0, period, particle_turns, phase, method, *, tol, max_iter, rtol, atol, segments=None, picard=None
) -> PeriodicOrbit:
    """:func:`find_periodic_orbit` by the blocks, Newton-Krylov (:mod:`.long_orbits`) or Newton-Picard (:mod:`.newton_picard`: the
    trivial multiplier and those above its rho), with the multipliers' errors
    (by the blocks with ``segments``: from the segments' matrices, :func:`~.long_orbits.orbit_multipliers`)."""
    correct = {"krylov": long_orbits.krylov_correction, "picard": newton_picard.picard_correction}.get(
        method, long_orbits.blocks_correction
    )
    options = {} if segments is None else {"segments": segments}
    if method == "picard":
        options.update(picard or {})
    try:
        solved, monodromy = correct(
            system, phase, particle_turns, np.append(y0[phase.keep], period), tol=tol, max_iter=max_iter, rtol=rtol, atol=atol,
            damping=MAX_HALVINGS, **options,
        )  # fmt: skip
        if not solved.converged:
            hint = "; Newton-Picard wants a guess near the orbit: method='blocks' converges from farther" if method == "picard" else ""
            raise OrbitError(_no_convergence(system.moment, turns, solved.iterations, solved.norm) + hint)
        y0 = phase.state(solved.w[:-1])
        if method == "picard":  # the Ritz values of the converged dominant subspace
            (multipliers, errors), logs = monodromy, None
        else:
            multipliers, errors, logs = long_orbits.orbit_multipliers(system, y0, solved.w[-1], monodromy, segments, rtol=rtol, atol=atol)
    except EvaluationFailed as err:
        raise OrbitError(f"the monodromy's products at the orbit failed: {err}") from err
    return _orbit_from(
        system, turns, y0, solved.w[-1], multipliers, solved.norm, solved.iterations, particle_turns, phase.normal, errors,
        multiplier_log_moduli=logs,
    )  # fmt: skip


def _no_convergence(moment: float, turns: int, iterations: int, norm: float) -> str:
    return (
        f"Newton on the shooting map did not converge at M={moment!r} with turns={turns} "
        f"({iterations} iterations, closure {norm:.3g}); start from an orbit at a nearby moment, try turns=2 or 3 "
        "(states that repeat after several turns), or the rotation may not be periodic (chaotic)"
    )


def _orbit(
    system: _System,
    turns: int,
    y0: np.ndarray,
    period: float,
    mono: np.ndarray,
    closure: float,
    iterations: int,
    particle_turns: np.ndarray,
    phase_normal: np.ndarray | None = None,
) -> PeriodicOrbit:
    multipliers, _, _ = _multipliers(system, y0, period, mono, "dense", None, RTOL, ATOL)
    return _orbit_from(system, turns, y0, period, multipliers, closure, iterations, particle_turns, phase_normal)


def _orbit_from(
    system: _System,
    turns: int,
    y0: np.ndarray,
    period: float,
    multipliers: np.ndarray,
    closure: float,
    iterations: int,
    particle_turns: np.ndarray,
    phase_normal: np.ndarray | None = None,
    multiplier_errors: np.ndarray | None = None,
    multiplier_log_moduli: np.ndarray | None = None,
) -> PeriodicOrbit:
    """The solved orbit at y0 with its multipliers (all, by decreasing modulus, or the leading ones with their errors)."""
    x, v = _from_y(system.params, y0)
    return PeriodicOrbit(
        params=system.params,
        model=system.model.name,
        moment=float(system.moment),
        turns=turns,
        particle=system.particle,
        period=float(period),
        x=x,
        v=v,
        multipliers=multipliers,
        closure=float(closure),
        iterations=iterations,
        particle_turns=particle_turns,
        phase_normal=phase_normal,
        multiplier_errors=multiplier_errors,
        multiplier_log_moduli=multiplier_log_moduli,
    )


#: Ways a continuation ends.
END_FOLD = "fold"
END_INFINITE_PERIOD = "infinite_period"
END_MOMENT_MIN = "moment_min"
END_MAX_POINTS = "max_points"
END_STEP_TOO_SMALL = Status.STEP_TOO_SMALL
END_UNSTABLE = "unstable"
#: M turned back on a transversal phase plane without a real Floquet multiplier crossing +1: not a fold of cycles.
END_UNCONFIRMED_TURN = "unconfirmed_turn"
#: Located events where an orbit may lose its stability (:attr:`OrbitBranch.stability_lost_at`).
STABILITY_EVENTS = ("period_doubling", "torus", "branch_point")
#: An orbit whose trivial multiplier (1 exactly) is off by more than this has its other multipliers unresolved too:
#: :attr:`OrbitBranch.stability_lost_at` reads the branch's stability only up to the first such orbit (a collocation
#: branch of the N = 1 sine chain towards its homoclinic end, 40 intervals, "lost" it at T = 22 where the trivial one
#: was 0.7 off and the largest other 14.4, for a true 0.37).
STABILITY_RESOLVED = 1e-2
#: The message of a branch that ends at a fold of cycles (the shooting's and the collocation's).
FOLD_OF_CYCLES = "fold of limit cycles: the moment turns back with the period finite and a Floquet multiplier crosses +1"


@dataclass
class OrbitBranch:
    """Periodic orbits traced in M by :func:`continue_orbit`.

    Attributes
    ----------
    orbits : list of PeriodicOrbit
        In the order traced (downwards in M until the end).
    end : str
        ``fold`` (a fold of limit cycles: M turns back, the period stays finite, and a real
        Floquet multiplier crosses +1 between the orbits around the turn),
        ``infinite_period`` (T exceeded ``period_max``: a homoclinic end),
        ``moment_min``, ``unstable`` (asked to stop at the first unstable orbit after
        stable ones), ``max_points``, ``step_too_small`` (continuation failed) or
        ``unconfirmed_turn`` (M turned back without a multiplier at +1: no fold of cycles
        is claimed; the message says where).
    end_moment : float
        Where the orbit ceases to exist: the fold's moment (a parabola through the
        three points around the turn), or the last moment reached for the other ends.
    message : str
    events : list of dict
        In the order of the branch. Branch points of cycles passed on the way: ``{"kind": "branch_point",
        "moment": M}``, where a real multiplier crosses +1 while M does not turn (M interpolated linearly in
        the multiplier between the two orbits around it); the branch goes on through them. Period
        doublings and tori (``"kind": "period_doubling"`` or ``"torus"``, with ``"located"``,
        ``"multiplier"`` [re, im] and a torus's ``"angle"``): located on every route, the shooting's
        (:func:`~.cycle_events.locate_circle_events`: M to its ``"accuracy"``, with the located ``"orbit"``) and
        the collocation's (``CollocationBranch.orbit_branch``).
    """

    orbits: list[PeriodicOrbit]
    end: str
    end_moment: float
    message: str
    settings: dict = field(default_factory=dict)
    events: list[dict] = field(default_factory=list)

    @property
    def moment(self) -> np.ndarray:
        return np.array([o.moment for o in self.orbits])

    @property
    def period(self) -> np.ndarray:
        return np.array([o.period for o in self.orbits])

    @property
    def mean_angular_velocity(self) -> np.ndarray:
        return np.array([o.mean_angular_velocity for o in self.orbits])

    @property
    def max_multiplier(self) -> np.ndarray:
        return np.array([o.max_multiplier for o in self.orbits])

    @property
    def stable(self) -> np.ndarray:
        return np.array([o.stable for o in self.orbits])

    @property
    def stability_lost_at(self) -> float | None:
        """M where the orbit, stable at the start, first loses stability along the branch.

        A located event between the last stable and the first unstable orbit (a period
        doubling, a torus or a branch point of cycles) gives it; otherwise the largest
        nontrivial multiplier modulus is interpolated linearly in M to 1 between them (the
        collocation's steps are long: the interpolation put the sine chain's period doubling
        at gamma_phi = 0.15 at 0.17269, located at 0.17288). None if it never does.
        Below it the rotating state seen in a simulation is no longer this orbit, so
        with a fold below it this, not the fold, is the lower edge of the hysteresis loop.
        Read only up to the first orbit whose trivial multiplier is off by more than
        :data:`STABILITY_RESOLVED` (its multipliers do not decide stability).
        """
        resolved = np.array([abs(o.trivial_multiplier - 1.0) <= STABILITY_RESOLVED for o in self.orbits])
        stable = self.stable[: len(resolved) if resolved.all() else int(np.argmin(resolved))]
        if not stable.size or not stable[0] or stable.all():
            return None
        i = int(np.argmin(stable))
        (m0, m1), (r0, r1) = self.moment[i - 1 : i + 1], self.max_multiplier[i - 1 : i + 1]
        for event in self.events:
            if event["kind"] in STABILITY_EVENTS and event.get("located", True) and min(m0, m1) <= event["moment"] <= max(m0, m1):
                return float(event["moment"])
        return float(m0 + (1.0 - r0) * (m1 - m0) / (r1 - r0))


@one_blas_thread
def continue_orbit(
    orbit: PeriodicOrbit,
    *,
    moment_min: float = 0.0,
    period_max: float = 2000.0,
    step: float = 0.05,
    min_step: float = 1e-7,
    max_step: float = 0.5,
    max_points: int = 400,
    until_unstable: bool = False,
    tol: float = CLOSURE_TOL,
    rtol: float = RTOL,
    atol: float = ATOL,
    progress: ProgressCallback | None = None,
    method: str = "auto",
    segments: int | None = None,
) -> OrbitBranch:
    """Pseudo-arclength continuation of a periodic orbit towards smaller |M|, until it ceases to exist.

    The unknowns are w = (y0, log T, M), y0 without phi_0 on the section phi_0 = 0, the equations (P) (and the
    phase plane's, where one replaces the section) and the
    arclength condition t . (w - w_pred) = 0 with t the unit tangent of the branch
    (the null vector of d(P)/dw); the bordered Jacobian is regular at a fold of
    limit cycles, so a fold is passed and detected as a sign change of dM/ds (the kit's
    driver, :func:`~.kit.continuation`, with its corrector in chord iterations:
    :data:`NEWTON_RATE`). A step over
    which a multiplier near the unit circle (:data:`MULTIPLIER_WATCH`) moves farther than
    :data:`MAX_MULTIPLIER_MOTION` in the complex plane is retaken shorter, so that a loss of
    stability between two stable orbits is not stepped over (a window can still hide where
    the multipliers move less than that across it).

    The phase condition never goes singular: where the flow turns towards tangency with the
    section (the cosine |phi_0'| / |f| below :data:`TRANSVERSAL_DROP` of its value at the
    start, or the crossing reversed) the continuation goes on from that orbit with the plane
    through it normal to the flow, itself re-chosen where the flow turns away from it. A turn
    of M is a fold of cycles only where a real multiplier crosses +1 between the orbits
    around it; on the section, a turn without one (two crossings of the section merging) is
    passed the same way, and on a plane it ends the branch as ``unconfirmed_turn``.

    Period doublings and tori are located once the branch is traced: between two consecutive orbits
    where a test function of :func:`~.cycle_events.circle_tests` changes sign, Brent's method in M
    (to :data:`~.cycle_events.MOMENT_TOL`) on that test, each trial the orbit re-solved at its M by
    :func:`find_periodic_orbit` with this ``method`` (and ``segments``) from the orbit interpolated
    between the two; kept where the critical multiplier lies on -1 or the unit circle
    (:attr:`OrbitBranch.events`). M turns in the step that holds the fold, so where a test also changes sign
    there the kit locates the fold (then the branch's ``end_moment``) and that step is searched in its two halves on
    either side of it (:func:`~.cycle_events.steps`, as on a system's branch). With ``picard`` the tests see the multipliers above rho only,
    where every crossing of the unit circle happens.

    Parameters
    ----------
    orbit : PeriodicOrbit
        Start (from :func:`find_periodic_orbit`).
    moment_min : float
        Stop when |M| falls below it.
    period_max : float
        Stop when T exceeds it: the period diverges (a homoclinic or SNIC end).
    step, min_step, max_step : float
        Initial, smallest and largest arclength steps in (y0, log T, M).
    max_points : int
    until_unstable : bool
        Stop at the first unstable orbit after stable ones: where the stability is lost is
        then known (:attr:`OrbitBranch.stability_lost_at`) and the rest of the branch, down
        to its fold, is not traced (benchmarks/TIMINGS.md).
    tol, rtol, atol : float
        As for :func:`find_periodic_orbit`.
    progress : callable(points, max_points), optional
    method : {"auto", "dense", "blocks", "picard"}
        How the monodromy is integrated (:func:`find_periodic_orbit`); ``blocks`` takes
        dPhi_T/dM by central differences in M (:func:`~.long_orbits.blocked_shooting`), and
        every orbit's multipliers as :func:`find_periodic_orbit`'s blocks give them (the trivial
        one deflated, with its error: :attr:`PeriodicOrbit.trivial_multiplier_error`);
        ``picard`` never forms the monodromy: Newton-Picard corrector steps and tangents on the
        subspace of the multipliers above ``newton_picard.RHO``, carried from point to point
        (:class:`_PicardBranchProblem`), each orbit with the trivial multiplier and those above
        rho and their Ritz residuals (the ones a fold, a branch point or a loss of stability moves
        across the unit circle); dPhi_T/dM as the blocks take it.
    segments : int, optional
        Every orbit's multipliers from the Jacobians of this many equal pieces of it, with their
        log-moduli, as ``find_periodic_orbit(..., segments=)`` (one more integration of the
        monodromy's cost a point: the corrector still forms M for its Newton steps and the
        tangent). The branch itself is the one without segments.

    Returns
    -------
    OrbitBranch

    Raises
    ------
    ValueError
        For non-positive steps, an unordered step range, a method not in auto, dense, blocks, picard, or bad
        ``segments`` (as :func:`find_periodic_orbit`; picard takes none).
    OrbitError
        With ``picard``, where the start does not close under Newton-Picard at its moment.
    """
    for name, value in (("step", step), ("min_step", min_step), ("max_step", max_step), ("period_max", period_max)):
        if not (math.isfinite(value) and value > 0):
            raise ValueError(f"{name} must be a finite number > 0, got {value!r}")
    if not min_step <= step <= max_step:
        raise ValueError(f"steps must satisfy min_step <= step <= max_step, got {min_step!r}, {step!r}, {max_step!r}")
    method = long_orbits.choose_method(orbit.params, method)
    if method == "krylov":
        raise ValueError(
            "continue_orbit's method must be auto, dense, blocks or picard (a continuation needs the monodromy or its dominant "
            "subspace), got 'krylov'"
        )
    _check_segments(orbit.params, segments, method)
    params, model = orbit.params, get_model(orbit.model)
    sign = math.copysign(1.0, orbit.moment)
    settings = {"moment_min": moment_min, "period_max": period_max, "step": step, "max_step": max_step, "tol": tol, "rtol": rtol}
    system = _System(params, model, orbit.moment, orbit.particle)
    phase = _phase_for(system, _to_y(params, orbit.x, orbit.v), orbit.phase_normal)
    if segments is not None and orbit.multiplier_log_moduli is None:
        # The start's multipliers from its segments too, so that the whole branch carries them alike.
        y = _to_y(params, orbit.x, orbit.v)
        values, errors, logs = _multipliers(
            system, y, orbit.period, long_orbits.Monodromy(system, y, orbit.period, rtol, atol), method, segments, rtol, atol
        )  # fmt: skip
        orbit = dataclasses.replace(orbit, multipliers=values, multiplier_errors=errors, multiplier_log_moduli=logs)
    orbits: list[PeriodicOrbit] = []
    first, notes, h = orbit, [], step
    # Newton-Picard's dominant subspace goes on from problem to problem (a restart on a phase plane).
    carried = {"direction": -sign} if method == "picard" else {}
    orientation = None
    while True:
        problem = (_PicardBranchProblem if method == "picard" else _OrbitBranchProblem)(
            first, model, phase, tol, rtol, atol, moment_min, period_max, until_unstable, orbit.stable, method=method, segments=segments,
            **carried,
        )  # fmt: skip
        w0 = problem.pack(first)
        if method == "picard":
            w0, settled = problem.settle(w0)
            first = first if settled else None
            carried["subspace"] = problem.subspace
        # A restart's first orbit is the last one already traced.
        offset = max(len(orbits) - 1, 0)
        traced = continuation(
            problem,
            w0,
            step=h,
            min_step=min_step,
            max_step=max_step,
            max_points=max_points - offset,
            direction=-sign,
            tangent0=orientation,
            stop_at=(BranchEnd.FOLD,),
            progress=None if progress is None else (lambda done, total, offset=offset: progress(offset + done, max_points)),
            corrector={"max_iterations": MAX_CORRECTOR_ITERATIONS, "chord": NEWTON_RATE, "forgive": 0},
            easy=EASY_ITERATIONS,
            hard=HARD_ITERATIONS,
            # The fold's moment is the parabola through the last three orbits (_fold_moment); the kit locates a fold only
            # in a step where a circle test also changes sign (_OrbitBranchProblem.locate), whose halves are searched.
            locate=True,
            tangent_method="svd",
            first=first,
        )
        orbits.extend(traced.points[1:] if orbits else traced.points)
        folds = {offset + e.index: e.point for e in traced.events if e.kind == BranchEnd.FOLD and e.located}
        turned_falsely = traced.end == BranchEnd.FOLD and not _crosses_one(*traced.points[-2:])
        if not ((problem.rechoose or turned_falsely) and phase.normal is None and len(traced.points) >= 2):
            break
        # The section has become (nearly) tangent to the flow: on from the last orbit with the plane through it,
        # at the step that reached that orbit.
        last = traced.points[-1]
        h = min(max_step, max(min_step, float(np.linalg.norm(problem.pack(last) - problem.pack(traced.points[-2])))))
        phase = _plane(_System(params, model, last.moment, last.particle), _to_y(params, last.x, last.v))
        first = dataclasses.replace(last, phase_normal=phase.normal)
        # On the way the last step went in (log T, M): towards a homoclinic end M hardly moves, and the sign of the new
        # tangent's dM (the orientation from rest) is round-off; it took the branch back the way it came.
        previous = traced.points[-2]
        orientation = np.zeros(phase.head + 2)
        orientation[phase.head :] = (math.log(last.period / previous.period), last.moment - previous.moment)
        notes.append(
            f"the flow became tangent to the section phi_0 = 0 near M = {last.moment:.10g}"
            + (" (the section's system turned back there with no multiplier at +1: no fold)" if turned_falsely else "")
            + "; continued with the phase plane normal to the flow"
        )
    end, message = _ORBIT_ENDS[traced.end], traced.message
    if traced.end == BranchEnd.FOLD and not _crosses_one(*orbits[-2:]):
        end = END_UNCONFIRMED_TURN
        message = (
            f"M turned back near M = {orbits[-1].moment:.10g} with no real Floquet multiplier crossing +1: not a fold of cycles "
            "(the phase condition may be singular there); try smaller steps"
        )
    elif traced.end == BranchEnd.FOLD:
        message = FOLD_OF_CYCLES
    elif traced.end == BranchEnd.MAX_POINTS:
        message = f"stopped after max_points={max_points} orbits"
    elif traced.end == BranchEnd.STEP_TOO_SMALL:
        message = f"the arclength step fell below min_step={min_step:g} after M={orbits[-1].moment:.10g}"
        if orbits[-1].period > 2.0 * orbits[0].period:
            message += (
                f" with the period grown to T = {orbits[-1].period:.6g}: single shooting's accuracy runs out towards a "
                "homoclinic or SNIC end (the flow's growth past the saddle); collocation (method='collocation') follows the period further"
            )
    end_moment = orbits[-1].moment
    if end == END_FOLD and folds:
        end_moment = next(iter(folds.values())).moment
    elif end == END_FOLD and len(orbits) >= 3:
        end_moment = _fold_moment(orbits[-3:], sign)
    # Period doublings and tori located in M between the orbits where their tests turned, each trial re-solved by this
    # branch's corrector (cycle_events; a step that holds a located fold in its halves on either side of it, as on a
    # system's branch); branch points of cycles interpolated: in the order of the branch.
    between = partial(_orbit_between, method=method, segments=segments, tol=tol, rtol=rtol, atol=atol)
    found = [*_branch_points(orbits, end == END_FOLD), *cycle_events.locate_circle_events(orbits, between, folds=folds)]
    events = [event for _, event in sorted(found, key=lambda item: item[0])]
    message = "; ".join([message, *notes])
    return OrbitBranch(orbits=orbits, end=end, end_moment=float(end_moment), message=message, settings=settings, events=events)


def _one_test(orbit: PeriodicOrbit) -> float:
    """Re prod (mu - 1) over the nontrivial multipliers: its sign changes where a real one crosses +1.

    Where only the leading multipliers are known (Newton-Picard: those above rho), each one left out
    lies inside the unit circle, so a real one contributes a negative factor and a complex pair a
    positive one: the product's sign is the known factors' times (-1) to the number left out, which
    keeps a real multiplier that drops below rho from passing for a crossing of +1.
    """
    omitted = 2 * n_free(orbit.params) - orbit.multipliers.size
    return float(np.real(np.prod(orbit.nontrivial_multipliers - 1.0))) * (-1.0) ** omitted


def _crosses_one(before: PeriodicOrbit, after: PeriodicOrbit) -> bool:
    """Whether a real nontrivial Floquet multiplier crosses +1 between two orbits."""
    return _one_test(before) * _one_test(after) < 0


def _branch_points(orbits: list[PeriodicOrbit], folded: bool) -> list[tuple[int, dict]]:
    """Crossings of +1 between consecutive orbits, but the fold's (the last pair when ``folded``), each with the index
    of the orbit after it."""
    events = []
    last = len(orbits) - 1 - folded
    for i, (a, b) in enumerate(zip(orbits[:last], orbits[1 : last + 1]), start=1):
        if _crosses_one(a, b):
            ga, gb = _one_test(a), _one_test(b)
            events.append((i, {"kind": "branch_point", "moment": float(a.moment + ga * (b.moment - a.moment) / (ga - gb))}))
    return events


def _orbit_between(
    moment: float, a: PeriodicOrbit, b: PeriodicOrbit, *, method: str, segments: int | None, tol: float, rtol: float, atol: float
) -> PeriodicOrbit:
    """The orbit at ``moment`` between two consecutive orbits a and b of a branch, by :func:`find_periodic_orbit`'s
    ``method`` from the orbit interpolated linearly in M between them (on b's phase condition: a plane re-chosen at a
    passes through a)."""
    w = (moment - a.moment) / (b.moment - a.moment)
    guess = dataclasses.replace(b, x=a.x + w * (b.x - a.x), v=a.v + w * (b.v - a.v), period=a.period + w * (b.period - a.period))
    return find_periodic_orbit(
        b.params, b.model, moment, turns=b.turns, particle=b.particle, guess=guess, tol=tol, rtol=rtol, atol=atol, method=method,
        segments=segments,
    )  # fmt: skip


#: The kit's ends as :class:`OrbitBranch` names them.
_ORBIT_ENDS = {
    BranchEnd.FOLD: END_FOLD,
    BranchEnd.INFINITE_PERIOD: END_INFINITE_PERIOD,
    BranchEnd.PARAMETER_LIMIT: END_MOMENT_MIN,
    BranchEnd.MAX_POINTS: END_MAX_POINTS,
    BranchEnd.STEP_TOO_SMALL: END_STEP_TOO_SMALL,
    BranchEnd.UNSTABLE: END_UNSTABLE,
}


@dataclass
class _OrbitBranchProblem:
    """(P) and the phase condition with M unknown for :func:`~.kit.continuation`: w = (y0's unknowns, log T, M)."""

    start: PeriodicOrbit
    model: Model
    phase: _Phase
    tol: float
    rtol: float
    atol: float
    moment_min: float
    period_max: float
    until_unstable: bool
    start_stable: bool
    #: Set by :meth:`stop` where the section must give way to a plane (the branch is then ended here and restarted).
    rechoose: bool = False
    #: ``dense`` or ``blocks`` (:func:`continue_orbit`).
    method: str = "dense"
    #: Pieces of each orbit its multipliers come from (:func:`_multipliers`); None: the formed monodromy.
    segments: int | None = None
    #: The residual from the state's own integration with or without the Jacobian (:func:`_shooting`'s ``consistent``):
    #: a branch's corrector; False for the more accurate residual of the variational integration (the march onto a
    #: Hopf point's small orbits, whose double multiplier at +1 turns residual noise into amplitude).
    consistent: bool = True

    def __post_init__(self) -> None:
        self.crossing0 = self._crossing(self.start)
        # (orbit, cosine, ||M||) of the dense orbits whose trivial multiplier is not along the flow (ALONG_FLOW).
        self.lost: list[tuple[PeriodicOrbit, float, float]] = []

    def pack(self, orbit: PeriodicOrbit) -> np.ndarray:
        return np.concatenate([_to_y(orbit.params, orbit.x, orbit.v)[self.phase.keep], [math.log(orbit.period), orbit.moment]])

    def _crossing(self, orbit: PeriodicOrbit) -> float:
        system = _System(orbit.params, self.model, orbit.moment, orbit.particle)
        return self.phase.crossing(system, _to_y(orbit.params, orbit.x, orbit.v))

    def evaluate(self, w: np.ndarray, jacobian: bool) -> Evaluation:
        """(P) and the phase condition at w and, with ``jacobian``, their Jacobian in (y0's unknowns, log T, M)."""
        head = self.phase.head
        if w[head] > math.log(100 * self.period_max):
            raise EvaluationFailed("the period ran off to 100 period_max: the corrector has left the branch")
        y0 = self.phase.state(w[:head])
        period, moment = math.exp(w[head]), w[head + 1]
        system = _System(self.start.params, self.model, moment, self.start.particle)
        shooting = partial(_shooting, consistent=self.consistent) if self.method == "dense" else long_orbits.blocked_shooting
        try:
            residual, jac_y, jac_t, d_moment, mono = shooting(system, self.start.particle_turns, self.rtol, self.atol)(y0, period, jacobian)
        except OrbitError as err:
            raise EvaluationFailed(str(err)) from err
        residual = np.append(residual, self.phase.residual(y0))
        if not jacobian:
            return Evaluation(residual)
        top = np.column_stack([jac_y[:, self.phase.keep], period * jac_t, d_moment])
        return Evaluation(residual, np.vstack([top, self.phase.rows(len(w))]), mono)

    def point(self, w: np.ndarray, evaluation: Evaluation, iterations: int) -> PeriodicOrbit:
        head = self.phase.head
        y0 = self.phase.state(w[:head])
        system = _System(self.start.params, self.model, float(w[head + 1]), self.start.particle)
        closure, period = float(np.max(np.abs(evaluation.residual))), math.exp(w[head])
        multipliers, errors, logs = _multipliers(system, y0, period, evaluation.data, self.method, self.segments, self.rtol, self.atol)
        orbit = _orbit_from(
            system, self.start.turns, y0, period, multipliers, closure, iterations, self.start.particle_turns, self.phase.normal,
            errors, logs,
        )  # fmt: skip
        if self.method == "dense":
            cosine = _along_flow(evaluation.data, orbit.trivial_multiplier, system.velocity(y0))
            if cosine < ALONG_FLOW or abs(orbit.trivial_multiplier - 1.0) > shooting.TRIVIAL_LOST:
                self.lost.append((orbit, cosine, float(np.linalg.norm(evaluation.data, np.inf))))
        return orbit

    def accept(self, previous: PeriodicOrbit, candidate: PeriodicOrbit) -> bool:
        # A step over which a multiplier near the unit circle moves this far can hide a
        # window of instability between two stable orbits (one random N = 4 chain's pair
        # rose above 1 and came back between M = 0.677 and 0.620, the largest modulus
        # there 0.975 and 0.982): retaken shorter. So is a step that lands on a crossing of
        # the phase condition the other way (the section's point slid to where the loaded
        # particle backs up).
        if self._crossing(candidate) * self.crossing0 <= 0:
            return False
        return _multiplier_motion(previous.multipliers, candidate.multipliers) <= MAX_MULTIPLIER_MOTION

    def tests(self, point: PeriodicOrbit) -> dict[str, float]:
        return {}

    def stop(self, point: PeriodicOrbit) -> tuple[BranchEnd, str] | None:
        lost = next((entry for entry in self.lost if entry[0] is point), None)
        if lost is not None:
            return (
                BranchEnd.INFINITE_PERIOD,
                f"the shooting's accuracy is exhausted at M = {point.moment:.12g}, T = {point.period:.8g}: the multiplier nearest +1 "
                f"is {point.trivial_multiplier:.4g}, its eigenvector at cosine {lost[1]:.2g} to the flow (the trivial one: 1 along "
                f"it; ||M|| = {lost[2]:.2g}); the period grows on: collocation (--method collocation) follows the branch further",
            )
        if point.period > self.period_max:
            return BranchEnd.INFINITE_PERIOD, f"the period exceeded period_max={self.period_max:g}: it diverges (a homoclinic or SNIC end)"
        if abs(point.moment) < self.moment_min:
            return BranchEnd.PARAMETER_LIMIT, f"|M| fell below moment_min={self.moment_min:g}"
        if self.until_unstable and self.start_stable and not point.stable:
            return BranchEnd.UNSTABLE, f"stopped at the first unstable orbit, M = {point.moment:.10g}"
        crossing = self._crossing(point)
        if abs(crossing) < TRANSVERSAL_DROP * abs(self.crossing0) or crossing * self.crossing0 <= 0:
            if self.phase.normal is None:
                # The unknowns change (phi_0 joins them): continue_orbit restarts the branch from here.
                self.rechoose = True
                return BranchEnd.MAX_POINTS, "the section is re-chosen"
            # The whole state is unknown on a plane: the next plane passes through this orbit, normal to the flow.
            self.phase = _plane(_System(point.params, self.model, point.moment, point.particle), _to_y(point.params, point.x, point.v))
            self.crossing0 = 1.0
        return None

    def confirm(self, kind: str, point: PeriodicOrbit) -> bool:
        return True

    def locate(self, kind: str, w, t, h, previous: PeriodicOrbit, candidate: PeriodicOrbit, index: int) -> Event | None:
        """The kit's event of ``kind`` between ``previous`` and ``candidate`` as the kit reports an unlocated one (at
        ``candidate``), but a fold in a step where a test of :func:`~.cycle_events.circle_tests` also changes sign: None,
        so that the kit locates it (its orbit splits the step for :func:`~.cycle_events.locate_circle_events`).
        Newton-Picard's corrections have no formed Jacobian to locate with: its folds stay unlocated."""
        before, after = (cycle_events.circle_tests(orbit.nontrivial_multipliers) for orbit in (previous, candidate))
        if kind == BranchEnd.FOLD and self.method != "picard" and any(before[k] * after[k] < 0 for k in cycle_events.CIRCLE_KINDS):
            return None
        return Event(kind, candidate, candidate.moment, index, None, located=False)


#: Subspace-iteration sweeps for each orbit's multipliers on a picard branch, from the last point's basis: those near the
#: unit circle (the ones an end moves across it) converge first, those just above rho last; each carries its residual.
BRANCH_RITZ_SWEEPS = 3
#: Picard's relative tolerance in the tangent's solve (the predictor's direction and the sign of its dM that tells a fold).
TANGENT_PICARD_RTOL = 1e-8


@dataclass
class _PicardJacobian:
    """dR/dw of :class:`_PicardBranchProblem` at one iterate, as products, never formed: the monodromy's (at
    :data:`~.long_orbits.NEWTON_PRODUCTS_RTOL`), f(Phi_T(y0)) and dPhi_T/dM (central differences, at its first use)."""

    system: _System
    monodromy: long_orbits.Monodromy
    velocity_end: np.ndarray
    rtol: float
    atol: float
    moment: np.ndarray | None = None

    def moment_column(self) -> np.ndarray:
        if self.moment is None:
            self.moment = long_orbits.moment_column(self.system, self.monodromy.start, self.monodromy.period, self.rtol, self.atol)
        return self.moment


@dataclass
class _PicardBranchProblem(_OrbitBranchProblem):
    """The branch of :class:`_OrbitBranchProblem` corrected by Newton-Picard steps (:mod:`~.newton_picard`).

    The bordered Newton step of (P), the phase condition and the arclength condition b . dw = r,

        (M - I) dy + T f(Phi_T(y0)) d(log T) + dPhi_T/dM dM = -R,   c . dy = -phase residual,

    is split as dy = V_p a + q along the basis V_p of the multipliers above ``rho`` carried from
    step to step and from point to point (the previous point's basis is the next one's warm start
    of the subspace iteration): Picard gives q = q_R + q_T d(log T) + q_M dM on the complement
    (:func:`~.newton_picard.complement`, three columns), and a dense (p + 2) system gives a,
    d(log T) and dM. The tangent is the same solve with R = 0 and the previous tangent as the
    border (b . t = 1), from the correction's last step (its V_p, q_T and q_M: no more products).
    Every point's multipliers are the trivial one and those above ``rho`` with their Ritz residuals (:func:`~.newton_picard.ritz_multipliers`), which hold every multiplier
    that a fold, a branch point, a torus or a period doubling moves across the unit circle.
    """

    #: -1 or +1: the sign of dM the branch starts with.
    direction: float = -1.0
    rho: float = newton_picard.RHO
    guard: int = newton_picard.GUARD
    subspace: object = None
    #: The last Newton-Picard step's reduced system (:meth:`solve`), None before a correction's first step.
    reduced: tuple | None = None

    def __post_init__(self) -> None:
        super().__post_init__()
        # A short chain's whole space is smaller than the default guard asks for.
        self.guard = min(self.guard, 2 * n_free(self.start.params) - 2)
        if self.subspace is None:
            self.subspace = newton_picard._Subspace(self.rho, self.guard, np.random.default_rng(long_orbits.SEED))
        self.shift = long_orbits._shift(
            _System(self.start.params, self.model, self.start.moment, self.start.particle), self.start.particle_turns
        )

    def evaluate(self, w: np.ndarray, jacobian: bool) -> Evaluation:
        """(P) and the phase condition at w = (y0's unknowns, log T, M), with their Jacobian as products (:class:`_PicardJacobian`)."""
        head = self.phase.head
        if w[head] > math.log(100 * self.period_max):
            raise EvaluationFailed("the period ran off to 100 period_max: the corrector has left the branch")
        system = _System(self.start.params, self.model, float(w[head + 1]), self.start.particle)
        loose = (max(self.rtol, long_orbits.NEWTON_PRODUCTS_RTOL), max(self.atol, long_orbits.NEWTON_PRODUCTS_RTOL))
        closure = long_orbits._closure(system, self.phase, self.shift, self.rtol, self.atol, loose)
        residual, monodromy, velocity = closure(np.append(w[:head], math.exp(w[head])))
        at = _PicardJacobian(system, monodromy, velocity, self.rtol, self.atol)
        return Evaluation(residual, at, at)

    def solve(self, at: _PicardJacobian, residual: np.ndarray, border: np.ndarray, border_rhs: float, forcing: float) -> np.ndarray:
        """dw with (P)'s and the phase condition's linearisation at ``at`` equal to -``residual`` and border . dw = border_rhs."""
        head, size, period = self.phase.head, at.monodromy.size, at.monodromy.period
        if self.subspace.basis is None:
            self.subspace.start(at.monodromy)
        basis, _, schur, p = self.subspace.sweep(at.monodromy)
        dominant = basis[:, :p]
        normal = np.zeros(size)
        if self.phase.normal is None:
            normal[self.phase.dof] = 1.0  # dy keeps the section's angle
        else:
            normal[:] = self.phase.normal
        along = np.zeros(size)
        along[self.phase.keep] = border[:head]
        top, target = -residual[:size], (-residual[size] if residual.size > size else 0.0)
        columns = np.column_stack([-top, period * at.velocity_end, at.moment_column()])
        q, mapped = newton_picard.complement(at.monodromy, dominant, columns, forcing, self.subspace)
        coupling = dominant.T @ mapped
        matrix = np.zeros((p + 2, p + 2))
        matrix[:p, :p] = schur[:p, :p] - np.eye(p)
        matrix[:p, p] = coupling[:, 1] + dominant.T @ columns[:, 1]
        matrix[:p, p + 1] = coupling[:, 2] + dominant.T @ columns[:, 2]
        matrix[p, :p], matrix[p, p:] = normal @ dominant, normal @ q[:, 1:]
        matrix[p + 1, :p], matrix[p + 1, p:] = along @ dominant, along @ q[:, 1:] + border[head:]
        right = np.concatenate([dominant.T @ top - coupling[:, 0], [target - normal @ q[:, 0], border_rhs - along @ q[:, 0]]])
        solution = np.linalg.solve(matrix, right)
        dy = dominant @ solution[:p] + q @ np.append(1.0, solution[p:])
        # The rows of (P) and the phase condition in (a, d log T, dM), and dy's map: the tangent's system at no more products.
        self.reduced = (matrix[: p + 1], np.column_stack([dominant, q[:, 1:]]), p)
        return np.concatenate([dy[self.phase.keep], solution[p:]])

    def _reduced_tangent(self, border: np.ndarray) -> np.ndarray:
        """The tangent from the last Newton-Picard step's reduced system (V_p, q_T and q_M at the iterate before the solution)."""
        rows, span, p = self.reduced
        along = np.zeros(span.shape[0])
        along[self.phase.keep] = border[: self.phase.head]
        bordered = np.vstack([rows, np.append(along @ span[:, :p], along @ span[:, p:] + border[self.phase.head :])])
        solution = np.linalg.solve(bordered, np.append(np.zeros(p + 1), 1.0))
        dy = span @ solution
        return np.concatenate([dy[self.phase.keep], solution[p:]])

    def _newton(self, start: np.ndarray, border: np.ndarray, w_pred: np.ndarray, criterion: dict) -> Correction:
        """Newton-Picard on the equations with the border ``border`` . (w - w_pred) = 0 (:func:`~.kit.newton`)."""
        self.reduced = None

        def step(w: np.ndarray, evaluation: Evaluation, at: _PicardJacobian) -> np.ndarray:
            residual = np.asarray(evaluation.residual)
            forcing = min(newton_picard.PICARD_RTOL_MAX, max(newton_picard.PICARD_RTOL_MIN, float(np.max(np.abs(residual)))))
            return self.solve(at, residual, border, -float(border @ (w - w_pred)), forcing)

        return newton(
            self.evaluate, start, **criterion, max_iterations=MAX_CORRECTOR_ITERATIONS, damping=MAX_HALVINGS, divergence=None, newton_step=step
        )  # fmt: skip

    def settle(self, w0: np.ndarray) -> tuple[np.ndarray, bool]:
        """w0 closed to ``tol`` at its moment (an orbit from another method closes a little differently here), and whether it already was.

        Raises
        ------
        OrbitError
            Where it does not close.
        """
        fixed = np.zeros(w0.size)
        fixed[-1] = 1.0
        settled = self._newton(w0, fixed, w0, {"tol": self.tol})
        if not settled.converged:
            raise OrbitError(_no_convergence(self.start.moment, self.start.turns, settled.iterations, settled.norm))
        return settled.w, settled.iterations == 0

    def correct(self, w: np.ndarray, t: np.ndarray, h: float, jacobian) -> Correction:
        """The kit's corrector stage: Newton-Picard from w + h t on the arclength plane through it."""
        return self._newton(w + h * t, t, w + h * t, {"converged": long_orbits.deep_convergence(self.tol)})

    def tangent(self, jacobian: _PicardJacobian, previous: np.ndarray | None) -> np.ndarray:
        """The unit null vector of dR/dw at ``jacobian``, along ``previous`` (at the start, with dM of sign ``direction``)."""
        border = previous
        if border is None:
            border = np.zeros(self.phase.head + 2)
            border[-1] = self.direction
        if self.reduced is not None:  # the correction's last step: its Jacobian is the solution's to the step's length
            t = self._reduced_tangent(border)
        else:
            residual = np.zeros(jacobian.monodromy.size + (self.phase.normal is not None))
            t = self.solve(jacobian, residual, border, 1.0, TANGENT_PICARD_RTOL)
        return t / np.linalg.norm(t)

    def events(self, previous: PeriodicOrbit, candidate: PeriodicOrbit, t_before: np.ndarray, t_after: np.ndarray) -> list[str]:
        """A turn of M (the tangent's dM changes sign); branch points of cycles are read from the multipliers (:func:`_branch_points`)."""
        return ["fold"] if t_before[-1] * t_after[-1] < 0 else []

    def point(self, w: np.ndarray, evaluation: Evaluation, iterations: int) -> PeriodicOrbit:
        """The orbit at w with the trivial multiplier and those above ``rho`` (Ritz values at the shooting's tolerance after
        :data:`BRANCH_RITZ_SWEEPS` sweeps, with their residuals); the refined basis, with the flow, is the next corrections' warm start."""
        at = evaluation.data
        y0, period = at.monodromy.start, at.monodromy.period
        flow = at.system.velocity(y0)
        accurate = long_orbits.Monodromy(at.system, y0, period, self.rtol, self.atol)
        values, errors, basis = newton_picard.ritz_multipliers(
            accurate, flow, self.subspace.basis, rho=self.rho, guard=self.guard, sweeps=BRANCH_RITZ_SWEEPS
        )  # fmt: skip
        self.subspace.basis = np.linalg.qr(np.column_stack([flow, basis]))[0]
        closure = float(np.max(np.abs(evaluation.residual)))
        return _orbit_from(
            at.system, self.start.turns, y0, period, values, closure, iterations, self.start.particle_turns, self.phase.normal, errors
        )  # fmt: skip


def _multiplier_motion(before: np.ndarray, after: np.ndarray) -> float:
    """How far the multipliers near the unit circle moved from ``before`` to ``after``: the largest distance
    in the matching of the two sets that minimises the total distance (eigenvalues carry no labels)."""
    import scipy.optimize as so

    distance = np.abs(before[:, None] - after[None, :])
    rows, cols = so.linear_sum_assignment(distance)
    low, high = MULTIPLIER_WATCH
    near = ((np.abs(before[rows]) >= low) | (np.abs(after[cols]) >= low)) & (np.abs(before[rows]) <= high) & (np.abs(after[cols]) <= high)
    return float(np.max(distance[rows, cols][near], initial=0.0))


def _fold_moment(last: list[PeriodicOrbit], sign: float) -> float:
    """Extreme M of the parabola M(log T) through the three orbits around the turn."""
    s = np.array([math.log(o.period) for o in last])
    m = np.array([o.moment for o in last])
    a, b, c = np.polyfit(s - s[1], m, 2)
    extreme = c - b * b / (4 * a) if a != 0 else m[1]
    bound = min(m) if sign > 0 else max(m)
    return float(extreme) if sign * (extreme - bound) <= 0 else float(bound)


#: Largest |mu| - 1 of a nontrivial multiplier of a Hamiltonian orbit that still counts as on the
#: unit circle: the monodromy is accurate to about 1e-9, and a colliding pair splits like its root.
HAMILTONIAN_CIRCLE_TOL = 1e-6


def require_undamped(params: ChainParams) -> None:
    """Refuse a damped chain for the Hamiltonian orbits (their energy must be conserved).

    Raises
    ------
    ValueError
        Naming every non-zero viscosity.
    """
    damped = [f"{name}={value!r}" for name, value in zip(("gamma_u", "gamma_v", "gamma_phi"), params.damping) if value != 0]
    if damped:
        raise ValueError(
            f"Hamiltonian orbits need an undamped chain (gamma_u = gamma_v = gamma_phi = 0), got {', '.join(damped)}; "
            "set them to 0 (params.replace(gamma_u=0, gamma_v=0, gamma_phi=0))"
        )


@dataclass(frozen=True)
class _UndampedSystem(_System):
    """The undamped, unloaded chain with the unfolding damping rate ``eps`` on every velocity.

    The field f + eps g, g = (0, -v), dissipates energy at the rate eps sum m v^2, so a
    periodic orbit of it has eps = 0; as an unknown eps makes the shooting's Newton system
    regular although the Hamiltonian flow has a second multiplier at +1 (the family).
    """

    eps: float = 0.0

    def parameters(self, ncols: int):
        rhs, kernel, ends, coef, rpar, ipar = super().parameters(ncols)
        rpar[1 + self.nf :] = self.eps
        return rhs, kernel, ends, coef, rpar, np.append(ipar, 1)


@dataclass
class HamiltonianOrbit(PeriodicOrbit):
    """A periodic orbit of the undamped, unloaded chain with a prescribed frequency (:func:`find_hamiltonian_orbit`).

    ``moment`` is 0; the loaded particle of :class:`PeriodicOrbit` is the rotating one.

    Attributes
    ----------
    unfolding : float
        The unfolding parameter eps at the solution: 0 up to the Newton tolerance.
    energy : float or None
        Total energy (kinetic + potential) on the section; None for a model without a
        potential (the sine model, eq. (2)).
    """

    unfolding: float = 0.0
    energy: float | None = None

    @property
    def omega(self) -> float:
        """Omega = 2 pi k / T, the rotating particle's mean angular velocity."""
        return 2.0 * math.pi * self.turns / self.period

    @property
    def mean_angular_velocity(self) -> float:
        return self.omega

    @property
    def nontrivial_multipliers(self) -> np.ndarray:
        """All multipliers but the Hamiltonian pair at +1 (the flow and the family)."""
        closest = np.argsort(np.abs(self.multipliers - 1.0), kind="stable")[:2]
        return np.delete(self.multipliers, closest)

    @property
    def stable(self) -> bool:
        """Linearly stable: every nontrivial multiplier on the unit circle (to :data:`HAMILTONIAN_CIRCLE_TOL`)."""
        return self.max_multiplier <= 1.0 + HAMILTONIAN_CIRCLE_TOL

    def as_dict(self) -> dict:
        """JSON-ready summary (:meth:`PeriodicOrbit.as_dict` with omega, the unfolding and the energy)."""
        out = super().as_dict()
        out.update({"omega": self.omega, "unfolding": self.unfolding, "energy": self.energy})
        return out


def hamiltonian_energy(params: ChainParams, model: str | Model, x: np.ndarray, v: np.ndarray) -> float | None:
    """Kinetic plus potential energy of the state (x, v) (3, 2N+1); None for a non-conservative model."""
    model = get_model(model)
    if not model.conservative:
        return None
    inertia = pack(params, params.particle_inertia)
    return float(0.5 * np.sum(inertia * pack(params, v) ** 2) + model.energy(params, x))


def hamiltonian_setup(params, model, omega, guess, turns, particle, particle_turns, tol, rtol, atol) -> tuple[Model, np.ndarray]:
    """The checked arguments of a Hamiltonian orbit's solve (:func:`find_hamiltonian_orbit`'s) and the turns of its particles.

    The turns are ``particle_turns`` checked, else the guess's where it turns the particle as
    often, else ``turns`` on the rotating particle alone.

    Raises
    ------
    ValueError
        For a non-positive or non-finite omega or tolerance, turns < 1, a damped chain or ends the shooting cannot take.
    """
    model = get_model(model)
    if not (isinstance(omega, (int, float)) and math.isfinite(omega) and omega > 0):
        raise ValueError(f"omega must be a finite number > 0 (the rotating particle's mean angular velocity), got {omega!r}")
    _check_moment_and_turns(1.0, turns)
    for name, value in (("tol", tol), ("rtol", rtol), ("atol", atol)):
        if not (math.isfinite(value) and value > 0):
            raise ValueError(f"{name} must be a finite number > 0, got {value!r}")
    require_orbit_ends(params)
    require_undamped(params)
    if particle_turns is not None:
        return model, _check_particle_turns(params, particle, turns, 1.0, particle_turns)
    if isinstance(guess, PeriodicOrbit) and guess.particle_turns[column(params, particle)] == turns:
        return model, guess.particle_turns
    return model, _loaded_turns(params, particle, turns, 1.0)


@one_blas_thread
def find_hamiltonian_orbit(
    params: ChainParams,
    model: str | Model,
    omega: float,
    guess: PeriodicOrbit | tuple,
    *,
    turns: int = 1,
    particle: int = 0,
    particle_turns: np.ndarray | None = None,
    tol: float = CLOSURE_TOL,
    max_iter: int = 25,
    rtol: float = RTOL,
    atol: float = ATOL,
) -> HamiltonianOrbit:
    """The undamped rotating orbit with frequency ``omega``, by Newton on the unfolded shooting map.

    With gamma = 0 and no load the multiplier +1 is double (the flow direction, and the
    family of orbits through it), so (P) with T unknown is singular. Here T = 2 pi k / Omega
    is prescribed and the unknowns are the state on the section phi_particle = 0 (the phase
    condition) and the unfolding eps of :class:`_UndampedSystem`:

        Phi_T^eps(y0) - y0 - 2 pi k e_phi = 0,   Jacobian [(dPhi_T/dy0 - I) without the
        phi column, dPhi_T/deps],

    integrated with the shooting's DOP853 and variational equations (:func:`_shooting`).

    Parameters
    ----------
    params : ChainParams
        Undamped (:func:`require_undamped`), held against translation (:func:`require_orbit_ends`).
    model : str or Model
        A model 2 pi periodic in the angles (``nonlinear``, ``sine``).
    omega : float
        Omega > 0, the rotating particle's mean angular velocity.
    guess : PeriodicOrbit or (x (3, 2N+1), v (3, 2N+1))
        Start of Newton's method (a nearby orbit, or an anti-continuum state).
    turns : int
        k >= 1, turns of the rotating particle per period.
    particle : int
        The rotating particle: its angle is 0 on the section.
    particle_turns : ndarray (2N+1,) int, optional
        Signed turns per period of every particle, ``turns`` at ``particle``: other rotors
        (a multi-site roto-breather, +-k for rotors turning with or against it). Default:
        ``particle`` alone turns (or the guess's, for a :class:`PeriodicOrbit` guess).
    tol : float
        Newton stops when max |Phi_T(y0) - y0 - 2 pi k e_phi| <= tol.
    max_iter : int
    rtol, atol : float
        Tolerances of the DOP853 integrations.

    Returns
    -------
    HamiltonianOrbit

    Raises
    ------
    ValueError
        For a non-positive or non-finite omega, turns < 1, a damped chain or ends the shooting cannot take.
    OrbitError
        If Newton's method does not converge.
    """
    model, particle_turns = hamiltonian_setup(params, model, omega, guess, turns, particle, particle_turns, tol, rtol, atol)
    if isinstance(guess, PeriodicOrbit):
        x0, v0 = guess.x, guess.v
    else:
        x0, v0 = guess
    period = 2.0 * math.pi * turns / float(omega)
    require_integrable_period(params, model, period)
    dof = _System(params, model, 0.0, particle).load_dof
    y0 = _to_y(params, check_state(params, x0, "guess x"), check_state(params, v0, "guess v"))
    y0[dof] = 0.0
    keep = np.arange(len(y0)) != dof

    def closure(w: np.ndarray, jacobian: bool) -> Evaluation:
        """The unfolded (P) at w = (y0 without phi_particle, eps) and, with ``jacobian``, its Jacobian and the monodromy."""
        y = np.zeros(len(keep))
        y[keep] = w[:-1]
        system = _UndampedSystem(params, model, 0.0, particle, w[-1])
        try:
            residual, jac_y, _, d_eps, mono = _shooting(system, particle_turns, rtol, atol)(y, period, jacobian)
        except OrbitError as err:
            # A step far off the orbit can make the flow run away before T: halved as a worse closure.
            raise EvaluationFailed(str(err)) from err
        return Evaluation(residual, None if jac_y is None else np.column_stack([jac_y[:, keep], d_eps]), mono)

    # Newton with a fresh Jacobian every step, halved while it makes the closure worse.
    solved = newton(closure, np.append(y0[keep], 0.0), tol=tol, max_iterations=max_iter, divergence=None, damping=MAX_HALVINGS)
    if not solved.converged:
        raise OrbitError(_no_hamiltonian_convergence(omega, turns, solved.iterations, solved.norm))
    y0[keep] = solved.w[:-1]
    eps, mono, norm, iterations = solved.w[-1], solved.evaluation.data, solved.norm, solved.iterations
    base = _orbit(_System(params, model, 0.0, particle), turns, y0, period, mono, norm, iterations, particle_turns)
    fields = {name: getattr(base, name) for name in PeriodicOrbit.__dataclass_fields__}
    return HamiltonianOrbit(**fields, unfolding=float(eps), energy=hamiltonian_energy(params, model, base.x, base.v))


def _no_hamiltonian_convergence(omega: float, turns: int, iterations: int, norm: float) -> str:
    return (
        f"Newton on the unfolded shooting map did not converge at omega={omega!r} with turns={turns} "
        f"({iterations} iterations, closure {norm:.3g}); start from an orbit at a nearby frequency (smaller continuation "
        "steps), or the family may end here (a resonance with a band, or a fold in the frequency)"
    )


@dataclass
class HamiltonianFamily:
    """Undamped rotating orbits followed in the frequency by :func:`continue_in_frequency`.

    Attributes
    ----------
    orbits : list of HamiltonianOrbit
        In the order traced.
    requested : ndarray
        The frequencies asked for; the family may end before the last (``complete`` False).
    message : str
        Why the family ended (empty when every frequency was reached).
    """

    orbits: list[HamiltonianOrbit]
    requested: np.ndarray
    message: str = ""

    @property
    def complete(self) -> bool:
        return len(self.orbits) == len(self.requested)

    @property
    def omega(self) -> np.ndarray:
        return np.array([o.omega for o in self.orbits])

    @property
    def energy(self) -> np.ndarray:
        return np.array([math.nan if o.energy is None else o.energy for o in self.orbits])

    @property
    def max_multiplier(self) -> np.ndarray:
        return np.array([o.max_multiplier for o in self.orbits])

    @property
    def stable(self) -> np.ndarray:
        return np.array([o.stable for o in self.orbits], dtype=bool)


@one_blas_thread
def continue_in_frequency(
    orbit: HamiltonianOrbit,
    omegas: np.ndarray | list[float],
    *,
    tol: float = CLOSURE_TOL,
    rtol: float = RTOL,
    atol: float = ATOL,
    progress: ProgressCallback | None = None,
) -> HamiltonianFamily:
    """Follow a Hamiltonian orbit through the frequencies ``omegas`` (the first is the orbit's own or near it).

    Each orbit starts Newton from the secant through the two before it (the previous
    orbit for the second); the family ends at the first frequency where Newton fails.
    A first frequency equal to the orbit's own takes the orbit as it is.

    Returns
    -------
    HamiltonianFamily
    """
    omegas = np.asarray(omegas, dtype=float)
    params, model = orbit.params, orbit.model
    orbits: list[HamiltonianOrbit] = []
    message = ""
    guess: PeriodicOrbit | tuple = orbit
    for i, omega in enumerate(omegas):
        if i == 0 and math.isclose(omega, orbit.omega, rel_tol=1e-14):
            orbits.append(orbit)
            if progress is not None:
                progress(1, len(omegas))
            continue
        if len(orbits) >= 2:
            a, b = orbits[-2], orbits[-1]
            r = (omega - b.omega) / (b.omega - a.omega)
            guess = (b.x + r * (b.x - a.x), b.v + r * (b.v - a.v))
        try:
            found = find_hamiltonian_orbit(
                params,
                model,
                float(omega),
                guess,
                turns=orbit.turns,
                particle=orbit.particle,
                particle_turns=orbit.particle_turns,
                tol=tol,
                rtol=rtol,
                atol=atol,
            )
        except OrbitError as err:
            message = f"the family ends before omega={omega:.10g}: {err}"
            break
        orbits.append(found)
        guess = found
        if progress is not None:
            progress(i + 1, len(omegas))
    return HamiltonianFamily(orbits=orbits, requested=omegas, message=message)
