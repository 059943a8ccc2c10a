"""What makes ``reproduce`` cheaper leaves its results as they were (issue 44 item 1).

The state diagram's rows bracket their end by a continuation at looser tolerances
(``diagram.SCOUT``) and locate it at full accuracy; an end read from the branch itself is
traced again at full accuracy. The background process imports nothing the first writes need
that the main process did not import before the fork.
"""

from __future__ import annotations

import subprocess
import sys
import textwrap

import pytest

from cosserat_chain import ChainParams
from cosserat_chain.experiments import diagram

#: The paper's chain at gamma_phi = 0.2: the sine model's rotation stops at a fold of cycles (a cheap row).
ROW = 0.2

#: The row's continuations by their start and options, traced once for this module's tests: the same start and options
#: give the same branch, and both tests trace the loose and the accurate branch from the row's first orbit.
_TRACED: dict = {}


@pytest.fixture
def calls(monkeypatch) -> list[dict]:
    """The options of each ``continue_orbit`` call the diagram makes, each continuation traced once a module."""
    made, continue_orbit = [], diagram.continue_orbit

    def recorded(orbit, **options):
        made.append(options)
        key = (orbit.moment, orbit.period, orbit.x.tobytes(), orbit.v.tobytes(), tuple(sorted(options.items())))
        if key not in _TRACED:
            _TRACED[key] = continue_orbit(orbit, **options)
        return _TRACED[key]

    monkeypatch.setattr(diagram, "continue_orbit", recorded)
    return made


@pytest.mark.usefixtures("calls")
def test_the_loose_continuation_locates_the_same_edge_as_the_accurate_one(monkeypatch):
    paper = ChainParams()
    scouted = diagram.state_diagram(paper, "sine", "gamma_phi", [ROW]).rows[0]
    monkeypatch.setattr(diagram, "SCOUT", {})
    accurate = diagram.state_diagram(paper, "sine", "gamma_phi", [ROW]).rows[0]
    assert scouted.method == accurate.method == "located"
    assert (scouted.end, scouted.below) == (accurate.end, accurate.below) == ("fold_of_cycles", "rest")
    # Both are the augmented system's solution at full tolerances, from different orbits nearby.
    assert scouted.rotation_stops == pytest.approx(accurate.rotation_stops, rel=1e-11)


def test_an_end_read_from_the_loose_branch_is_traced_again_at_full_accuracy(monkeypatch, calls):
    """Where the end cannot be located its value is the branch's own estimate: that branch must be the accurate one.

    Each continuation is traced once for its start and options (``calls``: the row without the loose one asks for the
    accurate branch again, as the first row's second call did, and the test above traced both)."""

    def unlocatable(*args, **kwargs):
        raise ValueError("not located in this test")

    monkeypatch.setattr(diagram, "locate_cycle_end", unlocatable)
    row = diagram.state_diagram(ChainParams(), "sine", "gamma_phi", [ROW]).rows[0]
    assert row.method == "one_parameter" and "not located exactly" in row.message
    assert [set(diagram.SCOUT) <= set(options) for options in calls] == [True, False]
    assert not {"rtol", "atol", "tol", "step"} & set(calls[1])
    # The value is the accurate branch's: the same as with no loose continuation at all.
    monkeypatch.setattr(diagram, "SCOUT", {})
    calls.clear()
    assert diagram.state_diagram(ChainParams(), "sine", "gamma_phi", [ROW]).rows[0].rotation_stops == row.rotation_stops


def test_after_the_first_writes_a_dataset_and_a_figure_import_nothing_more():
    """What the report's background process would otherwise import again after the fork (report.background)."""
    script = textwrap.dedent(
        """
        import io, sys
        import numpy as np, xarray as xr
        from matplotlib.figure import Figure
        from cosserat_chain.io import netcdf_image
        from cosserat_chain.report import background
        background._first_writes()
        before = set(sys.modules)
        netcdf_image(xr.Dataset({"v": (("t",), np.arange(3.0))}, coords={"t": [0.0, 1.0, 2.0]}, attrs={"model": "sine"}))
        figure = Figure(figsize=(2, 2))
        figure.subplots().plot([0, 1], [1, 0], label="a")
        for kind in ("png", "svg"):
            figure.savefig(io.BytesIO(), format=kind)
        print(sorted(name for name in set(sys.modules) - before if not name.startswith("cosserat_chain")))
        """
    )
    out = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, check=True).stdout
    assert out.strip() == "[]"
