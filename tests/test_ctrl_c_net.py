"""Ctrl-C in a command without its own handling exits 130 saying so (the application's net), not with a traceback or in
silence (``theory``, ``critical`` and ``waves`` had no handler of their own)."""

from __future__ import annotations

import pytest
from typer.testing import CliRunner

from cosserat_chain.cli import app


def ctrl_c(*args, **kwargs):
    raise KeyboardInterrupt


@pytest.mark.parametrize(
    "argv, target",
    [
        (["theory"], "cosserat_chain.analysis.continuum.convergence"),
        (["critical"], "cosserat_chain.experiments.critical.critical_point"),
        (["waves"], "cosserat_chain.analysis.dispersion.wave_summary"),
    ],
)
def test_ctrl_c_exits_130_saying_nothing_was_kept(monkeypatch, argv, target):
    monkeypatch.setattr(target, ctrl_c)
    result = CliRunner().invoke(app, argv)
    assert result.exit_code == 130, result.output
    assert f"{argv[0]} was interrupted before it finished: its result is not complete" in result.output
    assert "Traceback" not in result.output
