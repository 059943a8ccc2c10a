"""Periodic orbits of a user's system by orthogonal collocation, and their continuation in any parameter.

Contract
--------
For a :class:`~cosserat_chain.systems.base.System` M q'' = F(q; p) - C q' with state y = (q, q')
(2n), the orbit of period T that turns k_i times in each angle i solves (C) of
:mod:`~cosserat_chain.numerics.collocation_core` with the shift s = (2 pi k, 0): u' = T f(u),
u(1) = u(0) + s, and the integral phase condition. The scheme (mesh, Gauss collocation, the sparse
bordered Newton, the adapted mesh, the multipliers by condensation and the periodic Schur form,
whose trivial one's distance to 1 is its error) is the chain's; this module gives it what it needs
of a system, :class:`SystemFields`: f, df/dy on a fixed sparsity pattern (from
:meth:`~cosserat_chain.systems.base.System.force_jacobian`) and df/dp of the continued parameter
(:meth:`~cosserat_chain.systems.base.System.parameter_forces`), point by point.

* :func:`find_collocation_orbit` solves one orbit from a state and a period, a shooting
  :class:`~cosserat_chain.numerics.shooting.Orbit`, or another collocation orbit.
* :func:`continue_collocation_orbits` follows it in a named parameter with the chain's branch
  driver (:func:`~cosserat_chain.numerics.collocation.trace_collocation`): folds of cycles located
  and confirmed by a second multiplier at +1, period doublings and tori located, and (with
  ``through_folds``) on through the folds, so that a branch snaking towards a homoclinic loop is
  followed where single shooting's monodromy (||M|| ~ 1e9) no longer resolves it.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from ..linalg.threads import one_blas_thread
from ..models.base import no_ends
from ..systems.base import System
from .collocation import NTST_MAX, PERIOD_MAX, REMESH_EVERY, CollocationBranch, trace_collocation
from .collocation_core import (
    ADAPTATIONS,
    NCOL,
    NTST,
    TOL,
    CollocationError,
    ProfileOrbit,
    _batch,
    _Collocation,
    _node_times,
    check_mesh,
    scheme,
    solve_profile,
)
from .shooting import Orbit, _no_force, read_guess, require_periodic_turns, second_multiplier_at_one, states

#: The seed of the random states whose force Jacobians give the sparsity pattern.
PATTERN_SEED = 0
PATTERN_STATES = 3


class SystemFields:
    """f(y), df/dy (on a fixed pattern) and df/dp of a system at many points: what :class:`_Collocation` reads.

    The pattern is the union of the force Jacobian's entries at :data:`PATTERN_STATES` random states,
    with dq'/dv = I and dv'/dv = -C/M. A compiled system (:meth:`~cosserat_chain.systems.base.System.flow_kernels`)
    gives them all at once from its variational right-hand side, the coordinates seeded in columns of one
    colour each (no two of a colour share a row of the pattern, so each entry is read off its colour's
    column: O(n) per point, as the chain's fields); another system point by point from
    :meth:`~cosserat_chain.systems.base.System.force_jacobian`, where an entry outside the pattern is refused.
    ``parameter`` (or None) is the continued parameter, whose value each call passes as ``value``.
    """

    def __init__(self, system: System, parameter: str | None):
        if parameter is not None:
            system.parameter(parameter)
        self.system, self.parameter = system, parameter
        nf = system.size
        self.nf, self.n = nf, 2 * nf
        rng = np.random.default_rng(PATTERN_SEED)
        draws = [self._keys(system.force_jacobian(rng.uniform(-math.pi, math.pi, nf)))[0] for _ in range(PATTERN_STATES)]
        self._keys_sorted = np.unique(np.concatenate(draws))
        j_rows, j_cols = np.divmod(self._keys_sorted, nf)
        eye = np.arange(nf)
        self.rows = np.concatenate([eye, nf + eye, nf + j_rows])
        self.cols = np.concatenate([nf + eye, nf + eye, j_cols])
        #: Every state component's own "particle" (the nested dissection's unit): the pattern's band sets the separators.
        self.particle = np.concatenate([eye, eye])
        self._compiled = system.flow_kernels() is not None
        if self._compiled:
            colour = _colours(nf, j_rows, j_cols)
            #: Variational columns: one per colour, the last dy/dp.
            self._ncols = int(colour.max(initial=-1)) + 2
            self._seed = np.zeros((self.n, self._ncols))
            self._seed[eye, colour] = 1.0
            self._read = self.n + (nf + j_rows) * self._ncols + colour[j_cols]
            self._read_parameter = self.n + (nf + eye) * self._ncols + self._ncols - 1
        self._cache: tuple | None = None

    @property
    def nnz(self) -> int:
        return self.rows.size

    @staticmethod
    def _keys(jacobian) -> tuple[np.ndarray, np.ndarray]:
        matrix = sp.csr_matrix(jacobian)
        matrix.sum_duplicates()
        rows = np.repeat(np.arange(matrix.shape[0]), np.diff(matrix.indptr))
        return rows * matrix.shape[1] + matrix.indices, matrix.data

    def _at(self, value: float) -> tuple:
        """The system at the parameter's ``value``, its 1/M, C/M and (compiled) the flow's kernels and rpar."""
        if self._cache is None or self._cache[0] != value:
            system = self.system if self.parameter is None else self.system.with_parameters(**{self.parameter: value})
            inverse = 1.0 / system.mass()
            rate = system.damping() * inverse
            kernels = rpar = None
            if self._compiled:
                kernels = system.flow_kernels()
                d_inverse, d_rate = system.parameter_mass_damping(self.parameter) if self.parameter else (0 * inverse, 0 * rate)
                rpar = np.concatenate([inverse, rate, d_inverse, d_rate])
            self._cache = (value, system, inverse, rate, kernels, rpar)
        return self._cache[1:]

    def _batch(self, points: np.ndarray, value: float, ncols: int) -> np.ndarray:
        """The compiled right-hand side at every point with ``ncols`` seeded variational columns (P, 2n (1 + ncols))."""
        _, _, _, kernels, rpar = self._at(value)
        k = kernels.parameter_index[self.parameter] if (ncols and self.parameter) else -1
        ipar = np.array([*kernels.head, ncols, k], dtype=np.int64)
        start = np.zeros((points.shape[0], self.n * (1 + ncols)))
        start[:, : self.n] = points
        if ncols:
            start[:, self.n :] = self._seed.ravel()
        out = np.empty_like(start)
        _batch(kernels.rhs, _no_force, no_ends, kernels.coef, rpar, ipar, start, out)
        return out

    def values(self, points: np.ndarray, value: float) -> np.ndarray:
        """f at ``points`` (P, 2n)."""
        points = np.ascontiguousarray(points, dtype=float)
        if self._compiled:
            return self._batch(points, value, 0)
        system, inverse, rate, _, _ = self._at(value)
        nf = self.nf
        out = np.empty_like(points)
        out[:, :nf] = points[:, nf:]
        out[:, nf:] = np.array([system.forces(y[:nf]) for y in points]) * inverse - points[:, nf:] * rate
        return out

    def jacobian(self, points: np.ndarray, value: float) -> tuple[np.ndarray, np.ndarray]:
        """f (P, 2n) and A = df/dy on (:attr:`rows`, :attr:`cols`) (P, nnz) at ``points``."""
        points = np.ascontiguousarray(points, dtype=float)
        system, inverse, rate, _, _ = self._at(value)
        nf = self.nf
        out = np.zeros((points.shape[0], self.nnz))
        out[:, :nf] = 1.0
        out[:, nf : 2 * nf] = -rate
        if self._compiled:
            full = self._batch(points, value, self._ncols)
            out[:, 2 * nf :] = full[:, self._read]
            return full[:, : self.n], out
        factor = inverse[self.rows[2 * nf :] - nf]
        for p, y in enumerate(points):
            keys, data = self._keys(system.force_jacobian(y[:nf]))
            where = np.searchsorted(self._keys_sorted, keys).clip(max=self._keys_sorted.size - 1)
            outside = (self._keys_sorted[where] != keys) & (data != 0.0)
            if np.any(outside):
                row, col = divmod(int(keys[np.flatnonzero(outside)[0]]), nf)
                raise CollocationError(
                    f"the force Jacobian of {system.name} has an entry at ({row}, {col}) outside the pattern of its "
                    f"{PATTERN_STATES} random states: give force_jacobian every structural entry"
                )
            block = np.zeros(self._keys_sorted.size)
            np.add.at(block, where[~outside], data[~outside])
            out[p, 2 * nf :] = factor * block
        return self.values(points, value), out

    def parameter_derivative(self, points: np.ndarray, value: float) -> np.ndarray:
        """df/dp (P, 2n) of the continued parameter at ``points``."""
        if self.parameter is None:
            raise ValueError("these fields continue no parameter: give parameter= to SystemFields")
        points = np.ascontiguousarray(points, dtype=float)
        nf = self.nf
        out = np.zeros_like(points)
        if self._compiled:
            out[:, nf:] = self._batch(points, value, self._ncols)[:, self._read_parameter]
            return out
        system, inverse, _, _, _ = self._at(value)
        d_inverse, d_rate = system.parameter_mass_damping(self.parameter)
        for p, y in enumerate(points):
            q, v = y[:nf], y[nf:]
            out[p, nf:] = inverse * system.parameter_forces(q, self.parameter) + d_inverse * system.forces(q) - d_rate * v
        return out

    def dense(self, values: np.ndarray) -> np.ndarray:
        """A (P, 2n, 2n) from its pattern values (P, nnz)."""
        out = np.zeros((values.shape[0], self.n, self.n))
        np.add.at(out, (slice(None), self.rows, self.cols), values)
        return out


def _colours(n: int, rows: np.ndarray, cols: np.ndarray) -> np.ndarray:
    """A colour (n,) of each column of the pattern (rows, cols), greedily, no two columns of one colour sharing a row."""
    by_row = [cols[rows == r] for r in range(n)]
    by_col = [rows[cols == c] for c in range(n)]
    colour = np.full(n, -1)
    for c in range(n):
        taken = {int(colour[other]) for r in by_col[c] for other in by_row[r]}
        colour[c] = next(k for k in range(n + 1) if k not in taken)
    return colour


@dataclass(frozen=True)
class _Bound:
    """What :class:`_Collocation` reads of its system besides the fields: the continued parameter's value (``moment``)."""

    moment: float


@dataclass
class SystemCollocationOrbit(ProfileOrbit):
    """A periodic orbit of a system solved by collocation.

    Attributes
    ----------
    base : System
        The system (at the start's parameters; :attr:`system` is it at :attr:`moment`).
    parameter : str or None
        The parameter a continuation varies (None for a lone orbit).
    moment : float
        That parameter's value (NaN without one); named as the chain's moment, so that one branch driver
        (:func:`~cosserat_chain.numerics.collocation.trace_collocation`) serves both.
    turns : ndarray (n,) int
    period : float
    mesh : ndarray (ntst + 1,)
    ncol : int
    profile : ndarray (ntst ncol + 1, 2n)
        u at the nodes, unwrapped (the angles gain 2 pi k from the first node to the last).
    multipliers : ndarray (2n,) complex
        Floquet multipliers by decreasing modulus.
    residual : float
        max |R| at the solution.
    iterations : int
    multiplier_log_moduli : ndarray (2n,) or None
        ln |mu|, in range where mu under- or overflows.
    """

    base: System
    parameter: str | None
    moment: float
    turns: np.ndarray
    period: float
    mesh: np.ndarray
    ncol: int
    profile: np.ndarray
    multipliers: np.ndarray
    residual: float
    iterations: int
    multiplier_log_moduli: np.ndarray | None = None

    @property
    def system(self) -> System:
        return self.base if self.parameter is None else self.base.with_parameters(**{self.parameter: self.moment})

    @property
    def y0(self) -> np.ndarray:
        """The state at tau = 0 (2n,)."""
        return self.profile[0].copy()

    def as_dict(self) -> dict:
        """JSON-ready summary."""
        return {
            **self.system.describe(),
            "period": self.period,
            "turns": self.turns.tolist(),
            "y0": self.y0.tolist(),
            "ntst": self.ntst,
            "ncol": self.ncol,
            "multipliers_abs": np.abs(self.multipliers).tolist(),
            "trivial_multiplier_error": self.trivial_multiplier_error,
            "max_multiplier": self.max_multiplier,
            "stable": self.stable,
            "residual": self.residual,
        }


def _shift(system: System, turns: np.ndarray) -> np.ndarray:
    return np.concatenate([2 * math.pi * turns, np.zeros(system.size)])


@one_blas_thread
def find_collocation_orbit(
    system: System,
    guess: tuple[np.ndarray, float] | Orbit | SystemCollocationOrbit,
    *,
    turns: Mapping[str | int, int] | np.ndarray | None = None,
    ntst: int = NTST,
    ncol: int = NCOL,
    adapt: int = ADAPTATIONS,
    tol: float = TOL,
    max_iterations: int = 25,
) -> SystemCollocationOrbit:
    """The periodic orbit of ``system`` near ``guess``, by collocation (module docstring).

    Parameters
    ----------
    system : System
    guess : (y0 (2n,), T), Orbit or SystemCollocationOrbit
        A state on or near the orbit and its period (the flow from y0 over T, its mismatch spread
        linearly, is the first profile), or an orbit solved before (its turns are taken unless
        ``turns`` is given; a collocation orbit's profile is interpolated onto the new mesh).
    turns : mapping coordinate (name or index) -> k, or (n,) array
        Turns per period of the angles.
    ntst, ncol : int
        Mesh intervals and Gauss points per interval (AUTO-07p's NTST, NCOL).
    adapt : int
        Mesh adaptations after the first solve.
    tol : float
        Newton's tolerance on max |R|.

    Raises
    ------
    ValueError
        For a bad guess, mesh, adapt or tol.
    SystemDefinitionError
        For turns the forces are not periodic in.
    CollocationError
        If Newton's method does not converge.
    """
    check_mesh(ntst, ncol)
    y0, period, k = read_guess(system, guess, turns, (Orbit, SystemCollocationOrbit))
    require_periodic_turns(system, y0[: system.size], k)
    shift = _shift(system, k)
    if isinstance(guess, SystemCollocationOrbit):
        mesh, profile = guess.mesh, guess.profile
    else:
        mesh = np.linspace(0.0, 1.0, ntst + 1)
        tau = _node_times(mesh, scheme(ncol))
        profile = states(system, y0, tau * period)
        profile = profile - tau[:, None] * (profile[-1] - profile[0] - shift)[None, :]
    solution = solve_profile(
        _Bound(math.nan), y0, period, None, ntst=ntst, ncol=ncol, adapt=adapt, tol=tol, max_iter=max_iterations,
        profile=profile, mesh=mesh, shift=shift, fields=SystemFields(system, None),
        where=", ".join(f"{name}={value!r}" for name, value in system.parameters.items()),
    )  # fmt: skip
    return SystemCollocationOrbit(
        system, None, math.nan, np.asarray(k), solution.period, solution.mesh, solution.ncol, solution.profile,
        solution.multipliers, solution.residual, solution.iterations, solution.log_moduli,
    )  # fmt: skip


@one_blas_thread
def continue_collocation_orbits(
    orbit: SystemCollocationOrbit,
    parameter: str,
    *,
    direction: float = -1.0,
    limits: tuple[float, float] = (-math.inf, math.inf),
    period_max: float = PERIOD_MAX,
    through_folds: bool = False,
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
    """Follow a collocation orbit in the named ``parameter`` by pseudo-arclength (module docstring).

    The driver and its arguments are :func:`~cosserat_chain.numerics.collocation.continue_collocation`'s
    (``limits`` its ``moment_min``, ``moment_max``); each orbit's ``moment`` is the parameter's value.
    The branch ends at its first fold of cycles, or with ``through_folds`` goes on through each (every
    one an event of the branch, located by the secant method on the tangent's parameter component and
    kept only with a second multiplier at +1, as the shooting's: the second nearest +1, or the two
    nearest a double multiplier that the discretisation split symmetrically about +1,
    :func:`~cosserat_chain.numerics.shooting.second_multiplier_at_one`). The message warns where the trivial multiplier's error
    exceeds :data:`~cosserat_chain.numerics.collocation.TRIVIAL_WARNING` (raise ntst or give max_interval).

    Raises
    ------
    SystemDefinitionError
        For a parameter the system does not have.
    ValueError
        As :func:`~cosserat_chain.numerics.collocation.continue_collocation`.
    """
    base = orbit.system
    start = dataclasses.replace(orbit, base=base, parameter=parameter, moment=base.parameter(parameter))
    fields = SystemFields(base, parameter)
    shift = _shift(base, orbit.turns)
    return trace_collocation(
        start, lambda mesh, profile: _Collocation(_Bound(start.moment), mesh, orbit.ncol, shift, profile, free_moment=True, fields=fields),
        moment_min=limits[0], moment_max=limits[1], period_max=period_max, direction=direction, step=step, min_step=min_step,
        max_step=max_step, max_points=max_points, remesh_every=remesh_every, ntst=ntst, max_interval=max_interval,
        ntst_max=ntst_max, progress=progress, stop_at=() if through_folds else ("fold",),
        fold_message=f"fold of cycles: {parameter} turns back with the period finite and a second Floquet multiplier at +1",
        second_at_one=second_multiplier_at_one, parameter=parameter,
    )  # fmt: skip
