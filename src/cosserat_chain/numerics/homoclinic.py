"""Homoclinic ends of rotating orbits, solved as boundary-value problems rather than fitted.

Contract
--------
Below the static fold M_c a rotating orbit can end where it grows into a loop through the
static branch's unstable equilibrium, the saddle y_s: the orbit leaves y_s along its
unstable direction, turns k times in its angles and comes back to the same saddle shifted
by 2 pi k, y_s + 2 pi k. Its period diverges there like -log(M - M_h) / lambda_u, which is
why a continuation of the orbits can only creep towards M_h. Here the loop itself is the
unknown, on a truncated interval [0, T] with projection boundary conditions (the
formulation of HomCont, Champneys, Kuznetsov and Sandstede 1996, and Beyn 1990):

    y(0) = y_s(p) + eps0 v_u(p),                                           (H0)
    w_u(p) . (y(T) - y_s(p) - 2 pi k) = 0,                                (H1)
    |y(T) - y_s(p) - 2 pi k| = eps1,                                      (H2)

with v_u the saddle's unstable eigenvector (oriented so that the winding angle grows) and
w_u its left eigenvector, which is normal to the stable eigenspace: (H1) puts the end on
the stable eigenspace of the shifted saddle. (H0) and (H2) fix the time shift, so the
unknowns are the parameter p (the moment, or any named parameter of a
:class:`~cosserat_chain.systems.base.System`) and the time T: two equations in two
unknowns, solved by Newton with y(T) from the flow (:func:`~cosserat_chain.numerics.shooting.flow`),
dR/dT exact (the vector field at y(T)) and dR/dp by central differences ((H2) is solved as
log(|d| / eps1), nearly linear in T near the saddle). The saddle at each
p is Newton's (:func:`~cosserat_chain.numerics.equilibria.find_equilibrium`) from the nearest
one solved. The error of the linear boundary conditions is O(eps0^2 + eps1^2) in p; eps runs
down a ladder (1e-2 to 1e-6 by default), each rung started from the one before, and the
difference between the last two rungs is the reported accuracy (with the last Newton step
and the integration tolerance: :attr:`HomoclinicOrbit.accuracy`).

* :func:`homoclinic_end` solves (H0)-(H2) for any system, starting from a bracket of p in
  which the saddle's unstable manifold goes from falling back to turning over (bisection on
  that fate first, then the ladder).
* :func:`chain_homoclinic_end` does so for the paper's chain: the saddle is the static
  branch's equilibrium past the fold (:func:`~cosserat_chain.numerics.newton.solve_rotation_controlled`).
* :func:`continue_homoclinic` follows the end in a second parameter (the damping, say): each
  end predicted by a secant, bracketed around the prediction by the manifold's fate and
  solved down the ladder.
* :func:`fold_turns_over` tells, at one value of the second parameter, a homoclinic end from a
  SNIC: whether the fold's centre manifold turns over (a rotation exists at the fold; its end
  lies below) or falls back into the shifted fold (a SNIC).
* :func:`locate_snic_point` locates the codimension-two point where the homoclinic end meets
  the static fold and becomes a saddle-node on the invariant circle (SNIC) by the augmented
  system: the equilibrium is the fold (F = 0, J v = 0, in (q, M)), the orbit leaves it along
  its centre direction v (eigenvalue 0) and returns on the shifted fold's strong stable
  eigenspace, w_0 . (y(T) - y_f - 2 pi k) = 0: (H0)-(H2) with the fold for the saddle and
  the second parameter for p. Leaving along a zero eigenvalue is slow (the time to leave a
  distance eps0 grows like 1 / eps0), but the centre manifold attracts the start's
  O(eps0^2) offset on that side, so eps0 there is 1e-2 at no cost in accuracy.
  :func:`chain_snic_point` does so for the paper's chain in any of its fields.

The saddle's unstable eigenvalues must be real and off the imaginary axis. With one of them
(m = 1) the unknowns are (p, T) as above. With m > 1 (the in-phase saddle of AUTO-07p's two
coupled pendula also leaves in anti-phase) the loop leaves along the largest one's direction
tilted by m - 1 coefficients a into the others, y(0) = y_s + eps0 (v_u + V a) / |v_u + V a|,
and (H1) asks the end to lie on the stable eigenspace, W^T (y(T) - y_s - 2 pi k) = 0 with W
the m left unstable eigenvectors: m + 1 equations in (p, T, a). A saddle with a complex
unstable pair (the sine chain's unstable branch past a Hopf point) is refused with a message.

A saddle whose leading stable eigenvalues are a complex pair (a saddle-focus: the loop comes back
spiralling, and a rotation snakes into it through a fold of cycles at every turn) is solved by
:func:`homoclinic_from_orbit` with T fixed instead of (H2), whose |d| oscillates under its
envelope and has several roots in T (:func:`_solve_focus_ladder`); :func:`solve_branch_end` does
so for an orbit branch from its longest orbits.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field

import numpy as np

from ..errors import CosseratChainError
from ..linalg.threads import one_blas_thread
from ..state import pack, unpack
from ..systems.base import System
from .brent import brentq
from .equilibria import EquilibriumNotFound, find_equilibrium
from .kit import EvaluationFailed
from .periodic import OrbitError, PeriodicOrbit
from .shooting import states, turns_vector

#: Distances eps0 = eps1 of the boundary conditions, solved in turn, each from the one before.
EPS_LADDER = (1e-2, 1e-3, 1e-4, 1e-5, 1e-6)
#: eps0 at a fold (the codimension-two point): the orbit leaves along the centre direction,
#: which attracts the start's offset, while the time to leave grows like 1 / eps0.
FOLD_EPS0 = 1e-2
#: Tolerances of the integrations (DOP853).
RTOL = 1e-12
ATOL = 1e-13
#: Newton on (H1)-(H2) stops when max |R| is below this.
RESIDUAL_TOL = 1e-10
#: Newton iterations per rung of the ladder.
MAX_ITERATIONS = 30
#: First relative step of the central differences in the parameter (the scale is max(|p|, 1)), made smaller until
#: the residual changes by at most FD_CHANGE over it (within its linear range; the integrations' noise in R is ~1e-7).
FD_STEP = 1e-8
FD_CHANGE = 1e-2
#: The bisection on the manifold's fate stops at this relative width of the bracket.
BISECTION_RTOL = 1e-6
#: Time step of the sampled trajectories (fate and first guess of T), in units of 1 / |lambda|max.
SAMPLE = 0.05
#: The manifold turns over once the winding angle passes the shifted saddle's by this (rad).
OVER_MARGIN = 0.5
#: Largest change of any coordinate when the saddle is followed to a new parameter value in one Newton solve (rad, or
#: the coordinate's unit); a larger one is taken in halves (Newton from far lands on the node).
JUMP = 0.3
#: After the bisection the manifold must come within this many eps0 of the shifted saddle (else the fate changes at
#: another boundary: the N = 2 sine chain at gamma_phi = 0.02 passes 0.27 from it, crossing an unstable orbit's manifold).
APPROACH_FACTOR = 10.0
#: Doublings of the step while :func:`continue_homoclinic` brackets an end around its prediction (from 1e-4 of
#: the value, or a tenth of the last change, to 0.4 of the value).
BRACKET_DOUBLINGS = 12
#: Largest |Im| / |lambda| of a real leaving eigenvalue.
REAL_TOL = 1e-8
#: Samples per period of a long-period orbit, where :func:`homoclinic_from_orbit` reads off its first guess.
ORBIT_SAMPLES = 4001
#: :func:`homoclinic_from_orbit`'s first rung is at least this many times the orbit's closest passage by the saddle
#: (a rung before the ladder's first where that is too near), and at most FIRST_RUNG_MAX.
ORBIT_NEAR = 4.0
FIRST_RUNG_MAX = 0.1
#: FIRST_RUNG_MAX where the loop returns to a saddle-focus (:func:`_solve_focus_ladder`, T fixed): the orbits of a
#: snaking approach pass the saddle no nearer than 0.07 at T = 30 (three Josephson junctions).
FOCUS_FIRST_RUNG_MAX = 0.4
#: The rungs :func:`homoclinic_from_orbit` adds above the ladder's first are at most this factor apart.
RUNG_RATIO = 1.5
#: Rungs inserted (each halfway in log eps to the one that failed) where Newton misses a rung from a tilted start.
SPLITS = 4


class HomoclinicError(CosseratChainError, RuntimeError):
    """The homoclinic orbit (or its codimension-two point) was not found; the message says why."""


#: What a trial of the loop may raise without ending the search: no saddle there, or an integration that fails.
_FAILURES = (HomoclinicError, EvaluationFailed, OrbitError)


def _states(system: System, y0: np.ndarray, times: np.ndarray, *, rtol: float, atol: float) -> np.ndarray:
    """The states (len(times), 2n) at ``times`` from y0 at times[0].

    The paper's chain (:class:`~cosserat_chain.systems.chain.ChainSystem`, whose flow SciPy would integrate from
    Python forces) goes through :meth:`~cosserat_chain.numerics.periodic.PeriodicOrbit.trajectory`, the public
    door to the orbits' compiled DOP853 (same state layout: free coordinates, then their velocities): 20-40 times
    faster at N = 1. Every other system goes through :func:`~cosserat_chain.numerics.shooting.states`.
    """
    from ..systems.chain import ChainSystem

    if not isinstance(system, ChainSystem):
        return states(system, y0, times, rtol=rtol, atol=atol)
    chain, n = system.chain, system.size
    carrier = PeriodicOrbit(
        chain, system.model.name, system.parameter("M"), 1, system.particle, math.nan,
        unpack(chain, y0[:n]), unpack(chain, y0[n:]), np.empty(0), math.nan, 0,
    )  # fmt: skip
    x, v = carrier.trajectory(np.asarray(times[1:], dtype=float) - times[0], rtol=rtol, atol=atol)
    later = [np.concatenate([pack(chain, a), pack(chain, b)]) for a, b in zip(x, v)]
    return np.vstack([np.asarray(y0, dtype=float)[None, :], *later]) if later else np.asarray(y0, dtype=float)[None, :]


@dataclass(frozen=True)
class Rest:
    """An equilibrium with its leaving direction: the saddle (or fold) an end's orbit leaves and returns to.

    Attributes
    ----------
    system : System
        At the parameters of this equilibrium.
    q : ndarray (n,)
    leaving : ndarray (2n,)
        Unit right eigenvector of the eigenvalue ``rate``, its winding angle growing.
    normal : ndarray (2n,)
        Unit left eigenvector of ``rate``: normal to the invariant subspace of all other eigenvalues.
    rate : float
        The leaving eigenvalue: > 0 at a saddle, 0 at a fold.
    decay : float
        -Re of the leading stable eigenvalue (> 0).
    eigenvalues : ndarray (2n,) complex
    others : ndarray (2n, m - 1)
        Unit right eigenvectors of the saddle's other unstable eigenvalues (real, each with its
        first sizeable component > 0); none (m = 1) at a fold or a saddle with one.
    normals : ndarray (2n, m)
        An orthonormal basis of the left unstable eigenspace, normal to the stable eigenspace (``normal``
        alone where m = 1): the end condition (H1) asks all of them.
    """

    system: System
    q: np.ndarray
    leaving: np.ndarray
    normal: np.ndarray
    rate: float
    decay: float
    eigenvalues: np.ndarray
    others: np.ndarray | None = None
    normals: np.ndarray | None = None

    def __post_init__(self):
        if self.others is None:
            object.__setattr__(self, "others", np.zeros((self.leaving.size, 0)))
        if self.normals is None:
            object.__setattr__(self, "normals", self.normal[:, None])

    def start(self, eps0: float, direction: np.ndarray | None = None) -> np.ndarray:
        """y(0) of (H0): eps0 along the leaving direction, tilted by ``direction`` (m - 1) into the other unstable ones."""
        u = self.leaving if direction is None or not direction.size else self.leaving + self.others @ direction
        return self.y + eps0 * u / np.linalg.norm(u)

    @property
    def y(self) -> np.ndarray:
        """The state (q, 0) (2n,)."""
        return np.concatenate([self.q, np.zeros_like(self.q)])


def dynamics_matrix(system: System, q: np.ndarray) -> np.ndarray:
    """The Jacobian of the first-order field at rest, [[0, I], [M^-1 dF/dq, -M^-1 C]] (2n, 2n)."""
    n = system.size
    inverse = 1.0 / system.mass()
    a = np.zeros((2 * n, 2 * n))
    a[:n, n:] = np.eye(n)
    a[n:, :n] = inverse[:, None] * system.force_jacobian(q).toarray()
    a[n:, n:] = -np.diag(system.damping() * inverse)
    return a


def rest(system: System, q: np.ndarray, winding: int, *, fold: bool = False, toward: np.ndarray | None = None) -> Rest:
    """The equilibrium ``q`` of ``system`` with its leaving direction (:class:`Rest`).

    ``fold``: the leaving eigenvalue is the one nearest 0 (a fold's centre direction), and all
    others must be stable. Else the leaving eigenvalue is the largest real one; a saddle may have
    further real unstable eigenvalues (the in-phase saddle of two coupled pendula has the
    anti-phase one too), which the loop's start may tilt into (:class:`Rest` ``others``).
    ``toward`` (2n,): the leaving eigenvalue is instead the real unstable one whose eigenvector
    lies nearest that direction, oriented along it (a loop that leaves along a weaker unstable
    direction, as most orbits of a saddle's unstable manifold do, then has a small tilt).

    Raises
    ------
    HomoclinicError
        If the leaving eigenvalue is complex, another unstable one is complex or on the imaginary
        axis, or a fold has more than one centre direction.
    """
    a = dynamics_matrix(system, q)
    eig, right = np.linalg.eig(a)
    scale = max(1.0, float(np.max(np.abs(eig))))
    i = int(np.argmin(np.abs(eig))) if fold else int(np.argmax(eig.real))
    if toward is not None and not fold:
        real = [j for j in range(eig.size) if eig[j].real > 1e-9 * scale and abs(eig[j].imag) <= REAL_TOL * scale]
        i = max(real, key=lambda j: abs(right[:, j].real @ toward) / np.linalg.norm(right[:, j].real), default=i)
    rate = eig[i]
    if not fold and rate.real <= 1e-9 * scale:
        raise HomoclinicError(f"the equilibrium is not a saddle: its eigenvalues all have Re <= 0 (largest {rate:.6g})")
    if abs(rate.imag) > REAL_TOL * scale:
        raise HomoclinicError(f"the leaving eigenvalue {rate:.6g} of the equilibrium is complex: no single leaving direction")
    rest_of = np.delete(np.arange(eig.size), i)
    others = eig[rest_of]
    near_axis = np.abs(others.real) <= 1e-9 * scale
    unstable = rest_of[others.real > 1e-9 * scale]
    if fold or np.any(near_axis) or np.any(np.abs(eig[unstable].imag) > REAL_TOL * scale):
        if np.max(others.real) >= -1e-9 * scale:
            count = int(np.sum(eig.real > -1e-9 * scale))
            raise HomoclinicError(
                f"the equilibrium has {count} eigenvalues with Re >= 0 ({', '.join(f'{e:.4g}' for e in eig[eig.real > -1e-9 * scale])}): "
                "only a saddle with real unstable eigenvalues off the imaginary axis (or a fold with one centre direction) is supported"
            )
    v = right[:, i].real
    v /= np.linalg.norm(v)
    if (v[winding] < 0) if toward is None else (v @ toward < 0):
        v = -v
    left_eig, left = np.linalg.eig(a.T)
    w = left[:, int(np.argmin(np.abs(left_eig - rate)))].real
    w /= np.linalg.norm(w)
    if w @ v < 0:
        w = -w
    extra = np.zeros((v.size, unstable.size))
    lefts = [w]
    for column, j in enumerate(unstable):
        u = right[:, j].real / np.linalg.norm(right[:, j].real)
        # A sign fixed by the vector itself, so that the tilt means the same at neighbouring parameters.
        first = int(np.flatnonzero(np.abs(u) > 1e-3 * np.max(np.abs(u)))[0])
        extra[:, column] = u if u[first] > 0 else -u
        lefts.append(left[:, int(np.argmin(np.abs(left_eig - eig[j])))].real)
    normals = np.linalg.qr(np.column_stack(lefts))[0] if unstable.size else w[:, None]
    stable = others.real[others.real < 0]
    return Rest(system, np.array(q, dtype=float), v, w, float(rate.real), float(-np.max(stable)), eig, extra, normals)


@dataclass
class HomoclinicOrbit:
    """A solved homoclinic end (see the module docstring, (H0)-(H2)).

    Attributes
    ----------
    parameter : str
        The parameter solved for (``M`` on the chain).
    value : float
        Its value at the homoclinic orbit: M_h.
    accuracy : float
        Estimated error of ``value``: the largest of the difference between the last two
        rungs of the eps ladder, the last Newton step and 100 RTOL max(|value|, 1) (the
        integrations: the pendulum's ends agree with an independent computation to 1e-13).
    rest : Rest
        The saddle (or, at a codimension-two point, the fold) at ``value``.
    time : float
        T, the length of the truncated interval.
    eps : float
        eps0 = eps1 of the last rung (eps1 only, at a fold: eps0 is :data:`FOLD_EPS0`).
    shift : ndarray (2n,)
        2 pi k: the shifted saddle is rest.y + shift.
    ladder : list of (eps, value)
        The value at each rung.
    iterations : int
        Newton iterations of the last rung.
    direction : ndarray (m - 1,)
        The start's tilt into the saddle's other unstable directions (:meth:`Rest.start`; empty where it has one).
    """

    parameter: str
    value: float
    accuracy: float
    rest: Rest
    time: float
    eps: float
    shift: np.ndarray
    ladder: list[tuple[float, float, float]] = field(default_factory=list)
    iterations: int = 0
    direction: np.ndarray = field(default_factory=lambda: np.zeros(0))

    @property
    def system(self) -> System:
        return self.rest.system

    @property
    def start(self) -> np.ndarray:
        """y(0) (2n,)."""
        eps0 = FOLD_EPS0 if abs(self.rest.rate) < 1e-6 else self.eps
        return self.rest.start(eps0, self.direction)

    def trajectory(self, times: np.ndarray) -> np.ndarray:
        """States (len(times), 2n) of the truncated orbit at ``times`` in [0, T]."""
        return _states(self.system, self.start, np.asarray(times, dtype=float), rtol=RTOL, atol=ATOL)

    def as_dict(self) -> dict:
        return {
            "parameter": self.parameter,
            "value": float(self.value),
            "accuracy": float(self.accuracy),
            "method": "solved",
            "saddle_eigenvalue": self.rest.rate,
            "stable_decay": self.rest.decay,
            "time": float(self.time),
            "eps": float(self.eps),
            "ladder": [[float(x) for x in rung] for rung in self.ladder],
            "unstable_directions": 1 + int(self.rest.others.shape[1]),
        }


class _Equilibria:
    """Equilibria of ``system`` at values of ``parameter``, each solved by Newton from the nearest one known."""

    def __init__(self, system: System, parameter: str, q0: np.ndarray, winding: int, toward: np.ndarray | None = None):
        self.system, self.parameter, self.winding, self.toward = system, parameter, winding, toward
        self.known: dict[float, np.ndarray] = {float(system.parameter(parameter)): np.asarray(q0, dtype=float)}

    def __call__(self, value: float, depth: int = 0) -> Rest:
        nearest = min(self.known, key=lambda v: abs(v - value))
        system = self.system.with_parameters(**{self.parameter: float(value)})
        start = self.known[nearest]
        try:
            found = find_equilibrium(system, start, tol=1e-13, descent=False)
            # Newton from too far lands on the node or on another saddle: take it only near the one it started from.
            if np.max(np.abs(found.q - start)) > JUMP:
                raise EquilibriumNotFound("jumped")
            saddle = rest(system, found.q, self.winding, toward=self.toward)
        except (EquilibriumNotFound, HomoclinicError) as err:
            if value == nearest:
                raise
            if depth >= 12:
                raise HomoclinicError(
                    f"the saddle was lost on the way from {self.parameter} = {nearest:.12g} to {value:.12g} ({err})"
                ) from None
            self(0.5 * (nearest + value), depth + 1)
            return self(value, depth + 1)
        self.known[float(value)] = found.q
        return saddle


class _Folds:
    """The fold of the static branch in ``moment`` at values of ``parameter``: F(q; M) = 0, J(q) v = 0, |v| = 1
    by Newton on (q, v, M), each from the nearest one known (second derivatives by differences of J)."""

    def __init__(self, system: System, parameter: str, moment: str, q0: np.ndarray, winding: int):
        self.system, self.parameter, self.moment, self.winding = system, parameter, moment, winding
        jac = system.force_jacobian(q0).toarray()
        _, _, vt = np.linalg.svd(jac)
        self.known: dict[float, tuple[np.ndarray, np.ndarray, float]] = {
            float(system.parameter(parameter)): (np.asarray(q0, dtype=float), vt[-1], system.parameter(moment))
        }

    def solve(self, value: float) -> tuple[System, np.ndarray]:
        nearest = min(self.known, key=lambda v: abs(v - value))
        q, v, m = self.known[nearest]
        q, v = q.copy(), v.copy()
        base = self.system.with_parameters(**{self.parameter: float(value)})
        n = q.size
        reference = v.copy()
        for _ in range(MAX_ITERATIONS):
            system = base.with_parameters(**{self.moment: m})
            jac = system.force_jacobian(q).toarray()
            residual = np.concatenate([system.forces(q), jac @ v, [reference @ v - 1.0]])
            if np.max(np.abs(residual)) < 1e-13:
                break
            h = 1e-6 * max(1.0, float(np.max(np.abs(q))))
            second = np.column_stack(
                [(system.force_jacobian(q + h * e).toarray() - system.force_jacobian(q - h * e).toarray()) @ v / (2 * h) for e in np.eye(n)]
            )
            big = np.zeros((2 * n + 1, 2 * n + 1))
            big[:n, :n] = jac
            big[:n, 2 * n] = system.parameter_forces(q, self.moment)
            big[n : 2 * n, :n] = second
            big[n : 2 * n, n : 2 * n] = jac
            big[2 * n, n : 2 * n] = reference
            step = np.linalg.solve(big, -residual)
            q, v, m = q + step[:n], v + step[n : 2 * n], m + step[2 * n]
            if np.max(np.abs(step)) <= 4 * np.finfo(float).eps * (1.0 + float(np.max(np.abs(q)))):
                break  # at round-off: the residual cannot fall further
        else:
            raise HomoclinicError(
                f"Newton on the fold did not converge at {self.parameter} = {value:.12g} (max residual {np.max(np.abs(residual)):.3g})"
            )
        self.known[float(value)] = (q, v, m)
        return system, q

    def __call__(self, value: float) -> Rest:
        system, q = self.solve(value)
        return rest(system, q, self.winding, fold=True)


class _Loop:
    """The residual (H1)-(H2) of the loop from ``rests(p)`` with eps0, eps1, as a function of (p, T) and, where the
    saddle has m > 1 unstable directions, of the start's tilt a (m - 1) into the others: (H1) then holds m equations."""

    def __init__(
        self,
        rests: Callable[[float], Rest],
        shift: np.ndarray,
        eps0: float,
        eps1: float,
        direction: np.ndarray | None = None,
        fixed_time: bool = False,
    ):
        self.rests, self.shift, self.eps0, self.eps1 = rests, shift, eps0, eps1
        self.direction = np.zeros(0) if direction is None else np.asarray(direction, dtype=float)
        self.step: float | None = None
        #: Without (H2): T is given, and the unknowns are p and the tilt (:meth:`solve_at_time`, a saddle-focus's return).
        self.fixed_time = fixed_time

    def end(self, p: float, time: float, direction: np.ndarray) -> tuple[Rest, np.ndarray]:
        r = self.rests(p)
        y = _states(r.system, r.start(self.eps0, direction), np.array([0.0, time]), rtol=RTOL, atol=ATOL)[-1]
        return r, y

    def residual(self, p: float, time: float, direction: np.ndarray | None = None) -> tuple[np.ndarray, Rest, np.ndarray]:
        r, y = self.end(p, time, self.direction if direction is None else direction)
        d = y - r.y - self.shift
        if self.fixed_time:
            return r.normals.T @ d / self.eps1, r, y
        # (H2) as log(|d| / eps1): near the saddle |d| decays exponentially in T, so the log is nearly linear in T.
        return np.concatenate([r.normals.T @ d / self.eps1, [math.log(np.linalg.norm(d) / self.eps1)]]), r, y

    def differences(self, p: float, time: float) -> tuple[np.ndarray, np.ndarray, float]:
        """R at p + h and p - h, with h small enough that R changes by at most FD_CHANGE (the loop is
        sensitive to p like 1 / eps: the N = 1 chain's R moves by 50 per 1e-9 of M at eps = 1e-5)."""
        h = self.step if self.step is not None else FD_STEP * max(1.0, abs(p))
        for _ in range(8):
            plus, _, _ = self.residual(p + h, time)
            minus, _, _ = self.residual(p - h, time)
            change = float(np.max(np.abs(plus - minus))) / 2
            if change <= FD_CHANGE:
                break
            h *= 0.5 * FD_CHANGE / change
        self.step = h
        return plus, minus, h

    def tilt_columns(self, p: float, time: float) -> np.ndarray:
        """dR/da by central differences, each step made small enough that R changes by at most FD_CHANGE."""
        columns = []
        for j in range(self.direction.size):
            h = FD_STEP
            for _ in range(8):
                e = np.zeros(self.direction.size)
                e[j] = h
                plus = self.residual(p, time, self.direction + e)[0]
                minus = self.residual(p, time, self.direction - e)[0]
                change = float(np.max(np.abs(plus - minus))) / 2
                if change <= FD_CHANGE:
                    break
                h *= 0.5 * FD_CHANGE / change
            columns.append((plus - minus) / (2 * h))
        return np.column_stack(columns) if columns else np.zeros((self.direction.size + (1 if self.fixed_time else 2), 0))

    def solve_at_time(self, p: float, time: float, what: str) -> tuple[float, float, int, Rest]:
        """Newton on (p, a) with T fixed: (H1) alone, m equations (the end on the shifted saddle's stable eigenspace),
        damped as :meth:`solve`; returns (p, last |dp|, iterations, rest). The tilt found is left in ``direction``."""
        p, _, moved, iteration, r, _ = self._newton(p, time, what)
        return p, moved, iteration, r

    def solve(self, p: float, time: float, what: str) -> tuple[float, float, float, int, Rest, float]:
        """Newton on (p, T, a); returns (p, T, last |dp|, iterations, rest, the rate at which |d| falls at T).
        The tilt a found is left in ``direction``."""
        p, time, moved, iteration, r, y = self._newton(p, time, what)
        d = y - r.y - self.shift
        return p, time, moved, iteration, r, float(-(d @ r.system.vector_field(y)) / (d @ d))

    def _newton(self, p: float, time: float, what: str) -> tuple[float, float, float, int, Rest, np.ndarray]:
        """Damped Newton on (p, T, a), or on (p, a) where ``fixed_time``; returns (p, T, last |dp|, iterations,
        rest, the loop's end). Each step is halved until max |R| does not grow; the tilt found is left in
        ``direction``."""
        extra = self.rests(p).others.shape[1]
        if self.direction.size != extra:
            self.direction = np.zeros(extra)
        first_tilt = 1 if self.fixed_time else 2
        residual, r, y = self.residual(p, time)
        for iteration in range(1, MAX_ITERATIONS + 1):
            plus, minus, h = self.differences(p, time)
            columns = [(plus - minus) / (2 * h)]
            if not self.fixed_time:
                d = y - r.y - self.shift
                velocity = r.system.vector_field(y)
                columns.append(np.concatenate([r.normals.T @ velocity / self.eps1, [d @ velocity / (d @ d)]]))
            columns.append(self.tilt_columns(p, time))
            try:
                step = np.linalg.solve(np.column_stack(columns), -residual)
            except np.linalg.LinAlgError:
                raise HomoclinicError(f"{what}: singular Newton system at p = {p:.12g}, T = {time:.6g}") from None
            # Keep T positive and the step inside the region where the residual falls.
            scale = 1.0
            for _ in range(20):
                trial_p, trial_a = p + scale * step[0], self.direction + scale * step[first_tilt:]
                trial_t = time if self.fixed_time else time + scale * step[1]
                if self.fixed_time or 0 < trial_t <= 2.0 * time:  # T at most doubled: a longer trial runs far from the loop, at a cost
                    try:
                        trial, r_trial, y_trial = self.residual(trial_p, trial_t, trial_a)
                    except _FAILURES:
                        trial = None
                    if trial is not None and np.max(np.abs(trial)) < max(np.max(np.abs(residual)), 1e-300) * (1 + 1e-9) + 1e-12:
                        break
                scale *= 0.5
            else:
                raise HomoclinicError(
                    f"{what}: Newton made no progress at p = {p:.12g}, T = {time:.6g} (max |R| = {np.max(np.abs(residual)):.3g})"
                )
            moved = abs(trial_p - p)
            p, time, residual, r, y, self.direction = trial_p, trial_t, trial, r_trial, y_trial, trial_a
            if np.max(np.abs(residual)) < RESIDUAL_TOL or moved < 4 * np.finfo(float).eps * max(1.0, abs(p)):
                return p, time, moved, iteration, r, y
        raise HomoclinicError(f"{what}: Newton did not converge in {MAX_ITERATIONS} iterations (max |R| = {np.max(np.abs(residual)):.3g})")


def _sampled(r: Rest, eps0: float, t_max: float, shift: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Times and the distance |y(t) - y_s - shift| along the manifold from y_s + eps0 v, up to t_max."""
    step = SAMPLE / max(1e-3, float(np.max(np.abs(r.eigenvalues))))
    times = np.arange(0.0, t_max + step, step)
    ys = _states(r.system, r.y + eps0 * r.leaving, times, rtol=RTOL, atol=ATOL)
    return times, np.linalg.norm(ys - r.y - shift, axis=1)


def _turns_over(r: Rest, eps0: float, shift: np.ndarray, winding: int, t_max: float) -> bool:
    """Whether the manifold from y_s + eps0 v passes the shifted saddle's winding angle by OVER_MARGIN
    within t_max (else it falls back: it comes to rest away from the saddle, or runs out of time)."""
    target = r.q[winding] + shift[winding] + np.sign(shift[winding]) * OVER_MARGIN
    chunk = max(20.0 / max(1e-3, float(np.max(np.abs(r.eigenvalues))) ** 0.5), t_max / 20.0)
    y, t = r.y + eps0 * r.leaving, 0.0
    sign = np.sign(shift[winding])
    highest = sign * y[winding]
    n = r.q.size
    while t < t_max:
        times = np.linspace(t, t + chunk, 201)
        ys = _states(r.system, y, times, rtol=1e-10, atol=1e-12)
        angle = sign * ys[:, winding]
        if np.any(angle >= sign * target):
            return True
        highest = max(highest, float(np.max(angle)))
        y, t = ys[-1], t + chunk
        # Fallen back: a whole turn below the highest point, or at rest away from the shifted saddle.
        if highest - angle[-1] > math.pi:
            return False
        if np.max(np.abs(y[n:])) < 1e-6 and min(np.linalg.norm(y - r.y - shift), np.linalg.norm(y - r.y)) > 0.1:
            return False
    return False


def _winding(system: System, turns: Mapping[str | int, int] | np.ndarray) -> tuple[np.ndarray, int]:
    k = turns_vector(system, turns)
    if not np.any(k):
        raise ValueError(f"turns must name at least one angle of {system.name} that turns, got {turns!r}")
    return np.concatenate([2 * np.pi * k, np.zeros(system.size)]), int(np.flatnonzero(k)[0])


def _solve_ladder(
    loop_for: Callable[[float], _Loop],
    parameter: str,
    p: float,
    time: float,
    rate: float,
    decay: float,
    ladder: Sequence[float],
    what: str,
    direction: np.ndarray | None = None,
) -> tuple[float, float, float, list[tuple[float, float, float]], int, Rest, float, np.ndarray]:
    """Newton on every rung of ``ladder`` from the one before (the start's tilt too, where the saddle has several
    unstable directions); T grows by log(ratio) (1/rate + 1/approach).

    A rung that fails after three have converged ends the ladder there (the loop's sensitivity to p grows
    like 1 / eps times e^(rate T): on the N = 2 chain near its fold the differences in p reach round-off at
    eps = 1e-6). The accuracy is the difference between the last two rungs that converged, or where larger the last
    one's error by Richardson's estimate from the last three. ``direction`` is the first rung's tilt (default none);
    a rung Newton misses from a tilted start (a saddle with several unstable directions) before three have
    converged is approached through rungs halfway in log eps (at most SPLITS).
    """
    values: list[tuple[float, float, float]] = []
    previous_eps = None
    moved = iterations = 0
    r = None
    approach = decay
    direction = solved = np.zeros(0) if direction is None else np.asarray(direction, dtype=float)
    tilts: list[np.ndarray] = []
    pending, splits = list(ladder), 0
    while pending:
        eps = pending.pop(0)
        loop = loop_for(eps)
        start = (p, time, direction, approach)
        if previous_eps is not None:
            # Leaving takes log(ratio) / rate longer (nothing at a fold, where eps0 stays), arriving log(ratio) / approach;
            # with several unstable directions, the start is the last one's taken back along the saddle's linear flow.
            if direction.size and r is not None and loop.eps0 < previous_eps:
                leaving, direction = _taken_back(r, previous_eps, loop.eps0, direction)
            else:
                leaving = math.log(previous_eps / loop.eps0) / rate if rate > 1e-6 and loop.eps0 < previous_eps else 0.0
            time += leaving + math.log(previous_eps / eps) / max(approach, 1e-6)
            p = _extrapolated(values, eps, p)
            if len(tilts) >= 2 and np.all(tilts[-1] * tilts[-2] > 0):
                # The tilt of the last two rungs as a power of eps (where its components keep their signs): the loop is
                # so sensitive to it that the linear flow's prediction (1 % off at eps = 0.04) leaves Newton's reach.
                exponent = math.log(eps / values[-1][0]) / math.log(values[-1][0] / values[-2][0])
                direction = tilts[-1] * (tilts[-1] / tilts[-2]) ** exponent
        loop.direction = direction
        try:
            p, time, moved, iterations, r, approach = loop.solve(p, time, f"{what} (eps = {eps:g})")
            direction = solved = loop.direction
            tilts.append(direction)
        except HomoclinicError:
            p, time, direction, approach = start
            if direction.size and previous_eps is not None and splits < SPLITS:
                # A tilted start: the rung halfway (in log eps) first, its solution a nearer start for this one.
                splits += 1
                pending[:0] = [math.sqrt(previous_eps * eps), eps]
                continue
            if len(values) < 3:
                raise
            p, time, direction = values[-1][1], values[-1][2], solved
            break
        values.append((eps, p, time))
        previous_eps = eps
    spread = abs(values[-1][1] - values[-2][1]) if len(values) > 1 else math.inf
    accuracy = max(spread, _richardson(values), moved, 100.0 * RTOL * max(1.0, abs(p)))
    return p, time, accuracy, values, iterations, r, spread, direction


def _focus(r: Rest) -> bool:
    """Whether the saddle's leading stable eigenvalue is complex (a saddle-focus on the stable side): the loop comes
    back spiralling, |y(t) - y_s - 2 pi k| oscillates under its envelope, and (H2) has several roots in T."""
    eig = r.eigenvalues
    scale = max(1.0, float(np.max(np.abs(eig))))
    stable = eig[eig.real < -1e-9 * scale]
    if not stable.size:
        return False
    lead = stable[int(np.argmax(stable.real))]
    return bool(abs(lead.imag) > REAL_TOL * scale)


def _solve_focus_ladder(
    loop_for: Callable[[float], _Loop], p: float, time: float, r: Rest, ladder: Sequence[float], what: str, direction: np.ndarray
) -> tuple[float, float, float, list[tuple[float, float, float]], int, Rest, np.ndarray]:
    """Newton on every rung of ``ladder`` with T fixed (:meth:`_Loop.solve_at_time`: (H0), (H1), no (H2)), for a loop
    that returns to a saddle-focus. Each rung's T is the last one's plus the time the saddle's linear flow takes to
    bring the start from the last eps0 to this one (:func:`_taken_back`) and log(ratio) / decay for the arrival, so that
    the end lies about eps from the shifted saddle, where the linear end condition errs by O(eps^2) in p; p starts from
    the last rungs' extrapolation (:func:`_extrapolated`). A rung that fails after three have converged ends the ladder;
    the accuracy is as :func:`_solve_ladder`'s."""
    values: list[tuple[float, float, float]] = []
    previous_eps, moved, iterations = None, 0.0, 0
    direction = np.asarray(direction, dtype=float)
    for eps in ladder:
        loop = loop_for(eps)
        if previous_eps is not None:
            if direction.size:
                leaving, direction = _taken_back(r, previous_eps, eps, direction)
            else:
                leaving = math.log(previous_eps / eps) / r.rate
            time += leaving + math.log(previous_eps / eps) / r.decay
            p = _extrapolated(values, eps, p)
        loop.direction = direction
        try:
            p, moved, iterations, r = loop.solve_at_time(p, time, f"{what} (eps = {eps:g})")
        except HomoclinicError:
            if len(values) < 3:
                raise
            p, time = values[-1][1], values[-1][2]
            break
        direction = loop.direction
        values.append((eps, p, time))
        previous_eps = eps
    spread = abs(values[-1][1] - values[-2][1]) if len(values) > 1 else math.inf
    accuracy = max(spread, _richardson(values), moved, 100.0 * RTOL * max(1.0, abs(p)))
    return p, time, accuracy, values, iterations, r, direction


def _richardson(values: Sequence[tuple[float, float, float]]) -> float:
    """The last rung's error where p = p* + c eps^k, k from the last three rungs: the last change over (ratio^k - 1). It
    exceeds the last change where the rungs are close (the ones :func:`homoclinic_from_orbit` adds) and k is small; 0
    where fewer than three rungs or their changes differ in sign."""
    if len(values) < 3:
        return 0.0
    (e0, p0, _), (e1, p1, _), (e2, p2, _) = values[-3:]
    before, after = p0 - p1, p1 - p2
    if before * after <= 0 or e0 <= e1 or e1 <= e2:
        return 0.0
    # At most the boundary conditions' order 2: rungs close together (a factor 1.15) overstate a measured order.
    order = min(max(math.log(abs(before / after)) / math.log(e0 / e1), 0.5), 2.0)
    return abs(after) / ((e1 / e2) ** order - 1.0)


def _extrapolated(values: Sequence[tuple[float, float, float]], eps: float, p: float) -> float:
    """The rung at ``eps``'s first p: the last rungs' values (eps, p, T) extrapolated by p = p* + c eps^k (k from the last
    three, else 2, the order of the linear boundary conditions' error, kept within [1, 4]); ``p`` where fewer than two."""
    if len(values) < 2:
        return p
    (e0, p0, _), (e1, p1, _) = values[-2], values[-1]
    order = 2.0
    if len(values) >= 3 and e0 != e1:
        before, after = values[-3][1] - p0, p0 - p1
        if before * after > 0 and abs(after) > 0:
            order = min(4.0, max(1.0, math.log(abs(before / after)) / math.log(values[-3][0] / e0)))
    denominator = e1**order - e0**order
    return p if denominator == 0 else p1 + (p1 - p0) * (eps**order - e1**order) / denominator


def _taken_back(r: Rest, eps_from: float, eps_to: float, direction: np.ndarray) -> tuple[float, np.ndarray]:
    """The time tau and the tilt at which the saddle's linear flow, run backwards from the start at distance
    ``eps_from`` with tilt ``direction``, reaches the distance ``eps_to``: each unstable component shrinks at its own
    rate, so the tilt into the weaker directions grows (the loop's start at the smaller distance)."""
    basis = np.column_stack([r.leaving, r.others])
    matrix = dynamics_matrix(r.system, r.q)
    rates = np.einsum("ij,ij->j", basis, matrix @ basis)  # unit eigenvectors: their Rayleigh quotients
    c = np.concatenate([[1.0], direction])
    c *= eps_from / np.linalg.norm(basis @ c)

    def excess(tau: float) -> float:
        return float(np.linalg.norm(basis @ (c * np.exp(-rates * tau)))) - eps_to

    upper = math.log(eps_from / eps_to) / float(np.min(rates))
    while excess(upper) > 0:
        upper *= 2.0
    tau = brentq(excess, 0.0, upper, xtol=1e-12)
    back = c * np.exp(-rates * tau)
    return tau, back[1:] / back[0]


def _first_time(r: Rest, eps0: float, eps1: float, shift: np.ndarray, t_max: float) -> tuple[float, float]:
    """The first time the manifold from y_s + eps0 v comes within eps1 of the shifted saddle (else the time of its
    closest approach), and that closest distance."""
    times, distance = _sampled(r, eps0, t_max, shift)
    closest = float(np.min(distance))
    inside = np.flatnonzero(distance <= eps1)
    if inside.size:
        i = int(inside[0])
        if i == 0:
            return float(times[0]), closest
        a, b = distance[i - 1], distance[i]
        return float(times[i - 1] + (times[i] - times[i - 1]) * (a - eps1) / (a - b)), closest
    return float(times[int(np.argmin(distance))]), closest


def _bracketed(fate: Callable[[float], bool], low: float, high: float, parameter: str) -> tuple[float, float]:
    """Bisection of ``fate`` (True: over) between ``low`` and ``high`` to BISECTION_RTOL; returns (over, back) ends."""
    over_low, over_high = fate(low), fate(high)
    if over_low == over_high:
        raise HomoclinicError(
            f"the saddle's unstable manifold {'turns over' if over_low else 'falls back'} at both ends of the bracket "
            f"{parameter} in [{low:.10g}, {high:.10g}]: no homoclinic end between them (widen the bracket)"
        )
    over, back = (low, high) if over_low else (high, low)
    while abs(over - back) > BISECTION_RTOL * max(abs(over), abs(back), 1e-300):
        middle = 0.5 * (over + back)
        if fate(middle):
            over = middle
        else:
            back = middle
    return over, back


def _t_max(r: Rest, t_max: float | None, eps0: float) -> float:
    if t_max is not None:
        return float(t_max)
    # Leaving eps0 (a few e-foldings of the saddle's rate; at a fold, where the rate is 0, the quadratic drift
    # takes ~ 1 / (eps0 |lambda|max)), the passage near the shifted saddle, and the turn in between.
    fast = float(np.max(np.abs(r.eigenvalues)))
    leaving = 20.0 / r.rate if r.rate > 1e-6 else 20.0 / (eps0 * fast)
    return leaving + 20.0 / r.decay + 200.0 / fast


@one_blas_thread
def homoclinic_end(
    system: System,
    saddle: np.ndarray,
    *,
    turns: Mapping[str | int, int] | np.ndarray,
    bracket: tuple[float, float],
    parameter: str = "M",
    ladder: Sequence[float] = EPS_LADDER,
    t_max: float | None = None,
) -> HomoclinicOrbit:
    """The orbit homoclinic to the saddle that leaves it and returns shifted by 2 pi ``turns``: (H0)-(H2).

    Parameters
    ----------
    system : System
        Any system (:mod:`cosserat_chain.systems`); its value of ``parameter`` is where ``saddle`` holds.
    saddle : ndarray (n,)
        The saddle's coordinates at that value (or near them: Newton corrects them).
    turns : mapping name-or-index -> int, or ndarray (n,)
        The turns of the angles along the loop (``{"phi_0": 1}``).
    bracket : (float, float)
        Values of ``parameter`` between which the saddle's unstable manifold goes from falling
        back to turning over: the homoclinic end lies between them (the saddle is followed to both).
    parameter : str
        The parameter solved for.
    ladder : sequence of float
        eps0 = eps1 of the boundary conditions, solved in turn (at least two: their last two
        values give the accuracy).
    t_max : float, optional
        Longest integration of the manifold while bracketing (default from the saddle's eigenvalues).

    Returns
    -------
    HomoclinicOrbit

    Raises
    ------
    ValueError
        For bad input (turns, ladder, bracket).
    HomoclinicError
        If the saddle has more than one unstable direction, the bracket holds no end, or Newton fails.
    """
    shift, winding = _winding(system, turns)
    ladder = _check_ladder(ladder)
    low, high = (float(b) for b in bracket)
    if not (math.isfinite(low) and math.isfinite(high) and low != high):
        raise ValueError(f"bracket must be two different finite values of {parameter}, got {bracket!r}")
    rests = _Equilibria(system, parameter, system.check_state(saddle, "saddle"), winding)
    horizon = _t_max(rests(float(system.parameter(parameter))), t_max, ladder[0])
    try:
        return _end_in_bracket(rests, shift, winding, (low, high), parameter, ladder, horizon)
    except (EvaluationFailed, OrbitError) as err:
        # An integration of the manifold that fails (a weakly damped chain's at max_steps) ends the search
        # as any other failure does: no loop found, with the reason.
        raise HomoclinicError(f"the homoclinic orbit in {parameter} in [{low:.10g}, {high:.10g}] was not found: {err}") from err


def _end_in_bracket(
    rests: _Equilibria,
    shift: np.ndarray,
    winding: int,
    bracket: tuple[float, float],
    parameter: str,
    ladder: Sequence[float],
    horizon: float,
) -> HomoclinicOrbit:
    """Bisection on the manifold's fate in ``bracket``, then Newton down the ladder from the bracket's middle."""
    over, back = _bracketed(lambda p: _turns_over(rests(p), ladder[0], shift, winding, horizon), *bracket, parameter)
    r = rests(over)
    time, closest = _first_time(r, ladder[0], ladder[0], shift, horizon)
    if closest > APPROACH_FACTOR * ladder[0]:
        raise HomoclinicError(
            f"the saddle's unstable manifold changes fate at {parameter} = {0.5 * (over + back):.10g} without coming near the "
            f"shifted saddle (closest {closest:.3g}): the boundary it crosses there is not the saddle's stable manifold (an "
            "unstable orbit's, say), so the rotation does not end at a loop through this saddle in the bracket"
        )

    def loop_for(eps: float) -> _Loop:
        return _Loop(rests, shift, eps, eps)

    p, time, accuracy, values, iterations, r, _, direction = _solve_ladder(
        loop_for, parameter, 0.5 * (over + back), time, r.rate, r.decay, ladder, "homoclinic end"
    )
    return HomoclinicOrbit(parameter, p, accuracy, r, time, values[-1][0], shift, values, iterations, direction)


@one_blas_thread
def homoclinic_from_orbit(
    orbit,
    *,
    turns: Mapping[str | int, int] | np.ndarray,
    parameter: str,
    value: float | None = None,
    ladder: Sequence[float] = EPS_LADDER,
) -> HomoclinicOrbit:
    """The homoclinic end a long-period orbit is close to: (H0)-(H2) started from the loop the orbit nearly is.

    The saddle is the equilibrium Newton reaches from the orbit's slowest point, the one the orbit lingers at
    (whichever branch it lies on, and with as many real unstable directions as it has: an unequal pendulum pair's
    in-phase rotation ends at the saddle with both pendula up, not at the static branch's saddle past the fold). Along
    the orbit from that point, the first guess of T is the time from leaving the distance eps0 of the saddle to
    coming within eps1 of the shifted saddle, and the start's tilt is that of the leaving point's components along the
    saddle's unstable eigenvectors; the parameter starts at ``value`` (the fit of the period's growth) else the
    orbit's. Newton then runs down the ladder as in :func:`homoclinic_end`, the saddle followed in the parameter.

    Parameters
    ----------
    orbit : Orbit
        A periodic orbit of a system (:class:`~cosserat_chain.numerics.shooting.Orbit`) near its homoclinic end: it
        passes the saddle within FIRST_RUNG_MAX / ORBIT_NEAR (a first rung ORBIT_NEAR times that distance is added
        where the ladder's first is smaller).
    turns : mapping name-or-index -> int, or ndarray (n,)
        The turns of the angles along the loop: the orbit's over one period.
    parameter : str
        The parameter solved for.
    value : float, optional
        Where Newton starts in ``parameter`` (default the orbit's value).
    ladder : sequence of float
        eps0 = eps1 of the boundary conditions, as in :func:`homoclinic_end`.

    Returns
    -------
    HomoclinicOrbit

    Raises
    ------
    ValueError
        For bad input (turns, ladder, value).
    HomoclinicError
        If the orbit's slowest point leads to no saddle with real unstable eigenvalues, the orbit does not pass it
        close enough, or Newton fails.
    """
    system = orbit.system
    shift, winding = _winding(system, turns)
    ladder = _check_ladder(ladder)
    start = float(system.parameter(parameter)) if value is None else float(value)
    if not math.isfinite(start):
        raise ValueError(f"value must be a finite number, got {value!r}")
    n = system.size
    times = np.linspace(0.0, float(orbit.period), ORBIT_SAMPLES)
    try:
        path = _states(system, orbit.y0, times, rtol=RTOL, atol=ATOL)
        i = int(np.argmin([np.linalg.norm(system.vector_field(y)) for y in path]))
        slow = path[i]
        try:
            found = find_equilibrium(system, slow[:n], tol=1e-13, descent=False)
        except EquilibriumNotFound as err:
            raise HomoclinicError(f"no equilibrium near the orbit's slowest point ({err})") from None
        if np.max(np.abs(found.q - slow[:n])) > JUMP:
            raise HomoclinicError("Newton from the orbit's slowest point went to an equilibrium the orbit does not pass")
        r = rest(system, found.q, winding)
        # The loop from the slowest point, on the same times: the rest of this period, then its start shifted by the
        # turns (y(t + T) = y(t) + 2 pi k). A whole period integrated from the slowest point would carry its round-off
        # times ||M|| (1e9 on the unequal pairs' last orbits) and miss the shifted saddle by up to 5.8.
        passage = np.concatenate([path[i:], path[1 : i + 1] + shift])
        leaving = np.linalg.norm(passage - r.y, axis=1)
        arriving = np.linalg.norm(passage - r.y - shift, axis=1)
        nearest = max(leaving[0], arriving[-1])
        focus = _focus(r)
        if ORBIT_NEAR * nearest > ladder[0]:
            # A first rung the orbit reaches, where the ladder's first one is too near the saddle for it.
            widest = FOCUS_FIRST_RUNG_MAX if focus else FIRST_RUNG_MAX
            if ORBIT_NEAR * nearest > widest:
                raise HomoclinicError(
                    f"the orbit passes the saddle no nearer than {nearest:.3g}: it is not close enough to its homoclinic "
                    f"loop (at most {widest / ORBIT_NEAR:g})"
                )
            # Rungs at most a factor RUNG_RATIO apart from there to the ladder's first: the loop's sensitivity to p
            # grows like 1 / eps, and a solution at the next rung must lie within Newton's reach of the last one.
            count = math.ceil(math.log(ORBIT_NEAR * nearest / ladder[0]) / math.log(RUNG_RATIO))
            ladder = (*(ladder[0] * (ORBIT_NEAR * nearest / ladder[0]) ** (1 - i / count) for i in range(count)), *ladder)
        out = _crossing(times, leaving, ladder[0], rising=True)
        back = _crossing(times, arriving, ladder[0], rising=False, after=out)
        away = passage[int(np.searchsorted(times, out))] - r.y
        basis = np.column_stack([r.leaving, r.others])
        components = np.linalg.lstsq(basis, away, rcond=None)[0]
        # The loop leaves along the unstable eigenvector the orbit's start has most of (tilted into the others).
        j = int(np.argmax(np.abs(components)))
        toward = basis[:, j] * np.sign(components[j])
        r = rest(system, found.q, winding, toward=toward)
        components = np.linalg.lstsq(np.column_stack([r.leaving, r.others]), away, rcond=None)[0]
        rests = _Equilibria(system, parameter, found.q, winding, toward)

        def loop_for(eps: float) -> _Loop:
            return _Loop(rests, shift, eps, eps, fixed_time=focus)

        tilt = components[1:] / components[0]
        if focus:
            p, time, accuracy, values, iterations, r, direction = _solve_focus_ladder(
                loop_for, start, back - out, r, ladder, "homoclinic end (saddle-focus) from the orbit", tilt
            )
        else:
            p, time, accuracy, values, iterations, r, _, direction = _solve_ladder(
                loop_for, parameter, start, back - out, r.rate, r.decay, ladder, "homoclinic end from the orbit", tilt
            )
    except (EvaluationFailed, OrbitError) as err:
        raise HomoclinicError(
            f"the homoclinic orbit near the orbit at {parameter} = {system.parameter(parameter):.10g} was not found: {err}"
        ) from err
    return HomoclinicOrbit(parameter, p, accuracy, r, time, values[-1][0], shift, values, iterations, direction)


#: The longest-period orbits (a unit of time apart) of a branch :func:`solve_branch_end` starts from in turn.
BRANCH_END_TRIES = 6


def branch_end_orbits(branch) -> list:
    """The orbits of a branch whose period grew to start :func:`homoclinic_from_orbit` from, in turn: its longest ones,
    longest first, at least a unit of time apart, at most :data:`BRANCH_END_TRIES`. The longest ones next to each other
    fail alike (a tilted start's ladder misses the same rung; seed 2's unequal pair from T = 28.6 and 27.6, solved from
    26.5)."""
    orbits: list = []
    for orbit in sorted(branch.orbits, key=lambda o: -o.period):
        if len(orbits) < BRANCH_END_TRIES and all(abs(orbit.period - o.period) >= 1.0 for o in orbits):
            orbits.append(orbit)
    return orbits


def solve_branch_end(branch, *, ladder: Sequence[float] = EPS_LADDER) -> HomoclinicOrbit | None:
    """The homoclinic end of an orbit branch whose period grew (:func:`~cosserat_chain.numerics.shooting.continue_orbits`),
    solved: :func:`homoclinic_from_orbit` from its longest orbits in turn (:func:`branch_end_orbits`, each at its own
    parameter value: a snaking approach's fit is no start), the turns those of the orbits.

    The first solved sets ``branch.end_value``, ``end_uncertainty`` (its accuracy) and ``end_method`` ``solved`` and
    says so in the message; where none is, the branch keeps its fit (``end_method`` ``fitted``) and the message says
    why. A loop that returns to a saddle-focus (a snaking approach: the period grows while the parameter oscillates about
    the end, the folds of cycles accumulating there) is solved with T fixed (:func:`_solve_focus_ladder`).

    Returns
    -------
    HomoclinicOrbit or None
        The solved end, or None where no orbit led to one.
    """
    reasons = []
    for orbit in branch_end_orbits(branch):
        if not np.any(orbit.turns):
            return None
        try:
            end = homoclinic_from_orbit(orbit, turns=orbit.turns, parameter=branch.parameter, ladder=ladder)
        except HomoclinicError as err:
            reasons.append(f"from T = {orbit.period:.6g}: {err}")
            continue
        branch.end_value, branch.end_uncertainty, branch.end_method = end.value, end.accuracy, "solved"
        branch.message = branch.message.split("; the period grows like a homoclinic end's")[0] + (
            f"; homoclinic end {branch.parameter} = {end.value:.12g} +- {end.accuracy:.2g}, solved (a loop through the saddle, "
            f"from the orbit of period {orbit.period:.6g})"
        )
        return end
    if reasons:
        branch.message += f"; the homoclinic end was not solved ({'; '.join(reasons)})"
    return None


def _crossing(times: np.ndarray, distance: np.ndarray, eps: float, *, rising: bool, after: float = -math.inf) -> float:
    """The first time (after ``after``) the sampled ``distance`` rises through (else falls through) ``eps``,
    interpolated in log(distance) (which is nearly linear in time near a saddle)."""
    side = distance >= eps if rising else distance <= eps
    index = np.flatnonzero(side[1:] & ~side[:-1] & (times[1:] > after))
    if not index.size:
        raise HomoclinicError(f"the orbit does not {'leave' if rising else 'come back within'} eps = {eps:g} of the saddle")
    i = int(index[0])
    a, b = math.log(distance[i]), math.log(distance[i + 1])
    return float(times[i] + (times[i + 1] - times[i]) * (math.log(eps) - a) / (b - a))


def _check_ladder(ladder: Sequence[float]) -> tuple[float, ...]:
    values = tuple(float(e) for e in ladder)
    if len(values) < 2 or not all(0 < e < 1 for e in values) or any(b >= a for a, b in zip(values, values[1:])):
        raise ValueError(f"ladder must hold at least two decreasing distances in (0, 1), got {ladder!r}")
    return values


@dataclass
class HomoclinicCurve:
    """The homoclinic end followed in a second parameter.

    Attributes
    ----------
    name : str
        The second parameter.
    values : ndarray
        Its values reached, in order.
    ends : ndarray
        The homoclinic end (the first parameter's value) at each.
    accuracy : ndarray
        Each end's accuracy (:attr:`HomoclinicOrbit.accuracy`).
    orbits : list of HomoclinicOrbit
    complete : bool
        Whether every value was reached; ``message`` says why not.
    message : str
    """

    name: str
    values: np.ndarray
    ends: np.ndarray
    accuracy: np.ndarray
    orbits: list[HomoclinicOrbit]
    complete: bool
    message: str

    def as_dict(self) -> dict:
        return {
            "parameter": self.name,
            "values": self.values.tolist(),
            "ends": self.ends.tolist(),
            "accuracy": self.accuracy.tolist(),
            "complete": self.complete,
            "message": self.message,
        }


@one_blas_thread
def continue_homoclinic(
    orbit: HomoclinicOrbit, name: str, values: Sequence[float], *, ladder: Sequence[float] = EPS_LADDER, t_max: float | None = None
) -> HomoclinicCurve:
    """Follow the homoclinic end ``orbit`` through ``values`` of the parameter ``name``.

    At each value the end is predicted by a secant through the two before (the orbit's own
    value first), bracketed around that prediction by the manifold's fate (the bracket widened
    until the fate changes across it) and solved as :func:`homoclinic_end` does, the saddle
    followed from the value before. Stops where that fails (near the codimension-two point,
    where the saddle's unstable eigenvalue goes to zero; :func:`locate_snic_point`), saying why.

    Raises
    ------
    ValueError
        For an unknown ``name`` or a bad ``ladder``.
    """
    ladder = _check_ladder(ladder)
    system = orbit.system
    first = float(system.parameter(name))
    winding = int(np.flatnonzero(orbit.shift)[0])
    points = [(first, orbit.value)]
    done: list[HomoclinicOrbit] = []
    message = ""
    current = orbit.rest
    for value in (float(v) for v in values):
        v0, p0 = points[-1]
        predicted = p0 if len(points) == 1 else p0 + (value - v0) * (p0 - points[-2][1]) / (v0 - points[-2][0])
        base = current.system.with_parameters(**{name: value})
        rests = _Equilibria(base, orbit.parameter, current.q, winding)
        try:
            horizon = _t_max(rests(float(base.parameter(orbit.parameter))), t_max, ladder[0])
            end = _end_in_bracket(
                rests,
                orbit.shift,
                winding,
                _bracket_near(rests, orbit, predicted, p0, ladder[0], horizon),
                orbit.parameter,
                ladder,
                horizon,
            )
        except _FAILURES as err:
            message = f"stopped before {name} = {value:.10g}: {err}"
            break
        current = end.rest
        points.append((value, end.value))
        done.append(end)
    return HomoclinicCurve(
        name,
        np.array([p[0] for p in points[1:]]),
        np.array([o.value for o in done]),
        np.array([o.accuracy for o in done]),
        done,
        not message,
        message,
    )


def _bracket_near(
    rests: _Equilibria, orbit: HomoclinicOrbit, predicted: float, previous: float, eps: float, horizon: float
) -> tuple[float, float]:
    """A bracket of the end around ``predicted``: from there, steps doubling towards the side the fate points to
    (a manifold that turns over puts the end below, as the moment's; the sign is read from the orbit's own side)."""
    winding = int(np.flatnonzero(orbit.shift)[0])
    # Which way the end lies when the manifold turns over: the previous end's own fate just above and below it.
    for _ in range(40):
        try:
            rests(predicted)
            break
        except HomoclinicError:
            # Predicted past the fold, where the saddle is gone: back towards the previous end.
            predicted = 0.5 * (predicted + previous)
    step = max(0.1 * abs(predicted - previous), 1e-4 * max(abs(previous), 1e-3))
    over_up = _turns_over(rests(predicted + step), eps, orbit.shift, winding, horizon)
    over_down = _turns_over(rests(predicted - step), eps, orbit.shift, winding, horizon)
    if over_up != over_down:
        return predicted - step, predicted + step
    # Both ends agree: the end lies beyond one of them. Over with "over above" (over_up at the true end's upper side)
    # is not known here, so walk both ways at once, doubling, until the fate changes.
    low, high = predicted - step, predicted + step
    for _ in range(BRACKET_DOUBLINGS):
        step *= 2.0
        for is_low in (True, False):
            bound = low if is_low else high
            candidate = bound - step if is_low else bound + step
            fate = None
            for _ in range(20):
                try:
                    fate = _turns_over(rests(candidate), eps, orbit.shift, winding, horizon)
                    break
                except _FAILURES:
                    # No saddle there (past the fold): closer to the last value that had one.
                    candidate = 0.5 * (bound + candidate)
            if fate is None:
                continue
            if fate != over_up:
                return (candidate, low) if is_low else (high, candidate)
            if is_low:
                low = candidate
            else:
                high = candidate
    raise HomoclinicError(f"no change of the manifold's fate found near {orbit.parameter} = {predicted:.10g}")


@dataclass
class SnicPoint:
    """The codimension-two point where the homoclinic end meets the static fold (a non-central saddle-node homoclinic orbit).

    Attributes
    ----------
    name : str
        The second parameter.
    value : float
        Its value there.
    accuracy : float
        Estimated error of ``value`` (as :attr:`HomoclinicOrbit.accuracy`).
    moment : float
        The first parameter there: the fold's, M_c.
    orbit : HomoclinicOrbit
        The loop from the fold (``orbit.rest`` is the fold, ``orbit.parameter`` the second parameter).
    """

    name: str
    value: float
    accuracy: float
    moment: float
    orbit: HomoclinicOrbit

    def as_dict(self) -> dict:
        return {
            "parameter": self.name,
            "value": float(self.value),
            "accuracy": float(self.accuracy),
            "moment": float(self.moment),
            "method": "augmented_system",
        }


def fold_turns_over(
    system: System,
    fold: np.ndarray,
    *,
    turns: Mapping[str | int, int] | np.ndarray,
    name: str,
    moment: str = "M",
    t_max: float | None = None,
) -> bool:
    """Whether the centre manifold of the static fold turns over (a rotation exists at the fold, so the rotating
    orbit ends below it, at a homoclinic loop) rather than falling back into the shifted fold (a SNIC).

    The fold is first solved exactly (F = 0, J v = 0 in (q, v, ``moment``), as :func:`locate_snic_point` does at the
    value of ``name`` the system has), so that a drive a little past the fold, where no equilibrium holds the
    manifold back, cannot make it turn over.

    Raises
    ------
    HomoclinicError
        If Newton on the fold fails or the fold has more than one centre direction.
    """
    shift, winding = _winding(system, turns)
    folds = _Folds(system, name, moment, system.check_state(fold, "fold"), winding)
    r = folds(float(system.parameter(name)))
    return _turns_over(r, FOLD_EPS0, shift, winding, _t_max(r, t_max, FOLD_EPS0))


@one_blas_thread
def locate_snic_point(
    system: System,
    fold: np.ndarray,
    *,
    name: str,
    bracket: tuple[float, float],
    turns: Mapping[str | int, int] | np.ndarray,
    moment: str = "M",
    ladder: Sequence[float] = EPS_LADDER,
    t_max: float | None = None,
) -> SnicPoint:
    """The value of ``name`` where the homoclinic end meets the static fold in ``moment`` (module docstring).

    Parameters
    ----------
    system : System
        Its ``moment`` and ``name`` values at (or near) a fold of the static branch.
    fold : ndarray (n,)
        The fold's coordinates (or near them: Newton on the fold corrects them).
    name : str
        The second parameter (the damping).
    bracket : (float, float)
        Values of ``name`` between which the fold's centre manifold goes from falling back
        (a SNIC: it creeps back into the shifted fold) to turning over (a homoclinic end below M_c).
    turns : mapping or ndarray
        As :func:`homoclinic_end`.
    ladder : sequence of float
        eps1 of the end condition, solved in turn (eps0 is :data:`FOLD_EPS0`).

    Returns
    -------
    SnicPoint

    Raises
    ------
    HomoclinicError
        If the bracket holds no change of fate, or Newton fails.
    """
    shift, winding = _winding(system, turns)
    ladder = _check_ladder(ladder)
    low, high = (float(b) for b in bracket)
    if not (math.isfinite(low) and math.isfinite(high) and low != high):
        raise ValueError(f"bracket must be two different finite values of {name}, got {bracket!r}")
    folds = _Folds(system, name, moment, system.check_state(fold, "fold"), winding)
    first = folds(float(system.parameter(name)))
    horizon = _t_max(first, t_max, FOLD_EPS0)
    over, back = _bracketed(lambda p: _turns_over(folds(p), FOLD_EPS0, shift, winding, horizon), low, high, name)
    r = folds(over)
    time, _ = _first_time(r, FOLD_EPS0, ladder[0], shift, horizon)

    def loop_for(eps: float) -> _Loop:
        return _Loop(folds, shift, FOLD_EPS0, eps)

    p, time, accuracy, values, iterations, r, _, _ = _solve_ladder(
        loop_for, name, 0.5 * (over + back), time, 0.0, r.decay, ladder, "codimension-two point"
    )
    orbit = HomoclinicOrbit(name, p, accuracy, r, time, values[-1][0], shift, values, iterations)
    return SnicPoint(name, p, accuracy, float(r.system.parameter(moment)), orbit)


def _chain_system(params, model, moment: float, particle: int):
    from ..systems.chain import ChainSystem

    return ChainSystem(params, model, M=moment, particle=particle)


def chain_saddle(params, model, moment: float, *, particle: int = 0, fold=None) -> np.ndarray:
    """The free coordinates (n,) of the static branch's saddle at ``moment``: the equilibrium just past the fold,
    where M(phi_0) falls back through ``moment`` (rotation-controlled Newton from the fold outwards).

    Raises
    ------
    HomoclinicError
        If the branch has no fold, or ``moment`` is not below it.
    """

    from .continuation import locate_fold
    from .newton import solve_rotation_controlled

    fold = locate_fold(params, model, particle=particle) if fold is None else fold
    if fold is None:
        raise HomoclinicError(f"the static branch of the {getattr(model, 'name', model)} chain has no fold: no saddle to be homoclinic to")
    if not 0 < moment < fold.moment:
        raise HomoclinicError(f"moment {moment!r} is not between 0 and the fold's M_c = {fold.moment:.12g}: no saddle there")
    cache = {fold.phi0: (fold.x, fold.moment)}

    def solve(phi0: float) -> tuple[np.ndarray, float]:
        nearest = min(cache, key=lambda a: abs(a - phi0))
        x, m = solve_rotation_controlled(params, model, phi0, particle=particle, x0=cache[nearest][0], moment0=cache[nearest][1])
        cache[phi0] = (x, m)
        return x, m

    step, phi0 = 1e-3, fold.phi0
    while solve(phi0 + step)[1] > moment:
        phi0, step = phi0 + step, 2.0 * step
        if step > 4 * np.pi:
            raise HomoclinicError(f"M(phi_0) does not fall to {moment!r} past the fold at phi_0 = {fold.phi0:.6g}")
    angle = brentq(lambda a: solve(a)[1] - moment, phi0, phi0 + step, xtol=1e-14)
    return pack(params, solve(angle)[0])


def chain_homoclinic_end(
    params, model, *, bracket: tuple[float, float], particle: int = 0, fold=None, ladder: Sequence[float] = EPS_LADDER
) -> HomoclinicOrbit:
    """The paper's chain's homoclinic end M_h in ``bracket``: the loaded particle's one turn from the saddle to itself.

    Parameters
    ----------
    params : ChainParams
    model : str or Model
    bracket : (float, float)
        Moments between which the rotation ends (below M_c): the rotating orbit's last moment and a
        moment where the saddle's unstable manifold falls back (the diagram's fit minus a few of its uncertainties).
    particle : int
        The loaded particle.
    fold : Fold, optional
        The static fold (:func:`~cosserat_chain.numerics.continuation.locate_fold`), if known.

    Returns
    -------
    HomoclinicOrbit
        ``value`` is M_h, ``accuracy`` its error estimate.

    Raises
    ------
    HomoclinicError
        As :func:`homoclinic_end`, or when the static branch has no fold below which the bracket lies.
    """
    high = max(float(b) for b in bracket)
    system = _chain_system(params, model, high, particle)
    saddle = chain_saddle(params, model, high, particle=particle, fold=fold)
    return homoclinic_end(system, saddle, turns={f"phi_{particle}": 1}, bracket=bracket, parameter="M", ladder=ladder)


def chain_snic_point(
    params, model, *, name: str, bracket: tuple[float, float], particle: int = 0, fold=None, ladder: Sequence[float] = EPS_LADDER
) -> SnicPoint:
    """The value of the chain's field ``name`` (``gamma_phi``, say) where its homoclinic end meets the static fold.

    Raises
    ------
    HomoclinicError
        As :func:`locate_snic_point`, or when the static branch has no fold.
    """
    from .continuation import locate_fold

    fold = locate_fold(params, model, particle=particle) if fold is None else fold
    if fold is None:
        raise HomoclinicError(f"the static branch of the {getattr(model, 'name', model)} chain has no fold")
    system = _chain_system(params, model, fold.moment, particle)
    return locate_snic_point(system, pack(params, fold.x), name=name, bracket=bracket, turns={f"phi_{particle}": 1}, ladder=ladder)
