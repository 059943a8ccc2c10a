"""AUTO-07p's period-doubled family of the paper's sine chain at gamma_phi = 0.15 (N = 3) beside the package's switch
(``cycle_switching.switch_at_period_doubling``, issue 40 item 4).

AUTO continues the one-turn orbit from M = 0.1735 down to its period doubling (``auto07p_chain_fold_step.py``'s
equations and start, STOP PD1), switches there onto the doubled family (ISW = -1: the mesh doubled, the period 2 T)
and follows it down in M to a user point (UZR, UZSTOP) at the package's first doubled orbit; there the package's
doubled orbit solved at AUTO's M (``find_periodic_orbit``, two turns, from the switch's) gives the period and the
Floquet multipliers printed beside AUTO's. The switch is run from both signs of the flip vector (the package's, and
its opposite by hand) with its CPU seconds and the load. Measured (AUTO-07p 0.9.2, NTST = 200 doubled to 400 by the
switch, 312 steps, 120 s of CPU in all at load 11): the user point at M = 0.17287144382642, both signs' first doubled
orbit; AUTO's period there 25.739097371, the switch's 25.7390973707 (solved again at AUTO's printed M, 3.6e-12 off,
25.739097363: dT/dM is about -2000 this near the period doubling); the multipliers above 1e-3 (20 of them, the flip's
square 0.98456) equal to AUTO's 6 printed digits; the switch from the package's e 2.92 s of CPU, from -e 0.90 s.

Needs ``auto-07p`` on the PATH (the Debian package auto-07p, with gfortran). Usage::

    python benchmarks/auto07p_chain_doubled.py WORKDIR
"""

from __future__ import annotations

import os
import sys
import time
from pathlib import Path

import numpy as np

from auto07p_chain_fold_step import SETTINGS
from auto07p_common import b_rows, chain_files, constants_file, multipliers, one_run_script, run_auto
from cosserat_chain import ChainParams
from cosserat_chain.numerics import cycle_switching
from cosserat_chain.numerics.periodic import continue_orbit, find_periodic_orbit
from cosserat_chain.state import n_free


def switches(branch) -> dict[str, cycle_switching.PeriodDoubling]:
    """The switch from the package's sign of the flip vector and from its opposite, with their CPU seconds printed."""
    own = cycle_switching.flip_vector
    out = {}
    for name, sign in (("package's e", 1.0), ("-e by hand", -1.0)):
        cycle_switching.flip_vector = lambda *a, s=sign, **k: (lambda r: (r[0], s * r[1]))(own(*a, **k))
        try:
            start = time.process_time()
            out[name] = cycle_switching.switch_at_period_doubling(branch, follow=False)
            cpu = time.process_time() - start
        finally:
            cycle_switching.flip_vector = own
        d = out[name].doubled
        print(f"switch from the {name}: {cpu:.2f} s of CPU (load {os.getloadavg()[0]:.1f}), M = {d.moment:.14g}, T = {d.period:.12g}")
    return out


def main(workdir: Path, ntst: int = 200, dsmax: float = 1e-3) -> None:
    params = ChainParams(gamma_phi=0.15)
    branch = continue_orbit(find_periodic_orbit(params, "sine", 0.2), period_max=2000.0)
    (event,) = [e for e in branch.events if e["kind"] == "period_doubling"]
    point = event["orbit"]
    switch = switches(branch)["package's e"]
    target = switch.doubled.moment
    orbit = [o for o in branch.orbits if o.moment > 0.1735][-1]
    workdir.mkdir(parents=True, exist_ok=True)
    script = one_run_script("chain", "r1", constants="chain.1", dat="chain") + (
        f"r2 = run(r1('PD1'), c='chain.1', ISW=-1, STOP=[], NMX=1000, UZSTOP={{1: {target!r}}})\nsave(r2, 'r2')\n"
    )
    constants = constants_file(NDIM=2 * n_free(params), NTST=ntst, DSMAX=dsmax, **{**SETTINGS, "STOP": ["PD1"]})
    run_auto(workdir, "chain.auto", {**chain_files(orbit, 601), "c.chain.1": constants, "chain.auto": script})
    for _, kind, values in b_rows(workdir / "b.r1"):
        if kind == 7:
            print(f"AUTO-07p: PD at M = {values[0]:.12g}, period {values[-1]:.11g}; the package's {point.moment:.14g}, {point.period:.11g}")
    # AUTO's label type of a user point is 4, -4 where it ends the run.
    rows = {pt: values for pt, kind, values in b_rows(workdir / "b.r2") if abs(kind) == 4}
    found = {}
    for pt, mu in multipliers(workdir / "d.r2"):
        found.setdefault(pt, []).append(mu)
    for pt, values in rows.items():
        moment, period = values[0], values[-1]
        ours = find_periodic_orbit(params, "sine", moment, turns=2, guess=switch.doubled)
        near = lambda mu: np.sort_complex(np.asarray(mu)[np.abs(mu) > 1e-3])  # noqa: E731
        print(
            f"UZ at M = {moment:.12g} (M_PD - {point.moment - moment:.3g}): AUTO period {period:.11g}, the package's {ours.period:.11g} "
            f"(relative {abs(ours.period - period) / period:.2g}); multipliers above 1e-3: AUTO {near(found.get(pt, [])).round(7)}, "
            f"the package's {near(ours.multipliers).round(7)}"
        )


if __name__ == "__main__":
    main(Path(sys.argv[1] if len(sys.argv) > 1 else "auto07p-chain-doubled"))
