"""AUTO-07p's torus curve of the paper's chain in (M, E2), beside ``numerics.cycle_curve``'s codimension-two points.

The sine chain's equations are linear in (u, v, sin phi) with a stiffness K linear in E2
(``auto07p_common.chain_equations``). This script writes them as an AUTO-07p
equations file (the matrices as data, checked against the package's vector field), the package's
one-turn orbit at 1.05 M_c as AUTO's starting data, and runs: (1) the orbit continued down in M to
its torus point (TR); (2) that point continued in (M, E2) both ways (ISW = 2, a first run that
generates the extended system's data, then the curve). It prints AUTO's TR point, the branch point
its two-parameter run reports (the 1:2 resonance) and where the printed critical pair's angle passes
2 pi / 3 and pi / 2 (R3, R4; AUTO does not label them), next to the package's values. AUTO's label
types: 8 its TR point, 86 the branch point of the torus curve's extended system (the 1:2 resonance,
where the pair reaches -1), -84 the end at E2 = 0.6.

Needs ``auto-07p`` on the PATH (the Debian package auto-07p, with gfortran). Usage::

    python benchmarks/auto07p_torus_curve.py WORKDIR
"""

from __future__ import annotations

import math
import sys
from pathlib import Path

from auto07p_common import b_rows, chain_files, constants_file, multipliers, run_auto, two_parameter_script
from cosserat_chain import ChainParams
from cosserat_chain.numerics.continuation import locate_fold
from cosserat_chain.numerics.periodic import find_periodic_orbit
from cosserat_chain.state import n_free

#: The run in M down to the torus point.
SETTINGS = dict(
    NTST=60, NMX=300, RL0=0.15, RL1=0.3, NPR=500, EPSL=1e-08, EPSU=1e-08, EPSS=1e-06, DS=-0.001, DSMIN=1e-5, DSMAX=0.005, STOP=["TR1"]
)


def points(fort7: Path, fort9: Path) -> tuple[list, dict]:
    """AUTO's labelled points (type, M, E2, period) and each point's critical pair angle, from its output files."""
    labelled, rows, angles = [], {}, {}
    for point, kind, values in b_rows(fort7):
        rows[point] = row = (values[0], values[6], values[7])
        if kind != 0:
            labelled.append((kind, *row))
    for point, mu in multipliers(fort9):
        if mu.imag > 0 and abs(abs(mu) - 1.0) < 1e-3:
            angles.setdefault(point, math.atan2(mu.imag, mu.real))
    return labelled, {pt: (*rows[pt], angles[pt]) for pt in rows if pt in angles}


def main(workdir: Path) -> None:
    params = ChainParams()
    orbit = find_periodic_orbit(params, "sine", 1.05 * locate_fold(params, "sine").moment)
    workdir.mkdir(parents=True, exist_ok=True)
    script = two_parameter_script(
        "chain", "TR1", "curve", constants="chain.1", dat="chain", nmx=(300, 400), ISP=2, DS=0.002, DSMAX=0.01, UZSTOP={2: [0.6, 1.2]}
    )
    files = {**chain_files(orbit, 301), "c.chain.1": constants_file(NDIM=2 * n_free(params), **SETTINGS), "chain.auto": script}
    run_auto(workdir, "chain.auto", files)
    labelled, curve = points(workdir / "b.curve", workdir / "d.curve")
    for kind, moment, _, period in points(workdir / "b.r1", workdir / "d.r1")[0]:
        print(f"AUTO's run in M, label type {kind}: M = {moment:.11g}, period = {period:.11g} (E2 = {params.E2})")
    for kind, moment, e2, period in labelled:
        print(f"AUTO's torus curve, label type {kind}: M = {moment:.11g}, E2 = {e2:.11g}, period = {period:.11g}")
    ordered = [curve[pt] for pt in sorted(curve)]
    for target, name in ((2 * math.pi / 3, "R3"), (math.pi / 2, "R4")):
        for a, b in zip(ordered, ordered[1:]):
            if (a[3] - target) * (b[3] - target) < 0:
                w = (target - a[3]) / (b[3] - a[3])
                print(f"AUTO's pair passes the {name} angle at E2 = {a[1] + w * (b[1] - a[1]):.8g}, M = {a[0] + w * (b[0] - a[0]):.8g}")
    print("the package (docs/state-diagram.md): R2 at E2 = 1.1336439615, R3 at 0.92131306, R4 at 0.72809819")


if __name__ == "__main__":
    main(Path(sys.argv[1] if len(sys.argv) > 1 else "auto07p-torus-curve"))
