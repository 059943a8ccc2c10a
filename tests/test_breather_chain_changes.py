"""The chain's roto-breather families on the user systems' mechanism: changes of stability at the zero of the
colliding pair's discriminant, folds and branch points by the kit's driver (issue 41).

The cheap case is the sine chain with N = 2 (5 particles, 2 free): from Omega = 6.2 down to 4.8 its family loses
stability at a Krein collision near 5.89 (a complex quartet leaves the circle), regains it near 5.04, and loses it
at +1 near 4.91, where the kit's driver finds no branch point (the pair's passage is the energy-frequency
relation's turn, not a pitchfork). The nonlinear chain's in-band family (N = 3, the paper's damped rotation
landed at gamma = 0) has a pitchfork and a fold (slow).
"""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from typer.testing import CliRunner

from cosserat_chain import ChainParams
from cosserat_chain.cli import app
from cosserat_chain.experiments.breathers import (
    branch_discriminants,
    damped_to_undamped,
    located_changes,
    natural_events,
    roto_breather_family,
)
from cosserat_chain.experiments.system_breathers import TIGHT_CLOSURE, TIGHT_RTOL
from cosserat_chain.numerics.breather_arclength import collision_discriminant, continue_hamiltonian_arclength
from cosserat_chain.numerics.periodic import continue_in_frequency, find_hamiltonian_orbit, find_periodic_orbit


def undamped(**fields) -> ChainParams:
    return ChainParams(gamma_u=0.0, gamma_v=0.0, gamma_phi=0.0, **fields)


@pytest.fixture(scope="module")
def sine_n2():
    return roto_breather_family(undamped(N=2), "sine", [6.2, 6.0, 5.8, 5.2, 5.0, 4.8])


def _tight_discriminant(family, omega: float, kind: str, centre) -> float:
    """D of the member at ``omega`` found, and its multipliers integrated, at the tight tolerances (an independent solve)."""
    near = min(family.family.orbits, key=lambda o: abs(o.omega - omega))
    orbit = find_hamiltonian_orbit(
        near.params, near.model, omega, near, turns=near.turns, particle=near.particle, particle_turns=near.particle_turns,
        tol=TIGHT_CLOSURE, rtol=TIGHT_RTOL, atol=TIGHT_RTOL,
    )  # fmt: skip
    return collision_discriminant(orbit.multipliers, kind, centre)


def test_every_change_between_members_is_located_by_the_discriminant_inside_the_moduli_bisections_bound(sine_n2):
    changes = sine_n2.changes
    orbits = sine_n2.family.orbits
    # One change per pair of neighbouring members of opposite stability, in the order followed.
    flips = [(a.omega, b.omega) for a, b in zip(orbits[:-1], orbits[1:], strict=True) if a.stable != b.stable]
    assert len(changes) == len(flips) == 3
    assert [c.kind for c in changes] == ["complex", "complex", "+1"]
    for change, (high, low) in zip(changes, flips, strict=True):
        assert low < change.omega < high
        assert change.method == "discriminant" and change.accuracy is not None
        # The moduli's bisection agrees within its own (splitting-law) bound, which is far wider than the discriminant's.
        assert abs(change.omega - change.moduli_omega) <= change.moduli_accuracy
        assert change.accuracy < 1e-3 * change.moduli_accuracy
        # The bisection's bracket holds the change, the stable side on the side the members say.
        assert min(change.stable_omega, change.unstable_omega) - change.accuracy <= change.omega
        assert change.omega <= max(change.stable_omega, change.unstable_omega) + change.accuracy


def test_the_accuracy_is_confirmed_by_orbits_solved_again_at_the_tight_tolerance(sine_n2):
    """D of independent tight solves changes sign across [omega - 2 accuracy, omega + 2 accuracy], and not between the
    moduli's middle and its mirror image about it: a location off by the bisection's error would fail."""
    first = sine_n2.family.orbits[0]
    for change in sine_n2.changes:
        centre = None
        if change.kind == "complex":
            # A Krein collision's centre: the point of the circle where the pair meets, from a tight solve at the change.
            near = min(sine_n2.family.orbits, key=lambda o: abs(o.omega - change.omega))
            orbit = find_hamiltonian_orbit(first.params, "sine", change.omega, near, tol=TIGHT_CLOSURE, rtol=TIGHT_RTOL, atol=TIGHT_RTOL)
            mu = orbit.nontrivial_multipliers
            centre = complex(np.exp(1j * abs(np.angle(mu[np.argmax(np.abs(mu))]))))
        d_below = _tight_discriminant(sine_n2, change.omega - 2 * change.accuracy, change.kind, centre)
        d_above = _tight_discriminant(sine_n2, change.omega + 2 * change.accuracy, change.kind, centre)
        assert d_below * d_above < 0
        mirror = 2 * change.moduli_omega - change.omega
        lo, hi = sorted((change.moduli_omega, mirror))
        assert hi - lo > 4 * change.accuracy
        d_lo = _tight_discriminant(sine_n2, lo + change.accuracy, change.kind, centre)
        d_hi = _tight_discriminant(sine_n2, hi - change.accuracy, change.kind, centre)
        assert d_lo * d_hi > 0


def test_a_change_at_plus_one_without_a_branch_point_reports_no_event(sine_n2):
    """The +1 change near 4.91: the kit's driver traced between its two members finds no branch point, so the
    natural family's events are empty (the pair's passage through +1 is not a pitchfork there)."""
    assert sine_n2.changes[-1].kind == "+1"
    assert sine_n2.events == []
    summary = sine_n2.as_dict()
    assert summary["events"] == [] and len(summary["stability_changes"]) == 3
    assert summary["stability_changes"][0]["resonance"]["band"] in sine_n2.bands


def test_locating_changes_the_members_nothing():
    """The family's members are those of the old path (natural steps at the frequencies asked for), bit for bit."""
    params = undamped(N=2)
    located = roto_breather_family(params, "sine", [6.0, 5.8])
    plain = roto_breather_family(params, "sine", [6.0, 5.8], locate=False)
    assert plain.changes == [] and plain.events is None
    for a, b in zip(located.family.orbits, plain.family.orbits, strict=True):
        assert np.array_equal(a.x, b.x) and np.array_equal(a.v, b.v) and np.array_equal(a.multipliers, b.multipliers)
    assert located_changes(plain.family.orbits, plain.bands)[0].omega == located.changes[0].omega


def test_cli_prints_and_writes_the_located_changes(tmp_path):
    config = tmp_path / "chain.toml"
    config.write_text("N = 2\n")
    base = ["breathers", "--model", "sine", "--omega", "6.0", "--to", "5.8", "--steps", "2", "--config", str(config)]
    text = CliRunner().invoke(app, base)
    assert text.exit_code == 0, text.output
    assert "stability lost going down at Omega = 5.8936510" in text.output and "+- " in text.output
    result = CliRunner().invoke(app, [*base, "--json"])
    assert result.exit_code == 0, result.output
    change = json.loads(result.output)["stability_changes"][0]
    assert change["method"] == "discriminant" and change["omega"] == pytest.approx(5.89365109, abs=1e-8)
    assert change["accuracy"] < 1e-8 and change["moduli_accuracy"] > 1e-6


@pytest.fixture(scope="module")
def in_band():
    """The in-band nonlinear family (N = 3) the paper's damped rotation (gamma = 0.1, M = 0.30) lands on."""
    damped = find_periodic_orbit(ChainParams(gamma_u=0.1, gamma_v=0.1, gamma_phi=0.1), "nonlinear", 0.30)
    return damped_to_undamped(damped).landed


@pytest.mark.slow
def test_the_chains_branch_point_by_arclength_carries_its_discriminants_zero(in_band):
    """The pitchfork before the fold (Omega = 1.3763283): the zero of its pair's discriminant agrees with the kit's
    relocation (24 bisections on the pair's test) within the two accuracies, and is closer than either's bracket."""
    arc = continue_hamiltonian_arclength(in_band, 1.2, 1.45, max_points=40, branches=True)
    zeros = branch_discriminants(arc)
    (index,) = [i for i, e in enumerate(arc.events) if e.kind == "branch_point"]
    omega, accuracy = zeros[index]
    relocated = arc.branches[index]
    assert accuracy < 1e-10
    assert abs(omega - relocated.point.omega) <= accuracy + relocated.accuracy
    assert omega < arc.folds[0].parameter


@pytest.mark.slow
def test_the_natural_family_reports_the_branch_point_and_the_fold_that_stop_it(in_band):
    """Natural steps up in Omega from the landed orbit stop before the fold at 1.3767878; the kit's driver from the
    last member finds the pitchfork (at its discriminant's zero) and the fold, each with its accuracy."""
    grid = np.round(np.arange(1.36, 1.3801, 0.005), 6)
    start = continue_in_frequency(in_band, [in_band.omega, 1.36]).orbits[-1]
    family = continue_in_frequency(start, grid)
    assert not family.complete and family.orbits[-1].omega < 1.3763283
    events = natural_events(family.orbits, family.requested)
    kinds = [e["kind"] for e in events]
    assert kinds == ["branch_point", "fold"]
    branch, fold = events
    assert branch["omega"] == pytest.approx(1.3763282566, abs=1e-9) and branch["accuracy"] < 1e-9
    assert abs(branch["kit_omega"] - branch["omega"]) < 1e-6
    assert fold["omega"] == pytest.approx(1.3767878, abs=1e-6) and fold["accuracy"] is not None and fold["accuracy"] < 1e-5
    assert branch["between"] == fold["between"] == [len(family.orbits) - 1, None]
    assert math.isfinite(fold["energy"])


@pytest.mark.slow
def test_a_systems_arclength_branch_points_carry_their_discriminants_zero_at_the_mathieu_edges(monkeypatch, tmp_path):
    """``--arclength`` for a user system: each branch point of the rotor-Mathieu family (test_breather_pitchfork) gets
    the zero of its pair's discriminant, within its accuracy of SciPy's Mathieu edge (round-off there), where the
    relocation's bisection gives its bracket's half-width."""
    from scipy.special import mathieu_a, mathieu_b

    from cosserat_chain.experiments import system_breathers as sb
    from test_breather_pitchfork import rotor_mathieu, tongue_edge

    monkeypatch.setenv("COSSERAT_CHAIN_CACHE", str(tmp_path / "cache"))
    family = sb.roto_breather_family(rotor_mathieu(), 1.1, to=0.9, arclength=True)
    points = [e for e in family.events if e.kind == "branch_point"]
    assert len(points) == 2
    for event, edge in zip(points, (tongue_edge(mathieu_b), tongue_edge(mathieu_a)), strict=True):
        omega, accuracy = event.discriminant
        assert accuracy < 1e-9
        assert abs(omega - edge) <= accuracy + 1e-13
        assert abs(omega - event.value) <= accuracy + event.accuracy
        assert event.as_dict()["discriminant_value"] == omega


def test_the_family_figure_marks_each_located_change(sine_n2):
    import matplotlib

    matplotlib.use("Agg")
    from cosserat_chain.plots.breathers import breather_family_figure

    fig = breather_family_figure(sine_n2)
    dashed = [line.get_xdata()[0] for line in fig.axes[1].get_lines() if line.get_linestyle() == "--"]
    assert dashed == [change.omega for change in sine_n2.changes]


def test_a_member_the_driver_cannot_start_from_is_reported_untraced(monkeypatch):
    """Where the family ends early and its last member does not correct as the driver's start, the events say so
    (kind ``untraced`` with the kit's message) instead of failing the whole family."""
    from cosserat_chain.experiments import breathers
    from cosserat_chain.numerics.kit import StartError

    family = roto_breather_family(undamped(N=1), "sine", [6.0], locate=False)

    def refuse(*args, **kwargs):
        raise StartError("the start is not on the branch: the corrector diverged with max|R| = 1")

    monkeypatch.setattr(breathers, "continue_hamiltonian_arclength", refuse)
    (event,) = natural_events(family.family.orbits, np.array([6.0, 6.2]))
    assert event["kind"] == "untraced" and event["between"] == [0, None] and "not on the branch" in event["message"]
