"""Waves: the infinite chain's branches, the continuum dispersion, and the finite chain's modes."""

from __future__ import annotations

import numpy as np
import pytest

from conftest import ROUND_OFF, random_geometries
from cosserat_chain import ChainParams, moment_load
from cosserat_chain.analysis.dispersion import (
    BRANCHES,
    continuum_dispersion,
    dispersion,
    finite_modes,
    parameter_scan,
    wave_summary,
)
from cosserat_chain.models import NONLINEAR
from cosserat_chain.models.linear import bloch_stiffness, stiffness_matrix
from cosserat_chain.numerics.newton import solve_equilibrium
from cosserat_chain.state import pack

GEOMETRIES = random_geometries(6, seed=7) + [ChainParams()]


@pytest.mark.parametrize("params", GEOMETRIES)
def test_branches_are_the_eigenvalues_of_the_bloch_stiffness(params):
    q = np.linspace(-np.pi, np.pi, 41)
    scale = 1.0 / np.sqrt(np.array(params.inertia))
    reference = np.linalg.eigvalsh(bloch_stiffness(params, q) * scale[:, None] * scale[None, :])
    omega2 = dispersion(params, q).omega2
    top = np.max(reference)
    np.testing.assert_allclose(np.sort(omega2.T, axis=1), reference, rtol=0, atol=1e-12 * top)
    # Rows are labelled: the longitudinal row is k_u s2 / m, the acoustic row lies below the optical one.
    np.testing.assert_allclose(omega2[0], params.k_u * 4 * np.sin(q / 2) ** 2 / params.m, rtol=ROUND_OFF, atol=ROUND_OFF)
    assert np.all(omega2[1] <= omega2[2])


@pytest.mark.parametrize("params", GEOMETRIES)
def test_long_wave_limits(params):
    q = np.array([1e-3, 2e-3])
    omega = dispersion(params, q).omega
    # omega_L ~ q sqrt(k_u/m) and omega_TA ~ q^2 b sqrt(2 E1/m) / h, both with relative corrections O(q^2).
    np.testing.assert_allclose(omega[0] / q, np.sqrt(params.k_u / params.m), rtol=1e-6)
    np.testing.assert_allclose(omega[1] / q**2, params.b * np.sqrt(2 * params.E1 / params.m) / params.h, rtol=1e-4)
    at_zero = dispersion(params, 0.0).omega[:, 0]
    np.testing.assert_allclose(at_zero, [0.0, 0.0, np.sqrt(2 * params.b**2 * params.D2 / params.j)], rtol=ROUND_OFF, atol=ROUND_OFF)


@pytest.mark.parametrize("params", GEOMETRIES)
def test_zone_boundary_values(params):
    omega = dispersion(params, np.pi).omega[:, 0]
    transverse, rotational = 2 * np.sqrt(params.k_v / params.m), np.sqrt(8 * params.b**2 * params.E1 / params.j)
    expected = [2 * np.sqrt(params.k_u / params.m), min(transverse, rotational), max(transverse, rotational)]
    np.testing.assert_allclose(omega, expected, rtol=1e-12)


@pytest.mark.parametrize("params", GEOMETRIES[:3])
def test_continuum_dispersion_agrees_at_long_waves_but_bends_with_D1_instead_of_E1(params):
    q = np.array([1e-3, 2e-3])
    discrete, continuum = dispersion(params, q).omega2, continuum_dispersion(params, q).omega2
    np.testing.assert_allclose(continuum[[0, 2]], discrete[[0, 2]], rtol=1e-5)
    # Acoustic branch: omega^2 ~ 2 b^2 X q^4 / (m h^2) with X = D1 (continuum eq. 6), X = E1 = D1 + D2/4 (chain).
    flexural = 2 * params.b**2 * q**4 / (params.m * params.h**2)
    np.testing.assert_allclose(continuum[1] / flexural, params.D1, rtol=1e-5)
    np.testing.assert_allclose(discrete[1] / flexural, params.E1, rtol=1e-5)


def test_continuum_acoustic_branch_is_imaginary_for_the_paper_chain(paper):
    assert paper.D1 < 0
    curves = continuum_dispersion(paper, np.array([0.1, 1.0]))
    assert np.all(curves.omega2[1] < 0) and np.all(np.isnan(curves.omega[1]))
    assert np.all(np.isfinite(dispersion(paper, np.array([0.1, 1.0])).omega))


def test_wave_summary_of_the_paper_chain(paper):
    summary = wave_summary(paper)
    k_v, j = 8 * 0.04 / 0.52, 0.08 / 3
    assert summary.gap == pytest.approx((2 * np.sqrt(k_v), np.sqrt(8 * 0.04 / j)), rel=1e-12)
    assert summary.bands["rotational_optical"][1] == pytest.approx(np.sqrt(2 * 0.04 * paper.D2 / j), rel=1e-12)
    # The longitudinal band (up to 2 sqrt(k_u/m) = 3.68) covers the v-phi gap: no complete gap.
    assert summary.bands["longitudinal"][1] > summary.gap[1] and summary.complete_gaps == ()
    assert set(summary.as_dict()) >= {"at_zero", "at_pi", "bands", "gap", "gap_width", "complete_gaps"}


def test_band_edges_inside_the_zone_are_found():
    # Heavy rotation (large j): the optical branch has its minimum inside the zone, not at 0 or pi.
    params = ChainParams(b=0.4, a=0.1, j=0.5, E2=3.0)
    summary = wave_summary(params)
    q = np.linspace(0, np.pi, 20001)
    omega = dispersion(params, q).omega
    for row, name in enumerate(BRANCHES):
        assert summary.bands[name][0] == pytest.approx(np.min(omega[row]), rel=1e-7, abs=1e-12)
        assert summary.bands[name][1] == pytest.approx(np.max(omega[row]), rel=1e-7)


def test_complete_gap_appears_when_longitudinal_waves_are_stiff_enough_to_clear_it():
    # Soft horizontal links keep the longitudinal band low; then nothing propagates in the v-phi gap above it.
    params = ChainParams(E1=0.05, E2=1.0, b=0.3, a=0.35)
    summary = wave_summary(params)
    assert summary.gap is not None and summary.complete_gaps
    low, high = summary.complete_gaps[0]
    assert low == pytest.approx(max(summary.bands["longitudinal"][1], summary.gap[0]))
    assert high == pytest.approx(summary.gap[1])


def test_parameter_scan_matches_wave_summary_and_rejects_unknown_fields(paper):
    scan = parameter_scan(paper, "b", [0.1, 0.3])
    single = wave_summary(paper.replace(b=0.3))
    assert scan["gap_width"][1] == pytest.approx(single.gap[1] - single.gap[0])
    assert scan["rotational_optical_at_pi"][1] == pytest.approx(single.at_pi["rotational_optical"])
    with pytest.raises(ValueError, match="field must be one of"):
        parameter_scan(paper, "stiffness", [1.0])
    with pytest.raises(ValueError, match="b must be > 0"):
        parameter_scan(paper, "b", [-0.1])


@pytest.mark.parametrize("params", GEOMETRIES[:4])
def test_longitudinal_modes_of_the_clamped_chain_lie_exactly_on_their_branch(params):
    modes = finite_modes(params)
    longitudinal = np.sum(modes.shapes[:, 0] ** 2, axis=1) > np.sum(modes.shapes[:, 1:] ** 2, axis=(1, 2))
    found = np.sort(modes.frequencies[longitudinal])
    n = 2 * params.N
    expected = np.sort(dispersion(params, np.arange(1, n) * np.pi / n).omega[0])
    np.testing.assert_allclose(found, expected, rtol=1e-10)


def _outside_bands(params: ChainParams, modes) -> np.ndarray:
    """Modes whose frequency lies outside the bands of their polarisation (u: longitudinal; v, phi: the other two)."""
    summary = wave_summary(params)
    f = modes.frequencies
    longitudinal = np.sum(modes.shapes[:, 0] ** 2, axis=1) > np.sum(modes.shapes[:, 1:] ** 2, axis=(1, 2))

    def within(name: str) -> np.ndarray:
        low, high = summary.bands[name]
        return (f >= low * (1 - 1e-10)) & (f <= high * (1 + 1e-10))

    inside = np.where(longitudinal, within("longitudinal"), within("transverse_acoustic") | within("rotational_optical"))
    return ~inside


@pytest.mark.parametrize("n", [3, 10, 30])
def test_finite_chain_frequencies_lie_on_the_infinite_branches(n):
    params = ChainParams(N=n)
    modes = finite_modes(params)
    assert not np.any(_outside_bands(params, modes))
    # The bands fill up as N grows: every band frequency is near a mode, at distance O(1/N).
    if n == 30:
        band = dispersion(params, np.linspace(0, np.pi, 200)).omega
        distance = np.abs(band.ravel()[:, None] - modes.frequencies[None, :]).min(axis=1)
        assert np.max(distance) < 0.15


def test_modes_in_a_gap_are_bound_to_the_clamped_ends():
    # Some geometries bind modes in the v-phi gap; they are edge modes, not waves.
    params = ChainParams(E1=1.3, E2=2.8, h=1.6, a=0.6, b=0.08, m=1.8, N=20)
    modes = finite_modes(params)
    outside = np.where(_outside_bands(params, modes))[0]
    assert 1 <= outside.size <= 4
    for i in outside:
        weight = np.sum(modes.shapes[i] ** 2, axis=0)
        middle = weight[params.N - params.N // 2 : params.N + params.N // 2 + 1].sum()
        assert middle < 0.05 * weight.sum()


@pytest.mark.parametrize("params", GEOMETRIES[:4])
def test_linearisation_about_rest_gives_the_same_spectrum_for_every_model(params):
    spectra = {model: finite_modes(params, model) for model in ("linear", "sine", "nonlinear")}
    reference = spectra["linear"].omega2.real
    for model, modes in spectra.items():
        assert modes.stable, model
        np.testing.assert_allclose(modes.omega2.real, reference, rtol=0, atol=1e-9 * np.max(reference), err_msg=model)
        assert np.max(np.abs(modes.omega2.imag)) <= 1e-9 * np.max(reference)


def test_sine_model_about_a_loaded_state_uses_its_non_symmetric_jacobian(paper):
    x = solve_equilibrium(paper, "sine", moment_load(0.05))
    modes = finite_modes(paper, "sine", x)
    # K diag(1, 1, cos phi) is similar to the symmetric T K T with T = (C / M)^(1/2), C = diag(1, 1, cos phi).
    cos_phi = np.vstack([np.ones((2, paper.n_particles)), np.cos(x[2:3])])[:, 1:-1].T.reshape(-1)
    t = np.sqrt(cos_phi / np.tile(paper.inertia, paper.n_particles - 2))
    K = stiffness_matrix(paper).toarray()
    expected = np.linalg.eigvalsh(t[:, None] * K * t[None, :])
    np.testing.assert_allclose(modes.omega2.real, expected, rtol=1e-10, atol=1e-12)
    rest = finite_modes(paper, "sine")
    assert not np.allclose(modes.omega2.real, rest.omega2.real, rtol=1e-3)


def test_mode_shapes_solve_the_eigen_problem_about_a_nonlinear_static_state(paper):
    x = solve_equilibrium(paper, "nonlinear", moment_load(0.05))
    modes = finite_modes(paper, "nonlinear", x)
    K = NONLINEAR.stiffness(paper, x).toarray()
    mass = np.tile(paper.inertia, paper.n_particles - 2)
    vectors = np.stack([pack(paper, shape) for shape in modes.shapes], axis=1)
    np.testing.assert_allclose(K @ vectors, mass[:, None] * vectors * modes.omega2.real[None, :], atol=1e-10)
    np.testing.assert_allclose(vectors.T @ (mass[:, None] * vectors), np.eye(vectors.shape[1]), atol=1e-10)
    assert np.all(modes.shapes[:, :, [0, -1]] == 0)


def test_bad_input_to_finite_modes_is_refused(paper):
    with pytest.raises(ValueError, match="model must be one of"):
        finite_modes(paper, "quadratic")
    with pytest.raises(ValueError, match=r"must have shape \(3, 2N\+1\)"):
        finite_modes(paper, "linear", np.zeros((3, 5)))
    with pytest.raises(ValueError, match="q must be a finite"):
        dispersion(paper, [0.1, np.nan])
