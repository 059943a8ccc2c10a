"""AUTO-07p's snake of three unequal Josephson junctions (tests/test_snaking_homoclinic.py's ``jj3``): every fold of
cycles of the one-turn rotation continued down in I from 0.97 to a period of ``PERIOD_STOP``, at NTST = 100 and 200
(NCOL = 4; the difference is AUTO's own error), for tests/test_system_collocation.py's slow test of the package's
collocation through the same folds.

The junctions: phi_i'' + alpha phi_i' + Ic_i sin phi_i = I + kappa (phi_{i+1} - 2 phi_i + phi_{i-1}) with free ends
(PAR(1..6) = I, kappa, alpha, ica, icb, icc), checked against the package's vector field at a random state; the
package's shooting orbit at I = 0.97 is AUTO's starting data. Usage::

    python benchmarks/auto07p_jj3_snake.py [WORKDIR]

writes ``benchmarks/results/auto07p_jj3_snake.json``. Needs ``auto-07p`` on the PATH.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np

from auto07p_common import b_rows, run_auto
from auto07p_user_systems import EQUATIONS, fortran
from cosserat_chain.numerics.shooting import find_orbit, settled_guess

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))
from three_junctions import jj3  # noqa: E402 - the tests' system, one definition

#: AUTO stops where the period reaches this.
PERIOD_STOP = 150.0
PARAMETERS = dict(jj3().parameters)
FORCES = (
    "PAR(1)-PAR(4)*SIN(U(1))-PAR(3)*U(4)+PAR(2)*(U(2)-U(1))",
    "PAR(1)-PAR(5)*SIN(U(2))-PAR(3)*U(5)+PAR(2)*(U(1)-2.0D0*U(2)+U(3))",
    "PAR(1)-PAR(6)*SIN(U(3))-PAR(3)*U(6)+PAR(2)*(U(2)-U(3))",
)
CONSTANTS = """NDIM=  6, IPS =   2, IRS =   0, ILP =   1
ICP =  [1, 11]
NTST=  {ntst}, NCOL=   4, IAD =   3, ISP =   2, ISW = 1, IPLT= 0, NBC= 0, NINT= 0
NMX= 20000, RL0=  0.2, RL1=  1.0, A0=   0.0, A1= 1e6
NPR= 50000, MXBF=  10, IID =   2, ITMX=   8, ITNW= 7, NWTN= 3, JAC= 0
EPSL= 1e-10, EPSU = 1e-10, EPSS =1e-08
DS  =  -0.002, DSMIN=  1e-9, DSMAX=   0.02, IADS=   1
THL =  {{11: 0.0}}, THU =  {{}}
UZSTOP = {{11: {period_stop}}}
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
    out = {"parameters": PARAMETERS, "period_stop": PERIOD_STOP}
    for ntst in (100, 200):
        where = workdir / f"ntst{ntst}"
        where.mkdir(parents=True, exist_ok=True)
        files = {
            "u.f90": EQUATIONS.format(*FORCES, start),
            "u.dat": rows,
            "c.u": CONSTANTS.format(ntst=ntst, period_stop=PERIOD_STOP),
            "u.auto": "r = run('u', c='u', dat='u')\nsave(r, 'u')\n",
        }
        run_auto(where, "u.auto", files)
        folds, last = [], None
        for _, kind, row in b_rows(where / "b.u"):
            last = {"I": row[0], "period": row[-1]}
            if kind == 5:
                folds.append({"I": row[0], "period": row[-1]})
        out[f"ntst{ntst}"] = {"folds": folds, "last": last}
        print(f"NTST = {ntst}: {len(folds)} folds", *(f"I = {f['I']:.11f} (T = {f['period']:.4f})" for f in folds), sep="\n  ")
    RESULTS.write_text(json.dumps(out, indent=1) + "\n")
    print(f"wrote {RESULTS}")


if __name__ == "__main__":
    main(Path(sys.argv[1] if len(sys.argv) > 1 else "auto07p-jj3-snake"))
