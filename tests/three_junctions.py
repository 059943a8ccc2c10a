"""Three Josephson junctions in a row with unequal critical currents, one site of three phases: the system of the
snaking homoclinic tests (defaults) and of the audit's period doublings (I = 0.8, alpha = 0.21), built here and named on
the command line as :data:`REFERENCE` (a user's system file)."""

from pathlib import Path

from cosserat_chain.systems import LatticeSystem

#: The ``--system`` reference of :func:`jj3` (arguments by ``--set``).
REFERENCE = f"{Path(__file__).resolve()}:jj3"


def jj3(*, I=0.97, kappa=0.29, alpha=0.45, ica=0.91, icb=1.13, icc=0.78):  # noqa: E741
    return LatticeSystem(
        sites=1,
        dofs=("phi_a", "phi_b", "phi_c"),
        site_energy="ica*(1-cos(phi_a)) + icb*(1-cos(phi_b)) + icc*(1-cos(phi_c)) - I*(phi_a+phi_b+phi_c)"
        " + kappa/2*((phi_b-phi_a)**2 + (phi_c-phi_b)**2)",
        damping="alpha",
        parameters={"I": I, "kappa": kappa, "alpha": alpha, "ica": ica, "icb": icb, "icc": icc},
        name="jj3",
    )
