"""The pen demo's state diagram at one eps with the defaults, computed once a session for each eps: the row's test of
``tests/test_system_diagram.py``, and the ``diagram --system pen`` commands of that file and of
``tests/test_cf_files.py``, which are given it in place of their own call of ``system_diagram`` (the same system, values
and defaults, asserted by :func:`assert_the_pen_loops_call`; the command's parsing, JSON and file as before)."""

from __future__ import annotations

import functools

import numpy as np

from cosserat_chain.experiments.system_diagram import PERIOD_MAX, system_diagram
from cosserat_chain.systems.pen import pen


@functools.cache
def pen_loop(eps: float):
    """``system_diagram(pen(), "eps", [eps], "I")``: its defaults (the function itself, bound here: the stand-in below
    replaces the module's name while a command runs)."""
    return system_diagram(pen(), "eps", [eps], "I")


def pen_loop_given(eps: float, calls: list):
    """A stand-in for ``system_diagram`` that records each call's arguments in ``calls`` and gives ``pen_loop(eps)``."""

    def given(system, vary, values, drive, **options):
        calls.append((system.describe(), vary, list(values), drive, options))
        return pen_loop(eps)

    return given


def assert_the_pen_loops_call(call: tuple, eps: float) -> None:
    """The recorded call is ``pen_loop(eps)``'s: the pen demo, ``eps`` varied over ``[eps]``, ``I`` driven, the defaults."""
    system, vary, values, drive, options = call
    assert (system, vary, values, drive) == (pen().describe(), "eps", [eps], "I")
    assert options["turns"] == pen_loop(eps).turns == {"phi_0": 1, "phi_1": 1}
    assert np.array_equal(options["start"], np.zeros(2)) and options["period_max"] == PERIOD_MAX
    assert options["codim2"] is False
