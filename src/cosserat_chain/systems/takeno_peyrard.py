"""The Takeno-Peyrard rotator lattice: periodic on-site and periodic inter-site potentials.

    H = sum_i [ phi_i'^2 / 2 + (1 - cos phi_i) + C (1 - cos(phi_{i+1} - phi_i)) ]

(S. Takeno and M. Peyrard, Physica D 92, 140 (1996), "Nonlinear modes in coupled rotator
models"): unlike the Frenkel-Kontorova chain, neighbours may turn by whole turns relative
to each other at finite energy, so rotobreathers (one rotor turning, the rest oscillating)
exist. Linear band about phi = 0: omega^2 = 1 + 4 C sin^2(q/2); in the continuum limit
C >> 1 a static kink is the sine-Gordon kink 4 arctan exp(i / sqrt(C)) with energy 8 sqrt(C).
A torque T (its work -T phi counted in the energy) and a damping gamma drive and damp every rotor.
"""

from __future__ import annotations

from .lattice import LatticeSystem


def takeno_peyrard(sites: int, *, C: float = 1.0, T: float = 0.0, gamma: float = 0.0, boundary: str = "free") -> LatticeSystem:
    """The Takeno-Peyrard rotator lattice (module docstring)."""
    return LatticeSystem(
        sites=sites,
        site_energy="1 - cos(phi) - T*phi",
        bond_energy="C*(1 - cos(phi_r - phi_l))",
        damping="gamma",
        boundary=boundary,
        parameters={"C": C, "T": T, "gamma": gamma},
        name="takeno_peyrard",
    )
