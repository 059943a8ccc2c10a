"""AUTO-07p on the paper's sine chain at gamma_phi = 0.15 (N = 3): its one-turn orbit from M = 0.1735 down to the fold of
cycles, with the period doubling on the way (``tests/test_chain_cycle_events_fold.py``, issue 40 item 4).

The chain's equations are those of ``auto07p_torus_curve.py`` (the matrices as data, checked against the package's
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

import numpy as np
from scipy.integrate import solve_ivp

from auto07p_common import b_rows, run_auto
from auto07p_torus_curve import equations
from cosserat_chain import ChainParams
from cosserat_chain.models.base import get_model
from cosserat_chain.numerics.periodic import _System, _to_y, continue_orbit, find_periodic_orbit
from cosserat_chain.state import n_free

CONSTANTS = """NDIM=  {ndim}, IPS =   2, IRS =   0, ILP =   1
ICP =  [1, 11]
NTST=  {ntst}, NCOL=   4, IAD =   3, ISP =   2, ISW = 1, IPLT= 0, NBC= 0, NINT= 0
NMX=  3000, RL0=  0.15, RL1=  0.3, A0=   0.0, A1= 1000.0
NPR=  5000, MXBF=  10, IID =   2, ITMX=   8, ITNW= 7, NWTN= 3, JAC= 0
EPSL= 1e-10, EPSU = 1e-10, EPSS =1e-08
DS  =  -1e-4, DSMIN=  1e-7, DSMAX=   {dsmax}, IADS=   1
THL =  {{11: 0.0}}, THU =  {{}}
STOP = ['LP1']
"""


def main(workdir: Path, ntst: int = 200, dsmax: float = 1e-3) -> None:
    params = ChainParams(gamma_phi=0.15)
    branch = continue_orbit(find_periodic_orbit(params, "sine", 0.2), period_max=2000.0)
    orbit = [o for o in branch.orbits if o.moment > 0.1735][-1]
    workdir.mkdir(parents=True, exist_ok=True)
    (workdir / "chain.f90").write_text(equations(params, orbit.moment, orbit.period))
    system = _System(params, get_model("sine"), orbit.moment, 0)
    times = np.linspace(0.0, orbit.period, 601)
    states = solve_ivp(
        system.rhs(0), (0.0, orbit.period), _to_y(params, orbit.x, orbit.v), method="DOP853", rtol=1e-12, atol=1e-12, t_eval=times
    ).y.T
    (workdir / "chain.dat").write_text("".join(" ".join(f"{v:.15E}" for v in (t, *y)) + "\n" for t, y in zip(times / orbit.period, states)))
    script = "r1 = run('chain', c='chain.1', dat='chain')\nsave(r1, 'r1')\n"
    constants = CONSTANTS.format(ndim=2 * n_free(params), ntst=ntst, dsmax=dsmax)
    run_auto(workdir, "chain.auto", {"c.chain.1": constants, "chain.auto": script})
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
