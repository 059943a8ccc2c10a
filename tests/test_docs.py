"""Every Python block of README.md and docs/*.md runs as written (issue 16, item 2).

The blocks of one file run in order as one script (later blocks may use what earlier
ones made), as ``__main__``, in a fresh folder, with matplotlib's non-interactive
backend: what a reader who copies them gets.
"""

from __future__ import annotations

import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PAGES = [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]


def python_blocks(page: Path) -> list[str]:
    return re.findall(r"^```python\n(.*?)^```", page.read_text(encoding="utf-8"), flags=re.S | re.M)


@pytest.mark.parametrize("page", [p for p in PAGES if python_blocks(p)], ids=lambda p: p.name)
def test_the_pages_python_blocks_run(page, tmp_path):
    script = tmp_path / f"{page.stem}.py"
    script.write_text("\n\n".join(python_blocks(page)), encoding="utf-8")
    env = {**os.environ, "MPLBACKEND": "Agg", "PYTHONPATH": os.pathsep.join([str(ROOT / "src"), os.environ.get("PYTHONPATH", "")])}
    result = subprocess.run([sys.executable, str(script)], cwd=tmp_path, env=env, capture_output=True, text=True, timeout=600)
    assert result.returncode == 0, f"{page.name}: {result.stderr[-3000:]}"


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
