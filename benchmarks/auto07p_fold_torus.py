"""AUTO-07p on three systems of ``tests/test_cycle_curve_codim2_more.py`` built to have codimension-two points of cycles,
beside the package's: the fold-torus point (LTR) on the fold-of-cycles curve of the fold-torus system, and the R3, R4
and R1 points on the torus curve of the resonant system, and the cusp (CP) on the cusp system's fold-of-cycles curve.

The system (a rotor beside a fold x'' = a - 0.1 - 0.5 (s - 0.24) - xi^2 - x' and a circulatory pair
y'' = -(1.44 + xi) y + s J y - 0.2 y') is written as an AUTO-07p equations file (PAR(1) = a, PAR(2) = s); AUTO
continues the rotation down in a to its fold (LP), then the fold in (a, s) from s = 0.2 to 0.3 (ISW = 2). AUTO
labels fold-torus points (LTR) on the curves of maps only, so the point is read from the Floquet multipliers it
prints along the curve: where the pair's modulus crosses 1 (log |mu| interpolated linearly between its two
points around the crossing). The closed form is s = 0.24, a = 0.1.

The resonant system (y'' = -(s - 0.3) y - (a - 0.05 - 0.5 (s - 0.3)) y' beside the rotor) is continued down in a
from 0.12 at s = 0.42 to its torus point (TR), then the torus curve in (a, s) down to s = 0.25: AUTO labels R3, R4
and R1 on it (types -87, -88, -85), at the closed forms s = 0.3 + 1/9, 0.3 + 1/16 and 0.3.

The cusp system (x'' = (a - 0.3) + (s - 0.2) xi - xi^3 - x', the rotor's torque 1 + 0.2 xi) is continued down in a
from 0.29 at s = 0.3 to its fold, then the fold in (a, s) through its turn in s: AUTO labels no CP on the fold curves
of periodic solutions, so the turn is read from its points, the parabola through the three around the least s (in
x, the rest point's coordinate along the curve). The closed form is s = 0.2, a = 0.3.

Needs ``auto-07p`` on the PATH (the Debian package auto-07p, with gfortran). Usage::

    python benchmarks/auto07p_fold_torus.py WORKDIR
"""

from __future__ import annotations

import math
import sys
from pathlib import Path

import numpy as np

from auto07p_common import EMPTY_ROUTINES, b_rows, constants_file, multipliers, run_auto, two_parameter_script
from cosserat_chain.numerics.cycle_curve import continue_cycle_end

EQUATIONS = """      SUBROUTINE FUNC(NDIM,U,ICP,PAR,IJAC,F,DFDU,DFDP)
      IMPLICIT DOUBLE PRECISION (A-H,O-Z)
      DIMENSION U(NDIM),PAR(*),F(NDIM)
      XI=U(2)-0.5D0
      AK=1.44D0+XI
      F(1)=U(5)
      F(2)=U(6)
      F(3)=U(7)
      F(4)=U(8)
      F(5)=1.0D0-U(5)
      F(6)=PAR(1)-0.1D0-0.5D0*(PAR(2)-0.24D0)-XI**2-U(6)
      F(7)=-AK*U(3)+PAR(2)*U(4)-0.2D0*U(7)
      F(8)=-AK*U(4)-PAR(2)*U(3)-0.2D0*U(8)
      RETURN
      END
      SUBROUTINE STPNT(NDIM,U,PAR,T)
      IMPLICIT DOUBLE PRECISION (A-H,O-Z)
      DIMENSION U(NDIM),PAR(*)
      PI=4.0D0*ATAN(1.0D0)
      PAR(1)=0.09D0
      PAR(2)=0.2D0
      PAR(11)=2.0D0*PI
      U(1)=2.0D0*PI*T
      U(2)=0.6D0
      U(3)=0.0D0
      U(4)=0.0D0
      U(5)=1.0D0
      U(6)=0.0D0
      U(7)=0.0D0
      U(8)=0.0D0
      RETURN
      END
"""

#: The three systems' runs in a down to their fold or torus point (each system's NDIM and STOP are :func:`main`'s).
SETTINGS = dict(NTST=20, NMX=200, RL0=0.0, RL1=0.5, NPR=500, DS=-0.001, DSMIN=1e-6, DSMAX=0.005)

RESONANT = """      SUBROUTINE FUNC(NDIM,U,ICP,PAR,IJAC,F,DFDU,DFDP)
      IMPLICIT DOUBLE PRECISION (A-H,O-Z)
      DIMENSION U(NDIM),PAR(*),F(NDIM)
      F(1)=U(3)
      F(2)=U(4)
      F(3)=1.0D0-U(3)
      F(4)=-(PAR(2)-0.3D0)*U(2)-(PAR(1)-0.05D0-0.5D0*(PAR(2)-0.3D0))*U(4)
      RETURN
      END
      SUBROUTINE STPNT(NDIM,U,PAR,T)
      IMPLICIT DOUBLE PRECISION (A-H,O-Z)
      DIMENSION U(NDIM),PAR(*)
      PI=4.0D0*ATAN(1.0D0)
      PAR(1)=0.12D0
      PAR(2)=0.42D0
      PAR(11)=2.0D0*PI
      U(1)=2.0D0*PI*T
      U(2)=0.0D0
      U(3)=1.0D0
      U(4)=0.0D0
      RETURN
      END
"""

CUSP = """      SUBROUTINE FUNC(NDIM,U,ICP,PAR,IJAC,F,DFDU,DFDP)
      IMPLICIT DOUBLE PRECISION (A-H,O-Z)
      DIMENSION U(NDIM),PAR(*),F(NDIM)
      XI=U(2)-0.5D0
      F(1)=U(3)
      F(2)=U(4)
      F(3)=1.0D0+0.2D0*XI-U(3)
      F(4)=PAR(1)-0.3D0+(PAR(2)-0.2D0)*XI-XI**3-U(4)
      RETURN
      END
      SUBROUTINE STPNT(NDIM,U,PAR,T)
      IMPLICIT DOUBLE PRECISION (A-H,O-Z)
      DIMENSION U(NDIM),PAR(*)
      PI=4.0D0*ATAN(1.0D0)
      XI=0.1153D0
      PAR(1)=0.29D0
      PAR(2)=0.3D0
      PAR(11)=2.0D0*PI/(1.0D0+0.2D0*XI)
      U(1)=2.0D0*PI*T
      U(2)=0.5D0+XI
      U(3)=1.0D0+0.2D0*XI
      U(4)=0.0D0
      RETURN
      END
"""

#: AUTO-07p's codes of the points on a torus curve of periodic solutions (its manual's table).
TORUS_CODES = {-85: "R1", -87: "R3", -88: "R4"}


def crossing(fort7: Path, fort9: Path) -> tuple[float, float, float]:
    """(s, a, the pair's angle) where AUTO's printed complex pair's modulus crosses 1 along its curve."""
    rows = {point: (values[0], values[6]) for point, _, values in b_rows(fort7)}
    pairs = {}
    for point, mu in multipliers(fort9):
        if mu.imag > 1e-3 and abs(abs(mu) - 1.0) < 0.2:
            pairs.setdefault(point, (math.log(abs(mu)), math.atan2(mu.imag, mu.real)))
    points = sorted(p for p in pairs if p in rows)
    for p, q in zip(points, points[1:]):
        if pairs[p][0] * pairs[q][0] < 0:
            w = pairs[p][0] / (pairs[p][0] - pairs[q][0])
            (a0, s0), (a1, s1) = rows[p], rows[q]
            return s0 + w * (s1 - s0), a0 + w * (a1 - a0), pairs[p][1] + w * (pairs[q][1] - pairs[p][1])
    raise SystemExit("AUTO's curve has no complex pair crossing the unit circle")


def labelled(fort7: Path) -> list[tuple[int, float, float]]:
    """AUTO's labelled points (type, a, s) from its b-file."""
    return [(kind, values[0], values[6]) for _, kind, values in b_rows(fort7) if kind != 0]


def turn(fort7: Path) -> tuple[float, float]:
    """(s, a) at the least s along AUTO's curve: the parabolas in x (MAX U(2)) through its three points around it."""
    rows = [(values[0], values[6], values[3]) for _, _, values in b_rows(fort7)]
    i = min(range(1, len(rows) - 1), key=lambda k: rows[k][1])
    a, s, x = (np.array(column) for column in zip(*rows[i - 1 : i + 2]))
    fit = np.polyfit(x, s, 2)
    at = -fit[1] / (2 * fit[0])
    return float(np.polyval(fit, at)), float(np.polyval(np.polyfit(x, a, 2), at))


def solve(workdir: Path, name: str, equations: str, constants: str, script: str) -> None:
    """Run AUTO-07p on one problem: its equations (with empty boundary and integral conditions), constants and script."""
    run_auto(workdir, f"{name}.auto", {f"{name}.f90": equations + EMPTY_ROUTINES, f"c.{name}": constants, f"{name}.auto": script})


def main(workdir: Path) -> None:
    workdir.mkdir(parents=True, exist_ok=True)
    script = two_parameter_script("ft", "LP1", "curve", nmx=(200, 200), DS=0.001, DSMAX=0.002, UZSTOP={2: [0.15, 0.3]})
    solve(workdir, "ft", EQUATIONS, constants_file(NDIM=8, **SETTINGS, STOP=["LP1"]), script)
    script = two_parameter_script("rs", "TR1", "rcurve", nmx=(2000, 2000), DS=-0.001, DSMAX=0.005, UZSTOP={2: [0.25, 0.45]})
    solve(workdir, "rs", RESONANT, constants_file(NDIM=4, **SETTINGS, STOP=["TR1"]), script)
    script = two_parameter_script("cu", "LP1", "ccurve", nmx=(400, 400), DS=0.001, DSMAX=0.002, UZSTOP={2: [0.31]})
    solve(workdir, "cu", CUSP, constants_file(NDIM=4, **SETTINGS, STOP=["LP1"]), script)
    s, a, angle = crossing(workdir / "b.curve", workdir / "d.curve")
    print(f"AUTO-07p's fold curve: the pair crosses the unit circle at s = {s:.10g}, a = {a:.10g}, angle {angle:.8g}")
    sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))
    from test_cycle_curve_codim2_more import Resonant, cusp_curve, fold_torus_fold_curve, orbit_at

    (point,) = fold_torus_fold_curve().points
    print(
        f"the package's fold-torus (LTR): s = {point.value:.12g} +- {point.uncertainty:.2g}, a = {point.moment:.12g}, angle {point.angle:.10g}"
    )
    print(f"the closed form: s = 0.24, a = 0.1, angle 2 pi / 5 = {2 * math.pi / 5:.10g}")
    for code, a, s in labelled(workdir / "b.rcurve"):
        if code in TORUS_CODES:
            print(f"AUTO-07p's torus curve: {TORUS_CODES[code]} (type {code}) at s = {s:.11g}, a = {a:.11g}")
    start = orbit_at(Resonant(a=0.12, s=0.42), 0.0)
    for point in continue_cycle_end(start, "torus", "s", [0.42, 0.4, 0.35, 0.31, 0.29], parameter="a").points:
        print(f"the package's {point.label}: s = {point.value:.12g} +- {point.uncertainty:.2g}, a = {point.moment:.12g}")
    print("the closed forms: R3 at s = 0.3 + 1/9, R4 at 0.3 + 1/16, R1 at 0.3, a = 0.05 + 0.5 (s - 0.3)")
    s, a = turn(workdir / "b.ccurve")
    print(f"AUTO-07p's fold curve of the cusp system turns back in s at s = {s:.11g}, a = {a:.10g} (its points' parabola)")
    point = cusp_curve([0.3, 0.15]).points[-1]
    print(
        f"the package's {point.label}: s = {point.value:.12g} +- {point.uncertainty:.2g}, a = {point.moment:.12g}; the closed form 0.2, 0.3"
    )


if __name__ == "__main__":
    main(Path(sys.argv[1] if len(sys.argv) > 1 else "auto07p-fold-torus"))
