"""Rotating states as periodic orbits: closure, Floquet multipliers, mean angular velocity, continuation to the orbit's end."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from typer.testing import CliRunner

from conftest import random_state
from cosserat_chain import ChainParams, moment_load
from cosserat_chain.cli import app
from cosserat_chain.experiments.orbits import periodic_orbit, rotation_characteristic
from cosserat_chain.experiments.sweep import relaxation_sweep
from cosserat_chain.models import get_model
from cosserat_chain.numerics.adaptive import integrate_adaptive
from cosserat_chain.numerics.continuation import locate_fold
from cosserat_chain.numerics.dynamics import integrate
from cosserat_chain.numerics.periodic import OrbitError, _System, continue_orbit, find_periodic_orbit
from cosserat_chain.state import n_free, pack

#: Closure of an orbit re-integrated by the independent adaptive reference (rtol 1e-12).
CLOSURE_TOL = 1e-7
#: The trivial Floquet multiplier equals 1 to this.
TRIVIAL_TOL = 1e-6
#: Overdamped chain: the orbit ends at the static fold (saddle-node on the invariant circle).
STRONG = ChainParams(gamma_u=1.0, gamma_v=1.0, gamma_phi=1.0)
#: Weakly damped chain: the rotation outlives the static fold (the hysteresis loop opens).
WEAK = ChainParams(gamma_u=0.02, gamma_v=0.02, gamma_phi=0.02)


@pytest.fixture(scope="module")
def sine_orbit(paper_sine_orbit):
    """The paper chain's 1-turn rotating state of the sine model at M = 0.22 (default damping)."""
    return paper_sine_orbit


@pytest.mark.parametrize("model", ["nonlinear", "sine"])
def test_variational_force_jacobian_equals_minus_stiffness(paper, model):
    m = get_model(model)
    x, v = random_state(paper, 0.3, seed=2), random_state(paper, 1.0, seed=3)
    system = _System(paper, m, 0.2, 0)
    nf = n_free(paper)
    y = np.concatenate([pack(paper, x), pack(paper, v), np.hstack([np.eye(2 * nf), np.zeros((2 * nf, 1))]).ravel()])
    dphi = system.rhs(2 * nf + 1)(0.0, y)[2 * nf :].reshape(2 * nf, 2 * nf + 1)
    inv_mass = np.tile(1.0 / np.array(paper.inertia), paper.n_particles - 2)
    expected = -m.stiffness(paper, x).toarray() * inv_mass[:, None]
    np.testing.assert_allclose(dphi[nf:, :nf], expected, atol=1e-6 * np.abs(expected).max())
    # The moment column: the load enters only the loaded particle's rotation, as 1 / j.
    assert dphi[nf + system.load_dof, -1] == pytest.approx(1.0 / paper.j)


def test_orbit_closes_under_an_independent_integrator(sine_orbit):
    o = sine_orbit
    run = integrate_adaptive(o.params, "sine", moment_load(o.moment), t_end=o.period, x0=o.x, v0=o.v, n_frames=2, rtol=1e-12, atol=1e-13)
    shift = np.zeros_like(o.x)
    shift[2, o.params.N] = 2 * math.pi
    np.testing.assert_allclose(run.x[-1], o.x + shift, atol=CLOSURE_TOL)
    np.testing.assert_allclose(run.v[-1], o.v, atol=CLOSURE_TOL)
    assert o.closure <= 1e-9 and o.x[2, o.params.N] == 0.0


def test_one_floquet_multiplier_is_one_and_the_orbit_is_stable(sine_orbit):
    assert abs(sine_orbit.trivial_multiplier - 1.0) < TRIVIAL_TOL
    assert sine_orbit.stable and sine_orbit.max_multiplier < 1.0


def test_longitudinal_multipliers_of_the_sine_model_are_exp_of_minus_half_the_damping_times_the_period(sine_orbit):
    # In eq. (2) u is decoupled, linear and underdamped: its 2N-1 modes give 2(2N-1)
    # multipliers of modulus exp(-gamma_u T / 2m), whatever the rotation does.
    o = sine_orbit
    expected = math.exp(-o.params.gamma_u * o.period / (2 * o.params.m))
    count = np.sum(np.abs(np.abs(o.multipliers) - expected) < 1e-7)
    assert count == 2 * (2 * o.params.N - 1)


def test_mean_angular_velocity_equals_the_long_run_average_of_a_simulation(sine_orbit):
    o = sine_orbit
    periods = 20
    on = integrate(o.params, "sine", moment_load(o.moment), t_end=periods * o.period, x0=o.x, v0=o.v, method="yoshida4", n_frames=2)
    assert (on.x[-1, 2, o.params.N] - o.x[2, o.params.N]) / on.time[-1] == pytest.approx(o.mean_angular_velocity, rel=1e-6)
    # From a perturbed state the rotation settles on the orbit: after a transient, a
    # window of a whole number of periods (any phase) gives the same average.
    rng = np.random.default_rng(0)
    v0 = o.v.copy()
    v0[:, 1:-1] += 0.1 * rng.standard_normal(v0[:, 1:-1].shape)
    loads = moment_load(o.moment)
    transient = integrate(o.params, "sine", loads, t_end=30 * o.period, x0=o.x, v0=v0, method="yoshida4", n_frames=2)
    late = integrate(
        o.params, "sine", loads, t_end=periods * o.period, x0=transient.x[-1], v0=transient.v[-1], method="yoshida4", n_frames=2
    )
    rate = (late.x[-1, 2, o.params.N] - late.x[0, 2, o.params.N]) / late.time[-1]
    assert rate == pytest.approx(o.mean_angular_velocity, rel=1e-6)


def test_nonlinear_orbit_balances_load_work_and_dissipation_over_a_period():
    # The nonlinear model is conservative: over a period the potential and kinetic energies
    # return, so the work of the moment, 2 pi k M, is all dissipated.
    o = find_periodic_orbit(WEAK, "nonlinear", 0.21)
    run = integrate_adaptive(WEAK, "nonlinear", moment_load(0.21), t_end=o.period, x0=o.x, v0=o.v, n_frames=2)
    assert run.load_work[-1] == pytest.approx(2 * math.pi * 0.21, rel=1e-9)
    assert run.dissipated[-1] == pytest.approx(run.load_work[-1], rel=1e-7)
    assert abs(o.trivial_multiplier - 1.0) < TRIVIAL_TOL


def test_with_weak_damping_the_orbit_exists_and_is_stable_well_below_the_static_fold():
    fold = locate_fold(WEAK, "nonlinear").moment
    branch = continue_orbit(find_periodic_orbit(WEAK, "nonlinear", 0.21))
    assert branch.end == "fold" and branch.end_moment < fold - 0.05
    # The hysteresis loop opens: the rotating state is stable down to far below M_c (first lost at
    # 0.1478 in a window of instability down to about 0.1415, stable again below; M_c = 0.1975).
    assert branch.stability_lost_at is not None and branch.stability_lost_at < fold - 0.04
    assert branch.end_moment < branch.stability_lost_at
    assert np.all(branch.period > 0) and np.all(np.diff(branch.moment[: int(np.argmin(branch.moment)) + 1]) < 0)


def test_default_damping_sine_orbit_loses_stability_then_folds_below_the_static_fold(sine_orbit, paper_sine_branch):
    branch = paper_sine_branch  # sine_orbit continued down to M = 0.1 (conftest.py)
    fold = locate_fold(sine_orbit.params, "sine").moment
    assert branch.end == "fold"
    # Measured: stable down to 0.1731, fold of limit cycles at 0.16395 (docs/periodic-orbits.md).
    assert 0.17 < branch.stability_lost_at < 0.18 < fold
    assert 0.16 < branch.end_moment < branch.stability_lost_at
    # At a fold of limit cycles a second multiplier reaches 1: the last orbit is close.
    assert branch.period[-1] < 2 * sine_orbit.period


def test_rotation_characteristic_follows_one_branch_and_marks_missing_orbits(paper):
    result = rotation_characteristic(paper, "sine", [0.2, 0.22, 0.1])
    np.testing.assert_array_equal(result.moment, [0.22, 0.2, 0.1])
    assert result.found.tolist() == [True, True, False]
    assert result.mean_angular_velocity[0] > result.mean_angular_velocity[1] > 0
    assert result.static_fold == pytest.approx(0.203960948396095, abs=1e-12)
    ds = result.to_dataset()
    assert ds.attrs["model"] == "sine" and np.isnan(ds["period"].values[2])
    assert json.loads(json.dumps(result.as_dict()))["period"][2] is None


@pytest.mark.parametrize(
    "kwargs, match",
    [({"moment": 0.0}, "moment"), ({"moment": 0.22, "turns": 0}, "turns"), ({"moment": 0.22, "tol": -1.0}, "tol")],
)
def test_bad_orbit_input_is_refused(paper, kwargs, match):
    with pytest.raises(ValueError, match=match):
        find_periodic_orbit(paper, "sine", **kwargs)


def test_no_rotation_below_the_static_fold_from_rest_says_so(paper):
    with pytest.raises(OrbitError, match="static fold"):
        find_periodic_orbit(paper, "sine", 0.1, transient_turns=2)


def test_orbit_command_prints_period_multipliers_and_stability(tmp_path):
    out = tmp_path / "orbit.nc"
    result = CliRunner().invoke(app, ["orbit", "--model", "sine", "--moment", "0.22", "--json", "--out", str(out)])
    assert result.exit_code == 0, result.output
    data = json.loads(result.output)
    assert data["period"] == pytest.approx(9.4911877, rel=1e-6) and data["stable"] is True
    assert data["mean_angular_velocity"] == pytest.approx(2 * math.pi / data["period"])
    assert min(abs(m - 1.0) for m in data["floquet_multipliers_abs"]) < TRIVIAL_TOL
    assert out.exists()
    bad = CliRunner().invoke(app, ["orbit", "--model", "sine", "--moment", "0.22", "--turns", "0"])
    assert bad.exit_code == 2 and "turns" in bad.output


def test_orbit_down_to_reports_where_the_orbit_ends_and_plots(tmp_path, monkeypatch, paper_sine_orbit, paper_sine_branch):
    """The command's continuation is ``paper_sine_branch``'s call (the orbit at 0.22 continued down to 0.1 with the
    defaults: asserted), given the session's branch in place of tracing it again; its report and plot as before."""
    from cosserat_chain.experiments import orbits

    calls = []

    def given(orbit, **options):
        calls.append((orbit, options))
        return paper_sine_branch

    monkeypatch.setattr(orbits, "continue_orbit", given)
    png = tmp_path / "characteristic.png"
    result = CliRunner().invoke(app, ["orbit", "--model", "sine", "--moment", "0.22", "--down-to", "0.1", "--plot", str(png)])
    assert result.exit_code == 0, result.output
    ((orbit, options),) = calls
    assert (orbit.params, orbit.model, orbit.moment, orbit.turns) == (ChainParams(), "sine", 0.22, 1)
    assert orbit.period == pytest.approx(paper_sine_orbit.period, rel=1e-12)
    assert {k: v for k, v in options.items() if k != "progress"} == {"moment_min": 0.1, "period_max": 2000.0, "method": "auto"}
    assert "fold of limit cycles" in result.output and "loses stability" in result.output
    assert png.stat().st_size > 0


@pytest.mark.slow
def test_with_strong_damping_the_orbit_ends_at_the_static_fold_with_period_like_inverse_square_root():
    fold = locate_fold(STRONG, "sine").moment
    result = periodic_orbit(STRONG, "sine", 0.21, down_to=0.1, period_max=300.0)
    branch = result.branch
    assert branch.end == "infinite_period" and branch.stable.all()
    assert 0 < branch.end_moment - fold < 2e-3
    near = branch.moment - fold < 5e-3
    exponent = -np.polyfit(np.log(branch.moment[near] - fold), np.log(branch.period[near]), 1)[0]
    assert exponent == pytest.approx(0.5, abs=0.05)


def test_each_edge_of_the_hysteresis_loop_lies_in_the_load_step_where_the_sweep_changes_state(paper, paper_sine_branch):
    # Default damping, sine model: the 1-turn orbit is stable from above M_c down to
    # 0.1731, which is 2.7e-3 from the nearest load of the sweep (dM = 0.01), and going
    # up the static state is lost at M_c = 0.20396 (4e-3 from the nearest load): both
    # edges are well inside their steps, so the comparison is robust (about 3 s).
    dm = 0.01
    sweep = relaxation_sweep(paper, "sine", m_max=0.25, dm=dm, down=True)
    fold = locate_fold(paper, "sine").moment
    assert sweep.onset_load - dm < fold <= sweep.onset_load
    branch = paper_sine_branch  # the orbit at M = 0.22 continued down to M = 0.1 (conftest.py)
    assert sweep.stop_load < branch.stability_lost_at <= sweep.stop_load + dm


def test_the_rotation_characteristic_is_drawn_against_the_dimensionless_moment():
    """A chain with E1 = 2 and h = 1.5: the orbits and the static fold sit at M / (E1 h^2) on an axis that says so."""
    import matplotlib

    matplotlib.use("Agg")
    from cosserat_chain.plots.orbits import rotation_characteristic_figure

    chain = ChainParams(E1=2.0, h=1.5, a=0.3, b=0.3)
    fold = locate_fold(chain, "sine").moment
    result = rotation_characteristic(chain, "sine", [1.2 * fold])
    assert result.found.all() and result.as_dict()["moment_scale"] == pytest.approx(4.5, rel=1e-15)
    ax = rotation_characteristic_figure(result).axes[0]
    assert "E_1 h^2" in ax.get_xlabel()
    orbit_line = next(line for line in ax.lines if "periodic orbits" in str(line.get_label()))
    assert orbit_line.get_xdata()[0] == pytest.approx(1.2 * fold / 4.5, rel=1e-12)
    fold_line = next(line for line in ax.lines if "static fold" in str(line.get_label()))
    assert fold_line.get_xdata()[0] == pytest.approx(fold / 4.5, rel=1e-12)


def test_orbit_without_turns_takes_the_first_stable_of_one_two_and_three_turns():
    """The paper's sine chain at M = 0.3 has no 1-turn orbit (Newton diverges) but a stable 3-turn one."""
    from typer.testing import CliRunner

    from cosserat_chain.cli import app

    result = CliRunner().invoke(app, ["orbit", "--model", "sine", "--moment", "0.3", "--json"])
    assert result.exit_code == 0, result.output
    data = json.loads(result.output)
    assert data["turns"] == 3 and data["stable"] is True


def test_a_continuation_asked_to_stop_at_the_first_unstable_orbit_stops_there_with_the_same_loss(paper_sine_orbit, paper_sine_branch):
    full = paper_sine_branch  # the same orbit continued with the same settings, to its fold of cycles
    short = continue_orbit(paper_sine_orbit, moment_min=0.1, until_unstable=True)
    assert full.end == "fold"
    assert short.end == "unstable" and not short.orbits[-1].stable and all(o.stable for o in short.orbits[:-1])
    assert len(short.orbits) < len(full.orbits)
    assert short.stability_lost_at == full.stability_lost_at  # the same steps up to there
