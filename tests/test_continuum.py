"""Section 3: the continuum solutions against the discrete chain."""

from __future__ import annotations

import numpy as np
import pytest
from matplotlib.figure import Figure

from conftest import ROUND_OFF, random_geometries
from cosserat_chain import ChainParams
from cosserat_chain.analysis.beam import clamped_central_compliance
from cosserat_chain.analysis.continuum import (
    central_rotation,
    compare_profiles,
    convergence,
    discrete_residuals,
    discrete_static,
    general_solution,
    integration_constants,
    printed_D1,
    reduced_E1,
    reduced_solution,
    residue,
    sampled_state,
    solution,
)
from cosserat_chain.models import LINEAR
from cosserat_chain.plots.theory import plot_convergence, plot_profiles

# Chains with coupling (E2 > 0), which the continuum solution needs, of several lengths.
CHAINS = [p for p in random_geometries(8, seed=4) if p.E2 > 0.05] + [ChainParams(), ChainParams(N=12)]


def _scale(params: ChainParams, moment: float) -> float:
    """Typical size of the terms of eq. (5) for the sampled solution, to make round-off relative."""
    x = sampled_state(params, moment)
    return max(params.D1, params.D2, 1.0) * (np.max(np.abs(x[2])) + np.max(np.abs(x[1])) / params.h)


@pytest.mark.parametrize("params", CHAINS)
def test_eq11_satisfies_discrete_eq4_exactly(params):
    r4, _ = discrete_residuals(params, 0.7)
    x = sampled_state(params, 0.7)
    assert np.max(np.abs(r4)) * params.h**2 <= ROUND_OFF * 10 * np.max(np.abs(x[1:]) * np.array([[1.0], [params.h]]))
    # The package's linear model sees no transverse force at all on the sampled continuum solution.
    forces = LINEAR.forces(params, x)
    assert np.max(np.abs(forces[1])) <= ROUND_OFF * 10 * params.k_v * np.max(np.abs(x[1:]) * np.array([[1.0], [params.h]]))


@pytest.mark.parametrize("params", CHAINS)
def test_residue_in_eq5_equals_eq12_at_every_interior_site(params):
    moment = 0.7
    _, r5 = discrete_residuals(params, moment)
    expected = residue(params, moment)
    interior = np.r_[1 : params.N, params.N + 1 : 2 * params.N]
    np.testing.assert_allclose(r5[interior], expected, rtol=0, atol=ROUND_OFF * 10 * _scale(params, moment))
    # The moment balance (9) of the loaded particle and the clamped ends hold exactly.
    assert abs(r5[params.N]) <= ROUND_OFF * 10 * 2 * params.b**2 * _scale(params, moment)
    # Independently, through the linear model: its moment on particle k is 2 b^2 times the residue of eq. (5).
    forces = LINEAR.forces(params, sampled_state(params, moment))
    forces[2, params.N] += moment
    np.testing.assert_allclose(forces[2, interior], 2 * params.b**2 * expected, rtol=1e-10)
    assert abs(forces[2, params.N]) <= ROUND_OFF * 10 * 2 * params.b**2 * _scale(params, moment)


@pytest.mark.parametrize("params", CHAINS[:4])
def test_closed_form_eq11_equals_eq7_with_constants_from_conditions_8_and_10(params):
    x = np.linspace(0.0, params.N * params.h, 9)
    constants = integration_constants(params, -1.3)
    np.testing.assert_allclose(general_solution(params, x, constants), solution(params, x, -1.3), rtol=1e-10, atol=1e-12)
    assert central_rotation(params, -1.3) == pytest.approx(float(solution(params, 0.0, -1.3)[1]), rel=1e-12)


@pytest.mark.parametrize("params", CHAINS[:4])
def test_reduced_solution_equals_eq11_at_D1_zero(params):
    x = np.linspace(0.0, params.N * params.h, 7)
    np.testing.assert_allclose(reduced_solution(params, x, 0.4), solution(params, x, 0.4, D1=0.0), rtol=1e-12, atol=1e-14)
    # The chain whose geometry gives D1 = 0 (E1 = (h/d)^2 E2) has the same solution, to round-off in D1.
    reduced = params.replace(E1=reduced_E1(params))
    assert abs(reduced.D1) <= ROUND_OFF * reduced.D2
    np.testing.assert_allclose(reduced_solution(reduced, x, 0.4), solution(reduced, x, 0.4), rtol=1e-9, atol=1e-12)


def test_reduced_solution_meets_its_boundary_conditions(paper):
    h, L, moment = paper.h, paper.N * paper.h, 0.3
    (v0, v_h, v_L), (phi0, _, phi_L) = reduced_solution(paper, np.array([0.0, h, L]), moment)
    assert v0 == 0 and v_L == 0 and phi_L == 0
    assert 2 * paper.b**2 * paper.D2 * (v_h / h - phi0) + moment == pytest.approx(0.0, abs=ROUND_OFF)


def test_continuum_compliance_converges_to_discrete_at_the_order_of_the_residue():
    table = convergence(ChainParams(), [20, 40, 80, 160, 320, 640])
    residue_order = -np.polyfit(np.log(table.N), np.log(table.residue), 1)[0]
    assert residue_order == pytest.approx(1.0, abs=0.02)
    assert table.order() == pytest.approx(residue_order, abs=0.03)
    assert np.all(np.diff(table.relative_error) < 0)


@pytest.mark.parametrize("params", CHAINS[:3])
def test_residue_vanishes_like_one_over_N(params):
    # N * residue -> M D2 / (2 b^2 (8 D1 + 2 D2)) = M D2 / (16 b^2 E1), with a correction O(1/N).
    limit = params.D2 / (16 * params.b**2 * params.E1)
    gaps = [abs(n * residue(params.replace(N=n)) - limit) for n in (100, 1000, 10000)]
    assert gaps[1] < gaps[0] / 8 and gaps[2] < gaps[1] / 8
    assert gaps[2] < 1e-3 * limit


def test_sampled_solution_is_mirror_symmetric_and_clamped(paper):
    x = sampled_state(paper, 1.0)
    np.testing.assert_array_equal(x[1], -x[1][::-1])
    np.testing.assert_array_equal(x[2], x[2][::-1])
    assert np.all(x[0] == 0) and np.all(x[:, [0, -1]] == 0)


def test_printed_D1_turns_the_paper_chain_against_the_moment(paper):
    # Erratum 2: with Section 3's printed D1 the continuum phi(0) has the wrong sign.
    assert printed_D1(paper) == pytest.approx(1 - 2 / 0.52)
    assert central_rotation(paper) > 0 and discrete_static(paper)[2, paper.N] > 0
    assert central_rotation(paper, D1=printed_D1(paper)) < 0


def test_bad_input_is_refused_with_the_field_and_value(paper):
    with pytest.raises(ValueError, match=r"x must lie in the half chain 0 <= x <= L = N h = 3.0, got 3.5"):
        solution(paper, [1.0, 3.5])
    with pytest.raises(ValueError, match="E2 > 0"):
        central_rotation(paper.replace(E2=0.0))
    with pytest.raises(ValueError, match="moment must be finite"):
        residue(paper, float("nan"))
    with pytest.raises(ValueError, match="constants must be four"):
        general_solution(paper, 0.0, [1.0, 2.0])
    with pytest.raises(ValueError, match="empty"):
        convergence(paper, [])
    with pytest.raises(ValueError, match="N must be an integer >= 1"):
        convergence(paper, [3, 0])


def test_plots_show_the_profiles_and_the_convergence(paper):
    comparison = compare_profiles(paper.replace(N=6), 0.5)
    fig = plot_profiles(comparison)
    assert isinstance(fig, Figure) and len(fig.axes) == 2
    markers = fig.axes[1].lines[2]
    np.testing.assert_array_equal(markers.get_ydata(), comparison.discrete[2])
    table = convergence(paper, [3, 10, 30])
    fig = plot_convergence(table)
    (ax,) = fig.axes
    assert ax.get_xscale() == "log" and ax.get_yscale() == "log"
    np.testing.assert_array_equal(ax.lines[0].get_ydata(), table.relative_error)


def test_the_discrete_compliance_of_long_chains_is_checked_against_the_chains_closed_form(monkeypatch):
    # K's condition number grows like N^4 (the clamped chain's softest mode): a factorisation of
    # K, even refined in extended precision, was 4e-4 off at N = 3 10^4 and 60 % at 10^5, and
    # made theory flag the exact root solve "inaccurate". The check is the nodal Timoshenko
    # beam's closed form, equal to the chain in exact arithmetic: the root solve agrees with it
    # to round-off at N = 3 10^4 (condition 4e18; N = 10^5 with the slow tests below), and the
    # continuum's error falls like 1/N.
    table = convergence(ChainParams(), [100, 200, 30_000])
    assert table.condition[1] / table.condition[0] == pytest.approx(16, rel=0.05)
    assert table.condition[2] > 1e18 and list(table.accurate) == [True] * 3
    assert np.all(table.discrete_error < 1e-12)
    for n, discrete in zip(table.N, table.discrete):
        assert discrete == pytest.approx(clamped_central_compliance(ChainParams(N=int(n)), nodal=True), rel=1e-12)
    # N times the error: 0.9587 at N = 200, 0.9615 at 3 10^4 (its limit as N grows).
    assert 30_000 * table.relative_error[2] == pytest.approx(200 * table.relative_error[1], rel=1e-2)
    assert table.order() == pytest.approx(1.0, abs=0.01)
    # A discrete value 1e-5 off (a solve that lost digits) is flagged, left out of the fit, and theory says why.
    from cosserat_chain.analysis import continuum

    exact_solve = continuum.discrete_static

    def lossy(params, moment=1.0):
        state = exact_solve(params, moment)
        return state * (1 + 1e-5) if params.N == 300 else state

    monkeypatch.setattr(continuum, "discrete_static", lossy)
    flagged = convergence(ChainParams(), [100, 200, 300])
    assert list(flagged.accurate) == [True, True, False]
    assert flagged.discrete_error[2] == pytest.approx(1e-5, rel=1e-4)
    assert flagged.order() == pytest.approx(float(-np.polyfit(np.log([100, 200]), np.log(flagged.relative_error[:2]), 1)[0]))
    from typer.testing import CliRunner

    from cosserat_chain.cli import app

    result = CliRunner().invoke(app, ["theory", "--n-list", "100,200,300"])
    assert result.exit_code == 0, result.output
    rows = [line for line in result.stdout.splitlines() if line.split()[:1] in (["100"], ["200"], ["300"])]
    assert [row.endswith("(inaccurate)") for row in rows[:3]] == [False, False, True]
    assert "N = 300: the discrete value is inaccurate: it is 1.0e-05 (relative) off the chain's closed form" in result.stdout


@pytest.mark.slow
def test_the_root_solve_of_a_chain_of_10_5_particles_is_the_closed_form_to_round_off():
    """N = 10^5 (condition above 1e20, where a factorisation of K was 60 % off): the root solve equals the nodal beam's
    closed form to round-off, and N times the continuum's error is the same as at N = 3 10^4 to 1e-4."""
    table = convergence(ChainParams(), [30_000, 100_000])
    assert table.condition[1] > 1e20 and list(table.accurate) == [True] * 2
    assert np.all(table.discrete_error < 1e-12)
    for n, discrete in zip(table.N, table.discrete):
        assert discrete == pytest.approx(clamped_central_compliance(ChainParams(N=int(n)), nodal=True), rel=1e-12)
    assert 100_000 * table.relative_error[1] == pytest.approx(30_000 * table.relative_error[0], rel=1e-4)


def test_the_signed_error_changes_sign_for_some_geometries_and_theory_says_so(tmp_path):
    from typer.testing import CliRunner

    from cosserat_chain.cli import app

    chain = ChainParams(a=0.3, b=0.1, E1=2.0, E2=0.3)
    table = convergence(chain, [2, 5, 100])
    assert np.allclose(np.abs(table.signed_error), table.relative_error, rtol=1e-14, atol=0)
    # Below the continuum at N = 2, above it from N = 5 on: |error| ~ 1/N only past the change.
    assert table.signed_error[0] < 0 < table.signed_error[1] and table.signed_error[2] > 0
    paper = convergence(ChainParams(), [2, 5, 100])
    assert np.all(paper.signed_error > 0)
    assert convergence(ChainParams(), [1]).relative_error[0] < 1e-12  # one free particle: equal to round-off
    config = tmp_path / "chain.toml"
    config.write_text("a = 0.3\nb = 0.1\nE1 = 2.0\nE2 = 0.3\n")
    changed = CliRunner().invoke(app, ["theory", "--config", str(config), "--n-list", "2,5,100"])
    same = CliRunner().invoke(app, ["theory", "--n-list", "2,5,100"])
    assert changed.exit_code == 0 and "changes sign" in changed.stdout
    assert same.exit_code == 0 and "changes sign" not in same.stdout
