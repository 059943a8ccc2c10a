"""The sine chain's one-turn branch down from 1.1 M_c to its first unstable orbit, and the end located there, computed
once a session for every test module that starts from them.

``tests/test_cycle_curve.py``, ``tests/test_cycle_curve_codim2.py``, ``tests/test_diagram_codim2.py``,
``tests/test_cycle_switching.py`` and the collocation modules (``tests/collocation_crossings.py``) each traced the
same branch (most of its CPU the orbits' monodromies) for the same chains; the branch and the located end are
deterministic functions of the chain, and no test changes them.
"""

from __future__ import annotations

import functools

import numpy as np

from cosserat_chain import ChainParams
from cosserat_chain.numerics.continuation import locate_fold
from cosserat_chain.numerics.cycle_curve import locate_cycle_end
from cosserat_chain.numerics.periodic import OrbitBranch, PeriodicOrbit, continue_orbit, find_periodic_orbit


@functools.cache
def shooting_crossing(params: ChainParams) -> tuple[OrbitBranch, int]:
    """The shooting's branch down from 1.1 M_c to its first unstable orbit (traced no further), and that orbit's
    index."""
    start = find_periodic_orbit(params, "sine", 1.1 * locate_fold(params, "sine").moment)
    branch = continue_orbit(start, period_max=100.0, until_unstable=True)
    return branch, int(np.argmin(branch.stable))


def around_loss(params: ChainParams) -> list[PeriodicOrbit]:
    """The branch's last stable and first unstable orbit."""
    branch, index = shooting_crossing(params)
    return branch.orbits[index - 1 : index + 1]


@functools.cache
def located_end(params: ChainParams, kind: str) -> PeriodicOrbit:
    """The end of ``kind`` located from the orbits around the loss of stability."""
    return locate_cycle_end(around_loss(params), kind)
