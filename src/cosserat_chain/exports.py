"""A run in the formats other tools read: VTK for ParaView, extended XYZ for OVITO, CSV for anything.

Contract
--------
Each function takes a run written by ``simulate --out`` (read with
:func:`~cosserat_chain.io.read_dataset`) and writes it, frame by frame, in world
coordinates (particle k's centre at (k h + u_k, v_k)):

- :func:`to_vtk`: a ParaView collection ``PATH.pvd`` listing one VTK XML unstructured
  grid per frame (``PATH_frames/frame_00000.vtu`` ...) with its time. Each grid holds the
  particles as quadrilaterals (their four corners, rotated by phi) and the links as
  lines (two horizontal, two diagonal per bond), with the particle index, u, v, phi
  and their velocities as cell data of the quadrilaterals and the link's kind and
  stretch L - L0 as cell data of the lines. The grids are written by meshio; the
  collection is the small XML index ParaView reads.
- :func:`to_xyz`: extended XYZ, one block per frame: the particle count, a comment line
  with ``Time=`` and the ``Properties`` of the columns, then one line per particle
  (``species`` P, ``pos`` x y 0, ``phi``, ``particle``).
- :func:`to_csv`: long format, one row per (time, particle): u, v, phi, their
  velocities and the centre's x, y.

Every file is written atomically (:func:`~cosserat_chain.io.atomic_path`); the frames of a
VTK collection go to their own folder, replaced whole.
"""

from __future__ import annotations

import shutil
import tempfile
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from .geometry import bond_links, corner_positions, particle_positions
from .io import atomic_path, params_of, run_states, write_text
from .params import ChainParams
from .state import ROWS

if TYPE_CHECKING:
    import xarray as xr

#: Formats of :func:`export` and the suffix of the file each writes.
FORMATS = {"vtk": ".pvd", "xyz": ".xyz", "csv": ".csv"}


def _frames(dataset: xr.Dataset) -> tuple[ChainParams, np.ndarray, np.ndarray, np.ndarray]:
    """Parameters, times (F,), states (F, 3, n) and velocities (F, 3, n) of a run."""
    params = params_of(dataset)
    times, states = run_states(params, dataset)
    velocities = np.stack([dataset.sortby("particle")[f"{row}_dot"].transpose("time", "particle").values for row in ROWS], axis=1)
    return params, times, states, velocities


def centres(params: ChainParams, x: np.ndarray) -> np.ndarray:
    """World positions (2N+1, 2) of the particle centres of state ``x`` (3, 2N+1)."""
    return np.column_stack([particle_positions(params) + x[0], x[1]])


def link_segments(params: ChainParams, x: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Every link of state ``x`` as a segment between two corner indices of :func:`corner_positions`, flattened.

    Returns
    -------
    segments : ndarray of int (4 * 2N, 2)
        Indices into the (2N+1) * 4 corners, bond by bond, links in :func:`~cosserat_chain.geometry.bond_links` order.
    kind : ndarray of int (4 * 2N,)
        0 top, 1 bottom, 2 and 3 the diagonals.
    stretch : ndarray (4 * 2N,)
        L - L0 of each link.
    """
    corners = corner_positions(params, x)
    order = {(params.a, params.b): 0, (-params.a, params.b): 1, (-params.a, -params.b): 2, (params.a, -params.b): 3}
    links = bond_links(params)
    n = params.n_particles
    segments = np.empty((4 * (n - 1), 2), dtype=np.int64)
    kind = np.tile(np.arange(4), n - 1)
    stretch = np.empty(4 * (n - 1))
    for i, link in enumerate(links):
        left = 4 * np.arange(n - 1) + order[link.left_corner]
        right = 4 * np.arange(1, n) + order[link.right_corner]
        segments[i::4, 0], segments[i::4, 1] = left, right
        length = np.linalg.norm(corners.reshape(-1, 2)[right] - corners.reshape(-1, 2)[left], axis=1)
        stretch[i::4] = length - link.rest_length
    return segments, kind, stretch


def to_vtk(dataset: xr.Dataset, path: str | Path, progress: Callable[[int, int], None] | None = None) -> Path:
    """Write the run as a ParaView collection ``path`` (.pvd) of per-frame .vtu grids; returns the path.

    ``progress(frames_written, frames)`` is called after every frame (one file each: the slow format).
    """
    import meshio

    params, times, states, velocities = _frames(dataset)
    path = Path(path)
    folder = path.with_name(f"{path.stem}_frames")
    staging = Path(tempfile.mkdtemp(prefix=f".{folder.name}.", dir=path.parent))
    try:
        entries = []
        for f, (t, x, v) in enumerate(zip(times, states, velocities)):
            corners = corner_positions(params, x).reshape(-1, 2)
            points = np.column_stack([corners, np.zeros(len(corners))])
            quads = np.arange(len(corners)).reshape(-1, 4)
            segments, kind, stretch = link_segments(params, x)
            particle = np.arange(-params.N, params.N + 1)
            quad_data = {"particle": particle.astype(float), **{row: x[i] for i, row in enumerate(ROWS)}}
            quad_data.update({f"{row}_dot": v[i] for i, row in enumerate(ROWS)})
            cell_data = {name: [values, np.full(len(segments), np.nan)] for name, values in quad_data.items()}
            cell_data["link_kind"] = [np.full(len(quads), -1.0), kind.astype(float)]
            cell_data["link_stretch"] = [np.full(len(quads), np.nan), stretch]
            name = f"frame_{f:05d}.vtu"
            meshio.write(staging / name, meshio.Mesh(points, [("quad", quads), ("line", segments)], cell_data=cell_data))
            entries.append(f'    <DataSet timestep="{float(t)!r}" group="" part="0" file="{folder.name}/{name}"/>')
            if progress is not None:
                progress(f + 1, len(times))
        # The frames replace the folder whole, then the index is written: a reader of the
        # index never finds frames of another run.
        if folder.is_symlink() or folder.is_file():
            raise ValueError(f"{str(folder)!r} exists and is not a folder of frames: refusing to replace it")
        if folder.exists():
            shutil.rmtree(folder)
        staging.rename(folder)
    finally:
        if staging.exists():
            shutil.rmtree(staging)
    index = (
        '<?xml version="1.0"?>\n<VTKFile type="Collection" version="0.1">\n  <Collection>\n'
        + "\n".join(entries)
        + "\n  </Collection>\n</VTKFile>\n"
    )
    write_text(index, path)
    return path


def to_xyz(dataset: xr.Dataset, path: str | Path) -> Path:
    """Write the run as extended XYZ (one block per frame, particle centres and angles); returns the path."""
    params, times, states, _ = _frames(dataset)
    particle = np.arange(-params.N, params.N + 1)
    lattice = f'Lattice="{params.h * (params.n_particles + 1)!r} 0 0 0 {4 * params.b + params.h!r} 0 0 0 1" pbc="F F F"'
    with atomic_path(path) as tmp, tmp.open("w", encoding="utf-8") as out:
        for t, x in zip(times, states):
            out.write(f"{params.n_particles}\n{lattice} Time={float(t)!r} Properties=species:S:1:pos:R:3:phi:R:1:particle:I:1\n")
            for (cx, cy), phi, k in zip(centres(params, x), x[2], particle):
                out.write(f"P {float(cx)!r} {float(cy)!r} 0.0 {float(phi)!r} {int(k)}\n")
    return Path(path)


def to_csv(dataset: xr.Dataset, path: str | Path) -> Path:
    """Write the run in long format, one row per (time, particle); returns the path."""
    params, times, states, velocities = _frames(dataset)
    n = params.n_particles
    columns = {
        "time": np.repeat(times, n),
        "particle": np.tile(np.arange(-params.N, params.N + 1), len(times)),
        **{row: states[:, i].ravel() for i, row in enumerate(ROWS)},
        **{f"{row}_dot": velocities[:, i].ravel() for i, row in enumerate(ROWS)},
        "x": (particle_positions(params)[None, :] + states[:, 0]).ravel(),
        "y": states[:, 1].ravel(),
    }
    with atomic_path(path) as tmp:
        # 17 significant digits: every double reads back exactly.
        np.savetxt(
            tmp,
            np.column_stack(list(columns.values())),
            delimiter=",",
            header=",".join(columns),
            comments="",
            fmt=["%.17g", "%d", *["%.17g"] * 8],
        )
    return Path(path)


def export(dataset: xr.Dataset, to: str, path: str | Path, progress: Callable[[int, int], None] | None = None) -> Path:
    """Write the run in format ``to`` (one of :data:`FORMATS`) to ``path``; ``progress`` follows the VTK frames.

    Raises
    ------
    ValueError
        For an unknown format, or a dataset that is not a run of ``simulate`` (no u, v, phi over time).
    """
    writers = {"vtk": to_vtk, "xyz": to_xyz, "csv": to_csv}
    if to not in writers:
        raise ValueError(f"unknown export format {to!r}; allowed: {', '.join(writers)}")
    return to_vtk(dataset, path, progress) if to == "vtk" else writers[to](dataset, path)
