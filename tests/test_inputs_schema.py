"""Every input checked by one schema, work bounded before it starts, outcomes told honestly (issue 46, items 5-7).

Each test reproduces a case of the issue's corpus that gave a traceback, a hang or a false
``completed`` before, and checks the class it belongs to: the refusal is a ``ValueError``
(exit 2 on the command line) that names the file or the key and what is wrong.
"""

from __future__ import annotations

import json
import re

import numpy as np
import pytest
import xarray as xr
from typer.testing import CliRunner

from cosserat_chain import ChainParams
from cosserat_chain.cli import app
from cosserat_chain.experiments.checkpoint import seal
from cosserat_chain.experiments.simulation import _STATE_ATTRIBUTES, CHECKPOINT_EXPERIMENT, CHECKPOINT_FORMAT, simulate
from cosserat_chain.inputs import InputFileError, check_counts, check_run, params_from_mapping
from cosserat_chain.io import load_config, read_dataset, run_frame, write_dataset
from cosserat_chain.loads import MAX_KNOTS, Loads, Schedule, load_from_table, loads_from_tables, moment_load
from in_process_study import study_in_process  # noqa: F401 (a fixture)

runner = CliRunner()


@pytest.fixture(scope="module")
def run_file(tmp_path_factory):
    """A short run of the linear chain with its velocities, written as ``simulate --out`` writes it."""
    ds = simulate(ChainParams(), "linear", moment_load(0.1), t_end=2.0, n_frames=5)
    path = tmp_path_factory.mktemp("run") / "run.nc"
    write_dataset(ds, path)
    return path


def _no_traceback(result) -> None:
    assert result.exception is None or isinstance(result.exception, SystemExit), f"TRACEBACK: {result.exception!r}"
    assert "Traceback" not in result.output


# ---------------------------------------------------------------- config tables


@pytest.mark.parametrize(
    "table, named",
    [
        ({"row": ["phi"], "particle": 0, "value": 0.1}, ".row"),
        ({"row": "phi", "particle": 0, "kind": ["step"], "value": 0.1}, ".kind"),
        ({"row": "phi", "particle": 0, "kind": {"a": 1}, "value": 0.1}, ".kind"),
        ({"row": "phi", "particle": [0], "value": 0.1}, ".particle"),
        ({"row": "phi", "particle": 0, "kind": "knots", "times": [[0.0]], "values": [1.0]}, ".times[0]"),
    ],
)
def test_load_tables_of_the_wrong_type_are_refused_naming_the_key(table, named):
    with pytest.raises(ValueError, match=named.replace("[", r"\[").replace("]", r"\]")):
        load_from_table(table, "loads[0]")


def test_disorder_fields_that_are_not_names_are_refused(tmp_path):
    path = tmp_path / "chain.toml"
    path.write_text('[disorder]\nseed = 1\nspread = 0.1\nfields = [["E1"]]\n')
    with pytest.raises(ValueError, match=r"\[disorder\].*fields"):
        load_config(path)


def test_e1_factors_must_be_a_flat_list():
    """A table of factors (nested lists) ravelled into one would silently pick a bond order."""
    with pytest.raises(ValueError, match=r"E1_factors\[0\] must be a finite number"):
        ChainParams(N=2, E1_factors=[[1.0, 2.0], [1.0, 2.0]])
    with pytest.raises(ValueError, match="E1_factors must be a list of numbers"):
        ChainParams(N=2, E1_factors=np.ones((2, 2)))
    assert ChainParams(N=2, E1_factors=np.array([1.0, 2.0, 1.0, 2.0])).E1_factors == (1.0, 2.0, 1.0, 2.0)


def test_an_enormous_schedule_is_refused_with_its_memory_before_it_is_built():
    table = {"row": "phi", "particle": 0, "kind": "staircase", "increment": 0.001, "hold": 1e-6, "n_steps": 100_000_000}
    with pytest.raises(ValueError, match=r"n_steps asks for a schedule of 2e\+08 knots \(about .* GiB\)"):
        loads_from_tables([table])
    with pytest.raises(ValueError, match="knots"):
        Schedule.staircase(0.1, 1.0, MAX_KNOTS)
    assert len(Schedule.staircase(0.1, 1.0, MAX_KNOTS // 2).times) == MAX_KNOTS


def test_loads_json_of_the_wrong_shape_is_a_value_error():
    for items, named in ((["phi"], r"loads_json\[0\]"), ({"a": 1}, "must be a list"), ([{"row": "phi", "particle": 0.5}], "particle")):
        with pytest.raises(ValueError, match=named):
            Loads.from_list(items)


def test_params_json_that_is_not_a_table_is_named():
    with pytest.raises(ValueError, match="params_json must be a table of parameters"):
        params_from_mapping([1, 2], source="params_json")


# ---------------------------------------------------------------- result files


def _edited(run_file, edit):
    ds = read_dataset(run_file)
    return edit(ds.copy())


@pytest.mark.parametrize(
    "edit, named",
    [
        (lambda ds: ds.isel(time=slice(0, 0)), "holds no frame"),
        (lambda ds: ds.drop_vars("phi_dot"), r"lacks the variable\(s\) \['phi_dot'\]"),
        (lambda ds: ds.assign(phi=ds.phi.where(ds.time < 1.0)), "'phi' holds .* not finite"),
        (lambda ds: ds.assign(u=ds.u.astype(str)), "'u' holds <U.* values, not real numbers"),
        (lambda ds: ds.assign(v=ds.v.isel(particle=0)), r"'v' is over \('time',\)"),
        (lambda ds: ds.assign_coords(particle=ds.particle + 1), "particle coordinate"),
        (lambda ds: ds.assign_coords(time=ds.time[::-1].values), "increasing"),
        (lambda ds: ds.assign_attrs(params_json="[1, 2]"), "params_json"),
        (lambda ds: ds.assign_attrs(params_json="{not json"), "params_json is not valid JSON"),
        (lambda ds: ds.assign_attrs(params_json=json.dumps({"N": -3})), "params_json holds no valid chain: N"),
        (lambda ds: ds.assign_attrs(loads_json='{"a": 1}'), "loads_json must be a list"),
        (lambda ds: ds.assign_attrs(loads_json='[{"row": "phi", "particle": 3, "times": [0], "values": [1]}]'), "particle 3"),
    ],
    ids=["no-frames", "no-phi_dot", "nan", "strings", "wrong-dims", "particles", "time-order", "params-list", "params-text",
         "params-invalid", "loads-dict", "load-on-end"],  # fmt: skip
)
def test_a_damaged_run_is_refused_naming_the_file_and_the_field(run_file, edit, named):
    ds = _edited(run_file, edit)
    with pytest.raises(InputFileError, match=f"^RUN 'x.nc'.*{named}"):
        check_run(ds, "RUN 'x.nc'", velocities=True)
    with pytest.raises(ValueError, match=named):
        run_frame(ds, source="'x.nc'")


def test_a_sound_run_passes_the_schema_and_gives_its_frame(run_file):
    ds = read_dataset(run_file)
    params, loads = check_run(ds, "run", velocities=True)
    assert params == ChainParams() and loads == moment_load(0.1)
    _, _, t, x, v = run_frame(ds)
    assert t == pytest.approx(2.0) and x.shape == v.shape == (3, params.n_particles)


def test_any_error_of_the_netcdf_reader_becomes_a_value_error(run_file, monkeypatch):
    def broken(*args, **kwargs):
        raise RuntimeError("HDF5: bad symbol table")

    monkeypatch.setattr(xr, "open_dataset", broken)
    with pytest.raises(ValueError, match="not a readable NetCDF file.*RuntimeError: HDF5"):
        read_dataset(run_file)


@pytest.fixture(scope="module")
def damaged_runs(run_file, tmp_path_factory):
    """Edit -> the run file damaged so, written once for the four commands that read it."""
    edits = {
        "no-frames": lambda ds: ds.isel(time=slice(0, 0)),
        "no-phi_dot": lambda ds: ds.drop_vars("phi_dot"),
        "nan": lambda ds: ds.assign(phi=ds.phi * np.nan),
    }
    paths = {}
    for name, edit in edits.items():
        paths[name] = tmp_path_factory.mktemp(name) / "bad.nc"
        _edited(run_file, edit).to_netcdf(paths[name], engine="h5netcdf")
    return paths


@pytest.mark.parametrize("command", ["draw", "export", "x0", "guess"])
@pytest.mark.parametrize("edit", ["no-frames", "no-phi_dot", "nan"])
def test_commands_refuse_a_damaged_run_with_exit_2(damaged_runs, tmp_path, command, edit):
    bad = damaged_runs[edit]
    argv = {
        "draw": ["draw", str(bad), "--out", str(tmp_path / "x.png")],
        "export": ["export", str(bad), "--to", "csv", "--out", str(tmp_path / "x.csv")],
        "x0": ["simulate", "--model", "linear", "--t-end", "9", "--x0", str(bad)],
        "guess": ["orbit", "--moment", "0.3", "--guess", str(bad), "--json"],
    }[command]
    result = runner.invoke(app, argv)
    _no_traceback(result)
    if command == "draw" and edit == "no-phi_dot":  # a picture needs no velocities
        assert result.exit_code == 0, result.output
        return
    assert result.exit_code == 2, result.output
    assert result.output.count("bad.nc") == 1, result.output  # named once, not once per layer


@pytest.mark.usefixtures("study_in_process")  # the study only writes the file damaged below
def test_a_study_file_damaged_under_the_same_spec_is_refused(tmp_path):
    spec = tmp_path / "spec.toml"
    spec.write_text('models = ["linear"]\nquantities = ["compliance"]\n[parameters]\na = [0.1, 0.2]\n')
    out = tmp_path / "study.nc"
    assert runner.invoke(app, ["study", str(spec), "--out", str(out), "--workers", "1"]).exit_code == 0
    xr.load_dataset(out).drop_vars("error").to_netcdf(tmp_path / "noerror.nc", engine="h5netcdf")
    result = runner.invoke(app, ["study", str(spec), "--out", str(tmp_path / "noerror.nc"), "--workers", "1"])
    _no_traceback(result)
    assert result.exit_code == 2 and "lacks the variable 'error'" in result.output


# ---------------------------------------------------------------- checkpoints and honest outcomes


def _resealed(checkpoint: xr.Dataset, edit):
    return seal(edit(checkpoint.copy()), CHECKPOINT_EXPERIMENT, CHECKPOINT_FORMAT, _STATE_ATTRIBUTES)


def test_a_checkpoint_sealed_again_with_impossible_counts_or_frames_is_refused(tmp_path):
    """Its seal is a checksum anyone can recompute: the counts and frames themselves are checked."""
    params, loads = ChainParams(), moment_load(0.1)
    path = tmp_path / "run.checkpoint.nc"
    settings = {"t_end": 3.0, "n_frames": 11, "checkpoint_every": 1e9}  # written once, at the end
    simulate(params, "linear", loads, checkpoint=path, **settings)
    assert simulate(params, "linear", loads, checkpoint=path, resume=True, **settings).sizes["time"] == 11
    checkpoint = read_dataset(path)  # read once, each edit made on a copy

    def cut(ds):
        out = ds.isel(time=slice(0, 3))
        out.attrs = dict(ds.attrs)
        return out

    for edit, named in (
        (lambda ds: ds.assign_attrs(steps=-5), "the count steps must be a whole number >= 0, got -5"),
        (lambda ds: ds.assign_attrs(steps=10**9), "beyond the run's n_steps"),
        (lambda ds: ds.assign_attrs(chunk_steps=2.5), "chunk_steps"),
        (cut, "holds 3 frames"),
        (lambda ds: ds.assign(final_phi=ds.final_phi * np.inf), "'final_phi' holds"),
    ):
        tampered = tmp_path / "tampered.nc"
        _resealed(checkpoint, edit).to_netcdf(tampered, engine="h5netcdf")
        with pytest.raises(ValueError, match=named):
            simulate(params, "linear", loads, checkpoint=tampered, resume=True, **settings)


def test_step_counts_are_whole_numbers_not_beyond_the_total():
    assert check_counts({"steps": np.int64(3), "n_steps": 5.0}, ("steps", "n_steps"), "f", total="n_steps") == {"steps": 3, "n_steps": 5}
    for attrs in ({"steps": True, "n_steps": 5}, {"steps": 6, "n_steps": 5}, {"n_steps": 5}, {"steps": float("nan"), "n_steps": 5}):
        with pytest.raises(InputFileError):
            check_counts(attrs, ("steps", "n_steps"), "f", total="n_steps")


# ---------------------------------------------------------------- commands: loads they do not use, work bounded


@pytest.fixture
def loads_config(tmp_path):
    path = tmp_path / "loads.toml"
    path.write_text('N = 3\n[[loads]]\nrow = "phi"\nparticle = 0\nvalue = 0.1\n')
    return path


def _forbid(monkeypatch, *targets):
    def computed(*args, **kwargs):
        raise AssertionError("COMPUTED before refusing")

    for target in targets:
        monkeypatch.setattr(target, computed)


@pytest.mark.parametrize(
    "argv, compute",
    [
        (["critical", "--model", "linear"], "cosserat_chain.experiments.critical.critical_point"),
        (["orbit", "--moment", "0.3"], "cosserat_chain.experiments.orbits.periodic_orbit"),
        (["waves"], "cosserat_chain.analysis.dispersion.wave_summary"),
        (["draw", "--t-end", "1", "--out", "{tmp}/x.png"], "cosserat_chain.experiments.simulation.simulate"),
    ],
    ids=["critical", "orbit", "waves", "draw"],
)
def test_commands_that_ignore_loads_refuse_a_config_with_loads(loads_config, tmp_path, monkeypatch, argv, compute):
    _forbid(monkeypatch, compute)
    result = runner.invoke(app, [*(a.format(tmp=tmp_path) for a in argv), "--config", str(loads_config)])
    _no_traceback(result)
    assert result.exit_code == 2 and "[[loads]]" in result.output and "loads.toml" in result.output, result.output


@pytest.mark.parametrize(
    "argv, compute, named",
    [
        (["rotate", "--dt", "1e-300", "--moment", "0.3", "--turns", "1"], "cosserat_chain.experiments.localization.localization_run",
         "particle-steps"),
        (["rotate", "--moment", "1e15", "--turns", "1"], "cosserat_chain.experiments.localization.localization_run",
         "half a turn a step"),
        (["states", "--moment", "0.22", "--random-starts", "1000000000"], "cosserat_chain.experiments.coexisting.states_at",
         "1000000000 long runs"),
        (["states", "--moment", "0.22", "--turns", "1000000000"], "cosserat_chain.experiments.coexisting.states_at",
         "particle-steps"),
        (["orbit", "--moment", "1e300"], "cosserat_chain.experiments.orbits.periodic_orbit", "half a turn a step"),
        (["animate", "--fps", "1e-300", "--out", "{tmp}/a.gif"], "cosserat_chain.experiments.simulation.simulate", "--fps"),
        (["simulate", "--dt", "1e-12", "--t-end", "300"], "cosserat_chain.experiments.simulation.simulate", "24.3 days"),
        (["simulate", "--t-end", "1", "--config", "{stiff}"], "cosserat_chain.experiments.simulation.simulate", "fastest mode"),
        (["simulate", "--moment", "1e300", "--t-end", "1"], "cosserat_chain.experiments.simulation.simulate", "half a turn a step"),
        (["simulate", "--load", "phi:1=3e300", "--t-end", "1"], "cosserat_chain.experiments.simulation.simulate",
         "a moment of 3e+300 on particle 1"),
        (["sweep", "--model", "linear", "--m-max", "0.1", "--dm", "1e-300"], "cosserat_chain.experiments.sweep.relaxation_sweep",
         "1e+299 load steps"),
    ],
    ids=["rotate-dt", "rotate-moment", "states-starts", "states-turns", "orbit-moment", "animate-fps", "simulate-dt", "simulate-stiff",
         "simulate-moment", "simulate-load", "sweep-dm"],
)  # fmt: skip
def test_absurd_work_is_refused_with_its_estimate_before_it_starts(tmp_path, monkeypatch, argv, compute, named):
    _forbid(monkeypatch, compute)
    stiff = tmp_path / "stiff.toml"
    stiff.write_text("E1 = 1e100\n")  # the default step, 3e-52, follows it
    result = runner.invoke(app, [a.format(tmp=tmp_path, stiff=stiff) for a in argv])
    _no_traceback(result)
    assert result.exit_code == 2 and named in result.output, result.output


def test_the_work_estimate_is_a_lower_bound_that_a_real_rotation_meets():
    """rotate's estimate (the turns at the spin's bound |M| / gamma_phi) lies below the time the run takes."""
    result = runner.invoke(app, ["rotate", "--model", "sine", "--moment", "0.3", "--turns", "2", "--json"])
    assert result.exit_code == 0, result.output
    summary = json.loads(result.stdout)
    params = ChainParams()
    least = max(2 * 2 * np.pi * params.gamma_phi / 0.3, np.sqrt(2 * params.j * 2 * 2 * np.pi / 0.3))
    assert summary["turns_completed"] == 2 and summary["t_end"] >= least


@pytest.mark.parametrize("failure, named", [("hang", "did not finish within 0.5 s"), ("crash", "crashed the HDF5 reader (signal 11)")])
def test_a_file_that_hangs_or_crashes_the_hdf5_reader_is_refused(run_file, monkeypatch, failure, named):
    """HDF5 loops for ever in C on some damaged dimension lists (a byte flip found by fuzzing): a child opens the structure first."""
    import os
    import signal
    import time

    import cosserat_chain.io as io

    def misbehave(*args, **kwargs):
        if failure == "hang":
            time.sleep(60)
        os.kill(os.getpid(), signal.SIGSEGV)

    monkeypatch.setattr(io, "READ_PROBE_SECONDS", 0.5)
    monkeypatch.setattr(xr, "open_dataset", misbehave)
    with pytest.raises(ValueError, match=f"run.nc.*{re.escape(named)}"):
        read_dataset(run_file)


def test_a_rotation_checkpoint_sealed_again_without_its_state_is_refused(tmp_path):
    from cosserat_chain.experiments.localization import _STATE_ATTRIBUTES as ROTATE_ATTRIBUTES
    from cosserat_chain.experiments.localization import CHECKPOINT_FORMAT as ROTATE_FORMAT

    out = tmp_path / "rot.nc"
    argv = ["rotate", "--model", "sine", "--moment", "0.3", "--turns", "2", "--out", str(out), "--checkpoint-every", "0"]
    assert runner.invoke(app, argv).exit_code == 0
    checkpoint = tmp_path / "rot.checkpoint.nc"
    for drop, named in (("final_phi", "final_phi"), ("diag_turn_times", "diag_turn_times")):
        ds = xr.load_dataset(checkpoint, engine="h5netcdf").drop_vars(drop)
        edited = tmp_path / f"edited-{drop}.nc"
        seal(ds, "localization_run", ROTATE_FORMAT, ROTATE_ATTRIBUTES).to_netcdf(edited, engine="h5netcdf")
        resumed = ["rotate", "--model", "sine", "--moment", "0.3", "--turns", "3", "--checkpoint", str(edited), "--resume"]
        result = runner.invoke(app, resumed)
        _no_traceback(result)
        assert result.exit_code == 2 and named in result.output and edited.name in result.output, result.output


@pytest.mark.parametrize(
    "argv, option, value, allowed",
    [
        (["simulate", "--threads", "0"], "--threads", "0", ">= 1"),
        (["simulate", "--frames", "1"], "--frames", "1", ">= 2"),
        (["critical", "--max-points", "-4"], "--max-points", "-4", ">= 2"),
        (["rotate", "--turns", "0"], "--turns", "0", ">= 1"),
        (["orbit", "--moment", "0.3", "--segments", "0"], "--segments", "0", ">= 1"),
    ],
)
def test_a_whole_number_out_of_range_is_named_with_its_value_and_range(argv, option, value, allowed):
    result = runner.invoke(app, argv)
    _no_traceback(result)
    assert result.exit_code == 2, result.output
    assert option in result.output and f"got {value}" in result.output and allowed in result.output, result.output


@pytest.mark.parametrize("argv", [["--moment", "0"], ["--load", "phi:1=0"], ["--moment", "0", "--load", "phi:0=0"]])
def test_simulate_takes_a_zero_moment(argv):
    """A moment of zero (whose terminal spin is zero) runs: the spin check divides by nothing."""
    result = runner.invoke(app, ["simulate", *argv, "--t-end", "0.5", "--frames", "2", "--json"])
    _no_traceback(result)
    assert result.exit_code == 0, result.output
