"""``OrbitBranch.stability_lost_at``: a located event between the last stable and the first unstable orbit gives
the moment; without one, the largest multiplier's modulus interpolated to 1 (the collocation's long steps put the
sine chain's period doubling at gamma_phi = 0.15 at 0.17269 by interpolation, located at 0.1728824)."""

from __future__ import annotations

from types import SimpleNamespace

import pytest

from cosserat_chain.numerics.periodic import OrbitBranch


def branch(events):
    # Moduli 0.9 at M = 0.2, 1.1 at M = 0.1: the interpolation says 0.15.
    orbits = [
        SimpleNamespace(moment=m, stable=r < 1, max_multiplier=r, trivial_multiplier=1.0)
        for m, r in ((0.3, 0.5), (0.2, 0.9), (0.1, 1.1), (0.05, 1.5))
    ]
    return OrbitBranch(orbits, "moment_min", 0.05, "", events=events)


def test_without_a_located_event_the_modulus_is_interpolated_to_one():
    assert branch([]).stability_lost_at == pytest.approx(0.15, rel=1e-14)
    # An unlocated event, an event of another kind or one outside the stable-unstable pair does not count.
    others = [
        {"kind": "period_doubling", "moment": 0.17, "located": False},
        {"kind": "fold", "moment": 0.12},
        {"kind": "torus", "moment": 0.25, "located": True},
    ]
    assert branch(others).stability_lost_at == pytest.approx(0.15, rel=1e-14)


@pytest.mark.parametrize("kind", ["period_doubling", "torus", "branch_point"])
def test_a_located_event_between_the_last_stable_and_first_unstable_orbit_gives_the_moment(kind):
    event = {"kind": kind, "moment": 0.1728824, **({} if kind == "branch_point" else {"located": True})}
    assert branch([event]).stability_lost_at == 0.1728824


def test_a_branch_that_starts_unstable_or_stays_stable_has_none():
    stable = OrbitBranch(
        [SimpleNamespace(moment=m, stable=True, max_multiplier=0.5, trivial_multiplier=1.0) for m in (0.3, 0.2)], "moment_min", 0.2, ""
    )
    assert stable.stability_lost_at is None


def test_orbits_whose_trivial_multiplier_is_lost_decide_nothing():
    # The same branch with the trivial multiplier of the orbit at M = 0.1 off by 0.3 (a long orbit on a coarse mesh,
    # its other multipliers as wrong): the loss of stability is read up to M = 0.2 only, where it is still stable.
    lost = branch([])
    lost.orbits[2].trivial_multiplier = 1.3
    assert lost.stability_lost_at is None
    # Off by the resolution's bound, not beyond it, the orbit still counts.
    lost.orbits[2].trivial_multiplier = 1.0 + 0.99e-2
    assert lost.stability_lost_at == pytest.approx(0.15, rel=1e-14)
