"""Lifetimes at every point of a roto-breather atlas (issue 41): direct runs from the perturbed orbits.

A stable orbit outlives the run; an unstable one leaves the threshold after about
ln(threshold / perturbation) / ln max|mu| periods, its deviation growing by about max|mu| a period
(the orbit's Floquet multiplier, an independent computation). The same on a user system's atlas.
"""

from __future__ import annotations

import json

import numpy as np
import pytest
from typer.testing import CliRunner

from cosserat_chain import ChainParams
from cosserat_chain.cli import app
from cosserat_chain.experiments.breather_atlas import breather_atlas
from cosserat_chain.experiments.system_breather_atlas import system_breather_atlas
from cosserat_chain.systems import takeno_peyrard

runner = CliRunner()
RUN = 300


def _check_lifetimes(atlas):
    stable = unstable = 0
    for row in atlas.points:
        for p in row:
            life = p.lifetime
            assert (life is None) == (p.orbit is None)
            if life is None:
                continue
            assert life.run_periods == RUN
            if p.orbit.stable:
                stable += 1
                assert life.periods is None  # it outlived the run
            else:
                unstable += 1
                mu = p.orbit.max_multiplier
                assert life.periods is not None and life.predicted_periods / 2 < life.periods < 2 * life.predicted_periods
                assert life.growth_per_period == pytest.approx(mu, rel=0.15)
    return stable, unstable


@pytest.fixture(scope="module")
def chain_atlas():
    """The sine chain, N = 3, b = 0.2, at Omega = 6.6 and 5.0, every orbit run for RUN periods."""
    atlas = breather_atlas(ChainParams(N=3, gamma_u=0.0, gamma_v=0.0, gamma_phi=0.0), "sine", [6.6, 5.0], "b", [0.2])
    atlas.measure_lifetimes(RUN)
    return atlas


@pytest.fixture(scope="module")
def system_atlas():
    """Takeno-Peyrard, 9 sites, C = 0.05, at Omega = 1.3 and 1.2, every orbit run for RUN periods."""
    atlas = system_breather_atlas(takeno_peyrard(9, C=0.05), [1.3, 1.2], "C", [0.05])
    atlas.measure_lifetimes(RUN)
    return atlas


def test_chain_atlas_lifetimes_follow_the_multipliers_and_reach_the_file(chain_atlas):
    atlas = chain_atlas
    assert _check_lifetimes(atlas) == (1, 1)  # 6.6 stable, 5.0 unstable (|mu| = 1.24)
    ds = atlas.to_dataset()
    points = atlas.as_dict()["points"]
    for i, point in enumerate(points[0]):
        life = point["lifetime"]
        assert bool(ds["outlived_run"][0, i]) == (life["lifetime_periods"] is None)
        assert float(ds["lifetime_periods"][0, i]) == (RUN if life["lifetime_periods"] is None else life["lifetime_periods"])
    assert all(ds[n].attrs.get("units") and ds[n].attrs.get("long_name") for n in ("lifetime_periods", "outlived_run", "growth_per_period"))
    assert atlas.settings["lifetime"]["max_periods"] == RUN


def test_system_atlas_lifetimes_follow_the_multipliers(system_atlas):
    atlas = system_atlas
    stable, unstable = _check_lifetimes(atlas)
    assert stable + unstable == int(atlas.grid("exists").sum()) > 0
    assert "lifetime_periods" in atlas.to_dataset("takeno_peyrard")


def test_an_atlas_without_lifetimes_has_no_lifetime_columns_and_bad_runs_are_refused():
    atlas = breather_atlas(ChainParams(N=2, gamma_u=0.0, gamma_v=0.0, gamma_phi=0.0), "nonlinear", [10.5], "b", [0.2])
    assert "lifetime_periods" not in atlas.to_dataset() and "lifetime" not in atlas.as_dict()["points"][0][0]
    with pytest.raises(ValueError, match="max_periods must be an integer >= 1, got 0"):
        atlas.measure_lifetimes(0)
    with pytest.raises(ValueError, match="perturbation < threshold"):
        atlas.measure_lifetimes(10, perturbation=1.0, threshold=0.5)


def test_cli_atlas_lifetimes_in_json_and_text(tmp_path):
    config = tmp_path / "chain.toml"
    config.write_text("N = 3\n")
    args = ["breathers", "--model", "sine", "--omega", "6.6", "--to", "5.0", "--steps", "2", "--atlas", "b=0.2", "--config", str(config)]
    result = runner.invoke(app, [*args, "--lifetimes", "100", "--json"])
    assert result.exit_code == 0, result.output
    points = json.loads(result.stdout)["points"][0]
    assert [p["lifetime"]["lifetime_periods"] is None for p in points] == [True, False]
    text = runner.invoke(app, [*args, "--lifetimes", "100"])
    assert (
        text.exit_code == 0
        and "lifetime > 100 periods" in text.stdout
        and np.sum(["lifetime" in line for line in text.stdout.splitlines()]) == 2
    )


def test_the_atlas_figures_draw_the_lifetimes_where_they_were_measured(tmp_path, chain_atlas, system_atlas):
    """A second panel with one marker per orbit: the lost ones coloured by log10 of their periods, survivors as triangles."""
    import matplotlib

    matplotlib.use("Agg")
    from cosserat_chain.plots.breathers import atlas_lifetime_grid, breather_atlas_figure, system_atlas_figure

    unmeasured = breather_atlas(ChainParams(N=1, gamma_u=0.0, gamma_v=0.0, gamma_phi=0.0), "sine", [6.0], "b", [0.2])
    before = breather_atlas_figure(unmeasured)
    assert atlas_lifetime_grid(unmeasured) is None and len([a for a in before.axes if a.get_label() != "<colorbar>"]) == 1
    atlas, system = chain_atlas, system_atlas
    periods, stayed = atlas_lifetime_grid(atlas)
    assert stayed.tolist() == [[True, False]] and periods[0, 0] == RUN and periods[0, 1] == atlas.points[0][1].lifetime.periods
    figures = [breather_atlas_figure(atlas), system_atlas_figure(system)]
    for fig, drawn in zip(figures, (atlas, system)):
        periods, stayed = atlas_lifetime_grid(drawn)
        lower = fig.axes[1]
        lost, survivors = lower.collections[0], lower.collections[1]
        # The lost orbits' colours are log10 of their lifetimes; the survivors sit where the grid says they stayed.
        assert np.allclose(np.sort(lost.get_array()), np.sort(np.log10(periods[np.isfinite(periods) & ~stayed])))
        assert len(survivors.get_offsets()) == int(stayed.sum())
        assert "lifetimes" in lower.get_title()
        fig.savefig(tmp_path / "atlas.png")
        matplotlib.pyplot.close(fig)
    matplotlib.pyplot.close(before)
