"""Rotating orbits of long chains: the monodromy in column blocks, Newton-Krylov shooting, deflated Floquet multipliers.

Contract
--------
The dense shooting of :mod:`~.periodic` integrates the monodromy matrix M = dPhi_T/dy0 as
2 n_free + 1 variational columns together with the state in one DOP853 run: its time grows
like N^2 per unit time, and its memory too (the integrator's ~16 copies of (2 n_free)^2
numbers: 0.7 GB at N = 200, 18 GB at N = 1000). Here the products M V with a block of p
columns V (2 n_free, p) come from one integration of the state with p variational columns
(:class:`Monodromy`, O(N p) a step), and

* **blocks** (:func:`blocks_correction`, ``method="blocks"``): M formed from the identity's
  columns :data:`BLOCK_COLUMNS` at a time, the blocks on parallel threads (the compiled
  integrator releases the GIL), with the memory of M alone; a block's variational state stays
  in cache, so even on one thread it is faster than the one-piece integration (1.7x at
  N = 100). Newton as the dense method: the package's corrector (:func:`~.kit.newton`) in
  chord iterations, M formed again only where the closure stops falling tenfold a step; the
  steps' M at the looser :data:`NEWTON_PRODUCTS_RTOL` (the closure at the shooting's tolerance,
  Newton carried below ``tol``: :data:`NEWTON_DEPTH`), M at the solution at the shooting's.
  :func:`~.periodic.continue_orbit` takes them too (:func:`blocked_shooting`: dPhi_T/dM,
  which only the one-piece integration carries as a column, by differences in M).
* **Newton-Krylov** (:func:`krylov_correction`, ``method="krylov"``): M never formed;
  each Newton step of (P) and the phase condition, in the same unknowns (y0 on the section or
  the plane of :class:`~.periodic._Phase`, and T),

      [(M - I) E    f(Phi_T(y0))] [dy]   [-R      ]
      [ phase rows            0 ] [dT] = [-phase  ]

  (E embeds the unknowns of y0) is solved by GMRES with one-column products, its relative
  tolerance following the closure (between :data:`GMRES_RTOL_MIN` and :data:`GMRES_RTOL_MAX`:
  an inexact Newton that keeps Newton's fast convergence). It pays only where few
  multipliers lie near the unit circle: the chain's damped modes put a ring of them at
  |mu| ~ exp(-gamma T / 2 m) and its soft overdamped bending modes a cluster below 1, and M
  is far from normal (eigenvector condition ~1e4 at N = 30), so GMRES needs a large part of
  2 n_free products, each ~8 times a column of a block (benchmarks/README.md, long orbits).
* **multipliers** (:func:`leading_multipliers`): the trivial one deflated with its known
  eigenvector, the flow f(y0), and the others as eigenvalues of the deflated M: all of them
  from a formed M up to 2 n_free = :data:`ALL_MULTIPLIERS_UP_TO`; above it the :data:`MULTIPLIERS`
  leading ones, by ARPACK on the formed M twice: largest modulus, and shift-invert nearest
  :data:`SHIFT` (just above 1) through one LU factorisation of M - SHIFT I (:func:`_leading_core`),
  which resolves the long chain's soft multipliers that crowd within 1e-7 below 1 where the
  first run does not converge; or by Arnoldi on products (no M formed, for ``krylov`` above
  2 n_free = :data:`FORM_UP_TO`, or where the LU factors do not fit in memory: a warning says
  so). Each comes with an error estimate (its residual), and one above :data:`UNCONVERGED` is
  flagged by a warning; the trivial one's, |(M - I) f| / |f|, bounds its distance from 1 (tested).
* **segments** (:func:`orbit_multipliers`, ``find_periodic_orbit(..., segments=m)`` and
  ``continue_orbit(..., segments=m)`` with the blocks): the multipliers of a formed M below about 1e-16 |M| are round-off. With m segments
  every block is integrated piece by piece, each piece's transfer matrix G_k assembled from the
  blocks (:func:`segment_matrices`: m (2 n_free)^2 numbers), and all multipliers come from the
  periodic Schur form of G_m ... G_1 (:func:`~.floquet.periodic_schur_multipliers`) with their
  log-moduli, the trivial one with its error |G_m ... G_1 f - f| / |f|; up to 2 n_free =
  :data:`ALL_MULTIPLIERS_UP_TO`, above which the leading ones come as without segments (a warning
  says the small ones are not computed).

The result is a :class:`~.periodic.PeriodicOrbit` like the dense method's, with
``multiplier_errors`` (the trivial one's in ``as_dict``); where not all multipliers are
computed, ``multipliers`` holds the leading ones by decreasing modulus. The method is chosen by
``find_periodic_orbit(..., method=)``: ``"auto"`` takes the blocks from N = :data:`BLOCKS_FROM_N`.
"""

from __future__ import annotations

import dataclasses
import math
import os
import warnings
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
import scipy.linalg as sla
import scipy.sparse.linalg as spla

from ..errors import CosseratChainError
from ..linalg.eigen import largest_and_nearest, merge_eigenpairs
from ..memory import FLOAT, MemoryEstimateError, require
from ..params import ChainParams
from ..state import ROW_INDEX, pack, zeros
from . import dop853, floquet
from .kit import Correction, Evaluation, EvaluationFailed, newton

if TYPE_CHECKING:
    # The solvers below serve numerics.periodic, which imports this module: its classes are only named here.
    from .periodic import _Phase, _System

#: The methods of :func:`~.periodic.find_periodic_orbit`: the monodromy in one integration, in column blocks, Newton-Krylov,
#: Newton-Picard (:mod:`~.newton_picard`), or by the chain's length.
METHODS = ("auto", "dense", "blocks", "krylov", "picard")
#: ``method="auto"`` assembles the monodromy from column blocks from this N on (benchmarks/README.md, long orbits).
BLOCKS_FROM_N = 50
#: Columns of the monodromy integrated together in one block (a few hundred kB of variational state: in cache).
BLOCK_COLUMNS = 64
#: Threads the blocks run on; None: the CPUs this process may use.
THREADS: int | None = None
#: Up to this size (2 n_free) the multipliers of a formed monodromy are all its eigenvalues; above, the leading ones.
ALL_MULTIPLIERS_UP_TO = 2500
#: Newton (chord) reuses the formed monodromy while each step divides the closure by at least 1 / CHORD_RATE.
CHORD_RATE = 0.1
#: Nontrivial Floquet multipliers computed where not all of them are (Arnoldi, ARPACK).
MULTIPLIERS = 12
#: Products with M form it (from column blocks) for its multipliers up to this size (2 n_free); Arnoldi above.
FORM_UP_TO = 600
#: Most Arnoldi vectors (products with M) spent on the leading multipliers.
ARNOLDI_MAX = 240
#: A Ritz pair has converged when its estimated residual is below this times max(1, |mu|).
ARNOLDI_TOL = 1e-10
#: Arnoldi's Ritz values are checked every this many products.
ARNOLDI_CHECK = 10
#: Most implicit restarts of ARPACK on the formed M: a long chain's soft modes crowd below 1 (the sine chain's at
#: M = 0.5, N = 1000, within 1e-6 of 1 and of one another), where ARPACK would restart for hours; those that converged
#: by then are reported.
ARPACK_RESTARTS = 50
#: GMRES's relative tolerance in a Newton step: the closure max |R|, clipped to this range.
GMRES_RTOL_MIN, GMRES_RTOL_MAX = 1e-10, 1e-2
#: Most GMRES iterations (products with M) in one Newton step (no restart).
GMRES_MAX_ITERATIONS = 400
#: Relative step of the fourth-order central differences in the moment of :func:`blocked_shooting`.
MOMENT_STEP = 1e-5
#: ... and where that step moves the state by more than this, the step that moves it by this.
MOMENT_REACH = 1e-3
#: The blocks' Newton steps form M at this relative and absolute tolerance (or the shooting's, if looser): about
#: (this / rtol)^(1/8) times fewer DOP853 steps; the closure, and M at the solution, keep the shooting's tolerances.
NEWTON_PRODUCTS_RTOL = 1e-8
#: ... and Newton goes on below ``tol`` to ``tol`` times this, or until a step no longer divides the closure by
#: 1 / CHORD_RATE (its noise floor): the inexact steps converge linearly, and the orbit's position along the
#: soft directions (multipliers near 1) needs the closure well below ``tol`` for the multipliers to agree.
NEWTON_DEPTH = 1e-3
#: Seed of Arnoldi's start vector (reproducible multipliers).
SEED = 20240
#: Above :data:`ALL_MULTIPLIERS_UP_TO` the multipliers nearest this shift come by shift-invert on the formed M
#: (:func:`_leading_core`): just above 1, within the width of the crowd of soft multipliers below it.
SHIFT = 1.0 + 1e-9
#: A multiplier whose error estimate exceeds this times max(1, |mu|) is flagged as not converged (a warning).
UNCONVERGED = 1e-6
#: Copies of the segments' matrices alive at once with ``segments`` (theirs, and two in the periodic Schur form).
SEGMENT_COPIES = 3


def choose_method(params: ChainParams, method: str) -> str:
    """``"dense"``, ``"blocks"``, ``"krylov"`` or ``"picard"``: ``method`` itself, or for ``"auto"`` by the chain's length (:data:`BLOCKS_FROM_N`).

    Raises
    ------
    ValueError
        For a method not in :data:`METHODS`.
    """
    if method not in METHODS:
        raise ValueError(
            f"method must be one of {', '.join(METHODS)} (the monodromy in one integration or in column blocks, Newton-Krylov, "
            f"Newton-Picard, or by the chain's length), got {method!r}"
        )
    if method == "auto":
        return "blocks" if params.N >= BLOCKS_FROM_N else "dense"
    return method


@dataclass
class Monodromy:
    """The monodromy matrix M = dPhi_T/dy0 (2 n_free, 2 n_free) of the flow from ``start`` over ``period``, as products.

    Attributes
    ----------
    products : int
        Columns applied so far (each a column of the variational equations over one period).
    integrations : int
        Integrations so far (one per :meth:`apply`).
    """

    system: _System
    start: np.ndarray
    period: float
    rtol: float
    atol: float
    products: int = 0
    integrations: int = 0
    #: M once :meth:`matrix` has formed it.
    formed: np.ndarray | None = None

    @property
    def size(self) -> int:
        return self.start.size

    def apply(self, columns: np.ndarray) -> np.ndarray:
        """M V for V (2 n_free, p) real or complex (or a vector), by one integration of the state with p (2 p) columns."""
        columns = np.asarray(columns)
        vector = columns.ndim == 1
        block = columns.reshape(self.size, -1)
        if np.iscomplexobj(block):
            real = self.apply(np.hstack([block.real, block.imag]))
            out = real[:, : block.shape[1]] + 1j * real[:, block.shape[1] :]
            return out[:, 0] if vector else out
        # Unit columns: DOP853's absolute tolerance then means the same for each (M is linear).
        scale = np.linalg.norm(block, axis=0)
        scale[scale == 0] = 1.0
        ncols = block.shape[1]
        rhs, kernel, ends, coef, rpar, ipar = self.system.parameters(ncols)
        y0 = np.concatenate([self.start, (block / scale).ravel()])
        sol = dop853.solve(
            rhs, kernel, coef, rpar, ipar, y0, np.array([0.0, self.period]), rtol=self.rtol, atol=self.atol,
            end_force=ends,
        )  # fmt: skip
        if not sol.success:
            raise EvaluationFailed(f"the variational equations over T={self.period!r} failed at M={self.system.moment!r}: {sol.message}")
        self.products += ncols
        self.integrations += 1
        out = sol.y[-1][self.size :].reshape(self.size, ncols) * scale
        return out[:, 0] if vector else out

    def matrix(self, block: int = BLOCK_COLUMNS, threads: int | None = None) -> np.ndarray:
        """M itself (2 n_free, 2 n_free), from the identity's columns ``block`` at a time, the blocks on ``threads``
        threads (default :data:`THREADS`); the integrator releases the GIL, so they run in parallel.
        Formed once (:attr:`formed`), each block written into M in place (the memory of M and the blocks in flight)."""
        if self.formed is not None:
            return self.formed
        size = self.size
        firsts = range(0, size, block)
        formed = np.empty((size, size))

        def columns(first: int) -> None:
            width = min(block, size - first)
            unit = np.zeros((size, width))
            unit[first + np.arange(width), np.arange(width)] = 1.0
            formed[:, first : first + width] = self.apply(unit)

        workers = threads or THREADS or len(os.sched_getaffinity(0))
        with ThreadPoolExecutor(max_workers=max(1, min(workers, len(firsts)))) as pool:
            list(pool.map(columns, firsts))
        self.formed = formed
        return formed


def _shift(system: _System, particle_turns: np.ndarray) -> np.ndarray:
    """2 pi times every angle's turns a period, in the layout of y (eq. (P))."""
    shift = np.zeros(2 * system.nf)
    angles = zeros(system.params)
    angles[ROW_INDEX["phi"]] = particle_turns
    shift[: system.nf] = 2 * math.pi * pack(system.params, angles)
    return shift


@dataclass
class _ShootingStep:
    """The Newton step of (P) and the phase condition at (y0, T), solved by GMRES with products of :class:`Monodromy`."""

    monodromy: Monodromy
    phase: _Phase
    velocity_end: np.ndarray

    def _apply(self, x: np.ndarray) -> np.ndarray:
        head = self.phase.head
        dy = np.zeros(self.monodromy.size)
        dy[self.phase.keep] = x[:head]
        top = self.monodromy.apply(dy) - dy + self.velocity_end * x[head]
        return np.concatenate([top, self.phase.rows(x.size) @ x])

    def solve(self, rhs: np.ndarray, rtol: float) -> np.ndarray:
        n = rhs.size
        operator = spla.LinearOperator((n, n), matvec=self._apply, dtype=float)
        step, _ = spla.gmres(operator, rhs, rtol=rtol, atol=0.0, restart=GMRES_MAX_ITERATIONS, maxiter=1)
        # A step GMRES did not resolve to rtol (after GMRES_MAX_ITERATIONS) is still taken: Newton's halving judges it.
        return step


def _closure(system: _System, phase: _Phase, shift: np.ndarray, rtol: float, atol: float, products: tuple[float, float] | None = None):
    """(P) and the phase condition at w = (y0's unknowns, T), with the :class:`Monodromy` there (at the tolerances
    ``products``, default rtol and atol) and f(Phi_T(y0)) (a state-only integration)."""
    mono_rtol, mono_atol = products or (rtol, atol)

    def evaluate(w: np.ndarray) -> tuple[np.ndarray, Monodromy, np.ndarray]:
        if not w[-1] > 0:
            raise EvaluationFailed(f"the period must stay > 0, got {w[-1]!r}")
        y = phase.state(w[:-1])
        try:
            end, _, _ = system.flow(y, w[-1], rtol=rtol, atol=atol, variations=False)
        except CosseratChainError as err:  # the integration failed (periodic.OrbitError)
            raise EvaluationFailed(str(err)) from err
        residual = np.append(end - y - shift, phase.residual(y))
        return residual, Monodromy(system, y, float(w[-1]), mono_rtol, mono_atol), system.velocity(end)

    return evaluate


def krylov_correction(
    system: _System,
    phase: _Phase,
    particle_turns: np.ndarray,
    w0: np.ndarray,
    *,
    tol: float,
    max_iter: int,
    rtol: float,
    atol: float,
    damping: int,
) -> tuple[Correction, Monodromy | None]:
    """Newton-Krylov shooting from w0 = (y0's unknowns on ``phase``, T); the correction and, converged, M's products there.

    The Newton steps by GMRES on products (module docstring); ``damping`` halvings of a step
    that does not reduce the closure (:func:`~.kit.newton`).
    """
    evaluate = _closure(system, phase, _shift(system, particle_turns), rtol, atol)

    def closure(w: np.ndarray, jacobian: bool) -> Evaluation:
        # The step's operator costs nothing until GMRES applies it: given with every residual.
        residual, monodromy, velocity = evaluate(w)
        return Evaluation(residual, _ShootingStep(monodromy, phase, velocity))

    def krylov_step(w: np.ndarray, evaluation: Evaluation, step: _ShootingStep) -> np.ndarray:
        residual = np.asarray(evaluation.residual)
        eta = min(GMRES_RTOL_MAX, max(GMRES_RTOL_MIN, float(np.max(np.abs(residual)))))
        return step.solve(-residual, eta)

    solved = newton(closure, w0, tol=tol, max_iterations=max_iter, divergence=None, damping=damping, newton_step=krylov_step)
    return solved, (solved.evaluation.matrix().monodromy if solved.converged else None)


def blocks_correction(
    system: _System,
    phase: _Phase,
    particle_turns: np.ndarray,
    w0: np.ndarray,
    *,
    tol: float,
    max_iter: int,
    rtol: float,
    atol: float,
    damping: int,
    threads: int | None = None,
    segments: int | None = None,
) -> tuple[Correction, np.ndarray | None]:
    """Newton on (P) from w0 with the monodromy from column blocks (:meth:`Monodromy.matrix`); the correction and, converged, M there.

    As the dense shooting (chord iterations: :data:`CHORD_RATE`), with the memory of M alone
    instead of the integrator's copies of 2 n_free + 1 columns, the blocks on ``threads`` threads.
    The Newton steps' M is integrated at :data:`NEWTON_PRODUCTS_RTOL` (fewer steps; the closure
    itself at ``rtol``, ``atol``), Newton goes on to ``tol`` times :data:`NEWTON_DEPTH` or its
    noise floor, and M at the solution is formed at ``rtol``, ``atol``.
    With ``segments`` up to 2 n_free = :data:`ALL_MULTIPLIERS_UP_TO` M is not formed at the
    solution (None): :func:`orbit_multipliers` takes them from the segments' matrices.
    """
    loose = (max(rtol, NEWTON_PRODUCTS_RTOL), max(atol, NEWTON_PRODUCTS_RTOL))
    evaluate = _closure(system, phase, _shift(system, particle_turns), rtol, atol, loose)
    kept = np.flatnonzero(phase.keep)

    def closure(w: np.ndarray, jacobian: bool) -> Evaluation:
        residual, monodromy, velocity = evaluate(w)

        def matrix() -> np.ndarray:
            # [(M - I) E, f(Phi_T(y0)); phase rows], written into one array a few columns at a time, and M let go
            # (only the Jacobian is kept): one copy of M's size at the peak instead of several.
            mono, size = monodromy.matrix(threads=threads), monodromy.size
            rows = phase.rows(len(w))
            out = np.empty((size + rows.shape[0], kept.size + 1))
            for first in range(0, kept.size, BLOCK_COLUMNS):
                chunk = kept[first : first + BLOCK_COLUMNS]
                out[:size, first : first + chunk.size] = mono[:, chunk]
            out[kept, np.arange(kept.size)] -= 1.0
            out[:size, -1] = velocity
            out[size:] = rows
            monodromy.formed = None
            return out

        # M is formed only where Newton asks for a fresh Jacobian (chord iterations, and at the solution).
        return Evaluation(residual, matrix, monodromy)

    solved = newton(
        closure, w0, converged=deep_convergence(tol), max_iterations=max_iter, divergence=None, chord=CHORD_RATE, damping=damping
    )
    if not solved.converged or (segments is not None and solved.evaluation.data.size <= ALL_MULTIPLIERS_UP_TO):
        return solved, None
    return solved, Monodromy(system, solved.evaluation.data.start, solved.evaluation.data.period, rtol, atol).matrix(threads=threads)


def deep_convergence(tol: float):
    """The convergence test of Newton with inexact steps (:func:`~.kit.newton`'s ``converged``): the closure at
    ``tol`` times :data:`NEWTON_DEPTH`, or at ``tol`` where a step no longer divides it by 1 / :data:`CHORD_RATE`
    (its noise floor)."""
    previous = [math.inf]

    def converged(evaluation: Evaluation, norm: float) -> bool:
        done = norm <= tol * NEWTON_DEPTH or (norm <= tol and norm > CHORD_RATE * previous[0])
        previous[0] = norm
        return done

    return converged


def blocked_shooting(system: _System, particle_turns: np.ndarray, rtol: float, atol: float):
    """:func:`~.periodic._shooting` with M from column blocks and dPhi_T/dM by central differences in the moment.

    The variational equations give dPhi_T/dM only as the one-piece integration's last column;
    here it is the fourth-order central difference of Phi_T(y0; M) with step h =
    :data:`MOMENT_STEP` max(1, |M|), four state-only integrations, or, where that step moves
    the state by more than :data:`MOMENT_REACH`, the step that moves it by that. On the paper's
    orbit at M = 0.22 (|dPhi_T/dM| = 318) it equals the variational column to 1.4e-10 relative;
    second order needed h = 1e-7 for 7e-10 (its truncation, (318 h)^2, against the integrations'
    1e-11 / h).
    """
    shift = _shift(system, particle_turns)

    def evaluate(y0: np.ndarray, period: float, variations: bool = True):
        end, _, _ = system.flow(y0, period, rtol=rtol, atol=atol, variations=False)
        residual = end - y0 - shift
        if not variations:
            return residual, None, None, None, None
        mono = Monodromy(system, y0, period, rtol, atol).matrix()
        return residual, mono - np.eye(len(y0)), system.velocity(end), moment_column(system, y0, period, rtol, atol), mono

    return evaluate


def moment_column(system: _System, y0: np.ndarray, period: float, rtol: float, atol: float) -> np.ndarray:
    """dPhi_T/dM (2 n_free,) at y0 by the fourth-order central difference of :func:`blocked_shooting`'s contract."""
    d_moment = _moment_derivative(system, y0, period, MOMENT_STEP * max(1.0, abs(system.moment)), rtol, atol)
    reach = float(np.max(np.abs(d_moment))) * MOMENT_STEP * max(1.0, abs(system.moment))
    if reach > MOMENT_REACH:
        # A sensitive orbit (near a fold of cycles |dPhi_T/dM| reaches 7e4): the step moves the state
        # by no more than MOMENT_REACH, so that the differences stay in the linear range.
        d_moment = _moment_derivative(system, y0, period, MOMENT_REACH / float(np.max(np.abs(d_moment))), rtol, atol)
    return d_moment


def _moment_derivative(system: _System, y0: np.ndarray, period: float, step: float, rtol: float, atol: float) -> np.ndarray:
    """dPhi_T/dM (2 n_free,) by the fourth-order central difference with ``step``."""
    near, far = (
        [
            dataclasses.replace(system, moment=system.moment + sign * reach * step).flow(
                y0, period, rtol=rtol, atol=atol, variations=False
            )[0]
            for sign in (1.0, -1.0)
        ]
        for reach in (1.0, 2.0)
    )
    return (8.0 * (near[0] - near[1]) - (far[0] - far[1])) / (12.0 * step)


def segment_matrices(
    system: _System,
    y0: np.ndarray,
    period: float,
    segments: int,
    *,
    rtol: float,
    atol: float,
    block: int = BLOCK_COLUMNS,
    threads: int | None = None,
) -> np.ndarray:
    """The transfer matrices G_1 ... G_m (m, 2 n_free, 2 n_free) of ``segments`` equal pieces of [0, period] from y0, from column blocks.

    The pieces' start states come from state-only integrations carried from y0; each block of
    ``block`` identity columns is integrated over every piece from its start (one
    integration a piece, from the identity's columns again), the blocks on ``threads`` threads
    (default :data:`THREADS`) as in :meth:`Monodromy.matrix`. G_m ... G_1 is the monodromy; kept
    apart, the strongly damped directions keep their digits (:mod:`~.floquet`).

    Raises
    ------
    MemoryEstimateError
        Where the matrices and the periodic Schur form's working copies of them
        (:data:`SEGMENT_COPIES` in all) do not fit in the free memory.
    """
    size = y0.size
    require(
        SEGMENT_COPIES * segments * size * size * FLOAT,
        f"{segments} segment matrices of {size} x {size} and the periodic Schur form's {SEGMENT_COPIES - 1} working copies",
        "fewer segments (--segments: 16 to 64 keep the smallest multipliers to round-off)",
    )  # fmt: skip
    piece = period / segments
    starts = [np.asarray(y0, dtype=float)]
    for _ in range(segments - 1):
        starts.append(system.flow(starts[-1], piece, rtol=rtol, atol=atol, variations=False)[0])
    out = np.empty((segments, size, size))

    def columns(first: int) -> None:
        width = min(block, size - first)
        unit = np.zeros((size, width))
        unit[first + np.arange(width), np.arange(width)] = 1.0
        for k, start in enumerate(starts):
            out[k, :, first : first + width] = Monodromy(system, start, piece, rtol, atol).apply(unit)

    firsts = range(0, size, block)
    workers = threads or THREADS or len(os.sched_getaffinity(0))
    with ThreadPoolExecutor(max_workers=max(1, min(workers, len(firsts)))) as pool:
        list(pool.map(columns, firsts))
    return out


def orbit_multipliers(
    system: _System,
    y0: np.ndarray,
    period: float,
    monodromy: Monodromy | np.ndarray | None,
    segments: int | None,
    *,
    rtol: float,
    atol: float,
    threads: int | None = None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
    """The orbit's Floquet multipliers, their error estimates and, from segments, their log-moduli (else None).

    Without ``segments``: :func:`leading_multipliers` of ``monodromy``. With them, up to 2 n_free =
    :data:`ALL_MULTIPLIERS_UP_TO`: all multipliers by the periodic Schur form of the segments'
    matrices (:func:`segment_matrices`, :func:`~.floquet.periodic_schur_multipliers`), each
    small one as accurate as its pieces; the trivial one's error is |G_m ... G_1 f - f| / |f|
    for the unit flow f at y0 (the factors applied in turn), the others' are not estimated
    (NaN). Above that size the periodic Schur form of the full matrices is not computed: the
    leading ones from the formed ``monodromy`` as without segments, with a warning that the
    small ones are not computed.
    """
    flow = system.velocity(y0)
    if segments is not None and y0.size > ALL_MULTIPLIERS_UP_TO:
        warnings.warn(
            f"segments={segments}: only the {MULTIPLIERS} leading nontrivial Floquet multipliers are computed above "
            f"2 n_free = {ALL_MULTIPLIERS_UP_TO} (this orbit has {y0.size}), from the formed monodromy as without segments; "
            "the small ones are not computed",
            stacklevel=3,
        )
        segments = None
    if segments is None:
        values, errors = leading_multipliers(monodromy, flow)
        return values, errors, None
    stack = segment_matrices(system, y0, period, segments, rtol=rtol, atol=atol, threads=threads)
    found = floquet.periodic_schur_multipliers(stack)
    unit = flow / np.linalg.norm(flow)
    mapped = unit
    for factor in stack:
        mapped = factor @ mapped
    errors = np.full(found.values.size, np.nan)
    errors[np.argmin(np.abs(found.values - 1.0))] = float(np.linalg.norm(mapped - unit))
    return found.values, errors, found.log_moduli


def leading_multipliers(
    monodromy: Monodromy | np.ndarray,
    flow: np.ndarray,
    count: int = MULTIPLIERS,
    *,
    form: bool | None = None,
    max_dimension: int = ARNOLDI_MAX,
) -> tuple[np.ndarray, np.ndarray]:
    """The trivial Floquet multiplier and the nontrivial ones of largest modulus, with their error estimates.

    The flow direction f = f(y0) is the trivial multiplier's eigenvector at a closed orbit
    (M f = f), so in an orthonormal basis (f / |f|, Q) M is block upper triangular up to the
    integration error, [[mu_1, *], [c, Q^T M Q]] with c = Q^T M f / |f| ~ 0: the trivial
    multiplier is mu_1 = f^T M f / |f|^2, its error |(M - I) f| / |f| (>= |mu_1 - 1|: 1 is an
    exact multiplier of a monodromy that far from M), and the others are the eigenvalues of
    Q^T M Q, the deflated M (a cluster of nontrivial multipliers near 1 cannot blur the
    trivial one). Their errors are the residual norms |Q^T M Q x - mu x| of unit eigenvectors
    plus |c| (each is an exact eigenvalue of a matrix that close to the computed M where M is
    normal; a non-normal M can multiply the distance by the eigenvalue's condition number).

    Parameters
    ----------
    monodromy : Monodromy or ndarray (2 n_free, 2 n_free)
        Products with M, or M formed.
    flow : ndarray (2 n_free,)
        f(y0), the vector field at the orbit's start.
    count : int
        How many nontrivial multipliers beyond the formed M's :data:`ALL_MULTIPLIERS_UP_TO`
        (then by ARPACK on the deflated M: those that converge within :data:`ARPACK_RESTARTS` restarts), or by
        Arnoldi on products.
    form : bool, optional
        Form M from column blocks (:meth:`Monodromy.matrix`) rather than Arnoldi on products;
        default where 2 n_free <= :data:`FORM_UP_TO`, or 2 count + 2 (Arnoldi needs room).
    max_dimension : int
        Most Arnoldi vectors; where the leading Ritz values have not converged by then (a
        cluster of equal moduli among them) they are reported with their larger errors.

    Returns
    -------
    multipliers : ndarray (k,) complex
        By decreasing modulus, the trivial one among them.
    errors : ndarray (k,)
        Their error estimates (above).

    Raises
    ------
    ValueError
        For count < 1 or a zero flow (a rest state is no orbit).
    """
    if not (isinstance(count, int | np.integer) and count >= 1):
        raise ValueError(f"count must be an integer >= 1 (leading Floquet multipliers), got {count!r}")
    norm = float(np.linalg.norm(flow))
    if not (math.isfinite(norm) and norm > 0):
        raise ValueError(f"flow must be a finite non-zero vector (the vector field on the orbit), got norm {norm!r}")
    unit = np.asarray(flow, dtype=float) / norm
    size = unit.size
    if form is None:
        form = size <= max(FORM_UP_TO, 2 * count + 2)
    if isinstance(monodromy, np.ndarray) or form:
        matrix = monodromy if isinstance(monodromy, np.ndarray) else monodromy.matrix()
        mapped = matrix @ unit
        trivial = float(unit @ mapped)
        # Householder reflector H (symmetric, orthogonal) with H unit = -+e_1: H M H = [[mu_1, *], [c, core]].
        w = unit.copy()
        w[0] += math.copysign(1.0, unit[0])
        beta = 2.0 / float(w @ w)

        def reflect(z: np.ndarray) -> np.ndarray:
            return z - beta * np.outer(w, w @ z).reshape(z.shape)

        def deflated(z: np.ndarray) -> np.ndarray:
            # H M H z for z (2 n_free,) or (2 n_free, k): products only, no second matrix of M's size.
            return reflect(matrix @ reflect(z))

        def core_product(z: np.ndarray) -> np.ndarray:
            padded = np.zeros((size,) + z.shape[1:], dtype=np.result_type(z, float))
            padded[1:] = z
            return deflated(padded)[1:]

        coupling = float(np.linalg.norm(deflated(np.eye(size, 1)[:, 0])[1:]))
        if size <= ALL_MULTIPLIERS_UP_TO:
            values, vectors = sla.eig(reflect(reflect(matrix.T).T)[1:, 1:])
        else:
            values, vectors = _leading_core(matrix, reflect, core_product, count, min(max_dimension, size - 2))
        vectors = vectors / np.linalg.norm(vectors, axis=0)
        errors = np.linalg.norm(core_product(vectors) - vectors * values, axis=0) + coupling
        if size > ALL_MULTIPLIERS_UP_TO:
            _flag_unconverged(values, errors)
    else:

        def deflated_product(z: np.ndarray) -> np.ndarray:
            out = monodromy.apply(z)
            return out - unit * (unit @ out)

        start = np.random.default_rng(SEED).standard_normal(size)
        values, vectors = _arnoldi(deflated_product, start - unit * (unit @ start), count, min(max_dimension, size - 2))
        # Every Ritz vector and the flow direction in one integration.
        mapped = monodromy.apply(np.column_stack([vectors, unit]))
        mapped_unit = mapped[:, -1].real
        trivial = float(unit @ mapped_unit)
        coupling = float(np.linalg.norm(mapped_unit - trivial * unit))
        products = mapped[:, :-1] - np.outer(unit, unit @ mapped[:, :-1])
        errors = np.linalg.norm(products - vectors * values, axis=0) + coupling
        _flag_unconverged(values, errors)
        mapped = mapped_unit
    values = np.append(trivial, values)
    errors = np.append(np.linalg.norm(mapped - unit), errors)
    order = np.argsort(-np.abs(values), kind="stable")
    return values[order], errors[order]


def _leading_core(matrix: np.ndarray, reflect, core_product, count: int, dimension: int) -> tuple[np.ndarray, np.ndarray]:
    """The leading eigenpairs of the deflated monodromy C = (H M H)[1:, 1:] (:func:`leading_multipliers`) above
    :data:`ALL_MULTIPLIERS_UP_TO`: those of largest modulus and those nearest :data:`SHIFT` (shift-invert), by ARPACK
    (:func:`~cosserat_chain.linalg.eigen.largest_and_nearest`).

    (C - s)^-1 b comes from one LU factorisation of M - s I: X = H (M - s)^-1 H is the inverse of
    A = H M H - s, and the inverse of its trailing block C - s is X_22 - X_21 X_12 / X_11
    (the Schur complement of X's first entry), so (C - s)^-1 b = z[1:] - g[1:] z[0] / g[0]
    with z = X (0, b) and g = X e_1: exact whatever the coupling c, with one matrix beside M (its
    memory checked first). Where it does not fit, a warning says so and the leading Ritz pairs
    come from ARPACK on the products, and where it converges on fewer than ``count`` within
    :data:`ARPACK_RESTARTS` restarts, from the package's Arnoldi (``dimension`` products), with
    their residual errors (:func:`_flag_unconverged` warns where these are large).
    """
    size = matrix.shape[0]
    try:
        require(
            size * size * FLOAT, f"the LU factors of M - {SHIFT!r} I ({size} x {size}) beside the monodromy",
            "the leading multipliers come by ARPACK and Arnoldi on products instead (less accurate where they crowd near 1)",
        )  # fmt: skip
    except MemoryEstimateError as err:
        warnings.warn(f"{err}", stacklevel=4)
    else:
        work = np.array(matrix, order="C")
        work.flat[:: size + 1] -= SHIFT
        # The transpose is Fortran-ordered: LAPACK factors it in place, and M - s I is solved with trans=1.
        factors = sla.lu_factor(work.T, overwrite_a=True, check_finite=False)

        def shifted(z: np.ndarray) -> np.ndarray:
            return reflect(sla.lu_solve(factors, reflect(z), trans=1, check_finite=False))

        first = shifted(np.eye(size, 1)[:, 0])

        def inverse(b: np.ndarray) -> np.ndarray:
            padded = np.zeros((size,) + b.shape[1:])
            padded[1:] = b
            z = shifted(padded)
            return z[1:] - np.multiply.outer(first[1:], z[0] / first[0]).reshape(b.shape)

        values, vectors, (largest, nearest) = largest_and_nearest(
            core_product, inverse, size - 1, SHIFT, count, tol=ARNOLDI_TOL, restarts=ARPACK_RESTARTS
        )  # fmt: skip
        if values.size < count:
            # Neither run converged on enough (a crowd wider than the shift-invert's reach too): Arnoldi's Ritz pairs
            # fill in, with their larger residual errors (flagged by _flag_unconverged).
            start = np.random.default_rng(SEED).standard_normal(size - 1)
            values, vectors = merge_eigenpairs(core_product, (values, vectors), _arnoldi(core_product, start, count, dimension))
        values, vectors = values[:count], vectors[:, :count]
        if largest < count:
            reach = float(np.max(np.abs(values - SHIFT), initial=0.0))
            warnings.warn(
                f"ARPACK converged on {largest} of the {count} nontrivial Floquet multipliers of largest modulus within "
                f"{ARPACK_RESTARTS} restarts (they crowd): the {nearest} nearest {SHIFT!r} come by shift-invert, those reported lie "
                f"within {reach:.3g} of it, and a multiplier farther from it with a larger modulus than some of them is not excluded",
                stacklevel=4,
            )
        return values, vectors
    # ARPACK on the products: a deflated copy of M would double the memory of a long chain's multipliers.
    core = spla.LinearOperator((size - 1, size - 1), matvec=core_product, matmat=core_product, dtype=float)
    start = np.random.default_rng(SEED).standard_normal(size - 1)
    try:
        # The fixed start (ARPACK's own is random): the multipliers' last digits do not change from run to run.
        return spla.eigs(core, k=min(count, size - 3), which="LM", tol=ARNOLDI_TOL, maxiter=ARPACK_RESTARTS, v0=start.copy())
    except spla.ArpackNoConvergence as err:
        if err.eigenvalues.size >= count:
            return err.eigenvalues, err.eigenvectors
    return _arnoldi(core_product, start, count, dimension)


def _flag_unconverged(values: np.ndarray, errors: np.ndarray) -> None:
    """Warn where a nontrivial multiplier's error estimate exceeds :data:`UNCONVERGED` (a Ritz value, not an eigenvalue)."""
    loose = errors > UNCONVERGED * np.maximum(1.0, np.abs(values))
    if np.any(loose):
        warnings.warn(
            f"{int(np.count_nonzero(loose))} of {values.size} nontrivial Floquet multipliers did not converge: their residual "
            f"errors reach {float(np.max(errors[loose])):.2g} (multiplier_errors); they are Ritz values, not eigenvalues",
            stacklevel=4,
        )


def _arnoldi(product, start: np.ndarray, count: int, dimension: int) -> tuple[np.ndarray, np.ndarray]:
    """The ``count`` Ritz pairs of largest modulus of the operator ``product`` from Arnoldi's method (unit Ritz vectors).

    Stops once their estimated residuals are below :data:`ARNOLDI_TOL` (checked every
    :data:`ARNOLDI_CHECK` products), at an invariant subspace, or after ``dimension`` products.
    """
    size = start.size
    basis = np.zeros((size, dimension + 1))
    hessenberg = np.zeros((dimension + 1, dimension))
    basis[:, 0] = start / np.linalg.norm(start)
    for m in range(1, dimension + 1):
        w = product(basis[:, m - 1])
        # Two passes of Gram-Schmidt keep the basis orthonormal to round-off.
        for _ in range(2):
            coefficients = basis[:, :m].T @ w
            w -= basis[:, :m] @ coefficients
            hessenberg[:m, m - 1] += coefficients
        hessenberg[m, m - 1] = np.linalg.norm(w)
        invariant = hessenberg[m, m - 1] <= 1e-14 * np.linalg.norm(hessenberg[: m + 1, m - 1])
        if not invariant:
            basis[:, m] = w / hessenberg[m, m - 1]
        if invariant or m == dimension or (m >= count and m % ARNOLDI_CHECK == 0):
            values, small = sla.eig(hessenberg[:m, :m])
            leading = np.argsort(-np.abs(values), kind="stable")[:count]
            estimate = abs(hessenberg[m, m - 1]) * np.abs(small[m - 1, leading])
            if invariant or m == dimension or np.all(estimate <= ARNOLDI_TOL * np.maximum(1.0, np.abs(values[leading]))):
                break
    vectors = basis[:, :m] @ small[:, leading]
    return values[leading], vectors / np.linalg.norm(vectors, axis=0)
