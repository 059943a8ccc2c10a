"""``cosserat-chain export RUN.nc --to {vtk,xyz,csv} --out PATH``: a run for ParaView, OVITO, ASE or a spreadsheet."""

from __future__ import annotations

from enum import Enum
from pathlib import Path

import typer

from ..exports import FORMATS
from .common import app, bar_callback, fail, outputs_or_exit, progress_bar, run_or_exit

#: The ``--to`` choices: the formats of :data:`cosserat_chain.exports.FORMATS` (a light import: NumPy and the geometry).
ExportFormat = Enum("ExportFormat", {name: name for name in FORMATS}, type=str)


@app.command()
def export(
    run: Path = typer.Argument(..., help="NetCDF run written by `simulate --out`."),
    to: ExportFormat = typer.Option(
        ..., "--to", help="vtk: a ParaView .pvd collection of .vtu frames; xyz: extended XYZ for OVITO and ASE (boxes with orientation, mass, velocities; see docs/files.md); csv: long format."
    ),
    out: Path = typer.Option(..., "--out", help="File to write: .pvd for vtk (its frames go to OUT_frames/), .xyz, .csv."),
) -> None:
    """Write a run in a format other tools read: VTK (ParaView, meshio), extended XYZ (OVITO, ASE) or CSV."""
    outputs_or_exit({"--out": out}, {"RUN": run}, formats={"--out": (FORMATS[to.value],)})
    if to.value == "vtk":
        from ..exports import frames_folder
        from ..io import OutputError

        try:
            frames_folder(out)  # a folder of the user's in the way is refused before any work
        except OutputError as err:
            fail(f"--out {str(out)!r}: {err}")
    ds = run_or_exit(run, velocities=True)
    from ..exports import export as write_export

    bar = progress_bar(f"export {to.value}", "frame")
    try:
        write_export(ds, to.value, out, progress=bar_callback(bar))
    except (OSError, ValueError) as err:
        bar.close()
        fail(f"could not export to {str(out)!r}: {err}", code=3)
    bar.finish()
    typer.echo(f"wrote {out} ({ds.sizes['time']} frames, {to.value})")
