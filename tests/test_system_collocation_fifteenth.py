"""User systems' collocation from the command line (``orbit --system REF --method collocation``), its messages naming the
continued parameter, and the period doublings its branch reports beside the junctions' later folds of cycles (issue 40).

The quick tests: the pen demo's in-phase rotation by collocation through the CLI, against the independent period of
tests/test_cli_systems.py and Liouville's identity (the product of the multipliers is exp(-trace of the damping times
T)); its branch in I with the trivial multiplier's error at every orbit and a message that says I, not M. The slow
test: the period doubling 1.5e-7 in I beside the snake's second fold is real, a multiplier at -1 that single shooting
finds too (docs/collocation.md says why AUTO-07p steps over it).
"""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from typer.testing import CliRunner

from conftest import SYSTEMS_CACHE
from cosserat_chain.cli import app
from test_cli_systems import PEN_PERIOD
from three_junctions import jj3

#: Agreement of two independent methods (collocation, shooting) on one orbit, and the collocation's own trivial multiplier.
AGREE = 1e-8


@pytest.fixture(autouse=True)
def _cache(monkeypatch):
    """The compiled systems go to the tests' cache folder, not the user's."""
    monkeypatch.setenv("COSSERAT_CHAIN_CACHE", str(SYSTEMS_CACHE))


def invoke(*args: str):
    return CliRunner().invoke(app, list(args), terminal_width=200)


def test_cli_collocation_orbit_and_branch_of_the_pen_demo():
    result = invoke("orbit", "--system", "pen", "--method", "collocation", "--vary", "I", "--down-to", "0.38", "--json")
    assert result.exit_code == 0, result.output
    out = json.loads(result.stdout)
    assert out["method"] == "collocation" and out["parameters"]["I"] == 0.4
    assert out["period"] == pytest.approx(PEN_PERIOD, abs=AGREE)
    multipliers = np.array([complex(*m) for m in out["multipliers"]])
    # The error reported is the distance of the nearest multiplier from +1.
    assert out["trivial_multiplier_error"] == pytest.approx(np.min(np.abs(multipliers - 1.0)), abs=1e-15)
    assert out["trivial_multiplier_error"] < AGREE
    # Liouville: det of the monodromy = exp(-(eps + eps) T) for two pendula of unit mass and damping eps.
    eps = out["parameters"]["eps"]
    assert np.prod(multipliers).real == pytest.approx(math.exp(-2.0 * eps * out["period"]), rel=1e-9)
    branch = out["branch"]
    assert branch["parameter"] == "I" and branch["values"][0] == 0.4
    # A slower drive, a longer period, all the way down; every orbit's trivial multiplier resolved.
    assert np.all(np.diff(branch["periods"]) > 0)
    assert max(branch["trivial_multiplier_error"]) < AGREE
    assert branch["end"] == "parameter_limit" and branch["message"].startswith("I=")


@pytest.mark.parametrize(
    ("args", "words"),
    [
        (["--method", "dense"], ["--method", "auto or collocation", "'dense'"]),
        # --out with collocation writes the file (tests/test_orbit_collocation_cli_sixteenth.py); --ntst needs collocation.
        (["--ntst", "60"], ["--ntst", "--method collocation"]),
    ],
)
def test_cli_collocation_bad_options_exit_2_naming_them(args, words, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    result = invoke("orbit", "--system", "pen", *args)
    assert result.exit_code == 2, result.output
    for word in words:
        assert word in result.output, (word, result.output)


@pytest.mark.slow
def test_period_doubling_beside_the_second_fold_is_a_multiplier_at_minus_one_by_shooting():
    # The snake's first fold has no period doubling beside it; the second has one 1.5e-7 in I away, on the side the
    # branch leaves the fold (T 22.16 against the fold's 22.09): the multiplier that the fold puts at +1 falls through
    # -1 there. Single shooting at that I, from the collocation's orbit, finds the same -1 to its own trivial
    # multiplier's accuracy; the fold's orbit itself has no multiplier near -1 (the event is not the fold's double +1).
    from cosserat_chain.numerics.shooting import find_orbit
    from cosserat_chain.numerics.system_collocation import continue_collocation_orbits, find_collocation_orbit
    from test_system_collocation import junction_rotation

    shooting = junction_rotation(jj3())
    start = find_collocation_orbit(shooting.system, shooting, ntst=200)
    branch = continue_collocation_orbits(start, "I", through_folds=True, period_max=22.6, max_points=2000)
    folds = [e for e in branch.events if e["kind"] == "fold"]
    assert len(folds) == 2
    fold = folds[1]
    beside = [e for e in branch.events if e["kind"] == "period_doubling" and e["orbit"].period > folds[0]["orbit"].period]
    assert len(beside) == 1 and beside[0]["located"]
    doubling = beside[0]
    assert 0.0 < fold["moment"] - doubling["moment"] < 2e-7
    assert doubling["orbit"].period > fold["orbit"].period
    assert np.min(np.abs(fold["orbit"].multipliers + 1.0)) > 0.5
    orbit = doubling["orbit"]
    shot = find_orbit(orbit.system, (orbit.y0, orbit.period), turns=orbit.turns)
    assert shot.period == pytest.approx(orbit.period, abs=1e-7)
    trivial = np.min(np.abs(shot.multipliers - 1.0))
    assert trivial < 1e-5
    assert np.min(np.abs(shot.multipliers + 1.0)) < 2.0 * trivial


def test_a_failed_solve_names_the_systems_parameters_not_the_chains_moment(pen_in_phase_orbit):
    from cosserat_chain.numerics.collocation_core import CollocationError
    from cosserat_chain.numerics.system_collocation import find_collocation_orbit

    orbit = pen_in_phase_orbit
    with pytest.raises(CollocationError, match=r"did not converge at I=0\.4, gamma=0\.175, eps=0\.1 .*a nearby value") as failed:
        find_collocation_orbit(orbit.system, (orbit.y0, 1.7 * orbit.period), turns=orbit.turns, max_iterations=1)
    assert "M=" not in str(failed.value)
