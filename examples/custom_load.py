"""A custom load: a staircase of moments on one particle and a constant transverse force on another.

    python examples/custom_load.py            # t = 0 ... 2000
    python examples/custom_load.py --quick    # t = 0 ... 400

Loads are any number of PointLoad(row, particle, schedule): row "phi" is a moment, "u" and "v"
forces; a Schedule is piecewise linear in time (constant, step, ramp, staircase or your own knots).
"""

import argparse

from cosserat_chain import ChainParams, Loads, PointLoad, Schedule, simulate

parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
parser.add_argument("--quick", action="store_true", help="a shorter run")
args = parser.parse_args()

params = ChainParams(N=5)
hold = 80.0 if args.quick else 400.0
loads = Loads(
    [
        PointLoad("phi", 0, Schedule.staircase(increment=0.05, hold=hold, n_steps=5)),  # 0.05, 0.1, ... 0.25
        PointLoad("v", 2, Schedule.constant(0.01)),
        PointLoad("u", -1, Schedule(times=(0.0, hold, 2 * hold), values=(0.0, 0.02, 0.0))),  # your own knots
    ]
)
run = simulate(params, "nonlinear", loads, t_end=5 * hold, n_frames=501)
phi0 = run.phi.sel(particle=0)
for k in range(1, 6):
    t = k * hold - 1.0
    print(f"t = {t:7.1f}: moment {0.05 * k:.2f}, phi_0 = {float(phi0.sel(time=t, method='nearest')):.5f} rad")
print(run.attrs["status"], run.attrs["message"])
