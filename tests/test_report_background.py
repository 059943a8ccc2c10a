"""The report's state diagram on a second core: the same report as in order, failures reported, progress honest."""

from __future__ import annotations

import json
import os
import sys

import pytest

import cosserat_chain.report as report_module
from cosserat_chain.report import ReproduceSettings, background, reproduce

#: One cheap row of the sine model's diagram (a fold of cycles) and nothing else.
QUICK = ReproduceSettings(diagram_damping={"sine": (0.2,), "nonlinear": ()})
STAGES = ["state_map", "errata"]

pytestmark = pytest.mark.skipif(background.free_cores() < 2 or not sys.platform.startswith("linux"), reason="needs fork and 2 cores")


def _files(folder) -> dict[str, str]:
    return json.loads((folder / "manifest.json").read_text())["files"]


def test_the_state_diagram_beside_the_other_stages_gives_the_report_in_order(tmp_path, monkeypatch):
    calls = []
    beside = reproduce(tmp_path / "beside", settings=QUICK, stages=STAGES, progress=lambda *call: calls.append(call))
    monkeypatch.setattr(background, "free_cores", lambda: 1)
    in_order = reproduce(tmp_path / "in_order", settings=QUICK, stages=STAGES)
    for name in STAGES:
        assert beside.summary["stages"][name]["numbers"] == in_order.summary["stages"][name]["numbers"]
        assert beside.summary["stages"][name]["error"] is None and beside.summary["stages"][name]["cpu_seconds"] > 0
    # The same files; the data the diagram wrote byte for byte.
    assert _files(tmp_path / "beside").keys() == _files(tmp_path / "in_order").keys()
    for name in ("data/state_diagram.json", "data/errata.json"):
        assert (tmp_path / "beside" / name).read_bytes() == (tmp_path / "in_order" / name).read_bytes()
    # Every stage announced in order, the diagram's rows reported, the count never falling, ending at the total.
    assert [name for name, *_ in calls if ":" not in name] == [*STAGES, "done"]
    assert any(name.startswith("state_map: sine") for name, *_ in calls)
    counts = [done for _, done, _ in calls]
    assert counts == sorted(counts) and calls[-1] == ("done", 2, 2)


def test_a_failing_background_stage_is_reported_and_the_others_still_appear(tmp_path, monkeypatch):
    def broken(stage):
        raise RuntimeError("the diagram exploded")

    monkeypatch.setitem(report_module.STAGES, "state_map", broken)
    result = reproduce(tmp_path, settings=QUICK, stages=STAGES)
    assert result.failed == ["state_map"]
    assert "the diagram exploded" in (tmp_path / "report.md").read_text()


def test_a_background_process_that_dies_leaves_an_error_section(tmp_path, monkeypatch):
    monkeypatch.setitem(report_module.STAGES, "state_map", lambda stage: os._exit(3))
    result = reproduce(tmp_path, settings=QUICK, stages=STAGES)
    assert result.failed == ["state_map"]
    assert "exit code 3" in result.summary["stages"]["state_map"]["error"]
    assert result.summary["stages"]["errata"]["error"] is None
