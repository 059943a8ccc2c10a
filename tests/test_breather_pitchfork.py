"""A roto-breather family built to have two symmetric pitchforks at known frequencies: a rotor and a Mathieu oscillator.

One site, two coordinates: an angle phi (a free rotor) and an oscillator x whose stiffness the rotor modulates,

    E = phi'^2 / 2 + x'^2 / 2 + (w0^2 + C cos phi) x^2 / 2.

The energy is even in x, so x = 0 is invariant, and on it the rotor turns uniformly: phi = Omega t exactly, for every
C. Along that family the linearised x obeys Mathieu's equation x'' + (w0^2 + C cos Omega t) x = 0, in tau = Omega t / 2
x_tau_tau + (a - 2 q cos 2 tau) x = 0 with a = 4 w0^2 / Omega^2, q = -2 C / Omega^2. Its multipliers over the orbit's
period (tau's pi) pass through +1 where a pi-periodic Mathieu function exists: a = a_2(q) or b_2(q) near Omega = w0
(a_2, b_2 even in q). Between the two the pair is real: the family is unstable, and at each end a family of orbits with
x != 0 branches off (a pitchfork: its mirror image x -> -x is an orbit too). SciPy's Mathieu characteristic values
give the two frequencies to round-off, independent of any shooting.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.optimize import brentq
from scipy.special import mathieu_a, mathieu_b

from conftest import SYSTEMS_CACHE
from cosserat_chain.experiments import system_breathers as sb
from cosserat_chain.numerics.shooting import flow
from cosserat_chain.systems.lattice import LatticeSystem

C, W0 = 0.3, 1.0


@pytest.fixture(autouse=True)
def _cache(monkeypatch):
    """The compiled systems go to the tests' cache folder (compiled once, not every session), not the user's."""
    monkeypatch.setenv("COSSERAT_CHAIN_CACHE", str(SYSTEMS_CACHE))


def rotor_mathieu() -> LatticeSystem:
    return LatticeSystem(
        sites=1, dofs=("phi", "x"), site_energy="(w0**2 + C*cos(phi))*x**2/2", bond_energy="0", damping="gamma",
        parameters={"C": C, "w0": W0, "gamma": 0.0}, name="rotor_mathieu",
    )  # fmt: skip


def tongue_edge(characteristic) -> float:
    """The Omega near w0 with 4 w0^2 / Omega^2 = a_2(2 C / Omega^2) (or b_2)."""
    return brentq(lambda w: 4 * W0**2 / w**2 - characteristic(2, 2 * C / w**2), 0.9, 1.1, xtol=1e-15)


def test_the_kit_locates_both_pitchforks_of_the_family_at_the_mathieu_tongue_edges():
    """From Omega = 1.1 down to 0.9: the kit's driver reports two branch points, each within its accuracy (half the
    relocation's bracket, 1e-9) of the Mathieu edge; the two changes of stability, located by the collision's
    discriminant, lie within 1e-12 of them and within their accuracy (1e-11), and each branch point carries its
    change's value; the family keeps x = 0 to round-off, unstable between the edges (a real pair), stable outside."""
    upper, lower = tongue_edge(mathieu_b), tongue_edge(mathieu_a)
    assert 0.98 < lower < 0.99 < 1.0 < upper < 1.01
    family = sb.roto_breather_family(rotor_mathieu(), 1.1, to=0.9)
    x = family.system.coordinates.index("x_0")
    assert max(np.max(np.abs(o.y0[[x, family.system.size + x]])) for o in family.orbits) < 1e-12
    assert max(abs(o.v0[0] - w) for o, w in zip(family.orbits, family.omegas, strict=True)) < 1e-10  # phi = Omega t

    kinds = [e.kind for e in family.events]
    assert kinds == ["branch_point", "branch_point"]
    for event, edge in zip(family.events, (upper, lower), strict=True):
        assert 0 < event.accuracy < 1e-8
        assert abs(event.value - edge) <= event.accuracy
        assert event.as_dict()["accuracy"] == event.accuracy
        # Its pair through +1 by the collision's discriminant: the same point, 1e-4 times more accurately.
        value, accuracy = event.discriminant
        assert abs(value - edge) <= accuracy < 1e-10
        assert event.as_dict()["discriminant_value"] == value

    lost, regained = family.changes
    for change, edge in ((lost, upper), (regained, lower)):
        assert change.kind == "+1" and change.method == "discriminant"
        assert abs(change.omega - edge) <= change.accuracy < 1e-10
        assert abs(change.omega - edge) < 1e-12
    assert lost.unstable_omega < lost.stable_omega and regained.stable_omega < regained.unstable_omega
    inside = (family.omegas < lower) | (family.omegas > upper)
    stable = np.array([o.stable for o in family.orbits])
    assert np.array_equal(stable, inside)
    for o in np.array(family.orbits)[~stable]:
        assert np.min(np.abs(o.nontrivial_multipliers.imag)) < 1e-9  # a real pair, not a quartet
    summary = family.as_dict()
    assert [e["kind"] for e in summary["events"]] == kinds


def test_the_branch_breaks_the_mirror_symmetry_and_its_image_is_an_orbit():
    """The family followed from the upper edge (``branches``): x grows from 0 along the branch, and the mirror image
    (x, x') -> (-x, -x') of a branch orbit closes over its period under the flow (the pitchfork's other half)."""
    family = sb.roto_breather_family(rotor_mathieu(), 1.1, to=0.9, arclength=True, branches=True)
    first = next(e for e in family.events if e.kind == "branch_point")
    assert abs(first.value - tongue_edge(mathieu_b)) <= first.accuracy
    branch = first.branch
    assert len(branch) >= 5
    x = family.system.coordinates.index("x_0")
    n = family.system.size
    size = np.array([max(abs(o.y0[x]), abs(o.y0[n + x])) for o in branch])
    assert size[0] > 1e-3 and np.all(np.diff(size[:5]) > 0)
    orbit = branch[4]
    image = orbit.y0.copy()
    image[[x, n + x]] *= -1
    end = flow(orbit.system, image, orbit.period, variations=False)[0]
    shift = np.concatenate([2 * math.pi * orbit.turns, np.zeros(n)])
    assert np.max(np.abs(end - image - shift)) < 1e-8


def test_the_natural_family_reports_its_fold_in_the_frequency_and_no_change_of_stability_across_it():
    """The Takeno-Peyrard one-site family of three sites at C = 0.02, from Omega = 0.9 up: it turns back at a fold in
    Omega (docs: 0.96531910) and comes down again. The family in the period reports the fold (the fixed-frequency
    Newton system singular there, to round-off) and the branch point just before it; no member lies beyond the fold,
    and no change of stability is bisected across it (the period is not a coordinate there)."""
    from cosserat_chain.systems import takeno_peyrard

    family = sb.roto_breather_family(takeno_peyrard(3, C=0.02), 0.9, to=0.97)
    fold = next(e for e in family.events if e.kind == "fold")
    assert fold.value == pytest.approx(0.96531910, abs=2e-8) and fold.accuracy < 1e-7
    assert fold.singular_value < 1e-14
    assert np.max(family.omegas) <= fold.value + fold.accuracy
    assert family.omegas[-1] < family.omegas[fold.index - 1]  # it came back down
    assert sorted(e.kind for e in family.events) == ["branch_point", "fold"]
    # No change across the fold; on the way down both members about Omega = 0.92 are unstable, a second pair leaving
    # at -1 there: the pairs' counts see it (a stable/unstable flag did not).
    (change,) = family.changes
    assert change.kind == "-1" and change.method == "discriminant" and 0.918 < change.omega < 0.924
    assert family.energy_extrema() == []  # the energy goes on through the fold: dE/dOmega turns with Omega, not with E
