"""The roto-breathers' existence map: the Hamiltonian shooting in column blocks, the atlas over (Omega, a field),
its localization measures, its band lines, and the command's --atlas and --from-moment."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
import xarray as xr
from typer.testing import CliRunner

from cosserat_chain.analysis.diagnostics import participation_ratio
from cosserat_chain.analysis.dispersion import wave_summary
from cosserat_chain.cli import app
from cosserat_chain.experiments.breather_atlas import breather_atlas, chain_at, localization_length, orbit_localization
from cosserat_chain.experiments.breathers import anti_continuum_state
from cosserat_chain.loads import moment_load
from cosserat_chain.numerics import periodic
from cosserat_chain.numerics.dynamics import integrate
from cosserat_chain.numerics.long_breathers import _eps_derivative, find_breather_orbit
from cosserat_chain.params import ChainParams
from cosserat_chain.state import ROW_INDEX

PHI = ROW_INDEX["phi"]
#: Closure of an atlas orbit by an independent fixed-step integrator (Yoshida-4, 4000 steps a period).
RETURN_TOL = 1e-6
runner = CliRunner()


def undamped(**fields) -> ChainParams:
    return ChainParams(gamma_u=0.0, gamma_v=0.0, gamma_phi=0.0, **fields)


@pytest.fixture(scope="module")
def small_atlas():
    """Nonlinear chain, N = 3, above every band (stable orbits), over two heights b."""
    return breather_atlas(undamped(N=3), "nonlinear", [10.5, 10.0, 9.5], "b", [0.2, 0.25, 0.3])


def test_blocks_orbit_equals_the_dense_one():
    params = undamped(N=3)
    start = anti_continuum_state(params, "sine", 6.6)[:2]
    dense = find_breather_orbit(params, "sine", 6.6, start, method="dense").orbit
    blocks = find_breather_orbit(params, "sine", 6.6, start, method="blocks")
    assert np.max(np.abs(blocks.orbit.x - dense.x)) < 1e-9 and np.max(np.abs(blocks.orbit.v - dense.v)) < 1e-9
    assert blocks.orbit.max_multiplier == pytest.approx(dense.max_multiplier, abs=1e-8)
    assert abs(blocks.orbit.unfolding) < 1e-10
    # The next orbit of the family from the last Jacobian: the same orbit as the dense method's from its own start.
    after = find_breather_orbit(params, "sine", 6.5, blocks.orbit, method="blocks", jacobian0=blocks.jacobian).orbit
    dense_after = find_breather_orbit(params, "sine", 6.5, dense, method="dense").orbit
    assert np.max(np.abs(after.v - dense_after.v)) < 1e-9


def test_unfolding_column_by_differences_equals_the_variational_one():
    params = undamped(N=2)
    orbit = find_breather_orbit(params, "nonlinear", 9.8, anti_continuum_state(params, "nonlinear", 9.8)[:2], method="dense").orbit
    system = periodic._UndampedSystem(params, periodic.get_model("nonlinear"), 0.0, 0, 0.0)
    y0 = periodic._to_y(params, orbit.x, orbit.v)
    _, _, variational = system.flow(y0, orbit.period, rtol=1e-12, atol=1e-12, variations=True)
    by_differences = _eps_derivative(system, y0, orbit.period, 1e-12, 1e-12)
    assert np.max(np.abs(by_differences - variational)) < 1e-6 * np.max(np.abs(variational))


def test_localization_length_of_an_exponential_tail_is_its_decay_length():
    d = np.arange(1, 31)
    assert localization_length(0.7 * 0.3**d) == pytest.approx(-1 / math.log(0.3), rel=1e-10)
    # Below the floor the tail is noise: only the resolved sites are fitted.
    tail = np.where(d < 12, 2.0 * 0.2**d, 1e-14)
    assert localization_length(tail) == pytest.approx(-1 / math.log(0.2), rel=1e-10)
    assert localization_length(np.full(10, 0.1)) == math.inf
    assert math.isnan(localization_length(np.array([1e-3, 0.0])))


def test_participation_ratio_of_an_exponential_energy_profile_matches_its_closed_form():
    r, n = 0.4, 200  # e_k = r^|k|: PR = (1 + r)^3 / ((1 - r) (1 + r^2)) on an infinite chain
    energy = r ** np.abs(np.arange(-n, n + 1))
    assert participation_ratio(energy) == pytest.approx((1 + r) ** 3 / ((1 - r) * (1 + r**2)), rel=1e-12)


def test_a_lone_rotor_is_the_pendulum_fully_localized():
    # N = 1, clamped ends: the rotor is the only free particle, its turn the anti-continuum orbit itself.
    params = undamped(N=1)
    x, v, energy = anti_continuum_state(params, "nonlinear", 9.0)
    orbit = find_breather_orbit(params, "nonlinear", 9.0, (x, v), method="blocks").orbit
    loc = orbit_localization(orbit)
    assert orbit.energy == pytest.approx(energy, rel=1e-9)
    assert loc.participation_ratio == pytest.approx(1.0, abs=1e-12) and loc.localized
    assert all(value == 0 for value in loc.amplitudes.values()) and loc.energy_drift < 1e-9 and loc.return_error < 1e-8


def test_every_atlas_orbit_is_closed_and_conserves_energy(small_atlas):
    assert small_atlas.grid("exists").all()
    assert [p.source for p in small_atlas.points[0]] == ["anti_continuum", "omega", "omega"]
    assert [row[0].source for row in small_atlas.points[1:]] == ["field", "field"]
    for row in small_atlas.points:
        for p in row:
            o = p.orbit
            assert p.localization.energy_drift < 1e-9 and p.localization.return_error < 1e-8
            run = integrate(
                o.params, "nonlinear", moment_load(0.0, 0), t_end=o.period, dt=o.period / 4000, x0=o.x, v0=o.v, method="yoshida4",
                n_frames=2,
            )  # fmt: skip
            shift = np.zeros_like(o.x)
            shift[PHI, o.params.N] = 2 * math.pi
            assert np.max(np.abs(run.x[-1] - o.x - shift)) < RETURN_TOL and np.max(np.abs(run.v[-1] - o.v)) < RETURN_TOL
            assert o.omega == pytest.approx(p.omega, rel=1e-14) and o.params.b == p.value


def test_field_continuation_reaches_the_orbit_found_from_the_rotor(small_atlas):
    p = small_atlas.points[2][0]  # b = 0.3, continued from b = 0.2 and 0.25
    params = chain_at(undamped(N=3), "b", 0.3)
    direct = find_breather_orbit(params, "nonlinear", 10.5, anti_continuum_state(params, "nonlinear", 10.5)[:2]).orbit
    assert p.source == "field"
    assert np.max(np.abs(p.orbit.x - direct.x)) < 1e-8 and np.max(np.abs(p.orbit.v - direct.v)) < 1e-8


def test_atlas_band_lines_are_the_waves_edges_and_their_harmonics(small_atlas):
    ds = small_atlas.to_dataset()
    for j, b in enumerate(ds["value"].values):
        bands = wave_summary(ChainParams(b=float(b))).bands  # j re-derived from the new b: the default chain's own
        for k, band in enumerate(ds["band"].values):
            assert np.allclose(ds["band_edge"].values[j, k], bands[str(band)], rtol=1e-12, atol=0)
            for n in range(1, 7):
                assert np.allclose(ds["resonance_omega"].values[j, k, :, n - 1] * n, bands[str(band)], rtol=1e-12, atol=0)
    # The particle's inertia follows its shape (j = m (a^2 + b^2) / 3), not the paper's particle's j.
    kept = wave_summary(ChainParams(b=0.3, j=ChainParams().j)).bands["rotational_optical"]
    assert abs(ds["band_edge"].sel(band="rotational_optical").values[-1] - np.array(kept)).max() > 0.1


def test_atlas_refuses_bad_fields_and_values():
    with pytest.raises(ValueError, match="field must be one of a, b, h, E1, E2"):
        breather_atlas(undamped(N=1), "sine", [6.0], "gamma_u", [0.1])
    with pytest.raises(ValueError, match="the chain refuses b=-1.0: b must be > 0"):
        breather_atlas(undamped(N=1), "sine", [6.0], "b", [-1.0])
    with pytest.raises(ValueError, match="gamma_phi=0.1"):
        breather_atlas(ChainParams(N=1, gamma_u=0, gamma_v=0), "sine", [6.0], "b", [0.2])
    with pytest.raises(ValueError, match="omegas must be"):
        breather_atlas(undamped(N=1), "sine", [0.0], "b", [0.2])


def test_cli_atlas_json_and_netcdf_round_trip(tmp_path):
    config = tmp_path / "chain.toml"
    config.write_text("N = 2\n")
    out = tmp_path / "atlas.nc"
    args = ["breathers", "--model", "nonlinear", "--omega", "10.5", "--to", "10", "--steps", "2", "--atlas", "b=0.2,0.3"]
    result = runner.invoke(app, [*args, "--config", str(config), "--json", "--out", str(out), "--plot", str(tmp_path / "a.png")])
    assert result.exit_code == 0, result.output
    data = json.loads(result.stdout)
    assert data["field"] == "b" and data["values"] == [0.2, 0.3] and data["omegas"] == [10.5, 10.0]
    assert (tmp_path / "a.png").stat().st_size > 0
    with xr.open_dataset(out) as ds:
        assert ds.attrs["experiment"] == "roto_breather_atlas" and ds.attrs["field"] == "b" and ds.attrs["model"] == "nonlinear"
        assert ds.attrs["param_N"] == 2 and ds.attrs["param_gamma_phi"] == 0 and "cosserat_chain_version" in ds.attrs
        for j, row in enumerate(data["points"]):
            for i, point in enumerate(row):
                assert point["exists"] and bool(ds["exists"][j, i])
                assert float(ds["max_multiplier"][j, i]) == point["max_multiplier"]
                assert float(ds["participation_ratio"][j, i]) == point["participation_ratio"]
                assert float(ds["energy"][j, i]) == point["energy"]
        undescribed = [str(n) for n in ds.data_vars if not (ds[n].attrs.get("units") and ds[n].attrs.get("long_name"))]
        assert not undescribed
        # Each point's orbit from the file alone: the chain from its attributes and the field's value, the start from
        # its states, one period by Yoshida-4 (not the shooting's integrator) returns it with the rotor a turn further.
        base = ChainParams(**json.loads(ds.attrs["params_json"]))
        for j, b in enumerate(ds["value"].values):
            params = chain_at(base, ds.attrs["field"], float(b))
            for i, omega in enumerate(ds["omega"].values):
                x0 = np.array([ds[r].values[j, i] for r in ("u", "v", "phi")])
                v0 = np.array([ds[f"{r}_dot"].values[j, i] for r in ("u", "v", "phi")])
                period = 2 * math.pi / float(omega)
                run = integrate(params, "nonlinear", moment_load(0.0, 0), t_end=period, dt=period / 4000, x0=x0, v0=v0, method="yoshida4",
                                n_frames=2)  # fmt: skip
                x0[PHI, params.N] += 2 * math.pi
                assert np.max(np.abs(run.x[-1] - x0)) < RETURN_TOL and np.max(np.abs(run.v[-1] - v0)) < RETURN_TOL


@pytest.mark.parametrize(
    ("extra", "message"),
    [
        (["--atlas", "c=1,2"], "FIELD one of a, b, h, E1, E2"),
        (["--atlas", "b=x"], "must be numbers separated by commas"),
        (["--atlas", "b="], "one or more finite values"),
        (["--atlas", "b=0.2,-1"], "b must be > 0"),
        (["--atlas", "b=0.2", "--method", "krylov"], "--method must be auto, dense or blocks"),
        (["--atlas", "b=0.2", "--counter"], "give --partner as well"),
        (["--atlas", "b=0.2", "--set", "C=1"], "need(s) --system REF"),
        (["--atlas", "K=0.1", "--system", "takeno_peyrard", "--set", "sites=5"], "FIELD one of C, T, gamma"),
        (["--atlas", "gamma=0.1", "--system", "takeno_peyrard", "--set", "sites=5"], "other than its damping 'gamma'"),
        (["--atlas", "C=0.1", "--system", "takeno_peyrard", "--set", "sites=5", "--method", "dense"], "--method"),
        (["--atlas", "C=0.1", "--system", "takeno_peyrard", "--set", "sites=5", "--partner", "40"], "--partner 40 is off the system"),
        (["--method", "blocks"], "--method chooses the atlas's shooting"),
        (["--gamma", "0.1"], "--gamma sets the damped start"),
        (["--from-moment", "0.2", "--atlas", "b=0.2"], "leave out --system and --atlas"),
    ],
)
def test_cli_atlas_and_homotopy_refuse_bad_input(extra, message):
    result = runner.invoke(app, ["breathers", "--omega", "6", *extra])
    assert result.exit_code == 2 and message in result.output, result.output


def test_cli_atlas_refuses_a_folder_as_out_before_computing(tmp_path):
    result = runner.invoke(app, ["breathers", "--omega", "6", "--atlas", "b=0.2", "--out", str(tmp_path)])
    assert result.exit_code == 2 and "--out" in result.output


def test_cli_breathers_needs_a_frequency():
    result = runner.invoke(app, ["breathers", "--to", "5"])
    assert result.exit_code == 2 and "give --omega" in result.output


def test_cli_from_moment_lands_on_the_anti_continuum_family():
    # The paper's chain (N = 3) under weak damping turns above every band: it lands on the roto-breather there.
    result = runner.invoke(app, ["breathers", "--model", "nonlinear", "--from-moment", "0.21", "--gamma", "0.02", "--json"])
    assert result.exit_code == 0, result.output
    data = json.loads(result.stdout)
    assert data["path"]["end"] == "value" and data["same_orbit"] and data["state_difference"] < 1e-8
    assert data["landed"]["period"] == pytest.approx(data["orbit"]["period"], rel=1e-12)
    assert data["params"]["gamma_phi"] == 0.02


def test_cli_from_moment_refuses_an_undamped_start(tmp_path):
    config = tmp_path / "chain.toml"
    config.write_text("N = 1\ngamma_u = 0\ngamma_v = 0\ngamma_phi = 0\n")
    result = runner.invoke(app, ["breathers", "--from-moment", "0.21", "--config", str(config)])
    assert result.exit_code == 2 and "needs a damped chain" in result.output


@pytest.mark.slow
def test_a_long_chain_atlas_point_by_the_blocks_is_a_closed_orbit():
    # N = 50 (101 particles, 594 phase-space dimensions): the method the atlas takes by default there.
    atlas = breather_atlas(undamped(N=50), "sine", [6.6], "b", [0.2])
    p = atlas.points[0][0]
    assert p.exists and p.orbit.multiplier_errors is not None and p.orbit.stable
    assert p.localization.return_error < 1e-8 and p.localization.participation_ratio < 2.0
    assert 0.2 < p.localization.length < 1.0
    # Localized: the N = 10 chain by the dense method carries the same orbit near the rotor (the tail falls below 1e-9 within 10 sites).
    short = breather_atlas(undamped(N=10), "sine", [6.6], "b", [0.2]).points[0][0]
    assert short.localization.participation_ratio == pytest.approx(p.localization.participation_ratio, rel=1e-6)
    assert short.orbit.max_multiplier == pytest.approx(p.orbit.max_multiplier, abs=1e-6)
    assert np.max(np.abs(short.orbit.v[:, 5:16] - p.orbit.v[:, 45:56])) < 1e-7  # particles -5..5


def test_the_nonlinear_rotor_strains_the_chain_statically_while_its_oscillation_is_localized():
    atlas = breather_atlas(undamped(N=6), "nonlinear", [10.5], "b", [0.2])
    p = atlas.points[0][0]
    loc = p.localization
    # The oscillation about the mean falls by more than 20 a site: a localization length below 1/3 site ...
    assert np.all(loc.site_amplitudes[1:5] < loc.site_amplitudes[:4] / 20) and loc.length < 1 / 3
    # ... while the mean pull is a uniform strain: mean u falls linearly from the rotor's neighbours to the clamped ends.
    x, _ = p.orbit.trajectory(p.orbit.period * np.arange(1, 65) / 64)
    mean_u = x[:, ROW_INDEX["u"]].mean(axis=0)
    right = mean_u[p.orbit.params.N + 2 :]  # particles 2..6, the last clamped
    assert np.allclose(np.diff(right), np.diff(right)[0], rtol=1e-3) and right[-1] == 0
    assert loc.static_displacement == pytest.approx(np.max(np.abs(np.delete(mean_u, p.orbit.params.N))), rel=1e-2)
    # Pulled towards the rotor, symmetrically: a turning corner's mean distance from the centre along the chain is 0, not a.
    assert mean_u[p.orbit.params.N + 1] < -0.1 and mean_u[p.orbit.params.N + 1] == pytest.approx(-mean_u[p.orbit.params.N - 1], rel=1e-6)
