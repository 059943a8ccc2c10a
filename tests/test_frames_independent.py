"""The stored frames do not change a run: the states are the same bits whichever steps are stored.

A frame gets the velocities at the step boundary from the open sub-step without writing
them back (numerics/engine.py), and a chunk of ``integrate`` ends open, so runs with a
frame every 1, 7 or 100 steps, or none between the start and the end, on chains of
every model, method, end and threads, end in the same state and agree on every frame
they share, positions, velocities and energy sums. The rotation check of ``simulate``
sees every step, not only the stored ones.
"""

from __future__ import annotations

import numpy as np
import pytest
from tests.conftest import random_geometries, random_state

from cosserat_chain.experiments.simulation import ROTATION_PER_STEP, simulate
from cosserat_chain.loads import Schedule, moment_load
from cosserat_chain.numerics import dynamics
from cosserat_chain.numerics.batch import integrate_batch
from cosserat_chain.numerics.dynamics import integrate
from cosserat_chain.params import ChainParams

#: Steps of each run: frames every 7 and every 100 steps share steps 0, 700 and 1400.
STEPS = 1500
#: Steps of the blocks' runs: four of their super-steps (engine.SUPER_STEPS), frames every 100 steps at 0, 100, 200, 300.
BLOCK_STEPS = 300
#: Strides of the stored frames; None: only the start and the end.
STRIDES = (1, 7, 100, None)


def _chain(seed: int, ends: str, n: int | None = None) -> ChainParams:
    """A random admissible chain (conftest.random_geometries) with the given ends: "clamped",
    "pinned", "free", "mixed" (pinned left, free right), "ring" or "graded" (stiffness and inertia)."""
    p = random_geometries(1, seed)[0]
    fields = p.model_dump(exclude={"j"})
    if n is not None:
        fields["N"] = n
    rng = np.random.default_rng(seed)
    fields.update(gamma_u=0.02, gamma_v=0.02, gamma_phi=0.01 * (seed % 2))  # an undamped angle too
    if ends == "ring":
        fields.update(periodic=True)
        del fields["left_end"], fields["right_end"]
    elif ends == "graded":
        fields["E1_factors"] = rng.uniform(0.5, 2.0, 2 * fields["N"]).tolist()
        fields["m_factors"] = rng.uniform(0.5, 2.0, 2 * fields["N"] + 1).tolist()
    elif ends == "mixed":
        fields.update(left_end="pinned", right_end="free")
    else:
        fields.update(left_end=ends, right_end=ends)
    return ChainParams(**fields)


def _runs(params, model, method, threads, moment, scale, seed, steps=STEPS, **extra):
    """One run per stride from the same moving start: {stride: Trajectory}."""
    x0 = random_state(params, scale, seed)
    v0 = random_state(params, scale, seed + 1)
    dt = dynamics.default_time_step(params, model)
    out = {}
    for stride in STRIDES:
        out[stride] = integrate(
            params, model, moment_load(moment, 0), t_end=steps * dt, dt=dt, method=method, x0=x0, v0=v0,
            stride=stride, n_frames=2, threads=threads, **extra,
        )  # fmt: skip
        assert out[stride].steps == steps and out[stride].ok, out[stride].message
    return out


def _frame_steps(trajectory, stride) -> np.ndarray:
    return np.append(np.arange(0, trajectory.steps, stride or trajectory.steps), trajectory.steps)


def _assert_same(runs: dict) -> None:
    """Every run's final state and the frames two runs share are the same bits."""
    reference = runs[1]
    for stride, run in runs.items():
        for name in ("x", "v", "load_work", "dissipated"):
            mine, theirs = getattr(run, name), getattr(reference, name)
            assert np.array_equal(mine[-1], theirs[-1]), f"stride {stride}: the final {name} differs from stride 1's"
            shared = _frame_steps(run, stride)
            assert np.array_equal(mine, theirs[shared]), f"stride {stride}: a stored {name} differs from stride 1's at the same step"


@pytest.mark.parametrize(
    ("model", "ends", "method", "moment", "scale"),
    [
        ("nonlinear", "clamped", "verlet", 0.4, 0.3),
        ("nonlinear", "free", "yoshida4", 0.3, 0.3),
        ("nonlinear", "graded", "verlet", 0.3, 0.2),
        ("nonlinear", "ring", "yoshida4", 0.2, 0.2),
        ("sine", "pinned", "verlet", 0.5, 0.3),
        ("sine", "mixed", "yoshida4", 0.3, 0.2),
        ("linear", "clamped", "verlet", 0.01, 0.01),
        ("linear", "graded", "yoshida4", 0.01, 0.01),
    ],
)
def test_one_chain_same_bits_whatever_the_frames(model, ends, method, moment, scale):
    seed = 3 + len(ends) + len(model)
    _assert_same(_runs(_chain(seed, ends), model, method, 1, moment, scale, seed))


@pytest.mark.parametrize(("ends", "method"), [("pinned", "verlet"), ("free", "yoshida4"), ("clamped", "verlet")])
def test_blocks_on_two_threads_same_bits_whatever_the_frames(ends, method):
    """A chain long enough for blocks (engine.Blocks): each block stores its frame apart; the
    states equal one thread's to the last bit, the energy sums to round-off. BLOCK_STEPS steps: a
    frame at every step is a meeting of the threads; a few super-steps (engine.SUPER_STEPS) between
    the blocks' exchanges are enough."""
    params = _chain(11, ends, n=400)
    two = _runs(params, "nonlinear", method, 2, 0.5, 0.2, 11, steps=BLOCK_STEPS)
    _assert_same(two)
    one = _runs(params, "nonlinear", method, 1, 0.5, 0.2, 11, steps=BLOCK_STEPS)
    assert np.array_equal(one[7].x, two[7].x) and np.array_equal(one[7].v, two[7].v)
    np.testing.assert_allclose(two[7].dissipated, one[7].dissipated, rtol=1e-12, atol=1e-15)


def test_chunks_end_open(monkeypatch):
    """Chunks of a few strides (each storing its frame, closing nothing) give the run of one chunk, bit for bit."""
    params = _chain(5, "free")
    whole = _runs(params, "nonlinear", "yoshida4", 1, 0.4, 0.3, 5)
    monkeypatch.setattr(dynamics, "CHUNK_WORK", 3 * params.n_particles * 3)  # chunks of 3 steps' work, rounded to strides
    _assert_same({1: whole[1], **{stride: run for stride, run in _runs(params, "nonlinear", "yoshida4", 1, 0.4, 0.3, 5).items()}})
    pieces = _runs(params, "nonlinear", "yoshida4", 1, 0.4, 0.3, 5)
    assert np.array_equal(pieces[None].v[-1], whole[None].v[-1])


@pytest.mark.parametrize("threads", [1, 2])
def test_batch_same_bits_whatever_the_records(threads):
    """integrate_batch: the members' final states, sums and the records they share do not depend on n_records."""
    params = [_chain(seed, "clamped", n=4) for seed in range(2)]
    members = [params[b % 2] for b in range(6)]
    moments = np.linspace(0.1, 0.6, 6)
    dt = min(dynamics.default_time_step(p, "nonlinear") for p in params)
    x0 = np.stack([random_state(p, 0.2, 20 + b) for b, p in enumerate(members)])
    runs = {
        records: integrate_batch(members, "nonlinear", moments, t_end=STEPS * dt, dt=dt, x0=x0, n_records=records, threads=threads)
        for records in (2, 16, 1501)  # strides 1500, 100 and 1
    }
    every = runs[1501]
    for records, run in runs.items():
        for name in ("x", "v", "load_work", "dissipated"):
            assert np.array_equal(getattr(run, name), getattr(every, name)), f"n_records={records}: {name} differs"
        stride = STEPS // (records - 1)
        assert np.array_equal(run.record_angle, every.record_angle[:, ::stride])


def test_a_spin_between_frames_is_flagged():
    """A moment pulse that spins a particle beyond ROTATION_PER_STEP between the two stored frames:
    inaccurate, with the rotation a frame at every step gives, to the last bit."""
    params = ChainParams(N=1, gamma_phi=0.3)
    pulse = Schedule(times=(0.0, 1.0, 1.0, 1.5, 1.5), values=(0.0, 0.0, 8.0, 8.0, 0.0))
    few = simulate(params, "nonlinear", moment_load(pulse, 0), t_end=4.0, dt=0.02, n_frames=2)
    every = simulate(params, "nonlinear", moment_load(pulse, 0), t_end=4.0, dt=0.02, stride=1)
    assert float(np.abs(few.phi_dot).max()) * 0.02 < 0.01 * ROTATION_PER_STEP  # the frames see no spin
    assert float(np.abs(every.phi_dot).max()) * 0.02 > ROTATION_PER_STEP
    for ds in (few, every):
        assert ds.attrs["status"] == "inaccurate" and "rad per step" in ds.attrs["message"], ds.attrs["message"]
        assert ds.attrs["rotation_per_step"] == float(np.abs(every.phi_dot).max()) * 0.02
    np.testing.assert_array_equal(few.phi.values[-1], every.phi.values[-1])


def test_a_resolved_run_is_not_flagged():
    """The same pulse at a quarter of the moment stays below the tolerance at every step: completed."""
    params = ChainParams(N=1, gamma_phi=0.3)
    pulse = Schedule(times=(0.0, 1.0, 1.0, 1.5, 1.5), values=(0.0, 0.0, 2.0, 2.0, 0.0))
    ds = simulate(params, "nonlinear", moment_load(pulse, 0), t_end=4.0, dt=0.02, n_frames=2)
    assert ds.attrs["status"] == "completed" and ds.attrs["rotation_per_step"] < ROTATION_PER_STEP
