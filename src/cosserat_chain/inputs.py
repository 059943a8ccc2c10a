"""The one schema of the result files the package reads back as inputs.

Contract
--------
A file given as an input (``simulate --x0``, ``draw``, ``animate``, ``export``, a checkpoint
to resume) may be corrupted, edited or of another program. Reading it as NetCDF is not
enough: :func:`check_run` checks, before anything uses it, everything a run's reader
relies on, and raises a :class:`InputFileError` (a ``ValueError``) that names the file and
the first thing wrong:

- ``params_json``: a JSON object of valid :class:`~cosserat_chain.params.ChainParams` fields;
- ``loads_json`` (optional): a JSON list of loads that act on the chain's free degrees of freedom;
- the variables ``u``, ``v``, ``phi`` (and ``u_dot``, ``v_dot``, ``phi_dot`` where velocities
  are read) over exactly the dimensions ``time`` and ``particle``, real numbers, all finite;
- the ``particle`` coordinate: the integers -N..N of the stored chain, each once;
- the ``time`` coordinate: at least one frame, finite, increasing.

:func:`check_counts` checks the step counts of a checkpoint (whole numbers >= 0, a step
count not beyond the run's) and :func:`check_finite` its state variables. This module
sits with the data (params, loads, state): it reads no file and imports neither xarray
nor the writers, so that every reader above it can use it.
"""

from __future__ import annotations

import json
import math
from collections.abc import Iterable, Mapping
from typing import TYPE_CHECKING, Any

import numpy as np

from .errors import CosseratChainError
from .params import ChainParams
from .state import ROWS

if TYPE_CHECKING:  # loads import numba: the command line imports them where a command needs them
    from .loads import Loads


class InputFileError(CosseratChainError, ValueError):
    """A file given as an input that is not what the command reads (named, with what is wrong)."""


def params_from_mapping(mapping: Any, source: str = "config") -> ChainParams:
    """Validated ``ChainParams`` from a mapping of field names.

    Raises
    ------
    ValueError
        Naming the source if it is not a mapping, an unknown (e.g. misspelled) key and
        listing the allowed ones, or the field, value and rule of an invalid value.
    """
    allowed = list(ChainParams.model_fields)
    if not isinstance(mapping, Mapping):
        raise ValueError(f"{source} must be a table of parameters ({', '.join(allowed)}), got {type(mapping).__name__}")
    unknown = [key for key in mapping if key not in allowed]
    if unknown:
        raise ValueError(f"unknown key(s) {unknown} in {source}; allowed keys: {', '.join(allowed)}")
    return ChainParams(**mapping)


def _json_attribute(attrs: Mapping[str, Any], name: str, source: str, default: str | None = None) -> Any:
    text = attrs.get(name, default)
    if text is None:
        raise InputFileError(f"{source} has no {name} attribute: it is not a result of this package")
    if not isinstance(text, str):
        raise InputFileError(f"{source}: the attribute {name} must be JSON text, got {type(text).__name__}")
    try:
        return json.loads(text)
    except (json.JSONDecodeError, RecursionError) as err:
        raise InputFileError(f"{source}: the attribute {name} is not valid JSON ({err})") from None


def stored_params(attrs: Mapping[str, Any], source: str) -> ChainParams:
    """The ``ChainParams`` of a result's ``params_json`` attribute.

    Raises
    ------
    InputFileError
        Naming the source: no such attribute, not JSON, not an object, or invalid parameters.
    """
    try:
        return params_from_mapping(_json_attribute(attrs, "params_json", source), source="params_json")
    except InputFileError:
        raise
    except ValueError as err:  # pydantic's ValidationError too
        raise InputFileError(f"{source}: the attribute params_json holds no valid chain: {_first_line(err)}") from None


def stored_loads(attrs: Mapping[str, Any], params: ChainParams, source: str) -> Loads:
    """The :class:`~cosserat_chain.loads.Loads` of a result's ``loads_json`` attribute (none if absent), on ``params``' chain.

    Raises
    ------
    InputFileError
        Naming the source: not JSON, not a list of loads, or a load off the chain's free degrees of freedom.
    """
    from .loads import Loads

    try:
        return Loads.from_list(_json_attribute(attrs, "loads_json", source, "[]"), source="loads_json").validate(params)
    except InputFileError:
        raise
    except ValueError as err:
        raise InputFileError(f"{source}: {err}") from None


def _first_line(err: Exception) -> str:
    errors = getattr(err, "errors", None)
    if callable(errors):  # pydantic: the field and its message
        first = errors()[0]
        return f"{'.'.join(map(str, first['loc'])) or 'params'}: {first['msg']}"
    return str(err).splitlines()[0]


def _real(values: np.ndarray) -> bool:
    return values.dtype.kind in "fiu"


def check_finite(dataset: Any, names: Iterable[str], source: str, *, dims: tuple[str, ...] | None = None) -> None:
    """Refuse a dataset that lacks one of ``names`` or holds a value that is not a finite real number there.

    Parameters
    ----------
    dataset : xarray.Dataset
    names : iterable of str
        The variables that must be present.
    source : str
        The file, for the messages.
    dims : tuple of str, optional
        The dimensions each variable must have (in any order).

    Raises
    ------
    InputFileError
    """
    for name in names:
        if name not in dataset.variables:
            raise InputFileError(f"{source} lacks the variable {name!r}")
        variable = dataset.variables[name]
        if dims is not None and set(variable.dims) != set(dims):
            raise InputFileError(f"{source}: the variable {name!r} is over {tuple(variable.dims)}, not over {dims}")
        values = np.asarray(variable.values)
        if not _real(values):
            raise InputFileError(f"{source}: the variable {name!r} holds {values.dtype} values, not real numbers")
        if not np.isfinite(values).all():
            bad = int(np.size(values) - np.count_nonzero(np.isfinite(values)))
            raise InputFileError(f"{source}: the variable {name!r} holds {bad} value(s) that are not finite (NaN or infinite)")


def check_counts(attrs: Mapping[str, Any], names: Iterable[str], source: str, *, total: str | None = None) -> dict[str, int]:
    """The whole numbers >= 0 that ``attrs`` hold under ``names`` (step counts), or an error naming the first bad one.

    With ``total``, the count ``steps`` may not pass the count named ``total`` (a run's steps
    beyond the steps it asked for).

    Raises
    ------
    InputFileError
    """
    counts = {}
    for name in names:
        value = attrs.get(name)
        value = value.item() if isinstance(value, np.generic) else value
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value) or value != int(value) or value < 0:
            raise InputFileError(f"{source}: the count {name} must be a whole number >= 0, got {value!r}")
        counts[name] = int(value)
    if total is not None and "steps" in counts and counts["steps"] > counts[total]:
        raise InputFileError(f"{source}: steps={counts['steps']} is beyond the run's {total}={counts[total]}")
    return counts


def check_run(dataset: Any, source: str, *, velocities: bool = False) -> tuple[ChainParams, Loads]:
    """The chain and the loads of a run (``simulate --out``) read from ``source``, every field checked (module docstring).

    Parameters
    ----------
    dataset : xarray.Dataset
    source : str
        The file, for the messages.
    velocities : bool
        Require ``u_dot``, ``v_dot``, ``phi_dot`` as well (a run to start from or to export).

    Returns
    -------
    params : ChainParams
    loads : Loads

    Raises
    ------
    InputFileError
        Naming the source and the first field that is missing, of the wrong type or shape, or not finite.
    """
    names = [*ROWS, *(f"{row}_dot" for row in ROWS)] if velocities else list(ROWS)
    missing = [name for name in names if name not in dataset.variables]
    if missing:
        what = "a run to start from or export needs its velocities too" if velocities else "a run has u, v, phi over (time, particle)"
        raise InputFileError(f"{source} lacks the variable(s) {missing}: {what} (written by simulate --out)")
    params = stored_params(dataset.attrs, source)
    loads = stored_loads(dataset.attrs, params, source)
    check_finite(dataset, names, source, dims=("time", "particle"))
    for coordinate in ("time", "particle"):
        if coordinate not in dataset.coords:
            raise InputFileError(f"{source} has no {coordinate} coordinate")
    particle = np.asarray(dataset["particle"].values)
    if particle.dtype.kind not in "iu" or sorted(particle.tolist()) != list(range(-params.N, params.N + 1)):
        raise InputFileError(
            f"{source}: the particle coordinate must be the integers -N..N of its chain (N={params.N}, "
            f"{params.n_particles} particles), got {particle.size} values"
        )
    times = np.asarray(dataset["time"].values)
    if times.size == 0:
        raise InputFileError(f"{source} holds no frame (its time axis is empty)")
    if not _real(times) or not np.isfinite(times).all() or (np.diff(times) <= 0).any():
        raise InputFileError(f"{source}: the time coordinate must be finite and increasing")
    return params, loads
