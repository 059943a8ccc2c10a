"""How far the three models agree under small loads: the paper's remark on Fig. 2, measured.

Contract
--------
Every model shares the stiffness K at rest (eqs. (2) and (3) are derived from the
Hessian of potential (1) there), hence the rotation compliance c = d phi_0 / dM at
M = 0: the tangent phi_0 = c M of every static branch, and the whole branch of the
linear model (3). Write p = c M for that *linear angle*. A model's static rotation of
the loaded particle leaves the tangent by the relative deviation

    deviation(M) = phi_0(M) / (c M) - 1,

measured on the stable static branch from rest (load control up to the first fold).
This module computes it exactly, never from dynamics:

* :func:`static_deviation`: the deviation at given linear angles, by Newton's method in
  load control stepped up from rest;
* :func:`agreement_range`: the load range [0, M*] (equivalently [0, p*]) over which
  |deviation| stays within a tolerance: the branch by pseudo-arclength continuation
  (:func:`~cosserat_chain.numerics.continuation.continue_in_moment`), the edge located
  between its points by Brent's method in M;
* :func:`errors_against`: the relative errors of models against a reference model at
  the same loads (the paper's remark that the sine model's error exceeds the linear one's).

What it shows (``docs/agreement.md``): the sine model's statics are the linear model's in
(u, v, sin phi), so its deviation is arcsin(p) / p - 1 = p^2/6 + 3 p^4/40 + ... for every
chain; the nonlinear model's is kappa p^2 + O(p^4), with kappa set by the transverse
displacements: they grow with the chain's length and stretch the links at second order,
which stiffens the chain (kappa about -0.17 (v_max / (b phi_0))^2 for the paper's
geometry), while the central particle of N = 1 does not move (kappa > 0: softer).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from ..loads import moment_load
from ..models.base import Model, get_model
from ..numerics.brent import brentq
from ..numerics.continuation import PHI0_STEP, Branch, compliance, continue_in_moment
from ..numerics.newton import NewtonError, solve_equilibrium
from ..numerics.stability import static_stability
from ..params import ChainParams
from ..state import ROW_INDEX, column, zeros

#: Default tolerance on |deviation|: the models "agree" while they differ by at most 1 %.
TOLERANCE = 0.01
#: Halvings of a load step before :func:`static_deviation` gives up: the load lies beyond
#: the first fold (no static state of the branch from rest holds it).
MAX_HALVINGS = 20
#: Largest step in the linear angle p = c M when stepping up from rest (rad): Newton in
#: load control converges from the previous state within it on the paper's chain and
#: on long ones alike.
P_STEP = 0.02


@dataclass(frozen=True)
class AgreementRange:
    """The load range over which a model's static rotation stays within ``tolerance`` of the linear one.

    Attributes
    ----------
    model : str
    tolerance : float
        Bound on |phi_0 / (c M) - 1|.
    compliance : float
        c = d phi_0 / dM at rest, shared by every model.
    moment : float
        M*, the end of the range (the first load at which |deviation| reaches
        ``tolerance``, or the first fold, or the branch's end; see ``bound``).
    phi0_linear : float
        p* = c M*, the linear model's (3) angle at M*.
    phi0 : float
        The model's own angle of the loaded particle at M*.
    deviation : float
        phi0 / phi0_linear - 1 at M*: +-``tolerance`` when ``bound`` is "tolerance";
        its sign says whether the model is softer (+) or stiffer (-) than the linear one.
    bound : {"tolerance", "fold", "end"}
        What ends the range: the tolerance; the first fold (M_c of load control:
        the model agrees up to where its static branch ends); or the end of the traced
        branch (``phi0_max`` reached within the tolerance: the linear model itself).
    """

    model: str
    tolerance: float
    compliance: float
    moment: float
    phi0_linear: float
    phi0: float
    deviation: float
    bound: str

    def as_dict(self) -> dict:
        """JSON-ready, every attribute by name."""
        return {
            "model": self.model,
            "tolerance": self.tolerance,
            "compliance": self.compliance,
            "moment": self.moment,
            "phi0_linear": self.phi0_linear,
            "phi0": self.phi0,
            "deviation": self.deviation,
            "bound": self.bound,
        }


def _angle(params: ChainParams, x: np.ndarray, particle: int) -> float:
    return float(x[ROW_INDEX["phi"], column(params, particle)])


def _continues(params: ChainParams, model: Model, before: np.ndarray, after: np.ndarray) -> bool:
    """Whether ``after`` continues the stable branch from ``before``: no angle jumps, and stable."""
    turned = np.max(np.abs(after[ROW_INDEX["phi"]] - before[ROW_INDEX["phi"]]))
    return bool(turned <= PHI0_STEP and static_stability(params, model, after).stable)


def static_deviation(
    params: ChainParams, model: str | Model, phi0_linear: Sequence[float] | np.ndarray, *, particle: int = 0
) -> np.ndarray:
    """phi_0(M) / (c M) - 1 at the loads M = p / c of the linear angles p.

    The loads are solved in increasing order from rest, each state the start of the
    next solve, with steps of at most :data:`P_STEP` in p, each halved until its state is
    stable and no angle changed by more than
    :data:`~cosserat_chain.numerics.continuation.PHI0_STEP`: the result lies on the
    stable branch from rest.

    Parameters
    ----------
    params : ChainParams
    model : str or Model
    phi0_linear : array_like (k,)
        Linear angles p > 0 (rad).
    particle : int
        The loaded particle.

    Returns
    -------
    ndarray (k,)
        The deviations, in the order given.

    Raises
    ------
    ValueError
        If an angle is not finite and positive, or a load lies beyond the model's first
        fold (no step down to 2^-MAX_HALVINGS of the last one continues the branch).
    """
    model = get_model(model)
    p = np.asarray(phi0_linear, dtype=float)
    if p.ndim != 1 or not np.all(np.isfinite(p) & (p > 0)):
        raise ValueError(f"phi0_linear must be a 1-d array of finite angles > 0, got {phi0_linear!r}")
    c = compliance(params, model, particle=particle)
    x, reached = zeros(params), 0.0
    out = np.empty_like(p)
    for i in np.argsort(p):
        target = p[i]
        while reached < target:
            step = min(P_STEP, target - reached)
            for _ in range(MAX_HALVINGS):
                try:
                    solved = solve_equilibrium(params, model, moment_load((reached + step) / c, particle), x0=x)
                except NewtonError:
                    solved = None
                # Past the fold Newton may still converge, to a far static state: a step that
                # turns a particle by more than PHI0_STEP, or ends unstable, left the branch.
                if solved is not None and _continues(params, model, x, solved):
                    x = solved
                    break
                step /= 2
            else:
                raise ValueError(
                    f"no static state of the {model.name} branch from rest holds M = {target / c:.6g} (linear angle {target:.6g}): "
                    f"the load lies beyond the first fold (reached M = {reached / c:.6g})"
                )
            reached += step
        out[i] = _angle(params, x, particle) / target - 1.0
    return out


def agreement_range(
    params: ChainParams,
    model: str | Model,
    *,
    tolerance: float = TOLERANCE,
    particle: int = 0,
    phi0_max: float = math.pi,
    branch: Branch | None = None,
) -> AgreementRange:
    """The loads from rest over which the model's phi_0 stays within ``tolerance`` of the linear c M.

    Parameters
    ----------
    params : ChainParams
    model : str or Model
    tolerance : float
        Relative tolerance on phi_0 / (c M) - 1, in (0, 1).
    particle : int
        The loaded particle.
    phi0_max : float
        The branch is traced until |phi_0| reaches this (or its first fold).
    branch : Branch, optional
        The model's static branch from rest under a positive moment on ``particle``
        (:func:`~cosserat_chain.numerics.continuation.continue_in_moment` or
        :func:`~cosserat_chain.experiments.critical.critical_point`'s), to reuse
        instead of tracing it again.

    Returns
    -------
    AgreementRange

    Raises
    ------
    ValueError
        If ``tolerance`` is not in (0, 1), or ``branch`` belongs to another particle.
    """
    if not (math.isfinite(tolerance) and 0.0 < tolerance < 1.0):
        raise ValueError(f"tolerance must be a number in (0, 1), got {tolerance!r}")
    model = get_model(model)
    if branch is None:
        branch = continue_in_moment(params, model, particle=particle, phi0_stop=phi0_max, max_folds=1)
    elif branch.particle != particle:
        raise ValueError(f"the branch is loaded on particle {branch.particle}, not on particle {particle}")
    c = compliance(params, model, particle=particle)
    first_fold = branch.folds[0] if branch.folds else None
    # The stable branch from rest: its points up to the first fold, then the fold itself.
    moments, phis, states = [], [], []
    for moment, phi, x in zip(branch.moment, branch.phi0, branch.x):
        # Past the fold M falls, or (the point after it) lies beyond the fold's angle.
        past = moments and moment <= moments[-1]
        if past or (first_fold is not None and (moment >= first_fold.moment or phi >= first_fold.phi0)):
            break
        moments.append(float(moment))
        phis.append(float(phi))
        states.append(x)
    if first_fold is not None:
        moments.append(first_fold.moment)
        phis.append(first_fold.phi0)
        states.append(first_fold.x)

    def result(moment: float, phi: float, bound: str) -> AgreementRange:
        return AgreementRange(model.name, tolerance, c, moment, c * moment, phi, phi / (c * moment) - 1.0, bound)

    outside = [i for i in range(1, len(moments)) if abs(phis[i] / (c * moments[i]) - 1.0) >= tolerance]
    if not outside:
        return result(first_fold.moment, first_fold.phi0, "fold") if first_fold is not None else result(moments[-1], phis[-1], "end")
    i = outside[0]
    # Between two points of the branch where M still rises: load control is regular there,
    # and the solved state nearest in M starts each solve.
    solved = {moments[i - 1]: states[i - 1], moments[i]: states[i]}

    def excess(moment: float) -> float:
        start = solved[min(solved, key=lambda m: abs(m - moment))]
        x = solve_equilibrium(params, model, moment_load(moment, particle), x0=start, tol=1e-13)
        solved[moment] = x
        return abs(_angle(params, x, particle) / (c * moment) - 1.0) - tolerance

    # At rest the deviation is 0 / 0 (its limit is 0): the bracket starts just above it.
    low = moments[i - 1] if i > 1 else moments[i] * 1e-6
    edge = brentq(excess, low, moments[i], xtol=1e-14 * moments[i], rtol=4 * np.finfo(float).eps)
    if edge not in solved:
        excess(edge)
    return result(edge, _angle(params, solved[edge], particle), "tolerance")


def errors_against(
    params: ChainParams,
    reference: str | Model,
    models: Sequence[str | Model],
    phi0_linear: Sequence[float] | np.ndarray,
    *,
    particle: int = 0,
) -> dict[str, np.ndarray]:
    """Relative errors phi_0^model / phi_0^reference - 1 at the loads M = p / c (the same loads for all).

    The paper's remark on Fig. 2 that "the error of the model (2) increases compared with
    the error of the model (3)" takes the nonlinear model (1) as the reference.

    Returns
    -------
    dict
        Model name -> ndarray (k,) of errors.
    """
    base = 1.0 + static_deviation(params, reference, phi0_linear, particle=particle)
    return {get_model(m).name: (1.0 + static_deviation(params, m, phi0_linear, particle=particle)) / base - 1.0 for m in models}
