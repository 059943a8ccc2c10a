"""The collocation branches over a loss of stability that several test modules check, computed once a session.

``tests/test_collocation_events.py`` locates the event of each branch against the shooting, and
``tests/test_collocation_switching.py`` switches at the period doubling of the gamma_phi = 0.15 one:
the same shooting branch and the same collocation branch (most of either module's CPU is the
branch's Floquet multipliers), so they share them here.
"""

from __future__ import annotations

import functools

import numpy as np

from cosserat_chain import ChainParams
from cosserat_chain.numerics.collocation import CollocationBranch, CollocationOrbit, continue_collocation, find_collocation_orbit
from cosserat_chain.numerics.continuation import locate_fold
from cosserat_chain.numerics.periodic import OrbitBranch, continue_orbit, find_periodic_orbit


@functools.cache
def shooting_crossing(params: ChainParams) -> tuple[OrbitBranch, int]:
    """The shooting's branch down from 1.1 M_c to its first unstable orbit, and the index of that orbit."""
    start = find_periodic_orbit(params, "sine", 1.1 * locate_fold(params, "sine").moment)
    branch = continue_orbit(start, period_max=100.0, until_unstable=True)
    return branch, int(np.argmin(branch.stable))


@functools.cache
def collocation_crossing(params: ChainParams) -> tuple[CollocationOrbit, CollocationBranch]:
    """The collocation start two stable shooting orbits above the loss of stability, and the collocation branch from
    there to two steps of the shooting below it."""
    branch, index = shooting_crossing(params)
    above = branch.orbits[index - 2]
    start = find_collocation_orbit(params, "sine", above.moment, guess=above)
    below = branch.orbits[index].moment - 2 * (branch.orbits[index - 1].moment - branch.orbits[index].moment)
    return start, continue_collocation(start, moment_min=below, period_max=200.0)
