"""Fourteenth session's outside audit of the chain: cases not in the other tests (H14aud).

A fold that ends the stable branch from rest is M_c only where the slowly loaded chain leaves rest there. The pinned-clamped
chain below folds at M = 1.2757 on the traced branch from rest (traced over its whole turn, no other stable part on it),
but the chain snaps onto a stable state of a branch the trace never reaches and rests there up to M = 8.8989: ramped runs
(load 0 -> M over 3000 time units, then held) rest at 1.01 times the first fold and at 0.99 times the second, and rotate
at 1.01 times the second (the audit's independent corner-spring energy, SymPy, holds the second fold at the same moment
to 5e-14 with the angle held).
"""

from __future__ import annotations

import numpy as np
import pytest

from cosserat_chain import ChainParams, Schedule, moment_load
from cosserat_chain.experiments.critical import critical_point
from cosserat_chain.numerics.dynamics import integrate

#: Found by ramped runs against ``critical`` on random geometries (seed 3, case 14 of the audit's search, rounded).
SNAPPING = ChainParams(N=6, h=1.6, a=0.69, b=0.83, E1=2.3, E2=2.5, left_end="pinned")
LOADED = 3
FIRST_FOLD = 1.275699275431419


def _ramped(params: ChainParams, moment: float, particle: int) -> tuple[float, float]:
    """Largest |velocity| at the end and largest |phi| of a run with the load ramped 0 -> ``moment`` then held."""
    run = integrate(params, "nonlinear", moment_load(Schedule.ramp(moment, duration=3000.0), particle), t_end=5000.0, n_frames=11)
    return float(np.max(np.abs(run.v[-1]))), float(np.max(np.abs(run.x[:, 2])))


def test_a_fold_the_chain_snaps_past_onto_an_untraced_branch_is_not_mc():
    result = critical_point(SNAPPING, "nonlinear", particle=LOADED)
    assert result.complete and result.first_fold.moment == pytest.approx(FIRST_FOLD, rel=1e-9)
    # The chain rests just above the first fold: it is not where rotation starts.
    speed, turned = _ramped(SNAPPING, 1.01 * FIRST_FOLD, LOADED)
    assert speed < 1e-10 and turned < 1.0
    mc = result.critical_moment
    assert result.onset == "crossing_fold" and result.onset_checked and result.accurate
    assert mc == pytest.approx(8.898909901207288, rel=1e-6)
    speed, turned = _ramped(SNAPPING, 0.99 * mc, LOADED)
    assert speed < 1e-10 and turned < np.pi
    speed, turned = _ramped(SNAPPING, 1.01 * mc, LOADED)
    assert turned > 100.0
