"""Chains with other ends: clamped, pinned, a cantilever, free ends and a ring, each under a moment.

    python examples/chain_ends.py                             # t = 0 ... 400, writes chain_ends.png
    python examples/chain_ends.py --quick                     # t = 0 ... 60
    python examples/chain_ends.py --out docs/img/chain_ends.png

The ends are fields of ChainParams (and keys of a TOML config): left_end and right_end,
each "clamped" (u = v = phi = 0), "pinned" (u = v = 0, phi free) or "free"; periodic = True
makes a ring. The same damped dynamics run for all of them; a moment on a free chain turns
the whole chain, so it never comes to rest.
"""

import argparse

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt

from cosserat_chain import ChainParams, Loads, PointLoad, Schedule, integrate
from cosserat_chain.plots.chain import draw_chain

parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
parser.add_argument("--quick", action="store_true", help="a shorter run")
parser.add_argument("--out", default="chain_ends.png", help="the picture (PNG)")
args = parser.parse_args()

t_end = 60.0 if args.quick else 400.0
# (parameters, loaded particle, moment); the cantilever's free end has one bond and turns over at a smaller moment.
setups = {
    "clamped ends (the paper's)": (ChainParams(N=3), 0, 0.1),
    "pinned ends": (ChainParams(N=3, left_end="pinned", right_end="pinned"), 0, 0.1),
    "a cantilever: clamped left, free right": (ChainParams(N=3, right_end="free"), 3, 0.02),
    "free ends": (ChainParams(N=3, left_end="free", right_end="free"), 0, 0.1),
    "a ring (particle 3 bonded to particle -3)": (ChainParams(N=3, periodic=True), 0, 0.1),
}
figure, axes = plt.subplots(len(setups), 1, figsize=(8, 2.2 * len(setups)))
for ax, (title, (params, particle, moment)) in zip(axes, setups.items()):
    loads = Loads([PointLoad("phi", particle, Schedule.constant(moment))])
    run = integrate(params, "nonlinear", loads, t_end=t_end, n_frames=2)
    x, v = run.x[-1], run.v[-1]
    draw_chain(params, x, ax, loaded=particle, legend=False)
    ax.set_title(f"{title}: M = {moment:g} on particle {particle}, t = {t_end:g}", fontsize="small")
    print(
        f"{title:45s} phi of particle {particle}: {x[2, particle + params.N]:+.4f} rad, "
        f"end angles {x[2, 0]:+.4f} / {x[2, -1]:+.4f}, max |velocity| {abs(v).max():.2e} ({run.status})"
    )
figure.tight_layout()
figure.savefig(args.out, dpi=110)
print(f"wrote {args.out}")
