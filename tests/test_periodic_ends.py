"""Periodic orbits of chains with pinned and free ends: closure, period against a long run, Floquet multipliers, held dofs."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.optimize import linear_sum_assignment

from conftest import random_geometries, random_state
from cosserat_chain import ChainParams, moment_load
from cosserat_chain.experiments.critical import critical_point
from cosserat_chain.models import get_model
from cosserat_chain.numerics.adaptive import integrate_adaptive
from cosserat_chain.numerics.dynamics import TurnWatch, default_time_step, integrate
from cosserat_chain.numerics.periodic import _System, _to_y, find_periodic_orbit
from cosserat_chain.state import fixed_mask, n_free, pack, per_dof

#: The shooting's closure.
CLOSURE_TOL = 1e-9
#: Closure under the independent adaptive reference (rtol 1e-12).
REFERENCE_CLOSURE_TOL = 1e-7
#: Period of the orbit against the turns of a long damped run (yoshida4, a quarter of the default dt).
PERIOD_RTOL = 1e-4
#: Multipliers against a central-difference monodromy (clusters of equal modulus compared by their mean).
#: The difference's own error: the random sine cantilever's trivial multiplier came out 2.4e-7 and
#: 1.4e-6 from 1 for two starts of its orbit that differ at round-off (their multipliers agree to 1e-8).
MULTIPLIER_TOL = 2e-6
#: Strong enough damping that the rotation just above M_c is a stable one-turn orbit for every case below.
DAMPED = {"gamma_u": 0.5, "gamma_v": 0.5, "gamma_phi": 0.5}
GEOMETRY = random_geometries(1, seed=0)[0]  # N = 4

#: (name, chain, model, turns): each rotates on a stable orbit at 1.2 M_c (measured).
CASES = [
    ("paper pinned-pinned", ChainParams(left_end="pinned", right_end="pinned", **DAMPED), "sine", 1),
    ("paper pinned-pinned", ChainParams(left_end="pinned", right_end="pinned", **DAMPED), "nonlinear", 1),
    ("paper clamped-pinned", ChainParams(right_end="pinned", **DAMPED), "sine", 1),
    ("paper clamped-pinned", ChainParams(right_end="pinned", **DAMPED), "nonlinear", 1),
    ("random pinned-pinned", GEOMETRY.replace(left_end="pinned", right_end="pinned", **DAMPED), "sine", 1),
    ("random pinned-pinned", GEOMETRY.replace(left_end="pinned", right_end="pinned", **DAMPED), "nonlinear", 1),
    ("random clamped-pinned", GEOMETRY.replace(right_end="pinned", **DAMPED), "sine", 1),
    ("random clamped-pinned", GEOMETRY.replace(right_end="pinned", **DAMPED), "nonlinear", 1),
    ("random clamped-free", GEOMETRY.replace(right_end="free", **DAMPED), "sine", 1),
    # The cantilever's free arm whips round as a whole: particles 1..3 wind once while the loaded one turns twice.
    ("paper clamped-free", ChainParams(right_end="free"), "nonlinear", 2),
]
IDS = [f"{name}-{model}" for name, _, model, _ in CASES]
#: M_c of the paper's nonlinear cantilever, the branch point where its stable branch ends
#: (critical_point, docs/statics.md), given here so that this test does not rest on locating it.
CANTILEVER_NONLINEAR_MC = 0.08197793601


#: The nonlinear cantilever's two-turn orbit is a long run (its damped run from rest most of all): slow, the sine
#: cantilever of the random chain keeping a free end in the quick suite. The paper chain's other ends repeat, on
#: seven particles, what the random four-particle chain checks of the same ends and models: slow but for one, the
#: nonlinear chain clamped and pinned, which keeps the paper's chain with a held end in the quick suite.
SLOW_CASES = {
    "paper clamped-free-nonlinear",
    "paper pinned-pinned-sine",
    "paper pinned-pinned-nonlinear",
    "paper clamped-pinned-sine",
}


@pytest.fixture(
    scope="module", params=[pytest.param(i, marks=pytest.mark.slow) if IDS[i] in SLOW_CASES else i for i in range(len(CASES))], ids=IDS
)
def case(request):
    name, params, model, turns = CASES[request.param]
    if name == "paper clamped-free" and model == "nonlinear":
        moment = 1.2 * CANTILEVER_NONLINEAR_MC
    else:
        moment = 1.2 * critical_point(params, model).critical_moment
    return params, model, find_periodic_orbit(params, model, moment, turns=turns)


def _shift(orbit) -> np.ndarray:
    shift = np.zeros_like(orbit.x)
    shift[2] = 2 * math.pi * orbit.particle_turns
    return shift


def test_orbit_closes_under_an_independent_integrator(case):
    params, model, o = case
    assert o.closure <= CLOSURE_TOL
    run = integrate_adaptive(params, model, moment_load(o.moment), t_end=o.period, x0=o.x, v0=o.v, n_frames=2, rtol=1e-12, atol=1e-13)
    np.testing.assert_allclose(run.x[-1], o.x + _shift(o), atol=REFERENCE_CLOSURE_TOL)
    np.testing.assert_allclose(run.v[-1], o.v, atol=REFERENCE_CLOSURE_TOL)


def test_period_equals_the_turns_of_a_long_damped_run_from_rest(case):
    params, model, o = case
    assert o.stable
    dt = 0.25 * default_time_step(params, get_model(model))
    # Long enough for the start's transient to die out (largest other multiplier to the 150th power).
    run = integrate(
        params, model, moment_load(o.moment), t_end=150 * o.period, dt=dt, method="yoshida4", n_frames=2,
        turns=TurnWatch(o.particle, 1.0, keep=o.turns + 1),
    )  # fmt: skip
    times = run.turns.times
    assert (times[-1] - times[0]) / o.period == pytest.approx(1.0, rel=PERIOD_RTOL)


def test_floquet_multipliers_equal_a_finite_difference_monodromy(case):
    params, model, o = case
    system = _System(params, get_model(model), o.moment, o.particle)
    y0 = _to_y(params, o.x, o.v)

    def central(step: float) -> np.ndarray:
        columns = []
        for j in range(y0.size):
            e = np.zeros(y0.size)
            e[j] = step
            ends = [system.flow(y0 + s * e, o.period, rtol=1e-13, atol=1e-13, variations=False)[0] for s in (1.0, -1.0)]
            columns.append((ends[0] - ends[1]) / (2 * step))
        return np.column_stack(columns)

    # Richardson's extrapolation of two steps: near onset the flow's third derivatives are large
    # (the step^2 error of one central difference reaches 2e-2 at 1e-5 for the sine cantilever).
    fd = np.linalg.eigvals((4 * central(1e-5) - central(2e-5)) / 3)
    # Multipliers of equal modulus (the sine model's decoupled longitudinal modes) are sensitive
    # one by one, not as a cluster: match them, then compare the means of clusters.
    rows, cols = linear_sum_assignment(np.abs(fd[:, None] - o.multipliers[None, :]))
    fd = fd[rows][np.argsort(cols)]
    labels = _clusters(o.multipliers, 1e-3)
    for label in np.unique(labels):
        members = labels == label
        assert abs(fd[members].mean() - o.multipliers[members].mean()) <= MULTIPLIER_TOL
    assert abs(o.trivial_multiplier - 1.0) <= MULTIPLIER_TOL


def _clusters(values: np.ndarray, radius: float) -> np.ndarray:
    """Labels of the single-linkage clusters of complex ``values`` within ``radius``."""
    labels = np.arange(values.size)
    for i in range(values.size):
        for j in range(i):
            if abs(values[i] - values[j]) <= radius:
                labels[labels == labels[i]] = labels[j]
    return labels


def test_held_degrees_of_freedom_stay_exactly_zero_along_the_orbit(case):
    params, _, o = case
    x, v = o.trajectory(np.linspace(0.0, o.period, 41)[1:])
    held = fixed_mask(params)
    assert held.any()
    assert np.all(x[:, held] == 0.0) and np.all(v[:, held] == 0.0)
    # ... and the end that moves does move.
    moving = ~held[:, [0, -1]]
    assert np.ptp(x[:, :, [0, -1]][:, moving], axis=0).max() > 1e-3


@pytest.mark.parametrize("ends", [("pinned", "pinned"), ("clamped", "free"), ("pinned", "free"), ("free", "clamped")])
@pytest.mark.parametrize("model", ["nonlinear", "sine"])
def test_variational_force_jacobian_equals_minus_stiffness_for_any_ends(ends, model):
    # The coloured differences and the band product cover the end columns (1 or 3 free dofs each).
    params = GEOMETRY.replace(left_end=ends[0], right_end=ends[1])
    m = get_model(model)
    x, v = random_state(params, 0.3, seed=2), random_state(params, 1.0, seed=3)
    system = _System(params, m, 0.2, 0)
    nf = n_free(params)
    y = np.concatenate([pack(params, x), pack(params, v), np.hstack([np.eye(2 * nf), np.zeros((2 * nf, 1))]).ravel()])
    dy = system.rhs(2 * nf + 1)(0.0, y)
    inv_mass = 1.0 / pack(params, params.particle_inertia)
    gamma = per_dof(params, params.damping)
    forces = pack(params, m.compiled_forces(params, x))
    np.testing.assert_allclose(
        dy[nf : 2 * nf], (forces + 0.2 * (np.arange(nf) == system.load_dof)) * inv_mass - gamma * inv_mass * pack(params, v)
    )
    dphi = dy[2 * nf :].reshape(2 * nf, 2 * nf + 1)
    expected = -m.stiffness(params, x).toarray() * inv_mass[:, None]
    np.testing.assert_allclose(dphi[nf:, :nf], expected, atol=1e-6 * np.abs(expected).max())
    np.testing.assert_array_equal(dphi[nf:, nf : 2 * nf], -np.diag(gamma / pack(params, params.particle_inertia)))


@pytest.mark.parametrize("model", ["nonlinear", "sine"])
def test_clamped_chain_right_hand_side_is_unchanged_by_the_general_layout(paper, model):
    # The clamped layout is the general one's special case: the same numbers as the explicit formula.
    m = get_model(model)
    x = random_state(paper, 0.3, seed=4)
    system = _System(paper, m, 0.25, 0)
    nf = n_free(paper)
    *_, ipar = system.parameters(0)
    assert list(ipar[:6]) == [paper.n_particles, system.load_dof, 0, nf, 1, paper.n_particles - 1]
    dy = system.velocity(np.concatenate([pack(paper, x), np.zeros(nf)]))
    np.testing.assert_array_equal(
        dy[nf:],
        (pack(paper, m.compiled_forces(paper, x)) + 0.25 * (np.arange(nf) == system.load_dof)) / pack(paper, paper.particle_inertia),
    )


def test_pinned_free_sine_chain_turns_its_loaded_particle_at_m_over_gamma():
    # The sine chain spun about its pin: only the loaded particle winds, at the rate M / gamma_phi
    # of a free particle (measured T = 2 pi gamma_phi / M to 1e-13), the rest oscillates.
    params = ChainParams(left_end="pinned", right_end="free")
    o = find_periodic_orbit(params, "sine", 0.1)
    assert o.closure <= CLOSURE_TOL and o.stable
    assert list(o.particle_turns) == [0, 0, 0, 1, 0, 0, 0]
    assert o.period == pytest.approx(2 * math.pi * params.gamma_phi / 0.1, rel=1e-10)
    run = integrate(params, "sine", moment_load(0.1), t_end=150 * o.period, method="yoshida4", n_frames=2, turns=TurnWatch(0, 1.0, keep=2))
    assert (run.turns.times[-1] - run.turns.times[0]) / o.period == pytest.approx(1.0, rel=PERIOD_RTOL)
    x, _ = o.trajectory(np.linspace(0.0, o.period, 11)[1:])
    assert np.all(x[:, :2, 0] == 0.0)


def test_a_ring_is_refused_naming_why():
    with pytest.raises(ValueError, match="needs an open chain .* got a ring: .* not block tridiagonal"):
        find_periodic_orbit(ChainParams(periodic=True), "sine", 0.3)


def test_free_ends_are_refused_naming_why():
    with pytest.raises(ValueError, match="held against translation, got free ends: .* singular; pin or clamp one end"):
        find_periodic_orbit(ChainParams(left_end="free", right_end="free"), "sine", 0.3)


def test_a_guess_with_the_wrong_particle_turns_is_refused(paper):
    o = find_periodic_orbit(paper, "sine", 0.22)
    with pytest.raises(ValueError, match="particle_turns must be 7 integers"):
        find_periodic_orbit(paper, "sine", 0.22, guess=(o.x, o.v, o.period, np.zeros(7, dtype=int)))
    with pytest.raises(ValueError, match="0 where an end holds the angle"):
        find_periodic_orbit(paper, "sine", 0.22, guess=(o.x, o.v, o.period, np.array([1, 0, 0, 1, 0, 0, 0])))
    again = find_periodic_orbit(paper, "sine", 0.22, guess=(o.x, o.v, o.period, o.particle_turns))
    assert again.period == pytest.approx(o.period, rel=1e-9)
