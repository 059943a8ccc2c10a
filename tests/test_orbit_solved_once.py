"""``orbit --method collocation --down-to`` solves its starting orbit once.

The command solved the orbit at its moment by collocation (``find_periodic_orbit``), and the
collocation continuation solved it again from that (``find_collocation_orbit``). Counted here:
every orbit solve, of either kind, at the starting moment.
"""

from __future__ import annotations

import json

import pytest
from typer.testing import CliRunner

from cosserat_chain import ChainParams
from cosserat_chain.cli import app
from cosserat_chain.experiments import orbits
from cosserat_chain.experiments.orbits import periodic_orbit
from cosserat_chain.numerics import collocation, periodic

MOMENT = 0.3
#: A short branch (a few orbits above the first branch point of cycles, 0.2977): the start's solves are the claim.
DOWN_TO = 0.299


@pytest.fixture
def solves(monkeypatch):
    """The moments of every orbit solve (shooting or collocation) the code makes, wherever it names the solvers."""
    moments: list[float] = []

    def counted(solver):
        def wrapper(params, model, moment, *args, **kwargs):
            moments.append(moment)
            return solver(params, model, moment, *args, **kwargs)

        return wrapper

    for module in (orbits, periodic, collocation):
        for name in ("find_periodic_orbit", "find_collocation_orbit"):
            if hasattr(module, name):
                monkeypatch.setattr(module, name, counted(getattr(module, name)))
    return moments


def test_the_api_solves_the_starting_orbit_once_and_continues_from_that_solve(solves):
    result = periodic_orbit(ChainParams(N=1), "nonlinear", MOMENT, down_to=DOWN_TO, method="collocation")
    assert solves == [MOMENT]
    # The branch starts at the very orbit reported.
    assert result.collocation is not None and result.branch.orbits[0].period == result.orbit.period
    assert result.branch.end == "moment_min" and result.branch.settings["method"] == "collocation"


def test_the_command_solves_the_starting_orbit_once(solves, tmp_path):
    config = tmp_path / "N1.toml"
    config.write_text("N = 1\n")
    command = ["orbit", "--model", "nonlinear", "--moment", str(MOMENT), "--down-to", str(DOWN_TO), "--method", "collocation"]
    result = CliRunner().invoke(app, [*command, "--config", str(config), "--json"])
    assert result.exit_code == 0, result.output
    assert solves.count(MOMENT) == 1 and len(solves) == 1
    data = json.loads(result.output)
    assert data["continuation"]["moment"][0] == pytest.approx(MOMENT, abs=0) and data["period"] == data["continuation"]["period"][0]


def test_the_shootings_branch_starts_from_its_own_single_solve(solves):
    result = periodic_orbit(ChainParams(N=1), "nonlinear", MOMENT, down_to=DOWN_TO, method="dense")
    assert solves == [MOMENT] and result.collocation is None


def test_collocation_with_segments_is_refused_naming_both():
    with pytest.raises(ValueError, match="segments applies to the dense and blocks shooting only, got method='collocation'"):
        periodic_orbit(ChainParams(N=1), "nonlinear", MOMENT, down_to=DOWN_TO, method="collocation", segments=4)
