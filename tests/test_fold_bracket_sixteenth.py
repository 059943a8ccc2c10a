"""A collocation branch's fold confirmed from its step's two orbits where the located orbit's multipliers are lost.

Next to a saddle-focus (the three junctions' snake beyond its eighth fold) the monodromy's norm is 1e14 ... 1e20 and
the located orbit shows no second multiplier at +1 (its trivial one lost too); the two orbits that bracket the turn
still tell on which side of +1 theirs lie, and a real multiplier through +1 between them is the fold's signature (the shooting's test,
``periodic._crosses_one``). A turn without such a crossing stays unconfirmed; a period doubling's -1 or a complex pair
does not count; an orbit whose trivial multiplier is lost, or off by more than its distance to +1 of another, decides nothing.
"""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np

from cosserat_chain.numerics.collocation import _BranchProblem, _crossing_between


def orbit(*nontrivial: complex) -> SimpleNamespace:
    multipliers = np.array([1.0, *nontrivial], dtype=complex)
    return SimpleNamespace(
        multipliers=multipliers,
        profile=np.zeros((3, multipliers.size)),
        trivial_multiplier=complex(multipliers[0]),
        nontrivial_multipliers=multipliers[1:],
    )


def problem(step) -> _BranchProblem:
    return _BranchProblem(collocation=None, template=None, moment_range=(0.0, 1.0), period_max=100.0, step=step)


def test_a_real_multiplier_through_one_between_the_steps_orbits_is_the_crossing():
    assert _crossing_between(orbit(0.97, -3e6, 0.2 + 0.1j, 0.2 - 0.1j), orbit(1.04, -3e6, 0.2 + 0.1j, 0.2 - 0.1j))
    # Both on one side, or a multiplier through -1, or a complex pair through the circle: no crossing of +1.
    assert not _crossing_between(orbit(0.97, 4.0), orbit(0.95, 5.0))
    assert not _crossing_between(orbit(-0.97, 0.5), orbit(-1.03, 0.5))
    assert not _crossing_between(orbit(0.9 + 0.3j, 0.9 - 0.3j), orbit(1.0 + 0.3j, 1.0 - 0.3j))
    # An orbit whose trivial multiplier is lost (or whose multipliers are not all known) decides nothing.
    lost = orbit(1.04, 3.0)
    lost.trivial_multiplier = 1.3
    assert not _crossing_between(orbit(0.97, 3.0), lost)
    partial = orbit(1.04)
    partial.profile = np.zeros((3, 4))
    assert not _crossing_between(orbit(0.97), partial)
    # Off by 0.017 (the junctions' thirteenth fold) with the others far from +1 it still tells their side; a nontrivial
    # one within twice that error of +1 it does not.
    rough = orbit(7.7e6, -1.25e20, 2.4e-16)
    rough.trivial_multiplier = 1.017
    assert _crossing_between(orbit(-4.6e8, -1.3e19, 1.1e-15), rough)
    near = orbit(1.03, -1.25e20)
    near.trivial_multiplier = 1.017
    assert not _crossing_between(orbit(0.97, -1.3e19), near)


def test_a_fold_is_confirmed_by_its_located_orbit_or_by_its_bracket():
    garbage = orbit(-1.4e14, -1.46, -0.73)  # the located orbit at the junctions' ninth fold (200 x 7)
    garbage.trivial_multiplier = 3e-12
    crossing = (orbit(0.97, -1.5e6), orbit(1.03, -1.2e6))
    assert problem(crossing).confirm("fold", garbage)
    assert not problem((orbit(0.97, -1.5e6), orbit(0.96, -1.2e6))).confirm("fold", garbage)
    assert not problem(None).confirm("fold", garbage)
    # A branch point is not confirmed by the bracket (a multiplier through +1 where the parameter does not turn is
    # the located orbit's to show); a located orbit with its pair at +1 confirms either.
    assert not problem(crossing).confirm("branch_point", garbage)
    assert problem(None).confirm("fold", orbit(1.0 + 1e-4, 0.5))
