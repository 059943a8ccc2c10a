"""find_equilibrium's descent where Newton fails: Frenkel-Kontorova kinks started anywhere between their sites.

The discrete sine-Gordon (Frenkel-Kontorova) kink has two stationary positions a site: centred
on a site (one particle on the substrate's top, x = pi: a saddle of the energy, index 1) and
between two sites (a minimum, index 0); their energy difference is the Peierls-Nabarro barrier,
which falls like C exp(-pi^2 sqrt(C / V)) in the continuum limit (the exponent is the kink's
Fourier transform 2 pi / sinh(pi^2 sqrt(C / V) ...) at the lattice's wavenumber 2 pi).
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from cosserat_chain.numerics import equilibria, kit
from cosserat_chain.systems.base import SystemDefinitionError
from cosserat_chain.systems.frenkel_kontorova import frenkel_kontorova
from cosserat_chain.systems.lattice import LatticeSystem
from cosserat_chain.systems.takeno_peyrard import takeno_peyrard


def arctan_kink(sites: int, coupling: float, centre: float) -> np.ndarray:
    """The continuum kink 4 arctan exp((i - centre) / sqrt(C)), from 0 to 2 pi."""
    return 4 * np.arctan(np.exp((np.arange(sites) - centre) / math.sqrt(coupling)))


def kink_centre(q: np.ndarray) -> float:
    """Where the kink crosses pi (linear interpolation between sites)."""
    return float(np.interp(math.pi, q, np.arange(q.size)))


# 41 sites at C = 0.5 and 2 (the starts Newton failed from at C = 2); at C = 8 a free chain of 41
# sites holds no kink near its middle (test below), so there 101.
@pytest.mark.parametrize("coupling, sites", [(0.5, 41), (2.0, 41), (8.0, 101)])
@pytest.mark.parametrize("offset", [0.0, 0.25, 0.5, 0.75])
def test_a_kink_started_anywhere_reaches_a_neighbouring_stationary_kink(coupling, sites, offset):
    system = frenkel_kontorova(sites, C=coupling)
    start_centre = (sites - 1) / 2 + offset
    q0 = arctan_kink(sites, coupling, start_centre)
    kink = equilibria.find_equilibrium(system, q0)
    assert kink.residual <= equilibria.FORCE_TOL
    assert np.max(np.abs(system.forces(kink.q))) <= equilibria.FORCE_TOL
    assert kink.q[-1] - kink.q[0] == pytest.approx(2 * math.pi, abs=1e-3)
    if kink.method == "descent":
        assert system.energy(kink.q) <= system.energy(q0)
    # One of the two stationary kinks next to the start (a half site apart), classified:
    # centred on a site a saddle, between two a minimum.
    centre = kink_centre(kink.q)
    position = round(2 * centre) / 2
    assert abs(centre - position) < 1e-3
    assert math.floor(2 * start_centre) / 2 <= position <= math.ceil(2 * start_centre) / 2
    assert kink.index == (1 if position == int(position) else 0)
    assert kink.stable == (kink.index == 0)


def test_the_starts_newton_diverged_from_now_descend_to_the_minimum_between_sites():
    """C = 2, a quarter site off: Newton alone diverges (descent=False raises), the descent lowers the energy."""
    system = frenkel_kontorova(41, C=2.0)
    q0 = arctan_kink(41, 2.0, 20.25)
    with pytest.raises(equilibria.EquilibriumNotFound, match="descent=False"):
        equilibria.find_equilibrium(system, q0, descent=False)
    kink = equilibria.find_equilibrium(system, q0)
    assert kink.method == "descent"
    assert kink.index == 0
    assert kink_centre(kink.q) == pytest.approx(20.5, abs=1e-6)
    assert system.energy(kink.q) < system.energy(q0)


def test_every_descent_step_lowers_the_energy_and_the_last_ones_are_newtons():
    """The kit's corrector with the descent's step (as find_equilibrium runs it), each iterate recorded:
    the energy falls at every step, and the last step divides max |F| by more than 1000 (the pseudo time step
    has grown so large that the steps are Newton's)."""
    system = frenkel_kontorova(101, C=8.0)
    energies, norms = [], []

    def record(q, evaluation):
        energies.append(system.energy(q))
        norms.append(float(np.max(np.abs(evaluation.residual))))

    def evaluate(q, jacobian):
        return kit.Evaluation(system.forces(q), system.force_jacobian(q).tocsc() if jacobian else None)

    q0 = arctan_kink(101, 8.0, 50.25)
    descended = kit.newton(
        evaluate, q0, tol=1e-13, max_iterations=500, divergence=None, newton_step=equilibria._DescentStep(system), iterate=record
    )
    assert descended.converged
    assert len(energies) > 10
    # Up to the energy's round-off, which the descent allows for (eps n max(1, |E|)), once max |F| is small.
    slack = np.finfo(float).eps * system.size * max(energies)
    assert np.all(np.diff(energies) <= slack)
    assert np.all(np.diff(energies)[np.array(norms[:-1]) > 1e-6] < 0)
    assert norms[-1] < 1e-3 * norms[-2]


def test_symmetric_starts_give_symmetric_kinks():
    """The mirror q_i -> 2 pi - q_(n-1-i) maps the chain onto itself: a symmetric start stays symmetric,
    on a site (odd n: the saddle) and between two (even n: the minimum), with the descent too."""
    for sites, index in ((41, 1), (40, 0)):
        system = frenkel_kontorova(sites, C=2.0)
        q0 = arctan_kink(sites, 2.0, (sites - 1) / 2)
        for kink in (equilibria.find_equilibrium(system, q0), equilibria.find_equilibrium(system, q0, max_iterations=0)):
            np.testing.assert_allclose(kink.q + kink.q[::-1], 2 * math.pi, atol=1e-12)
            assert kink.index == index


def test_a_short_free_chain_at_strong_coupling_holds_no_kink_in_its_middle():
    """At C = 8 the free ends' attraction (about exp(-2 L / sqrt(C)) of the kink's energy, L = 20 sites)
    outweighs the Peierls-Nabarro barrier (4e-9): started off the symmetric saddle, the kink leaves
    through an end, and the descent ends at the uniform ground state, of energy 0."""
    system = frenkel_kontorova(41, C=8.0)
    q0 = arctan_kink(41, 8.0, 20.25)
    ground = equilibria.find_equilibrium(system, q0)
    assert ground.method == "descent"
    assert ground.index == 0
    assert system.energy(ground.q) == pytest.approx(0.0, abs=1e-20)
    assert np.ptp(ground.q) < 1e-12


def test_the_peierls_nabarro_barrier_is_positive_and_falls_with_the_continuum_exponent():
    """E(on site) - E(between sites) > 0, falling with C; ln(barrier / C) against sqrt(C) has the
    continuum estimate's slope -pi^2 (V = 1; fitted over C = 2 to 8: -9.75, within 2 %)."""
    couplings = np.array([2.0, 3.0, 4.0, 6.0, 8.0])
    barriers = []
    for coupling in couplings:
        sites = 101
        system = frenkel_kontorova(sites, C=coupling)
        saddle = equilibria.find_equilibrium(system, arctan_kink(sites, coupling, 50.0))
        minimum = equilibria.find_equilibrium(system, arctan_kink(sites, coupling, 50.3))
        assert (saddle.index, minimum.index) == (1, 0)
        barriers.append(system.energy(saddle.q) - system.energy(minimum.q))
    barriers = np.array(barriers)
    assert np.all(barriers > 0)
    assert np.all(np.diff(barriers) < 0)
    slope = np.polyfit(np.sqrt(couplings), np.log(barriers / couplings), 1)[0]
    assert slope == pytest.approx(-(math.pi**2), rel=0.02)


def test_where_newton_converges_the_answer_is_newtons_bit_for_bit():
    """A Takeno-Peyrard kink and a two-dof lattice: descent=True changes nothing where Newton converges,
    and the descent alone (max_iterations=0) reaches the same minimum to round-off."""
    rotators = takeno_peyrard(61, C=4.0)
    q0 = arctan_kink(61, 4.0, 30.5)
    springs = LatticeSystem(
        sites=12,
        dofs=("u", "phi"),
        site_energy="(1 - cos(phi)) + u**2/2 - F*u",
        bond_energy="K/2*(u_r - u_l)**2 + K/2*(phi_r - phi_l)**2",
        parameters={"K": 1.5, "F": 0.2},
        name="springs",
    )
    cases = [(rotators, q0), (springs, np.linspace(0.0, 0.3, springs.size))]
    for system, start in cases:
        plain = equilibria.find_equilibrium(system, start, descent=False)
        found = equilibria.find_equilibrium(system, start)
        assert found.method == "newton"
        np.testing.assert_array_equal(found.q, plain.q)
        descended = equilibria.find_equilibrium(system, start, max_iterations=0)
        assert descended.method == "descent"
        assert descended.index == plain.index == 0
        np.testing.assert_allclose(descended.q, plain.q, atol=1e-9)


def test_a_start_that_is_not_finite_is_a_clear_error():
    system = frenkel_kontorova(41, C=2.0)
    q0 = arctan_kink(41, 2.0, 20.25)
    q0[7] = math.nan
    with pytest.raises(SystemDefinitionError, match="q0 must be finite.*index 7"):
        equilibria.find_equilibrium(system, q0)


def test_a_driven_chain_without_equilibria_is_a_clear_error():
    """F > V: no particle can rest (sin x = F has no root), the energy -F x falls without bound; the
    descent says so instead of looping."""
    system = frenkel_kontorova(41, C=2.0, F=2.0)
    with pytest.raises(equilibria.EquilibriumNotFound, match=r"descent from q0 stalled after 50 steps .*energy lowered from 0 to -"):
        equilibria.find_equilibrium(system, np.zeros(41), max_descent_steps=50)


def test_a_system_without_an_energy_is_not_descended():
    """A non-conservative site force: no energy to descend, Newton's failure is reported as before."""
    system = LatticeSystem(
        sites=3,
        site_energy="1 - cos(phi)",
        bond_energy="g/2*(phi_r - phi_l)**2",
        site_force={"phi": "T"},
        parameters={"g": 0.3, "T": 2.0},
        name="driven",
    )
    with pytest.raises(equilibria.EquilibriumNotFound, match="diverged|stalled|not_contracting|not_finite"):
        equilibria.find_equilibrium(system, np.zeros(3))
