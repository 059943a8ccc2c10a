"""AUTO-07p's torus curve of the paper's chain in (M, E2), beside ``numerics.cycle_curve``'s codimension-two points.

The sine chain's equations are linear in (u, v, sin phi) with a stiffness K linear in E2:
M q'' = -(K0 + E2 K1) s(q) - Gamma q' + M_load e_0. This script writes them as an AUTO-07p
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

import numpy as np
from scipy.integrate import solve_ivp

from auto07p_common import b_rows, multipliers, run_auto, two_parameter_script
from cosserat_chain import ChainParams
from cosserat_chain.models.base import get_model
from cosserat_chain.models.linear import stiffness_matrix
from cosserat_chain.numerics.continuation import locate_fold
from cosserat_chain.numerics.periodic import _System, _to_y, find_periodic_orbit
from cosserat_chain.state import free_rows, n_free

CONSTANTS = """NDIM=  {ndim}, IPS =   2, IRS =   0, ILP =   1
ICP =  [1, 11]
NTST=  60, NCOL=   4, IAD =   3, ISP =   2, ISW = 1, IPLT= 0, NBC= 0, NINT= 0
NMX=  300, RL0=  0.15, RL1=  0.3, A0=   0.0, A1= 1000.0
NPR=  500, MXBF=  10, IID =   2, ITMX=   8, ITNW= 7, NWTN= 3, JAC= 0
EPSL= 1e-08, EPSU = 1e-08, EPSS =1e-06
DS  =  -0.001, DSMIN=  1e-5, DSMAX=   0.005, IADS=   1
THL =  {{11: 0.0}}, THU =  {{}}
STOP = ['TR1']
"""


def fortran(values: np.ndarray) -> str:
    return ",".join(f"{v:.17E}".replace("E", "D") for v in values)


def equations(params: ChainParams, moment: float, period: float) -> str:
    """The chain's vector field in AUTO's FUNC (PAR(1) = M, PAR(2) = E2) and its start in STPNT."""
    nf, rows = n_free(params), free_rows(params)
    k0 = stiffness_matrix(params.replace(E2=0.0)).toarray()
    k1 = stiffness_matrix(params.replace(E2=1.0)).toarray() - k0
    assert np.allclose(k0 + 0.7 * k1, stiffness_matrix(params.replace(E2=0.7)).toarray(), atol=1e-14)
    mass = np.where(rows == 2, params.j, params.m)
    damping = np.where(rows == 0, params.gamma_u, np.where(rows == 1, params.gamma_v, params.gamma_phi))
    load = _System(params, get_model("sine"), moment, 0).load_dof
    lines = [
        "      SUBROUTINE FUNC(NDIM,U,ICP,PAR,IJAC,F,DFDU,DFDP)",
        "      IMPLICIT DOUBLE PRECISION (A-H,O-Z)",
        f"      DIMENSION U(NDIM),PAR(*),F(NDIM),S({nf}),B0({nf * nf}),B1({nf * nf}),AM({nf}),G({nf})",
    ]
    for name, array in (("B0", k0), ("B1", k1), ("AM", mass), ("G", damping)):
        flat = array.ravel(order="F")
        for i in range(0, flat.size, 3):
            chunk = flat[i : i + 3]
            lines.append(f"      DATA ({name}(I),I={i + 1},{i + chunk.size}) /{fortran(chunk)}/")
    lines += [f"      N={nf}", "      DO I=1,N", "        S(I)=U(I)", "      ENDDO"]
    lines += [f"      S({i + 1})=SIN(U({i + 1}))" for i in np.flatnonzero(rows == 2)]
    lines += [
        "      DO I=1,N",
        "        F(I)=U(N+I)",
        "        ACC=-G(I)*U(N+I)",
        "        DO J=1,N",
        "          ACC=ACC-(B0(I+(J-1)*N)+PAR(2)*B1(I+(J-1)*N))*S(J)",
        "        ENDDO",
        f"        IF(I.EQ.{load + 1}) ACC=ACC+PAR(1)",
        "        F(N+I)=ACC/AM(I)",
        "      ENDDO",
        "      RETURN",
        "      END",
        "      SUBROUTINE STPNT(NDIM,U,PAR)",
        "      IMPLICIT DOUBLE PRECISION (A-H,O-Z)",
        "      DIMENSION U(NDIM),PAR(*)",
        f"      PAR(1)={fortran([moment])}",
        f"      PAR(2)={fortran([params.E2])}",
        f"      PAR(11)={fortran([period])}",
        "      RETURN",
        "      END",
    ]
    for name in ("BCND", "ICND", "FOPT", "PVLS"):
        lines += [f"      SUBROUTINE {name}", "      RETURN", "      END"]
    # The same vector field as the package's, at a random state.
    y = np.random.default_rng(2).standard_normal(2 * nf)
    q, qd = y[:nf], y[nf:]
    s = np.where(rows == 2, np.sin(q), q)
    acc = -(k0 + params.E2 * k1) @ s - damping * qd
    acc[load] += moment
    assert np.allclose(_System(params, get_model("sine"), moment, 0).velocity(y)[nf:], acc / mass, atol=1e-12)
    return "\n".join(lines) + "\n"


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
    (workdir / "chain.f90").write_text(equations(params, orbit.moment, orbit.period))
    system = _System(params, get_model("sine"), orbit.moment, 0)
    times = np.linspace(0.0, orbit.period, 301)
    states = solve_ivp(
        system.rhs(0), (0.0, orbit.period), _to_y(params, orbit.x, orbit.v), method="DOP853", rtol=1e-12, atol=1e-12, t_eval=times
    ).y.T
    (workdir / "chain.dat").write_text("".join(" ".join(f"{v:.15E}" for v in (t, *y)) + "\n" for t, y in zip(times / orbit.period, states)))
    script = two_parameter_script(
        "chain", "TR1", "curve", constants="chain.1", dat="chain", nmx=(300, 400), ISP=2, DS=0.002, DSMAX=0.01, UZSTOP={2: [0.6, 1.2]}
    )
    run_auto(workdir, "chain.auto", {"c.chain.1": CONSTANTS.format(ndim=2 * n_free(params)), "chain.auto": script})
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
