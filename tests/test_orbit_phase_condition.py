"""The shooting's phase condition cannot go singular, and a fold of cycles needs its multiplier at +1 (issue 40, item 1).

The case: the N = 2 sine chain at gamma_phi = 0.15 (other fields default). Its loaded particle backs
up after each turn, so phi_0 crosses the old section phi_0 = 0 three times a period; where two
crossings merge (M = 0.18223) the section's Newton system is singular and it reported a fold of
cycles there, although the orbit goes on, stable, to a real fold at M = 0.1803666.
"""

from __future__ import annotations

import dataclasses
import json
import math

import numpy as np
import pytest
from typer.testing import CliRunner

from cosserat_chain import ChainParams, moment_load
from cosserat_chain.cli import app
from cosserat_chain.experiments.diagram import _lower_edge, state_diagram
from cosserat_chain.models import get_model
from cosserat_chain.numerics import periodic, shooting
from cosserat_chain.numerics.adaptive import integrate_adaptive
from cosserat_chain.numerics.continuation import locate_fold
from cosserat_chain.numerics.cycle_curve import locate_cycle_end
from cosserat_chain.numerics.periodic import _System, _to_y, continue_orbit, find_periodic_orbit
from cosserat_chain.systems import pen

CHAIN = ChainParams(N=2, gamma_phi=0.15)
#: Where the section's system was singular: the old code's fold of cycles.
FALSE_FOLD = 0.18223
#: The real fold of cycles (located by the augmented shooting system on the phase plane).
FOLD = 0.1803666


@pytest.fixture(scope="module")
def branch():
    start = find_periodic_orbit(CHAIN, "sine", 1.1 * locate_fold(CHAIN, "sine").moment)
    return continue_orbit(start, period_max=100.0)


def test_the_orbit_is_continued_past_the_sections_false_fold_to_a_real_one(branch):
    assert branch.end == "fold"
    assert branch.end_moment == pytest.approx(FOLD, abs=2e-6)
    below = [o for o in branch.orbits if o.moment < FALSE_FOLD - 1e-3]
    assert below and all(o.phase_normal is not None for o in below)  # on the plane normal to the flow
    assert "tangent to the section" in branch.message
    # The turn is a fold of cycles: a real nontrivial multiplier crosses +1 between the two orbits around it.
    mu_before, mu_after = (o.nontrivial_multipliers for o in branch.orbits[-2:])
    real_before = mu_before[np.abs(mu_before.imag) < 1e-9].real
    real_after = mu_after[np.abs(mu_after.imag) < 1e-9].real
    assert np.sum(real_before > 1.0) + 1 == np.sum(real_after > 1.0)
    assert branch.events == []  # no branch point of cycles on the way


def test_the_located_fold_has_a_second_multiplier_at_plus_one(branch):
    end = locate_cycle_end(branch.orbits[-3:], "fold_of_cycles")
    assert end.moment == pytest.approx(FOLD, abs=1e-7)
    nearest = np.sort(np.abs(end.multipliers - 1.0))
    assert nearest[1] < 1e-4 < nearest[2]  # the trivial multiplier and the fold's, nothing else near +1


def test_the_sections_singular_point_is_not_taken_for_a_fold(branch):
    # The old section imposed as a plane of normal e_phi0 through an orbit on phi_0 = 0 at M = 0.1824, where
    # the flow crosses it at a small angle: Newton on the augmented system converges to where the section's
    # system is singular (the old "fold" at 0.18223), which has no multiplier at +1, and is refused.
    on_section = [o for o in branch.orbits if o.phase_normal is None][-1]
    orbit = find_periodic_orbit(CHAIN, "sine", 0.1824, guess=on_section)
    assert orbit.phase_normal is None and orbit.x[2, CHAIN.N] == 0.0
    section = np.zeros(2 * orbit.x[:, 1:-1].size)
    section[_System(CHAIN, get_model("sine"), orbit.moment, orbit.particle).load_dof] = 1.0
    with pytest.raises(ValueError, match="no second Floquet multiplier at \\+1"):
        locate_cycle_end([dataclasses.replace(orbit, phase_normal=section)], "fold_of_cycles")
    # With the phase condition the package chooses there, the same start reaches the real fold.
    assert locate_cycle_end([orbit], "fold_of_cycles").moment == pytest.approx(FOLD, abs=1e-7)


def test_a_direct_run_below_the_old_end_keeps_rotating_on_the_orbit(branch):
    # Independent of the shooting: an adaptive run from the orbit at M = 0.181 (below the old false end)
    # turns with the orbit's mean rate and returns to its start after whole periods.
    orbit = min(branch.orbits, key=lambda o: abs(o.moment - 0.181))
    assert FOLD < orbit.moment < FALSE_FOLD - 1e-3 and orbit.stable
    periods = 20
    run = integrate_adaptive(
        CHAIN, "sine", moment_load(orbit.moment), t_end=periods * orbit.period, x0=orbit.x, v0=orbit.v, n_frames=2, rtol=1e-12, atol=1e-13
    )
    advance = run.x[-1, 2, CHAIN.N] - orbit.x[2, CHAIN.N]
    assert advance / run.time[-1] == pytest.approx(orbit.mean_angular_velocity, rel=1e-6)
    shift = np.zeros_like(orbit.x)
    shift[2, CHAIN.N] = 2 * math.pi * periods
    np.testing.assert_allclose(run.x[-1], orbit.x + shift, atol=1e-6)
    np.testing.assert_allclose(run.v[-1], orbit.v, atol=1e-6)


def test_the_diagram_reports_the_real_fold(tmp_path):
    config = tmp_path / "N2.toml"
    config.write_text("N = 2\n")
    result = CliRunner().invoke(
        app, ["diagram", "--model", "sine", "--vary", "gamma_phi", "--values", "0.15", "--config", str(config), "--json"]
    )
    assert result.exit_code == 0, result.output
    row = json.loads(result.output[result.output.index("{") :])["rows"][0]
    assert row["end"] == "fold_of_cycles" and row["method"] == "located"
    assert row["rotation_stops"] == pytest.approx(FOLD, abs=1e-7)


def test_period_and_multipliers_do_not_depend_on_the_phase_condition():
    # The paper's chain at M = 0.22, where the section phi_0 = 0 is regular: the values of the section
    # (as before this change: period 9.491187724911082, largest nontrivial |mu| 0.6221591279520509) and
    # those of a phase plane through a point a third of a period on agree.
    section = find_periodic_orbit(ChainParams(), "sine", 0.22)
    assert section.phase_normal is None and section.x[2, ChainParams().N] == 0.0
    assert section.period == pytest.approx(9.491187724911082, rel=1e-9)
    assert section.max_multiplier == pytest.approx(0.6221591279520509, rel=1e-9)
    x, v = section.trajectory(np.array([section.period / 3]))
    system = _System(section.params, get_model("sine"), section.moment, section.particle)
    later = _to_y(section.params, x[0], v[0])
    normal = system.velocity(later)
    guess = dataclasses.replace(section, x=x[0], v=v[0], phase_normal=normal / np.linalg.norm(normal))
    plane = find_periodic_orbit(ChainParams(), "sine", 0.22, guess=guess)
    assert plane.phase_normal is not None and plane.as_dict()["phase_condition"] == "plane"
    assert plane.period == pytest.approx(section.period, rel=1e-9)
    np.testing.assert_allclose(np.sort_complex(plane.multipliers), np.sort_complex(section.multipliers), atol=1e-9)


@pytest.fixture(scope="module")
def nonlinear_one():
    """The nonlinear N = 1 chain's 1-turn orbit at M = 0.3, whose real multiplier crosses +1 at M = 0.29772 and back
    at 0.29503 while M goes on falling: two branch points of cycles, no fold."""
    return find_periodic_orbit(ChainParams(N=1), "nonlinear", 0.3)


def test_a_multiplier_through_plus_one_without_a_turn_is_a_branch_point(nonlinear_one):
    branch = continue_orbit(nonlinear_one, moment_min=0.294)
    assert branch.end == "moment_min" and np.all(np.diff(branch.moment) < 0)
    moments = [event["moment"] for event in branch.events]
    assert [event["kind"] for event in branch.events] == ["branch_point", "branch_point"]
    assert moments == pytest.approx([0.29772, 0.29503], abs=2e-4)
    # Independent: orbits found on their own by Newton just above and below each have a real multiplier on
    # either side of +1 (unstable between the two).
    guess = nonlinear_one
    for moment, unstable_below in zip(moments, (True, False)):
        above = find_periodic_orbit(ChainParams(N=1), "nonlinear", moment + 3e-4, guess=guess)
        below = find_periodic_orbit(ChainParams(N=1), "nonlinear", moment - 3e-4, guess=above)
        real_above, real_below = (o.nontrivial_multipliers.real[np.abs(o.nontrivial_multipliers.imag) < 1e-9] for o in (above, below))
        assert (np.max(real_below) > 1.0 > np.max(real_above)) == unstable_below
        assert (np.max(real_above) > 1.0 > np.max(real_below)) != unstable_below
        guess = below


def test_the_diagram_names_a_branch_point_of_cycles_not_a_fold():
    # The diagram's lower edge of that chain, its orbit sought at 1.1 M_c = 0.3: the orbit loses stability through
    # +1 while M goes on falling. Located by the fold's augmented system: two multipliers at +1.
    edge = _lower_edge(ChainParams(N=1), get_model("nonlinear"), 0.3 / 1.1, 1, 0, 30.0, "gamma_phi")
    assert edge.end == "branch_point_of_cycles" and edge.method == "located"
    assert edge.stops == pytest.approx(0.29772, abs=2e-4)
    assert np.sort(np.abs(edge.orbit.multipliers - 1.0))[1] < 1e-6


def test_a_user_systems_branch_point_of_cycles_needs_a_multiplier_at_plus_one():
    # numerics.shooting (any system) keeps its phase plane normal to the flow; a located sign change of the kit's
    # branch-point test counts only with a second multiplier at +1 (the pen's in-phase orbit at I = 0.4 has none).
    system = pen()
    orbit = shooting.find_orbit(
        system, shooting.settled_guess(system, np.array([0.0, 0.0, 2.0, 2.0]), coordinate="phi_0"), turns={"phi_0": 1, "phi_1": 1}
    )
    plane = shooting._Shooting(system, orbit.turns, orbit.y0, orbit.period, (shooting.PERIOD, "I"), 1e-9, 1e-11, 1e-11)
    problem = shooting._OrbitProblem(plane, 1e3, (-math.inf, math.inf), False, orbit.stable, None)
    assert np.min(np.abs(orbit.nontrivial_multipliers - 1.0)) > 0.1
    assert not problem.confirm("branch_point", orbit)
    mu = orbit.multipliers.copy()
    mu[int(np.argmax(np.abs(mu - 1.0)))] = 1.0 + 1e-4
    assert problem.confirm("branch_point", dataclasses.replace(orbit, multipliers=mu))


def test_the_fold_on_the_phase_plane_followed_in_the_damping_equals_each_value_located_on_its_own():
    followed = state_diagram(ChainParams(N=2), "sine", "gamma_phi", [0.15, 0.16], follow=True)
    alone = state_diagram(ChainParams(N=2), "sine", "gamma_phi", [0.16])
    assert [row.method for row in followed.rows] == ["located", "followed"] and alone.rows[0].method == "located"
    assert [row.end for row in followed.rows] == ["fold_of_cycles"] * 2 == [followed.rows[0].end, alone.rows[0].end]
    assert followed.rows[0].rotation_stops == pytest.approx(FOLD, abs=1e-7)
    assert "tangent to the section phi_0 = 0 near M = 0.1831" in followed.rows[0].message
    assert followed.rows[1].rotation_stops == pytest.approx(alone.rows[0].rotation_stops, rel=1e-9)


def test_orbit_down_to_goes_past_the_old_end(tmp_path):
    config = tmp_path / "N2.toml"
    config.write_text("N = 2\ngamma_phi = 0.15\n")
    result = CliRunner().invoke(
        app, ["orbit", "--model", "sine", "--moment", "0.3195", "--down-to", "0.1", "--config", str(config), "--json"]
    )
    assert result.exit_code == 0, result.output
    branch = json.loads(result.output[result.output.index("{") :])["continuation"]
    assert branch["end"] == "fold" and branch["end_moment"] == pytest.approx(FOLD, abs=2e-6)
    assert branch["phase_condition"][0] == "section" and branch["phase_condition"][-1] == "plane"
    assert branch["branch_points"] == [] and min(branch["moment"]) < FALSE_FOLD - 1e-3


def test_a_turn_of_the_sections_system_without_a_multiplier_at_plus_one_is_passed(monkeypatch):
    # With the early re-choice of the phase condition switched off, the continuation on the section meets the
    # section's own turn (the old false fold, 0.1822292); it is not taken for a fold of cycles, and the branch goes on
    # from there on the phase plane to the real fold.
    monkeypatch.setattr(periodic, "TRANSVERSAL_DROP", 0.0)
    branch = continue_orbit(find_periodic_orbit(CHAIN, "sine", 1.1 * locate_fold(CHAIN, "sine").moment), period_max=100.0)
    assert "no multiplier at +1: no fold" in branch.message and "near M = 0.18222919" in branch.message
    assert branch.end == "fold" and branch.end_moment == pytest.approx(FOLD, abs=2e-6)
