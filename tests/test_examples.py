"""The scripts in examples/ run on small sizes (``--quick``), as the CI runs them (issue 16, item 2).

Each script runs as ``python SCRIPT --quick`` would run it: as ``__main__``, with that command line, in a fresh
folder and namespace, its own folder first on ``sys.path``, matplotlib's non-interactive backend. The scripts share
one interpreter (the package's imports, about 2 s, paid once); a script guarded by ``if __name__ == "__main__"``
(its worker processes import the script again) runs in a process of its own.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

from conftest import selected_params

ROOT = Path(__file__).resolve().parents[1]
EXAMPLES = sorted((ROOT / "examples").glob("*.py"))
#: Examples that are long runs (a study on a local Dask cluster of worker processes): slow tests.
SLOW_EXAMPLES = {"parameter_study.py"}

#: Arguments: pairs of a script and the folder to run it in. Runs each as ``python SCRIPT --quick`` in that folder,
#: one after the other, and prints a JSON object of script -> [its exit code, what it printed, the end of its traceback or
#: null].
_DRIVER = """
import contextlib, io, json, os, runpy, sys, traceback
import matplotlib.pyplot as plt
outcome = {}
for script, folder in zip(sys.argv[1::2], sys.argv[2::2]):
    os.chdir(folder)
    sys.argv = [script, "--quick"]
    sys.path.insert(0, os.path.dirname(script))
    printed, code, failure = io.StringIO(), 0, None
    try:
        with contextlib.redirect_stdout(printed):
            runpy.run_path(script, run_name="__main__")
    except SystemExit as stop:
        code = stop.code if isinstance(stop.code, int) else (0 if stop.code is None else 1)
    except BaseException:
        code, failure = 1, traceback.format_exc()[-3000:]
    sys.path.remove(os.path.dirname(script))
    plt.close("all")
    outcome[script] = [code, printed.getvalue(), failure]
print(json.dumps(outcome))
"""


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
    shared = {script: tmp_path_factory.mktemp(script.stem) for script in wanted if not _needs_its_own_process(script)}
    arguments = [str(part) for pair in shared.items() for part in pair]
    result = subprocess.run([sys.executable, "-c", _DRIVER, *arguments], env=_env(), capture_output=True, text=True, timeout=1200)
    driven = json.loads(result.stdout.strip().splitlines()[-1]) if result.returncode == 0 else {}
    outcome = {}
    for script in shared:
        code, printed, failure = driven.get(str(script), (1, "", None))
        outcome[script.name] = (code, printed, failure or result.stderr[-3000:])
    for script in wanted:
        if script not in shared:
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


def test_a_failing_or_silent_example_is_told_by_the_driver(tmp_path):
    """The driver reports a script's exit code, its output and its traceback, each script in its own namespace."""
    scripts = {}
    for name, text in (("prints", "import math\nprint(math.pi)\n"), ("fails", "print(math.pi)\n"), ("exits", "raise SystemExit(3)\n")):
        scripts[name] = tmp_path / f"{name}.py"
        scripts[name].write_text(text, encoding="utf-8")
    arguments = [str(part) for script in scripts.values() for part in (script, tmp_path)]
    result = subprocess.run([sys.executable, "-c", _DRIVER, *arguments], env=_env(), capture_output=True, text=True, timeout=600)
    outcome = json.loads(result.stdout.strip().splitlines()[-1])
    assert outcome[str(scripts["prints"])][:2] == [0, "3.141592653589793\n"]
    assert outcome[str(scripts["fails"])][0] == 1 and "NameError" in outcome[str(scripts["fails"])][2]
    assert outcome[str(scripts["exits"])][0] == 3


def test_the_four_examples_are_there():
    assert {p.stem for p in EXAMPLES} >= {"fig2", "long_chain", "parameter_study", "custom_load"}
