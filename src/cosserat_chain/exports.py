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
- :func:`to_xyz`: extended XYZ written by ASE, one block per frame, for OVITO and ASE: the
  cell and its origin around the chain, the time, and per particle a neutral species with
  the particle's mass, the centre, velocities, the orientation as a quaternion, the
  rectangle's half-sizes (``aspherical_shape``), the angular velocity, phi and the index.
- :func:`to_csv`: long format, one row per (time, particle): u, v, phi, their
  velocities and the centre's x, y.

Every file is written atomically (:func:`~cosserat_chain.io.atomic_path`); the frames of a
VTK collection go to their own folder, replaced whole, marked as the package's by the file
:data:`FRAMES_MARKER` that lists them: a folder without it (the user's), or one holding files
it does not list, is refused, never removed.
"""

from __future__ import annotations

import json
import os
import shutil
import stat
import tempfile
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from .geometry import bond_links, corner_positions, particle_positions
from .io import OutputError, atomic_path, new_mode, params_of, run_states, write_text
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


#: The file that marks a frames folder as this package's, listing its frames: only such a
#: folder is ever replaced, and only the files it lists are removed with it.
FRAMES_MARKER = ".cosserat-chain-frames.json"


def frames_folder(path: str | Path) -> Path:
    """The folder of the frames of the ParaView collection ``path`` (``PATH_frames``), checked before any work.

    Raises
    ------
    OutputError
        If something that is not a frames folder of this package is in the way: a file, a
        link, a folder without the marker file :data:`FRAMES_MARKER` (the user's), or one
        holding files its marker does not list (named).
    """
    path = Path(path)
    folder = path.with_name(f"{path.stem}_frames")
    _frames_written(folder)
    return folder


def _frames_written(folder: Path) -> list[str] | None:
    """The frames of the package's frames folder ``folder`` (None if there is no folder); refuses anything else in the way."""
    try:
        info = os.lstat(folder)
    except FileNotFoundError:
        return None
    if not stat.S_ISDIR(info.st_mode):
        raise OutputError(f"{str(folder)!r} exists and is not a folder of frames: refusing to replace it")
    try:
        marker = folder / FRAMES_MARKER
        listed = json.loads(marker.read_text(encoding="utf-8"))["frames"] if stat.S_ISREG(os.lstat(marker).st_mode) else None
        entries = os.listdir(folder)
    except (OSError, ValueError, KeyError, TypeError):
        listed = None
    if not isinstance(listed, list) or not all(isinstance(name, str) for name in listed):
        raise OutputError(
            f"{str(folder)!r} exists and was not written by cosserat-chain (it has no {FRAMES_MARKER}): "
            "refusing to replace it; move it or choose another --out"
        )
    foreign = sorted(
        name for name in entries if name != FRAMES_MARKER and (name not in listed or not stat.S_ISREG(os.lstat(folder / name).st_mode))
    )
    if foreign:
        raise OutputError(
            f"{str(folder)!r} holds files cosserat-chain did not write ({', '.join(foreign[:5])}{', ...' if len(foreign) > 5 else ''}): "
            "refusing to replace it; move them or choose another --out"
        )
    return listed


def to_vtk(dataset: xr.Dataset, path: str | Path, progress: Callable[[int, int], None] | None = None) -> Path:
    """Write the run as a ParaView collection ``path`` (.pvd) of per-frame .vtu grids; returns the path.

    ``progress(frames_written, frames)`` is called after every frame (one file each: the slow format).
    The frames go to the folder :func:`frames_folder`, which replaces an earlier one of this
    package's whole and keeps its mode (a new one gets 0777 less the umask).

    Raises
    ------
    OutputError
        Before any work, if something other than this package's frames folder is in the way.
    """
    import meshio

    path = Path(path)
    folder = frames_folder(path)
    params, times, states, velocities = _frames(dataset)
    staging = Path(tempfile.mkdtemp(prefix=f".{folder.name}.", dir=path.parent))
    try:
        entries, names = [], []
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
            names.append(name)
            entries.append(f'    <DataSet timestep="{float(t)!r}" group="" part="0" file="{folder.name}/{name}"/>')
            if progress is not None:
                progress(f + 1, len(times))
        (staging / FRAMES_MARKER).write_text(json.dumps({"written_by": "cosserat-chain", "frames": names}), encoding="utf-8")
        _swap_frames(staging, folder)
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


def _swap_frames(staging: Path, folder: Path) -> None:
    """Put the new frames folder ``staging`` in the place of ``folder``; the old one (checked again: ours) loses only its frames.

    The frames replace the folder whole, then the index is written: a reader of the
    index never finds frames of another run.
    """
    previous = _frames_written(folder)
    if previous is None:
        os.chmod(staging, new_mode(folder=True))
        staging.rename(folder)
        return
    info = os.stat(folder)
    os.chmod(staging, stat.S_IMODE(info.st_mode))
    if (info.st_uid, info.st_gid) != (os.geteuid(), os.getegid()):
        try:
            os.chown(staging, info.st_uid, info.st_gid)
        except PermissionError:
            pass
    old = Path(tempfile.mkdtemp(prefix=f".{folder.name}.old.", dir=folder.parent))
    folder.rename(old)  # onto the empty folder just made: the name is ours and unpredictable
    staging.rename(folder)
    for name in [*previous, FRAMES_MARKER]:
        try:
            (old / name).unlink()
        except FileNotFoundError:
            pass
    old.rmdir()


#: Half-thickness of a particle in the XYZ export, in units of its smaller half-size: the
#: chain is planar, and OVITO draws a box or an ellipsoid, so the rectangle gets a thin third axis.
XYZ_THICKNESS = 0.1


def xyz_frames(dataset: xr.Dataset) -> Iterator[Any]:
    """The run's frames as ASE ``Atoms`` for extended XYZ, one per stored time (see :func:`to_xyz`).

    Raises
    ------
    ValueError
        If the dataset is not a run with velocities (``simulate --out``).
    """
    import ase

    params, times, states, velocities = _frames(dataset)
    n = params.n_particles
    # One cell for every frame, a margin of h/2 around every corner the run reaches.
    corners = (corner_positions(params, x).reshape(-1, 2) for x in states)
    bounds = np.array([(c.min(axis=0), c.max(axis=0)) for c in corners])  # (frames, low/high, x/y)
    half_thickness = XYZ_THICKNESS * min(params.a, params.b)
    low = np.append(bounds[:, 0].min(axis=0) - params.h / 2, -2.0 * half_thickness)
    size = np.append(bounds[:, 1].max(axis=0) + params.h / 2, 2.0 * half_thickness) - low
    shape = np.tile([params.a, params.b, half_thickness], (n, 1))
    masses = params.particle_inertia[0]
    for t, x, v in zip(times, states, velocities):
        atoms = ase.Atoms(symbols=["X"] * n, positions=np.column_stack([centres(params, x), np.zeros(n)]), cell=np.diag(size), pbc=False)
        # The mass twice: ASE reads "masses" (get_masses), OVITO "mass" (its Mass property).
        atoms.set_masses(masses)
        atoms.new_array("mass", masses.copy())
        atoms.new_array("velo", np.column_stack([v[0], v[1], np.zeros(n)]))
        # The rotation by phi about z as a unit quaternion in OVITO's order (x, y, z, w).
        atoms.new_array("orientation", np.column_stack([np.zeros(n), np.zeros(n), np.sin(x[2] / 2), np.cos(x[2] / 2)]))
        atoms.new_array("aspherical_shape", shape)
        atoms.new_array("omega", np.column_stack([np.zeros(n), np.zeros(n), v[2]]))
        atoms.new_array("phi", x[2].copy())
        atoms.new_array("particle", np.arange(-params.N, params.N + 1))
        atoms.info.update({"Time": float(t), "Origin": low})
        yield atoms


def to_xyz(dataset: xr.Dataset, path: str | Path) -> Path:
    """Write the run as extended XYZ through ASE's writer, one block per frame; returns the path.

    Each block's comment line holds the cell (``Lattice``, with its ``Origin`` so that it
    encloses the chain in every frame), ``Time`` and the columns: the species ``X`` (ASE's
    dummy element: no chemical element, so no element's mass) with the particle's mass
    (``masses``, which ASE reads, and ``mass``, which OVITO reads), the centre ``pos``
    (x, y, 0), the velocity ``velo`` (du/dt, dv/dt, 0), the rotation as a unit quaternion
    ``orientation`` (0, 0, sin(phi/2), cos(phi/2)), the half-sizes ``aspherical_shape`` (a,
    b and a thin :data:`XYZ_THICKNESS` of the smaller), the angular velocity ``omega`` (0,
    0, dphi/dt), ``phi`` and the index ``particle``: the names OVITO maps to its Mass,
    Velocity, Orientation, Aspherical Shape and Angular Velocity. ASE writes the numbers
    with 8 decimals: the file is for drawing, NetCDF and CSV keep every bit.
    """
    from ase.io.extxyz import write_extxyz

    frames = xyz_frames(dataset)
    with atomic_path(path) as tmp, tmp.open("w", encoding="utf-8") as out:
        write_extxyz(out, frames)
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
