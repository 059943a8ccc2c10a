"""The compiled DOP853: its coefficient table, its order, its agreement with SciPy's, and its failures."""

from __future__ import annotations

import math

import numpy as np
import pytest
from numba import njit
from scipy.integrate import solve_ivp

from conftest import ROUND_OFF, random_state
from cosserat_chain import ChainParams, moment_load
from cosserat_chain.models import get_model
from cosserat_chain.models.base import FORCE_SIGNATURE
from cosserat_chain.numerics import dop853
from cosserat_chain.numerics.adaptive import integrate_adaptive

#: Measured convergence orders may differ from the declared one by this.
ORDER_TOL = 0.25
#: Damped harmonic oscillator x'' + 2 zeta omega x' + omega^2 x = 0 from x = 1, x' = 0.
OMEGA, ZETA = 1.0, 0.1
#: Number of rooted trees of orders 1..8 (OEIS A000081): one order condition each.
TREES_PER_ORDER = (1, 1, 2, 4, 9, 20, 48, 115)


@njit(FORCE_SIGNATURE)
def no_force(x, coef, out, start, stop):  # pragma: no cover - compiled
    """The force kernel handed to right-hand sides that have no chain."""


@njit(dop853.RHS_SIGNATURE)
def oscillator(force, end_force, t, y, coef, rpar, ipar, dy):  # pragma: no cover - compiled
    omega, zeta = rpar[0], rpar[1]
    dy[0] = y[1]
    dy[1] = -omega * omega * y[0] - 2.0 * zeta * omega * y[1]


@njit(dop853.RHS_SIGNATURE)
def riccati(force, end_force, t, y, coef, rpar, ipar, dy):  # pragma: no cover - compiled
    # y' = y^2 from y(0) = 1: y = 1 / (1 - t) blows up at t = 1.
    dy[0] = y[0] * y[0]


def oscillator_exact(t: np.ndarray) -> np.ndarray:
    """(x, x') at the times t, shape (len(t), 2)."""
    decay, damped = ZETA * OMEGA, OMEGA * math.sqrt(1.0 - ZETA**2)
    envelope = np.exp(-decay * t)
    x = envelope * (np.cos(damped * t) + decay / damped * np.sin(damped * t))
    v = -envelope * (damped + decay**2 / damped) * np.sin(damped * t)
    return np.stack([x, v], axis=-1)


def solve_oscillator(times, **kwargs) -> dop853.Solution:
    return dop853.solve(
        oscillator, no_force, np.zeros(1), np.array([OMEGA, ZETA]), np.zeros(1, np.int64), np.array([1.0, 0.0]), times, **kwargs
    )


def forests(pool: list[tuple[tuple, int]], total: int, first: int = 0):
    """Multisets of trees from ``pool[first:]`` of total order ``total``, as non-decreasing index sequences (each once)."""
    if total == 0:
        yield ()
        return
    for i in range(first, len(pool)):
        tree, size = pool[i]
        if size <= total:
            for rest in forests(pool, total - size, i):
                yield (tree, *rest)


def rooted_trees(max_order: int) -> list[tuple[tuple, int]]:
    """Every rooted tree up to ``max_order`` once, as (children, order); a tree is the tuple of its subtrees."""
    trees: list[tuple[tuple, int]] = [((), 1)]
    for order in range(2, max_order + 1):
        trees += [(children, order) for children in forests(list(trees), order - 1)]
    return trees


def stage_weights(children: tuple) -> np.ndarray:
    """Elementary weights of the stages: prod over the subtrees of A @ (their weights)."""
    weights = np.ones(dop853.N_STAGES)
    for child in children:
        weights = weights * (dop853.A @ stage_weights(child))
    return weights


def order_of(children: tuple) -> int:
    return 1 + sum(order_of(c) for c in children)


def density(children: tuple) -> int:
    """gamma(tree): a method of order >= |tree| has b . weights = 1 / gamma (Butcher)."""
    return order_of(children) * math.prod(density(c) for c in children)


TREES = rooted_trees(8)


def test_tree_enumeration_counts_every_order_condition_once():
    assert [sum(1 for _, order in TREES if order == p) for p in range(1, 9)] == list(TREES_PER_ORDER)


def test_table_is_explicit_consistent_and_sums_to_one():
    assert np.all(np.triu(dop853.A) == 0.0)
    np.testing.assert_allclose(dop853.A.sum(axis=1), dop853.C, rtol=0, atol=ROUND_OFF)
    assert dop853.B.sum() == pytest.approx(1.0, abs=ROUND_OFF)
    assert dop853.C[0] == 0.0 and dop853.C[-1] == 1.0


@pytest.mark.parametrize("k", range(8))
def test_weights_integrate_polynomials_up_to_degree_seven(k):
    assert dop853.B @ dop853.C**k == pytest.approx(1.0 / (k + 1), rel=ROUND_OFF)


def test_weights_satisfy_all_200_order_conditions_of_order_eight():
    for children, _ in TREES:
        gamma = density(children)
        assert gamma * (dop853.B @ stage_weights(children)) == pytest.approx(1.0, abs=ROUND_OFF), children


@pytest.mark.parametrize("row, order", [("E5", 5), ("E3", 3)])
def test_error_rows_are_differences_of_embedded_methods_of_orders_five_and_three(row, order):
    # b - b_hat annihilates every tree up to b_hat's order and no further: the estimate
    # is O(h^(order + 1)), not identically small.
    error = getattr(dop853, row)
    residual = {p: max(abs(density(c) * (error @ stage_weights(c))) for c, size in TREES if size == p) for p in range(1, order + 2)}
    assert all(residual[p] < ROUND_OFF for p in range(1, order + 1)), residual
    assert residual[order + 1] > 1e-3, residual


def test_step_clipped_onto_output_times_converges_with_order_eight():
    # With tolerances so loose that only the output times limit the step (all steps
    # shorter than the first one SciPy's rule picks here, 0.5), every step is one output
    # interval: a fixed-step run of the method.
    steps = np.array([0.4, 0.3, 0.2])
    errors = []
    for h in steps:
        intervals = round(12.0 / h)
        times = np.linspace(0.0, 12.0, intervals + 1)
        sol = solve_oscillator(times, rtol=1.0, atol=1.0)
        assert sol.success and sol.steps == intervals
        errors.append(np.max(np.abs(sol.y - oscillator_exact(times))))
    orders = np.log(np.array(errors[:-1]) / np.array(errors[1:])) / np.log(steps[:-1] / steps[1:])
    assert np.all(np.abs(orders - 8) < ORDER_TOL), (errors, orders)


def test_global_error_is_within_and_proportional_to_the_tolerance():
    tolerances = np.array([1e-6, 1e-8, 1e-10, 1e-12])
    errors = np.array(
        [np.max(np.abs(solve_oscillator([0.0, 10.0], rtol=tol, atol=tol).y[-1] - oscillator_exact(np.array(10.0)))) for tol in tolerances]
    )
    assert np.all(errors < tolerances), errors
    slope = np.polyfit(np.log(tolerances), np.log(errors), 1)[0]
    assert slope == pytest.approx(1.0, abs=0.1), errors


@pytest.mark.parametrize("model", ["sine", "nonlinear"])
def test_chain_run_takes_the_same_steps_as_scipy_dop853(model):
    # The right-hand side for SciPy is built from the model's NumPy twin, independently of
    # the compiled one. Same error norm, step control and first step: the same accepted and
    # rejected steps, so the same state to round-off. SciPy evaluates f(t + h, y1) also after
    # a rejected step (12 evaluations per attempt); dop853.f and this module only after an
    # accepted one (11 per attempt plus 1 per accepted step).
    params, loads = ChainParams(), moment_load(0.15)
    m, n = get_model(model), params.n_particles
    x0, v0 = random_state(params, 0.05, seed=11), random_state(params, 0.2, seed=12)
    mass, gamma = np.array(params.inertia)[:, None], np.array(params.damping)[:, None]

    def f(t, y):
        x, v = y[: 3 * n].reshape(3, n), y[3 * n : 6 * n].reshape(3, n)
        load = loads.as_array(params, t)
        acc = (m.forces(params, x) + load - gamma * v) / mass
        acc[:, [0, -1]] = 0.0
        return np.concatenate([v.ravel(), acc.ravel(), [np.sum(load * v), np.sum(gamma * v * v)]])

    y0 = np.concatenate([x0.ravel(), v0.ravel(), [0.0, 0.0]])
    ref = solve_ivp(f, (0.0, 10.0), y0, method="DOP853", rtol=1e-10, atol=1e-12)
    run = integrate_adaptive(params, model, loads, t_end=10.0, x0=x0, v0=v0, n_frames=2, rtol=1e-10, atol=1e-12)
    attempts, accepted = (ref.nfev - 2) // 12, len(ref.t) - 1
    assert run.ok and run.steps == 2 + 11 * attempts + accepted
    end = np.concatenate([run.x[-1].ravel(), run.v[-1].ravel(), [run.load_work[-1], run.dissipated[-1]]])
    np.testing.assert_allclose(end, ref.y[:, -1], rtol=0, atol=ROUND_OFF)


def test_a_blow_up_is_returned_as_a_step_size_fallen_to_round_off_with_the_outputs_before_it():
    sol = dop853.solve(
        riccati, no_force, np.zeros(1), np.zeros(1), np.zeros(1, np.int64), np.array([1.0]), [0.0, 0.5, 2.0], rtol=1e-8, atol=1e-10
    )
    assert sol.status == "step_too_small" and "round-off" in sol.message
    assert sol.reached == pytest.approx(1.0, abs=1e-6)
    np.testing.assert_array_equal(sol.t, [0.0, 0.5])
    assert sol.y[-1, 0] == pytest.approx(2.0, rel=1e-8)


def test_too_many_steps_is_returned_with_what_to_do_and_the_frames_reached(paper):
    sol = solve_oscillator(np.linspace(0.0, 10.0, 5), rtol=1e-10, atol=1e-10, max_steps=12)
    assert sol.status == "max_steps" and "increase max_steps" in sol.message
    assert sol.steps == 12 and 2.5 < sol.reached < 5.0 and len(sol.t) == 2
    run = integrate_adaptive(paper, "sine", moment_load(0.15), t_end=10.0, n_frames=3, max_steps=5)
    assert run.status == "failed" and "max_steps" in run.message and len(run.time) == 1


@pytest.mark.parametrize(
    "kwargs, match",
    [
        ({"y0": np.array([1.0, math.nan])}, r"y0 .* non-finite at index 1"),
        ({"y0": np.array([math.inf, 0.0])}, "y0"),
        ({"rtol": 0.0}, "rtol"),
        ({"rtol": 1e-16}, r"rtol must be a finite number >= 2\.22e-14"),
        ({"rtol": math.nan}, "rtol"),
        ({"atol": 0.0}, "atol must be a finite number > 0"),
        ({"atol": -1e-9}, "atol"),
        ({"atol": math.inf}, "atol"),
        ({"times": [0.0]}, "times"),
        ({"times": [0.0, 1.0, 1.0]}, "strictly increasing"),
        ({"times": [0.0, math.nan]}, "times"),
        ({"max_steps": 0}, "max_steps"),
    ],
)
def test_bad_input_is_refused_naming_the_field(kwargs, match):
    args = {"y0": np.array([1.0, 0.0]), "times": [0.0, 1.0], "rtol": 1e-8, "atol": 1e-10, **kwargs}
    y0, times = args.pop("y0"), args.pop("times")
    with pytest.raises(ValueError, match=match):
        dop853.solve(oscillator, no_force, np.zeros(1), np.array([OMEGA, ZETA]), np.zeros(1, np.int64), y0, times, **args)


def test_adaptive_reference_refuses_other_methods(paper):
    with pytest.raises(ValueError, match="method must be 'DOP853'"):
        integrate_adaptive(paper, "sine", moment_load(0.15), t_end=1.0, method="RK45")
