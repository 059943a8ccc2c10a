"""Every error the package defines derives from one base class, and keeps its builtin kind."""

from __future__ import annotations

import importlib
import inspect
import pkgutil

import pytest

import cosserat_chain
from cosserat_chain import CosseratChainError


def package_exceptions() -> list[type[BaseException]]:
    """Every exception class defined at the top of one of the package's modules (warnings left out).

    Each module is imported (``__main__`` modules, which run the command line, left out) and
    its own classes kept: a class imported from elsewhere is counted in its module.
    """
    found = []
    for info in pkgutil.walk_packages(cosserat_chain.__path__, "cosserat_chain."):
        if info.name.rsplit(".", 1)[-1] == "__main__":
            continue
        module = importlib.import_module(info.name)
        found += [
            obj
            for obj in vars(module).values()
            if inspect.isclass(obj) and issubclass(obj, BaseException) and not issubclass(obj, Warning) and obj.__module__ == module.__name__
        ]
    return found


def test_every_error_of_the_package_derives_from_the_one_base_class():
    errors = package_exceptions()
    names = {cls.__name__ for cls in errors}
    # The walk found the errors it must (a walk that found nothing would pass the check below).
    assert {"CosseratChainError", "NewtonError", "BranchEndError", "OrbitError", "IntegrationError", "OutputError", "InputFileError"} <= names
    outside = sorted(f"{cls.__module__}.{cls.__qualname__}" for cls in errors if not issubclass(cls, CosseratChainError))
    assert not outside, f"these errors do not derive from CosseratChainError: {outside}"


@pytest.mark.parametrize(
    "module, name, kind",
    [
        ("inputs", "InputFileError", ValueError),
        ("io", "OutputError", ValueError),
        ("memory", "MemoryEstimateError", ValueError),
        ("numerics.newton", "NewtonError", RuntimeError),
        ("numerics.newton", "BranchEndError", RuntimeError),
        ("numerics.periodic", "OrbitError", RuntimeError),
        ("numerics.dynamics", "IntegrationError", RuntimeError),
        ("study_runner", "ClusterError", RuntimeError),
    ],
)
def test_each_error_keeps_its_builtin_kind_so_existing_handlers_still_catch_it(module, name, kind):
    cls = getattr(importlib.import_module(f"cosserat_chain.{module}"), name)
    assert issubclass(cls, CosseratChainError) and issubclass(cls, kind)


def test_a_package_error_is_caught_by_the_base_class_and_by_its_kind():
    from cosserat_chain.io import OutputError

    for handler in (CosseratChainError, ValueError):
        with pytest.raises(handler, match="cannot write"):
            raise OutputError("cannot write here")
    assert not issubclass(ValueError, CosseratChainError)  # a plain ValueError is not the package's own
