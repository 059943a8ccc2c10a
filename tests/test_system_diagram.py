"""The hysteresis diagram of a user's system (experiments/system_diagram.py, ``diagram --system``; issue 40 items 3, 4).

Every system here has an in-phase (uniform) rotation that is one damped driven pendulum's,
phi'' + alpha phi' + sin(phi) = I: it ends at the pendulum's retrapping current I_r(alpha), where the orbit
becomes homoclinic to the saddle pi - arcsin(I), for alpha below alpha* and at the fold I = 1 (a SNIC) above.
The references are independent of the package: I_r by the fate of the saddle's unstable manifold on either side
of the value checked (SciPy's DOP853 at rtol 1e-12: does it pass the shifted saddle, or turn back?), and alpha* by Lin's method on the
fold's centre manifold and the shifted fold's strong stable manifold (Brent in alpha).
"""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from scipy.integrate import solve_ivp
from scipy.optimize import brentq
from typer.testing import CliRunner

from conftest import SYSTEMS_CACHE
from cosserat_chain.cli import app
from cosserat_chain.experiments import system_diagram as module
from cosserat_chain.experiments.system_diagram import SystemDiagramRow, system_diagram
from cosserat_chain.numerics.homoclinic import HomoclinicError, homoclinic_end
from cosserat_chain.numerics.shooting import find_orbit, settled_guess
from cosserat_chain.systems.frenkel_kontorova import frenkel_kontorova
from cosserat_chain.systems.josephson import josephson_array
from cosserat_chain.systems.pen import pen
from cosserat_chain.systems.takeno_peyrard import takeno_peyrard
from pen_loops import assert_the_pen_loops_call, pen_loop, pen_loop_given

#: The accuracy the issue asks of the lower edge of the loop.
ASKED = 1e-8


@pytest.fixture(autouse=True)
def _cache(monkeypatch):
    """The compiled systems go to the tests' cache folder, not the user's."""
    monkeypatch.setenv("COSSERAT_CHAIN_CACHE", str(SYSTEMS_CACHE))


def _turns_over(alpha: float, current: float, eps: float = 1e-9) -> bool:
    """Whether the saddle's unstable manifold of the pendulum passes the shifted saddle (else its velocity turns back)."""
    saddle = math.pi - math.asin(current)
    up = (-alpha + math.sqrt(alpha**2 - 4 * math.cos(saddle))) / 2

    def over(t, y):
        return y[0] - (saddle + 2 * math.pi + 0.5)

    def back(t, y):
        return y[1]

    over.terminal = back.terminal = True
    back.direction = -1
    run = solve_ivp(
        lambda t, y: [y[1], current - alpha * y[1] - math.sin(y[0])], (0.0, 1e4), [saddle + eps, up * eps],
        method="DOP853", events=[over, back], rtol=1e-12, atol=1e-14,
    )  # fmt: skip
    return run.t_events[0].size > 0


def holds_the_retrapping_current(alpha: float, value: float, accuracy: float) -> bool:
    """Whether I_r(alpha) lies within ``accuracy`` of ``value``: the manifold falls back below and turns over above
    (the fate changes once, at I_r; the interval clipped to the currents where the saddle exists, 0 <= I < 1)."""
    return _turns_over(alpha, min(value + accuracy, 1.0 - 1e-6)) and not _turns_over(alpha, max(value - accuracy, 0.0))


def snic_damping() -> float:
    """alpha* where I_r(alpha*) = 1, by Lin's method at I = 1: the fold's centre manifold forward from pi/2 and the
    shifted fold's strong stable manifold (direction (1, -alpha)) backward from 5 pi / 2, their velocities at 3 pi / 2."""

    def velocity_at(alpha, start, backward):
        def hit(t, y):
            return y[0] - 1.5 * math.pi

        hit.terminal = True
        run = solve_ivp(
            lambda t, y: [y[1], 1.0 - alpha * y[1] - math.sin(y[0])], (0.0, -1e4 if backward else 1e4), start,
            method="DOP853", events=hit, rtol=1e-13, atol=1e-15,
        )  # fmt: skip
        return run.y_events[0][0][1]

    def splitting(alpha):
        # On the centre manifold alpha phi' = 1 - sin(phi) ~ d^2 / 2 to leading order.
        d, e = 1e-3, 1e-7
        forward = velocity_at(alpha, [math.pi / 2 + d, d * d / (2 * alpha)], False)
        return forward - velocity_at(alpha, [2.5 * math.pi - e, alpha * e], True)

    return brentq(splitting, 1.15, 1.3, xtol=1e-14, rtol=1e-14)


def invoke(*args: str):
    return CliRunner().invoke(app, list(args), terminal_width=200)


# -- the homoclinic ends, solved ------------------------------------------------------------------


@pytest.mark.parametrize("eps", [0.3, pytest.param(0.1, marks=pytest.mark.slow)])
def test_the_pen_demos_in_phase_rotation_ends_at_the_pendulums_retrapping_current(eps):
    """AUTO-07p's pen demo: its in-phase rotation is one pendulum's, so it ends at I_r(eps), solved to the asked
    accuracy (the in-phase saddle has two unstable directions: in phase and anti-phase); rotation starts at the fold
    I = 1; the orbit period-doubles on the way down, and the row says so."""
    (row,) = pen_loop(eps).rows
    assert row.end == "homoclinic" and row.method == "solved"
    assert row.accuracy <= ASKED
    assert holds_the_retrapping_current(eps, row.stops, row.accuracy)
    assert row.starts == pytest.approx(1.0, abs=1e-8) and row.open is True
    assert row.homoclinic["unstable_directions"] == 2
    assert row.stability_lost is not None and row.stops < row.stability_lost < row.starts
    assert "loses stability" in row.warning and "period_doubling" in row.warning
    assert "fit of the period's growth gave" in row.message


@pytest.mark.parametrize(
    ("build", "vary", "drive"),
    [
        (lambda: josephson_array(3, alpha=0.3), "alpha", "I"),
        pytest.param(lambda: takeno_peyrard(2, gamma=0.3), "gamma", "T", marks=pytest.mark.slow),
        pytest.param(lambda: frenkel_kontorova(2, gamma=0.3), "gamma", "F", marks=pytest.mark.slow),
    ],
    ids=["josephson_array", "takeno_peyrard", "frenkel_kontorova"],
)
def test_lattices_from_formulas_end_at_the_uniform_loop(build, vary, drive):
    """A Josephson array, the Takeno-Peyrard and the Frenkel-Kontorova lattice: their uniform rotation (bonds at rest)
    is the pendulum's with damping 0.3, so it ends at I_r(0.3), the uniform saddle having one unstable direction."""
    (row,) = system_diagram(build(), vary, [0.3], drive).rows
    assert (row.end, row.method) == ("homoclinic", "solved")
    assert row.accuracy <= ASKED and holds_the_retrapping_current(0.3, row.stops, row.accuracy)
    assert row.homoclinic["unstable_directions"] == 1
    assert row.starts == pytest.approx(1.0, abs=1e-8)


@pytest.mark.slow
def test_a_potential_with_two_harmonics_ends_where_its_manifold_changes_fate():
    """A rotor in 1 - cos(phi) + b (1 - cos 2 phi) (not the pendulum: its fold and saddle have no closed form): the
    fold is the maximum of sin(phi) + 2 b sin(2 phi), and the end is where the saddle's unstable manifold changes
    fate, both computed here with SciPy alone."""
    from scipy.optimize import minimize_scalar

    from cosserat_chain.systems import LatticeSystem

    b, alpha = 0.2, 0.3

    def drive(phi):
        return math.sin(phi) + 2 * b * math.sin(2 * phi)

    peak = minimize_scalar(lambda phi: -drive(phi), bounds=(0.0, math.pi), method="bounded", options={"xatol": 1e-12})

    def turns_over(current, eps=1e-9):
        saddle = brentq(lambda phi: drive(phi) - current, peak.x, math.pi, xtol=1e-15)
        up = (-alpha + math.sqrt(alpha**2 - 4 * (math.cos(saddle) + 4 * b * math.cos(2 * saddle)))) / 2

        def over(t, y):
            return y[0] - (saddle + 2 * math.pi + 0.5)

        def back(t, y):
            return y[1]

        over.terminal = back.terminal = True
        back.direction = -1
        run = solve_ivp(
            lambda t, y: [y[1], current - alpha * y[1] - drive(y[0])], (0.0, 1e4), [saddle + eps, up * eps],
            method="DOP853", events=[over, back], rtol=1e-12, atol=1e-14,
        )  # fmt: skip
        return run.t_events[0].size > 0

    low, high = 0.2, 0.6
    while high - low > 1e-13:
        middle = 0.5 * (low + high)
        low, high = (low, middle) if turns_over(middle) else (middle, high)
    system = LatticeSystem(
        sites=1, site_energy="1 - cos(phi) + b*(1 - cos(2*phi)) - I*phi", damping="alpha",
        parameters={"I": 0.0, "b": b, "alpha": alpha}, name="two_harmonics",
    )  # fmt: skip
    (row,) = system_diagram(system, "alpha", [alpha], "I").rows
    assert row.starts == pytest.approx(-peak.fun, abs=1e-9)
    assert (row.end, row.method) == ("homoclinic", "solved") and row.accuracy <= ASKED
    assert abs(row.stops - 0.5 * (low + high)) <= row.accuracy


def test_a_saddle_with_two_unstable_directions_leaves_in_phase():
    """The pen's in-phase saddle: the solved loop's tilt into the anti-phase direction is zero (the in-phase
    subspace is invariant), and the loop returns to the saddle shifted by 2 pi in both angles, in phase."""
    current = 0.4
    system = pen(I=current, eps=0.3)
    end = homoclinic_end(
        system, np.full(2, math.pi - math.asin(current)), turns={"phi_0": 1, "phi_1": 1}, bracket=(0.36, current), parameter="I"
    )
    assert end.rest.others.shape[1] == 1 and abs(end.direction[0]) < 1e-8
    times = np.linspace(0.0, end.time, 50)
    path = end.trajectory(times)
    assert np.max(np.abs(path[:, 0] - path[:, 1])) < 1e-6
    assert holds_the_retrapping_current(0.3, end.value, end.accuracy)


def test_a_fitted_end_says_it_is_a_fit_and_why(monkeypatch):
    """Where the boundary-value problem is not solved (neither from the last orbit nor in a bracket), the fit of the
    period's growth stays, labelled ``fitted``, with the reason and the fit's own uncertainty (which holds the true end)."""

    def refuse(*args, **kwargs):
        raise HomoclinicError("no loop in this bracket")

    monkeypatch.setattr(module, "homoclinic_end", refuse)
    monkeypatch.setattr(module, "homoclinic_from_orbit", refuse)
    # The row computed once: the command's call of system_diagram (spied on) is the API's on the same system.
    calls = []

    def spy(system, vary, values, drive, **options):
        calls.append((system, vary, list(values), drive, system_diagram(system, vary, values, drive, **options)))
        return calls[-1][-1]

    monkeypatch.setattr(module, "system_diagram", spy)
    text = invoke("diagram", "--system", "josephson_array", "--set", "sites=1", "--vary", "alpha", "--values", "0.3", "--drive", "I")
    assert text.exit_code == 0, text.output
    assert "fitted +-" in text.stdout and "a fit, not a computed point: " in text.stdout and "no loop in this bracket" in text.stdout
    ((system, vary, values, drive, result),) = calls
    assert system.name == josephson_array(1).name and (vary, values, drive) == ("alpha", [0.3], "I")
    (row,) = result.rows
    assert (row.end, row.method) == ("homoclinic", "fitted")
    assert "no loop in this bracket" in row.reason and "fitted" in row.message
    assert f"+- {row.accuracy:.2g}, fitted (the fit's own uncertainty)" in row.message
    assert holds_the_retrapping_current(0.3, row.stops, row.accuracy)


# -- the SNIC end and the SNIC point ----------------------------------------------------------------


def test_strong_damping_ends_at_a_snic_on_the_fold():
    """Above alpha* = 1.19305 the rotation is born and dies on the fold I = 1 with an infinite period: no hysteresis."""
    (row,) = system_diagram(josephson_array(1, alpha=1.3), "alpha", [1.3], "I").rows
    assert (row.end, row.method) == ("snic", "static_fold")
    assert row.stops == row.starts == pytest.approx(1.0, abs=1e-8)
    assert row.open is False and row.accuracy is None
    assert "homoclinic" not in row.message


def test_just_below_the_snic_point_the_end_is_bounded_by_the_fold_not_called_a_snic():
    """At alpha = 1.19 < alpha* the rotation ends at I_r just below the fold, but its period passes period_max above
    the fold: the fold's centre manifold turns over there (a rotation exists at I = 1), so the row is a homoclinic
    end bounded by the fold, not a SNIC; at 1.197 > alpha* the manifold falls back: a SNIC."""
    below, above = system_diagram(josephson_array(1, alpha=1.19), "alpha", [1.19, 1.197], "I").rows
    assert (below.end, below.method, below.stops, below.open) == ("homoclinic", "upper_bound", below.starts, None)
    assert "turns over" in below.reason and "period_max" in below.reason
    assert (above.end, above.method) == ("snic", "static_fold") and "falls back" in above.message


@pytest.mark.slow
def test_the_snic_point_is_where_the_retrapping_current_reaches_the_fold():
    """Between a homoclinic row and a SNIC row the codimension-two point is solved by the augmented system, and
    agrees with Lin's method to its accuracy; the drive there is the fold's, I = 1."""
    diagram = system_diagram(pen(), "eps", [0.3, 1.3], "I")
    assert [row.end for row in diagram.rows] == ["homoclinic", "snic"]
    point = diagram.snic_point
    assert point["method"] == "solved" and point["between"] == [0.3, 1.3]
    assert point["accuracy"] <= ASKED
    assert abs(point["value"] - snic_damping()) <= point["accuracy"]
    assert point["drive"] == pytest.approx(1.0, abs=1e-12)


def test_no_snic_point_without_a_homoclinic_row_next_to_a_snic_row():
    row = SystemDiagramRow(0.3, starts=1.0, stops=0.37, end="homoclinic")
    diagram = module.SystemDiagram(pen(), "eps", "I", {"phi_0": 1, "phi_1": 1}, [row, SystemDiagramRow(0.5, end="fold_of_cycles")])
    assert module._snic_point(diagram, np.array([1, 1])) is None


# -- a fold of cycles: does the rotation go on below it? ----------------------------------------------


def _pendulum_orbit(alpha: float, current: float):
    system = josephson_array(1, alpha=alpha, I=current)
    # Started with more than the barrier's energy (2): it settles on the rotation wherever one exists.
    guess = settled_guess(system, np.array([0.0, 3.0]), coordinate=0)
    return find_orbit(system, guess, turns={"phi_0": 1})


@pytest.mark.parametrize(("current", "below"), [(0.8, "rotating"), (0.38, "rest")])
def test_a_run_below_a_fold_of_cycles_tells_rest_from_rotation(current, below):
    """The run from a fold's orbit just below it: where another rotation exists there (the pendulum at I = 0.79,
    above I_r(0.3) = 0.3735) it keeps rotating and the row warns that the fold ends one orbit, not the rotation;
    below I_r (0.376) it comes to rest and the fold is the edge."""
    row = SystemDiagramRow(0.3, starts=1.0, stops=current * 0.99, end="fold_of_cycles")
    module._below_fold(row, _pendulum_orbit(0.3, current), "I", 0)
    assert row.below == below
    if below == "rotating":
        assert "not the rotation" in row.warning and "coexisting orbit" in row.warning
    else:
        assert not row.warning and "edge of rotation" in row.message


# -- the command line -------------------------------------------------------------------------------


def test_the_command_saves_and_dumps_the_solved_end(tmp_path, monkeypatch):
    """``diagram --system --json --out``: the JSON and the NetCDF file carry ``stops_method``, ``stops_uncertainty``
    and the SNIC point (none here)."""
    import xarray as xr

    # The command's call of system_diagram is the pen row's test's (the same system, values and defaults): its diagram
    # computed once (pen_loop), the command's parsing, JSON and file as before.
    calls = []
    monkeypatch.setattr(module, "system_diagram", pen_loop_given(0.3, calls))
    out = tmp_path / "loop.nc"
    args = ("diagram", "--system", "pen", "--vary", "eps", "--values", "0.3", "--drive", "I")
    result = invoke(*args, "--json", "--out", str(out))
    assert result.exit_code == 0, result.output
    payload = json.loads(result.stdout)
    (row,) = payload["rows"]
    assert row["stops_method"] == "solved" and row["stops_uncertainty"] <= ASKED
    assert row["end"] == "homoclinic" and row["open"] is True and payload["snic_point"] is None
    assert payload["reference"] == "pen" and payload["drive"] == "I"
    with xr.open_dataset(out) as ds:
        assert str(ds.stops_method.values[0]) == "solved"
        assert float(ds.stops[0]) == row["stops"] and float(ds.stops_uncertainty[0]) == row["stops_uncertainty"]
        assert json.loads(ds.attrs["snic_point_json"]) is None and ds.attrs["drive"] == "I"
    (call,) = calls
    assert_the_pen_loops_call(call, 0.3)


@pytest.mark.slow
def test_the_command_reports_the_snic_point(tmp_path):
    """Its JSON, NetCDF file and table: each row's method (solved with its accuracy, the static fold), the warning of
    the period doubling on the way, and the SNIC point solved between the rows."""
    import xarray as xr

    out = tmp_path / "loop.nc"
    args = ("diagram", "--system", "pen", "--vary", "eps", "--values", "0.3,1.3", "--drive", "I")
    result = invoke(*args, "--json", "--out", str(out))
    assert result.exit_code == 0, result.output
    payload = json.loads(result.stdout)
    assert [r["stops_method"] for r in payload["rows"]] == ["solved", "static_fold"]
    assert payload["snic_point"]["method"] == "solved" and payload["snic_point"]["value"] == pytest.approx(1.19304591882, abs=1e-10)
    with xr.open_dataset(out) as ds:
        assert json.loads(ds.attrs["snic_point_json"]) == payload["snic_point"]
    text = invoke(*args)
    assert text.exit_code == 0 and "solved +- 1e-10" in text.stdout and "static_fold" in text.stdout
    assert "warning: eps = 0.3" in text.stdout and "period_doubling" in text.stdout
    assert "the homoclinic end meets the fold" in text.stdout and "eps = 1.19304591882" in text.stdout


@pytest.mark.parametrize(
    ("args", "words"),
    [
        (["--vary", "nope", "--values", "0.3", "--drive", "I"], ["--vary", "nope"]),
        (["--vary", "eps", "--values", "0.3", "--drive", "J"], ["--drive", "J"]),
        (["--vary", "eps", "--values", "nan", "--drive", "I"], ["finite"]),
        (["--vary", "eps", "--values", "0.3", "--drive", "I", "--start", "1,2,3"], ["--start", "2"]),
        (["--vary", "eps", "--values", "0.3", "--drive", "I", "--turn", "phi_9=1"], ["--turn", "phi_9"]),
        (["--vary", "eps", "--values", "0.3", "--drive", "I", "--period-max", "-1"], ["--period-max"]),
    ],
)
def test_bad_input_to_the_command_is_named(args, words):
    result = invoke("diagram", "--system", "pen", *args)
    assert result.exit_code == 2, result.output
    assert all(w in result.output for w in words), result.output
    assert "Traceback" not in result.output


@pytest.mark.parametrize(
    ("kwargs", "words"),
    [
        ({"vary": "eps", "drive": "eps"}, ["different", "eps"]),
        ({"vary": "nope", "drive": "I"}, ["nope"]),
        ({"vary": "eps", "drive": "I", "values": [math.inf]}, ["finite"]),
        ({"vary": "eps", "drive": "I", "period_max": 0.0}, ["period_max"]),
        ({"vary": "eps", "drive": "I", "turns": {"phi_0": 0, "phi_1": 0}}, ["turns"]),
    ],
)
def test_bad_input_to_the_function_is_named(kwargs, words):
    arguments = {"values": [0.3], **kwargs}
    with pytest.raises(ValueError) as err:
        system_diagram(pen(), arguments.pop("vary"), arguments.pop("values"), arguments.pop("drive"), **arguments)
    assert all(w in str(err.value) for w in words)
