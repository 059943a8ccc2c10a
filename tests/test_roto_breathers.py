"""Roto-breathers: Hamiltonian orbits (gamma = 0) by the unfolded shooting, their anti-continuum limit,
Floquet multipliers and the resonances of their harmonics with the bands."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
import xarray as xr
from scipy.optimize import brentq
from scipy.special import ellipk
from typer.testing import CliRunner

from cosserat_chain.analysis.dispersion import wave_summary
from cosserat_chain.cli import app
from cosserat_chain.experiments.breathers import (
    anti_continuum_state,
    coupled_bands,
    harmonics_in_bands,
    lifetime,
    resonances,
    roto_breather_family,
)
from cosserat_chain.loads import moment_load
from cosserat_chain.models.base import get_model
from cosserat_chain.numerics import periodic
from cosserat_chain.numerics.dynamics import integrate
from cosserat_chain.numerics.periodic import continue_in_frequency, find_hamiltonian_orbit, hamiltonian_energy
from cosserat_chain.params import ChainParams
from cosserat_chain.state import ROW_INDEX, zeros

#: Closure of the computed orbits against an independent evaluation (Newton's tolerance and DOP853's).
ORBIT_TOL = 1e-8
PHI = ROW_INDEX["phi"]
runner = CliRunner()


def undamped(**fields) -> ChainParams:
    return ChainParams(gamma_u=0.0, gamma_v=0.0, gamma_phi=0.0, **fields)


def pendulum_rate_at_bottom(params: ChainParams, omega: float) -> float:
    """phi' at phi = 0 of the pendulum J phi'' = -c sin phi turning at mean rate omega: 2 w0 / k with 2 k K(k) / w0 = 2 pi / omega."""
    c = get_model("linear").stiffness(params, zeros(params)).toarray()[2, 2]  # the angle's diagonal entry: the on-site pendulum
    w0 = math.sqrt(c / params.particle_inertia[PHI, params.N])
    k = brentq(lambda k: 2 * k * ellipk(k * k) / w0 - 2 * math.pi / omega, 1e-12, 1 - 1e-15, xtol=1e-15)
    return 2 * w0 / k


def test_anti_continuum_rotor_of_the_sine_chain_is_the_pendulum_closed_form():
    # N = 1, clamped: the centre particle alone moves, between neighbours held at rest.
    params = undamped(N=1)
    omega = 6.0
    exact = pendulum_rate_at_bottom(params, omega)
    x, v, _ = anti_continuum_state(params, "sine", omega)
    assert v[PHI, 1] == pytest.approx(exact, rel=1e-10)
    v[PHI, 1] *= 1.02  # Newton must find the rotor from a wrong start
    orbit = find_hamiltonian_orbit(params, "sine", omega, (x, v))
    assert orbit.iterations >= 2
    assert orbit.v[PHI, 1] == pytest.approx(exact, rel=1e-9)
    assert abs(orbit.unfolding) < 1e-10
    assert np.max(np.abs(orbit.x)) == 0.0 and abs(orbit.v[1, 1]) < 1e-12  # v decouples from the centre's angle
    assert orbit.period == pytest.approx(2 * math.pi / omega, rel=1e-15)


def test_nonlinear_rotor_between_held_neighbours_turns_in_its_on_site_potential():
    """T(E) = int sqrt(J / 2 (E - V)) dphi with V from the model's energy, independent of the shooting."""
    params = undamped(N=1)
    omega = 6.0
    orbit = find_hamiltonian_orbit(params, "nonlinear", omega, anti_continuum_state(params, "nonlinear", omega)[:2])
    model = get_model("nonlinear")
    angles = 2 * math.pi * np.arange(2048) / 2048
    potential = []
    for phi in angles:
        x = zeros(params)
        x[PHI, 1] = phi
        potential.append(model.energy(params, x) - model.energy(params, zeros(params)))
    inertia = params.particle_inertia[PHI, 1]
    energy = orbit.energy - model.energy(params, zeros(params))
    period = 2 * math.pi * np.mean(np.sqrt(inertia / (2 * (energy - np.array(potential)))))
    assert period == pytest.approx(2 * math.pi / omega, rel=1e-9)
    assert np.max(np.abs(orbit.v[:2, 1])) < 1e-12  # the point symmetry keeps u, v at rest


@pytest.fixture(scope="module")
def chain_orbit():
    """A roto-breather of the nonlinear chain with N = 2 (the neighbours move) above every band."""
    params = undamped(N=2)
    return roto_breather_family(params, "nonlinear", [6.5]).family.orbits[0]


def test_energy_is_conserved_along_the_orbit(chain_orbit):
    o = chain_orbit
    times = o.period * np.arange(1, 41) / 40
    xs, vs = o.trajectory(times)
    energies = np.array([hamiltonian_energy(o.params, "nonlinear", x, v) for x, v in zip(xs, vs)])
    assert np.max(np.abs(energies - o.energy)) < 1e-9 * abs(o.energy)
    assert np.max(np.abs(xs[:, :, [0, 1, 3, 4]])) > 1e-3  # the neighbours do oscillate


def test_orbit_returns_to_itself_modulo_2pi_by_an_independent_integrator(chain_orbit):
    o = chain_orbit
    run = integrate(
        o.params, "nonlinear", moment_load(0.0, 0), t_end=o.period, dt=o.period / 4000, x0=o.x, v0=o.v, method="yoshida4", n_frames=2
    )
    shift = np.zeros_like(o.x)
    shift[PHI, o.params.N] = 2 * math.pi
    assert np.max(np.abs(run.x[-1] - o.x - shift)) < 1e-7
    assert np.max(np.abs(run.v[-1] - o.v)) < 1e-6
    assert o.closure < ORBIT_TOL


def test_multipliers_come_in_symplectic_pairs_and_match_a_finite_difference_monodromy(chain_orbit):
    o = chain_orbit
    mu = o.multipliers
    assert np.prod(mu).real == pytest.approx(1.0, abs=1e-7)  # Liouville: the undamped flow keeps volume
    inverse = 1.0 / mu
    assert max(np.min(np.abs(mu - m)) for m in inverse) < 1e-5
    assert sorted(np.abs(mu - 1.0))[1] < 1e-4  # the Hamiltonian pair at +1
    params, model = o.params, get_model("nonlinear")
    system = periodic._UndampedSystem(params, model, 0.0, 0, 0.0)
    y0 = periodic._to_y(params, o.x, o.v)
    h = 1e-6
    columns = []
    for j in range(y0.size):
        e = np.zeros_like(y0)
        e[j] = h
        plus = system.flow(y0 + e, o.period, rtol=1e-12, atol=1e-12, variations=False)[0]
        minus = system.flow(y0 - e, o.period, rtol=1e-12, atol=1e-12, variations=False)[0]
        columns.append((plus - minus) / (2 * h))
    finite = np.column_stack(columns)
    _, mono, _ = system.flow(y0, o.period, rtol=1e-11, atol=1e-11, variations=True)
    assert np.max(np.abs(finite - mono)) < 1e-5 * np.max(np.abs(mono))
    by_differences = np.linalg.eigvals(finite)
    assert max(np.min(np.abs(by_differences - m)) for m in o.nontrivial_multipliers) < 1e-4


def test_a_stable_rotor_has_every_multiplier_on_the_unit_circle():
    params = undamped(N=1)
    orbit = find_hamiltonian_orbit(params, "nonlinear", 6.0, anti_continuum_state(params, "nonlinear", 6.0)[:2])
    assert orbit.stable
    assert np.max(np.abs(np.abs(orbit.multipliers) - 1.0)) < 1e-4
    assert np.max(np.abs(np.abs(orbit.nontrivial_multipliers) - 1.0)) < 1e-6


def test_the_family_follows_the_pendulum_in_omega():
    params = undamped(N=1)
    start = find_hamiltonian_orbit(params, "sine", 6.0, anti_continuum_state(params, "sine", 6.0)[:2])
    family = continue_in_frequency(start, [6.0, 5.8, 5.6, 5.4])
    assert family.complete
    for o in family.orbits:
        assert o.v[PHI, 1] == pytest.approx(pendulum_rate_at_bottom(params, o.omega), rel=1e-9)


def test_resonances_are_where_a_harmonic_meets_a_band_edge():
    params = undamped()
    bands = wave_summary(params).bands
    found = resonances(params, 1.0, 5.0)
    assert found
    for r in found:
        assert r.harmonic * r.omega == pytest.approx(bands[r.band][0 if r.edge == "bottom" else 1], rel=1e-14)
        below = harmonics_in_bands(params, r.omega * (1 - 1e-9))
        above = harmonics_in_bands(params, r.omega * (1 + 1e-9))
        assert ((r.harmonic, r.band) in below) != ((r.harmonic, r.band) in above)
    # The numbers for the paper's geometry: the sine chain's gap 1.569 .. 3.464 and the optical top 4.804.
    assert any(r.harmonic == 3 and r.band == "rotational_optical" and r.omega == pytest.approx(4.803844614152615 / 3) for r in found)
    assert harmonics_in_bands(params, 2.0, bands=("transverse_acoustic",)) == []
    assert (2, "rotational_optical") in harmonics_in_bands(params, 2.0)


def test_the_sine_rotor_drives_no_longitudinal_wave():
    params = undamped()
    assert coupled_bands(params, "sine") == ("transverse_acoustic", "rotational_optical")
    assert "longitudinal" in coupled_bands(params, "nonlinear")


def test_damped_chain_and_bad_frequency_are_refused_naming_the_field():
    with pytest.raises(ValueError, match="gamma_u=0.1"):
        find_hamiltonian_orbit(ChainParams(N=1), "sine", 6.0, (zeros(ChainParams(N=1)), zeros(ChainParams(N=1))))
    with pytest.raises(ValueError, match="omega must be a finite number > 0"):
        find_hamiltonian_orbit(undamped(N=1), "sine", -1.0, (zeros(undamped(N=1)), zeros(undamped(N=1))))
    with pytest.raises(ValueError, match="omegas must be"):
        roto_breather_family(undamped(N=1), "sine", [])


def test_cli_breathers_json_and_netcdf(tmp_path):
    config = tmp_path / "chain.toml"
    config.write_text("N = 1\n")  # its default viscosities are set to 0 by the command
    out = tmp_path / "family.nc"
    result = runner.invoke(
        app,
        [
            "breathers",
            "--config",
            str(config),
            "--omega",
            "6",
            "--to",
            "5.6",
            "--steps",
            "3",
            "--json",
            "--out",
            str(out),
            "--plot",
            str(tmp_path / "family.png"),
        ],
    )
    assert result.exit_code == 0, result.output
    data = json.loads(result.stdout)
    assert data["omega"] == pytest.approx([6.0, 5.8, 5.6])
    assert all(data["stable"]) and data["complete"] and (tmp_path / "family.png").stat().st_size > 0
    with xr.open_dataset(out) as ds:
        assert ds.attrs["experiment"] == "roto_breathers" and ds.sizes["point"] == 3
        assert float(ds["omega"][0]) == pytest.approx(6.0)
        undescribed = [str(name) for name in ds.variables if not (ds[name].attrs.get("units") and ds[name].attrs.get("long_name"))]
        assert not undescribed


def test_cli_breathers_refuses_a_bad_frequency():
    result = runner.invoke(app, ["breathers", "--omega", "0"])
    assert result.exit_code == 2 and "--omega" in result.output


@pytest.mark.slow
def test_a_stable_roto_breather_survives_1000_periods_of_a_direct_run():
    params = undamped(N=1)
    orbit = find_hamiltonian_orbit(params, "nonlinear", 6.0, anti_continuum_state(params, "nonlinear", 6.0)[:2])
    periods = 1000
    run = integrate(
        params, "nonlinear", moment_load(0.0, 0), t_end=periods * orbit.period, dt=orbit.period / 1000, x0=orbit.x, v0=orbit.v,
        method="yoshida4", n_frames=2,
    )  # fmt: skip
    shift = np.zeros_like(orbit.x)
    shift[PHI, 1] = 2 * math.pi * periods
    assert np.max(np.abs(run.x[-1] - orbit.x - shift)) < 1e-5
    assert np.max(np.abs(run.v[-1] - orbit.v)) < 1e-4


@pytest.mark.slow
def test_sine_roto_breathers_gain_stability_where_the_combination_resonance_ends():
    """Omega = w_TA,top + w_RO,top (1.569 + 4.804 = 6.373): below it a phonon pair is parametrically excited."""
    params = undamped(N=10)
    edge = sum(band[1] for band in (wave_summary(params).bands["transverse_acoustic"], wave_summary(params).bands["rotational_optical"]))
    assert edge == pytest.approx(6.373, abs=1e-3)
    below, above = (roto_breather_family(params, "sine", [w]).family.orbits[0] for w in (6.2, 6.4))
    assert not below.stable and np.max(np.abs(below.nontrivial_multipliers.imag)) > 0.1  # a complex quadruplet off the circle
    pair = below.nontrivial_multipliers[np.argmax(np.abs(below.nontrivial_multipliers))]
    assert np.min(np.abs(below.multipliers - 1 / np.conj(pair))) < 1e-6  # ... with its symplectic partner
    assert above.stable


@pytest.mark.parametrize("direction", [1, -1], ids=["co-rotating", "counter-rotating"])
def test_two_site_roto_breathers_keep_the_chains_symmetry(direction):
    """Rotors at -1 and +1: turning together, the orbit is invariant under the half-turn of the chain
    (n -> -n, u, v -> -u, -v); turning against each other, under its mirror (n -> -n, u, phi -> -u, -phi)."""
    params = undamped(N=2)
    result = roto_breather_family(params, "nonlinear", [6.5], particle=-1, partners={1: direction})
    o = result.family.orbits[0]
    assert list(o.particle_turns) == [0, 1, 0, direction, 0]
    sign = np.array([-1.0, -1.0, 1.0])[:, None] if direction == 1 else np.array([-1.0, 1.0, -1.0])[:, None]
    assert np.max(np.abs(o.x - sign * o.x[:, ::-1])) < 1e-8
    assert np.max(np.abs(o.v - sign * o.v[:, ::-1])) < 1e-7
    x, _ = o.trajectory(np.array([o.period]))
    assert x[0, PHI, 3] - o.x[PHI, 3] == pytest.approx(2 * math.pi * direction, abs=1e-8)


def test_cli_counter_needs_a_partner():
    result = runner.invoke(app, ["breathers", "--omega", "6", "--counter"])
    assert result.exit_code == 2 and "--partner" in result.output


def test_a_perturbed_unstable_orbit_leaves_at_the_rate_of_its_largest_multiplier():
    """A direct run (Yoshida-4, independent of the monodromy) grows by |mu_max| a period."""
    params = undamped(N=2)
    unstable = roto_breather_family(params, "nonlinear", [5.0]).family.orbits[0]
    stable = roto_breather_family(params, "nonlinear", [6.5]).family.orbits[0]
    assert not unstable.stable and stable.stable
    life = lifetime(unstable, perturbation=1e-8, threshold=1e-2, max_periods=40)
    assert life.growth_per_period == pytest.approx(unstable.max_multiplier, rel=0.05)
    expected = math.log(1e6) / math.log(unstable.max_multiplier)
    assert abs(life.periods - expected) <= 2
    assert lifetime(stable, perturbation=1e-8, threshold=1e-2, max_periods=40).periods is None
    with pytest.raises(ValueError, match="perturbation"):
        lifetime(stable, perturbation=1.0, threshold=1e-2)
