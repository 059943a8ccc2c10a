"""The report's folder: what it holds, its manifest, and the removal of an older report's stale files.

Contract
--------
:func:`check_folder` refuses, before any work, a folder where the report's files or folders
cannot go. :func:`write_manifest` writes ``manifest.json`` (:data:`MANIFEST`), the list of the
report's files with their SHA-256 and the package's marker (:data:`MANIFEST_MARKER`), after
removing the files an older report of the package wrote there and this one did not write again,
and only those still as the package wrote them. :func:`json_default` writes NumPy values in the
report's JSON files.
"""

from __future__ import annotations

import hashlib
import json
import math
import stat
from pathlib import Path
from typing import Any

import numpy as np

from .._version import __version__
from ..io import OutputError, write_text

#: The list of the files a report consists of, written last: the next report into the same
#: folder removes those of them it does not write again (a stage that is gone, a figure
#: renamed), and nothing else (a file of the user's stays).
MANIFEST = "manifest.json"


#: The mark of a manifest this package wrote.
MANIFEST_MARKER = "cosserat-chain reproduce"


def _manifest_files(manifest: Path) -> dict[str, str]:
    """The files and SHA-256 a previous manifest of this package lists; none for a manifest it did not write or cannot read."""
    try:
        record = json.loads(manifest.read_text(encoding="utf-8")) if manifest.is_file() and not manifest.is_symlink() else {}
    except (OSError, ValueError):
        return {}
    files = record.get("files") if isinstance(record, dict) and record.get("written_by") == MANIFEST_MARKER else None
    if not isinstance(files, dict):
        return {}
    return {str(name): digest for name, digest in files.items() if isinstance(digest, str)}


def _own_file(out: Path, relative: str) -> Path | None:
    """``out / relative`` if it is a regular file under ``out`` reached through no link (no ``..``, not absolute); else None."""
    parts = Path(relative).parts
    if not parts or Path(relative).is_absolute() or any(part in ("..", "") for part in parts):
        return None
    path = out
    for part in parts:
        path = path / part
        try:
            mode = path.lstat().st_mode
        except OSError:
            return None
        if stat.S_ISLNK(mode):
            return None
    return path if stat.S_ISREG(mode) else None


#: What the report writes at the top of its folder, and whether each is a folder.
_LAYOUT = {
    "figures": True,
    "data": True,
    "index.html": False,
    "report.md": False,
    "summary.json": False,
    "params.json": False,
    MANIFEST: False,
}


def check_folder(out: str | Path) -> None:
    """Refuse, before any work, a report folder where a file of the report is a folder or one of its folders is not one.

    Raises
    ------
    OutputError
        Naming the path in the way and what the report writes there.
    """
    for name, folder in _LAYOUT.items():
        path = Path(out) / name
        try:
            mode = path.stat().st_mode
        except FileNotFoundError:
            continue
        except OSError as err:
            raise OutputError(f"--out {str(out)!r}: {str(path)!r} cannot be examined ({err.strerror})") from None
        if folder and not stat.S_ISDIR(mode):
            raise OutputError(f"--out {str(out)!r}: {str(path)!r} is not a folder, and the report writes its {name} there: move it")
        if not folder and not stat.S_ISREG(mode):
            raise OutputError(f"--out {str(out)!r}: {str(path)!r} is not a regular file, and the report writes its {name} there: move it")


def _sha256(path: Path) -> str:
    """SHA-256 of a file's content (hex)."""
    digest = hashlib.sha256()
    with path.open("rb") as fh:
        for block in iter(lambda: fh.read(1 << 20), b""):
            digest.update(block)
    return digest.hexdigest()


def write_manifest(out: Path, written: set[str]) -> None:
    """Write the manifest of the report of the files ``written`` (relative to ``out``), after removing the files
    of the previous one it did not write again.

    A file is removed only where the previous manifest carries this package's marker
    (:data:`MANIFEST_MARKER`) and the file still holds what that manifest's SHA-256
    says the package wrote, reached without a symbolic link: a manifest the package
    never wrote, or a file changed since, removes nothing.
    """
    manifest = out / MANIFEST
    for relative, digest in _manifest_files(manifest).items():
        if relative in written:
            continue
        stale = _own_file(out, relative)
        if stale is not None and _sha256(stale) == digest:
            stale.unlink()
    files = {relative: _sha256(out / relative) for relative in sorted(written)}
    record = {"written_by": MANIFEST_MARKER, "cosserat_chain_version": __version__, "files": files}
    write_text(json.dumps(record, indent=1), manifest)


def json_default(value: Any) -> Any:
    if isinstance(value, np.integer):
        return int(value)
    if isinstance(value, np.floating):
        return None if not math.isfinite(value) else float(value)
    if isinstance(value, np.ndarray):
        return value.tolist()
    raise TypeError(f"not JSON serialisable: {type(value).__name__}")
