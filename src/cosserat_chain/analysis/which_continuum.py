"""The answer to the paper's open problem, as the package computes it: which continuum describes the chain, and where it stops.

Contract
--------
:func:`answer` runs the three comparisons of ``docs/which-continuum.md`` for one geometry:
small deformations (the Timoshenko beam and eq. (11) against the discrete linear chain, clamped,
moment on particle 0), large bending (the exact beam's circle against model (i)'s cantilever),
and a particle's full rotation (the held lattice's quasi-continuum front, the discrete front and
the turn barrier). :meth:`Answer.lines` states the answer in sentences with the numbers; a report
section prints them and draws :func:`cosserat_chain.plots.theory.plot_continua` of the two tables.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from ..params import ChainParams
from .exact_beam import BendingConvergence, bending_convergence
from .rotation_front import DiscreteFront, QuasiContinuum, TurnBarrier, discrete_front, quasi_continuum, turn_barrier
from .timoshenko import BeamConvergence, convergence

#: Chain lengths of the default answer (seconds on one core).
DEFAULT_N = (10, 30, 100, 300, 1000)


@dataclass(frozen=True)
class Answer:
    """The three comparisons for one geometry (see the module docstring)."""

    params: ChainParams
    beam: BeamConvergence
    bending: BendingConvergence
    quasi_continuum: QuasiContinuum
    front: DiscreteFront
    barrier: TurnBarrier

    def lines(self) -> list[str]:
        """The answer in sentences, with the computed numbers and orders."""
        beam, bending, qc, front, barrier = self.beam, self.bending, self.quasi_continuum, self.front, self.barrier
        last = -1
        # The orders over the three longest chains: shorter ones may lie below the shear length.
        since = int(beam.N[-3]) if beam.N.size >= 3 else 1
        order_t, order_p = beam.order("timoshenko", since=since), beam.order("paper", since=since)

        def fmt(order: float | None) -> str:
            return "n/a" if order is None else f"{order:.2f}"

        lines = [
            f"Small deformations: the Timoshenko beam (EI = 2 E1 b^2 h, GA = k_v h, EA = k_u h) converges to the discrete chain with "
            f"order {fmt(order_t)} over N >= {since} (compliance error {beam.timoshenko_error[last]:+.1e} at N = {beam.N[last]}); the paper's eq. (11) with "
            f"order {fmt(order_p)} ({beam.paper_error[last]:+.1e}). The chain is, at its particles and exactly, the beam with shear "
            "compliance 1/GA - h^2/(12 EI).",
            f"Large bending: the geometrically exact beam with the same stiffnesses; model (i)'s cantilever turned by "
            f"{bending.angle:.3g} rad by an end moment differs from its circle by {bending.moment_error[last]:+.1e} in the moment and "
            f"{bending.tip_error[last]:.1e} of the length at the tip at N = {bending.N[last]} (orders {fmt(bending.order('moment'))} "
            f"and {fmt(bending.order('tip'))}).",
        ]
        if front.smooth:
            lines.append(
                f"Full rotation: a 2 pi front {front.width:.3g} particles wide, energy {front.energy:.4g} against the quasi-continuum's "
                f"{qc.front_energy:.4g} (width {qc.width:.3g}): a continuum with model (i)'s exact bond potential describes it."
            )
        else:
            width = "none" if math.isnan(qc.width) else f"{qc.width:.3g} particles"
            lines.append(
                f"Full rotation: no continuum. The quasi-continuum front's width is {width} (tails {qc.tail:.3g} particles); the "
                f"discrete front slips into one bond, so the rotation localises on one particle, whose turn past fixed neighbours "
                f"costs {barrier.fixed:.4g} ("
                + (
                    f"{barrier.barrier:.4g} with the others relaxing, the top of the turn's minimum energy path"
                    if math.isfinite(barrier.barrier)
                    else f"at least {barrier.relaxed:.4g} with the others relaxing"
                )
                + ")."
            )
        return lines

    def as_dict(self) -> dict[str, object]:
        """Everything as plain data (for JSON)."""
        return {
            "params": self.params.model_dump(),
            "timoshenko": self.beam.as_dict(),
            "exact_beam": self.bending.as_dict(),
            "quasi_continuum": self.quasi_continuum.as_dict(),
            "discrete_front": self.front.as_dict(),
            "barrier": self.barrier.as_dict(),
            "answer": self.lines(),
        }


def answer(params: ChainParams | None = None, *, n_values: tuple[int, ...] = DEFAULT_N, angle: float = math.pi) -> Answer:
    """The three comparisons for the geometry of ``params`` (default the paper's chain); its ends are set for each.

    Raises
    ------
    ValueError
        As :func:`.timoshenko.convergence` and :func:`.exact_beam.bending_convergence` (E2 = 0, a graded chain, a bad list or angle).
    """
    params = ChainParams() if params is None else params
    if params.periodic:
        params = params.replace(periodic=False)
    clamped = params.replace(left_end="clamped", right_end="clamped")
    qc = quasi_continuum(params)
    half_length = int(min(max(30, 6 * (qc.tail if math.isfinite(qc.tail) else 0)), 200))
    return Answer(
        params=params,
        beam=convergence(clamped, list(n_values)),
        bending=bending_convergence(params.replace(left_end="clamped", right_end="free"), list(n_values), angle=angle),
        quasi_continuum=qc,
        front=discrete_front(params, half_length=half_length),
        barrier=turn_barrier(params, half_length=min(half_length, 30), points=32),
    )
