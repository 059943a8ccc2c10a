"""Two parts of ``cosserat-chain reproduce`` timed alone: the figures' saving and the orbits' monodromy integrations.

Run from the repository root::

    python benchmarks/bench_reproduce_parts.py                        # this checkout
    PYTHONPATH=/tmp/old/src python benchmarks/bench_reproduce_parts.py  # another checkout's package (before/after)
    python benchmarks/bench_reproduce_parts.py --where                 # where a warm reproduce spends its CPU

``figures``: three of the report's figures (the continuum profiles, the convergence and the
dispersion) laid out once and saved as PNG and SVG at the report's resolution, the layout
engine then either left as matplotlib's ``"none"`` placeholder (with which ``savefig`` draws the
figure once more before printing) or removed, as ``report.stages._Stage.figure`` does;
interleaved, thread CPU time summed over the rounds. ``monodromy``: one period of the variational
equations (DOP853 at the state diagram's scouting tolerance, 1e-8) of the paper's chain's orbit
at M = 0.22 (sine) and 0.25 (nonlinear), milliseconds of CPU per integration, best of the rounds.
``--where``: instead, one whole report in this process, every stage in order on one core (the second
process left out, so that every CPU second is counted here), and its CPU split by what spends it: the
imports, each stage, and across the stages the figures' layout, PNG and SVG files, the animation, the
data files, the state diagram's orbit continuations and locations, and the critical points. With a
warm Numba cache this is the warm command's work less its second process's overhead.
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


class _Timed:
    """CPU seconds spent in wrapped callables by label (an outer call counts once: a label's own recursion is not added)."""

    def __init__(self) -> None:
        self.seconds: dict[str, float] = {}
        self.calls: dict[str, int] = {}
        self._inside: set[str] = set()

    def wrap(self, owner, name: str, label: str) -> None:
        original = getattr(owner, name)

        def timed(*args, **kwargs):
            if label in self._inside:
                return original(*args, **kwargs)
            self._inside.add(label)
            start = time.process_time()
            try:
                return original(*args, **kwargs)
            finally:
                self._inside.discard(label)
                self.seconds[label] = self.seconds.get(label, 0.0) + time.process_time() - start
                self.calls[label] = self.calls.get(label, 0) + 1

        setattr(owner, name, timed)


def where() -> dict[str, dict[str, float]]:
    """One report in this process on one core (``--where``): CPU seconds of the imports, of each stage and of the
    mechanisms across them (module docstring), with the number of calls of each."""
    import tempfile

    start = time.process_time()
    import matplotlib.layout_engine as layouts

    import cosserat_chain.experiments.critical as critical
    import cosserat_chain.experiments.diagram as diagram
    import cosserat_chain.plots.chain as chain_plots
    import cosserat_chain.report as report
    from cosserat_chain.report import background, stages

    imports = time.process_time() - start
    timed = _Timed()
    original_write = stages.write_figure

    def write_figure(fig, path, **savefig):
        kind = str(path).rsplit(".", 1)[-1]
        began = time.process_time()
        try:
            return original_write(fig, path, **savefig)
        finally:
            timed.seconds[f"figure files ({kind})"] = timed.seconds.get(f"figure files ({kind})", 0.0) + time.process_time() - began
            timed.calls[f"figure files ({kind})"] = timed.calls.get(f"figure files ({kind})", 0) + 1

    stages.write_figure = write_figure
    timed.wrap(layouts.ConstrainedLayoutEngine, "execute", "figure layout (constrained)")
    timed.wrap(layouts.TightLayoutEngine, "execute", "figure layout (tight)")
    timed.wrap(chain_plots, "animate", "animation (GIF)")
    timed.wrap(stages._Stage, "data", "data files")
    timed.wrap(critical, "critical_point", "critical points")
    for name in ("continue_orbit", "find_periodic_orbit", "locate_cycle_end", "relax"):
        timed.wrap(diagram, name, f"state diagram: {name}")
    background.free_cores = lambda: 1  # every stage here, in order
    with tempfile.TemporaryDirectory() as out:
        result = report.reproduce(out)
    parts = {"imports": imports, **{f"stage {n}": s["cpu_seconds"] for n, s in result.summary["stages"].items()}}
    return {
        "parts": parts,
        "mechanisms": dict(sorted(timed.seconds.items(), key=lambda item: -item[1])),
        "calls": timed.calls,
        "total": time.process_time() - start,
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rounds", type=int, default=3, help="rounds of each measurement (default 3)")
    parser.add_argument("--where", action="store_true", help="instead: one report on one core, its CPU split by what spends it")
    args = parser.parse_args()
    if args.rounds < 1:
        parser.error(f"--rounds must be an integer >= 1, got {args.rounds}")
    load = os.getloadavg()[0]
    if args.where:
        found = where()
        print(f"one report on one core: {found['total']:.2f} s of CPU")
        for label, seconds in found["parts"].items():
            print(f"  {label:34s} {seconds:6.2f}")
        print("across the stages:")
        for label, seconds in found["mechanisms"].items():
            print(f"  {label:34s} {seconds:6.2f}  ({found['calls'][label]} calls)")
        print(f"load average {load:.1f} -> {os.getloadavg()[0]:.1f}")
        return
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
