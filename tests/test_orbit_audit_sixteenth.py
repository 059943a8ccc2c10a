"""The sixteenth audit of the orbit machinery (H16audit): defects found on cases outside the other tests.

``orbit --down-to`` by shooting reported a fold of cycles at the parabola through the three orbits around the turn,
printed with 17 digits: on a clamped-pinned N = 3 sine chain loaded at its pinned end 0.3033010370, where the
collocation's branch and the augmented system both give 0.3033015372 (5.0e-7 apart). The fold is now located by the
augmented shooting system, as the diagram's rows locate theirs.

Next to a homoclinic orbit single shooting's monodromy loses its trivial multiplier (1.95 at T = 10.3 on the N = 1 sine
chain, ||M|| ~ 1e6): taken with the multiplier nearest +1 for the trivial one, the stable orbit read as unstable, and
``diagram --vary gamma_phi --values 0.1`` on N = 1 said branch_point_of_cycles at 0.4290037, below the pendulum's
homoclinic end 0.4290033951 (an intermediate state of the sixteenth session, never committed).

A branch whose first orbit's period already exceeds ``period_max`` ended at once, ``infinite_period``, "it diverges
(homoclinic end)": a clamped-free N = 4 sine chain at 1.25 M_c (T = 2612 > 2000) claimed a homoclinic end at its start.
"""

from __future__ import annotations

import pytest
from typer.testing import CliRunner

from cosserat_chain import ChainParams
from cosserat_chain.cli import app
from cosserat_chain.experiments.diagram import state_diagram
from cosserat_chain.experiments.orbits import periodic_orbit
from test_diagram import holds_the_pendulums_homoclinic

#: A random admissible chain of the audit (seed 8): clamped-pinned, loaded at the pinned end.
PINNED = ChainParams(
    N=3, h=1.3924, a=0.2724, b=0.3366, E1=1.8048, E2=0.8431, m=1.1568, gamma_u=0.2177, gamma_v=0.0981, gamma_phi=0.2655,
    j=0.0331, left_end="clamped", right_end="pinned",
)  # fmt: skip


@pytest.mark.slow
def test_the_shootings_fold_of_cycles_is_the_collocations_located_fold():
    shooting = periodic_orbit(PINNED, "sine", 0.3219, particle=3, down_to=0.0966).branch
    collocation = periodic_orbit(PINNED, "sine", 0.3219, particle=3, down_to=0.0966, method="collocation").branch
    assert shooting.end == collocation.end == "fold"
    assert "located at M" in shooting.message
    # Two independent discretisations of the same fold: 5.5e-11 apart (the parabola was 5.0e-7 off).
    assert shooting.end_moment == pytest.approx(collocation.end_moment, abs=1e-9)
    # The fold is the branch's least M: every orbit traced lies above it.
    assert min(o.moment for o in shooting.orbits) >= shooting.end_moment


@pytest.mark.slow
def test_the_pendulums_diagram_row_at_gamma_0_1_ends_at_its_homoclinic_orbit():
    # The row of docs/state-diagram's pendulum table at gamma_phi = 0.1 (alpha = 0.9), against the bisection on the
    # saddle's unstable manifold (tests/test_diagram.py).
    params = ChainParams(N=1, gamma_phi=0.1)
    row = state_diagram(params, "sine", "gamma_phi", [0.1]).rows[0]
    assert row.end == "homoclinic" and row.method == "solved"
    assert holds_the_pendulums_homoclinic(params.j, 0.1, row.static_fold, row.rotation_stops, row.uncertainty)


@pytest.mark.parametrize("method", ["auto", "collocation"])
def test_a_branch_whose_start_exceeds_period_max_is_refused_not_ended_at_a_homoclinic_end(method, tmp_path):
    config = tmp_path / "N1.toml"
    config.write_text("N = 1\n")
    args = ["orbit", "--moment", "0.5", "--config", str(config), "--down-to", "0.45", "--period-max", "1", "--method", method]
    result = CliRunner().invoke(app, args)
    # The orbit at M = 0.5 has T = 1.609: the branch cannot start below period_max = 1.
    assert result.exit_code == 2, result.output
    assert "period_max (--period-max)" in result.output and "T = 1.60897" in result.output and "got period_max = 1.0" in result.output
    with pytest.raises(ValueError, match="must exceed the period of the orbit"):
        periodic_orbit(ChainParams(N=1), "sine", 0.5, down_to=0.45, period_max=1.0)
