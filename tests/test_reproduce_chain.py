"""``reproduce`` computes the paper's chain: ends other than clamped and graded chains are refused before any stage runs."""

from __future__ import annotations

import pytest
from typer.testing import CliRunner

from cosserat_chain.cli import app

runner = CliRunner()


@pytest.mark.parametrize(
    ("config", "named"),
    [
        ('left_end = "pinned"\n', "needs both ends clamped"),
        ("E1_factors = [1, 1.2, 1, 1.2, 1, 1.2]\n", "got a graded one: E1_factors"),
        ("m_factors = [1, 1, 1, 2, 1, 1, 1]\nE2_factors = [1, 1, 1, 1, 1, 0.5]\n", "E2_factors, m_factors"),
    ],
)
def test_a_chain_the_report_does_not_compute_is_refused_before_any_stage(tmp_path, config, named):
    path = tmp_path / "chain.toml"
    path.write_text(config)
    out = tmp_path / "report"
    result = runner.invoke(app, ["reproduce", "--config", str(path), "--out", str(out), "--json"])
    assert result.exit_code == 2, result.output
    assert named in result.output and "Traceback" not in result.output
    assert not out.exists() or not any(out.iterdir())


def test_factors_all_alike_are_the_uniform_chain_and_pass_the_check():
    from cosserat_chain.params import ChainParams
    from cosserat_chain.report.settings import ReproduceSettings, chain_for_reading

    params = ChainParams(E1_factors=(2.0,) * 6)
    assert chain_for_reading(ReproduceSettings(), params) == ChainParams(E1=2.0)
