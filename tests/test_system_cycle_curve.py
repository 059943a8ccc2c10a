"""Two-parameter curves of a user system's cycle ends (:func:`~cosserat_chain.numerics.cycle_curve.continue_cycle_end`
on a :class:`~cosserat_chain.numerics.shooting.Orbit`)."""

import numpy as np
import pytest

from cosserat_chain.numerics import shooting
from cosserat_chain.numerics.cycle_curve import continue_cycle_end
from cosserat_chain.numerics.cycle_switching import switch_at_period_doubling
from cosserat_chain.systems import pen


def in_phase_branch(**parameters) -> shooting.OrbitBranch:
    """The pen demo's in-phase rotation followed down in I to its period doubling (located by the one-parameter
    continuation's own event: an independent method, a multiplier's test function on the orbit branch); at the
    defaults (eps = 0.1) it is the session's ``pen_in_phase_branch`` (conftest.py)."""
    system = pen(**parameters)
    guess = shooting.settled_guess(system, np.array([0.0, 0.0, 2.0, 2.0]), coordinate="phi_0")
    orbit = shooting.find_orbit(system, guess, turns={"phi_0": 1, "phi_1": 1})
    return shooting.continue_orbits(orbit, "I", direction=-1, max_points=60, stop_at=("period_doubling",))


def period_doubling_on(branch: shooting.OrbitBranch) -> shooting.Orbit:
    return next(e for e in branch.events if e.kind == "period_doubling" and e.located).point


@pytest.fixture(scope="module")
def curve(pen_in_phase_branch):
    """AUTO-07p's demo ``pen``: the in-phase rotation period-doubles at I = 0.17916377626 for eps = 0.1
    (``tests/test_cycle_switching.py``); its curve followed in eps."""
    start = period_doubling_on(pen_in_phase_branch)
    assert start.parameter("I") == pytest.approx(0.17916377626, abs=1e-9)
    return continue_cycle_end(start, "period_doubling", "eps", [0.1, 0.12, 0.15], parameter="I")


def test_the_pen_demo_s_period_doubling_curve_in_eps_is_where_each_value_s_own_branch_doubles(curve):
    """Each point of the curve is the period doubling that a one-parameter continuation in I of that eps's own
    in-phase rotation (from a settled run) locates, to 1e-8 in I and the period; a multiplier is -1 there. The last
    point is checked here, the middle one (eps = 0.12) by the system diagram's own row below."""
    assert curve.complete and curve.parameter == "I" and list(curve.values) == [0.1, 0.12, 0.15]
    assert np.all(np.diff(curve.moment) > 0.01)  # more damping, a larger current to keep it rotating in phase
    for eps, current, orbit in zip(curve.values[1:], curve.moment[1:], curve.orbits[1:]):
        assert orbit.parameter("eps") == eps and orbit.parameter("I") == current
        assert np.min(np.abs(orbit.multipliers + 1.0)) < 1e-8
    independent = period_doubling_on(in_phase_branch(eps=0.15))
    assert curve.moment[-1] == pytest.approx(independent.parameter("I"), abs=1e-8)
    assert curve.period[-1] == pytest.approx(independent.period, abs=1e-8)
    summary = curve.as_dict()
    assert summary["parameter"] == "I" and [r["moment"] for r in summary["rows"]] == list(curve.moment)


def doubled_fold(branch: shooting.OrbitBranch) -> shooting.Orbit:
    """The fold of cycles on the pen demo's out-of-phase (period-doubled) branch, switched onto at the period
    doubling of ``branch`` and followed up in I (``tests/test_cycle_switching.py``: above I = 0.39 at eps = 0.1)."""
    switch = switch_at_period_doubling(branch, stop_at=("fold",), limits=(0.0, 1.0), max_points=80)
    return next(e for e in switch.branch.events if e.kind == "fold" and e.located).point


def test_the_fold_of_cycles_on_the_pen_demo_s_doubled_branch_followed_in_eps_is_each_eps_s_own_fold(pen_in_phase_branch):
    """The fold-of-cycles curve (the bordered test function of the shooting Jacobian, a second multiplier at +1):
    at eps = 0.11 it lies where the one-parameter continuation of that eps's own doubled branch turns, to 1e-8."""
    start = doubled_fold(pen_in_phase_branch)
    assert start.parameter("I") > 0.39
    curve = continue_cycle_end(start, "fold_of_cycles", "eps", [0.1, 0.105, 0.11], parameter="I")
    assert curve.complete and list(curve.values) == [0.1, 0.105, 0.11]
    independent = doubled_fold(in_phase_branch(eps=0.11))
    assert curve.moment[-1] == pytest.approx(independent.parameter("I"), abs=1e-8)
    assert curve.period[-1] == pytest.approx(independent.period, abs=1e-8)
    assert np.sort(np.abs(curve.orbits[-1].multipliers - 1.0))[1] < 1e-3  # the second multiplier at +1


def test_a_system_s_curve_refuses_unknown_parameters_and_bad_values(curve):
    start = curve.orbits[0]
    with pytest.raises(ValueError, match="parameter and field must be two different parameters of pen"):
        continue_cycle_end(start, "period_doubling", "eps", [0.1])
    with pytest.raises(ValueError, match="got parameter='I', field='mass'"):
        continue_cycle_end(start, "period_doubling", "mass", [0.1], parameter="I")
    with pytest.raises(ValueError, match="values of eps must be one or more finite numbers"):
        continue_cycle_end(start, "period_doubling", "eps", [0.1, float("nan")], parameter="I")
    with pytest.raises(ValueError, match="kind must be one of"):
        continue_cycle_end(start, "hopf", "eps", [0.1], parameter="I")


def test_the_system_diagram_follows_each_row_s_period_doubling_to_the_next_value(curve, monkeypatch):
    """``system_diagram(codim2=True)`` on the pen demo: each row's orbit loses stability at a period doubling, whose
    curve from eps = 0.1 reaches eps = 0.12 where that row's own one-parameter continuation locates it, and where
    the curve followed from the located start (the fixture) lies, to 1e-8; JSON and NetCDF carry the entries. The rows'
    homoclinic ends, which the curve does not read, are left unsolved here (``tests/test_system_diagram.py`` solves them)."""
    import json

    from cosserat_chain.experiments import system_diagram as system_diagram_module
    from cosserat_chain.experiments.system_diagram import SystemDiagram, system_diagram

    def end_not_solved(row, system, drive, k, winding, branch, last):
        row.stops, row.method = last, "last_orbit"

    monkeypatch.setattr(system_diagram_module, "_homoclinic", end_not_solved)
    diagram = system_diagram(pen(), "eps", [0.1, 0.12], "I", codim2=True)
    assert [row.curve for row in diagram.rows] == ["period_doubling", "period_doubling"]
    (entry,) = diagram.codim2_between
    assert entry["followed"] == "period_doubling" and entry["from"] == 0.1 and entry["complete"] is True and entry["points"] == []
    assert entry["reaches"] == pytest.approx(diagram.rows[1].stability_lost, abs=1e-8)
    assert entry["reaches"] == pytest.approx(curve.moment[1], abs=1e-8)
    assert "reaches 0.12 at I = 0.21454571" in entry["message"]
    assert json.loads(diagram.to_dataset().attrs["codim2_between_json"]) == diagram.as_dict()["codim2_between"]
    assert SystemDiagram(pen(), "eps", "I", {"phi_0": 1, "phi_1": 1}).as_dict()["codim2_between"] is None
    with pytest.raises(ValueError, match="codim2 must be True or False, got 'yes'"):
        system_diagram(pen(), "eps", [0.1], "I", codim2="yes")


@pytest.mark.slow
def test_diagram_system_codim2_prints_and_writes_the_curve_between_the_rows():
    import json

    from typer.testing import CliRunner

    from cosserat_chain.cli import app

    args = ["diagram", "--system", "pen", "--vary", "eps", "--values", "0.1,0.12", "--drive", "I", "--codim2"]
    result = CliRunner().invoke(app, [*args, "--json"])
    assert result.exit_code == 0, result.output
    (entry,) = json.loads(result.output)["codim2_between"]
    assert entry["curves"] == ["period_doubling", "period_doubling"] and entry["reaches"] == pytest.approx(0.2145457198, abs=1e-8)
    text = CliRunner().invoke(app, args)
    assert text.exit_code == 0 and "between eps = 0.1 and 0.12: the period_doubling curve followed from eps = 0.1" in text.output
