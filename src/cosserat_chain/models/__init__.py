"""The three discrete models of the paper behind one interface (see :mod:`.base`).

``nonlinear`` (model i, eq. 1), ``sine`` (model ii, eq. 2) and ``linear`` (model iii, eq. 3).
"""

from .base import FORCE_KERNEL_TYPE, FORCE_SIGNATURE, Model, available_models, get_model, register_model, unregister_model
from .linear import LinearModel
from .nonlinear import NonlinearModel
from .sine import SineModel

# The registry lines, in the paper's order: the CLI offers the models, and its
# ``--model all`` runs them, in registration order.
NONLINEAR = register_model(NonlinearModel())
SINE = register_model(SineModel())
LINEAR = register_model(LinearModel())

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
    "unregister_model",
]
