"""AUTO-07p's snake of three unequal Josephson junctions (tests/test_snaking_homoclinic.py's ``jj3``): every fold of
cycles of the one-turn rotation continued down in I from 0.97, for the package's collocation through the same folds
(tests/test_system_collocation.py's slow test, folds 1-8; tests/test_snake_folds_sixteenth.py, folds 9-13).

The junctions: phi_i'' + alpha phi_i' + Ic_i sin phi_i = I + kappa (phi_{i+1} - 2 phi_i + phi_{i-1}) with free ends
(PAR(1..6) = I, kappa, alpha, ica, icb, icc), checked against the package's vector field at a random state; the
package's shooting orbit at I = 0.97 is AUTO's starting data. Two sets of runs:

* ``ntst100``, ``ntst200``: the other comparisons' settings (NCOL = 4, EPSL = EPSU = 1e-10, EPSS = 1e-8, ITMX = 8,
  DSMAX = 0.02) to a period of ``PERIOD_STOP``. The two meshes agree on folds 1-8 to their 11 printed digits; beyond
  them each labels some folds only: there the fold function (I's component of the tangent) is ~1e-8 and its noise
  ~1e-11, so the secant iteration that locates a fold does not settle to EPSS within ITMX steps, and AUTO goes on
  without a label.
* ``refined``: EPSL = EPSU = 1e-12, EPSS = 1e-6 (I at a fold is quadratic in the location's error along the branch,
  so no digit of I is lost; the period there is linear in it), ITMX = 20, DSMAX = 0.002, to a period of
  ``REFINED_STOP``, on the meshes ``REFINED_MESHES``: every fold labelled, and I printed to 15 digits through PVLS
  (PAR(12) = (I - ``I_REF``) ``SCALE``, whose 11 printed digits reach 1e-17 in I).

Usage::

    python benchmarks/auto07p_jj3_snake.py [WORKDIR]

writes ``benchmarks/results/auto07p_jj3_snake.json``. Needs ``auto-07p`` on the PATH.
"""

from __future__ import annotations

import json
import resource
import sys
from pathlib import Path

import numpy as np

from auto07p_common import b_rows, run_auto
from auto07p_user_systems import EQUATIONS, fortran
from cosserat_chain.numerics.shooting import find_orbit, settled_guess

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))
from three_junctions import jj3  # noqa: E402 - the tests' system, one definition

#: AUTO stops where the period reaches this (the default runs) or ``REFINED_STOP`` (the refined ones).
PERIOD_STOP = 150.0
REFINED_STOP = 100.0
#: The refined runs' meshes (NTST, NCOL).
REFINED_MESHES = ((200, 4), (400, 4), (400, 7))
#: The refined runs' PAR(12) = (I - I_REF) SCALE (I_REF near the homoclinic end, I = 0.53179413051).
I_REF = 0.5317941
SCALE = 1e6
PARAMETERS = dict(jj3().parameters)
FORCES = (
    "PAR(1)-PAR(4)*SIN(U(1))-PAR(3)*U(4)+PAR(2)*(U(2)-U(1))",
    "PAR(1)-PAR(5)*SIN(U(2))-PAR(3)*U(5)+PAR(2)*(U(1)-2.0D0*U(2)+U(3))",
    "PAR(1)-PAR(6)*SIN(U(3))-PAR(3)*U(6)+PAR(2)*(U(2)-U(3))",
)
CONSTANTS = """NDIM=  6, IPS =   2, IRS =   0, ILP =   1
ICP =  {icp}
NTST=  {ntst}, NCOL=   {ncol}, IAD =   3, ISP =   2, ISW = 1, IPLT= 0, NBC= 0, NINT= 0
NMX= {nmx}, RL0=  0.2, RL1=  1.0, A0=   0.0, A1= 1e6
NPR= {nmx}, MXBF=  10, IID =   2, ITMX=   {itmx}, ITNW= 7, NWTN= 3, JAC= 0
EPSL= {eps}, EPSU = {eps}, EPSS ={epss}
DS  =  -0.002, DSMIN=  {dsmin}, DSMAX=   {dsmax}, IADS=   1
THL =  {{11: 0.0}}, THU =  {{}}
UZSTOP = {{11: {period_stop}}}
"""
DEFAULT = dict(icp=[1, 11], ncol=4, nmx=20000, itmx=8, eps=1e-10, epss=1e-8, dsmin=1e-9, dsmax=0.02, period_stop=PERIOD_STOP)
#: PAR(12) is printed, not free (ICP's third entry; a periodic orbit has one free parameter besides the period).
REFINED = dict(icp=[1, 11, 12], nmx=200000, itmx=20, eps=1e-12, epss=1e-6, dsmin=1e-10, dsmax=0.002, period_stop=REFINED_STOP)
DIGITS = f"""      SUBROUTINE PVLS(NDIM,U,PAR)
      IMPLICIT DOUBLE PRECISION (A-H,O-Z)
      DIMENSION U(NDIM),PAR(*)
      PAR(12)=(PAR(1)-{fortran(I_REF)})*{fortran(SCALE)}
      RETURN
      END
"""
RESULTS = Path(__file__).resolve().parent / "results" / "auto07p_jj3_snake.json"


def main(workdir: Path) -> None:
    system = jj3()
    c = system.parameters
    y = np.random.default_rng(3).standard_normal(6)
    p, v = y[:3], y[3:]
    acc = c["I"] - np.array([c["ica"], c["icb"], c["icc"]]) * np.sin(p) - c["alpha"] * v
    acc += c["kappa"] * np.array([p[1] - p[0], p[0] - 2 * p[1] + p[2], p[1] - p[2]])
    assert np.allclose(system.vector_field(y), np.concatenate([v, acc]), atol=1e-13), "AUTO's equations differ from the package's"
    drift = c["I"] / c["alpha"]
    orbit = find_orbit(
        system,
        settled_guess(system, np.concatenate([np.zeros(3), np.full(3, drift)]), coordinate=0),
        turns=dict.fromkeys(system.coordinates, 1),
    )
    times = np.linspace(0.0, orbit.period, 401)
    states = orbit.trajectory(times, rtol=1e-12, atol=1e-12)
    rows = "".join(" ".join(f"{x:.16E}" for x in (t, *s)) + "\n" for t, s in zip(times / orbit.period, states))
    start = "\n".join(f"      PAR({k})={fortran(value)}" for k, value in zip([1, 2, 3, 4, 5, 6, 11], [*PARAMETERS.values(), orbit.period]))
    equations = EQUATIONS.format(*FORCES, start)
    out = {"parameters": PARAMETERS, "period_stop": PERIOD_STOP}
    settings = {"EPSL": REFINED["eps"], "EPSU": REFINED["eps"]} | {k.upper(): REFINED[k] for k in ("epss", "itmx", "dsmin", "dsmax")}
    refined = {"produced_by": "python benchmarks/auto07p_jj3_snake.py", "settings": settings, "i_ref": I_REF, "scale": SCALE}
    refined |= {"period_stop": REFINED_STOP, "runs": {}}
    runs = [(f"ntst{n}", dict(DEFAULT, ntst=n), False) for n in (100, 200)]
    runs += [(f"ntst{n}_ncol{k}", dict(DEFAULT, **REFINED, ntst=n, ncol=k), True) for n, k in REFINED_MESHES]
    for name, constants, fine in runs:
        where = workdir / name
        where.mkdir(parents=True, exist_ok=True)
        files = {
            "u.f90": equations.replace("      SUBROUTINE PVLS\n      RETURN\n      END\n", DIGITS) if fine else equations,
            "u.dat": rows,
            "c.u": CONSTANTS.format(**constants),
            "u.auto": "r = run('u', c='u', dat='u')\nsave(r, 'u')\n",
        }
        before = resource.getrusage(resource.RUSAGE_CHILDREN)
        run_auto(where, "u.auto", files)
        after = resource.getrusage(resource.RUSAGE_CHILDREN)
        folds, last = [], None
        for _, kind, row in b_rows(where / "b.u"):
            # A refined row ends in PERIOD, PAR(12); a default one in PERIOD.
            last = {"I": I_REF + row[-1] / SCALE, "period": row[-2]} if fine else {"I": row[0], "period": row[-1]}
            if kind == 5:
                folds.append(last)
        if fine:
            cpu = after.ru_utime + after.ru_stime - before.ru_utime - before.ru_stime
            refined["runs"][name] = {
                "ntst": constants["ntst"],
                "ncol": constants["ncol"],
                "folds": folds,
                "cpu_s_with_compile": round(cpu, 1),
            }
        else:
            out[name] = {"folds": folds, "last": last}
        print(f"{name}: {len(folds)} folds", *(f"I = {f['I']:.15f} (T = {f['period']:.6f})" for f in folds), sep="\n  ")
    out["refined"] = refined
    RESULTS.write_text(json.dumps(out, indent=1) + "\n")
    print(f"wrote {RESULTS}")


if __name__ == "__main__":
    main(Path(sys.argv[1] if len(sys.argv) > 1 else "auto07p-jj3-snake"))
