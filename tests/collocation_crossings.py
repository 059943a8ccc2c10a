"""The collocation branches over a loss of stability that several test modules check, computed once a session.

``tests/test_collocation_events.py`` locates the event of each branch against the shooting, and
``tests/test_collocation_switching.py`` switches at the period doubling of the gamma_phi = 0.15 one:
the same shooting branch and the same collocation branch (most of either module's CPU is the
branch's Floquet multipliers), so they share them here (the shooting's branch is ``tests/cycle_ends.py``'s).
"""

from __future__ import annotations

import functools

from cosserat_chain import ChainParams
from cosserat_chain.numerics.collocation import CollocationBranch, CollocationOrbit, continue_collocation, find_collocation_orbit
from cycle_ends import shooting_crossing


@functools.cache
def collocation_crossing(params: ChainParams) -> tuple[CollocationOrbit, CollocationBranch]:
    """The collocation start at the shooting's last stable orbit, and the collocation branch from there to a step of
    the shooting below its first unstable one (stable orbits above the crossing, unstable ones below, each branch's
    Floquet multipliers most of its CPU)."""
    branch, index = shooting_crossing(params)
    above = branch.orbits[index - 1]
    start = find_collocation_orbit(params, "sine", above.moment, guess=above)
    below = branch.orbits[index].moment - (branch.orbits[index - 1].moment - branch.orbits[index].moment)
    return start, continue_collocation(start, moment_min=below, period_max=200.0)
