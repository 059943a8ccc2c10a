"""What the AUTO-07p comparisons share: running AUTO on a problem's files, its two-parameter script,
and reading its output (the b-file's rows and labels, the d-file's Floquet multipliers).

Benchmark code only, not part of the package. Needs ``auto-07p`` on the PATH (the Debian package
auto-07p, with gfortran).
"""

from __future__ import annotations

import os
import re
import subprocess
from collections.abc import Iterator
from pathlib import Path

#: A Floquet multiplier's line of an AUTO d-file: the point's number, the real and imaginary parts.
MULTIPLIER = re.compile(r"\s+\d+\s+(\d+)\s+Multiplier\s+\d+\s+(\S+)\s+(\S+)\s+Abs")


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
    first = f"r1 = run('{name}', c='{c}'" + (f", dat='{dat}'" if dat else "") + ")"
    options = ", ".join(f"{key}={value!r}" for key, value in settings.items())
    runs = [
        f"run({source}, c='{c}', ICP=[1, 2, 11], ISW=2, {options}, NMX={n}, STOP=[])"
        for source, n in ((f"r1('{start}')", nmx[0]), ("start('EP1')", nmx[1]))
    ]
    return f"{first}\nsave(r1, 'r1')\nstart = {runs[0]}\nsave(start, 'start')\ncurve = {runs[1]}\nsave(curve, '{curve}')\n"


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
