"""Angles never overflow: a particle ten million turns out moves as one near zero, to the last bit.

The engine keeps a rotating model's angles as whole turns (int64) plus an angle below
``trig.WRAP_ANGLE``; these tests start particles far out (where the old range reduction,
valid below 1e6 rad, stopped every run as a false blow-up) and check the motion against
the same start reduced by whole turns, the reduction against exact rational arithmetic,
the turn counts, restarts and checkpoints across the wraps, and the blow-up messages.
"""

from __future__ import annotations

import math
from fractions import Fraction

import numpy as np
import pytest

from cosserat_chain import ChainParams, moment_load
from cosserat_chain.experiments import simulation
from cosserat_chain.models.trig import MAX_START_ANGLE, WRAP_ANGLE, join_turns, split_turns
from cosserat_chain.numerics import dynamics
from cosserat_chain.numerics.batch import integrate_batch
from cosserat_chain.numerics.dynamics import TurnWatch, integrate
from cosserat_chain.numerics.engine import MAX_ROTATION_PER_STEP, WRAP_EVERY

TURNS = 2_000_000  # 2 pi 2e6 = 1.26e7 rad: beyond the old limit of 1e6 rad by a factor 12
#: 2 pi to 100 digits (exact reference for the reduction).
TWO_PI = 2 * Fraction("3.141592653589793238462643383279502884197169399375105820974944592307816406286208998628034825342117068")


def _start(params: ChainParams, offsets: dict[int, float]) -> tuple[np.ndarray, np.ndarray]:
    """A moving start: angles phi0[k] = 0.2 k + offset of column k, random small velocities."""
    rng = np.random.default_rng(7)
    x0 = np.zeros((3, params.n_particles))
    x0[2] = 0.2 * np.arange(params.n_particles)
    for col, offset in offsets.items():
        x0[2, col] += offset
    v0 = 0.05 * rng.standard_normal((3, params.n_particles))
    v0[2] += 2.0
    x0[:, [0, -1]] = v0[:, [0, -1]] = 0.0  # the clamped ends
    return x0, v0


def test_split_turns_agrees_with_exact_arithmetic_at_every_magnitude():
    rng = np.random.default_rng(1)
    angles = np.concatenate(
        [rng.uniform(-1e3, 1e3, 50), rng.uniform(-1e8, 1e8, 50), rng.uniform(-1e15, 1e15, 50), [MAX_START_ANGLE, -MAX_START_ANGLE]]
    )
    reduced, turns = split_turns(angles)
    for angle, r, k in zip(angles, reduced, turns):
        exact = Fraction(float(angle)) - int(k) * TWO_PI
        assert abs(float(exact)) <= (math.pi + 1e-15 if abs(angle) > WRAP_ANGLE else WRAP_ANGLE)
        assert r == float(exact)  # one rounding: the nearest double
    small = np.array([0.0, -3.0, WRAP_ANGLE, -WRAP_ANGLE])
    kept, none = split_turns(small)
    assert np.array_equal(kept, small) and not none.any()  # within the wrap limit: untouched


def test_split_turns_refuses_angles_no_double_locates_within_a_turn():
    with pytest.raises(ValueError, match=r"x0 phi.*1e\+17.*within \+-9\.007e\+15 rad"):
        split_turns(np.array([1e17]), "x0 phi")
    with pytest.raises(ValueError, match="must be finite"):
        split_turns(np.array([math.nan]))


def test_join_turns_is_the_nearest_double_of_the_exact_angle():
    reduced, turns = np.array([0.1, -3.0, 2.5]), np.array([0, 10**6, -(10**9)])
    joined = join_turns(reduced, turns)
    for r, k, j in zip(reduced, turns, joined):
        exact = Fraction(float(r)) + int(k) * TWO_PI
        assert abs(Fraction(float(j)) - exact) <= Fraction(abs(np.spacing(j))) / 2 * Fraction(1001, 1000)


@pytest.mark.parametrize("model", ["nonlinear", "sine"])
def test_a_particle_ten_million_turns_out_moves_as_one_near_zero(model):
    """Started at 2 pi 2e6 + a (and one at -2 pi 5e6 + b): the run is bit for bit the run from a (and b)."""
    params = ChainParams(N=3)
    far, _ = _start(params, {3: 2 * math.pi * TURNS, 5: -2 * math.pi * 5 * TURNS})
    near = far.copy()
    near[2], k0 = split_turns(far[2])
    assert k0[3] == TURNS and k0[5] == -5 * TURNS
    _, v0 = _start(params, {})
    loads = moment_load(0.3, 0)
    run_far = integrate(params, model, loads, t_end=200.0, x0=far, v0=v0, n_frames=11, throw=True)
    run_near = integrate(params, model, loads, t_end=200.0, x0=near, v0=v0, n_frames=11, throw=True)
    # The same motion to the last bit: displacements, velocities, energies, the angles less their turns.
    assert np.array_equal(run_far.x[1:, :2], run_near.x[1:, :2]) and np.array_equal(run_far.v, run_near.v)
    assert np.array_equal(run_far.reduced_phi[1:], run_near.reduced_phi[1:])
    assert np.array_equal(run_far.load_work, run_near.load_work) and np.array_equal(run_far.dissipated, run_near.dissipated)
    assert np.array_equal(run_far.winding[1:] - run_near.winding[1:], np.broadcast_to(k0, run_far.winding[1:].shape))
    # The particles did turn (the loaded one by about 60 rad), and the unwrapped doubles show it to their last bits.
    assert run_near.x[-1, 2, 3] - run_near.x[0, 2, 3] > 50
    turned_far = run_far.x[:, 2] - run_far.x[0, 2]
    turned_near = run_near.x[:, 2] - run_near.x[0, 2]
    # (Each unwrapped double is rounded once, to 7.5e-9 at 6.3e7 rad.)
    assert np.allclose(turned_far, turned_near, rtol=1e-9, atol=abs(np.spacing(far[2, 5])))
    # Frame 0 is the start as given.
    assert np.array_equal(run_far.x[0], far) and not run_far.winding[0].any()


def test_angles_wrap_in_the_loop_and_keep_the_motion():
    """A spinning chain passes WRAP_ANGLE many times: the angles stay small, the turns exact, the motion as without wraps."""
    params = ChainParams(N=3)
    x0, v0 = _start(params, {})
    # M / gamma_phi = 20 rad per unit time: some 0.4 rad a step, 64 rad in 150 steps.
    run = integrate(params, "nonlinear", moment_load(2.0, 0), t_end=60.0, x0=x0, v0=v0, n_frames=201, throw=True)
    assert run.winding[-1, 3] > 20  # the loaded particle wrapped many times
    assert np.abs(run.reduced_phi).max() < WRAP_ANGLE + WRAP_EVERY * 0.5
    exact = run.reduced_phi + 2 * math.pi * run.winding
    assert np.allclose(run.x[:, 2], exact, rtol=1e-15, atol=0)
    # The moment's work counts the unwrapped turning across the wraps (trapezoidal: exact for a constant moment).
    assert run.load_work[-1] == pytest.approx(2.0 * (run.x[-1, 2, 3] - run.x[0, 2, 3]), rel=1e-12)
    assert np.all(np.diff(run.x[:, 2, 3]) > 0)  # no jump back by whole turns
    # The linear model's angles are not periodic: never wrapped.
    far = np.zeros_like(x0)
    far[2, 1:-1] = 100.0
    linear = integrate(params, "linear", t_end=5.0, x0=far, n_frames=3, throw=True)
    assert not linear.winding.any() and np.array_equal(linear.reduced_phi, linear.x[:, 2])


def test_blocks_on_two_threads_wrap_as_one_thread():
    """A chain split into blocks wraps its halos as their owners: the states and windings are one thread's, bit for bit."""
    params = ChainParams(N=300)
    rng = np.random.default_rng(3)
    x0 = np.zeros((3, params.n_particles))
    x0[2, 1:-1] = 60.0 + 0.01 * rng.standard_normal(params.n_particles - 2)
    runs = [integrate(params, "nonlinear", moment_load(2.0, 0), t_end=50.0, x0=x0, n_frames=5, threads=t, throw=True) for t in (1, 2)]
    assert runs[0].winding[-1, 300] > 5 and runs[0].winding[0].any() == runs[0].winding[-1, 0] == 0
    assert np.array_equal(runs[0].x, runs[1].x) and np.array_equal(runs[0].winding, runs[1].winding)


def test_turns_far_out_are_counted_as_near_zero():
    params = ChainParams(N=3)
    far, v0 = _start(params, {3: 2 * math.pi * TURNS})
    near = far.copy()
    near[2] = split_turns(far[2])[0]
    runs = [
        integrate(params, "nonlinear", moment_load(0.3, 0), t_end=200.0, x0=x0, v0=v0, n_frames=3, turns=TurnWatch(0, stop_after=10))
        for x0 in (far, near)
    ]
    assert runs[0].turns.made == runs[1].turns.made == 10
    assert np.array_equal(runs[0].turns.times, runs[1].turns.times)
    assert runs[0].time[-1] == runs[1].time[-1] < 200.0


def test_a_run_resumed_from_its_checkpoint_keeps_the_turns_bit_for_bit(monkeypatch, tmp_path):
    """The checkpoint carries the windings: a run interrupted past many wraps and resumed gives the whole run's bits."""
    params = ChainParams(N=3)
    x0, v0 = _start(params, {3: 2 * math.pi * TURNS})
    monkeypatch.setattr(dynamics, "CHUNK_WORK", 7 * 640)  # chunks of 640 steps
    kwargs = dict(t_end=60.0, x0=x0, v0=v0, n_frames=21)
    whole = simulation.simulate(params, "nonlinear", moment_load(2.0, 0), **kwargs)

    def stop(done, total):
        if done > total // 2:
            raise KeyboardInterrupt

    path = tmp_path / "run.nc"
    cut = simulation.simulate(params, "nonlinear", moment_load(2.0, 0), checkpoint=path, checkpoint_every=0, progress=stop, **kwargs)
    assert cut.attrs["status"] == "interrupted"
    resumed = simulation.simulate(params, "nonlinear", moment_load(2.0, 0), checkpoint=path, resume=True, **kwargs)
    assert resumed.attrs["status"] == whole.attrs["status"]
    assert int(resumed.phi_winding[-1, 3]) > 20
    for name in ("phi", "phi_reduced", "phi_winding", "u", "phi_dot"):
        assert np.array_equal(resumed[name].values, whole[name].values), name


def test_a_batch_member_far_out_records_the_same_turning():
    params = ChainParams(N=3)
    far, v0 = _start(params, {3: 2 * math.pi * TURNS})
    near = far.copy()
    near[2] = split_turns(far[2])[0]
    run = integrate_batch([params, params], "nonlinear", 0.3, t_end=100.0, x0=np.stack([far, near]), v0=v0, n_records=5)
    turned = run.record_angle - run.record_angle[:, :1]
    assert np.allclose(turned[0], turned[1], rtol=1e-9, atol=1e-8)
    assert np.array_equal(run.x[0, :2], run.x[1, :2])


def test_a_spin_no_step_follows_is_a_blow_up_that_names_the_particle():
    params = ChainParams(N=3, gamma_phi=0.0)  # no damping: the spin stays
    v0 = np.zeros((3, params.n_particles))
    v0[2, 3] = 2 * MAX_ROTATION_PER_STEP / dynamics.default_time_step(params)
    run = integrate(params, "nonlinear", t_end=50.0, v0=v0, n_frames=3)
    assert run.status == "blew_up"
    assert "particle 0 turned by" in run.message and "in one step" in run.message and "1e+06" not in run.message


def test_a_blow_up_message_names_the_value_that_ran_away():
    params = ChainParams(N=3)
    x0, v0 = _start(params, {})
    unstable = integrate(params, "nonlinear", t_end=50.0, x0=x0, v0=v0, dt=5.0, check_stability=False, n_frames=3)
    assert unstable.status == "blew_up" and "of particle" in unstable.message and "smaller time step than dt=5" in unstable.message
    bounded = integrate(params, "nonlinear", t_end=50.0, x0=x0, v0=v0, max_displacement=1e-3, n_frames=3)
    assert bounded.status == "blew_up" and "beyond the bound 0.001" in bounded.message and "max_displacement" in bounded.message


def test_a_run_goes_on_from_the_turns_and_the_rest_without_a_bit_lost():
    """x0 with the reduced angles and winding0 start the next run exactly where the last one ended."""
    params = ChainParams(N=3)
    x0, v0 = _start(params, {3: 2 * math.pi * TURNS})
    first = integrate(params, "nonlinear", moment_load(2.0, 0), t_end=30.0, x0=x0, v0=v0, n_frames=3, throw=True)
    start = first.x[-1].copy()
    start[2] = first.reduced_phi[-1]
    more = integrate(
        params, "nonlinear", moment_load(2.0, 0), t0=30.0, t_end=40.0, x0=start, v0=first.v[-1], winding0=first.winding[-1], n_frames=3
    )
    assert np.array_equal(more.x[0], first.x[-1]) and np.array_equal(more.winding[0], first.winding[-1])
    assert np.array_equal(more.reduced_phi[0], first.reduced_phi[-1])
    assert more.x[-1, 2, 3] > more.x[0, 2, 3] + 100  # it went on turning
    with pytest.raises(ValueError, match=r"winding0 of particle 1 is 0\.5; whole numbers"):
        integrate(params, "nonlinear", t_end=1.0, winding0=[0, 0, 0, 0, 0.5, 0, 0])
    with pytest.raises(ValueError, match="linear model does not rotate"):
        integrate(params, "linear", t_end=1.0, winding0=[0, 0, 0, 1, 0, 0, 0])
    with pytest.raises(ValueError, match="particle -3 is 2, but its end holds phi fixed"):
        integrate(params, "nonlinear", t_end=1.0, winding0=[2, 0, 0, 0, 0, 0, 0])
