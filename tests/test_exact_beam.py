"""The geometrically exact planar beam: its BVP against closed forms, its linearisation, and model (i) bent into a circle."""

from __future__ import annotations

import math

import numpy as np
import pytest

from conftest import random_geometries
from cosserat_chain import ChainParams
from cosserat_chain.analysis.exact_beam import (
    bending_convergence,
    bond_bending,
    cantilever,
    chain_end_moment,
    circle,
)
from cosserat_chain.analysis.timoshenko import PointLoad, beam_stiffness, static_solution

CANTILEVER = ChainParams(N=5, right_end="free")


def test_end_moment_bends_the_bvp_beam_into_the_closed_form_circle_that_closes_at_2_pi_ei_over_length():
    EI, length = beam_stiffness(CANTILEVER).EI, 2 * CANTILEVER.N * CANTILEVER.h
    closing = 2 * math.pi * EI / length
    solved = cantilever(CANTILEVER, end_moment=closing)
    exact = circle(CANTILEVER, closing, solved.s)
    for field in ("x", "y", "theta", "moment"):
        np.testing.assert_allclose(getattr(solved, field), getattr(exact, field), rtol=0, atol=1e-9 * length)
    # Closed into a ring: the free end is back on the clamped one, turned once.
    assert solved.x[-1] == pytest.approx(-CANTILEVER.N * CANTILEVER.h, abs=1e-9) and abs(solved.y[-1]) < 1e-9
    assert solved.theta[-1] == pytest.approx(2 * math.pi, rel=1e-12)


@pytest.mark.parametrize("params", random_geometries(3, seed=5))
def test_exact_beam_linearises_to_the_timoshenko_beam(params):
    chain = params.replace(N=4, right_end="free")
    EI, L = beam_stiffness(chain).EI, chain.N * chain.h
    gaps = []
    for scale in (1e-3, 1e-4):
        load = scale * EI / L**2  # a tip force whose deflection is about `scale` of the length
        solved = cantilever(chain, end_moment=0.5 * load * L, force=(0.0, load), steps=1)
        _, v, phi = static_solution(chain, solved.s - L, PointLoad(chain.N, moment=0.5 * load * L, force_v=load))
        gaps.append(max(np.abs(solved.y - v).max() / np.abs(v).max(), np.abs(solved.theta - phi).max() / np.abs(phi).max()))
    # The difference is the first nonlinear term, relative O(load^2): a transverse load's response is odd in it.
    assert gaps[1] < 1e-6 and gaps[0] / gaps[1] == pytest.approx(100.0, rel=0.05)


def test_axial_dead_load_stretches_the_beam_by_f_over_ea_exactly_as_the_timoshenko_beam():
    stiffness = beam_stiffness(CANTILEVER)
    pull = 0.2 * stiffness.EA
    solved = cantilever(CANTILEVER, force=(pull, 0.0))
    L = CANTILEVER.N * CANTILEVER.h
    u, _, _ = static_solution(CANTILEVER, solved.s - L, PointLoad(CANTILEVER.N, force_u=pull))
    np.testing.assert_allclose(solved.x, solved.s - L + u, rtol=0, atol=1e-10)
    np.testing.assert_allclose(solved.theta, 0.0, atol=1e-12)


def test_elastica_keeps_the_moment_balance_about_the_clamp():
    load = (0.0, 0.05)
    solved = cantilever(CANTILEVER, force=load, end_moment=0.02)
    arm = np.array([solved.x[-1] - solved.x, solved.y[-1] - solved.y])
    # m(s) = M0 + (r(2L) - r(s)) x F everywhere, the tip turned by a large angle.
    np.testing.assert_allclose(solved.moment, 0.02 + arm[0] * load[1] - arm[1] * load[0], rtol=0, atol=1e-8)
    assert solved.theta[-1] > 1.0


@pytest.mark.parametrize("params", [ChainParams(), *random_geometries(2, seed=9)])
def test_model_i_bent_by_an_end_moment_tends_to_the_circle_with_order_2(params):
    table = bending_convergence(params.replace(right_end="free"), [10, 20, 40, 80], angle=math.pi)
    assert table.order("moment") == pytest.approx(2.0, abs=0.05)
    assert table.order("tip") == pytest.approx(2.0, abs=0.05)
    # The per-bond reduction is the whole chain, to its round-off.
    assert np.all(table.direct_spread < 1e-7)
    assert np.all(np.abs(table.direct_tip - table.chain_tip).max(axis=1) < 1e-8 * table.length)


def test_closing_the_paper_chain_into_a_ring_takes_less_moment_than_the_beam_by_a_relative_1_42_over_n_squared():
    table = bending_convergence(ChainParams(right_end="free"), [100, 200], angle=2 * math.pi)
    assert np.all(table.tip_error < 1e-12)  # every bond alike: the chain's centres close exactly as well
    assert np.all(table.moment_error > 0)
    assert table.N[-1] ** 2 * table.moment_error[-1] == pytest.approx(4 * 0.3553, rel=0.01)


def test_one_bond_state_is_the_whole_chains():
    chain = ChainParams(N=3, right_end="free")
    state, moment = chain_end_moment(chain, 1.2)
    per_bond, chord = bond_bending(chain, 0.2)
    assert per_bond == pytest.approx(moment, rel=1e-10)
    assert complex(chain.h + state[0, 1] - state[0, 0], state[1, 1] - state[1, 0]) == pytest.approx(chord, rel=1e-10)


@pytest.mark.parametrize(
    ("call", "words"),
    [
        (lambda: cantilever(ChainParams()), "cantilever"),
        (lambda: cantilever(CANTILEVER, end_moment=math.inf), "finite"),
        (lambda: cantilever(CANTILEVER, steps=0), "steps"),
        (lambda: bending_convergence(CANTILEVER, [4], angle=7.0), "angle"),
        (lambda: bending_convergence(CANTILEVER, []), "n_values"),
        (lambda: circle(ChainParams(periodic=True), 0.1), "cantilever"),
    ],
)
def test_bad_input_is_refused_naming_it(call, words):
    with pytest.raises(ValueError, match=words):
        call()


def test_theory_cli_bends_the_cantilever_and_reports_orders_in_json_and_netcdf(tmp_path):
    import json

    import xarray as xr
    from typer.testing import CliRunner

    from cosserat_chain.cli import app

    out = tmp_path / "continua.nc"
    runner = CliRunner()
    result = runner.invoke(app, ["theory", "--n-list", "10,20,40", "--bend-angle", "3.0", "--json", "--out", str(out)])
    assert result.exit_code == 0, result.output
    bending = json.loads(result.stdout)["exact_beam"]
    library = bending_convergence(ChainParams(right_end="free"), [10, 20, 40], angle=3.0)
    assert bending["moment_error"] == pytest.approx(list(library.moment_error), rel=1e-9)
    assert bending["moment_order"] == pytest.approx(2.0, abs=0.05)
    with xr.open_dataset(out) as written:
        np.testing.assert_allclose(written["bending_tip_error"], library.tip_error, rtol=1e-9)
        assert "timoshenko_error" in written and written.attrs["bending_angle"] == 3.0
    bad = runner.invoke(app, ["theory", "--bend-angle", "7"])
    assert bad.exit_code == 2 and "--bend-angle" in bad.output


@pytest.mark.parametrize("params", [ChainParams(), *random_geometries(1, seed=12)])
def test_model_i_under_an_end_force_tends_to_the_exact_beams_elastica_with_order_2(params):
    from cosserat_chain.analysis.exact_beam import elastica_convergence

    table = elastica_convergence(params.replace(right_end="free"), [10, 20, 40, 80], load=2.0)
    assert table.beam_angle[-1] > 0.5  # a large deflection: the free end turned by about 45 degrees
    assert table.order("angle") == pytest.approx(2.0, abs=0.1)
    # The tip's error may change sign at small N (the random geometry's does near N = 10): its last halving.
    assert table.tip_error[-2] / table.tip_error[-1] == pytest.approx(4.0, rel=0.1)


def test_theory_cli_elastica_matches_the_library_and_refuses_a_bad_load():
    import json

    from typer.testing import CliRunner

    from cosserat_chain.analysis.exact_beam import elastica_convergence
    from cosserat_chain.cli import app

    runner = CliRunner()
    result = runner.invoke(app, ["theory", "--n-list", "5,10", "--elastica", "1.5", "--json"])
    assert result.exit_code == 0, result.output
    data = json.loads(result.stdout)["elastica"]
    library = elastica_convergence(ChainParams(right_end="free"), [5, 10], load=1.5)
    assert data["angle_error"] == pytest.approx(list(library.angle_error), rel=1e-8)
    bad = runner.invoke(app, ["theory", "--elastica", "-1"])
    assert bad.exit_code == 2 and "--elastica" in bad.output


def test_a_coarse_chain_whose_branch_folds_below_the_end_force_is_refused_with_where_it_folds(tmp_path):
    """N = 2 of large particles (a = 0.43 h) folds at 0.766 of F (2L)^2 / EI = 1.3: the elastica table says so
    (exit 2, the fold's fraction), where it raised Newton's traceback; just below the fold the chain's state is
    the one its branch from rest reaches, and just above none is."""
    import re

    from typer.testing import CliRunner

    from cosserat_chain.analysis.exact_beam import elastica_convergence
    from cosserat_chain.cli import app

    chain = ChainParams(E1=1.37, E2=0.61, a=0.43, b=0.29, m=1.2, j=0.07, left_end="clamped", right_end="free")
    config = tmp_path / "coarse.toml"
    config.write_text("E1 = 1.37\nE2 = 0.61\na = 0.43\nb = 0.29\nm = 1.2\nj = 0.07\n")
    result = CliRunner().invoke(app, ["theory", "--config", str(config), "--n-list", "2,4,8", "--elastica", "1.3"])
    assert result.exit_code == 2, result.output
    assert "N = 2 chain" in result.output and "folds at" in result.output
    fraction = float(re.search(r"folds at ([0-9.]+) of it", result.output).group(1))
    assert 0.7 < fraction < 0.8
    below = elastica_convergence(chain, [2], load=1.3 * fraction * (1 - 1e-3))
    with pytest.raises(ValueError, match="folds at"):
        elastica_convergence(chain, [2], load=1.3 * fraction * (1 + 1e-3))
    # Near its fold the coarse chain's tip is off the beam's by more than 0.01 h: its own state, not the beam sampled.
    assert below.chain_tip[0, 1] > 1.2 and abs(below.chain_tip[0, 1] - below.beam_tip[0, 1]) > 0.01
