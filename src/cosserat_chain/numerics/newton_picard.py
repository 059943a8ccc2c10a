"""Newton-Picard shooting: rotating orbits of long chains with a small dominant subspace of the monodromy.

Contract
--------
The method of Lust, Roose, Spence and Champneys (SIAM J. Sci. Comput. 19, 1998; PDECONT),
``find_periodic_orbit(..., method="picard")``. The Newton step of (P) and the phase condition
(the unknowns of :mod:`~.long_orbits`: y0 on the section or plane of
:class:`~.periodic._Phase`, and T),

    (M - I) dy + f(Phi_T(y0)) dT = -R,      c . dy = -phase residual,

is split along an orthonormal basis V_p (2 n_free, p) of the multipliers above ``rho``
(default :data:`RHO`) and its orthogonal complement, dy = V_p a + q with V_p^T q = 0:

* **Picard** on the complement, where M's multipliers are below ``rho``: q = q_R + q_T dT with
  Q (M - I) q_R = -Q R and Q (M - I) q_T = -Q f(Phi_T(y0)) (Q = I - V_p V_p^T), as
  q = Q M q + Q b for both columns together (one integration with two columns a step), from
  q = Q b, until a step moves each by less than the forcing term (the closure, clipped to
  [:data:`PICARD_RTOL_MIN`, :data:`PICARD_RTOL_MAX`]: an inexact Newton) or :data:`PICARD_MAX`
  products; it contracts at the rate of the largest multiplier left out (where it blows up,
  :data:`PICARD_BLOWUP`, the step takes Q b alone).
* **Newton** on the p-dimensional projection with T and the phase condition (p + 1 unknowns,
  a dense solve), the couplings V_p^T M q from Picard's last product. A step longer than
  :data:`REACH` times the step taken before it is replaced by the Levenberg-Marquardt step of
  that length (a trust region; :func:`_trust_region_step`): far from a long chain's orbit the
  multipliers of its soft modes, within 1e-8 of 1 at the orbit, move by more than that, some
  above 1, and the Newton step along them is long and points the wrong way, which halving it
  (the corrector's damping) does not change.

V_p comes from subspace iteration with block products M V (:class:`~.long_orbits.Monodromy`, one
integration of the state with p + g columns, O(N (p + g)) a step): each Newton step applies M
to the basis, orders its Schur-Rayleigh-Ritz form by modulus (the first p, those above ``rho``,
are V_p) and takes the orthonormalised image as the next step's basis; the basis keeps
max(``guard``, p / 2) columns beyond the p above ``rho`` (``guard`` default :data:`GUARD`), so
a multiplier that crosses ``rho`` between steps enters V_p, and grows by random columns when it
does; a direction along which Picard grows or stalls (a multiplier above ``rho`` still outside
V_p) joins it too. The basis
starts from the flow f(y0) (the trivial multiplier's vector) and random columns, swept at the
guess until the count above ``rho`` and their moduli settle with ``guard`` columns below them
(:data:`START_SWEEPS`). Newton's products use the looser
:data:`~.long_orbits.NEWTON_PRODUCTS_RTOL`; the closure itself is at the shooting's tolerance and
the convergence test is the blocks' (:func:`~.long_orbits.deep_convergence`). Each Newton step
costs one state integration, one block and the Picard products: no monodromy is ever formed
(memory: a few (2 n_free, p + g) blocks). The split step is exact only where V_p is invariant,
so far from the orbit it is a poorer step than the blocks' Newton step: Newton-Picard wants a
guess near the orbit (a settled simulation of a damped chain, or the orbit at a nearby moment);
from a settled guess that closes only to 1e-1 (a random geometry at N = 3, tests) it may stall
where the blocks converge.

**Multipliers and their guarantee** (:func:`ritz_multipliers`): at the solution the basis is
refined by subspace iteration on the monodromy at the shooting's tolerance, with the flow
direction u = f / |f| deflated as in :func:`~.long_orbits.leading_multipliers`: the trivial
multiplier u . M u with its error |(M - I) u| (>= its distance from 1 up to the products'
accuracy), the others the Ritz values of the deflated M on the basis, each with its residual
|M x - mu x| (unit Ritz vector x, plus the flow's coupling |M u - (u . M u) u|, the integrations' floor), until the residuals of
those above ``rho`` (without the coupling) are below :data:`RITZ_TOL` max(1, |mu|) or
:data:`REFINE_MAX` sweeps. The residual
is a backward error: each mu is an exact multiplier of a monodromy within that distance of the
computed one (the eigenvalue itself may move further by its condition number where M is far
from normal). A multiplier is *certified above rho* where |mu| - residual > rho. The orbit's
``multipliers`` are the trivial one and those above ``rho``, by decreasing modulus, with
``multiplier_errors``; the smaller ones are not computed.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
import scipy.linalg as sla

from .kit import Correction, Evaluation, newton
from .long_orbits import NEWTON_PRODUCTS_RTOL, SEED, Monodromy, _closure, _shift, deep_convergence

if TYPE_CHECKING:
    from .periodic import _Phase, _System

#: Multipliers above this modulus are Newton's (V_p); below, Picard's.
RHO = 0.5
#: Columns of the basis beyond those above ``rho`` (they catch a multiplier crossing ``rho``, and speed up the iteration).
GUARD = 8
#: Subspace-iteration sweeps at the guess before the first Newton step: at least this many, and on (up to the
#: second number) until the count of multipliers above ``rho`` repeats with ``guard`` columns of the basis below it
#: and their moduli move by at most START_SETTLED.
START_SWEEPS, START_SWEEPS_MAX, START_SETTLED = 3, 40, 1e-3
#: Picard's relative tolerance on q in a Newton step: the closure max |R|, clipped to this range.
PICARD_RTOL_MIN, PICARD_RTOL_MAX = 1e-10, 1e-2
#: Most Picard products in one Newton step.
PICARD_MAX = 60
#: Picard stops where an iterate exceeds this times its start (a multiplier above 1 outside V_p, far from the orbit).
PICARD_BLOWUP = 1e3
#: The multipliers above ``rho`` have converged when their residuals are below this times max(1, |mu|).
RITZ_TOL = 1e-10
#: Most subspace-iteration sweeps spent on the multipliers at the solution.
REFINE_MAX = 60
#: A Newton step is at most this many times as long as the step taken before it (a trust region on the p + 1 system,
#: solved there in the Levenberg-Marquardt form; the first step is free).
REACH = 2.0


def check_options(rho: float, guard: int, size: int) -> None:
    """Refuse a ``rho`` outside (0, 1) or a ``guard`` that is not an integer in [1, 2 n_free - 2].

    Raises
    ------
    ValueError
        Naming the value and what is allowed.
    """
    if not (isinstance(rho, float | int) and math.isfinite(rho) and 0 < rho < 1):
        raise ValueError(f"rho must be a number in (0, 1) (multipliers above it are Newton's, below Picard's), got {rho!r}")
    if not (isinstance(guard, int | np.integer) and 1 <= guard <= size - 2):
        raise ValueError(f"guard must be an integer in [1, {size - 2}] (basis columns beyond the multipliers above rho), got {guard!r}")


def _orthonormal(block: np.ndarray) -> np.ndarray:
    """An orthonormal basis of the columns of ``block`` (QR, in their order)."""
    return np.linalg.qr(block)[0]


@dataclass
class _Subspace:
    """The basis of the subspace iteration, carried from Newton step to Newton step."""

    rho: float
    guard: int
    rng: np.random.Generator
    basis: np.ndarray | None = None

    def _grow(self, wanted: int) -> None:
        """Random columns (orthonormalised against the basis) up to ``wanted`` columns."""
        size, have = self.basis.shape
        wanted = min(wanted, size - 2)
        if wanted > have:
            self.basis = _orthonormal(np.hstack([self.basis, self.rng.standard_normal((size, wanted - have))]))

    def add(self, direction: np.ndarray) -> None:
        """A direction Picard found growing or slow (a multiplier above ``rho`` not yet in the basis) joins the basis."""
        if self.basis.shape[1] < self.basis.shape[0] - 2:
            self.basis = _orthonormal(np.column_stack([self.basis, direction]))

    def start(self, monodromy: Monodromy) -> None:
        """Sweeps at the guess: at least :data:`START_SWEEPS`, on until the count above ``rho`` repeats with ``guard``
        columns below it and their moduli settle (:data:`START_SETTLED`; at most :data:`START_SWEEPS_MAX`)."""
        moduli, settled, sweeps = None, False, 0
        while sweeps < START_SWEEPS_MAX and not (settled and sweeps >= START_SWEEPS):
            columns = self.basis.shape[1] if self.basis is not None else 0
            _, _, schur, above = self.sweep(monodromy)
            sweeps += 1
            previous, moduli = moduli, np.sort(np.abs(sla.eigvals(schur[:above, :above])))
            settled = (
                previous is not None and previous.size == above and columns >= above + self.guard
                and np.max(np.abs(moduli - previous), initial=0.0) <= START_SETTLED
            )  # fmt: skip

    def sweep(self, monodromy: Monodromy) -> tuple[np.ndarray, np.ndarray, np.ndarray, int]:
        """One Schur-Rayleigh-Ritz sweep: (V, M V, V^T M V) in the Schur basis, those above ``rho`` first, and their count p.

        The basis becomes the orthonormalised image, with ``guard`` columns beyond p.
        """
        if self.basis is None:
            flow = monodromy.system.velocity(monodromy.start)
            self.basis = _orthonormal(np.column_stack([flow, self.rng.standard_normal((flow.size, self.guard))]))
        image = monodromy.apply(self.basis)
        rayleigh = self.basis.T @ image
        schur, rotation, above = sla.schur(rayleigh, output="real", sort=lambda re, im: math.hypot(re, im) > self.rho)
        basis, image = self.basis @ rotation, image @ rotation
        self.basis = _orthonormal(image)
        self._grow(above + max(self.guard, above // 2))
        return basis, image, schur, int(above)


def complement(monodromy: Monodromy, dominant: np.ndarray, sources: np.ndarray, forcing: float, subspace: _Subspace) -> tuple:
    """Picard on the complement of ``dominant`` (V_p): the columns q with Q (M - I) q = -Q b for the columns b of ``sources``.

    q = Q M q + Q b for all columns at once (one integration a step), from q = Q b, until a step
    moves each by at most ``forcing`` times its norm or :data:`PICARD_MAX` products; on a blow-up
    (:data:`PICARD_BLOWUP`) q = Q b. Where the first column's iteration is slow or grows (a multiplier
    above rho outside V_p), its direction joins ``subspace``.

    Returns
    -------
    q : ndarray (2 n_free, k)
    mapped : ndarray (2 n_free, k)
        M applied to the last iterate but one (the couplings V_p^T M q of the projected Newton step).
    """
    rhs = sources - dominant @ (dominant.T @ sources)
    q, mapped, first = rhs, None, None
    for _ in range(PICARD_MAX):
        mapped = monodromy.apply(q)
        first = mapped if first is None else first
        following = mapped - dominant @ (dominant.T @ mapped) + rhs
        change = following - q
        moved = np.linalg.norm(change, axis=0)
        # A non-normal M can make the first moves grow before they contract: only a blow-up stops Picard early,
        # and its step is then Q b's alone.
        if np.any(np.linalg.norm(following, axis=0) > PICARD_BLOWUP * np.maximum(np.linalg.norm(rhs, axis=0), 1e-300)):
            q, mapped = rhs, first
            break
        q = following
        if np.all(moved <= forcing * np.maximum(np.linalg.norm(q, axis=0), 1e-300)):
            break
    if not np.all(moved <= forcing * np.maximum(np.linalg.norm(q, axis=0), 1e-300)):
        # Slow or growing: a multiplier above rho outside V_p, whose direction joins the basis.
        subspace.add(change[:, 0] / max(moved[0], 1e-300))
    return q, mapped


@dataclass
class _PicardStep:
    """The Newton-Picard step at one iterate: the monodromy's products there and the flow at Phi_T(y0)."""

    monodromy: Monodromy
    velocity_end: np.ndarray


def picard_correction(
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
    rho: float | None = None,
    guard: int | None = None,
) -> tuple[Correction, tuple[np.ndarray, np.ndarray] | None]:
    """Newton-Picard shooting from w0 = (y0's unknowns on ``phase``, T); the correction and, converged, the multipliers.

    See the module docstring. ``rho`` and ``guard`` default to :data:`RHO` and :data:`GUARD`.

    Returns
    -------
    correction : Correction
        Its ``evaluation.data`` the :class:`Monodromy` at the last iterate.
    found : (multipliers, errors) or None
        Converged: :func:`ritz_multipliers` at the solution (the trivial one and those above ``rho``).

    Raises
    ------
    ValueError
        For a ``rho`` outside (0, 1) or a bad ``guard`` (:func:`check_options`).
    """
    rho = RHO if rho is None else rho
    guard = GUARD if guard is None else guard
    size = 2 * system.nf
    check_options(rho, guard, size)
    loose = (max(rtol, NEWTON_PRODUCTS_RTOL), max(atol, NEWTON_PRODUCTS_RTOL))
    evaluate = _closure(system, phase, _shift(system, particle_turns), rtol, atol, loose)
    subspace = _Subspace(rho, guard, np.random.default_rng(SEED))
    # The phase condition c . dy = target over the whole of dy (the section holds the loaded angle).
    normal = np.zeros(size)
    if phase.normal is None:
        normal[phase.dof] = 1.0
    else:
        normal[:] = phase.normal

    def closure(w: np.ndarray, jacobian: bool) -> Evaluation:
        residual, monodromy, velocity = evaluate(w)
        return Evaluation(residual, _PicardStep(monodromy, velocity), monodromy)

    previous: list[np.ndarray] = []

    def step(w: np.ndarray, evaluation: Evaluation, at: _PicardStep) -> np.ndarray:
        residual = np.asarray(evaluation.residual)
        if subspace.basis is None:
            subspace.start(at.monodromy)
        basis, image, schur, p = subspace.sweep(at.monodromy)
        dominant = basis[:, :p]
        closure_r, target = residual[:size], (-residual[size:] if residual.size > size else np.zeros(1))[0]
        # Picard on the complement, dy = V_p a + q_R + q_T dT with Q (M - I) q_R = -Q R and Q (M - I) q_T = -Q f(Phi_T(y0)).
        forcing = min(PICARD_RTOL_MAX, max(PICARD_RTOL_MIN, float(np.max(np.abs(residual)))))
        q, mapped = complement(at.monodromy, dominant, np.column_stack([closure_r, at.velocity_end]), forcing, subspace)
        # Newton on the projection, the couplings V_p^T M q from Picard's last product:
        # [V^T (M - I) V, V^T M q_T + V^T f; c . V, c . q_T] (a, dT) = (-V^T R - V^T M q_R, target - c . q_R).
        coupling = dominant.T @ mapped
        system_matrix = np.zeros((p + 1, p + 1))
        system_matrix[:p, :p] = schur[:p, :p] - np.eye(p)
        system_matrix[:p, p] = coupling[:, 1] + dominant.T @ at.velocity_end
        system_matrix[p, :p] = normal @ dominant
        system_matrix[p, p] = normal @ q[:, 1]
        right = np.append(-dominant.T @ closure_r - coupling[:, 0], target - normal @ q[:, 0])

        def taken(solution: np.ndarray) -> np.ndarray:
            dy = dominant @ solution[:p] + q[:, 0] + q[:, 1] * solution[p]
            return np.append(dy[phase.keep], solution[p])

        reach = REACH * float(np.linalg.norm(w - previous[-1])) if previous else math.inf
        previous[:] = [w.copy()]
        return _trust_region_step(system_matrix, right, taken, reach)

    solved = newton(
        closure, w0, converged=deep_convergence(tol), max_iterations=max_iter, divergence=None, damping=damping, newton_step=step
    )
    if not solved.converged:
        return solved, None
    at = solved.evaluation.data
    accurate = Monodromy(system, at.start, at.period, rtol, atol)
    values, errors, _ = ritz_multipliers(accurate, system.velocity(at.start), subspace.basis, rho=rho, guard=guard)
    return solved, (values, errors)


def _trust_region_step(matrix: np.ndarray, right: np.ndarray, taken, reach: float) -> np.ndarray:
    """The step ``taken(x)`` of the solution x of ``matrix`` x = ``right``, or, where that step is longer than ``reach``,
    of the Levenberg-Marquardt solution x(lam) = argmin |matrix x - right|^2 + lam^2 |x|^2 whose step is ``reach`` long.

    Far from a long chain's orbit its soft multipliers (within 1e-8 of 1 at the orbit) move by more than their distance
    from 1, some above it: the Newton step along them is long and wrong, and halving it keeps its direction
    (docs/periodic-orbits.md). The regularised step leaves those directions until the iterate is nearer, and takes the
    rest of the correction.
    """
    left, values, rows = np.linalg.svd(matrix)
    projected = left.T @ right

    def step(lam: float) -> np.ndarray:
        with np.errstate(divide="ignore", invalid="ignore"):
            gains = np.where(values > 0, values / (values**2 + lam**2), 0.0)
        return taken(rows.T @ (gains * projected))

    full = step(0.0)
    if not np.linalg.norm(full) > reach:
        return full
    low, high = 0.0, max(float(values[0]), 1e-300)
    for _ in range(200):  # lam large enough (the Picard part alone may stay longer than reach: then lam's largest)
        if not np.linalg.norm(step(high)) > reach:
            break
        high *= 2.0
    for _ in range(60):  # bisection on lam, the step's length falling as lam grows
        middle = 0.5 * (low + high)
        low, high = (middle, high) if np.linalg.norm(step(middle)) > reach else (low, middle)
        if high - low <= 1e-6 * high:
            break
    return step(high)


def ritz_multipliers(
    monodromy, flow: np.ndarray, basis: np.ndarray | None = None, *, rho: float = RHO, guard: int = GUARD, sweeps: int = REFINE_MAX
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The trivial Floquet multiplier and those above ``rho``, with their residuals, by subspace iteration on products.

    Parameters
    ----------
    monodromy : Monodromy or a stand-in with ``apply(columns)`` and ``size``
        Products with M.
    flow : ndarray (2 n_free,)
        f(y0), the trivial multiplier's eigenvector at a closed orbit.
    basis : ndarray (2 n_free, k), optional
        Start of the iteration (Newton's last basis); default ``guard`` random columns.
    rho, guard : float, int
        The multipliers wanted are those above ``rho``; the basis keeps ``guard`` columns more.
    sweeps : int
        Most sweeps (block products).

    Returns
    -------
    multipliers : ndarray (k,) complex
        The trivial one and those above ``rho``, by decreasing modulus.
    errors : ndarray (k,)
        The trivial one's |(M - I) u|, u = f / |f|; the others' residuals |M x - mu x| of unit
        Ritz vectors of the deflated M, plus the flow's coupling |M u - (u . M u) u|.
    basis : ndarray
        The last basis (orthonormal, orthogonal to the flow).

    Raises
    ------
    ValueError
        For a bad ``rho`` or ``guard`` (:func:`check_options`) or a zero flow.
    """
    size = monodromy.size
    check_options(rho, guard, size)
    norm = float(np.linalg.norm(flow))
    if not (math.isfinite(norm) and norm > 0):
        raise ValueError(f"flow must be a finite non-zero vector (the vector field on the orbit), got norm {norm!r}")
    unit = np.asarray(flow, dtype=float) / norm
    rng = np.random.default_rng(SEED)
    if basis is None:
        basis = rng.standard_normal((size, guard))
    basis = basis - np.outer(unit, unit @ basis)
    basis = _orthonormal(basis)[:, : min(basis.shape[1], size - 2)]
    for sweep in range(sweeps):
        mapped = monodromy.apply(np.column_stack([unit, basis]))
        mapped_unit, image = mapped[:, 0], mapped[:, 1:]
        trivial = float(unit @ mapped_unit)
        coupling = float(np.linalg.norm(mapped_unit - trivial * unit))
        # The deflated M on the basis: (I - u u^T) M V.
        image = image - np.outer(unit, unit @ image)
        rayleigh = basis.T @ image
        values, vectors = sla.eig(rayleigh)
        vectors = vectors / np.linalg.norm(vectors, axis=0)
        residuals = np.linalg.norm(image @ vectors - (basis @ vectors) * values, axis=0)
        errors = residuals + coupling
        above = np.abs(values) > rho
        wanted = int(np.count_nonzero(above))
        # The flow's coupling is the integrations' floor, the same every sweep: the test is on the residuals alone.
        done = np.all(residuals[above] <= RITZ_TOL * np.maximum(1.0, np.abs(values[above])))
        # Converged once the basis also holds a multiplier below rho (none above it left out).
        if (done and wanted < basis.shape[1]) or sweep == sweeps - 1:
            break
        schur, rotation, _ = sla.schur(rayleigh, output="real", sort=lambda re, im: math.hypot(re, im) > rho)
        basis = _orthonormal(image @ rotation)
        if basis.shape[1] < min(wanted + guard, size - 2):
            extra = rng.standard_normal((size, min(wanted + guard, size - 2) - basis.shape[1]))
            extra -= np.outer(unit, unit @ extra)
            basis = _orthonormal(np.hstack([basis, extra]))
    values = np.append(trivial, values[above])
    errors = np.append(float(np.linalg.norm(mapped_unit - unit)), errors[above])
    order = np.argsort(-np.abs(values), kind="stable")
    return values[order], errors[order], basis
