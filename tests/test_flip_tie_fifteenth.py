"""The flip vector's sign where two components tie in modulus (numerics/cycle_switching.flip_vector).

A symmetric system's flip mode can have two components of equal modulus and opposite sign, equal up to round-off:
"largest component positive" then picks the component, and with it the sign, by round-off. Ties to TIE_TOL take the
first, as the Hopf vector's turn does.
"""

from __future__ import annotations

import math

import numpy as np
import scipy.linalg as sla

from cosserat_chain.numerics import cycle_switching, shooting
from cosserat_chain.numerics.cycle_switching import flip_vector

#: LAPACK's eigensolver as scipy gives it, kept before the test replaces it.
EIG = sla.eig


def _orbit_with_monodromy(monodromy: np.ndarray) -> shooting.Orbit:
    """A shooting orbit carrying only the monodromy that ``flip_vector`` reads."""
    orbit = object.__new__(shooting.Orbit)
    object.__setattr__(orbit, "monodromy", monodromy)
    return orbit


def test_a_tie_in_modulus_takes_the_first_component_whatever_the_round_off_and_lapack_s_sign(monkeypatch):
    for skew in (1e-15, -1e-15, 0.0):
        # The flip mode (1, -(1 + skew)): its second component is the larger by round-off only where skew > 0.
        basis = np.array([[1.0, 1.0], [-(1.0 + skew), 1.0]])
        monodromy = basis @ np.diag([-1.0, 0.5]) @ np.linalg.inv(basis)
        orbit = _orbit_with_monodromy(monodromy)
        multiplier, vector = flip_vector(orbit)
        assert abs(multiplier + 1.0) < 1e-14
        assert vector[0] > 0 and vector[1] < 0 and abs(abs(vector[0]) - 1 / math.sqrt(2)) < 1e-14
        with monkeypatch.context() as patch:
            patch.setattr(cycle_switching.sla, "eig", lambda a: (lambda w, v: (w, -v))(*EIG(a)))
            assert np.array_equal(flip_vector(orbit)[1], vector)
