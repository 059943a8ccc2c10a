"""The eleventh outside audit: defects a user meets through the Python API and the command line (H11audit).

Each test fails on the code before its fix.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from cosserat_chain.numerics.shooting import find_orbit, require_periodic_turns
from cosserat_chain.systems.base import System, SystemDefinitionError


class QuadraticPendula(System):
    """Three pendula joined by quadratic springs k/2 (q_r - q_l)^2, free ends, written by hand.

    A turn of one pendulum alone stretches its springs by 2 pi: the forces are not 2 pi periodic in
    one angle, only in the three together (their differences are unchanged).
    """

    name = "quadratic-pendula"

    def __init__(self, **parameters):
        super().__init__({"k": 0.1, "alpha": 0.0, **parameters})

    @property
    def coordinates(self):
        return ("phi_0", "phi_1", "phi_2")

    @property
    def angles(self):
        return np.ones(3, dtype=bool)

    def forces(self, q):
        k = self.parameters["k"]
        bond = k * np.diff(q)
        return -np.sin(q) + np.concatenate([bond, [0.0]]) - np.concatenate([[0.0], bond])

    def force_jacobian(self, q):
        import scipy.sparse as sp

        k = self.parameters["k"]
        main = -np.cos(q) - k * np.array([1.0, 2.0, 1.0])
        return sp.diags([np.full(2, k), main, np.full(2, k)], [-1, 0, 1], format="csr")

    def mass(self):
        return np.ones(3)

    def damping(self):
        return np.full(3, self.parameters["alpha"])


def test_an_orbit_turning_an_angle_its_forces_are_not_periodic_in_is_refused_naming_it():
    """Before: Newton 'found' a roto-breather of a quadratically coupled chain by taking the unfolding
    damping at -0.28 (``breathers --system`` printed it as an orbit of the undamped system, exit 0): no
    orbit turning phi_1 alone closes, since the turn changes the forces by 4 pi k."""
    system = QuadraticPendula()
    y0 = np.array([0.0, 0.0, 0.0, 0.0, 3.0, 0.0])
    with pytest.raises(SystemDefinitionError, match=r"phi_1.*2 pi periodic"):
        find_orbit(system, (y0, 2 * math.pi / 3.0), turns={"phi_1": 1}, unfold="alpha")
    # Turning the three together keeps every spring's length: that rotation is posed.
    require_periodic_turns(system, np.array([0.3, -1.0, 2.0]), np.ones(3))


@pytest.mark.parametrize("reference", ["./ring:ring", "systems/ring:ring", "../ring:ring"])
def test_a_system_file_named_without_py_is_refused_saying_how_to_name_it(reference):
    """Before: ``--system ./ring:ring`` (the .py left out) reached importlib.import_module, whose TypeError about
    relative imports ('the package argument is required') was all the user saw."""
    from cosserat_chain.systems.loader import load_system

    with pytest.raises(SystemDefinitionError, match=r"not a \.py file.*file\.py:function"):
        load_system(reference)


def test_a_lattice_too_large_for_the_memory_is_refused_before_it_is_built(monkeypatch):
    """Before: ``--system ... --set sites=1000000000`` (a typo of three zeros) built a tuple of 10^9 coordinate
    names and a Jacobian's triplets until the machine ran out of memory; now it is refused, naming sites."""
    from cosserat_chain import memory
    from cosserat_chain.systems import LatticeSystem

    monkeypatch.setattr(memory, "available", lambda: 2**30)
    with pytest.raises(SystemDefinitionError, match=r"not enough memory: a lattice of sites=100000000 .*fewer sites"):
        LatticeSystem(sites=100_000_000, site_energy="1 - cos(phi)", bond_energy="C*(1 - cos(phi_r - phi_l))", parameters={"C": 1.0})
