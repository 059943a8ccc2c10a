"""Coexisting states at one moment (experiments/coexisting.py, ``cosserat-chain states``; issue 13, item 4)."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
import scipy.integrate as si
import scipy.linalg as la
from typer.testing import CliRunner

from conftest import ROUND_OFF
from cosserat_chain import ChainParams
from cosserat_chain.cli import app
from cosserat_chain.experiments.coexisting import states_at
from cosserat_chain.loads import moment_load
from cosserat_chain.models.base import get_model
from cosserat_chain.numerics.continuation import locate_fold
from cosserat_chain.numerics.dynamics import TurnWatch, integrate
from cosserat_chain.numerics.newton import moment_dof
from cosserat_chain.numerics.stability import damped_dynamics_matrix, static_stability
from cosserat_chain.state import ROW_INDEX, column, n_free, pack, unpack

runner = CliRunner()
#: Closure of a listed orbit after its period, recomputed here.
CLOSURE = 1e-8
#: The sine chain's two rotating states at M = 0.22 (docs/periodic-orbits.md).
RATE_ONE_TURN = 0.6620020054
RATE_TWO_TURNS = 1.2387873428


@pytest.fixture(scope="module")
def at_022():
    return states_at(ChainParams(), "sine", 0.22, random_starts=4, t_long=3000.0)


def _dense_stable(params, model, x) -> bool:
    """Stable iff every eigenvalue of the damped dynamics linearised at x has a negative real part (dense)."""
    k = get_model(model).stiffness(params, x).toarray()
    return bool(np.max(la.eigvals(damped_dynamics_matrix(params, k)).real) < 0.0)


@pytest.mark.parametrize("model, moment", [("sine", 0.18), ("nonlinear", 0.15)])
def test_every_static_state_solves_the_equilibrium_to_round_off_and_its_stability_agrees_with_the_dense_spectrum(model, moment):
    params = ChainParams()
    result = states_at(params, model, moment, starts=("rest",), turns=(1,))
    assert len(result.static) == 2  # below the fold: the state from rest and the saddle beyond the fold
    m = get_model(model)
    for state in result.static:
        forces = m.compiled_forces(params, state.x)
        forces[ROW_INDEX["phi"], column(params, 0)] += moment
        residual = float(np.max(np.abs(pack(params, forces))))
        assert residual < ROUND_OFF and state.residual == pytest.approx(residual, abs=ROUND_OFF)
        assert (
            state.stability.stable == _dense_stable(params, model, state.x) == static_stability(params, model, state.x, dense=True).stable
        )
    assert [s.stability.stable for s in sorted(result.static, key=lambda s: s.phi0)] == [True, False]
    # A sudden load from rest overshoots: the sine chain at 0.18 rotates although a stable static state exists.
    assert result.from_rest.reached in ("static", "orbit") and result.from_rest.index is not None


def test_every_orbit_listed_closes_after_its_period_and_turns_at_2pi_k_over_T(at_022):
    assert len(at_022.orbits) == 2
    for found in at_022.orbits:
        o = found.orbit
        x, v = o.trajectory(np.array([o.period]))
        shifted = x[0].copy()
        shifted[ROW_INDEX["phi"], column(o.params, 0)] -= 2 * math.pi * o.turns
        assert max(np.max(np.abs(shifted - o.x)), np.max(np.abs(v[0] - o.v))) < CLOSURE
        assert o.mean_angular_velocity == pytest.approx(2 * math.pi * o.turns / o.period, rel=1e-15)
        # Listed with its least turns: after fewer turns it has not closed.
        for j in range(1, o.turns):
            xj, vj = o.trajectory(np.array([o.period * j / o.turns]))
            assert np.max(np.abs(vj[0] - o.v)) > 1e-3
    by_turns = {f.orbit.turns: f.orbit for f in at_022.orbits}
    assert by_turns[1].mean_angular_velocity == pytest.approx(RATE_ONE_TURN, rel=1e-9)
    assert by_turns[2].mean_angular_velocity == pytest.approx(RATE_TWO_TURNS, rel=1e-9)
    assert by_turns[1].stable and by_turns[2].stable


def test_shooting_with_two_and_three_turns_from_rest_finds_the_one_turn_orbit_once(at_022):
    one = next(f for f in at_022.orbits if f.orbit.turns == 1)
    assert {"shooting from rest, 1 turn(s)", "shooting from rest, 2 turn(s)", "shooting from rest, 3 turn(s)", "rest"} <= set(
        one.found_from
    )
    assert not at_022.static and not at_022.irregular
    assert all(run.reached == "orbit" for run in at_022.runs)


def test_the_rest_protocol_settles_on_the_one_turn_orbit_and_its_fixed_time_window_spread_is_the_orbits_own(at_022):
    """The 'modulated' rotation from rest (window rates 0.652-0.668) is the 1-turn orbit seen through windows of fixed time."""
    rest = at_022.orbits[at_022.from_rest.index].orbit
    assert at_022.from_rest.reached == "orbit" and rest.turns == 1
    params, col = ChainParams(), column(ChainParams(), 0)
    run = integrate(params, "sine", moment_load(0.22), t_end=3000.0, n_frames=3001, method="yoshida4", turns=TurnWatch(0, keep=1000))
    t, phi = run.time, run.x[:, ROW_INDEX["phi"], col]
    w = int(round(500.0 / (t[1] - t[0])))
    starts = np.arange(len(t) // 3, len(t) - w)
    rates = (phi[starts + w] - phi[starts]) / (t[starts + w] - t[starts])
    s = np.linspace(0.0, rest.period, 2001)
    p = np.concatenate([[0.0], rest.trajectory(s[1:])[0][:, ROW_INDEX["phi"], col]]) - rest.mean_angular_velocity * s
    width = float(t[w] - t[0])
    shift = np.interp((s + width) % rest.period, s, p) - p
    assert rates.min() == pytest.approx(rest.mean_angular_velocity + shift.min() / width, abs=2e-4)
    assert rates.max() == pytest.approx(rest.mean_angular_velocity + shift.max() / width, abs=2e-4)
    assert np.ptp(rates) > 0.01  # the spread the issue saw
    turns = run.turns.times
    whole = 2 * math.pi * 12 / (turns[12:] - turns[:-12])
    assert np.ptp(whole[len(whole) // 3 :]) < 1e-5 * RATE_ONE_TURN  # over whole turns: no modulation


@pytest.mark.parametrize("moment", [0.05, 0.5, 3.0, -0.4])
def test_the_linear_model_has_exactly_one_static_state_and_no_orbit(moment):
    params = ChainParams()
    result = states_at(params, "linear", moment)
    assert len(result.static) == 1 and not result.orbits and not result.irregular
    k = get_model("linear").stiffness(params, np.zeros((3, params.n_particles))).toarray()
    e = np.zeros(n_free(params))
    e[moment_dof(params, 0)] = 1.0
    np.testing.assert_allclose(result.static[0].x, unpack(params, np.linalg.solve(k, moment * e)), atol=ROUND_OFF * (1 + abs(moment)))
    assert result.static[0].stability.stable and result.from_rest.reached == "static" and result.from_rest.index == 0


def _pendulum_period(j: float, gamma: float, c: float, moment: float) -> float:
    """Period of the rotation of j phi'' + gamma phi' + c sin phi = M, from a settled run (SciPy's DOP853: the transient
    decays like exp(-gamma t / j), below round-off long before t = 100)."""

    def crossing(t, y):
        return math.sin(0.5 * y[0])  # zero at every multiple of 2 pi

    crossing.direction = 0
    sol = si.solve_ivp(lambda t, y: [y[1], (moment - c * math.sin(y[0]) - gamma * y[1]) / j], (0, 100), [0.0, 0.0],
                       events=crossing, rtol=1e-12, atol=1e-12, method="DOP853")  # fmt: skip
    times = sol.t_events[0]
    return float(times[-1] - times[-2])


def test_with_one_particle_the_sine_chain_is_a_damped_driven_pendulum():
    params = ChainParams(N=1)
    fold = locate_fold(params, "sine")
    c = fold.moment  # the sine model's phi equation is j phi'' + gamma_phi phi' + c sin phi = M (u, v decouple)
    assert fold.phi0 == pytest.approx(math.pi / 2, abs=1e-9)
    # The pendulum's runs settle within a few hundred time units (decay time j / gamma_phi); below the fold the one-turn
    # search stands for every k (each k's search from rest settles to the same static state).
    below = states_at(params, "sine", 0.3 * c, turns=(1,), random_starts=4, t_long=500.0)
    phi0 = sorted(s.phi0 for s in below.static)
    assert phi0 == pytest.approx([math.asin(0.3), math.pi - math.asin(0.3)], abs=1e-10)
    stable = {round(s.phi0, 6): (s.stability.stable, s.stability.index) for s in below.static}
    assert stable[round(phi0[0], 6)] == (True, 0) and stable[round(phi0[1], 6)] == (False, 1)
    assert not below.orbits and not below.irregular and all(r.reached == "static" and r.index is not None for r in below.runs)
    above = states_at(params, "sine", 1.3 * c, random_starts=4, t_long=500.0)
    assert not above.static and not above.irregular and len(above.orbits) == 1
    orbit = above.orbits[0].orbit
    assert orbit.turns == 1 and orbit.stable and above.from_rest.reached == "orbit"
    assert orbit.period == pytest.approx(_pendulum_period(params.j, params.gamma_phi, c, 1.3 * c), rel=1e-8)


@pytest.mark.parametrize(
    "kwargs, word",
    [
        ({"moment": math.nan}, "moment"),
        ({"starts": ("bogus",)}, "starts"),
        ({"turns": (0,)}, "turns"),
        ({"t_long": -1.0}, "t_long"),
        ({"window_turns": 0}, "window_turns"),
        ({"random_starts": -1}, "random_starts"),
        ({"particle": 9}, "particle"),
    ],
)
def test_bad_input_is_refused_naming_the_argument(kwargs, word):
    arguments = {"moment": 0.22, **kwargs}
    with pytest.raises(ValueError, match=word):
        states_at(ChainParams(), "sine", arguments.pop("moment"), **arguments)


def test_states_command_prints_json_with_every_state_and_the_rest_outcome():
    result = runner.invoke(app, ["states", "--model", "sine", "--moment", "0.22", "--random-starts", "0", "--t-long", "1000", "--json"])
    assert result.exit_code == 0, result.output
    data = json.loads(result.stdout)
    assert {"params", "model", "moment", "static", "orbits", "irregular", "runs", "from_rest", "status"} <= set(data)
    assert data["from_rest"]["reached"] == "orbit" and data["from_rest"]["relaxation"]["status"] == "rotating"
    one = data["orbits"][data["from_rest"]["index"]]
    assert one["turns"] == 1 and one["stable"] and one["mean_angular_velocity"] == pytest.approx(RATE_ONE_TURN, rel=1e-9)


@pytest.mark.parametrize(
    "extra, option",
    [(["--moment", "nan"], "--moment"), (["--moment", "0.2", "--turns", "0"], "--turns"), (["--moment", "0.2", "--t-long", "0"], "--t-long"),
     (["--moment", "0.2", "--particle", "9"], "--particle"), (["--moment", "0.2", "--random-starts", "-1"], "--random-starts"),
     (["--moment", "0.2", "--model", "bogus"], "--model")],
)  # fmt: skip
def test_states_command_refuses_bad_options_with_exit_2_naming_them(extra, option):
    result = runner.invoke(app, ["states", *extra])
    assert result.exit_code == 2
    assert option in result.output


def test_states_command_refuses_loads_in_the_config(tmp_path):
    config = tmp_path / "c.toml"
    config.write_text('[[loads]]\nrow = "u"\nparticle = 1\nvalue = 0.01\n')
    result = runner.invoke(app, ["states", "--moment", "0.2", "--config", str(config)])
    assert result.exit_code == 2 and "--config" in result.output
