"""The flip vector's sign is the package's, not LAPACK's (issue 40 item 4: a deterministic switch at a period doubling).

``cycle_switching.flip_vector`` takes the monodromy's eigenvector for the multiplier nearest -1 from LAPACK, whose sign
is arbitrary; a positive amplitude along it picks one of the doubled orbit's two starts, half a period apart, and the
switch's normal-form probes, so LAPACK's sign decided a test's outcome. The vector is now returned with its component
of largest modulus positive: an eigensolver that returns every eigenvector negated gives the same vector, the same
start and the same doubled orbit.
"""

from __future__ import annotations

import numpy as np
import pytest
import scipy.linalg as sla

from cosserat_chain import ChainParams
from cosserat_chain.numerics import cycle_switching
from cosserat_chain.numerics.cycle_switching import doubled_orbit, flip_vector
from cycle_ends import shooting_crossing

#: LAPACK's eigensolver as scipy gives it, kept before any test replaces it.
EIG = sla.eig
#: The sine chain whose period doubling at M = 0.17288 the switching tests share (tests/cycle_ends.py).
PARAMS = ChainParams(gamma_phi=0.15)


def negated_eig(matrix):
    """LAPACK's eigenpairs with every eigenvector's sign flipped: as valid an answer as LAPACK's own."""
    values, vectors = EIG(matrix)
    return values, -vectors


@pytest.fixture(scope="module")
def point():
    """The located period doubling of the shared branch (its event's orbit)."""
    branch, _ = shooting_crossing(PARAMS)
    (event,) = [e for e in branch.events if e["kind"] == "period_doubling"]
    return event["orbit"]


def test_the_flip_vector_has_its_largest_component_positive_whatever_lapacks_sign(point, monkeypatch):
    multiplier, vector = flip_vector(point)
    assert abs(multiplier + 1.0) < 1e-8 and np.linalg.norm(vector) == pytest.approx(1.0, abs=1e-14)
    assert vector[np.argmax(np.abs(vector))] > 0
    monkeypatch.setattr(cycle_switching.sla, "eig", negated_eig)
    again_multiplier, again = flip_vector(point)
    assert again_multiplier == multiplier and np.array_equal(again, vector)


def test_the_doubled_orbit_does_not_depend_on_lapacks_sign(point, monkeypatch):
    own = doubled_orbit(point, 1e-3)
    monkeypatch.setattr(cycle_switching.sla, "eig", negated_eig)
    flipped = doubled_orbit(point, 1e-3)
    assert flipped.moment == own.moment and flipped.period == own.period
    assert np.array_equal(flipped.x, own.x) and np.array_equal(flipped.v, own.v)
    # The orbit half a period on (the other sign of the amplitude) is another start of the same doubled orbit, not this one.
    other = doubled_orbit(point, -1e-3)
    assert np.abs(other.x - own.x).max() > 1e-4
