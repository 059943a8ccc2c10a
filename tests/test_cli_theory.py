"""The theory and waves commands, run as a user would."""

from __future__ import annotations

import json

import numpy as np
import pytest
from typer.testing import CliRunner

from cosserat_chain import ChainParams
from cosserat_chain.analysis.continuum import central_rotation, discrete_static, residue
from cosserat_chain.analysis.dispersion import continuum_dispersion, dispersion, wave_summary
from cosserat_chain.cli import app
from cosserat_chain.plots.theory import plot_dispersion

runner = CliRunner()


def test_theory_json_reports_compliances_errors_residues_and_errata():
    result = runner.invoke(app, ["theory", "--n-list", "3,10,100", "--json"])
    assert result.exit_code == 0, result.output
    data = json.loads(result.stdout)
    assert [row["N"] for row in data["rows"]] == [3, 10, 100]
    for row in data["rows"]:
        params = ChainParams(N=row["N"])
        assert row["continuum"] == pytest.approx(central_rotation(params), rel=1e-12)
        assert row["discrete"] == pytest.approx(discrete_static(params)[2, params.N], rel=1e-12)
        assert row["relative_error"] == pytest.approx(abs(row["continuum"] - row["discrete"]) / row["discrete"], rel=1e-12)
        assert row["residue"] == pytest.approx(residue(params), rel=1e-12)
    errors = [row["relative_error"] for row in data["rows"]]
    assert errors == sorted(errors, reverse=True) and 0.9 < data["order"] < 1.05
    assert data["D1"] == pytest.approx(ChainParams().D1) and data["printed_D1"] == pytest.approx(1 - 2 / 0.52)
    assert [e["number"] for e in data["errata"]] == list(range(1, 11))
    assert all({"where", "printed", "derived", "consequence"} <= set(e) for e in data["errata"])


def test_theory_prints_a_table_and_the_errata():
    result = runner.invoke(app, ["theory", "--n-list", "3,30"])
    assert result.exit_code == 0, result.output
    assert "continuum phi0/M" in result.stdout and "errata" in result.stdout
    assert "1. eq. (3)" in result.stdout and "6. Section 2" in result.stdout


@pytest.mark.parametrize("bad", ["3,x", "0", "", "-2,5"])
def test_theory_refuses_a_bad_n_list_naming_the_option(bad):
    result = runner.invoke(app, ["theory", "--n-list", bad])
    assert result.exit_code == 2 and "--n-list" in result.output and repr(bad) in result.output


def test_theory_refuses_a_chain_without_coupling(tmp_path):
    config = tmp_path / "chain.toml"
    config.write_text("E2 = 0.0\n")
    result = runner.invoke(app, ["theory", "--config", str(config)])
    assert result.exit_code == 2 and "E2" in result.output


def test_waves_json_matches_the_library_for_the_configured_chain(tmp_path):
    config = tmp_path / "chain.toml"
    config.write_text("b = 0.3\nE2 = 0.5\n")
    result = runner.invoke(app, ["waves", "--config", str(config), "--json"])
    assert result.exit_code == 0, result.output
    data = json.loads(result.stdout)
    summary = wave_summary(ChainParams(b=0.3, E2=0.5))
    assert data["at_zero"] == pytest.approx(summary.at_zero) and data["at_pi"] == pytest.approx(summary.at_pi)
    assert data["gap"] == pytest.approx(list(summary.gap)) and data["params"]["b"] == 0.3
    assert data["gap_width"] == pytest.approx(summary.gap[1] - summary.gap[0])


def test_waves_prints_branches_and_gap():
    result = runner.invoke(app, ["waves"])
    assert result.exit_code == 0, result.output
    for name in ("longitudinal", "transverse_acoustic", "rotational_optical", "band gap"):
        assert name in result.stdout
    low, high = wave_summary(ChainParams()).gap
    assert f"{low:.6g} < omega < {high:.6g}" in result.stdout


@pytest.mark.parametrize("name", ["waves.png", "waves.svg"])
def test_waves_plot_writes_the_figure_by_extension(tmp_path, name):
    out = tmp_path / "figs" / name
    result = runner.invoke(app, ["waves", "--plot", str(out), "--json"])
    assert result.exit_code == 0, result.output
    assert json.loads(result.stdout)["plot"] == str(out)
    head = out.read_bytes()[:64]
    assert head.startswith(b"\x89PNG") if name.endswith(".png") else b"<svg" in out.read_bytes()[:2000]


def test_waves_refuses_an_unknown_figure_format(tmp_path):
    out = tmp_path / "waves.jpg"
    result = runner.invoke(app, ["waves", "--plot", str(out)])
    assert result.exit_code == 2 and ".png" in result.output and not out.exists()


def test_dispersion_figure_shades_the_gap():
    params = ChainParams()
    summary = wave_summary(params)
    fig = plot_dispersion(dispersion(params), summary, continuum_dispersion(params))
    (ax,) = fig.axes
    (span,) = ax.patches
    # The span's corners in data coordinates (its x extent is in axes coordinates).
    corners = span.get_path().transformed(span.get_transform() - ax.transData).vertices
    np.testing.assert_allclose([corners[:, 1].min(), corners[:, 1].max()], summary.gap, rtol=1e-12)
