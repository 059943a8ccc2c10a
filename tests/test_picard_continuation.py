"""Continuation of orbits by Newton-Picard steps (numerics.periodic.continue_orbit(method="picard")).

The picard branch is checked against independent computations: each of its orbits is the dense
shooting's orbit at the same moment (found from it, with the whole monodromy), its multipliers above
rho are eigenvalues of that orbit's monodromy within their Ritz residuals, and where the branch ends
(a fold of cycles, the paper's sine chain) it ends as the dense continuation does, at the same moment.
The fold test's count of the multipliers left out is checked on built multiplier sets, and the branch
is checked to never form a monodromy.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from conftest import random_geometries
from cosserat_chain import ChainParams
from cosserat_chain.numerics import long_orbits
from cosserat_chain.numerics.newton_picard import RHO
from cosserat_chain.numerics.periodic import END_FOLD, END_INFINITE_PERIOD, _crosses_one, continue_orbit, find_periodic_orbit, initial_guess

#: A picard orbit and the dense shooting's at its moment agree to this (both closed to 1e-9 or better, the products at
#: 1e-11 and the Newton-Picard steps' at 1e-8).
SAME_ORBIT = 1e-8
#: The fold's moment is the extreme of the parabola through the last three orbits of each branch (the branches' points
#: differ): the two agree to this.
SAME_FOLD = 1e-8


def _check_points_against_dense(branch, points: int = 4) -> None:
    """Every ``points``-th orbit of the branch is the dense shooting's orbit at its moment, with the same multipliers above rho."""
    for orbit in branch.orbits[1 :: max(1, len(branch.orbits) // points)]:
        dense = find_periodic_orbit(orbit.params, orbit.model, orbit.moment, guess=orbit, method="dense", turns=orbit.turns)
        assert dense.period == pytest.approx(orbit.period, abs=SAME_ORBIT * max(1.0, orbit.period))
        assert np.max(np.abs(dense.x - orbit.x)) < SAME_ORBIT and np.max(np.abs(dense.v - orbit.v)) < SAME_ORBIT
        # Each Ritz value is an eigenvalue of the monodromy within its residual (the eigenvalues' condition about 1 here),
        # and none of the monodromy's above rho is left out.
        assert orbit.multiplier_errors is not None and orbit.multiplier_errors.shape == orbit.multipliers.shape
        for mu, error in zip(orbit.multipliers, orbit.multiplier_errors, strict=True):
            assert np.min(np.abs(dense.multipliers - mu)) <= 10 * error + SAME_ORBIT
        assert np.count_nonzero(np.abs(dense.multipliers) > RHO + 1e-6) <= orbit.multipliers.size
        assert orbit.stable == dense.stable


def test_the_paper_sine_chains_branch_ends_at_the_dense_continuations_fold_of_cycles(paper_sine_branch):
    # From the dense branch's first orbit below M = 0.166, past its torus and period doubling (where the picard branch
    # loses its stability is tested against the dense one's located torus in test_shooting_cycle_events.py): the picard
    # branch's own way to the fold, in nine orbits (from the first below 0.165, seven orbits end 2e-8 off the dense fold).
    start = paper_sine_branch.orbits[int(np.argmax(paper_sine_branch.moment < 0.166))]
    picard = continue_orbit(start, method="picard", moment_min=0.1)
    assert paper_sine_branch.end == END_FOLD and picard.end == END_FOLD
    assert picard.end_moment == pytest.approx(paper_sine_branch.end_moment, abs=SAME_FOLD)
    # The fold's real multiplier crosses +1 between the picard orbits around the turn, as between the dense ones.
    assert _crosses_one(*picard.orbits[-2:])
    _check_points_against_dense(picard)


@pytest.mark.parametrize(
    ("params", "model", "moment"),
    [
        (ChainParams(N=6, gamma_u=1.0, gamma_v=1.0, gamma_phi=1.0), "nonlinear", 0.5),
        pytest.param(ChainParams(N=6, gamma_u=1.0, gamma_v=1.0, gamma_phi=1.0), "sine", 0.3, marks=pytest.mark.slow),
        (random_geometries(6, seed=3)[1], "sine", 0.41),
    ],
    ids=["nonlinear N=6", "sine N=6", "random sine N=3"],
)
def test_each_picard_orbit_is_the_dense_shootings_orbit_at_its_moment(params, model, moment):
    start = find_periodic_orbit(params, model, moment, method="dense")
    picard = continue_orbit(start, method="picard", max_points=3, step=0.02)
    assert len(picard.orbits) == 3 and np.all(np.diff(picard.moment) < 0)
    _check_points_against_dense(picard, points=3)


def test_a_picard_continuation_never_forms_the_monodromy(paper_sine_orbit, monkeypatch):
    def refuse(*args, **kwargs):
        raise AssertionError("the monodromy was formed")

    monkeypatch.setattr(long_orbits.Monodromy, "matrix", refuse)
    branch = continue_orbit(paper_sine_orbit, method="picard", max_points=3, step=0.02)
    assert len(branch.orbits) == 3


def test_a_real_multiplier_that_drops_below_rho_is_not_a_crossing_of_one(paper_sine_orbit):
    # Newton-Picard keeps only the multipliers above rho: one that drops below it leaves the known product, whose sign
    # alone would then flip as at a crossing of +1; counting the ones left out keeps the test's sign.
    def orbit(*values):
        return dataclasses.replace(paper_sine_orbit, multipliers=np.array([1.0, *values], dtype=complex))

    assert not _crosses_one(orbit(0.9, 0.6), orbit(0.9))
    assert not _crosses_one(orbit(0.9, 0.7 + 0.2j, 0.7 - 0.2j), orbit(0.9))
    assert _crosses_one(orbit(0.9, 0.6), orbit(1.1, 0.6))
    assert _crosses_one(orbit(0.99, 0.6), orbit(1.01))
    # A whole set (the dense shooting's, nothing left out): a real multiplier through +1 flips the sign, one below rho does not.
    size = paper_sine_orbit.multipliers.size
    rest = [0.3] * (size - 3)
    assert _crosses_one(orbit(0.9, 0.6, *rest), orbit(1.1, 0.6, *rest))
    assert not _crosses_one(orbit(0.9, 0.6, *rest), orbit(0.9, 0.4, *rest))


def test_krylov_and_segments_with_picard_are_refused_naming_what_is_allowed(paper_sine_orbit):
    with pytest.raises(ValueError, match="auto, dense, blocks or picard"):
        continue_orbit(paper_sine_orbit, method="krylov")
    with pytest.raises(ValueError, match="segments applies to the dense and blocks shooting only"):
        continue_orbit(paper_sine_orbit, method="picard", segments=4)


@pytest.mark.slow
def test_at_thirty_one_particles_each_side_the_picard_branch_ends_where_the_blocks_one_does():
    # The strongly damped sine chain of benchmarks/bench_picard_continuation.py at N = 30: its orbit's period grows
    # towards the static fold (a SNIC); both branches end where it passes period_max, at the same moment up to where
    # their last steps fall, and every picard orbit is the dense shooting's orbit at its moment.
    params = ChainParams(N=30, gamma_u=1.0, gamma_v=1.0, gamma_phi=1.0)
    start = find_periodic_orbit(params, "sine", 0.3, guess=initial_guess(params, "sine", 0.3), method="blocks")
    common = {"period_max": 40.0, "step": 0.02}
    picard, blocks = (continue_orbit(start, method=method, **common) for method in ("picard", "blocks"))
    assert picard.end == blocks.end == END_INFINITE_PERIOD

    def crossing(branch) -> float:
        """M where log T passes log period_max, linear between the branch's last two orbits."""
        (m0, m1), (t0, t1) = branch.moment[-2:], np.log(branch.period[-2:])
        return float(m0 + (np.log(common["period_max"]) - t0) * (m1 - m0) / (t1 - t0))

    assert crossing(picard) == pytest.approx(crossing(blocks), abs=0.1 * abs(blocks.moment[-1] - blocks.moment[-2]))
    _check_points_against_dense(picard, points=3)
