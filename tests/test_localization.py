"""The localization run: streaming diagnostics, checkpoints and resuming, classification, CLI."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from typer.testing import CliRunner

from conftest import ROUND_OFF
from cosserat_chain import ChainParams, get_model, moment_load
from cosserat_chain.analysis import diagnostics as diag
from cosserat_chain.cli import app
from cosserat_chain.experiments import localization
from cosserat_chain.experiments.localization import grid_time_step, localization_run
from cosserat_chain.io import read_dataset
from cosserat_chain.numerics import dynamics
from cosserat_chain.numerics.dynamics import integrate
from cosserat_chain.status import Status

runner = CliRunner()
TWO_PI = 2 * math.pi
#: Critical moments of the paper's chain (docs/statics.md): nonlinear 0.19750, sine 0.20396.
ABOVE = {"nonlinear": 0.25, "sine": 0.3}
#: The exactly repeated quantities of a run (everything but wall time and messages).
EXACT_KEYS = (
    "turns_completed", "mean_angular_velocity", "max_abs_phi_others", "max_abs_v_others", "max_abs_u_others",
    "classification", "t_end", "recent_angular_velocity", "participation_ratio", "winding", "steps",
)  # fmt: skip


def _trajectory(params, model="nonlinear", moment=0.25, t_end=40.0):
    dt = grid_time_step(dynamics.default_time_step(params))
    return integrate(params, model, moment_load(moment), t_end=t_end, dt=dt, stride=1)


def _feed(params, model, trajectory, cuts):
    """Diagnostics of a trajectory fed in chunks that end at the frame indices ``cuts``."""
    d = diag.StreamingDiagnostics(params, model, 0, trajectory.x[0], trajectory.v[0], trajectory.time[0])
    start = 0
    for stop in [*cuts, trajectory.time.size - 1]:
        d.update(trajectory.time[start : stop + 1], trajectory.x[start : stop + 1], trajectory.v[start : stop + 1])
        start = stop
    return d


def test_bond_energies_sum_to_the_models_potential(paper):
    rng = np.random.default_rng(3)
    x = np.zeros((4, 3, paper.n_particles))
    x[:, :, 1:-1] = 0.4 * rng.standard_normal((4, 3, paper.n_particles - 2))
    for name in ("nonlinear", "linear"):
        expected = [get_model(name).energy(paper, frame) for frame in x]
        np.testing.assert_allclose(diag.bond_energies(paper, name, x).sum(axis=-1), expected, rtol=ROUND_OFF)
    # Particle energies split the total (kinetic + bond) energy without loss, also at the clamped ends.
    v = rng.standard_normal(x.shape)
    v[:, :, [0, -1]] = 0
    total = 0.5 * np.sum(np.asarray(paper.inertia)[:, None] * v**2, axis=(-2, -1)) + diag.bond_energies(paper, "sine", x).sum(-1)
    np.testing.assert_allclose(diag.particle_energies(paper, "sine", x, v).sum(-1), total, rtol=ROUND_OFF)


def test_streaming_in_chunks_equals_the_whole_stored_trajectory(paper):
    run = _trajectory(paper)
    whole = _feed(paper, "nonlinear", run, [])
    chunked = _feed(paper, "nonlinear", run, [1, 2, 500, 501, 900, 1733])
    for name in ("max_abs_u", "max_abs_v", "max_abs_phi", "turns", "last_turn_time", "turn_times", "angle"):
        np.testing.assert_array_equal(getattr(chunked, name), getattr(whole, name), err_msg=name)
    assert chunked.steps == whole.steps == run.time.size - 1
    assert chunked.participation_ratio == pytest.approx(whole.participation_ratio, rel=ROUND_OFF)
    # ... and both equal the quantities computed directly from the stored frames.
    for i, name in enumerate(("max_abs_u", "max_abs_v", "max_abs_phi")):
        np.testing.assert_array_equal(whole.__dict__[name], np.abs(run.x[:, i]).max(axis=0))
    ratio = diag.participation_ratio(diag.particle_energies(paper, "nonlinear", run.x, run.v))
    assert whole.participation_ratio == pytest.approx(np.nanmean(ratio), rel=ROUND_OFF)
    assert whole.energy_steps == np.count_nonzero(np.isfinite(ratio))
    # The checkpointed state round-trips exactly.
    again = diag.StreamingDiagnostics.from_variables(paper, "nonlinear", 0, whole.to_variables())
    assert again.to_variables().keys() == whole.to_variables().keys()
    for key, (_, value) in whole.to_variables().items():
        np.testing.assert_array_equal(again.to_variables()[key][1], value, err_msg=key)


def test_winding_is_the_full_turns_of_the_unwrapped_angle():
    params = ChainParams(N=2)
    time = np.linspace(0.0, 10.0, 401)
    x = np.zeros((time.size, 3, params.n_particles))
    x[:, 2, 2] = 2.0 * time  # the loaded particle turns at constant speed 2
    x[:, 2, 1] = -0.3 * np.sin(time)  # a neighbour swings slightly to negative angles
    x[:, 2, 3] = np.where(time < 4.0, 1.6 * time, 6.4)  # another makes one turn, then stops
    v = np.zeros_like(x)
    d = diag.StreamingDiagnostics(params, "sine", 0, x[0], v[0])
    d.update(time[:150], x[:150], v[:150])
    d.update(time[149:], x[149:], v[149:])
    theta = x[-1, 2]
    np.testing.assert_array_equal(d.winding, np.trunc(theta / TWO_PI))
    assert d.winding[2] == math.floor(20.0 / TWO_PI) == d.turns_completed == 3
    assert d.winding[1] == 0 and d.turns[1] == 0  # trunc, not floor: a swing to -0.3 rad is no turn
    assert d.turns[3] == 1 and d.last_turn_time[3] == time[np.argmax(x[:, 2, 3] >= TWO_PI)]
    # Turn times are interpolated between steps: exact for a uniform rotation.
    np.testing.assert_allclose(d.turn_times, TWO_PI * np.arange(1, 4) / 2.0, rtol=ROUND_OFF)
    assert d.recent_angular_velocity == pytest.approx(2.0, rel=ROUND_OFF)
    assert d.mean_angular_velocity == pytest.approx(2.0, rel=ROUND_OFF)
    # Particle 1 (column 3) turned once but stopped long before the last quarter: not rotating.
    assert list(d.rotating) == [False, False, True, False, False]
    # No other particle rotates, but the one that turned once went far: not a small oscillation.
    assert d.large_motion == ("phi",) and d.classification == "rotation_with_large_motion"


def test_classification_several_rotating_and_static():
    params = ChainParams(N=2)
    time = np.linspace(0.0, 10.0, 101)
    x = np.zeros((time.size, 3, params.n_particles))
    x[:, 2, 3] = -2.0 * time  # a particle other than the loaded one turns (backwards)
    d = diag.StreamingDiagnostics(params, "linear", 0, x[0], x[0])
    d.update(time, x, np.zeros_like(x))
    assert d.classification == "several_rotating" and d.winding[3] == -3
    assert diag.StreamingDiagnostics(params, "linear", 0, x[0], x[0]).classification == "static"


def _frames(params, others, time=np.linspace(0.0, 10.0, 201)):
    """Stored frames: the loaded particle turns at speed 2, every other free particle oscillates with the
    amplitudes ``others`` (row -> amplitude, u and v in the units of h as they are stored)."""
    x = np.zeros((time.size, 3, params.n_particles))
    c = params.N
    for row, amplitude in others.items():
        x[:, row, 1:-1] = amplitude * np.sin(3.0 * time)[:, None]
    x[:, 2, c] = 2.0 * time
    x[:, :2, c] = 0.0
    return time, x


@pytest.mark.parametrize("model", ["nonlinear", "sine"])
@pytest.mark.parametrize(("row", "name"), [(0, "u_over_h"), (1, "v_over_h"), (2, "phi")])
def test_the_classification_compares_every_amplitude_of_the_others_with_its_threshold(model, row, name):
    """Just below every threshold: localized; one amplitude just above: large motion, naming it. With h = 2,
    |u| and |v| count in units of h (a classifier comparing |v| itself would call 0.15 large)."""
    params = ChainParams(N=2, h=2.0, a=0.4, b=0.4)
    below = {0: 0.99 * diag.SMALL_DISPLACEMENT * params.h, 1: 0.99 * diag.SMALL_DISPLACEMENT * params.h, 2: 0.99 * diag.SMALL_ANGLE}
    time, x = _frames(params, below)
    d = diag.StreamingDiagnostics(params, model, 0, x[0], x[0])
    d.update(time, x, np.zeros_like(x))
    assert d.turns_completed == 3 and d.large_motion == () and d.classification == "localized_rotation"
    assert d.amplitudes_of_others[name] == pytest.approx(0.99 * diag.THRESHOLDS[name], rel=1e-3)
    above = {**below, row: 1.02 * below[row] / 0.99}
    time, x = _frames(params, above)
    d = diag.StreamingDiagnostics(params, model, 0, x[0], x[0])
    d.update(time, x, np.zeros_like(x))
    assert d.large_motion == (name,) and d.classification == "rotation_with_large_motion"
    # Only a model linear in the row leaves its range of validity: the sine model in u and v, the nonlinear never.
    assert d.outside_validity == ((name,) if model == "sine" and name != "phi" else ())


def test_the_models_linear_rows_come_from_their_stiffness():
    for params in (ChainParams(), ChainParams(N=5, h=2.0, a=0.5, b=0.3, E2=0.4)):
        assert diag.linear_rows(params, "nonlinear") == ()
        assert diag.linear_rows(params, "sine") == ("u_over_h", "v_over_h")
        assert diag.linear_rows(params, "linear") == ("u_over_h", "v_over_h", "phi")


def test_the_thresholds_are_where_the_quadratic_term_is_a_tenth_of_the_linear_one():
    """The reasons the constants' docstrings give, evaluated exactly: a corner turned by SMALL_ANGLE, a link of
    length h whose ends move apart transversally by twice SMALL_DISPLACEMENT h."""
    tolerance = diag.LINEARISATION_TOLERANCE
    phi, r = diag.SMALL_ANGLE, np.array([0.2, 0.3])
    rotated = np.array([[math.cos(phi), -math.sin(phi)], [math.sin(phi), math.cos(phi)]]) @ r
    linear = phi * np.array([-r[1], r[0]])
    assert np.linalg.norm(rotated - r - linear) / np.linalg.norm(linear) == pytest.approx(tolerance, rel=0.02)
    delta = 2 * diag.SMALL_DISPLACEMENT  # link length 1 (= h)
    assert (math.hypot(1.0, delta) - 1.0) / delta == pytest.approx(tolerance, rel=0.02)


@pytest.mark.parametrize("model", ["nonlinear", "sine"])
def test_above_the_critical_moment_only_the_loaded_particle_turns_but_the_others_move_far(paper, model):
    result = localization_run(paper, model, ABOVE[model], turns=25, t_max=1000.0)
    summary = result.as_dict()
    assert summary["status"] == "completed" and summary["turns_completed"] == 25
    assert summary["winding"] == {"-3": 0, "-2": 0, "-1": 0, "0": 25, "1": 0, "2": 0, "3": 0}
    assert summary["max_abs_phi_others"] < 1.0 and summary["max_abs_v_others"] < 1.0
    # Beyond the small-motion thresholds (the others reach 0.33-0.48 rad and 0.34-0.70 h):
    # the rotation is localized, the others' motion is not small.
    assert summary["thresholds"] == {"phi": diag.SMALL_ANGLE, "u_over_h": diag.SMALL_DISPLACEMENT, "v_over_h": diag.SMALL_DISPLACEMENT}
    assert summary["classification"] == "rotation_with_large_motion"
    if model == "sine":  # eq. (2) is linear in u, which nothing drives; v leaves the range of a model linear in it
        assert summary["max_abs_u_others"] == 0.0
        assert summary["large_motion"] == ["phi", "v_over_h"] and summary["outside_model_validity"] == ["v_over_h"]
    else:  # the nonlinear model holds at any amplitude
        assert summary["large_motion"] == ["phi", "u_over_h", "v_over_h"] and summary["outside_model_validity"] == []
    # The run stops at the step that completes the last turn, so omega t_end = 2 pi turns to one step.
    omega = summary["mean_angular_velocity"]
    assert abs(omega * summary["t_end"] - TWO_PI * 25) <= abs(result.v[2, 3]) * result.dt + ROUND_OFF
    # A driven particle can spin no faster than M / gamma_phi.
    assert 0 < omega < ABOVE[model] / paper.gamma_phi


def test_static_below_the_critical_moment_with_strong_damping():
    params = ChainParams(gamma_u=1.0, gamma_v=1.0, gamma_phi=1.0)
    result = localization_run(params, "nonlinear", 0.18, turns=5, t_max=150.0)
    assert result.status == "time_limit" and result.diagnostics.turns_completed == 0
    assert result.as_dict()["classification"] == "static"
    assert result.t_end >= 150.0 and result.t_end - result.dt < 150.0
    assert abs(result.v).max() < 1e-3  # come to rest


def test_run_equals_the_diagnostics_of_one_stored_trajectory(paper):
    result = localization_run(paper, "nonlinear", 0.25, turns=1000, t_max=40.0, chunk_time=7.0)
    run = _trajectory(paper, t_end=result.t_end)
    whole = _feed(paper, "nonlinear", run, [])
    np.testing.assert_array_equal(result.x, run.x[-1])
    for name in ("max_abs_u", "max_abs_v", "max_abs_phi", "turns", "last_turn_time", "turn_times"):
        np.testing.assert_array_equal(getattr(result.diagnostics, name), getattr(whole, name), err_msg=name)


def test_resume_after_a_time_limit_repeats_the_uninterrupted_run_bitwise(paper, tmp_path):
    settings = dict(turns=15, chunk_time=10.0)
    full = localization_run(paper, "sine", 0.3, t_max=500.0, **settings)
    path = tmp_path / "c.nc"
    first = localization_run(paper, "sine", 0.3, t_max=21.7, checkpoint=path, **settings)  # stops inside a chunk
    assert first.status == "time_limit" and first.step % first.chunk_steps != 0
    resumed = localization_run(paper, "sine", 0.3, t_max=500.0, checkpoint=path, resume=True, **settings)
    assert resumed.status == "completed"
    assert {k: resumed.as_dict()[k] for k in EXACT_KEYS} == {k: full.as_dict()[k] for k in EXACT_KEYS}
    np.testing.assert_array_equal(resumed.x, full.x)
    np.testing.assert_array_equal(resumed.v, full.v)
    # The checkpoint of the finished run describes it; resuming it again does nothing.
    again = localization_run(paper, "sine", 0.3, t_max=500.0, checkpoint=path, resume=True, **settings)
    assert again.step == full.step and read_dataset(path).attrs["status"] == "completed"


def test_ctrl_c_keeps_the_work_and_resuming_gives_the_same_result(paper, tmp_path, monkeypatch):
    settings = dict(turns=12, t_max=500.0, chunk_time=10.0)
    full = localization_run(paper, "nonlinear", 0.25, **settings)
    path = tmp_path / "c.nc"
    calls = []

    def ctrl_c(done, total):
        calls.append(done)
        if len(calls) == 3:
            raise KeyboardInterrupt

    stopped = localization_run(paper, "nonlinear", 0.25, checkpoint=path, checkpoint_every=1e9, progress=ctrl_c, **settings)
    assert stopped.status == "interrupted" and stopped.step == 3 * stopped.chunk_steps
    assert read_dataset(path).attrs["steps"] == stopped.step  # saved on the way out
    # Ctrl-C inside the compiled loop (small internal chunks): integrate returns what it computed.
    monkeypatch.setattr(dynamics, "CHUNK_WORK", 7 * 100)
    original = localization.integrate
    count = iter(range(1000))

    def interrupted_integrate(*args, **kwargs):
        def stop(done, total):
            if next(count) == 5:
                raise KeyboardInterrupt

        return original(*args, **kwargs, progress=stop)

    monkeypatch.setattr(localization, "integrate", interrupted_integrate)
    inside = localization_run(paper, "nonlinear", 0.25, checkpoint=path, resume=True, **settings)
    assert inside.status == "interrupted" and inside.step % inside.chunk_steps != 0 and inside.step > stopped.step
    monkeypatch.setattr(localization, "integrate", original)
    resumed = localization_run(paper, "nonlinear", 0.25, checkpoint=path, resume=True, **settings)
    assert {k: resumed.as_dict()[k] for k in EXACT_KEYS} == {k: full.as_dict()[k] for k in EXACT_KEYS}
    np.testing.assert_array_equal(resumed.x, full.x)


def test_a_blow_up_raises_and_asks_for_a_smaller_step(paper, monkeypatch):
    original = localization.integrate
    # A tiny runaway bound makes the integrator report a blow-up as soon as the chain moves.
    monkeypatch.setattr(localization, "integrate", lambda *args, **kwargs: original(*args, **kwargs, max_displacement=1e-6))
    with pytest.raises(dynamics.IntegrationError, match="smaller time step"):
        localization_run(paper, "nonlinear", 0.25, turns=2, t_max=50.0)


def test_a_checkpoint_of_other_parameters_or_settings_is_refused(paper, tmp_path):
    path = tmp_path / "c.nc"
    localization_run(paper, "sine", 0.3, turns=2, t_max=5.0, checkpoint=path)
    with pytest.raises(ValueError, match=r"params\.E2=1\.0.*params\.E2=2\.0"):
        localization_run(paper.replace(E2=2.0), "sine", 0.3, turns=2, t_max=5.0, checkpoint=path, resume=True)
    with pytest.raises(ValueError, match="moment=0.3.*moment=0.35"):
        localization_run(paper, "sine", 0.35, turns=2, t_max=5.0, checkpoint=path, resume=True)
    with pytest.raises(ValueError, match="model='sine'.*model='nonlinear'"):
        localization_run(paper, "nonlinear", 0.3, turns=2, t_max=5.0, checkpoint=path, resume=True)
    with pytest.raises(ValueError, match="dt="):
        localization_run(paper, "sine", 0.3, turns=2, t_max=5.0, dt=0.01, checkpoint=path, resume=True)


@pytest.mark.parametrize(
    "kwargs, field",
    [({"turns": 0}, "turns"), ({"t_max": -1.0}, "t_max"), ({"particle": 3}, "particle"), ({"resume": True}, "resume"),
     ({"chunk_time": 0.0}, "chunk_time"), ({"dt": float("nan")}, "dt")],
)  # fmt: skip
def test_bad_input_names_the_field(paper, kwargs, field):
    settings = {"turns": 2, "t_max": 5.0, **kwargs}
    with pytest.raises(ValueError, match=field):
        localization_run(paper, "sine", 0.3, **settings)


def test_result_file_is_self_describing(paper, tmp_path):
    ds = localization_run(paper, "nonlinear", 0.25, turns=3, t_max=100.0).to_dataset()
    assert list(ds.particle.values) == list(range(-3, 4))
    assert ds.attrs["model"] == "nonlinear" and ds.attrs["param_E1"] == 1.0 and "cosserat_chain_version" in ds.attrs
    assert int(ds.winding.sel(particle=0)) == 3
    # The classification's thresholds travel with it (NetCDF attributes hold numbers and strings).
    summary = localization_run(paper, "nonlinear", 0.25, turns=3, t_max=100.0).as_dict()
    assert ds.attrs["classification"] == summary["classification"]
    assert ds.attrs["threshold_phi"] == diag.SMALL_ANGLE and ds.attrs["threshold_v_over_h"] == diag.SMALL_DISPLACEMENT
    assert ds.attrs["large_motion"] == ",".join(summary["large_motion"])
    assert ds.attrs["max_abs_v_others_over_h"] == pytest.approx(float(ds.max_abs_v.drop_sel(particle=0).max()) / paper.h, rel=ROUND_OFF)


def test_cli_rotate_json_and_resume(tmp_path):
    out = tmp_path / "rot.nc"
    args = ["rotate", "--model", "sine", "--moment", "0.3", "--turns", "8", "--out", str(out), "--json"]
    result = runner.invoke(app, args)
    assert result.exit_code == 0, result.output
    data = json.loads(result.stdout)
    required = {"model", "moment", "turns_completed", "mean_angular_velocity", "max_abs_phi_others", "max_abs_v_others",
                "max_abs_u_others", "classification", "t_end"}  # fmt: skip
    assert required <= set(data)
    assert data["turns_completed"] == 8 and data["classification"] == "rotation_with_large_motion"
    assert data["thresholds"] == {"phi": diag.SMALL_ANGLE, "u_over_h": diag.SMALL_DISPLACEMENT, "v_over_h": diag.SMALL_DISPLACEMENT}
    assert data["outside_model_validity"] == ["v_over_h"] and data["max_abs_v_others_over_h"] > diag.SMALL_DISPLACEMENT
    text = runner.invoke(app, ["rotate", "--model", "sine", "--moment", "0.3", "--turns", "8"])
    assert text.exit_code == 0 and f"|u|, |v| <= {diag.SMALL_DISPLACEMENT:g} h" in text.stdout and "v_over_h" in text.stdout
    assert (tmp_path / "rot.checkpoint.nc").exists() and read_dataset(out).attrs["turns_completed"] == 8
    more = runner.invoke(app, [*args[:6], "12", *args[7:], "--resume"])
    assert more.exit_code == 0, more.output
    assert json.loads(more.stdout)["turns_completed"] == 12
    bad = runner.invoke(app, ["rotate", "--model", "sine", "--moment", "0.3", "--turns", "0"])
    assert bad.exit_code == 2 and "turns" in bad.output


@pytest.mark.slow
@pytest.mark.parametrize("model", ["nonlinear", "sine"])
def test_paper_1500_rotations_turn_no_other_particle(paper, model):
    # The paper's test run (end of Section 4); numbers in docs/localization.md.
    result = localization_run(paper, model, ABOVE[model], turns=1500, t_max=1e5)
    summary = result.as_dict()
    assert summary["turns_completed"] == 1500 and summary["classification"] == "rotation_with_large_motion"
    assert summary["winding"] == {str(k): 1500 if k == 0 else 0 for k in range(-3, 4)}
    assert summary["max_abs_phi_others"] < 1.0


def test_turns_made_faster_than_the_step_can_follow_are_flagged_inaccurate(paper):
    """M = 100 spins the sine model's particle at about 400 rad per unit time: 8.6 rad per default step."""
    fast = localization_run(paper, "sine", 100.0, turns=20, t_max=10.0)
    assert fast.status == Status.INACCURATE and "rad per step" in fast.message
    spin = fast.as_dict()["mean_angular_velocity"]
    suggested = float(fast.message.rsplit("dt <= ", 1)[1])
    assert suggested == pytest.approx(0.5 / spin, rel=1e-2)
    fine = localization_run(paper, "sine", 100.0, turns=20, t_max=10.0, dt=suggested / 2)
    assert fine.status == Status.COMPLETED and fine.as_dict()["turns_completed"] == 20
