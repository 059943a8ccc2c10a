"""The finite chain's first frequencies against its Timoshenko beam's (order 2) and eq. (6)'s (no convergence)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from conftest import random_geometries
from cosserat_chain import ChainParams
from cosserat_chain.analysis.beam_frequencies import beam_frequencies, chain_frequencies, frequency_convergence
from cosserat_chain.analysis.dispersion import finite_modes
from cosserat_chain.analysis.timoshenko import beam_stiffness

ENDS = [("clamped", "clamped"), ("pinned", "free"), ("free", "clamped"), ("free", "free")]


@pytest.mark.parametrize("ends", ENDS)
def test_chain_frequencies_are_the_dense_solvers_elastic_modes_split_into_families(ends):
    params = ChainParams(N=7, a=0.3, b=0.4, E2=0.5, left_end=ends[0], right_end=ends[1])
    modes = finite_modes(params)
    dense = np.sort(modes.frequencies[modes.rigid :])
    for family in ("flexural", "axial"):
        ours = chain_frequencies(params, 3, family)
        assert np.all(ours > 0)
        # Every one of the family's frequencies is one of the dense solver's.
        assert np.min(np.abs(dense[:, None] - ours[None, :]), axis=0) == pytest.approx(np.zeros(3), abs=1e-10)
    # The sparse path (N >= 10) agrees with the dense one.
    longer = params.replace(N=20)
    modes = finite_modes(longer)
    flexural = np.sort(modes.frequencies[modes.rigid :][np.abs(modes.shapes[modes.rigid :, 0]).max(axis=1) < 1e-8])
    # To the dense solver's round-off, eps |K| in omega^2 (1e-10 relative for the softest mode here).
    np.testing.assert_allclose(chain_frequencies(longer, 4), flexural[:4], rtol=1e-8)


def test_axial_beam_frequencies_are_the_strings_closed_form():
    params = ChainParams(N=12)
    speed = math.sqrt(beam_stiffness(params).EA / beam_stiffness(params).mass)
    L = params.N * params.h
    expected = np.arange(1, 5) * math.pi * speed / (2 * L)
    np.testing.assert_allclose(beam_frequencies(params, 4, "axial"), expected, rtol=1e-12)


@pytest.mark.parametrize("params", random_geometries(3, seed=11))
@pytest.mark.parametrize("ends", ENDS[:3])
def test_timoshenko_frequencies_converge_with_order_2_on_random_geometries(params, ends):
    params = params.replace(left_end=ends[0], right_end=ends[1])
    table = frequency_convergence(params, [100, 300, 1000], count=2)
    for order in table.orders():
        assert order == pytest.approx(2.0, abs=0.1)
    assert np.all(np.abs(table.timoshenko_error[-1]) < 2e-5)
    axial = frequency_convergence(params, [30, 100, 300], count=2, family="axial")
    for order in axial.orders():
        assert order == pytest.approx(2.0, abs=0.02)


def test_eq6_frequencies_do_not_converge_they_tend_to_sqrt_d1_over_e1_times_the_chains():
    params = ChainParams(a=0.3, b=0.4, E2=0.5)
    assert params.D1 > 0
    table = frequency_convergence(params, [30, 100, 1000], count=2)
    np.testing.assert_allclose(table.paper_error[-1], math.sqrt(params.D1 / params.E1) - 1, rtol=1e-4)
    assert all(abs(order) < 0.05 for order in table.orders("paper"))
    # The paper's chain (D1 < 0): eq. (6) has no real frequencies.
    paper = frequency_convergence(ChainParams(), [10, 30], count=1)
    assert np.all(np.isnan(paper.paper)) and paper.orders("paper") == [None]


def test_bad_input_is_refused_naming_it():
    with pytest.raises(ValueError, match="family"):
        chain_frequencies(ChainParams(), 2, "torsional")
    with pytest.raises(ValueError, match="count"):
        beam_frequencies(ChainParams(), 0)
    with pytest.raises(ValueError, match="bending"):
        beam_frequencies(ChainParams(), 1, bending=-1.0)
    with pytest.raises(ValueError, match="cut-off"):
        beam_frequencies(ChainParams(N=2), 30)
    with pytest.raises(ValueError, match="n_values"):
        frequency_convergence(ChainParams(), [])
    with pytest.raises(ValueError, match="more flexural modes"):
        chain_frequencies(ChainParams(N=2), 20)


def test_theory_cli_frequencies_json_is_the_librarys_and_bad_counts_exit_2(tmp_path):
    import json

    from typer.testing import CliRunner

    from cosserat_chain.cli import app

    config = tmp_path / "chain.toml"
    config.write_text('a = 0.3\nb = 0.4\nE2 = 0.5\nright_end = "free"\n')
    result = CliRunner().invoke(app, ["theory", "--config", str(config), "--n-list", "10,20", "--frequencies", "2", "--json"])
    assert result.exit_code == 0, result.output
    modes = json.loads(result.stdout)["frequencies"]
    params = ChainParams(a=0.3, b=0.4, E2=0.5, right_end="free", N=20)
    np.testing.assert_allclose(modes["flexural"]["chain"][1], chain_frequencies(params, 2), rtol=1e-12)
    np.testing.assert_allclose(modes["axial"]["timoshenko"][1], beam_frequencies(params, 2, "axial"), rtol=1e-12)
    assert len(modes["flexural"]["timoshenko_order"]) == 2
    printed = CliRunner().invoke(app, ["theory", "--config", str(config), "--n-list", "10,20", "--frequencies", "1"])
    assert printed.exit_code == 0 and "measured orders of Timoshenko's errors" in printed.output
    bad = CliRunner().invoke(app, ["theory", "--n-list", "10", "--frequencies", "0"])
    assert bad.exit_code == 2 and "--frequencies" in bad.output


def test_a_long_chains_frequencies_are_the_same_bits_at_every_call():
    """N = 16 (the sparse Lanczos path): ARPACK's own random start gave other last digits at each call
    (theory --frequencies' JSON differed between runs); a fixed start gives the same bits."""
    params = ChainParams(N=16)
    first = chain_frequencies(params, 3)
    for _ in range(3):
        assert np.array_equal(chain_frequencies(params, 3), first)
