"""Every kind of NetCDF file the package writes passes two CF checkers and reads back with units.

One small file of each kind (a run, its checkpoint, the statics, a sweep, a localization run
and its checkpoint, an orbit with its continuation, a rotation characteristic, a study, a state
diagram, a roto-breather family, the report's stacked data files and the files of a user
system: a run, an orbit and a diagram) is checked by IOOS compliance-checker (``cf:1.10``) and
by cfchecks, neither finding an error, and read back through cf-xarray's unit registry with
pint-xarray.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

import h5py
import numpy as np
import pytest
import xarray as xr
from typer.testing import CliRunner

from cosserat_chain import ChainParams, simulate
from cosserat_chain.analysis.exact_beam import bending_convergence
from cosserat_chain.analysis.timoshenko import convergence
from cosserat_chain.cli import app
from cosserat_chain.experiments import system_diagram as system_diagram_module
from cosserat_chain.experiments.critical import critical_point
from cosserat_chain.experiments.orbits import rotation_characteristic
from cosserat_chain.experiments.study import compute_cell, empty_results, spec_from_mapping, store_cell
from cosserat_chain.experiments.sweep import relaxation_sweep
from cosserat_chain.io import (
    CONVENTIONS,
    FILE_TIME,
    LABEL_SUFFIX,
    SCALES,
    SYSTEM_UNITS_CONVENTION,
    VARIABLES,
    cf_attributes,
    describe,
    read_dataset,
    stack_models,
    write_dataset,
)
from pen_loops import assert_the_pen_loops_call, pen_loop_given

runner = CliRunner()


def _cli(tmp: Path, name: str, *argv: str) -> Path:
    out = tmp / f"{name}.nc"
    result = runner.invoke(app, [*argv, "--out", str(out)])
    assert result.exit_code == 0, (name, result.output)
    return out


def _write(tmp: Path, name: str, dataset: xr.Dataset) -> Path:
    return write_dataset(dataset, tmp / f"{name}.nc")


def _study(tmp: Path) -> Path:
    spec = spec_from_mapping({"models": ["linear"], "quantities": ["compliance", "band_gap"], "parameters": {"E2": [0.5, 1.0]}})
    ds = empty_results(spec)
    store_cell(ds, spec, (0,), "linear", compute_cell({"E2": 0.5}, "linear", spec.to_json()))
    store_cell(ds, spec, (1,), "linear", {"error": "a failed cell keeps its message"})
    return _write(tmp, "study", ds)


@pytest.fixture(scope="module")
def files(tmp_path_factory) -> dict[str, Path]:
    """One small file of every kind the package writes, by kind."""
    tmp = tmp_path_factory.mktemp("cf")
    paper = ChainParams()
    sine_critical = critical_point(paper, "sine")  # the critical file's and, with the linear model's, the report's
    out = {
        "simulate": _cli(tmp, "simulate", "simulate", "--model", "sine", "--t-end", "1", "--frames", "3"),
        "simulate_pinned_free": _write(
            tmp, "pinned_free", simulate(ChainParams(left_end="pinned", right_end="free"), "nonlinear", 0.01, t_end=0.5, n_frames=3)
        ),
        "critical": _write(tmp, "critical", sine_critical.to_dataset()),
        "sweep": _write(tmp, "sweep", relaxation_sweep(paper, "linear", m_max=0.02, dm=0.02).to_dataset()),
        "localization": _cli(tmp, "rotate", "rotate", "--model", "sine", "--moment", "0.3", "--turns", "1"),
        "orbit": _cli(tmp, "orbit", "orbit", "--moment", "0.22", "--down-to", "0.21"),
        "rotation_characteristic": _write(tmp, "characteristic", rotation_characteristic(paper, "sine", [0.22, 0.21]).to_dataset()),
        "study": _study(tmp),
        "state_diagram": _cli(tmp, "diagram", "diagram", "--vary", "E2", "--values", "1.0"),
        "report_critical": _write(
            tmp,
            "report_critical",
            stack_models({"sine": sine_critical.to_dataset(), "linear": critical_point(paper, "linear").to_dataset()}),
        ),
        # Sweeps of different lengths, as the report's: stacking pads their text with NaN.
        "report_sweep": _write(
            tmp,
            "report_sweep",
            stack_models({m: relaxation_sweep(paper, m, m_max=top, dm=0.01).to_dataset() for m, top in (("sine", 0.03), ("linear", 0.02))}),
        ),
    }
    # theory --out: the beam table merged with the bending table, as the command merges them.
    beam, bending = (
        convergence(paper, [3, 10]).to_dataset(paper),
        bending_convergence(paper.replace(right_end="free"), [3, 10], angle=0.5).to_dataset(),
    )
    out["theory"] = _write(tmp, "theory", beam.merge(bending).assign_attrs(bending.attrs))
    out["theory_force"] = _write(tmp, "theory_force", convergence(paper, [3, 10], load="force").to_dataset(paper))
    checkpoint = tmp / "run.checkpoint.nc"
    _cli(tmp, "checkpointed", "simulate", "--t-end", "1", "--frames", "3", "--checkpoint-every", "0.5", "--checkpoint", str(checkpoint))
    out["checkpoint"] = checkpoint
    out["localization_checkpoint"] = tmp / "rotate.checkpoint.nc"
    out["breathers"] = _cli(tmp, "breathers", "breathers", "--model", "nonlinear", "--omega", "10.5", "--to", "10.3", "--steps", "2")
    out["system_simulate"] = _cli(tmp, "system_simulate", "simulate", "--system", "pen", "--velocity", "4", "--t-end", "5", "--frames", "6")
    out["system_orbit"] = _cli(tmp, "system_orbit", "orbit", "--system", "pen")
    # eps = 0.3: the same columns as at 0.1, its edge in half the shooting evaluations. The command's diagram is the one
    # tests/test_system_diagram.py checks (its call asserted to be that one's), computed once a session.
    calls: list = []
    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(system_diagram_module, "system_diagram", pen_loop_given(0.3, calls))
        argv = ("diagram", "--system", "pen", "--vary", "eps", "--values", "0.3", "--drive", "I")
        out["system_diagram"] = _cli(tmp, "system_diagram", *argv)
    (call,) = calls
    assert_the_pen_loops_call(call, 0.3)
    return out


@pytest.fixture(scope="module")
def read(files):
    """The package's reader on a kind's file, each file read once for the tests that only look at what it holds."""
    cache: dict[str, xr.Dataset] = {}

    def read_kind(kind: str) -> xr.Dataset:
        if kind not in cache:
            cache[kind] = read_dataset(files[kind])
        return cache[kind]

    return read_kind


KINDS = [
    "simulate", "simulate_pinned_free", "checkpoint", "critical", "sweep", "localization", "localization_checkpoint", "orbit",
    "rotation_characteristic", "study", "state_diagram", "breathers", "report_critical", "report_sweep", "theory", "theory_force",
    "system_simulate", "system_orbit", "system_diagram",
]  # fmt: skip
#: The files of a user system (``--system``): in the system's own units, not the chain's.
SYSTEM_KINDS = [kind for kind in KINDS if kind.startswith("system_")]


def _compliance_errors(path: Path, tmp: Path, priorities: tuple[str, ...] = ("high_priorities",)) -> list[str]:
    """The messages of compliance-checker's results of ``priorities`` (errors; "medium_priorities": warnings) on ``path`` for cf:1.10."""
    pytest.importorskip("compliance_checker", reason="compliance-checker is not installed (pip install -e .[test])")
    from compliance_checker.runner import CheckSuite, ComplianceChecker

    CheckSuite.load_all_available_checkers()
    report = tmp / "report.json"
    ComplianceChecker.run_checker(str(path), ["cf:1.10"], 0, "normal", output_filename=str(report), output_format="json")
    results = json.loads(report.read_text())["cf:1.10"]
    return [message for priority in priorities for result in results[priority] for message in result["msgs"]]


def _cfchecks(tmp: Path):
    """cfchecks' checker, with the standard names compliance-checker ships (no network)."""
    try:
        from cfchecker.cfchecks import CFChecker
    except (ImportError, OSError) as err:  # cfunits raises OSError where the udunits2 C library is missing
        pytest.skip(f"cfchecks cannot be imported ({err}): pip install cfchecker and apt-get install libudunits2-0")
    pytest.importorskip("compliance_checker", reason="cfchecks reads the standard name table compliance-checker ships")
    import compliance_checker

    # The files use no area types and no region names: empty tables stand for the ones cfchecks downloads.
    tables = {}
    for name, root in (("area", "standard_area_type_table"), ("region", "standardized_region_list")):
        tables[name] = tmp / f"{name}.xml"
        tables[name].write_text(f'<?xml version="1.0"?>\n<{root}><version_number>1</version_number><date>2025-01-01</date></{root}>\n')
    names = Path(compliance_checker.__file__).parent / "data" / "cf-standard-name-table.xml"
    checker = CFChecker(
        cfStandardNamesXML=str(names), cfAreaTypesXML=str(tables["area"]), cfRegionNamesXML=str(tables["region"]), silent=True
    )
    return checker


@pytest.mark.parametrize("kind", KINDS)
def test_compliance_checker_finds_no_error_nor_warning_in_a_file_of_each_kind(files, kind, tmp_path):
    assert _compliance_errors(files[kind], tmp_path, ("high_priorities", "medium_priorities")) == [], kind


@pytest.mark.parametrize("kind", KINDS)
def test_cfchecks_finds_no_error_nor_warning_in_a_file_of_each_kind(files, kind, tmp_path):
    results = _cfchecks(tmp_path).checker(str(files[kind]))
    levels = ("FATAL", "ERROR", "WARN")
    found = [message for level in levels for message in results["global"][level]]
    found += [f"{name}: {message}" for name, messages in results["variables"].items() for level in levels for message in messages[level]]
    assert found == [], kind


def test_a_text_coordinate_is_a_label_in_the_file_and_the_coordinate_again_when_read(files, read):
    """A CF coordinate variable holds numbers (cfchecks warned of the models' text one): text is a label (CF 6.1)."""
    with h5py.File(files["study"]) as f:
        assert "model_label" in f and f["model_label"].dtype.kind == "S", "the label, as characters"
        assert "model_label" in str(f["compliance"].attrs["coordinates"]).split()
    for kind, name, values in (("study", "model", ["linear"]), ("system_orbit", "coordinate", ["phi_0", "phi_1"])):
        ds = read(kind)
        assert ds[name].values.tolist() == values and name in ds.indexes and f"{name}{LABEL_SUFFIX}" not in ds.variables, kind


def test_a_dimension_named_time_draws_the_checkers_time_rules_which_the_files_avoid(files, read, tmp_path):
    """A file's time axis is "t": named "time", compliance-checker asks it for standard_name "time" (seconds from an
    epoch, which the model's number of time units is not), and giving it that name draws the epoch rule instead."""
    renamed = tmp_path / "named_time.nc"
    with xr.open_dataset(files["simulate"], engine="h5netcdf") as ds:
        assert FILE_TIME in ds.dims and "time" not in ds.variables and ds.attrs["Conventions"] == CONVENTIONS
        ds.load().rename({FILE_TIME: "time"}).to_netcdf(renamed, engine="h5netcdf")
    assert "Coordinate variable 'time' should have standard_name='time', found: 'None'" in _compliance_errors(renamed, tmp_path)
    with xr.open_dataset(renamed, engine="h5netcdf") as ds:
        ds.load()["time"].attrs["standard_name"] = "time"
        ds.to_netcdf(named := tmp_path / "standard_time.nc", engine="h5netcdf")
    assert any("time must be in a valid units format <unit> since <epoch>" in m for m in _compliance_errors(named, tmp_path))
    # The package reads its files, and one written before the rename, with the axis named "time".
    assert read("simulate").time.dims == ("time",) and read_dataset(renamed).time.dims == ("time",)
    assert read("system_simulate").q.dims == ("time", "coordinate")


@pytest.mark.parametrize("kind", SYSTEM_KINDS)
def test_a_user_systems_file_is_in_its_own_units(read, kind):
    ds = read(kind)
    assert ds.attrs["units_convention"] == SYSTEM_UNITS_CONVENTION and "references" not in ds.attrs, "not the paper's chain"
    for name, variable in ds.variables.items():
        assert variable.attrs.get("long_name"), (kind, name)
        assert "scale" not in variable.attrs, (kind, name)
        if variable.dtype.kind == "f":
            assert variable.attrs["units"] == "1", (kind, name)


@pytest.mark.parametrize("kind", KINDS)
def test_every_file_reads_back_with_units_that_pint_parses(files, kind):
    cf_xarray_units = pytest.importorskip("cf_xarray.units", reason="cf-xarray is not installed (pip install -e .[test])")
    pytest.importorskip("pint_xarray", reason="pint-xarray is not installed (pip install -e .[test])")
    ds = xr.open_dataset(files[kind], engine="h5netcdf")
    quantified = ds.pint.quantify(unit_registry=cf_xarray_units.units)
    units = {
        name: quantified[name].data.units for name in ("u", "u_dot", "phi", "phi_dot", FILE_TIME, "moment") if name in quantified.variables
    }
    for name, unit in units.items():
        # Displacements were read as hours when their units said "h": now they are numbers, angles radians.
        assert unit == (cf_xarray_units.units.radian if name.startswith("phi") else cf_xarray_units.units.dimensionless), (kind, name, unit)
    described = [str(name) for name in ds.variables if name in VARIABLES or kind in SYSTEM_KINDS]
    described = [name for name in described if ds[name].dtype.kind == "f"]
    assert described and all(ds[name].attrs["units"] in ("1", "rad") for name in described), kind


def test_a_quantity_keeps_its_units_and_scale_in_every_file(read):
    seen: dict[str, tuple[str, str | None]] = {}
    for kind in [kind for kind in KINDS if kind != "theory_force" and kind not in SYSTEM_KINDS]:
        ds = read(kind)
        for name in ds.variables:
            attrs = (ds[name].attrs["units"], ds[name].attrs.get("scale"))
            assert seen.setdefault(str(name), attrs) == attrs, (kind, name, attrs, seen[str(name)])
    assert seen["u"] == ("1", "length: " + SCALES["length"])
    assert seen["time"] == ("1", "time: " + SCALES["time"])
    assert seen["phi_dot"][0] == "rad" and "time is sqrt(mass / stiffness)" in seen["phi_dot"][1]
    assert seen["particle"] == ("1", None)
    assert seen["discrete"] == seen["compliance"] and seen["compliance"][0] == "rad", "every phi/M alike"
    assert seen["bending_chain_moment"] == seen["moment"]


def test_a_beam_tables_compliances_follow_its_load(files):
    force = xr.open_dataset(files["theory_force"], engine="h5netcdf")
    for name in ("discrete", "timoshenko", "nodal", "paper"):
        assert force[name].attrs["units"] == "1" and force[name].attrs["scale"].startswith("length^2 / energy, where length is"), name
    assert force.attrs["load"] == "force"


def test_coordinates_have_no_fill_value_and_text_is_characters(files, read):
    with h5py.File(files["study"]) as f:
        for name in ("E2", "model_label"):
            assert "_FillValue" not in f[name].attrs, name
        assert f["error"].dtype.kind == "S" and f["error"].dtype.itemsize == 1, "a character array, not the string type"
    with h5py.File(files["simulate"]) as f:
        assert "_FillValue" not in f[FILE_TIME].attrs and "_FillValue" not in f["particle"].attrs
    stacked = read("report_sweep")
    assert stacked["status"].sel(model="linear").values.tolist() == ["static", "static", ""], "a gap is an empty string"
    assert stacked["direction"].dims == ("model", "step") and "direction" in stacked.data_vars, "no label of two dimensions"
    study = read("study")
    assert study["error"].values.tolist() == [[""], ["a failed cell keeps its message"]]
    assert study["model"].values.tolist() == ["linear"]


def test_long_names_are_true_for_the_file_at_hand(read):
    pinned_free = read("simulate_pinned_free")
    assert pinned_free["particle"].attrs["long_name"] == "particle index k in -N..N (left pinned, right free)"
    assert pinned_free["potential"].attrs["long_name"] == "potential energy P", "no sine caveat on a nonlinear run"
    assert np.isfinite(pinned_free["potential"].values).all()
    sine = read("simulate")
    assert sine["particle"].attrs["long_name"] == "particle index k in -N..N (clamped ends)"
    assert "NaN for the non-conservative sine model" in sine["potential"].attrs["long_name"]
    assert read("state_diagram")["value"].attrs["long_name"].startswith("the varied field E2")
    assert "sine model" in read("critical")["critical_eigenvalue"].attrs["long_name"]
    linear = describe(critical_point(ChainParams(), "linear").to_dataset())
    assert linear["critical_eigenvalue"].attrs["long_name"] == "lowest eigenvalue of the stiffness matrix"


def test_history_names_the_command_without_the_folder_it_lies_in(monkeypatch):
    run = simulate(ChainParams(), "linear", 0.01, t_end=0.2, n_frames=2)
    monkeypatch.setattr(sys, "argv", ["/home/someone/.venv/bin/cosserat-chain", "simulate", "--out", "run one.nc"])
    history = describe(run).attrs["history"]
    assert history.endswith(": cosserat-chain simulate --out 'run one.nc'") and "/home/someone" not in history
    monkeypatch.setattr(sys, "argv", ["/home/someone/src/cosserat_chain/__main__.py", "simulate"])
    assert describe(run).attrs["history"].endswith(": python -m cosserat_chain simulate")
    twice = describe(describe(run))
    assert twice.attrs["history"].count("\n") == 1 and twice["u"].attrs == describe(run)["u"].attrs, "describing again adds a line only"


def test_a_quantity_with_a_factor_that_is_no_base_quantity_is_refused():
    with pytest.raises(ValueError, match=r"quantity 'furlong / time' has the factor\(s\) \['furlong'\]; allowed: rad, 1, length"):
        cf_attributes("furlong / time", "speed")
    assert cf_attributes("rad / energy", "compliance")["units"] == "rad"
    assert cf_attributes("1 / time", "band gap") == {
        "units": "1",
        "long_name": "band gap",
        "scale": "1 / time, where time is " + SCALES["time"],
    }
