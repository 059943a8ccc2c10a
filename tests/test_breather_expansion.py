"""Small-coupling expansions of the Takeno-Peyrard roto-breathers: the frequency-energy relation, the pair's phase mode.

    E(Omega, C) = (1 + 2 C) E_0(Omega / sqrt(1 + 2 C)) - (C^2 / 2) d/dT [T sum_n s_n^2 / (1 - n^2 Omega^2)] + O(C^3)

E_0 the free pendulum's rotation energy at frequency Omega (its period 4 K(2/E) / sqrt(2 E)),
s_n the sine coefficients of sin phi_0(t) along that rotation, T = 2 pi / Omega (derived in
docs/roto-breathers.md, "An analytic value"). The first term is the rotor between neighbours
held at rest (:func:`held_rotor_energy`); the second the neighbours' linear response
C sin phi_0(t). Both are computed here independently of the package's shooting (the elliptic
integral, a SciPy DOP853 run of the lone pendulum and its FFT).

Two neighbouring rotors turning together have a relative-phase mode: averaged over the fast
rotation the bond between them is a potential C W(psi) in their phase difference, so psi
oscillates at sigma^2 = 2 C (dOmega/dE) <phi_0'^2> / Omega (docs, same section), and its
multipliers sit at exp(+-i sigma T).
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.integrate import solve_ivp
from scipy.optimize import brentq
from scipy.special import ellipk

from cosserat_chain.experiments.system_breathers import BreatherError, held_rotor_energy, orbit_energy, roto_breather_family
from cosserat_chain.systems import takeno_peyrard

OMEGA = 1.3  # above the band [1, sqrt(1 + 4 C)] and every harmonic's resonance


def pendulum_energy(omega: float) -> float:
    """E_0: the rotation of p^2 / 2 + 1 - cos phi whose turn takes 2 pi / omega."""
    return brentq(lambda e: 4 * ellipk(2 / e) / math.sqrt(2 * e) - 2 * math.pi / omega, 2 + 1e-14, 1e4, xtol=1e-15, rtol=1e-15)


def held_closed_form(omega: float, c: float) -> float:
    g = 1 + 2 * c
    return g * pendulum_energy(omega / math.sqrt(g))


def response_sum(period: float, samples: int = 512) -> float:
    """T sum_n s_n^2 / (1 - n^2 Omega^2) over the lone pendulum's rotation of period T."""
    omega = 2 * math.pi / period
    t = np.arange(samples) * period / samples
    run = solve_ivp(
        lambda _, y: [y[1], -math.sin(y[0])], (0, period), [0.0, math.sqrt(2 * pendulum_energy(omega))],
        method="DOP853", rtol=1e-13, atol=1e-13, t_eval=t,
    )  # fmt: skip
    sine = -2 * np.fft.rfft(np.sin(run.y[0])).imag / samples
    n = np.arange(1, 40)
    return period * float(np.sum(sine[n] ** 2 / (1 - (n * omega) ** 2)))


def second_order(omega: float) -> float:
    """The coefficient of C^2: -(1/2) d/dT [T sum ...], by central differences in T."""
    period, h = 2 * math.pi / omega, 1e-4
    return -0.5 * (response_sum(period + h) - response_sum(period - h)) / (2 * h)


def test_held_rotor_is_the_pendulum_with_the_bonds_added():
    for c in (0.0, 0.05, 0.3):
        assert held_rotor_energy(takeno_peyrard(9, C=c), OMEGA) == pytest.approx(held_closed_form(OMEGA, c), rel=1e-11)
    # the first-order coefficient dE/dC = 2 E_0 - Omega E_0'(Omega): nonzero, so a rotor without its bonds misses it
    slope = (held_closed_form(OMEGA, 1e-6) - held_closed_form(OMEGA, 0.0)) / 1e-6
    assert slope == pytest.approx(3.3874, abs=1e-3)


def test_family_energy_follows_the_expansion_to_second_order():
    coefficient = second_order(OMEGA)
    assert coefficient == pytest.approx(3.1949, abs=1e-3)  # positive: the neighbours' response adds energy
    ratios = []
    for c in (0.005, 0.01, 0.02):
        system = takeno_peyrard(9, C=c)
        orbit = roto_breather_family(system, OMEGA).orbits[0]
        residual = orbit_energy(orbit) - held_rotor_energy(system, OMEGA)
        ratios.append(residual / (coefficient * c**2))
    # the remainder is O(C^3): the ratio tends to 1 linearly in C (the next order bends it by 10 % at C = 0.02)
    assert abs(ratios[0] - 1) < 0.005
    assert abs(ratios[1] - 1) == pytest.approx(2 * abs(ratios[0] - 1), rel=0.1)
    assert abs(ratios[2] - 1) == pytest.approx(4 * abs(ratios[0] - 1), rel=0.15)


def test_held_rotor_energy_refuses_bad_input():
    system = takeno_peyrard(5, C=0.1)
    with pytest.raises(BreatherError, match="omega"):
        held_rotor_energy(system, 0.0)
    with pytest.raises(BreatherError, match="turns"):
        held_rotor_energy(system, 1.3, turns=0)
    with pytest.raises(BreatherError, match="rotor"):
        held_rotor_energy(system, 1.3, rotor=17)
    with pytest.raises(BreatherError, match="drive"):
        held_rotor_energy(takeno_peyrard(5, C=0.1, T=0.2), 1.3)


def test_pair_turning_together_has_the_averaged_phase_mode():
    energy, step = pendulum_energy(OMEGA), 1e-6
    frequency = [2 * math.pi * math.sqrt(2 * e) / (4 * ellipk(2 / e)) for e in (energy - step, energy + step)]
    slope = (frequency[1] - frequency[0]) / (2 * step)  # dOmega/dE of the rotation
    phi = np.linspace(0, 2 * math.pi, 4096, endpoint=False)
    mean_square = OMEGA * float(np.mean(np.sqrt(2 * (energy - 1 + np.cos(phi)))))  # <phi'^2> = (1/T) int phi' dphi
    errors = []
    for c in (0.0025, 0.005):
        orbit = roto_breather_family(takeno_peyrard(10, C=c), OMEGA, rotor=4, partner=5).orbits[0]
        predicted = math.sqrt(2 * c * slope * mean_square / OMEGA) * orbit.period
        angles = np.sort(np.abs(np.angle(orbit.nontrivial_multipliers)))
        assert orbit.stable and angles[0] == pytest.approx(angles[1], abs=1e-9)  # a pair exp(+-i sigma T)
        errors.append(angles[0] / predicted - 1)
    # O(sqrt(C)) angles, the relative error O(C): 0.6 % and 1.2 %
    assert 0 < errors[0] < 0.01 and errors[1] == pytest.approx(2 * errors[0], rel=0.15)
