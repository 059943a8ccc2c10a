"""``cosserat-chain orbit --segments M``: every Floquet multiplier of a long, strongly damped orbit.

Near the nonlinear one-particle chain's SNIC (M = 0.265, T = 15.9) the smallest multiplier is about
1e-26, below the formed monodromy's round-off. Liouville's formula fixes the product of all the
multipliers (the flow's divergence is minus the damping's trace at every state), so the sum of the
printed log10 |mu| is known exactly; the formed monodromy misses it by half.
"""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from typer.testing import CliRunner

from cosserat_chain import ChainParams
from cosserat_chain.cli import app
from cosserat_chain.state import pack, per_dof

runner = CliRunner()


def _orbit(tmp_path, *extra):
    config = tmp_path / "N1.toml"
    config.write_text("N = 1\n")
    command = ["orbit", "--model", "nonlinear", "--moment", "0.265", "--turns", "1", "--config", str(config), "--json", *extra]
    result = runner.invoke(app, command)
    assert result.exit_code == 0, result.output
    return json.loads(result.output)


def test_segments_give_every_multiplier_with_liouvilles_product(tmp_path):
    params = ChainParams(N=1)
    rate = float(np.sum(per_dof(params, params.damping) / pack(params, params.particle_inertia)))
    split = _orbit(tmp_path, "--segments", "16")
    exact = -split["period"] * rate / math.log(10.0)
    assert sum(split["floquet_multipliers_log10_abs"]) == pytest.approx(exact, rel=1e-8)
    assert min(split["floquet_multipliers_log10_abs"]) < -25
    # Without segments: the formed monodromy's multipliers, its smallest at round-off, no log-moduli claimed.
    formed = _orbit(tmp_path)
    assert "floquet_multipliers_log10_abs" not in formed
    assert abs(sum(math.log10(m) for m in formed["floquet_multipliers_abs"]) - exact) > 0.1 * abs(exact)
    # The multipliers above the formed monodromy's round-off are the same.
    big = [m for m in formed["floquet_multipliers_abs"] if m > 1e-10]
    assert np.allclose(sorted(big), sorted(m for m in split["floquet_multipliers_abs"] if m > 1e-10), rtol=1e-8, atol=1e-10)


def test_segments_with_the_blocks_give_the_dense_segments_multipliers(tmp_path):
    # The long chains' shooting (auto from N = 50) forced on the one-particle chain: the same pieces, assembled from column blocks.
    params = ChainParams(N=1)
    exact = -_orbit(tmp_path)["period"] * float(np.sum(per_dof(params, params.damping) / pack(params, params.particle_inertia)))
    blocks = _orbit(tmp_path, "--segments", "16", "--method", "blocks")
    dense = _orbit(tmp_path, "--segments", "16", "--method", "dense")
    assert sum(blocks["floquet_multipliers_log10_abs"]) == pytest.approx(exact / math.log(10.0), rel=1e-8)
    assert np.allclose(blocks["floquet_multipliers_log10_abs"], dense["floquet_multipliers_log10_abs"], rtol=0, atol=1e-8)
    assert 0 < blocks["trivial_multiplier_error"] < 1e-8


@pytest.mark.parametrize(
    "extra", [("--segments", "0"), ("--segments", "2", "--method", "krylov"), ("--segments", "x"), ("--segments", "1000000000")]
)
def test_bad_segments_are_refused_with_the_value(tmp_path, extra):
    # Refused before the orbit is computed (a billion segments: by the memory estimate, naming them).
    config = tmp_path / "N1.toml"
    config.write_text("N = 1\n")
    result = runner.invoke(app, ["orbit", "--model", "nonlinear", "--moment", "0.265", "--config", str(config), *extra])
    assert result.exit_code == 2 and "segments" in result.output and "Traceback" not in result.output


def test_turns_beyond_the_limit_are_refused_before_computing(tmp_path):
    result = runner.invoke(app, ["orbit", "--moment", "0.3", "--turns", "1000000000"])
    assert result.exit_code == 2 and "turns must be an integer from 1 to 1000" in result.output and "1000000000" in result.output
