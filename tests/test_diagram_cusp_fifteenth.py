"""Rows of the state diagram whose followed fold is not M_c: the row's M_c is ``critical``'s (experiments/diagram.py).

The fold curve follows one fold through the field. On the nonlinear N = 1 chain a cusp between E2 = 1.0 and 1.1
creates a pair of folds before it: at E2 = 1.1 the branch from rest folds at M = 0.264718 (phi_0 = 1.01), turns back
to 0.260273 and folds again at the followed 0.262889 (phi_0 = 1.79). A slowly loaded chain leaves rest at the first,
``critical``'s M_c; the row said 0.262889 (found by H15suite: the row alone and ``critical`` gave 0.264718). On the
fourteenth audit's snapping chain the fold curve's fold is the first fold, 1.275699, past which the chain snaps onto a
branch it rests on up to 8.898910 (``critical``'s M_c, checked there by ramped runs); every row said 1.275699.
"""

from __future__ import annotations

import pytest

from cosserat_chain.experiments import diagram
from cosserat_chain.experiments.critical import critical_point
from cosserat_chain.numerics.fold_curve import continue_fold
from cosserat_chain.params import ChainParams


def test_a_row_past_a_cusp_takes_critical_s_onset_not_the_followed_fold():
    curve = continue_fold(ChainParams(N=1), "nonlinear", "E2", [1.0, 1.1])
    followed, angle = float(curve.moment[1]), float(curve.phi0[1])
    row = ChainParams(N=1, E2=1.1)
    reference = critical_point(row, "nonlinear", dynamics=False)
    # The curve's fold is a later one of the branch: lower than where the branch from rest ends.
    assert followed < reference.critical_moment - 1e-3
    moment, phi0, note = diagram._static_onset(row, "nonlinear", 0, followed, angle)
    assert moment == pytest.approx(reference.critical_moment, rel=1e-12)
    assert phi0 == pytest.approx(reference.phi0_at_onset, rel=1e-12)
    assert "fold curve followed the fold at M = 0.262889" in note and "ends at the fold at M = 0.264718" in note
    # Where the followed fold is the branch's own end the row keeps it, without a note.
    first = ChainParams(N=1)
    kept = diagram._static_onset(first, "nonlinear", 0, float(curve.moment[0]), float(curve.phi0[0]))
    assert kept == (float(curve.moment[0]), float(curve.phi0[0]), "")
    assert kept[0] == pytest.approx(critical_point(first, "nonlinear", dynamics=False).critical_moment, rel=1e-10)


def test_a_row_of_a_chain_that_snaps_past_its_first_fold_takes_critical_s_onset():
    snapping = ChainParams(N=6, h=1.6, a=0.69, b=0.83, E1=2.3, E2=2.5, left_end="pinned")
    curve = continue_fold(snapping, "nonlinear", "gamma_phi", [snapping.gamma_phi], particle=3)
    assert curve.moment[0] == pytest.approx(1.275699275431419, rel=1e-9)
    moment, _, note = diagram._static_onset(snapping, "nonlinear", 3, float(curve.moment[0]), float(curve.phi0[0]))
    assert moment == pytest.approx(8.898909901207288, rel=1e-6)
    assert "snaps past the fold at M = 1.2757" in note and "(crossing_fold)" in note


@pytest.mark.slow
def test_the_diagram_row_past_the_cusp_equals_the_row_alone():
    both = diagram.state_diagram(ChainParams(N=1), "nonlinear", "E2", [1.0, 1.1])
    alone = diagram.state_diagram(ChainParams(N=1, E2=1.1), "nonlinear", "E2", [1.1])
    assert both.rows[1].static_fold == pytest.approx(alone.rows[0].static_fold, rel=1e-10)
    assert both.rows[1].static_fold == pytest.approx(0.2647178723628719, rel=1e-9)
