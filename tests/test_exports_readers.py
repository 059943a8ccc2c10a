"""The exports as their readers load them: ASE and OVITO (extended XYZ), meshio (the VTK time series).

A graded chain (its particles of different masses) turns and moves; each reader must give
back the run: positions, the angle from the orientation quaternion, velocities, the time of
every frame, the particles' own masses, and a cell that encloses the chain.
"""

from __future__ import annotations

import xml.etree.ElementTree as ElementTree

import ase.io
import meshio
import numpy as np
import pytest

from cosserat_chain import ChainParams
from cosserat_chain.experiments.simulation import simulate
from cosserat_chain.exports import XYZ_THICKNESS, export
from cosserat_chain.geometry import corner_positions, particle_positions
from cosserat_chain.io import read_dataset, write_dataset
from cosserat_chain.state import ROWS

#: ASE writes extended XYZ with 8 decimals.
XYZ_DECIMALS = 5e-9


@pytest.fixture(scope="module")
def run(tmp_path_factory):
    """A sine-model run of a graded chain (N = 3, h = 1.3, masses 0.5..2), turning, 5 frames."""
    params = ChainParams(N=3, h=1.3, a=0.3, b=0.25, m_factors=(0.5, 1.0, 2.0, 1.5, 1.0, 0.8, 1.2))
    ds = simulate(params, "sine", 0.4, t_end=30.0, n_frames=5)
    return params, read_dataset(write_dataset(ds, tmp_path_factory.mktemp("run") / "run.nc"))


def _frames(ds):
    """States and velocities (F, 3, n) of a run."""
    return np.stack([ds[row].values for row in ROWS], axis=1), np.stack([ds[f"{row}_dot"].values for row in ROWS], axis=1)


def _wrapped(phi):
    """phi in (-pi, pi]: angles that differ by whole turns are the same rotation."""
    return np.angle(np.exp(1j * phi))


def test_extended_xyz_loads_in_ase_with_positions_orientation_time_and_masses(run, tmp_path):
    params, ds = run
    frames = ase.io.read(export(ds, "xyz", tmp_path / "run.xyz"), index=":")
    states, velocities = _frames(ds)
    assert len(frames) == ds.sizes["time"]
    for atoms, t, x, v in zip(frames, ds.time.values, states, velocities):
        assert atoms.info["Time"] == t
        assert set(atoms.get_chemical_symbols()) == {"X"}, "a dummy species: no chemical element's mass"
        np.testing.assert_array_equal(atoms.get_masses(), params.particle_inertia[0])
        np.testing.assert_array_equal(atoms.arrays["mass"], params.particle_inertia[0])
        np.testing.assert_allclose(atoms.positions, np.column_stack([particle_positions(params) + x[0], x[1], 0 * x[1]]), atol=XYZ_DECIMALS)
        q = atoms.arrays["orientation"]
        np.testing.assert_allclose(np.linalg.norm(q, axis=1), 1.0, atol=4 * XYZ_DECIMALS)
        np.testing.assert_allclose(q[:, :2], 0.0)
        np.testing.assert_allclose(_wrapped(2 * np.arctan2(q[:, 2], q[:, 3]) - x[2]), 0.0, atol=4 * XYZ_DECIMALS)
        np.testing.assert_allclose(atoms.arrays["velo"], np.column_stack([v[0], v[1], 0 * v[0]]), atol=XYZ_DECIMALS)
        np.testing.assert_allclose(atoms.arrays["omega"][:, 2], v[2], atol=XYZ_DECIMALS)
        np.testing.assert_allclose(atoms.arrays["aspherical_shape"], [[params.a, params.b, XYZ_THICKNESS * params.b]] * params.n_particles)
        np.testing.assert_array_equal(atoms.arrays["particle"], np.arange(-params.N, params.N + 1))
        # The cell, from its origin, encloses every corner of every particle.
        corners = corner_positions(params, x).reshape(-1, 2)
        origin, size = atoms.info["Origin"], np.diag(atoms.cell)
        assert np.all(corners > origin[:2]) and np.all(corners < origin[:2] + size[:2])
        assert origin[2] < 0 < origin[2] + size[2] and not atoms.pbc.any()
    assert np.ptp(states[:, 2, params.N]) > 0.5, "the loaded particle turns"


def test_extended_xyz_loads_in_ovito_as_boxes_with_mass_velocity_and_orientation(run, tmp_path):
    io = pytest.importorskip("ovito.io", reason="OVITO's Python module is not installed (pip install ovito)")
    params, ds = run
    pipeline = io.import_file(str(export(ds, "xyz", tmp_path / "run.xyz")), multiple_frames=True)
    states, velocities = _frames(ds)
    assert pipeline.num_frames == ds.sizes["time"]
    for frame, (t, x, v) in enumerate(zip(ds.time.values, states, velocities)):
        data = pipeline.compute(frame)
        assert data.attributes["Time"] == t
        particles = data.particles
        np.testing.assert_allclose(particles.positions[:, 0], particle_positions(params) + x[0], atol=XYZ_DECIMALS)
        np.testing.assert_array_equal(particles["Mass"][...], params.particle_inertia[0])
        np.testing.assert_allclose(particles.velocities[:, :2], v[:2].T, atol=XYZ_DECIMALS)
        np.testing.assert_allclose(particles["Angular Velocity"][:, 2], v[2], atol=XYZ_DECIMALS)
        orientation = particles["Orientation"][...]  # OVITO's order x, y, z, w, kept in single precision
        np.testing.assert_allclose(
            _wrapped(2 * np.arctan2(orientation[:, 2], orientation[:, 3]) - x[2]), 0.0, atol=4 * np.finfo(np.float32).eps
        )
        np.testing.assert_allclose(particles["Aspherical Shape"][:, :2], [[params.a, params.b]] * params.n_particles)
        cell = np.asarray(data.cell[...])
        corners = corner_positions(params, x).reshape(-1, 2)
        assert np.all(corners > cell[:2, 3]) and np.all(corners < cell[:2, 3] + np.diag(cell)[:2]), "the cell is around the chain"


def test_vtk_time_series_reads_with_meshio_frame_by_frame(run, tmp_path):
    params, ds = run
    pvd = export(ds, "vtk", tmp_path / "run.pvd")
    entries = ElementTree.parse(pvd).getroot().findall("./Collection/DataSet")
    states, velocities = _frames(ds)
    times = [float(entry.get("timestep")) for entry in entries]
    assert times == list(ds.time.values) and times == sorted(times)
    for entry, x, v in zip(entries, states, velocities):
        mesh = meshio.read(pvd.parent / entry.get("file"))
        quad = {name: values["quad"] for name, values in mesh.cell_data_dict.items()}
        np.testing.assert_array_equal(quad["particle"], np.arange(-params.N, params.N + 1))
        for i, row in enumerate(ROWS):
            np.testing.assert_array_equal(quad[row], x[i])
            np.testing.assert_array_equal(quad[f"{row}_dot"], v[i])
        np.testing.assert_allclose(mesh.points[:, :2].reshape(-1, 4, 2).mean(axis=1)[:, 0], particle_positions(params) + x[0], atol=1e-12)
