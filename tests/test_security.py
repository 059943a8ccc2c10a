"""A hostile second user on the same machine: planted links, predictable names, modes (issue 47).

The tests run as root and plant their traps as ``nobody`` (a forked child that drops to
that user), in a sticky world-writable folder like /tmp; they are skipped where the test
does not run as root or there is no ``nobody``.
"""

from __future__ import annotations

import errno
import os
import pwd
import shutil
import stat
import tempfile
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest
import xarray as xr
from typer.testing import CliRunner

from cosserat_chain.cli import app
from cosserat_chain.io import OutputError, read_dataset, write_dataset

try:
    NOBODY = pwd.getpwnam("nobody")
except KeyError:
    NOBODY = None

pytestmark = pytest.mark.skipif(os.geteuid() != 0 or NOBODY is None, reason="two users need root and the user nobody")

runner = CliRunner()

#: The smallest run the CLI makes.
TINY = ["simulate", "--t-end", "1", "--frames", "3"]

#: What the victim's root-only file holds.
SECRET = b"root-only configuration\n"


def as_nobody(action: Callable[[], None]) -> None:
    """Run ``action`` in a forked child as the user nobody (the attacker)."""
    pid = os.fork()
    if pid == 0:
        try:
            os.setgroups([])
            os.setgid(NOBODY.pw_gid)
            os.setuid(NOBODY.pw_uid)
            action()
        except BaseException:
            os._exit(1)
        os._exit(0)
    _, status = os.waitpid(pid, 0)
    assert os.waitstatus_to_exitcode(status) == 0, "the attacker's step failed"


@pytest.fixture
def machine():
    """A folder the two users share: ``shared/`` (sticky, world-writable, as /tmp), ``victim/important.conf`` (root's, 0600)."""
    root = Path(tempfile.mkdtemp(prefix="cosserat-security-"))
    root.chmod(0o755)
    shared = root / "shared"
    shared.mkdir()
    shared.chmod(0o1777)
    victim = root / "victim"
    victim.mkdir(mode=0o700)
    secret = victim / "important.conf"
    secret.write_bytes(SECRET)
    secret.chmod(0o600)
    try:
        yield root, shared, secret
    finally:
        shutil.rmtree(root)


def _untouched(secret: Path) -> bool:
    info = secret.lstat()
    return secret.read_bytes() == SECRET and stat.S_IMODE(info.st_mode) == 0o600 and info.st_uid == 0


def test_out_through_a_link_planted_in_a_shared_folder_is_refused_naming_link_and_owner(machine):
    _, shared, secret = machine
    link = shared / "flip.nc"
    as_nobody(lambda: os.symlink(secret, link))
    result = runner.invoke(app, [*TINY, "--out", str(link)])
    assert result.exit_code == 2, result.output
    assert str(link) in result.output and "nobody" in result.output
    assert _untouched(secret) and link.is_symlink()


def test_a_planted_link_in_a_parent_folder_is_refused(machine):
    _, shared, secret = machine
    as_nobody(lambda: os.symlink(secret.parent, shared / "results"))
    result = runner.invoke(app, [*TINY, "--out", str(shared / "results" / "important.conf")])
    assert result.exit_code == 2 and "nobody" in result.output
    assert _untouched(secret)


def test_a_link_of_another_user_in_their_own_folder_is_refused(machine):
    root, _, secret = machine
    theirs = root / "theirs"
    theirs.mkdir()
    os.chown(theirs, NOBODY.pw_uid, NOBODY.pw_gid)
    as_nobody(lambda: os.symlink(secret, theirs / "run.nc"))
    with pytest.raises(OutputError, match="nobody"):
        write_dataset(xr.Dataset({"x": ("i", np.zeros(2))}), theirs / "run.nc")
    assert _untouched(secret)


def test_the_callers_own_link_in_a_shared_folder_is_refused_and_its_folder_link_followed(machine):
    root, shared, _ = machine
    target = root / "mine.nc"
    link = shared / "mine.nc"
    link.symlink_to(target)
    result = runner.invoke(app, [*TINY, "--out", str(link)])
    assert result.exit_code == 2 and "symbolic link to" in result.output, result.output
    assert link.is_symlink() and not target.exists()
    (shared / "mine").symlink_to(root, target_is_directory=True)
    result = runner.invoke(app, [*TINY, "--out", str(shared / "mine" / "run.nc")])
    assert result.exit_code == 0, result.output
    assert read_dataset(root / "run.nc").sizes["time"] == 3


def test_the_fallback_never_follows_a_link_planted_at_its_name(machine, monkeypatch):
    """The attack of the issue: --out cannot be written, and the fallback's old name (NAME.recovered-PID) waits as a link."""
    root, shared, secret = machine
    full = root / "full"
    full.mkdir()
    real_fallocate = os.posix_fallocate

    def fallocate(fd, offset, length):  # the disk of full/ is full
        if os.readlink(f"/proc/self/fd/{fd}").startswith(str(full)):
            raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))
        return real_fallocate(fd, offset, length)

    monkeypatch.setattr(os, "posix_fallocate", fallocate)
    monkeypatch.chdir(shared)
    monkeypatch.setattr(tempfile, "tempdir", str(shared))
    as_nobody(lambda: os.symlink(secret, shared / f"flip.recovered-{os.getppid()}.nc"))
    result = runner.invoke(app, [*TINY, "--out", str(full / "flip.nc")])
    assert result.exit_code == 3, result.output
    assert _untouched(secret)
    (fallback,) = [p for p in shared.iterdir() if not p.is_symlink()]
    assert str(fallback) in result.output and fallback.name.startswith("flip.recovered-")
    info = fallback.lstat()
    assert stat.S_ISREG(info.st_mode) and info.st_uid == 0 and stat.S_IMODE(info.st_mode) == 0o600


def test_another_users_file_in_a_shared_folder_is_not_replaced(machine):
    _, shared, _ = machine
    theirs = shared / "run.nc"
    as_nobody(lambda: theirs.write_bytes(b"nobody's file"))
    result = runner.invoke(app, [*TINY, "--out", str(theirs)])
    assert result.exit_code == 2 and "nobody" in result.output
    assert theirs.read_bytes() == b"nobody's file"


def test_a_lock_file_planted_as_a_link_is_refused(machine):
    _, shared, secret = machine
    as_nobody(lambda: os.symlink(secret, shared / ".run.nc.lock"))
    result = runner.invoke(app, [*TINY, "--out", str(shared / "run.nc")])
    assert result.exit_code == 2 and "lock file" in result.output
    assert _untouched(secret) and not (shared / "run.nc").exists()


def test_a_replaced_file_keeps_its_owner_and_mode(machine):
    root, _, _ = machine
    out = root / "run.nc"
    out.write_bytes(b"old")
    os.chown(out, NOBODY.pw_uid, NOBODY.pw_gid)
    out.chmod(0o640)
    write_dataset(xr.Dataset({"x": ("i", np.zeros(2))}), out)
    info = out.stat()
    assert (info.st_uid, info.st_gid, stat.S_IMODE(info.st_mode)) == (NOBODY.pw_uid, NOBODY.pw_gid, 0o640)


def test_another_users_temporary_files_are_never_removed(machine):
    _, shared, _ = machine
    theirs = shared / ".run.nc.tmp999999999-abcdefgh.nc"  # the name of a dead writer's temporary file
    as_nobody(lambda: theirs.write_bytes(b"nobody's"))
    assert runner.invoke(app, [*TINY, "--out", str(shared / "run.nc")]).exit_code == 0
    assert theirs.read_bytes() == b"nobody's"


def test_a_report_folder_that_is_another_users_link_is_refused(machine):
    _, shared, secret = machine
    as_nobody(lambda: os.symlink(secret.parent, shared / "rep"))
    result = runner.invoke(app, ["reproduce", "--out", str(shared / "rep")])
    assert result.exit_code == 2 and "nobody" in result.output
    assert sorted(p.name for p in secret.parent.iterdir()) == ["important.conf"] and _untouched(secret)
