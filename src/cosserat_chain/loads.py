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
from .state import ROW_INDEX, column, held

#: Most knots of one schedule: a million knots (some 100 MB as Python numbers and the compiled
#: table) is far beyond any loading protocol, and a staircase of 10^8 steps would take gigabytes.
MAX_KNOTS = 1_000_000

#: Bytes one knot takes, as two Python floats in the schedule's tuples and a row of the compiled table.
_KNOT_BYTES = 2 * (24 + 8) + 16


def _check_knots(count: int, where: str) -> None:
    """Refuse a schedule of more than :data:`MAX_KNOTS` knots before it is built, with the memory it would take."""
    if count > MAX_KNOTS:
        raise ValueError(
            f"{where} asks for a schedule of {count:.3g} knots (about {count * _KNOT_BYTES / 2**30:.3g} GiB), "
            f"more than {MAX_KNOTS:,}: a loading protocol of fewer steps, or a ramp, describes it"
        )


@dataclass(frozen=True)
class Schedule:
    """Piecewise-linear schedule of a load in time.

    Parameters
    ----------
    times, values : sequence of float
        Knots; ``times`` non-decreasing, both finite and of equal non-zero length.
    amplitude, frequency, phase : float
        A harmonic part ``amplitude * sin(2 pi frequency t + phase)`` added to the knots'
        value (default none); ``frequency`` in cycles per unit time, >= 0.
    """

    times: tuple[float, ...]
    values: tuple[float, ...]
    amplitude: float = 0.0
    frequency: float = 0.0
    phase: float = 0.0

    def __post_init__(self) -> None:
        _check_knots(len(self.times), "a schedule")
        times = tuple(float(t) for t in self.times)
        values = tuple(float(v) for v in self.values)
        object.__setattr__(self, "times", times)
        object.__setattr__(self, "values", values)
        for name in ("amplitude", "frequency", "phase"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, (int, float, np.floating, np.integer)) or not math.isfinite(value):
                raise ValueError(f"schedule {name} must be a finite number, got {value!r}")
            object.__setattr__(self, name, float(value))
        if self.frequency < 0:
            raise ValueError(f"schedule frequency must be >= 0 (cycles per unit time), got {self.frequency!r}")
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
        _check_knots(2 * n_steps, "staircase n_steps")
        times: list[float] = []
        values: list[float] = []
        for i in range(n_steps):
            t = start + i * hold
            times += [t, t]
            values += [increment * i, increment * (i + 1)]
        return cls(tuple(times), tuple(values))

    @classmethod
    def harmonic(cls, amplitude: float, frequency: float, phase: float = 0.0, offset: float = 0.0) -> Schedule:
        """``offset + amplitude * sin(2 pi frequency t + phase)`` (``frequency`` in cycles per unit time).

        :attr:`~cosserat_chain.analysis.dispersion.Modes.frequencies` are angular: to drive a
        mode of angular frequency omega, pass ``frequency = omega / (2 pi)``.
        """
        return cls((0.0,), (offset,), amplitude, frequency, phase)

    @property
    def is_constant(self) -> bool:
        """Whether the schedule has one value at all times."""
        return len(self.times) == 1 and self.amplitude == 0.0

    def bound(self) -> float:
        """The largest |value| the schedule takes."""
        return max(abs(v) for v in self.values) + abs(self.amplitude)

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
        if self.amplitude != 0.0:
            out = out + self.amplitude * np.sin(2.0 * math.pi * self.frequency * t_arr + self.phase)
        return float(out) if np.ndim(t) == 0 else out

    def knots(self) -> list[tuple[float, float]]:
        """Rows of the compiled knot table (:func:`schedule_value`): a harmonic part first, as two header rows."""
        rows = list(zip(self.times, self.values))
        if self.amplitude != 0.0:
            rows = [(-math.inf, self.amplitude), (self.frequency, self.phase), *rows]
        return rows

    def to_dict(self) -> dict[str, Any]:
        out: dict[str, Any] = {"times": list(self.times), "values": list(self.values)}
        if self.amplitude != 0.0:
            out.update(amplitude=self.amplitude, frequency=self.frequency, phase=self.phase)
        return out


@dataclass(frozen=True)
class PointLoad:
    """A schedule applied to one degree of freedom of one particle.

    Parameters
    ----------
    row : {"u", "v", "phi"}
        ``phi`` is a moment M_k (eqs. (2)-(3)); ``u`` and ``v`` are forces.
    particle : int
        Particle index in -N..N, on a degree of freedom its end does not hold
        (-N+1..N-1 for the paper's clamped chain).
    schedule : Schedule
    """

    row: str
    particle: int
    schedule: Schedule

    def __post_init__(self) -> None:
        if not isinstance(self.row, str) or self.row not in ROW_INDEX:
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
            If a load sits outside the chain or on a degree of freedom an end holds fixed.
        """
        for i, load in enumerate(self):
            if not -params.N <= load.particle <= params.N:
                raise ValueError(f"load {i} (on {load.row}): particle must be in -N..N = {-params.N}..{params.N}, got {load.particle!r}")
            col = column(params, load.particle)
            if (ROW_INDEX[load.row], col) in held(params):
                end = "left" if col == 0 else "right"
                raise ValueError(
                    f"load on {load.row} of particle {load.particle}: the {end} end is {params.ends[0 if col == 0 else 1]} "
                    f"and holds {load.row} fixed; loads may act on the free degrees of freedom (particles "
                    f"{-params.N + 1}..{params.N - 1} of a clamped chain)"
                )
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
            knots += load.schedule.knots()
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

    @classmethod
    def from_list(cls, items: Any, source: str = "loads_json") -> Loads:
        """Inverse of :meth:`to_list` (a result's ``loads_json``).

        Raises
        ------
        ValueError
            Naming the entry that is not a load.
        """
        if not isinstance(items, list):
            raise ValueError(f"{source} must be a list of loads, got {items!r}")
        loads = []
        for i, item in enumerate(items):
            if not isinstance(item, dict):
                raise ValueError(f"{source}[{i}] is not a load (an object with row, particle, times, values), got {item!r}")
            try:
                schedule = {key: item[key] for key in ("times", "values", "amplitude", "frequency", "phase") if key in item}
                particle = item["particle"]
                if isinstance(particle, bool) or not isinstance(particle, int):
                    raise ValueError(f"particle must be an integer, got {particle!r}")
                loads.append(PointLoad(item["row"], particle, Schedule(**schedule)))
            except (KeyError, TypeError, ValueError) as err:
                raise ValueError(f"{source}[{i}] is not a load (row, particle, times, values): {err}") from None
        return cls(loads)


def moment_load(moment: float | Schedule, particle: int = 0) -> Loads:
    """A moment on one particle (default: the central one, as in the paper)."""
    schedule = moment if isinstance(moment, Schedule) else Schedule.constant(moment)
    return Loads([PointLoad("phi", particle, schedule)])


#: The schedules a ``[[loads]]`` table may name with ``kind``: required and optional fields
#: (the constructor's arguments). A table without ``kind`` holds a constant ``value``.
SCHEDULE_KINDS: dict[str, tuple[tuple[str, ...], tuple[str, ...]]] = {
    "constant": (("value",), ()),
    "step": (("value", "at"), ("before",)),
    "ramp": (("value", "duration"), ("start",)),
    "staircase": (("increment", "hold", "n_steps"), ("start",)),
    "harmonic": (("amplitude", "frequency"), ("phase", "offset")),
    "knots": (("times", "values"), ()),
}


def _number(value: Any, where: str) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        raise ValueError(f"{where} must be a finite number, got {value!r}")
    return float(value)


def load_from_table(table: Any, where: str = "loads[0]") -> PointLoad:
    """One :class:`PointLoad` from a ``[[loads]]`` table of a config file.

    Keys: ``row`` ("u", "v" or "phi"), ``particle`` (an integer), and either ``value``
    (a constant load) or ``kind`` with that schedule's fields (:data:`SCHEDULE_KINDS`):
    ``step`` value, at[, before]; ``ramp`` value, duration[, start]; ``staircase``
    increment, hold, n_steps[, start]; ``harmonic`` amplitude, frequency[, phase, offset]
    (offset + amplitude sin(2 pi frequency t + phase)); ``knots`` times, values.

    Raises
    ------
    ValueError
        Naming the table (``where``), the key, the value and what is allowed.
    """
    if not isinstance(table, dict):
        raise ValueError(f"{where} must be a table (row, particle, value or kind), got {table!r}")
    kind = table.get("kind", "constant")
    if not isinstance(kind, str) or kind not in SCHEDULE_KINDS:
        raise ValueError(f"{where}.kind must be one of {', '.join(map(repr, SCHEDULE_KINDS))}, got {kind!r}")
    required, optional = SCHEDULE_KINDS[kind]
    allowed = ("row", "particle", "kind", *required, *optional)
    unknown = [key for key in table if key not in allowed]
    if unknown:
        raise ValueError(f"unknown key(s) {unknown} in {where} (kind {kind!r}); allowed keys: {', '.join(allowed)}")
    missing = [key for key in ("row", "particle", *required) if key not in table]
    if missing:
        raise ValueError(f"{where} (kind {kind!r}) lacks {', '.join(missing)}")
    row, particle = table["row"], table["particle"]
    if not isinstance(row, str) or row not in ROW_INDEX:
        raise ValueError(f"{where}.row must be one of {', '.join(map(repr, ROW_INDEX))}, got {row!r}")
    if isinstance(particle, bool) or not isinstance(particle, int):
        raise ValueError(f"{where}.particle must be an integer (a particle in -N..N), got {particle!r}")
    if kind == "knots":
        times, values = table["times"], table["values"]
        if not (isinstance(times, list) and isinstance(values, list)):
            raise ValueError(f"{where}.times and .values must be arrays of numbers, got {times!r} and {values!r}")
        fields = {"times": [_number(t, f"{where}.times[{i}]") for i, t in enumerate(times)],
                  "values": [_number(v, f"{where}.values[{i}]") for i, v in enumerate(values)]}  # fmt: skip
    else:
        fields = {key: _number(table[key], f"{where}.{key}") for key in (*required, *optional) if key in table}
        if kind == "staircase":
            if not float(fields["n_steps"]).is_integer():
                raise ValueError(f"{where}.n_steps must be an integer >= 1, got {table['n_steps']!r}")
            fields["n_steps"] = int(fields["n_steps"])
            _check_knots(2 * fields["n_steps"], f"{where}.n_steps")
    try:
        schedule = Schedule(**fields) if kind == "knots" else getattr(Schedule, kind)(**fields)
    except ValueError as err:
        raise ValueError(f"{where}: {err}") from None
    return PointLoad(row, particle, schedule)


def loads_from_tables(tables: Any, source: str = "loads") -> Loads:
    """:class:`Loads` from a config file's ``[[loads]]`` array of tables (:func:`load_from_table`)."""
    if not isinstance(tables, list):
        raise ValueError(f"{source} must be an array of tables ([[loads]] in TOML), got {tables!r}")
    return Loads([load_from_table(table, f"{source}[{i}]") for i, table in enumerate(tables)])


def parse_load(text: str) -> PointLoad:
    """A constant load from the command line's ``ROW:PARTICLE=VALUE``, e.g. ``phi:0=0.1`` or ``v:-2=0.01``.

    Raises
    ------
    ValueError
        Saying what the text should look like.
    """
    head, sep, value = text.partition("=")
    row, colon, particle = head.partition(":")
    try:
        if not (sep and colon):
            raise ValueError
        number = float(value)
        index = int(particle)
    except ValueError:
        raise ValueError(f"--load must read ROW:PARTICLE=VALUE (ROW one of u, v, phi; e.g. phi:0=0.1), got {text!r}") from None
    if row.strip() not in ROW_INDEX:
        raise ValueError(f"--load {text!r}: ROW must be one of {', '.join(ROW_INDEX)}, got {row!r}")
    if not math.isfinite(number):
        raise ValueError(f"--load {text!r}: VALUE must be finite")
    return PointLoad(row.strip(), index, Schedule.constant(number))


@njit(cache=True, nogil=True, error_model="numpy", inline="always")
def schedule_value(knots: np.ndarray, start: int, stop: int, t: float) -> float:
    """Compiled twin of :meth:`Schedule.__call__` for knots[start:stop] (:meth:`Schedule.knots`)."""
    if knots[start, 0] == -math.inf:
        # A harmonic part: header rows (-inf, amplitude) and (frequency, phase), then the knots.
        harmonic = knots[start, 1] * math.sin(2.0 * math.pi * knots[start + 1, 0] * t + knots[start + 1, 1])
        return harmonic + _piecewise(knots, start + 2, stop, t)
    return _piecewise(knots, start, stop, t)


@njit(cache=True, nogil=True, error_model="numpy", inline="always")
def _piecewise(knots: np.ndarray, start: int, stop: int, t: float) -> float:
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
