"""The one continuation kit on problems with closed-form roots and branches: folds, branch points, branch
switching, ends, and its one corrector in each of the package's Newton variants (chord iterations, damping, a
problem's own convergence test, lazy Jacobians, unforgiving divergence), each against what a wrong
implementation would do: converge elsewhere, compute Jacobians it should reuse, or go on where it should stop."""

from __future__ import annotations

import math

import numpy as np
import pytest

from cosserat_chain.numerics.kit import (
    BranchEnd,
    Corrector,
    Evaluation,
    Event,
    StartError,
    branch_directions,
    continuation,
    newton,
    tangent,
)


class Algebraic:
    """R(x, lam) = 0 for a scalar x (the unknowns w = (x, lam))."""

    tol = 1e-12

    def __init__(self, residual, jacobian, limits=(-math.inf, math.inf)):
        self.residual, self.jacobian, self.limits = residual, jacobian, limits

    def evaluate(self, w, jacobian):
        return Evaluation(np.array([self.residual(*w)]), np.array([self.jacobian(*w)]) if jacobian else None)

    def point(self, w, ev, iterations):
        return w.copy()

    def accept(self, previous, candidate):
        return True

    def tests(self, point):
        return {}

    def confirm(self, kind, point):
        return True

    def stop(self, point):
        if not self.limits[0] <= point[-1] <= self.limits[1]:
            return BranchEnd.PARAMETER_LIMIT, "left the range"
        return None


def test_the_circle_folds_at_lambda_plus_and_minus_one():
    circle = Algebraic(lambda x, lam: x * x + lam * lam - 1, lambda x, lam: [2 * x, 2 * lam])
    branch = continuation(circle, np.array([1.0, 0.0]), step=0.1, min_step=1e-6, max_step=0.3, max_points=200, direction=1.0, stop_at=())
    folds = [e.parameter for e in branch.events if e.kind == "fold"]
    assert len(folds) >= 2
    assert folds[0] == pytest.approx(1.0, abs=1e-10) and folds[1] == pytest.approx(-1.0, abs=1e-10)
    assert all(abs(p[0] ** 2 + p[1] ** 2 - 1) < 1e-11 for p in branch.points)
    assert branch.end == BranchEnd.MAX_POINTS


def test_a_pitchfork_branch_point_is_located_and_the_other_branch_followed():
    """x (lam - x^2) = 0: the trivial branch x = 0 meets the parabola lam = x^2 at lam = 0."""
    pitchfork = Algebraic(lambda x, lam: x * (lam - x * x), lambda x, lam: [lam - 3 * x * x, x], limits=(-1.0, 1.0))
    branch = continuation(
        pitchfork, np.array([0.0, -0.5]), step=0.07, min_step=1e-8, max_step=0.1, max_points=100, stop_at=("branch_point",)
    )
    assert branch.end == BranchEnd.BRANCH_POINT
    point = branch.events[-1]
    assert point.parameter == pytest.approx(0.0, abs=1e-9)
    other = branch_directions(pitchfork.evaluate(point.point, True).jacobian, point.tangent)
    assert abs(other[0]) == pytest.approx(1.0, abs=1e-6)  # the parabola leaves vertically
    switched = continuation(
        pitchfork, np.array([0.0, 0.0]) + 0.0, step=0.05, min_step=1e-8, max_step=0.1, max_points=8, tangent0=other, stop_at=()
    )
    assert all(abs(p[1] - p[0] ** 2) < 1e-10 for p in switched.points[1:])
    assert abs(switched.points[-1][0]) > 0.1


def test_newton_names_why_it_stopped():
    def square(w, jacobian):
        return Evaluation(np.array([w[0] ** 2 - 2.0]), np.array([[2 * w[0]]]))

    assert newton(square, np.array([1.0]), tol=1e-14).status == Corrector.CONVERGED
    assert newton(square, np.array([1.0]), tol=1e-14, max_iterations=2).status == Corrector.STALLED
    assert newton(square, np.array([0.0]), tol=1e-14).status == Corrector.NOT_FINITE

    def runaway(w, jacobian):
        # Newton on the cube root overshoots: x -> -2 x, so |R| grows every iteration.
        return Evaluation(np.array([math.copysign(abs(w[0]) ** (1 / 3), w[0])]), np.array([[abs(w[0]) ** (-2 / 3) / 3]]))

    assert newton(runaway, np.array([1.0]), tol=1e-14).status == Corrector.DIVERGED


def test_bad_continuation_arguments_and_starts_are_refused():
    line = Algebraic(lambda x, lam: x - lam, lambda x, lam: [1.0, -1.0])
    with pytest.raises(ValueError, match="min_step <= step <= max_step"):
        continuation(line, np.zeros(2), step=1.0, min_step=0.1, max_step=0.5, max_points=5)
    with pytest.raises(ValueError, match="unknown event kinds"):
        continuation(line, np.zeros(2), step=0.1, min_step=0.01, max_step=0.5, max_points=5, stop_at=("flod",))
    far = Algebraic(lambda x, lam: math.exp(x) + 1, lambda x, lam: [math.exp(x), 0.0])
    with pytest.raises(StartError, match="not on the branch"):
        continuation(far, np.zeros(2), step=0.1, min_step=0.01, max_step=0.5, max_points=5)


class Counted:
    """R(w) = w^3 - (1, 8) componentwise, counting residuals and Jacobians."""

    roots = np.array([1.0, 2.0])

    def __init__(self) -> None:
        self.residuals = 0
        self.jacobians = 0
        self.asked: list[bool] = []

    def __call__(self, w: np.ndarray, jacobian: bool) -> Evaluation:
        self.residuals += 1
        self.asked.append(jacobian)
        if jacobian:
            self.jacobians += 1
        return Evaluation(w**3 - self.roots**3, np.diag(3 * w**2) if jacobian else None, data=w.copy())


def test_chord_iterations_reach_the_root_with_fewer_jacobians_and_a_fresh_one_at_the_solution():
    full, chord = Counted(), Counted()
    start = np.array([1.3, 2.4])
    plain = newton(full, start, tol=1e-13)
    reused = newton(chord, start, tol=1e-13, chord=0.1, max_iterations=25)
    assert plain.converged and reused.converged
    np.testing.assert_allclose(reused.w, Counted.roots, atol=1e-13)
    assert chord.jacobians < full.jacobians
    # The returned evaluation carries the Jacobian at the returned w (the caller's tangent, multipliers).
    np.testing.assert_array_equal(reused.evaluation.data, reused.w)
    np.testing.assert_allclose(reused.evaluation.matrix(), np.diag(3 * reused.w**2), rtol=1e-15)


def test_chord_iterations_start_from_a_given_jacobian_and_refresh_it_when_it_converges_slowly():
    problem = Counted()
    stale = np.diag([30.0, 30.0])  # far from the Jacobian at the start: steps too short to converge fast
    reused = newton(problem, np.array([1.3, 2.4]), tol=1e-13, chord=0.1, jacobian0=stale, max_iterations=25)
    assert reused.converged
    np.testing.assert_allclose(reused.w, Counted.roots, atol=1e-13)
    # The first step used the given Jacobian (a residual only at the start), the slow steps had it
    # refreshed, and the solution has its own.
    assert problem.asked[0] is False and problem.asked[-1] is True and problem.jacobians >= 2
    assert problem.jacobians < problem.residuals


def test_a_chord_step_that_raises_the_residual_is_retreated_from_with_a_fresh_jacobian_where_it_started():
    # A kept Jacobian far too soft (a soft mode that has stiffened since it was factored) throws
    # the first chord step far off. Without retreat the iterate goes there and its residual
    # grows by orders; with it that step is not taken: the next Jacobian is the start's own,
    # and from there Newton converges with every iterate below the start's residual.
    soft = np.diag([1e-3, 1e-3])
    start = np.array([1.3, 2.4])
    first = float(np.max(np.abs(start**3 - Counted.roots**3)))
    seen: dict[float | None, list[float]] = {}
    for retreat in (None, 1.0):
        problem = Counted()
        norms = seen.setdefault(retreat, [])
        found = newton(
            problem, start, tol=1e-13, chord=0.25, jacobian0=soft, retreat=retreat, max_iterations=40, divergence=None,
            iterate=lambda w, ev, norms=norms: norms.append(float(np.max(np.abs(ev.residual)))),
        )  # fmt: skip
        if retreat:
            assert found.converged
            np.testing.assert_allclose(found.w, Counted.roots, atol=1e-13)
            # The Jacobian asked for after the refused step is the start's (a residual at the refused trial between).
            assert problem.asked[:3] == [False, False, True]
    assert max(seen[None][1:]) > 1e3 * first
    assert max(seen[1.0][1:]) < first


def arctan(w: np.ndarray, jacobian: bool) -> Evaluation:
    # Newton on arctan overshoots from |w| > 1.39: |w| grows every step without damping.
    return Evaluation(np.arctan(w), np.array([[1.0 / (1.0 + w[0] ** 2)]]))


def test_damping_converges_where_newton_runs_off_and_without_it_the_growth_is_named_diverged():
    assert newton(arctan, np.array([3.0]), tol=1e-12).status == Corrector.DIVERGED
    damped = newton(arctan, np.array([3.0]), tol=1e-12, damping=10, divergence=None)
    assert damped.converged and abs(damped.w[0]) < 1e-12


def test_no_damped_step_that_reduces_the_residual_is_named_diverged():
    def wrong_sign(w, jacobian):
        # A Jacobian of the wrong sign: every Newton direction climbs.
        return Evaluation(np.array([w[0] - 1.0]), np.array([[-1.0]]))

    assert newton(wrong_sign, np.array([3.0]), tol=1e-12, damping=4, divergence=None).status == Corrector.DIVERGED


def test_a_trial_that_cannot_be_evaluated_is_halved_not_fatal():
    def log_root(w, jacobian):
        # log w = 0: the full step from 5 lands at w < 0, where log is undefined.
        if w[0] <= 0:
            raise ArithmeticError("log of a non-positive number")
        return Evaluation(np.array([math.log(w[0])]), np.array([[1.0 / w[0]]]))

    assert newton(log_root, np.array([5.0]), tol=1e-12).status == Corrector.NOT_FINITE
    damped = newton(log_root, np.array([5.0]), tol=1e-12, damping=10, divergence=None)
    assert damped.converged and damped.w[0] == pytest.approx(1.0, abs=1e-12)


def test_one_growth_is_forgiven_by_default_and_none_with_forgive_zero():
    start = np.array([1.45])  # just beyond the arctan's radius of convergence: slow growth
    assert newton(arctan, start, tol=1e-12, forgive=0).iterations == 1
    assert newton(arctan, start, tol=1e-12).iterations == 2


def test_a_problem_s_own_convergence_test_and_lazy_jacobians():
    made = []

    def lazy(w, jacobian):
        def matrix():
            made.append(w.copy())
            return np.diag(3 * w**2)

        return Evaluation(w**3 - Counted.roots**3, matrix)

    # One tolerance per block: the first equation to 1e-14, the second only to 1e-3.
    solved = newton(lazy, np.array([1.3, 2.4]), converged=lambda ev, norm: abs(ev.residual[0]) <= 1e-14 and abs(ev.residual[1]) <= 1e-3)
    assert solved.converged and abs(solved.w[0] ** 3 - 1.0) <= 1e-14 and abs(solved.w[1] ** 3 - 8.0) <= 1e-3
    # A Jacobian was made for every step and none at the solution.
    assert len(made) == solved.iterations and not any(np.array_equal(m, solved.w) for m in made)
    with pytest.raises(ValueError, match="exactly one of tol"):
        newton(lazy, np.array([1.0, 2.0]))
    with pytest.raises(ValueError, match="exactly one of tol"):
        newton(lazy, np.array([1.0, 2.0]), tol=1e-12, converged=lambda ev, norm: True)


def test_the_svd_tangent_equals_the_bordered_one():
    rng = np.random.default_rng(3)
    jacobian = rng.normal(size=(6, 7))
    previous = rng.normal(size=7)
    by_svd = tangent(jacobian, previous, method="svd")
    by_border = tangent(jacobian, previous)
    np.testing.assert_allclose(by_svd, by_border, atol=1e-12)
    np.testing.assert_allclose(jacobian @ by_svd, 0.0, atol=1e-12)
    assert tangent(jacobian, None, direction=-1.0, method="svd")[-1] < 0
    with pytest.raises(ValueError, match="method must be 'bordered' or 'svd'"):
        tangent(jacobian, previous, method="qr")


class Parabola(Algebraic):
    """x^2 + lam - 1 = 0: lam = 1 - x^2 folds at x = 0, lam = 1; counts its Jacobians."""

    def __init__(self) -> None:
        super().__init__(lambda x, lam: x * x + lam - 1.0, lambda x, lam: [2 * x, 1.0])
        self.jacobians = 0

    def evaluate(self, w, jacobian):
        self.jacobians += bool(jacobian)
        return super().evaluate(w, jacobian)


def test_an_unlocated_fold_ends_the_branch_at_the_point_after_it_and_says_so():
    start = np.array([-1.0, 0.0])
    kwargs = dict(step=0.1, min_step=1e-8, max_step=0.2, max_points=100, direction=1.0, stop_at=("fold",))
    located = continuation(Parabola(), start, **kwargs)
    passed = continuation(Parabola(), start, locate=False, **kwargs)
    assert located.end == passed.end == BranchEnd.FOLD
    assert located.events[-1].located and located.events[-1].parameter == pytest.approx(1.0, abs=1e-10)
    event = passed.events[-1]
    assert not event.located and event.point is passed.points[-1] and event.parameter == passed.points[-1][1]
    assert passed.points[-1][0] > 0 > passed.points[-2][0] and "passed before" in passed.message
    # Locating costs corrections that the unlocated branch does not make; the points are the same.
    assert len(located.points) == len(passed.points)
    np.testing.assert_array_equal(np.array(located.points), np.array(passed.points))


def test_chord_corrections_follow_the_same_branch_and_the_given_first_point_is_kept():
    start = np.array([-1.0, 0.0])
    first = object()
    kwargs = dict(step=0.05, min_step=1e-8, max_step=0.05, max_points=12, direction=1.0)
    plain_problem, chord_problem = Parabola(), Parabola()
    plain = continuation(plain_problem, start, **kwargs)
    chord = continuation(chord_problem, start, corrector={"chord": 0.5, "forgive": 0}, first=first, easy=0, hard=100, **kwargs)
    assert chord.points[0] is first
    for p in chord.points[1:]:
        assert abs(p[0] ** 2 + p[1] - 1.0) <= 1e-12
    # Steps stay fixed (no growth with easy = 0, max_step reached): the same arclength, so the same points to round-off.
    np.testing.assert_allclose(np.array(chord.points[1:]), np.array(plain.points[1:]), atol=1e-9)
    assert chord_problem.jacobians <= plain_problem.jacobians


def curved(w: np.ndarray, jacobian: bool) -> Evaluation:
    """R = (x, 1000 (y - x^2)): from (1, 1) the Newton step lands at (0, -1), where max |R| grew 1000-fold,
    yet the Newton step there is shorter, and the next one ends at the root (0, 0)."""
    x, y = w
    return Evaluation(np.array([x, 1000.0 * (y - x * x)]), np.array([[1.0, 0.0], [-2000.0 * x, 1000.0]]))


def test_the_natural_monotonicity_test_takes_a_step_that_max_r_alone_refuses_and_each_iterate_is_reported():
    seen = []
    natural = newton(
        curved, np.array([1.0, 1.0]), tol=1e-12, damping=5, natural=True, divergence=None, iterate=lambda w, ev: seen.append(w.copy())
    )
    assert natural.converged and natural.iterations == 2
    np.testing.assert_array_equal(natural.w, [0.0, 0.0])
    np.testing.assert_array_equal(np.array(seen), [[1.0, 1.0], [0.0, -1.0], [0.0, 0.0]])
    assert newton(curved, np.array([1.0, 1.0]), tol=1e-12, damping=5, divergence=None).status == Corrector.DIVERGED


def test_an_iteration_that_does_not_contract_is_named_and_a_problem_s_own_step_is_used():
    def linear(w, jacobian):
        return Evaluation(w.copy(), np.eye(1))

    # A tenth of the Newton step each time: max |R| falls only by 0.9 an iteration.
    slow = newton(linear, np.array([1.0]), tol=1e-12, newton_step=lambda w, ev, jacobian: -0.1 * ev.residual, contraction=0.5)
    assert slow.status == Corrector.NOT_CONTRACTING and slow.iterations == 2
    assert slow.w[0] == pytest.approx(0.81, rel=1e-15)
    assert newton(linear, np.array([1.0]), tol=1e-12, newton_step=lambda w, ev, jacobian: -0.1 * ev.residual).status == Corrector.STALLED

    def undefined(w, ev, jacobian):
        raise np.linalg.LinAlgError("no step here")

    assert newton(linear, np.array([1.0]), tol=1e-12, newton_step=undefined).status == Corrector.NOT_FINITE


def test_the_contraction_of_the_best_lets_an_iteration_that_rises_and_comes_back_go_on():
    """Residuals 1e-1, 1e-3, 1e-5, 1e-3, 1e-7, 1e-9 (one iterate thrown off and back, as a long chain's statics do)."""
    sequence = iter([1e-1, 1e-3, 1e-5, 1e-3, 1e-7, 1e-9, 1e-11, 1e-13])

    def scripted(w, jacobian):
        return Evaluation(np.array([next(sequence)]), np.eye(1))

    step = lambda w, ev, jacobian: np.array([1.0])  # noqa: E731 - the residuals are scripted, the step moves the iterate
    best = newton(scripted, np.array([0.0]), tol=1e-8, newton_step=step, contraction=0.5, contraction_of_best=True, divergence=None)
    assert best.converged and best.iterations == 5
    sequence = iter([1e-1, 1e-3, 1e-5, 1e-3, 1e-7, 1e-9])
    each = newton(scripted, np.array([0.0]), tol=1e-8, newton_step=step, contraction=0.5, divergence=None)
    assert each.status == Corrector.NOT_CONTRACTING and each.iterations == 3
    # A wandering one (the sine model's fallbacks) stops either way.
    sequence = iter([1.6e-3, 4.2e-4, 1.6e-4, 8.7e-4, 2.6e-4, 1.3e-4, 1.4e-2])
    assert newton(scripted, np.array([0.0]), tol=1e-8, newton_step=step, contraction=0.5, contraction_of_best=True, divergence=None).status == Corrector.NOT_CONTRACTING


def cube_root(w: np.ndarray, jacobian: bool) -> Evaluation:
    # Newton on the cube root doubles |w| and flips its sign every step: |R| grows by 2^(1/3).
    return Evaluation(np.cbrt(w), np.array([[1.0 / (3.0 * np.cbrt(w[0]) ** 2)]]))


def test_a_step_with_a_fresh_jacobian_that_blows_the_residual_up_is_named_diverged_and_jacobians_are_counted():
    # |R| after the steps: 2^(1/3), 4^(1/3), 2 (not above 2 times the first), 16^(1/3): diverged at the fourth.
    blown = newton(cube_root, np.array([1.0]), tol=1e-12, divergence=None, blowup=2.0)
    assert blown.status == Corrector.DIVERGED and blown.iterations == 4 and blown.jacobians == 4
    assert blown.w[0] == pytest.approx(16.0, rel=1e-15)
    assert newton(cube_root, np.array([1.0]), tol=1e-12, divergence=None, max_iterations=6).status == Corrector.STALLED
    # A chord correction counts only the Jacobians its steps were computed with, not the kept first one.
    problem = Counted()
    start = newton(problem, np.array([1.3, 2.4]), tol=1e-13)
    kept = Counted()
    reused = newton(kept, np.array([1.3, 2.4]), tol=1e-13, chord=0.1, jacobian0=start.evaluation.matrix(), max_iterations=25)
    assert reused.converged and reused.jacobians == kept.jacobians - 1  # the solution's own is not a step's


def test_a_given_first_evaluation_is_used_instead_of_evaluating_the_start_again():
    start = newton(Counted(), np.array([1.3, 2.4]), tol=1e-13).evaluation.matrix()
    plain, given = Counted(), Counted()
    w0 = np.array([1.1, 2.2])
    first = given(w0, False)
    a = newton(plain, w0, tol=1e-13, chord=0.1, jacobian0=start)
    b = newton(given, w0, tol=1e-13, chord=0.1, jacobian0=start, evaluation0=first)
    assert a.converged and np.array_equal(a.w, b.w) and a.iterations == b.iterations
    assert given.residuals == plain.residuals and given.asked == plain.asked  # the one evaluation of the start


class Monitored(Algebraic):
    """The circle with its own stages: a step may move lambda by MOVE at most (``review``), the next
    step is always LONG (``next_step``), and the events are where x changes sign (``events``, ``locate``)."""

    MOVE, LONG = 0.05, 0.2

    def __init__(self):
        super().__init__(lambda x, lam: x * x + lam * lam - 1, lambda x, lam: [2 * x, 2 * lam])
        self.retaken, self.failures = [], 0

    def review(self, previous, candidate, h):
        if abs(candidate[-1] - previous[-1]) > self.MOVE:
            self.retaken.append(h)
            return h / 4
        return None

    def next_step(self, h, correction, candidate):
        return self.LONG

    def events(self, previous, candidate, t_before, t_after):
        return ["x_zero"] if previous[0] * candidate[0] < 0 else []

    def locate(self, kind, w, t, h, previous, candidate, index):
        # On the unit circle x = 0 is lambda = +-1: the sign of lambda at the candidate says which.
        return Event(kind, candidate, math.copysign(1.0, candidate[-1]), index)


def test_a_problem_s_own_stages_replace_the_driver_s():
    problem = Monitored()
    branch = continuation(problem, np.array([1.0, 0.0]), step=0.2, min_step=1e-6, max_step=0.3, max_points=200)
    lam = np.array([p[-1] for p in branch.points])
    assert np.all(np.abs(np.diff(lam)) <= Monitored.MOVE)
    assert problem.retaken and all(h == pytest.approx(Monitored.LONG) or h == pytest.approx(Monitored.LONG / 4) for h in problem.retaken)
    crossings = [e for e in branch.events if e.kind == "x_zero"]
    assert [e.parameter for e in crossings][:2] == [1.0, -1.0]
    assert not [e for e in branch.events if e.kind == "fold"]  # the built-in tests are the problem's events now


def test_the_static_branch_ends_in_the_kit_s_vocabulary():
    from cosserat_chain.numerics.continuation import continue_in_moment
    from cosserat_chain.params import ChainParams

    branch = continue_in_moment(ChainParams(N=3), "sine", max_folds=1)
    assert branch.stop is BranchEnd.MAX_FOLDS and branch.stop == "max_folds" and branch.complete
    assert continue_in_moment(ChainParams(N=3), "sine", max_points=5).stop is BranchEnd.MAX_POINTS


def test_a_jacobian_that_cannot_be_computed_ends_the_correction_as_not_finite():
    def evaluate(w, jacobian):
        def matrix():
            raise ArithmeticError("no Jacobian here")

        return Evaluation(np.array([w[0] - 2.0]), matrix)

    corrected = newton(evaluate, np.array([1.0]), tol=1e-12)
    assert corrected.status == Corrector.NOT_FINITE and corrected.w[0] == 1.0


def test_a_diverging_rotation_controlled_newton_is_a_newton_error_not_a_traceback(monkeypatch):
    from cosserat_chain.numerics import newton as rotation
    from cosserat_chain.params import ChainParams

    monkeypatch.setattr(rotation, "DIVERGED", -1.0)  # every iterate counts as diverging: the corrector must stop cleanly
    with pytest.raises(rotation.NewtonError, match="did not converge"):
        rotation.solve_rotation_controlled(ChainParams(N=3), "nonlinear", 1.0)
