"""The rotor beside two Mathieu oscillators, one site of three coordinates: the atlas tests' system, built here and
named on the command line as :data:`REFERENCE` (a user's system file)."""

from pathlib import Path

from cosserat_chain.systems.lattice import LatticeSystem

#: The ``--system`` reference of :func:`rotor_two_mathieu`.
REFERENCE = f"{Path(__file__).resolve()}:rotor_two_mathieu"


def rotor_two_mathieu(*, C=0.3, w0=1.0, w1=1.01):
    return LatticeSystem(
        sites=1, dofs=("phi", "x", "y"), damping="gamma", bond_energy="0",
        site_energy="(w0**2 + C*cos(phi))*x**2/2 + (w1**2 + C*cos(phi))*y**2/2",
        parameters={"C": C, "w0": w0, "w1": w1, "gamma": 0.0}, name="rotor_two_mathieu",
    )  # fmt: skip
