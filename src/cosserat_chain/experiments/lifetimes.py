"""How long a perturbed periodic orbit stays near itself in a direct run: the lifetime of a roto-breather.

Contract
--------
A run from an orbit whose velocities are perturbed by ``perturbation`` is sampled once a
period; :func:`lifetime_from_deviation` turns the deviation from the orbit at each period into
a :class:`Lifetime`: the first period at which it exceeds ``threshold``, its growth per period
where it is well above the perturbation and well below the threshold (the largest multiplier's
modulus for an unstable orbit), and the prediction ln(threshold / perturbation) / ln max|mu|.
The runs themselves are the chain's (:func:`~.breathers.lifetime`, Yoshida-4) and a user
system's (:func:`~.system_breathers.system_lifetime`, its DOP853 flow).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np


def check_lifetime_run(perturbation: float, threshold: float, max_periods: int) -> None:
    """Raise ValueError unless 0 < perturbation < threshold (finite) and max_periods is an integer >= 1."""
    if not (math.isfinite(perturbation) and perturbation > 0 and math.isfinite(threshold) and threshold > perturbation):
        raise ValueError(f"need 0 < perturbation < threshold, got perturbation={perturbation!r}, threshold={threshold!r}")
    if not (isinstance(max_periods, int) and not isinstance(max_periods, bool) and max_periods >= 1):
        raise ValueError(f"max_periods must be an integer >= 1, got {max_periods!r}")


@dataclass
class Lifetime:
    """How a roto-breather perturbed by ``perturbation`` leaves its orbit in a direct undamped run.

    Attributes
    ----------
    deviation : ndarray (periods + 1,)
        max over the coordinates and velocities of |state(k T) - orbit(k T)|, k = 0, 1, ...
        (the angles unwrapped, the rotors' advanced by 2 pi times their turns).
    periods : int or None
        First k with deviation > ``threshold``: the lifetime in periods (None: it stayed).
    growth_per_period : float
        Geometric mean of deviation[k+1] / deviation[k] while the deviation lies between 10 times
        the perturbation and the threshold / 10: the largest |multiplier| for an unstable orbit
        (NaN where the deviation never grows that far).
    period : float
        The orbit's period T.
    predicted_periods : float
        ln(threshold / perturbation) / ln max|mu|: the periods the largest multiplier needs to
        grow the perturbation to the threshold (NaN for a stable orbit).
    run_periods : int
        Length of the run in periods (a lifetime of None means beyond it).
    """

    deviation: np.ndarray
    periods: int | None
    growth_per_period: float
    period: float
    predicted_periods: float = math.nan
    run_periods: int = 0

    def as_dict(self) -> dict:
        return {
            "lifetime_periods": self.periods,
            "lifetime": None if self.periods is None else self.periods * self.period,
            "growth_per_period": None if not math.isfinite(self.growth_per_period) else self.growth_per_period,
            "predicted_periods": None if not math.isfinite(self.predicted_periods) else self.predicted_periods,
            "run_periods": self.run_periods,
        }


def lifetime_from_deviation(
    deviation: np.ndarray, *, period: float, perturbation: float, threshold: float, max_multiplier: float | None
) -> Lifetime:
    """The :class:`Lifetime` of a run whose deviation from the orbit at periods 0, 1, ... is ``deviation``.

    Parameters
    ----------
    deviation : ndarray (periods + 1,)
        Non-finite entries (a run that blew up) count as infinitely far.
    period : float
    perturbation, threshold : float
        The run's perturbation and the deviation at which the orbit counts as lost.
    max_multiplier : float or None
        The largest nontrivial |multiplier| of an unstable orbit (None for a stable one).
    """
    deviation = np.where(np.isfinite(deviation), deviation, np.inf)
    lost = np.flatnonzero(deviation > threshold)
    window = np.flatnonzero((deviation > 10 * perturbation) & (deviation < threshold / 10))
    growth = math.nan
    if window.size >= 2 and window[-1] > window[0]:
        growth = float((deviation[window[-1]] / deviation[window[0]]) ** (1.0 / (window[-1] - window[0])))
    mu = max_multiplier
    predicted = math.log(threshold / perturbation) / math.log(mu) if mu is not None and mu > 1.0 else math.nan
    return Lifetime(
        deviation=deviation, periods=int(lost[0]) if lost.size else None, growth_per_period=growth, period=period,
        predicted_periods=predicted, run_periods=deviation.size - 1,
    )  # fmt: skip


def measure_point_lifetimes(points: list[list], run: Callable[[Any], Lifetime], progress: Callable[[int, int], None] | None = None) -> None:
    """Set ``lifetime`` on every point of an atlas's rows that has an orbit, from ``run(orbit)``.

    ``progress(done, total)`` after each run (the points with an orbit).
    """
    found = [p for row in points for p in row if p.orbit is not None]
    for done, point in enumerate(found, 1):
        point.lifetime = run(point.orbit)
        if progress is not None:
            progress(done, len(found))


def lifetime_variables(points: list[list], dims: tuple[str, str]) -> dict[str, tuple]:
    """An atlas's lifetimes as Dataset variables over ``dims`` (NaN where no orbit or no run).

    ``lifetime_periods`` is the run's length where the orbit outlived it, flagged by ``outlived_run``.
    """
    shape = (len(points), len(points[0]) if points else 0)
    periods, growth, predicted = (np.full(shape, np.nan) for _ in range(3))
    outlived = np.zeros(shape, dtype=np.int8)
    for j, row in enumerate(points):
        for i, p in enumerate(row):
            life = getattr(p, "lifetime", None)
            if life is None:
                continue
            outlived[j, i] = life.periods is None
            periods[j, i] = life.run_periods if life.periods is None else life.periods
            growth[j, i], predicted[j, i] = life.growth_per_period, life.predicted_periods
    return {
        "lifetime_periods": (dims, periods, {"units": "1", "long_name": "periods until the perturbed orbit's deviation exceeded the threshold (the run's length where it never did: outlived_run)"}),
        "outlived_run": (dims, outlived, {"units": "1", "long_name": "the perturbed orbit stayed within the threshold for the whole run"}),
        "growth_per_period": (dims, growth, {"units": "1", "long_name": "geometric mean growth of the deviation per period while it grew"}),
        "predicted_lifetime_periods": (dims, predicted, {"units": "1", "long_name": "ln(threshold / perturbation) / ln max|mu| (unstable orbits)"}),
    }  # fmt: skip
