"""The scripts in examples/ run on small sizes (``--quick``), as the CI runs them (issue 16, item 2).

Each script runs as ``python SCRIPT --quick`` would run it: as ``__main__``, with that command line, in a fresh
folder and namespace, its own folder first on ``sys.path``, matplotlib's non-interactive backend. The scripts run in
the test process (``in_process.run_script``: the package's imports and compiled kernels are the session's, what a
script changes in the process is put back); a script guarded by ``if __name__ == "__main__"`` (its worker processes
import the script again) runs in a fresh interpreter of its own.
"""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

from conftest import selected_params
from in_process import run_script

ROOT = Path(__file__).resolve().parents[1]
EXAMPLES = sorted((ROOT / "examples").glob("*.py"))
#: Examples that are long runs (a study on a local Dask cluster of worker processes): slow tests.
SLOW_EXAMPLES = {"parameter_study.py", "chain_ends.py"}


def _env() -> dict[str, str]:
    return {**os.environ, "MPLBACKEND": "Agg", "PYTHONPATH": os.pathsep.join([str(ROOT / "src"), os.environ.get("PYTHONPATH", "")])}


def _needs_its_own_process(script: Path) -> bool:
    """A script guarded by ``if __name__ == "__main__"`` starts worker processes that import it again."""
    return "__main__" in script.read_text(encoding="utf-8")


@pytest.fixture(scope="module")
def example_runs(request, tmp_path_factory) -> dict[str, tuple[int, str, str]]:
    """Script name -> (exit code, what it printed, why it failed: a traceback or stderr's end), for the scripts of
    the tests selected in this session."""
    wanted = [script for script in EXAMPLES if script in selected_params(request, "script")]
    outcome = {}
    for script in wanted:
        if not _needs_its_own_process(script):
            outcome[script.name] = run_script(script, tmp_path_factory.mktemp(script.stem), ("--quick",))
        else:
            alone = subprocess.run(
                [sys.executable, str(script), "--quick"], cwd=tmp_path_factory.mktemp(script.stem), env=_env(), capture_output=True,
                text=True, timeout=600,
            )  # fmt: skip
            outcome[script.name] = (alone.returncode, alone.stdout, alone.stderr[-3000:])
    return outcome


@pytest.mark.parametrize(
    "script", [pytest.param(p, marks=pytest.mark.slow) if p.name in SLOW_EXAMPLES else p for p in EXAMPLES], ids=lambda p: p.stem
)
def test_example_runs_quick(script, example_runs):
    code, printed, failure = example_runs[script.name]
    assert code == 0, failure
    assert printed.strip(), "an example prints what it computed"


def test_a_failing_or_silent_example_is_told_in_process(tmp_path):
    """A script's exit code, its output and its traceback are told, each script in its own namespace, with its own
    command line and folder; the test process's are as they were."""
    scripts = {}
    for name, text in (
        ("prints", "import math, sys\nprint(math.pi, sys.argv[1:])\n"),
        ("fails", "print(math.pi)\n"),
        ("exits", "raise SystemExit(3)\n"),
    ):
        scripts[name] = tmp_path / f"{name}.py"
        scripts[name].write_text(text, encoding="utf-8")
    cwd, argv = os.getcwd(), sys.argv[:]
    assert run_script(scripts["prints"], tmp_path, ("--quick",)) == (0, "3.141592653589793 ['--quick']\n", None)
    code, _, failure = run_script(scripts["fails"], tmp_path)
    assert code == 1 and "NameError" in failure
    assert run_script(scripts["exits"], tmp_path)[0] == 3
    assert os.getcwd() == cwd and sys.argv == argv


def test_the_four_examples_are_there():
    assert {p.stem for p in EXAMPLES} >= {"fig2", "long_chain", "parameter_study", "custom_load"}
