"""One command reproduces the paper: every result computed on its defaults, written as a report.

Contract
--------
:func:`reproduce` runs the stages below in turn. Each one computes with the public
API, writes its figures (PNG and SVG) and data (NetCDF and JSON) under the output
folder, and returns a section of the report: text, tables and figures. A stage that
fails becomes a section with its error, and the other stages still run. At the end,
``index.html`` (self-contained: the figures are embedded, so it opens from disk with no
server and no network), ``report.md`` (the same content) and ``summary.json`` (every
number, the resolved parameters, the package version and the run time of each stage)
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
"""

from __future__ import annotations

import base64
import hashlib
import json
import logging
import math
import re
import stat
import time
import traceback
from collections.abc import Callable
from dataclasses import asdict, dataclass, field, fields
from pathlib import Path
from typing import Any, get_type_hints

import numpy as np

from ._version import __version__
from .io import REFERENCES, OutputError, stack_models, write_dataset, write_figure, write_text
from .models import get_model
from .params import ChainParams
from .state import require_clamped

log = logging.getLogger(__name__)

#: The paper's three models, named on purpose: the report reproduces the paper's
#: content, not whatever else is registered (the CLI's ``--model all`` does that).
MODELS = ("nonlinear", "sine", "linear")
#: Those of them that support full rotations (Fig. 3, the localization run).
ROTATING = tuple(name for name in MODELS if get_model(name).rotates)


@dataclass(frozen=True)
class ReproduceSettings:
    """What the report computes; the defaults reproduce the paper (Section 4).

    Attributes
    ----------
    m_max, dm : float
        Relaxation protocol of Fig. 2: loads dm, 2 dm, ..., m_max, then back down. The
        top is raised to :data:`ABOVE_CRITICAL` times the largest computed M_c when
        ``m_max`` does not reach past it (a chain stiffer than the paper's).
    rotation_moment : dict
        Moment per rotating model for Fig. 3 and the localization run (the paper's:
        0.25 and 0.3). One that is not above the model's computed M_c is replaced by
        :data:`ABOVE_CRITICAL` M_c, and the report says so.
    snapshot_times : tuple of float
        Times of the panels of Figs. 3a and 3b.
    animation_frames : int
    turns : int
        Full turns of the localization run (the paper: 1500).
    orbit_moment, orbit_down_to : float
        The sine model's rotating orbit is found at ``orbit_moment`` and continued down
        towards ``orbit_down_to`` until it ceases to exist. An ``orbit_moment`` not
        above the sine model's M_c is replaced by :data:`ABOVE_CRITICAL` M_c.
    n_list : tuple of int
        Chain half-lengths N for the continuum comparison.
    long_n_list : tuple of int
        Chain half-lengths N of the critical moment against the chain's length.
    diagram_damping : dict
        Per rotating model, the values of gamma_phi of the state diagram (both edges of
        the hysteresis loop, :func:`~cosserat_chain.experiments.diagram.state_diagram`).
        The nonlinear model's rows cost minutes each (its SNIC at gamma_phi = 0.5 took
        15 minutes), so its default is one value; an empty tuple leaves a model out.
    reading : str or None
        Which reading of Section 4's "a finite 1D chain consists of seven particles" sets
        the chain's N (:data:`READINGS`): ``"clamped-ends-among-seven"`` (N = 3, the
        package's default chain) or ``"seven-between-walls"`` (N = 4: seven free particles
        and two clamped ones). None: the chain's own N. The statics stage computes both
        readings whichever is chosen.
    """

    m_max: float = 0.3
    dm: float = 0.01
    rotation_moment: dict[str, float] = field(default_factory=lambda: {"nonlinear": 0.25, "sine": 0.3})
    snapshot_times: tuple[float, ...] = (40.0, 41.0, 42.0, 43.0)
    animation_frames: int = 80
    turns: int = 1500
    orbit_moment: float = 0.22
    orbit_down_to: float = 0.1
    n_list: tuple[int, ...] = (3, 10, 30, 100, 300, 1000)
    long_n_list: tuple[int, ...] = (3, 10, 30, 100, 300)
    diagram_damping: dict[str, tuple[float, ...]] = field(
        default_factory=lambda: {"sine": (0.05, 0.1, 0.15, 0.2, 0.3, 0.5), "nonlinear": (0.2,)}
    )
    reading: str | None = None


#: The two readings of Section 4's "seven particles" and the N of each. The paper's chain has
#: "2N+1 particles with fixed particles at the boundaries": seven with the two clamped ends
#: among them (N = 3), or seven free particles between two clamped ones, the walls (N = 4).
READINGS = {"clamped-ends-among-seven": 3, "seven-between-walls": 4}


def reading_error(reading: object) -> str | None:
    """Why ``reading`` is not one of :data:`READINGS` (naming the field, the value and the allowed ones), or None."""
    if reading is None or reading in READINGS:
        return None
    allowed = ", ".join(f"{name!r} (N = {n})" for name, n in READINGS.items())
    return f"reading must be one of {allowed}, got {reading!r}"


def chain_for_reading(settings: ReproduceSettings, params: ChainParams | None = None) -> ChainParams:
    """The chain the report computes: ``params`` (default the paper's), with the N of ``settings.reading``.

    Raises
    ------
    ValueError
        For an unknown reading, a ``params`` whose N is not the reading's, or one whose
        ends are not both clamped.
    """
    error = reading_error(settings.reading)
    if error:
        raise ValueError(error)
    if params is not None:
        # The report reproduces the paper, whose chain and continuum solutions are clamped.
        require_clamped(params, "the paper's reproduction (reproduce)")
    if settings.reading is None:
        return params or ChainParams()
    n = READINGS[settings.reading]
    if params is None:
        return ChainParams(N=n)
    if params.N != n:
        raise ValueError(f"the chain's N = {params.N} contradicts reading = {settings.reading!r} (N = {n}); give one of them")
    return params


#: A load the report must place above a model's critical moment but is configured at or
#: below it is replaced by this multiple of the computed M_c.
ABOVE_CRITICAL = 1.25


def settings_from_mapping(mapping: dict[str, Any], source: str = "[reproduce]") -> ReproduceSettings:
    """:class:`ReproduceSettings` from a TOML table, strict on keys and types.

    Raises
    ------
    ValueError
        Naming an unknown key (with the allowed ones), or the key and value of one of the
        wrong type or out of range.
    """
    from pydantic import TypeAdapter, ValidationError

    allowed = [f.name for f in fields(ReproduceSettings)]
    unknown = [key for key in mapping if key not in allowed]
    if unknown:
        raise ValueError(f"unknown key(s) {unknown} in {source}; allowed keys: {', '.join(allowed)}")
    hints = get_type_hints(ReproduceSettings)
    checked, errors = {}, []
    for key, value in mapping.items():
        try:
            if isinstance(value, dict):
                # A table of lists (diagram_damping): TOML arrays are lists, the settings hold tuples.
                value = {k: tuple(v) if isinstance(v, list) else v for k, v in value.items()}
            checked[key] = TypeAdapter(hints[key]).validate_python(tuple(value) if isinstance(value, list) else value, strict=True)
        except ValidationError as err:
            errors += [f"{'.'.join(map(str, (key, *e['loc'])))}: {e['msg']} (got {e.get('input')!r})" for e in err.errors()]
    if errors:
        raise ValueError(f"invalid {source}: " + "; ".join(errors))
    settings = ReproduceSettings(**checked)
    problems = [
        f"{name} must be > 0, got {getattr(settings, name)!r}"
        for name in ("m_max", "dm", "orbit_moment", "turns", "animation_frames")
        if not (math.isfinite(getattr(settings, name)) and getattr(settings, name) > 0)
    ]
    problems += [
        f"rotation_moment.{m} must be a finite number, got {v!r}" for m, v in settings.rotation_moment.items() if not math.isfinite(v)
    ]
    problems += [f"rotation_moment needs {m}" for m in ROTATING if m not in settings.rotation_moment]
    problems += [
        f"{name} must be integers N >= 1" for name in ("n_list", "long_n_list") if not all(n >= 1 for n in getattr(settings, name))
    ]
    problems += [
        f"diagram_damping: unknown model {m!r} (the rotating ones: {', '.join(ROTATING)})"
        for m in settings.diagram_damping
        if m not in ROTATING
    ]
    problems += [
        f"diagram_damping.{m} must hold finite numbers > 0, got {list(v)!r}"
        for m, v in settings.diagram_damping.items()
        if not all(math.isfinite(x) and x > 0 for x in v)
    ]
    problems += [error for error in [reading_error(settings.reading)] if error]
    if problems:
        raise ValueError(f"invalid {source}: " + "; ".join(problems))
    return settings


def above_critical(configured: float, critical: float | None) -> tuple[float, str]:
    """The load to use where a model must rotate, and how it relates to M_c, in words.

    ``configured`` if it is above ``critical`` (or there is no fold), else
    :data:`ABOVE_CRITICAL` ``critical``.
    """
    if critical is None or not math.isfinite(critical):
        return configured, "the model has no static fold"
    if configured > critical:
        return configured, f"{configured / critical:.3g} times its M_c = {critical:.4g}"
    load = ABOVE_CRITICAL * critical
    return load, f"{ABOVE_CRITICAL:g} times its M_c = {critical:.4g}: the configured M = {configured:g} is not above M_c for this chain"


@dataclass
class Section:
    """One part of the report: paragraphs, tables (header + rows) and figures (stem -> caption)."""

    title: str
    paragraphs: list[str] = field(default_factory=list)
    tables: list[tuple[str, list[str], list[list[Any]]]] = field(default_factory=list)
    figures: list[tuple[str, str]] = field(default_factory=list)
    numbers: dict[str, Any] = field(default_factory=dict)
    error: str | None = None
    seconds: float = 0.0


@dataclass
class Report:
    """What :func:`reproduce` wrote."""

    out: Path
    sections: list[Section]
    summary: dict[str, Any]

    @property
    def failed(self) -> list[str]:
        return [s.title for s in self.sections if s.error]


#: Width (inches) of every figure of the report.
FIGURE_WIDTH = 10.0

#: The list of the files a report consists of, written last: the next report into the same
#: folder removes those of them it does not write again (a stage that is gone, a figure
#: renamed), and nothing else (a file of the user's stays).
MANIFEST = "manifest.json"


class _Stage:
    def __init__(self, out: Path, params: ChainParams, settings: ReproduceSettings):
        self.out, self.params, self.settings = out, params, settings
        #: Results one stage shares with a later one (the sweeps of Fig. 2 feed the hysteresis picture).
        self.shared: dict[str, Any] = {}
        #: Every file written, relative to ``out`` (the manifest).
        self.written: set[str] = set()
        #: How far the running stage is, for :func:`reproduce`'s ``progress`` (set by it).
        self.progress: Callable[[str], None] = lambda detail: None
        (out / "figures").mkdir(parents=True, exist_ok=True)
        (out / "data").mkdir(parents=True, exist_ok=True)

    def critical(self, model: str):
        """The model's :class:`~cosserat_chain.experiments.critical.CriticalPoint` on this chain (computed once, shared by the stages)."""
        from .experiments.critical import critical_point

        exact = self.shared.setdefault("exact", {})
        if model not in exact:
            exact[model] = critical_point(self.params, model)
        return exact[model]

    def within(self, what: str, unit: str) -> Callable[[float, float], None]:
        """A library ``progress(done, total)`` callback that reports ``what`` of the running stage: whole counts
        of ``unit`` as such, a quantity that is not a count as a whole percentage."""

        def progress(done: float, total: float) -> None:
            if float(done).is_integer() and float(total).is_integer():
                self.progress(f"{what} {int(done)}/{int(total)} {unit}")
            elif total > 0:
                self.progress(f"{what} {min(100, int(100 * done / total))} %")

        return progress

    def load(self, model: str, configured: float) -> tuple[float, str]:
        """:func:`above_critical` for ``model`` on this chain."""
        return above_critical(configured, self.critical(model).critical_moment)

    def path(self, relative: str) -> Path:
        """Where the report's file ``relative`` goes, recorded in the manifest."""
        self.written.add(relative)
        return self.out / relative

    def figure(self, fig, stem: str) -> str:
        import matplotlib.pyplot as plt

        # Every figure of the report at the same width (a single panel grows to it, its text
        # keeping its size), so that the page shows them alike at any window width.
        width, height = fig.get_size_inches()
        if width < FIGURE_WIDTH:
            fig.set_size_inches(FIGURE_WIDTH, max(height, min(height * FIGURE_WIDTH / width, 0.6 * FIGURE_WIDTH)))
        for suffix in ("png", "svg"):
            write_figure(fig, self.path(f"figures/{stem}.{suffix}"), dpi=130)
        plt.close(fig)
        return stem

    def data(self, name: str, payload: Any) -> None:
        if hasattr(payload, "to_netcdf"):
            write_dataset(payload, self.path(f"data/{name}.nc"))
        else:
            write_text(json.dumps(payload, indent=1, default=_json_default), self.path(f"data/{name}.json"))

    def finish(self) -> None:
        """Write the manifest of this report, after removing the files of the previous one it did not write again.

        A file is removed only where the previous manifest carries this package's marker
        (:data:`MANIFEST_MARKER`) and the file still holds what that manifest's SHA-256
        says the package wrote, reached without a symbolic link: a manifest the package
        never wrote, or a file changed since, removes nothing.
        """
        manifest = self.out / MANIFEST
        for relative, digest in _manifest_files(manifest).items():
            if relative in self.written:
                continue
            stale = _own_file(self.out, relative)
            if stale is not None and _sha256(stale) == digest:
                stale.unlink()
        files = {relative: _sha256(self.out / relative) for relative in sorted(self.written)}
        record = {"written_by": MANIFEST_MARKER, "cosserat_chain_version": __version__, "files": files}
        write_text(json.dumps(record, indent=1), manifest)


#: The mark of a manifest this package wrote.
MANIFEST_MARKER = "cosserat-chain reproduce"


def _manifest_files(manifest: Path) -> dict[str, str]:
    """The files and SHA-256 a previous manifest of this package lists; none for a manifest it did not write or cannot read."""
    try:
        record = json.loads(manifest.read_text(encoding="utf-8")) if manifest.is_file() and not manifest.is_symlink() else {}
    except (OSError, ValueError):
        return {}
    files = record.get("files") if isinstance(record, dict) and record.get("written_by") == MANIFEST_MARKER else None
    if not isinstance(files, dict):
        return {}
    return {str(name): digest for name, digest in files.items() if isinstance(digest, str)}


def _own_file(out: Path, relative: str) -> Path | None:
    """``out / relative`` if it is a regular file under ``out`` reached through no link (no ``..``, not absolute); else None."""
    parts = Path(relative).parts
    if not parts or Path(relative).is_absolute() or any(part in ("..", "") for part in parts):
        return None
    path = out
    for part in parts:
        path = path / part
        try:
            mode = path.lstat().st_mode
        except OSError:
            return None
        if stat.S_ISLNK(mode):
            return None
    return path if stat.S_ISREG(mode) else None


#: What the report writes at the top of its folder, and whether each is a folder.
_LAYOUT = {"figures": True, "data": True, "index.html": False, "report.md": False, "summary.json": False, "params.json": False, MANIFEST: False}


def check_folder(out: str | Path) -> None:
    """Refuse, before any work, a report folder where a file of the report is a folder or one of its folders is not one.

    Raises
    ------
    OutputError
        Naming the path in the way and what the report writes there.
    """
    for name, folder in _LAYOUT.items():
        path = Path(out) / name
        try:
            mode = path.stat().st_mode
        except FileNotFoundError:
            continue
        except OSError as err:
            raise OutputError(f"--out {str(out)!r}: {str(path)!r} cannot be examined ({err.strerror})") from None
        if folder and not stat.S_ISDIR(mode):
            raise OutputError(f"--out {str(out)!r}: {str(path)!r} is not a folder, and the report writes its {name} there: move it")
        if not folder and not stat.S_ISREG(mode):
            raise OutputError(f"--out {str(out)!r}: {str(path)!r} is not a regular file, and the report writes its {name} there: move it")


def _sha256(path: Path) -> str:
    """SHA-256 of a file's content (hex)."""
    digest = hashlib.sha256()
    with path.open("rb") as fh:
        for block in iter(lambda: fh.read(1 << 20), b""):
            digest.update(block)
    return digest.hexdigest()


def _statics(stage: _Stage) -> Section:
    from .experiments.sweep import relaxation_sweep
    from .plots.statics import figure2, hysteresis_figure

    p, s = stage.params, stage.settings
    exact = {m: stage.critical(m) for m in MODELS}
    largest = max((e.critical_moment for e in exact.values() if e.critical_moment is not None), default=0.0)
    # The protocol must pass every fold to show an onset: raise its top for a stiffer chain.
    m_max = max(s.m_max, math.ceil(ABOVE_CRITICAL * largest / s.dm) * s.dm)
    sweeps = {m: relaxation_sweep(p, m, m_max=m_max, dm=s.dm, down=True, progress=stage.within(f"{m} sweep", "loads")) for m in MODELS}
    stage.shared.update(sweeps=sweeps)
    stage.data("critical", stack_models({m: r.to_dataset() for m, r in exact.items()}))
    stage.data("sweep", stack_models({m: r.to_dataset() for m, r in sweeps.items()}))
    rows, numbers = [], {}
    for m in MODELS:
        e, w = exact[m], sweeps[m]
        numbers[m] = {
            "compliance": e.compliance,
            "M_c": e.critical_moment,
            "M_c_dimensionless": None if e.critical_moment is None else e.critical_moment / p.moment_scale,
            "phi0_at_fold": e.phi0_at_fold,
            "onset": e.onset,
            "phi0_at_onset": e.phi0_at_onset,
            "onset_load": w.onset_load,
            "stop_load": w.stop_load,
        }
        rows.append([m, e.compliance, e.critical_moment, e.phi0_at_onset, w.onset_load, w.stop_load])
    numbers["moment_scale"] = p.moment_scale
    stage.data("statics", numbers)
    section = Section("Static response and the onset of rotation (Fig. 2)", numbers=numbers)
    section.paragraphs.append(
        f"The moment on the central particle is raised in steps of {s.dm:g} up to {m_max:g}, each step run to rest "
        "(the paper's relaxation protocol, dots), then lowered again; a star marks the first step at which the particle "
        "rotates. Lines: the exact static branches by pseudo-arclength continuation (dashed: unstable), open circles: "
        "the folds, located to round-off. The linear model never rotates."
    )
    section.tables.append(
        (
            "Compliance, critical moment and fold angle: exact (continuation) and by the relaxation protocol",
            ["model", "compliance dphi0/dM", "M_c exact", "phi0 at M_c (rad)", "onset (relaxation)", "rotation stops (down)"],
            rows,
        )
    )
    agreement = _agreement(stage, exact)
    numbers["agreement"] = agreement
    section.paragraphs.append(_agreement_sentence(agreement))
    section.tables.append(
        (
            f"How far the models agree: within {100 * agreement['tolerance']:g} % of the linear phi0 = c M (exact branches)",
            ["model", "up to M", "linear phi0 there (rad)", "model's phi0 there (rad)", "ends by",
             f"deviation at linear phi0 = {agreement['phi0_linear']:g}"],
            [[m, r["moment"], r["phi0_linear"], r["phi0"], r["bound"], agreement["deviation"][m]] for m, r in agreement["ranges"].items()],
        )
    )  # fmt: skip
    seven = _seven_particles(stage)
    numbers["seven_particles"] = seven
    section.paragraphs.append(_readings_sentence(seven))
    section.tables.append(
        (
            "The paper's seven particles, both readings (this chain's geometry): exact statics",
            ["reading", "N", "particles (free)", "compliance dphi0/dM", *(f"M_c {m}" for m in ROTATING),
             *(f"phi0 at fold {m} (rad)" for m in ROTATING), "this report"],
            [[name, r["N"], f"{2 * r['N'] + 1} ({2 * r['N'] - 1})", r["compliance"], *(r["M_c"][m] for m in ROTATING),
              *(r["phi0_at_fold"][m] for m in ROTATING), name == seven["used"]] for name, r in seven["readings"].items()],
        )
    )  # fmt: skip
    section.figures.append(
        (
            stage.figure(figure2(exact, sweeps), "fig2"),
            "Fig. 2: phi_0 of the loaded particle against M (small circles: relaxation steps; stars: onset of rotation; lines: "
            "exact branches, dashed where unstable; open circles: folds); right: M(phi_0) over one turn.",
        )
    )
    section.figures.append(
        (
            stage.figure(hysteresis_figure({m: sweeps[m] for m in ROTATING}, {m: exact[m] for m in ROTATING}), "hysteresis"),
            "Hysteresis loop: mean angular velocity of the loaded particle at each load step, going up and coming down; "
            "dotted: the exact static fold M_c.",
        )
    )
    return section


def _seven_particles(stage: _Stage) -> dict[str, Any]:
    """Exact statics of both readings of "seven particles" (:data:`READINGS`) with this chain's geometry.

    The rotating models' M_c and fold angle, and the compliance at rest (every model's),
    for N = 3 and N = 4; the chain's own N reuses the statics already computed.
    """
    from .experiments.critical import critical_point

    readings = {}
    for name, n in READINGS.items():
        chain = stage.params.replace(N=n)
        exact = {m: stage.critical(m) if n == stage.params.N else critical_point(chain, m, dynamics=False) for m in ROTATING}
        readings[name] = {
            "N": n,
            "compliance": exact[ROTATING[0]].compliance,
            "M_c": {m: exact[m].critical_moment for m in ROTATING},
            "phi0_at_fold": {m: exact[m].phi0_at_fold for m in ROTATING},
        }
    first, second = readings.values()
    change = {
        m: None if first["M_c"][m] is None or second["M_c"][m] is None else second["M_c"][m] / first["M_c"][m] - 1.0 for m in ROTATING
    }
    used = next((name for name, n in READINGS.items() if n == stage.params.N), None)
    return {
        "readings": readings,
        "M_c_change": change,
        "compliance_change": second["compliance"] / first["compliance"] - 1.0,
        "N": stage.params.N,
        "used": used,
    }


def _readings_sentence(seven: dict[str, Any]) -> str:
    """What the choice between the two readings of "seven particles" changes, in a sentence computed from them."""
    (first, a), (second, b) = seven["readings"].items()
    changes = ", ".join(f"{m} {100 * c:+.3g} %" for m, c in seven["M_c_change"].items() if c is not None)
    order = {name: sorted(ROTATING, key=lambda m: r["M_c"][m] or math.inf) for name, r in seven["readings"].items()}
    flips = (
        f"; the model that starts to rotate first changes ({order[first][0]} for N = {a['N']}, {order[second][0]} for N = {b['N']})"
        if order[first][0] != order[second][0]
        else ""
    )
    used = (
        f"This report's chain is the reading {seven['used']!r}"
        if seven["used"]
        else f"This report's chain has N = {seven['N']}, neither reading"
    )
    return (
        f'Section 4\'s "seven particles" reads two ways: seven with the clamped ends among them ({first}, N = {a["N"]}) or seven '
        f"free particles between clamped walls ({second}, N = {b['N']}). From N = {a['N']} to N = {b['N']} the compliance at rest "
        f"changes by {100 * seven['compliance_change']:+.3g} % and M_c by {changes}{flips}. {used}; the setting reading = "
        '"..." of [reproduce] selects one.'
    )


#: Tolerance of the small-load agreement, and the linear angle at which the deviations and the
#: errors against the nonlinear model are given (``docs/agreement.md``).
AGREEMENT_TOLERANCE = 0.01
AGREEMENT_ANGLE = 0.1


def _agreement(stage: _Stage, exact: dict[str, Any]) -> dict[str, Any]:
    """The models' small-load agreement on this chain, from the branches already traced, and the errors of (2) and (3)
    against (1) on this chain and on the same geometry with N = 1 (where the paper's remark on them fails)."""
    from .analysis.agreement import agreement_range, errors_against, static_deviation

    p = stage.params
    angle = [AGREEMENT_ANGLE]
    # The linear model is the reference: its branch is the tangent itself.
    ranges = {m: agreement_range(p, m, tolerance=AGREEMENT_TOLERANCE, branch=exact[m].branch).as_dict() for m in ROTATING}
    errors = {}
    for label, chain in (("this chain", p), ("N = 1", p.model_copy(update={"N": 1}))):
        errors[label] = {m: float(e[0]) for m, e in errors_against(chain, "nonlinear", ["sine", "linear"], angle).items()}
    return {
        "tolerance": AGREEMENT_TOLERANCE,
        "phi0_linear": AGREEMENT_ANGLE,
        "ranges": ranges,
        "deviation": {m: float(static_deviation(p, m, angle)[0]) for m in ROTATING},
        "errors_against_nonlinear": errors,
    }


def _agreement_sentence(agreement: dict[str, Any]) -> str:
    r, dev = agreement["ranges"], agreement["deviation"]
    return (
        f"All three models share the tangent phi0 = c M at rest, and they stay within {100 * agreement['tolerance']:g} % of it "
        f"up to M = {r['nonlinear']['moment']:.4g} (nonlinear, linear phi0 {r['nonlinear']['phi0_linear']:.4g}) and "
        f"M = {r['sine']['moment']:.4g} (sine, linear phi0 {r['sine']['phi0_linear']:.6g}: arcsin(p) = 1.01 p on every chain). "
        f"At a linear phi0 of {agreement['phi0_linear']:g} the nonlinear model lies {100 * dev['nonlinear']:+.3g} % and the sine "
        f"model {100 * dev['sine']:+.3g} % (= arcsin(p)/p - 1) from the linear one. The nonlinear chain stiffens through its "
        "transverse displacements, which grow with the chain's length: the range of agreement shrinks like 1/N "
        "(docs/agreement.md)."
    )


def _orbits(stage: _Stage) -> Section:
    from .experiments.orbits import periodic_orbit
    from .experiments.sweep import relaxation_sweep
    from .plots.orbits import rotation_characteristic_figure

    p, s = stage.params, stage.settings
    model = "sine"
    critical = stage.critical(model)
    moment, relation = stage.load(model, s.orbit_moment)
    sweep = stage.shared.get("sweeps", {}).get(model) or relaxation_sweep(p, model, m_max=max(s.m_max, moment), dm=s.dm, down=True)
    result = periodic_orbit(p, model, moment, down_to=min(s.orbit_down_to, moment), progress=stage.within("continuation", "orbits"))
    stage.data("orbits", result.to_dataset())
    branch = result.branch
    numbers = {
        "model": model,
        "moment": moment,
        "period": result.orbit.period,
        "mean_angular_velocity": result.orbit.mean_angular_velocity,
        "stable": bool(result.orbit.stable),
        "orbit_end": branch.end,
        "orbit_end_moment": branch.end_moment,
        "stability_lost_at": branch.stability_lost_at,
        "static_fold": critical.critical_moment,
        "relaxation_onset": sweep.onset_load,
        "relaxation_stop": sweep.stop_load,
    }
    stage.data("orbit_summary", numbers)
    section = Section("Rotating states as periodic orbits: the hysteresis loop", numbers=numbers)
    section.paragraphs.append(
        f"Above M_c the rotating state of the {model} model is a limit cycle: the loaded particle advances by one turn per "
        f"period while everything else returns. It is found at M = {moment:.4g} ({relation}) by Newton's method on a "
        "shooting map and continued downwards in M. " + _loop_edges(numbers)
    )
    section.tables.append(
        (
            "Edges of the hysteresis loop: exact, and by the relaxation protocol",
            [
                "model",
                "static fold M_c",
                "orbit loses stability at",
                "orbit ends at",
                "how",
                "onset (relaxation up)",
                "stop (relaxation down)",
            ],
            [[model, numbers["static_fold"], branch.stability_lost_at, branch.end_moment, branch.end, sweep.onset_load, sweep.stop_load]],
        )
    )
    section.tables.append(
        (
            f"Periodic orbit at M = {moment:.4g}",
            ["period T", "mean angular velocity", "largest non-trivial Floquet multiplier", "stable"],
            [[result.orbit.period, result.orbit.mean_angular_velocity, result.orbit.max_multiplier, bool(result.orbit.stable)]],
        )
    )
    fig = rotation_characteristic_figure(branches=[branch], sweep=sweep, static_fold=numbers["static_fold"], model=model)
    section.figures.append(
        (
            stage.figure(fig, "rotation_characteristic"),
            "Rotation characteristic: mean angular velocity of the periodic orbit against M "
            "(dashed: unstable), with the relaxation sweep's steps up and down, the static fold M_c (dotted), where the "
            "orbit loses stability (dashed line) and where it ends (cross).",
        )
    )
    return section


def _state_map(stage: _Stage) -> Section:
    """Issue 13: the phase diagram in (gamma_phi, M) of the paper's chain for both rotating models."""
    from .experiments.diagram import state_diagram
    from .plots.diagram import diagram_figure

    p, s = stage.params, stage.settings
    section = Section("The map of static and rotating states against the damping")
    section.paragraphs.append(
        "For each value of the rotational damping gamma_phi: the static fold M_c (the onset of rotation under a rising "
        "load; it does not depend on the damping) and where a falling load stops the stable periodic rotation, and how: "
        "at a fold of cycles, a period doubling or a torus (a Floquet multiplier leaving the unit circle), at a homoclinic "
        "orbit, or at a saddle-node on the invariant circle (snic: the loop closes, no hysteresis). Between the two edges "
        "the chain rests or rotates depending on its history."
    )
    rows, numbers = [], {}
    for model in ROTATING:
        values = s.diagram_damping.get(model, ())
        if not values:
            continue
        result = state_diagram(p, model, "gamma_phi", list(values), progress=stage.within(model, "values"))
        stage.data(f"diagram_{model}", result.to_dataset())
        numbers[model] = result.as_dict()["rows"]
        for row in result.rows:
            rows.append([model, row.value, row.static_fold, row.rotation_stops, row.end, row.hysteresis])
        section.figures.append(
            (
                stage.figure(diagram_figure(result), f"state_diagram_{model}"),
                f"{model} model: static (blue), static or rotating (hysteresis, orange) and rotating (red) in "
                "(gamma_phi, M / (E1 h^2)); solid: M_c, dashed: where the rotation stops, labelled with how.",
            )
        )
    section.numbers = numbers
    stage.data("state_diagram", numbers)
    section.tables.append(
        (
            "Both edges of the hysteresis loop against gamma_phi",
            ["model", "gamma_phi", "M_c", "rotation stops at", "how", "hysteresis"],
            rows,
        )
    )
    return section


def _rotation(stage: _Stage) -> Section:
    from .experiments.simulation import simulate
    from .plots.chain import animate, snapshot_figure

    p, s = stage.params, stage.settings
    t_end = max(s.snapshot_times) + 1.0
    section = Section("The rotating chain (Figs. 3a and 3b)")
    # The paper's figures: Fig. 3a is the sine model, Fig. 3b (and the animation) the nonlinear one.
    for label, m in (("fig3a", "sine"), ("fig3b", "nonlinear")):
        moment, relation = stage.load(m, s.rotation_moment[m])
        run = simulate(p, m, moment, t_end=t_end, n_frames=int(t_end / 0.05) + 1)
        stage.data(f"rotation_{m}", run)
        shown = [float(run.time.sel(time=t, method="nearest")) for t in s.snapshot_times]  # the stored frames drawn
        section.figures.append(
            (
                stage.figure(snapshot_figure(p, run, list(s.snapshot_times)), label),
                f"Fig. {label[-2:]}: the {m} model under M = {moment:.4g} ({relation}), snapshots at t = "
                + ", ".join(f"{t:.6g}" for t in shown)
                + ".",
            )
        )
        if m == "nonlinear":
            animate(p, run, stage.path("figures/rotation.gif"), t_start=t_end - 10.0, t_stop=t_end, max_frames=s.animation_frames, fps=15)
    section.paragraphs.append(
        "In the sine model u decouples, so the other particles only move transversally (Fig. 3a); in the nonlinear model "
        "every degree of freedom is coupled (Fig. 3b). Animation of the nonlinear chain over the last 10 time units "
        "(the loaded particle in colour, the links as lines): [figures/rotation.gif](figures/rotation.gif)."
    )
    return section


def _localization(stage: _Stage) -> Section:
    from .experiments.localization import localization_run

    p, s = stage.params, stage.settings
    rows, numbers = [], {}
    relations = {}
    for m in ROTATING:
        moment, relations[m] = stage.load(m, s.rotation_moment[m])
        result = localization_run(p, m, moment, turns=s.turns, t_max=100.0 * s.turns, progress=stage.within(m, "turns"))
        stage.data(f"localization_{m}", result.to_dataset())
        d = result.as_dict()
        numbers[m] = d
        rows.append(
            [
                m,
                moment,
                d["turns_completed"],
                d["t_end"],
                d["mean_angular_velocity"],
                d["max_abs_phi_others"],
                d["max_abs_v_others_over_h"],
                d["max_abs_u_others_over_h"],
                ", ".join(d["outside_model_validity"]) or "—",
                d["classification"],
            ]
        )
    stage.data("localization", numbers)
    section = Section(f"Localization: {s.turns} rotations of the central particle", numbers=numbers)
    section.paragraphs.append(
        f"The central particle is driven from rest until it has made {s.turns} full turns (the paper's test), at "
        + "; ".join(f"M = {numbers[m]['moment']:.4g} for the {m} model ({relations[m]})" for m in ROTATING)
        + ". "
        + " ".join(_localization_outcome(m, numbers[m], s.turns) for m in ROTATING)
        + " Their largest excursions over the whole run are below, against the thresholds of a small motion "
        + _thresholds_text(numbers[ROTATING[0]]["thresholds"])
        + ": where the first neglected term of the linear models is a tenth of the kept one."
    )
    section.tables.append(
        (
            "Statistics of the localization run",
            [
                "model",
                "M",
                "turns",
                "t_end",
                "mean angular velocity",
                "max abs phi, others (rad)",
                "max abs v / h, others",
                "max abs u / h, others",
                "outside the model's linear range",
                "state",
            ],
            rows,
        )
    )
    return section


def _localization_outcome(model: str, result: dict[str, Any], turns: int) -> str:
    """What the run shows for one model, in a sentence computed from its result."""
    made = result["turns_completed"]
    if result["classification"] == "localized_rotation":
        return (
            f"In the {model} model the loaded particle made {made} turns, no other particle turned and the others' motion "
            "stayed small: the rotation stays localized."
        )
    if result["classification"] == "rotation_with_large_motion":
        beyond = ", ".join(_AMPLITUDES[name] for name in result["large_motion"])
        outside = [_AMPLITUDES[name] for name in result["outside_model_validity"]]
        return (
            f"In the {model} model the loaded particle made {made} turns and no other particle turned, but the others' "
            f"motion is not small ({beyond} beyond the thresholds)"
            + (f", and the model, linear in {', '.join(outside)}, is outside its range of validity there." if outside else ".")
        )
    if made < turns:
        return f"In the {model} model the loaded particle made only {made} of the {turns} turns by t = {result['t_end']:.6g} ({result['classification']})."
    return f"In the {model} model other particles turned as well ({result['classification']}): the rotation is not localized."


#: The localization amplitudes' names (those of ``diagnostics.THRESHOLDS``) as the report writes them.
_AMPLITUDES = {"phi": "|phi|", "u_over_h": "|u|/h", "v_over_h": "|v|/h"}


def _thresholds_text(thresholds: dict[str, float]) -> str:
    """The localization thresholds in words (phi in rad, the displacements in units of h)."""
    return f"(|phi| <= {thresholds['phi']:g} rad, |u|, |v| <= {thresholds['v_over_h']:g} h)"


def _loop_edges(numbers: dict[str, Any]) -> str:
    """Both edges of the hysteresis loop as the orbit stage found them, in a sentence."""

    def value(x: float | None) -> str:
        return "none" if x is None or not math.isfinite(x) else f"{x:.4g}"

    lost = numbers["stability_lost_at"]
    down = (
        f"coming down, the orbit loses stability at M = {value(lost)} and ends at M = {value(numbers['orbit_end_moment'])} ({numbers['orbit_end']})"
        if lost is not None
        else f"coming down, the orbit stays stable until it ends at M = {value(numbers['orbit_end_moment'])} ({numbers['orbit_end']})"
    )
    return (
        f"Going up, the static branch ends at its fold M_c = {value(numbers['static_fold'])} and the relaxation protocol sees "
        f"rotation start at M = {value(numbers['relaxation_onset'])}; {down}, and the protocol sees rotation stop at "
        f"M = {value(numbers['relaxation_stop'])}: the two edges of the hysteresis loop."
    )


def _trend(model: str, items: list[dict[str, Any]]) -> str:
    """How the model's M_c changes along the chain lengths computed, in a sentence."""
    found = [item for item in items if item["M_c"] is not None]
    if len(found) < 2:
        return f"The {model} model has a fold for {len(found)} of the {len(items)} lengths."
    first, last = found[0], found[-1]
    scaled = [item["N"] * item["M_c"] for item in found]
    if model == "sine":
        spread = max(scaled) / min(scaled) - 1.0
        return (
            f"The sine model's M_c is 1/(largest rotation compliance); N M_c goes from {scaled[0]:.4g} (N = {first['N']}) to "
            f"{scaled[-1]:.4g} (N = {last['N']})" + (f", within {100 * spread:.2g} %: M_c falls like 1/N." if spread < 0.1 else ".")
        )
    return (
        f"The {model} model's M_c goes from {first['M_c']:.4g} (N = {first['N']}) to {last['M_c']:.4g} (N = {last['N']}), "
        f"and phi_0 at its fold from {first['phi0_at_fold']:.3g} to {last['phi0_at_fold']:.3g} rad."
    )


def _long_chains(stage: _Stage) -> Section:
    from .experiments.critical import critical_point
    from .plots.statics import critical_against_length

    p, s = stage.params, stage.settings
    results = {m: [critical_point(p.replace(N=n), m, dynamics=False) for n in s.long_n_list] for m in ROTATING}

    def summary(result) -> dict:
        whole = result.as_dict()
        picked = {k: whole[k] for k in ("M_c", "phi0_at_fold", "first_fold", "snap_through", "branch_complete")}
        return {"N": result.params.N, **picked, "folds": len(result.branch.folds)}

    numbers = {m: [summary(r) for r in rows] for m, rows in results.items()}
    stage.data("long_chains", numbers)
    section = Section("The critical moment of longer chains", numbers=numbers)
    section.paragraphs.append(
        "The statics of this chain's geometry for longer chains (2N+1 particles, both ends clamped), each branch traced over "
        "one turn of the loaded particle. "
        + " ".join(_trend(m, items) for m, items in numbers.items())
        + " (docs/statics.md has the paper chain's table to N = 1000, the first fold of N = 10^4 and the cost.)"
    )
    rows = []
    for m, items in numbers.items():
        for item in items:
            first = item["first_fold"]
            rows.append(
                [
                    m,
                    item["N"],
                    item["M_c"],
                    item["phi0_at_fold"],
                    None if first is None else first["moment"],
                    item["folds"],
                    item["branch_complete"],
                ]
            )
    section.tables.append(
        ("M_c against N", ["model", "N", "M_c", "phi0 at fold (rad)", "first fold M", "folds over the turn", "branch complete"], rows)
    )
    section.figures.append(
        (stage.figure(critical_against_length(results), "critical_vs_N"), "M_c (sine: N M_c) and phi_0 at the fold against N.")
    )
    return section


def _continuum(stage: _Stage) -> Section:
    from .analysis.continuum import compare_profiles, convergence, reduced_discrete
    from .plots.theory import plot_convergence, plot_profiles

    p, s = stage.params, stage.settings
    table = convergence(p, list(s.n_list))
    reduced = reduced_discrete(p).as_dict()
    stage.data("continuum", table.as_dict())
    stage.data("reduced", reduced)
    section = Section(
        "Continuum theory (Section 3) against the discrete chain",
        numbers={"table": table.as_dict(), "order": table.order(), "reduced": reduced},
    )
    section.paragraphs.append(
        "phi_0 / M of the long-wave solution (11) with the geometry-derived D1, D2, against the discrete linear chain (3), "
        f"and the residue (12); the relative error falls like N^-{table.order():.2f}. "
        + (
            "For this chain continuum - discrete keeps one sign over the list; "
            if np.all(np.sign(table.signed_error[table.N > 1]) == np.sign(table.signed_error[-1]))
            else "For this chain continuum - discrete changes sign along the list; "
        )
        + "for some geometries it changes sign at small N, and the 1/N fall holds only past the change (docs/continuum.md)."
    )
    section.tables.append(
        (
            "Continuum against discrete compliance",
            ["N", "continuum phi0/M", "discrete phi0/M", "relative error", "residue", "(continuum - discrete) / discrete"],
            [
                [int(n), c, d, e, r, se]
                for n, c, d, e, r, se in zip(
                    table.N, table.continuum, table.discrete, table.relative_error, table.residue, table.signed_error
                )
            ],
        )
    )
    section.figures.append(
        (
            stage.figure(plot_profiles(compare_profiles(p)), "profiles"),
            "Continuum solution (lines, open circles at the particles) against the discrete chain (crosses): profiles v_k and phi_k.",
        )
    )
    section.figures.append((stage.figure(plot_convergence(table), "convergence"), "Relative error and residue against N."))
    section.paragraphs.append(_reduced_sentence(reduced))
    section.tables.append(
        (
            "The reduced model (D1 = 0, Section 3.2): continuum family against the discrete chain",
            ["E1 of the reduced chain", "K positive definite", "lowest eigenvalue of K", "discrete phi0/M",
             "continuum phi(0)/M (the paper's cubic)", "d phi(0) / d alpha", "alpha matching the chain"],
            [[reduced["E1"], reduced["positive_definite"], reduced["lowest_eigenvalue"], reduced["compliance"],
              reduced["continuum_compliance"], reduced["family_slope"], reduced["matching_alpha"]]],
        )
    )  # fmt: skip
    return section


def _which_continuum(stage: _Stage) -> Section:
    """The paper's open problem (its introduction): which continuum describes small deformations, large bending, a full rotation."""
    from .analysis.which_continuum import answer
    from .plots.theory import plot_continua

    result = answer(stage.params)
    numbers = result.as_dict()
    stage.data("which_continuum", numbers)
    section = Section("Which continuum? The paper's open problem answered in numbers", numbers=numbers)
    section.paragraphs.extend(result.lines())
    section.paragraphs.append(
        "Each number is computed against the discrete chain of this report's geometry; docs/which-continuum.md derives the "
        "three levels and maps where each stops being valid over the geometry."
    )
    section.figures.append(
        (
            stage.figure(plot_continua(result.beam, result.bending), "which_continuum"),
            "Left: compliance error of the Timoshenko beam and of eq. (11) against the discrete chain, against N. "
            "Right: model (i)'s cantilever bent by an end moment against the exact beam's circle.",
        )
    )
    return section


def _reduced_sentence(reduced: dict[str, Any]) -> str:
    """The reduced model's continuum arbitrariness against the discrete chain's uniqueness, in a sentence from the numbers."""
    continuum = (
        "the four conditions fix phi(0) only for N = 1"
        if reduced["family_slope"] == 0
        else f"phi(0)/M = {reduced['continuum_compliance']:.4g} + {reduced['family_slope']:.4g} alpha takes any value"
    )
    discrete = (
        f"positive definite (lowest eigenvalue {reduced['lowest_eigenvalue']:.4g}), so its static state is unique: "
        f"phi_0/M = {reduced['compliance']:.4g}"
        if reduced["positive_definite"]
        else "not positive definite"
    )
    return (
        "The reduced model (D1 = 0) as a continuum is arbitrary, as Section 3.2 says, beyond the paper's cubic as well: "
        "v = v_3 + alpha x (L - x)^2 (x + (L - h)^2 / (2L - h)) meets its equations and all four conditions for every alpha, "
        f"and {continuum}. The discrete reduced chain (E1 = {reduced['E1']:.4g}, so that D1 = 0) keeps its bending "
        f"energy E1 b^2 (phi_k+1 - phi_k)^2; its stiffness K is {discrete}."
    )


def _waves(stage: _Stage) -> Section:
    from .analysis.dispersion import continuum_dispersion, dispersion, wave_summary
    from .plots.theory import plot_dispersion

    summary = wave_summary(stage.params)
    data = summary.as_dict()
    stage.data("waves", data)
    section = Section("Waves: dispersion of the infinite linear chain", numbers=data)
    section.tables.append(
        (
            "Branch frequencies",
            ["branch", "omega at q = 0", "omega at q = pi/h"],
            [[b, data["at_zero"][b], data["at_pi"][b]] for b in data["at_zero"]],
        )
    )
    gap = data["gap"]
    section.paragraphs.append(
        "Transverse and rotational waves cannot travel for "
        + (f"{gap[0]:.4g} < omega < {gap[1]:.4g}." if gap else "no frequency: the bands overlap.")
    )
    fig = plot_dispersion(dispersion(stage.params), summary, continuum_dispersion(stage.params))
    section.figures.append((stage.figure(fig, "dispersion"), "Dispersion curves, gap shaded; dashed: the continuum theory."))
    return section


def readable(formula: str) -> str:
    """A SymPy string as a reader writes it: ``2*E2*b**2*h**2/d**2`` -> ``2 E2 b² h² / d²``."""
    superscripts = str.maketrans("0123456789", "⁰¹²³⁴⁵⁶⁷⁸⁹")
    text = re.sub(r"(?:\*\*|\^)(\d+)", lambda m: m.group(1).translate(superscripts), formula)
    text = re.sub(r"(?<=\S)\*(?=\S)", " ", text)
    return re.sub(r"(?<=[\w)²³⁴'])/(?=[\w(])", " / ", text)


def _errata(stage: _Stage) -> Section:
    from .analysis.symbolic import errata

    items = [e.as_dict() for e in errata(stage.params)]
    stage.data("errata", items)
    section = Section("Errata: where the printed equations disagree with the derivation", numbers={"errata": items})
    section.tables.append(
        (
            "Errata (derived with SymPy from the geometry of model (i))",
            ["#", "where", "printed", "derived", "consequence"],
            [[e["number"], e["where"], readable(e["printed"]), readable(e["derived"]), readable(e["consequence"])] for e in items],
        )
    )
    return section


STAGES: dict[str, Callable[[_Stage], Section]] = {
    "statics": _statics,
    "long_chains": _long_chains,
    "orbits": _orbits,
    "state_map": _state_map,
    "rotation": _rotation,
    "localization": _localization,
    "continuum": _continuum,
    "which_continuum": _which_continuum,
    "waves": _waves,
    "errata": _errata,
}


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
    sections = []
    for i, name in enumerate(names):
        if progress is not None:
            progress(name, i, len(names))
            stage.progress = lambda detail, name=name, i=i: progress(f"{name}: {detail}", i, len(names))
        start = time.perf_counter()
        try:
            section = STAGES[name](stage)
        except Exception as err:  # a failed stage is reported in the page; the others still run
            log.exception("stage %s failed", name)
            section = Section(name, error=f"{type(err).__name__}: {err}\n\n{traceback.format_exc(limit=4)}")
        section.seconds = time.perf_counter() - start
        sections.append(section)
    if progress is not None:
        progress("done", len(names), len(names))
    table = claims(dict(zip(names, sections)), settings)
    summary = {
        "claims": [dict(zip(CLAIMS_HEADER, row)) for row in table],
        "cosserat_chain_version": __version__,
        "params": params.model_dump(),
        "settings": asdict(settings),
        "stages": {
            name: {"title": s.title, "seconds": s.seconds, "error": s.error, "numbers": s.numbers} for name, s in zip(names, sections)
        },
    }
    write_text(json.dumps(params.model_dump(), indent=1), stage.path("params.json"))
    write_text(json.dumps(summary, indent=1, default=_json_default), stage.path("summary.json"))
    write_text(_markdown(sections, params, table), stage.path("report.md"))
    write_text(_html(sections, params, out, table), stage.path("index.html"))
    stage.finish()
    return Report(out, sections, summary)


def claims(results: dict[str, Section], settings: ReproduceSettings) -> list[list[str]]:
    """The report's first table: what the paper says, what this package computes, and whether they agree.

    One row per claim of the paper's Section 4 (and Section 3's continuum solution), each
    computed from the stage that tests it; a stage that failed or did not run says so.
    """

    def number(value: Any, digits: int = 4) -> str:
        return "none" if value is None or (isinstance(value, float) and not math.isfinite(value)) else f"{value:.{digits}g}"

    rows: list[list[str]] = []

    def stage(name: str) -> dict[str, Any] | None:
        section = results.get(name)
        return None if section is None or section.error else section.numbers

    def missing(name: str, claim: str) -> None:
        rows.append([claim, f"stage {name!r} {'failed' if name in results else 'was not run'}", "—"])

    statics = stage("statics")
    claim = "Under small loads all three models give very similar static deformations"
    if statics is None:
        missing("statics", claim)
    else:
        slopes = [statics[m]["compliance"] for m in MODELS]
        spread = max(slopes) / min(slopes) - 1.0
        rows.append([claim, "compliance dphi0/dM at rest: " + ", ".join(f"{m} {number(statics[m]['compliance'], 8)}" for m in MODELS),
                     "yes: the same slope at rest" if spread < 1e-9 else f"no: slopes differ by {spread:.2g}"])  # fmt: skip
        agreement = statics["agreement"]
        r, tol = agreement["ranges"], agreement["tolerance"]
        claim = "The results for all three models agree quite well for small applied moments and induced angles"
        rows.append([claim, f"within {100 * tol:g} % of the linear phi0 up to M = {number(r['nonlinear']['moment'])} (nonlinear), "
                            f"{number(r['sine']['moment'])} (sine); at linear phi0 = {agreement['phi0_linear']:g}: nonlinear "
                            f"{100 * agreement['deviation']['nonlinear']:+.3g} %, sine {100 * agreement['deviation']['sine']:+.3g} %",
                     f"yes, up to linear phi0 = {number(min(r[m]['phi0_linear'] for m in ROTATING), 3)} on this chain; the range shrinks "
                     "like 1/N (geometric stiffening of the nonlinear chain through its transverse displacements)"])  # fmt: skip
        claim = "The error of the sine model (2) increases compared with the error of the linear model (3)"
        errors = agreement["errors_against_nonlinear"]
        worse = {label: abs(e["sine"]) > abs(e["linear"]) for label, e in errors.items()}
        rows.append([claim, f"against model (1) at linear phi0 = {agreement['phi0_linear']:g}: " + "; ".join(
                         f"{label}: sine {100 * e['sine']:+.3g} %, linear {100 * e['linear']:+.3g} %" for label, e in errors.items()),
                     "; ".join(f"{'yes' if w else 'no'} ({label})" for label, w in worse.items())
                     + ("" if all(worse.values()) else ": where the nonlinear chain is softer than the linear one by more than "
                        "half the sine model's excess, the sine model is the closer")])  # fmt: skip
        claim = "Under strong load the central particle rotates; the linear model (3) does not describe it"
        folds = {m: statics[m]["M_c"] for m in MODELS}
        rotating_ok = all(folds[m] is not None for m in ROTATING) and folds["linear"] is None
        rows.append([claim, "M_c: " + ", ".join(f"{m} {number(folds[m])}" for m in MODELS),
                     "yes: a fold (M_c) for models (1) and (2), none for (3)" if rotating_ok else "no"])  # fmt: skip
        claim = "Stars in Fig. 2: the load step at which the central particle starts to rotate"
        onsets = {m: statics[m]["onset_load"] for m in ROTATING}
        within = all(onsets[m] is not None and folds[m] < onsets[m] <= folds[m] + settings.dm + 1e-12 for m in ROTATING)
        rows.append([claim, "; ".join(f"{m}: onset {number(onsets[m])}, exact M_c {number(folds[m])}" for m in ROTATING),
                     f"yes: the first step above M_c (steps of {settings.dm:g})" if within else "no: the onset is not the first step above M_c"])  # fmt: skip
    localization = stage("localization")
    claim = "A test run: the central particle made 1500 full rotations, while the other particles performed small oscillations only"
    if localization is None:
        missing("localization", claim)
    else:
        made = {m: localization[m] for m in ROTATING}
        turned = all(d["turns_completed"] >= settings.turns for d in made.values())
        classes = {d["classification"] for d in made.values()}
        outside = [
            f"{m} ({', '.join(_AMPLITUDES[n] for n in d['outside_model_validity'])})"
            for m, d in made.items()
            if d["outside_model_validity"]
        ]
        if turned and classes == {"localized_rotation"}:
            verdict = f"yes over {settings.turns} turns: no other particle turned, and their motion stayed small"
        elif turned and classes <= {"localized_rotation", "rotation_with_large_motion"}:
            verdict = (
                f"partly: over {settings.turns} turns no other particle turned, but their oscillations are not small "
                + _thresholds_text(next(iter(made.values()))["thresholds"])
                + (f"; outside the linear range of the model: {', '.join(outside)}" if outside else "")
            )
        else:
            verdict = "no: see the localization section"
        rows.append([claim, "; ".join(f"{m}: {d['turns_completed']} turns, {d['classification']}, others max |phi| "
                                      f"{number(d['max_abs_phi_others'], 3)} rad, |v| {number(d['max_abs_v_others_over_h'], 3)} h, "
                                      f"|u| {number(d['max_abs_u_others_over_h'], 3)} h" for m, d in made.items()),
                     verdict])  # fmt: skip
    continuum = stage("continuum")
    claim = "The continuum solution (11) approximates the discrete chain's rotation of the central particle"
    if continuum is None:
        missing("continuum", claim)
    else:
        table = continuum["table"]
        errors = dict(zip(table["N"], table["relative_error"]))
        first, last = min(errors), max(errors)
        rows.append([claim, f"relative error {number(100 * errors[first], 3)} % at N = {first}, {number(100 * errors[last], 3)} % at N = {last}",
                     f"approximately, better for longer chains (error like N^-{continuum['order']:.2f})"])  # fmt: skip
    errata = stage("errata")
    claim = "The coefficients of eqs. (2)-(3) and of Section 3"
    if errata is None:
        missing("errata", claim)
    else:
        rows.append([claim, f"{len(errata['errata'])} printed coefficients or statements disagree with the derivation from model (1)",
                     "no: see the errata (the package uses the derived ones)"])  # fmt: skip
    claim = 'Section 4: "In our simulations a finite 1D chain consists of seven particles"'
    if statics is None:
        missing("statics", claim)
    else:
        seven = statics["seven_particles"]
        computed = "; ".join(
            f"{name} (N = {r['N']}): compliance {number(r['compliance'])}, M_c " + ", ".join(f"{m} {number(r['M_c'][m])}" for m in ROTATING)
            for name, r in seven["readings"].items()
        )
        changes = ", ".join(f"{m} {number(100 * c, 3)} %" for m, c in seven["M_c_change"].items() if c is not None)
        used = f"this report uses {seven['used']!r}" if seven["used"] else f"this report's chain (N = {seven['N']}) is neither"
        rows.append([claim, f"{computed}; M_c changes by {changes}",
                     f"ambiguous: both readings computed, {used} (reading in [reproduce] selects one)"])  # fmt: skip
    claim = "Section 3.2: the reduced model (D1 = 0) exhibits some arbitrariness; with the cubic (14) the four conditions give its solution"
    if continuum is None:
        missing("continuum", claim)
    else:
        reduced = continuum["reduced"]
        rows.append([claim, f"continuum: v + alpha x (L - x)^2 (x + (L - h)^2/(2L - h)) meets all four for every alpha, "
                            f"phi(0)/M = {number(reduced['continuum_compliance'])} + {number(reduced['family_slope'])} alpha; "
                            f"discrete reduced chain (E1 = {number(reduced['E1'])}): lowest eigenvalue of K "
                            f"{number(reduced['lowest_eigenvalue'])}, phi_0/M = {number(reduced['compliance'])}",
                     ("yes for the continuum, beyond the cubic too (phi(0) is not determined); the discrete chain's K is positive "
                      "definite: one static state" if reduced["positive_definite"] else "no: the discrete reduced chain's K is not "
                      "positive definite")])  # fmt: skip
    claim = 'Fig. 2: the applied moment is plotted as a "dimensionless moment"'
    if statics is None:
        missing("statics", claim)
    else:
        rows.append([claim, f"M / (E1 h^2) on every moment axis and as M_c_dimensionless in the JSON; E1 h^2 = "
                            f"{number(statics['moment_scale'])} here: M_c / (E1 h^2) = "
                            + ", ".join(f"{m} {number(statics[m]['M_c_dimensionless'])}" for m in ROTATING),
                     "the paper does not name its unit; E1 h^2 (a link's stiffness times the spacing squared) makes chains "
                     "of other E1 or h comparable, and equals 1 for the paper's chain"])  # fmt: skip
    return rows


def _json_default(value: Any) -> Any:
    if isinstance(value, np.integer):
        return int(value)
    if isinstance(value, np.floating):
        return None if not math.isfinite(value) else float(value)
    if isinstance(value, np.ndarray):
        return value.tolist()
    raise TypeError(f"not JSON serialisable: {type(value).__name__}")


def format_cell(value: Any) -> str:
    """How a table cell is printed in both renderings: numbers to 6 significant digits (every digit is in
    summary.json and data/), None as a dash."""
    if value is None or (isinstance(value, float) and not math.isfinite(value)):
        return "—"
    if isinstance(value, bool | np.bool_):
        return str(bool(value))
    if isinstance(value, int | np.integer):
        return str(int(value))
    if isinstance(value, float | np.floating):
        return f"{float(value):.6g}"
    return str(value)


def _intro(params: ChainParams) -> str:
    return (
        f'cosserat-chain {__version__} reproduces "Modeling of static deformations and dynamics of localized rotation '
        f'in a chain of finite size particles": {params.n_particles} particles (N = {params.N}), E1 = {params.E1:g}, E2 = {params.E2:g}, h = {params.h:g}, a = {params.a:g}, b = {params.b:g}, '
        f"m = {params.m:g}, j = {params.j:.6g}, damping gamma = ({params.gamma_u:g}, {params.gamma_v:g}, {params.gamma_phi:g}). "
        "All numbers are in summary.json and data/; the resolved parameters in params.json. "
        f"Please cite: {REFERENCES}; and the package (CITATION.cff)."
    )


#: Columns of :func:`claims`.
CLAIMS_HEADER = ("the paper says", "this package computes", "agreement")


def _anchor(index: int) -> str:
    return f"section-{index + 1}"


def _markdown(sections: list[Section], params: ChainParams, table: list[list[str]]) -> str:
    lines = ["# Reproduction of the paper", "", _intro(params), "", "## Contents", ""]
    lines += [f"{i + 1}. [{s.title}](#{_anchor(i)})" for i, s in enumerate(sections)]
    lines += ["", "## The paper's claims", "", "| " + " | ".join(CLAIMS_HEADER) + " |", "|---|---|---|"]
    lines += ["| " + " | ".join(row) + " |" for row in table]
    lines += ["", "| stage | seconds | status |", "|---|---|---|"]
    lines += [f"| {s.title} | {s.seconds:.1f} | {'failed' if s.error else 'ok'} |" for s in sections]
    for i, s in enumerate(sections):
        lines += ["", f'<a id="{_anchor(i)}"></a>', "", f"## {s.title}", ""]
        if s.error:
            lines += ["**This stage failed:**", "", "```", s.error.strip(), "```"]
            continue
        for paragraph in s.paragraphs:
            lines += [paragraph, ""]
        for caption, header, rows in s.tables:
            lines += [f"*{caption}*", "", "| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
            lines += ["| " + " | ".join(format_cell(v) for v in row) + " |" for row in rows]
            lines.append("")
        for stem, caption in s.figures:
            lines += [f"![{caption}](figures/{stem}.png)", "", f"*{caption}* ([SVG](figures/{stem}.svg))", ""]
    return "\n".join(lines) + "\n"


#: The page: a viewport for phones, figures and the animation no wider than the window, wide tables
#: scrolling inside themselves. Jinja2 escapes every value (autoescape); ``embedded`` holds the
#: figures as data URIs, so the page opens from disk with no server.
PAGE = """<!DOCTYPE html>
<html lang='en'>
<head>
<meta charset='utf-8'>
<meta name='viewport' content='width=device-width, initial-scale=1'>
<title>cosserat-chain: reproduction of the paper</title>
<style>
body { font-family: sans-serif; max-width: 1100px; margin: 2em auto; padding: 0 1em; line-height: 1.45; }
img { max-width: 100%; height: auto; }
figure { margin: 1em 0; }
table { border-collapse: collapse; margin: 1em 0; display: block; overflow-x: auto; max-width: 100%; }
td, th { border: 1px solid #bbb; padding: 3px 8px; text-align: left; }
th { background: #eee; }
.error { background: #fee; border: 1px solid #c00; padding: 1em; white-space: pre-wrap; overflow-x: auto; }
</style>
</head>
<body>
<h1>Reproduction of the paper</h1>
<p>{{ intro }}</p>
<h2>Contents</h2>
<ol>
{%- for s in sections %}
<li><a href='#{{ s.anchor }}'>{{ s.title }}</a></li>
{%- endfor %}
</ol>
<h2>The paper's claims</h2>
<table>
<tr>{% for h in claims_header %}<th>{{ h }}</th>{% endfor %}</tr>
{%- for row in claims %}
<tr>{% for cell in row %}<td>{{ cell }}</td>{% endfor %}</tr>
{%- endfor %}
</table>
<table>
<tr><th>stage</th><th>seconds</th><th>status</th></tr>
{%- for s in sections %}
<tr><td>{{ s.title }}</td><td>{{ "%.1f" | format(s.seconds) }}</td><td>{{ "failed" if s.error else "ok" }}</td></tr>
{%- endfor %}
</table>
{%- for s in sections %}
<h2 id='{{ s.anchor }}'>{{ s.title }}</h2>
{%- if s.error %}
<p><b>This stage failed:</b></p>
<div class='error'>{{ s.error }}</div>
{%- else %}
{%- for paragraph in s.paragraphs %}
<p>{{ paragraph.text }}{% if paragraph.animation %}<br><img alt='animation of the rotating chain' src='data:image/gif;base64,{{ paragraph.animation }}'>{% endif %}</p>
{%- endfor %}
{%- for table in s.tables %}
<p><i>{{ table.caption }}</i></p>
<table>
<tr>{% for h in table.header %}<th>{{ h }}</th>{% endfor %}</tr>
{%- for row in table.rows %}
<tr>{% for cell in row %}<td>{{ cell }}</td>{% endfor %}</tr>
{%- endfor %}
</table>
{%- endfor %}
{%- for figure in s.figures %}
<figure><img alt='{{ figure.caption }}' src='data:image/png;base64,{{ figure.png }}'><figcaption>{{ figure.caption }} (<a href='figures/{{ figure.stem }}.svg'>SVG</a>)</figcaption></figure>
{%- endfor %}
{%- endif %}
{%- endfor %}
</body>
</html>
"""

#: Where a paragraph names the animation, the page shows it.
ANIMATION_LINK = "[figures/rotation.gif](figures/rotation.gif)"


def _html(sections: list[Section], params: ChainParams, out: Path, table: list[list[str]]) -> str:
    import jinja2

    def embedded(path: Path) -> str | None:
        return base64.b64encode(path.read_bytes()).decode() if path.exists() else None

    def paragraph(text: str) -> dict[str, Any]:
        if ANIMATION_LINK not in text:
            return {"text": text, "animation": None}
        animation = embedded(out / "figures" / "rotation.gif")
        shown = "figures/rotation.gif" if animation else "(animation missing)"
        return {"text": text.replace(ANIMATION_LINK, shown), "animation": animation}

    pages = [
        {
            "anchor": _anchor(i),
            "title": s.title,
            "seconds": s.seconds,
            "error": s.error.strip() if s.error else None,
            "paragraphs": [paragraph(text) for text in s.paragraphs],
            "tables": [{"caption": c, "header": h, "rows": [[format_cell(v) for v in row] for row in rows]} for c, h, rows in s.tables],
            "figures": [{"stem": stem, "caption": c, "png": embedded(out / "figures" / f"{stem}.png")} for stem, c in s.figures],
        }
        for i, s in enumerate(sections)
    ]
    template = jinja2.Environment(autoescape=True, undefined=jinja2.StrictUndefined).from_string(PAGE)
    return template.render(intro=_intro(params), sections=pages, claims_header=CLAIMS_HEADER, claims=table)
