"""Every Python block of README.md and docs/*.md runs as written (issue 16, item 2).

The blocks of one file run in order as one script (later blocks may use what earlier
ones made), as ``__main__``, in a fresh folder and a fresh namespace, with matplotlib's
non-interactive backend: what a reader who copies them gets. The pages run in the test
process (``in_process.run_script``: the package's imports and compiled kernels are the
session's, what a page changes in the process is put back); a page guarded by
``if __name__ == "__main__"`` (its worker processes import the script again) runs in a
fresh interpreter of its own.
"""

from __future__ import annotations

import math
import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

from conftest import selected_params
from in_process import run_script

ROOT = Path(__file__).resolve().parents[1]
PAGES = [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]
#: Pages whose blocks are long runs (a study on a local Dask cluster of worker processes; the roto-breather atlas of a
#: 101-particle chain over a grid of frequencies and geometries; the period-doubling switch of periodic-orbits.md, whose
#: branch, switch and branch point the quick tests of test_cycle_switching.py and test_cycle_switching_branch_points.py
#: compute on the same chains; collocation.md's N = 1 branch to its SNIC, which test_orbit_collocation_cli.py's quick
#: tests follow from the same orbit through the same calls; homoclinic.md's retrapping current, its curve in the damping
#: and the codimension-two point, test_homoclinic.py's quick tests on the same pendulum): slow tests.
SLOW_PAGES = {"studies.md", "roto-breathers.md", "periodic-orbits.md", "collocation.md", "homoclinic.md"}
#: A block that runs only in a page's slow case (the whole page), found by a line of it; the quick case runs the page's
#: other blocks. README's last block is the call test_report.py's quick test_table_numbers_equal_the_python_api makes
#: too (the paper chain's sine orbit at M = 0.22 followed down to its fold of cycles). statics.md's Fig. 2 block is
#: examples/fig2.py's calls, which test_examples.py runs quick (its load steps coarser).
SLOW_BLOCKS = {
    "README.md": 'result = periodic_orbit(ChainParams(), "sine", 0.22, down_to=0.1)',
    "statics.md": "sweeps = {m: relaxation_sweep(params, m, m_max=0.3, dm=0.01, down=True) for m in exact}",
}


def python_blocks(page: Path) -> list[str]:
    return re.findall(r"^```python\n(.*?)^```", page.read_text(encoding="utf-8"), flags=re.S | re.M)


def page_script(page: Path, every_block: bool) -> str:
    """The page's blocks as one script: every block, or all but its slow one (``SLOW_BLOCKS``)."""
    slow = SLOW_BLOCKS.get(page.name)
    return "\n\n".join(block for block in python_blocks(page) if every_block or slow is None or slow not in block)


def case_name(case: tuple[Path, bool]) -> str:
    """The page's name; ``-every-block`` added for the slow case of a page with a slow block."""
    page, every_block = case
    return f"{page.name}-every-block" if every_block and page.name in SLOW_BLOCKS else page.name


def _cases() -> list:
    cases = []
    for page in (page for page in PAGES if python_blocks(page)):
        if page.name in SLOW_BLOCKS:
            cases += [(page, False), pytest.param((page, True), marks=pytest.mark.slow)]
        else:
            cases.append(pytest.param((page, True), marks=pytest.mark.slow) if page.name in SLOW_PAGES else (page, True))
    return cases


def _needs_its_own_process(script: str) -> bool:
    """A page guarded by ``if __name__ == "__main__"`` starts worker processes that import the script again."""
    return "__main__" in script


@pytest.fixture(scope="module")
def page_runs(request, tmp_path_factory) -> dict[str, str | None]:
    """Page name -> None if its blocks ran as one script, else why not: the pages without a ``__main__`` guard in
    this process, one after the other, each guarded page in a fresh interpreter of its own, as a reader would run it
    (only the pages of the tests selected in this session)."""
    env = {**os.environ, "MPLBACKEND": "Agg", "PYTHONPATH": os.pathsep.join([str(ROOT / "src"), os.environ.get("PYTHONPATH", "")])}
    shared, own = {}, {}
    for case in selected_params(request, "case"):
        page, every_block = case
        text = page_script(page, every_block)
        if text:
            script = tmp_path_factory.mktemp(page.stem) / f"{page.stem}.py"
            script.write_text(text, encoding="utf-8")
            (own if _needs_its_own_process(text) else shared)[str(script)] = case_name(case)
    outcome = {}
    for script, name in shared.items():
        code, _, failure = run_script(script, Path(script).parent)
        outcome[name] = None if code == 0 else failure or f"it exited {code}"
    for script, name in own.items():
        alone = subprocess.run([sys.executable, script], cwd=Path(script).parent, env=env, capture_output=True, text=True, timeout=600)
        outcome[name] = None if alone.returncode == 0 else alone.stderr[-3000:]
    return outcome


@pytest.mark.parametrize("case", _cases(), ids=case_name)
def test_the_pages_python_blocks_run(case, page_runs):
    name = case_name(case)
    assert page_runs[name] is None, f"{name}: {page_runs[name]}"


def test_a_slow_block_is_one_block_of_its_page_and_the_quick_case_runs_the_others():
    for name, line in SLOW_BLOCKS.items():
        (page,) = (page for page in PAGES if page.name == name)
        assert sum(line in block for block in python_blocks(page)) == 1, name
        assert len(python_blocks(page)) > 1 and page_script(page, False).strip()
        assert line in page_script(page, True) and line not in page_script(page, False)


def test_a_page_that_fails_or_misses_an_import_is_reported_in_process(tmp_path):
    """The pages' namespaces are fresh: a name imported by an earlier page is not defined in a later one; each page runs
    in its own folder, and the test process's folder and command line are as they were."""
    first, second = tmp_path / "a" / "first.py", tmp_path / "b" / "second.py"
    for script, text in ((first, "import math, os\nprint(math.pi, os.getcwd())\n"), (second, "print(math.pi)\n")):
        script.parent.mkdir()
        script.write_text(text, encoding="utf-8")
    cwd, argv = os.getcwd(), sys.argv[:]
    assert run_script(first, first.parent) == (0, f"{math.pi} {first.parent}\n", None)
    code, printed, failure = run_script(second, second.parent)
    assert code == 1 and printed == "" and "NameError" in failure
    assert os.getcwd() == cwd and sys.argv == argv


def test_no_python_block_escapes_the_extraction():
    """An indented or unclosed block would silently not run: every ```python opening is one extracted block."""
    for page in PAGES:
        assert len(python_blocks(page)) == page.read_text(encoding="utf-8").count("```python"), page.name


def test_the_docs_site_builds_strictly(tmp_path):
    """MkDocs with mkdocstrings (numpy docstrings): every page, link and API entry resolves, no warning."""
    env = {**os.environ, "NO_MKDOCS_2_WARNING": "1", "PYTHONPATH": os.pathsep.join([str(ROOT / "src"), os.environ.get("PYTHONPATH", "")])}
    result = subprocess.run(
        [sys.executable, "-m", "mkdocs", "build", "--strict", "--site-dir", str(tmp_path / "site")],
        cwd=ROOT, env=env, capture_output=True, text=True, timeout=600,
    )  # fmt: skip
    assert result.returncode == 0, result.stderr[-3000:]
    api = (tmp_path / "site" / "api" / "index.html").read_text(encoding="utf-8")
    for name in ("critical_point", "localization_run", "ChainParams", "export"):
        assert name in api
