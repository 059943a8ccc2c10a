"""A chain of n coupled pendula: a one-dimensional array of Josephson junctions.

    phi_i'' + alpha phi_i' + sin phi_i = I + kappa (phi_{i+1} - 2 phi_i + phi_{i-1}),

with bias current (or torque) I, damping alpha and coupling kappa, in units of the
junctions' plasma frequency; free ends by default, a ring (an annular array) with ``boundary="periodic"``: its
closing bond sees the phase difference itself, not modulo 2 pi, so it holds no trapped fluxon (that needs a
twisted closing bond, phi_0 + 2 pi - phi_{n-1}, which the lattice's ring does not offer). Its linear band about phi = arcsin I is
omega^2 = sqrt(1 - I^2) + 4 kappa sin^2(q/2).
"""

from __future__ import annotations

from .lattice import LatticeSystem


def josephson_array(sites: int, *, I: float = 0.0, kappa: float = 1.0, alpha: float = 0.1, boundary: str = "free") -> LatticeSystem:  # noqa: E741
    """n pendula (Josephson junctions) coupled to their neighbours (module docstring)."""
    return LatticeSystem(
        sites=sites,
        site_energy="1 - cos(phi) - I*phi",
        bond_energy="kappa/2*(phi_r - phi_l)**2",
        damping="alpha",
        boundary=boundary,
        parameters={"I": I, "kappa": kappa, "alpha": alpha},
        name="josephson_array",
    )
