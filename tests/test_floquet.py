"""Floquet multipliers from the product of segment matrices (numerics/floquet.py): exact products, a linear damped
system's exp(A T), high-precision references, ordering, bad input, and the orbits' multipliers against Liouville's formula."""

from __future__ import annotations

import math

import mpmath
import numpy as np
import pytest
import scipy.linalg as sla

from cosserat_chain import ChainParams
from cosserat_chain.numerics.collocation import continue_collocation, find_collocation_orbit
from cosserat_chain.numerics.floquet import periodic_schur_multipliers
from cosserat_chain.numerics.periodic import find_periodic_orbit
from cosserat_chain.state import pack, per_dof

N1 = ChainParams(N=1)


def _rotation(angle: float) -> np.ndarray:
    return np.array([[math.cos(angle), -math.sin(angle)], [math.sin(angle), math.cos(angle)]])


def _conjugated_chain(rng, m: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """G_k = S_{k+1} D_k S_k^-1 with S_{m+1} = S_1 (random, well conditioned): the product is S_1 (D_m ... D_1) S_1^-1.

    D_k: a multiplier near 1, a negative real one, a rotating pair and two strongly damped reals (one of alternating
    sign), so that the exact multipliers are the products of D's entries: ln|mu| (6,) and arg mu (6,), by decreasing modulus.
    """
    n = 6
    s = [np.eye(n) + 0.3 * rng.standard_normal((n, n)) for _ in range(m)]
    s.append(s[0])
    logs, angles, factors = np.zeros(n), np.zeros(n), []
    for k in range(m):
        d = np.zeros((n, n))
        entries = [rng.uniform(0.9, 1.1), -rng.uniform(0.5, 1.0), rng.uniform(1e-6, 1e-5), rng.uniform(1e-6, 1e-5) * (-1) ** k]
        radius, turn = rng.uniform(0.3, 0.6), rng.uniform(0.1, 0.5)
        d[0, 0], d[1, 1], d[4, 4], d[5, 5] = entries
        d[2:4, 2:4] = radius * _rotation(turn)
        logs += np.log(np.abs([entries[0], entries[1], radius, radius, entries[2], entries[3]]))
        angles += [0.0, math.pi, turn, -turn, 0.0, math.pi * (k % 2)]
        factors.append(s[k + 1] @ d @ np.linalg.inv(s[k]))
    return np.array(factors), logs, angles


def _high_precision(factors: np.ndarray) -> list:
    """The eigenvalues of the product of the (rounded) factors in 600-digit arithmetic, by decreasing modulus."""
    with mpmath.workdps(600):
        product = mpmath.eye(factors.shape[1])
        for factor in factors:
            product = mpmath.matrix(factor.tolist()) * product
        values = mpmath.eig(product, left=False, right=False)
        return sorted(values, key=lambda z: -abs(z))


def _wrapped(angle):
    return (np.asarray(angle) + math.pi) % (2.0 * math.pi) - math.pi


def test_products_of_conjugated_random_factors_match_600_digit_eigenvalues_down_to_1e_150():
    # The product's smallest multipliers, near 1e-160, are far below the formed product's round-off (1e-16): its
    # eigenvalues miss them by many decades, the periodic Schur form keeps 9 digits of them and 14 of the others.
    factors, exact_logs, exact_angles = _conjugated_chain(np.random.default_rng(2), 30)
    found = periodic_schur_multipliers(factors)
    reference = _high_precision(factors)
    ref_logs = np.array([float(mpmath.log(abs(z))) for z in reference])
    assert ref_logs[-1] < math.log(1e-150)
    assert found.log_moduli == pytest.approx(ref_logs, rel=1e-11, abs=1e-12)
    assert np.sort(found.log_moduli) == pytest.approx(np.sort(exact_logs), rel=1e-11)
    # The complex pair's angles and the real ones' signs.
    ref_angles = np.array([float(mpmath.arg(z)) for z in reference])
    assert np.sort(np.abs(_wrapped(found.angles))) == pytest.approx(np.sort(np.abs(_wrapped(ref_angles))), abs=1e-9)
    assert np.sort(_wrapped(found.angles)) == pytest.approx(np.sort(_wrapped(exact_angles)), abs=1e-9)
    formed = np.linalg.eigvals(np.linalg.multi_dot(factors[::-1]))
    assert np.min(np.abs(formed)) > 1e-40


def test_a_damped_linear_system_has_multipliers_exp_lambda_t_from_segments_of_expm():
    # x' = A x with eigenvalues -0.01 +- 2i, -0.5 +- 0.7i, -2, -5 (a damped oscillator pair and overdamped modes),
    # A = S diag S^-1: the monodromy over T = 60 is expm(A T), its multipliers exp(lambda T), down to exp(-300) = 5e-131.
    rng = np.random.default_rng(7)
    lambdas = np.array([-0.01 + 2.0j, -0.01 - 2.0j, -0.5 + 0.7j, -0.5 - 0.7j, -2.0, -5.0])
    real = np.zeros((6, 6))
    real[0:2, 0:2] = [[-0.01, -2.0], [2.0, -0.01]]
    real[2:4, 2:4] = [[-0.5, -0.7], [0.7, -0.5]]
    real[4, 4], real[5, 5] = -2.0, -5.0
    s = np.eye(6) + 0.2 * rng.standard_normal((6, 6))
    a = s @ real @ np.linalg.inv(s)
    period, m = 60.0, 120
    step = sla.expm(a * period / m)
    found = periodic_schur_multipliers(np.repeat(step[None], m, axis=0))
    order = np.argsort(-lambdas.real, kind="stable")
    assert found.log_moduli == pytest.approx(lambdas.real[order] * period, rel=1e-10)
    assert found.log_moduli[-1] / math.log(10.0) == pytest.approx(-300.0 / math.log(10.0), rel=1e-10)
    # The pairs' angles are +-Im(lambda) T modulo 2 pi, the positive one first.
    assert found.angles[0] == pytest.approx(abs(_wrapped(2.0 * period)), abs=1e-8)
    assert found.angles[1] == pytest.approx(-found.angles[0], abs=1e-15)
    assert found.angles[2] == pytest.approx(abs(_wrapped(0.7 * period)), abs=1e-8)
    assert np.all(found.angles[4:] == 0.0)
    # The formed product cannot see below its round-off.
    formed = np.abs(np.linalg.eigvals(np.linalg.matrix_power(step, m)))
    assert np.min(formed) > 1e-60


def test_multipliers_below_the_floating_point_range_keep_their_log_moduli():
    # diag(1, 1e-3, 1e-6) over 150 segments: 1, 1e-450, 1e-900, zeros as values, exact as log-moduli.
    rng = np.random.default_rng(3)
    s = np.eye(3) + 0.2 * rng.standard_normal((3, 3))
    step = s @ np.diag([1.0, -1e-3, 1e-6]) @ np.linalg.inv(s)
    found = periodic_schur_multipliers([step] * 150)
    # The formed step's 1e-6 eigenvalue carries its own round-off, eps / 1e-6 relative, 150 times over (1e-9 in
    # log10 on an AMD EPYC's BLAS): the bound is that, not the product's, which is exact to round-off per segment.
    assert found.log10_moduli == pytest.approx([0.0, -450.0, -900.0], rel=2e-11, abs=1e-12)
    assert found.values[1] == 0.0 and found.values[2] == 0.0
    assert found.angles.tolist() == [0.0, 0.0, 0.0]  # (-1e-3)^150 > 0


def test_many_close_moduli_spanning_decades_are_separated():
    # 20 rotating pairs whose moduli exp(-c_i) per segment step by 0.85 from 1 to exp(-3): over 40 segments the
    # multipliers run from 1 to 1e-52 with neighbours only 0.001 apart per period, so that no pair is isolated by
    # the first sweeps; an iteration stopped early (or a block taken from its formed product) misses the small ones.
    rng = np.random.default_rng(5)
    n, m = 40, 40
    decay = np.linspace(0.0, 3.0, n // 2)
    s = [np.eye(n) + 0.2 / math.sqrt(n) * rng.standard_normal((n, n)) for _ in range(m)]
    s.append(s[0])
    factors = np.array(
        [
            s[k + 1] @ sla.block_diag(*(math.exp(-c) * _rotation(rng.uniform(0.1, 1.0)) for c in decay)) @ np.linalg.inv(s[k])
            for k in range(m)
        ]
    )
    found = periodic_schur_multipliers(factors)
    assert found.separated
    assert found.log_moduli == pytest.approx(np.repeat(-m * decay, 2), rel=1e-10, abs=1e-10)
    assert not periodic_schur_multipliers(factors, max_sweeps=1).separated


def test_ordering_is_by_decreasing_modulus_with_a_pairs_positive_angle_first():
    rng = np.random.default_rng(4)
    factors = rng.standard_normal((5, 7, 7))
    found = periodic_schur_multipliers(factors)
    assert np.all(np.diff(found.log_moduli) <= 1e-12)
    formed = np.linalg.eigvals(np.linalg.multi_dot(factors[::-1]))
    assert np.sort_complex(found.values) == pytest.approx(np.sort_complex(formed), rel=1e-9)
    for k in np.flatnonzero(found.values.imag > 0):
        assert found.values[k + 1] == pytest.approx(np.conj(found.values[k]), rel=1e-12)


def test_equal_moduli_and_single_factors():
    # Rotations: every multiplier on the unit circle (the iteration cannot separate them: one block); one factor: its eig.
    rotations = [sla.block_diag(_rotation(0.1 * k), _rotation(0.3)) for k in range(1, 6)]
    found = periodic_schur_multipliers(rotations)
    assert found.log_moduli == pytest.approx(np.zeros(4), abs=1e-13)
    assert np.sort(np.abs(found.angles)) == pytest.approx(np.sort([1.5, 1.5, _wrapped(1.5), _wrapped(1.5)]), abs=1e-12)
    single = np.array([[2.0, 1.0], [0.0, -3.0]])
    assert periodic_schur_multipliers([single]).values == pytest.approx([-3.0, 2.0])
    assert periodic_schur_multipliers(np.array([[[0.5]], [[-4.0]]])).values == pytest.approx([-2.0])


@pytest.mark.parametrize(
    ("segments", "match"),
    [
        (np.ones((2, 3)), "square n x n"),
        (np.ones((2, 3, 4)), "square n x n"),
        (np.ones((0, 3, 3)), "m >= 1"),
        ([np.eye(2), np.eye(3)], "one size"),
        (np.full((2, 2, 2), np.nan), "finite, got nan at segment 0, entry \\(0, 0\\)"),
        (np.eye(2)[None] * 1j, "real"),
    ],
)
def test_bad_segments_are_refused_naming_what_is_wrong(segments, match):
    with pytest.raises(ValueError, match=match):
        periodic_schur_multipliers(segments)


def test_bad_max_sweeps_is_refused():
    with pytest.raises(ValueError, match="max_sweeps must be an integer >= 1, got 0"):
        periodic_schur_multipliers([np.eye(2)], max_sweeps=0)


def _damping_rate(params: ChainParams) -> float:
    """sum_i gamma_i / mass_i: minus the trace of the linearised flow, the same at every state of the chain."""
    return float(np.sum(per_dof(params, params.damping) / pack(params, params.particle_inertia)))


def test_long_orbit_multipliers_obey_liouville_by_segments_where_the_formed_monodromy_cannot():
    # Nonlinear N = 1 near its SNIC (M = 0.265, T = 15.9): the smallest multiplier is about 1e-26, below the formed
    # monodromy's round-off, whose eigenvalues then violate prod |mu| = exp(-T sum gamma_i / m_i) by half of its
    # logarithm; 16 segments satisfy it to 1e-8, and the multipliers above 1e-10 stay the formed monodromy's.
    options = {"tol": 1e-10, "rtol": 1e-12, "atol": 1e-12}
    formed = find_periodic_orbit(N1, "nonlinear", 0.265, **options)
    split = find_periodic_orbit(N1, "nonlinear", 0.265, segments=16, **options)
    exact = -split.period * _damping_rate(N1)
    assert np.sum(split.log_moduli) == pytest.approx(exact, rel=1e-8)
    assert np.sum(formed.log_moduli) != pytest.approx(exact, rel=0.1)
    assert split.log_moduli[-1] < math.log(1e-20)
    assert split.as_dict()["floquet_multipliers_log10_abs"] == pytest.approx(split.log_moduli / math.log(10.0))
    assert "floquet_multipliers_log10_abs" not in formed.as_dict()
    big = np.abs(formed.multipliers) > 1e-10
    assert np.sort(np.abs(split.multipliers[big])) == pytest.approx(np.sort(np.abs(formed.multipliers[big])), abs=1e-10)


def test_collocation_multipliers_obey_liouville_on_a_long_orbit():
    # The same orbit by collocation on 100 intervals of NCOL = 7 (fine enough to resolve the damped modes): the
    # periodic Schur form of the intervals' transfer matrices gives its smallest multiplier near 1e-26 with the
    # product of all of them right to 1e-8; the trivial multiplier stays within 1e-10 of 1.
    orbit = find_collocation_orbit(N1, "nonlinear", 0.265, ntst=100, ncol=7)
    assert np.sum(orbit.log_moduli) == pytest.approx(-orbit.period * _damping_rate(N1), rel=1e-8)
    assert orbit.log_moduli[-1] < math.log(1e-20)
    assert orbit.trivial_multiplier_error < 1e-10
    assert orbit.as_dict()["floquet_multipliers_log10_abs"] == pytest.approx(orbit.log_moduli / math.log(10.0))


@pytest.mark.slow
def test_collocation_resolves_multipliers_of_1e_170_at_period_100_on_a_fine_mesh():
    # Towards the SNIC to T > 100 (M - M_c ~ 1e-4): Liouville's product is 1e-181, the smallest multiplier about
    # 1e-172. On 400 intervals of NCOL = 7 the damped modes are resolved, and the periodic Schur form of the
    # intervals' transfer matrices gives the product to 1e-10 (the FLOWKM pencil used before gave 1e-28).
    start = find_collocation_orbit(N1, "nonlinear", 0.3, ntst=80)
    last = continue_collocation(start, moment_min=0.1, period_max=100.0).orbits[-1]
    orbit = find_collocation_orbit(N1, "nonlinear", last.moment, guess=last, ntst=400, ncol=7)
    assert orbit.period > 100.0
    assert np.sum(orbit.log_moduli) == pytest.approx(-orbit.period * _damping_rate(N1), rel=1e-10)
    assert orbit.log_moduli[-1] < math.log(1e-150)
    assert orbit.trivial_multiplier_error < 1e-10


def test_segments_are_refused_outside_the_dense_and_blocks_shooting():
    with pytest.raises(ValueError, match="segments must be an integer >= 1"):
        find_periodic_orbit(N1, "sine", 0.5, segments=0)
    with pytest.raises(ValueError, match="segments applies to the dense and blocks shooting only"):
        find_periodic_orbit(N1, "sine", 0.5, segments=4, method="collocation")
