"""The states at M = 0.22 (paper's chain, sine model, default damping): is the rotation from rest modulated?

    python examples/coexisting_states.py            # runs to t = 30000 (a few seconds)
    python examples/coexisting_states.py --quick    # t = 3000

A run from rest seems to rotate at a modulated rate: over windows of 500 time units it
varies between 0.652 and 0.667, while the 1-turn periodic orbit turns at 0.6620. This script
measures where the spread comes from: it starts the same run exactly on the orbit, predicts
the spread from the orbit's own angle phi_0(t), compares windows of fixed time with windows
of whole turns, and times the transient from rest turn by turn. Then it lists every state
at that moment from several starts (cosserat-chain states).
"""

import argparse
import math

import numpy as np

from cosserat_chain import ChainParams
from cosserat_chain.experiments.coexisting import states_at
from cosserat_chain.loads import moment_load
from cosserat_chain.numerics.dynamics import TurnWatch, integrate
from cosserat_chain.numerics.periodic import find_periodic_orbit
from cosserat_chain.state import ROW_INDEX, column

parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
parser.add_argument("--quick", action="store_true", help="shorter runs")
args = parser.parse_args()

params, model, moment = ChainParams(), "sine", 0.22
t_end = 3000.0 if args.quick else 30000.0
col = column(params, 0)
phi_row = ROW_INDEX["phi"]

orbit = find_periodic_orbit(params, model, moment)
omega = orbit.mean_angular_velocity
print(f"1-turn orbit: T = {orbit.period:.10f}, rate {omega:.10f}, largest other |mu| {orbit.max_multiplier:.4f}")


def run_from(x0=None, v0=None):
    """Angle of the loaded particle at t = 0, 1, 2, ... and its turn times."""
    run = integrate(params, model, moment_load(moment), t_end=t_end, n_frames=int(t_end) + 1, method="yoshida4", x0=x0, v0=v0,
                    turns=TurnWatch(0, 1.0, keep=100_000))  # fmt: skip
    return run.time, run.x[:, phi_row, col], run.turns.times


def fixed_windows(time, phi, width):
    """Rates over consecutive windows of about ``width`` time units (the frames lie about 1 apart)."""
    w = int(round(width / (time[1] - time[0])))
    ends = np.arange(0, len(time) - w, w)
    return (phi[ends + w] - phi[ends]) / (time[ends + w] - time[ends])


# The orbit's phi_0(t) = omega t + p(t), p periodic: over a window of width W the rate is
# omega + (p(s + W) - p(s)) / W, whose range over the phase s is the spread of a periodic rotation.
s = np.linspace(0.0, orbit.period, 4001)[1:]
p_orbit = np.concatenate([[0.0], orbit.trajectory(s)[0][:, phi_row, col] - omega * s])
s = np.concatenate([[0.0], s])

for label, start in (("from rest", (None, None)), ("from the orbit's own start", (orbit.x, orbit.v))):
    time, phi, turn_times = run_from(*start)
    print(f"{label}, t = 0 ... {t_end:g}:")
    for width in (100.0, 500.0, 1000.0):
        rates = fixed_windows(time, phi, width)
        rates = rates[len(rates) // 3 :]  # the last two thirds
        shift = np.interp((s + width) % orbit.period, s, p_orbit) - p_orbit
        print(f"  windows of {width:g} time units: rates {rates.min():.4f} ... {rates.max():.4f} "
              f"(the orbit alone over all phases: {omega + shift.min() / width:.4f} ... {omega + shift.max() / width:.4f})")  # fmt: skip
    late = turn_times[len(turn_times) // 3 :]
    rates = 2 * math.pi * 12 / (late[12:] - late[:-12])
    print(f"  windows of 12 whole turns: rates {rates.min():.7f} ... {rates.max():.7f}")
    if label == "from rest":
        error = np.abs(np.diff(turn_times) - orbit.period) / orbit.period
        for tol in (1e-2, 1e-4, 1e-5):
            n = int(np.flatnonzero(error >= tol)[-1]) + 1 if np.any(error >= tol) else 0
            print(f"  turn periods within {tol:g} of T from turn {n + 1} on (t = {turn_times[n]:.0f})")
        print(f"  turn-period error over turns 1..12: {' '.join(f'{e:.1e}' for e in error[:12])}")

result = states_at(params, model, moment, t_long=min(t_end, 5000.0), random_starts=4 if args.quick else 8)
for i, found in enumerate(result.orbits):
    o = found.orbit
    print(f"orbit {i}: {o.turns} turn(s), T = {o.period:.8f}, rate {o.mean_angular_velocity:.7f}, "
          f"largest other |mu| {o.max_multiplier:.4f}, {'stable' if o.stable else 'unstable'}, from {len(found.found_from)} start(s)")  # fmt: skip
print(f"static states: {len(result.static)}, irregular rotations: {len(result.irregular)}")
print(
    f"from rest: relaxation {result.relaxation['status']} at t = {result.relaxation['time']:g}, settles on {result.from_rest.reached} {result.from_rest.index}"
)
print("runs:", ", ".join(f"{r.start} -> {r.reached} {r.index}" for r in result.runs))

if not args.quick:
    # Basins: random starts of growing size (angles, displacements, velocities), each run to t = 3000.
    one_turn = next(f.orbit for f in result.orbits if f.orbit.turns == 1)
    for scale in (0.3, 1.0, 3.0):
        fast = 0
        for seed in range(12):
            rng = np.random.default_rng(seed)
            x0, v0 = np.zeros((3, params.n_particles)), np.zeros((3, params.n_particles))
            x0[:, 1:-1] = 0.3 * scale * rng.standard_normal((3, params.n_particles - 2))
            x0[phi_row, 1:-1] = min(1.0, scale) * rng.uniform(-math.pi, math.pi, params.n_particles - 2)
            v0[:, 1:-1] = scale * rng.standard_normal((3, params.n_particles - 2))
            run = integrate(params, model, moment_load(moment), t_end=3000.0, n_frames=2, method="yoshida4", x0=x0, v0=v0,
                            turns=TurnWatch(0, 1.0, keep=64))  # fmt: skip
            times = run.turns.times
            fast += 2 * math.pi * 40 / (times[-1] - times[-41]) > 1.5 * one_turn.mean_angular_velocity
        print(f"random starts of size {scale:g}: {fast} of 12 reach the 2-turn orbit, the others the 1-turn one")
