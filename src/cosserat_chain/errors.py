"""The one base class of the package's errors.

Contract
--------
Every exception class the package defines derives from :class:`CosseratChainError` and
keeps the builtin base that says what kind of failure it is (``ValueError`` for bad input,
``RuntimeError`` for a computation that could not be completed), so a caller can catch all
of the package's errors at once (``except CosseratChainError``) or by kind
(``except ValueError``) as before. A floor module: it imports nothing from the package.
"""

from __future__ import annotations


class CosseratChainError(Exception):
    """Base class of every error the package raises of its own (not of the builtin errors it raises directly)."""
