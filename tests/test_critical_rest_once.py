"""``critical`` solves the chain's response at rest once per model, and still refuses a K singular at rest up front.

The command checked K at rest by solving the whole chain's response before ``critical_point``,
which solves it again (its compliance). The up-front check now runs on a short chain of the same
fields (a K singular by fields far from order 1 is so at any length), and the response
``critical_point`` solves is checked on its result.
"""

from __future__ import annotations

import pytest
from typer.testing import CliRunner

from cosserat_chain import ChainParams
from cosserat_chain.cli import app
from cosserat_chain.cli.common import SHORT_N
from cosserat_chain.experiments import critical
from cosserat_chain.numerics import continuation

runner = CliRunner()


def _config(folder, text: str) -> str:
    (folder / "chain.toml").write_text(text)
    return str(folder / "chain.toml")


def test_the_command_solves_the_whole_chains_response_at_rest_no_more_than_critical_point_does(monkeypatch, tmp_path):
    lengths: list[int] = []
    solve = continuation.moment_response

    def counted(params, *args, **kwargs):
        lengths.append(params.N)
        return solve(params, *args, **kwargs)

    monkeypatch.setattr(continuation, "moment_response", counted)
    monkeypatch.setattr(critical, "moment_response", counted)
    critical.critical_point(ChainParams(N=12), "linear")
    by_the_api = lengths.count(12)
    lengths.clear()
    result = runner.invoke(app, ["critical", "--model", "linear", "--config", _config(tmp_path, "N = 12\n"), "--json"])
    assert result.exit_code == 0, result.output
    assert by_the_api >= 1 and lengths.count(12) == by_the_api and lengths.count(SHORT_N) == 1


def _never(*args, **kwargs):
    raise AssertionError("the computation ran")


@pytest.mark.parametrize("field", ["E1", "b"])
def test_a_k_singular_by_its_fields_is_refused_before_the_computation(monkeypatch, tmp_path, field):
    monkeypatch.setattr(critical, "critical_point", _never)
    result = runner.invoke(app, ["critical", "--model", "nonlinear", "--config", _config(tmp_path, f"N = 200\n{field} = 1e-100\n")])
    assert result.exit_code == 2, result.output
    assert "singular in double precision" in result.output and f"{field}=1e-100" in result.output


def test_a_compliance_beyond_range_from_the_computation_is_refused_naming_the_fields(tmp_path):
    # Fields the short chain passes (its compliance about 4e99) while the whole chain's is beyond 1e100.
    result = runner.invoke(app, ["critical", "--model", "linear", "--config", _config(tmp_path, "N = 40\nE1 = 1e-99\n")])
    assert result.exit_code == 2, result.output
    assert "singular in double precision" in result.output and "E1=1e-99" in result.output
