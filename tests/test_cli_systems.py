"""The commands on a user's system (``--system REF``, issue 39 item 5): built-in examples, a user's file, bad references."""

from __future__ import annotations

import json
import math

import pytest
from typer.testing import CliRunner

from conftest import SYSTEMS_CACHE
from cosserat_chain.cli import app

#: The in-phase rotation of AUTO-07p's pen demo at I = 0.4 (gamma = 0.175, eps = 0.1): one damped driven
#: pendulum's, from an independent SciPy shooting (tests of numerics.shooting).
PEN_PERIOD = 1.5738796958

#: A user's file: the pen demo's formulas on any number of sites (the same formulas compile to the same kernels, so
#: the session compiles them once; what is tested is the file, its function and the config's [system] table).
USER_SYSTEM = """
from cosserat_chain.systems import LatticeSystem


def pendula(*, sites=2, I=0.4, gamma=0.175, eps=0.1):
    return LatticeSystem(
        sites=sites,
        site_energy="1 - cos(phi) - I*phi",
        bond_energy="gamma/2*(phi_r - phi_l)**2",
        damping="eps",
        parameters={"I": I, "gamma": gamma, "eps": eps},
        name="my_pendula",
    )


not_a_system = 3
"""


@pytest.fixture(autouse=True)
def _cache(monkeypatch):
    """The compiled systems go to the tests' cache folder, not the user's."""
    monkeypatch.setenv("COSSERAT_CHAIN_CACHE", str(SYSTEMS_CACHE))


def invoke(*args: str):
    return CliRunner().invoke(app, list(args), terminal_width=200)


def ok_json(*args: str) -> dict:
    result = invoke(*args, "--json")
    assert result.exit_code == 0, result.output
    return json.loads(result.stdout)


def test_orbit_of_the_pen_demo_has_its_known_period():
    """The in-phase rotation at I = 0.4 from a settled run and shooting: period to 1e-8, both angles turning once, stable."""
    result = ok_json("orbit", "--system", "pen")
    assert result["system"] == "pen" and result["parameters"]["I"] == 0.4
    assert result["period"] == pytest.approx(PEN_PERIOD, abs=1e-8)
    assert result["turns"] == [1.0, 1.0]
    # In phase: both pendula in the same state; the trivial multiplier is 1.
    assert result["q0"][0] == pytest.approx(result["q0"][1], abs=1e-9)
    assert min(abs(complex(*m) - 1) for m in result["multipliers"]) < 1e-6
    assert result["stable"] is True


def test_orbit_parameter_from_set_changes_the_orbit():
    """--set I=... is the system's parameter: a stronger drive turns the pendula faster (a shorter period)."""
    faster = ok_json("orbit", "--system", "pen", "--set", "I=0.6")
    assert faster["parameters"]["I"] == 0.6
    assert faster["period"] < PEN_PERIOD - 0.1


def test_states_of_a_josephson_array_are_the_uniform_equilibria():
    """Free ends, I = 0.5: Newton from q = 0 reaches the uniform sin phi = I (stable); its partner pi - arcsin I is unstable."""
    result = ok_json("states", "--system", "josephson_array", "--set", "sites=3", "--set", "I=0.5", "--start", "0", "--start", "2.6")
    phis = sorted(tuple(e["q"]) for e in result["equilibria"])
    assert len(phis) == 2
    low, high = phis
    assert low == pytest.approx([math.asin(0.5)] * 3, abs=1e-10)
    assert high == pytest.approx([math.pi - math.asin(0.5)] * 3, abs=1e-10)
    by_phi = {round(e["q"][0], 6): e for e in result["equilibria"]}
    assert by_phi[round(low[0], 6)]["stable"] is True and by_phi[round(low[0], 6)]["index"] == 0
    assert by_phi[round(high[0], 6)]["stable"] is False and by_phi[round(high[0], 6)]["index"] >= 1


def test_critical_of_a_josephson_array_is_the_fold_at_unit_current():
    """The uniform equilibrium sin phi = I of an array with free ends folds at I = 1 exactly, phi = pi / 2."""
    result = ok_json("critical", "--system", "josephson_array", "--set", "sites=3", "--vary", "I")
    assert result["fold"]["value"] == pytest.approx(1.0, abs=1e-8)
    assert result["fold"]["q"] == pytest.approx([math.pi / 2] * 3, abs=1e-4)
    assert result["start_stable"] is True
    text = invoke("critical", "--system", "josephson_array", "--set", "sites=3", "--vary", "I")
    assert text.exit_code == 0 and "fold at I = 1" in text.stdout


@pytest.mark.slow
def test_diagram_of_the_pen_demo_has_the_folds_and_the_homoclinic_end(tmp_path):
    """Rotation starts where the equilibrium folds, I = 1 at any damping; the in-phase rotation (a single damped
    pendulum's) ends at its homoclinic orbit, I = 4 eps / pi to first order in eps (Melnikov), below: the loop is open."""
    import xarray as xr

    out = tmp_path / "loop.nc"
    result = ok_json("diagram", "--system", "pen", "--vary", "eps", "--values", "0.05", "--drive", "I", "--out", str(out))
    (row,) = result["rows"]
    assert row["starts"] == pytest.approx(1.0, abs=1e-8)
    assert row["stops"] == pytest.approx(4 * 0.05 / math.pi, rel=5e-3)
    assert row["open"] is True
    with xr.open_dataset(out) as ds:
        assert ds.attrs["drive"] == "I" and ds.attrs["varied"] == "eps"
        assert float(ds.stops[0]) == row["stops"]


def test_a_users_file_with_parameters_from_the_config(tmp_path):
    """A file with a function returning a LatticeSystem, its arguments in the config's [system] table and --set."""
    source = tmp_path / "mine.py"
    source.write_text(USER_SYSTEM)
    config = tmp_path / "mine.toml"
    config.write_text("[system]\nsites = 3\nI = 0.25\n")
    reference = f"{source}:pendula"
    result = ok_json("critical", "--system", reference, "--config", str(config), "--vary", "I")
    assert result["system"] == "my_pendula" and result["parameters"]["I"] == 0.25
    assert result["fold"]["value"] == pytest.approx(1.0, abs=1e-8)
    # --set overrides the file; the equilibrium from rest is sin phi = I.
    states = ok_json("states", "--system", reference, "--config", str(config), "--set", "I=0.3")
    assert states["parameters"]["I"] == 0.3
    assert states["equilibria"][0]["q"] == pytest.approx([math.asin(0.3)] * 3, abs=1e-10)


def test_simulate_writes_the_systems_coordinates(tmp_path):
    """simulate --system: a NetCDF over time and the system's named coordinates, parameters in the attributes; the
    damped pendula from rest with a small push settle back to sin phi = I."""
    import xarray as xr

    out = tmp_path / "run.nc"
    result = invoke(
        "simulate", "--system", "pen", "--set", "I=0.2", "--t-end", "150", "--frames", "6", "--start", "0.1,-0.1", "--out", str(out)
    )
    assert result.exit_code == 0, result.output
    with xr.open_dataset(out) as ds:
        assert list(ds.coordinate_label.values) == ["phi_0", "phi_1"], "a text coordinate is a CF label in the file"
        assert ds.q.shape == (6, 2) and ds.t.values[-1] == 150.0, "the file's time axis is t (cosserat_chain.io.FILE_TIME)"
        assert ds.attrs["system"] == "pen" and ds.attrs["param_I"] == 0.2 and ds.attrs["status"] == "completed"
        assert ds.q.values[0] == pytest.approx([0.1, -0.1])
        assert ds.q.values[-1] == pytest.approx([math.asin(0.2)] * 2, abs=1e-3)
        # Damped: the energy only decreases.
        energy = (ds.potential_energy + ds.kinetic_energy).values
        assert all(energy[1:] <= energy[:-1] + 1e-12)


@pytest.mark.parametrize(
    ("args", "words"),
    [
        (["states", "--system", "no_such_module_xyz:pen"], ["cannot import", "no_such_module_xyz"]),
        (["states", "--system", "pendulum"], ["built-in", "module:function", "'pendulum'"]),
        (["states", "--system", "missing.py:f"], ["no file", "missing.py"]),
        (["states", "--system", "cosserat_chain.systems:nothing_here"], ["has no", "nothing_here"]),
        (["states", "--system", "pen", "--set", "J=1"], ["J", "check the [system] parameters"]),
        (["states", "--system", "pen", "--set", "I"], ["--set", "NAME=VALUE"]),
        (["critical", "--system", "pen", "--vary", "K"], ["--vary", "'K'", "I, gamma, eps"]),
        (["critical", "--system", "pen"], ["--vary"]),
        (["orbit", "--system", "pen", "--turn", "psi=1"], ["--turn", "'psi'", "phi_0, phi_1"]),
        (["states", "--system", "pen", "--start", "1,2,3"], ["--start", "2"]),
        (["states", "--system", "pen", "--model", "sine"], ["--model", "belong", "--system"]),
        (["orbit", "--system", "pen", "--moment", "0.3"], ["--moment", "belong"]),
        (["critical", "--vary", "I"], ["--vary", "need", "--system"]),
        (["orbit"], ["--moment is required"]),
        (["diagram", "--system", "pen", "--vary", "eps", "--values", "0.1"], ["--drive"]),
        (["diagram", "--system", "pen", "--vary", "I", "--values", "0.1", "--drive", "I"], ["--drive", "different"]),
        (["diagram", "--system", "pen", "--vary", "eps", "--values", "0.1", "--drive", "I", "--follow"], ["--follow", "belong"]),
        (["diagram", "--vary", "E1", "--values", "1", "--drive", "I"], ["--drive", "need", "--system"]),
    ],
)
def test_bad_references_and_options_exit_2_with_a_message(args, words):
    result = invoke(*args)
    assert result.exit_code == 2, result.output
    assert "Traceback" not in result.output
    for word in words:
        assert word in result.output, (word, result.output)


def test_a_user_function_that_returns_no_system_or_fails_exits_2(tmp_path):
    source = tmp_path / "bad.py"
    source.write_text(USER_SYSTEM + "\n\ndef broken():\n    raise RuntimeError('lattice not ready')\n")
    for name, word in (("not_a_system", "must return a cosserat_chain System"), ("broken", "lattice not ready")):
        result = invoke("states", "--system", f"{source}:{name}")
        assert result.exit_code == 2, result.output
        assert word in result.output


def test_an_orbit_that_is_not_there_exits_3_saying_what_to_try():
    """An undriven array (I = 0) settles at rest: no rotation to shoot from; the message points to --velocity."""
    result = invoke("orbit", "--system", "josephson_array", "--set", "sites=3")
    assert result.exit_code == 3, result.output
    assert "did not turn" in result.output and "--velocity" in result.output


@pytest.mark.parametrize(
    ("table", "named"), [('I = "strong"', "'I'"), ("I = [1, 2]", "'I'"), ("alpha = { a = 1 }", "'alpha'"), ("I = nan", "finite")]
)
def test_system_tables_of_the_wrong_type_exit_2_naming_the_argument(tmp_path, table, named):
    config = tmp_path / "bad.toml"
    config.write_text(f"[system]\nsites = 3\n{table}\n")
    result = invoke("states", "--system", "josephson_array", "--config", str(config))
    assert result.exit_code == 2, result.output
    assert named in result.output and "Traceback" not in result.output


def test_a_config_with_chain_fields_is_refused_with_system(tmp_path):
    config = tmp_path / "chain.toml"
    config.write_text("N = 3\n[system]\nI = 0.3\n")
    result = invoke("states", "--system", "pen", "--config", str(config))
    assert result.exit_code == 2 and "'N'" in result.output and "[system]" in result.output
