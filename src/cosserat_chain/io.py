"""Files: NetCDF results and figures written atomically and safely, and TOML configuration files.

Contract
--------
:func:`write_dataset` writes an xarray Dataset to NetCDF (h5netcdf), :func:`write_text`
a text file and :func:`write_figure` a matplotlib figure, through :func:`atomic_path`:
a temporary file in the same folder and an atomic rename, so that a reader never sees a
half-written file. Nothing that is not a regular file is ever replaced: a target that
is a folder, a FIFO or a device is refused (:class:`OutputError`), and a symbolic link is
written through (its target is replaced, the link stays). :func:`check_output` runs the
same checks, and a probe of the folder's writability, before any work is done, so a
command refuses a bad ``--out`` before it computes. :func:`load_params` reads
``ChainParams`` fields from a TOML file (top-level keys, the paper's symbols) and names
any unknown key; :func:`read_config` reads at most :data:`MAX_CONFIG_BYTES` from a regular
file.
"""

from __future__ import annotations

import json
import math
import os
import shlex
import stat
import sys
import tempfile
import tomllib
from collections.abc import Iterator, Mapping
from contextlib import contextmanager
from datetime import UTC, datetime
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from .params import ChainParams
from .state import ROWS

if TYPE_CHECKING:  # xarray is imported where a file is read or written: the command line starts without it
    import xarray as xr

    from .loads import Loads

#: Largest configuration or study spec read (bytes): a TOML file of parameters is a few
#: hundred bytes; this bounds what a mistyped path (a log, /dev/zero) can make us read.
MAX_CONFIG_BYTES = 1 << 20

#: Picture formats the package writes (matplotlib's, chosen by the file's suffix).
FIGURE_FORMATS = (".png", ".svg", ".pdf")

#: The marker in the names of temporary files, ``.NAME.tmp<pid>-<random><suffix>``: the
#: writer's process id lets a later write to the same place remove those whose writer died.
_TMP_MARK = ".tmp"


class OutputError(ValueError):
    """An output path that cannot or must not be written (named with its option in the message)."""


def _kind(mode: int) -> str:
    """What a non-regular file is, in words."""
    for test, name in (
        (stat.S_ISDIR, "a folder"),
        (stat.S_ISFIFO, "a FIFO"),
        (stat.S_ISCHR, "a character device"),
        (stat.S_ISBLK, "a block device"),
        (stat.S_ISSOCK, "a socket"),
    ):
        if test(mode):
            return name
    return "not a regular file"


def _target(path: Path, label: str) -> Path:
    """Where a write to ``path`` lands: through symbolic links, and only onto a regular file or nothing."""
    if str(path) == "":
        raise OutputError(f"{label} is empty: give a file name")
    target = Path(os.path.realpath(path))
    try:
        mode = target.stat().st_mode
    except FileNotFoundError:
        return target
    except NotADirectoryError:
        raise OutputError(f"{label} {str(path)!r}: {str(_existing_folder(target.parent, label, path))!r} is not a folder") from None
    except OSError as err:
        raise OutputError(f"{label} {str(path)!r} cannot be examined: {err.strerror}") from None
    if stat.S_ISDIR(mode):
        raise OutputError(f"{label} {str(path)!r} is a folder: give a file name inside it")
    if not stat.S_ISREG(mode):
        raise OutputError(f"{label} {str(path)!r} exists and is {_kind(mode)}, not a regular file: refusing to replace it")
    return target


def _existing_folder(folder: Path, label: str, path: Path) -> Path:
    """The nearest existing ancestor of ``folder``; it must be a folder."""
    probe = folder
    while not probe.exists() and probe != probe.parent:
        probe = probe.parent
    if not probe.is_dir():
        raise OutputError(f"{label} {str(path)!r}: {str(probe)!r} is not a folder")
    return probe


def _probe_writable(folder: Path, label: str, path: Path) -> None:
    """Create and remove a file in ``folder``: the only test of writability that root, read-only mounts and /proc all answer truly."""
    try:
        fd, name = tempfile.mkstemp(prefix=f".probe{_TMP_MARK}{os.getpid()}-", dir=folder)
    except OSError as err:
        raise OutputError(f"{label} {str(path)!r}: cannot write in {str(folder)!r} ({err.strerror or err})") from None
    os.close(fd)
    os.unlink(name)


def check_output(
    path: str | Path,
    option: str = "--out",
    *,
    formats: tuple[str, ...] | None = None,
    inputs: Mapping[str, str | Path | None] | None = None,
    folder: bool = False,
) -> Path:
    """Check, before any work, that ``path`` can be written as an output; returns it.

    Parameters
    ----------
    path : path
        The output file (or folder, with ``folder``).
    option : str
        The option that named it, for the messages (``--out``, ``--plot``).
    formats : tuple of str, optional
        Allowed suffixes (lower case, with the dot).
    inputs : mapping, optional
        The command's input files by option (``{"--config": path}``); the output must be none of them.
    folder : bool
        ``path`` is a folder to write files into (created if missing).

    Raises
    ------
    OutputError
        Naming the option and the path: an empty path, an unknown format, a folder
        where a file is expected (or the reverse), a target that exists and is not a
        regular file (a FIFO, a device), a path under a regular file, a place where
        nothing can be written, or one of the command's inputs.
    """
    path = Path(path)
    if str(path) == "":
        raise OutputError(f"{option} is empty: give a {'folder' if folder else 'file'} name")
    if formats is not None and path.suffix.lower() not in formats:
        raise OutputError(f"unknown format {path.suffix or '(none)'!r} of {option} {str(path)!r}; allowed: {', '.join(formats)}")
    if folder:
        target = Path(os.path.realpath(path))
        if target.exists() and not target.is_dir():
            raise OutputError(f"{option} {str(path)!r} exists and is not a folder")
        _probe_writable(_existing_folder(target, option, path), option, path)
        return path
    target = _target(path, f"{option}")
    for name, other in (inputs or {}).items():
        if other is not None and str(other) != "" and Path(os.path.realpath(other)) == target:
            raise OutputError(f"{option} {str(path)!r} is the {name} file: refusing to overwrite an input")
    _probe_writable(_existing_folder(target.parent, option, path), option, path)
    return path


def _remove_stale(target: Path) -> None:
    """Remove temporary files left beside ``target`` by writers that were killed (their process is gone)."""
    prefix = f".{target.name}{_TMP_MARK}"
    try:
        entries = list(target.parent.iterdir())
    except OSError:
        return
    for entry in entries:
        name = entry.name
        if not name.startswith(prefix):
            continue
        pid = name[len(prefix) :].split("-", 1)[0]
        if not pid.isdigit() or _alive(int(pid)):
            continue
        try:
            if stat.S_ISREG(entry.lstat().st_mode):
                entry.unlink()
        except OSError:
            pass


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return True


@contextmanager
def atomic_path(path: str | Path) -> Iterator[Path]:
    """A temporary file beside ``path`` (same extension), renamed onto it if the block succeeds.

    A reader never sees a half-written file, and an interrupted write leaves none
    behind (a killed one is removed by the next write to the same place). The file
    gets the usual permissions (mkstemp creates it 0600). A symbolic link is written
    through: its target is replaced and the link kept. Missing folders are created.

    Raises
    ------
    OutputError
        If ``path`` is empty, a folder, or exists and is not a regular file (a FIFO, a device):
        such a target is never replaced.
    """
    target = _target(Path(path), "output")
    try:
        target.parent.mkdir(parents=True, exist_ok=True)
    except (FileExistsError, NotADirectoryError):
        raise OutputError(f"output {str(path)!r}: {str(_existing_folder(target.parent, 'output', Path(path)))!r} is not a folder") from None
    _remove_stale(target)
    fd, tmp = tempfile.mkstemp(prefix=f".{target.name}{_TMP_MARK}{os.getpid()}-", suffix=target.suffix, dir=target.parent)
    os.close(fd)
    try:
        yield Path(tmp)
        umask = os.umask(0)
        os.umask(umask)
        os.chmod(tmp, 0o666 & ~umask)
        # The target may have become something else while we wrote (a FIFO made meanwhile).
        _target(target, "output")
        os.replace(tmp, target)
    finally:
        if os.path.exists(tmp):
            os.unlink(tmp)


#: The paper this package reproduces, for the files' ``references`` attribute.
REFERENCES = (
    "Vasiliev A. A. et al., Modeling of static deformations and dynamics of localized rotation in a chain of finite "
    "size particles; extending Vasiliev A. A. and Dmitriev S. V., Discrete and Multifield Models of a Cosserat Chain: "
    "One-Period and Two-Period Solutions, Russ. Phys. J. 59, 961 (2016)"
)

#: How the dimensionless model's units read (every file's ``units_convention`` attribute).
UNITS_CONVENTION = (
    "The model is dimensionless and takes its units from its parameters: 'length' is the unit of h, a and b; "
    "'mass' that of m; 'stiffness' that of E1 and E2; 'time' is sqrt(mass / stiffness) and 'energy' (also the "
    "unit of a moment) stiffness x length^2. With the paper's chain (h = E1 = m = 1) all are 1."
)

#: Units and long name of every variable and coordinate the package writes, by name.
VARIABLES: dict[str, tuple[str, str]] = {
    "u": ("length", "displacement u of a particle's centre along the chain"),
    "v": ("length", "displacement v of a particle's centre across the chain"),
    "phi": ("rad", "rotation angle phi of a particle"),
    "u_dot": ("length/time", "velocity du/dt"),
    "v_dot": ("length/time", "velocity dv/dt"),
    "phi_dot": ("rad/time", "angular velocity dphi/dt"),
    "time": ("time", "time"),
    "particle": ("1", "particle index k in -N..N (the ends +-N clamped)"),
    "kinetic": ("energy", "kinetic energy K"),
    "potential": ("energy", "potential energy P (NaN for the non-conservative sine model)"),
    "load_work": ("energy", "work W done by the loads since the start"),
    "dissipated": ("energy", "energy D dissipated by the viscous damping since the start"),
    "balance_error": ("energy", "energy balance residual K + P - W + D - (K0 + P0)"),
    "moment": ("energy", "moment M on the loaded particle"),
    "phi0": ("rad", "rotation angle phi_0 of the loaded particle"),
    "point": ("1", "index of a point along the branch"),
    "stable": ("1", "1 if the state is stable, 0 if not"),
    "critical_eigenvalue": ("stiffness", "lowest eigenvalue of the stiffness (symmetric similar of the sine model's Jacobian)"),
    "M_c": ("energy", "critical moment M_c: onset of rotation under a slowly rising load (NaN: no fold)"),
    "phi0_at_fold": ("rad", "phi_0 of the loaded particle at the fold M_c"),
    "compliance": ("rad/energy", "compliance dphi_0/dM at rest"),
    "model": ("1", "model name"),
    "winding": ("1", "signed full turns trunc(theta / 2 pi) at the end"),
    "turns": ("1", "full turns of the loaded particle"),
    "unwrapped_angle": ("rad", "phi at the end minus phi at the start"),
    "max_abs_u": ("length", "largest |u| over the run"),
    "max_abs_v": ("length", "largest |v| over the run"),
    "max_abs_phi": ("rad", "largest |phi| over the run"),
    "last_turn_time": ("time", "time of the latest new full turn"),
    "mean_energy_share": ("1", "mean fraction of the chain's energy held by the particle"),
    "rotating": ("1", "1 if the particle still rotates at the end"),
    "recent_turn": ("1", "index of a recent turn (the latest ones kept)"),
    "onset_load": ("energy", "first load of the upward relaxation sweep at which the loaded particle rotates (NaN: none)"),
    "stop_load": ("energy", "first load of the downward relaxation sweep at which rotation has stopped (NaN: none)"),
    "mean_angular_velocity": ("rad/time", "mean angular velocity of the loaded particle"),
    "band_gap": ("1/time", "width of the transverse-rotational band gap of the infinite linear chain (0: none)"),
    "done": ("1", "1 once the cell was computed (successfully or not)"),
    "error": ("1", "error message of a failed cell (empty if it succeeded)"),
    "load": ("energy", "moment M of the relaxation"),
    "angular_velocity": ("rad/time", "angular velocity of each particle at the end of the load step"),
    "status": ("1", "how the load step ended (static, rotating, not_converged, ...)"),
    "relax_time": ("time", "time the load step ran"),
    "step": ("1", "index of the load step"),
    "direction": ("1", "up or down: the sweep's direction at this step"),
    "multiplier": ("1", "index of a Floquet multiplier"),
    "multiplier_real": ("1", "real part of a Floquet multiplier"),
    "multiplier_imag": ("1", "imaginary part of a Floquet multiplier"),
    "branch_moment": ("energy", "moment M of the continued orbit"),
    "branch_period": ("time", "period T of the continued orbit"),
    "branch_mean_angular_velocity": ("rad/time", "mean angular velocity of the loaded particle on the continued orbit"),
    "branch_max_multiplier": ("1", "largest modulus of a non-trivial Floquet multiplier on the continued orbit"),
    "branch_stable": ("1", "1 if the continued orbit is stable"),
    "E1": ("stiffness", "stiffness E1 of a horizontal link"),
    "E2": ("stiffness", "stiffness E2 of a diagonal link"),
    "h": ("length", "distance h between particle centres"),
    "a": ("length", "half-width a of a particle"),
    "b": ("length", "half-height b of a particle"),
    "m": ("mass", "mass m of a particle"),
    "j": ("mass length^2", "moment of inertia j of a particle"),
    "gamma_u": ("mass/time", "viscous coefficient of u"),
    "gamma_v": ("mass/time", "viscous coefficient of v"),
    "gamma_phi": ("mass length^2/time", "viscous coefficient of phi"),
    "N": ("1", "half the number of particles (particles -N..N)"),
}

#: Titles of the files by their ``experiment`` attribute (a simulation has none).
TITLES = {
    None: "Damped simulation of a discrete Cosserat chain under loads",
    "simulation_checkpoint": "Checkpoint of a damped simulation of a discrete Cosserat chain (simulate --checkpoint-every)",
    "critical_point": "Static branch, folds and critical moment of a discrete Cosserat chain",
    "relaxation_sweep": "Relaxation protocol (the paper's Fig. 2) of a discrete Cosserat chain",
    "localization_run": "Localized rotation of one particle of a discrete Cosserat chain",
    "periodic_orbit": "Rotating state of a discrete Cosserat chain as a periodic orbit",
    "rotation_characteristic": "Rotation characteristic of a discrete Cosserat chain",
    "parameter_study": "Parameter study of a discrete Cosserat chain",
    "state_diagram": "Both edges of the hysteresis loop of a discrete Cosserat chain against one of its parameters",
}


def _description(name: str) -> tuple[str, str] | None:
    """Units and long name of a variable, from :data:`VARIABLES` (prefixed names: final_u, diag_turns)."""
    if name in VARIABLES:
        return VARIABLES[name]
    for prefix, what in (("final_", "at the end of the run"), ("diag_", "state of the streaming diagnostics, for resuming")):
        if name.startswith(prefix):
            base = VARIABLES.get(name[len(prefix) :])
            units = base[0] if base else "1"
            return units, f"{base[1] if base else name[len(prefix) :].replace('_', ' ')}, {what}"
    return None


def describe(dataset: xr.Dataset) -> xr.Dataset:
    """The dataset with the CF-1.10 attributes every file of the package carries (a new Dataset).

    Global: ``Conventions``, ``title``, ``history`` (time, version and command line),
    ``source``, ``references`` (the paper) and ``units_convention``. Every variable and
    coordinate: ``units`` and ``long_name``, from :data:`VARIABLES` where the producer set none.
    """
    from . import __version__

    dataset = dataset.copy()
    stamp = f"{datetime.now(UTC).isoformat(timespec='seconds')} cosserat-chain {__version__}: {' '.join(map(shlex.quote, sys.argv))}"
    previous = dataset.attrs.get("history")
    dataset.attrs.update(
        {
            "Conventions": "CF-1.10",
            "title": dataset.attrs.get("title") or TITLES.get(dataset.attrs.get("experiment"), "Result of cosserat-chain"),
            "history": stamp if not previous else f"{previous}\n{stamp}",
            "source": f"cosserat-chain {__version__}",
            "references": REFERENCES,
            "units_convention": UNITS_CONVENTION,
        }
    )
    for name, variable in dataset.variables.items():
        described = _description(str(name))
        if name == "value" and dataset.attrs.get("parameter") in VARIABLES:
            # A state diagram's coordinate: the values of the field it varies.
            units, what = VARIABLES[dataset.attrs["parameter"]]
            described = units, f"the varied field {dataset.attrs['parameter']}: {what}"
        if described is None:
            continue
        units, long_name = described
        variable.attrs.setdefault("units", units)
        variable.attrs.setdefault("long_name", long_name)
    return dataset


def write_dataset(dataset: xr.Dataset, path: str | Path) -> Path:
    """Write ``dataset`` to NetCDF at ``path`` atomically, CF-described (:func:`describe`); returns the path.

    Attribute values that are subclasses of ``str`` (a :class:`~cosserat_chain.status.Status`)
    are written as plain strings: h5netcdf finds no conversion for them. Booleans (such as
    ``param_periodic``) are written as 0 or 1: NetCDF has no boolean type (``params_json``
    keeps them as booleans).
    """
    dataset = describe(dataset)
    for attrs in [dataset.attrs, *(variable.attrs for variable in dataset.variables.values())]:
        attrs.update({key: str(value) for key, value in attrs.items() if isinstance(value, str) and type(value) is not str})
        attrs.update({key: int(value) for key, value in attrs.items() if isinstance(value, (bool, np.bool_))})
    with atomic_path(path) as tmp:
        dataset.to_netcdf(tmp, engine="h5netcdf")
    return Path(path)


def write_text(text: str, path: str | Path) -> Path:
    """Write ``text`` (UTF-8) to ``path`` atomically; returns the path."""
    with atomic_path(path) as tmp:
        tmp.write_text(text, encoding="utf-8")
    return Path(path)


def write_figure(figure: Any, path: str | Path, **savefig: Any) -> Path:
    """Write a matplotlib figure to ``path`` atomically, in the format its suffix names; returns the path."""
    path = Path(path)
    with atomic_path(path) as tmp:
        figure.savefig(tmp, format=path.suffix.lstrip(".").lower() or None, **savefig)
    return path


def stack_models(datasets: dict[str, xr.Dataset]) -> xr.Dataset:
    """One Dataset with a ``model`` dimension from per-model results of the same experiment.

    Dimensions of different lengths (e.g. the points of each model's branch) are
    padded with NaN; attributes that differ between models (the model's name and
    equation) are dropped, and the names are the ``model`` coordinate.
    """
    import xarray as xr

    if len(datasets) == 1:
        return next(iter(datasets.values()))
    stacked = xr.concat(list(datasets.values()), dim="model", join="outer", combine_attrs="drop_conflicts")
    return stacked.assign_coords(model=list(datasets))


def read_dataset(path: str | Path) -> xr.Dataset:
    """Load a NetCDF result written by :func:`write_dataset` into memory.

    Raises
    ------
    ValueError
        Naming the path, if it does not exist, is not a regular file, or is not a
        readable NetCDF-4 file (truncated, another format).
    """
    path = Path(path)
    try:
        mode = path.stat().st_mode
    except FileNotFoundError:
        raise ValueError(f"{str(path)!r} does not exist") from None
    if not stat.S_ISREG(mode):
        raise ValueError(f"{str(path)!r} is {_kind(mode)}, not a NetCDF file")
    import xarray as xr

    try:
        with xr.open_dataset(path, engine="h5netcdf") as ds:
            return ds.load()
    except (OSError, ValueError, KeyError, TypeError) as err:  # h5py and xarray say "truncated", "not HDF5", ... in their own words
        raise ValueError(f"{str(path)!r} is not a readable NetCDF file written by this package ({type(err).__name__}: {err})") from None


def read_config(path: str | Path) -> dict[str, Any]:
    """Parse a TOML file into a dict.

    Raises
    ------
    ValueError
        If the file does not exist, is not a regular file (a folder, /dev/zero), is
        larger than :data:`MAX_CONFIG_BYTES`, cannot be read, or is not valid UTF-8 TOML.
    """
    path = Path(path)
    try:
        mode = path.stat().st_mode
        if not stat.S_ISREG(mode):
            raise ValueError(f"config file {str(path)!r} is {_kind(mode)}, not a regular file")
        with path.open("rb") as fh:
            data = fh.read(MAX_CONFIG_BYTES + 1)
    except FileNotFoundError:
        raise ValueError(f"config file {str(path)!r} does not exist") from None
    except OSError as err:
        raise ValueError(f"config file {str(path)!r} cannot be read: {err.strerror or err}") from None
    if len(data) > MAX_CONFIG_BYTES:
        raise ValueError(f"config file {str(path)!r} is larger than {MAX_CONFIG_BYTES} bytes: not a TOML file of parameters")
    try:
        return tomllib.loads(data.decode("utf-8"))
    except UnicodeDecodeError as err:
        raise ValueError(f"config file {str(path)!r} is not valid TOML: not UTF-8 text ({err.reason} at byte {err.start})") from None
    except tomllib.TOMLDecodeError as err:
        raise ValueError(f"config file {str(path)!r} is not valid TOML: {err}") from None


def params_from_mapping(mapping: dict[str, Any], source: str = "config") -> ChainParams:
    """Validated ``ChainParams`` from a mapping of field names.

    Raises
    ------
    ValueError
        Naming an unknown (e.g. misspelled) key and listing the allowed ones, or
        the field, value and rule of an invalid value.
    """
    allowed = list(ChainParams.model_fields)
    unknown = [key for key in mapping if key not in allowed]
    if unknown:
        raise ValueError(f"unknown key(s) {unknown} in {source}; allowed keys: {', '.join(allowed)}")
    return ChainParams(**mapping)


#: The table of a config file that holds loads (``[[loads]]``, :func:`cosserat_chain.loads.load_from_table`).
LOADS_TABLE = "loads"
#: The table of a config file that draws a disordered chain (:func:`cosserat_chain.params.disordered`).
DISORDER_TABLE = "disorder"


def disorder_from_table(params: ChainParams, table: Any, source: str) -> ChainParams:
    """``params`` made disordered by a ``[disorder]`` table: ``seed``, ``spread`` and optionally ``fields``.

    Raises
    ------
    ValueError
        Naming the source and the key: a table that is not one, an unknown or missing key,
        a bad value (:func:`~cosserat_chain.params.disordered`'s rules), or a field whose
        factors the file also gives by hand (``E1_factors`` and ``fields`` with "E1").
    """
    from .params import DISORDER_FIELDS, disordered

    where = f"[{DISORDER_TABLE}] of {source}"
    if not isinstance(table, dict):
        raise ValueError(f"{where} must be a table with keys seed, spread and optionally fields, got {table!r}")
    unknown = [key for key in table if key not in ("seed", "spread", "fields")]
    missing = [key for key in ("seed", "spread") if key not in table]
    if unknown or missing:
        raise ValueError(
            f"{where}: "
            + (f"unknown key(s) {unknown}" if unknown else f"missing key(s) {missing}")
            + "; its keys are seed, spread and fields"
        )
    fields = table.get("fields", ["E1", "E2"])
    if isinstance(fields, str) or not isinstance(fields, list):
        raise ValueError(f"{where}: fields must be a list of {', '.join(DISORDER_FIELDS)}, got {fields!r}")
    given = [DISORDER_FIELDS[f] for f in fields if f in DISORDER_FIELDS and getattr(params, DISORDER_FIELDS[f]) is not None]
    if given:
        raise ValueError(f"{where} draws factors that the file also gives ({', '.join(given)}): give one or the other")
    try:
        return disordered(params, table["seed"], table["spread"], tuple(fields))
    except ValueError as err:
        raise ValueError(f"{where}: {err}") from None


def load_params(path: str | Path | None = None) -> ChainParams:
    """``ChainParams`` from a TOML file, or the paper's defaults when ``path`` is None.

    A ``[[loads]]`` array in the file is not a parameter: :func:`load_config` reads both.
    """
    return load_config(path)[0]


def load_config(path: str | Path | None = None) -> tuple[ChainParams, Loads]:
    """``ChainParams`` and the ``[[loads]]`` of a TOML file (the paper's chain and no loads when ``path`` is None).

    A ``[disorder]`` table (``seed``, ``spread``, ``fields``) draws the chain's factors:
    :func:`disorder_from_table`.

    Raises
    ------
    ValueError
        For a bad parameter or load, naming the key, the value and what is allowed (a
        load on a degree of freedom the chain's ends hold included).
    """
    from .loads import Loads, loads_from_tables

    if path is None:
        return ChainParams(), Loads()
    mapping = read_config(path)
    tables = mapping.pop(LOADS_TABLE, [])
    disorder = mapping.pop(DISORDER_TABLE, None)
    params = params_from_mapping(mapping, source=str(path))
    if disorder is not None:
        params = disorder_from_table(params, disorder, repr(str(path)))
    return params, loads_from_tables(tables, source=f"[[{LOADS_TABLE}]] of {str(path)!r}").validate(params)


def params_of(dataset: xr.Dataset) -> ChainParams:
    """The ``ChainParams`` stored in a result's ``params_json`` attribute.

    Raises
    ------
    ValueError
        If the Dataset has no ``params_json`` attribute or it holds invalid parameters.
    """
    if "params_json" not in dataset.attrs:
        raise ValueError("the dataset has no params_json attribute: pass params explicitly")
    return params_from_mapping(json.loads(dataset.attrs["params_json"]), source="params_json")


def run_frame(dataset: xr.Dataset, at: float | None = None) -> tuple[ChainParams, Loads, float, np.ndarray, np.ndarray]:
    """The chain, the loads and one stored frame (time, positions, velocities) of a run, to start another from.

    ``at`` picks the stored frame nearest that time (default the last); the run's own
    parameters and loads come with it, so that a run started there continues its time
    axis and its loads' schedules.

    Raises
    ------
    ValueError
        If the dataset is not a run with velocities (``simulate --out``), or ``at`` lies
        outside its time axis.
    """
    from .loads import Loads

    params = params_of(dataset)
    times, states = run_states(params, dataset)
    missing = [f"{row}_dot" for row in ROWS if f"{row}_dot" not in dataset]
    if missing:
        raise ValueError(f"the dataset lacks the velocities {missing}: start from a run written by simulate --out")
    if at is None:
        frame = times.size - 1
    else:
        if not (math.isfinite(at) and times[0] <= at <= times[-1]):
            raise ValueError(f"--at must lie within the run's times {times[0]:g}..{times[-1]:g}, got {at!r}")
        frame = int(np.argmin(np.abs(times - at)))
    ordered = dataset.sortby("particle").isel(time=frame)
    velocities = np.stack([np.asarray(ordered[f"{row}_dot"].values, dtype=float) for row in ROWS])
    loads = Loads.from_list(json.loads(dataset.attrs.get("loads_json", "[]")))
    return params, loads.validate(params), float(times[frame]), np.ascontiguousarray(states[frame]), velocities


def run_states(params: ChainParams, dataset: xr.Dataset) -> tuple[np.ndarray, np.ndarray]:
    """Times (n,) and states (n, 3, 2N+1) of a run (``simulate --out``), particles in order -N..N.

    Raises
    ------
    ValueError
        If the dataset lacks u, v or phi, or has another number of particles than ``params``.
    """
    missing = [row for row in ROWS if row not in dataset]
    if missing:
        raise ValueError(f"the dataset lacks the variable(s) {missing}; a run has u, v, phi over (time, particle)")
    dataset = dataset.sortby("particle")
    if dataset.sizes["particle"] != params.n_particles:
        raise ValueError(f"the dataset has {dataset.sizes['particle']} particles but params describe 2N+1 = {params.n_particles}")
    states = np.stack([dataset[row].transpose("time", "particle").values for row in ROWS], axis=1)
    return np.asarray(dataset["time"].values, dtype=float), states
