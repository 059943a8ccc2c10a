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
from cosserat_chain.experiments import diagram
from cosserat_chain.experiments.diagram import ENDS, state_diagram
from cosserat_chain.experiments.orbits import periodic_orbit
from cosserat_chain.models.base import get_model
from cosserat_chain.numerics.continuation import locate_fold
from cosserat_chain.numerics.periodic import continue_orbit, find_periodic_orbit
from static_onsets import nonlinear_critical

runner = CliRunner()


def natural_continuation(chain: ChainParams, start: float, stop: float):
    """The orbit at ``stop`` by Newton from the orbit at ``start`` in short steps of M, each from the last
    (natural-parameter continuation: independent of the package's pseudo-arclength one)."""
    orbit = find_periodic_orbit(chain, "sine", start)
    for moment in np.linspace(start, stop, 12)[1:]:
        orbit = find_periodic_orbit(chain, "sine", moment, guess=orbit)
    return orbit


#: The arguments of ``sine_loop``'s diagram.
SINE_LOOP = (ChainParams(), "sine", "gamma_phi", [0.1, 0.12])


@pytest.fixture(scope="module")
def sine_loop():
    """The paper's sine chain's diagram at two weak dampings."""
    return state_diagram(*SINE_LOOP)


def test_the_sine_chains_loop_is_open(sine_loop):
    assert sine_loop.independent  # the statics do not read the viscosity
    for row in sine_loop.rows:
        chain = ChainParams().replace(gamma_phi=row.value)
        assert row.static_fold == pytest.approx(locate_fold(chain, "sine").moment, abs=1e-10)
        assert row.end in ("torus", "period_doubling") and row.hysteresis is True and row.rotation_starts == "jump"
        assert 0.16 < row.rotation_stops < row.static_fold
    # The two damping values lose the orbit in different ways: a complex pair, then -1.
    assert [row.end for row in sine_loop.rows] == ["torus", "period_doubling"]


# The torus row's edge in the quick suite, the period-doubling row's with the slow tests.
@pytest.mark.parametrize("row_index", [0, pytest.param(1, marks=pytest.mark.slow)], ids=["torus", "period_doubling"])
def test_the_sine_chains_lower_edge_is_where_the_orbit_loses_stability(sine_loop, row_index, paper_sine_branch):
    row = sine_loop.rows[row_index]
    chain = ChainParams().replace(gamma_phi=row.value)
    # Stable just above the edge (Newton in short steps down from 1.1 M_c, on its own), and
    # the package's branch orbits below it unstable, their leading multiplier as named. The paper's chain (the torus
    # row) has its branch down to its fold in the session (conftest.py, from M = 0.22): the same continuation.
    assert natural_continuation(chain, 1.1 * row.static_fold, 1.03 * row.rotation_stops).stable
    if chain == paper_sine_branch.orbits[0].params:
        branch = paper_sine_branch
    else:
        branch = periodic_orbit(chain, "sine", 1.1 * row.static_fold, down_to=0.9 * row.rotation_stops).branch
    below = [o for o in branch.orbits if o.moment < row.rotation_stops]
    assert below and not below[0].stable and all(o.stable for o in branch.orbits if o.moment > 1.001 * row.rotation_stops)


def test_where_no_stable_periodic_orbit_exists_above_the_fold_the_row_says_so():
    row = state_diagram(ChainParams(), "nonlinear", "E2", [1.0], turns=2).rows[0]
    assert row.end == "not_found" and row.rotation_stops is None and row.hysteresis is None and row.rotation_starts is None
    assert "no stable periodic orbit" in row.message and "modulated" in row.message
    assert row.static_fold == pytest.approx(locate_fold(ChainParams(), "nonlinear").moment, abs=1e-12)


@pytest.mark.slow
def test_strong_damping_closes_the_loop_at_a_saddle_node_on_the_invariant_circle():
    params = ChainParams(gamma_phi=0.5)
    row = state_diagram(params, "sine", "gamma_phi", [0.5]).rows[0]
    assert row.end == "snic" and row.hysteresis is False
    assert row.rotation_stops == pytest.approx(row.static_fold, rel=1e-12)


def test_the_command_prints_rows_writes_the_file_and_draws_the_phase_diagram(tmp_path, monkeypatch, sine_loop):
    # The command asks for ``sine_loop``'s diagram (asserted: the same arguments, the defaults for the rest): it is
    # given that one rather than computing it again.
    from cosserat_chain.experiments import diagram

    calls = []

    def shared(params, model, field_name, values, progress=None, **options):
        calls.append(((params, model, field_name, list(values)), options))
        return sine_loop

    monkeypatch.setattr(diagram, "state_diagram", shared)
    out, png = tmp_path / "d.nc", tmp_path / "d.png"
    args = ["diagram", "--model", "sine", "--vary", "gamma_phi", "--range", "0.1:0.12:2", "--out", str(out), "--plot", str(png), "--json"]
    result = runner.invoke(app, args)
    assert result.exit_code == 0, result.output
    assert calls == [(SINE_LOOP, {"turns": 3, "period_max": diagram.PERIOD_MAX, "follow": False, "codim2": False})]
    data = json.loads(result.output)
    assert data["parameter"] == "gamma_phi" and [r["value"] for r in data["rows"]] == [0.1, 0.12]
    assert all(r["end"] in ENDS for r in data["rows"]) and data["static_fold_independent_of_parameter"] is True
    assert out.stat().st_size > 0 and png.stat().st_size > 0
    from cosserat_chain.io import read_dataset

    ds = read_dataset(out)
    assert ds.attrs["experiment"] == "state_diagram" and list(ds["end"].values) == [r["end"] for r in data["rows"]]
    assert list(ds["method"].values) == [r["method"] for r in data["rows"]] == ["located", "located"]
    assert list(ds["rotation_starts"].values) == [r["rotation_starts"] for r in data["rows"]] == ["jump", "jump"]


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


# --------------------------------------------------------------------------- N = 1: a damped, driven pendulum
def holds_the_pendulums_homoclinic(j: float, gamma: float, c: float, value: float, accuracy: float) -> bool:
    """Whether M_h of j phi'' + gamma phi' + c sin(phi) = M lies within ``accuracy`` of ``value``.

    Independent of the package: from the saddle phi_s = pi - arcsin(M / c), along its
    unstable direction, the trajectory either reaches the next saddle phi_s + 2 pi (M above
    M_h: rotation survives) or turns back (below); the fate changes once, at M_h.
    """
    from scipy.integrate import solve_ivp

    def rotates(moment: float) -> bool:
        saddle = np.pi - np.arcsin(moment / c)
        rate = (-gamma + np.sqrt(gamma**2 - 4 * j * c * np.cos(saddle))) / (2 * j)
        eps = 1e-9

        def back(t, y):
            return y[1]

        def over(t, y):
            return y[0] - saddle - 2 * np.pi

        back.terminal = over.terminal = True
        back.direction, over.direction = -1, 1
        # DOP853: at rtol 1e-12 the eighth-order pair takes a fraction of RK45's steps.
        run = solve_ivp(
            lambda t, y: [y[1], (moment - gamma * y[1] - c * np.sin(y[0])) / j],
            (0.0, 200.0), [saddle + eps, rate * eps], events=(back, over), method="DOP853", rtol=1e-12, atol=1e-14,
        )  # fmt: skip
        return run.t_events[1].size > 0

    return rotates(value + accuracy) and not rotates(value - accuracy)


@pytest.mark.parametrize("gamma", [0.02, pytest.param(0.05, marks=pytest.mark.slow)])
def test_the_one_particle_sine_chain_stops_rotating_at_the_pendulums_homoclinic_orbit(gamma, monkeypatch):
    """N = 1: the sine model is j phi'' + gamma_phi phi' + M_c sin(phi) = M (u and v decouple). A weakly
    damped pendulum's rotation ends at a homoclinic orbit, where its period grows only like -log(M - M_h)
    (T = 4 at M - M_h = 1e-8): found from that growth, not a period cap. Against the manifold's fate above, and
    against Melnikov's small-damping asymptotics M_h = (4 / pi) gamma sqrt(M_c / j) (1 - k alpha^2),
    alpha = gamma / sqrt(j M_c), whose first correction k lies near 0.245 (measured)."""
    params = ChainParams(N=1, gamma_phi=gamma)
    traced = _traced_branches(monkeypatch)
    row = state_diagram(params, "sine", "gamma_phi", [gamma]).rows[0]
    c = row.static_fold
    assert row.end == "homoclinic" and row.hysteresis is True
    # The loop is solved in the bracket of the scouting branch's fit: the branch is not traced again.
    assert traced == [diagram.SCOUT["tol"]]
    # The end is solved (the loop homoclinic to the saddle, projection boundary conditions: issue 40 item 3), with an
    # accuracy that covers its error; the fit of the period's growth it replaces is in the message.
    assert row.method == "solved" and "solved by projection boundary conditions" in row.message and "the fit" in row.message
    assert holds_the_pendulums_homoclinic(params.j, gamma, c, row.rotation_stops, row.uncertainty)
    assert row.uncertainty <= 1e-9 * row.rotation_stops
    assert row.as_dict()["rotation_stops_uncertainty"] == row.uncertainty
    alpha = gamma / np.sqrt(params.j * c)
    melnikov = 4 / np.pi * gamma * np.sqrt(c / params.j)
    assert 0.2 * alpha**2 < 1 - row.rotation_stops / melnikov < 0.3 * alpha**2


def _traced_branches(monkeypatch) -> list:
    """The closure tolerance of every orbit branch the diagram traces (None: the package's full accuracy), as it goes."""
    traced = []

    def spy(orbit, **kwargs):
        traced.append(kwargs.get("tol"))
        return continue_orbit(orbit, **kwargs)

    monkeypatch.setattr(diagram, "continue_orbit", spy)
    return traced


@pytest.mark.slow
@pytest.mark.parametrize("gamma", [0.01, 0.02, 0.05])
def test_a_homoclinic_end_solved_from_the_scouting_branch_is_the_accurate_branchs(gamma, monkeypatch):
    # The row's loop is solved once, in the bracket of the scouting branch's fit; the branch traced again at full
    # accuracy, as the diagram did before, brackets and solves the same loop, to far below the solve's accuracy.
    params = ChainParams(N=1, gamma_phi=gamma)
    seen = []
    edge_of_branch = diagram._edge_of_branch

    def spy(orbit, branch, *args):
        seen.append((orbit, args))
        return edge_of_branch(orbit, branch, *args)

    monkeypatch.setattr(diagram, "_edge_of_branch", spy)
    row = state_diagram(params, "sine", "gamma_phi", [gamma]).rows[0]
    assert row.method == "solved" and len(seen) == 1
    orbit, args = seen[0]
    period_max = args[4]
    accurate = edge_of_branch(orbit, continue_orbit(orbit, moment_min=0.0, period_max=period_max, until_unstable=True), *args)
    assert accurate.method == "solved" and accurate.uncertainty == row.uncertainty
    assert abs(accurate.stops - row.rotation_stops) <= 1e-3 * row.uncertainty


def test_the_strongly_damped_pendulum_closes_its_loop_at_a_snic():
    """Above alpha = gamma / sqrt(j M_c) of about 1.19 the pendulum's homoclinic orbit has met the static
    fold: the rotation ends at M_c with a period diverging like (M - M_c)^(-1/2), no hysteresis."""
    params = ChainParams(N=1, gamma_phi=0.2)  # alpha = 1.79
    row = state_diagram(params, "sine", "gamma_phi", [0.2]).rows[0]
    assert row.end == "snic" and row.hysteresis is False and row.rotation_stops == row.static_fold
    assert row.rotation_starts == "snic" and row.as_dict()["rotation_starts"] == "snic"


def test_an_orbit_losing_stability_above_the_static_fold_leaves_the_loop_unknown():
    """Above M_c no static state exists, so the rotation cannot stop there: the sine chain at
    gamma_phi = 0.3 period-doubles at 0.2105 > M_c and the row says the loop is not known."""
    row = state_diagram(ChainParams(), "sine", "gamma_phi", [0.3]).rows[0]
    assert row.end == "period_doubling" and row.rotation_stops > row.static_fold
    assert row.hysteresis is None and "not followed" in row.message


def test_the_snic_point_extrapolates_the_closing_gap_linearly_in_its_square_root():
    """Synthetic rows with (M_c - M_h) / M_c = (2 - p)^2 / 16 exactly: the point is p* = 2."""
    from cosserat_chain.experiments.diagram import DiagramRow, StateDiagram

    def row(p, end):
        stops = 1.0 - (2.0 - p) ** 2 / 16 if end == "homoclinic" else 1.0
        return DiagramRow(p, 1.0, 1.0, stops, end, end == "homoclinic")

    diagram = StateDiagram(ChainParams(), "sine", "gamma_phi", 3, [row(1.0, "homoclinic"), row(1.5, "homoclinic"), row(2.5, "snic")])
    assert diagram.snic_point["value"] == pytest.approx(2.0, rel=1e-12)
    assert diagram.snic_point["between"] == [1.5, 2.5]
    diagram.rows[-1] = row(1.8, "snic")  # the extrapolated point would lie beyond the SNIC row
    assert diagram.snic_point["method"] == "not_located" and diagram.snic_point["value"] is None


@pytest.mark.slow
def test_the_pendulums_homoclinic_end_meets_the_static_fold_at_the_known_damping():
    """N = 1: alpha* = gamma_phi / sqrt(j M_c) where the homoclinic end becomes a SNIC, for phi'' + alpha phi' +
    sin(phi) = beta 1.1930459188 as solved by the augmented system and Lin's method (tests/test_homoclinic.py;
    the often-quoted 1.1925 is off in its fourth digit): the diagram's point solved to its accuracy, and its
    fallback, the extrapolation from two rows, within 1e-3."""
    params = ChainParams(N=1)
    scale = np.sqrt(params.j * locate_fold(params, "sine").moment)
    diagram = state_diagram(params, "sine", "gamma_phi", [1.1 * scale, 1.15 * scale, 1.25 * scale])
    assert [row.end for row in diagram.rows] == ["homoclinic", "homoclinic", "snic"]
    assert diagram.extrapolated_snic_point()["value"] / scale == pytest.approx(1.1930459188, rel=1e-3)
    point = diagram.snic_point
    assert point["method"] == "solved" and abs(point["value"] / scale - 1.1930459188) <= max(point["accuracy"] / scale, 1e-9)


@pytest.mark.parametrize("ends", [{}, {"right_end": "free"}, {"left_end": "pinned", "right_end": "pinned"}])
def test_each_rows_M_c_is_where_the_stable_branch_from_rest_ends_as_critical_says(ends):
    """The nonlinear cantilever's stable branch ends at a branch point (M = 0.08198) before its fold
    (0.08375): the diagram's M_c is the branch point's, as ``critical``'s; other ends keep the fold."""
    from cosserat_chain.experiments.diagram import _static_onset
    from cosserat_chain.numerics.fold_curve import continue_fold

    chain = ChainParams(**ends)
    fold = continue_fold(chain, "nonlinear", "E2", [1.0])
    moment, phi0, note = _static_onset(chain, get_model("nonlinear"), 0, float(fold.moment[0]), float(fold.phi0[0]))
    reference = nonlinear_critical(chain)
    assert moment == pytest.approx(reference.critical_moment, rel=1e-9)
    assert phi0 == pytest.approx(reference.phi0_at_onset, rel=1e-6)
    assert (reference.onset == "branch_point") == bool(note) == (moment < float(fold.moment[0]))
    if ends == {"right_end": "free"}:
        assert "branch point" in note and moment == pytest.approx(0.08198, abs=1e-5)
