"""What the AUTO-07p comparisons share: the constants file, the equations file of a chain or of three coupled
angles with an orbit of the package's as AUTO's starting data, running AUTO on a problem's files, its one- and
two-parameter scripts, and reading its output (the b-file's rows and labels, the d-file's Floquet multipliers).

Benchmark code only, not part of the package. Needs ``auto-07p`` on the PATH (the Debian package
auto-07p, with gfortran).
"""

from __future__ import annotations

import os
import re
import subprocess
from collections.abc import Iterator, Sequence
from pathlib import Path

import numpy as np
from scipy.integrate import solve_ivp

from cosserat_chain import ChainParams
from cosserat_chain.models.base import get_model
from cosserat_chain.models.linear import stiffness_matrix
from cosserat_chain.numerics.periodic import PeriodicOrbit, _System, _to_y
from cosserat_chain.state import free_rows, n_free

#: A Floquet multiplier's line of an AUTO d-file: the point's number, the real and imaginary parts.
MULTIPLIER = re.compile(r"\s+\d+\s+(\d+)\s+Multiplier\s+\d+\s+(\S+)\s+(\S+)\s+Abs")


#: AUTO-07p's constants every comparison here shares: periodic orbits (IPS = 2) continued in PAR(1) with the period
#: PAR(11) free and left out of the step's norm (THL), NCOL = 4 on an adapted mesh, folds (ILP) and period doublings and
#: tori (ISP = 2) detected. A run adds its own (:func:`constants_file`): NDIM, NTST, NMX, RL0, RL1, NPR, DS, DSMIN, DSMAX, stops.
SHARED_CONSTANTS = {
    "IPS": 2,
    "IRS": 0,
    "ILP": 1,
    "ICP": [1, 11],
    "NCOL": 4,
    "IAD": 3,
    "ISP": 2,
    "ISW": 1,
    "IPLT": 0,
    "NBC": 0,
    "NINT": 0,
    "A0": 0.0,
    "A1": 1000.0,
    "MXBF": 10,
    "IID": 2,
    "ITMX": 8,
    "ITNW": 7,
    "NWTN": 3,
    "JAC": 0,
    "EPSL": 1e-10,
    "EPSU": 1e-10,
    "EPSS": 1e-08,
    "IADS": 1,
    "THL": {11: 0.0},
    "THU": {},
}

#: The routines an equations file must define and these problems leave empty.
EMPTY_ROUTINES = "".join(f"      SUBROUTINE {name}\n      RETURN\n      END\n" for name in ("BCND", "ICND", "FOPT", "PVLS"))

#: AUTO's equations file of three coordinates U(1..3) of second order (their rates U(4..6)): ``{0}``, ``{1}``, ``{2}``
#: the three accelerations in Fortran, ``{3}`` STPNT's lines (the parameters, :func:`parameter_lines`).
EQUATIONS = (
    """      SUBROUTINE FUNC(NDIM,U,ICP,PAR,IJAC,F,DFDU,DFDP)
      IMPLICIT DOUBLE PRECISION (A-H,O-Z)
      DIMENSION U(NDIM),PAR(*),F(NDIM)
      F(1)=U(4)
      F(2)=U(5)
      F(3)=U(6)
      F(4)={0}
      F(5)={1}
      F(6)={2}
      RETURN
      END
      SUBROUTINE STPNT(NDIM,U,PAR,T)
      IMPLICIT DOUBLE PRECISION (A-H,O-Z)
      DIMENSION U(NDIM),PAR(*)
{3}
      RETURN
      END
"""
    + EMPTY_ROUTINES
)


def constants_file(**settings) -> str:
    """AUTO-07p's constants file: :data:`SHARED_CONSTANTS` with ``settings`` (AUTO's names and values) added or in their
    place, one ``NAME = value`` a line."""
    return "".join(f"{name} = {value!r}\n" for name, value in {**SHARED_CONSTANTS, **settings}.items())


def fortran(value: float) -> str:
    """A double precision constant in Fortran, to the last digit (``1.25D+00``)."""
    return f"{value:.17E}".replace("E", "D")


def parameter_lines(values: Sequence[float]) -> str:
    """STPNT's lines setting PAR(1), PAR(2), ... to ``values``, the last of them (the period) in PAR(11)."""
    slots = [*range(1, len(values)), 11]
    return "\n".join(f"      PAR({k})={fortran(v)}" for k, v in zip(slots, values))


def data_file(tau: np.ndarray, states: np.ndarray) -> str:
    """AUTO's starting data: a row a scaled time ``tau`` (k,) in [0, 1], then the state there (``states`` (k, ndim))."""
    return "".join(" ".join(f"{v:.16E}" for v in (t, *y)) + "\n" for t, y in zip(tau, states))


def one_run_script(name: str, save: str, *, constants: str | None = None, dat: str | None = None) -> str:
    """AUTO's script of one run of problem ``name`` (constants file ``constants``, default ``name``, starting data
    ``dat``), saved as ``save``."""
    c = constants or name
    return f"r1 = run('{name}', c='{c}'" + (f", dat='{dat}'" if dat else "") + f")\nsave(r1, '{save}')\n"


def orbit_files(accelerations: Sequence[str], parameters: Sequence[float], orbit, samples: int = 401) -> dict[str, str]:
    """The equations file ``u.f90`` of three angles (:data:`EQUATIONS`) and their orbit ``orbit`` of the package
    (``numerics.shooting.Orbit``) as AUTO's starting data ``u.dat`` (``samples`` points), PAR(1), PAR(2), ... the
    ``parameters`` and PAR(11) the period."""
    times = np.linspace(0.0, orbit.period, samples)
    states = orbit.trajectory(times, rtol=1e-12, atol=1e-12)
    return {
        "u.f90": EQUATIONS.format(*accelerations, parameter_lines([*parameters, orbit.period])),
        "u.dat": data_file(times / orbit.period, states),
    }


def chain_equations(params: ChainParams, moment: float, period: float) -> str:
    """The sine chain's vector field in AUTO's FUNC (PAR(1) = M, PAR(2) = E2) and its start in STPNT.

    The equations are linear in (u, v, sin phi) with a stiffness K linear in E2, M q'' = -(K0 + E2 K1) s(q) - Gamma q'
    + M_load e_0: the matrices go in as data, checked against the package's vector field at a random state.
    """
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
            lines.append(f"      DATA ({name}(I),I={i + 1},{i + chunk.size}) /{','.join(fortran(v) for v in chunk)}/")
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
        f"      PAR(1)={fortran(moment)}",
        f"      PAR(2)={fortran(params.E2)}",
        f"      PAR(11)={fortran(period)}",
        "      RETURN",
        "      END",
    ]
    y = np.random.default_rng(2).standard_normal(2 * nf)
    q, qd = y[:nf], y[nf:]
    s = np.where(rows == 2, np.sin(q), q)
    acc = -(k0 + params.E2 * k1) @ s - damping * qd
    acc[load] += moment
    assert np.allclose(_System(params, get_model("sine"), moment, 0).velocity(y)[nf:], acc / mass, atol=1e-12)
    return "\n".join(lines) + "\n" + EMPTY_ROUTINES


def chain_files(orbit: PeriodicOrbit, samples: int) -> dict[str, str]:
    """The sine chain's equations file ``chain.f90`` (:func:`chain_equations`) at the orbit's moment and its orbit
    ``orbit`` of the package as AUTO's starting data ``chain.dat`` (``samples`` points, integrated again by DOP853)."""
    params = orbit.params
    system = _System(params, get_model("sine"), orbit.moment, 0)
    times = np.linspace(0.0, orbit.period, samples)
    start = _to_y(params, orbit.x, orbit.v)
    states = solve_ivp(system.rhs(0), (0.0, orbit.period), start, method="DOP853", rtol=1e-12, atol=1e-12, t_eval=times).y.T
    return {"chain.f90": chain_equations(params, orbit.moment, orbit.period), "chain.dat": data_file(times / orbit.period, states)}


def run_auto(workdir: Path, script_name: str, files: dict[str, str]) -> None:
    """Write ``files`` (name -> text) into ``workdir`` and run AUTO-07p's script ``script_name`` there on one thread."""
    for name, text in files.items():
        (workdir / name).write_text(text)
    subprocess.run(["auto-07p", script_name], cwd=workdir, check=True, env={**os.environ, "OMP_NUM_THREADS": "1"})


def two_parameter_script(
    name: str, start: str, curve: str, *, constants: str | None = None, dat: str | None = None, nmx: tuple[int, int], **settings
) -> str:
    """AUTO's script of a one-parameter run to a special point ``start`` (e.g. 'LP1', 'TR1'), then that point continued in
    PAR(1), PAR(2) (ISW = 2): a first run that generates the extended system's data, then the curve, saved as ``curve``.

    ``constants`` names the constants file (default ``name``), ``dat`` a starting-data file; ``nmx`` is the two runs'
    NMX; ``settings`` (DS, DSMAX, UZSTOP, ISP, ...) go to both two-parameter runs.
    """
    c = constants or name
    options = ", ".join(f"{key}={value!r}" for key, value in settings.items())
    runs = [
        f"run({source}, c='{c}', ICP=[1, 2, 11], ISW=2, {options}, NMX={n}, STOP=[])"
        for source, n in ((f"r1('{start}')", nmx[0]), ("start('EP1')", nmx[1]))
    ]
    return f"{one_run_script(name, 'r1', constants=c, dat=dat)}start = {runs[0]}\nsave(start, 'start')\ncurve = {runs[1]}\nsave(curve, '{curve}')\n"


def b_rows(path: Path) -> Iterator[tuple[int, int, list[float]]]:
    """Every numeric row of an AUTO b-file: (point number, label type, the row's numbers from its fifth field on)."""
    for line in path.read_text().splitlines():
        f = line.split()
        if len(f) >= 12 and all(re.fullmatch(r"-?\d+", x) for x in f[:3]):
            try:
                values = [float(x) for x in f[4:]]
            except ValueError:
                continue
            yield abs(int(f[1])), int(f[2]), values


def fortran_float(text: str) -> float:
    """A number as Fortran prints it, also where a three-digit exponent has lost its E (``1.79769+308``)."""
    return float(re.sub(r"(\d)([+-]\d{3})$", r"\1E\2", text))


def multipliers(path: Path) -> Iterator[tuple[int, complex]]:
    """Every Floquet multiplier an AUTO d-file prints: (point number, multiplier)."""
    for line in path.read_text().splitlines():
        if m := MULTIPLIER.match(line):
            yield int(m[1]), complex(fortran_float(m[2]), fortran_float(m[3]))
