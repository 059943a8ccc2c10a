"""The Frenkel-Kontorova chain: particles in a sinusoidal substrate, bound by harmonic springs.

    x_i'' + gamma x_i' + V sin x_i = F + C (x_{i+1} - 2 x_i + x_{i-1})   (springs of rest length a0:
                                                                        their energy C/2 (x_r - x_l - a0)^2),

in units where the substrate's period is 2 pi. The positions are periodic coordinates of
the substrate, so a particle that slides by one period is an orbit with a phase gain
(a running state under the driving force F). Linear band about x = 0 (F = 0):
omega^2 = V + 4 C sin^2(q/2); in the continuum limit C >> V a static kink is the
sine-Gordon kink 4 arctan exp(i sqrt(V/C)) with energy 8 sqrt(C V).
"""

from __future__ import annotations

from .lattice import LatticeSystem


def frenkel_kontorova(
    sites: int, *, C: float = 1.0, V: float = 1.0, F: float = 0.0, a0: float = 0.0, gamma: float = 0.0, boundary: str = "free"
) -> LatticeSystem:
    """The Frenkel-Kontorova chain (module docstring)."""
    return LatticeSystem(
        sites=sites,
        dofs=("x",),
        angles=("x",),
        site_energy="V*(1 - cos(x)) - F*x",
        bond_energy="C/2*(x_r - x_l - a0)**2",
        damping="gamma",
        boundary=boundary,
        parameters={"C": C, "V": V, "F": F, "a0": a0, "gamma": gamma},
        name="frenkel_kontorova",
    )
