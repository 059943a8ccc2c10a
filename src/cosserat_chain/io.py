"""Files: NetCDF results and figures written atomically and safely, and TOML configuration files.

Contract
--------
:func:`write_dataset` writes an xarray Dataset to NetCDF (h5netcdf), :func:`write_text`
a text file and :func:`write_figure` a matplotlib figure, through :func:`atomic_path`:
a temporary file in the same folder and an atomic rename, so that a reader never sees a
half-written file. Nothing that is not a regular file is ever replaced: a target that
is a folder, a FIFO or a device is refused (:class:`OutputError`), and a symbolic link is
written through (its target is replaced, the link stays). :func:`check_output` runs the
same checks, and a probe of the folder's writability, before any work is done, so a
command refuses a bad ``--out`` before it computes. :func:`load_params` reads
``ChainParams`` fields from a TOML file (top-level keys, the paper's symbols) and names
any unknown key; :func:`read_config` reads at most :data:`MAX_CONFIG_BYTES` from a regular
file.
"""

from __future__ import annotations

import os
import stat
import tempfile
import tomllib
from collections.abc import Iterator, Mapping
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import xarray as xr

from .params import ChainParams

#: Largest configuration or study spec read (bytes): a TOML file of parameters is a few
#: hundred bytes; this bounds what a mistyped path (a log, /dev/zero) can make us read.
MAX_CONFIG_BYTES = 1 << 20

#: Picture formats the package writes (matplotlib's, chosen by the file's suffix).
FIGURE_FORMATS = (".png", ".svg", ".pdf")

#: The marker in the names of temporary files, ``.NAME.tmp<pid>-<random><suffix>``: the
#: writer's process id lets a later write to the same place remove those whose writer died.
_TMP_MARK = ".tmp"


class OutputError(ValueError):
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


def _target(path: Path, label: str) -> Path:
    """Where a write to ``path`` lands: through symbolic links, and only onto a regular file or nothing."""
    if str(path) == "":
        raise OutputError(f"{label} is empty: give a file name")
    target = Path(os.path.realpath(path))
    try:
        mode = target.stat().st_mode
    except FileNotFoundError:
        return target
    except NotADirectoryError:
        raise OutputError(f"{label} {str(path)!r}: {str(_existing_folder(target.parent, label, path))!r} is not a folder") from None
    except OSError as err:
        raise OutputError(f"{label} {str(path)!r} cannot be examined: {err.strerror}") from None
    if stat.S_ISDIR(mode):
        raise OutputError(f"{label} {str(path)!r} is a folder: give a file name inside it")
    if not stat.S_ISREG(mode):
        raise OutputError(f"{label} {str(path)!r} exists and is {_kind(mode)}, not a regular file: refusing to replace it")
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
        nothing can be written, or one of the command's inputs.
    """
    path = Path(path)
    if str(path) == "":
        raise OutputError(f"{option} is empty: give a {'folder' if folder else 'file'} name")
    if formats is not None and path.suffix.lower() not in formats:
        raise OutputError(f"unknown format {path.suffix or '(none)'!r} of {option} {str(path)!r}; allowed: {', '.join(formats)}")
    if folder:
        target = Path(os.path.realpath(path))
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
    """Remove temporary files left beside ``target`` by writers that were killed (their process is gone)."""
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
            if stat.S_ISREG(entry.lstat().st_mode):
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


@contextmanager
def atomic_path(path: str | Path) -> Iterator[Path]:
    """A temporary file beside ``path`` (same extension), renamed onto it if the block succeeds.

    A reader never sees a half-written file, and an interrupted write leaves none
    behind (a killed one is removed by the next write to the same place). The file
    gets the usual permissions (mkstemp creates it 0600). A symbolic link is written
    through: its target is replaced and the link kept. Missing folders are created.

    Raises
    ------
    OutputError
        If ``path`` is empty, a folder, or exists and is not a regular file (a FIFO, a device):
        such a target is never replaced.
    """
    target = _target(Path(path), "output")
    try:
        target.parent.mkdir(parents=True, exist_ok=True)
    except (FileExistsError, NotADirectoryError):
        raise OutputError(f"output {str(path)!r}: {str(_existing_folder(target.parent, 'output', Path(path)))!r} is not a folder") from None
    _remove_stale(target)
    fd, tmp = tempfile.mkstemp(prefix=f".{target.name}{_TMP_MARK}{os.getpid()}-", suffix=target.suffix, dir=target.parent)
    os.close(fd)
    try:
        yield Path(tmp)
        umask = os.umask(0)
        os.umask(umask)
        os.chmod(tmp, 0o666 & ~umask)
        # The target may have become something else while we wrote (a FIFO made meanwhile).
        _target(target, "output")
        os.replace(tmp, target)
    finally:
        if os.path.exists(tmp):
            os.unlink(tmp)


def write_dataset(dataset: xr.Dataset, path: str | Path) -> Path:
    """Write ``dataset`` to NetCDF at ``path`` atomically; returns the path.

    Attribute values that are subclasses of ``str`` (a :class:`~cosserat_chain.status.Status`)
    are written as plain strings: h5netcdf finds no conversion for them.
    """
    dataset = dataset.copy()
    for attrs in [dataset.attrs, *(variable.attrs for variable in dataset.variables.values())]:
        attrs.update({key: str(value) for key, value in attrs.items() if isinstance(value, str) and type(value) is not str})
    with atomic_path(path) as tmp:
        dataset.to_netcdf(tmp, engine="h5netcdf")
    return Path(path)


def write_text(text: str, path: str | Path) -> Path:
    """Write ``text`` (UTF-8) to ``path`` atomically; returns the path."""
    with atomic_path(path) as tmp:
        tmp.write_text(text, encoding="utf-8")
    return Path(path)


def write_figure(figure: Any, path: str | Path, **savefig: Any) -> Path:
    """Write a matplotlib figure to ``path`` atomically, in the format its suffix names; returns the path."""
    path = Path(path)
    with atomic_path(path) as tmp:
        figure.savefig(tmp, format=path.suffix.lstrip(".").lower() or None, **savefig)
    return path


def stack_models(datasets: dict[str, xr.Dataset]) -> xr.Dataset:
    """One Dataset with a ``model`` dimension from per-model results of the same experiment.

    Dimensions of different lengths (e.g. the points of each model's branch) are
    padded with NaN; attributes that differ between models (the model's name and
    equation) are dropped, and the names are the ``model`` coordinate.
    """
    if len(datasets) == 1:
        return next(iter(datasets.values()))
    stacked = xr.concat(list(datasets.values()), dim="model", join="outer", combine_attrs="drop_conflicts")
    return stacked.assign_coords(model=list(datasets))


def read_dataset(path: str | Path) -> xr.Dataset:
    """Load a NetCDF result written by :func:`write_dataset` into memory.

    Raises
    ------
    ValueError
        Naming the path, if it does not exist, is not a regular file, or is not a
        readable NetCDF-4 file (truncated, another format).
    """
    path = Path(path)
    try:
        mode = path.stat().st_mode
    except FileNotFoundError:
        raise ValueError(f"{str(path)!r} does not exist") from None
    if not stat.S_ISREG(mode):
        raise ValueError(f"{str(path)!r} is {_kind(mode)}, not a NetCDF file")
    try:
        with xr.open_dataset(path, engine="h5netcdf") as ds:
            return ds.load()
    except (OSError, ValueError, KeyError, TypeError) as err:  # h5py and xarray say "truncated", "not HDF5", ... in their own words
        raise ValueError(f"{str(path)!r} is not a readable NetCDF file written by this package ({type(err).__name__}: {err})") from None


def read_config(path: str | Path) -> dict[str, Any]:
    """Parse a TOML file into a dict.

    Raises
    ------
    ValueError
        If the file does not exist, is not a regular file (a folder, /dev/zero), is
        larger than :data:`MAX_CONFIG_BYTES`, cannot be read, or is not valid UTF-8 TOML.
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
        return tomllib.loads(data.decode("utf-8"))
    except UnicodeDecodeError as err:
        raise ValueError(f"config file {str(path)!r} is not valid TOML: not UTF-8 text ({err.reason} at byte {err.start})") from None
    except tomllib.TOMLDecodeError as err:
        raise ValueError(f"config file {str(path)!r} is not valid TOML: {err}") from None


def params_from_mapping(mapping: dict[str, Any], source: str = "config") -> ChainParams:
    """Validated ``ChainParams`` from a mapping of field names.

    Raises
    ------
    ValueError
        Naming an unknown (e.g. misspelled) key and listing the allowed ones, or
        the field, value and rule of an invalid value.
    """
    allowed = list(ChainParams.model_fields)
    unknown = [key for key in mapping if key not in allowed]
    if unknown:
        raise ValueError(f"unknown key(s) {unknown} in {source}; allowed keys: {', '.join(allowed)}")
    return ChainParams(**mapping)


def load_params(path: str | Path | None = None) -> ChainParams:
    """``ChainParams`` from a TOML file, or the paper's defaults when ``path`` is None."""
    if path is None:
        return ChainParams()
    return params_from_mapping(read_config(path), source=str(path))
