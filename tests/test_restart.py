"""Runs that start where another stopped (issue 14, item 4): ``simulate --x0 RUN.nc [--at T]``.

A frame stores the state at a step boundary (positions and velocities), so a run started
from it with the same step takes the same steps as the uninterrupted run: its states are
equal to the last bit. The step 1/64 and the times are binary fractions, so that both runs
also compute the same times for the loads' schedules.
"""

from __future__ import annotations

import numpy as np
import pytest
import xarray as xr
from typer.testing import CliRunner

from cosserat_chain import ChainParams
from cosserat_chain.cli import app
from cosserat_chain.experiments.simulation import simulate
from cosserat_chain.io import read_dataset, run_frame
from cosserat_chain.loads import Loads, PointLoad, Schedule

runner = CliRunner()
DT = 1.0 / 64.0
LOADS = Loads([PointLoad("phi", 0, Schedule.ramp(0.15, 20.0)), PointLoad("v", 2, Schedule.harmonic(0.01, 0.2, phase=0.3))])


@pytest.mark.parametrize("params", [ChainParams(N=3), ChainParams(N=5, left_end="pinned", right_end="free")], ids=["paper", "pinned-free"])
def test_a_run_started_from_a_stored_frame_equals_the_uninterrupted_run_bit_for_bit(params):
    whole = simulate(params, "nonlinear", LOADS, t_end=100.0, dt=DT, n_frames=9)
    chain, loads, t0, x0, v0 = run_frame(whole, at=50.0)
    assert (chain, loads, t0) == (params, LOADS, 50.0)
    rest = simulate(chain, "nonlinear", loads, t_end=100.0, t0=t0, dt=DT, x0=x0, v0=v0, n_frames=5)
    np.testing.assert_array_equal(rest.time.values, whole.time.values[4:])
    for name in ("u", "v", "phi", "u_dot", "v_dot", "phi_dot"):
        np.testing.assert_array_equal(rest[name].values, whole[name].values[4:], err_msg=name)


def test_simulate_x0_goes_on_from_a_run_on_its_time_axis_with_its_loads(tmp_path):
    first, second = tmp_path / "first.nc", tmp_path / "second.nc"
    config = tmp_path / "c.toml"
    config.write_text(
        'N = 2\nright_end = "free"\n[[loads]]\nrow = "v"\nparticle = 2\nkind = "harmonic"\namplitude = 0.01\nfrequency = 0.25\n'
    )
    common = ["--dt", str(DT), "--frames", "5", "--moment", "0.05"]
    assert runner.invoke(app, ["simulate", "--config", str(config), "--t-end", "64", "--out", str(first), *common]).exit_code == 0
    result = runner.invoke(
        app, ["simulate", "--x0", str(first), "--at", "32", "--t-end", "64", "--dt", str(DT), "--frames", "3", "--out", str(second)]
    )
    assert result.exit_code == 0, result.output
    a, b = read_dataset(first), read_dataset(second)
    assert b.attrs["loads_json"] == a.attrs["loads_json"] and b.attrs["params_json"] == a.attrs["params_json"]
    assert float(b.time[0]) == 32.0 and "first.nc at t = 32.0" in b.attrs["started_from"]
    xr.testing.assert_equal(b[["u", "v", "phi"]].isel(time=-1), a[["u", "v", "phi"]].isel(time=-1))


@pytest.mark.parametrize(
    ("extra", "message"),
    [
        (["--at", "500"], "--at must lie within the run's times 0..64"),
        (["--t-end", "10"], "--t-end 10 must be after the start frame's time 64"),
        (["--out", "{first}"], "--out"),
        (["--config", "{config}"], "--config describes another chain"),
    ],
)
def test_bad_starts_are_refused_before_any_work(tmp_path, extra, message):
    first = tmp_path / "first.nc"
    config = tmp_path / "c.toml"
    config.write_text("N = 4\n")
    assert runner.invoke(app, ["simulate", "--t-end", "64", "--out", str(first), "--frames", "3"]).exit_code == 0
    extra = [e.format(first=first, config=config) for e in extra]
    result = runner.invoke(app, ["simulate", "--x0", str(first), *(["--t-end", "100"] if "--t-end" not in extra else []), *extra])
    assert result.exit_code == 2 and message in result.output, result.output
    assert runner.invoke(app, ["simulate", "--at", "3"]).exit_code == 2
    config.write_text("N = 3\n")
    result = runner.invoke(app, ["simulate", "--x0", str(config), "--t-end", "100"])
    assert result.exit_code == 2 and "--x0" in result.output
