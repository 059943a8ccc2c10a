"""Is the diagram's fold of cycles the edge of rotation? (issue 40: coexisting orbits, an edge where the rotation goes on)

Below a fold of cycles the followed orbit no longer exists; the chain may come to rest there, or jump onto another
rotating orbit. The diagram runs the chain just below the fold from the fold's orbit and says which, follows the new
orbit where there is one, and warns where it cannot. Checked against runs of another integrator (Yoshida-4 at a fixed
step, not the relaxation protocol the diagram uses) from an orbit near the fold from the package's continuation, on
a light N = 2 sine chain whose first orbit's fold is not the edge and on the paper's N = 2 chain at gamma_phi = 0.15,
whose fold is.
"""

from __future__ import annotations

import json

import pytest
from typer.testing import CliRunner

from cosserat_chain import ChainParams
from cosserat_chain.cli import app
from cosserat_chain.experiments import diagram as diagram_module
from cosserat_chain.experiments.diagram import state_diagram
from cosserat_chain.experiments.orbits import periodic_orbit
from cosserat_chain.loads import moment_load
from cosserat_chain.numerics.continuation import locate_fold
from cosserat_chain.numerics.dynamics import integrate
from cosserat_chain.state import ROW_INDEX

#: The light chain (the issue's masses and dampings, the paper's geometry).
LIGHT = {"N": 2, "m": 0.01, "j": 0.05, "gamma_u": 0.05, "gamma_v": 0.05, "gamma_phi": 0.03}


def orbit_near(chain: ChainParams, fold: float):
    """The stable orbit nearest the fold, from the continuation down from 1.1 M_c (the package's, not the diagram's check)."""
    branch = periodic_orbit(chain, "sine", 1.1 * locate_fold(chain, "sine").moment, turns=1, down_to=0.5 * fold).branch
    return min((o for o in branch.orbits if o.stable), key=lambda o: abs(o.moment - fold))


def late_rate(chain: ChainParams, orbit, moment: float, t_end: float) -> float:
    """Mean angular velocity of the loaded particle over the last quarter of a run from ``orbit``'s state at ``moment``."""
    run = integrate(chain, "sine", moment_load(moment), t_end=t_end, x0=orbit.x, v0=orbit.v, method="yoshida4", n_frames=5)
    phi = run.x[:, ROW_INDEX["phi"], chain.N]
    return float((phi[-1] - phi[-2]) / (run.time[-1] - run.time[-2]))


@pytest.fixture(scope="module")
def light_row():
    return state_diagram(ChainParams(**LIGHT), "sine", "gamma_phi", [LIGHT["gamma_phi"]]).rows[0]


def test_where_the_chain_jumps_to_another_orbit_below_the_fold_the_row_follows_that_one(light_row):
    chain, row = ChainParams(**LIGHT), light_row
    first, second = row.followed
    assert first["end"] == "fold_of_cycles" and first["below"] == "rotating"
    assert second["found_at"] == pytest.approx(0.99 * first["rotation_stops"], rel=1e-12)
    assert row.rotation_stops == second["rotation_stops"] < first["rotation_stops"] < row.static_fold
    assert row.end == second["end"] and row.warning == "" and "goes on to a 1-turn orbit" in row.message
    # Independently: just above the fold the first orbit turns at its own rate; a run from it below the fold keeps
    # turning, at another rate (the second orbit's), half way down to the second orbit's end.
    fold = first["rotation_stops"]
    near = orbit_near(chain, fold)
    below = 0.5 * (fold + row.rotation_stops)
    rate = late_rate(chain, near, below, 400.0)
    assert rate > 0.5 * second["mean_angular_velocity"]
    assert abs(rate - near.mean_angular_velocity) > 0.1 * near.mean_angular_velocity


def test_the_relaxation_protocols_down_sweep_stops_at_the_rows_edge_not_at_the_first_fold(light_row):
    """The paper's protocol (relax at each step of a falling load, from the last state) rotates on past the first
    orbit's fold and comes to rest within two steps below the row's edge (just below a period doubling the doubled
    orbit still turns)."""
    from cosserat_chain.experiments.sweep import relaxation_sweep

    dm = 0.0025
    sweep = relaxation_sweep(ChainParams(**LIGHT), "sine", m_max=0.3, dm=dm, down=True, stop_at_onset=True)
    fold = light_row.followed[0]["rotation_stops"]
    assert light_row.rotation_stops - 2 * dm <= sweep.stop_load < light_row.rotation_stops < fold - 5 * dm


def test_where_the_chain_rests_below_the_fold_the_fold_is_the_edge():
    chain = ChainParams(N=2, gamma_phi=0.15)
    row = state_diagram(chain, "sine", "gamma_phi", [0.15]).rows[0]
    assert row.end == "fold_of_cycles" and row.below == "rest" and row.rotation_continues_below is False
    assert len(row.followed) == 1 and row.warning == "" and "the fold is the edge of rotation" in row.message
    assert row.as_dict()["rotation_continues_below"] is False and row.as_dict()["warning"] is None
    near = orbit_near(chain, row.rotation_stops)
    assert abs(late_rate(chain, near, 0.99 * row.rotation_stops, 1500.0)) < 1e-6


def test_where_the_next_orbit_is_not_followed_the_fold_is_flagged_and_warned(tmp_path, monkeypatch):
    """With one orbit allowed, the light chain's row keeps its fold and says in the JSON and the text that it is not the edge."""
    monkeypatch.setattr(diagram_module, "MAX_ORBITS", 1)
    (tmp_path / "light.toml").write_text("".join(f"{key} = {value}\n" for key, value in LIGHT.items()))
    command = ["diagram", "--model", "sine", "--vary", "gamma_phi", "--values", "0.03", "--config", str(tmp_path / "light.toml")]
    result = CliRunner().invoke(app, [*command, "--json"])
    assert result.exit_code == 0, result.output
    row = json.loads(result.stdout)["rows"][0]
    assert row["end"] == "fold_of_cycles" and row["below_edge"] == "rotating" and row["rotation_continues_below"] is True
    assert "the fold ends one orbit, not the rotation" in row["warning"]
    text = CliRunner().invoke(app, command)
    assert text.exit_code == 0 and "warning: gamma_phi = 0.03: below the fold of cycles" in text.output
