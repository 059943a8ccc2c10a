"""Load schedules: semantics, compiled twin, validation."""

from __future__ import annotations

import numpy as np
import pytest

from cosserat_chain import ChainParams, Loads, PointLoad, Schedule, moment_load
from cosserat_chain.loads import schedule_value

SCHEDULES = [
    Schedule.constant(0.3),
    Schedule.step(1.0, at=2.0, before=-0.5),
    Schedule.ramp(2.0, duration=4.0, start=1.0),
    Schedule.staircase(0.1, hold=3.0, n_steps=5, start=0.5),
    Schedule((0.0, 1.0, 1.0, 3.0), (0.0, 1.0, 5.0, -1.0)),
]


@pytest.mark.parametrize("schedule", SCHEDULES)
def test_compiled_schedule_matches_numpy(schedule):
    knots = np.ascontiguousarray(np.column_stack([schedule.times, schedule.values]))
    times = np.concatenate([np.linspace(-1, 20, 2001), schedule.times])
    compiled = np.array([schedule_value(knots, 0, len(schedule.times), t) for t in times])
    np.testing.assert_array_equal(compiled, schedule(times))


def test_schedule_shapes():
    step = Schedule.step(1.0, at=2.0)
    assert step(1.999) == 0.0 and step(2.0) == 1.0
    ramp = Schedule.ramp(2.0, duration=4.0, start=1.0)
    assert ramp(0.5) == 0.0 and ramp(3.0) == pytest.approx(1.0) and ramp(10.0) == 2.0
    stairs = Schedule.staircase(0.1, hold=3.0, n_steps=5)
    assert [stairs(t) for t in (0.0, 2.9, 3.0, 14.9, 100.0)] == pytest.approx([0.1, 0.1, 0.2, 0.5, 0.5])


@pytest.mark.parametrize(
    ("make", "match"),
    [
        (lambda: Schedule((1.0, 0.0), (0.0, 1.0)), "non-decreasing"),
        (lambda: Schedule((0.0,), (float("nan"),)), "finite"),
        (lambda: Schedule((), ()), "at least one"),
        (lambda: Schedule.ramp(1.0, duration=0.0), "duration must be > 0"),
        (lambda: PointLoad("w", 0, Schedule.constant(1.0)), "row must be one of"),
    ],
)
def test_bad_schedules_are_rejected(make, match):
    with pytest.raises(ValueError, match=match):
        make()


def test_loads_on_clamped_or_missing_particles_are_rejected():
    params = ChainParams(N=3)
    with pytest.raises(ValueError, match="particle 3: the right end is clamped"):
        moment_load(1.0, particle=3).validate(params)
    with pytest.raises(ValueError, match=r"load 0 \(on phi\): particle must be in -N..N = -3..3, got 7"):
        moment_load(1.0, particle=7).validate(params)


def test_loads_as_array_places_every_load():
    params = ChainParams(N=3)
    loads = Loads([PointLoad("phi", 0, Schedule.constant(0.2)), PointLoad("v", -1, Schedule.ramp(1.0, 2.0))])
    array = loads.as_array(params, 1.0)
    assert array[2, 3] == 0.2 and array[1, 2] == 0.5 and np.count_nonzero(array) == 2
