"""``study`` refuses, before any cell runs, a chain too long for this machine's memory.

A spec with N = 10^9 ran every cell, each failing on its own memory estimate (exit 3). The
estimates its quantities check first are now checked for the study's longest chain up front
(exit 2 naming N's entry, its value, and the memory needed against the memory free), and they
are the cells' own: a cell run anyway fails with the same numbers.
"""

from __future__ import annotations

import pytest
from typer.testing import CliRunner

from cosserat_chain import memory
from cosserat_chain.cli import app
from cosserat_chain.experiments.study import compute_cell, spec_from_mapping

runner = CliRunner()
FREE = 16 * 2**30


@pytest.fixture
def sixteen_gib(monkeypatch):
    monkeypatch.setattr(memory, "available", lambda: FREE)


def _never(*args, **kwargs):
    raise AssertionError("a cell ran")


@pytest.mark.parametrize("quantity", ["M_c", "onset_load", "mean_angular_velocity"])
def test_the_up_front_estimate_is_the_one_a_cell_fails_on(monkeypatch, quantity):
    # A machine with 1 MiB free: a chain of N = 2000 (arrays of 100 kB) is refused by the branch's and the
    # batch's estimates, and a cell run anyway fails on the same numbers.
    monkeypatch.setattr(memory, "available", lambda: 2**20)
    spec = spec_from_mapping({"models": ["sine"], "quantities": [quantity], "loads": [0.3], "parameters": {"N": [3, 2000]}})
    with pytest.raises(ValueError, match=r"^parameters.N = 2000: every cell of this chain would fail: not enough memory") as caught:
        spec.check_memory()
    needed = str(caught.value).split("not enough memory: ", 1)[1]
    assert "and this machine has 1 MiB free" in needed
    (fields,) = [fields for _, _, fields in spec.cells() if fields["N"] == 2000]
    assert compute_cell(fields, "sine", spec.to_json())["error"].endswith(needed)


def test_a_study_that_fits_passes_and_band_gap_needs_no_chain(sixteen_gib):
    spec_from_mapping({"models": ["sine"], "quantities": ["M_c", "onset_load"], "parameters": {"N": [3, 30]}}).check_memory()
    spec_from_mapping({"models": ["sine"], "quantities": ["band_gap"], "parameters": {"N": [3, 10**9]}}).check_memory()


def test_a_fixed_n_is_named_as_fixed(sixteen_gib):
    spec = spec_from_mapping({"models": ["sine"], "quantities": ["compliance"], "parameters": {"a": [0.1, 0.2]}, "fixed": {"N": 10**9}})
    with pytest.raises(ValueError, match=r"^fixed.N = 1000000000: .*40 states of 2000000001 particles .*needs about 1.75 TiB"):
        spec.check_memory()


def test_the_command_exits_2_before_any_cell_runs(sixteen_gib, monkeypatch, tmp_path):
    monkeypatch.setattr("cosserat_chain.study_runner.run_study", _never)
    spec = tmp_path / "big.toml"
    spec.write_text('models = ["nonlinear"]\nquantities = ["compliance"]\n[parameters]\nN = [3, 1000000000]\n')
    result = runner.invoke(app, ["study", str(spec), "--json"])
    assert result.exit_code == 2, result.output
    assert "parameters.N = 1000000000" in result.output and "needs about 1.75 TiB" in result.output and "16 GiB free" in result.output
