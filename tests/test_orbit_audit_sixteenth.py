"""The sixteenth audit of the orbit machinery (H16audit): defects found on cases outside the other tests.

``orbit --down-to`` by shooting reported a fold of cycles at the parabola through the three orbits around the turn,
printed with 17 digits: on a clamped-pinned N = 3 sine chain loaded at its pinned end 0.3033010370, where the
collocation's branch and the augmented system both give 0.3033015372 (5.0e-7 apart). The fold is now located by the
augmented shooting system, as the diagram's rows locate theirs.

Next to a homoclinic orbit single shooting's monodromy loses its trivial multiplier (1.95 at T = 10.3 on the N = 1 sine
chain, ||M|| ~ 1e6): taken with the multiplier nearest +1 for the trivial one, the stable orbit read as unstable, and
``diagram --vary gamma_phi --values 0.1`` on N = 1 said branch_point_of_cycles at 0.4290037, below the pendulum's
homoclinic end 0.4290033951 (an intermediate state of the sixteenth session, never committed).
"""

from __future__ import annotations

import pytest

from cosserat_chain import ChainParams
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
