"""The command line, run as a user would."""

from __future__ import annotations

import json

import numpy as np
import pytest
from typer.testing import CliRunner

from cosserat_chain import ChainParams, moment_load
from cosserat_chain.cli import app
from cosserat_chain.io import read_dataset
from cosserat_chain.numerics.newton import solve_equilibrium

runner = CliRunner()


def test_simulate_json_reports_params_final_state_and_energy(tmp_path):
    out = tmp_path / "run.nc"
    result = runner.invoke(app, ["simulate", "--model", "linear", "--moment", "0.02", "--t-end", "800", "--json", "--out", str(out)])
    assert result.exit_code == 0, result.output
    data = json.loads(result.stdout)
    assert {"model", "params", "t_end", "dt", "steps", "final", "energy"} <= set(data)
    assert data["params"] == ChainParams().model_dump()
    static = solve_equilibrium(ChainParams(), "linear", moment_load(0.02))
    np.testing.assert_allclose(data["final"]["phi"], static[2], atol=1e-9)
    energy = data["energy"]
    assert set(energy) == {"kinetic", "potential", "load_work", "dissipated", "balance_error"}
    # At rest under a constant moment the load's work splits equally into potential energy and dissipation.
    assert energy["potential"] == pytest.approx(0.5 * energy["load_work"], rel=1e-6)
    ds = read_dataset(out)
    assert ds.attrs["model"] == "linear" and ds.attrs["param_N"] == 3 and "cosserat_chain_version" in ds.attrs
    assert list(ds.particle.values) == [-3, -2, -1, 0, 1, 2, 3]
    np.testing.assert_allclose(ds.phi.isel(time=-1).values, data["final"]["phi"])


def test_simulate_sine_has_no_potential_in_json():
    result = runner.invoke(app, ["simulate", "--model", "sine", "--t-end", "5", "--json"])
    assert result.exit_code == 0
    assert json.loads(result.stdout)["energy"]["potential"] is None


def test_unknown_config_key_is_an_error_naming_it(tmp_path):
    config = tmp_path / "chain.toml"
    config.write_text("E1 = 1.0\ngama_phi = 0.2\n")
    result = runner.invoke(app, ["simulate", "--config", str(config)])
    assert result.exit_code == 2
    assert "gama_phi" in result.output and "allowed keys" in result.output


def test_invalid_parameter_names_field_and_value(tmp_path):
    config = tmp_path / "chain.toml"
    config.write_text("a = 0.7\n")
    result = runner.invoke(app, ["simulate", "--config", str(config)])
    assert result.exit_code == 2 and "a must satisfy 0 < a < h/2" in result.output and "0.7" in result.output


def test_too_large_time_step_is_refused_with_a_suggestion():
    result = runner.invoke(app, ["simulate", "--dt", "1.0", "--t-end", "10"])
    assert result.exit_code == 2 and "stability limit" in result.output and "smaller step" in result.output


def test_load_on_clamped_particle_is_refused():
    result = runner.invoke(app, ["simulate", "--particle", "3"])
    assert result.exit_code == 2 and "clamped" in result.output


def test_write_is_atomic_and_leaves_no_temporary_files(tmp_path):
    from cosserat_chain.experiments.simulation import simulate
    from cosserat_chain.io import write_dataset

    ds = simulate(ChainParams(), "linear", 0.01, t_end=1.0)
    path = write_dataset(ds, tmp_path / "sub" / "a.nc")
    write_dataset(ds, path)  # overwrite in place
    assert sorted(p.name for p in path.parent.iterdir()) == ["a.nc"]
    assert read_dataset(path).attrs["status"] == "completed"
    assert float(read_dataset(path).time[-1]) == 1.0


def test_every_status_has_one_exit_code_and_only_results_exit_zero():
    from cosserat_chain.cli.common import EXIT_CODES
    from cosserat_chain.status import Status

    assert set(EXIT_CODES) == set(Status)
    assert {s for s, code in EXIT_CODES.items() if code == 0} == {s for s in Status if s.ok}


def test_rotate_that_reaches_its_time_limit_exits_4_and_says_how_to_go_on(tmp_path):
    out = tmp_path / "rot.nc"
    result = runner.invoke(app, ["rotate", "--model", "sine", "--moment", "0.3", "--turns", "50", "--t-max", "5", "--out", str(out)])
    assert result.exit_code == 4, result.output
    assert "time_limit" in result.output and out.exists()


def test_progress_bars_show_whole_counts_and_reach_100_percent():
    import io

    from tqdm import tqdm

    from cosserat_chain.cli.common import bar_callback

    counted = tqdm(total=None, file=io.StringIO())
    progress = bar_callback(counted)
    progress(3, 10)
    progress(10, 10)
    assert (counted.n, counted.total) == (10, 10)
    angle = tqdm(total=None, unit="rad", file=io.StringIO())
    progress = bar_callback(angle)
    progress(1.234, 2 * np.pi)
    assert (angle.n, angle.total, angle.unit) == (19, 100, "%")
    progress(2 * np.pi, 2 * np.pi)
    assert angle.n == 100
