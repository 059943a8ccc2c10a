"""The relaxation protocol: end states, onset of rotation against the exact fold, hysteresis, failures."""

from __future__ import annotations

import math

import numpy as np
import pytest

from cosserat_chain import ChainParams, moment_load
from cosserat_chain.experiments.sweep import load_steps, relaxation_sweep
from cosserat_chain.io import read_dataset, write_dataset
from cosserat_chain.numerics.continuation import locate_fold
from cosserat_chain.numerics.dynamics import integrate
from cosserat_chain.numerics.newton import solve_equilibrium
from cosserat_chain.numerics.relaxation import relax

#: Overdamped: a load step raises phi_0 monotonically (checked below), no overshoot.
STRONG = ChainParams(gamma_u=2.0, gamma_v=2.0, gamma_phi=2.0)
#: Weakly damped: a sudden load step overshoots.
WEAK = ChainParams(gamma_u=0.02, gamma_v=0.02, gamma_phi=0.02)
LOADS = load_steps(0.3, steps=12)


def first_load_above(loads: np.ndarray, moment: float) -> float:
    return float(loads[np.argmax(loads > moment)])


@pytest.mark.parametrize("model", ["nonlinear", "sine", "linear"])
def test_relaxation_end_state_equals_newton_state(paper, model):
    step = relax(paper, model, 0.15)
    assert step.status == "static"
    newton = solve_equilibrium(paper, model, moment_load(0.15), x0=step.x)
    # The rest test stops at a force residual of 1e-9; the compliance is about 5.
    np.testing.assert_allclose(step.x, newton, atol=1e-8)
    assert step.speed <= 1e-9 and step.residual <= 1e-9 * 1.15


@pytest.mark.parametrize("model", ["nonlinear", "sine"])
@pytest.mark.parametrize("params", [ChainParams(), STRONG, WEAK], ids=["default", "strong", "weak"])
def test_onset_is_never_beyond_the_first_load_step_above_the_fold(params, model):
    sweep = relaxation_sweep(params, model, m_max=0.3, steps=12)
    fold = locate_fold(params, model)
    assert sweep.onset_load is not None
    assert sweep.onset_load <= first_load_above(LOADS, fold.moment)
    # Every step below the onset ended at rest on the stable branch.
    assert set(sweep.status[sweep.moment < sweep.onset_load]) == {"static"}


@pytest.mark.parametrize("model", ["nonlinear", "sine"])
def test_with_strong_damping_rotation_starts_within_the_step_that_crosses_the_fold(model):
    sweep = relaxation_sweep(STRONG, model, m_max=0.3, steps=12)
    fold = locate_fold(STRONG, model)
    assert sweep.onset_load == first_load_above(LOADS, fold.moment)
    # No overshoot: the step just below the fold raises phi_0 monotonically.
    below = LOADS[LOADS < fold.moment]
    run = integrate(STRONG, model, moment_load(below[-1]), x0=sweep.x[len(below) - 2], t_end=100.0, n_frames=2001)
    assert np.all(np.diff(run.x[:, 2, STRONG.N]) >= -1e-12)


def test_with_weak_damping_the_overshoot_of_a_step_starts_rotation_below_the_fold():
    sweep = relaxation_sweep(WEAK, "sine", m_max=0.3, steps=12)
    fold = locate_fold(WEAK, "sine")
    assert sweep.onset_load < fold.moment
    # A static state exists at the onset load: the rotation was started by the overshoot.
    static = solve_equilibrium(WEAK, "sine", moment_load(sweep.onset_load), x0=sweep.x[np.argmax(sweep.moment == sweep.onset_load) - 1])
    assert abs(static[2, WEAK.N]) < math.pi / 2


@pytest.mark.parametrize("model", ["nonlinear", "sine"])
def test_hysteresis_rotation_stops_no_higher_than_it_starts(paper, model):
    sweep = relaxation_sweep(paper, model, m_max=0.3, steps=12, down=True)
    assert sweep.onset_load is not None and sweep.stop_load is not None
    assert sweep.stop_load <= sweep.onset_load
    down = sweep.direction == "down"
    assert sweep.moment[down][-1] == 0.0 and sweep.status[down][-1] == "static"
    # A rotating step records a mean angular velocity along the moment, the others oscillate.
    rotating = sweep.status == "rotating"
    omega = sweep.angular_velocity[rotating]
    assert np.all(omega[:, paper.N] > 0.1)
    assert np.all(np.abs(np.delete(omega, paper.N, axis=1)) < 0.1 * omega[:, [paper.N]])


def test_linear_model_never_rotates(paper):
    sweep = relaxation_sweep(paper, "linear", m_max=0.6, steps=3)
    assert sweep.onset_load is None and set(sweep.status) == {"static"}
    np.testing.assert_allclose(sweep.phi0 / sweep.moment, sweep.phi0[0] / sweep.moment[0], rtol=1e-7)


def test_a_step_that_hits_its_time_cap_says_so(paper):
    step = relax(paper, "nonlinear", 0.1, t_max=10.0)
    assert step.status == "not_converged"
    assert "t_max=10" in step.message and np.isnan(step.angular_velocity).all()


def test_sweep_dataset_is_self_describing(paper, tmp_path):
    sweep = relaxation_sweep(paper, "sine", m_max=0.25, steps=5, down=True)
    ds = read_dataset(write_dataset(sweep.to_dataset(), tmp_path / "sweep.nc"))
    assert float(ds.onset_load) == sweep.onset_load and float(ds.stop_load) == sweep.stop_load
    assert list(ds.status.values) == list(sweep.status)
    assert list(ds.direction.values) == ["up"] * 5 + ["down"] * 5
    assert ds.attrs["model"] == "sine" and ds.attrs["experiment"] == "relaxation_sweep"
    summary = sweep.as_dict()
    assert summary["loads"] == sweep.moment.tolist() and summary["onset_load"] == sweep.onset_load


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"m_max": 0.3}, "exactly one of steps"),
        ({"m_max": 0.3, "steps": 3, "dm": 0.1}, "exactly one of steps"),
        ({"m_max": 0.3, "steps": 0}, "steps must be an integer >= 1"),
        ({"m_max": 0.3, "dm": -0.1}, "dm must be a finite number > 0"),
        ({"m_max": 0.3, "dm": 0.5}, "larger than"),
        ({"m_max": math.nan, "steps": 3}, "m_max must be a finite"),
    ],
)
def test_bad_load_steps_are_refused(kwargs, match):
    with pytest.raises(ValueError, match=match):
        load_steps(**kwargs)


def test_bad_relaxation_settings_are_refused(paper):
    with pytest.raises(ValueError, match="v_tol must be a finite number > 0"):
        relax(paper, "linear", 0.1, v_tol=0.0)
    with pytest.raises(ValueError, match="window_turns must be an integer >= 1"):
        relax(paper, "linear", 0.1, window_turns=0)
    with pytest.raises(ValueError, match="particle must be in"):
        relaxation_sweep(paper, "linear", m_max=0.1, steps=1, particle=7)


def test_stop_at_onset_ends_the_upward_sweep_at_the_first_rotating_step(paper):
    full = relaxation_sweep(paper, "sine", m_max=0.3, steps=12)
    short = relaxation_sweep(paper, "sine", m_max=0.3, steps=12, stop_at_onset=True)
    assert short.onset_load == full.onset_load
    assert short.moment[-1] == full.onset_load and list(short.status) == list(full.status[: len(short.moment)])
