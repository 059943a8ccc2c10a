"""Section 4's "seven particles": both readings, as the statics compute them and as ``reproduce`` takes them."""

from __future__ import annotations

import json

import numpy as np
import pytest
import scipy.sparse.linalg as spla
from typer.testing import CliRunner

import cosserat_chain.report as report_module
from cosserat_chain import ChainParams
from cosserat_chain.analysis.continuum import reduced_discrete
from cosserat_chain.cli import app
from cosserat_chain.experiments.critical import critical_point
from cosserat_chain.models.linear import stiffness_matrix
from cosserat_chain.report import READINGS, ReproduceSettings, chain_for_reading, reproduce, settings_from_mapping

#: What docs/statics.md and the README state for the paper's geometry (the tests below compute them).
DOCUMENTED = {
    "clamped-ends-among-seven": {"compliance": 4.90289934354, "nonlinear": 0.197495317503, "sine": 0.203960948396},
    "seven-between-walls": {"compliance": 6.41263940520, "nonlinear": 0.195248555919, "sine": 0.155942028986},
}


def _linear_rotation_compliance(params: ChainParams) -> float:
    """phi_0 / M from one sparse solve of the linear model: independent of the continuation."""
    phi0 = 3 * (params.N - 1) + 2  # free degrees of freedom particle by particle from -N+1 (state.py)
    load = np.zeros(stiffness_matrix(params).shape[0])
    load[phi0] = 1.0
    return float(spla.spsolve(stiffness_matrix(params).tocsc(), load)[phi0])


@pytest.fixture(scope="module")
def statics():
    return {name: {m: critical_point(ChainParams(N=n), m) for m in ("nonlinear", "sine")} for name, n in READINGS.items()}


def test_the_two_readings_are_three_and_four_and_seven_particles_either_way():
    assert READINGS == {"clamped-ends-among-seven": 3, "seven-between-walls": 4}
    among, between = (ChainParams(N=n) for n in READINGS.values())
    assert among.n_particles == 7 and between.n_particles - 2 == 7


def test_both_readings_statics_differ_as_documented(statics):
    for name, exact in statics.items():
        n = READINGS[name]
        for model in ("nonlinear", "sine"):
            assert exact[model].critical_moment == pytest.approx(DOCUMENTED[name][model], rel=1e-9), (name, model)
        assert exact["sine"].compliance == pytest.approx(DOCUMENTED[name]["compliance"], rel=1e-9)
        # The sine model's M_c is 1/(its rotation compliance) exactly, the compliance a linear solve's.
        assert exact["sine"].compliance == pytest.approx(_linear_rotation_compliance(ChainParams(N=n)), rel=1e-10)
        assert exact["sine"].critical_moment == pytest.approx(1.0 / exact["sine"].compliance, rel=1e-10)
    among, between = statics.values()
    sine = between["sine"].critical_moment / among["sine"].critical_moment - 1.0
    nonlinear = between["nonlinear"].critical_moment / among["nonlinear"].critical_moment - 1.0
    assert sine == pytest.approx(-0.2354, abs=5e-4) and nonlinear == pytest.approx(-0.01140, abs=5e-5)
    # The order of the folds flips: with seven in all the nonlinear model folds first, with seven free ones the sine model.
    assert among["sine"].critical_moment > among["nonlinear"].critical_moment
    assert between["sine"].critical_moment < between["nonlinear"].critical_moment


def test_the_reading_setting_parses_and_sets_N():
    settings = settings_from_mapping({"reading": "seven-between-walls"})
    assert settings.reading == "seven-between-walls" and chain_for_reading(settings).N == 4
    assert chain_for_reading(settings_from_mapping({"reading": "clamped-ends-among-seven"})) == ChainParams()
    assert chain_for_reading(ReproduceSettings(), ChainParams(N=10)).N == 10  # no reading: the chain's own N
    assert chain_for_reading(settings, ChainParams(N=4, E2=0.5)).E2 == 0.5


def test_a_wrong_reading_is_refused_naming_the_field_value_and_allowed_values():
    allowed = r"'clamped-ends-among-seven' \(N = 3\), 'seven-between-walls' \(N = 4\)"
    with pytest.raises(ValueError, match=rf"invalid \[reproduce\]: reading must be one of {allowed}, got 'nine-particles'"):
        settings_from_mapping({"reading": "nine-particles"})
    with pytest.raises(ValueError, match=r"reading: Input should be a valid string \(got 4\)"):
        settings_from_mapping({"reading": 4})
    with pytest.raises(ValueError, match=rf"reading must be one of {allowed}, got 'walls'"):
        chain_for_reading(ReproduceSettings(reading="walls"))
    with pytest.raises(ValueError, match=r"the chain's N = 3 contradicts reading = 'seven-between-walls' \(N = 4\)"):
        chain_for_reading(ReproduceSettings(reading="seven-between-walls"), ChainParams())


def test_reproduce_takes_either_reading_from_the_command_line_or_the_config(tmp_path, monkeypatch):
    monkeypatch.setattr(report_module, "STAGES", {"errata": report_module.STAGES["errata"]})
    runner = CliRunner()
    result = runner.invoke(app, ["reproduce", "--out", str(tmp_path / "a"), "--reading", "seven-between-walls", "--json"])
    assert result.exit_code == 0, result.output
    summary = json.loads(result.stdout)
    assert summary["params"]["N"] == 4 and summary["settings"]["reading"] == "seven-between-walls"
    config = tmp_path / "chain.toml"
    config.write_text('E2 = 0.5\n[reproduce]\nreading = "seven-between-walls"\n')
    result = runner.invoke(app, ["reproduce", "--config", str(config), "--out", str(tmp_path / "b"), "--json"])
    assert result.exit_code == 0, result.output
    assert json.loads(result.stdout)["params"]["N"] == 4 and json.loads(result.stdout)["params"]["E2"] == 0.5
    # Bad values exit 2 before any work, naming the option or field, the value and the allowed ones.
    result = runner.invoke(app, ["reproduce", "--out", str(tmp_path / "c"), "--reading", "walls"])
    assert result.exit_code == 2 and "--reading must be one of 'clamped-ends-among-seven'" in result.output and "'walls'" in result.output
    config.write_text('N = 10\n[reproduce]\nreading = "seven-between-walls"\n')
    result = runner.invoke(app, ["reproduce", "--config", str(config), "--out", str(tmp_path / "d")])
    assert result.exit_code == 2 and "N = 10 contradicts reading = 'seven-between-walls'" in result.output
    assert not (tmp_path / "c").exists() and not (tmp_path / "d").exists()


def _statics_and_continuum(reading: str, tmp_path, request):
    """A report's statics and continuum sections with ``reading``, and its folder: the paper chain's own reading
    (its N = 3, no reading set) from the session's quick report (conftest.py), the other computed here."""
    if chain_for_reading(ReproduceSettings(reading=reading)) == ChainParams():
        report = request.getfixturevalue("quick_report_and_figures")[0]
        return report, report.out
    settings = ReproduceSettings(dm=0.05, n_list=(3, 10), reading=reading)
    return reproduce(tmp_path, settings=settings, stages=["statics", "continuum"]), tmp_path


@pytest.mark.parametrize("reading", [r if r == "clamped-ends-among-seven" else pytest.param(r, marks=pytest.mark.slow) for r in READINGS])
def test_the_report_gives_both_readings_and_the_reduced_model_from_its_stages(tmp_path, reading, statics, request):
    report, tmp_path = _statics_and_continuum(reading, tmp_path, request)
    sections = {section.title: section for section in report.sections}
    assert report.failed == [] and report.summary["params"]["N"] == READINGS[reading]
    seven = sections["Static response and the onset of rotation (Fig. 2)"].numbers["seven_particles"]
    assert seven["used"] == reading and set(seven["readings"]) == set(READINGS)
    for name, exact in statics.items():
        for model in ("nonlinear", "sine"):
            assert seven["readings"][name]["M_c"][model] == pytest.approx(exact[model].critical_moment, rel=1e-12)
    among, between = (seven["readings"][name]["M_c"]["sine"] for name in READINGS)
    assert seven["M_c_change"]["sine"] == pytest.approx(between / among - 1.0, rel=1e-12)
    rows = {row["the paper says"]: row for row in report.summary["claims"]}
    row = next(r for claim, r in rows.items() if "seven particles" in claim)
    assert f"sine {100 * seven['M_c_change']['sine']:.3g} %" in row["this package computes"]
    assert row["agreement"].startswith("ambiguous") and f"uses {reading!r}" in row["agreement"]
    markdown = (tmp_path / "report.md").read_text()
    assert "*The paper's seven particles, both readings (this chain's geometry): exact statics*" in markdown
    reduced = sections["Continuum theory (Section 3) against the discrete chain"].numbers["reduced"]
    chain = ChainParams(N=READINGS[reading])
    assert reduced == reduced_discrete(chain).as_dict() and reduced["positive_definite"]
    row = next(r for claim, r in rows.items() if claim.startswith("Section 3.2"))
    assert f"lowest eigenvalue of K {reduced['lowest_eigenvalue']:.4g}" in row["this package computes"]
    assert f"phi(0)/M = {reduced['continuum_compliance']:.4g} + {reduced['family_slope']:.4g} alpha" in row["this package computes"]
    assert row["agreement"].startswith("yes for the continuum")
