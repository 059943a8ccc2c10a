"""Runs that start where another stopped (issue 14, item 4): ``simulate --x0 RUN.nc [--at T]`` and
``simulate --checkpoint-every S`` / ``--resume``.

A frame stores the state at a step boundary (positions and velocities), so a run started
from it with the same step takes the same steps as the uninterrupted run: its states are
equal to the last bit. The step 1/64 and the times are binary fractions, so that both runs
also compute the same times for the loads' schedules.

A checkpoint holds more (the forces, the energy sums, the chunk length and the frames so
far), so a resumed run equals the uninterrupted one bit for bit with any step: the tests
use dt = 0.0173, whose multiples are not exact, and a harmonic load, with which forces
evaluated anew at the restart would differ in their last bits. The integrator's chunks are
made small (``CHUNK_WORK``) so that a short run has several.
"""

from __future__ import annotations

import h5py
import numpy as np
import pytest
import xarray as xr
from typer.testing import CliRunner

from cosserat_chain import ChainParams
from cosserat_chain.cli import app
from cosserat_chain.cli import simulate as simulate_command
from cosserat_chain.experiments import simulation
from cosserat_chain.experiments.simulation import simulate
from cosserat_chain.io import read_dataset, run_frame, write_dataset
from cosserat_chain.loads import Loads, PointLoad, Schedule
from cosserat_chain.numerics import dynamics

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


# --- Checkpoints and --resume ---------------------------------------------------------------

#: A step whose multiples are not binary fractions, and the steps of a short run's chunks.
ODD_DT = 0.0173
CHUNK = 176
RUN = dict(t_end=30.0, dt=ODD_DT, n_frames=41)  # 1735 steps, a frame every 44, chunks of 176: ten chunks


@pytest.fixture
def small_chunks(monkeypatch):
    """Chunks of CHUNK steps of the seven-particle chain (the default makes a short run one chunk)."""
    monkeypatch.setattr(dynamics, "CHUNK_WORK", 7 * 200)


def ctrl_c_after(chunks: int):
    """A progress callback that presses Ctrl-C after ``chunks`` chunks."""
    calls = []

    def progress(done, total):
        calls.append(done)
        if len(calls) == chunks:
            raise KeyboardInterrupt

    return progress


def assert_same_run(a: xr.Dataset, b: xr.Dataset) -> None:
    """Every variable and coordinate equal to the last bit (NaN where NaN), the same steps and status."""
    assert set(a.variables) == set(b.variables)
    for name in a.variables:
        assert np.array_equal(a[name].values, b[name].values, equal_nan=True), name
    assert (a.attrs["steps"], a.attrs["status"], a.attrs["dt"]) == (b.attrs["steps"], b.attrs["status"], b.attrs["dt"])


@pytest.mark.parametrize("method", ["verlet", pytest.param("yoshida4", marks=pytest.mark.slow)])
def test_a_run_resumed_from_its_checkpoint_equals_the_uninterrupted_run_bit_for_bit(tmp_path, small_chunks, method):
    params = ChainParams(N=3)
    whole = simulate(params, "nonlinear", LOADS, method=method, **RUN)
    path = tmp_path / "run.checkpoint.nc"
    stopped = simulate(params, "nonlinear", LOADS, method=method, checkpoint=path, checkpoint_every=1e9, progress=ctrl_c_after(3), **RUN)
    assert stopped.attrs["status"] == "interrupted" and str(path) in stopped.attrs["message"]
    saved = read_dataset(path)
    chunk = saved.attrs["chunk_steps"]  # CHUNK for Verlet, a third of it for yoshida4's three force evaluations a step
    assert saved.attrs["steps"] == 3 * chunk and saved.sizes["time"] == 3 * chunk // 44 + 1  # written on the way out
    np.testing.assert_array_equal(saved.u.values, whole.u.values[: saved.sizes["time"]])
    resumed = simulate(params, "nonlinear", LOADS, method=method, checkpoint=path, resume=True, **RUN)
    assert_same_run(resumed, whole)
    # The checkpoint of the finished run is kept and describes it: resuming it again computes nothing new.
    assert read_dataset(path).attrs["steps"] == whole.attrs["steps"]
    assert_same_run(
        simulate(params, "nonlinear", LOADS, method=method, checkpoint=path, resume=True, progress=ctrl_c_after(1), **RUN), whole
    )


def test_a_run_split_over_two_threads_resumes_bitwise_on_two_and_its_states_on_one(tmp_path, monkeypatch):
    # 601 particles: two blocks (a chain of seven runs on one thread whatever --threads says).
    monkeypatch.setattr(dynamics, "CHUNK_WORK", 601 * 100)
    params = ChainParams(N=300)
    run = dict(t_end=10.0, dt=ODD_DT, n_frames=11)
    whole = simulate(params, "nonlinear", LOADS, threads=2, **run)
    path = tmp_path / "c.nc"
    simulate(params, "nonlinear", LOADS, threads=2, checkpoint=path, checkpoint_every=1e9, progress=ctrl_c_after(2), **run)
    assert read_dataset(path).sizes["split_sum"] == 3  # the sums at the split and those of the two blocks
    write_dataset(read_dataset(path), tmp_path / "copy.nc")  # to resume on one thread below
    assert_same_run(simulate(params, "nonlinear", LOADS, threads=2, checkpoint=path, resume=True, **run), whole)
    # On one thread the blocks' sums are added in another order: the states stay bitwise, the sums to round-off.
    one = simulate(params, "nonlinear", LOADS, threads=1, **run)
    other = simulate(params, "nonlinear", LOADS, threads=1, checkpoint=tmp_path / "copy.nc", resume=True, **run)
    for name in ("u", "v", "phi", "u_dot", "v_dot", "phi_dot"):
        np.testing.assert_array_equal(other[name].values, one[name].values, err_msg=name)
    np.testing.assert_allclose(other.dissipated.values, one.dissipated.values, rtol=1e-12)


def test_checkpoints_are_written_on_the_wall_clock_between_chunks(tmp_path, small_chunks):
    params = ChainParams(N=3)
    path = tmp_path / "c.nc"
    seen = []
    run = {**RUN, "t_end": 12.0, "n_frames": 17}  # 694 steps: four chunks, each written

    def look(done, total):
        # The attribute alone, by h5py: the package's reader (at the end) opens the file's structure in a child first.
        if path.exists():
            with h5py.File(path, "r") as file:
                seen.append(int(file.attrs["steps"].item()))
        else:
            seen.append(None)

    simulate(params, "nonlinear", LOADS, checkpoint=path, checkpoint_every=0.0, progress=look, **run)
    assert seen == [min((k + 1) * CHUNK, 694) for k in range(len(seen))] and len(seen) == 4, seen
    path.unlink()
    seen.clear()
    simulate(params, "nonlinear", LOADS, checkpoint=path, checkpoint_every=1e9, progress=look, **run)
    assert seen == [None] * 4 and read_dataset(path).attrs["steps"] == 694  # only at the end


def test_an_error_during_the_run_leaves_a_checkpoint_of_the_last_chunk(tmp_path, small_chunks):
    params = ChainParams(N=3)
    path = tmp_path / "c.nc"

    def broken(done, total):
        if done >= 2 * CHUNK:
            raise RuntimeError("a progress bar that failed")

    with pytest.raises(RuntimeError, match="progress bar"):
        simulate(params, "nonlinear", LOADS, checkpoint=path, checkpoint_every=1e9, progress=broken, **RUN)
    assert read_dataset(path).attrs["steps"] == 2 * CHUNK
    assert_same_run(simulate(params, "nonlinear", LOADS, checkpoint=path, resume=True, **RUN), simulate(params, "nonlinear", LOADS, **RUN))


def _write_config(path, e2=1.0):
    path.write_text(
        f'N = 3\nE2 = {e2}\n[[loads]]\nrow = "v"\nparticle = 2\nkind = "harmonic"\namplitude = 0.01\nfrequency = 0.2\nphase = 0.3\n'
    )
    return path


def _interrupt_the_command(monkeypatch, chunks):
    """Make ``simulate``'s progress bar press Ctrl-C after ``chunks`` chunks."""
    monkeypatch.setattr(simulate_command, "bar_callback", lambda bar: ctrl_c_after(chunks))


def test_simulate_resume_after_ctrl_c_gives_the_uninterrupted_file(tmp_path, small_chunks, monkeypatch):
    config = _write_config(tmp_path / "c.toml")
    common = ["simulate", "--config", str(config), "--moment", "0.15", "--ramp", "20", "--t-end", "30", "--dt", str(ODD_DT)]
    common += ["--frames", "41"]
    whole = tmp_path / "whole.nc"
    assert runner.invoke(app, [*common, "--out", str(whole)]).exit_code == 0
    out = tmp_path / "run.nc"
    checkpoint = tmp_path / "run.checkpoint.nc"
    with monkeypatch.context() as patch:
        _interrupt_the_command(patch, 4)
        stopped = runner.invoke(app, [*common, "--out", str(out), "--checkpoint-every", "60"])
    assert stopped.exit_code == 130 and "resume" in stopped.output, stopped.output
    assert read_dataset(checkpoint).attrs["steps"] == 4 * CHUNK and read_dataset(out).attrs["status"] == "interrupted"
    again = runner.invoke(app, [*common, "--out", str(out), "--checkpoint-every", "60"])
    assert again.exit_code == 2 and "--resume" in again.output and "--force" in again.output, again.output
    resumed = runner.invoke(app, [*common, "--out", str(out), "--resume"])
    assert resumed.exit_code == 0, resumed.output
    assert_same_run(read_dataset(out), read_dataset(whole))
    assert read_dataset(checkpoint).attrs["steps"] == 1735  # kept, as rotate keeps its own
    forced = runner.invoke(app, [*common, "--out", str(out), "--checkpoint-every", "60", "--force"])
    assert forced.exit_code == 0, forced.output


def test_simulate_resume_from_a_stored_frame_takes_the_same_x0_and_at(tmp_path, small_chunks, monkeypatch):
    first = tmp_path / "first.nc"
    assert runner.invoke(app, ["simulate", "--t-end", "20", "--dt", str(ODD_DT), "--frames", "5", "--out", str(first)]).exit_code == 0
    go_on = ["simulate", "--x0", str(first), "--at", "10", "--t-end", "40", "--dt", str(ODD_DT), "--frames", "41"]
    whole = tmp_path / "whole.nc"
    assert runner.invoke(app, [*go_on, "--out", str(whole)]).exit_code == 0
    out, checkpoint = tmp_path / "second.nc", tmp_path / "second.ck"
    with monkeypatch.context() as patch:
        _interrupt_the_command(patch, 2)
        assert runner.invoke(app, [*go_on, "--out", str(out), "--checkpoint", str(checkpoint)]).exit_code == 130
    other_frame = runner.invoke(app, [*go_on[:3], "--at", "15", *go_on[5:], "--out", str(out), "--checkpoint", str(checkpoint), "--resume"])
    assert other_frame.exit_code == 2 and "was written for t0=" in other_frame.output, other_frame.output
    resumed = runner.invoke(app, [*go_on, "--out", str(out), "--checkpoint", str(checkpoint), "--resume"])
    assert resumed.exit_code == 0, resumed.output
    assert_same_run(read_dataset(out), read_dataset(whole))


@pytest.fixture(scope="module")
def interrupted(tmp_path_factory):
    """A ``simulate`` stopped by Ctrl-C after two chunks: (its checkpoint, its bytes, its options, another chain's config),
    made once for the refused resumes below; each test starts from these bytes."""
    folder = tmp_path_factory.mktemp("interrupted")
    config = _write_config(folder / "c.toml")
    other_config = _write_config(folder / "other.toml", e2=2.0)
    checkpoint = folder / "c.nc"
    base = {"--config": str(config), "--model": "nonlinear", "--dt": str(ODD_DT), "--moment": "0.15", "--t-end": "30", "--frames": "41"}
    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(dynamics, "CHUNK_WORK", 7 * 200)
        _interrupt_the_command(patch, 2)
        assert runner.invoke(app, _resume_line(base, checkpoint)).exit_code == 130
    return checkpoint, checkpoint.read_bytes(), base, other_config


def _resume_line(options: dict[str, str], checkpoint) -> list[str]:
    return ["simulate", *(item for pair in options.items() for item in pair), "--checkpoint", str(checkpoint)]


@pytest.mark.parametrize(
    ("change", "named"),
    [
        (["--config", "{other_config}"], "params.E2=1.0, but this run has params.E2=2.0"),
        (["--model", "sine"], "model='nonlinear', but this run has model='sine'"),
        (["--dt", "0.017"], "dt=0.0173, but this run has dt=0.017"),
        (["--moment", "0.2"], "loads_json="),
        (["--t-end", "31"], "t_end=30.0, but this run has t_end=31.0"),
        (["--method", "yoshida4"], "method='verlet', but this run has method='yoshida4'"),
        (["--frames", "40"], "n_frames=41, but this run has n_frames=40"),
    ],
    ids=["params", "model", "dt", "loads", "t_end", "method", "frames"],
)
def test_a_resume_with_other_settings_is_refused_naming_what_differs(interrupted, small_chunks, change, named):
    checkpoint, before, base, other_config = interrupted
    checkpoint.write_bytes(before)
    changed = {**base, change[0]: change[1].format(other_config=other_config)}
    result = runner.invoke(app, [*_resume_line(changed, checkpoint), "--resume"])
    assert result.exit_code == 2 and named in result.output and "Traceback" not in result.output, result.output
    assert checkpoint.read_bytes() == before, "a refused resume leaves the checkpoint as it was"


def test_the_checkpoint_the_refused_resumes_left_resumes_with_its_own_settings(interrupted, small_chunks):
    """The control of the refusals above: their checkpoint, byte for byte as they left it, resumes with the same settings."""
    checkpoint, before, base, _ = interrupted
    checkpoint.write_bytes(before)
    assert runner.invoke(app, [*_resume_line(base, checkpoint), "--resume"]).exit_code == 0, "the same settings resume"


def test_a_simulation_checkpoint_edited_or_of_another_command_is_refused(tmp_path, small_chunks):
    params = ChainParams(N=3)
    path = tmp_path / "c.nc"
    simulate(params, "nonlinear", LOADS, checkpoint=path, checkpoint_every=1e9, progress=ctrl_c_after(2), **RUN)
    ds = read_dataset(path)
    edited = ds.copy()
    edited["final_force_phi"] = edited["final_force_phi"] + 1e-12
    write_dataset(edited, path)
    with pytest.raises(ValueError, match="altered or damaged"):
        simulate(params, "nonlinear", LOADS, checkpoint=path, resume=True, **RUN)
    write_dataset(simulate(params, "nonlinear", LOADS, **RUN), path)  # a result, not a checkpoint
    with pytest.raises(ValueError, match="is not a simulation checkpoint"):
        simulate(params, "nonlinear", LOADS, checkpoint=path, resume=True, **RUN)
    with pytest.raises(ValueError, match="reference"):
        simulate(params, "nonlinear", LOADS, checkpoint=path, reference=True, **RUN)


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["--out", "{out}", "--checkpoint-every", "-1"], "--checkpoint-every"),
        (["--checkpoint-every", "5"], "--checkpoint-every needs --checkpoint or --out"),
        (["--resume"], "--resume needs --checkpoint or --out"),
        (["--out", "{out}", "--resume", "--force"], "contradict"),
        (["--out", "{out}", "--force"], "--force replaces an existing checkpoint"),
        (["--out", "{out}", "--checkpoint-every", "1", "--reference"], "--reference"),
        (["--out", "{out}", "--checkpoint", "{out}"], "--checkpoint"),
        (["--checkpoint", "{folder}"], "folder"),
        (["--config", "{config}", "--checkpoint", "{config}"], "--config"),
        (["--checkpoint", "{existing}"], "--resume"),
    ],
    ids=[
        "negative",
        "no-file",
        "resume-no-file",
        "resume-force",
        "force-alone",
        "reference",
        "same-as-out",
        "folder",
        "is-config",
        "exists",
    ],
)
def test_bad_checkpoint_options_are_refused_before_any_work(tmp_path, monkeypatch, args, message):
    config = _write_config(tmp_path / "c.toml")
    existing = tmp_path / "old.checkpoint.nc"
    existing.write_bytes(b"hours of an earlier run")
    files = dict(out=tmp_path / "run.nc", folder=tmp_path, config=config, existing=existing)

    def no_work(*args, **kwargs):
        raise AssertionError("computed before refusing")

    monkeypatch.setattr(simulation, "simulate", no_work)
    result = runner.invoke(app, ["simulate", "--t-end", "1", *(a.format(**files) for a in args)])
    assert result.exit_code == 2 and message in result.output and "Traceback" not in result.output, result.output
    assert existing.read_bytes() == b"hours of an earlier run" and not files["out"].exists()
