"""Loads from config files and the command line (issue 14, item 2): ``[[loads]]`` tables, ``--load``, harmonic drives.

The physics checks: the damped linear chain driven harmonically settles on the analytic
frequency response (K - omega^2 M + i omega Gamma)^-1 F, and the linear model superposes
several loads exactly.
"""

from __future__ import annotations

import json

import numpy as np
import pytest
import scipy.sparse as sp
from typer.testing import CliRunner

from conftest import random_geometries
from cosserat_chain import ChainParams
from cosserat_chain.cli import app
from cosserat_chain.io import load_config
from cosserat_chain.loads import Loads, PointLoad, Schedule, load_from_table, loads_from_tables, parse_load, schedule_value
from cosserat_chain.models import LINEAR
from cosserat_chain.numerics.dynamics import integrate
from cosserat_chain.state import free_index, pack, per_dof

runner = CliRunner()


def test_each_kind_of_table_builds_its_schedule():
    t = np.linspace(-1.0, 30.0, 311)
    cases = [
        ({"value": 0.2}, np.full_like(t, 0.2)),
        ({"kind": "step", "value": 0.3, "at": 5.0, "before": -0.1}, np.where(t < 5.0, -0.1, 0.3)),
        ({"kind": "ramp", "value": 0.4, "duration": 10.0, "start": 2.0}, np.clip((t - 2.0) / 10.0, 0, 1) * 0.4),
        ({"kind": "staircase", "increment": 0.05, "hold": 4.0, "n_steps": 3}, 0.05 * np.clip(np.floor(t / 4.0) + 1, 0, 3) * (t >= 0)),
        (
            {"kind": "harmonic", "amplitude": 0.7, "frequency": 0.3, "phase": 0.4, "offset": 0.1},
            0.1 + 0.7 * np.sin(2 * np.pi * 0.3 * t + 0.4),
        ),
        ({"kind": "knots", "times": [0.0, 10.0, 20.0], "values": [0.0, 1.0, -1.0]}, np.interp(t, [0, 10, 20], [0, 1, -1])),
    ]
    for table, expected in cases:
        load = load_from_table({"row": "phi", "particle": 1, **table})
        assert (load.row, load.particle) == ("phi", 1)
        np.testing.assert_allclose(load.schedule(t), expected, atol=1e-14, err_msg=str(table))


def test_the_compiled_schedule_equals_the_python_one_with_a_harmonic_part():
    schedule = Schedule((0.0, 3.0, 3.0, 8.0), (0.0, 1.0, 2.0, -1.0), amplitude=0.5, frequency=0.7, phase=-1.1)
    knots = np.array(schedule.knots())
    for t in np.linspace(-2.0, 12.0, 57):
        assert schedule_value(knots, 0, knots.shape[0], t) == pytest.approx(schedule(t), abs=1e-15)


@pytest.mark.parametrize(
    ("table", "message"),
    [
        ({"particle": 0, "value": 1.0}, r"loads\[0\] \(kind 'constant'\) lacks row"),
        ({"row": "w", "particle": 0, "value": 1.0}, r"loads\[0\].row must be one of 'u', 'v', 'phi', got 'w'"),
        ({"row": "v", "particle": 0.5, "value": 1.0}, r"loads\[0\].particle must be an integer"),
        ({"row": "v", "particle": 0, "kind": "sawtooth"}, r"loads\[0\].kind must be one of 'constant', 'step'"),
        ({"row": "v", "particle": 0, "kind": "harmonic", "amplitude": 1.0}, r"lacks frequency"),
        ({"row": "v", "particle": 0, "kind": "harmonic", "amplitude": 1.0, "frequency": -2.0}, r"frequency must be >= 0"),
        ({"row": "v", "particle": 0, "value": "1"}, r"loads\[0\].value must be a finite number, got '1'"),
        ({"row": "v", "particle": 0, "value": 1.0, "amplitude": 2.0}, r"unknown key\(s\) \['amplitude'\] in loads\[0\]"),
        ({"row": "v", "particle": 0, "kind": "staircase", "increment": 1.0, "hold": 1.0, "n_steps": 2.5}, "n_steps must be an integer"),
    ],
)
def test_a_bad_table_is_refused_naming_the_table_the_key_and_the_value(table, message):
    with pytest.raises(ValueError, match=message):
        loads_from_tables([table])


def test_the_command_line_load_and_its_errors():
    assert parse_load("v:-2=0.01") == PointLoad("v", -2, Schedule.constant(0.01))
    for text in ("phi0=0.1", "phi:0", "x:0=1", "phi:a=1", "phi:0=nan"):
        with pytest.raises(ValueError, match="--load"):
            parse_load(text)


def test_a_config_holds_the_chain_and_its_loads_checked_against_the_ends(tmp_path):
    path = tmp_path / "c.toml"
    path.write_text('N = 2\nright_end = "free"\n[[loads]]\nrow = "u"\nparticle = 2\nvalue = 0.1\n')
    params, loads = load_config(path)
    assert params.right_end == "free" and loads == Loads([PointLoad("u", 2, Schedule.constant(0.1))])
    path.write_text('N = 2\n[[loads]]\nrow = "u"\nparticle = 2\nvalue = 0.1\n')
    with pytest.raises(ValueError, match="the right end is clamped"):
        load_config(path)


def test_simulate_takes_config_loads_and_load_options_and_keeps_moment_as_the_shorthand(tmp_path):
    path = tmp_path / "c.toml"
    path.write_text('N = 2\n[[loads]]\nrow = "v"\nparticle = 1\nkind = "harmonic"\namplitude = 0.01\nfrequency = 0.1\n')
    result = runner.invoke(app, ["simulate", "--config", str(path), "--load", "u:-1=0.02", "--t-end", "5", "--json"])
    assert result.exit_code == 0, result.output
    loads = json.loads(result.output)["loads"]
    assert [(d["row"], d["particle"]) for d in loads] == [("v", 1), ("u", -1)]  # no moment unless asked
    result = runner.invoke(app, ["simulate", "--config", str(path), "--moment", "0.05", "--t-end", "5", "--json"])
    assert [(d["row"], d["particle"]) for d in json.loads(result.output)["loads"]] == [("phi", 0), ("v", 1)]
    result = runner.invoke(app, ["simulate", "--t-end", "5", "--json"])
    assert json.loads(result.output)["loads"] == [{"row": "phi", "particle": 0, "times": [0.0], "values": [0.1]}]
    result = runner.invoke(app, ["simulate", "--load", "v:3=0.1", "--t-end", "5"])
    assert result.exit_code == 2 and "the right end is clamped" in result.output


@pytest.mark.parametrize(
    "params", [ChainParams(N=3), random_geometries(1, seed=21)[0].replace(N=4, left_end="pinned")], ids=["paper", "pinned"]
)
def test_a_harmonic_force_settles_on_the_analytic_frequency_response(params):
    omega = 1.3
    frequency = omega / (2 * np.pi)
    loads = Loads(
        [PointLoad("v", 1, Schedule.harmonic(0.01, frequency)), PointLoad("phi", -1, Schedule.harmonic(0.004, frequency, phase=0.5))]
    )
    # The slowest mode decays like exp(-gamma t / (2 m)): t = 600 leaves 1e-13 of the transient.
    run = integrate(params, "linear", loads, t_end=600.0, dt=0.005, method="yoshida4", n_frames=6001)
    K = LINEAR.stiffness(params).toarray()
    M = np.diag(per_dof(params, params.inertia))
    G = np.diag(per_dof(params, params.damping))
    # F(t) = Im(F e^{i omega t}) with complex amplitudes amplitude e^{i phase}.
    force = np.zeros((3, params.n_particles), dtype=complex)
    force[1, params.N + 1] = 0.01
    force[2, params.N - 1] = 0.004 * np.exp(0.5j)
    response = np.linalg.solve(K - omega**2 * M + 1j * omega * G, pack(params, force.real) + 1j * pack(params, force.imag))
    late = run.time > 550.0
    expected = np.imag(response[None, :] * np.exp(1j * omega * run.time[late])[:, None])
    got = run.x[late].transpose(0, 2, 1).reshape(late.sum(), -1)[:, free_index(params)]
    np.testing.assert_allclose(got, expected, atol=1e-6 * np.abs(response).max())


def test_the_linear_model_superposes_several_loads_exactly():
    params = random_geometries(1, seed=22)[0].replace(N=5, right_end="free")
    a = Loads([PointLoad("phi", 0, Schedule.ramp(0.05, 10.0)), PointLoad("u", 5, Schedule.harmonic(0.01, 0.3))])
    b = Loads([PointLoad("v", -2, Schedule.step(0.02, at=3.0)), PointLoad("phi", 5, Schedule.constant(-0.01))])
    runs = [integrate(params, "linear", loads, t_end=40.0, dt=0.01, n_frames=5) for loads in (a, b, Loads([*a, *b]))]
    np.testing.assert_allclose(runs[2].x, runs[0].x + runs[1].x, rtol=0, atol=1e-13)
    assert sp.issparse(LINEAR.stiffness(params))


def test_relaxation_under_a_moment_and_a_constant_force_comes_to_the_static_state_of_both():
    from cosserat_chain.experiments.sweep import relaxation_sweep
    from cosserat_chain.numerics.newton import solve_equilibrium
    from cosserat_chain.numerics.relaxation import relax

    params = random_geometries(1, seed=23)[0].replace(N=3, right_end="free")
    push = Loads([PointLoad("u", 3, Schedule.constant(-0.02)), PointLoad("v", 2, Schedule.constant(0.005))])
    step = relax(params, "nonlinear", 0.03, loads=push)
    assert step.status == "static"
    static = solve_equilibrium(params, "nonlinear", Loads([PointLoad("phi", 0, Schedule.constant(0.03)), *push]))
    np.testing.assert_allclose(step.x, static, atol=1e-7)
    sweep = relaxation_sweep(params, "nonlinear", m_max=0.03, steps=1, loads=push)
    np.testing.assert_allclose(sweep.x[-1], static, atol=1e-7)
    assert sweep.as_dict()["extra_loads"] == push.to_list()
    assert json.loads(sweep.to_dataset().attrs["loads_json"]) == push.to_list()
    with pytest.raises(ValueError, match="needs constant extra loads .* on v of particle 2"):
        relax(params, "nonlinear", 0.03, loads=Loads([PointLoad("v", 2, Schedule.harmonic(0.01, 0.1))]))


def test_sweep_and_rotate_take_load_options(tmp_path):
    result = runner.invoke(app, ["sweep", "--model", "sine", "--m-max", "0.05", "--steps", "1", "--load", "v:1=0.001", "--json"])
    assert result.exit_code == 0, result.output
    assert json.loads(result.output)["models"]["sine"]["extra_loads"] == [{"row": "v", "particle": 1, "times": [0.0], "values": [0.001]}]
    result = runner.invoke(app, ["sweep", "--m-max", "0.05", "--steps", "1", "--load", "v:1=0.001", "--plot", str(tmp_path / "f.png")])
    assert result.exit_code == 2 and "--plot" in result.output
    out = tmp_path / "r.nc"
    args = ["rotate", "--moment", "0.3", "--turns", "1", "--out", str(out), "--checkpoint-every", "0"]
    result = runner.invoke(app, [*args, "--load", "u:1=0.001", "--json"])
    assert result.exit_code == 0, result.output
    from cosserat_chain.io import read_dataset

    assert [(d["row"], d["particle"]) for d in json.loads(read_dataset(out).attrs["loads_json"])] == [("phi", 0), ("u", 1)]
    result = runner.invoke(app, [*args, "--turns", "2", "--resume", "--load", "u:1=0.002"])
    assert result.exit_code == 2 and "loads_json" in result.output
