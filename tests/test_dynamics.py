"""Damped dynamics: convergence orders, energy balance, relaxation, reference agreement, failures."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse.linalg as spla

import cosserat_chain.numerics.dynamics as dynamics
import cosserat_chain.numerics.engine as engine
from conftest import random_state
from cosserat_chain import ChainParams, moment_load
from cosserat_chain.analysis.energy import energy_budget
from cosserat_chain.loads import Loads, PointLoad, Schedule
from cosserat_chain.models import LINEAR
from cosserat_chain.models.linear import max_frequency
from cosserat_chain.numerics.adaptive import integrate_adaptive
from cosserat_chain.numerics.dynamics import IntegrationError, default_time_step, integrate
from cosserat_chain.numerics.integrators import DEFAULT_OMEGA_DT, METHODS
from cosserat_chain.state import pack, unpack
from cosserat_chain.status import Status

ORDER_TOL = 0.25
UNDAMPED = ChainParams(gamma_u=0.0, gamma_v=0.0, gamma_phi=0.0)


def kicked_start(params):
    """A state with every degree of freedom moving, so that no error term vanishes by symmetry."""
    return random_state(params, 0.05, seed=11), random_state(params, 0.2, seed=12)


@pytest.fixture(scope="module")
def reference_runs():
    params = ChainParams()
    x0, v0 = kicked_start(params)
    return {
        model: integrate_adaptive(params, model, moment_load(0.15), t_end=20.0, x0=x0, v0=v0, n_frames=5, rtol=1e-13, atol=1e-15)
        for model in ("nonlinear", "sine")
    }


@pytest.mark.parametrize("method", list(METHODS.values()), ids=lambda m: m.name)
@pytest.mark.parametrize("model", ["nonlinear", "sine"])
def test_measured_convergence_order_equals_declared(method, model, reference_runs):
    params = ChainParams()
    x0, v0 = kicked_start(params)
    ref = reference_runs[model]
    errors = []
    for dt in (0.04, 0.02, 0.01):
        run = integrate(params, model, moment_load(0.15), t_end=20.0, dt=dt, x0=x0, v0=v0, method=method, n_frames=5)
        np.testing.assert_allclose(run.time, ref.time, atol=1e-9)
        errors.append(np.max(np.abs(run.x - ref.x)))
    orders = np.log2(np.array(errors[:-1]) / np.array(errors[1:]))
    assert np.all(np.abs(orders - method.order) < ORDER_TOL), (errors, orders)


def test_methods_are_symmetric_compositions_summing_to_one():
    for method in METHODS.values():
        assert sum(method.weights) == pytest.approx(1.0, abs=1e-15)
        assert method.weights == tuple(reversed(method.weights))


def test_stability_limits_from_transfer_matrix():
    assert METHODS["verlet"].stability_limit == pytest.approx(2.0, abs=1e-9)
    assert 1.0 < METHODS["yoshida4"].stability_limit < 2.0


@pytest.mark.parametrize("method", list(METHODS.values()), ids=lambda m: m.name)
def test_linear_chain_is_stable_just_below_the_limit_and_blows_up_just_above(method):
    params = UNDAMPED
    K = LINEAR.stiffness(params).toarray()
    inertia = np.tile(params.inertia, params.n_particles - 2)
    omega = np.sqrt(np.max(np.linalg.eigvals(K / inertia[:, None]).real))
    assert omega <= max_frequency(params) * (1 + 1e-12)  # the infinite chain bounds the finite one
    x0 = random_state(params, 0.01, seed=13)
    limit = method.stability_limit / omega
    below = integrate(params, "linear", t_end=3000 * limit, dt=0.98 * limit, x0=x0, method=method, n_frames=3, check_stability=False)
    above = integrate(params, "linear", t_end=30000 * limit, dt=1.02 * limit, x0=x0, method=method, n_frames=3, check_stability=False)
    assert below.ok and np.max(np.abs(below.x[-1])) < 1.0
    assert above.status == "blew_up"


@pytest.mark.parametrize("model", ["nonlinear", "linear"])
def test_undamped_energy_error_is_bounded_without_secular_drift(model):
    x0, v0 = kicked_start(UNDAMPED)
    run = integrate(UNDAMPED, model, t_end=2000.0, dt=0.02, x0=x0, v0=v0, n_frames=1001)
    assert run.steps == 100_000
    budget = energy_budget(UNDAMPED, model, run)
    error = np.abs(budget.balance_error)
    energy0 = budget.kinetic[0] + budget.potential[0]
    early, late = error[1:101].max(), error[-100:].max()
    assert error.max() < 1e-3 * energy0
    assert late < 2.0 * early  # bounded oscillation, not growth


@pytest.mark.parametrize("method", list(METHODS.values()), ids=lambda m: m.name)
@pytest.mark.parametrize("model", ["nonlinear", "linear"])
def test_damped_energy_balance_closes_at_the_declared_order(method, model):
    params = ChainParams()
    x0, v0 = kicked_start(params)
    errors = []
    for dt in (0.04, 0.02):
        run = integrate(params, model, moment_load(0.1), t_end=60.0, dt=dt, x0=x0, v0=v0, method=method, n_frames=61)
        budget = energy_budget(params, model, run)
        assert budget.dissipated[-1] > 0.01 and budget.load_work[-1] > 0.01
        errors.append(np.max(np.abs(budget.balance_error)))
    order = np.log2(errors[0] / errors[1])
    assert abs(order - method.order) < ORDER_TOL, (errors, order)
    assert errors[1] < 1e-3 * budget.dissipated[-1]


def test_damped_linear_chain_relaxes_to_static_solution(paper):
    f = np.zeros((3, paper.n_particles))
    f[2, paper.N] = 0.02
    static = unpack(paper, spla.spsolve(LINEAR.stiffness(paper).tocsc(), pack(paper, f)))
    run = integrate(paper, "linear", moment_load(0.02), t_end=800.0, n_frames=2)
    np.testing.assert_allclose(run.x[-1], static, atol=1e-9)
    assert np.max(np.abs(run.v[-1])) < 1e-9


@pytest.mark.parametrize("model", ["nonlinear", "sine", "linear"])
def test_fixed_step_agrees_with_adaptive_reference(model, paper):
    ref = integrate_adaptive(paper, model, moment_load(0.15), t_end=40.0, n_frames=9, rtol=1e-12, atol=1e-14)
    run = integrate(paper, model, moment_load(0.15), t_end=40.0, dt=0.005, method="yoshida4", n_frames=9)
    np.testing.assert_allclose(run.x, ref.x, atol=1e-8)
    np.testing.assert_allclose(run.dissipated, ref.dissipated, atol=1e-9)
    np.testing.assert_allclose(run.load_work, ref.load_work, atol=1e-9)


def test_time_step_beyond_stability_limit_is_refused(paper):
    with pytest.raises(ValueError, match=r"dt=0\.5 is beyond the stability limit of verlet.*dt must be < 0\.41"):
        integrate(paper, "nonlinear", moment_load(0.1), t_end=10.0, dt=0.5)
    with pytest.raises(ValueError, match="dt must be a finite number > 0, got nan"):
        integrate(paper, "nonlinear", t_end=10.0, dt=float("nan"))
    with pytest.raises(ValueError, match="t_end must be finite"):
        integrate(paper, "nonlinear", t_end=-1.0)
    with pytest.raises(ValueError, match=r"x0\[phi\] of particle 0 is nan"):
        x0 = np.zeros((3, paper.n_particles))
        x0[2, paper.N] = np.nan
        integrate(paper, "nonlinear", t_end=1.0, x0=x0)


def test_blow_up_stops_with_a_clear_message_and_keeps_the_frames(paper):
    dt = 1.5 * 2.0 / max_frequency(paper)
    run = integrate(paper, "nonlinear", moment_load(0.1), t_end=1e4, dt=dt, check_stability=False, n_frames=10001)
    assert run.status == "blew_up"
    assert run.dt <= dt and "smaller time step" in run.message and f"dt={run.dt:g}" in run.message
    assert 0 < len(run.time) and np.all(np.isfinite(run.x)) and run.steps < 1e4 / dt
    with pytest.raises(IntegrationError) as err:
        integrate(paper, "nonlinear", moment_load(0.1), t_end=1e4, dt=dt, check_stability=False, throw=True)
    assert err.value.trajectory.status == "blew_up"


def test_results_do_not_depend_on_chunking_or_threads(paper, monkeypatch):
    params = paper.replace(N=40)
    x0, v0 = kicked_start(params)
    kwargs = dict(t_end=50.0, dt=0.02, x0=x0, v0=v0, n_frames=26)
    whole = integrate(params, "nonlinear", moment_load(0.2), **kwargs)
    monkeypatch.setattr(dynamics, "CHUNK_WORK", 81 * 7)
    chunked = integrate(params, "nonlinear", moment_load(0.2), **kwargs)
    threaded = integrate(params, "nonlinear", moment_load(0.2), threads=2, **kwargs)
    np.testing.assert_array_equal(chunked.x, whole.x)
    np.testing.assert_array_equal(chunked.time, whole.time)
    np.testing.assert_array_equal(threaded.x, whole.x)
    np.testing.assert_allclose(threaded.dissipated, whole.dissipated, rtol=1e-12)


@pytest.mark.parametrize("method", ["verlet", "yoshida4"])
def test_a_long_chain_on_two_threads_gives_the_states_of_one_bit_for_bit(method, monkeypatch):
    # Long enough for several blocks with halos, which meet only every few steps;
    # loads inside blocks, in halos and on a block edge, one of them scheduled.
    params = ChainParams(N=1500, a=0.3, E2=0.7)
    x0, v0 = kicked_start(params)
    loads = Loads(
        (
            PointLoad("phi", 0, Schedule.ramp(0.3, 5.0)),
            PointLoad("v", 1200, Schedule.constant(0.01)),
            PointLoad("u", -1499, Schedule.constant(0.02)),
        )
    )
    kwargs = dict(t_end=12.0, x0=x0, v0=v0, n_frames=7, method=method)
    one = integrate(params, "nonlinear", loads, **kwargs)
    # Several compiled calls (chunks) per run, each of several exchanges of halos.
    monkeypatch.setattr(dynamics, "CHUNK_WORK", 3001 * 150)
    two = integrate(params, "nonlinear", loads, threads=2, **kwargs)
    assert one.ok and two.ok
    np.testing.assert_array_equal(two.x, one.x)
    np.testing.assert_array_equal(two.v, one.v)
    # The energy sums are added up in another order: equal to round-off.
    np.testing.assert_allclose(two.load_work, one.load_work, rtol=1e-12, atol=1e-15)
    np.testing.assert_allclose(two.dissipated, one.dissipated, rtol=1e-12, atol=1e-15)


@pytest.mark.parametrize("model", ["nonlinear", "sine", "linear"])
def test_a_chain_too_long_for_the_cache_runs_as_blocks_on_one_thread_with_the_same_bits(model, monkeypatch):
    # The thresholds scaled down (2^18 and 2^15 columns in earnest), so that a chain of 3001
    # columns splits: 10 blocks on one thread and on two, a pinned and a free end, with loads.
    params = ChainParams(N=1500, a=0.27, b=0.12, E1=1.3, E2=0.6, left_end="pinned", right_end="free")
    x0, v0 = kicked_start(params)
    loads = Loads((PointLoad("phi", 0, Schedule.ramp(0.3, 5.0)), PointLoad("v", 700, Schedule.constant(0.01))))
    kwargs = dict(t_end=6.0, x0=x0, v0=v0, n_frames=5)
    whole = integrate(params, model, loads, **kwargs)
    monkeypatch.setattr(engine, "SPLIT_COLUMNS", 3000)
    monkeypatch.setattr(engine, "CACHE_COLUMNS", 300)
    assert engine.Blocks.count(params.n_particles, 1, 1) == engine.Blocks.count(params.n_particles, 2, 1) == 10
    one = integrate(params, model, loads, **kwargs)
    two = integrate(params, model, loads, threads=2, **kwargs)
    assert whole.ok and one.ok and two.ok
    np.testing.assert_array_equal(one.x, whole.x)
    np.testing.assert_array_equal(one.v, whole.v)
    np.testing.assert_allclose(one.dissipated, whole.dissipated, rtol=1e-12, atol=1e-15)
    assert not np.array_equal(one.dissipated, whole.dissipated)  # summed block by block: it did split
    # Split alike on one thread and on two: the sums too are the same bits.
    for name in ("x", "v", "load_work", "dissipated"):
        np.testing.assert_array_equal(getattr(two, name), getattr(one, name))


def test_a_blow_up_in_blocks_is_reported_at_its_first_bad_step(monkeypatch):
    """A chain split into blocks that blows up: the chunk is rerun unsplit and stops at the same first bad state."""
    params = ChainParams(N=600)
    dt = 30 * default_time_step(params)  # far beyond the stability limit
    kwargs = dict(t_end=2000 * dt, dt=dt, stride=1, check_stability=False)
    whole = integrate(params, "nonlinear", moment_load(0.1), **kwargs)
    monkeypatch.setattr(engine, "SPLIT_COLUMNS", 1200)
    monkeypatch.setattr(engine, "CACHE_COLUMNS", 300)
    assert engine.Blocks.count(params.n_particles, 1, 1) == 4
    split = integrate(params, "nonlinear", moment_load(0.1), **kwargs)
    assert whole.status == split.status == Status.BLEW_UP and 1 < split.steps < 1024
    assert split.steps == whole.steps and split.message == whole.message
    assert f"step {split.steps}, the first state out of bounds" in split.message
    np.testing.assert_array_equal(split.x, whole.x)


def test_stride_keeps_first_last_and_every_kth_step(paper):
    run = integrate(paper, "linear", moment_load(0.1), t_end=1.0, dt=0.1, stride=3)
    np.testing.assert_allclose(run.time, [0.0, 0.3, 0.6, 0.9, 1.0])
    assert run.steps == 10 and run.x.shape == (5, 3, paper.n_particles)


def test_ctrl_c_between_chunks_keeps_what_was_computed(paper, monkeypatch):
    monkeypatch.setattr(dynamics, "CHUNK_WORK", 7 * 1000)

    def interrupt(done, total):
        if done >= 3000:
            raise KeyboardInterrupt

    run = integrate(paper, "nonlinear", moment_load(0.1), t_end=200.0, dt=0.02, stride=100, progress=interrupt)
    assert run.status == "interrupted" and run.steps == 3000
    assert run.time[-1] == pytest.approx(60.0) and np.all(np.isfinite(run.x))


def test_the_default_step_is_inside_every_methods_stability_limit():
    # integrate and the batches skip the stability check for the default step on this ground.
    for method in METHODS.values():
        assert DEFAULT_OMEGA_DT < 0.5 * method.stability_limit


@pytest.mark.parametrize("moment", [0.4, -0.4])
def test_a_run_that_follows_turns_stops_at_the_step_completing_the_asked_turn(paper, moment):
    loads = moment_load(moment)
    sense = np.sign(moment)
    whole = integrate(paper, "sine", loads, t_end=40.0, stride=1)
    winding = sense * whole.x[:, 2, paper.N] / (2 * np.pi)
    first = int(np.argmax(winding >= 5))
    assert first > 0 and winding[first - 1] < 5
    stopped = integrate(paper, "sine", loads, t_end=40.0, stride=1, turns=dynamics.TurnWatch(0, sense, stop_after=5, keep=3))
    assert stopped.ok and stopped.steps == first and stopped.turns.made == 5
    # The same steps as the run that went on: the states up to there agree bit for bit.
    np.testing.assert_array_equal(stopped.x, whole.x[: first + 1])
    np.testing.assert_array_equal(stopped.v[-1], whole.v[first])
    # The ring keeps the latest three turns, each interpolated between the steps around it ...
    times, made = stopped.turns.times, engine.turns_in_frames(whole.time, whole.x[:, 2, paper.N], sense, 0.0, 0)[0]
    steps = [int(np.argmax(winding >= n)) for n in (3, 4, 5)]
    expected = [whole.time[k - 1] + (n - winding[k - 1]) / (winding[k] - winding[k - 1]) * whole.dt for n, k in zip((3, 4, 5), steps)]
    np.testing.assert_allclose(times, expected, rtol=1e-12)
    np.testing.assert_allclose(stopped.turns.step_times, whole.time[steps], rtol=1e-12)
    np.testing.assert_array_equal(stopped.turns.phi, whole.x[steps, 2])
    # ... and the detector on stored frames finds the same turns as the one in the loop.
    _, frame_times = engine.turns_in_frames(whole.time[: first + 1], whole.x[: first + 1, 2, paper.N], sense, 0.0, 0)
    assert frame_times.size == 5 and made == int(np.floor(winding.max()))
    np.testing.assert_allclose(frame_times[2:], times, rtol=1e-12)


def test_following_turns_goes_on_counting_across_runs(paper):
    loads = moment_load(0.4)
    dt = 0.01  # a whole number of steps in both parts: the same steps as the whole run (to round-off:
    # a run closes its last step, where the whole run fuses closing and opening)
    whole = integrate(paper, "sine", loads, t_end=30.0, dt=dt, turns=dynamics.TurnWatch(0, keep=64))
    first = integrate(paper, "sine", loads, t_end=12.0, dt=dt, turns=dynamics.TurnWatch(0, keep=64))
    second = integrate(paper, "sine", loads, t0=12.0, t_end=30.0, dt=dt, x0=first.x[-1], v0=first.v[-1], turns=first.turns.following())
    np.testing.assert_allclose(second.x[-1], whole.x[-1], rtol=0, atol=1e-9)
    assert second.turns.made == whole.turns.made > first.turns.made > 0
    np.testing.assert_allclose(np.concatenate([first.turns.times, second.turns.times]), whole.turns.times, rtol=1e-9)
    # A swing back and forth over the start is no turn: a chain at rest after a small kick makes none.
    _, v0 = kicked_start(paper)
    rest = integrate(paper, "linear", Loads(), t_end=20.0, v0=v0, turns=dynamics.TurnWatch(0))
    assert rest.turns.made == 0 and rest.turns.times.size == 0


def test_a_turn_watch_is_checked(paper):
    with pytest.raises(ValueError, match="direction must be 1.0 or -1.0"):
        dynamics.TurnWatch(0, direction=2.0)
    with pytest.raises(ValueError, match="stop_after must exceed made=3"):
        dynamics.TurnWatch(0, made=3, stop_after=3)
    with pytest.raises(ValueError, match="keep must be >= 1"):
        dynamics.TurnWatch(0, keep=0)
    with pytest.raises(ValueError, match="particle"):
        integrate(paper, "sine", moment_load(0.4), t_end=1.0, turns=dynamics.TurnWatch(paper.N + 1))


def test_a_blow_up_in_a_later_chunk_is_found_at_the_same_step(monkeypatch):
    """The rerun of a chunk that blew up starts from the frame stored at the chunk's start,
    with the forces and sums saved there: under a ramp (forces that depend on the time), on a
    stride of 5, it finds the step and states of a run in one chunk."""
    params = ChainParams(N=4, a=0.3, E2=0.7)
    dt = 25 * default_time_step(params)  # beyond the stability limit: it grows for some 40 steps
    loads = Loads((PointLoad("phi", 0, Schedule.ramp(0.3, 50 * dt)),))
    kwargs = dict(t_end=2000 * dt, dt=dt, stride=5, check_stability=False)
    whole = integrate(params, "nonlinear", loads, **kwargs)
    monkeypatch.setattr(dynamics, "CHUNK_WORK", params.n_particles * 10)  # chunks of two strides
    chunked = integrate(params, "nonlinear", loads, **kwargs)
    assert whole.status == chunked.status == Status.BLEW_UP and 30 < whole.steps < 1024
    assert chunked.steps == whole.steps and chunked.message == whole.message
    np.testing.assert_array_equal(chunked.x, whole.x)
    np.testing.assert_array_equal(chunked.dissipated, whole.dissipated)


def test_a_blow_up_is_reported_at_its_first_bad_step_not_at_the_periodic_check():
    """The loop checks every 1024 steps; the reported step is the first state out of bounds, found by a rerun of the chunk."""
    params = ChainParams()
    dt = 30 * default_time_step(params)  # far beyond the stability limit
    run = integrate(params, "nonlinear", moment_load(0.1), t_end=2000 * dt, dt=dt, stride=1, check_stability=False)
    assert run.status == Status.BLEW_UP and 1 < run.steps < 1024
    assert f"step {run.steps}, the first state out of bounds" in run.message
    assert run.time[-1] < run.steps * dt and np.isfinite(run.x).all()
    before = integrate(params, "nonlinear", moment_load(0.1), t_end=(run.steps - 1) * dt, dt=dt, stride=1, check_stability=False)
    assert before.status == Status.COMPLETED and before.steps == run.steps - 1
    np.testing.assert_array_equal(before.x, run.x[: before.x.shape[0]])
    at = integrate(params, "nonlinear", moment_load(0.1), t_end=run.steps * dt, dt=dt, stride=1, check_stability=False)
    assert at.status == Status.BLEW_UP and at.steps == run.steps
