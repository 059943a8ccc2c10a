"""The geometrically exact (Reissner / Simo) planar beam of the chain: large bending, against model (i).

Contract
--------
The beam has the stiffnesses of the chain's Timoshenko beam (:mod:`.timoshenko`: EI = 2 E1 b^2 h,
GA = k_v h, EA = k_u h) and exact kinematics: a centre line r(s) = (x, y) and a section angle
theta(s) over the arclength 0 <= s <= 2L of the chain at rest (L = N h; s = 0 at particle -N),
with the strains measured in the section's frame,

    r_s = R(theta) (1 + n/EA, q/GA),   theta_s = m/EI,

where (n, q) = R(theta)^T F are the axial and shear components of the force F that the part
beyond s exerts on the part before it, and m the bending moment. Without distributed loads F is
constant and m_s = -(r_s x F). :func:`cantilever` solves the cantilever (clamped at s = 0, an
end moment and a dead end force at s = 2L) with ``scipy.integrate.solve_bvp``, the load raised
in steps from zero (continuation), each step starting from the last. Linearised about rest
these are the Timoshenko beam's equations (tested).

Under an end moment alone F = 0: the beam bends into a circle of curvature M/EI
(:func:`circle`), closing at M = 2 pi EI / (2L). :func:`bending_convergence` compares it with
model (i) under the same end angle (the rotation-controlled equilibrium of the package, each
bond of the chain the same): the moment that holds the angle and the tip's position, with the
errors' measured orders.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..params import ChainParams
from ..state import zero_held
from .beam import BeamStiffness, beam_stiffness
from .timoshenko import _fit_order, _half_lengths

#: Relative tolerance of the BVP solves (solve_bvp's residual measure).
BVP_TOL = 1e-9
#: Most mesh nodes solve_bvp may use.
MAX_NODES = 100_000


def _require_cantilever(params: ChainParams, what: str) -> None:
    if params.periodic or params.ends != ("clamped", "free"):
        raise ValueError(
            f"{what} is a cantilever: left_end = 'clamped' and right_end = 'free' (the load on particle N), got {params.describe_ends()}"
        )


@dataclass(frozen=True)
class BeamSolution:
    """A static state of the exact beam over the arclength.

    Attributes
    ----------
    s : ndarray, shape (n,)
        Arclength at rest, 0..2L (s = 0 at the clamped particle -N).
    x, y : ndarray, shape (n,)
        Centre line, in the chain's coordinates (particle k at rest at (k h, 0)).
    theta : ndarray, shape (n,)
        Section angle (the particles' phi).
    moment : ndarray, shape (n,)
        Bending moment m(s) = EI theta_s.
    force : tuple of float
        The constant force (F_x, F_y).
    end_moment : float
    """

    s: np.ndarray
    x: np.ndarray
    y: np.ndarray
    theta: np.ndarray
    moment: np.ndarray
    force: tuple[float, float]
    end_moment: float

    def at_particles(self, params: ChainParams) -> np.ndarray:
        """The state (3, 2N+1) of the chain sampled from the beam: u = x - k h, v = y, phi = theta at s = (k + N) h.

        The clamped end's values, zero to the BVP's tolerance, are set to zero.
        """
        k = np.arange(-params.N, params.N + 1)
        s = (k + params.N) * params.h
        x, y, theta = (np.interp(s, self.s, f) for f in (self.x, self.y, self.theta))
        return zero_held(params, np.array([x - k * params.h, y, theta]))


def _rates(stiffness: BeamStiffness, force: tuple[float, float]):
    fx, fy = force

    def rates(s: np.ndarray, state: np.ndarray) -> np.ndarray:
        _, _, theta, m = state
        c, si = np.cos(theta), np.sin(theta)
        axial = (fx * c + fy * si) / stiffness.EA
        shear = (-fx * si + fy * c) / stiffness.GA
        dx = c * (1 + axial) - si * shear
        dy = si * (1 + axial) + c * shear
        return np.array([dx, dy, m / stiffness.EI, -(dx * fy - dy * fx)])

    return rates


def circle(params: ChainParams, end_moment: float, s: np.ndarray | None = None) -> BeamSolution:
    """The cantilever under an end moment alone: a circle of curvature M/EI (closed form).

    theta = M s / EI, x = -L + (EI/M) sin theta, y = (EI/M) (1 - cos theta); no force, so no
    stretch or shear. ``s`` defaults to 201 points over [0, 2L].
    """
    _require_cantilever(params, "the circle")
    if not math.isfinite(end_moment):
        raise ValueError(f"end_moment must be finite, got {end_moment!r}")
    EI = beam_stiffness(params).EI
    length = 2 * params.N * params.h
    s = np.linspace(0.0, length, 201) if s is None else np.asarray(s, dtype=float)
    theta = end_moment * s / EI
    # sin(theta)/kappa and (1 - cos theta)/kappa written without dividing by a small curvature.
    x = -params.N * params.h + s * np.sinc(theta / np.pi)
    y = s * theta / 2 * np.sinc(theta / (2 * np.pi)) ** 2
    return BeamSolution(s, x, y, theta, np.full_like(s, end_moment), (0.0, 0.0), float(end_moment))


def cantilever(
    params: ChainParams, *, end_moment: float = 0.0, force: tuple[float, float] = (0.0, 0.0), steps: int = 8, n_nodes: int = 201
) -> BeamSolution:
    """Statics of the exact cantilever beam by ``solve_bvp``, with continuation in the load.

    Parameters
    ----------
    params : ChainParams
        A uniform chain with left_end = 'clamped' and right_end = 'free', E2 > 0.
    end_moment : float
        Moment on the free end (particle N).
    force : (float, float)
        Dead force (F_x, F_y) on the free end.
    steps : int
        Load steps from zero to the load (>= 1); each solve starts from the last solution.
    n_nodes : int
        Initial mesh (solve_bvp refines it).

    Raises
    ------
    ValueError
        For another kind of ends, a non-finite load, steps < 1, or a load step solve_bvp
        does not converge on (naming the step and saying to take more).
    """
    from scipy.integrate import solve_bvp

    _require_cantilever(params, "the exact beam's statics")
    stiffness = beam_stiffness(params)
    values = (end_moment, *force)
    if not all(math.isfinite(v) for v in values):
        raise ValueError(f"end_moment and force must be finite, got end_moment={end_moment!r}, force={force!r}")
    if steps < 1 or n_nodes < 3:
        raise ValueError(f"steps must be >= 1 and n_nodes >= 3, got steps={steps!r}, n_nodes={n_nodes!r}")
    L = params.N * params.h
    s = np.linspace(0.0, 2 * L, n_nodes)
    guess = np.array([s - L, 0 * s, 0 * s, 0 * s])
    for step in range(1, steps + 1):
        fraction = step / steps
        moment, fx, fy = (fraction * v for v in values)

        def ends(left: np.ndarray, right: np.ndarray, moment: float = moment) -> np.ndarray:
            return np.array([left[0] + L, left[1], left[2], right[3] - moment])

        result = solve_bvp(_rates(stiffness, (fx, fy)), ends, s, guess, tol=BVP_TOL, max_nodes=MAX_NODES)
        if not result.success:
            raise ValueError(f"the exact beam's BVP did not converge at load step {step} of {steps} ({result.message}): take more steps")
        s, guess = result.x, result.y
    return BeamSolution(s, guess[0], guess[1], guess[2], guess[3], (float(force[0]), float(force[1])), float(end_moment))


# ---------------------------------------------------------------------------- against model (i)
#: Longest chain that :func:`bending_convergence` also solves whole (the per-bond reduction covers any N).
DIRECT_LIMIT = 1000
#: Errors at or below this (round-off of agreeing values) are left out of the measured orders.
FIT_FLOOR = 1e-13


@dataclass(frozen=True)
class BendingConvergence:
    """Model (i)'s cantilever bent by an end moment to the end angle ``angle``, against the beam's circle.

    Under an end moment alone every bond of the chain carries the same moment and no force, so
    every bond takes the same state: model (i)'s moment and tip follow from one bond
    (:func:`bond_bending`), for any N. The whole chain, solved directly up to
    :data:`DIRECT_LIMIT`, checks that reduction; its moment is limited by round-off (the
    force balance's residual, about 1e-13 on each particle, adds up along 2N bonds: 1e-6 of the
    moment at N = 1000 for the paper's chain), which the reduction avoids.

    Attributes
    ----------
    angle : float
        The free end's angle (rad), the same for every N (2 pi: the chain closes into a ring).
    N : ndarray of int, shape (n,)
    chain_moment, beam_moment : ndarray, shape (n,)
        The end moment that holds the angle: model (i)'s (per-bond reduction) and the beam's, angle EI / (2L).
    chain_tip, beam_tip : ndarray, shape (n, 2)
        The free end's position (x, y).
    length : ndarray, shape (n,)
        The chain's length at rest, 2 N h.
    direct_moment : ndarray, shape (n,)
        Model (i)'s moment from the whole chain (NaN beyond :data:`DIRECT_LIMIT`).
    direct_tip : ndarray, shape (n, 2)
        Its free end's position (NaN beyond the limit).
    """

    angle: float
    N: np.ndarray
    chain_moment: np.ndarray
    beam_moment: np.ndarray
    chain_tip: np.ndarray
    beam_tip: np.ndarray
    length: np.ndarray
    direct_moment: np.ndarray
    direct_tip: np.ndarray

    @property
    def moment_error(self) -> np.ndarray:
        """(beam - chain) / chain of the moment that holds the angle."""
        return (self.beam_moment - self.chain_moment) / self.chain_moment

    @property
    def tip_error(self) -> np.ndarray:
        """|chain tip - beam tip| over the length 2L."""
        return np.hypot(*(self.chain_tip - self.beam_tip).T) / self.length

    @property
    def direct_spread(self) -> np.ndarray:
        """How far the whole chain's moment lies from the per-bond one, relative (NaN where not solved)."""
        return np.abs(self.direct_moment - self.chain_moment) / np.abs(self.chain_moment)

    def order(self, which: str = "moment") -> float | None:
        """Measured order p of |error| ~ N^-p of ``"moment"`` or ``"tip"`` (least squares on log-log axes)."""
        if which not in ("moment", "tip"):
            raise ValueError(f"which must be 'moment' or 'tip', got {which!r}")
        return _fit_order(self.N, self.moment_error if which == "moment" else self.tip_error, FIT_FLOOR)

    def to_dataset(self):
        """The table as an xarray Dataset over ``N`` (variables ``bending_*``), to merge with the Timoshenko table's."""
        import xarray as xr

        columns = {
            "bending_chain_moment": (self.chain_moment, "end moment holding the end angle, model (i)"),
            "bending_beam_moment": (self.beam_moment, "end moment holding the end angle, exact beam (angle EI / 2L)"),
            "bending_moment_error": (self.moment_error, "(beam - chain) / chain of the end moment"),
            "bending_tip_error": (self.tip_error, "distance of the chain's free end from the beam's, over 2L"),
            "bending_direct_spread": (self.direct_spread, "whole chain's moment against the per-bond one, relative"),
        }
        data = {name: ("N", values, {"long_name": text}) for name, (values, text) in columns.items()}
        dataset = xr.Dataset(data, coords={"N": ("N", self.N)})
        dataset.attrs.update(
            {
                "bending_angle": self.angle,
                **{f"bending_{which}_order": np.nan if self.order(which) is None else self.order(which) for which in ("moment", "tip")},
            }
        )
        return dataset

    def as_dict(self) -> dict[str, object]:
        """Columns as lists and both orders (for JSON); NaN becomes None."""

        def plain(values: np.ndarray) -> list:
            return [plain(v) if np.ndim(v) else (float(v) if math.isfinite(v) else None) for v in values]

        return {
            "angle": self.angle,
            "N": [int(n) for n in self.N],
            "chain_moment": plain(self.chain_moment),
            "beam_moment": plain(self.beam_moment),
            "moment_error": plain(self.moment_error),
            "chain_tip": plain(self.chain_tip),
            "beam_tip": plain(self.beam_tip),
            "tip_error": plain(self.tip_error),
            "direct_moment": plain(self.direct_moment),
            "direct_spread": plain(self.direct_spread),
            "moment_order": self.order("moment"),
            "tip_order": self.order("tip"),
        }


def chain_end_moment(params: ChainParams, angle: float) -> tuple[np.ndarray, float]:
    """Model (i)'s cantilever with its free end turned to ``angle``: the state (3, 2N+1) and the end moment that holds it.

    The rotation-controlled Newton method of :func:`cosserat_chain.numerics.newton.solve_rotation_controlled`,
    started on the beam's circle with the same end angle.
    """
    from ..numerics.newton import solve_rotation_controlled

    _require_cantilever(params, "the chain bent by an end moment")
    EI = beam_stiffness(params).EI
    moment = angle * EI / (2 * params.N * params.h)
    start = circle(params, moment).at_particles(params)
    return solve_rotation_controlled(params, "nonlinear", angle, particle=params.N, x0=start, moment0=moment)


def bond_bending(params: ChainParams, per_bond: float) -> tuple[float, complex]:
    """One bond of model (i) bent by ``per_bond`` (rad) with no force: the moment it carries, and its chord.

    Solved as the shortest cantilever (N = 1, two bonds) with its end turned by 2 per_bond,
    whose two bonds are alike. The chord is the vector from a particle's centre to the next
    one's, as x + i y in the frame of the first particle.
    """
    short = params.replace(N=1)
    x, moment = chain_end_moment(short, 2 * per_bond)
    return moment, complex(short.h + x[0, 1] - x[0, 0], x[1, 1] - x[1, 0])


def bending_convergence(params: ChainParams, n_values: list[int] | np.ndarray, *, angle: float = math.pi) -> BendingConvergence:
    """Model (i) against the exact beam's circle for each N, the free end turned to ``angle``.

    Parameters
    ----------
    params : ChainParams
        A cantilever (left_end = 'clamped', right_end = 'free'); N replaced by each of ``n_values``.
    n_values : sequence of int
    angle : float
        End angle in (0, 2 pi] (rad); 2 pi closes the chain into a ring, pi a half circle.

    Raises
    ------
    ValueError
        For an empty list, N < 1, an angle outside (0, 2 pi], or another kind of ends.
    """
    _require_cantilever(params, "the chain bent by an end moment")
    if not (math.isfinite(angle) and 0 < angle <= 2 * math.pi):
        raise ValueError(f"angle must lie in (0, 2 pi] (the free end's angle, rad), got {angle!r}")
    n_values = _half_lengths(n_values)
    rows = []
    for n in n_values:
        chain = params.replace(N=n)
        length = 2 * n * chain.h
        per_bond = angle / (2 * n)
        moment, chord = bond_bending(chain, per_bond)
        # 2N chords, each turned by per_bond from the last: a geometric sum.
        tip = -n * chain.h + chord * np.sum(np.exp(1j * per_bond * np.arange(2 * n)))
        beam_moment = angle * beam_stiffness(chain).EI / length
        end = circle(chain, beam_moment, np.array([length]))
        direct_moment, direct_tip = math.nan, (math.nan, math.nan)
        if n <= DIRECT_LIMIT:
            state, direct_moment = chain_end_moment(chain, angle)
            direct_tip = (n * chain.h + state[0, -1], state[1, -1])
        rows.append((moment, beam_moment, (tip.real, tip.imag), (end.x[0], end.y[0]), length, direct_moment, direct_tip))
    moments, beam_moments, tips, beam_tips, lengths, direct_moments, direct_tips = zip(*rows)
    return BendingConvergence(
        angle=float(angle),
        N=np.array(n_values),
        chain_moment=np.array(moments),
        beam_moment=np.array(beam_moments),
        chain_tip=np.array(tips),
        beam_tip=np.array(beam_tips),
        length=np.array(lengths),
        direct_moment=np.array(direct_moments),
        direct_tip=np.array(direct_tips),
    )


@dataclass(frozen=True)
class ElasticaConvergence:
    """Model (i)'s cantilever under a transverse dead force at its free end, against the exact beam (the elastica with stretch and shear).

    Attributes
    ----------
    load : float
        The load parameter F (2L)^2 / EI, the same for every N.
    N : ndarray of int, shape (n,)
    chain_tip, beam_tip : ndarray, shape (n, 2)
        The free end's position (x, y).
    chain_angle, beam_angle : ndarray, shape (n,)
        The free end's angle.
    length : ndarray, shape (n,)
        2 N h.
    """

    load: float
    N: np.ndarray
    chain_tip: np.ndarray
    beam_tip: np.ndarray
    chain_angle: np.ndarray
    beam_angle: np.ndarray
    length: np.ndarray

    @property
    def tip_error(self) -> np.ndarray:
        """|chain tip - beam tip| over the length 2L."""
        return np.hypot(*(self.chain_tip - self.beam_tip).T) / self.length

    @property
    def angle_error(self) -> np.ndarray:
        """(beam - chain) / chain of the free end's angle."""
        return (self.beam_angle - self.chain_angle) / self.chain_angle

    def order(self, which: str = "tip") -> float | None:
        """Measured order p of |error| ~ N^-p of ``"tip"`` or ``"angle"``."""
        if which not in ("tip", "angle"):
            raise ValueError(f"which must be 'tip' or 'angle', got {which!r}")
        return _fit_order(self.N, self.tip_error if which == "tip" else self.angle_error, FIT_FLOOR)

    def as_dict(self) -> dict[str, object]:
        """Columns as lists and both orders (for JSON)."""
        return {
            "load": self.load,
            "N": [int(n) for n in self.N],
            "chain_tip": self.chain_tip.tolist(),
            "beam_tip": self.beam_tip.tolist(),
            "tip_error": self.tip_error.tolist(),
            "chain_angle": self.chain_angle.tolist(),
            "beam_angle": self.beam_angle.tolist(),
            "angle_error": self.angle_error.tolist(),
            "tip_order": self.order("tip"),
            "angle_order": self.order("angle"),
        }


def elastica_convergence(
    params: ChainParams, n_values: list[int] | np.ndarray, *, load: float = 2.0, steps: int = 4
) -> ElasticaConvergence:
    """Model (i) against the exact beam under a transverse dead force F = load EI / (2L)^2 at the free end, for each N.

    The beam by :func:`cantilever` (``steps`` load steps); model (i) by Newton's method
    (:func:`cosserat_chain.numerics.newton.solve_equilibrium`) started on the beam sampled at the particles.

    Raises
    ------
    ValueError
        For another kind of ends, an empty list or N < 1, a load that is not finite and > 0, or
        a chain whose branch from rest folds below the load (no static state to compare).
    """
    from ..loads import Loads, Schedule
    from ..loads import PointLoad as ChainLoad
    from ..numerics.newton import BranchEndError, NewtonError, solve_equilibrium

    _require_cantilever(params, "the elastica")
    if not (math.isfinite(load) and load > 0):
        raise ValueError(f"load (F (2L)^2 / EI) must be finite and > 0, got {load!r}")
    n_values = _half_lengths(n_values)
    rows = []
    for n in n_values:
        chain = params.replace(N=n)
        length = 2 * n * chain.h
        force = load * beam_stiffness(chain).EI / length**2
        beam = cantilever(chain, force=(0.0, force), steps=steps)
        loads = Loads([ChainLoad("v", n, Schedule.constant(force))])
        try:
            state = solve_equilibrium(chain, "nonlinear", loads, x0=beam.at_particles(chain))
        except NewtonError:
            # The beam is a start, not the chain's state: a coarse chain of large particles can sit far
            # from it. The chain's own branch from rest decides then, and says where it ends if it folds.
            try:
                state = solve_equilibrium(chain, "nonlinear", loads)
            except NewtonError as err:
                why = f"its branch from rest folds at {err.load_factor:.6g} of it" if isinstance(err, BranchEndError) else str(err)
                raise ValueError(f"no static state of the N = {n} chain holds the end force F = {force:.6g}: {why}") from err
        rows.append(((n * chain.h + state[0, -1], state[1, -1]), (beam.x[-1], beam.y[-1]), state[2, -1], beam.theta[-1], length))
    tips, beam_tips, angles, beam_angles, lengths = zip(*rows)
    return ElasticaConvergence(
        load=float(load),
        N=np.array(n_values),
        chain_tip=np.array(tips),
        beam_tip=np.array(beam_tips),
        chain_angle=np.array(angles),
        beam_angle=np.array(beam_angles),
        length=np.array(lengths),
    )
