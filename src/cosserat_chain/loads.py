"""External loads: moments M_k(t) of eqs. (2)-(3) and, beyond the paper, forces on u and v.

Contract
--------
A :class:`Schedule` is a piecewise-linear function of time given by knots
(t_i, value_i) with non-decreasing t_i; it is constant before the first knot and
after the last. Two knots at the same time make a jump: the later knot holds from
that time on. Constant, step, ramp and staircase schedules are special cases.

A :class:`PointLoad` applies a schedule to one degree of freedom (row ``u``,
``v`` or ``phi``) of one free particle. :class:`Loads` is a tuple of them; its
:meth:`Loads.compiled` form is what the compiled integrators read.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from numba import njit

from .params import ChainParams
from .state import ROW_INDEX, column


@dataclass(frozen=True)
class Schedule:
    """Piecewise-linear schedule of a load in time.

    Parameters
    ----------
    times, values : sequence of float
        Knots; ``times`` non-decreasing, both finite and of equal non-zero length.
    """

    times: tuple[float, ...]
    values: tuple[float, ...]

    def __post_init__(self) -> None:
        times = tuple(float(t) for t in self.times)
        values = tuple(float(v) for v in self.values)
        object.__setattr__(self, "times", times)
        object.__setattr__(self, "values", values)
        if len(times) == 0 or len(times) != len(values):
            raise ValueError(f"a schedule needs as many times as values (at least one), got {len(times)} and {len(values)}")
        if not all(math.isfinite(x) for x in times + values):
            raise ValueError(f"schedule times and values must be finite, got times={times}, values={values}")
        if any(t1 < t0 for t0, t1 in zip(times, times[1:])):
            raise ValueError(f"schedule times must be non-decreasing, got {times}")

    @classmethod
    def constant(cls, value: float) -> Schedule:
        """The same value at all times."""
        return cls((0.0,), (value,))

    @classmethod
    def step(cls, value: float, at: float = 0.0, before: float = 0.0) -> Schedule:
        """``before`` until time ``at``, then ``value``."""
        return cls((at, at), (before, value))

    @classmethod
    def ramp(cls, value: float, duration: float, start: float = 0.0) -> Schedule:
        """0 until ``start``, then linear up to ``value`` over ``duration`` (> 0), then constant."""
        if not duration > 0:
            raise ValueError(f"ramp duration must be > 0, got {duration!r}")
        return cls((start, start + duration), (0.0, value))

    @classmethod
    def staircase(cls, increment: float, hold: float, n_steps: int, start: float = 0.0) -> Schedule:
        """Raise by ``increment`` every ``hold`` time units, ``n_steps`` times, the first at ``start``.

        This is the paper's step-wise loading (Section 4): the value is
        ``increment * i`` on [start + (i-1) hold, start + i hold) for i = 1..n_steps,
        and stays at ``increment * n_steps`` afterwards.
        """
        if not hold > 0:
            raise ValueError(f"staircase hold time must be > 0, got {hold!r}")
        if n_steps < 1:
            raise ValueError(f"staircase needs n_steps >= 1, got {n_steps!r}")
        times: list[float] = []
        values: list[float] = []
        for i in range(n_steps):
            t = start + i * hold
            times += [t, t]
            values += [increment * i, increment * (i + 1)]
        return cls(tuple(times), tuple(values))

    def __call__(self, t: float | np.ndarray) -> float | np.ndarray:
        """Value at time(s) ``t``."""
        times = np.asarray(self.times)
        values = np.asarray(self.values)
        t_arr = np.asarray(t, dtype=float)
        if len(times) == 1:
            out = np.full(t_arr.shape, values[0])
        else:
            # Same rule as the compiled twin: knots[lo] <= t < knots[hi], jumps take the later knot.
            idx = np.searchsorted(times, t_arr, side="right")
            hi = np.clip(idx, 1, len(times) - 1)
            t0, t1 = times[hi - 1], times[hi]
            frac = np.clip((t_arr - t0) / np.where(t1 > t0, t1 - t0, 1.0), 0.0, 1.0)
            out = values[hi - 1] + (values[hi] - values[hi - 1]) * frac
            out = np.where(idx == 0, values[0], np.where(idx >= len(times), values[-1], out))
        return float(out) if np.ndim(t) == 0 else out

    def to_dict(self) -> dict[str, Any]:
        return {"times": list(self.times), "values": list(self.values)}


@dataclass(frozen=True)
class PointLoad:
    """A schedule applied to one degree of freedom of one particle.

    Parameters
    ----------
    row : {"u", "v", "phi"}
        ``phi`` is a moment M_k (eqs. (2)-(3)); ``u`` and ``v`` are forces.
    particle : int
        Particle index in -N+1..N-1 (the ends are clamped).
    schedule : Schedule
    """

    row: str
    particle: int
    schedule: Schedule

    def __post_init__(self) -> None:
        if self.row not in ROW_INDEX:
            raise ValueError(f"load row must be one of {tuple(ROW_INDEX)}, got {self.row!r}")

    def to_dict(self) -> dict[str, Any]:
        return {"row": self.row, "particle": self.particle, **self.schedule.to_dict()}


class Loads(tuple):
    """A tuple of :class:`PointLoad`; the empty tuple is an unloaded chain."""

    def __new__(cls, items: Sequence[PointLoad] = ()) -> Loads:
        return super().__new__(cls, tuple(items))

    def validate(self, params: ChainParams) -> Loads:
        """Check every particle index against the chain; returns self.

        Raises
        ------
        ValueError
            If a load sits on a clamped particle or outside the chain.
        """
        for load in self:
            column(params, load.particle)
            if abs(load.particle) == params.N:
                raise ValueError(f"load particle {load.particle} is clamped; loads must act on particles {-params.N + 1}..{params.N - 1}")
        return self

    def compiled(self, params: ChainParams) -> tuple[np.ndarray, np.ndarray]:
        """Arrays for the compiled kernels.

        Returns
        -------
        index : ndarray of int64, shape (n_loads, 4)
            Row, column, first knot and one-past-last knot of every load.
        knots : ndarray of float64, shape (n_knots, 2)
            Times and values of all schedules, concatenated.
        """
        self.validate(params)
        index = np.zeros((len(self), 4), dtype=np.int64)
        knots: list[tuple[float, float]] = []
        for i, load in enumerate(self):
            start = len(knots)
            knots += list(zip(load.schedule.times, load.schedule.values))
            index[i] = (ROW_INDEX[load.row], column(params, load.particle), start, len(knots))
        knot_array = np.array(knots, dtype=float).reshape(-1, 2)
        return index, np.ascontiguousarray(knot_array)

    def as_array(self, params: ChainParams, t: float) -> np.ndarray:
        """All loads at time ``t`` as a (3, 2N+1) array of generalised forces."""
        out = np.zeros((3, params.n_particles))
        for load in self:
            out[ROW_INDEX[load.row], column(params, load.particle)] += load.schedule(t)
        return out

    def to_list(self) -> list[dict[str, Any]]:
        return [load.to_dict() for load in self]


def moment_load(moment: float | Schedule, particle: int = 0) -> Loads:
    """A moment on one particle (default: the central one, as in the paper)."""
    schedule = moment if isinstance(moment, Schedule) else Schedule.constant(moment)
    return Loads([PointLoad("phi", particle, schedule)])


@njit(cache=True, nogil=True, error_model="numpy", inline="always")
def schedule_value(knots: np.ndarray, start: int, stop: int, t: float) -> float:
    """Compiled twin of :meth:`Schedule.__call__` for knots[start:stop]."""
    if t < knots[start, 0]:
        return knots[start, 1]
    if t >= knots[stop - 1, 0]:
        return knots[stop - 1, 1]
    lo = start
    hi = stop - 1
    # Invariant knots[lo, 0] <= t < knots[hi, 0]; bisect to neighbouring knots.
    while hi - lo > 1:
        mid = (lo + hi) // 2
        if knots[mid, 0] <= t:
            lo = mid
        else:
            hi = mid
    t0 = knots[lo, 0]
    t1 = knots[hi, 0]
    return knots[lo, 1] + (knots[hi, 1] - knots[lo, 1]) * (t - t0) / (t1 - t0)
