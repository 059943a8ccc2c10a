"""The static branch's fallback corrector gives up where it does not contract, and that changes the cost only.

Where the chord corrector fails, full Newton from the plain predictor takes over; on long
chains it mostly wanders (residuals between 1e-5 and 1e-2 against a limit of 1e-7 at
N = 10^4), and the step is halved after all. The kit's contraction test ends it early
(:data:`~cosserat_chain.numerics.continuation.FALLBACK_CONTRACTION`).
"""

from __future__ import annotations

import numpy as np

from cosserat_chain import ChainParams
from cosserat_chain.linalg import bordered
from cosserat_chain.numerics import continuation
from cosserat_chain.numerics.continuation import continue_in_moment
from cosserat_chain.numerics.kit import Corrector


def _traced(monkeypatch, contraction):
    """The sine model's branch of N = 300 with the fallback's contraction test set, its fallbacks' ends, its factors."""
    monkeypatch.setattr(continuation, "FALLBACK_CONTRACTION", contraction)
    ends, factors = [], [0]
    correct = continuation._StaticBranch._correct

    def spy(self, *args, **kwargs):
        found = correct(self, *args, **kwargs)
        if "contraction" in kwargs:
            ends.append(found.status)
        return found

    class Counted(bordered.BorderedFactor):
        def __init__(self, *args, **kwargs):
            factors[0] += 1
            super().__init__(*args, **kwargs)

    monkeypatch.setattr(continuation._StaticBranch, "_correct", spy)
    monkeypatch.setattr(continuation, "BorderedFactor", Counted)
    branch = continue_in_moment(ChainParams(N=300), "sine")
    monkeypatch.undo()
    return branch, ends, factors[0]


def test_the_fallback_that_does_not_contract_gives_up_early_and_the_branch_is_the_same(monkeypatch):
    patient, patient_ends, patient_factors = _traced(monkeypatch, None)
    quick, quick_ends, quick_factors = _traced(monkeypatch, 0.5)
    # The fallbacks happen (else this test checks nothing), and none of the patient ones converged:
    assert len(patient_ends) >= 10 and Corrector.CONVERGED not in patient_ends
    assert Corrector.NOT_CONTRACTING in quick_ends
    # ... so giving up early leaves the branch as it was: the same points, folds and end,
    assert quick.stop == patient.stop and quick.moment.size == patient.moment.size
    assert np.array_equal(quick.moment, patient.moment)
    assert [(f.moment, f.phi0) for f in quick.folds] == [(f.moment, f.phi0) for f in patient.folds]
    # ... for fewer factors of the stiffness.
    assert quick_factors < patient_factors - 2 * len(patient_ends)
