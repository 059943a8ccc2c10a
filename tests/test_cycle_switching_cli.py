"""``cosserat-chain orbit --down-to M --switch KIND`` (issue 40 item 4): the family born at the continued branch's
first period doubling or branch point of cycles, from the command line.

Checked against the Python API (``switch_at_branch_point``, ``switch_at_period_doubling`` on the same branch) on
the nonlinear N = 1 chain (mirror-symmetry-breaking branch point at M = 0.29772) and the sine chain at
gamma_phi = 0.15 (period doubling at M = 0.172882); bad values exit 2, a branch without the point exits 3.
"""

from __future__ import annotations

import json

import pytest
from typer.testing import CliRunner

from cosserat_chain.cli import app

runner = CliRunner()


@pytest.fixture(scope="module")
def config(tmp_path_factory):
    path = tmp_path_factory.mktemp("switch") / "N1.toml"
    path.write_text("N = 1\n")
    return str(path)


@pytest.mark.slow
def test_the_branch_point_switch_is_the_apis(config):
    from cosserat_chain import ChainParams
    from cosserat_chain.numerics.cycle_branch_points import switch_at_branch_point
    from cosserat_chain.numerics.periodic import continue_orbit, find_periodic_orbit

    command = ["orbit", "--model", "nonlinear", "--moment", "0.3", "--turns", "1", "--config", config, "--down-to", "0.294"]
    result = runner.invoke(app, [*command, "--switch", "branch-point", "--json"])
    assert result.exit_code == 0, result.output
    switch = json.loads(result.stdout)["switch"]
    api = switch_at_branch_point(continue_orbit(find_periodic_orbit(ChainParams(N=1), "nonlinear", 0.3), moment_min=0.294))
    assert switch["kind"] == "mirror_symmetry_breaking" == api.kind and switch["side"] == "above"
    assert switch["value"] == pytest.approx(api.value, abs=2e-5) and switch["value"] == pytest.approx(0.29772, abs=3e-5)
    assert switch["branch"]["end"] == api.branch.end
    text = runner.invoke(app, [*command, "--switch", "branch-point"])
    assert text.exit_code == 0 and "switched at the branch-point at M = 0.2977" in text.stdout


@pytest.mark.slow
def test_the_period_doubling_switch_follows_the_doubled_orbit(tmp_path):
    """The paper's chain at gamma_phi = 0.15 doubles at M = 0.172882 (tests/test_cycle_switching.py) into stable
    two-turn orbits below."""
    path = tmp_path / "gp.toml"
    path.write_text("gamma_phi = 0.15\n")
    command = ["orbit", "--model", "sine", "--moment", "0.19", "--turns", "1", "--config", str(path), "--down-to", "0.17"]
    result = runner.invoke(app, [*command, "--switch", "period-doubling", "--json"])
    assert result.exit_code == 0, result.output
    switch = json.loads(result.stdout)["switch"]
    assert switch["value"] == pytest.approx(0.172882, abs=1e-5) and switch["side"] == "below"
    assert switch["doubled"]["turns"] == 2 and switch["branch"] is not None


@pytest.mark.parametrize(
    "extra, code, message",
    [
        (["--switch", "torus"], 2, "--switch takes period-doubling or branch-point"),
        (["--switch", "branch-point", "--down-to", "0.299"], 3, "--switch branch-point: the branch has 0 branch point"),
    ],
)
def test_bad_switches_exit_with_a_message(config, extra, code, message):
    base = ["orbit", "--model", "nonlinear", "--moment", "0.3", "--turns", "1", "--config", config]
    if "--down-to" not in extra:
        base += ["--down-to", "0.294"]
    result = runner.invoke(app, [*base, *extra])
    assert result.exit_code == code and message in result.output


def test_a_switch_needs_the_continued_branch(config):
    result = runner.invoke(app, ["orbit", "--model", "nonlinear", "--moment", "0.3", "--config", config, "--switch", "branch-point"])
    assert result.exit_code == 2 and "with --down-to" in result.output
