"""Docstrings and comments say why once: measured timings live in ``benchmarks/TIMINGS.md``, not in the code.

A choice made for speed keeps its reason in the code and points to the page that holds the
measurement, so that a number measured once, on one machine, is not read as a property of
the code. The scan reads every comment (:mod:`tokenize`) and every docstring (:mod:`ast`:
string statements, which include attribute docstrings) of the package.
"""

from __future__ import annotations

import ast
import io
import re
import tokenize
from pathlib import Path

import pytest

import cosserat_chain

PACKAGE = Path(cosserat_chain.__file__).parent
ROOT = PACKAGE.parents[1]
TIMINGS = "benchmarks/TIMINGS.md"

#: A measured time or speed ratio: "52 -> 37 us", "0.5 s at N = 1000", "4.5 s of CPU", "3-10x slower",
#: "10 % faster", "took 15 minutes". Counts of steps or points, orders (O(N^2)) and tolerances do not match.
MEASURED = re.compile(
    r"\b\d+(?:\.\d+)?\s?(?:ms|us|µs)\b"
    r"|\b\d+(?:\.\d+)?\s?s (?:at|of CPU|each|a point|an orbit|for)\b"
    r"|\b\d+(?:\.\d+)? (?:seconds|minutes|hours)\b"
    r"|\b\d+(?:\.\d+)?x (?:faster|slower)\b|\b\d+(?:\.\d+)?x;"
    r"|\b\d+(?:\.\d+)? % (?:faster|slower|on the)\b"
)


def notes(source: str) -> list[tuple[int, str]]:
    """(line, text) of every comment and docstring of a module's source."""
    found = [(tok.start[0], tok.string) for tok in tokenize.generate_tokens(io.StringIO(source).readline) if tok.type == tokenize.COMMENT]
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, ast.Expr) and isinstance(node.value, ast.Constant) and isinstance(node.value.value, str):
            found.append((node.lineno, node.value.value))
    return found


def measured_timings(source: str) -> list[tuple[int, str]]:
    return sorted((line, match.group(0)) for line, text in notes(source) for match in MEASURED.finditer(" ".join(text.split())))


def test_the_scan_finds_a_timing_in_a_comment_and_a_docstring_and_not_in_code():
    source = (
        '"""A module (the factor 0.106 -> 0.086 ms at N = 1000)."""\n'
        "x = 1  # two threads were 3-10x slower than one\n"
        "def f():\n"
        '    """Slow: LAPACK took 0.5 s\n    at N = 1000."""\n'
        '    return f"{x} ms"\n'
        "y = 2 * 3  # O(N^2), 12 steps, 1e-9\n"
    )
    assert [text for _, text in measured_timings(source)] == ["0.086 ms", "10x slower", "0.5 s at"]


@pytest.mark.parametrize("path", sorted(PACKAGE.rglob("*.py")), ids=lambda p: str(p.relative_to(PACKAGE)))
def test_no_comment_or_docstring_quotes_a_measured_timing(path):
    found = measured_timings(path.read_text(encoding="utf-8"))
    assert not found, f"{path.name}: measured timings in the code {found}; move them to {TIMINGS} and point there"


def test_every_pointer_to_the_timings_page_names_a_page_that_lists_its_module():
    page = (ROOT / TIMINGS).read_text(encoding="utf-8")
    pointing = sorted(
        str(path.relative_to(PACKAGE)) for path in PACKAGE.rglob("*.py") if TIMINGS in " ".join(path.read_text(encoding="utf-8").split())
    )
    assert len(pointing) >= 10
    missing = [module for module in pointing if f"`{module}" not in page and f"`{module.split('/')[-1]}" not in page]
    assert not missing, f"these modules point to {TIMINGS}, which has no entry for them: {missing}"
