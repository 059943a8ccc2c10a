"""Period doublings and tori of cycles: their test functions, and their location between two orbits of a branch.

Contract
--------
An orbit branch loses (or regains) its stability where a nontrivial Floquet multiplier leaves (or
enters) the unit circle: at +1 (a fold or a branch point of cycles, the continuations' own tests),
at -1 (a period doubling) or as a complex pair (a torus, Neimark-Sacker). :func:`circle_tests` are
the two test functions of the multipliers of modulus above :data:`NEAR_CIRCLE` that change sign at
the last two; every branch of rotating orbits watches them between consecutive orbits: the
collocation's (:func:`~.collocation.continue_collocation`, through the kit's secant method on the
arclength), the chain's shooting (:func:`~.periodic.continue_orbit`, dense, blocks and Newton-Picard,
through :func:`locate_circle_events` after the branch is traced) and a user system's
(:func:`~.shooting.continue_orbits` in any named parameter, through :func:`circle_events_between` at
every step, so that ``stop_at`` can end the branch there).

:func:`locate_circle_events` finds the zero of the test that changed sign between two orbits a and b
of a branch by Brent's method in the branch's parameter (:func:`~.brent.brentq`; M for the chain,
``value`` says which for another branch), each trial the orbit re-solved at its parameter value
by the branch's own corrector from the orbit interpolated between a and b (a ``solve`` the caller
passes), to :data:`MOMENT_TOL` in the parameter (a step that holds a located fold, where the parameter turns, in
its two halves on either side of the fold: :func:`steps`, on every shooting branch), and polished by one secant step on the test (the event's own
refinement, which puts its critical multiplier on -1 or the circle to the orbits' accuracy). The test functions, not the critical multiplier itself, are the
functions whose zero is sought: they are symmetric functions of the multipliers near the circle and
stay continuous where two of them collide (at a period doubling of the paper's chain a complex pair
has just met on the negative real axis, and the multiplier nearest -1 is not a smooth function of M
there; :mod:`~.cycle_curve` says the same of its augmented systems). A zero is kept as an event
where its critical multiplier (:func:`critical_multiplier`) lies within :data:`CIRCLE_MULTIPLIER` of
-1 or of the circle; a sign change without one (a pair outside the circle turning real flips the
torus test) is no event. Where Brent's trials cannot be solved the event is reported unlocated, at
the first orbit past the sign change (the collocation's convention).

The tests are parities: two multipliers of one kind crossing within one step leave a sign as it
was. :func:`circle_counts` counts what the parities count (real multipliers below -1, complex pairs
outside the circle, classed as the tests class them); where a count changes by two or more between
two orbits the step is halved in the parameter, each midpoint solved, until the crossings lie apart. (The
roto-breathers' ``breather_arclength.instability_counts`` counts the same for conservative orbits, with a
band of 1e-6 about the circle that the exact parities here must not have, and lives above
:mod:`~.periodic`, which imports this module.) A crossing out and back within one step changes no
count; the branches' step control (``periodic.MAX_MULTIPLIER_MOTION``) keeps such windows from hiding.

Only the multipliers above :data:`NEAR_CIRCLE` enter: on long collocation orbits the strongly damped
ones are not resolved, and Newton-Picard (``newton_picard.RHO`` = 0.5) computes none below rho; a
multiplier crossing the unit circle lies above either bound on both sides of the crossing.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from typing import Any

import numpy as np

from ..errors import CosseratChainError
from .brent import brentq

#: The orbit at a parameter value between two orbits of a branch (:func:`locate_circle_events`' ``solve``).
Solve = Callable[[float, Any, Any], Any]
#: The continuation parameter's value at an orbit (:func:`locate_circle_events`' ``value``).
Value = Callable[[Any], float]

#: The period-doubling and torus tests take only the multipliers of modulus above this: on long orbits the
#: strongly damped ones are not resolved (docs/collocation.md, Limits), the ones near the circle are.
NEAR_CIRCLE = 0.5
#: A multiplier is complex where |Im mu| exceeds this times |mu|.
COMPLEX_RTOL = 1e-6
#: A located period doubling or torus is confirmed where its critical multiplier lies this close to -1 or to
#: the unit circle (on every branch: the chain's, the collocation's, a system's).
CIRCLE_MULTIPLIER = 1e-3
#: The events of :func:`circle_tests`.
CIRCLE_KINDS = ("period_doubling", "torus")
#: Brent's tolerance in the parameter (M for the chain) of an event located by :func:`locate_circle_events` (its ``"accuracy"``).
MOMENT_TOL = 1e-10
#: Most halvings of a step over which two multipliers of one kind crossed the circle (:func:`locate_circle_events`).
SPLITS = 8


def _near_circle(multipliers: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The multipliers of modulus above :data:`NEAR_CIRCLE`, and those of them that are complex with Im mu > 0."""
    near = multipliers[np.abs(multipliers) > NEAR_CIRCLE]
    return near, near[near.imag > COMPLEX_RTOL * np.abs(near)]


def circle_tests(multipliers: np.ndarray) -> dict[str, float]:
    """Test functions of the nontrivial ``multipliers`` that change sign at a period doubling and at a torus.

    Over the multipliers of modulus above :data:`NEAR_CIRCLE` only (the damped ones are not resolved
    on long orbits and cannot cross the circle):

    * ``period_doubling``: Re prod (mu + 1), whose sign is (-1)^(real multipliers below -1): a
      conjugate pair contributes |mu + 1|^2 > 0;
    * ``torus``: prod (1 - |mu|) over the complex ones with Im mu > 0, whose sign is (-1)^(pairs outside
      the circle): a pair inside the circle that turns real leaves the product without changing its sign.
    """
    near, pairs = _near_circle(np.asarray(multipliers))
    return {"period_doubling": float(np.real(np.prod(near + 1.0))), "torus": float(np.prod(1.0 - np.abs(pairs)))}


def critical_multiplier(multipliers: np.ndarray, kind: str) -> complex | None:
    """The multiplier of a ``kind`` event among the nontrivial ``multipliers``: for ``period_doubling`` the real
    negative one nearest -1, for ``torus`` the complex one (Im mu > 0) nearest the unit circle; None where there is none."""
    near, pairs = _near_circle(np.asarray(multipliers))
    if kind == "period_doubling":
        candidates = near[(np.abs(near.imag) <= COMPLEX_RTOL * np.abs(near)) & (near.real < 0)]
        return complex(candidates[np.argmin(np.abs(candidates + 1.0))].real) if candidates.size else None
    return complex(pairs[np.argmin(np.abs(np.abs(pairs) - 1.0))]) if pairs.size else None


def on_circle(multipliers: np.ndarray, kind: str) -> bool:
    """Whether the critical multiplier of a ``kind`` event lies within :data:`CIRCLE_MULTIPLIER` of -1 (a period
    doubling) or of the unit circle (a torus): what confirms a located event."""
    mu = critical_multiplier(multipliers, kind)
    return mu is not None and abs((mu + 1.0) if kind == "period_doubling" else (abs(mu) - 1.0)) < CIRCLE_MULTIPLIER


def event_record(kind: str, moment: float, located: bool, multipliers: np.ndarray) -> dict:
    """An event of :attr:`~.periodic.OrbitBranch.events`: ``kind``, ``moment``, ``located``, the critical
    ``"multiplier"`` as [re, im] (NaN where there is none) and, for a torus, its ``"angle"`` arg mu in (0, pi)."""
    mu = critical_multiplier(multipliers, kind)
    mu = complex(math.nan, math.nan) if mu is None else mu
    record = {"kind": kind, "moment": float(moment), "located": located, "multiplier": [mu.real, mu.imag]}
    if kind == "torus":
        record["angle"] = float(np.angle(mu)) if math.isfinite(mu.real) else math.nan
    return record


def circle_counts(multipliers: np.ndarray) -> tuple[int, int]:
    """How many real multipliers lie below -1 and how many complex pairs outside the unit circle, among those above
    :data:`NEAR_CIRCLE` and classed as :func:`circle_tests` class them: the tests' signs are (-1) to these counts, and a
    count that changes by two or more between two orbits is as many crossings, which the signs alone do not show."""
    near, pairs = _near_circle(np.asarray(multipliers))
    real = near[np.abs(near.imag) <= COMPLEX_RTOL * np.abs(near)]
    return int(np.count_nonzero(real.real < -1.0)), int(np.count_nonzero(np.abs(pairs) > 1.0))


def moment(orbit: Any) -> float:
    """The chain's continuation parameter of an orbit, M: the default ``value`` of :func:`locate_circle_events`."""
    return orbit.moment


def _separated(a: Any, b: Any, solve: Solve, value: Value, splits: int) -> list[Any]:
    """a, the orbits solved at the midpoints in the parameter between a and b until no count of :func:`circle_counts`
    changes by more than one from one to the next (at most ``splits`` halvings), and b."""
    if (
        splits == 0
        or max(abs(x - y) for x, y in zip(circle_counts(a.nontrivial_multipliers), circle_counts(b.nontrivial_multipliers))) <= 1
    ):
        return [a, b]
    try:
        middle = solve(0.5 * (value(a) + value(b)), a, b)
    except (CosseratChainError, RuntimeError, ValueError):
        return [a, b]
    return [*_separated(a, middle, solve, value, splits - 1)[:-1], *_separated(middle, b, solve, value, splits - 1)]


def _polished(root: float, solved: dict, test: Callable[[float], float]) -> float:
    """Brent's ``root`` and one secant step on the test from it and the nearest trial of the other sign, whichever has
    the smaller test: Brent's last step is at least half its tolerance long, so its root lies up to that far off, and
    the critical multiplier, steep in the parameter, farther off -1 (1.7e-8 at the nonlinear chain's period doubling at
    gamma_phi = 0.2, 1.1e-11 off in M); the secant through a bracket of 1e-10 is exact to its square."""
    here = test(root)
    other = [at for at in solved if test(at) * here < 0]
    if here == 0 or not other:
        return root
    near = min(other, key=lambda at: abs(at - root))
    step = root - here * (near - root) / (test(near) - here)
    if not min(root, near) < step < max(root, near):
        return root
    try:
        return step if abs(test(step)) < abs(here) else root
    except (CosseratChainError, RuntimeError, ValueError):
        return root


def _located(kind: str, a: Any, b: Any, solve: Solve, value: Value, tol: float) -> dict | None:
    """The ``kind`` event between a and b, whose test has opposite signs there (:func:`locate_circle_events`)."""
    solved = {value(a): a, value(b): b}

    def test(at: float) -> float:
        if at not in solved:
            solved[at] = solve(at, a, b)
        return circle_tests(solved[at].nontrivial_multipliers)[kind]

    try:
        root = _polished(brentq(test, value(a), value(b), xtol=tol), solved, test)
    except (CosseratChainError, RuntimeError, ValueError):
        # A trial that could not be solved (or a NaN test): the event is reported where its sign change was seen.
        return event_record(kind, value(b), False, b.nontrivial_multipliers)
    orbit = solved[root]
    if not on_circle(orbit.nontrivial_multipliers, kind):
        return None
    return {**event_record(kind, root, True, orbit.nontrivial_multipliers), "accuracy": tol, "orbit": orbit}


def circle_events_between(
    a: Any, b: Any, solve: Solve, *, value: Value = moment, tol: float = MOMENT_TOL, splits: int = SPLITS
) -> list[dict]:
    """The period doublings and tori between two consecutive orbits a and b of a branch, in the order from a to b
    (:func:`locate_circle_events`, whose parameters these are; one step of it). None between two orbits at one value
    of the parameter (no interval to locate in)."""
    if value(a) == value(b):
        return []
    found = []
    pieces = _separated(a, b, solve, value, splits)
    for start, stop in zip(pieces[:-1], pieces[1:], strict=True):
        before, after = circle_tests(start.nontrivial_multipliers), circle_tests(stop.nontrivial_multipliers)
        for kind in CIRCLE_KINDS:
            event = None if before[kind] * after[kind] >= 0 else _located(kind, start, stop, solve, value, tol)
            if event is not None:
                found.append(event)
    return found


def steps(orbits: Sequence[Any], folds: Mapping[int, Any] | None = None) -> list[tuple[int, Any, Any]]:
    """The steps of a branch in which :func:`circle_events_between` looks, each as (the index of the orbit after it, a, b):
    the consecutive pairs of ``orbits``, but a step that holds a located fold in its two halves, from the orbit before
    to the fold's and from the fold's to the orbit after.

    Across a fold the parameter turns: between the step's two orbits the branch passes every value twice or not at
    all, so Brent's method in the parameter has no bracket, and a trial interpolated between them lies on neither side
    (a period doubling 1.2e-5 in I before a fold of a driven chain was reported unlocated, at the step's end); on each
    half the parameter is monotone. ``folds`` maps the index of the orbit after each such step to the fold's orbit (the
    kit's located ``fold`` events). Every branch of rotating orbits searches its steps so: a user system's
    (:func:`~.shooting.continue_orbits`) and the chain's (:func:`~.periodic.continue_orbit`).
    """
    folds = folds or {}
    return [
        (i, a, b)
        for i in range(1, len(orbits))
        for a, b in ([(orbits[i - 1], folds[i]), (folds[i], orbits[i])] if i in folds else [(orbits[i - 1], orbits[i])])
    ]


def locate_circle_events(
    orbits: Sequence[Any],
    solve: Solve,
    *,
    value: Value = moment,
    tol: float = MOMENT_TOL,
    splits: int = SPLITS,
    folds: Mapping[int, Any] | None = None,
) -> list[tuple[int, dict]]:
    """The period doublings and tori between consecutive ``orbits`` of a branch, located in its parameter (module docstring).

    Where a count of :func:`circle_counts` changes by two or more between two orbits (two pairs leaving the circle
    within one step leave the torus test's sign as it was), the step is first halved in the parameter, each midpoint
    solved, until the crossings lie in different pieces (:data:`SPLITS` halvings at most).

    Parameters
    ----------
    orbits : sequence of orbits
        A branch's orbits in order, each with ``nontrivial_multipliers``.
    solve : callable(p, a, b) -> orbit
        The orbit at the parameter value p between the orbits a and b (Newton from their interpolation);
        raises where it cannot (:class:`~cosserat_chain.errors.CosseratChainError`, RuntimeError or ValueError).
    value : callable(orbit) -> float
        The continuation parameter's value at an orbit: M for the chain's (:func:`moment`, the default), any
        named parameter for a system's (:func:`~.shooting.continue_orbits`).
    tol : float
        Brent's tolerance in the parameter, each located event's ``"accuracy"``.
    splits : int
        Most halvings of one step.
    folds : mapping of int to orbit, optional
        The located folds of the branch, each at the index of the orbit after it: the step that holds one is searched
        in its halves on either side of it (:func:`steps`).

    Returns
    -------
    list of (int, dict)
        For each event, in the order of the branch, the index of the orbit after it (it lies between ``orbits[i - 1]``
        and ``orbits[i]``) and its record (:func:`event_record`, ``"moment"`` the parameter's value; a located one with
        ``"accuracy"`` and its ``"orbit"``).
    """
    return [
        (i, event) for i, a, b in steps(orbits, folds) for event in circle_events_between(a, b, solve, value=value, tol=tol, splits=splits)
    ]
