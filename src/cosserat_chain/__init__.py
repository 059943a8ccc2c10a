"""cosserat-chain: discrete Cosserat chains of finite-size particles that translate and rotate.

The package implements the three models of the paper (nonlinear springs, sine-Cosserat
eq. (2), linear Cosserat eq. (3)) with geometry-derived coefficients, compiled damped
dynamics under moment loads, and self-describing results.
"""

from importlib.metadata import PackageNotFoundError, version

try:
    __version__ = version("cosserat-chain")
except PackageNotFoundError:  # running from a source tree that was not installed
    __version__ = "0+unknown"

from .loads import Loads, PointLoad, Schedule, moment_load
from .models import available_models, get_model
from .params import ChainParams

__all__ = ["ChainParams", "Loads", "PointLoad", "Schedule", "__version__", "available_models", "get_model", "moment_load"]
