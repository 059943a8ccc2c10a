"""The Timoshenko beam of a uniform chain: its stiffnesses, and the clamped beam's compliance under a central moment.

Contract
--------
The beam's constants depend on :class:`~cosserat_chain.params.ChainParams` alone (the derivation
is in :mod:`cosserat_chain.analysis.timoshenko`'s docstring and
:func:`cosserat_chain.analysis.symbolic.timoshenko_derivation`). With the nodal shear compliance
1/GA - h^2/(12 EI) the beam is the linear chain at its particles, exactly, so
:func:`clamped_central_compliance` is the discrete chain's own phi_0/M in closed form: the
reference the continuum's comparison (:mod:`cosserat_chain.analysis.continuum`) checks its
discrete solve against. The module sits below both the continuum and the Timoshenko modules,
which re-export its names.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from ..params import ChainParams

__all__ = ["BeamStiffness", "beam_stiffness", "clamped_central_compliance", "require_uniform_chain"]


@dataclass(frozen=True)
class BeamStiffness:
    """The Timoshenko beam of a uniform chain (per unit length).

    Attributes
    ----------
    EI : float
        Bending stiffness 2 E1 b^2 h.
    GA : float
        Shear stiffness k_v h = 8 (b^2/d^2) E2 h.
    EA : float
        Axial stiffness k_u h.
    mass : float
        Mass per length m / h.
    rotary : float
        Rotary inertia per length j / h.
    h : float
        Spacing of the particles (the beam's element length).
    """

    EI: float
    GA: float
    EA: float
    mass: float
    rotary: float
    h: float

    @property
    def shear_compliance(self) -> float:
        """1 / GA of the plain Timoshenko beam."""
        return 1.0 / self.GA

    @property
    def shear_length(self) -> float:
        """sqrt(EI/GA): below it shear dominates the beam's compliance, beyond it bending does."""
        return math.sqrt(self.EI / self.GA)

    @property
    def nodal_shear_compliance(self) -> float:
        """1/GA - h^2/(12 EI): the beam with this shear compliance is the chain at its particles (module docstring).

        It is negative when GA h^2 > 12 EI, i.e. (h/d)^2 E2 > 3 E1: the statics still hold
        (a beam's compliances are affine in it), but no positive shear stiffness gives them.
        """
        return 1.0 / self.GA - self.h**2 / (12.0 * self.EI)

    def as_dict(self) -> dict[str, float]:
        """The stiffnesses and inertias, and both shear compliances (for JSON)."""
        return {
            "EI": self.EI,
            "GA": self.GA,
            "EA": self.EA,
            "mass": self.mass,
            "rotary": self.rotary,
            "shear_compliance": self.shear_compliance,
            "nodal_shear_compliance": self.nodal_shear_compliance,
            "shear_length": self.shear_length,
        }


def require_uniform_chain(params: ChainParams, what: str) -> None:
    if params.periodic:
        raise ValueError(f"{what} needs an open chain (periodic = false): a ring has no ends to hold it, got periodic=True")
    if params.graded_stiffness:
        raise ValueError(f"{what} needs a uniform chain: leave E1_factors and E2_factors out (a graded chain is no uniform beam)")
    if not params.E2 > 0:
        raise ValueError(f"{what} needs shear stiffness GA = 8 (b/d)^2 E2 h > 0, i.e. E2 > 0; got E2={params.E2!r}")


def beam_stiffness(params: ChainParams) -> BeamStiffness:
    """EI, GA, EA and the inertias of the chain's Timoshenko beam (module docstring).

    Raises
    ------
    ValueError
        For a ring, a graded chain, or E2 = 0 (no shear stiffness).
    """
    require_uniform_chain(params, "the Timoshenko beam")
    h = params.h
    return BeamStiffness(
        EI=2.0 * params.E1 * params.b**2 * h,
        GA=params.k_v * h,
        EA=params.k_u * h,
        mass=params.m / h,
        rotary=params.j / h,
        h=h,
    )


def clamped_central_compliance(params: ChainParams, *, nodal: bool = False) -> float:
    """phi(0)/M of the clamped-clamped beam under a moment at its centre: L (1 + P) / (8 EI (1 + P/4)), P = 12 EI c / L^2.

    c is the beam's shear compliance (``nodal`` as in :func:`static_solution`). Each half is a
    beam clamped at its far end and held (v = 0) at the centre by antisymmetry, whose
    rotational stiffness is (4 EI / L) (1 + P/4) / (1 + P); derived in
    :func:`cosserat_chain.analysis.symbolic.timoshenko_derivation`.
    """
    stiffness = beam_stiffness(params)
    c = stiffness.nodal_shear_compliance if nodal else stiffness.shear_compliance
    L = params.N * params.h
    ratio = 12.0 * stiffness.EI * c / L**2
    return L * (1 + ratio) / (8 * stiffness.EI * (1 + ratio / 4))
