"""Pictures of the chain: the artists carry the geometry, snapshots and animations the chosen times."""

from __future__ import annotations

import json

import matplotlib

matplotlib.use("Agg")

import imageio.v3 as iio
import numpy as np
import pytest
import xarray as xr
from typer.testing import CliRunner

from conftest import ROUND_OFF, random_geometries, random_state
from cosserat_chain import ChainParams, moment_load
from cosserat_chain.cli import app
from cosserat_chain.geometry import bond_links, corner_positions, particle_positions, rotate
from cosserat_chain.io import write_dataset
from cosserat_chain.plots.chain import animate, draw_chain, frame_indices, mp4_encoder_available, snapshot_figure

runner = CliRunner()


def artist(figure, gid):
    """The one artist of the figure's (first) axes with this gid."""
    ax = figure.axes[0]
    found = [a for a in [*ax.collections, *ax.lines] if a.get_gid() == gid]
    assert len(found) == 1, gid
    return found[0]


def polygons(collection) -> np.ndarray:
    """First four vertices of every polygon of a PolyCollection, shape (n, 4, 2)."""
    return np.array([path.vertices[:4] for path in collection.get_paths()])


def segments(collection) -> np.ndarray:
    return np.array(collection.get_segments())


def run_dataset(params: ChainParams, states: np.ndarray, times: np.ndarray) -> xr.Dataset:
    """A run as simulate() stores it (u, v, phi over time x particle, params and loads attributes)."""
    data = {row: (("time", "particle"), states[:, i, :]) for i, row in enumerate(("u", "v", "phi"))}
    attrs = {"params_json": json.dumps(params.model_dump()), "loads_json": json.dumps(moment_load(0.5).to_list()), "model": "sine"}
    return xr.Dataset(data, coords={"time": times, "particle": np.arange(-params.N, params.N + 1)}, attrs=attrs)


def wobbling_run(params: ChainParams, n_frames: int = 41, t_end: float = 4.0) -> xr.Dataset:
    """The central particle turning fast (unwrapped angle), the others wobbling."""
    times = np.linspace(0.0, t_end, n_frames)
    states = np.zeros((n_frames, 3, params.n_particles))
    k = np.arange(1, params.n_particles - 1)
    states[:, 1, 1:-1] = 0.1 * np.sin(times[:, None] + k)
    states[:, 0, 1:-1] = 0.05 * np.cos(2 * times[:, None] + k)
    states[:, 2, params.N] = 3.0 * times
    return run_dataset(params, states, times)


@pytest.mark.parametrize("params", random_geometries(3, seed=4))
def test_particle_polygons_are_the_corners_of_corner_positions(params):
    x = random_state(params, 0.3, seed=1)
    figure = draw_chain(params, x, loaded=0)
    corners = corner_positions(params, x)
    np.testing.assert_allclose(polygons(artist(figure, "particles")), corners, atol=ROUND_OFF)
    clamped = artist(figure, "clamped")
    np.testing.assert_allclose(polygons(clamped), corners[[0, -1]], atol=ROUND_OFF)
    assert clamped.get_hatch()


@pytest.mark.parametrize("params", random_geometries(3, seed=5))
def test_links_join_the_corners_named_by_bond_links(params):
    x = random_state(params, 0.3, seed=2)
    figure = draw_chain(params, x)
    horizontal, diagonal = segments(artist(figure, "links_horizontal")), segments(artist(figure, "links_diagonal"))
    bonds = params.n_particles - 1
    assert len(horizontal) + len(diagonal) == 4 * bonds
    centres = np.column_stack([particle_positions(params) + x[0], x[1]])

    def corner(column, body_corner):
        # Rebuilt from the link table and the rotation alone, not from corner_positions.
        return centres[column] + np.array(rotate(body_corner, x[2, column]))

    drawn = {"horizontal": iter(horizontal), "diagonal": iter(diagonal)}
    for k in range(bonds):
        for link in bond_links(params):
            segment = next(drawn["diagonal" if link.name.startswith("diagonal") else "horizontal"])
            np.testing.assert_allclose(segment, [corner(k, link.left_corner), corner(k + 1, link.right_corner)], atol=ROUND_OFF)
    # The two kinds of link are told apart by their style.
    assert artist(figure, "links_horizontal").get_linestyle() != artist(figure, "links_diagonal").get_linestyle()


def test_links_at_rest_have_their_rest_lengths(paper):
    figure = draw_chain(paper, np.zeros((3, paper.n_particles)))
    for gid, length in (("links_horizontal", paper.gap), ("links_diagonal", paper.d)):
        ends = segments(artist(figure, gid))
        np.testing.assert_allclose(np.linalg.norm(ends[:, 1] - ends[:, 0], axis=1), length, atol=ROUND_OFF)


def test_centre_line_joins_the_centres(paper):
    x = random_state(paper, 0.2, seed=3)
    line = artist(draw_chain(paper, x), "centre_line")
    np.testing.assert_allclose(line.get_xdata(), particle_positions(paper) + x[0])
    np.testing.assert_allclose(line.get_ydata(), x[1])


def test_unwrapped_angle_of_1500_turns_draws_like_the_wrapped_one(paper):
    x = random_state(paper, 0.3, seed=4)
    turned = x.copy()
    turned[2, paper.N] += 1500 * 2 * np.pi
    drawn = polygons(artist(draw_chain(paper, turned), "particles"))
    np.testing.assert_allclose(drawn, polygons(artist(draw_chain(paper, x), "particles")), atol=1e-9)


def test_wrong_state_shape_and_loaded_particle_are_refused(paper):
    with pytest.raises(ValueError, match=r"shape \(3, 2N\+1\) = \(3, 7\)"):
        draw_chain(paper, np.zeros((3, 5)))
    with pytest.raises(ValueError, match="loaded particle must be in -N..N = -3..3, got 4"):
        draw_chain(paper, np.zeros((3, 7)), loaded=4)


def test_snapshot_figure_has_one_panel_per_time_at_the_nearest_frames(paper, tmp_path):
    ds = wobbling_run(paper)
    out = tmp_path / "fig3.svg"
    figure = snapshot_figure(None, ds, [0.0, 1.04, 4.0], path=out)
    assert len(figure.axes) == 3
    assert [ax.get_title() for ax in figure.axes] == ["t = 0", "t = 1", "t = 4"]
    assert len({ax.get_xlim() for ax in figure.axes}) == 1 and len({ax.get_ylim() for ax in figure.axes}) == 1
    assert all(ax.get_aspect() == 1.0 for ax in figure.axes)
    assert out.read_text().lstrip().startswith("<?xml")
    # The panel at t = 1 shows the stored frame at t = 1 (frame 10), loaded particle in its own colour.
    particles = [a for a in figure.axes[1].collections if a.get_gid() == "particles"][0]
    x = np.stack([ds[row].values[10] for row in ("u", "v", "phi")])
    np.testing.assert_allclose(polygons(particles), corner_positions(paper, x), atol=ROUND_OFF)
    faces = particles.get_facecolors()
    assert not np.allclose(faces[paper.N], faces[paper.N + 1])


@pytest.mark.parametrize("t", [-0.5, 4.5, float("nan")])
def test_time_outside_the_run_names_the_value_and_the_range(paper, t):
    with pytest.raises(ValueError, match=rf"time = {t!r} is outside the run: allowed 0 <= t <= 4"):
        snapshot_figure(paper, wobbling_run(paper), [1.0, t])


def test_unknown_extensions_are_refused_with_the_allowed_ones(paper, tmp_path):
    ds = wobbling_run(paper)
    with pytest.raises(ValueError, match=r"'.jpg'.*allowed: .png, .svg, .pdf"):
        snapshot_figure(paper, ds, [1.0], path=tmp_path / "a.jpg")
    with pytest.raises(ValueError, match=r"'.avi'.*allowed: .gif, .mp4"):
        animate(paper, ds, tmp_path / "a.avi")
    assert not list(tmp_path.iterdir())


def test_frame_indices_subsample_the_window_evenly_keeping_its_ends():
    times = np.linspace(0.0, 100.0, 1001)
    chosen = frame_indices(times, 20.0, 60.0, 41)
    assert chosen.size == 41 and np.all(np.diff(chosen) > 0)
    assert times[chosen[0]] == pytest.approx(20.0) and times[chosen[-1]] == pytest.approx(60.0)
    np.testing.assert_allclose(np.diff(times[chosen]), 1.0)
    assert frame_indices(times, 20.0, 21.0, 500).size == 11  # fewer frames in the window than allowed: all of them
    with pytest.raises(ValueError, match=r"t_stop = 101.0 is outside the run: allowed 0 <= t <= 100"):
        frame_indices(times, 0.0, 101.0)
    with pytest.raises(ValueError, match="t_start = 5.0 must not exceed t_stop = 4.0"):
        frame_indices(times, 5.0, 4.0)
    with pytest.raises(ValueError, match="max_frames must be an integer >= 1"):
        frame_indices(times, max_frames=0)


def test_gif_has_the_requested_frames_all_from_the_window(paper, tmp_path):
    # At rest before t = 2, displaced (and turned by 1500 turns) from t = 2 on: a frame from outside
    # the window [2.5, 4] would show another chain, while inside it only the time in the title changes.
    times = np.linspace(0.0, 4.0, 81)
    states = np.zeros((times.size, 3, paper.n_particles))
    states[times >= 2.0, 1, paper.N + 1] = 0.3
    states[times >= 2.0, 2, paper.N] = 1500 * 2 * np.pi + 0.4
    path = animate(None, run_dataset(paper, states, times), tmp_path / "run.gif", t_start=2.5, t_stop=4.0, max_frames=7, fps=10, dpi=50)
    frames = iio.imread(path, index=None)
    assert frames.shape[0] == 7
    changed_rows = np.flatnonzero(np.any(frames != frames[0], axis=(0, 2, 3)))
    assert changed_rows.size and changed_rows.max() < frames.shape[1] // 3  # the title only, above the chain
    assert all(not np.array_equal(frame, frames[0]) for frame in frames[1:])
    assert [p.name for p in tmp_path.iterdir()] == ["run.gif"]


def test_mp4_needs_an_encoder(paper, tmp_path):
    ds = wobbling_run(paper, n_frames=11)
    if mp4_encoder_available():
        path = animate(paper, ds, tmp_path / "run.mp4", max_frames=5, dpi=50)
        import imageio.v2 as iio2

        assert iio2.get_reader(path, format="FFMPEG").count_frames() == 5
    else:
        with pytest.raises(RuntimeError, match="install imageio-ffmpeg"):
            animate(paper, ds, tmp_path / "run.mp4")
        assert not list(tmp_path.iterdir())


def test_cli_draws_and_animates_a_run_file(paper, tmp_path):
    run = write_dataset(wobbling_run(paper), tmp_path / "run.nc")
    result = runner.invoke(app, ["draw", str(run), "--out", str(tmp_path / "fig.png"), "--times", "1,2,3"])
    assert result.exit_code == 0, result.output
    assert iio.imread(tmp_path / "fig.png").ndim == 3
    result = runner.invoke(app, ["animate", str(run), "--out", str(tmp_path / "a.gif"), "--t-start", "1", "--t-stop", "3", "--frames", "5"])
    assert result.exit_code == 0, result.output
    assert iio.imread(tmp_path / "a.gif", index=None).shape[0] == 5


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["draw", "{run}", "--out", "{tmp}/a.jpg"], "unknown format '.jpg' of --out"),
        (["animate", "{run}", "--out", "{tmp}/a.avi"], "allowed: .gif, .mp4"),
        (["draw", "{run}", "--out", "{tmp}/a.png", "--times", "1,9"], "time = 9.0 is outside the run: allowed 0 <= t <= 4"),
        (["animate", "{run}", "--out", "{tmp}/a.gif", "--t-start", "-1"], "t_start = -1.0 is outside the run"),
        (["draw", "{tmp}/missing.nc", "--out", "{tmp}/a.png"], "missing.nc' does not exist"),
        (["draw", "{run}", "--out", "{tmp}/a.png", "--times", "1,x"], "got 'x'"),
    ],
)
def test_cli_errors_exit_2_with_a_message(paper, tmp_path, args, message):
    run = write_dataset(wobbling_run(paper), tmp_path / "run.nc")
    result = runner.invoke(app, [arg.format(run=run, tmp=tmp_path) for arg in args])
    assert result.exit_code == 2
    assert message in result.output


def test_cli_draws_straight_from_a_simulation(tmp_path):
    result = runner.invoke(app, ["draw", "--model", "sine", "--moment", "0.3", "--t-end", "5", "--out", str(tmp_path / "sim.png")])
    assert result.exit_code == 0, result.output
    assert (tmp_path / "sim.png").stat().st_size > 0
