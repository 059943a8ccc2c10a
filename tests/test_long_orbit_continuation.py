"""Continuation of long chains' orbits (numerics.periodic.continue_orbit with the blocks and segments).

With ``segments`` every orbit's multipliers come from the periodic Schur form of its pieces'
matrices; the branch is the one without them, and its multipliers are the formed monodromy's
wherever that keeps them. The slow test follows the sine chain's rotating orbit at N = 100 and
checks each point against the flow itself: a direct run from the orbit's state returns to it
after one period, and Liouville's formula fixes the product of the segments' multipliers.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from cosserat_chain import ChainParams
from cosserat_chain.models import get_model
from cosserat_chain.numerics.periodic import _System, _to_y, continue_orbit, find_periodic_orbit, initial_guess
from cosserat_chain.state import pack, per_dof

#: The two continuations' multipliers agree to this (absolute: the formed monodromy's eigenvalues carry the
#: integration's error, 1e-11 of its norm, amplified by their condition; the small ones only to that).
AGREE = 1e-8


#: The segments' trivial error |G_m ... G_1 f - f| / |f| is the residual of the flow direction: the computed multiplier
#: lies within it times the eigenvalue's condition (about 1 here; 1.05 seen on the paper's chain), not within it exactly.
CONDITION = 2.0


def _damping_rate(params: ChainParams) -> float:
    """sum_i gamma_i / m_i: minus the flow's divergence (Liouville: sum ln |mu| = -T times it)."""
    return float(np.sum(per_dof(params, params.damping) / pack(params, params.particle_inertia)))


def _same_branch(plain, split, agree: float = AGREE) -> None:
    assert len(plain.orbits) == len(split.orbits) >= 3
    for a, b in zip(plain.orbits, split.orbits, strict=True):
        assert b.moment == a.moment and b.period == a.period  # segments change the multipliers only
        assert a.multiplier_log_moduli is None and b.multiplier_log_moduli is not None
        assert b.multipliers.size == a.multipliers.size
        assert max(np.min(np.abs(a.multipliers - mu)) for mu in b.multipliers) < agree
        assert abs(b.trivial_multiplier - 1.0) <= CONDITION * b.trivial_multiplier_error < 1e-8
    # The start is the dense shooting's orbit; the blocks' own carry the trivial multiplier's error.
    for a in plain.orbits[1:]:
        assert abs(a.trivial_multiplier - 1.0) <= a.trivial_multiplier_error < 1e-8


def test_a_blocks_continuation_with_segments_is_the_one_without_with_the_segments_multipliers(paper_sine_orbit):
    common = {"method": "blocks", "max_points": 4, "step": 0.02}
    _same_branch(continue_orbit(paper_sine_orbit, **common), continue_orbit(paper_sine_orbit, segments=8, **common))


def test_a_dense_continuation_with_segments_meets_liouvilles_product():
    params = ChainParams(N=1)
    orbit = find_periodic_orbit(params, "sine", 0.5)
    branch = continue_orbit(orbit, method="dense", segments=4, max_points=3, step=0.02)
    rate = _damping_rate(params)
    for point in branch.orbits:
        assert float(np.sum(point.multiplier_log_moduli)) == pytest.approx(-point.period * rate, abs=1e-7)


@pytest.mark.parametrize(
    ("segments", "method", "match"),
    [
        (0, "blocks", "segments must be an integer >= 1"),
        (2.5, "dense", "segments must be an integer >= 1"),
        (True, "blocks", "segments must be an integer >= 1"),
    ],
)
def test_bad_segments_of_a_continuation_are_refused_naming_the_field(paper_sine_orbit, segments, method, match):
    with pytest.raises(ValueError, match=match):
        continue_orbit(paper_sine_orbit, method=method, segments=segments)


@pytest.mark.slow
def test_the_sine_chains_orbit_at_a_hundred_particles_is_followed_in_the_moment_and_each_point_closes_under_the_flow():
    # The sine chain of benchmarks/bench_long_orbits.py --segments (gamma_phi = 0.1: its angles' modes damped at
    # gamma_phi / j = 3.75, so that 8 pieces keep every multiplier; T = 2.1) at N = 100, by the blocks with 8 segments.
    params = ChainParams(N=100, gamma_u=1.0, gamma_v=1.0, gamma_phi=0.1)
    guess = initial_guess(params, "sine", 0.3)
    orbit = find_periodic_orbit(params, "sine", 0.3, guess=guess, method="blocks")
    branch = continue_orbit(orbit, method="blocks", segments=8, max_points=3, step=0.01)
    assert len(branch.orbits) == 3 and branch.orbits[-1].moment < 0.3
    system = _System(params, get_model("sine"), 0.3, 0)
    rate = _damping_rate(params)
    for point in branch.orbits:
        assert abs(point.trivial_multiplier - 1.0) <= CONDITION * point.trivial_multiplier_error < 1e-7
        assert float(np.sum(point.multiplier_log_moduli)) == pytest.approx(-point.period * rate, abs=1e-6)
        # A direct run from the orbit's state comes back after one period, the loaded particle one turn on.
        start = _to_y(params, point.x, point.v)
        system = _System(params, get_model("sine"), point.moment, 0)
        end, _, _ = system.flow(start, point.period, rtol=1e-11, atol=1e-11, variations=False)
        shift = np.zeros_like(start)
        shift[system.load_dof] = 2 * math.pi
        assert np.max(np.abs(end - start - shift)) < 1e-8
    # The first point is the orbit found directly: the continuation's own correction left it where it was.
    assert branch.orbits[0].period == pytest.approx(orbit.period, rel=1e-12)
    assert branch.orbits[0].max_multiplier == pytest.approx(orbit.max_multiplier, abs=1e-9)
