"""``cosserat-chain sweep`` and ``cosserat-chain critical``, run as a user would."""

from __future__ import annotations

import json

import numpy as np
import pytest
from typer.testing import CliRunner

from cosserat_chain import ChainParams
from cosserat_chain.cli import app
from cosserat_chain.io import read_dataset
from cosserat_chain.numerics.continuation import compliance, locate_fold

runner = CliRunner()


def test_critical_json_gives_the_fold_and_compliance_of_every_model(tmp_path):
    out = tmp_path / "critical.nc"
    result = runner.invoke(app, ["critical", "--json", "--out", str(out)])
    assert result.exit_code == 0, result.output
    models = json.loads(result.stdout)["models"]
    assert set(models) == {"nonlinear", "sine", "linear"}
    params = ChainParams()
    for name in ("nonlinear", "sine"):
        fold = locate_fold(params, name)
        assert models[name]["M_c"] == pytest.approx(fold.moment, rel=1e-12)
        assert models[name]["phi0_at_fold"] == pytest.approx(fold.phi0, rel=1e-12)
    assert models["linear"]["M_c"] is None and models["linear"]["phi0_at_fold"] is None
    assert models["linear"]["compliance"] == pytest.approx(compliance(params, "linear"), rel=1e-12)
    branch = models["sine"]["branch"]
    assert len(branch["moment"]) == len(branch["phi0"]) == len(branch["stable"]) > 10
    ds = read_dataset(out)
    assert list(ds.model.values) == ["nonlinear", "sine", "linear"]
    np.testing.assert_allclose(ds.M_c.values[:2], [models["nonlinear"]["M_c"], models["sine"]["M_c"]])


def test_sweep_json_reports_steps_onset_and_stop(tmp_path):
    out, plot = tmp_path / "sweep.nc", tmp_path / "fig2.png"
    result = runner.invoke(
        app, ["sweep", "--model", "sine", "--m-max", "0.3", "--steps", "6", "--down", "--json", "--out", str(out), "--plot", str(plot)]
    )
    assert result.exit_code == 0, result.output
    sine = json.loads(result.stdout)["models"]["sine"]
    assert sine["loads"][:6] == pytest.approx([0.05, 0.1, 0.15, 0.2, 0.25, 0.3])
    assert sine["status"][:4] == ["static"] * 4 and sine["status"][4] == "rotating"
    assert sine["onset_load"] == pytest.approx(0.25)
    assert sine["stop_load"] is not None and sine["stop_load"] <= sine["onset_load"]
    assert len(sine["phi0"]) == len(sine["status"]) == 12  # 6 up, then 0.25 down to 0
    assert read_dataset(out).attrs["model"] == "sine"
    assert plot.stat().st_size > 10_000


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["sweep", "--m-max", "0.3"], "exactly one of --steps"),
        (["sweep", "--m-max", "0.3", "--steps", "3", "--dm", "0.1"], "exactly one of --steps"),
        (["sweep", "--m-max", "0.3", "--steps", "3", "--particle", "3"], "end is clamped"),
    ],
)
def test_sweep_bad_input_exits_2_with_a_message(args, message):
    result = runner.invoke(app, args)
    assert result.exit_code == 2
    assert message in result.output


def test_critical_refuses_a_clamped_particle():
    result = runner.invoke(app, ["critical", "--model", "sine", "--particle", "-3"])
    assert result.exit_code == 2 and "is held fixed by the left end (clamped)" in result.output


def test_critical_with_a_branch_cut_short_writes_it_and_exits_max_steps(tmp_path):
    out = tmp_path / "short.nc"
    result = runner.invoke(app, ["critical", "--model", "sine", "--max-points", "10", "--json", "--out", str(out)])
    assert result.exit_code == 3 and "max_steps" in result.stderr and "--max-points" in result.stderr
    summary = json.loads(result.stdout)["models"]["sine"]
    assert summary["branch_complete"] is False and summary["branch"]["stop"] == "max_points" and len(summary["branch"]["moment"]) == 10
    dataset = read_dataset(out)
    assert dataset.attrs["branch_stop"] == "max_points" and dataset.sizes["point"] == 10
