"""The blocks' shooting with segments (numerics.long_orbits.orbit_multipliers): every Floquet multiplier of a long chain's orbit.

Liouville's formula fixes the product of all multipliers: the flow's divergence is minus the
damping's trace at every state, so sum ln |mu| = -T sum_i gamma_i / m_i exactly. The formed
monodromy's multipliers below 1e-16 |M| are round-off and miss it; the segments' periodic Schur
form keeps them. The blocks with segments must give the dense shooting's segments' multipliers.
"""

from __future__ import annotations

import numpy as np
import pytest

from cosserat_chain import ChainParams
from cosserat_chain.models import get_model
from cosserat_chain.numerics import long_orbits
from cosserat_chain.numerics.long_orbits import Monodromy, segment_matrices
from cosserat_chain.numerics.periodic import _System, _to_y, find_periodic_orbit, initial_guess
from cosserat_chain.state import pack, per_dof

#: Nontrivial multipliers above 1e-12 of the two shootings agree to this relative (the same integrations' tolerance 1e-11).
AGREE = 1e-9
#: ln |mu| of the small multipliers agree to this.
LOG_AGREE = 1e-8
#: Liouville's sum of ln |mu| is met to this (absolute; the sum is about -60 at N = 1).
LIOUVILLE = 1e-7


def _damping_rate(params: ChainParams) -> float:
    """sum_i gamma_i / m_i: minus the flow's divergence."""
    return float(np.sum(per_dof(params, params.damping) / pack(params, params.particle_inertia)))


@pytest.fixture(scope="module")
def snic_orbits():
    """The nonlinear one-particle chain near its SNIC (M = 0.265, T = 15.9, smallest multiplier ~1e-26): blocks and dense, with 16
    segments and without."""
    params = ChainParams(N=1)
    guess = initial_guess(params, "nonlinear", 0.265)
    return params, {
        (method, segments): find_periodic_orbit(params, "nonlinear", 0.265, guess=guess, method=method, segments=segments)
        for method in ("blocks", "dense")
        for segments in (None, 16)
    }


def _compare(dense, blocks, agree: float = AGREE, log_agree: float = LOG_AGREE) -> None:
    """The blocks' segment multipliers are the dense shooting's: the nontrivial ones above 1e-12 to ``agree``, all log-moduli to ``log_agree``."""
    assert blocks.multipliers.shape == dense.multipliers.shape == blocks.log_moduli.shape
    # Each nontrivial one above 1e-12 against the nearest of the other's (a complex pair's two members may come in either order).
    big = dense.multipliers[(np.abs(dense.multipliers) > 1e-12) & (np.abs(dense.multipliers - 1.0) > 1e-6)]
    assert max(np.min(np.abs(blocks.multipliers - mu)) / abs(mu) for mu in big) < agree
    assert np.max(np.abs(blocks.log_moduli - dense.log_moduli)) < log_agree
    assert abs(blocks.trivial_multiplier - dense.trivial_multiplier) < 1e-8


def test_the_blocks_with_segments_give_the_dense_segments_multipliers(snic_orbits):
    _, orbits = snic_orbits
    _compare(orbits["dense", 16], orbits["blocks", 16])


def test_the_blocks_with_segments_meet_liouvilles_product_where_the_formed_monodromy_misses_it(snic_orbits):
    params, orbits = snic_orbits
    split, formed = orbits["blocks", 16], orbits["blocks", None]
    exact = -split.period * _damping_rate(params)
    assert np.sum(split.log_moduli) == pytest.approx(exact, abs=LIOUVILLE)
    assert np.min(split.log_moduli) < -25 * np.log(10.0)
    assert formed.multiplier_log_moduli is None
    assert abs(np.sum(np.log(np.abs(formed.multipliers))) - exact) > 0.1 * abs(exact)
    # JSON: the log10 moduli with segments, none claimed without.
    assert sum(split.as_dict()["floquet_multipliers_log10_abs"]) == pytest.approx(exact / np.log(10.0), abs=LIOUVILLE)
    assert "floquet_multipliers_log10_abs" not in formed.as_dict()


def test_the_trivial_multiplier_of_the_segments_equals_one_within_its_reported_error(snic_orbits):
    _, orbits = snic_orbits
    orbit = orbits["blocks", 16]
    assert 0 < orbit.trivial_multiplier_error < 1e-8
    assert abs(orbit.trivial_multiplier - 1.0) <= orbit.trivial_multiplier_error
    assert orbit.as_dict()["trivial_multiplier_error"] == orbit.trivial_multiplier_error
    # Only the trivial one's error is estimated from the segments.
    assert np.sum(np.isfinite(orbit.multiplier_errors)) == 1


def test_the_segment_matrices_from_blocks_are_the_dense_pieces_and_multiply_to_the_monodromy():
    # The paper's sine chain (2 n_free = 30): blocks of 8 columns, so that a piece is assembled from four blocks.
    params = ChainParams()
    orbit = find_periodic_orbit(params, "sine", 0.22, method="dense")
    system = _System(params, get_model("sine"), orbit.moment, 0)
    start = _to_y(params, orbit.x, orbit.v)
    stack = segment_matrices(system, start, orbit.period, 5, rtol=1e-11, atol=1e-11, block=8, threads=2)
    dense = system.segment_jacobians(start, orbit.period, 5, rtol=1e-11, atol=1e-11)
    assert np.max(np.abs(stack - dense)) < 1e-8 * np.max(np.abs(dense))
    product = np.linalg.multi_dot(stack[::-1])
    formed = Monodromy(system, start, orbit.period, 1e-11, 1e-11).matrix()
    assert np.max(np.abs(product - formed)) < 1e-8 * np.max(np.abs(formed))


def test_above_the_size_of_all_multipliers_the_leading_ones_come_with_a_warning(monkeypatch):
    params = ChainParams()
    monkeypatch.setattr(long_orbits, "ALL_MULTIPLIERS_UP_TO", 20)  # the paper's chain: 2 n_free = 30
    with pytest.warns(UserWarning, match="the small ones are not computed"):
        orbit = find_periodic_orbit(params, "sine", 0.22, method="blocks", segments=8)
    assert orbit.multipliers.size == long_orbits.MULTIPLIERS + 1 and orbit.multiplier_log_moduli is None
    assert abs(orbit.trivial_multiplier - 1.0) <= orbit.trivial_multiplier_error < 1e-8


@pytest.mark.parametrize(
    ("segments", "method", "match"),
    [
        (0, "blocks", "segments must be an integer >= 1"),
        (2.5, "blocks", "segments must be an integer >= 1"),
        (True, "blocks", "segments must be an integer >= 1"),
        ("4", "blocks", "segments must be an integer >= 1"),
        (4, "krylov", "segments applies to the dense and blocks shooting only, got method='krylov'"),
        (4, "collocation", "segments applies to the dense and blocks shooting only, got method='collocation'"),
    ],
)
def test_bad_segments_are_refused_before_computing(segments, method, match):
    with pytest.raises(ValueError, match=match):
        find_periodic_orbit(ChainParams(N=1), "nonlinear", 0.265, method=method, segments=segments)


@pytest.mark.slow
def test_a_hundred_and_one_particle_orbit_by_blocks_and_segments_equals_the_dense_segments_and_meets_liouville():
    # The smallest chain `auto` gives the blocks (N = 50), its angles damped at gamma_phi / j = 11.25 (T = 6.4, smallest
    # multiplier ~1e-31): the formed monodromy misses Liouville's product; each of 16 pieces damps by exp(-4.4) at most.
    params = ChainParams(N=50, gamma_u=1.0, gamma_v=1.0, gamma_phi=0.3)
    guess = initial_guess(params, "sine", 0.3)
    blocks = find_periodic_orbit(params, "sine", 0.3, guess=guess, segments=16)  # auto: the blocks
    assert blocks.multipliers.size == 2 * 3 * 99 and blocks.multiplier_log_moduli is not None
    dense = find_periodic_orbit(params, "sine", 0.3, guess=guess, method="dense", segments=16)
    # 594 multipliers of a non-normal monodromy from two integrations at rtol 1e-11: ln |mu| measured 6.8e-9 apart at most.
    _compare(dense, blocks, agree=1e-8, log_agree=2e-8)
    exact = -blocks.period * _damping_rate(params)
    assert np.sum(blocks.log_moduli) == pytest.approx(exact, rel=1e-8)
    formed = find_periodic_orbit(params, "sine", 0.3, guess=guess)
    assert abs(np.sum(np.log(np.abs(formed.multipliers))) - exact) > 1e-3 * abs(exact)
    assert abs(blocks.trivial_multiplier - 1.0) <= blocks.trivial_multiplier_error < 1e-8
