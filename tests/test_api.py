"""The public API and the package's entry points (issue 16, item 3)."""

from __future__ import annotations

import importlib
import os
import subprocess
import sys

import pytest

import cosserat_chain


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
    "orbit": ["orbit", "--model", "sine", "--moment", "0.3", "--json"],
    "sweep": ["sweep", "--model", "sine", "--m-max", "0.05", "--steps", "1", "--json"],
    "waves": ["waves", "--json"],
    "states": ["states", "--model", "sine", "--moment", "0.22", "--random-starts", "0", "--t-long", "1000", "--json"],
    "theory": ["theory", "--json"],
    "breathers": ["breathers", "--omega", "6", "--json"],
}

#: The command line as ``python -m cosserat_chain ARGS`` runs it, with the heavy libraries loaded by then printed at exit.
_HEAVY_AT_EXIT = """
import atexit, runpy, sys
heavy = ("xarray", "pandas", "dask", "distributed", "matplotlib")
atexit.register(lambda: print("HEAVY", sorted(m for m in heavy if m in sys.modules)))
sys.argv = ["cosserat-chain", *sys.argv[1:]]
runpy.run_module("cosserat_chain", run_name="__main__")
"""


@pytest.mark.parametrize("command", list(_JSON_COMMANDS))
def test_computing_commands_with_json_load_no_data_or_plotting_library(command):
    """Issue 44, item 3: with --json and no file output, a command computes and prints without xarray, pandas, Dask or
    matplotlib (xarray and pandas alone cost about 1 s of start-up); the result is still the full JSON object."""
    import json

    args = _JSON_COMMANDS[command]
    run = subprocess.run([sys.executable, "-c", _HEAVY_AT_EXIT, *args], capture_output=True, text=True)
    assert run.returncode == 0, run.stderr[-2000:]
    *printed, heavy = run.stdout.strip().splitlines()
    assert heavy == "HEAVY []", f"{command}: {heavy}"
    assert isinstance(json.loads("\n".join(printed)), dict)


def test_python_dash_m_and_version():
    out = subprocess.run([sys.executable, "-m", "cosserat_chain", "--version"], capture_output=True, text=True, check=True).stdout
    assert out.strip() == f"cosserat-chain {cosserat_chain.__version__}"
    help_text = subprocess.run([sys.executable, "-m", "cosserat_chain", "--help"], capture_output=True, text=True, check=True).stdout
    assert "simulate" in help_text and "export" in help_text and "reproduce" in help_text


def test_shell_completion_script_is_offered():
    # The shell named, not detected: typer detects it from the process tree, which a test
    # runner started outside a shell lacks ("Shell  not supported"); with detection off,
    # --show-completion takes the shell's name.
    env = {**os.environ, "_TYPER_COMPLETE_TEST_DISABLE_SHELL_DETECTION": "1"}
    result = subprocess.run([sys.executable, "-m", "cosserat_chain", "--show-completion", "bash"], capture_output=True, text=True, env=env)
    assert result.returncode == 0, result.stderr[-2000:]
    assert "complete" in result.stdout and "COMP_WORDS" in result.stdout


def test_models_command_lists_the_registry():
    import json

    out = subprocess.run([sys.executable, "-m", "cosserat_chain", "models", "--json"], capture_output=True, text=True, check=True).stdout
    rows = json.loads(out)["models"]
    assert [r["name"] for r in rows] == ["nonlinear", "sine", "linear"]
    assert [r["rotates"] for r in rows] == [True, True, False] and rows[1]["equation"] == "eq. (2)" and not rows[1]["conservative"]
