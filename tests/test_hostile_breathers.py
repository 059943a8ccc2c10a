"""``breathers`` refuses, before computing, a family from one frequency to itself, frequencies whose rotor energy
leaves double precision and absurd turns (hostile audit: these printed a NaN-state message, overflow warnings
with exit 0, or ran on)."""

from __future__ import annotations

import pytest
from typer.testing import CliRunner

from cosserat_chain.cli import app


@pytest.mark.parametrize(
    "arguments, named",
    [
        (["--omega", "6", "--to", "6"], "--to must differ from --omega"),
        (["--omega", "6", "--to", "1e300"], "--to"),
        (["--omega", "1e300"], "--omega"),
        (["--omega", "6", "--turns", "1000000000"], "--turns"),
        (["--system", "takeno_peyrard", "--omega", "2", "--to", "2"], "--to must differ from --omega"),
    ],
)
def test_bad_frequencies_and_turns_are_refused_naming_the_option(arguments, named):
    result = CliRunner().invoke(app, ["breathers", *arguments])
    assert result.exit_code == 2 and named in result.output and "Traceback" not in result.output
