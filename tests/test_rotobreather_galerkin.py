"""Roto-breathers of the Takeno-Peyrard lattice against an independent method: Fourier-Galerkin (harmonic balance).

The package finds a roto-breather by Newton on the period map (shooting with DOP853 and its variational
equations, from the anti-continuum rotor, continued in the coupling). This file solves the same orbit with no
integration at all: every angle is a truncated Fourier series in tau = Omega t,

    phi_n(tau) = s_n tau + sum_{k=1..K} b_{n,k} sin(k tau)        (s_n the turns of site n),

odd in tau because the lattice is reversible ((phi, t) -> (-phi, -t)) and the orbit through the section
phi_rotor = 0 with every angle at 0 is the symmetric one. The equations of motion
Omega^2 phi_n'' + sin phi_n + C [sin(phi_n - phi_{n-1}) + sin(phi_n - phi_{n+1})] = 0 (free ends) are odd too, so
collocating them at tau_j = j pi / (K + 1), j = 1..K, is exact for a sine series of K modes; Newton with the
analytic Jacobian, continued from C = 0 (the pendulum turning alone), solves them. Its Floquet multipliers come
from the linearized equations along that series, integrated by SciPy: an independent monodromy.

No published roto-breather value with its equations fully given was reachable for this project (see
docs/roto-breathers.md, "Checked against an independent method"); this agreement, to 1e-9 in the state and
2e-8 in the multipliers, is the check in its place.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.integrate import solve_ivp
from scipy.optimize import brentq

from conftest import SYSTEMS_CACHE
from cosserat_chain.experiments import system_breathers as sb
from cosserat_chain.numerics.breather_arclength import collision_discriminant
from cosserat_chain.systems import takeno_peyrard

SITES = 7
COUPLING = 0.05
#: Sine modes of the series: the rotor's coefficients fall below 1e-16 by the 20th at these frequencies.
MODES = 32


@pytest.fixture(autouse=True)
def _cache(monkeypatch):
    """The compiled systems go to the tests' cache folder (compiled once, not every session), not the user's."""
    monkeypatch.setenv("COSSERAT_CHAIN_CACHE", str(SYSTEMS_CACHE))


def _hessian(phi: np.ndarray, C: float) -> tuple[np.ndarray, np.ndarray]:
    """Diagonal (n, ...) and bond (n-1, ...) entries of the potential's Hessian at the angles ``phi`` (free ends)."""
    bond = C * np.cos(phi[:-1] - phi[1:])
    diagonal = np.cos(phi)
    diagonal[:-1] += bond
    diagonal[1:] += bond
    return diagonal, bond


def _collocation(turns: np.ndarray, b: np.ndarray, c: float, omega: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The collocation equations' residual (n, modes), their Jacobian in b (n modes, n modes) and in Omega (n, modes)."""
    n, modes = b.shape
    k = np.arange(1, modes + 1)
    tau = np.arange(1, modes + 1) * math.pi / (modes + 1)
    S = np.sin(np.outer(tau, k))  # S[j, k]: mode k at node j
    phi = turns[:, None] * tau[None, :] + b @ S.T
    force = np.sin(phi)
    pull = c * np.sin(phi[:-1] - phi[1:])
    force[:-1] += pull
    force[1:] -= pull
    inertia = (b * k**2) @ S.T
    diagonal, bond = _hessian(phi, c)
    J = np.zeros((n, modes, n, modes))
    for i in range(n):
        J[i, :, i, :] = -(omega**2) * S * k**2 + diagonal[i][:, None] * S
        if i + 1 < n:
            J[i, :, i + 1, :] = J[i + 1, :, i, :] = -bond[i][:, None] * S
    return -(omega**2) * inertia + force, J.reshape(n * modes, n * modes), -2 * omega * inertia


def galerkin(turns: np.ndarray, C: float, omega: float, modes: int = MODES, start: np.ndarray | None = None) -> np.ndarray:
    """Sine coefficients b (sites, modes) of the symmetric orbit at coupling C, by Newton on the collocation equations.

    Without ``start`` the coupling is raised from 0 in five steps, each solved from the one before.
    """
    n = turns.size

    def solve(c: float, b: np.ndarray) -> np.ndarray:
        for _ in range(30):
            residual, J, _ = _collocation(turns, b, c, omega)
            step = np.linalg.solve(J, -residual.ravel()).reshape(n, modes)
            b = b + step
            if np.max(np.abs(step)) < 1e-14:
                return b
        raise AssertionError(f"Galerkin Newton did not converge at C = {c}, Omega = {omega}")

    if start is not None:
        return solve(C, start)
    b = np.zeros((n, modes))
    for c in np.linspace(0.0, C, 6):
        b = solve(c, b)
    return b


def energy_slope(b: np.ndarray, turns: np.ndarray, C: float, omega: float) -> float:
    """dE/dOmega along the family, E = sum phi_n'(0)^2 / 2: db/dOmega from the collocation's Jacobian (no differences)."""
    _, J, d_omega = _collocation(turns, b, C, omega)
    db = np.linalg.solve(J, -d_omega.ravel()).reshape(b.shape)
    k = np.arange(1, b.shape[1] + 1)
    rate = turns + b @ k  # phi_n'(0) / Omega
    return float(np.sum(omega * rate * (rate + omega * (db @ k))))


def state_at_zero(b: np.ndarray, turns: np.ndarray, omega: float) -> np.ndarray:
    """y(0) = (phi, phi') of the series: every angle 0, velocities Omega (s_n + sum_k k b_{n,k})."""
    k = np.arange(1, b.shape[1] + 1)
    return np.concatenate([np.zeros(turns.size), omega * (turns + b @ k)])


def monodromy(b: np.ndarray, turns: np.ndarray, C: float, omega: float) -> np.ndarray:
    """The linearized flow over one period along the series, dy/dt = [[0, I], [-Hessian(phi(t)), 0]] y, by DOP853."""
    n, modes = b.shape
    k = np.arange(1, modes + 1)

    def rhs(t, flat):
        phi = turns * omega * t + b @ np.sin(k * omega * t)
        diagonal, bond = _hessian(phi, C)
        Y = flat.reshape(2 * n, 2 * n)
        q, v = Y[:n], Y[n:]
        accel = -diagonal[:, None] * q
        accel[:-1] += bond[:, None] * q[1:]
        accel[1:] += bond[:, None] * q[:-1]
        return np.concatenate([v, accel]).ravel()

    period = 2 * math.pi / omega
    run = solve_ivp(rhs, (0.0, period), np.eye(2 * n).ravel(), method="DOP853", rtol=1e-12, atol=1e-13)
    return run.y[:, -1].reshape(2 * n, 2 * n)


def _rotor_turns(pairs: dict[int, int]) -> np.ndarray:
    turns = np.zeros(SITES)
    for site, k in pairs.items():
        turns[site] = k
    return turns


@pytest.mark.parametrize("omega", [1.3, 1.1])
def test_the_package_orbit_is_the_galerkin_orbit_and_has_its_multipliers(omega):
    """One rotor (site 3 of 7), C = 0.05: at Omega = 1.3 a stable member, at 1.1 one past the loss of stability
    (a real pair through +1, max |mu| = 1.94). The package's state on the section equals the series' y(0) to 1e-9,
    its energy to 1e-10, and its Floquet multipliers the independent monodromy's to 2e-8."""
    turns = _rotor_turns({3: 1})
    b = galerkin(turns, COUPLING, omega)
    # The series itself is converged: 8 modes fewer change no coefficient by 1e-14.
    assert np.max(np.abs(galerkin(turns, COUPLING, omega, MODES - 8)[:, : MODES - 8] - b[:, : MODES - 8])) < 1e-14
    expected = state_at_zero(b, turns, omega)

    orbit = sb.roto_breather_family(takeno_peyrard(SITES, C=COUPLING), omega, rotor=3, locate=False).orbits[0]
    assert orbit.period == pytest.approx(2 * math.pi / omega, rel=1e-14)
    assert abs(orbit.unfolding) < 1e-10
    assert np.max(np.abs(orbit.y0 - expected)) < 1e-9
    assert sb.orbit_energy(orbit) == pytest.approx(0.5 * np.sum(expected[SITES:] ** 2), abs=1e-10)

    independent = np.linalg.eigvals(monodromy(b, turns, COUPLING, omega))
    # The pair at +1 is a Jordan block (split by the square root of the integration error): set aside in both.
    ours = np.sort_complex(orbit.nontrivial_multipliers)
    theirs = independent[np.argsort(np.abs(independent - 1.0))[2:]]
    # The independent ones are converged in their tolerance to 1e-11; the package's (its flow at rtol 1e-11)
    # are within 1.5e-11 of them on the stable orbit and 7.6e-9 on the unstable one (its 1.94248758, 4e-9 relative below).
    assert max(np.min(np.abs(theirs - mu)) for mu in ours) < 2e-8
    assert max(np.min(np.abs(ours - mu)) for mu in theirs) < 2e-8
    if omega == 1.3:
        assert orbit.stable and np.max(np.abs(np.abs(theirs) - 1.0)) < 1e-9
    else:
        assert not orbit.stable and np.max(np.abs(theirs)) == pytest.approx(orbit.max_multiplier, rel=1e-8)
        assert orbit.max_multiplier > 1.9


def test_a_counter_rotating_pair_is_the_galerkin_orbit():
    """Two neighbouring rotors turning against each other (sites 3 and 4, turns +1 and -1) at Omega = 1.3."""
    turns = _rotor_turns({3: 1, 4: -1})
    b = galerkin(turns, COUPLING, 1.3)
    expected = state_at_zero(b, turns, 1.3)
    family = sb.roto_breather_family(takeno_peyrard(SITES, C=COUPLING), 1.3, rotor=3, partner=4, counter=True, locate=False)
    orbit = family.orbits[0]
    assert abs(orbit.unfolding) < 1e-10
    assert np.max(np.abs(orbit.y0 - expected)) < 1e-9


def test_the_located_loss_of_stability_is_at_the_galerkin_energy_minimum_within_its_reported_accuracy():
    """Going down in Omega the one-site family loses stability by a pair through +1. A Hamiltonian family's pair
    meets +1 where dE/dOmega = 0 (the energy criterion), here found on the series alone: E = sum phi_n'(0)^2 / 2
    (every angle 0 on the section), its slope from the collocation's Jacobian (db/dOmega, no differences), zeroed
    by Brent's method; the independent monodromy's collision discriminant vanishes there too (its zero 3e-12 away).

    The package's bisection on the multipliers' moduli is off by 5.4e-6 (the four multipliers at +1 resolved to
    the fourth root of the monodromy's error): within its reported moduli_accuracy (4 delta^(1/2) / |D'|, 1.8e-5)
    and not absurdly inside it (a factor 10). The zero of the discriminant is within 1e-12 of the series' value,
    inside its reported bracket (3e-9); the same zero from the shooting's own orbits and monodromies (at their
    rtol), 3.4e-10 off, is what that accuracy measures: it holds it, within a factor 20."""
    turns = _rotor_turns({3: 1})
    top = galerkin(turns, COUPLING, 1.3)

    def coefficients(omega: float) -> np.ndarray:
        b = top
        for w in np.linspace(1.3, omega, 5)[1:]:
            b = galerkin(turns, COUPLING, w, start=b)
        return b

    minimum = brentq(lambda w: energy_slope(coefficients(w), turns, COUPLING, w), 1.12, 1.17, xtol=1e-15)
    assert math.sqrt(1 + 4 * COUPLING) < minimum  # above the band's top, as the existing family test has it
    # The series is converged in its modes at the minimum, and its own monodromy's pair meets +1 there.
    assert brentq(lambda w: energy_slope(coefficients(w)[:, :24], turns, COUPLING, w), 1.12, 1.17, xtol=1e-15) == pytest.approx(
        minimum, abs=1e-13
    )
    side = [
        collision_discriminant(np.linalg.eigvals(monodromy(coefficients(w), turns, COUPLING, w)), "+1")
        for w in (minimum - 1e-9, minimum + 1e-9)
    ]
    assert side[0] > 0 > side[1]

    family = sb.roto_breather_family(takeno_peyrard(SITES, C=COUPLING), 1.3, rotor=3, to=1.1)
    (change,) = family.changes
    assert change.kind == "+1" and change.method == "discriminant"
    assert change.unstable_omega < change.stable_omega
    low, high = change.bracket
    assert low <= minimum <= high
    assert abs(change.omega - minimum) < 1e-11
    assert abs(change.shooting_omega - minimum) <= change.accuracy <= 20 * abs(change.shooting_omega - minimum)
    assert abs(change.moduli_omega - minimum) <= change.moduli_accuracy <= 10 * abs(change.moduli_omega - minimum)
    # The reported numbers reach the JSON.
    summary = change.as_dict()
    assert summary["bracket"] == [low, high] and summary["accuracy"] == change.accuracy and summary["method"] == "discriminant"
