"""AUTO-07p on the paper's sine chain at gamma_phi = 0.15 (N = 3): its one-turn orbit from M = 0.1735 down to the fold of
cycles, with the period doubling on the way (``tests/test_chain_cycle_events_fold.py``, issue 40 item 4).

The chain's equations are ``auto07p_common.chain_equations`` (the matrices as data, checked against the package's
vector field). The package's branch from M = 0.2 (``periodic.continue_orbit``) gives AUTO its start, the orbit last
above M = 0.1735 (0.4 % above the period doubling); AUTO continues it down in M (ICP = [1, 11]) with period-doubling
detection (ISP = 2) to its first fold (STOP LP1) and its PD and LP labels (M, period) are printed beside the
package's located period doubling and fold. Measured: AUTO's PD at 0.17288242687 (period 12.85836551) and LP at
0.17073193979 (period 13.766022526); the package's period doubling 0.17288242686549 (period 12.85836551), its fold
by the parabola through the last three orbits 0.17073193373706 and as the kit locates it 0.17073193980413.

Needs ``auto-07p`` on the PATH (the Debian package auto-07p, with gfortran). Usage::

    python benchmarks/auto07p_chain_fold_step.py WORKDIR
"""

from __future__ import annotations

import sys
from pathlib import Path

from auto07p_common import b_rows, chain_files, constants_file, one_run_script, run_auto
from cosserat_chain import ChainParams
from cosserat_chain.numerics.periodic import continue_orbit, find_periodic_orbit
from cosserat_chain.state import n_free

#: The run in M down to the fold of cycles (NTST and DSMAX are :func:`main`'s).
SETTINGS = dict(NMX=3000, RL0=0.15, RL1=0.3, NPR=5000, DS=-1e-4, DSMIN=1e-7, STOP=["LP1"])


def main(workdir: Path, ntst: int = 200, dsmax: float = 1e-3) -> None:
    params = ChainParams(gamma_phi=0.15)
    branch = continue_orbit(find_periodic_orbit(params, "sine", 0.2), period_max=2000.0)
    orbit = [o for o in branch.orbits if o.moment > 0.1735][-1]
    workdir.mkdir(parents=True, exist_ok=True)
    files = {
        **chain_files(orbit, 601),
        "c.chain.1": constants_file(NDIM=2 * n_free(params), NTST=ntst, DSMAX=dsmax, **SETTINGS),
        "chain.auto": one_run_script("chain", "r1", constants="chain.1", dat="chain"),
    }
    run_auto(workdir, "chain.auto", files)
    names = {7: "PD", 5: "LP", 8: "TR"}
    for _, kind, values in b_rows(workdir / "b.r1"):
        if kind in names:
            print(f"AUTO-07p (NTST = {ntst}, DSMAX = {dsmax:g}): {names[kind]} at M = {values[0]:.12g}, period {values[-1]:.11g}")
    for event in branch.events:
        if event["kind"] == "period_doubling":
            print(f"the package: period doubling at M = {event['moment']:.14g}, period {event['orbit'].period:.11g}")
    print(f"the package: {branch.end} at M = {branch.end_moment:.14g}")


if __name__ == "__main__":
    main(Path(sys.argv[1] if len(sys.argv) > 1 else "auto07p-chain-fold-step"))
