"""Batched dynamics: every member of a batch equals its own single run (integrate, relax, relaxation_sweep)."""

from __future__ import annotations

import numpy as np
import pytest

from conftest import ROUND_OFF, random_state
from cosserat_chain import ChainParams, moment_load
from cosserat_chain.experiments.sweep import relaxation_sweep, relaxation_sweeps
from cosserat_chain.numerics.batch import integrate_batch
from cosserat_chain.numerics.dynamics import IntegrationError, default_time_step, integrate
from cosserat_chain.numerics.relaxation import relax, relax_batch

#: Members that differ in geometry, stiffness, inertia and damping (same N).
MEMBERS = [
    ChainParams(),
    ChainParams(a=0.3, E2=0.5, gamma_phi=0.2),
    ChainParams(m=2.0, b=0.3, gamma_u=0.05),
]
MOMENTS = [0.1, 0.3, -0.2]
#: The rest test stops at |v|, |F + L| <= 1e-9 and the compliance is about 5: two
#: runs that both passed it agree to about 1e-8 however they got there.
REST = 1e-8
#: Short, but long enough for steady rotation; keeps the file well under 30 s.
RELAX = {"t_max": 3000.0}


@pytest.mark.parametrize("model", ["nonlinear", "sine", "linear"])
def test_batch_members_equal_their_single_runs(model):
    x0 = np.array([random_state(p, 0.05, seed=i) for i, p in enumerate(MEMBERS)])
    batch = integrate_batch(MEMBERS, model, MOMENTS, t_end=30.0, x0=x0, n_records=41)
    for i, params in enumerate(MEMBERS):
        run = integrate(params, model, moment_load(MOMENTS[i]), t_end=30.0, x0=x0[i], n_frames=41)
        # The same scheme, step and kernel: equal to round-off (bitwise when the
        # batch loop and the single-run loop are compiled with the same options).
        np.testing.assert_allclose(batch.x[i], run.x[-1], rtol=0, atol=ROUND_OFF)
        np.testing.assert_allclose(batch.v[i], run.v[-1], rtol=0, atol=ROUND_OFF)
        count = run.time.size
        np.testing.assert_array_equal(batch.record_time[i, :count], run.time)
        np.testing.assert_allclose(batch.record_angle[i, :count], run.x[:, 2, params.N], rtol=0, atol=ROUND_OFF)
        assert np.isnan(batch.record_angle[i, count:]).all()
        assert batch.status[i] == "completed" and batch.steps[i] == run.steps and batch.dt[i] == run.dt
        # The energy sums too (summed over the columns in another order).
        assert batch.load_work[i] == pytest.approx(run.load_work[-1], rel=1e-12, abs=ROUND_OFF)
        assert batch.dissipated[i] == pytest.approx(run.dissipated[-1], rel=1e-12, abs=ROUND_OFF)
        assert batch.dissipated[i] > 0


def test_two_threads_give_the_same_states_as_one():
    members = MEMBERS * 3
    one = integrate_batch(members, "nonlinear", MOMENTS * 3, t_end=20.0, threads=1)
    two = integrate_batch(members, "nonlinear", MOMENTS * 3, t_end=20.0, threads=2)
    # Each member runs the same code on either core: identical bits.
    np.testing.assert_array_equal(one.x, two.x)
    np.testing.assert_array_equal(one.record_angle, two.record_angle)


def test_yoshida4_members_equal_their_single_runs():
    batch = integrate_batch(MEMBERS, "sine", MOMENTS, t_end=10.0, method="yoshida4")
    for i, params in enumerate(MEMBERS):
        run = integrate(params, "sine", moment_load(MOMENTS[i]), t_end=10.0, method="yoshida4")
        np.testing.assert_allclose(batch.x[i], run.x[-1], rtol=0, atol=ROUND_OFF)


@pytest.mark.parametrize("model", ["nonlinear", "sine"])
def test_relax_batch_equals_relax_member_by_member(model):
    # A grid of loads on one chain and other chains: static, rotating (many more
    # turns than the ring of crossings holds) and both signs.
    members = [MEMBERS[0]] * 4 + MEMBERS[1:]
    moments = [0.05, 0.2, 0.5, -0.5, 0.1, 0.25]
    steps = relax_batch(members, model, moments, threads=2, **RELAX)
    for params, moment, batch in zip(members, moments, steps):
        single = relax(params, model, moment, **RELAX)
        assert batch.status == single.status, (moment, batch.message, single.message)
        if single.status == "static":
            np.testing.assert_allclose(batch.x, single.x, rtol=0, atol=REST)
            assert batch.time == pytest.approx(single.time)
        else:
            col = params.N
            # Steady rotation agrees to the test's own tolerance (5 %) at worst.
            assert batch.angular_velocity[col] == pytest.approx(single.angular_velocity[col], rel=0.05)
            assert batch.turns > 2 * 12 and np.sign(batch.angular_velocity[col]) == np.sign(moment)


def test_relax_batch_from_given_states_continues_like_relax(paper):
    start = relax(paper, "sine", 0.1, **RELAX)
    (batch,) = relax_batch([paper], "sine", [0.15], x0=start.x[None], v0=start.v[None], **RELAX)
    single = relax(paper, "sine", 0.15, x0=start.x, v0=start.v, **RELAX)
    assert batch.status == single.status == "static"
    np.testing.assert_allclose(batch.x, single.x, rtol=0, atol=REST)


@pytest.mark.parametrize("model", ["sine", "nonlinear"])
def test_relaxation_sweeps_equal_relaxation_sweep_member_by_member(model):
    # Loads up to 0.3, where every step ends static or in a steady rotation (above,
    # some rotations stay chaotic past t_max, and whether a window of 12 turns passes
    # the 5 % test then hangs on the last bits).
    members = [MEMBERS[0], MEMBERS[1], ChainParams(E2=2.0)]
    sweeps = relaxation_sweeps(members, model, m_max=0.3, steps=6, down=True, threads=2, **RELAX)
    for params, batch in zip(members, sweeps):
        single = relaxation_sweep(params, model, m_max=0.3, steps=6, down=True, **RELAX)
        assert list(batch.status) == list(single.status)
        np.testing.assert_array_equal(batch.moment, single.moment)
        assert batch.onset_load == single.onset_load and batch.stop_load == single.stop_load
        assert batch.completed and batch.settings == single.settings
        static = batch.status == "static"
        np.testing.assert_allclose(batch.x[static], single.x[static], rtol=0, atol=REST)


def test_stop_at_onset_and_per_member_loads():
    members = [MEMBERS[0], ChainParams(E2=2.0)]
    sweeps = relaxation_sweeps(members, "sine", m_max=[0.3, 0.45], dm=0.05, stop_at_onset=True, **RELAX)
    for params, top, batch in zip(members, (0.3, 0.45), sweeps):
        single = relaxation_sweep(params, "sine", m_max=top, dm=0.05, stop_at_onset=True, **RELAX)
        assert list(batch.status) == list(single.status) and batch.onset_load == single.onset_load
        assert batch.status[-1] == "rotating"


def test_members_of_different_length_are_refused():
    with pytest.raises(ValueError, match=r"params_list\[1\]\.N=4 differs"):
        integrate_batch([ChainParams(), ChainParams(N=4)], "sine", 0.1, t_end=1.0)


def test_a_step_beyond_a_members_stability_limit_is_refused():
    stiff = ChainParams(E1=50.0)
    dt = default_time_step(ChainParams()) * 10
    with pytest.raises(ValueError, match=r"member 1 \(params_list\[1\]\): dt=.*beyond the stability limit"):
        relax_batch([ChainParams(), stiff], "sine", 0.1, dt=dt)


def test_non_finite_input_is_refused_naming_member_and_field(paper):
    with pytest.raises(ValueError, match=r"moments\[1\] \(member 1\) is nan"):
        relax_batch([paper, paper], "sine", [0.1, np.nan])
    x0 = np.zeros((2, 3, paper.n_particles))
    x0[1, 2, 3] = np.inf
    with pytest.raises(ValueError, match=r"x0\[1\]\[phi\] of particle 0 is inf"):
        integrate_batch([paper, paper], "sine", 0.1, t_end=1.0, x0=x0)
    with pytest.raises(ValueError, match=r"dt\[0\] \(member 0\) is nan"):
        integrate_batch([paper, paper], "sine", 0.1, t_end=1.0, dt=[np.nan, 0.01])
    with pytest.raises(ValueError, match=r"member 0 \(params_list\[0\]\): m_max"):
        relaxation_sweeps([paper], "sine", m_max=np.nan, steps=2)


def test_a_member_that_runs_away_is_reported_by_name(paper):
    x0 = np.zeros((2, 3, paper.n_particles))
    x0[1, 0, 3] = 1e5  # far beyond the runaway bound of 100 chain lengths
    run = integrate_batch([paper, paper], "linear", 0.1, t_end=5.0, x0=x0)
    assert run.status == ["completed", "blew_up"]
    with pytest.raises(IntegrationError, match=r"member 1 \(params_list\[1\], moment 0.1\) blew up"):
        relax_batch([paper, paper], "linear", 0.1, x0=x0)
