"""Codimension-two points between the state diagram's rows (issue 40 item 4): ``state_diagram(codim2=True)``,
``cosserat-chain diagram --codim2``.

Where two neighbouring rows end in different kinds, one row's end is followed towards the other value by
``numerics.cycle_curve.continue_cycle_end`` and what it locates on the way is listed. On the paper's chain (N = 3
sine, E2 varied) the torus end at E2 = 1.1 becomes the period doubling at 1.2 through a 1:2 resonance, located by
``cycle_curve`` at 1.1336439613 +- 3.4e-10 from the torus curve (from 1.0 up) and 1.1336439616 +- 7.7e-13 from the
period-doubling curve (tests/test_cycle_curve_codim2.py), by AUTO-07p at 1.1336440222 (docs/state-diagram.md).
"""

from __future__ import annotations

import json
from types import SimpleNamespace

import numpy as np
import pytest
from typer.testing import CliRunner

from cosserat_chain import ChainParams
from cosserat_chain.cli import app
from cosserat_chain.experiments import diagram
from cosserat_chain.numerics.cycle_curve import Codim2Point

runner = CliRunner()

#: The 1:2 resonance located by cycle_curve from the torus curve, its accuracy there; AUTO-07p's value.
R2, R2_ACCURACY, R2_AUTO = 1.1336439613, 3.4e-10, 1.1336440222


def row(value: float, end: str) -> diagram.DiagramRow:
    return diagram.DiagramRow(value, 0.2, 1.0, 0.17, end, True)


def edge(end: str, located: bool = True, angle: float = 1.0) -> diagram._Edge:
    """A row's end with an orbit whose complex pair lies on the unit circle at ``angle``."""
    pair = np.exp(1j * angle)
    orbit = SimpleNamespace(moment=0.17, nontrivial_multipliers=np.array([pair, np.conj(pair), 0.1])) if located else None
    return diagram._Edge(0.17, end, "", orbit=orbit)


@pytest.fixture
def followed(monkeypatch):
    """continue_cycle_end replaced by a record of its calls; it returns a curve that stops at a made-up 1:2 resonance."""
    calls = []

    def fake(orbit, kind, field_name, values):
        calls.append((kind, field_name, list(values)))
        point = Codim2Point("resonance_1_2", "R2", 0.5 * sum(values), 0.18, 11.7, None, 1e-10, 2e-10, np.pi)
        return SimpleNamespace(complete=False, points=[point], message=f"the {kind} end stops: it meets a 1:2 resonance")

    monkeypatch.setattr(diagram, "continue_cycle_end", fake)
    return calls


def test_rows_of_the_same_kind_list_nothing_and_a_change_of_kind_follows_the_first_row_s_end(followed):
    rows = [row(1.0, "torus"), row(1.05, "torus"), row(1.1, "period_doubling"), row(1.2, "period_doubling")]
    edges = [edge(r.end) for r in rows]
    (entry,) = diagram._codim2_between(rows, edges, "E2")
    assert followed == [("torus", "E2", [1.05, 1.1])]
    assert entry["between"] == [1.05, 1.1] and entry["ends"] == ["torus", "period_doubling"]
    assert entry["followed"] == "torus" and entry["from"] == 1.05 and entry["complete"] is False
    (point,) = entry["points"]
    assert (point["name"], point["label"], point["kind"]) == ("1:2 resonance", "R2", "resonance_1_2")
    assert point["value"] == pytest.approx(1.075) and point["accuracy"] == 2e-10
    assert "meets a 1:2 resonance" in entry["message"]
    json.dumps(entry)  # the JSON output and the NetCDF attribute take it as it is


def test_two_torus_rows_whose_angles_straddle_a_strong_resonance_follow_the_torus_end_between_them(followed):
    """cos theta through -1/2 (1:3) or 0 (1:4) between two torus rows: the first row's end is followed to the second
    value; angles on one side of both, or a row whose end has no orbit, list nothing."""
    rows = [row(0.9, "torus"), row(0.95, "torus"), row(1.0, "torus"), row(1.05, "torus")]
    third = 2 * np.pi / 3
    entries = diagram._codim2_between(rows, [edge("torus", angle=a) for a in (third - 0.1, third + 0.1, 1.5, 1.4)], "E2")
    assert followed == [("torus", "E2", [0.9, 0.95]), ("torus", "E2", [0.95, 1.0])]
    assert [e["straddles"] for e in entries] == [["resonance_1_3"], ["resonance_1_3", "resonance_1_4"]]
    assert entries[0]["angles"] == pytest.approx([third - 0.1, third + 0.1]) and entries[0]["ends"] == ["torus", "torus"]
    assert entries[0]["followed"] == "torus" and entries[0]["from"] == 0.9
    json.dumps(entries)
    followed.clear()
    assert diagram._codim2_between(rows[:2], [edge("torus", angle=1.0), edge("torus", angle=1.2)], "E2") == []
    assert diagram._codim2_between(rows[:2], [edge("torus", angle=1.0), edge("torus", located=False)], "E2") == []
    assert followed == []
    # Rows of different ends carry no angles.
    (entry,) = diagram._codim2_between([row(1.0, "torus"), row(1.1, "period_doubling")], [edge("torus"), edge("period_doubling")], "E2")
    assert entry["angles"] is None and entry["straddles"] == []


def test_between_two_torus_rows_of_the_paper_s_chain_the_1_to_3_resonance_is_located():
    """The paper's chain at E2 = 0.9 and 0.95 (torus ends whose pairs' angles lie either side of 2 pi / 3,
    tests/test_cycle_curve_codim2.py): the entry follows the torus end between them and names the 1:3 resonance
    (R3), its pair at 2 pi / 3 to 1e-8 and its value between the rows, at AUTO-07p's 0.9213118 to 5e-6."""
    from cosserat_chain.numerics.cycle_curve import torus_angle
    from cycle_ends import located_end

    rows, edges = [], []
    for value in (0.9, 0.95):
        orbit = located_end(ChainParams(E2=value), "torus")  # the one-turn branch's end, located (test_cycle_curve_codim2.py's)
        rows.append(diagram.DiagramRow(value, 0.2, 1.0, orbit.moment, "torus", True))
        edges.append(diagram._Edge(orbit.moment, "torus", "", orbit=orbit))
    (entry,) = diagram._codim2_between(rows, edges, "E2")
    assert entry["straddles"] == ["resonance_1_3"] and entry["angles"][0] < 2 * np.pi / 3 < entry["angles"][1]
    assert entry["complete"] is True and entry["followed"] == "torus"
    (point,) = entry["points"]
    assert (point["kind"], point["label"]) == ("resonance_1_3", "R3") and 0.9 < point["value"] < 0.95
    assert point["angle"] == pytest.approx(2 * np.pi / 3, abs=1e-8) and point["accuracy"] < 1e-9
    assert point["value"] == pytest.approx(0.9213118, abs=5e-6)
    assert "passes the 1:3 resonance (R3) at E2 = 0.92131" in entry["message"]
    assert torus_angle(edges[0].orbit) == pytest.approx(entry["angles"][0], abs=1e-15)
    json.dumps(entry)


def test_a_homoclinic_end_is_not_followed_and_the_entry_says_why(followed):
    # Homoclinic then torus: the torus end is followed back towards the homoclinic row.
    (entry,) = diagram._codim2_between([row(0.1, "homoclinic"), row(0.2, "torus")], [edge("homoclinic"), edge("torus")], "gamma_phi")
    assert followed == [("torus", "gamma_phi", [0.2, 0.1])] and entry["followed"] == "torus" and entry["from"] == 0.2
    assert "homoclinic end at gamma_phi = 0.1" in entry["message"] and "cannot be followed" in entry["message"]
    # Homoclinic next to a SNIC, or to an end that was not located exactly: nothing is followed, and each reason is given.
    followed.clear()
    pairs = ([row(0.1, "homoclinic"), row(0.2, "snic")], [row(0.1, "homoclinic"), row(0.2, "period_doubling")])
    for rows, edges in zip(pairs, ([edge("homoclinic"), edge("snic")], [edge("homoclinic"), edge("period_doubling", located=False)])):
        (entry,) = diagram._codim2_between(rows, edges, "gamma_phi")
        assert entry["followed"] is None and entry["points"] == [] and entry["complete"] is None
        assert entry["message"].startswith("not followed: ") and "homoclinic end at gamma_phi = 0.1" in entry["message"]
    assert "SNIC end lies on the static fold" in diagram._codim2_between(pairs[0], [None, None], "gamma_phi")[0]["message"]
    assert "not located exactly" in entry["message"] and followed == []


def test_the_between_entries_are_absent_unless_asked_for():
    result = diagram.StateDiagram(ChainParams(), "sine", "E2", 3, rows=[row(1.0, "torus"), row(1.2, "period_doubling")])
    assert result.as_dict()["codim2_between"] is None
    assert json.loads(result.to_dataset().attrs["codim2_between_json"]) is None


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["--vary", "E2", "--values", "1.1,1.2", "--codim2=yes"], "--codim2"),
        (["--system", "pendulum", "--vary", "alpha", "--values", "0.1,0.2", "--codim2", "--follow"], "--follow belong(s) to the chain"),
    ],
)
def test_bad_options_are_refused(args, message):
    result = runner.invoke(app, ["diagram", *args])
    assert result.exit_code == 2 and message in result.output, result.output


def test_a_codim2_that_is_not_a_bool_is_refused_before_any_computation():
    with pytest.raises(ValueError, match=r"codim2 must be True or False, got 'yes'"):
        diagram.state_diagram(ChainParams(), "sine", "E2", [1.1, 1.2], codim2="yes")


def run_json(values: str, *extra: str) -> dict:
    result = runner.invoke(app, ["diagram", "--model", "sine", "--vary", "E2", "--values", values, "--json", *extra])
    assert result.exit_code == 0, result.output
    return json.loads(result.output)


def test_two_period_doubling_rows_of_the_paper_s_chain_list_nothing_between_them():
    data = run_json("1.15,1.2", "--codim2")
    assert [r["end"] for r in data["rows"]] == ["period_doubling", "period_doubling"]
    assert data["codim2_between"] == []


@pytest.mark.slow
@pytest.mark.parametrize(("values", "followed"), [("1.1,1.2", "torus"), ("1.2,1.1", "period_doubling")])
def test_the_1_to_2_resonance_between_the_torus_row_and_the_period_doubling_row(tmp_path, values, followed):
    """Either row first: its end is followed towards the other value, stops at the 1:2 resonance and names it, at
    cycle_curve's value (from the torus curve, started at 1.0) to the two stated accuracies, at AUTO-07p's to 1e-6."""
    import xarray as xr

    out = tmp_path / "diagram.nc"
    data = run_json(values, "--codim2", "--out", str(out))
    ends = {r["value"]: r["end"] for r in data["rows"]}
    assert ends == {1.1: "torus", 1.2: "period_doubling"}
    (entry,) = data["codim2_between"]
    assert entry["followed"] == followed and entry["from"] == float(values.split(",")[0]) and entry["complete"] is False
    (point,) = entry["points"]
    assert (point["kind"], point["label"], point["name"]) == ("resonance_1_2", "R2", "1:2 resonance")
    assert 1.1 < point["value"] < 1.2 and 0 < point["accuracy"] < 1e-9
    assert abs(point["value"] - R2) <= point["accuracy"] + R2_ACCURACY
    assert abs(point["value"] - R2_AUTO) < 1e-6
    assert point["moment"] == pytest.approx(0.1775300235, abs=1e-9)
    assert "1:2 resonance (R2)" in entry["message"] and "could not be followed beyond" in entry["message"]
    with xr.open_dataset(out) as ds:
        assert json.loads(ds.attrs["codim2_between_json"]) == data["codim2_between"]
    text = runner.invoke(app, ["diagram", "--model", "sine", "--vary", "E2", "--values", values, "--codim2"]).output
    assert f"a 1:2 resonance (R2) at E2 = {point['value']:.10g} +- {point['accuracy']:.2g}" in text
