"""The existence map of two-site roto-breathers of the chain and of a user system's roto-breathers (small sizes)."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
import xarray as xr
from scipy.integrate import solve_ivp
from typer.testing import CliRunner

from cosserat_chain import ChainParams
from cosserat_chain.cli import app
from cosserat_chain.experiments.breather_atlas import breather_atlas, chain_at
from cosserat_chain.experiments.breathers import roto_breather_family
from cosserat_chain.experiments.system_breather_atlas import system_breather_atlas
from cosserat_chain.experiments.system_breathers import BreatherError
from cosserat_chain.experiments.system_breathers import roto_breather_family as system_family
from cosserat_chain.systems import takeno_peyrard

runner = CliRunner()


@pytest.mark.parametrize(("sign", "stable"), [(1, False), (-1, True)])
def test_two_site_chain_atlas_is_the_two_rotor_family(sign, stable):
    # The sine chain (N = 3) above the bands: the pair turning together is unstable, against each other stable (as at N = 10).
    chain = ChainParams(N=3, gamma_u=0, gamma_v=0, gamma_phi=0)
    atlas = breather_atlas(chain, "sine", [6.6, 7.0], "b", [0.25], partners={1: sign})
    assert [p.source for p in atlas.points[0]] == ["anti_continuum", "omega"]
    family = roto_breather_family(chain_at(chain, "b", 0.25), "sine", [6.6, 7.0], partners={1: sign})
    for point, orbit in zip(atlas.points[0], family.family.orbits, strict=True):
        assert point.orbit.particle_turns.tolist() == [0, 0, 0, 1, sign, 0, 0]
        assert np.max(np.abs(point.orbit.v - orbit.v)) < 1e-8 and np.max(np.abs(point.orbit.x - orbit.x)) < 1e-8
        assert point.orbit.max_multiplier == pytest.approx(orbit.max_multiplier, abs=1e-6)
        assert point.orbit.stable == stable
        assert 1.8 < point.localization.participation_ratio < 2.5  # the energy on two rotors
        assert point.localization.return_error < 1e-9
    assert json.loads(atlas.to_dataset().attrs["settings_json"])["partners"] == {"1": sign}


def takeno_peyrard_field(c: float):
    def field(_, y):
        q, v = y[: y.size // 2], y[y.size // 2 :]
        bond = np.sin(np.diff(q))
        force = -np.sin(q)
        force[:-1] += c * bond
        force[1:] -= c * bond
        return np.concatenate([v, force])

    return field


@pytest.fixture(scope="module")
def tp_atlas():
    return system_breather_atlas(takeno_peyrard(9, C=0.05), [1.3, 1.2, 1.1], "C", [0.02, 0.05])


def test_system_atlas_points_are_orbits_of_the_lattice(tp_atlas):
    assert [[p.source for p in row] for row in tp_atlas.points] == [["anti_continuum", "omega", "omega"], ["field", "omega", "omega"]]
    for c, row in zip(tp_atlas.values, tp_atlas.points, strict=True):
        for p in row:
            o = p.orbit
            run = solve_ivp(takeno_peyrard_field(c), (0, o.period), o.y0, method="DOP853", rtol=1e-12, atol=1e-12)
            shift = np.concatenate([2 * math.pi * o.turns, np.zeros(9)])
            assert np.max(np.abs(run.y[:, -1] - o.y0 - shift)) < 1e-8
            assert p.localization.energy_drift < 1e-9 and p.localization.participation_ratio < 1.2


def test_system_atlas_continues_onto_the_anti_continuum_family(tp_atlas):
    # every point reached by continuation in Omega or C is the orbit Newton finds from the rotor at that point
    for c, row in zip(tp_atlas.values, tp_atlas.points, strict=True):
        for p in row[1:]:
            direct = system_family(takeno_peyrard(9, C=float(c)), p.omega).orbits[0]
            assert np.max(np.abs(p.orbit.y0 - direct.y0)) < 1e-7
    # stability lost at +1 below Omega = 1.0746 (C = 0.02) and 1.1440 (C = 0.05): only (0.05, 1.1) is past it
    assert tp_atlas.grid("stable").tolist() == [[1, 1, 1], [1, 1, 0]]
    # the tail lengthens towards the band (top sqrt(1 + 4 C)) and with the coupling
    xi = tp_atlas.grid("localization_length")
    assert np.all(np.diff(xi, axis=1) > 0) and np.all(xi[1] > xi[0])


def test_system_atlas_two_sites_in_and_out_of_phase():
    # 10 sites, rotors 4 and 5, C = 0.05: in phase a complex quartet at 1.5 (|mu| = 1.0097), stable at 1.4; out of phase stable
    system = takeno_peyrard(10, C=0.05)
    together = system_breather_atlas(system, [1.5, 1.4], "C", [0.05], rotor=4, partner=5)
    against = system_breather_atlas(system, [1.5, 1.4], "C", [0.05], rotor=4, partner=5, counter=True)
    assert together.grid("max_multiplier")[0, 0] == pytest.approx(1.0097, abs=2e-4)
    assert together.grid("stable").tolist() == [[0, 1]] and against.grid("stable").tolist() == [[1, 1]]
    for atlas, sign in ((together, 1), (against, -1)):
        assert atlas.rotors == {4: 1, 5: sign}
        assert np.all(np.abs(atlas.grid("participation_ratio") - 2) < 0.05)
        o = atlas.points[0][0].orbit
        # the pair's mirror symmetry about the bond between them: sites 4 + d and 5 - d swap (turning against: with a sign)
        q, v = o.q0, o.v0
        assert np.max(np.abs(v - sign * v[::-1])) < 1e-8 and np.max(np.abs(q - sign * q[::-1])) < 1e-8


def test_system_atlas_refuses_bad_input():
    system = takeno_peyrard(5, C=0.05)
    with pytest.raises(BreatherError, match="other than its damping"):
        system_breather_atlas(system, [1.3], "gamma", [0.1])
    with pytest.raises(BreatherError, match="field must be a parameter"):
        system_breather_atlas(system, [1.3], "K", [0.1])
    with pytest.raises(BreatherError, match="omegas"):
        system_breather_atlas(system, [0.0], "C", [0.1])
    with pytest.raises(BreatherError, match="values of C"):
        system_breather_atlas(system, [1.3], "C", [math.nan])
    with pytest.raises(BreatherError, match="partner must differ"):
        system_breather_atlas(system, [1.3], "C", [0.1], rotor=2, partner=2)


def test_cli_system_atlas_json_file_and_plot(tmp_path):
    out, plot = tmp_path / "atlas.nc", tmp_path / "atlas.png"
    result = runner.invoke(
        app,
        ["breathers", "--system", "takeno_peyrard", "--set", "sites=7", "--omega", "1.3", "--to", "1.2", "--steps", "2", "--atlas",
         "C=0.02,0.05", "--partner", "1", "--counter", "--json", "--out", str(out), "--plot", str(plot)],
    )  # fmt: skip
    assert result.exit_code == 0, result.output
    data = json.loads(result.stdout)
    assert data["rotors"] == {"phi_3": 1, "phi_4": -1} and data["field"] == "C"
    with xr.open_dataset(out) as ds:
        assert ds["stable"].values.tolist() == [[int(p["stable"]) for p in row] for row in data["points"]]
        assert ds.attrs["system_reference"] == "takeno_peyrard" and ds.attrs["field"] == "C"
        assert np.allclose(ds["energy"].values, [[p["energy"] for p in row] for row in data["points"]], rtol=1e-12)
    assert plot.stat().st_size > 0
