"""Pictures of the chain, drawn the way the paper's Figs. 1 and 3 show it.

Contract
--------
:func:`draw_chain` draws one state: every particle as its 2a x 2b rectangle at its
position and angle, the four links of every bond (horizontal links solid, diagonal
links dashed), the centres joined by a line, a tick from every centre along the
particle's body x-axis (its rotation), clamped ends hatched, pinned ends with a hinge, and the loaded
particle filled in colour. :func:`snapshot_figure` stacks one such panel per
requested time (Fig. 3a/3b) with limits shared by all panels, and :func:`animate`
writes a GIF (or an MP4 when an encoder is installed) of a time window of a run,
subsampled to at most ``max_frames`` frames, with fixed limits and the time in the
title.

States are arrays ``x`` of shape (3, 2N+1) (rows u, v, phi; see :mod:`..state`);
runs are the Datasets of :func:`cosserat_chain.experiments.simulation.simulate`
(or files read by :func:`cosserat_chain.io.read_dataset`). Angles may be unwrapped
(a particle that has turned 1500 times): the drawing depends on phi modulo 2 pi
only, and the angle is reduced before the corners are computed.

Artists carry a ``gid`` so that they can be found again: ``particles``,
``clamped``, ``pinned``, ``links_horizontal``, ``links_diagonal``, ``centre_line``,
``orientation``. Nothing here solves anything.
"""

from __future__ import annotations

import importlib.util
import json
import math
from collections.abc import Callable, Iterable, Sequence
from pathlib import Path
from typing import TYPE_CHECKING

import imageio.v2 as iio2
import numpy as np
from matplotlib.axes import Axes
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.collections import LineCollection, PolyCollection
from matplotlib.figure import Figure
from matplotlib.patches import Patch
from PIL import Image

from ..geometry import bond_links, corner_positions, particle_positions
from ..io import FIGURE_FORMATS, atomic_path, params_of, run_states, write_figure
from ..params import ChainParams

if TYPE_CHECKING:  # xarray is imported where a Dataset is built or read: commands without file output start without it
    import xarray as xr

#: Output formats of :func:`animate`, by file extension.
ANIMATION_FORMATS = (".gif", ".mp4")

#: Corner order of :func:`cosserat_chain.geometry.corner_positions`, as signs of (a, b).
_CORNER_SIGNS = ((1, 1), (-1, 1), (-1, -1), (1, -1))

_PARTICLE_COLOUR = "#d9d9d9"
_CLAMPED_COLOUR = "#8c8c8c"
_LOADED_COLOUR = "#d62728"
_HORIZONTAL_COLOUR = "#1f77b4"
_DIAGONAL_COLOUR = "#ff7f0e"


# ---------------------------------------------------------------- geometry of a picture
def _corner_index(corner: tuple[float, float]) -> int:
    signs = (int(math.copysign(1, corner[0])), int(math.copysign(1, corner[1])))
    return _CORNER_SIGNS.index(signs)


def wrapped(x: np.ndarray) -> np.ndarray:
    """Copy of the state(s) ``x`` (..., 3, 2N+1) with phi reduced to [-pi, pi).

    Corners depend on phi through cos and sin only; reducing first keeps the
    picture exact for unwrapped angles of thousands of turns.
    """
    out = np.array(x, dtype=float, copy=True)
    out[..., 2, :] = np.mod(out[..., 2, :] + np.pi, 2.0 * np.pi) - np.pi
    return out


def link_segments(params: ChainParams, x: np.ndarray) -> dict[str, np.ndarray]:
    """End points of the links of every bond in the state ``x``.

    Parameters
    ----------
    params : ChainParams
    x : ndarray, shape (3, 2N+1)
        Rows u, v, phi.

    Returns
    -------
    dict
        ``horizontal``: shape (2N, 2, 2, 2), for bond k (particles k and k+1 in
        array order) the top then the bottom link, each as ((X, Y) on the left
        particle, (X, Y) on the right one); ``diagonal``: the same for diagonal 1
        and diagonal 2 (:func:`cosserat_chain.geometry.bond_links`).
    """
    corners = corner_positions(params, wrapped(x))
    out: dict[str, list[np.ndarray]] = {"horizontal": [], "diagonal": []}
    for link in bond_links(params):
        left = corners[:-1, _corner_index(link.left_corner)]
        right = corners[1:, _corner_index(link.right_corner)]
        out["diagonal" if link.name.startswith("diagonal") else "horizontal"].append(np.stack([left, right], axis=1))
    return {kind: np.stack(segments, axis=1) for kind, segments in out.items()}


def _centres(params: ChainParams, x: np.ndarray) -> np.ndarray:
    return np.column_stack([particle_positions(params) + x[0], x[1]])


def _orientation_ticks(params: ChainParams, x: np.ndarray) -> np.ndarray:
    """Segments from every centre to the midpoint of its right edge, (2N+1, 2, 2)."""
    centres = _centres(params, x)
    tips = centres + params.a * np.column_stack([np.cos(x[2]), np.sin(x[2])])
    return np.stack([centres, tips], axis=1)


def chain_limits(params: ChainParams, states: np.ndarray) -> tuple[tuple[float, float], tuple[float, float]]:
    """Axis limits that contain the chain in every state of ``states``.

    Parameters
    ----------
    states : ndarray, shape (3, 2N+1) or (n, 3, 2N+1)

    Returns
    -------
    (xlim, ylim)
        The centres' range widened by the half-diagonal of a particle (the reach of
        a corner at any angle) and a margin of 0.15 h.
    """
    states = np.asarray(states, dtype=float).reshape(-1, 3, params.n_particles)
    reach = math.hypot(params.a, params.b) + 0.15 * params.h
    centre_x = particle_positions(params)[None, :] + states[:, 0, :]
    centre_y = states[:, 1, :]
    return (
        (float(centre_x.min()) - reach, float(centre_x.max()) + reach),
        (float(centre_y.min()) - reach, float(centre_y.max()) + reach),
    )


# ---------------------------------------------------------------- artists
class _ChainArtists:
    """The artists of one drawn chain; :meth:`update` moves them to another state."""

    def __init__(self, ax: Axes, params: ChainParams, x: np.ndarray, loaded: Sequence[int]) -> None:
        self.params = params
        n = params.n_particles
        columns = {"left": 0, "right": n - 1}
        clamped = [columns[side] for side, end in zip(columns, params.ends) if end == "clamped"]
        self._pinned_columns = [columns[side] for side, end in zip(columns, params.ends) if end == "pinned"]
        faces = [_PARTICLE_COLOUR] * n
        for k in clamped:
            faces[k] = _CLAMPED_COLOUR
        for particle in loaded:
            faces[particle + params.N] = _LOADED_COLOUR
        self.links_horizontal = LineCollection(
            [], colors=_HORIZONTAL_COLOUR, linewidths=1.4, zorder=1, gid="links_horizontal", label="horizontal links (E1)"
        )
        self.links_diagonal = LineCollection(
            [], colors=_DIAGONAL_COLOUR, linewidths=0.9, linestyles="--", zorder=1, gid="links_diagonal", label="diagonal links (E2)"
        )
        self.particles = PolyCollection([], facecolors=faces, edgecolors="black", linewidths=0.8, zorder=2, gid="particles")
        # The clamped particles get a hatched overlay of their own: a hatch applies to a whole collection.
        self.clamped = PolyCollection(
            [],
            facecolors="none",
            edgecolors="black",
            hatch="////",
            linewidths=0.8,
            zorder=2.5,
            gid="clamped",
            label="clamped" if clamped else "_nolegend_",
        )
        self.orientation = LineCollection([], colors="black", linewidths=1.0, zorder=3.5, gid="orientation")
        # A pinned end: a hinge at its centre (u = v = 0, the particle turns about it).
        (self.pinned,) = ax.plot(
            [], [], linestyle="none", marker="o", markersize=7, markerfacecolor="white", markeredgecolor="black", zorder=4,
            gid="pinned", label="pinned" if self._pinned_columns else "_nolegend_",
        )  # fmt: skip
        for artist in (self.links_horizontal, self.links_diagonal, self.particles, self.clamped, self.orientation):
            ax.add_collection(artist, autolim=False)
        (self.centre_line,) = ax.plot([], [], color="black", linewidth=0.8, marker="o", markersize=2.5, zorder=3, gid="centre_line")
        self._clamped_columns = clamped
        self.update(x)

    @property
    def moving(self) -> tuple:
        """The artists that change from one state to the next."""
        return (self.links_horizontal, self.links_diagonal, self.particles, self.clamped, self.orientation, self.centre_line, self.pinned)

    def update(self, x: np.ndarray) -> None:
        x = wrapped(np.asarray(x, dtype=float))
        corners = corner_positions(self.params, x)
        self.particles.set_verts(list(corners))
        self.clamped.set_verts([corners[k] for k in self._clamped_columns])
        links = link_segments(self.params, x)
        self.links_horizontal.set_segments(list(links["horizontal"].reshape(-1, 2, 2)))
        self.links_diagonal.set_segments(list(links["diagonal"].reshape(-1, 2, 2)))
        self.orientation.set_segments(list(_orientation_ticks(self.params, x)))
        centres = _centres(self.params, x)
        self.centre_line.set_data(centres[:, 0], centres[:, 1])
        self.pinned.set_data(centres[self._pinned_columns, 0], centres[self._pinned_columns, 1])


def _loaded_particles(params: ChainParams, loaded: int | Iterable[int] | None) -> tuple[int, ...]:
    if loaded is None:
        return ()
    particles = (loaded,) if isinstance(loaded, (int, np.integer)) else tuple(loaded)
    for particle in particles:
        if not -params.N <= particle <= params.N:
            raise ValueError(f"loaded particle must be in -N..N = {-params.N}..{params.N}, got {particle!r}")
    return tuple(int(p) for p in particles)


def _check_state(params: ChainParams, x: np.ndarray) -> np.ndarray:
    x = np.asarray(x, dtype=float)
    if x.shape != (3, params.n_particles):
        raise ValueError(f"state x must have shape (3, 2N+1) = (3, {params.n_particles}), got {x.shape}")
    return x


def _style_axes(ax: Axes, limits: tuple[tuple[float, float], tuple[float, float]]) -> None:
    ax.set_aspect("equal")
    ax.set_xlim(*limits[0])
    ax.set_ylim(*limits[1])
    ax.set_xlabel("X")
    ax.set_ylabel("Y")


def _legend(ax: Axes, loaded: bool) -> None:
    handles, _ = ax.get_legend_handles_labels()
    if loaded:
        handles.append(Patch(facecolor=_LOADED_COLOUR, edgecolor="black", label="loaded (moment M)"))
    ax.legend(handles=handles, loc="upper center", bbox_to_anchor=(0.5, -0.3), ncol=len(handles), frameon=False, fontsize="small")


def _chain_figure(limits: tuple[tuple[float, float], tuple[float, float]], rows: int, width: float = 8.0) -> Figure:
    """A figure whose panels fit the chain's aspect ratio; ``Figure`` keeps pyplot's global state out."""
    (x0, x1), (y0, y1) = limits
    panel = min(max(width * 0.85 * (y1 - y0) / (x1 - x0), 0.6), 6.0)
    figure = Figure(figsize=(width, rows * (panel + 0.5) + 0.7), layout="constrained")
    FigureCanvasAgg(figure)
    return figure


def draw_chain(
    params: ChainParams,
    x: np.ndarray,
    ax: Axes | None = None,
    *,
    loaded: int | Iterable[int] | None = None,
    time: float | None = None,
    limits: tuple[tuple[float, float], tuple[float, float]] | None = None,
    legend: bool = True,
) -> Figure:
    """Draw the chain in the state ``x`` (paper, Figs. 1 and 3).

    Parameters
    ----------
    params : ChainParams
    x : ndarray, shape (3, 2N+1)
        Rows u, v, phi (phi may be unwrapped); column k+N is particle k.
    ax : matplotlib Axes, optional
        Where to draw; a new figure when None.
    loaded : int or iterable of int, optional
        Particle(s), in -N..N, filled in colour as loaded.
    time : float, optional
        Shown in the title as ``t = ...``.
    limits : ((xmin, xmax), (ymin, ymax)), optional
        Axis limits; default :func:`chain_limits` of ``x``.
    legend : bool
        Legend of the link styles and the clamped ends below the axes.

    Returns
    -------
    matplotlib.figure.Figure

    Raises
    ------
    ValueError
        If ``x`` has the wrong shape or a loaded particle is outside the chain.
    """
    x = _check_state(params, x)
    particles = _loaded_particles(params, loaded)
    limits = limits or chain_limits(params, x)
    if ax is None:
        ax = _chain_figure(limits, 1).add_subplot()
    _ChainArtists(ax, params, x, particles)
    _style_axes(ax, limits)
    if time is not None:
        ax.set_title(f"t = {time:g}")
    if legend:
        _legend(ax, bool(particles))
    return ax.figure


# ---------------------------------------------------------------- runs
def loaded_particles_of(dataset: xr.Dataset) -> tuple[int, ...]:
    """Particles that carry a moment in a run's ``loads_json`` attribute (empty if none is recorded)."""
    loads = json.loads(dataset.attrs.get("loads_json", "[]"))
    return tuple(sorted({int(load["particle"]) for load in loads if load.get("row") == "phi"}))


def _time_range_error(name: str, value: float, times: np.ndarray) -> ValueError:
    return ValueError(f"{name} = {value!r} is outside the run: allowed {times[0]:g} <= t <= {times[-1]:g}")


def _nearest_frame(times: np.ndarray, t: float, name: str = "time") -> int:
    if not (math.isfinite(t) and times[0] - 1e-9 * max(1.0, abs(times[0])) <= t <= times[-1] + 1e-9 * max(1.0, abs(times[-1]))):
        raise _time_range_error(name, t, times)
    return int(np.argmin(np.abs(times - t)))


def _check_extension(path: str | Path, allowed: Sequence[str], what: str) -> Path:
    path = Path(path)
    if path.suffix.lower() not in allowed:
        raise ValueError(f"unknown {what} format {path.suffix or '(none)'!r} of {str(path)!r}; allowed: {', '.join(allowed)}")
    return path


def snapshot_figure(
    params: ChainParams | None,
    dataset: xr.Dataset,
    times: Sequence[float],
    *,
    loaded: int | Iterable[int] | None = None,
    path: str | Path | None = None,
    title: str | None = None,
) -> Figure:
    """Snapshots of a run at chosen times, one panel each, stacked (paper, Fig. 3a/3b).

    Parameters
    ----------
    params : ChainParams or None
        None: read from the Dataset's ``params_json`` attribute.
    dataset : xarray.Dataset
        A run: ``u, v, phi`` over (time, particle).
    times : sequence of float
        Each panel shows the stored frame nearest to one of these times (its own
        time in the panel's title). All panels share the limits.
    loaded : int or iterable of int, optional
        Particles marked as loaded; default those carrying a moment in the run's
        ``loads_json`` attribute (pass ``()`` for none).
    path : str or Path, optional
        Save the figure there; the format follows the extension (.png, .svg, .pdf).
    title : str, optional
        Figure title.

    Returns
    -------
    matplotlib.figure.Figure

    Raises
    ------
    ValueError
        If ``times`` is empty, a time is outside the run (naming it and the allowed
        range), or the extension of ``path`` is unknown.
    """
    if path is not None:
        path = _check_extension(path, FIGURE_FORMATS, "figure")
    params = params or params_of(dataset)
    run_times, states = run_states(params, dataset)
    times = [float(t) for t in times]
    if not times:
        raise ValueError("times must name at least one time of the run")
    frames = [_nearest_frame(run_times, t) for t in times]
    particles = _loaded_particles(params, loaded_particles_of(dataset) if loaded is None else loaded)
    limits = chain_limits(params, states[frames])
    figure = _chain_figure(limits, len(frames))
    axes = figure.subplots(len(frames), 1, sharex=True, squeeze=False)[:, 0]
    for i, (ax, frame) in enumerate(zip(axes, frames)):
        draw_chain(params, states[frame], ax, loaded=particles, time=float(run_times[frame]), limits=limits, legend=i == len(frames) - 1)
        if i < len(frames) - 1:
            ax.set_xlabel("")
    if title:
        figure.suptitle(title)
    if path is not None:
        write_figure(figure, path, bbox_inches="tight", pad_inches=0.05)
    return figure


# ---------------------------------------------------------------- animation
def mp4_encoder_available() -> bool:
    """Whether MP4 can be written (imageio's FFMPEG plugin needs the ``imageio-ffmpeg`` package)."""
    return importlib.util.find_spec("imageio_ffmpeg") is not None


def frame_indices(times: np.ndarray, t_start: float | None = None, t_stop: float | None = None, max_frames: int = 200) -> np.ndarray:
    """Stored frames of the window [t_start, t_stop], evenly subsampled to at most ``max_frames``.

    Parameters
    ----------
    times : ndarray, shape (n,)
        Increasing times of the stored frames.
    t_start, t_stop : float, optional
        The window; default the whole run.
    max_frames : int
        At least 1. The first and the last frame of the window are always kept.

    Returns
    -------
    ndarray of int
        Increasing indices into ``times``, min(max_frames, frames in the window) of them.

    Raises
    ------
    ValueError
        If a bound is outside the run (naming it and the allowed range), t_start >
        t_stop, max_frames < 1, or no stored frame lies in the window.
    """
    times = np.asarray(times, dtype=float)
    if isinstance(max_frames, bool) or not isinstance(max_frames, (int, np.integer)) or max_frames < 1:
        raise ValueError(f"max_frames must be an integer >= 1, got {max_frames!r}")
    start = times[0] if t_start is None else float(t_start)
    stop = times[-1] if t_stop is None else float(t_stop)
    _nearest_frame(times, start, "t_start")
    _nearest_frame(times, stop, "t_stop")
    if start > stop:
        raise ValueError(f"t_start = {start!r} must not exceed t_stop = {stop!r}")
    slack = 1e-9 * max(1.0, abs(start), abs(stop))
    inside = np.flatnonzero((times >= start - slack) & (times <= stop + slack))
    if inside.size == 0:
        raise ValueError(f"no stored frame lies in {start:g} <= t <= {stop:g}; widen the window or store more frames")
    if inside.size <= max_frames:
        return inside
    # Rounded evenly spaced positions are distinct because the spacing exceeds one.
    return inside[np.round(np.linspace(0, inside.size - 1, max_frames)).astype(int)]


def _time_format(times: np.ndarray) -> str:
    """Enough decimals that consecutive frame times print differently.

    GIF writers merge identical consecutive frames, so every title must differ.
    """
    steps = np.diff(times)
    smallest = float(steps[steps > 0].min()) if np.any(steps > 0) else 1.0
    decimals = min(max(0, math.ceil(-math.log10(smallest)) + 1), 9)
    return f"{{:.{decimals}f}}"


class _FrameWriter:
    """Appends RGB frames to a GIF (Pillow) or an MP4 (imageio's FFMPEG plugin) one at a time.

    GIF frames are mapped to one palette, taken from the first frame: a palette per
    frame would map the same colours differently from frame to frame and make still
    parts flicker. Pillow writes them itself, because handing it paletted frames
    through imageio makes it re-match the palette in Python for every frame.
    """

    def __init__(self, path: Path, fps: float) -> None:
        self._path = path
        self._duration = 1000.0 / fps
        self._gif = path.suffix.lower() == ".gif"
        self._frames: list[Image.Image] = []
        self._writer = None if self._gif else iio2.get_writer(path, format="FFMPEG", mode="I", fps=fps, codec="libx264", macro_block_size=2)

    def append(self, frame: np.ndarray) -> None:
        """Append one frame, an RGBA array (the canvas's own buffer: it is read here, not kept)."""
        if self._writer is not None:
            self._writer.append_data(np.ascontiguousarray(frame[..., :3]))
            return
        # Pillow drops the alpha channel in C, without the strided copy an RGB slice of the array would need.
        image = Image.fromarray(frame, "RGBA").convert("RGB")
        palette = self._frames[0] if self._frames else image.quantize(colors=256, dither=Image.Dither.NONE)
        self._frames.append(image.quantize(palette=palette, dither=Image.Dither.NONE))

    def close(self) -> None:
        if self._writer is not None:
            self._writer.close()
        elif self._frames:
            first, *rest = self._frames
            first.save(self._path, format="GIF", save_all=True, append_images=rest, duration=self._duration, loop=0)
            self._frames.clear()


def animate(
    params: ChainParams | None,
    dataset: xr.Dataset,
    path: str | Path,
    *,
    t_start: float | None = None,
    t_stop: float | None = None,
    max_frames: int = 200,
    fps: float = 20.0,
    loaded: int | Iterable[int] | None = None,
    dpi: int = 100,
    progress: Callable[[int, int], None] | None = None,
) -> Path:
    """Write an animation of a run over a time window: GIF always, MP4 with an encoder.

    Parameters
    ----------
    params : ChainParams or None
        None: read from the Dataset's ``params_json`` attribute.
    dataset : xarray.Dataset
        A run: ``u, v, phi`` over (time, particle).
    path : str or Path
        Output file; ``.gif`` (Pillow) or ``.mp4`` (needs ``imageio-ffmpeg``).
    t_start, t_stop : float, optional
        The window of the run to animate; default the whole run.
    max_frames : int
        The stored frames of the window are evenly subsampled to at most this many
        (:func:`frame_indices`); a long run is never animated from every frame.
    fps : float
        Frames per second of the animation, > 0.
    loaded : int or iterable of int, optional
        Particles marked as loaded; default those carrying a moment in the run.
    dpi : int
        Pixels per inch of the 8-inch-wide frames.
    progress : callable, optional
        Called as ``progress(frames_done, frames_total)`` after every frame.

    Returns
    -------
    Path
        ``path``, written atomically.

    Notes
    -----
    Frames are rendered one at a time into a single figure (only the chain and
    the title are redrawn). An MP4 is streamed to the encoder; a GIF keeps its
    frames (one byte per pixel, in the first frame's palette) until the file is
    written, so memory is bounded by ``max_frames``, not by the length of the run.

    Raises
    ------
    ValueError
        For an unknown extension, a window outside the run (naming the bound and
        the allowed range), ``max_frames < 1`` or ``fps <= 0``.
    RuntimeError
        For ``.mp4`` when no encoder is installed (install ``imageio-ffmpeg``).
    """
    path = _check_extension(path, ANIMATION_FORMATS, "animation")
    if not (math.isfinite(fps) and fps > 0):
        raise ValueError(f"fps must be > 0, got {fps!r}")
    if path.suffix.lower() == ".mp4" and not mp4_encoder_available():
        raise RuntimeError("writing MP4 needs an encoder: install imageio-ffmpeg (pip install imageio-ffmpeg), or write a .gif")
    params = params or params_of(dataset)
    run_times, states = run_states(params, dataset)
    frames = frame_indices(run_times, t_start, t_stop, max_frames)
    particles = _loaded_particles(params, loaded_particles_of(dataset) if loaded is None else loaded)
    limits = chain_limits(params, states[frames])
    time_format = _time_format(run_times[frames])

    figure = _chain_figure(limits, 1)
    # Even pixel sizes: H.264 in yuv420p needs them, and the MP4 writer would otherwise resize.
    width_px, height_px = (2 * math.ceil(size * dpi / 2) for size in figure.get_size_inches())
    figure.set_size_inches(width_px / dpi, height_px / dpi)
    figure.set_dpi(dpi)
    ax = figure.add_subplot()
    artists = _ChainArtists(ax, params, states[frames[0]], particles)
    _style_axes(ax, limits)
    _legend(ax, bool(particles))
    ax.set_title("t = " + time_format.format(run_times[frames[0]]))
    figure.canvas.draw()
    # Freeze the first frame's layout so the axes do not jitter, then blit: axes, ticks and
    # legend are rendered once and only the chain and the title are drawn for each frame.
    figure.set_layout_engine("none")
    moving = (*artists.moving, ax.title)
    for artist in moving:
        artist.set_animated(True)
    figure.canvas.draw()
    background = figure.canvas.copy_from_bbox(figure.bbox)
    with atomic_path(path) as tmp:
        writer = _FrameWriter(tmp, fps)
        try:
            for done, frame in enumerate(frames, start=1):
                artists.update(states[frame])
                ax.set_title("t = " + time_format.format(run_times[frame]))
                figure.canvas.restore_region(background)
                for artist in moving:
                    figure.draw_artist(artist)
                writer.append(np.asarray(figure.canvas.buffer_rgba()))
                if progress is not None:
                    progress(done, len(frames))
        finally:
            writer.close()
    return path
