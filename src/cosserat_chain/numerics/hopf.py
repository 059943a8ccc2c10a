"""Hopf points of static branches: where a complex pair of the damped dynamics crosses the imaginary axis.

Contract
--------
Along a static branch (x(s), M(s)) (:func:`~cosserat_chain.numerics.continuation.continue_in_moment`)
the eigenvalues of the damped dynamics linearised about each state
(:func:`~cosserat_chain.numerics.stability.dynamic_stability`) move; stability changes where
one crosses the imaginary axis. A real eigenvalue crosses at zero, where K is singular: a fold
or a branch point, which the continuation locates. A complex pair crosses at +-i omega with K
regular: a Hopf point, which K's inertia cannot see. For a conservative model with positive
damping there is none (the unstable count equals K's negative count at every state); the
sine model (eq. 2) has them: its unstable branch at N = 2 (paper's geometry) gains an unstable
pair at phi_0 = 1.658 (M = 0.2894) and loses it at phi_0 = 2.438 (M = 0.1880), where K keeps one
negative eigenvalue (and the mirror pair at 2 pi - phi_0, M -> -M).

:func:`hopf_points` detects them as a change of the number of unstable complex pairs between
two traced points with the same stiffness index, and locates each on the rotation-controlled
branch (:func:`~cosserat_chain.numerics.newton.solve_rotation_controlled`) by Brent's method on
the real part of the crossing pair: the largest real part of the complex eigenvalues, whose
sign changes there.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..models.base import Model, get_model
from ..params import ChainParams
from ..state import ROW_INDEX, column
from .brent import brentq
from .continuation import Branch
from .newton import NewtonError, solve_rotation_controlled
from .stability import DynamicStability, dynamic_stability

#: A Hopf point's phi_0 is located to this (rad).
PHI0_TOL = 1e-12
#: Eigenvalues with |Im| above this times their modulus are the complex ones.
COMPLEX_RTOL = 1e-8


@dataclass(frozen=True)
class HopfPoint:
    """A Hopf point of a static branch.

    Attributes
    ----------
    moment, phi0 : float
        Where the pair crosses (located to :data:`PHI0_TOL` in phi_0 where ``located``).
    frequency : float
        omega > 0 of the crossing pair +-i omega (rad per unit time).
    x : ndarray (3, 2N+1)
        The state there.
    after_point : int
        It lies between the traced points ``after_point`` and ``after_point + 1``.
    unstable_before, unstable_after : int
        Unstable eigenvalues of the damped dynamics on either side (in the direction of tracing).
    stiffness_index : int
        K's negative count there, the same on both sides.
    located : bool
        False where the rotation-controlled solve failed between the two points: ``x`` and
        ``moment`` are then those of the traced point before it.
    particle : int
    """

    moment: float
    phi0: float
    frequency: float
    x: np.ndarray
    after_point: int
    unstable_before: int
    unstable_after: int
    stiffness_index: int
    located: bool = True
    particle: int = 0

    def as_dict(self) -> dict[str, object]:
        """Plain types (for JSON), the state left out."""
        return {
            "moment": self.moment,
            "phi0": self.phi0,
            "frequency": self.frequency,
            "after_point": self.after_point,
            "unstable_before": self.unstable_before,
            "unstable_after": self.unstable_after,
            "stiffness_index": self.stiffness_index,
            "located": self.located,
        }


def crossing_part(stability: DynamicStability) -> tuple[float, float]:
    """(largest real part, its |Im|) of the complex eigenvalues in ``stability.rightmost``; (-inf, nan) if none."""
    values = np.array(stability.rightmost)
    complex_ = values[np.abs(values.imag) > COMPLEX_RTOL * np.abs(values)]
    if complex_.size == 0:
        return -math.inf, math.nan
    best = int(np.argmax(complex_.real))
    return float(complex_[best].real), float(abs(complex_[best].imag))


def hopf_points(
    params: ChainParams,
    model: str | Model,
    branch: Branch,
    *,
    checks: list[DynamicStability] | None = None,
    method: str = "auto",
) -> list[HopfPoint]:
    """The Hopf points of a traced static branch, each located (module docstring).

    Parameters
    ----------
    params : ChainParams
    model : str or Model
    branch : Branch
        From :func:`~cosserat_chain.numerics.continuation.continue_in_moment` of the same chain and model.
    checks : list of DynamicStability, optional
        :func:`~cosserat_chain.numerics.stability.dynamic_stability` at every point of the branch
        if the caller has it; computed otherwise.
    method : str
        Passed to :func:`~cosserat_chain.numerics.stability.dynamic_stability`.

    Returns
    -------
    list of HopfPoint
        In the order of tracing.

    Raises
    ------
    ValueError
        If ``checks`` does not have one entry a point of the branch.
    """
    model = get_model(model)
    if checks is None:
        checks = [dynamic_stability(params, model, x, method=method) for x in branch.x]
    if len(checks) != len(branch.moment):
        raise ValueError(f"checks must have one entry per point of the branch ({len(branch.moment)}), got {len(checks)}")
    col = column(params, branch.particle)
    out = []
    for i in range(len(checks) - 1):
        before, after = checks[i], checks[i + 1]
        if before.unstable_pairs == after.unstable_pairs or before.stiffness_index != after.stiffness_index:
            continue
        out.append(_locate(params, model, branch, i, before, after, col, method))
    return out


def _locate(params, model, branch: Branch, i: int, before: DynamicStability, after: DynamicStability, col: int, method: str) -> HopfPoint:
    """The Hopf point between traced points i and i + 1: Brent on the crossing pair's real part along phi_0."""
    particle = branch.particle
    phi = ROW_INDEX["phi"]
    low, high = float(branch.phi0[i]), float(branch.phi0[i + 1])
    states = {low: (branch.x[i], float(branch.moment[i])), high: (branch.x[i + 1], float(branch.moment[i + 1]))}

    def solve(phi0: float) -> tuple[np.ndarray, float]:
        if phi0 not in states:
            nearest = min(states, key=lambda p: abs(p - phi0))
            x0, m0 = states[nearest]
            states[phi0] = solve_rotation_controlled(params, model, phi0, particle=particle, x0=x0, moment0=m0, tol=1e-13)
        return states[phi0]

    def real_part(phi0: float) -> float:
        return crossing_part(dynamic_stability(params, model, solve(phi0)[0], method=method))[0]

    fallback = HopfPoint(
        float(branch.moment[i]), low, crossing_part(before)[1], branch.x[i], i,
        before.unstable_eigenvalues, after.unstable_eigenvalues, before.stiffness_index, False, particle,
    )  # fmt: skip
    try:
        a, b = real_part(low), real_part(high)
        if not (math.isfinite(a) and math.isfinite(b) and a * b < 0):
            return fallback
        root = brentq(real_part, low, high, xtol=PHI0_TOL, rtol=4 * np.finfo(float).eps)
        x, moment = solve(root)
    except NewtonError:
        return fallback
    frequency = crossing_part(dynamic_stability(params, model, x, method=method))[1]
    return HopfPoint(
        float(moment), float(x[phi, col]), frequency, x, i,
        before.unstable_eigenvalues, after.unstable_eigenvalues, before.stiffness_index, True, particle,
    )  # fmt: skip
