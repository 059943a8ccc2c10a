"""The one continuation kit on problems with closed-form branches: folds, branch points, branch switching, ends."""

from __future__ import annotations

import math

import numpy as np
import pytest

from cosserat_chain.numerics.kit import BranchEnd, Corrector, Evaluation, StartError, branch_directions, continuation, newton


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
