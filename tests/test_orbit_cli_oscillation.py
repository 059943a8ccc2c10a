"""``orbit --system FILE --oscillation``: a limit cycle with no angle turning, from the command line (issue 40 item 6).

The system is a rotationally symmetric oscillator under a saturating follower (circulatory) force, a Stuart-Landau
normal form in second-order form (``tests/follower_rotor_system.py``, a user's
file): q'' + c q' = -kk q + (a0 - b |q|^2) J q. Its limit cycle is the circle of radius sqrt((a0 - c sqrt(kk)) / b)
and period 2 pi / sqrt(kk), born at the Hopf point a0 = c sqrt(kk) of q = 0: closed forms that a wrong period, a
wrong phase of the settled guess or a rotation taken for the orbit would miss.
"""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from typer.testing import CliRunner

from cosserat_chain.cli import app
from follower_rotor_system import HOPF, PERIOD, ROTOR

runner = CliRunner()


def radius(a0: float) -> float:
    return math.sqrt(a0 - HOPF)


@pytest.fixture(scope="module")
def reference(tmp_path_factory) -> str:
    path = tmp_path_factory.mktemp("rotor") / "rotor.py"
    path.write_text(ROTOR)
    return f"{path}:build"


@pytest.mark.parametrize("a0", [0.3, 0.4])
def test_the_oscillation_is_the_closed_form_circle(reference, a0):
    result = runner.invoke(app, ["orbit", "--system", reference, "--set", f"a0={a0}", "--oscillation", "--start", "0.1,0", "--json"])
    assert result.exit_code == 0, result.output
    orbit = json.loads(result.stdout)
    assert orbit["turns"] == [0, 0] and orbit["closure"] < 1e-9
    assert orbit["period"] == pytest.approx(PERIOD, abs=1e-8)
    assert math.hypot(*orbit["q0"]) == pytest.approx(radius(a0), abs=1e-8)
    # On the circle the velocity is the rotation at rate sqrt(kk): v0 = sqrt(kk) J q0.
    assert np.allclose(orbit["v0"], math.sqrt(1.5) * np.array([-orbit["q0"][1], orbit["q0"][0]]), atol=1e-8)
    assert orbit["stable"] and orbit["max_multiplier"] < 1.0


def test_the_oscillation_followed_down_ends_at_its_hopf_point(reference):
    """From a0 = 0.27 (radius 0.16): five circles down to one of radius 0.1 where the family shrinks onto q = 0."""
    args = ["orbit", "--system", reference, "--set", "a0=0.27", "--oscillation", "--start", "0.1,0", "--vary", "a0"]
    result = runner.invoke(app, [*args, "--down-to", "0.2", "--json"])
    assert result.exit_code == 0, result.output
    branch = json.loads(result.stdout)["branch"]
    assert branch["parameter"] == "a0" and branch["end"] == "hopf", branch["message"]
    assert "Hopf point" in branch["message"] and abs(branch["values"][-1] - HOPF) < 0.02
    assert np.allclose(branch["periods"], PERIOD, atol=1e-7)
    assert not [e for e in branch["events"] if e["kind"] in ("fold", "branch_point")]


def test_the_text_output_names_an_oscillation(reference):
    result = runner.invoke(app, ["orbit", "--system", reference, "--oscillation", "--start", "0.1,0"])
    assert result.exit_code == 0, result.output
    assert "turns none (an oscillation)" in result.stdout and f"period T = {PERIOD:.8f}"[:20] in result.stdout


def test_bad_oscillation_requests_are_refused_with_a_reason(reference):
    both = runner.invoke(app, ["orbit", "--system", reference, "--oscillation", "--turn", "x=1"])
    assert both.exit_code == 2 and "--oscillation turns no angle: leave out --turn (got x=1)" in both.output
    # From the equilibrium itself a settling run never moves: the message says how to start it.
    still = runner.invoke(app, ["orbit", "--system", reference, "--oscillation"])
    assert still.exit_code != 0 and "did not oscillate" in still.output and "--start or --velocity" in still.output
    chain = runner.invoke(app, ["orbit", "--moment", "0.3", "--oscillation"])
    assert chain.exit_code == 2 and "--oscillation" in chain.output and "--system" in chain.output
    zero = runner.invoke(app, ["orbit", "--system", "pen", "--turn", "phi_0=0"])
    assert zero.exit_code == 2 and "is --oscillation" in zero.output


def test_from_a_subcritical_hopf_point_the_unstable_circles_no_settling_run_reaches(reference):
    """With b = -1 the circles (a0_H - a0 = R^2) lie below the Hopf point and are unstable: --from-hopf starts the family
    at the Hopf point of q = 0 sought up from a0 = 0.2, and follows it down to the range's end."""
    args = ["orbit", "--system", reference, "--set", "a0=0.2", "--set", "b=-1", "--oscillation", "--from-hopf", "--vary", "a0"]
    result = runner.invoke(app, [*args, "--down-to", "0.4", "--json"])
    assert result.exit_code == 0, result.output
    out = json.loads(result.stdout)
    assert out["hopf"]["value"] == pytest.approx(HOPF, abs=1e-9) and np.allclose(out["hopf"]["q"], 0.0, atol=1e-12)
    first_radius = math.hypot(*out["q0"])
    assert out["period"] == pytest.approx(PERIOD, abs=1e-8) and not out["stable"] and out["turns"] == [0, 0]
    branch = out["branch"]
    assert branch["end"] == "parameter_limit" and min(branch["values"]) < 0.2 < HOPF - first_radius**2 + 1e-6
    assert np.allclose(branch["periods"], PERIOD, atol=1e-7)
    # Without a Hopf point in the range: exit 3, saying so; without --down-to: exit 2.
    none = runner.invoke(app, [*args, "--down-to", "0.22"])
    assert none.exit_code == 3 and "no Hopf point for a0 between 0.2 and 0.22" in none.output
    bare = runner.invoke(app, args)
    assert bare.exit_code == 2 and "--from-hopf starts an --oscillation" in bare.output
