"""A chain far from unit scale: the stiffness's eigenvalue search says why it cannot run, not ``division by zero``."""

from __future__ import annotations

import pytest
from typer.testing import CliRunner

from cosserat_chain import ChainParams
from cosserat_chain.cli import app
from cosserat_chain.experiments.critical import critical_point

#: Lengths of 1e99-1e100 with a unit inertia: the stiffness band spans 1e-1 to 1e199.
HUGE = {"h": 1e100, "a": 1e99, "b": 1e99, "j": 1.0}


def test_the_search_names_the_span_of_the_entries():
    with pytest.raises(FloatingPointError, match=r"cannot be searched in double precision: its entries span \S+ to \S+e\+19\d"):
        critical_point(ChainParams(**HUGE), "sine")


def test_critical_exits_3_with_the_reason(tmp_path):
    config = tmp_path / "huge.toml"
    config.write_text("".join(f"{key} = {value!r}\n" for key, value in HUGE.items()))
    result = CliRunner().invoke(app, ["critical", "--config", str(config)])
    assert result.exit_code == 3 and "unit scale" in result.output and "Traceback" not in result.output
