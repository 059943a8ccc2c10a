"""The anti-continuum rotor: one angle turning alone in its on-site potential.

Contract
--------
Where the coupling of a lattice is switched off (a user system's coupling at 0) or the
neighbours are held at rest (the chain's anti-continuum limit), the rotor obeys
J phi'' = tau(phi), tau its torque, 2 pi periodic with zero mean. Both roto-breather modules
(:mod:`~cosserat_chain.experiments.breathers` for the chain,
:mod:`~cosserat_chain.experiments.system_breathers` for user systems) sample tau their own
way and share the rest here:

* :func:`potential_from_torque`: V(phi) = -int_0^phi tau, from :data:`POTENTIAL_POINTS` samples
  of tau as a Fourier series (V(0) = 0);
* :func:`rotor_period`: the time of one turn at energy E > max V,
  T(E) = int_0^{2 pi} sqrt(J / (2 (E - V))) dphi (trapezoid: spectral for a periodic integrand);
* :func:`rotor_energy`: the energy whose turn takes a given time (Brent's method on T(E)).
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np

from ..numerics.brent import brentq

#: Angles 2 pi i / POTENTIAL_POINTS at which the torque is sampled (the on-site potential is smooth).
POTENTIAL_POINTS = 256
#: Quadrature points of the rotor's period integral.
PERIOD_POINTS = 4096


def sample_angles() -> np.ndarray:
    """The :data:`POTENTIAL_POINTS` angles at which :func:`potential_from_torque` expects the torque."""
    return 2 * math.pi * np.arange(POTENTIAL_POINTS) / POTENTIAL_POINTS


def potential_from_torque(torque: np.ndarray) -> Callable[[np.ndarray], np.ndarray]:
    """V(phi) = -int_0^phi tau from the torque sampled at :func:`sample_angles` (its mean, a drive, is left out).

    Each harmonic c_n e^{i n phi} of the torque integrates to c_n e^{i n phi} / (i n); a
    rotor's torque must have zero mean, which its callers check where a user can set one.

    Parameters
    ----------
    torque : ndarray (POTENTIAL_POINTS,)

    Returns
    -------
    callable(phi ndarray) -> ndarray
    """
    coef = np.fft.rfft(np.asarray(torque, dtype=float)) / POTENTIAL_POINTS
    wave = np.arange(1, coef.size)

    def potential(phi: np.ndarray) -> np.ndarray:
        phi = np.asarray(phi, dtype=float)
        terms = (coef[1:, None] / (1j * wave[:, None])) * (np.exp(1j * np.outer(wave, phi.ravel())) - 1.0)
        return -2.0 * np.real(terms.sum(axis=0)).reshape(phi.shape)

    return potential


def rotor_period(potential: Callable[[np.ndarray], np.ndarray], inertia: float, energy: float) -> float:
    """Time of one turn of the rotor J phi'' = -V'(phi) at energy E > max V."""
    return _period(potential(_period_angles()), inertia, energy)


def _period_angles() -> np.ndarray:
    """The :data:`PERIOD_POINTS` angles of the turn's quadrature."""
    return 2 * math.pi * np.arange(PERIOD_POINTS) / PERIOD_POINTS


def _period(values: np.ndarray, inertia: float, energy: float) -> float:
    """:func:`rotor_period` from the potential's ``values`` at :func:`_period_angles`."""
    return float(np.mean(np.sqrt(inertia / (2.0 * (energy - values)))) * 2 * math.pi)


def rotor_energy(potential: Callable[[np.ndarray], np.ndarray], inertia: float, turn_time: float) -> float:
    """The energy E at which one turn of the rotor takes ``turn_time`` (every such time is reached: T -> inf at the barrier).

    Raises
    ------
    ValueError
        Where the turn is slower than the quadrature resolves just above the barrier (a
        frequency too close to 0).
    """
    # The potential at the quadrature's angles once: each of Brent's steps changes only the energy.
    values = potential(_period_angles())
    top = float(np.max(values))
    low = top + 1e-12 * max(1.0, abs(top))
    if _period(values, inertia, low) < turn_time:
        raise ValueError(f"a turn in {turn_time:.6g} is too slow to resolve: the rotor's frequency is too close to 0")
    high = max(2 * abs(top), 1.0)
    while _period(values, inertia, high) > turn_time:
        high *= 4.0
    return float(brentq(lambda e: _period(values, inertia, e) - turn_time, low, high, xtol=1e-14, rtol=1e-14))
