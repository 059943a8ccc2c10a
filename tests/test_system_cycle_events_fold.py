"""A period doubling in the same continuation step as a fold of cycles (issue 40 item 4): located, not passed.

An outside audit's chain of four pendula with sine bonds, the torque I on the first only, rotates phi_0 once a
period; followed up in I its orbit period-doubles at I = 0.50491170648 and folds 1.2e-5 above, at 0.50492376371
(AUTO-07p 0.9.2, NTST = 200, DSMAX = 1e-3; with its default steps AUTO labels only the fold: docs/periodic-orbits.md).
A step that holds both turns in I, so Brent's method in I between its two orbits has no bracket: the period doubling
was reported unlocated at the step's end. The step is now searched in its halves on either side of the fold.
"""

from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp

from cosserat_chain.numerics.shooting import continue_orbits, find_orbit
from cosserat_chain.systems.base import System

#: AUTO-07p's labels on this branch (printed digits).
AUTO_PD, AUTO_PD_PERIOD, AUTO_LP = 0.50491170648, 7.4757810111, 0.50492376371
#: The package's orbit at I = 0.5046702798329639, below both (its multipliers -0.738 and 2.42 beside 1).
START_I, START_PERIOD = 0.5046702798329639, 7.452959341098212
START = [
    -0.8552872076518547, 5.17057751117538, -0.4561539295462772, -0.13629630647994836,
    2.3253612262391794, -0.18665552436525495, -0.10249808145200551, -0.08808046673611385,
]  # fmt: skip


class DrivenEnd(System):
    """phi_i'' + alpha phi_i' + sin phi_i = I delta_i0 + sum of k_b sin(phi_j - phi_i) over the bonds b = (i, j)."""

    name = "driven_end"
    coordinates = ("phi_0", "phi_1", "phi_2", "phi_3")

    def __init__(self, **parameters):
        super().__init__({"I": START_I, "alpha": 0.2, "k1": 0.5, "k2": 0.3, "k3": 0.15, **parameters})

    @property
    def angles(self):
        return np.ones(4, dtype=bool)

    def _k(self):
        p = self.parameters
        return np.array([p["k1"], p["k2"], p["k3"]])

    def forces(self, q):
        bonds = self._k() * np.sin(q[1:] - q[:-1])
        f = -np.sin(q)
        f[0] += self.parameters["I"]
        f[:-1] += bonds
        f[1:] -= bonds
        return f

    def force_jacobian(self, q):
        c = self._k() * np.cos(q[1:] - q[:-1])
        j = np.diag(-np.cos(q))
        for i in range(3):
            j[i, i] -= c[i]
            j[i, i + 1] += c[i]
            j[i + 1, i + 1] -= c[i]
            j[i + 1, i] += c[i]
        return sp.csr_matrix(j)

    def parameter_forces(self, q, name):
        self._check_name(name)
        out = np.zeros(4)
        if name == "I":
            out[0] = 1.0
        elif name in ("k1", "k2", "k3"):
            i = int(name[1]) - 1
            s = np.sin(q[i + 1] - q[i])
            out[i] += s
            out[i + 1] -= s
        return out

    def mass(self):
        return np.ones(4)

    def damping(self):
        return np.full(4, self.parameters["alpha"])


@pytest.mark.slow  # each of Brent's trials on both halves of the step is a Newton solve of the long orbit from scratch
def test_a_period_doubling_in_a_step_with_a_fold_is_located_at_auto07ps_value():
    system = DrivenEnd()
    orbit = find_orbit(system, (np.array(START), START_PERIOD), turns={"phi_0": 1})
    # One step from the start passes the period doubling, the fold and comes back down in I.
    branch = continue_orbits(orbit, "I", direction=1, step=0.2, max_points=2, stop_at=())
    assert len(branch.orbits) == 2 and branch.values[1] < START_I < AUTO_PD
    (fold,) = [e for e in branch.events if e.kind == "fold"]
    (doubling,) = [e for e in branch.events if e.kind == "period_doubling"]
    assert fold.located and fold.index == doubling.index == 1 and fold.parameter == pytest.approx(AUTO_LP, abs=1e-10)
    assert doubling.located and doubling.parameter == pytest.approx(AUTO_PD, abs=1e-10)
    assert doubling.point.period == pytest.approx(AUTO_PD_PERIOD, abs=1e-9)
    assert np.min(np.abs(doubling.point.nontrivial_multipliers + 1.0)) < 1e-8
