"""AUTO-07p's demo ``pen``: two damped pendula under a constant torque, coupled linearly.

    phi_i'' + eps phi_i' + sin phi_i = I + gamma (phi_j - phi_i),   i, j = 1, 2,

the equations of two coupled Josephson junctions driven by a bias current I (AUTO-07p's
``demos/pen``, with gamma = 0.175 and eps = 0.1). Its in-phase rotations (phi_1 = phi_2)
are those of one damped, driven pendulum.
"""

from __future__ import annotations

from .lattice import LatticeSystem


def pen(*, I: float = 0.4, gamma: float = 0.175, eps: float = 0.1) -> LatticeSystem:  # noqa: E741 - the demo's name
    """The two coupled pendula of AUTO-07p's ``pen`` demo (module docstring)."""
    return LatticeSystem(
        sites=2,
        site_energy="1 - cos(phi) - I*phi",
        bond_energy="gamma/2*(phi_r - phi_l)**2",
        damping="eps",
        parameters={"I": I, "gamma": gamma, "eps": eps},
        name="pen",
    )
