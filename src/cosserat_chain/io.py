"""Files: NetCDF results and figures written atomically and safely, and TOML configuration files.

Contract
--------
:func:`write_dataset` writes an xarray Dataset to NetCDF (h5netcdf), :func:`write_text`
a text file and :func:`write_figure` a matplotlib figure: each is made in memory, then
written by :func:`write_bytes` into a temporary file in the same folder (its space
reserved first) and renamed onto the target, so that a reader never sees a half-written
file and a full disk is an OSError, never a crash. Nothing that is not a regular file is
ever replaced: a folder, a FIFO, a device or a symbolic link is refused
(:class:`OutputError`); links in the folders on the way are followed only where they and
their folders belong to the caller or root; a replaced file keeps its mode and owner. One process writes an output at a time: its
advisory lock (:func:`output_lock`) refuses a second. :func:`write_fallback` keeps a
result that could not be written where asked, under a name no other user can predict.
:func:`check_output` runs the same checks, and a probe of the folder's writability,
before any work is done, so a command refuses a bad ``--out`` before it computes.
:func:`load_params` reads
``ChainParams`` fields from a TOML file (top-level keys, the paper's symbols) and names
any unknown key; :func:`read_config` reads at most :data:`MAX_CONFIG_BYTES` from a regular
file.
"""

from __future__ import annotations

import errno
import faulthandler
import fcntl
import gc
import math
import os
import pwd
import shlex
import signal
import stat
import sys
import tempfile
import time
import tomllib
from collections.abc import Iterator, Mapping
from contextlib import contextmanager
from datetime import UTC, datetime
from io import BytesIO
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from .errors import CosseratChainError
from .inputs import check_finite, check_run, params_from_mapping, stored_params
from .params import ChainParams
from .state import ROWS

if TYPE_CHECKING:  # xarray is imported where a file is read or written: the command line starts without it
    import xarray as xr

    from .loads import Loads

#: Largest configuration or study spec read (bytes): a TOML file of parameters is a few
#: hundred bytes; this bounds what a mistyped path (a log, /dev/zero) can make us read.
MAX_CONFIG_BYTES = 1 << 20

#: Picture formats the package writes (matplotlib's, chosen by the file's suffix).
FIGURE_FORMATS = (".png", ".svg", ".pdf")

#: The marker in the names of temporary files, ``.NAME.tmp<pid>-<random><suffix>``: the
#: writer's process id lets a later write to the same place remove those whose writer died.
_TMP_MARK = ".tmp"


class OutputError(CosseratChainError, ValueError):
    """An output path that cannot or must not be written (named with its option in the message)."""


def _kind(mode: int) -> str:
    """What a non-regular file is, in words."""
    for test, name in (
        (stat.S_ISDIR, "a folder"),
        (stat.S_ISFIFO, "a FIFO"),
        (stat.S_ISCHR, "a character device"),
        (stat.S_ISBLK, "a block device"),
        (stat.S_ISSOCK, "a socket"),
    ):
        if test(mode):
            return name
    return "not a regular file"


def _trusted(uid: int) -> bool:
    """Whether ``uid`` is the caller or root: the only owners whose links are followed and whose files are replaced in shared folders."""
    return uid in (os.geteuid(), 0)


def _owner(uid: int) -> str:
    """A user in words: name and uid."""
    try:
        return f"{pwd.getpwuid(uid).pw_name} (uid {uid})"
    except KeyError:
        return f"uid {uid}"


def _shared(info: os.stat_result) -> bool:
    """Whether a folder lets every user create entries in it (world-writable, as /tmp)."""
    return bool(info.st_mode & stat.S_IWOTH)


def _check_link(link: Path, info: os.stat_result, label: str, path: Path) -> None:
    """Refuse to follow ``link`` unless it and the folder holding it belong to the caller (or root) and no other user can swap it.

    The test is made here, in user space, because a write resolves the link before it
    renames onto the target: the kernel's protected-symlinks setting never sees it.
    """
    folder = os.stat(link.parent)
    swappable = _shared(folder) and not folder.st_mode & stat.S_ISVTX
    if _trusted(info.st_uid) and _trusted(folder.st_uid) and not swappable:
        return
    where = f"the shared folder {str(link.parent)!r}" if _shared(folder) else f"{str(link.parent)!r} of {_owner(folder.st_uid)}"
    raise OutputError(
        f"{label} {str(path)!r}: {str(link)!r} is a symbolic link of {_owner(info.st_uid)} in {where}: refusing to write "
        "through a link another user controls; give the path it points to if that is the file meant"
    )


#: Most symbolic links followed in one path, the kernel's limit: a loop of links is refused.
_MAX_LINKS = 40


def _resolve(path: Path, label: str, *, through_last: bool = True) -> Path:
    """``path`` made absolute with its symbolic links followed, as the kernel does, through trusted links only (:func:`_check_link`).

    With ``through_last`` false a link in the last place (the file itself, not a folder on
    its way) is refused: writing through it would replace a file the package did not make.
    """
    parts = list(path.parts) if path.is_absolute() else [*Path.cwd().parts, *path.parts]
    current, rest, followed = Path(parts[0]), parts[1:], 0
    while rest:
        part = rest.pop(0)
        if part == "..":
            current = current.parent
            continue
        candidate = current / part
        try:
            info = os.lstat(candidate)
        except OSError:  # missing (created by the write) or under a file (refused by the caller)
            return Path(os.path.normpath(candidate.joinpath(*rest)))
        if not stat.S_ISLNK(info.st_mode):
            current = candidate
            continue
        _check_link(candidate, info, label, path)
        if not rest and not through_last:
            raise OutputError(
                f"{label} {str(path)!r} is a symbolic link to {os.readlink(candidate)!r}: refusing to replace the file it "
                "points to; give that path itself if it is the file meant, or remove the link"
            )
        followed += 1
        if followed > _MAX_LINKS:
            raise OutputError(f"{label} {str(path)!r}: more than {_MAX_LINKS} symbolic links (a loop of links?)")
        link = Path(os.readlink(candidate))
        if link.is_absolute():
            current = Path(link.anchor)
        rest = [*(link.parts[1:] if link.is_absolute() else link.parts), *rest]
    return current


def _target(path: Path, label: str) -> Path:
    """Where a write to ``path`` lands: through trusted symbolic links, and only onto a regular file the caller may replace, or nothing."""
    if str(path) == "":
        raise OutputError(f"{label} is empty: give a file name")
    target = _resolve(path, label, through_last=False)
    try:
        info = os.lstat(target)
    except FileNotFoundError:
        return target
    except NotADirectoryError:
        raise OutputError(f"{label} {str(path)!r}: {str(_existing_folder(target.parent, label, path))!r} is not a folder") from None
    except OSError as err:
        raise OutputError(f"{label} {str(path)!r} cannot be examined: {err.strerror}") from None
    if stat.S_ISDIR(info.st_mode):
        raise OutputError(f"{label} {str(path)!r} is a folder: give a file name inside it")
    if not stat.S_ISREG(info.st_mode):
        raise OutputError(f"{label} {str(path)!r} exists and is {_kind(info.st_mode)}, not a regular file: refusing to replace it")
    if not _trusted(info.st_uid):
        folder = os.stat(target.parent)
        if _shared(folder) and folder.st_mode & stat.S_ISVTX:
            raise OutputError(
                f"{label} {str(path)!r} is a file of {_owner(info.st_uid)} in the shared folder {str(target.parent)!r}: "
                "refusing to replace another user's file there; choose another name"
            )
    return target


def _existing_folder(folder: Path, label: str, path: Path) -> Path:
    """The nearest existing ancestor of ``folder``; it must be a folder."""
    probe = folder
    while not probe.exists() and probe != probe.parent:
        probe = probe.parent
    if not probe.is_dir():
        raise OutputError(f"{label} {str(path)!r}: {str(probe)!r} is not a folder")
    return probe


def _probe_writable(folder: Path, label: str, path: Path) -> None:
    """Create and remove a file in ``folder``: the only test of writability that root, read-only mounts and /proc all answer truly."""
    try:
        fd, name = tempfile.mkstemp(prefix=f".probe{_TMP_MARK}{os.getpid()}-", dir=folder)
    except OSError as err:
        raise OutputError(f"{label} {str(path)!r}: cannot write in {str(folder)!r} ({err.strerror or err})") from None
    os.close(fd)
    os.unlink(name)


def check_output(
    path: str | Path,
    option: str = "--out",
    *,
    formats: tuple[str, ...] | None = None,
    inputs: Mapping[str, str | Path | None] | None = None,
    folder: bool = False,
) -> Path:
    """Check, before any work, that ``path`` can be written as an output; returns it.

    Parameters
    ----------
    path : path
        The output file (or folder, with ``folder``).
    option : str
        The option that named it, for the messages (``--out``, ``--plot``).
    formats : tuple of str, optional
        Allowed suffixes (lower case, with the dot).
    inputs : mapping, optional
        The command's input files by option (``{"--config": path}``); the output must be none of them.
    folder : bool
        ``path`` is a folder to write files into (created if missing).

    Raises
    ------
    OutputError
        Naming the option and the path: an empty path, an unknown format, a folder
        where a file is expected (or the reverse), a target that exists and is not a
        regular file (a FIFO, a device), a path under a regular file, a place where
        nothing can be written, one of the command's inputs, a symbolic link another
        user controls (naming the link and its owner) or another user's file in a
        shared folder.
    """
    path = Path(path)
    if str(path) == "":
        raise OutputError(f"{option} is empty: give a {'folder' if folder else 'file'} name")
    if formats is not None and path.suffix.lower() not in formats:
        raise OutputError(f"unknown format {path.suffix or '(none)'!r} of {option} {str(path)!r}; allowed: {', '.join(formats)}")
    if folder:
        target = _resolve(path, option)
        if target.exists() and not target.is_dir():
            raise OutputError(f"{option} {str(path)!r} exists and is not a folder")
        _probe_writable(_existing_folder(target, option, path), option, path)
        return path
    target = _target(path, f"{option}")
    for name, other in (inputs or {}).items():
        if other is not None and str(other) != "" and Path(os.path.realpath(other)) == target:
            raise OutputError(f"{option} {str(path)!r} is the {name} file: refusing to overwrite an input")
    _probe_writable(_existing_folder(target.parent, option, path), option, path)
    return path


def _remove_stale(target: Path) -> None:
    """Remove the caller's temporary files left beside ``target`` by writers that were killed (their process is gone)."""
    prefix = f".{target.name}{_TMP_MARK}"
    try:
        entries = list(target.parent.iterdir())
    except OSError:
        return
    for entry in entries:
        name = entry.name
        if not name.startswith(prefix):
            continue
        pid = name[len(prefix) :].split("-", 1)[0]
        if not pid.isdigit() or _alive(int(pid)):
            continue
        try:
            info = entry.lstat()
            if stat.S_ISREG(info.st_mode) and info.st_uid == os.geteuid():
                entry.unlink()
        except OSError:
            pass


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return True


class _Held:
    """A lock file this process holds (open, ``flock``-ed), how many writers of this process use it, and the folders made for it."""

    def __init__(self, fd: int, made: list[Path]):
        self.fd, self.count, self.made = fd, 1, made


def _remove_empty(folders: list[Path]) -> None:
    """Remove the folders a lock made (deepest first) that nothing was written into: a refused run leaves no trace."""
    for folder in folders:
        try:
            folder.rmdir()
        except OSError:
            return


#: The lock files this process holds, by path: a writer nested in a command that holds its output's lock shares it.
_HELD: dict[str, _Held] = {}


def _lock_path(target: Path) -> Path:
    return target.with_name(f".{target.name}.lock")


def _holder(fd: int) -> str:
    """The process named in a held lock file, with its command line where it can be read."""
    try:
        pid = os.pread(fd, 32, 0).decode("ascii", "replace").strip()
    except OSError:
        pid = ""
    if not pid.isdigit():
        return "another process"
    try:
        command = Path(f"/proc/{pid}/cmdline").read_bytes().replace(b"\0", b" ").decode(errors="replace").strip()
    except OSError:
        command = ""
    return f"process {pid}" + (f" ({command[:160]})" if command else "")


def _acquire(target: Path, label: str, path: Path) -> str:
    """Take the lock of ``target`` (a file ``.NAME.lock`` beside it, ``flock``-ed and holding this process's id); returns its key.

    Raises
    ------
    OutputError
        If another process holds it (naming that process), or the lock file cannot be
        made or is not one this process may use (a link, a file of another user).
    """
    lock = _lock_path(target)
    key = str(lock)
    if key in _HELD:
        _HELD[key].count += 1
        return key
    made = [folder for folder in [lock.parent, *lock.parent.parents] if not folder.exists()]
    try:
        lock.parent.mkdir(parents=True, exist_ok=True)
    except (FileExistsError, NotADirectoryError):
        raise OutputError(f"{label} {str(path)!r}: {str(_existing_folder(lock.parent, label, path))!r} is not a folder") from None
    except OSError as err:
        raise OutputError(f"{label} {str(path)!r}: cannot make the folder {str(lock.parent)!r} ({err.strerror})") from None
    try:
        fd = _lock_file(lock, label, path)
    except BaseException:
        _remove_empty(made)
        raise
    _HELD[key] = _Held(fd, made)
    return key


def _lock_file(lock: Path, label: str, path: Path) -> int:
    """Open, check and ``flock`` the lock file ``lock``, writing this process's id into it; returns its descriptor."""
    while True:
        try:
            fd = os.open(lock, os.O_RDWR | os.O_CREAT | os.O_NOFOLLOW | os.O_CLOEXEC, 0o666)
        except OSError as err:
            raise OutputError(f"{label} {str(path)!r}: cannot open its lock file {str(lock)!r} ({err.strerror})") from None
        info = os.fstat(fd)
        if not stat.S_ISREG(info.st_mode) or info.st_uid != os.geteuid() or info.st_nlink != 1:
            os.close(fd)
            raise OutputError(
                f"{label} {str(path)!r}: its lock file {str(lock)!r} is not a plain file of this user (it belongs to "
                f"{_owner(info.st_uid)}): if no run is writing {str(path)!r}, remove it"
            )
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError:
            holder = _holder(fd)
            os.close(fd)
            raise OutputError(
                f"{label} {str(path)!r} is being written by {holder}: wait for it to finish or choose another file"
            ) from None
        try:
            now = os.lstat(lock)
        except FileNotFoundError:
            now = None
        if now is not None and (now.st_dev, now.st_ino) == (info.st_dev, info.st_ino):
            break
        os.close(fd)  # its last holder removed the file between our open and our lock: take the new one
    try:
        os.ftruncate(fd, 0)
        os.pwrite(fd, f"{os.getpid()}\n".encode(), 0)
    except OSError:  # a full disk: the lock holds all the same, only a refused run cannot name this process
        pass
    return fd


def _release(key: str) -> None:
    """Give back one use of a lock; the last removes the lock file (still the one locked) and unlocks it."""
    held = _HELD[key]
    held.count -= 1
    if held.count:
        return
    del _HELD[key]
    try:
        info, now = os.fstat(held.fd), os.lstat(key)
        if (now.st_dev, now.st_ino) == (info.st_dev, info.st_ino):
            os.unlink(key)
    except OSError:
        pass
    os.close(held.fd)
    _remove_empty(held.made)


@contextmanager
def output_lock(path: str | Path, label: str = "output", *, folder: bool = False) -> Iterator[Path]:
    """Hold the advisory lock of the output ``path`` (a file, or with ``folder`` a folder) for the block; yields where it lands.

    The lock is ``fcntl.flock`` on ``.NAME.lock`` beside the output (the folder is made if
    missing), holding this process's id: the kernel releases it when its process ends,
    however it ends, so a lock left by a killed run never blocks the next. Within one
    process the lock is shared (a write inside a command that holds it goes on).

    Raises
    ------
    OutputError
        If another process holds the lock (naming its id and command line), or
        ``path`` is refused as :func:`check_output` refuses it.
    """
    path = Path(path)
    target = _resolve(path, label) if folder else _target(path, label)
    key = _acquire(target, label, path)
    try:
        yield target
    finally:
        _release(key)


def new_mode(folder: bool = False) -> int:
    """The mode of a new file (0666) or folder (0777) less the process's umask, as ``open`` and ``mkdir`` give them."""
    return (0o777 if folder else 0o666) & ~_umask()


def _umask() -> int:
    """The process's umask, read without changing it where Linux tells it (another thread may be creating files)."""
    try:
        for line in Path("/proc/self/status").read_text().splitlines():
            if line.startswith("Umask:"):
                return int(line.split()[1], 8)
    except (OSError, ValueError, IndexError):
        pass
    umask = os.umask(0o022)
    os.umask(umask)
    return umask


def _settle(fd: int, target: Path) -> None:
    """Give the new file the owner and mode of the file it replaces (a new file: 0666 less the umask), then flush it to the disk."""
    try:
        old = os.lstat(target)
    except FileNotFoundError:
        old = None
    if old is not None and stat.S_ISREG(old.st_mode):
        if (old.st_uid, old.st_gid) != (os.geteuid(), os.getegid()):
            try:
                os.fchown(fd, old.st_uid, old.st_gid)
            except PermissionError:  # not root: keep at least the group where the caller is in it
                try:
                    os.fchown(fd, -1, old.st_gid)
                except PermissionError:
                    pass
        os.fchmod(fd, stat.S_IMODE(old.st_mode) & 0o777)
    else:
        os.fchmod(fd, new_mode())
    os.fsync(fd)


@contextmanager
def _replacing(path: str | Path) -> Iterator[tuple[int, Path]]:
    """A new temporary file beside ``path`` (its descriptor and name), renamed onto the target if the block succeeds.

    The output's lock is held throughout (:func:`output_lock`).
    """
    with output_lock(path) as target:
        _remove_stale(target)
        fd, name = tempfile.mkstemp(prefix=f".{target.name}{_TMP_MARK}{os.getpid()}-", suffix=target.suffix, dir=target.parent)
        tmp = Path(name)
        ours = os.fstat(fd)
        try:
            yield fd, tmp
            _settle(fd, target)
            # The name must still be our file, and the target a regular file or nothing (not a FIFO made meanwhile).
            now = os.lstat(tmp)
            if (now.st_dev, now.st_ino) != (ours.st_dev, ours.st_ino):
                raise OutputError(f"output {str(path)!r}: its temporary file {name!r} was replaced while it was written")
            _target(target, "output")
            os.replace(tmp, target)
        finally:
            os.close(fd)
            try:
                now = os.lstat(tmp)
                if (now.st_dev, now.st_ino) == (ours.st_dev, ours.st_ino):
                    tmp.unlink()
            except OSError:
                pass


@contextmanager
def atomic_path(path: str | Path) -> Iterator[Path]:
    """A temporary file beside ``path`` (same extension), renamed onto it if the block succeeds.

    A reader never sees a half-written file, and an interrupted write leaves none
    behind (a killed one is removed by the next write to the same place). The output's
    advisory lock is held while it is written (:func:`output_lock`). A replaced file keeps
    its mode and owner; a new one gets 0666 less the umask. A symbolic link at ``path`` is
    refused (the file it points to is not the package's to replace); links among the
    folders on the way are followed only where they and their folders are the caller's or
    root's. Missing folders are created.

    Raises
    ------
    OutputError
        If ``path`` is empty, a folder, a symbolic link, or exists and is not a regular file (a
        FIFO, a device): such a target is never replaced; a link another user controls; another user's file in
        a shared folder; an output another process is writing.
    """
    with _replacing(path) as (_, tmp):
        yield tmp


def _write_all(fd: int, data: bytes | memoryview) -> None:
    """Write ``data`` at the start of ``fd``, its space reserved first: a full disk or quota raises OSError before a byte is written."""
    view = memoryview(data).cast("B")
    try:
        os.posix_fallocate(fd, 0, max(len(view), 1))
    except OSError as err:
        if err.errno not in (errno.EOPNOTSUPP, errno.EINVAL, errno.ENOSYS):
            raise
    except AttributeError:  # no posix_fallocate on this system: the writes below raise instead
        pass
    written = 0
    while written < len(view):
        written += os.pwrite(fd, view[written:], written)
    os.ftruncate(fd, len(view))


def write_bytes(data: bytes | memoryview, path: str | Path) -> Path:
    """Write ``data`` to ``path`` atomically (:func:`atomic_path`); returns the path.

    Raises
    ------
    OSError
        If the disk is full, a quota is exceeded or the device fails: the target is untouched.
    OutputError
        As :func:`atomic_path`.
    """
    with _replacing(path) as (fd, _):
        try:
            _write_all(fd, data)
        except OSError as err:  # named after the target, not the descriptor, for the messages
            raise OSError(err.errno, err.strerror, str(path)) from None
    return Path(path)


def write_fallback(data: bytes | memoryview, folder: str | Path, stem: str, suffix: str) -> Path:
    """Write ``data`` to a new file ``STEM.recovered-XXXXXXXX.SUFFIX`` in ``folder``; returns its path.

    The name's random part is chosen by :func:`tempfile.mkstemp`, which creates the file
    (``O_CREAT | O_EXCL``, mode 0600): no other user can predict the name or have a link
    waiting at it, and nobody else can read the result in a shared folder.

    Raises
    ------
    OSError
        If the file cannot be made or written (it is then removed).
    """
    fd, name = tempfile.mkstemp(prefix=f"{stem}.recovered-", suffix=suffix, dir=folder)
    try:
        _write_all(fd, data)
        os.fsync(fd)
    except BaseException:
        os.close(fd)
        os.unlink(name)
        raise
    os.close(fd)
    return Path(name)


#: The paper this package reproduces, for the files' ``references`` attribute.
REFERENCES = (
    "Vasiliev A. A. et al., Modeling of static deformations and dynamics of localized rotation in a chain of finite "
    "size particles; extending Vasiliev A. A. and Dmitriev S. V., Discrete and Multifield Models of a Cosserat Chain: "
    "One-Period and Two-Period Solutions, Russ. Phys. J. 59, 961 (2016)"
)

#: What 1 of each base quantity is. The model is dimensionless: it takes its units from its parameters.
SCALES = {
    "length": "the unit of the parameters h, a and b",
    "mass": "the unit of the parameter m",
    "stiffness": "the unit of the parameters E1 and E2",
    "time": "sqrt(mass / stiffness), the unit of sqrt(m / E1)",
    "energy": "stiffness x length^2, the unit of E1 h^2 and of a moment",
}

#: The CF versions every file declares: it uses nothing newer than CF-1.8 and meets the rules of both, so that
#: cfchecks (whose newest release knows CF up to 1.8) and compliance-checker (``cf:1.10``) each find their version.
CONVENTIONS = "CF-1.8 CF-1.10"

#: The name of the time axis in a file. compliance-checker asks a dimension named "time" for the standard name
#: "time", whose units are seconds from an epoch; CF itself standardizes no names. The model's time is a number,
#: so the file names its axis "t", the paper's symbol; :func:`read_dataset` names it "time" again.
FILE_TIME = "t"

#: What a text coordinate's name takes in a file (``model`` -> ``model_label``): a CF coordinate variable holds
#: numbers, so text naming a dimension's entries is a label (CF 6.1), an auxiliary coordinate of another name;
#: :func:`read_dataset` makes it the dimension's coordinate again.
LABEL_SUFFIX = "_label"

#: How the dimensionless model's units read (every file's ``units_convention`` attribute).
UNITS_CONVENTION = (
    "Every quantity is a number (units '1', angles 'rad'): the model is dimensionless and takes its units from its "
    "parameters. A variable's 'scale' attribute names the quantity it measures in them: "
    + "; ".join(f"{base}, {meaning}" for base, meaning in SCALES.items())
    + ". With the paper's chain (h = E1 = m = 1) lengths are in units of h, times in units of sqrt(m / E1) and "
    "energies and moments in units of E1 h^2."
)

#: Quantity and long name of every variable and coordinate the package writes, by name. The
#: quantity is a product of the base quantities of :data:`SCALES` (and rad), "1" for a pure
#: number; :func:`cf_attributes` turns it into CF units and a ``scale``.
VARIABLES: dict[str, tuple[str, str]] = {
    "u": ("length", "displacement u of a particle's centre along the chain"),
    "v": ("length", "displacement v of a particle's centre across the chain"),
    "phi": ("rad", "rotation angle phi of a particle"),
    "phi_winding": ("1", "whole turns of phi"),
    "phi_reduced": ("rad", "phi less its whole turns"),
    "u_dot": ("length / time", "velocity du/dt"),
    "v_dot": ("length / time", "velocity dv/dt"),
    "phi_dot": ("rad / time", "angular velocity dphi/dt"),
    "peak_spin": ("rad / time", "largest |dphi/dt| at a step boundary beyond the rotation tolerance (0: none)"),
    "force_u": ("energy / length", "force plus load on u"),
    "force_v": ("energy / length", "force plus load on v"),
    "force_phi": ("energy", "moment plus load on phi"),
    "time": ("time", "time"),
    "particle": ("1", "particle index k in -N..N"),
    "kinetic": ("energy", "kinetic energy K"),
    "potential": ("energy", "potential energy P"),
    "load_work": ("energy", "work W done by the loads since the start"),
    "dissipated": ("energy", "energy D dissipated by the viscous damping since the start"),
    "balance_error": ("energy", "energy balance residual K + P - W + D - (K0 + P0)"),
    "frame_step": ("1", "step of the stored frame"),
    "split_sums": ("energy", "load work and dissipated energy: at the split over threads, then per block (none on one thread)"),
    "moment": ("energy", "moment M on the loaded particle"),
    "phi0": ("rad", "rotation angle phi_0 of the loaded particle"),
    "point": ("1", "index of a point along the branch"),
    "state": ("1", "index of a kept state of a thinned branch (a long chain's: every 2^j-th point)"),
    "state_point": ("1", "the point along the branch whose state a kept state is"),
    "stable": ("1", "1 if the state is stable, 0 if not"),
    "critical_eigenvalue": ("stiffness", "lowest eigenvalue of the stiffness matrix"),
    "dynamically_stable": (
        "1",
        "1 if the damped dynamics linearised about the state have no unstable eigenvalue, 0 if they have, -1 not computed",
    ),
    "unstable_eigenvalues": ("1", "unstable eigenvalues of the damped dynamics at the state, a complex pair counted twice (-1: not computed)"),
    "unstable_pairs": ("1", "complex-conjugate pairs among the unstable eigenvalues of the damped dynamics (-1: not computed)"),
    "stiffness_index": ("1", "stiffness index: negative eigenvalues of K = -dF/dq, not unstable eigenvalues of the dynamics (-1: not computed)"),
    "hopf": ("1", "index of a Hopf point of the branch"),
    "hopf_moment": ("energy", "moment M at a Hopf point of the branch (a complex pair of the damped dynamics crosses the axis)"),
    "hopf_phi0": ("rad", "phi_0 of the loaded particle at a Hopf point of the branch"),
    "hopf_frequency": ("rad / time", "angular frequency omega of the pair crossing the axis at a Hopf point"),
    "hopf_located": ("1", "1 if the Hopf point was located to round-off, 0 if only bracketed by two traced points"),
    "M_c": ("energy", "critical moment M_c: onset of rotation under a slowly rising load (NaN: no fold)"),
    "phi0_at_fold": ("rad", "phi_0 of the loaded particle at the fold M_c"),
    "compliance": ("rad / energy", "compliance dphi_0/dM at rest"),
    "model": ("1", "model name"),
    "winding": ("1", "signed full turns trunc(theta / 2 pi) at the end"),
    "turns": ("1", "full turns of the loaded particle"),
    "unwrapped_angle": ("rad", "phi at the end minus phi at the start"),
    "max_abs_u": ("length", "largest |u| over the run"),
    "max_abs_v": ("length", "largest |v| over the run"),
    "max_abs_phi": ("rad", "largest |phi| over the run"),
    "last_turn_time": ("time", "time of the latest new full turn"),
    "mean_energy_share": ("1", "mean fraction of the chain's energy held by the particle"),
    "rotating": ("1", "1 if the particle still rotates at the end"),
    "recent_turn": ("1", "index of a recent turn (the latest ones kept)"),
    "angle_start": ("rad", "phi at the start of the diagnostics"),
    "angle": ("rad", "phi at the latest frame"),
    "energy_share_sum": ("1", "sum over the frames of the particle's share of the chain's energy"),
    "turn_times": ("time", "times of the latest turns of the loaded particle"),
    "t_start": ("time", "time at the start of the diagnostics"),
    "steps": ("1", "steps taken"),
    "participation_sum": ("1", "sum over the frames of the energy participation number"),
    "energy_steps": ("1", "frames summed in the energy shares"),
    "onset_load": ("energy", "first load of the upward relaxation sweep at which the loaded particle rotates (NaN: none)"),
    "stop_load": ("energy", "first load of the downward relaxation sweep at which rotation has stopped (NaN: none)"),
    "mean_angular_velocity": ("rad / time", "mean angular velocity of the loaded particle"),
    "period": ("time", "period T of the periodic orbit"),
    "max_multiplier": ("1", "largest modulus of a non-trivial Floquet multiplier"),
    "band_gap": ("1 / time", "width of the transverse-rotational band gap of the infinite linear chain (0: none)"),
    "done": ("1", "1 once the cell was computed (successfully or not)"),
    "error": ("1", "error message of a failed cell (empty if it succeeded)"),
    "load": ("energy", "moment M of the relaxation"),
    "angular_velocity": ("rad / time", "angular velocity of each particle at the end of the load step"),
    "status": ("1", "how the load step ended (static, rotating, not_converged, ...)"),
    "relax_time": ("time", "time the load step ran"),
    "step": ("1", "index of the load step"),
    "direction": ("1", "up or down: the sweep's direction at this step"),
    "multiplier": ("1", "index of a Floquet multiplier"),
    "multiplier_real": ("1", "real part of a Floquet multiplier"),
    "multiplier_imag": ("1", "imaginary part of a Floquet multiplier"),
    "branch_moment": ("energy", "moment M of the continued orbit"),
    "branch_period": ("time", "period T of the continued orbit"),
    "branch_mean_angular_velocity": ("rad / time", "mean angular velocity of the loaded particle on the continued orbit"),
    "branch_max_multiplier": ("1", "largest modulus of a non-trivial Floquet multiplier on the continued orbit"),
    "branch_stable": ("1", "1 if the continued orbit is stable"),
    "branch_trivial_multiplier_error": ("1", "distance to 1 of the trivial Floquet multiplier of the continued orbit (collocation)"),
    "static_fold": ("energy", "M_c, the end of the static branch from rest"),
    "rotation_stops": ("energy", "moment at which a falling load stops the rotation"),
    "rotation_stops_uncertainty": ("energy", "accuracy of a homoclinic rotation_stops, solved or fitted (method says which; NaN: another computed point)"),
    "end": ("1", "how the rotation stops"),
    "hysteresis": ("1", "1: open loop (rotation_stops < static_fold), 0: closed, -1: unknown"),
    "rotation_starts": ("1", "how a rising load starts the rotation at M_c: snic, jump or unknown"),
    "method": ("1", "how rotation_stops was found: followed, located, solved, fitted or one_parameter"),
    "below_edge": ("1", "what a run just below a fold of cycles does: rest, rotating, not_converged or not_checked"),
    "particle_turns": ("1", "turns of each particle's angle per period"),
    "moment_scale": ("energy", "E1 h^2, the unit of the dimensionless moment M / (E1 h^2)"),
    "E1": ("stiffness", "stiffness E1 of a horizontal link"),
    "E2": ("stiffness", "stiffness E2 of a diagonal link"),
    "h": ("length", "distance h between particle centres"),
    "a": ("length", "half-width a of a particle"),
    "b": ("length", "half-height b of a particle"),
    "m": ("mass", "mass m of a particle"),
    "j": ("mass length^2", "moment of inertia j of a particle"),
    "gamma_u": ("mass / time", "viscous coefficient of u"),
    "gamma_v": ("mass / time", "viscous coefficient of v"),
    "gamma_phi": ("mass length^2 / time", "viscous coefficient of phi"),
    "N": ("1", "half the number of particles (particles -N..N)"),
    "discrete": ("rad / energy", "compliance of the loaded particle, discrete linear chain (iii)"),
    "timoshenko": ("rad / energy", "compliance of the loaded particle, Timoshenko beam"),
    "nodal": ("rad / energy", "compliance of the loaded particle, beam with the nodal shear compliance"),
    "paper": ("rad / energy", "compliance phi(0)/M of the paper's eq. (11)"),
    "timoshenko_error": ("1", "(timoshenko - discrete) / discrete"),
    "paper_error": ("1", "(paper - discrete) / discrete"),
    "discrete_error": ("1", "estimated relative error of the discrete compliance"),
    "bending_chain_moment": ("energy", "end moment holding the end angle, model (i)"),
    "bending_beam_moment": ("energy", "end moment holding the end angle, exact beam"),
    "bending_moment_error": ("1", "(beam - chain) / chain of the end moment"),
    "bending_tip_error": ("1", "distance of the chain's free end from the beam's, over 2L"),
    "bending_direct_spread": ("1", "whole chain's moment against the per-bond one, relative"),
}

#: How a user system's file reads (``--system``): its quantities are in the system's own units, not the chain's.
SYSTEM_UNITS_CONVENTION = (
    "Every quantity is a number (units '1') in the units of the system's own parameters and equations; the global "
    "attribute 'angles' names the generalized coordinates that are angles (in radians)."
)

#: Long names of the variables of a user system's file (``simulate``, ``orbit`` and ``diagram --system``), for
#: those its producer did not name.
SYSTEM_VARIABLES = {
    "time": "time",
    "coordinate": "name of a generalized coordinate of the system",
    "q": "generalized coordinates",
    "velocity": "generalized velocities dq/dt",
    "potential_energy": "potential energy of the system",
    "kinetic_energy": "kinetic energy of the system",
    "q0": "start of the orbit on its phase plane: coordinates",
    "v0": "start of the orbit on its phase plane: velocities",
    "turns": "turns of each coordinate per period",
    "multiplier_real": "real part of a Floquet multiplier",
    "multiplier_imag": "imaginary part of a Floquet multiplier",
    "branch_value": "the continued parameter",
    "branch_period": "period T of the continued orbit",
    "branch_max_multiplier": "largest modulus of a non-trivial Floquet multiplier on the continued orbit",
    "branch_trivial_multiplier_error": "distance to 1 of the trivial Floquet multiplier of the continued orbit (collocation)",
    "value": "the varied parameter",
    "starts": "drive where the equilibrium folds (rotation starts)",
    "stops": "drive where the rotation ends (NaN: not found)",
    "stops_uncertainty": "uncertainty of stops: the last step of the continuation towards the rotation's end",
    "open": "1 if the hysteresis loop is open (the rotation stops below where it starts), 0 if not",
    "end": "how the continued rotation ended",
}

#: Titles of the files by their ``experiment`` attribute (a simulation has none).
TITLES = {
    None: "Damped simulation of a discrete Cosserat chain under loads",
    "simulation_checkpoint": "Checkpoint of a damped simulation of a discrete Cosserat chain (simulate --checkpoint-every)",
    "critical_point": "Static branch, folds and critical moment of a discrete Cosserat chain",
    "relaxation_sweep": "Relaxation protocol (the paper's Fig. 2) of a discrete Cosserat chain",
    "localization_run": "Localized rotation of one particle of a discrete Cosserat chain",
    "periodic_orbit": "Rotating state of a discrete Cosserat chain as a periodic orbit",
    "rotation_characteristic": "Rotation characteristic of a discrete Cosserat chain",
    "parameter_study": "Parameter study of a discrete Cosserat chain",
    "state_diagram": "Both edges of the hysteresis loop of a discrete Cosserat chain against one of its parameters",
}

#: The compliances of a beam convergence table: phi/M under a moment (as :data:`VARIABLES` says), v/F under a force.
_COMPLIANCES = ("discrete", "timoshenko", "nodal", "paper")

#: Prefixes of variables that hold a quantity of :data:`VARIABLES` at one moment, and what they add to its long name.
_PREFIXES = {"final_": "at the end of the run", "diag_": "state of the streaming diagnostics, for resuming"}


def cf_attributes(quantity: str, long_name: str) -> dict[str, str]:
    """CF attributes of a variable measuring ``quantity`` (a product of :data:`SCALES`' base quantities, rad or 1).

    The units are UDUNITS strings: "rad" where the quantity is an angle or an angle per
    something (the other factors are numbers), "1" otherwise; the ``scale`` attribute says
    what 1 of the quantity is, with the meaning of each base quantity in it.

    Raises
    ------
    ValueError
        If ``quantity`` names a factor that is none of the base quantities, rad or 1.
    """
    factors = [word for word in quantity.replace("/", " ").replace("^2", " ").split() if word != "1"]
    unknown = [word for word in factors if word != "rad" and word not in SCALES]
    if unknown:
        raise ValueError(f"quantity {quantity!r} has the factor(s) {unknown}; allowed: rad, 1, {', '.join(SCALES)}")
    attrs = {"units": "rad" if quantity.split()[0] == "rad" else "1", "long_name": long_name}
    bases = [base for base in SCALES if base in factors]
    if quantity in SCALES:
        attrs["scale"] = f"{quantity}: {SCALES[quantity]}"
    elif bases:
        attrs["scale"] = f"{quantity}, where " + "; ".join(f"{base} is {SCALES[base]}" for base in bases)
    return attrs


def _describe_variable(name: str, dataset: xr.Dataset) -> tuple[str, str] | None:
    """Quantity and long name of a variable of ``dataset``: by name, prefix (final_u, diag_angle) or, for a diagram's values, its field.

    The long names that depend on the file say what holds for it: the particle index
    names the chain's ends, the potential says NaN (and the lowest eigenvalue what matrix
    it is of) only for the non-conservative sine model, and a beam table's compliances are
    phi/M or v/F as its load is a moment or a force.
    """
    if name == "value" and dataset.attrs.get("parameter") in VARIABLES:
        quantity, what = VARIABLES[dataset.attrs["parameter"]]
        return quantity, f"the varied field {dataset.attrs['parameter']}: {what}"
    if name == "particle" and "params_json" in dataset.attrs:
        try:
            ends = params_of(dataset).describe_ends()
        except ValueError:
            return VARIABLES[name]
        return "1", f"{VARIABLES[name][1]} ({ends})"
    if name == "potential" and "sine" in _models(dataset):
        return "energy", f"{VARIABLES[name][1]} (NaN for the non-conservative sine model)"
    if name == "critical_eigenvalue" and "sine" in _models(dataset):
        return "stiffness", f"{VARIABLES[name][1]} (for the sine model: of the symmetric matrix similar to its Jacobian)"
    if name in _COMPLIANCES and dataset.attrs.get("load") == "force":
        return "length^2 / energy", VARIABLES[name][1].replace("compliance", "compliance v/F", 1)
    if name in VARIABLES:
        return VARIABLES[name]
    for prefix, what in _PREFIXES.items():
        if name.startswith(prefix) and name[len(prefix) :] in VARIABLES:
            quantity, base = VARIABLES[name[len(prefix) :]]
            return quantity, f"{base}, {what}"
    return None


def _models(dataset: xr.Dataset) -> list[str]:
    """The models of a result: its ``model`` attribute, or the ``model`` coordinate of results stacked by model."""
    if "model" in dataset.coords:
        return [str(name) for name in np.atleast_1d(dataset["model"].values)]
    return [str(dataset.attrs.get("model", ""))]


def _command() -> str:
    """The command line of this process, its program named without the folder it lies in (no machine paths in files)."""
    program = Path(sys.argv[0]).name if sys.argv else ""
    if program == "__main__.py":
        program = f"python -m {Path(sys.argv[0]).parent.name}"
    elif program in ("", "-", "-c"):
        program = "python"
    return " ".join([program, *map(shlex.quote, sys.argv[1:])])


def describe(dataset: xr.Dataset) -> xr.Dataset:
    """The dataset with the CF-1.10 attributes every file of the package carries (a new Dataset).

    Global: ``Conventions`` (:data:`CONVENTIONS`), ``title``, ``history`` (time, version and
    the command, its program named without its folder), ``source``, ``references`` (the
    paper; none for a user system's file) and ``units_convention``. Every variable and
    coordinate of :data:`VARIABLES` (also with a ``final_`` or ``diag_`` prefix): ``units``
    ("1" or "rad") and ``scale`` (:func:`cf_attributes`), which replace any the producer set,
    and a ``long_name`` where the producer set none. A user system's file (``experiment``
    ``system_*``) is in the system's own units: its numbers get ``units = "1"`` and the long
    names of :data:`SYSTEM_VARIABLES` where the producer set none. Coordinates get no fill value (CF forbids one); text is
    written as character arrays, and a text coordinate of more than one dimension (results
    stacked by :func:`stack_models`) as a data variable, since a CF label has one.
    """
    from ._version import __version__

    dataset = dataset.copy()
    stamp = f"{datetime.now(UTC).isoformat(timespec='seconds')} cosserat-chain {__version__}: {_command()}"
    previous = dataset.attrs.get("history")
    system = str(dataset.attrs.get("experiment", "")).startswith("system_")
    dataset.attrs.update(
        {
            "Conventions": CONVENTIONS,
            "title": dataset.attrs.get("title") or TITLES.get(dataset.attrs.get("experiment"), "Result of cosserat-chain"),
            "history": stamp if not previous else f"{previous}\n{stamp}",
            "source": f"cosserat-chain {__version__}",
            "units_convention": SYSTEM_UNITS_CONVENTION if system else UNITS_CONVENTION,
        }
    )
    if system:  # a user's system is not the paper's chain
        dataset.attrs.pop("references", None)
    else:
        dataset.attrs["references"] = REFERENCES
    # A label (a text coordinate) has one dimension in CF: one of stacked results becomes a variable.
    labels = [name for name in dataset.coords if name not in dataset.indexes and dataset[name].ndim > 1 and dataset[name].dtype.kind in "USO"]
    dataset = dataset.reset_coords(labels)
    for name, variable in dataset.variables.items():
        if system:
            variable.attrs.setdefault("long_name", SYSTEM_VARIABLES.get(str(name), str(name)))
            if variable.dtype.kind in "fcbiu":
                variable.attrs["units"] = "1"
            described = None
        else:
            described = _describe_variable(str(name), dataset)
        if described is not None:
            attrs = cf_attributes(*described)
            variable.attrs.pop("scale", None)
            variable.attrs.update({key: value for key, value in attrs.items() if key != "long_name"})
            variable.attrs.setdefault("long_name", attrs["long_name"])
        if name in dataset.coords:
            variable.encoding["_FillValue"] = None
        if variable.dtype.kind in "US" or (name not in dataset.indexes and _text(variable)):
            # Character arrays, which every CF version and reader knows (the netCDF-4 string type is CF-1.9's).
            variable.encoding["dtype"] = "S1"
    return dataset


def _text(variable: xr.Variable) -> bool:
    """Whether an object array is text, its gaps (NaN or None, where results of different lengths were stacked) made empty strings."""
    if variable.dtype.kind != "O":
        return False
    flat = variable.values.ravel()
    text = np.array([isinstance(x, str) for x in flat], dtype=bool)
    gaps = np.array([x is None or (isinstance(x, float) and math.isnan(x)) for x in flat], dtype=bool)
    if not text.any() or not np.all(text | gaps):
        return False
    variable.values = np.where(gaps, "", flat).astype(object).reshape(variable.shape)
    return True


def netcdf_image(dataset: xr.Dataset) -> memoryview:
    """The bytes of the NetCDF file :func:`write_dataset` writes for ``dataset``, made in memory.

    The HDF5 library aborts the process when a write to a full disk fails under it, so
    it never writes to a disk here: the file is made in memory and written by
    :func:`write_bytes`, whose failures are Python errors. Attribute values that are
    subclasses of ``str`` (a :class:`~cosserat_chain.status.Status`) are written as plain
    strings: h5netcdf finds no conversion for them. Booleans (such as ``param_periodic``)
    are written as 0 or 1: NetCDF has no boolean type (``params_json`` keeps them as booleans).
    The time axis is named :data:`FILE_TIME` in the file, and a text coordinate (the models
    of stacked results, a system's coordinates) is a label named with :data:`LABEL_SUFFIX`.
    64-bit integers that fit are written as 32-bit ones (CF-1.8 has no 64-bit type).
    """
    dataset = describe(dataset)
    if "time" in dataset.dims and FILE_TIME not in dataset.variables:
        dataset = dataset.rename({"time": FILE_TIME})
    labels = {
        str(name): f"{name}{LABEL_SUFFIX}"
        for name in dataset.indexes
        if dataset[name].dtype.kind in "USO" and f"{name}{LABEL_SUFFIX}" not in dataset.variables
    }
    if labels:
        dataset = dataset.reset_index(list(labels)).rename_vars(labels)
        for label in labels.values():
            dataset[label].encoding["dtype"] = "S1"
    # CF-1.8, which every file declares (CONVENTIONS), has no 64-bit integers (compliance-checker's cf:1.8 refused
    # ``particle`` and ``phi_winding``): whole numbers that fit are written as 32-bit ones.
    wide = [name for name, variable in dataset.variables.items() if variable.dtype == np.int64 and _fits_int32(variable.values)]
    if wide:
        dataset = dataset.copy()
        for name in wide:
            dataset.variables[name].encoding["dtype"] = "int32"
    for attrs in [dataset.attrs, *(variable.attrs for variable in dataset.variables.values())]:
        attrs.update({key: str(value) for key, value in attrs.items() if isinstance(value, str) and type(value) is not str})
        attrs.update({key: int(value) for key, value in attrs.items() if isinstance(value, (bool, np.bool_))})
    return dataset.to_netcdf(engine="h5netcdf")


def _fits_int32(values: np.ndarray) -> bool:
    """Whether every value of the integer array lies in the range of a 32-bit integer."""
    limits = np.iinfo(np.int32)
    return values.size == 0 or (int(values.min()) >= limits.min and int(values.max()) <= limits.max)


def write_dataset(dataset: xr.Dataset, path: str | Path) -> Path:
    """Write ``dataset`` to NetCDF at ``path`` atomically, CF-described (:func:`describe`); returns the path.

    The file is made in memory (:func:`netcdf_image`) and written by :func:`write_bytes`:
    a full disk, a quota or an I/O error raises OSError and leaves the target as it was.
    """
    return write_bytes(netcdf_image(dataset), path)


def write_text(text: str, path: str | Path) -> Path:
    """Write ``text`` (UTF-8) to ``path`` atomically (:func:`write_bytes`); returns the path."""
    return write_bytes(text.encode("utf-8"), path)


def write_figure(figure: Any, path: str | Path, **savefig: Any) -> Path:
    """Write a matplotlib figure to ``path`` atomically (:func:`write_bytes`), in the format its suffix names; returns the path."""
    path = Path(path)
    buffer = BytesIO()
    figure.savefig(buffer, format=path.suffix.lstrip(".").lower() or None, **savefig)
    return write_bytes(buffer.getbuffer(), path)


def stack_models(datasets: dict[str, xr.Dataset]) -> xr.Dataset:
    """One Dataset with a ``model`` dimension from per-model results of the same experiment.

    Dimensions of different lengths (e.g. the points of each model's branch) are
    padded with NaN; attributes that differ between models (the model's name and
    equation) are dropped, and the names are the ``model`` coordinate.
    """
    import xarray as xr

    if len(datasets) == 1:
        return next(iter(datasets.values()))
    stacked = xr.concat(list(datasets.values()), dim="model", join="outer", combine_attrs="drop_conflicts")
    return stacked.assign_coords(model=list(datasets))


#: Seconds a child process may take to open a file's structure before the file is called damaged:
#: the HDF5 library loops for ever on some damaged dimension lists (found by the fuzz test), in C,
#: where no signal handler runs, and may crash on others.
READ_PROBE_SECONDS = 30.0


def _probe_structure(path: Path) -> str | None:
    """Open ``path``'s structure in a forked child: why it hung or crashed there, or None (it opened, or met an error).

    An error the child meets is met again, and reported in its own words, by the caller's
    open; only what cannot be caught in this process, a hang or a crash, is told here.
    """
    if not hasattr(os, "fork"):
        return None
    import xarray as xr

    pid = os.fork()
    if pid == 0:  # the child: never returns into the caller's code
        code = 1
        try:
            os.dup2(os.open(os.devnull, os.O_WRONLY), 2)  # h5netcdf's destructors complain on damaged files
            faulthandler.disable()  # a crash here is the parent's finding, not a report to print
            with xr.open_dataset(path, engine="h5netcdf"):
                code = 0
        finally:
            os._exit(code)
    deadline = time.monotonic() + READ_PROBE_SECONDS
    pause = 0.001
    while True:
        done, status = os.waitpid(pid, os.WNOHANG)
        if done:
            break
        if time.monotonic() > deadline:
            os.kill(pid, signal.SIGKILL)
            os.waitpid(pid, 0)
            return f"opening its structure did not finish within {READ_PROBE_SECONDS:g} s (a damaged HDF5 file)"
        time.sleep(pause)
        pause = min(2 * pause, 0.05)
    if os.WIFSIGNALED(status):
        return f"opening its structure crashed the HDF5 reader (signal {os.WTERMSIG(status)}): the file is damaged"
    return None


def _names_in_memory(ds: xr.Dataset) -> xr.Dataset:
    """A file's Dataset with the names of the results in memory: the time axis ``time``, text labels their dimension's coordinates."""
    if FILE_TIME in ds.dims and "time" not in ds.variables:
        ds = ds.rename({FILE_TIME: "time"})
    for name in list(ds.coords):
        dim = str(name)[: -len(LABEL_SUFFIX)]
        if str(name).endswith(LABEL_SUFFIX) and ds[name].dims == (dim,) and dim not in ds.variables:
            ds = ds.drop_vars(name).assign_coords({dim: (dim, ds[name].values, ds[name].attrs)})
    return ds


def read_dataset(path: str | Path) -> xr.Dataset:
    """Load a NetCDF result written by :func:`write_dataset` into memory.

    The file's structure is opened first in a forked child (:data:`READ_PROBE_SECONDS`), so
    that a damaged file on which the HDF5 library hangs or crashes is refused instead.
    What the file holds is checked by its reader (:func:`cosserat_chain.inputs.check_run`
    for a run). The time axis, :data:`FILE_TIME` in the file, is named ``time`` and a text
    label (:data:`LABEL_SUFFIX`) is its dimension's coordinate, as in the results in memory
    (a file written before either reads the same).

    Raises
    ------
    ValueError
        Naming the path, if it does not exist, is not a regular file, or is not a
        readable NetCDF-4 file (truncated, damaged, another format).
    """
    path = Path(path)
    try:
        mode = path.stat().st_mode
    except FileNotFoundError:
        raise ValueError(f"{str(path)!r} does not exist") from None
    except OSError as err:  # a loop of symbolic links, a folder on the way that may not be searched, a name too long
        raise ValueError(f"{str(path)!r} cannot be read: {err.strerror}") from None
    if not stat.S_ISREG(mode):
        raise ValueError(f"{str(path)!r} is {_kind(mode)}, not a NetCDF file")
    import xarray as xr

    problem = _probe_structure(path)
    if problem is not None:
        raise ValueError(f"{str(path)!r} is not a readable NetCDF file written by this package: {problem}")
    # A file object h5netcdf left half made on a damaged file complains from its destructor (a
    # traceback on stderr after the error, when the error is dropped or collected): muted here.
    hook = sys.unraisablehook
    sys.unraisablehook = lambda unraisable: None
    try:
        try:
            with xr.open_dataset(path, engine="h5netcdf") as ds:
                return _names_in_memory(ds.load())
        except MemoryError:
            raise
        except Exception as err:  # noqa: BLE001 - a damaged file fails in any of h5py's and xarray's errors (KeyError, ...)
            failure = f"{str(path)!r} is not a readable NetCDF file written by this package ({type(err).__name__}: {err})"
        gc.collect()
    finally:
        sys.unraisablehook = hook
    raise ValueError(failure)


def read_config(path: str | Path) -> dict[str, Any]:
    """Parse a TOML file into a dict.

    Raises
    ------
    ValueError
        If the file does not exist, is not a regular file (a folder, /dev/zero), is
        larger than :data:`MAX_CONFIG_BYTES`, cannot be read, or is not valid UTF-8 TOML (a leading byte-order
        mark is skipped).
    """
    path = Path(path)
    try:
        mode = path.stat().st_mode
        if not stat.S_ISREG(mode):
            raise ValueError(f"config file {str(path)!r} is {_kind(mode)}, not a regular file")
        with path.open("rb") as fh:
            data = fh.read(MAX_CONFIG_BYTES + 1)
    except FileNotFoundError:
        raise ValueError(f"config file {str(path)!r} does not exist") from None
    except OSError as err:
        raise ValueError(f"config file {str(path)!r} cannot be read: {err.strerror or err}") from None
    if len(data) > MAX_CONFIG_BYTES:
        raise ValueError(f"config file {str(path)!r} is larger than {MAX_CONFIG_BYTES} bytes: not a TOML file of parameters")
    try:
        # "utf-8-sig": a byte-order mark (Windows editors write one) is not TOML's, but it is no error of the user's.
        return tomllib.loads(data.decode("utf-8-sig"))
    except UnicodeDecodeError as err:
        raise ValueError(f"config file {str(path)!r} is not valid TOML: not UTF-8 text ({err.reason} at byte {err.start})") from None
    except tomllib.TOMLDecodeError as err:
        raise ValueError(f"config file {str(path)!r} is not valid TOML: {err}") from None


#: The table of a config file that holds loads (``[[loads]]``, :func:`cosserat_chain.loads.load_from_table`).
LOADS_TABLE = "loads"
#: The table of a config file that draws a disordered chain (:func:`cosserat_chain.params.disordered`).
DISORDER_TABLE = "disorder"


def disorder_from_table(params: ChainParams, table: Any, source: str) -> ChainParams:
    """``params`` made disordered by a ``[disorder]`` table: ``seed``, ``spread`` and optionally ``fields``.

    Raises
    ------
    ValueError
        Naming the source and the key: a table that is not one, an unknown or missing key,
        a bad value (:func:`~cosserat_chain.params.disordered`'s rules), or a field whose
        factors the file also gives by hand (``E1_factors`` and ``fields`` with "E1").
    """
    from .params import DISORDER_FIELDS, disordered

    where = f"[{DISORDER_TABLE}] of {source}"
    if not isinstance(table, dict):
        raise ValueError(f"{where} must be a table with keys seed, spread and optionally fields, got {table!r}")
    unknown = [key for key in table if key not in ("seed", "spread", "fields")]
    missing = [key for key in ("seed", "spread") if key not in table]
    if unknown or missing:
        raise ValueError(
            f"{where}: "
            + (f"unknown key(s) {unknown}" if unknown else f"missing key(s) {missing}")
            + "; its keys are seed, spread and fields"
        )
    fields = table.get("fields", ["E1", "E2"])
    if not isinstance(fields, list) or not all(isinstance(field, str) for field in fields):
        raise ValueError(f"{where}: fields must be a list of {', '.join(DISORDER_FIELDS)}, got {fields!r}")
    given = [DISORDER_FIELDS[f] for f in fields if f in DISORDER_FIELDS and getattr(params, DISORDER_FIELDS[f]) is not None]
    if given:
        raise ValueError(f"{where} draws factors that the file also gives ({', '.join(given)}): give one or the other")
    try:
        return disordered(params, table["seed"], table["spread"], tuple(fields))
    except ValueError as err:
        raise ValueError(f"{where}: {err}") from None


def load_params(path: str | Path | None = None) -> ChainParams:
    """``ChainParams`` from a TOML file, or the paper's defaults when ``path`` is None.

    A ``[[loads]]`` array in the file is not a parameter: :func:`load_config` reads both.
    """
    return load_config(path)[0]


def load_config(path: str | Path | None = None) -> tuple[ChainParams, Loads]:
    """``ChainParams`` and the ``[[loads]]`` of a TOML file (the paper's chain and no loads when ``path`` is None).

    A ``[disorder]`` table (``seed``, ``spread``, ``fields``) draws the chain's factors:
    :func:`disorder_from_table`.

    Raises
    ------
    ValueError
        For a bad parameter or load, naming the key, the value and what is allowed (a
        load on a degree of freedom the chain's ends hold included).
    """
    from .loads import Loads, loads_from_tables

    if path is None:
        return ChainParams(), Loads()
    mapping = read_config(path)
    tables = mapping.pop(LOADS_TABLE, [])
    disorder = mapping.pop(DISORDER_TABLE, None)
    params = params_from_mapping(mapping, source=str(path))
    if disorder is not None:
        params = disorder_from_table(params, disorder, repr(str(path)))
    return params, loads_from_tables(tables, source=f"[[{LOADS_TABLE}]] of {str(path)!r}").validate(params)


def params_of(dataset: xr.Dataset) -> ChainParams:
    """The ``ChainParams`` stored in a result's ``params_json`` attribute.

    Raises
    ------
    ValueError
        If the Dataset has no ``params_json`` attribute or it holds invalid parameters.
    """
    return stored_params(dataset.attrs, "the dataset")


def run_frame(
    dataset: xr.Dataset, at: float | None = None, *, source: str = "the dataset"
) -> tuple[ChainParams, Loads, float, np.ndarray, np.ndarray]:
    """The chain, the loads and one stored frame (time, positions, velocities) of a run, to start another from.

    ``at`` picks the stored frame nearest that time (default the last); the run's own
    parameters and loads come with it, so that a run started there continues its time
    axis and its loads' schedules.

    Raises
    ------
    ValueError
        Naming ``source``, if the dataset is not a sound run with velocities (``simulate --out``;
        :func:`cosserat_chain.inputs.check_run`), or ``at`` lies outside its time axis.
    """
    params, loads = check_run(dataset, source, velocities=True)
    times, states = run_states(params, dataset)
    if at is None:
        frame = times.size - 1
    else:
        if not (math.isfinite(at) and times[0] <= at <= times[-1]):
            raise ValueError(f"--at must lie within the run's times {times[0]:g}..{times[-1]:g}, got {at!r}")
        frame = int(np.argmin(np.abs(times - at)))
    ordered = dataset.sortby("particle").isel(time=frame)
    velocities = np.stack([np.asarray(ordered[f"{row}_dot"].values, dtype=float) for row in ROWS])
    return params, loads, float(times[frame]), np.ascontiguousarray(states[frame]), velocities


def run_states(params: ChainParams, dataset: xr.Dataset) -> tuple[np.ndarray, np.ndarray]:
    """Times (n,) and states (n, 3, 2N+1) of a run (``simulate --out``), particles in order -N..N.

    Raises
    ------
    ValueError
        If the dataset lacks u, v or phi over (time, particle), holds a value there that is not
        a finite number, or has another number of particles than ``params``.
    """
    check_finite(dataset, ROWS, "the dataset", dims=("time", "particle"))
    dataset = dataset.sortby("particle")
    if dataset.sizes["particle"] != params.n_particles:
        raise ValueError(f"the dataset has {dataset.sizes['particle']} particles but params describe 2N+1 = {params.n_particles}")
    states = np.stack([dataset[row].transpose("time", "particle").values for row in ROWS], axis=1)
    return np.asarray(dataset["time"].values, dtype=float), states
