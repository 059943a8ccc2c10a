"""numerics.brent.brentq is SciPy's ``brentq`` step for step: the same points evaluated, the same root, the same errors."""

from __future__ import annotations

import math

import numpy as np
import pytest
import scipy.optimize as so

from cosserat_chain.numerics.brent import RTOL_FLOOR, brentq

FUNCTIONS = {
    "steep tanh": lambda x, c: math.tanh(5 * (x - c)) + 0.01 * (x - c) ** 3,
    "flat cubic": lambda x, c: (x - c) ** 3 + 1e-3 * (x - c),
    "sine": lambda x, c: math.sin(3 * x) - 0.3 + 0.1 * c,
    "exponential, NumPy scalar": lambda x, c: np.float64(math.exp(x) - math.exp(c)),
    "cusp": lambda x, c: (x - c) * abs(x - c) ** 0.1,
}


def _solve(solver, f, a, b, **tolerances):
    """The points ``solver`` evaluated and its root, or its error's type and message."""
    points = []

    def recorded(x):
        points.append(x)
        return f(x)

    try:
        return points, solver(recorded, a, b, **tolerances)
    except (ValueError, RuntimeError) as err:
        return points, (type(err), str(err))


@pytest.mark.parametrize("name", FUNCTIONS)
def test_the_same_points_and_root_as_scipy_on_random_brackets_and_tolerances(name):
    rng = np.random.default_rng(sum(map(ord, name)))
    for _ in range(150):
        c = rng.uniform(-3, 3)
        a, b = rng.uniform(-4, c), rng.uniform(c, 4)
        tolerances = {"xtol": 10 ** rng.uniform(-15, -3), "rtol": RTOL_FLOOR * (1 + 10 * rng.random())}
        f = lambda x, c=c: FUNCTIONS[name](x, c)  # noqa: E731
        ours, theirs = _solve(brentq, f, a, b, **tolerances), _solve(so.brentq, f, a, b, **tolerances)
        assert ours == theirs
        assert len(ours[0]) > 2 or ours[1][0] is ValueError


def test_a_root_at_an_end_a_sign_error_a_nan_and_too_few_iterations_as_scipy():
    assert brentq(lambda x: x - 1.0, 1.0, 2.0) == so.brentq(lambda x: x - 1.0, 1.0, 2.0) == 1.0
    for f, a, b, kwargs, error in (
        (lambda x: x * x + 1.0, -1.0, 1.0, {}, ValueError),
        (lambda x: math.nan if x > 0.5 else x - 0.7, 0.0, 1.0, {}, ValueError),
        (lambda x: x - 0.3, 0.0, 1.0, {"xtol": 0.0}, ValueError),
        (lambda x: x - 0.3, 0.0, 1.0, {"rtol": 1e-17}, ValueError),
        (lambda x: math.copysign(1.0, x - 1e-3), -1.0, 1.0, {"maxiter": 3}, RuntimeError),
    ):
        with pytest.raises(error) as ours:
            brentq(f, a, b, **kwargs)
        with pytest.raises(error) as theirs:
            so.brentq(f, a, b, **kwargs)
        assert str(ours.value) == str(theirs.value)
