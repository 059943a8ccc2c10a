"""The map of static and rotating states against a parameter (issue 13): ``experiments.diagram``, ``cosserat-chain diagram``.

The edges are checked by independent computations: the static fold against a search at
each value, the loss of stability against the Floquet multipliers of orbits found on
their own just above and below it, and the SNIC against the static fold it must meet.
"""

from __future__ import annotations

import json

import numpy as np
import pytest
from typer.testing import CliRunner

from cosserat_chain import ChainParams
from cosserat_chain.cli import app
from cosserat_chain.experiments.diagram import ENDS, state_diagram
from cosserat_chain.experiments.orbits import periodic_orbit
from cosserat_chain.numerics.continuation import locate_fold
from cosserat_chain.numerics.periodic import find_periodic_orbit

runner = CliRunner()


def natural_continuation(chain: ChainParams, start: float, stop: float):
    """The orbit at ``stop`` by Newton from the orbit at ``start`` in short steps of M, each from the last
    (natural-parameter continuation: independent of the package's pseudo-arclength one)."""
    orbit = find_periodic_orbit(chain, "sine", start)
    for moment in np.linspace(start, stop, 12)[1:]:
        orbit = find_periodic_orbit(chain, "sine", moment, guess=orbit)
    return orbit


def test_the_sine_chains_loop_is_open_and_its_lower_edge_is_where_the_orbit_loses_stability():
    params = ChainParams()
    diagram = state_diagram(params, "sine", "gamma_phi", [0.1, 0.12])
    assert diagram.independent  # the statics do not read the viscosity
    for row in diagram.rows:
        chain = params.replace(gamma_phi=row.value)
        assert row.static_fold == pytest.approx(locate_fold(chain, "sine").moment, abs=1e-10)
        assert row.end in ("torus", "period_doubling") and row.hysteresis is True
        assert 0.16 < row.rotation_stops < row.static_fold
        # Stable just above the edge (Newton in short steps down from 1.1 M_c, on its own), and
        # the package's branch orbits below it unstable, their leading multiplier as named.
        assert natural_continuation(chain, 1.1 * row.static_fold, 1.03 * row.rotation_stops).stable
        branch = periodic_orbit(chain, "sine", 1.1 * row.static_fold, down_to=0.9 * row.rotation_stops).branch
        below = [o for o in branch.orbits if o.moment < row.rotation_stops]
        assert below and not below[0].stable and all(o.stable for o in branch.orbits if o.moment > 1.001 * row.rotation_stops)
    # The two damping values lose the orbit in different ways: a complex pair, then -1.
    assert [row.end for row in diagram.rows] == ["torus", "period_doubling"]


def test_where_no_stable_periodic_orbit_exists_above_the_fold_the_row_says_so():
    row = state_diagram(ChainParams(), "nonlinear", "E2", [1.0], turns=2).rows[0]
    assert row.end == "not_found" and row.rotation_stops is None and row.hysteresis is None
    assert "no stable periodic orbit" in row.message and "modulated" in row.message
    assert row.static_fold == pytest.approx(locate_fold(ChainParams(), "nonlinear").moment, abs=1e-12)


@pytest.mark.slow
def test_strong_damping_closes_the_loop_at_a_saddle_node_on_the_invariant_circle():
    params = ChainParams(gamma_phi=0.5)
    row = state_diagram(params, "sine", "gamma_phi", [0.5]).rows[0]
    assert row.end == "snic" and row.hysteresis is False
    assert row.rotation_stops == pytest.approx(row.static_fold, rel=1e-12)


def test_the_command_prints_rows_writes_the_file_and_draws_the_phase_diagram(tmp_path):
    out, png = tmp_path / "d.nc", tmp_path / "d.png"
    args = ["diagram", "--model", "sine", "--vary", "gamma_phi", "--range", "0.1:0.12:2", "--out", str(out), "--plot", str(png), "--json"]
    result = runner.invoke(app, args)
    assert result.exit_code == 0, result.output
    data = json.loads(result.output)
    assert data["parameter"] == "gamma_phi" and [r["value"] for r in data["rows"]] == [0.1, 0.12]
    assert all(r["end"] in ENDS for r in data["rows"]) and data["static_fold_independent_of_parameter"] is True
    assert out.stat().st_size > 0 and png.stat().st_size > 0
    from cosserat_chain.io import read_dataset

    ds = read_dataset(out)
    assert ds.attrs["experiment"] == "state_diagram" and list(ds["end"].values) == [r["end"] for r in data["rows"]]


def test_a_range_gives_the_decimal_values_without_linspace_noise():
    from cosserat_chain.cli.diagram import _values

    assert _values(None, "0.05:0.3:6") == [0.05, 0.1, 0.15, 0.2, 0.25, 0.3]
    assert _values(None, "1:1:1") == [1.0] and _values("0.1,0.3", None) == [0.1, 0.3]


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["--vary", "E2"], "--values V1,V2"),
        (["--vary", "E2", "--values", "1,x"], "--values must read"),
        (["--vary", "E2", "--values", "1", "--range", "1:2:3"], "one of them"),
        (["--vary", "E2", "--range", "1:2:0"], "NUM >= 1"),
        (["--vary", "N", "--values", "3,4"], "field must be one of"),
        (["--vary", "E2", "--values", "1", "--model", "linear"], "linear"),
    ],
)
def test_bad_options_are_refused(args, message):
    result = runner.invoke(app, ["diagram", *args])
    assert result.exit_code == 2 and message in result.output, result.output


def test_each_row_reads_its_moments_in_its_own_E1_h2_on_the_json_and_the_plot():
    """Varying h changes the unit E1 h^2 from row to row: the dimensionless edges and the plot use each row's."""
    from cosserat_chain.plots.diagram import diagram_figure

    params = ChainParams(E1=2.0)
    diagram = state_diagram(params, "nonlinear", "h", [1.0, 1.3], turns=1)
    for row, data in zip(diagram.rows, diagram.as_dict()["rows"]):
        chain = params.replace(h=row.value)
        assert data["moment_scale"] == pytest.approx(2.0 * row.value**2, rel=1e-15)
        assert data["static_fold_dimensionless"] == pytest.approx(locate_fold(chain, "nonlinear").moment / chain.moment_scale, rel=1e-9)
    curve = next(line for line in diagram_figure(diagram).axes[0].lines if line.get_label().startswith("M_c"))
    assert np.allclose(curve.get_ydata(), [r["static_fold_dimensionless"] for r in diagram.as_dict()["rows"]], rtol=1e-15)
    assert "E1 h^2" in diagram_figure(diagram).axes[0].get_ylabel()
