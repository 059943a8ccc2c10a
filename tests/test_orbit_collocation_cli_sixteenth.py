"""``orbit --method collocation`` from the command line: the mesh (``--ntst``, ``--ncol``, ``--max-interval``), the
NetCDF file (``--out``) and, for a user's system, the family born at a Hopf point (``--from-hopf``) (issue 40).

Checked against what a wrong implementation would miss: the mesh asked for is the mesh solved on (the trivial
multiplier's error of the API's orbit on that mesh, and a branch's intervals raised to 2 T / max_interval), the file
read back equals the JSON and starts the shooting's Newton on the same orbit, and the Hopf family's orbits are the
closed-form circles of tests/follower_rotor_system.py (period 2 pi / sqrt(kk), radius sqrt(a0_H - a0) with b = -1).
"""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
import xarray as xr
from typer.testing import CliRunner

from conftest import SYSTEMS_CACHE
from cosserat_chain import ChainParams
from cosserat_chain._version import __version__
from cosserat_chain.cli import app
from cosserat_chain.numerics.collocation import TRIVIAL_WARNING
from follower_rotor_system import HOPF, PERIOD, ROTOR
from test_cli_systems import PEN_PERIOD

#: Agreement of two independent methods (collocation, shooting) on one orbit.
AGREE = 1e-8
#: The nonlinear N = 1 chain's orbit at M = 0.3 followed a short way down (tests/test_orbit_solved_once.py's case).
CHAIN = ["--model", "nonlinear", "--moment", "0.3", "--method", "collocation"]
DOWN_TO = 0.299


@pytest.fixture(autouse=True)
def _cache(monkeypatch):
    """The compiled systems go to the tests' cache folder, not the user's."""
    monkeypatch.setenv("COSSERAT_CHAIN_CACHE", str(SYSTEMS_CACHE))


def invoke(*args: str):
    return CliRunner().invoke(app, [str(a) for a in args], terminal_width=200)


@pytest.fixture(scope="module")
def n1_config(tmp_path_factory):
    config = tmp_path_factory.mktemp("n1") / "N1.toml"
    config.write_text("N = 1\n")
    return config


def test_the_systems_branch_on_the_mesh_asked_for_and_its_file(tmp_path):
    """The pen demo on 60 intervals of 5 points, its branch no interval longer than 0.05 time units: the period is the
    independent shooting's, the branch's intervals rise to 2 T / 0.05, and the file holds what the JSON says."""
    out = tmp_path / "pen.nc"
    args = ["--ntst", "60", "--ncol", "5", "--vary", "I", "--down-to", "0.39", "--max-interval", "0.05"]
    result = invoke("orbit", "--system", "pen", "--method", "collocation", *args, "--out", out, "--json")
    assert result.exit_code == 0, result.output
    data = json.loads(result.stdout)
    assert (data["ntst"], data["ncol"]) == (60, 5)
    assert data["period"] == pytest.approx(PEN_PERIOD, abs=AGREE) and data["trivial_multiplier_error"] < AGREE
    branch = data["branch"]
    periods = np.array(branch["periods"])
    # Each mesh adaptation sets max(ntst, ceil(2 T / max_interval)) intervals, T the period of the orbit it restarts from.
    raised = {max(60, math.ceil(2.0 * t / 0.05)) for t in periods}
    assert branch["max_interval"] == 0.05 and branch["end_ntst"] in raised and branch["end_ntst"] > 60
    with xr.open_dataset(out) as ds:
        attrs = ds.attrs
        assert (attrs["method"], attrs["ntst"], attrs["ncol"], attrs["branch_end_ntst"]) == ("collocation", 60, 5, branch["end_ntst"])
        assert attrs["trivial_multiplier_error"] == data["trivial_multiplier_error"] and attrs["max_interval"] == 0.05
        assert attrs["period"] == data["period"] and attrs["cosserat_chain_version"] == __version__
        assert attrs["varied"] == "I" and attrs["branch_end"] == branch["end"] and attrs["param_I"] == 0.4
        assert "units" in attrs["units_convention"] and ds["branch_period"].attrs["units"] == "1"
        np.testing.assert_array_equal(ds["branch_value"].values, branch["values"])
        np.testing.assert_array_equal(ds["branch_period"].values, periods)
        np.testing.assert_array_equal(ds["branch_trivial_multiplier_error"].values, branch["trivial_multiplier_error"])
        np.testing.assert_array_equal(np.concatenate([ds["q0"].values, ds["v0"].values]), data["y0"])
        multipliers = ds["multiplier_real"].values + 1j * ds["multiplier_imag"].values
    np.testing.assert_array_equal(multipliers, [complex(*m) for m in data["multipliers"]])


def test_the_command_line_reaches_the_fine_meshes_the_api_takes():
    """NTST = 200 (the junctions' snake's mesh, docs/collocation.md) from the command line: the pen demo's orbit on it."""
    result = invoke("orbit", "--system", "pen", "--method", "collocation", "--ntst", "200", "--json")
    assert result.exit_code == 0, result.output
    data = json.loads(result.stdout)
    assert (data["ntst"], data["ncol"]) == (200, 4)
    assert data["period"] == pytest.approx(PEN_PERIOD, abs=AGREE) and data["trivial_multiplier_error"] < AGREE


@pytest.fixture(scope="module")
def chain_run(n1_config, tmp_path_factory):
    """The N = 1 chain's orbit and short branch on 30 intervals of 3 points, written to a file (JSON, file)."""
    out = tmp_path_factory.mktemp("chain") / "orbit.nc"
    result = invoke("orbit", *CHAIN, "--config", n1_config, "--down-to", DOWN_TO, "--ntst", "30", "--ncol", "3", "--out", out, "--json")
    assert result.exit_code == 0, result.output
    return json.loads(result.stdout), out


def test_the_chains_orbit_is_solved_on_the_mesh_asked_for(chain_run):
    from cosserat_chain.numerics.collocation import find_collocation_orbit

    data, _ = chain_run
    assert (data["method"], data["ntst"], data["ncol"]) == ("collocation", 30, 3)
    # The API's orbit on the same mesh has the same trivial multiplier; the default mesh's is far closer to 1.
    same = find_collocation_orbit(ChainParams(N=1), "nonlinear", 0.3, ntst=30, ncol=3)
    assert data["trivial_multiplier_error"] == pytest.approx(same.trivial_multiplier_error, rel=1e-6)
    assert data["trivial_multiplier_error"] == pytest.approx(abs(complex(*data["trivial_multiplier"]) - 1.0), abs=1e-15)
    default = find_collocation_orbit(ChainParams(N=1), "nonlinear", 0.3)
    assert data["trivial_multiplier_error"] > 10.0 * default.trivial_multiplier_error
    continuation = data["continuation"]
    # The branch keeps the orbit's mesh (no --max-interval), and every point carries its trivial multiplier's error.
    assert continuation["end"] == "moment_min" and continuation["end_ntst"] == 30 and continuation["max_interval"] is None
    assert continuation["trivial_multiplier_error"][0] == data["trivial_multiplier_error"]
    assert len(continuation["trivial_multiplier_error"]) == len(continuation["moment"])


def test_the_chains_file_is_the_json_and_starts_the_shootings_newton_on_the_orbit(chain_run, n1_config):
    data, out = chain_run
    continuation = data["continuation"]
    with xr.open_dataset(out) as ds:
        attrs = ds.attrs
        assert (attrs["method"], attrs["ntst"], attrs["ncol"], attrs["end_ntst"]) == ("collocation", 30, 3, 30)
        assert attrs["trivial_multiplier_error"] == data["trivial_multiplier_error"] and attrs["cosserat_chain_version"] == __version__
        assert (attrs["experiment"], attrs["period"], attrs["moment"]) == ("periodic_orbit", data["period"], 0.3)
        assert json.loads(attrs["settings_json"])["ntst"] == 30 and ds["branch_period"].attrs["units"] == "1"
        np.testing.assert_array_equal(ds["branch_moment"].values, continuation["moment"])
        np.testing.assert_array_equal(ds["branch_period"].values, continuation["period"])
        np.testing.assert_array_equal(ds["branch_trivial_multiplier_error"].values, continuation["trivial_multiplier_error"])
    # The file is an orbit file as the shooting writes it: --guess reads it, and the shooting's Newton lands on the same
    # orbit (the collocation's period on this coarse mesh within its discretisation error, the trivial one's size).
    shot = invoke("orbit", "--model", "nonlinear", "--moment", "0.3", "--config", n1_config, "--guess", out, "--json")
    assert shot.exit_code == 0, shot.output
    shooting = json.loads(shot.stdout)
    assert shooting["start"]["method"] == "guess" and shooting["turns"] == data["turns"]
    assert shooting["period"] == pytest.approx(data["period"], rel=1e-5)


def test_the_family_born_at_a_hopf_point_followed_by_collocation(tmp_path):
    """--from-hopf --method collocation: the subcritical rotor's unstable circles (b = -1: radius^2 = a0_H - a0), from the
    shooting's first orbit at the Hopf point, solved and followed by collocation down past a0 = 0.2."""
    rotor = tmp_path / "rotor.py"
    rotor.write_text(ROTOR)
    out = tmp_path / "hopf.nc"
    args = ["--set", "a0=0.2", "--set", "b=-1", "--oscillation", "--from-hopf", "--vary", "a0", "--down-to", "0.4"]
    result = invoke("orbit", "--system", f"{rotor}:build", *args, "--method", "collocation", "--ntst", "20", "--out", out, "--json")
    assert result.exit_code == 0, result.output
    data = json.loads(result.stdout)
    assert data["method"] == "collocation" and data["ntst"] == 20
    assert data["hopf"]["value"] == pytest.approx(HOPF, abs=1e-9)
    a0 = data["parameters"]["a0"]
    assert a0 < HOPF and not data["stable"] and data["turns"] == [0, 0]
    assert data["period"] == pytest.approx(PERIOD, abs=AGREE)
    assert math.hypot(*data["y0"][:2]) == pytest.approx(math.sqrt(HOPF - a0), abs=AGREE)
    branch = data["branch"]
    assert branch["end"] == "parameter_limit" and min(branch["values"]) < 0.2
    # Every orbit resolved: the trivial multiplier within the branch's warning threshold on 20 intervals.
    assert np.allclose(branch["periods"], PERIOD, atol=AGREE) and max(branch["trivial_multiplier_error"]) < TRIVIAL_WARNING
    assert "not resolved" not in branch["message"]
    with xr.open_dataset(out) as ds:
        assert ds.attrs["method"] == "collocation" and ds.attrs["param_a0"] == a0
        np.testing.assert_array_equal(ds["branch_value"].values, branch["values"])


@pytest.mark.parametrize(
    ("args", "words"),
    [
        (["--moment", "0.3", "--ntst", "60"], ["--ntst set(s) the collocation's mesh", "--method collocation", "got --method auto"]),
        (["--system", "pen", "--ncol", "5"], ["--ncol set(s) the collocation's mesh", "--method collocation"]),
        ([*CHAIN, "--ntst", "1"], ["--ntst", "integer >= 2", "got 1"]),
        ([*CHAIN, "--ncol", "8"], ["--ncol", "from 2 to 7", "got 8"]),
        (["--system", "pen", "--method", "collocation", "--ntst", "4001"], ["--ntst", "at most 4000", "got 4001"]),
        ([*CHAIN, "--max-interval", "0"], ["--max-interval", "must be > 0", "got 0.0"]),
        ([*CHAIN, "--max-interval", "1"], ["--max-interval bounds the mesh intervals of a branch", "--down-to or --from-above"]),
        (["--system", "pen", "--method", "collocation", "--max-interval", "1"], ["--max-interval", "--vary NAME"]),
    ],
)
def test_bad_mesh_options_exit_2_naming_the_option_the_value_and_what_is_allowed(args, words):
    result = invoke("orbit", *args)
    assert result.exit_code == 2, result.output
    for word in words:
        assert word in result.output, (word, result.output)


@pytest.mark.parametrize("form", ["chain", "system"])
def test_an_output_that_is_an_input_or_unwritable_is_refused_before_computing(form, tmp_path, monkeypatch):
    """--out is checked before any orbit is solved: the config given is never replaced, a path under a file never tried."""
    from cosserat_chain.experiments import orbits
    from cosserat_chain.numerics import shooting

    def never(*args, **kwargs):
        raise AssertionError("an orbit was solved before --out was checked")

    monkeypatch.setattr(orbits, "find_collocation_orbit", never)
    monkeypatch.setattr(shooting, "settled_guess", never)
    config = tmp_path / "in.toml"
    config.write_text("N = 1\n" if form == "chain" else "[system]\nI = 0.4\n")
    command = [*CHAIN, "--down-to", DOWN_TO] if form == "chain" else ["--system", "pen", "--method", "collocation"]
    same = invoke("orbit", *command, "--config", config, "--out", config)
    assert same.exit_code == 2 and "--out" in same.output, same.output
    assert config.read_text() == ("N = 1\n" if form == "chain" else "[system]\nI = 0.4\n")
    nowhere = invoke("orbit", *command, "--config", config, "--out", config / "orbit.nc")
    assert nowhere.exit_code == 2 and "--out" in nowhere.output, nowhere.output


def test_the_chains_branch_raises_its_intervals_to_the_max_interval(n1_config):
    """--max-interval on the chain: the branch's mesh rises from the orbit's 40 intervals to 2 T / 0.05."""
    result = invoke("orbit", *CHAIN, "--config", n1_config, "--down-to", DOWN_TO, "--max-interval", "0.05", "--json")
    assert result.exit_code == 0, result.output
    data = json.loads(result.stdout)
    continuation = data["continuation"]
    assert data["ntst"] == 40 and continuation["max_interval"] == 0.05 and continuation["end"] == "moment_min"
    raised = {max(40, math.ceil(2.0 * t / 0.05)) for t in continuation["period"]}
    assert continuation["end_ntst"] in raised and continuation["end_ntst"] > 40
