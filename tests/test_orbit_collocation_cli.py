"""``cosserat-chain orbit --method collocation``: a branch towards a SNIC end at a cost that does not grow with the period.

Issue 40: ``orbit --model nonlinear --moment 0.3 --down-to 0.1`` on the one-particle chain ran 30
minutes by shooting (every point integrates its monodromy over the whole period). By collocation
the branch reaches its period bound in seconds. Checked against independent references: the
statics' fold M_c (the orbit ends at a saddle-node on the invariant circle there), and the
shooting's Newton solved at the branch's last, longest orbit from it.
"""

from __future__ import annotations

import json

import pytest
from typer.testing import CliRunner

from cosserat_chain import ChainParams
from cosserat_chain.cli import app
from cosserat_chain.experiments import orbits
from cosserat_chain.numerics.collocation import continue_periodic_orbit
from cosserat_chain.numerics.periodic import find_periodic_orbit

runner = CliRunner()
#: The period bound: long enough for T ~ (M - M_c)^(-1/2) to put the end within 1e-4 of M_c.
PERIOD_MAX = 300.0


@pytest.fixture(scope="module")
def command_run(tmp_path_factory):
    """The command's JSON, and the arguments and result of the API call it made (:func:`continue_periodic_orbit`, spied
    on: the branch is computed once for the command's output and the API's checks)."""
    config = tmp_path_factory.mktemp("collocation_cli") / "N1.toml"
    config.write_text("N = 1\n")
    command = ["orbit", "--model", "nonlinear", "--moment", "0.3", "--down-to", "0.1", "--config", str(config)]
    calls = []

    def spy(orbit, **options):
        calls.append((orbit, options, continue_periodic_orbit(orbit, **options)))
        return calls[-1][2]

    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(orbits, "continue_periodic_orbit", spy)
        result = runner.invoke(app, [*command, "--period-max", str(PERIOD_MAX), "--method", "collocation", "--json"])
    assert result.exit_code == 0, result.output
    assert len(calls) == 1
    return json.loads(result.output), calls[0]


@pytest.fixture(scope="module")
def branch(command_run):
    return command_run[0]


def test_the_collocation_branch_ends_at_the_snic_of_the_static_fold(branch):
    continuation = branch["continuation"]
    assert continuation["end"] == "infinite_period" and continuation["end_period"] > PERIOD_MAX
    # A SNIC: the period diverges at the static fold, approached from above.
    assert 0.0 < continuation["end_moment"] - branch["static_fold"] < 1e-4
    # The branch points of cycles the nonlinear N = 1 orbit passes (mirror-symmetry breaking, issue 40).
    assert continuation["branch_points"][:2] == pytest.approx([0.2977176, 0.2949965], abs=1e-6)


def test_the_branchs_longest_orbit_is_the_shootings_at_its_moment(command_run):
    """The API's branch (the command's): its last, longest orbit solved again by shooting from it has the same period
    and the same largest multiplier (a separate integration of the variational equations over 300 time units)."""
    params = ChainParams(N=1)
    _, (orbit, options, branch) = command_run
    # The command's call is the API's: the N = 1 chain's orbit at M = 0.3 followed down to 0.1 within the period bound.
    assert orbit.params == params and orbit.model == "nonlinear" and orbit.moment == 0.3
    assert options["moment_min"] == 0.1 and options["period_max"] == PERIOD_MAX
    assert branch.end == "infinite_period" and branch.settings["method"] == "collocation"
    last = branch.orbits[-2]  # the last within the period bound
    shot = find_periodic_orbit(params, "nonlinear", last.moment, guess=last)
    assert last.period > 0.5 * PERIOD_MAX
    assert shot.period == pytest.approx(last.period, rel=1e-6)  # the default mesh (40 intervals of degree 4) there
    # The strongly damped multipliers of a long orbit are not resolved by the default mesh (6.6e-7 by shooting, 0.34
    # here): the stability is the same, and the branch's message says where the trivial multiplier showed it.
    assert shot.stable and last.stable
    assert "the multipliers there are not resolved" in branch.message


@pytest.mark.parametrize(
    ("options", "message"),
    [
        (["--method", "shooting"], "--method takes auto, dense, blocks, krylov, picard, collocation, got 'shooting'"),
        # With --system, --method is the system's (auto or collocation: tests/test_system_collocation_fifteenth.py); --moment is not.
        (["--system", "pen", "--method", "collocation"], "--moment belong(s) to the chain"),
    ],
)
def test_a_bad_method_exits_2_naming_what_is_allowed(options, message):
    result = runner.invoke(app, ["orbit", "--moment", "0.3", *options])
    assert result.exit_code == 2 and message in result.output, result.output


def test_the_json_lists_the_period_doublings_and_tori_a_branch_passed():
    """A collocation branch's period doublings and tori (its ``events``) reach ``continuation.events``; branch points stay apart."""
    from cosserat_chain.experiments.orbits import OrbitResult
    from cosserat_chain.numerics.periodic import OrbitBranch

    orbit = find_periodic_orbit(ChainParams(N=1), "sine", 0.5)
    events = [
        {"kind": "period_doubling", "moment": 0.45, "located": True, "multiplier": [-1.0, 0.0]},
        {"kind": "branch_point", "moment": 0.48},
        {"kind": "torus", "moment": 0.44, "located": True, "multiplier": [0.6, 0.8], "angle": 0.927},
    ]
    branch = OrbitBranch([orbit], "moment_min", 0.4, "", events=events)
    summary = OrbitResult(orbit=orbit, branch=branch, static_fold=0.47, settings={}).as_dict()["continuation"]
    assert summary["branch_points"] == [0.48]
    assert summary["events"] == [events[0], events[2]]
    json.dumps(summary)


@pytest.mark.parametrize(
    ("method", "branch_method"), [("dense", "dense"), ("blocks", "blocks"), ("krylov", "auto"), ("picard", "picard"), ("auto", "auto")]
)
def test_the_shooting_methods_reach_the_orbit_and_its_branch(monkeypatch, method, branch_method):
    """--method goes to the orbit's solve and to the continuation (krylov's continuation by auto: it needs the monodromy)."""
    from cosserat_chain.experiments import orbits

    seen = {}
    find, follow = orbits.find_periodic_orbit, orbits.continue_orbit

    def spy_find(*args, **kwargs):
        seen["find"] = kwargs.get("method")
        return find(*args, **kwargs)

    def spy_follow(*args, **kwargs):
        seen["follow"] = kwargs.get("method")
        return follow(*args, **{**kwargs, "max_points": 2})

    monkeypatch.setattr(orbits, "find_periodic_orbit", spy_find)
    monkeypatch.setattr(orbits, "continue_orbit", spy_follow)
    args = ["orbit", "--model", "sine", "--moment", "0.3", "--turns", "3", "--down-to", "0.29", "--method", method, "--json"]
    result = runner.invoke(app, args)
    assert result.exit_code == 0, result.output
    assert seen == {"find": method, "follow": branch_method}
