"""The modules the report's background stages import are imported before the fork (report.background.IMPORTS)."""

from __future__ import annotations

import importlib.util
import inspect
import re

from cosserat_chain.report import background, stages


def test_every_background_stage_names_the_modules_its_function_imports():
    assert set(background.IMPORTS) == set(background.BACKGROUND)
    for name, modules in background.IMPORTS.items():
        source = inspect.getsource(stages.STAGES[name])
        imported = {"cosserat_chain." + m for m in re.findall(r"from \.\.([\w.]+) import", source)}
        assert imported == set(modules), name


def test_the_imports_before_the_fork_exist():
    for module in [*background.SHARED_IMPORTS, *(m for modules in background.IMPORTS.values() for m in modules)]:
        assert importlib.util.find_spec(module) is not None, module
