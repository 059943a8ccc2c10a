"""The three discrete models of the paper behind one interface (see :mod:`.base`).

``nonlinear`` (model i, eq. 1), ``sine`` (model ii, eq. 2) and ``linear`` (model iii, eq. 3).
"""

from .base import FORCE_KERNEL_TYPE, FORCE_SIGNATURE, Model, available_models, get_model, register_model
from .linear import LINEAR, LinearModel
from .nonlinear import NONLINEAR, NonlinearModel
from .sine import SINE, SineModel

__all__ = [
    "FORCE_KERNEL_TYPE",
    "FORCE_SIGNATURE",
    "LINEAR",
    "NONLINEAR",
    "SINE",
    "LinearModel",
    "Model",
    "NonlinearModel",
    "SineModel",
    "available_models",
    "get_model",
    "register_model",
]
