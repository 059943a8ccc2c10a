"""Writing results: atomic and safe writes, checks before computing, fallbacks, checkpoints and the report's manifest (issue 15)."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time

import numpy as np
import pytest
import xarray as xr
from typer.testing import CliRunner

from cosserat_chain import ChainParams, __version__
from cosserat_chain.cli import app
from cosserat_chain.experiments.localization import localization_run
from cosserat_chain.experiments.study import spec_from_mapping
from cosserat_chain.io import OutputError, check_output, read_dataset, write_dataset, write_text
from cosserat_chain.memory import MemoryEstimateError, require
from in_process_study import study_in_process  # noqa: F401 (a fixture)

runner = CliRunner()


def _dataset(value: float) -> xr.Dataset:
    return xr.Dataset({"x": ("i", np.full(3, value))}, attrs={"what": "test"})


def test_a_symbolic_link_is_never_written_through(tmp_path):
    """The file a link points to is not the package's: an input, or a system file when run as root."""
    victim = tmp_path / "passwd"
    victim.write_text("root:x:0:0\n")
    target = tmp_path / "target.nc"
    write_dataset(_dataset(1.0), target)
    for name, points_to in (("link.nc", target), ("etc.nc", victim), ("dangling.nc", tmp_path / "gone.nc")):
        link = tmp_path / name
        link.symlink_to(points_to)
        with pytest.raises(OutputError, match=f"{name}' is a symbolic link to '{points_to}'"):
            check_output(link)
        with pytest.raises(OutputError, match="symbolic link"):
            write_dataset(_dataset(2.0), link)
        assert link.is_symlink() and os.readlink(link) == str(points_to)
    assert victim.read_text() == "root:x:0:0\n" and float(read_dataset(target).x[0]) == 1.0
    assert not (tmp_path / "gone.nc").exists()
    folder_link = tmp_path / "results"
    folder_link.symlink_to(tmp_path / "real", target_is_directory=True)
    (tmp_path / "real").mkdir()
    write_dataset(_dataset(3.0), folder_link / "run.nc")  # a link among the folders on the way is followed
    assert float(read_dataset(tmp_path / "real" / "run.nc").x[0]) == 3.0


def test_the_cli_refuses_a_link_before_computing(tmp_path):
    victim = tmp_path / "passwd"
    victim.write_text("root:x:0:0\n")
    (tmp_path / "run.nc").symlink_to(victim)
    result = runner.invoke(app, ["simulate", "--t-end", "0.2", "--frames", "2", "--out", str(tmp_path / "run.nc")])
    assert result.exit_code == 2 and "symbolic link" in result.output, result.output
    assert victim.read_text() == "root:x:0:0\n"


@pytest.mark.parametrize("kind", ["fifo", "folder"])
def test_a_target_that_is_not_a_regular_file_is_never_replaced(tmp_path, kind):
    path = tmp_path / "out.nc"
    os.mkfifo(path) if kind == "fifo" else path.mkdir()
    with pytest.raises(OutputError, match="out.nc"):
        write_dataset(_dataset(1.0), path)
    assert (path.is_fifo() if kind == "fifo" else path.is_dir()) and len(list(tmp_path.iterdir())) == 1


def test_temporary_files_of_a_killed_writer_are_removed_by_the_next_write(tmp_path):
    target = tmp_path / "run.nc"
    dead = subprocess.run([sys.executable, "-c", "import os; print(os.getpid())"], capture_output=True, text=True, check=True)
    stale = tmp_path / f".run.nc.tmp{int(dead.stdout)}-abc.nc"
    live = tmp_path / f".run.nc.tmp{os.getpid()}-abc.nc"  # a writer still running (this process) keeps its file
    other = tmp_path / f".run.checkpoint.nc.tmp{int(dead.stdout)}-abc.nc"  # another target's: not ours to judge here
    for path in (stale, live, other):
        path.write_text("half written")
    write_text("done", target)
    assert not stale.exists() and live.exists() and other.exists() and target.read_text() == "done"


def test_check_output_refuses_inputs_unknown_formats_and_unwritable_places(tmp_path):
    config = tmp_path / "chain.toml"
    config.write_text("N = 3\n")
    with pytest.raises(OutputError, match="--config"):
        check_output(config, "--out", inputs={"--config": config})
    alias = tmp_path / "alias"
    alias.symlink_to(tmp_path, target_is_directory=True)
    with pytest.raises(OutputError, match="--config"):  # the same file under another name
        check_output(alias / "chain.toml", "--out", inputs={"--config": config})
    with pytest.raises(OutputError, match="'.jpeg'"):
        check_output(tmp_path / "fig.jpeg", "--plot", formats=(".png", ".svg"))
    with pytest.raises(OutputError, match="cannot write"):
        check_output("/proc/out.nc")
    assert check_output(tmp_path / "new" / "deeper" / "out.nc") == tmp_path / "new" / "deeper" / "out.nc"
    assert not (tmp_path / "new").exists(), "a check creates nothing"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["alias", "chain.toml"], "the writability probe leaves nothing"


def test_a_result_whose_write_fails_after_the_work_is_kept_in_a_fallback(tmp_path, monkeypatch):
    """The write fails only once the run is done (the disk filled meanwhile): the run is saved beside, and the command says where."""
    import cosserat_chain.cli.common as common

    real = common.write_bytes
    out = tmp_path / "out" / "run.nc"

    def full_disk(data, path):
        if path == out:
            raise OSError(28, "No space left on device")
        return real(data, path)

    monkeypatch.setattr(common, "write_bytes", full_disk)
    monkeypatch.chdir(tmp_path)
    result = runner.invoke(app, ["simulate", "--model", "linear", "--t-end", "2", "--frames", "5", "--out", str(out)])
    assert result.exit_code == 3 and "No space left on device" in result.output
    (fallback,) = tmp_path.glob("run.recovered-*.nc")
    assert str(fallback) in result.output.replace("\n", "")
    ds = read_dataset(fallback)
    assert ds.sizes["time"] == 5 and ds.attrs["model"] == "linear"


def test_memory_estimates_refuse_what_cannot_fit_naming_the_size():
    with pytest.raises(MemoryEstimateError, match="a test array needs about 32 TiB"):
        require(2.0**45, "a test array")
    require(1024, "a kilobyte")  # fits


def test_a_checkpoint_edited_after_it_was_written_is_refused(tmp_path):
    params = ChainParams()
    checkpoint = tmp_path / "run.checkpoint.nc"
    localization_run(params, "sine", 0.3, turns=1, t_max=20.0, checkpoint=checkpoint)
    settings = dict(turns=2, t_max=40.0, checkpoint=checkpoint, resume=True)
    ds = read_dataset(checkpoint)
    edited = ds.copy()
    edited["final_phi"] = edited["final_phi"] + 1e-9
    write_dataset(edited, checkpoint)
    with pytest.raises(ValueError, match="altered or damaged"):
        localization_run(params, "sine", 0.3, **settings)
    write_dataset(ds, checkpoint)
    assert localization_run(params, "sine", 0.3, **settings).step > int(ds.attrs["steps"]), "the sound checkpoint resumes"
    checkpoint.write_bytes(checkpoint.read_bytes()[:1000])  # truncated
    with pytest.raises(ValueError, match="cannot resume from the checkpoint"):
        localization_run(params, "sine", 0.3, **settings)


def test_rotate_refuses_to_overwrite_a_checkpoint_without_resume_or_force(tmp_path):
    out = tmp_path / "rot.nc"
    first = runner.invoke(app, ["rotate", "--model", "sine", "--moment", "0.3", "--turns", "1", "--out", str(out)])
    assert first.exit_code == 0, first.output
    checkpoint = tmp_path / "rot.checkpoint.nc"
    before = checkpoint.read_bytes()
    again = runner.invoke(app, ["rotate", "--model", "sine", "--moment", "0.3", "--turns", "1", "--out", str(out)])
    assert again.exit_code == 2 and "--resume" in again.output and "--force" in again.output
    assert checkpoint.read_bytes() == before
    forced = runner.invoke(app, ["rotate", "--model", "sine", "--moment", "0.3", "--turns", "1", "--out", str(out), "--force"])
    assert forced.exit_code == 0, forced.output


def test_reproduce_replaces_its_own_older_files_and_keeps_the_users(tmp_path):
    import hashlib

    from cosserat_chain.report import MANIFEST, MANIFEST_MARKER, reproduce

    out = tmp_path / "paper"
    (out / "figures").mkdir(parents=True)
    (out / "figures" / "old_stage.png").write_bytes(b"an older report's figure")
    (out / "notes.txt").write_text("the user's own file")
    sha = {name: hashlib.sha256(text).hexdigest() for name, text in {"old": b"an older report's figure", "outside": b"not in the folder: never removed"}.items()}
    files = {"figures/old_stage.png": sha["old"], "../outside.txt": sha["outside"]}
    (out / MANIFEST).write_text(json.dumps({"written_by": MANIFEST_MARKER, "files": files}))
    (tmp_path / "outside.txt").write_text("not in the folder: never removed")
    reproduce(out, stages=["errata"])
    listed = json.loads((out / MANIFEST).read_text())["files"]
    assert {"index.html", "report.md", "summary.json", "params.json"} <= set(listed)
    assert all((out / name).is_file() for name in listed)
    assert not (out / "figures" / "old_stage.png").exists()
    assert (out / "notes.txt").exists() and (tmp_path / "outside.txt").exists()


@pytest.fixture
def cpu_taken():
    """Every core kept busy by another process for the test's duration: the load under which saving once waited on a dead scheduler's lock."""
    spinners = [subprocess.Popen([sys.executable, "-c", "while True: pass"]) for _ in range(os.cpu_count() or 1)]
    yield
    for spinner in spinners:
        spinner.kill()
        spinner.wait()


@pytest.mark.slow  # every core kept busy on purpose for the whole study: the suite's longest wait
def test_a_study_whose_scheduler_dies_keeps_its_cells_and_resumes(tmp_path, monkeypatch, cpu_taken):
    """A real scheduler and worker in their own processes; the scheduler is killed after the first chunk arrives, on a loaded machine."""
    import cosserat_chain.study_runner as study_runner

    monkeypatch.setattr(study_runner, "LOST_TIMEOUT", 2.0)
    spec = spec_from_mapping({"models": ["sine"], "quantities": ["M_c"], "parameters": {"a": [0.1 + 0.01 * i for i in range(16)]}})
    file = tmp_path / "scheduler.json"
    scheduler = subprocess.Popen(
        [sys.executable, "-m", "distributed.cli.dask_scheduler", "--port", "0", "--no-dashboard", "--scheduler-file", str(file)],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
    )
    worker = None
    try:
        for _ in range(300):
            if file.exists() and file.stat().st_size:
                break
            time.sleep(0.1)
        address = json.loads(file.read_text())["address"]
        worker = subprocess.Popen(
            [sys.executable, "-m", "distributed.cli.dask_worker", address, "--nthreads", "1", "--no-dashboard"],
            stdout=subprocess.DEVNULL,
            stderr=subprocess.DEVNULL,
        )
        from dask.distributed import Client

        with Client(address, timeout=60) as client:  # the worker registered before the study starts
            client.wait_for_workers(1, timeout=120)

        def kill_the_scheduler(done, total):
            if done > 0 and scheduler.poll() is None:
                scheduler.send_signal(signal.SIGKILL)
                scheduler.wait()

        out = tmp_path / "study.nc"
        run = study_runner.run_study(spec, out=out, scheduler=address, chunk=1, progress=kill_the_scheduler)
    finally:
        for process in (scheduler, worker):
            if process is not None and process.poll() is None:
                process.kill()
                process.wait()
    assert not run.completed and run.status == "failed" and run.message
    saved = int(read_dataset(out)["done"].sum())
    assert 1 <= saved < 16 and saved >= run.computed
    resumed = study_runner.run_study(spec, out=out, workers=1)
    assert resumed.completed and resumed.skipped == saved and resumed.computed == 16 - saved


def _assert_cf_described(ds: xr.Dataset, what: str) -> None:
    for key in ("Conventions", "title", "history", "source", "references", "units_convention"):
        assert ds.attrs.get(key), f"{what}: no {key}"
    assert ds.attrs["Conventions"] == "CF-1.8 CF-1.10" and "Vasiliev" in ds.attrs["references"]
    undescribed = [str(name) for name in ds.variables if not (ds[name].attrs.get("units") and ds[name].attrs.get("long_name"))]
    assert not undescribed, f"{what}: no units or long_name on {undescribed}"


@pytest.mark.usefixtures("study_in_process")  # the study's file, not its cluster (test_study.py)
def test_every_file_a_command_writes_is_cf_described(tmp_path):
    spec = tmp_path / "spec.toml"
    spec.write_text('models = ["linear"]\nquantities = ["compliance", "band_gap"]\n[parameters]\nE2 = [0.5, 1.0]\n')
    commands = {
        "simulate": ["simulate", "--model", "sine", "--t-end", "2", "--frames", "5"],
        "sweep": ["sweep", "--model", "linear", "--m-max", "0.02", "--steps", "1"],
        "critical": ["critical", "--model", "sine"],
        "rotate": ["rotate", "--model", "sine", "--moment", "0.3", "--turns", "1"],
        "orbit": ["orbit", "--moment", "0.22"],
        "study": ["study", str(spec), "--workers", "1"],
    }
    for name, argv in commands.items():
        out = tmp_path / f"{name}.nc"
        result = runner.invoke(app, [*argv, "--out", str(out)])
        assert result.exit_code == 0, (name, result.output)
        ds = read_dataset(out)
        _assert_cf_described(ds, name)
        assert f"cosserat-chain {__version__}:" in ds.attrs["history"] and ds.attrs["source"] == f"cosserat-chain {__version__}"
    _assert_cf_described(read_dataset(tmp_path / "rotate.checkpoint.nc"), "checkpoint")


def test_a_study_on_a_cluster_without_workers_stops_with_a_message_and_saves(tmp_path, monkeypatch):
    """No worker comes: no chunk can finish, so the study stops after START_TIMEOUT, saying why."""
    from dask.distributed import LocalCluster

    import cosserat_chain.study_runner as study_runner

    monkeypatch.setattr(study_runner, "START_TIMEOUT", 1.0)
    spec = spec_from_mapping({"models": ["linear"], "quantities": ["compliance"], "parameters": {"a": [0.1, 0.2]}})
    with LocalCluster(n_workers=0, processes=False, dashboard_address=":0") as cluster:
        run = study_runner.run_study(spec, out=tmp_path / "study.nc", scheduler=cluster.scheduler_address)
    assert run.status == "failed" and "no worker" in run.message and run.computed == 0
    assert int(read_dataset(tmp_path / "study.nc")["done"].sum()) == 0, "the (empty) result is saved, resumable"
