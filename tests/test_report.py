"""``cosserat-chain reproduce``: the report's content equals the API's numbers, every reference resolves, failures show."""

from __future__ import annotations

import json
import re

import numpy as np
import pytest
import scipy.sparse.linalg as spla
from typer.testing import CliRunner

import cosserat_chain.report as report_module
from conftest import quick_report_settings
from cosserat_chain import ChainParams
from cosserat_chain.analysis.agreement import agreement_range, static_deviation
from cosserat_chain.analysis.continuum import convergence
from cosserat_chain.cli import app
from cosserat_chain.experiments.critical import critical_point
from cosserat_chain.experiments.localization import localization_run
from cosserat_chain.experiments.sweep import relaxation_sweep
from cosserat_chain.io import read_dataset
from cosserat_chain.models.linear import stiffness_matrix
from cosserat_chain.numerics.continuation import locate_fold
from cosserat_chain.numerics.newton import moment_dof
from cosserat_chain.report import format_cell, reproduce
from cosserat_chain.state import n_free, unpack

QUICK = quick_report_settings()


@pytest.fixture(scope="module")
def quick_report(quick_report_and_figures):
    return quick_report_and_figures[0]


def markdown_tables(text: str) -> dict[str, list[list[str]]]:
    """Caption -> rows (header first) of every table in report.md."""
    tables, caption, rows = {}, None, []
    for line in text.splitlines():
        if line.startswith("*") and line.endswith("*") and not line.startswith("**"):
            caption = line.strip("*")
        elif line.startswith("|") and caption is not None:
            if not line.startswith("|---"):
                rows.append([cell.strip() for cell in line.strip("|").split("|")])
        elif rows:
            tables[caption], caption, rows = rows, None, []
    return tables


def test_every_stage_ran_and_the_summary_parses(quick_report):
    assert quick_report.failed == []
    summary = json.loads((quick_report.out / "summary.json").read_text())
    assert set(summary["stages"]) == set(report_module.STAGES)
    assert all(stage["seconds"] > 0 and stage["error"] is None for stage in summary["stages"].values())
    assert summary["params"] == ChainParams().model_dump() == json.loads((quick_report.out / "params.json").read_text())
    for path in (quick_report.out / "data").glob("*.json"):
        json.loads(path.read_text())


def test_every_figure_the_pages_reference_exists(quick_report):
    markdown = (quick_report.out / "report.md").read_text()
    page = (quick_report.out / "index.html").read_text()
    linked = set(re.findall(r"\((figures/[\w.]+)\)", markdown)) | set(re.findall(r"href='(figures/[\w.]+)'", page))
    assert {
        "figures/fig2.png",
        "figures/fig3a.svg",
        "figures/fig3b.png",
        "figures/rotation.gif",
        "figures/dispersion.svg",
        "figures/rotation_characteristic.png",
    } <= linked
    for link in linked:
        assert (quick_report.out / link).stat().st_size > 1000, link
    # Self-contained: pictures are embedded, nothing is fetched from a network.
    assert "http://" not in page and "https://" not in page
    assert page.count("src='data:image/png;base64,") == markdown.count("![")


def test_table_numbers_equal_the_python_api(quick_report, paper_sine_branch):
    """Each table's numbers are the API's, computed here again; the hysteresis edges' branch is the session's
    ``paper_sine_branch`` (conftest.py: the sine orbit at ``QUICK.orbit_moment`` = 0.22 continued down to
    ``orbit_down_to`` = 0.1 by ``continue_orbit`` with its defaults, the call ``periodic_orbit`` makes)."""
    params = ChainParams()
    assert (QUICK.orbit_moment, QUICK.orbit_down_to) == (paper_sine_branch.orbits[0].moment, 0.1)
    tables = markdown_tables((quick_report.out / "report.md").read_text())
    statics = next(rows for caption, rows in tables.items() if caption.startswith("Compliance, critical moment"))
    for row in statics[1:]:
        model = row[0]
        exact = critical_point(params, model)
        sweep = relaxation_sweep(params, model, m_max=QUICK.m_max, dm=QUICK.dm, down=True)
        assert row[1:] == [
            format_cell(v) for v in (exact.compliance, exact.critical_moment, exact.phi0_at_onset, sweep.onset_load, sweep.stop_load)
        ]
    localization = tables["Statistics of the localization run"]
    for row in localization[1:]:
        model = row[0]
        result = localization_run(params, model, QUICK.rotation_moment[model], turns=QUICK.turns, t_max=100.0 * QUICK.turns).as_dict()
        keys = (
            "turns_completed",
            "t_end",
            "mean_angular_velocity",
            "max_abs_phi_others",
            "max_abs_v_others_over_h",
            "max_abs_u_others_over_h",
        )
        assert row[2:8] == [format_cell(result[k]) for k in keys]
        assert row[8:] == [", ".join(result["outside_model_validity"]) or "—", result["classification"]]
    agreement = next(rows for caption, rows in tables.items() if caption.startswith("How far the models agree"))
    for row in agreement[1:]:
        # The stage reuses the critical branch; traced afresh here.
        edge = agreement_range(params, row[0], tolerance=report_module.AGREEMENT_TOLERANCE)
        assert row[1:6] == [format_cell(v) for v in (edge.moment, edge.phi0_linear, edge.phi0, edge.bound)] + [
            format_cell(float(static_deviation(params, row[0], [report_module.AGREEMENT_ANGLE])[0]))
        ]
    edges = tables["Edges of the hysteresis loop: exact, and by the relaxation protocol"][1]
    sine_sweep = relaxation_sweep(params, "sine", m_max=QUICK.m_max, dm=QUICK.dm, down=True)
    expected = [
        locate_fold(params, "sine").moment,
        paper_sine_branch.stability_lost_at,
        paper_sine_branch.end_moment,
        paper_sine_branch.end,
        sine_sweep.onset_load,
        sine_sweep.stop_load,
    ]
    assert edges[1:] == [format_cell(v) for v in expected]
    continuum = tables["Continuum against discrete compliance"]
    table = convergence(params, list(QUICK.n_list))
    assert [row[3] for row in continuum[1:]] == [format_cell(e) for e in table.relative_error]
    assert [row[5] for row in continuum[1:]] == [format_cell((c - d) / d) for c, d in zip(table.continuum, table.discrete)]
    # The sine model's M_c of each chain length is 1/(largest linear rotation compliance),
    # an independent linear solve; the nonlinear one equals the API's.
    long = tables["M_c against N"]
    for row in long[1:]:
        chain = params.replace(N=int(row[1]))
        if row[0] == "sine":
            e = np.zeros(n_free(chain))
            e[moment_dof(chain)] = 1.0
            rotations = unpack(chain, spla.spsolve(stiffness_matrix(chain).tocsc(), e))[2]
            assert float(row[2]) == pytest.approx(1.0 / np.max(np.abs(rotations)), rel=1e-5)
        else:
            assert row[2] == format_cell(critical_point(chain, row[0]).critical_moment)


def test_a_failing_stage_is_reported_and_the_others_still_appear(tmp_path, monkeypatch):
    def broken(stage):
        raise RuntimeError("the dispersion solver exploded")

    monkeypatch.setitem(report_module.STAGES, "waves", broken)
    result = reproduce(tmp_path, settings=QUICK, stages=["waves", "errata"])
    assert result.failed == ["waves"]
    markdown = (tmp_path / "report.md").read_text()
    assert "the dispersion solver exploded" in markdown and "Errata" in markdown
    assert "the dispersion solver exploded" in (tmp_path / "index.html").read_text()


def test_reproduce_refuses_unknown_stages(tmp_path):
    with pytest.raises(ValueError, match=r"unknown stage\(s\) \['fig9'\]"):
        reproduce(tmp_path, stages=["fig9"])


def test_reproduce_cli_writes_the_report(tmp_path, monkeypatch):
    monkeypatch.setattr(report_module, "STAGES", {"errata": report_module.STAGES["errata"]})
    result = CliRunner().invoke(app, ["reproduce", "--out", str(tmp_path), "--json"])
    assert result.exit_code == 0, result.output
    assert json.loads(result.stdout)["stages"]["errata"]["error"] is None
    assert (tmp_path / "index.html").exists() and (tmp_path / "report.md").exists()


def test_a_stiffer_chain_gets_loads_above_its_own_critical_moments(tmp_path, monkeypatch):
    """E2 = 2 lifts the nonlinear M_c above the paper's load 0.25: the report rotates it at 1.25 M_c and says so.
    (Its numbers and text only: the stages' figures and data files, which the quick report's tests check, not drawn.)"""
    import matplotlib.pyplot as plt

    monkeypatch.setattr(report_module._Stage, "figure", lambda self, fig, stem: plt.close(fig) or stem)
    monkeypatch.setattr(report_module._Stage, "data", lambda self, name, payload: None)
    params = ChainParams(E2=2.0)
    critical = critical_point(params, "nonlinear").critical_moment
    assert critical > QUICK.rotation_moment["nonlinear"]
    report = reproduce(tmp_path / "stiff", params, QUICK, stages=["statics", "localization"])
    assert report.failed == []
    statics = report.sections[0].numbers["nonlinear"]
    assert statics["onset_load"] is not None and statics["onset_load"] > critical, "the protocol now reaches past the fold"
    localized = report.sections[1].numbers["nonlinear"]
    assert localized["moment"] == pytest.approx(report_module.ABOVE_CRITICAL * critical)
    assert localized["turns_completed"] == QUICK.turns
    text = (report.out / "report.md").read_text()
    assert f"the configured M = {QUICK.rotation_moment['nonlinear']:g} is not above M_c for this chain" in text


def test_reproduce_reads_its_settings_from_the_config_and_names_bad_ones(tmp_path):
    config = tmp_path / "chain.toml"
    config.write_text("E2 = 1.0\n[reproduce]\nturns = 0\n")
    result = CliRunner().invoke(app, ["reproduce", "--config", str(config), "--out", str(tmp_path / "r")])
    assert result.exit_code == 2 and "turns must be > 0" in result.output
    config.write_text("[reproduce]\ntunrs = 3\n")
    result = CliRunner().invoke(app, ["reproduce", "--config", str(config), "--out", str(tmp_path / "r")])
    assert result.exit_code == 2 and "tunrs" in result.output and "allowed keys" in result.output
    assert not (tmp_path / "r").exists()


def test_the_reports_sentences_carry_the_numbers_they_describe(quick_report):
    """The hysteresis edges and the long-chain trend are written from the results, not asserted."""
    sections = {s.title: s for s in quick_report.sections}
    orbits = next(s for title, s in sections.items() if title.startswith("Rotating states"))
    text = " ".join(orbits.paragraphs)
    n = orbits.numbers
    assert f"fold M_c = {n['static_fold']:.4g}" in text and f"ends at M = {n['orbit_end_moment']:.4g} ({n['orbit_end']})" in text
    if n["stability_lost_at"] is not None:
        assert f"loses stability at M = {n['stability_lost_at']:.4g}" in text
    long = next(s for title, s in sections.items() if title.startswith("The critical moment of longer chains"))
    sine = long.numbers["sine"]
    assert f"N M_c goes from {sine[0]['N'] * sine[0]['M_c']:.4g} (N = {sine[0]['N']})" in " ".join(long.paragraphs)


def test_every_data_file_of_the_report_is_cf_described(quick_report):
    from test_outputs import _assert_cf_described

    files = sorted((quick_report.out / "data").glob("*.nc"))
    assert len(files) >= 5
    for path in files:
        _assert_cf_described(read_dataset(path), path.name)


def test_the_claims_table_is_computed_from_the_stages(quick_report):
    from cosserat_chain.report import CLAIMS_HEADER, Section, claims

    rows = quick_report.summary["claims"]
    statics = next(s for s in quick_report.sections if s.title.startswith("Static response")).numbers
    assert [set(row) for row in rows] == [set(CLAIMS_HEADER)] * len(rows) and len(rows) == 11
    assert f"nonlinear {statics['nonlinear']['M_c']:.4g}" in rows[3]["this package computes"]
    assert all(row["agreement"].startswith("yes") for row in rows[:5]), rows
    # Small loads: the range of agreement, and the paper's remark on the sine model's error failing at N = 1.
    ranges = statics["agreement"]["ranges"]
    assert f"up to M = {ranges['nonlinear']['moment']:.4g} (nonlinear)" in rows[1]["this package computes"]
    assert rows[2]["agreement"].startswith("yes (this chain); no (N = 1)")
    # Localization: no other particle turns, but the others' motion is beyond the small-motion thresholds.
    assert rows[5]["agreement"].startswith(f"partly: over {QUICK.turns} turns no other particle turned")
    assert "|phi| <= 0.2 rad, |u|, |v| <= 0.1 h" in rows[5]["agreement"] and "sine (|v|/h)" in rows[5]["agreement"]
    # Fig. 2's unit: the M_c of each rotating model divided by this chain's E1 h^2.
    assert f"E1 h^2 = {statics['moment_scale']:.4g} here" in rows[10]["this package computes"]
    assert statics["sine"]["M_c_dimensionless"] == pytest.approx(statics["sine"]["M_c"] / statics["moment_scale"], rel=1e-15)
    markdown = (quick_report.out / "report.md").read_text()
    assert "## Contents" in markdown and all(row["the paper says"] in markdown for row in rows)
    # A failed stage is named in its rows, not hidden.
    failed = claims({"statics": Section("statics", error="boom")}, QUICK)
    assert failed[0][1] == "stage 'statics' failed" and failed[1][1] == "stage 'localization' was not run"


def test_the_state_map_shows_both_edges_against_the_damping(quick_report):
    """The sine chain's loop closes at a SNIC at gamma_phi = 0.5 and is open at 0.2 (a fold of cycles below M_c)."""
    section = next(s for s in quick_report.sections if s.title.startswith("The map of static and rotating states"))
    assert section.error is None
    rows = {row["value"]: row for row in section.numbers["sine"]}
    assert rows[0.5]["end"] == "snic" and rows[0.5]["hysteresis"] is False
    assert rows[0.5]["rotation_stops"] == pytest.approx(rows[0.5]["static_fold"], rel=1e-10)
    assert rows[0.2]["hysteresis"] is True and rows[0.2]["rotation_stops"] < rows[0.2]["static_fold"]
    assert "nonlinear" not in section.numbers  # QUICK leaves it out with an empty tuple
    assert (quick_report.out / "figures" / "state_diagram_sine.png").stat().st_size > 0


def test_the_diagram_damping_setting_is_checked():
    from cosserat_chain.report import settings_from_mapping

    assert settings_from_mapping({"diagram_damping": {"sine": [0.1, 0.3]}}).diagram_damping == {"sine": (0.1, 0.3)}
    with pytest.raises(ValueError, match="diagram_damping: unknown model 'linear'"):
        settings_from_mapping({"diagram_damping": {"linear": [0.1]}})
    with pytest.raises(ValueError, match="diagram_damping.sine must hold finite numbers > 0"):
        settings_from_mapping({"diagram_damping": {"sine": [0.1, -1.0]}})
