"""One command reproduces the paper: every result computed on its defaults, written as a report.

Contract
--------
:func:`reproduce` runs the stages below in turn, those that share nothing with the others
(the state diagram, the chains of other lengths, which continuum) in a second process beside
them where two cores are free (:mod:`.background`: the same report, file for file). Each one computes with the public
API, writes its figures (PNG and SVG) and data (NetCDF and JSON) under the output
folder, and returns a section of the report: text, tables and figures. A stage that
fails becomes a section with its error, and the other stages still run. At the end,
``index.html`` (self-contained: the figures are embedded, so it opens from disk with no
server and no network), ``report.md`` (the same content) and ``summary.json`` (every
number, the resolved parameters, the package version and the wall and CPU time of each stage)
are written atomically. An interrupted run leaves no half-written report. Last comes
``manifest.json``, the list of the report's files with their SHA-256 and the package's
marker: a report written into a folder that holds an older one removes the older files
it did not write again, and only those still as the package wrote them (never a file of
the user's, nor one a manifest it did not write lists), so the folder holds one report,
whole.

Stages: ``statics`` (Fig. 2: compliance, critical moment and fold angle per model,
exactly and by the relaxation protocol, the hysteresis loop, and both readings of the
paper's "seven particles", :data:`READINGS`), ``orbits`` (rotating
states as periodic orbits: the rotation characteristic and both edges of the
hysteresis loop), ``state_map`` (the phase diagram against gamma_phi for both rotating
models, :attr:`ReproduceSettings.diagram_damping`), ``rotation`` (Figs. 3a
and 3b, an animation), ``localization`` (the 1500-rotation runs), ``continuum``
(Section 3 against the discrete chain, and the reduced model's continuum family against
the discrete reduced chain), ``waves`` (dispersion, band gap), ``errata``.

The package is split by concern: :mod:`.settings` (what the report computes and on which
chain), :mod:`.stages` (the stages and the :class:`Section` each returns), :mod:`.claims` (the
first table, read from the sections' numbers), :mod:`.rendering` (``report.md`` and
``index.html``), :mod:`.folder` (the folder's layout and manifest) and :mod:`.background` (stages
on a second core). This module runs them, and every name below is importable from it.
"""

from __future__ import annotations

import json
import logging
import time
import traceback
from collections.abc import Callable
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

from .._version import __version__
from ..io import write_text
from ..params import ChainParams
from . import background
from .claims import CLAIMS_HEADER, claims
from .folder import MANIFEST, MANIFEST_MARKER, check_folder, json_default
from .rendering import ANIMATION_LINK, PAGE, format_cell, html_page, markdown_page
from .settings import (
    ABOVE_CRITICAL,
    MODELS,
    READINGS,
    ROTATING,
    ReproduceSettings,
    above_critical,
    chain_for_reading,
    reading_error,
    settings_from_mapping,
)
from .stages import AGREEMENT_ANGLE, AGREEMENT_TOLERANCE, FIGURE_WIDTH, STAGES, Section, _Stage, readable

__all__ = [
    "ABOVE_CRITICAL",
    "AGREEMENT_ANGLE",
    "AGREEMENT_TOLERANCE",
    "ANIMATION_LINK",
    "CLAIMS_HEADER",
    "FIGURE_WIDTH",
    "MANIFEST",
    "MANIFEST_MARKER",
    "MODELS",
    "PAGE",
    "READINGS",
    "ROTATING",
    "STAGES",
    "Report",
    "ReproduceSettings",
    "Section",
    "above_critical",
    "chain_for_reading",
    "check_folder",
    "claims",
    "format_cell",
    "readable",
    "reading_error",
    "reproduce",
    "settings_from_mapping",
]

log = logging.getLogger(__name__)


@dataclass
class Report:
    """What :func:`reproduce` wrote."""

    out: Path
    sections: list[Section]
    summary: dict[str, Any]

    @property
    def failed(self) -> list[str]:
        return [s.title for s in self.sections if s.error]


def reproduce(
    out: str | Path,
    params: ChainParams | None = None,
    settings: ReproduceSettings | None = None,
    *,
    stages: list[str] | None = None,
    progress: Callable[[str, int, int], None] | None = None,
) -> Report:
    """Compute every result of the paper and write the report to ``out`` (see the module docstring).

    Parameters
    ----------
    out : path
        Output folder (created).
    params : ChainParams, optional
        Default: the paper's chain, with the N of ``settings.reading`` if it names one.
    settings : ReproduceSettings, optional
    stages : list of str, optional
        A subset of :data:`STAGES` (default all, in order).
    progress : callable(name, done, total), optional
        How far the report is, in whole stages: called before each stage with its name and
        the number of stages done, during a long stage with ``"stage: detail"`` (``"state_map:
        sine 2/6 values"``) and the same count, and at the end with ``("done", total, total)``.

    Returns
    -------
    Report

    Raises
    ------
    ValueError
        For an unknown stage or reading, or a ``params`` whose N contradicts ``settings.reading``.
    """
    settings = settings or ReproduceSettings()
    params = chain_for_reading(settings, params)
    names = list(STAGES) if stages is None else stages
    unknown = [n for n in names if n not in STAGES]
    if unknown:
        raise ValueError(f"unknown stage(s) {unknown}; allowed: {', '.join(STAGES)}")
    out = Path(out)
    stage = _Stage(out, params, settings)
    # The stages that share nothing with the others run on a second core beside them (.background).
    beside = background.start(stage, names, _run_stage)
    done: dict[str, Section] = {}
    cpu: dict[str, float] = {}

    def finished() -> int:
        return len(done) + (len(beside.sections) if beside is not None else 0)

    def detail(name: str, text: str) -> None:
        if progress is not None:
            progress(f"{name}: {text}", finished(), len(names))

    try:
        for name in names:
            if beside is not None:
                beside.poll(stage, detail)
            if progress is not None:
                progress(name, finished(), len(names))
                stage.progress = lambda text, name=name: detail(name, text)
            if beside is not None and name in beside.names:
                continue
            start = time.process_time()
            done[name] = _run_stage(stage, name)
            cpu[name] = time.process_time() - start
        if beside is not None:
            beside.poll(stage, detail, wait=True)
            done.update(beside.sections)
            cpu.update(beside.cpu_seconds)
    finally:
        if beside is not None:
            beside.stop()
    sections = [done[name] for name in names]
    if progress is not None:
        progress("done", len(names), len(names))
    table = claims(dict(zip(names, sections)), settings)
    summary = {
        "claims": [dict(zip(CLAIMS_HEADER, row)) for row in table],
        "cosserat_chain_version": __version__,
        "params": params.model_dump(),
        "settings": asdict(settings),
        "stages": {
            name: {"title": s.title, "seconds": s.seconds, "cpu_seconds": cpu[name], "error": s.error, "numbers": s.numbers}
            for name, s in zip(names, sections)
        },
    }
    write_text(json.dumps(params.model_dump(), indent=1), stage.path("params.json"))
    write_text(json.dumps(summary, indent=1, default=json_default), stage.path("summary.json"))
    write_text(markdown_page(sections, params, table), stage.path("report.md"))
    write_text(html_page(sections, params, out, table), stage.path("index.html"))
    stage.finish()
    return Report(out, sections, summary)


def _run_stage(stage: _Stage, name: str) -> Section:
    """Stage ``name``'s section, its wall time in ``seconds``; a failure becomes the section's error (the others still run)."""
    start = time.perf_counter()
    try:
        section = STAGES[name](stage)
    except Exception as err:  # a failed stage is reported in the page; the others still run
        log.exception("stage %s failed", name)
        section = Section(name, error=f"{type(err).__name__}: {err}\n\n{traceback.format_exc(limit=4)}")
    section.seconds = time.perf_counter() - start
    return section
