"""The exact answer to Fig. 2: compliance, critical moment and the static branch over a full turn.

Contract
--------
:func:`critical_point` computes, for one model and one loaded particle,

* the compliance d phi_0 / dM at M = 0 (the same for every model: they share K at rest);
* the branch traced by pseudo-arclength continuation over one full turn of the
  loaded particle, and on while it stays stable to where the stable branch from rest
  ends, within a budget of ``turns`` turns (a cantilever's branch point lies at
  phi_0 = 1.41 N on the paper's geometry), with the stability of every point and every
  fold it passes, each located to round-off
  (:func:`~cosserat_chain.numerics.continuation.locate_fold`); ``end`` says how the stable
  branch ends ("fold", "branch_point", or "budget" where it was still stable: not
  ``complete``), ``onset_particle`` which particle turns there (a pinned end can turn
  before the loaded particle; the trace stops once another particle has wound a full
  turn ahead of it, Branch.stop "wound");
* M_c, the onset of rotation under a slowly rising load: the highest end of a stable
  part of the branch, the largest maximum of M approached stably where no stable part
  ends higher at a branch point (of its traced part if
  the point budget ran out or the corrector stalled first: ``complete`` is then False
  and the command line exits with ``max_steps`` or ``step_too_small``), and the first
  fold, where the stable branch from rest ends. A branch can have several maxima (N = 10,
  a = 0.3, b = 0.1, E1 = 2, E2 = 0.3: a first one near phi_0 = 1.0, the largest near
  2.04): at the first the chain snaps through to a static state further along, and
  only above M_c does it rotate. For the paper's chain both are the same fold. None
  for a model without a fold (the linear model). A maximum approached on an unstable
  part is not M_c: the stable part before it ended at a branch point, at a lower moment,
  and the chain rotates above that (N = 2, a = 0.332, b = 0.492, E1 = 1.64, E2 = 2.65:
  a branch point at M = 2.8474 before the maximum at 2.8634; a relaxation at 1.001 times
  the branch point's moment rotates, tested).
* where the stable branch from rest ends at a branch point instead (K turns singular
  while M still rises: the cantilever of the paper's geometry, nonlinear model, at
  M = 0.08198 before its fold at 0.08375), M_c is that branch point's moment
  (``onset`` "branch_point"): the chain leaves the branch there, and for the cantilever
  a relaxation just above it rotates (tested). Where a stable crossing branch carries the
  chain on instead (a relaxation at :data:`CROSSING_EXCESS` times the branch point's moment,
  from its state nudged along K's lowest mode, comes to rest: a supercritical pitchfork, as
  on the symmetric clamped chain N = 2, a = 0.4444, b = 0.6084, h = 1.4673, E1 = 1.2228,
  E2 = 1.6538, whose branch point at M = 1.4245 is passed at rest up to 2.55), M_c is the
  first fold of the branch it rests on, followed with the angle held
  (:func:`crossing_fold`; ``onset`` "crossing_fold", ``crossing``: M = 2.6041 there, and
  a relaxation at 0.99 of it rests, at 1.01 rotates: tests/test_audit_twelfth_statics.py).
  Where that branch cannot be followed to a fold, M_c stays the branch point's moment, a
  lower bound, and ``accurate`` is False.
* where the trace is cut short past the fold that ends the stable branch from rest (the corrector stalls, the point
  budget runs out), the traced branch cannot say where the chain goes from that fold: a relaxation just above it decides,
  as past a branch point (:func:`onset_past`, the branch each relaxation rests on followed to its fold, up to
  :data:`MAX_CROSSINGS` of them). N = 10, a = 0.4166, b = 0.2224: the trace stalls past the first fold, M = 0.13239;
  the chain snaps onto a stable state near phi_0 = 1.08 and rotates only above that branch's fold, M_c = 0.371938
  (``onset`` "crossing_fold"; ramped runs rest at 0.99 of it and rotate at 1.01:
  tests/test_critical_past_trace.py). So past the fold of a whole trace too, except where K is near singular at rest
  (below): N = 6, pinned-clamped, h = 1.6, a = 0.69, b = 0.83, E1 = 2.3, E2 = 2.5, the moment on particle 3, folds at
  M = 1.2757 on a branch traced over its whole turn, and the chain snaps onto a branch the trace never meets and rotates
  only above M_c = 8.898910 (tests/test_audit_fourteenth_chain.py). Where such relaxations leave rest just above M_c
  (``onset_checked``), M_c is decided whatever the trace past it: the command line notes the incomplete branch and exits 0.
  Past a fold one relaxation suffices, started on the side its ghost runs to (:func:`ghost_passage`, the fold's normal
  form); where that ghost takes longer to pass than the relaxation may run (N = 1000 on the paper's geometry: 2.8 10^5
  against 20000; its fold's null vector is the long chain's slow bending), or a relaxation neither rests nor rotates,
  nothing is decided: past the fold of a whole trace M_c stays the traced fold without ``onset_checked``; past a branch
  point or a trace cut short it is a lower bound (``crossing_unresolved``).

Where K's softest eigenvalue at rest lies within :data:`CONFIRM_MARGIN` times its
round-off (a long clamped chain: its bending mode's eigenvalue falls like N^-4, within
ten times its round-off from N of about 1500 on the paper's geometry), the folds that decide
M_c (the first fold and every maximum that holds more) are re-solved by another method
(:func:`resolve_fold`): on the rotation-controlled branch, from the traced fold's state, as the
root of dM/dphi_0 within :data:`CONFIRM_PHI0_ATOL` of its angle, and each is ``confirmed``
where that root is a maximum or minimum of M as the traced fold is, at the same moment
(:func:`confirm_folds`). A re-solve costs a few sparse solves near the fold, not a second trace of
the branch. The other folds are not re-solved (``confirmed`` None). A fold the re-solve does not
find is an artefact of round-off (N = 10^4: eleven small folds near phi_0 = 2 pi, within 4e-5 of
M = 0, where dM/dphi_0 has no root of the kind traced, while the first fold agrees to 1e-14):
``accurate`` is False where the onset's fold or the first fold is not confirmed, and the command
line then exits with ``inaccurate``.

Where K is near singular at rest (as above), the end of the turn is not traced once M_c is decided: the turn of
a long clamped chain ends near the chain at rest turned once, where M falls towards the corrector's limit and
K's soft modes are again beyond its rounded entries (N = 10^5's trace crawled there, near phi_0 = 6.267 in the
band form: docs/statics.md). Eq. (2)'s branch is not traced there: from rest to its first fold and one step beyond
it is taken in closed form (below; ``Branch.stop`` "max_folds": the closed form bounds every static state's |M|
by that fold's), with every point's stability computed (N = 10^5's trace had crawled near 1.3 rad). Another model's trace ends once the stable branch from rest has ended at a fold, the loaded particle lies within
:data:`~cosserat_chain.numerics.continuation.END_ANGLE` of the turn and |M| has fallen to
:data:`~cosserat_chain.numerics.continuation.END_MOMENT` of the largest maximum traced ("decided";
``continue_in_moment(decided=True)``, the same M_c and folds as the full turn: tests/test_critical_decided.py).

Where the trace's band factor of K at rest loses the rest response (its compliance more than
:data:`~cosserat_chain.numerics.continuation.APPROACH_RTOL` off the one through K's square root:
the bending modes beyond double precision, N = 3 10^4 and up on the paper's geometry), the trace
starts from the approach from rest
(:func:`~cosserat_chain.numerics.continuation.approach_from_rest`: the branch solved with the angle
held at 2^-12 .. 1 rad, from the rest response), not from rest, where its moments lie below the
corrector's limit (N = 10^5: the trace from rest crawled at M = 1e-14 and turned back at a fold of
round-off). The approach's points are the branch's first (``Branch.approach``).

Eq. (2)'s folds are known in closed form: its static states are (u, v, sin phi) = M c with
c = K^-1 e at rest, so every fold lies at M = +-1 / max_j |c_j|, where the particle of largest
|c_j| passes pi/2. ``critical_point`` takes them there (``confirmation`` "closed form"; one
trace, however near singular K is), with the compliance of the linear model's K at rest, which
every model shares, refined in extended precision
(:func:`~cosserat_chain.numerics.continuation.moment_response`): at N = 10^4 M_c to round-off
where the traced folds were 3.6e-6 off and flagged.

Stability is reported as two things. K's inertia, the *stiffness index* (its negative
eigenvalues: ``stable`` along the branch, ``index_before`` / ``index_after`` of folds and branch
points), is what decides the folds; the *dynamic verdict* comes from the eigenvalues of the
damped first-order system (:func:`~cosserat_chain.numerics.stability.dynamic_stability`), its
*unstable eigenvalues*. ``dynamics_from`` says where the verdict comes from:

* "stiffness index": a conservative model (nonlinear, linear) with positive damping, whose
  unstable eigenvalues are K's negative ones (a theorem the stability tests check against the
  dense eigenvalues): the verdict is K's inertia, not recomputed, and the branch has no Hopf point;
* "eigenvalues": any other model (the sine model, eq. (2)) where the first-order system is
  dense (:data:`~cosserat_chain.numerics.stability.DENSE_LIMIT`, the limit ``states`` uses):
  its eigenvalues at every traced point (for eq. (2), at a point whose free angles are all
  within pi/2 of rest and whose neighbours' too, the theorem below instead, valid at every
  such state: :func:`~cosserat_chain.numerics.stability.sine_theorem_stability`, the same
  verdict without a dense eigenproblem, checked against one at every point by the tests),
  and the branch's Hopf points
  (:func:`~cosserat_chain.numerics.hopf.hopf_points`; N = 2, paper's geometry: phi_0 = 1.6575 and
  2.4380 on the unstable branch, where K keeps one negative eigenvalue and the dynamics have three
  unstable eigenvalues between them);
* "eq. (2) theorem": the sine model beyond the dense limit. On its branch from rest up to M_c every
  |phi_j| < pi/2 (closed form above), and K = K_lin D with D = diag(1, 1, cos phi_j) positive:
  multiplied by D the linearised dynamics are D M q'' + D Gamma q' + D K_lin D q = 0, symmetric
  with positive mass and stiffness and non-negative damping, hence dynamically stable. The
  verdict there is that theorem's; Hopf points are not searched (``hopf`` None: call
  ``hopf_points`` on the branch directly).

The result converts to a JSON-ready dict and to a self-describing xarray Dataset.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, replace
from typing import TYPE_CHECKING

import numpy as np

from ..linalg import smallest_eigenvalue
from ..linalg.threads import one_blas_thread
from ..loads import Loads, moment_load
from ..memory import FLOAT, require
from ..models.base import Model, get_model
from ..numerics.brent import brentq
from ..numerics.continuation import (
    FOLD_TOL,
    Branch,
    BranchPoint,
    Fold,
    continue_in_moment,
    locate_fold,
    moment_response,
    moment_slope,
    rest_resolved,
)
from ..numerics.kit import BranchEnd
from ..numerics.newton import NewtonError, moment_dof, solve_equilibrium, solve_rotation_controlled
from ..numerics.stability import static_stability
from ..params import ChainParams
from ..state import ROW_INDEX, ROWS, column, n_free, unpack
from ..status import Status

if TYPE_CHECKING:  # xarray is imported where a Dataset is built or read: commands without file output start without it
    import xarray as xr

    from ..numerics.hopf import HopfPoint
    from ..numerics.stability import DynamicStability

#: Default point budget of the full-turn branch (N = 1000: about 2600 points).
MAX_POINTS = 5000
#: Bytes of the branch's states kept (``Branch.x``): every point's state up to N of about 10^4 at the
#: default point budget's usual use, and a thinned set on longer chains (every 2^j-th point,
#: ``Branch.state_points``; :func:`~cosserat_chain.numerics.continuation.continue_in_moment`'s
#: ``max_states``), so that the branch's memory grows with N, not with N times its points.
STATE_BYTES = 2**27
#: Values a degree of freedom that :func:`critical_point` holds at its peak beside the branch's kept states
#: (:func:`critical_memory`): a trace's band factors, the rest response through K's square root, the approach's and
#: the re-solves' sparse factors, and bytes it takes whatever N (the first sparse factors' workspace): fitted to the
#: peaks of benchmarks/bench_critical_scaling.py at N = 3 10^4 and 10^5 (nonlinear: 630 and 1643 MiB above the start) ...
TRACE_VALUES = 272
TRACE_BYTES = 140 * 2**20
#: ... and eq. (2)'s closed-form branch's, its SINE_POINTS + 1 states included (139 at N = 10^4, 3 10^4 and 10^5).
SINE_VALUES = 140
#: Default budget in turns of the loaded particle for a branch from rest that stays stable
#: beyond its first turn (a cantilever of the paper's geometry: 1.41 N rad, N <= 71 within 16 turns).
TURNS = 16
#: The folds that decide M_c are re-solved where K's softest eigenvalue at rest is below this many
#: times its round-off (the paper's geometry: 18.5 at N = 1000, 1.17 at N = 2000, below 1 from N = 3000).
CONFIRM_MARGIN = 10.0
#: A traced fold and its re-solve are the same fold where their moments agree to this, relative to
#: the largest |M| of the branch: M_c to seven digits (two traces with other steps agreed on the
#: nonlinear model's folds of N = 1000 to 1e-9, its first fold at N = 10^4 to 1e-10 and two random
#: chains' to 1e-8, where the folds of round-off of N = 10^4 differed by 7e-5 and more) ...
CONFIRM_MOMENT_RTOL = 1e-7
#: ... and their angles phi_0 to this (rad; a simple fold's phi_0 is known to about the square root
#: of its moment's round-off: 3e-7 at N = 10^4). The re-solve looks for the root of dM/dphi_0 within it.
CONFIRM_PHI0_ATOL = 1e-5
#: The re-solve's root of dM/dphi_0 to this (rad): M is stationary there, so M is then known to
#: round-off, and a tighter root costs more solves for nothing.
CONFIRM_PHI0_XTOL = 1e-10
#: The re-solve's brackets, in units of CONFIRM_PHI0_ATOL, each tried where the wider one holds no
#: state on one side: phi_0 can turn back within 1e-5 rad of a fold (two folds of N = 1000 whose
#: phi_0 turns 1e-6 beyond them), and only where a solve fails, never where the slope's signs do
#: not bracket a fold of the kind traced (a narrow bracket would put that test into round-off).
CONFIRM_NARROWING = np.array([1.0, 0.1, 0.01])
#: Most Newton iterations of a re-solve's rotation-controlled solve from the nearest solved angle
#: (it starts within CONFIRM_PHI0_ATOL of a solved state: a few iterations, where more signal a
#: branch the rotation control does not follow there).
CONFIRM_ITERATIONS = 12
#: A branch point that ends the stable branch from rest is tested by a relaxation at this many times its moment,
#: from its state nudged by :data:`CROSSING_NUDGE` along K's lowest mode (each sign): where one comes to rest, a
#: stable crossing branch carries the chain beyond it (:func:`crossing_fold`) ...
CROSSING_EXCESS = 1.001
CROSSING_NUDGE = 1e-3
#: Turns in each of the two windows whose equal mean rates say a relaxation past the point rotates (relax's
#: ``window_turns``): just above a fold every turn passes the fold's ghost, one slow passage a turn, so the rotation
#: repeats turn by turn, and relax's 12 (for rotations that repeat only after 2 or 3 turns) cost four times as much.
CROSSING_WINDOW_TURNS = 3
#: ... which is followed with the loaded particle's angle held, in steps of this (rad), halved where a solve fails, up to
#: :data:`CROSSING_TURN` rad beyond its start, to its first maximum of M (located by Brent's method on dM/dphi_0).
CROSSING_STEP = 0.02
CROSSING_TURN = 2 * math.pi
#: A step whose state changes more than this many times faster per radian than the step before it has left the followed
#: branch (where the branch turns back in phi_0 the held angle's solve lands on another one: the N = 2 graded chain of
#: tests/test_audit_fourteenth_chain.py, whose followed branch ends at M = 1.730 while a jump gave a fold at 1.766): it
#: counts as a failed solve, the step is halved.
CROSSING_JUMP = 10.0
#: The step along a fold's null vector of the central difference that gives its normal form's quadratic coefficient
#: (:func:`ghost_passage`): K's third derivative along it is O(1) on the paper's geometry, so its error is ~1e-8 relative.
GHOST_STEP = 1e-4
#: Most stable branches a slowly loaded chain is followed onto, one after another, past the end of the traced branch's
#: stable part (:func:`onset_past`); still at rest past the last one's fold, M_c is that fold's moment, a lower bound.
MAX_CROSSINGS = 4

#: What ``index_before`` / ``index_after`` and ``stable`` along the branch count (the JSON's ``index_meaning``).
INDEX_MEANING = (
    "index_before, index_after and the branch's stable: the stiffness index, K's negative eigenvalues (K's inertia), "
    "not the unstable eigenvalues of the damped dynamics; those are under dynamics"
)
#: The output's sentence on where the dynamic verdict comes from, by ``dynamics_from`` (module docstring).
DYNAMICS_NOTES = {
    "stiffness index": (
        "the dynamic verdict is K's inertia: for a conservative model with positive damping the damped dynamics' unstable "
        "eigenvalues are K's negative ones (a theorem), so they are not recomputed; no Hopf points"
    ),
    "eigenvalues": (
        "the dynamic verdict from the damped dynamics' eigenvalues at every traced point (for eq. (2), where every "
        "|phi_j| < pi/2 and not next to a point beyond, its theorem: stable); Hopf points searched on the traced branch"
    ),
    "eq. (2) theorem": (
        "beyond the dense limit: on the branch from rest up to M_c every |phi_j| < pi/2, and eq. (2)'s linearised dynamics "
        "times diag(1, 1, cos phi_j) are a symmetric damped system with positive stiffness: dynamically stable (a theorem, "
        "not computed); Hopf points not searched (numerics.hopf.hopf_points searches the branch)"
    ),
    "not computed": (
        "the dynamic verdict is not computed (asked not to, or beyond the dense limit for a model without a theorem: "
        "numerics.stability.dynamic_stability gives it point by point); Hopf points not searched"
    ),
}


@dataclass
class CriticalResult:
    """Statics of one model under a moment on one particle.

    Attributes
    ----------
    fold : Fold or None
        The fold of M_c, the onset of rotation: the largest maximum of M approached stably
        (module docstring); where M_c is a branch point, the branch's largest maximum (None
        for a model without one: the linear model).
    first_fold : Fold or None
        The first fold along the branch from rest (where the stable branch ends; a
        snap-through when it is not ``fold``).
    snap_to : Fold or None
        At a snap-through: the first stable static state further along the branch that
        holds the first fold's moment (``maximum`` None), where a slowly loaded chain
        comes to rest if it jumps no further (the damped dynamics decide in general; for
        the N = 10 example a relaxation from the fold lands on it, tested). None without
        a snap-through or without such a state on the traced branch.
    compliance : float
        d phi_0 / dM at M = 0.
    branch : Branch
        Continuation over one turn of the loaded particle.
    branch_point : BranchPoint or None
        The branch point where M_c is: where the stable branch from rest ends, if it ends at one
        (before any fold), or where a later stable part that holds more than every fold approached
        stably ends (after a snap-through); M_c is then its moment.
    """

    params: ChainParams
    model: str
    particle: int
    fold: Fold | None
    compliance: float
    branch: Branch
    first_fold: Fold | None = None
    snap_to: Fold | None = None
    branch_point: BranchPoint | None = None
    #: How the folds were checked: "once" (K resolved at rest: the trace alone), "re-solved" (the
    #: folds that decide M_c re-solved, each one's ``confirmed`` says whether the re-solve found it
    #: too), or "closed form" (eq. (2): every fold at M = +-1 / max_j |c_j|, module docstring).
    confirmation: str = "once"
    #: The budget in turns of the loaded particle (None for a model that does not rotate: one turn).
    turns: float | None = None
    #: The particle (-N..N) that starts to rotate at the onset (the mode of the fold or branch
    #: point that ends the stable branch from rest; for eq. (2) the one of largest |c_j|).
    onset_particle: int | None = None
    #: Where the dynamic verdict comes from: "stiffness index", "eigenvalues", "eq. (2) theorem" or
    #: "not computed" (module docstring).
    dynamics_from: str = "stiffness index"
    #: The damped dynamics' verdict at every point of the branch (``dynamics_from`` "eigenvalues"), else None.
    dynamics: list[DynamicStability] | None = None
    #: The Hopf points of the traced branch ([] for a conservative model with positive damping; None: not searched).
    hopf: list[HopfPoint] | None = None
    #: Where the stable branch from rest ends at a branch point, or at a fold past which the trace was cut short, and a
    #: relaxation just past it comes to rest on a stable branch: the first fold past which the chain leaves rest, M_c
    #: (:func:`onset_past`); None otherwise.
    crossing: Fold | None = None
    #: True where such a branch was found but not followed to where the chain leaves rest: M_c is then a lower bound.
    crossing_unresolved: bool = False
    #: True where relaxations just above M_c leave rest (:func:`onset_past`): M_c is decided by the dynamics too, so a
    #: trace cut short past it leaves the branch incomplete but not M_c. False where no relaxation ran or they decided
    #: nothing (:func:`crossing_fold`).
    onset_checked: bool = False

    @property
    def rest_segment(self) -> int:
        """Points of the branch from rest up to the end of its stable part (K's inertia): the first ``rest_segment``."""
        unstable = np.flatnonzero(~self.branch.stable)
        return int(unstable[0]) if unstable.size else len(self.branch.stable)

    @property
    def dynamically_stable_to_onset(self) -> bool | None:
        """The damped dynamics' verdict on the branch from rest up to M_c (where its stable part ends): True where every
        point of it is dynamically stable (by the verdict ``dynamics_from`` names), None where not computed."""
        if self.dynamics_from in ("stiffness index", "eq. (2) theorem"):
            return self.rest_segment > 0 if self.dynamics_from == "stiffness index" else True
        if self.dynamics is None:
            return None
        return all(d.stable for d in self.dynamics[: self.rest_segment])

    @property
    def hopf_search(self) -> str:
        """How the Hopf points were sought: "searched" (``hopf`` lists what was found on the traced branch), "none by the theorem" (a conservative model
        with positive damping) or "not searched" (beyond the dense limit: ``hopf`` None)."""
        if self.hopf is None:
            return "not searched"
        return "none by the theorem" if self.dynamics_from == "stiffness index" else "searched"

    @property
    def dynamics_note(self) -> str:
        """One sentence: where the dynamic verdict comes from (module docstring)."""
        return DYNAMICS_NOTES[self.dynamics_from]

    @property
    def budget_reached(self) -> bool:
        """Whether the branch from rest was still stable when the loaded particle had turned ``turns`` times."""
        return self.turns is not None and self.branch.stop == BranchEnd.ANGLE_LIMIT and bool(np.all(self.branch.stable))

    @property
    def complete(self) -> bool:
        """Whether the branch was traced to its requested end: over a turn and to where the stable branch from rest ends
        (else M_c is that of its traced part, or unknown where the stable branch reached the budget in turns)."""
        return self.branch.complete and not self.budget_reached

    @property
    def end(self) -> str | None:
        """How the stable branch from rest ends: "branch_point", "fold", or where it was not seen to end "budget"
        (``turns`` reached), "max_points", "step_too_small" or "reversed" (the trace cut short); None for a model that never loses it (linear)."""
        if self.branch_point is not None and self.branch_point is self.branch.stable_end:
            return "branch_point"
        if self.first_fold is not None:
            return "fold"
        if self.branch.stop in (BranchEnd.MAX_POINTS, BranchEnd.STEP_TOO_SMALL, BranchEnd.REVERSED):
            return str(self.branch.stop)
        return "budget" if self.budget_reached else None

    @property
    def accurate(self) -> bool:
        """False where the fold of M_c or the first fold is not confirmed by its re-solve (module docstring)."""
        confirmed = all(f is None or f.confirmed is not False for f in (self.fold, self.first_fold))
        return confirmed and not self.crossing_unresolved

    @property
    def snap_through(self) -> bool:
        """Whether the stable branch from rest ends at its first fold while M_c lies further along (a later fold or branch
        point, or the fold of a branch the chain comes to rest on past the traced part: ``crossing``)."""
        return self.end == "fold" and (self.branch_point is not None or self.first_fold is not self.fold or self.crossing is not None)

    @property
    def onset(self) -> str | None:
        """What ends the stable branch from rest and starts the rotation: "fold", "branch_point", "crossing_fold" (the
        fold of a stable branch the chain comes to rest on past the branch point, or past a fold where the trace was cut
        short: ``crossing``) or None."""
        if self.crossing is not None:
            return "crossing_fold"
        if self.branch_point is not None:
            return "branch_point"
        return None if self.fold is None else "fold"

    @property
    def critical_moment(self) -> float | None:
        """M_c, the onset of rotation under a slowly rising load (module docstring)."""
        if self.crossing is not None:
            return self.crossing.moment
        if self.branch_point is not None:
            return self.branch_point.moment
        return None if self.fold is None else self.fold.moment

    @property
    def phi0_at_onset(self) -> float | None:
        if self.crossing is not None:
            return self.crossing.phi0
        if self.branch_point is not None:
            return self.branch_point.phi0
        return self.phi0_at_fold

    @property
    def phi0_at_fold(self) -> float | None:
        return None if self.fold is None else self.fold.phi0

    def as_dict(self) -> dict:
        """JSON-ready: ``M_c`` (onset of rotation; null without a fold), ``onset`` ("fold" or "branch_point"),
        ``phi0_at_onset``, ``phi0_at_fold`` (the largest maximum's), ``largest_fold``, ``first_fold``, ``snap_through``,
        ``crossing`` (the fold of a stable crossing branch past the branch point, M_c there) and ``crossing_unresolved``,
        ``branch_points``, ``compliance``, ``branch_complete``, ``end`` (how the stable branch from rest ends),
        ``onset_particle``, ``turns`` (the budget), ``folds`` (every fold in order: moment, phi_0, maximum,
        the index of K before and after it, ``confirmed``, ``discrepancy``), ``confirmation``, ``accurate`` and the branch (its ``approach``: the points after rest solved with the angle held
        before the trace, :func:`~cosserat_chain.numerics.continuation.approach_from_rest`). Moments are in
        the parameters' units; ``moment_scale`` (E1 h^2) is the unit of the paper's dimensionless moment,
        ``M_c_dimensionless`` = M_c / (E1 h^2)."""
        scale = self.params.moment_scale
        folds = [
            {
                "moment": f.moment,
                "phi0": f.phi0,
                "maximum": f.maximum,
                "index_before": f.index_before,
                "index_after": f.index_after,
                "confirmed": f.confirmed,
                "discrepancy": None if f.discrepancy is None or not math.isfinite(f.discrepancy) else f.discrepancy,
            }
            for f in self.branch.folds
        ]
        return {
            "model": self.model,
            "particle": self.particle,
            "M_c": self.critical_moment,
            "moment_scale": scale,
            "M_c_dimensionless": None if self.critical_moment is None else self.critical_moment / scale,
            "onset": self.onset,
            "onset_particle": self.onset_particle,
            "end": self.end,
            "turns": self.turns,
            "phi0_at_onset": self.phi0_at_onset,
            "phi0_at_fold": self.phi0_at_fold,
            "largest_fold": None if self.fold is None else {"moment": self.fold.moment, "phi0": self.fold.phi0},
            "first_fold": None if self.first_fold is None else {"moment": self.first_fold.moment, "phi0": self.first_fold.phi0},
            "snap_through": self.snap_through,
            "snap_to": None if self.snap_to is None else {"moment": self.snap_to.moment, "phi0": self.snap_to.phi0},
            "crossing": None if self.crossing is None else {"moment": self.crossing.moment, "phi0": self.crossing.phi0},
            "crossing_unresolved": self.crossing_unresolved,
            "onset_checked": self.onset_checked,
            "branch_points": [
                {
                    "moment": q.moment,
                    "phi0": q.phi0,
                    "index_before": q.index_before,
                    "index_after": q.index_after,
                    "located": q.located,
                    "bracket": q.bracket,
                }
                for q in self.branch.branch_points
            ],
            "compliance": self.compliance,
            "branch_complete": self.complete,
            "folds": folds,
            "confirmation": self.confirmation,
            "accurate": self.accurate,
            "index_meaning": INDEX_MEANING,
            "dynamics": {
                "verdict_from": self.dynamics_from,
                "note": self.dynamics_note,
                "stable_from_rest_to_onset": self.dynamically_stable_to_onset,
                "hopf_search": self.hopf_search,
            },
            "hopf_points": None if self.hopf is None else [h.as_dict() for h in self.hopf],
            "branch": {
                "stop": str(self.branch.stop),
                "message": self.branch.message,
                "approach": self.branch.approach,
                "moment": self.branch.moment.tolist(),
                "phi0": self.branch.phi0.tolist(),
                "stable": self.branch.stable.tolist(),
                "critical_eigenvalue": self.branch.critical_eigenvalue.tolist(),
                "folds": folds,
                "stiffness_index": None if self.dynamics is None else [d.stiffness_index for d in self.dynamics],
                "dynamically_stable": None if self.dynamics is None else [d.stable for d in self.dynamics],
                "unstable_eigenvalues": None if self.dynamics is None else [d.unstable_eigenvalues for d in self.dynamics],
                "unstable_pairs": None if self.dynamics is None else [d.unstable_pairs for d in self.dynamics],
            },
        }

    def to_dataset(self) -> xr.Dataset:
        """Dataset with dims ``point`` (along the branch) and ``particle``; scalars for M_c, phi_0 at the fold, compliance."""
        import xarray as xr

        from .simulation import run_attributes  # here, not at import: the simulation's engine is for a file only

        b = self.branch
        # A thinned branch keeps the states of some points only: dimension ``state``, its points in ``state_point``.
        dims = ("point", "particle") if b.state_points is None else ("state", "particle")
        data = {row: (dims, b.x[:, i, :]) for i, row in enumerate(ROWS)}
        data.update(
            {
                "moment": (("point",), b.moment),
                "phi0": (("point",), b.phi0),
                "stable": (("point",), b.stable.astype(np.int8)),
                "critical_eigenvalue": (("point",), b.critical_eigenvalue),
                "M_c": ((), np.nan if self.critical_moment is None else self.critical_moment),
                "phi0_at_fold": ((), np.nan if self.fold is None else self.fold.phi0),
                "compliance": ((), self.compliance),
            }
        )
        data.update(self._dynamics_variables())
        coords = {"point": np.arange(len(b.moment)), "particle": np.arange(-self.params.N, self.params.N + 1)}
        if b.state_points is not None:
            coords["state_point"] = ("state", b.state_points)
        ds = xr.Dataset(data, coords={**coords, "hopf": np.arange(len(self.hopf or []))})
        ds["M_c"].attrs["long_name"] = "critical moment, the onset of rotation (NaN: no fold)"
        ds["M_c"].attrs["onset"] = str(self.onset)
        ds["stable"].attrs["long_name"] = "1 if the static state is stable by K's inertia (stiffness index 0)"
        ds["dynamically_stable"].attrs["verdict_from"] = self.dynamics_from
        ds.attrs.update(run_attributes(self.params, get_model(self.model), Loads()))
        ds.attrs.update(
            {
                "experiment": "critical_point",
                "loaded_particle": self.particle,
                "branch_stop": str(self.branch.stop),
                "branch_complete": int(self.complete),
                "end": str(self.end),
                "onset_particle": "none" if self.onset_particle is None else self.onset_particle,
                "fold_confirmation": self.confirmation,
                "states_kept": "every point" if b.state_points is None else "the points in state_point",
                "approach_points": b.approach,
                "accurate": int(self.accurate),
                "dynamics_from": self.dynamics_from,
                "dynamics_note": self.dynamics_note,
                "dynamically_stable_to_onset": "unknown"
                if self.dynamically_stable_to_onset is None
                else int(self.dynamically_stable_to_onset),
                "hopf_search": self.hopf_search,
            }
        )
        return ds

    def _dynamics_variables(self) -> dict[str, tuple]:
        """The dynamic verdict along the branch (-1 where not computed; K's inertia where it is the verdict by the theorem)
        and the Hopf points (dimension ``hopf``; none where not searched: the attribute ``hopf_search`` says which)."""
        k = len(self.branch.moment)
        if self.dynamics is not None:
            stable = np.array([d.stable for d in self.dynamics], dtype=np.int8)
            unstable = np.array([d.unstable_eigenvalues for d in self.dynamics], dtype=np.int32)
            pairs = np.array([d.unstable_pairs for d in self.dynamics], dtype=np.int32)
            index = np.array([d.stiffness_index for d in self.dynamics], dtype=np.int32)
        else:
            theorem = self.dynamics_from == "stiffness index"
            stable = self.branch.stable.astype(np.int8) if theorem else np.full(k, -1, dtype=np.int8)
            if self.dynamics_from == "eq. (2) theorem":
                stable[: self.rest_segment] = 1
            unstable = pairs = index = np.full(k, -1, dtype=np.int32)
        hopf = self.hopf or []
        return {
            "dynamically_stable": (("point",), stable),
            "unstable_eigenvalues": (("point",), unstable),
            "unstable_pairs": (("point",), pairs),
            "stiffness_index": (("point",), index),
            "hopf_moment": (("hopf",), np.array([h.moment for h in hopf], dtype=float)),
            "hopf_phi0": (("hopf",), np.array([h.phi0 for h in hopf], dtype=float)),
            "hopf_frequency": (("hopf",), np.array([h.frequency for h in hopf], dtype=float)),
            "hopf_located": (("hopf",), np.array([h.located for h in hopf], dtype=np.int8)),
        }


@one_blas_thread
def critical_point(
    params: ChainParams,
    model: str | Model,
    *,
    particle: int = 0,
    max_points: int = MAX_POINTS,
    turns: float = TURNS,
    progress: Callable[[float, float], None] | None = None,
    dynamics: bool = True,
) -> CriticalResult:
    """Compliance, fold and branch of ``model`` under a moment on ``particle``.

    The branch is traced over one turn of the loaded particle and on, while it stays
    stable, to where the stable branch from rest ends, within ``turns`` turns (a model that
    does not rotate: one turn). ``max_points`` bounds the branch's points
    (:func:`continue_in_moment`); a branch cut short by it, or still stable after ``turns``,
    gives ``complete`` False. Where K is near singular at rest the folds that decide M_c are
    re-solved and confirmed (module docstring). ``dynamics``
    False skips the damped dynamics' eigenvalues along the branch of a model that is not
    conservative (dense, O(n^3) a point: benchmarks/TIMINGS.md) where only the folds
    are wanted: ``dynamics_from`` is then "not computed" (a conservative model's verdict, K's
    inertia by the theorem, costs nothing and is given).

    Raises
    ------
    ValueError
        For ``turns`` below 1 or not finite (and from the continuation: a chain that can move rigidly, memory).
    """
    model = get_model(model)
    if not (isinstance(turns, int | float) and math.isfinite(turns) and turns >= 1):
        raise ValueError(f"turns must be a finite number >= 1 (the budget in turns of the loaded particle), got {turns!r}")
    turn = 2 * math.pi
    budget = turn * turns if model.rotates else turn
    until = turn if model.rotates else None
    states = max_states(params)
    what = f"critical on {params.n_particles} particles (N={params.N}), a branch of up to {max_points} points keeping {min(max_points, states)} states"
    advice = "trace fewer points (max_points, --max-points) or a shorter chain"
    # The least this model's path can need is checked before K at rest is factored to choose the path, then the path's.
    require(critical_memory(params, model, max_points, model.rotates), what, advice)
    near_singular = model.rotates and near_singular_at_rest(params, model)
    require(critical_memory(params, model, max_points, near_singular), what, advice)
    closed = model.name == "sine"
    response = moment_response(params, model, particle=particle)
    approach = near_singular and not rest_resolved(params, model, particle=particle, response=response)
    # Where K's soft modes at rest are beyond its rounded entries, the trace ends once M_c is decided (module docstring),
    # short of the turn's end where its moment has fallen far below the largest maximum (continuation.END_ANGLE,
    # END_MOMENT); eq. (2)'s branch to its first fold is its closed form there (_sine_branch).
    trace = dict(
        particle=particle, phi0_stop=budget, phi0_until_unstable=until, max_points=max_points, max_states=states, response=response,
        decided=near_singular,
    )  # fmt: skip
    if closed and near_singular:
        branch = _sine_branch(params, model, response, particle, progress)
    else:
        branch = continue_in_moment(params, model, **trace, progress=progress, from_approach=approach)
    confirmation = "once"
    angles = unpack(params, response)[ROW_INDEX["phi"]]
    onset_particle = None
    if closed:
        branch.folds, onset_particle = _sine_folds(params, branch, angles, particle), int(np.argmax(np.abs(angles))) - params.N
        confirmation = "closed form"
    elif branch.folds and near_singular:
        deciding = _deciding_folds(branch)
        resolved = [resolve_fold(params, model, branch.folds[i], particle=particle) for i in deciding]
        checked = confirm_folds(branch, [g for g in resolved if g is not None])
        branch.folds = [checked[i] if i in deciding else f for i, f in enumerate(branch.folds)]
        confirmation = "re-solved"
    first = branch.folds[0] if branch.folds else None
    higher = [branch.folds[i] for i in _deciding_folds(branch)[1:]]
    fold = max(higher, key=lambda f: f.moment) if higher else (first if first is not None and first.maximum else None)
    compliance = float(response[moment_dof(params, particle)])
    onset = branch.stable_end if branch.stable_end is not None or first is None else _highest_stable_end(branch, first)
    if isinstance(onset, Fold):
        fold = onset
    if isinstance(onset, BranchPoint):
        # A stable part of the branch ends at a branch point, not at a fold: the chain leaves it there.
        if onset_particle is None and abs(onset.index_after - onset.index_before) == 1:
            # Several eigenvalues through zero together (a cantilever's bonds, all alike) name no one particle.
            onset_particle = onset.mode_particle
    elif onset_particle is None and first is not None:
        onset_particle = first.mode_particle
    snapped = branch.stable_end is None and first is not None and onset is not first
    snap_to = _snap_target(params, model, branch, first, particle) if snapped else None
    crossing, unresolved, checked = None, False, False
    # Past a branch point, or past a fold where the trace was cut short (a stalled corrector: N = 10, a = 0.4166,
    # b = 0.2224, whose chain snaps from the fold at M = 0.1324 onto a stable state the trace never reached and rotates
    # only above 0.3719), where the chain goes is decided by relaxations, not by the traced branch. So past a fold of a
    # whole trace too (N = 6, pinned-clamped, h = 1.6, a = 0.69, b = 0.83, E1 = 2.3, E2 = 2.5, moment on particle 3: the
    # chain snaps from the fold at M = 1.2757 onto a branch the trace never meets and rotates only above 8.8989), except
    # where K is near singular at rest (a long chain's relaxations take longer than its trace).
    past_trace = isinstance(onset, Fold) and not (branch.complete and near_singular)
    if model.conservative and (isinstance(onset, BranchPoint) and onset.index_before == 0 or past_trace):
        crossing, unresolved = onset_past(params, model, onset, particle=particle)
        onset_particle = onset_particle if crossing is None else crossing.mode_particle
        checked = unresolved is False
        if unresolved is None:
            # The relaxations decide nothing (the fold's ghost outlasts them: N = 1000 on the paper's geometry): past the
            # fold of a whole trace M_c stays the traced one, unchecked; elsewhere the point's moment is a lower bound.
            unresolved = not (isinstance(onset, Fold) and branch.complete)
    return CriticalResult(
        params, model.name, particle, fold, compliance, branch, first, snap_to, onset if isinstance(onset, BranchPoint) else None,
        confirmation, turns if model.rotates else None, onset_particle, *_dynamics(params, model, branch, dynamics),
        crossing, unresolved, checked,
    )  # fmt: skip


def critical_memory(params: ChainParams, model: str | Model, max_points: int = MAX_POINTS, near_singular: bool | None = None) -> int:
    """Bytes :func:`critical_point` allocates at its peak, checked against the free memory before it allocates: per
    degree of freedom :data:`TRACE_VALUES` and the kept states (at most :func:`max_states`, each held once), a record a
    point and :data:`TRACE_BYTES`, or where eq. (2)'s branch is taken in closed form (K near singular at rest: ``near_singular``, where
    known, else :func:`near_singular_at_rest`) :data:`SINE_VALUES`."""
    model = get_model(model)
    values = 3 * params.n_particles
    if model.name == "sine" and model.rotates and (near_singular_at_rest(params, model) if near_singular is None else near_singular):
        return FLOAT * values * SINE_VALUES
    return TRACE_BYTES + FLOAT * (values * (TRACE_VALUES + min(max_points, max_states(params)) + 2) + 40 * max_points)


def max_states(params: ChainParams) -> int:
    """The most states of the branch :func:`critical_point` keeps: :data:`STATE_BYTES` of them, at least two."""
    return max(2, STATE_BYTES // (FLOAT * 3 * params.n_particles))


def _dynamics(
    params: ChainParams, model: Model, branch: Branch, compute: bool = True
) -> tuple[str, list[DynamicStability] | None, list[HopfPoint] | None]:
    """``dynamics_from``, the dynamic verdict at every point and the Hopf points of ``branch`` (module docstring;
    ``compute`` False: only the theorems' verdicts, which cost nothing)."""
    from ..numerics.hopf import hopf_points
    from ..numerics.stability import DENSE_LIMIT, dynamic_stability, sine_theorem_stability
    from ..state import n_free

    if model.conservative and all(g > 0 for g in params.damping):
        return "stiffness index", None, []
    if not compute:
        return "not computed", None, None
    if 2 * n_free(params) <= DENSE_LIMIT and branch.state_points is None:
        # The theorem's verdict where every free angle is within pi/2 of rest (no eigenvalues: most of a
        # long chain's turn); the eigenvalues elsewhere and at the theorem's points next to such a point,
        # where the Hopf search compares neighbours.
        theorem = [sine_theorem_stability(params, model, x) for x in branch.x]
        near = [
            t is None or (i > 0 and theorem[i - 1] is None) or (i + 1 < len(theorem) and theorem[i + 1] is None)
            for i, t in enumerate(theorem)
        ]
        checks = [dynamic_stability(params, model, x) if dense else t for x, t, dense in zip(branch.x, theorem, near)]
        return "eigenvalues", checks, hopf_points(params, model, branch, checks=checks)
    return ("eq. (2) theorem" if model.name == "sine" else "not computed"), None, None


#: Points of eq. (2)'s closed-form branch (:func:`_sine_branch`) from rest to its first fold, at equal steps of the
#: turning particle's angle (pi / 2 / SINE_POINTS each), and one step beyond it.
SINE_POINTS = 16


def _sine_branch(params: ChainParams, model: Model, response: np.ndarray, particle: int, progress=None) -> Branch:
    """Eq. (2)'s branch from rest to its first fold and one step beyond, in closed form, with the fold.

    Its static states are (u, v, sin phi) = M c with c = K^-1 e (``response``): with j the particle of
    largest |c_j|, the branch from rest is M = M_c sin(theta), theta = 0 .. pi / 2 the angle of j,
    M_c = 1 / |c_j|, every other angle asin(M c_k) (|M c_k| <= 1 there), and beyond the fold j's angle is
    pi - theta. Used where K at rest is near singular (a trace of N = 10^5 crawled at 1.3 rad, where
    this costs one stability check a point). Each point's stability is computed
    (:func:`~cosserat_chain.numerics.stability.static_stability`: stable up to the fold by eq. (2)'s
    theorem, the index one beyond); ``Branch.stop`` "max_folds", as a trace stopped at its first fold.
    """
    n = params.N
    x_of = unpack(params, response)
    angles = x_of[ROW_INDEX["phi"]]
    turning = int(np.argmax(np.abs(angles)))
    exact = 1.0 / abs(float(angles[turning]))
    sign = math.copysign(1.0, angles[turning])
    loaded = column(params, particle)
    thetas = np.linspace(0.0, math.pi / 2, SINE_POINTS + 1)
    thetas = np.append(thetas, math.pi / 2 + thetas[1])
    moments, states, checks = [], [], []
    for theta in thetas:
        moment = exact * math.sin(theta)
        x = moment * x_of
        x[ROW_INDEX["phi"]] = np.arcsin(np.clip(moment * angles, -1.0, 1.0))
        x[ROW_INDEX["phi"], turning] = sign * theta  # pi / 2 at the fold, pi - (pi / 2 - theta) beyond: exact
        moments.append(moment)
        states.append(x)
        checks.append(None if theta == math.pi / 2 else static_stability(params, model, x))
        if progress is not None:
            progress(abs(float(x[ROW_INDEX["phi"], loaded])), 2 * math.pi)
    fold_x = states[SINE_POINTS]
    del moments[SINE_POINTS], states[SINE_POINTS], checks[SINE_POINTS]  # the fold is the Fold, not a point (K singular there)
    fold = Fold(
        moment=exact, phi0=float(fold_x[ROW_INDEX["phi"], loaded]), x=fold_x, particle=particle, maximum=True,
        index_before=checks[-2].index, index_after=checks[-1].index, mode_particle=turning - n,
    )  # fmt: skip
    phi0 = [float(x[ROW_INDEX["phi"], loaded]) for x in states]
    return Branch(
        moment=np.array(moments), phi0=np.array(phi0), x=np.array(states), stable=np.array([c.stable for c in checks]),
        critical_eigenvalue=np.array([c.critical_eigenvalue for c in checks]), folds=[fold], particle=particle,
        stop=BranchEnd.MAX_FOLDS, message="eq. (2)'s branch from rest to its first fold in closed form",
    )  # fmt: skip


def _sine_folds(params: ChainParams, branch: Branch, angles: np.ndarray, particle: int) -> list[Fold]:
    """The traced folds of eq. (2) at their exact moments, +-1 / max_j |c_j|, ``confirmed`` by that closed form.

    Eq. (2)'s forces are the linear model's at (u, v, sin phi), so the static states under M are
    (u, v, sin phi) = M c with c = K^-1 e (``angles``: c's angle components, refined), and a fold is
    where a particle passes phi = +-pi/2: only the particle j of largest |c_j| can (no |sin phi| exceeds
    1), at |M| = 1 / |c_j|. The first fold lies on the branch from rest, phi_0 = arcsin(c_0 / |c_j|)
    there. Traced, the folds' moments carry the continuation's round-off (N = 10^4: 3.6e-6 from this);
    ``discrepancy`` keeps it.
    """
    turning = int(np.argmax(np.abs(angles)))
    exact = 1.0 / abs(float(angles[turning]))
    loaded = column(params, particle)
    # asin near 1 loses half the digits of its argument's round-off: the turning particle's own angle is pi/2.
    first = math.copysign(math.pi / 2, angles[loaded]) if turning == loaded else math.asin(float(angles[loaded]) * exact)
    out = []
    for i, f in enumerate(branch.folds):
        moment = math.copysign(exact, f.moment)
        phi0 = first if i == 0 else f.phi0
        out.append(replace(f, moment=moment, phi0=phi0, confirmed=True, discrepancy=abs(f.moment - moment)))
    return out


def near_singular_at_rest(params: ChainParams, model: Model) -> bool:
    """Whether K's softest eigenvalue at rest lies below :data:`CONFIRM_MARGIN` times its round-off (never for a ring or a
    model without a banded similar, whose statics run dense, at small N)."""
    similar = None if params.periodic else model.symmetric_similar(params, np.zeros((3, params.n_particles)))
    if similar is None:  # the dense statics of a model without a banded similar
        return False
    value, resolution = smallest_eigenvalue(similar)
    return value < CONFIRM_MARGIN * resolution


def onset_past(params: ChainParams, model: Model, point: BranchPoint | Fold, *, particle: int = 0) -> tuple[Fold | None, bool | None]:
    """The onset of rotation past ``point``, where a stable part of the branch ends, by :func:`crossing_fold` repeated.

    Where a relaxation just past ``point`` comes to rest on a stable branch, that branch's first maximum of M is tested the
    same way, up to :data:`MAX_CROSSINGS` branches: the first maximum past which the chain leaves rest is M_c,
    ``(fold, False)``. ``(None, False)`` where the chain leaves rest at ``point`` itself; ``(fold, True)`` or
    ``(None, True)`` where a branch it rests on could not be followed to a maximum, or it still rests past the last one:
    the moment reached is then a lower bound of M_c. ``(None, None)`` where the relaxations past ``point`` itself decide
    nothing (:func:`crossing_fold`); past a later branch's fold that is ``(fold, True)``, a lower bound.
    """
    crossing, unresolved = crossing_fold(params, model, point, particle=particle)
    for _ in range(MAX_CROSSINGS - 1):
        if crossing is None or unresolved:
            return crossing, unresolved
        further, unresolved = crossing_fold(params, model, crossing, particle=particle)
        if further is None:
            return crossing, True if unresolved is None else unresolved
        crossing = further
    return crossing, True


def crossing_fold(params: ChainParams, model: Model, point: BranchPoint | Fold, *, particle: int = 0) -> tuple[Fold | None, bool | None]:
    """The onset of rotation past a branch point or fold that ends a stable part of the branch, where a crossing branch is stable.

    A relaxation (:func:`~cosserat_chain.numerics.relaxation.relax`, rotation told by windows of
    :data:`CROSSING_WINDOW_TURNS` turns) at :data:`CROSSING_EXCESS` times the point's moment starts from its state nudged
    by :data:`CROSSING_NUDGE` along K's lowest mode: each way past a branch point, and past a fold only the way its
    ghost's flow runs (:func:`ghost_passage`: the other start passes the same ghost to the same place). Where a
    relaxation neither comes to rest nor rotates within its ``t_max``, or past a fold whose ghost takes longer to pass
    than twice that (the relaxation would end inside it), nothing is decided: ``(None, None)``. Where none comes to
    rest at a stable state, the chain leaves the branch there: ``(None, False)``. Where one does, the branch it rests on
    is followed with the loaded particle's angle held (:func:`~cosserat_chain.numerics.newton.solve_rotation_controlled`,
    steps of :data:`CROSSING_STEP`) while it stays stable, to its first maximum of M, located by Brent's method on
    dM/dphi_0 (:func:`~cosserat_chain.numerics.continuation.locate_fold`): ``(fold, False)``, the fold of M_c. Where
    that branch turns unstable before a maximum (a branch point of its own), a solve fails or leaves the branch
    (:data:`CROSSING_JUMP`; the branch turns back in phi_0 before its maximum of M), or no maximum comes within
    :data:`CROSSING_TURN` rad: ``(None, True)``, M_c unresolved (the branch point's moment is then a lower bound).
    """
    from ..numerics.relaxation import RelaxSettings, relax  # the dynamics' engine only where a branch point needs it

    col = column(params, particle)
    moment = point.moment * CROSSING_EXCESS
    free = np.zeros(n_free(params))
    static_stability(params, model, point.x, start=free)
    free /= np.linalg.norm(free)
    mode = unpack(params, free)
    signs = (1.0, -1.0)
    if isinstance(point, Fold):
        ghost, flow = ghost_passage(params, model, point, free, moment, particle=particle)
        if flow and ghost / 2 > RelaxSettings().t_max:
            return None, None
        signs = (flow,) if flow else signs
    rest, undecided = None, False
    for sign in signs:
        step = relax(
            params, model, moment, particle=particle, x0=point.x + sign * CROSSING_NUDGE * mode, window_turns=CROSSING_WINDOW_TURNS
        )
        # A state at rest counts only where it is stable: next to a branch point a relaxation can slow to rest on the
        # unstable side before it leaves (its unstable eigenvalue is small there).
        if step.status == Status.STATIC and static_stability(params, model, step.x).stable:
            rest = step.x
            break
        undecided = undecided or step.status == Status.NOT_CONVERGED
    if rest is None:
        return None, (None if undecided else False)
    x, held = rest, float(rest[ROW_INDEX["phi"], col])
    start, delta, rate = held, math.copysign(CROSSING_STEP, moment), None
    while abs(held - start) < CROSSING_TURN:
        try:
            new_x, new_moment = solve_rotation_controlled(params, model, held + delta, particle=particle, x0=x, moment0=moment)
            change = float(np.max(np.abs(new_x - x))) / abs(delta)
            if rate is not None and change > CROSSING_JUMP * rate:
                raise NewtonError(f"the solve at phi_0 = {held + delta:.10g} left the followed branch", new_x)
        except NewtonError:
            if abs(delta) < CROSSING_STEP / 2**10:
                return None, True
            delta /= 2
            continue
        if moment_slope(params, model, new_x, particle=particle) * math.copysign(1.0, moment) <= 0:
            fold = locate_fold(params, model, particle=particle, bracket=(held, held + delta), seed=(x, moment))
            return (fold, False) if fold is not None else (None, True)
        if not static_stability(params, model, new_x).stable:
            return None, True
        x, moment, held, rate = new_x, new_moment, held + delta, change
    return None, True


def ghost_passage(
    params: ChainParams, model: Model, fold: Fold, mode: np.ndarray, moment: float, *, particle: int = 0
) -> tuple[float, float]:
    """How long the damped chain takes to pass ``fold``'s ghost under ``moment`` just beyond it, and which way it runs.

    Along K's null vector v at the fold (``mode``, unit, free degrees of freedom), the slow dynamics are overdamped
    and take the saddle-node's normal form gamma s' = mu - beta s^2: gamma = v^T Gamma v (the viscous coefficients),
    mu = (moment - M_f) v_0 (v_0 the loaded angle's component), beta = (d/ds v^T K(x_f + s v) v) / 2 (a central
    difference of two stiffness matrices). Past the fold (mu beta < 0: no equilibrium) s runs the way of mu's sign
    through the fold's ghost in the time pi gamma / sqrt(-mu beta) (N = 100 on the paper's geometry: 128 at 1.001 M_f, where a
    relaxation's turns take 175 each; N = 1000: 2.8 10^5, where two relaxations of t = 20000 turned the loaded
    particle by 0.006 turn). O(N).

    Returns
    -------
    time : float
        The passage from s = -inf to +inf (NaN where the normal form has no ghost: mu beta >= 0).
    flow : float
        +1 or -1: the sign of s along which the chain runs past the fold; 0.0 where there is no ghost.
    """
    v = unpack(params, mode)
    gamma = float(np.sum(np.asarray(params.damping)[:, None] * v * v))
    mu = (moment - fold.moment) * float(v[ROW_INDEX["phi"], column(params, particle)])
    step = GHOST_STEP
    curvature = [float(mode @ (model.stiffness(params, fold.x + side * step * v) @ mode)) for side in (1.0, -1.0)]
    beta = (curvature[0] - curvature[1]) / (4 * step)
    if not mu * beta < 0:
        return math.nan, 0.0
    return math.pi * gamma / math.sqrt(-mu * beta), math.copysign(1.0, mu)


def confirm_folds(branch: Branch, others: list[Fold]) -> list[Fold]:
    """``branch``'s folds, each ``confirmed`` where ``others`` (re-solved folds) holds a fold of the same kind (maximum or
    minimum) within :data:`CONFIRM_MOMENT_RTOL` times the branch's largest |M| in moment and :data:`CONFIRM_PHI0_ATOL` in
    phi_0, and with its ``discrepancy``: the moment difference to the nearest fold of the same kind in ``others``."""
    scale = float(np.max(np.abs(branch.moment)))
    out = []
    for f in branch.folds:
        kin = [g for g in others if g.maximum == f.maximum]
        confirmed = any(abs(g.moment - f.moment) <= CONFIRM_MOMENT_RTOL * scale and abs(g.phi0 - f.phi0) <= CONFIRM_PHI0_ATOL for g in kin)
        discrepancy = min((abs(g.moment - f.moment) for g in kin), default=math.inf)
        out.append(replace(f, confirmed=confirmed, discrepancy=discrepancy))
    return out


def _highest_stable_end(branch: Branch, first: Fold) -> Fold | BranchPoint | None:
    """Where M_c is, once the stable branch from rest has ended at its first fold: the highest end of a stable part.

    Each stable part of the branch (K's index 0) ends at a maximum of M approached with index 0
    or at a branch point left with index 0: a slowly loaded chain that has snapped through onto a
    later stable part leaves it there. A maximum approached on an unstable part (index before it
    above 0) is not where the chain leaves: the stable part before it ended at a branch point,
    at a lower moment (module docstring; tests/test_critical_stable_parts.py).
    A maximum without indices (located on its own) counts as approached stably. As for the maxima
    (:func:`_deciding_folds`), a branch point decides only where it holds more than the first fold by
    more than the folds' confirmation tolerance. None where the first fold is not a maximum.
    """
    if not first.maximum:
        return None
    above = first.moment + CONFIRM_MOMENT_RTOL * float(np.max(np.abs(branch.moment)))
    ends: list[Fold | BranchPoint] = [first]
    ends += [f for f in (branch.folds[i] for i in _deciding_folds(branch)[1:]) if not f.index_before]
    ends += [q for q in branch.branch_points if q.index_before == 0 < q.index_after and q.moment > above]
    return max(ends, key=lambda e: e.moment)


def _deciding_folds(branch: Branch) -> list[int]:
    """Indices of the folds that decide M_c: the first fold, then every maximum holding more than it.

    Under a positive moment from rest M rises first: the branch's first fold is a maximum. A later
    maximum is M_c only where it holds more than the first by more than the folds' confirmation
    tolerance: maxima equal to round-off (a wound particle repeating one fold) are one M_c.
    """
    if not branch.folds:
        return []
    first = branch.folds[0]
    above = first.moment + CONFIRM_MOMENT_RTOL * float(np.max(np.abs(branch.moment)))
    return [0] + [i for i, f in enumerate(branch.folds) if i > 0 and f.maximum and f.moment > above]


def resolve_fold(params: ChainParams, model: Model, fold: Fold, *, particle: int = 0) -> Fold | None:
    """``fold`` re-solved on the rotation-controlled branch: the root of dM/dphi_0 within :data:`CONFIRM_PHI0_ATOL` of its angle.

    Another parametrisation and other linear algebra than the trace's (the angle phi_0 held,
    :func:`~cosserat_chain.numerics.newton.solve_rotation_controlled`, and the exact slope
    :func:`~cosserat_chain.numerics.continuation.moment_slope`, sparse solves of the
    rotation-controlled Jacobian, which stays regular at a fold): the states at phi_0 -+
    :data:`CONFIRM_PHI0_ATOL` are solved from the traced fold's, and a maximum of M along the
    branch is one of M(phi_0) wherever phi_0 runs one way through it, so dM/dphi_0 falls through
    zero there (rises, at a minimum). Its root, to :data:`CONFIRM_PHI0_XTOL` (Brent's method), is
    the re-solved fold. Where a solve at an end fails (phi_0 turns back within the bracket), a
    narrower bracket is tried (:data:`CONFIRM_NARROWING`).

    Returns
    -------
    Fold or None
        The re-solved fold (``maximum`` the traced fold's), or None where dM/dphi_0 does not change
        sign as that kind of fold does within the bracket, or a solve there fails: no such fold
        within :data:`CONFIRM_PHI0_ATOL` of the traced one.
    """
    cache = {fold.phi0: (fold.x, fold.moment)}

    def solve(angle: float) -> tuple[np.ndarray, float]:
        if angle not in cache:
            nearest = min(cache, key=lambda a: abs(a - angle))
            cache[angle] = solve_rotation_controlled(
                params, model, angle, particle=particle, x0=cache[nearest][0], moment0=cache[nearest][1], tol=FOLD_TOL,
                max_iter=CONFIRM_ITERATIONS,
            )  # fmt: skip
        return cache[angle]

    def slope(angle: float) -> float:
        return moment_slope(params, model, solve(angle)[0], particle=particle)

    sign = 1.0 if fold.maximum else -1.0
    for width in CONFIRM_PHI0_ATOL * CONFIRM_NARROWING:
        low, high = fold.phi0 - width, fold.phi0 + width
        try:
            before, after = slope(low), slope(high)
        except NewtonError:
            continue  # phi_0 turns back within the bracket: no state there on this side of the fold
        if not (sign * before > 0.0 > sign * after):
            return None
        try:
            root = brentq(slope, low, high, xtol=min(CONFIRM_PHI0_XTOL, 1e-3 * width), rtol=4 * np.finfo(float).eps)
            x, moment = solve(root)
        except (NewtonError, ValueError):
            return None
        return replace(fold, moment=float(moment), phi0=float(root), x=x)
    return None


def _state_at(params: ChainParams, model: Model, branch: Branch, point: int) -> np.ndarray:
    """The state of the branch's ``point``: kept, or, on a thinned branch, solved anew point by point from the kept
    state before it, each at the traced angle phi_0 (rotation control, from the point before's state).

    Raises
    ------
    NewtonError
        Where a solve fails or lands off the traced branch (its moment not the traced one).
    """
    if branch.state_points is None:
        return branch.x[point]
    kept = int(np.searchsorted(branch.state_points, point, side="right")) - 1
    x, moment = branch.x[kept], float(branch.moment[branch.state_points[kept]])
    scale = float(np.max(np.abs(branch.moment)))
    for j in range(int(branch.state_points[kept]) + 1, point + 1):
        x, moment = solve_rotation_controlled(params, model, float(branch.phi0[j]), particle=branch.particle, x0=x, moment0=moment)
        if abs(moment - branch.moment[j]) > CONFIRM_MOMENT_RTOL * scale:
            raise NewtonError(f"the state of point {j} solved anew holds M = {moment:.10g}, not the traced {branch.moment[j]:.10g}", x)
    return x


def _snap_target(params: ChainParams, model: Model, branch: Branch, first: Fold, particle: int) -> Fold | None:
    """The first stable branch point pair beyond ``first`` that brackets its moment, solved there exactly.

    Load-controlled Newton from the bracket's interpolated state converges to the
    branch's state at that moment (K is regular on a stable segment). A bracket whose
    first point is still unstable holds the minimum of M where the stable segment
    begins (a long step after it can pass the moment at once): Newton starts from its
    stable end.
    """
    # The stable branch from rest ends at the first fold: the first unstable point is just past it
    # (M need not descend between two points: one step can pass the fold's minimum too).
    past = np.flatnonzero(~branch.stable)
    start = past[0] if past.size else branch.moment.size
    for i in range(start, branch.moment.size - 1):
        low, high = branch.moment[i] - first.moment, branch.moment[i + 1] - first.moment
        if branch.stable[i + 1] and low * high <= 0 and low != high:
            weight = low / (low - high) if branch.stable[i] else 1.0
            try:
                start, end = _state_at(params, model, branch, i), _state_at(params, model, branch, i + 1)
            except NewtonError:
                return None
            guess = start + weight * (end - start)
            x = solve_equilibrium(params, model, moment_load(first.moment, particle), x0=guess)
            if not static_stability(params, model, x).stable:
                return None
            return Fold(moment=first.moment, phi0=float(x[ROW_INDEX["phi"], column(params, particle)]), x=x, particle=particle)
    return None
