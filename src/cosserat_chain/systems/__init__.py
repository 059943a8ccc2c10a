"""Systems the package's analyses run on: the public interface, lattices from formulas, built-in examples.

* :class:`~cosserat_chain.systems.base.System`: the interface (coordinates, angles, forces,
  Jacobians, named parameters, optional energy) every analysis of
  :mod:`cosserat_chain.numerics.equilibria` and :mod:`cosserat_chain.numerics.shooting` takes;
* :class:`~cosserat_chain.systems.lattice.LatticeSystem`: a lattice from per-site and
  per-bond formulas, compiled with exact Jacobians;
* built-in examples, one file each: :func:`pen` (AUTO-07p's demo), :func:`josephson_array`,
  :func:`frenkel_kontorova`, :func:`takeno_peyrard`;
* :func:`load_system`: a user's system named as ``module:function`` or ``path/to/file.py:function``.
"""

from .base import ApproximateJacobianWarning, FlowKernels, System, SystemDefinitionError
from .frenkel_kontorova import frenkel_kontorova
from .josephson import josephson_array
from .lattice import LatticeSystem
from .loader import BUILTIN, load_system
from .pen import pen
from .takeno_peyrard import takeno_peyrard

__all__ = [
    "BUILTIN",
    "ApproximateJacobianWarning",
    "FlowKernels",
    "LatticeSystem",
    "System",
    "SystemDefinitionError",
    "frenkel_kontorova",
    "josephson_array",
    "load_system",
    "pen",
    "takeno_peyrard",
]
