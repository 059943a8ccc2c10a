"""Messages of the state diagram name the field it varies (issue 45, item 7)."""

from __future__ import annotations

import pytest

from cosserat_chain import ChainParams
from cosserat_chain.experiments import diagram
from cosserat_chain.numerics.cycle_curve import locate_cycle_end
from cosserat_chain.numerics.periodic import find_periodic_orbit


@pytest.fixture(scope="module")
def orbit():
    # A stable orbit far from any end of its branch: locating an end from it fails.
    found = find_periodic_orbit(ChainParams(N=1), "sine", 0.5)
    assert found.stable
    return found


def test_a_cycle_end_that_cannot_be_located_names_the_varied_field_and_its_value(orbit):
    with pytest.raises(ValueError, match=r"could not be located at gamma_phi = 0\.1 ") as err:
        locate_cycle_end([orbit], "period_doubling", field_name="gamma_phi")
    assert "E1" not in str(err.value)


def test_the_diagrams_edge_message_names_its_field(orbit):
    edge = diagram._located(diagram._Edge(0.5, "torus", "the orbit loses stability"), [orbit], "gamma_phi")
    assert edge.method != "located"
    assert "not located exactly" in edge.message and "gamma_phi = 0.1" in edge.message and "E1" not in edge.message
