"""A system named on the command line: a built-in example, ``module:function`` or ``file.py:function``.

The function is called with the parameters given (a TOML table or ``--set name=value``),
and must return a :class:`~cosserat_chain.systems.base.System`.
"""

from __future__ import annotations

import importlib
import importlib.util
import inspect
from collections.abc import Mapping
from pathlib import Path

from .base import System, SystemDefinitionError

#: The built-in examples, by the name ``--system`` accepts.
BUILTIN = {
    "pen": "cosserat_chain.systems.pen:pen",
    "josephson_array": "cosserat_chain.systems.josephson:josephson_array",
    "frenkel_kontorova": "cosserat_chain.systems.frenkel_kontorova:frenkel_kontorova",
    "takeno_peyrard": "cosserat_chain.systems.takeno_peyrard:takeno_peyrard",
}


def load_system(reference: str, arguments: Mapping[str, object] | None = None) -> System:
    """The system ``reference`` names, built with ``arguments``.

    Parameters
    ----------
    reference : str
        A built-in name (:data:`BUILTIN`), ``package.module:function`` or ``path/to/file.py:function``.
    arguments : mapping, optional
        Keyword arguments of the function (parameters, ``sites``, ``boundary``).

    Raises
    ------
    SystemDefinitionError
        For a reference that does not resolve, arguments the function does not take, or a
        function that does not return a System.
    """
    target = BUILTIN.get(reference, reference)
    module_name, sep, attribute = target.rpartition(":")
    if not sep or not module_name or not attribute:
        raise SystemDefinitionError(
            f"--system must be a built-in ({', '.join(BUILTIN)}), module:function or file.py:function, got {reference!r}"
        )
    if module_name.endswith(".py"):
        path = Path(module_name)
        if not path.is_file():
            raise SystemDefinitionError(f"--system: no file {str(path)!r}")
        spec = importlib.util.spec_from_file_location(f"cosserat_chain_user_{path.stem}", path)
        module = importlib.util.module_from_spec(spec)
        try:
            spec.loader.exec_module(module)
        except Exception as error:  # the user's file: any failure is reported, not raised
            raise SystemDefinitionError(f"--system: importing {str(path)!r} failed: {type(error).__name__}: {error}") from None
    else:
        if module_name.startswith(".") or "/" in module_name or "\\" in module_name:
            raise SystemDefinitionError(
                f"--system: {module_name!r} is a path but not a .py file: give path/to/file.py:function (or module:function)"
            )
        try:
            module = importlib.import_module(module_name)
        except ImportError as error:
            raise SystemDefinitionError(f"--system: cannot import {module_name!r}: {error}") from None
    factory = getattr(module, attribute, None)
    if factory is None:
        raise SystemDefinitionError(f"--system: {module_name!r} has no {attribute!r}")
    arguments = dict(arguments or {})
    if callable(factory) and not isinstance(factory, System):
        try:
            inspect.signature(factory).bind(**arguments)
        except TypeError as error:
            raise SystemDefinitionError(f"--system {reference}: {error} (check the [system] parameters)") from None
        system = factory(**arguments)
    else:
        system = factory
    if not isinstance(system, System):
        raise SystemDefinitionError(f"--system {reference} must return a cosserat_chain System, got {type(system).__name__}")
    return system
