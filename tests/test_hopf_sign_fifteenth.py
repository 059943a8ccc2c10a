"""The switch at a Hopf point does not depend on the phase and sign LAPACK gives the eigenvector (issue 40 item 4).

``cycle_switching.turned_hopf_vector`` fixes them: the real part on the major axis of the eigenvector's ellipse (on a
circle, the largest component real), its largest component positive. LAPACK's eigenvector is replaced here by itself
times exp(i theta) or -1 (``scipy.linalg.eig`` wrapped inside the module only): the first orbit of ``switch_at_hopf``
and of ``system_hopf_orbit`` must be the same orbit from the same point, and for -1 (exact in floating point) the
same bits. The orbits' agreement with the Hopf normal form (period -> 2 pi / omega, M - M_H ~ a^2, the rotor's
closed-form circles) is checked in ``tests/test_cycle_switching.py`` and ``tests/test_cycle_switching_system_hopf.py``.
"""

from __future__ import annotations

import math
import types

import numpy as np
import pytest
import scipy.linalg as sla

from cosserat_chain.numerics import cycle_switching
from cosserat_chain.numerics.continuation import continue_in_moment
from cosserat_chain.numerics.cycle_switching import switch_at_hopf, system_hopf_orbit, turned_hopf_vector
from cosserat_chain.numerics.equilibria import continue_equilibria, find_equilibrium
from cosserat_chain.numerics.hopf import hopf_points
from cosserat_chain.params import ChainParams
from follower_rotor_system import ROTOR

#: LAPACK's eigenvector times these: a few phases, and the sign.
FACTORS = [np.exp(1j * theta) for theta in (0.3, 1.2, math.pi / 2, 2.5, -2.0)] + [-1.0]
#: Agreement of orbits started from eigenvectors equal to round-off: Newton's closure (1e-10) lets the amplitude the
#: march reaches, and the start on the orbit, move by a few 1e-11.
ORBIT_TOL = 1e-9


@pytest.fixture(scope="module")
def hopf_chain():
    """The sine chain at N = 2 and its first Hopf point of positive M (phi_0 = 1.6575, ``tests/test_cycle_switching.py``)."""
    params = ChainParams(N=2)
    points = hopf_points(params, "sine", continue_in_moment(params, "sine", phi0_stop=2 * math.pi))
    return params, [h for h in points if h.moment > 0][0]


@pytest.fixture(scope="module")
def rotor_hopf():
    """The follower rotor's located Hopf point (its eigenvector's ellipse a circle: the rotor is rotationally symmetric)."""
    namespace: dict = {}
    exec(ROTOR, namespace)
    branch = continue_equilibria(
        find_equilibrium(namespace["build"](a0=0.2), np.zeros(2)), "a0", direction=1, stop_at=("hopf",), limits=(0.0, 0.4)
    )
    (event,) = [e for e in branch.events if e.kind == "hopf"]
    return event.point


def lapack_times(monkeypatch, factor):
    """Make the module's eigenvectors LAPACK's times ``factor`` (any multiple is an eigenvector as good)."""

    def eig(matrix):
        values, vectors = sla.eig(matrix)
        return values, vectors * factor

    monkeypatch.setattr(cycle_switching, "sla", types.SimpleNamespace(eig=eig))


def chain_matrix(params, point):
    """The damped dynamics linearised at the chain's Hopf point, and the index of its eigenvalue near +i omega."""
    system, state, _, _ = cycle_switching.hopf_vector(params, "sine", point)
    n = system.size
    jacobian = system.force_jacobian(state[:n]).toarray() / system.mass()[:, None]
    return np.block([[np.zeros((n, n)), np.eye(n)], [jacobian, -np.diag(system.damping() / system.mass())]])


def test_the_turned_hopf_vector_has_its_real_part_on_the_major_axis_and_its_largest_component_positive(hopf_chain):
    params, point = hopf_chain
    values, vectors = sla.eig(chain_matrix(params, point))
    v = vectors[:, np.argmin(np.abs(values - 1j * point.frequency))]
    turned = turned_hopf_vector(v)
    re, im = turned.real, turned.imag
    assert np.linalg.norm(re) == pytest.approx(1.0, rel=1e-14)
    assert abs(re @ im) < 1e-14 and re @ re > im @ im
    assert re[np.argmax(np.abs(re))] > 0
    # A multiple of v: the same eigenvector.
    ratio = turned / v
    assert np.allclose(ratio, ratio[0], rtol=1e-12, atol=0)
    assert np.allclose(turned_hopf_vector(3.7 * v), turned, rtol=0, atol=1e-13)
    for factor in FACTORS:
        again = turned_hopf_vector(factor * v)
        if factor == -1.0:
            assert np.array_equal(again, turned)  # -1 is exact: no bit changes
        else:
            assert np.allclose(again, turned, rtol=0, atol=1e-13)


def test_on_a_circle_the_turned_vector_has_its_largest_component_real_and_positive():
    # Real and imaginary parts orthogonal and of equal length: every phase puts the real part on a major axis.
    v = np.array([1.0, 1.0, 1j * math.sqrt(2.0), 0.0])
    for factor in [1.0, *FACTORS]:
        turned = turned_hopf_vector(factor * v)
        assert np.allclose(turned, [-math.sqrt(0.5) * 1j, -math.sqrt(0.5) * 1j, 1.0, 0.0], rtol=0, atol=1e-15)
    # Two components of equal modulus (the rotor's velocities): the first is taken whatever the phase's round-off.
    w = np.array([1.0, -1j, 1.5j, 1.5])
    for factor in [1.0, *FACTORS]:
        turned = turned_hopf_vector(factor * w)
        assert turned[2].imag == pytest.approx(0.0, abs=1e-15) and turned[2].real > 0


@pytest.mark.parametrize("factor", FACTORS, ids=lambda f: f"{f:.3g}")
def test_the_switch_at_a_hopf_point_starts_the_same_orbit_whatever_lapacks_phase_and_sign(hopf_chain, monkeypatch, factor):
    params, point = hopf_chain
    reference = switch_at_hopf(params, "sine", point, follow=False)
    lapack_times(monkeypatch, factor)
    switch = switch_at_hopf(params, "sine", point, follow=False)
    first, orbit = reference.orbit, switch.orbit
    assert switch.side == reference.side == "below"
    if factor == -1.0:
        assert np.array_equal(switch.eigenvector, reference.eigenvector)
        assert switch.amplitude == reference.amplitude and switch.coefficient == reference.coefficient
        assert orbit.period == first.period and orbit.moment == first.moment
        assert np.array_equal(orbit.x, first.x) and np.array_equal(orbit.v, first.v)
        assert np.array_equal(orbit.multipliers, first.multipliers)
        return
    assert np.allclose(switch.eigenvector, reference.eigenvector, rtol=0, atol=1e-13)
    assert switch.amplitude == pytest.approx(reference.amplitude, abs=ORBIT_TOL)
    assert switch.coefficient == pytest.approx(reference.coefficient, rel=1e-6)
    assert orbit.period == pytest.approx(first.period, rel=ORBIT_TOL)
    assert orbit.moment == pytest.approx(first.moment, rel=ORBIT_TOL)
    # The same point on the orbit: a start half a period on (the other sign of e) lies 2a away.
    assert np.allclose(orbit.x, first.x, rtol=0, atol=ORBIT_TOL) and np.allclose(orbit.v, first.v, rtol=0, atol=ORBIT_TOL)
    assert np.allclose(np.sort_complex(orbit.multipliers), np.sort_complex(first.multipliers), rtol=1e-7, atol=1e-9)


@pytest.mark.parametrize("factor", FACTORS, ids=lambda f: f"{f:.3g}")
def test_a_systems_hopf_orbit_starts_at_the_same_point_whatever_lapacks_phase_and_sign(rotor_hopf, monkeypatch, factor):
    reference = system_hopf_orbit(rotor_hopf, "a0", 4e-3)
    lapack_times(monkeypatch, factor)
    orbit = system_hopf_orbit(rotor_hopf, "a0", 4e-3)
    if factor == -1.0:
        assert np.array_equal(orbit.q0, reference.q0) and np.array_equal(orbit.v0, reference.v0)
        assert orbit.period == reference.period and orbit.parameter("a0") == reference.parameter("a0")
        return
    # On the rotor's circle every start is an orbit point: only the fixed phase puts it at the same one.
    assert np.allclose(orbit.q0, reference.q0, rtol=0, atol=ORBIT_TOL)
    assert np.allclose(orbit.v0, reference.v0, rtol=0, atol=ORBIT_TOL)
    assert orbit.period == pytest.approx(reference.period, rel=ORBIT_TOL)
