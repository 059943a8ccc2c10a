"""Every figure of the report draws the numbers of its stage's JSON, and the page fits any window (issue 43, item 4).

The report's figures are caught as its stages make them (before they become pictures),
and their artists' data are compared with the JSON files the same stages wrote under
``data/``.
"""

from __future__ import annotations

import json
import re

import numpy as np
import pytest

import cosserat_chain.report as report_module
from conftest import quick_report_settings
from cosserat_chain.experiments.diagram import DiagramRow, StateDiagram
from cosserat_chain.params import ChainParams
from cosserat_chain.plots.diagram import REGIONS, diagram_figure
from cosserat_chain.report import reproduce

RTOL = 1e-12

SETTINGS = quick_report_settings()


@pytest.fixture(scope="module")
def drawn(quick_report_and_figures):
    """(report, {stem: Figure}) of the quick report, whose stages' figures plot numbers of their JSON."""
    report, figures = quick_report_and_figures
    assert report.failed == []
    return report, figures


def data(report, name: str):
    return json.loads((report.out / "data" / f"{name}.json").read_text())


def points(ax) -> np.ndarray:
    """Every (x, y) point of the axes' lines, shape (n, 2)."""
    pairs = [np.column_stack([np.atleast_1d(line.get_xdata()), np.atleast_1d(line.get_ydata())]) for line in ax.lines]
    return np.concatenate(pairs).astype(float)


def has_point(ax, x: float, y: float | None = None, rtol: float = RTOL) -> bool:
    xy = points(ax)
    near_x = np.isclose(xy[:, 0], x, rtol=rtol, atol=0.0)
    return bool(near_x.any() if y is None else (near_x & np.isclose(xy[:, 1], y, rtol=rtol, atol=1e-12)).any())


def vertical_lines(ax) -> list[float]:
    return [float(line.get_xdata()[0]) for line in ax.lines if len(set(np.atleast_1d(line.get_xdata()).tolist())) == 1]


def region_span(ax, gid: str, value: float) -> tuple[float, float] | None:
    """Lowest and highest M that the region ``gid`` covers at ``value`` of the varied field, or None.

    Only what shows counts: a bar or an area of positive width around the value.
    """
    spans = []
    for patch in ax.patches:  # a value alone: bars
        if patch.get_gid() == gid and patch.get_width() > 0 and patch.get_x() <= value <= patch.get_x() + patch.get_width():
            spans.append((patch.get_y(), patch.get_y() + patch.get_height()))
    for collection in ax.collections:  # consecutive values: areas between them
        if collection.get_gid() == gid:
            for path in collection.get_paths():
                at = path.vertices[np.isclose(path.vertices[:, 0], value)]
                if at.size and np.ptp(path.vertices[:, 0]) > 0:
                    spans.append((at[:, 1].min(), at[:, 1].max()))
    if not spans:
        return None
    return min(s[0] for s in spans), max(s[1] for s in spans)


def line(ax, gid: str):
    return next(line for line in ax.lines if line.get_gid() == gid)


def check_regions(ax, rows: list[dict]) -> None:
    """The diagram's regions at each row agree with the row's edges (dimensionless) as the JSON gives them."""
    for row in rows:
        value, fold, stops = row["value"], row["static_fold_dimensionless"], row["rotation_stops_dimensionless"]
        static, loop, rotating = (region_span(ax, name, value) for name in ("static", "hysteresis", "rotating"))
        # No static state exists above M_c: the static region ends at M_c or where the rotation stops, the lower.
        assert static == pytest.approx((0.0, min(fold, stops)), rel=RTOL)
        assert rotating[0] == pytest.approx(fold, rel=RTOL)
        if row["hysteresis"]:
            assert loop == pytest.approx((stops, fold), rel=RTOL)
        else:
            assert loop is None or loop[1] - loop[0] == 0.0


def test_the_state_diagram_draws_the_edges_and_regions_of_its_json(drawn):
    report, figures = drawn
    rows = data(report, "state_diagram")["sine"]
    ax = figures["state_diagram_sine"].axes[0]
    assert line(ax, "static_fold").get_ydata().tolist() == pytest.approx([r["static_fold_dimensionless"] for r in rows], rel=RTOL)
    assert line(ax, "rotation_stops").get_ydata().tolist() == pytest.approx([r["rotation_stops_dimensionless"] for r in rows], rel=RTOL)
    assert line(ax, "static_fold").get_xdata().tolist() == [r["value"] for r in rows]
    check_regions(ax, rows)


def diagram(rows: list[tuple[float, float, float, str, bool | None]]) -> StateDiagram:
    return StateDiagram(
        ChainParams(),
        "sine",
        "gamma_phi",
        1,
        [DiagramRow(value, fold, 1.5, stops, end, loop) for value, fold, stops, end, loop in rows],
    )


def as_json(result: StateDiagram) -> list[dict]:
    return json.loads(json.dumps(result.as_dict()["rows"]))


def test_a_diagram_of_one_value_draws_its_regions_as_a_bar_and_its_edges_as_points():
    """The nonlinear state diagram of the report has one damping value: an area between values would be empty."""
    one = diagram([(0.2, 0.1975, 0.15, "torus", True)])
    ax = diagram_figure(one).axes[0]
    for name in REGIONS:
        span = region_span(ax, name, 0.2)
        assert span is not None and span[1] > span[0], name
    assert line(ax, "static_fold").get_marker() != "None" and has_point(ax, 0.2, 0.1975) and has_point(ax, 0.2, 0.15)
    check_regions(ax, as_json(one))


def test_no_static_region_above_the_critical_moment_where_the_rotation_stops_above_it():
    """Where the followed orbit loses stability above M_c (hysteresis unknown), no static state exists between M_c and it."""
    # The loop is open at 0.1 alone: its region there must show although its neighbours have none.
    rows = [(0.05, 0.204, 0.23, "torus", None), (0.1, 0.204, 0.17, "torus", True), (0.5, 0.204, 0.204, "snic", False)]
    for result in (diagram(rows), diagram(rows[:1])):
        ax = diagram_figure(result).axes[0]
        check_regions(ax, as_json(result))
        assert region_span(ax, "static", 0.05)[1] == pytest.approx(0.204, rel=RTOL)


def test_figure_2_marks_the_folds_and_onsets_of_its_json(drawn):
    report, figures = drawn
    numbers = data(report, "statics")
    left = figures["fig2"].axes[0]
    for model in ("nonlinear", "sine"):
        item = numbers[model]
        assert has_point(left, item["M_c_dimensionless"], item["phi0_at_fold"]), model
        assert has_point(left, item["onset_load"] / numbers["moment_scale"]), model
    hysteresis = figures["hysteresis"].axes[0]
    for model in ("nonlinear", "sine"):
        assert any(np.isclose(x, numbers[model]["M_c_dimensionless"], rtol=RTOL) for x in vertical_lines(hysteresis)), model


def test_the_rotation_characteristic_draws_the_edges_of_its_json(drawn):
    report, figures = drawn
    numbers = data(report, "orbit_summary")
    ax = figures["rotation_characteristic"].axes[0]
    verticals = vertical_lines(ax)
    for key in ("static_fold", "stability_lost_at"):
        assert any(np.isclose(x, numbers[key], rtol=RTOL) for x in verticals), key
    assert has_point(ax, numbers["orbit_end_moment"]) and has_point(ax, numbers["moment"], numbers["mean_angular_velocity"])


def test_the_critical_moment_against_length_draws_its_json(drawn):
    report, figures = drawn
    numbers = data(report, "long_chains")
    moment_axes = figures["critical_vs_N"].axes[0]
    for model, rows in numbers.items():
        for row in rows:
            shown = row["M_c"] * (row["N"] if model == "sine" else 1)
            assert has_point(moment_axes, row["N"], shown), (model, row["N"])


def test_the_continuum_convergence_draws_the_errors_of_its_json(drawn):
    report, figures = drawn
    numbers = data(report, "continuum")
    ax = figures["convergence"].axes[0]
    for n, error, residue in zip(numbers["N"], numbers["relative_error"], numbers["residue"]):
        assert has_point(ax, n, error) and has_point(ax, n, residue), n


def test_the_dispersion_figure_draws_the_band_edges_and_the_gap_of_its_json(drawn):
    report, figures = drawn
    numbers = data(report, "waves")
    ax = figures["dispersion"].axes[0]
    for branch in numbers["at_zero"]:
        # The curves are sampled on their own grid of q, the JSON's edges solved at q = 0 and pi.
        assert has_point(ax, 0.0, numbers["at_zero"][branch], rtol=1e-9), branch
        assert has_point(ax, np.pi, numbers["at_pi"][branch], rtol=1e-9), branch
    spans = [(patch.get_y(), patch.get_y() + patch.get_height()) for patch in ax.patches]
    assert any(np.allclose(span, numbers["gap"], rtol=RTOL) for span in spans), spans


@pytest.mark.parametrize("stem, model", [("fig3a", "sine"), ("fig3b", "nonlinear")])
def test_figure_3_draws_the_chain_of_its_run_at_the_stored_frames(drawn, stem, model):
    from cosserat_chain.io import read_dataset

    report, figures = drawn
    run = read_dataset(report.out / "data" / f"rotation_{model}.nc")
    panels = [ax for ax in figures[stem].axes if ax.get_title().startswith("t = ")]
    assert len(panels) == len(SETTINGS.snapshot_times)
    for ax, t in zip(panels, SETTINGS.snapshot_times):
        frame = run.sel(time=t, method="nearest")
        assert ax.get_title() == f"t = {float(frame.time):g}"
        centres = line(ax, "centre_line")
        assert centres.get_xdata() == pytest.approx(frame.particle.values * run.attrs["param_h"] + frame.u.values, rel=RTOL, abs=1e-15)
        assert centres.get_ydata() == pytest.approx(frame.v.values, rel=RTOL, abs=1e-15)


def test_the_page_fits_a_narrow_window(drawn):
    report, _ = drawn
    page = (report.out / "index.html").read_text()
    assert re.search(r"<meta name='viewport' content='width=device-width, initial-scale=1'>", page)
    assert re.search(r"img \{ max-width: 100%; height: auto; \}", page)  # every image, the animation's too
    assert page.count("<figure>") == sum(1 for line in (report.out / "report.md").read_text().splitlines() if line.startswith("!["))


def test_the_page_escapes_what_it_shows(tmp_path, monkeypatch):
    """Text of a stage reaches the page as text, never as markup."""

    def hostile(stage):
        return report_module.Section("a <b>bold</b> & 'quoted' title", paragraphs=["x < y & <script>alert(1)</script>"])

    monkeypatch.setitem(report_module.STAGES, "waves", hostile)
    reproduce(tmp_path, settings=SETTINGS, stages=["waves"])
    page = (tmp_path / "index.html").read_text()
    assert "<script>" not in page and "&lt;script&gt;" in page and "a &lt;b&gt;bold&lt;/b&gt; &amp;" in page


def test_a_study_of_one_cell_draws_its_values_as_points():
    from cosserat_chain.experiments.study import empty_results, spec_from_mapping, store_cell
    from cosserat_chain.plots.study import study_figure

    spec = spec_from_mapping({"parameters": {"a": [0.1]}, "models": ["sine", "nonlinear"], "quantities": ["M_c"]})
    ds = empty_results(spec)
    for model, value in (("sine", 0.204), ("nonlinear", 0.1975)):
        store_cell(ds, spec, (0,), model, {"M_c": value})
    (ax,) = study_figure(ds).axes
    drawn = {line.get_label(): line for line in ax.lines}
    for model, value in (("sine", 0.204), ("nonlinear", 0.1975)):
        assert drawn[model].get_marker() not in ("None", "", None) and has_point(ax, 0.1, value), model
