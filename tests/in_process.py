"""Scripts and commands run in the test process, as a fresh interpreter runs them, where the claim is not about the process.

A fresh ``python`` pays the package's imports again (numba, SciPy, xarray, matplotlib) and loads every compiled kernel
from Numba's cache anew: the docs pages, the examples and the commands whose progress bars are read run here instead,
each script as ``__main__`` in a fresh namespace (``runpy``), in its own folder, with its own command line. What a
script may change in the process is put back afterwards (:func:`restored`): the working folder, ``sys.argv``,
``sys.path``, the standard streams, the warnings filters, NumPy's error handling, matplotlib's backend, figures and
settings, the SIGINT and SIGTERM handlers and the model registry. A name a script uses without importing it is still a
``NameError`` (the namespace is fresh), but a submodule an earlier test imported is found as an attribute of its
package where a fresh interpreter would not have imported it.

The claims about the process itself keep one: the entry points (``python -m cosserat_chain``, the installed
``cosserat-chain`` of test_packaging.py), the libraries a command imports (test_api.py), the BLAS threads set before
NumPy loads (test_blas_threads.py), a crash inside HDF5 on a full file system and another process holding a lock
(test_safe_writing.py), Ctrl-C and other signals (test_ctrl_c_net.py), the pages and examples that start worker
processes (``if __name__ == "__main__"``) and the docs site's build.
"""

from __future__ import annotations

import contextlib
import fcntl
import io
import os
import pty
import runpy
import select
import signal
import struct
import sys
import termios
import threading
import traceback
import warnings
from collections.abc import Callable, Iterator
from pathlib import Path

import numpy as np


@contextlib.contextmanager
def restored() -> Iterator[None]:
    """Put back, on leaving, what a script run in this process may have changed in it (the module's docstring)."""
    import matplotlib
    import matplotlib.pyplot as plt

    from cosserat_chain.models import base

    cwd, argv, path = os.getcwd(), sys.argv[:], sys.path[:]
    streams = sys.stdin, sys.stdout, sys.stderr
    handlers = {sig: signal.getsignal(sig) for sig in (signal.SIGINT, signal.SIGTERM)}
    registry = dict(base._REGISTRY)
    backend = matplotlib.get_backend()
    plt.switch_backend("Agg")
    try:
        with warnings.catch_warnings(), np.errstate(), matplotlib.rc_context():
            yield
    finally:
        plt.close("all")
        plt.switch_backend(backend)
        os.chdir(cwd)
        sys.argv[:], sys.path[:] = argv, path
        sys.stdin, sys.stdout, sys.stderr = streams
        for sig, handler in handlers.items():
            signal.signal(sig, handler)
        base._REGISTRY.clear()
        base._REGISTRY.update(registry)


def run_script(script: str | Path, folder: str | Path, argv: tuple[str, ...] = ()) -> tuple[int, str, str | None]:
    """Run ``script`` as ``python SCRIPT ARGV`` would in ``folder``: (its exit code, what it printed, the end of its
    traceback or None). Its own folder comes first on ``sys.path``; an exception is exit code 1, ``SystemExit`` its code."""
    script = str(script)
    printed, code, failure = io.StringIO(), 0, None
    with restored():
        os.chdir(folder)
        sys.argv[:] = [script, *argv]
        sys.path.insert(0, os.path.dirname(script))
        try:
            with contextlib.redirect_stdout(printed):
                runpy.run_path(script, run_name="__main__")
        except SystemExit as stop:
            code = stop.code if isinstance(stop.code, int) else (0 if stop.code is None else 1)
        except Exception:  # noqa: BLE001 - the script's failure, whatever it is, is the finding
            code, failure = 1, traceback.format_exc()[-3000:]
    return code, printed.getvalue(), failure


def run_command(args: list[str]) -> int:
    """``python -m cosserat_chain ARGS`` in this process: the exit code (the command line as ``__main__`` runs it)."""
    from cosserat_chain.cli import app

    with restored():
        sys.argv[:] = ["cosserat-chain", *args]
        try:
            app(prog_name="cosserat-chain")
        except SystemExit as done:
            return done.code if isinstance(done.code, int) else (0 if done.code is None else 1)
    return 0


def on_terminal(work: Callable[[], int], cwd: str | Path, columns: int = 160) -> tuple[int, str]:
    """Run ``work()`` in ``cwd`` with ``sys.stderr`` on a pseudo-terminal ``columns`` wide (stdout discarded): (what it
    returned, everything written to the terminal). The terminal is read by a thread while ``work`` writes."""
    leader, follower = pty.openpty()
    fcntl.ioctl(follower, termios.TIOCSWINSZ, struct.pack("HHHH", 40, columns, 0, 0))
    chunks: list[bytes] = []

    def read() -> None:
        while True:
            select.select([leader], [], [])
            try:
                chunk = os.read(leader, 4096)
            except OSError:  # the follower closed
                return
            if not chunk:
                return
            chunks.append(chunk)

    reader = threading.Thread(target=read, daemon=True)
    reader.start()
    terminal = open(follower, "w", buffering=1, encoding="utf-8", errors="replace")  # noqa: SIM115 - closed below
    try:
        with restored():
            os.chdir(cwd)
            sys.stderr, sys.stdout = terminal, io.StringIO()
            code = work()
            terminal.flush()
    finally:
        terminal.close()
        reader.join(timeout=60)
        os.close(leader)
    return code, b"".join(chunks).decode(errors="replace")
