"""Defects found by the thirteenth session's audit of the chain's commands (H13audB).

Each test fails on the code before its fix.
"""

from __future__ import annotations

import pytest
from typer.testing import CliRunner

from cosserat_chain.cli import app

runner = CliRunner()


def _never(*args, **kwargs):
    raise AssertionError("computed before the refusal")


@pytest.mark.parametrize(("extra", "given"), [([], "neither"), (["--steps", "3", "--dm", "0.01"], "both")])
def test_sweep_without_exactly_one_of_steps_and_dm_is_refused_naming_both_options(monkeypatch, extra, given):
    """Before: ``sweep --m-max 0.05`` compiled the kernels and then failed with "member 0 (params_list[0]): give
    exactly one of steps ... and dm ...", naming an internal list and neither option."""
    monkeypatch.setattr("cosserat_chain.experiments.sweep.relaxation_sweep", _never)
    result = runner.invoke(app, ["sweep", "--model", "sine", "--m-max", "0.05", *extra])
    assert result.exception is None or isinstance(result.exception, SystemExit), repr(result.exception)
    text = result.output + getattr(result, "stderr", "")
    assert result.exit_code == 2, text
    assert "--steps" in text and "--dm" in text and given in text, text
    assert "params_list" not in text, text
