"""The help texts, the API reference and the README say what is true (issue 43, item 6)."""

from __future__ import annotations

import importlib
import re
from pathlib import Path

import pytest
import typer
from typer.testing import CliRunner

import cosserat_chain
from cosserat_chain.cli import app

ROOT = Path(__file__).resolve().parents[1]
COMMANDS = typer.main.get_command(app).commands
#: A TOML table name in a help text: ``[[loads]]``, ``[reproduce]``, ``[disorder]``.
TABLE = re.compile(r"\[\[?[a-z_]+\]\]?")


def written_help(command) -> str:
    """Everything the source says in a command's help: its docstring and every option's help."""
    return "\n".join([command.help or "", *(getattr(p, "help", None) or "" for p in command.params)])


def rendered_help(name: str) -> str:
    result = CliRunner().invoke(app, [name, "--help"], terminal_width=200)
    assert result.exit_code == 0, result.output
    return result.output


@pytest.mark.parametrize("name", sorted(COMMANDS))
def test_every_help_renders_the_toml_table_names_it_is_written_with(name):
    tables = set(TABLE.findall(written_help(COMMANDS[name])))
    shown = rendered_help(name)
    assert {table for table in tables if table not in shown} == set()
    assert "[]" not in shown


def test_the_commands_that_take_load_tables_name_them_in_their_help():
    for name in ("simulate", "rotate", "sweep"):
        assert "[[loads]]" in rendered_help(name), name
    assert "[reproduce]" in rendered_help("reproduce")


def test_rotate_help_states_the_exit_code_its_time_limit_gives(tmp_path, monkeypatch):
    """The command's exit code in this interpreter (the one ``python -m cosserat_chain`` passes on: test_api.py)."""
    shown = " ".join(rendered_help("rotate").split())
    stated = re.search(r"(\d+) --t-max reached", shown)
    assert stated is not None, shown
    monkeypatch.chdir(tmp_path)
    result = CliRunner().invoke(app, ["rotate", "--moment", "0.3", "--turns", "100", "--t-max", "5"])
    assert result.exit_code == int(stated.group(1)) == 4, result.output[-2000:]
    assert "time_limit" in result.stderr


def api_entries() -> list[tuple[str, str, bool]]:
    """(module, name, whether the page says it is top-level) for every ``:::`` entry of docs/api.md."""
    entries, top_level = [], True
    for line in (ROOT / "docs" / "api.md").read_text(encoding="utf-8").splitlines():
        if line.startswith("## "):
            top_level = line not in ("## More from the modules", "## Plotting")
        elif line.startswith("::: "):
            module, name = line[4:].strip().rsplit(".", 1)
            entries.append((module, name, top_level))
    return entries


def test_the_api_reference_has_the_top_level_names_and_the_plots():
    entries = api_entries()
    assert len(entries) > 40
    assert any(module.startswith("cosserat_chain.plots.") for module, _, _ in entries)
    assert {"diagram_figure", "figure2", "snapshot_figure", "animate"} <= {name for _, name, _ in entries}


@pytest.mark.parametrize("module, name, top_level", api_entries(), ids=lambda v: v if isinstance(v, str) and "." not in v else None)
def test_every_name_of_the_api_reference_imports_as_the_page_says(module, name, top_level):
    target = getattr(importlib.import_module(module), name)
    if top_level:
        assert name in cosserat_chain.__all__
        assert getattr(cosserat_chain, name) is target


def test_the_readme_names_only_files_the_main_job_writes():
    """The main job is ``reproduce --out results/paper``: every ``results/...`` the README names lies in that
    folder and is one of the report's pages."""
    text = (ROOT / "README.md").read_text(encoding="utf-8")
    named = set(re.findall(r"results/[\w./-]*\w", text))
    assert "results/paper" in named
    assert named <= {"results/paper", "results/paper/index.html", "results/paper/report.md", "results/paper/summary.json"}, named


def test_the_frequencies_say_they_are_angular_next_to_the_harmonic_schedule():
    from cosserat_chain.analysis.dispersion import Modes
    from cosserat_chain.loads import Schedule

    assert "omega / (2 pi)" in Modes.frequencies.__doc__
    assert "omega / (2 pi)" in Schedule.harmonic.__doc__
    page = (ROOT / "docs" / "api.md").read_text(encoding="utf-8")
    assert "omega / (2 * pi)" in page
