"""The rotor beside two Mathieu oscillators as a user system file (the atlas tests' ``--system`` source)."""

SYSTEM_FILE = """
from cosserat_chain.systems.lattice import LatticeSystem


def build():
    return LatticeSystem(
        sites=1, dofs=("phi", "x", "y"), damping="gamma", bond_energy="0",
        site_energy="(w0**2 + C*cos(phi))*x**2/2 + (w1**2 + C*cos(phi))*y**2/2",
        parameters={"C": 0.3, "w0": 1.0, "w1": 1.01, "gamma": 0.0}, name="rotor_two_mathieu",
    )
"""
