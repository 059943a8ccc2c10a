"""The public API and the package's entry points (issue 16, item 3)."""

from __future__ import annotations

import importlib
import os
import subprocess
import sys

import pytest

import cosserat_chain
from fresh_cli import fresh_run


def test_every_public_name_resolves_to_its_module_and_all_lists_them():
    assert set(cosserat_chain.__all__) == {"__version__", *cosserat_chain._API}
    for name, module in cosserat_chain._API.items():
        assert getattr(cosserat_chain, name) is getattr(importlib.import_module(f"cosserat_chain.{module}"), name), name
    assert set(cosserat_chain.__all__) <= set(dir(cosserat_chain))


def _fresh(code: str) -> str:
    return subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout.strip()


def test_importing_the_package_and_the_command_line_loads_no_heavy_library():
    """numba, SciPy and xarray load when a computation needs them, not at import (start-up stays quick)."""
    assert _fresh("import sys, cosserat_chain; print(sorted(m for m in ('numba', 'scipy', 'xarray') if m in sys.modules))") == "[]"
    assert _fresh("import sys, cosserat_chain.cli; print(sorted(m for m in ('numba', 'xarray', 'matplotlib') if m in sys.modules))") == "[]"


#: Computing commands with --json and their quickest options (each a few seconds on the paper's chain).
_JSON_COMMANDS = {
    "critical": ["critical", "--model", "sine", "--json"],
    "orbit": ["orbit", "--model", "sine", "--moment", "0.3", "--turns", "3", "--json"],
    "sweep": ["sweep", "--model", "sine", "--m-max", "0.05", "--steps", "1", "--json"],
    "waves": ["waves", "--json"],
    "states": ["states", "--model", "sine", "--moment", "0.22", "--random-starts", "0", "--t-long", "1000", "--json"],
    "theory": ["theory", "--json"],
    "breathers": ["breathers", "--omega", "6", "--json"],
}

#: The commands given as JSON lists of arguments, each as ``python -m cosserat_chain ARGS`` runs it, one after the
#: other in one fresh interpreter (the package's import paid once): after each, its exit code and the heavy libraries
#: loaded by then. The libraries only accumulate, so a command that loads one is the first listed with it.
_HEAVY_AFTER_EACH = """
import json, runpy, sys
heavy = ("xarray", "pandas", "dask", "distributed", "matplotlib", "scipy.optimize")
for args in sys.argv[1:]:
    sys.argv = ["cosserat-chain", *json.loads(args)]
    try:
        runpy.run_module("cosserat_chain", run_name="__main__")
        code = 0
    except SystemExit as done:
        code = done.code or 0
    print("\\nEXIT", code, "HEAVY", sorted(m for m in heavy if m in sys.modules), flush=True)
"""


#: The first command of :data:`_JSON_COMMANDS` that imports ``scipy.optimize`` (the dispersion curves' extrema);
#: the statics and the orbits before it take Brent's method from ``numerics.brent`` and start without that package,
#: whose ``__init__`` loads linear programming, global optimisers, ``scipy.spatial`` and ``scipy.fft``.
_FIRST_WITH_OPTIMIZE = "waves"


@pytest.fixture(scope="module")
def json_runs() -> dict[str, tuple[str, str, str]]:
    """Command -> (what it printed, its exit line, the interpreter's stderr) of the commands of ``_JSON_COMMANDS``."""
    import json

    run = subprocess.run(
        [sys.executable, "-c", _HEAVY_AFTER_EACH, *(json.dumps(args) for args in _JSON_COMMANDS.values())], capture_output=True, text=True
    )
    outputs = run.stdout.split("\nEXIT ")
    printed = [outputs[0]] + [part.split("\n", 1)[1] if "\n" in part else "" for part in outputs[1:-1]]
    ends = ["EXIT " + part.split("\n", 1)[0] for part in outputs[1:]]
    assert len(ends) == len(_JSON_COMMANDS), run.stderr[-2000:]
    return {command: (printed[i], ends[i], run.stderr[-2000:]) for i, command in enumerate(_JSON_COMMANDS)}


@pytest.mark.parametrize("command", list(_JSON_COMMANDS))
def test_computing_commands_with_json_load_no_data_or_plotting_library(command, json_runs):
    """Issue 44, item 3: with --json and no file output, a command computes and prints without xarray, pandas, Dask or
    matplotlib (xarray and pandas alone cost about 1 s of start-up), and critical, orbit and sweep without
    scipy.optimize; the result is still the full JSON object."""
    import json

    printed, end, stderr = json_runs[command]
    optimize_allowed = list(_JSON_COMMANDS).index(command) >= list(_JSON_COMMANDS).index(_FIRST_WITH_OPTIMIZE)
    assert end in ("EXIT 0 HEAVY []", *(["EXIT 0 HEAVY ['scipy.optimize']"] if optimize_allowed else [])), f"{command}: {end} {stderr}"
    assert isinstance(json.loads(printed), dict)


def test_python_dash_m_and_version():
    """``python -m cosserat_chain`` in a fresh interpreter (``fresh_cli``: the runs test_cli_startup.py reads too)."""
    version, _ = fresh_run("--version")
    assert version.returncode == 0 and version.stdout.strip() == f"cosserat-chain {cosserat_chain.__version__}"
    help_text, _ = fresh_run("--help")
    assert help_text.returncode == 0 and all(name in help_text.stdout for name in ("simulate", "export", "reproduce"))


def test_shell_completion_script_is_offered():
    # The shell named, not detected: typer detects it from the process tree, which a test
    # runner started outside a shell lacks ("Shell  not supported"); with detection off,
    # --show-completion takes the shell's name.
    env = {**os.environ, "_TYPER_COMPLETE_TEST_DISABLE_SHELL_DETECTION": "1"}
    result = subprocess.run([sys.executable, "-m", "cosserat_chain", "--show-completion", "bash"], capture_output=True, text=True, env=env)
    assert result.returncode == 0, result.stderr[-2000:]
    assert "complete" in result.stdout and "COMP_WORDS" in result.stdout


def test_models_command_lists_the_registry():
    """In this interpreter (``python -m cosserat_chain`` is the test above): a fresh one imports and loads every model."""
    import json

    from typer.testing import CliRunner

    from cosserat_chain.cli import app

    result = CliRunner().invoke(app, ["models", "--json"])
    assert result.exit_code == 0, result.output
    rows = json.loads(result.stdout)["models"]
    assert [r["name"] for r in rows] == ["nonlinear", "sine", "linear"]
    assert [r["rotates"] for r in rows] == [True, True, False] and rows[1]["equation"] == "eq. (2)" and not rows[1]["conservative"]
