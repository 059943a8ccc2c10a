"""The package's version, read once from its installed metadata (``pyproject.toml``'s ``version``).

A floor module with no imports from the package, so that every layer that stamps its results
with the version (files, the report, ``--version``) imports it downward rather than from the
package's top level.
"""

from __future__ import annotations

from importlib.metadata import PackageNotFoundError, version

try:
    __version__ = version("cosserat-chain")
except PackageNotFoundError:  # running from a source tree that was not installed
    __version__ = "0+unknown"
