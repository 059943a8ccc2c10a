"""Roto-breathers of user systems (experiments.system_breathers): the Takeno-Peyrard rotator lattice as the example."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
import xarray as xr
from scipy.optimize import brentq
from scipy.special import ellipk
from typer.testing import CliRunner

from conftest import SYSTEMS_CACHE, undamped_energies
from cosserat_chain.cli import app
from cosserat_chain.experiments import system_breathers as sb
from cosserat_chain.numerics import shooting
from cosserat_chain.systems import LatticeSystem, josephson_array, takeno_peyrard

SITES = 7
#: Coupling of the family shared by the tests: its band is [1, sqrt(1.2)].
COUPLING = 0.05


@pytest.fixture(autouse=True)
def _cache(monkeypatch):
    """The compiled systems go to the tests' cache folder (compiled once, not every session), not the user's."""
    monkeypatch.setenv("COSSERAT_CHAIN_CACHE", str(SYSTEMS_CACHE))


def pendulum_period(energy: float) -> float:
    """One turn of the rotating pendulum phi'' = -sin phi at energy E = phi'^2 / 2 + 1 - cos phi > 2: 4 K(2 / E) / sqrt(2 E)."""
    return 4.0 / math.sqrt(2.0 * energy) * ellipk(2.0 / energy)


@pytest.fixture(scope="module")
def family():
    """The one-site family at C = 0.05 from Omega = 1.3 down to 1.1, through its loss of stability."""
    return sb.roto_breather_family(takeno_peyrard(SITES, C=COUPLING), 1.3, to=1.1)


def test_anti_continuum_orbit_has_the_closed_form_rotating_pendulum_energy_for_its_period():
    omega = 1.7
    period = 2 * math.pi / omega
    expected = brentq(lambda e: pendulum_period(e) - period, 2 + 1e-12, 100.0, xtol=1e-15)
    system = takeno_peyrard(SITES, C=0.0)
    start = sb.anti_continuum_orbit(system, omega, {3: 1}, "C")
    assert start.period == pytest.approx(period, rel=1e-15)
    assert start.energies[3] == pytest.approx(expected, rel=1e-12)
    # The orbit found at C = 0 from it is itself: only the rotor moves, with that energy.
    found = sb.roto_breather_family(system, omega)
    orbit = found.orbits[0]
    assert abs(orbit.unfolding) < 1e-10
    assert sb.orbit_energy(orbit) == pytest.approx(expected, rel=1e-10)
    assert np.max(np.abs(np.delete(orbit.y0, [3, SITES + 3]))) < 1e-10


def test_continued_orbits_close_under_the_undamped_flow_and_conserve_energy(family):
    assert family.orbits[0].parameter("C") == COUPLING and len(family.orbits) >= 5
    assert family.omegas[0] == pytest.approx(1.3) and family.omegas[-1] == pytest.approx(1.1)
    shift = np.zeros(2 * SITES)
    shift[SITES // 2] = 2 * math.pi
    for orbit in family.orbits[::3]:
        undamped = orbit.system.with_parameters(gamma=0.0)
        end = shooting.flow(undamped, orbit.y0, orbit.period, variations=False)[0]
        assert np.max(np.abs(end - orbit.y0 - shift)) < 1e-8
        energy = undamped_energies(orbit, 7)
        assert np.ptp(energy) < 1e-9
        assert energy[0] == pytest.approx(sb.orbit_energy(orbit), abs=1e-12)


def test_a_stable_member_has_its_multipliers_on_the_unit_circle_and_a_symplectic_monodromy(family):
    orbit = family.orbits[0]
    assert orbit.stable
    # The pair at +1 (phase and energy) is a Jordan block, split by the square root of round-off: set aside.
    assert np.max(np.abs(np.abs(orbit.nontrivial_multipliers) - 1.0)) < 1e-9
    assert np.min(np.abs(orbit.multipliers - 1.0)) < 1e-4
    # Unit masses: (q, q') are canonical, so the monodromy preserves the symplectic form.
    n = SITES
    form = np.block([[np.zeros((n, n)), np.eye(n)], [-np.eye(n), np.zeros((n, n))]])
    assert np.max(np.abs(orbit.monodromy.T @ form @ orbit.monodromy - form)) < 1e-7


def test_stability_is_lost_at_plus_one_where_the_energy_is_least_above_the_first_harmonic_resonance(family):
    """Going down in Omega the family loses stability once, by a pair through +1, at the energy's minimum
    (a Hamiltonian family's pair at +1 turns real where dE/dOmega = 0), just above where Omega meets the band's top."""
    (change,) = family.changes
    assert change.unstable_omega < change.stable_omega
    assert change.kind == "+1"
    (extremum,) = family.energy_extrema()
    steps = np.abs(np.diff(family.omegas))
    assert abs(change.omega - extremum) < np.max(steps)
    assert change.resonance.harmonic == 1 and change.resonance.edge == "top"
    assert change.resonance.omega == pytest.approx(math.sqrt(1 + 4 * COUPLING), rel=1e-12)
    assert change.resonance.omega < change.omega < change.resonance.omega + 0.06
    stable = np.array([o.stable for o in family.orbits])
    assert np.all(stable[family.omegas > change.stable_omega]) and not np.any(stable[family.omegas < change.unstable_omega])


def test_a_parametric_instability_window_opens_where_half_the_frequency_meets_the_band():
    """Above the band, the rotor modulates its neighbours' stiffness at Omega: phonons with 2 w = Omega resonate
    parametrically (their multipliers meet at -1), so going down the family loses stability at -1 where Omega / 2
    reaches the band's top and regains it where Omega / 2 leaves the bottom (each within the family's step)."""
    family = sb.roto_breather_family(takeno_peyrard(11, C=COUPLING), 2.4, to=1.95)
    # The 11 sites' phonon pairs meet near -1 one after another (real pairs and Krein quartets): each collision is
    # located; the first is where the family loses stability, the last where it regains it.
    lost, regained = family.changes[0], family.changes[-1]
    step = np.max(np.abs(np.diff(family.omegas)))
    assert lost.unstable_omega < lost.stable_omega and regained.stable_omega < regained.unstable_omega
    assert all(c.multiplier.real < -0.9 for c in family.changes)
    assert (lost.resonance.harmonic, lost.resonance.edge) == (0.5, "top")
    assert (regained.resonance.harmonic, regained.resonance.edge) == (0.5, "bottom")
    assert abs(lost.omega - 2 * math.sqrt(1 + 4 * COUPLING)) < step
    assert abs(regained.omega - 2.0) < step
    inside = (family.omegas < lost.unstable_omega) & (family.omegas > regained.unstable_omega)
    assert inside.any() and not any(o.stable for o, flag in zip(family.orbits, inside, strict=True) if flag)


def test_linear_bands_from_the_ring_jacobian_equal_the_closed_forms():
    for C in (0.0, 0.3, 2.0):
        ((bottom, top),) = sb.linear_bands(takeno_peyrard(5, C=C))
        assert bottom == pytest.approx(1.0, abs=1e-12) and top == pytest.approx(math.sqrt(1 + 4 * C), rel=1e-12)
    ((bottom, top),) = sb.linear_bands(josephson_array(5, kappa=0.7))
    assert bottom == pytest.approx(1.0, abs=1e-12) and top == pytest.approx(math.sqrt(1 + 4 * 0.7), rel=1e-12)
    unstable = LatticeSystem(sites=4, site_energy="cos(phi)", bond_energy="C*(1 - cos(phi_r - phi_l))", parameters={"C": 1.0})
    with pytest.raises(sb.BreatherError, match="not a stable equilibrium"):
        sb.linear_bands(unstable)


def test_resonances_put_whole_and_half_harmonics_on_the_band_edges():
    bands = [(1.0, 1.2)]
    found = sb.resonances(bands, 0.5, 1.3)
    assert [(r.order, r.edge) for r in found] == [(4, "bottom"), (4, "top"), (3, "bottom"), (3, "top"), (2, "bottom"), (2, "top")]
    assert [r.omega for r in found] == pytest.approx([0.5, 0.6, 2 / 3, 0.8, 1.0, 1.2])
    assert [r.multiplier for r in found] == [1, 1, -1, -1, 1, 1]
    assert sb.nearest_resonance(bands, 0.78, multiplier=1).omega == pytest.approx(0.6)
    assert sb.harmonics_in_bands(bands, 0.55) == [(2, 0)]


def test_two_site_roto_breathers_in_and_out_of_phase_are_mirror_images_of_themselves():
    """Two neighbouring rotors (sites 3, 4 of 8): the in-phase orbit is symmetric under the mirror i -> 7 - i,
    the out-of-phase one under the mirror with the angles' sign flipped."""
    n = 8
    system = takeno_peyrard(n, C=0.05)
    mirror = np.arange(n)[::-1]
    for counter, sign in ((False, 1.0), (True, -1.0)):
        found = sb.roto_breather_family(system, 1.5, rotor=3, partner=4, counter=counter)
        orbit = found.orbits[0]
        assert abs(orbit.unfolding) < 1e-10
        assert orbit.v0[3] == pytest.approx(sign * orbit.v0[4], rel=1e-8)
        assert np.max(np.abs(orbit.q0 - sign * orbit.q0[mirror])) < 1e-8
        assert np.max(np.abs(orbit.v0 - sign * orbit.v0[mirror])) < 1e-8
        assert found.start.turns == {3: 1, 4: -1 if counter else 1}
        assert np.max(np.abs(orbit.v0[[0, 1, 2, 5, 6, 7]])) > 1e-3


def test_bad_rotors_couplings_and_frequencies_are_refused_by_name():
    system = takeno_peyrard(5, C=0.1)
    with pytest.raises(sb.BreatherError, match="coupling: takeno_peyrard has no parameter 'K'"):
        sb.roto_breather_family(system, 1.5, coupling="K")
    with pytest.raises(sb.BreatherError, match="rotor must be a coordinate"):
        sb.roto_breather_family(system, 1.5, rotor=9)
    with pytest.raises(sb.BreatherError, match="omega must be a finite number > 0"):
        sb.roto_breather_family(system, -1.0)
    with pytest.raises(sb.BreatherError, match="partner must differ"):
        sb.roto_breather_family(system, 1.5, rotor=2, partner="phi_2")
    springs = LatticeSystem(
        sites=3,
        dofs=("x",),
        angles=(),
        site_energy="x**2/2",
        bond_energy="C*(x_r - x_l)**2/2",
        damping="g",
        parameters={"C": 0.1, "g": 0.0},
    )
    with pytest.raises(sb.BreatherError, match="not an angle"):
        sb.roto_breather_family(springs, 1.5, rotor=1)
    with pytest.raises(sb.BreatherError, match="has the mean"):
        sb.roto_breather_family(takeno_peyrard(5, C=0.1, T=0.2), 1.5)
    undamped = LatticeSystem(sites=3, site_energy="1 - cos(phi)", bond_energy="C*(1 - cos(phi_r - phi_l))", parameters={"C": 0.1})
    with pytest.raises(sb.BreatherError, match="no damping parameter"):
        sb.roto_breather_family(undamped, 1.5)


def test_the_command_computes_a_system_family_as_json_and_refuses_chain_options():
    runner = CliRunner()
    result = runner.invoke(
        app, ["breathers", "--system", "takeno_peyrard", "--set", "sites=5", "--set", "C=0.05", "--omega", "1.4", "--json"]
    )
    assert result.exit_code == 0, result.output
    data = json.loads(result.stdout)
    assert data["system"] == "takeno_peyrard" and data["rotors"] == {"phi_2": 1} and data["stable"] == [True]
    assert data["bands"] == [[1.0, pytest.approx(math.sqrt(1.2))]]
    assert data["omega"] == [pytest.approx(1.4)]
    bad = runner.invoke(app, ["breathers", "--system", "takeno_peyrard", "--model", "sine", "--omega", "1.4"])
    assert bad.exit_code == 2 and "--model" in bad.output
    off = runner.invoke(app, ["breathers", "--system", "takeno_peyrard", "--set", "sites=5", "--omega", "1.4", "--particle", "3"])
    assert off.exit_code == 2 and "--particle 3 is off the system" in off.output
    chain = runner.invoke(app, ["breathers", "--omega", "1.4", "--set", "C=1"])
    assert chain.exit_code == 2 and "need(s) --system" in chain.output


def test_the_command_writes_a_self_describing_netcdf_file_that_reads_back(tmp_path):
    runner = CliRunner()
    out = tmp_path / "tp.nc"
    args = ["breathers", "--system", "takeno_peyrard", "--set", "sites=5", "--set", "C=0.05", "--omega", "1.4", "--to", "1.3"]
    result = runner.invoke(app, [*args, "--json", "--out", str(out)])
    assert result.exit_code == 0, result.output
    data = json.loads(result.stdout)
    with xr.open_dataset(out) as ds:
        np.testing.assert_array_equal(ds["omega"].values, data["omega"])
        np.testing.assert_array_equal(ds["energy"].values, data["energy"])
        assert ds["stable"].values.astype(bool).tolist() == data["stable"]
        # The start of every member closes under the flow of the system rebuilt from the file's own parameters.
        system = takeno_peyrard(5, **{k[len("param_") :]: float(v) for k, v in ds.attrs.items() if k.startswith("param_")})
        y0 = np.concatenate([ds["q0"].values[-1], ds["v0"].values[-1]])
        end = shooting.flow(system, y0, float(ds["period"].values[-1]), variations=False)[0]
        turns = np.zeros(10)
        turns[2] = 2 * math.pi
        assert np.max(np.abs(end - y0 - turns)) < 1e-8
        assert ds.attrs["experiment"] == "system_roto_breathers" and ds.attrs["system_reference"] == "takeno_peyrard"
        assert ds.attrs["coupling"] == "C" and json.loads(ds.attrs["rotors_json"]) == {"phi_2": 1}
        assert ds.attrs["cosserat_chain_version"] and ds["omega"].attrs["units"] == "1" and "Omega" in ds["omega"].attrs["long_name"]
        assert ds["band_top"].values[0] == pytest.approx(math.sqrt(1.2))
    # The output is checked before anything is computed: a folder is refused at once (exit 2).
    folder = runner.invoke(app, [*args, "--out", str(tmp_path)])
    assert folder.exit_code == 2 and "--out" in folder.output
