"""Period doublings and tori of cycles: their test functions, and their location between two orbits of a branch.

Contract
--------
An orbit branch loses (or regains) its stability where a nontrivial Floquet multiplier leaves (or
enters) the unit circle: at +1 (a fold or a branch point of cycles, the continuations' own tests),
at -1 (a period doubling) or as a complex pair (a torus, Neimark-Sacker). :func:`circle_tests` are
the two test functions of the multipliers of modulus above :data:`NEAR_CIRCLE` that change sign at
the last two; every branch of rotating orbits watches them between consecutive orbits: the
collocation's (:func:`~.collocation.continue_collocation`, through the kit's secant method on the
arclength) and the shooting's (:func:`~.periodic.continue_orbit`, dense, blocks and Newton-Picard,
through :func:`locate_circle_events` after the branch is traced).

:func:`locate_circle_events` finds the zero of the test that changed sign between two orbits a and b
of a branch by Brent's method in M (:func:`~.brent.brentq`), each trial the orbit re-solved at its M
by the branch's own corrector from the orbit interpolated between a and b (a ``solve`` the caller
passes), to :data:`MOMENT_TOL` in M. The test functions, not the critical multiplier itself, are the
functions whose zero is sought: they are symmetric functions of the multipliers near the circle and
stay continuous where two of them collide (at a period doubling of the paper's chain a complex pair
has just met on the negative real axis, and the multiplier nearest -1 is not a smooth function of M
there; :mod:`~.cycle_curve` says the same of its augmented systems). A zero is kept as an event
where its critical multiplier (:func:`critical_multiplier`) lies within :data:`CIRCLE_MULTIPLIER` of
-1 or of the circle; a sign change without one (a pair outside the circle turning real flips the
torus test) is no event. Where Brent's trials cannot be solved the event is reported unlocated, at
the first orbit past the sign change (the collocation's convention).

Only the multipliers above :data:`NEAR_CIRCLE` enter: on long collocation orbits the strongly damped
ones are not resolved, and Newton-Picard (``newton_picard.RHO`` = 0.5) computes none below rho; a
multiplier crossing the unit circle lies above either bound on both sides of the crossing.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from typing import Any

import numpy as np

from ..errors import CosseratChainError
from .brent import brentq

#: The period-doubling and torus tests take only the multipliers of modulus above this: on long orbits the
#: strongly damped ones are not resolved (docs/collocation.md, Limits), the ones near the circle are.
NEAR_CIRCLE = 0.5
#: A multiplier is complex where |Im mu| exceeds this times |mu|.
COMPLEX_RTOL = 1e-6
#: A located period doubling or torus is confirmed where its critical multiplier lies this close to -1 or to
#: the unit circle (the shooting's ``CONFIRM_TOL``).
CIRCLE_MULTIPLIER = 1e-3
#: The events of :func:`circle_tests`.
CIRCLE_KINDS = ("period_doubling", "torus")
#: Brent's tolerance in M of an event located by :func:`locate_circle_events` (reported as its ``"accuracy"``).
MOMENT_TOL = 1e-10


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


def locate_circle_events(
    orbits: Sequence[Any], solve: Callable[[float, Any, Any], Any], *, tol: float = MOMENT_TOL
) -> list[tuple[int, dict]]:
    """The period doublings and tori between consecutive ``orbits`` of a branch, located in M (module docstring).

    Parameters
    ----------
    orbits : sequence of orbits
        A branch's orbits in order, each with ``moment`` and ``nontrivial_multipliers``.
    solve : callable(moment, a, b) -> orbit
        The orbit at ``moment`` between the consecutive orbits a and b (Newton from their interpolation);
        raises where it cannot (:class:`~cosserat_chain.errors.CosseratChainError`, RuntimeError or ValueError).
    tol : float
        Brent's tolerance in M, each located event's ``"accuracy"``.

    Returns
    -------
    list of (int, dict)
        For each event, the index of the orbit after it (it lies between ``orbits[i - 1]`` and ``orbits[i]``)
        and its record (:func:`event_record`; a located one with ``"accuracy"`` and its ``"orbit"``).
    """
    found = []
    tests = [circle_tests(o.nontrivial_multipliers) for o in orbits]
    for i in range(1, len(orbits)):
        a, b = orbits[i - 1], orbits[i]
        for kind in CIRCLE_KINDS:
            if tests[i - 1][kind] * tests[i][kind] >= 0 or a.moment == b.moment:
                continue
            solved = {a.moment: a, b.moment: b}

            def value(moment: float, kind=kind, a=a, b=b, solved=solved) -> float:
                if moment not in solved:
                    solved[moment] = solve(moment, a, b)
                return circle_tests(solved[moment].nontrivial_multipliers)[kind]

            try:
                root = brentq(value, a.moment, b.moment, xtol=tol)
            except (CosseratChainError, RuntimeError, ValueError):
                # A trial that could not be solved (or a NaN test): the event is reported where its sign change was seen.
                found.append((i, event_record(kind, b.moment, False, b.nontrivial_multipliers)))
                continue
            orbit = solved[root]
            if on_circle(orbit.nontrivial_multipliers, kind):
                found.append((i, {**event_record(kind, root, True, orbit.nontrivial_multipliers), "accuracy": tol, "orbit": orbit}))
    return found
