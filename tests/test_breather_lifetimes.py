"""Lifetimes along whole roto-breather families (the chain's, a user system's): direct runs from the perturbed orbits against the multipliers."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
import xarray as xr
from typer.testing import CliRunner

from cosserat_chain import ChainParams
from cosserat_chain.cli import app
from cosserat_chain.experiments.breathers import lifetime, roto_breather_family
from cosserat_chain.experiments.system_breathers import roto_breather_family as system_family
from cosserat_chain.experiments.system_breathers import system_lifetime
from cosserat_chain.plots.breathers import breather_family_figure
from cosserat_chain.systems import takeno_peyrard

RUN = 200


@pytest.fixture(scope="module")
def family():
    """The sine chain's family at N = 3: weakly unstable at 5.0 and 6.0 (a complex quartet), stable at 6.6."""
    result = roto_breather_family(ChainParams(N=3, gamma_u=0, gamma_v=0, gamma_phi=0), "sine", [5.0, 6.0, 6.6])
    result.measure_lifetimes(RUN)
    return result


def test_a_stable_member_outlives_the_run(family):
    stable = family.family.orbits[2]
    life = family.lifetimes[2]
    assert stable.stable
    assert life.periods is None and life.run_periods == RUN
    assert np.all(life.deviation < 1e-2) and math.isnan(life.predicted_periods)


def test_an_unstable_member_lives_as_long_as_its_multiplier_allows(family):
    for orbit, life in zip(family.family.orbits[:2], family.lifetimes[:2], strict=True):
        mu = orbit.max_multiplier
        assert not orbit.stable and mu > 1.1
        predicted = math.log(1e-2 / 1e-8) / math.log(mu)
        assert life.predicted_periods == pytest.approx(predicted, rel=1e-12)
        assert 0.5 * predicted < life.periods < 2 * predicted
    # log(1/eps) scaling: 1000 times smaller a perturbation lives ln(1000) / ln|mu| periods longer
    orbit = family.family.orbits[1]
    shorter = lifetime(orbit, perturbation=1e-8, max_periods=RUN).periods
    longer = lifetime(orbit, perturbation=1e-11, max_periods=RUN).periods
    assert longer - shorter == pytest.approx(math.log(1e3) / math.log(orbit.max_multiplier), rel=0.3)


def test_lifetimes_go_into_the_summary_the_file_and_the_figure(family):
    lives = family.as_dict()["lifetimes"]
    assert [life["lifetime_periods"] for life in lives] == [life.periods for life in family.lifetimes]
    assert lives[2]["lifetime_periods"] is None and lives[2]["run_periods"] == RUN
    ds = family.to_dataset()
    assert np.isnan(ds["lifetime_periods"].values[2])
    assert ds["lifetime_periods"].values[:2].tolist() == [life.periods for life in family.lifetimes[:2]]
    for name in ("lifetime_periods", "growth_per_period", "predicted_lifetime_periods"):
        assert ds[name].attrs["units"] == "1" and ds[name].attrs["long_name"]
    assert json.loads(ds.attrs["settings_json"])["lifetime"] == {"max_periods": RUN, "perturbation": 1e-8, "threshold": 1e-2}
    figure = breather_family_figure(family)
    assert len(figure.axes) == 3 and figure.axes[2].get_ylabel() == "lifetime (periods)"


def test_command_writes_the_lifetimes(tmp_path):
    out, config = tmp_path / "family.nc", tmp_path / "chain.toml"
    config.write_text("N = 3\n")  # its viscosities are set to 0 by the command
    result = CliRunner().invoke(
        app,
        ["breathers", "--model", "sine", "--omega", "6.0", "--to", "6.6", "--steps", "2", "--lifetimes", "60", "--config", str(config),
         "--out", str(out), "--json"],
    )  # fmt: skip
    assert result.exit_code == 0, result.output
    summary = json.loads(result.stdout)
    with xr.open_dataset(out) as ds:
        stayed = np.isnan(ds["lifetime_periods"].values)
        assert stayed.tolist() == [life["lifetime_periods"] is None for life in summary["lifetimes"]]
        assert stayed[-1]  # the stable member at 6.6


def test_system_family_lifetimes_follow_the_multipliers():
    # Takeno-Peyrard, 9 sites, C = 0.05: stable down to 1.144, then a real multiplier grows (1.45 to 1.96 by 1.1)
    family = system_family(takeno_peyrard(9, C=0.05), 1.2, to=1.1, locate=False)
    lives = family.measure_lifetimes(150)
    assert lives[0].periods is None and family.orbits[0].stable and np.all(lives[0].deviation < 1e-2)
    unstable = [(o, life) for o, life in zip(family.orbits, lives, strict=True) if o.max_multiplier > 1.3]
    assert len(unstable) >= 3
    for orbit, life in unstable:
        predicted = math.log(1e-2 / 1e-8) / math.log(orbit.max_multiplier)
        assert life.predicted_periods == pytest.approx(predicted, rel=1e-12)
        assert 0.5 * predicted < life.periods < 2 * predicted
    ds = family.to_dataset()
    assert np.isnan(ds["lifetime_periods"].values[0]) and ds["lifetime_periods"].values[-1] == lives[-1].periods
    assert family.as_dict()["lifetimes"][-1]["run_periods"] == 150
    with pytest.raises(ValueError, match="max_periods"):
        system_lifetime(family.orbits[0], max_periods=0)


def test_command_measures_a_system_familys_lifetimes():
    result = CliRunner().invoke(
        app,
        ["breathers", "--system", "takeno_peyrard", "--set", "sites=7", "--set", "C=0.05", "--omega", "1.3", "--lifetimes", "30", "--json"],
    )  # fmt: skip
    assert result.exit_code == 0, result.output
    lives = json.loads(result.stdout)["lifetimes"]
    assert len(lives) == 1 and lives[0]["lifetime_periods"] is None and lives[0]["run_periods"] == 30
