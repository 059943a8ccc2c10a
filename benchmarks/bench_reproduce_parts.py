"""Two parts of ``cosserat-chain reproduce`` timed alone: the figures' saving and the orbits' monodromy integrations.

Run from the repository root::

    python benchmarks/bench_reproduce_parts.py                        # this checkout
    PYTHONPATH=/tmp/old/src python benchmarks/bench_reproduce_parts.py  # another checkout's package (before/after)

``figures``: three of the report's figures (the continuum profiles, the convergence and the
dispersion) laid out once and saved as PNG and SVG at the report's resolution, the layout
engine then either left as matplotlib's ``"none"`` placeholder (with which ``savefig`` draws the
figure once more before printing) or removed, as ``report.stages._Stage.figure`` does;
interleaved, thread CPU time summed over the rounds. ``monodromy``: one period of the variational
equations (DOP853 at the state diagram's scouting tolerance, 1e-8) of the paper's chain's orbit
at M = 0.22 (sine) and 0.25 (nonlinear), milliseconds of CPU per integration, best of the rounds.
The load average is printed with the results: on a shared machine compare only runs made side by side.
"""

from __future__ import annotations

import argparse
import io
import os
import time

import numpy as np


def figures(rounds: int) -> dict[str, float]:
    """CPU seconds of saving the three figures, the layout engine left as the placeholder or removed."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from cosserat_chain.analysis.continuum import compare_profiles, convergence
    from cosserat_chain.analysis.dispersion import continuum_dispersion, dispersion, wave_summary
    from cosserat_chain.params import ChainParams
    from cosserat_chain.plots.theory import plot_convergence, plot_dispersion, plot_profiles
    from cosserat_chain.report.stages import FIGURE_DPI

    chain = ChainParams()
    profiles, table = compare_profiles(chain), convergence(chain, [3, 10, 30, 100, 300, 1000])
    waves = (dispersion(chain), wave_summary(chain), continuum_dispersion(chain))
    makers = [lambda: plot_profiles(profiles), lambda: plot_convergence(table), lambda: plot_dispersion(waves[0], waves[1], waves[2])]

    def save(fig, engine_after: str | None) -> float:
        start = time.thread_time()
        fig.set_dpi(FIGURE_DPI)
        engine = fig.get_layout_engine()
        if engine is not None:
            engine.execute(fig)
            fig.set_layout_engine(engine_after)
        for kind in ("png", "svg"):
            fig.savefig(io.BytesIO(), format=kind, dpi=FIGURE_DPI)
        plt.close(fig)
        return time.thread_time() - start

    for make in makers:  # the first draw of each kind loads fonts and back-ends
        save(make(), "none")
    spent = {"none": 0.0, None: 0.0}
    for _ in range(rounds):
        for mode in spent:
            spent[mode] += sum(save(make(), mode) for make in makers)
    return {"placeholder_seconds": spent["none"], "removed_seconds": spent[None]}


def monodromy(rounds: int) -> dict[str, float]:
    """Milliseconds of CPU per monodromy integration over one period, best of ``rounds``."""
    from cosserat_chain.models.base import get_model
    from cosserat_chain.numerics.periodic import _System, _to_y, find_periodic_orbit
    from cosserat_chain.params import ChainParams

    out = {}
    for model, moment in (("sine", 0.22), ("nonlinear", 0.25)):
        orbit = find_periodic_orbit(ChainParams(), model, moment)
        system = _System(orbit.params, get_model(model), orbit.moment, orbit.particle)
        y0 = _to_y(orbit.params, orbit.x, orbit.v)
        system.flow(y0, orbit.period, rtol=1e-8, atol=1e-8, variations=True)
        best = np.inf
        for _ in range(rounds):
            start = time.thread_time()
            for _ in range(10):
                system.flow(y0, orbit.period, rtol=1e-8, atol=1e-8, variations=True)
            best = min(best, (time.thread_time() - start) / 10)
        out[f"{model}_ms"] = 1e3 * best
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rounds", type=int, default=3, help="rounds of each measurement (default 3)")
    args = parser.parse_args()
    if args.rounds < 1:
        parser.error(f"--rounds must be an integer >= 1, got {args.rounds}")
    load = os.getloadavg()[0]
    saved = figures(args.rounds)
    flows = monodromy(args.rounds)
    print(
        f"figures (3, PNG + SVG, {args.rounds} rounds): engine left as the placeholder {saved['placeholder_seconds']:.2f} s, "
        f"removed {saved['removed_seconds']:.2f} s of CPU"
    )
    print(f"monodromy over one period: sine {flows['sine_ms']:.2f} ms, nonlinear {flows['nonlinear_ms']:.2f} ms of CPU")
    print(f"load average {load:.1f} -> {os.getloadavg()[0]:.1f}")


if __name__ == "__main__":
    main()
