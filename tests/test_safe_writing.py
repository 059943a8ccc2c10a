"""Writing that cannot crash or lose the result, removes nothing of the user's, one writer at a time, modes kept (issue 46, items 1-4).

A full disk is tried two ways: an injected ENOSPC (always runs) and a real full tmpfs
(where the test runs as root and may mount one; skipped otherwise).
"""

from __future__ import annotations

import errno
import hashlib
import json
import os
import stat
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import xarray as xr
from typer.testing import CliRunner

from cosserat_chain.cli import app
from cosserat_chain.experiments.checkpoint import CheckpointClock
from cosserat_chain.io import OutputError, output_lock, read_dataset, write_dataset, write_text
from in_process_study import study_in_process  # noqa: F401 (a fixture)

runner = CliRunner()

#: The smallest run the CLI makes: three frames of the paper's chain over one time unit.
TINY = ["simulate", "--t-end", "1", "--frames", "3"]


def _dataset(value: float) -> xr.Dataset:
    return xr.Dataset({"x": ("i", np.full(3, value))}, attrs={"what": "test"})


@pytest.fixture
def full_folder(tmp_path, monkeypatch):
    """A folder ``full/`` whose disk is full: every reservation or write of a file in it fails with ENOSPC."""
    full = tmp_path / "full"
    full.mkdir()
    real_fallocate, real_pwrite = os.posix_fallocate, os.pwrite

    def in_full(fd: int) -> bool:
        return os.readlink(f"/proc/self/fd/{fd}").startswith(str(full))

    def fallocate(fd, offset, length):
        if in_full(fd):
            raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))
        return real_fallocate(fd, offset, length)

    def pwrite(fd, data, offset):
        if in_full(fd):
            raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))
        return real_pwrite(fd, data, offset)

    monkeypatch.setattr(os, "posix_fallocate", fallocate)
    monkeypatch.setattr(os, "pwrite", pwrite)
    return full


def _leftovers(folder: Path) -> list[str]:
    """Temporary and lock files left in a folder."""
    return sorted(p.name for p in folder.iterdir() if ".tmp" in p.name or p.name.endswith(".lock"))


# --- 1. a full disk is an error, never a crash, and the result is kept --------------------------------------------


def test_a_full_disk_raises_oserror_and_leaves_the_old_file_whole(full_folder):
    target = full_folder / "run.nc"
    target.write_bytes(b"the earlier result")
    with pytest.raises(OSError) as caught:
        write_dataset(_dataset(1.0), target)
    assert caught.value.errno == errno.ENOSPC
    assert target.read_bytes() == b"the earlier result"
    assert _leftovers(full_folder) == []


def test_simulate_on_a_full_disk_keeps_the_run_in_an_unpredictable_fallback_and_exits_3(full_folder, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    result = runner.invoke(app, [*TINY, "--out", str(full_folder / "run.nc")])
    assert result.exit_code == 3, result.output
    fallbacks = list(tmp_path.glob("run.recovered-*.nc"))
    assert len(fallbacks) == 1 and str(fallbacks[0]) in result.output and "No space left" in result.output
    assert fallbacks[0].name != f"run.recovered-{os.getpid()}.nc"  # the old, predictable name
    assert stat.S_IMODE(fallbacks[0].stat().st_mode) == 0o600
    assert read_dataset(fallbacks[0]).sizes["time"] == 3
    assert not (full_folder / "run.nc").exists() and _leftovers(full_folder) == []


def test_rotate_on_a_full_disk_goes_on_past_its_checkpoints_and_keeps_the_result(full_folder, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    out = full_folder / "rot.nc"
    result = runner.invoke(app, ["rotate", "--turns", "2", "--moment", "1", "--checkpoint-every", "0", "--out", str(out)])
    assert result.exit_code == 3, result.output
    (fallback,) = tmp_path.glob("rot.recovered-*.nc")
    assert str(fallback) in result.output and int(read_dataset(fallback).attrs["turns_completed"]) >= 2
    assert sorted(p.name for p in full_folder.iterdir()) == []


def test_a_failed_checkpoint_write_keeps_the_previous_one_and_the_run_goes_on(full_folder):
    path = full_folder / "run.checkpoint.nc"
    path.write_bytes(b"the previous checkpoint")
    clock = CheckpointClock(path, 0.0)
    clock.write(_dataset(1.0))  # raises nothing
    assert "No space left" in clock.error and path.read_bytes() == b"the previous checkpoint"


def test_a_study_file_that_cannot_be_written_is_reported_not_raised(full_folder):
    from cosserat_chain.study_runner import _save

    assert "No space left" in _save(_dataset(1.0), full_folder / "study.nc")
    assert not (full_folder / "study.nc").exists()


@pytest.mark.usefixtures("study_in_process")  # the claim is the study's files, not its cluster
def test_a_study_on_a_full_disk_keeps_its_cells_in_a_fallback_and_exits_3(full_folder, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    spec = tmp_path / "spec.toml"
    spec.write_text('models = ["linear"]\nquantities = ["compliance"]\n[parameters]\na = [0.1, 0.2]\n')
    result = runner.invoke(app, ["study", str(spec), "--out", str(full_folder / "study.nc"), "--workers", "1"])
    assert result.exit_code == 3, result.output
    (fallback,) = tmp_path.glob("study.recovered-*.nc")
    assert str(fallback) in result.output and int(read_dataset(fallback)["done"].sum()) == 2
    assert not (full_folder / "study.nc").exists() and _leftovers(full_folder) == []


def test_reproduce_on_a_full_disk_exits_3_naming_the_file(full_folder, monkeypatch):
    import cosserat_chain.report as report

    monkeypatch.setattr(report, "STAGES", {"errata": report.STAGES["errata"]})
    result = runner.invoke(app, ["reproduce", "--out", str(full_folder / "rep")])
    assert result.exit_code == 3 and "No space left" in result.output and str(full_folder / "rep" / "params.json") in result.output
    assert not (full_folder / "rep" / "manifest.json").exists()


def _mount_tmpfs(folder: Path, size: str) -> bool:
    if os.geteuid() != 0:
        return False
    folder.mkdir()
    done = subprocess.run(["mount", "-t", "tmpfs", "-o", f"size={size}", "tmpfs", str(folder)], capture_output=True)
    return done.returncode == 0


def test_simulate_on_a_real_full_tmpfs_exits_3_with_the_run_saved_elsewhere(tmp_path):
    """The case that segfaulted inside HDF5 (rc -11): a 200 kB run on a 64 kB file system."""
    full = tmp_path / "full"
    if not _mount_tmpfs(full, "64k"):
        pytest.skip("mounting a tmpfs needs root and a system that allows it")
    try:
        done = subprocess.run(
            [sys.executable, "-m", "cosserat_chain", "simulate", "--t-end", "10", "--frames", "2001", "--out", str(full / "big.nc")],
            capture_output=True,
            text=True,
            cwd=tmp_path,
            timeout=600,
        )
        left = sorted(p.name for p in full.iterdir())
    finally:
        subprocess.run(["umount", str(full)], check=False)
    assert done.returncode == 3, done.stderr[-2000:]
    fallbacks = list(tmp_path.glob("big.recovered-*.nc"))
    assert len(fallbacks) == 1 and str(fallbacks[0]) in done.stderr
    assert fallbacks[0].stat().st_size > 64 * 1024 and read_dataset(fallbacks[0]).sizes["time"] > 100
    assert left == []  # no temporary or lock file left on the full disk


# --- 2. nothing of the user's is removed --------------------------------------------------------------------------


@pytest.fixture
def run_file(tmp_path):
    result = runner.invoke(app, [*TINY, "--out", str(tmp_path / "run.nc")])
    assert result.exit_code == 0, result.output
    return tmp_path / "run.nc"


def test_export_refuses_a_folder_of_the_users_in_the_way_of_its_frames(run_file):
    frames = run_file.with_name("run_frames")
    frames.mkdir()
    (frames / "thesis.tex").write_text("months of work")
    result = runner.invoke(app, ["export", str(run_file), "--to", "vtk", "--out", str(run_file.with_suffix(".pvd"))])
    assert result.exit_code == 2 and "not written by cosserat-chain" in result.output
    assert (frames / "thesis.tex").read_text() == "months of work" and not run_file.with_suffix(".pvd").exists()


def test_export_replaces_its_own_frames_but_refuses_them_once_the_user_adds_a_file(run_file):
    pvd = run_file.with_suffix(".pvd")
    for _ in range(2):  # the second export replaces the first's frames
        result = runner.invoke(app, ["export", str(run_file), "--to", "vtk", "--out", str(pvd)])
        assert result.exit_code == 0, result.output
    frames = run_file.with_name("run_frames")
    assert sorted(p.name for p in frames.iterdir()) == [".cosserat-chain-frames.json", *(f"frame_{i:05d}.vtu" for i in range(3))]
    (frames / "notes.txt").write_text("mine")
    result = runner.invoke(app, ["export", str(run_file), "--to", "vtk", "--out", str(pvd)])
    assert result.exit_code == 2 and "notes.txt" in result.output and (frames / "notes.txt").exists()


def test_a_manifest_the_package_did_not_write_or_a_changed_file_removes_nothing(tmp_path):
    from cosserat_chain.report import MANIFEST, MANIFEST_MARKER, reproduce

    out = tmp_path / "rep"
    out.mkdir()
    for name in ("notes.txt", "draft.txt", "kept.txt"):
        (out / name).write_text(f"the user's {name}")
    (out / MANIFEST).write_text(json.dumps({"files": ["notes.txt"]}))  # the old format, or a planted list: no marker
    reproduce(out, stages=["errata"])
    assert (out / "notes.txt").exists()
    record = json.loads((out / MANIFEST).read_text())
    assert record["written_by"] == MANIFEST_MARKER
    assert all(hashlib.sha256((out / name).read_bytes()).hexdigest() == digest for name, digest in record["files"].items())
    # A marked manifest whose hash is not the file's (changed since, or never the package's): kept.
    record["files"]["draft.txt"] = hashlib.sha256(b"something else").hexdigest()
    record["files"]["kept.txt"] = hashlib.sha256(b"the user's kept.txt").hexdigest()  # as if written by an old report
    (out / MANIFEST).write_text(json.dumps(record))
    reproduce(out, stages=["errata"])
    assert (out / "draft.txt").exists() and not (out / "kept.txt").exists() and (out / "notes.txt").exists()


@pytest.mark.parametrize(("name", "make"), [("figures", "file"), ("index.html", "folder")])
def test_reproduce_refuses_a_folder_whose_layout_is_in_the_way_before_any_work(tmp_path, name, make):
    out = tmp_path / "rep"
    out.mkdir()
    (out / name).mkdir() if make == "folder" else (out / name).write_text("x")
    result = runner.invoke(app, ["reproduce", "--out", str(out)])
    assert result.exit_code == 2 and name in result.output
    assert sorted(p.name for p in out.iterdir()) == [name]


# --- 3. one writer at a time --------------------------------------------------------------------------------------


def _hold_lock(path: Path) -> subprocess.Popen:
    """Another process holding the lock of ``path`` until it is killed."""
    code = (
        "import sys, time\nfrom cosserat_chain.io import output_lock\n"
        f"with output_lock({str(path)!r}):\n    print('locked', flush=True)\n    time.sleep(600)\n"
    )
    holder = subprocess.Popen([sys.executable, "-c", code], stdout=subprocess.PIPE, text=True)
    assert holder.stdout.readline().strip() == "locked"
    return holder


def test_a_second_run_on_the_same_output_is_refused_before_it_computes_naming_the_first(tmp_path):
    out = tmp_path / "same.nc"
    holder = _hold_lock(out)
    try:
        result = runner.invoke(app, [*TINY, "--out", str(out)])
        checkpointed = runner.invoke(app, [*TINY, "--out", str(tmp_path / "other.nc"), "--checkpoint", str(out), "--checkpoint-every", "0"])
    finally:
        holder.kill()
        holder.wait()
    assert result.exit_code == 2 and f"process {holder.pid}" in result.output and "being written" in result.output
    assert checkpointed.exit_code == 2 and f"process {holder.pid}" in checkpointed.output
    assert not out.exists() and not (tmp_path / "other.nc").exists()
    # The holder is gone (killed): its lock went with it, and the next run writes.
    assert runner.invoke(app, [*TINY, "--out", str(out)]).exit_code == 0
    assert _leftovers(tmp_path) == []


@pytest.mark.parametrize("command", ["study", "rotate", "reproduce"])
def test_every_command_is_refused_on_an_output_another_run_writes(tmp_path, command):
    spec = tmp_path / "spec.toml"
    spec.write_text('models = ["linear"]\nquantities = ["compliance"]\n[parameters]\na = [0.1, 0.2]\n')
    out = tmp_path / ("rep" if command == "reproduce" else "same.nc")
    args = {"study": ["study", str(spec), "--workers", "1"], "rotate": ["rotate", "--turns", "1", "--moment", "1"], "reproduce": ["reproduce"]}[command]
    holder = _hold_lock(out)
    try:
        result = runner.invoke(app, [*args, "--out", str(out)])
    finally:
        holder.kill()
        holder.wait()
    assert result.exit_code == 2 and f"process {holder.pid}" in result.output, result.output
    assert not out.exists()


def test_a_stale_lock_file_of_a_dead_run_does_not_block(tmp_path):
    out = tmp_path / "run.nc"
    (tmp_path / ".run.nc.lock").write_text("999999999\n")  # no process holds it
    assert runner.invoke(app, [*TINY, "--out", str(out)]).exit_code == 0 and out.exists()
    assert _leftovers(tmp_path) == []


def test_the_lock_is_shared_within_a_process_and_released(tmp_path):
    out = tmp_path / "run.nc"
    with output_lock(out):
        write_dataset(_dataset(1.0), out)  # a writer inside the holder goes on
        assert (tmp_path / ".run.nc.lock").read_text().strip() == str(os.getpid())
    assert not (tmp_path / ".run.nc.lock").exists()


def test_a_lock_file_that_is_a_link_is_refused(tmp_path):
    victim = tmp_path / "victim.txt"
    victim.write_text("keep")
    (tmp_path / ".run.nc.lock").symlink_to(victim)
    with pytest.raises(OutputError, match="lock file"):
        write_dataset(_dataset(1.0), tmp_path / "run.nc")
    assert victim.read_text() == "keep"


# --- 4. permissions kept ------------------------------------------------------------------------------------------


def test_a_replaced_output_keeps_its_mode(tmp_path):
    out = tmp_path / "run.nc"
    out.write_bytes(b"old")
    out.chmod(0o600)
    assert runner.invoke(app, [*TINY, "--out", str(out)]).exit_code == 0
    assert stat.S_IMODE(out.stat().st_mode) == 0o600 and read_dataset(out).sizes["time"] == 3


def test_new_files_and_frames_folders_follow_the_umask(run_file):
    previous = os.umask(0o027)
    try:
        write_text("new", run_file.with_name("new.txt"))
        result = runner.invoke(app, ["export", str(run_file), "--to", "vtk", "--out", str(run_file.with_suffix(".pvd"))])
    finally:
        os.umask(previous)
    assert result.exit_code == 0, result.output
    assert stat.S_IMODE(run_file.with_name("new.txt").stat().st_mode) == 0o640
    assert stat.S_IMODE(run_file.with_suffix(".pvd").stat().st_mode) == 0o640
    assert stat.S_IMODE(run_file.with_name("run_frames").stat().st_mode) == 0o750


def test_a_run_refused_after_its_outputs_were_locked_leaves_no_folder_behind(tmp_path):
    config = tmp_path / "bad.toml"
    config.write_text("E1 = -1\n")
    result = runner.invoke(app, [*TINY, "--config", str(config), "--out", str(tmp_path / "new" / "sub" / "run.nc")])
    assert result.exit_code == 2 and "E1" in result.output
    assert sorted(p.name for p in tmp_path.iterdir()) == ["bad.toml"]
