"""Exports of a run (issue 16): what ParaView, OVITO and a CSV reader get back equals the run."""

from __future__ import annotations

import xml.etree.ElementTree as ElementTree

import ase.io
import meshio
import numpy as np
import pytest
from typer.testing import CliRunner

from cosserat_chain import ChainParams
from cosserat_chain.cli import app
from cosserat_chain.experiments.simulation import simulate
from cosserat_chain.exports import export
from cosserat_chain.geometry import bond_links, corner_positions, particle_positions
from cosserat_chain.io import read_dataset, write_dataset
from cosserat_chain.state import ROWS

runner = CliRunner()


@pytest.fixture(scope="module")
def run(tmp_path_factory):
    """A sine-model run of an unusual chain (N = 4, h = 1.3), moving and rotating, 6 frames."""
    params = ChainParams(N=4, h=1.3, a=0.3, b=0.25, E2=0.7)
    ds = simulate(params, "sine", 0.4, t_end=30.0, n_frames=6)
    path = write_dataset(ds, tmp_path_factory.mktemp("run") / "run.nc")
    return params, read_dataset(path), path


def _states(ds):
    return np.stack([ds[row].values for row in ROWS], axis=1)


def test_vtk_collection_reads_back_with_meshio_as_the_runs_corners_and_links(run, tmp_path):
    params, ds, _ = run
    calls = []
    pvd = export(ds, "vtk", tmp_path / "run.pvd", progress=lambda done, total: calls.append((done, total)))
    assert calls == [(k, ds.sizes["time"]) for k in range(1, ds.sizes["time"] + 1)], "progress counts every frame up to the last"
    entries = ElementTree.parse(pvd).getroot().findall("./Collection/DataSet")
    assert [float(e.get("timestep")) for e in entries] == list(ds.time.values)
    states = _states(ds)
    links = bond_links(params)
    for entry, x in zip(entries, states):
        mesh = meshio.read(tmp_path / entry.get("file"))
        np.testing.assert_allclose(mesh.points[:, :2], corner_positions(params, x).reshape(-1, 2), rtol=0, atol=1e-12)
        quads, lines = mesh.cells_dict["quad"], mesh.cells_dict["line"]
        assert quads.shape == (params.n_particles, 4) and lines.shape == (4 * 2 * params.N, 2)
        np.testing.assert_array_equal(mesh.cell_data_dict["phi"]["quad"], x[2])
        # Each line joins a right corner of particle k to a left corner of k+1, at the length the geometry gives.
        length = np.linalg.norm(mesh.points[lines[:, 1], :2] - mesh.points[lines[:, 0], :2], axis=1)
        rest = np.tile([link.rest_length for link in links], 2 * params.N)
        np.testing.assert_allclose(mesh.cell_data_dict["link_stretch"]["line"], length - rest, atol=1e-12)
        assert np.all(lines[:, 1] // 4 == lines[:, 0] // 4 + 1)
    assert np.abs(states[-1, 2]).max() > 0.1, "the run rotates"


def test_extended_xyz_reads_back_with_ase_as_the_centres_and_angles(run, tmp_path):
    params, ds, _ = run
    frames = ase.io.read(export(ds, "xyz", tmp_path / "run.xyz"), index=":")
    assert len(frames) == ds.sizes["time"]
    for atoms, t, x in zip(frames, ds.time.values, _states(ds)):
        assert atoms.info["Time"] == t
        # ASE's writer keeps 8 decimals (the file is for drawing).
        np.testing.assert_allclose(atoms.positions[:, 0], particle_positions(params) + x[0], rtol=0, atol=5e-9)
        np.testing.assert_allclose(atoms.positions[:, 1], x[1], rtol=0, atol=5e-9)
        np.testing.assert_allclose(atoms.arrays["phi"], x[2], rtol=0, atol=5e-9)
        np.testing.assert_array_equal(atoms.arrays["particle"], np.arange(-params.N, params.N + 1))


def test_csv_is_long_format_and_exact(run, tmp_path):
    params, ds, _ = run
    path = export(ds, "csv", tmp_path / "run.csv")
    header = path.read_text().splitlines()[0].split(",")
    assert header == ["time", "particle", "u", "v", "phi", "u_dot", "v_dot", "phi_dot", "x", "y"]
    table = np.loadtxt(path, delimiter=",", skiprows=1)
    assert table.shape == (ds.sizes["time"] * params.n_particles, 10)
    for column, name in enumerate(header[2:8], start=2):
        np.testing.assert_array_equal(table[:, column], ds[name].transpose("time", "particle").values.ravel())
    np.testing.assert_array_equal(table[:, 0], np.repeat(ds.time.values, params.n_particles))


def test_export_command_refuses_other_files_and_wrong_suffixes(run, tmp_path):
    _, _, path = run
    result = runner.invoke(app, ["export", str(path), "--to", "vtk", "--out", str(tmp_path / "run.vtu")])
    assert result.exit_code == 2 and "'.vtu'" in result.output and ".pvd" in result.output
    critical = tmp_path / "critical.nc"
    assert runner.invoke(app, ["critical", "--model", "linear", "--out", str(critical)]).exit_code == 0
    result = runner.invoke(app, ["export", str(critical), "--to", "csv", "--out", str(tmp_path / "c.csv")])
    assert result.exit_code == 2 and "cosserat-chain critical" in result.output
    result = runner.invoke(app, ["export", str(path), "--to", "csv", "--out", str(tmp_path / "ok.csv")])
    assert result.exit_code == 0 and (tmp_path / "ok.csv").stat().st_size > 0
