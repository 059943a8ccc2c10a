"""The public system interface: what every analysis of the package needs to know of a mechanical system.

Contract
--------
A :class:`System` is a mechanical system of n generalized coordinates q,

    M q'' = F(q; p) - C q',                                             (S)

with a diagonal mass M (n,), a diagonal viscous damping C (n,) and generalized forces F
(conservative, -dE/dq, or not, like the sine-Cosserat model (2) or a constant torque),
depending on named parameters p, any of which can be continued. Some coordinates are
angles: the system is 2 pi periodic in them, so a state that turns k times in a period
is a periodic orbit with the phase gain 2 pi k (:mod:`cosserat_chain.numerics.shooting`).

A system supplies F, its Jacobian dF/dq (sparse, banded for chains), dF/dp for every
parameter, optionally the energy E, and the flow of (S) with its variational equations.
The base class gives finite differences for the Jacobians and a SciPy DOP853 flow, so a
system written as plain NumPy forces works (slowly, with a warning once);
:class:`~cosserat_chain.systems.lattice.LatticeSystem` builds compiled forces, exact
Jacobians and a compiled flow from formulas, and
:class:`~cosserat_chain.systems.chain.ChainSystem` is the paper's chain (a
:class:`~cosserat_chain.params.ChainParams` and a model) seen through this interface.

Systems are immutable values: :meth:`System.with_parameters` returns a new one.
"""

from __future__ import annotations

import abc
import math
import warnings
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np
import scipy.sparse as sp

from ..errors import CosseratChainError

#: Relative step of the finite differences of the fallback Jacobians (central differences:
#: truncation step^2 meets round-off eps/step near 1e-5 .. 1e-6).
FD_STEP = 1e-6


class SystemDefinitionError(CosseratChainError, ValueError):
    """A system that cannot be posed as given (a bad parameter name, value or state)."""


@dataclass(frozen=True)
class FlowKernels:
    """A compiled flow of (S): what :mod:`cosserat_chain.numerics.shooting` hands to DOP853.

    ``rhs`` has the signature :data:`cosserat_chain.numerics.dop853.RHS_SIGNATURE` and reads
    y = (q (n), q' (n), then ``ncols`` variational columns row-major (2n, ncols)), ``coef``,
    ``rpar`` = (1/M, C/M, d(1/M)/dp, d(C/M)/dp) (n each) and ``ipar`` = (*head, ncols, k):
    with k >= 0 the last column carries dy/dp_k of the parameter ``coef[k]`` (k < 0: none).
    """

    rhs: Any
    coef: np.ndarray
    head: tuple[int, ...]
    parameter_index: Mapping[str, int]


class ApproximateJacobianWarning(UserWarning):
    """A system without its own Jacobian: finite differences stand in (accurate to about 1e-9)."""


class System(abc.ABC):
    """A mechanical system M q'' = F(q; p) - C q' (eq. (S) of the module docstring).

    Subclasses define :attr:`coordinates`, :attr:`angles`, :meth:`forces`, :meth:`mass`
    and :meth:`damping`, and keep their parameters in :attr:`parameters`; they may override
    :meth:`force_jacobian`, :meth:`parameter_forces`, :meth:`energy` and :meth:`flow` with
    exact or compiled versions.
    """

    #: Name shown in results and messages.
    name: str = "system"

    def __init__(self, parameters: Mapping[str, float]):
        values = {}
        for key, value in parameters.items():
            if not isinstance(key, str) or not key.isidentifier():
                raise SystemDefinitionError(f"parameter names must be identifiers, got {key!r}")
            try:
                number = float(value)
            except (TypeError, ValueError):
                raise SystemDefinitionError(f"parameter {key!r} must be a number, got {value!r}") from None
            if not math.isfinite(number):
                raise SystemDefinitionError(f"parameter {key!r} must be finite, got {value!r}")
            values[key] = number
        self._parameters = values

    # -- what a subclass defines --------------------------------------------------------

    @property
    @abc.abstractmethod
    def coordinates(self) -> tuple[str, ...]:
        """Names of the n generalized coordinates (e.g. ``phi_0``, ``phi_1``)."""

    @property
    @abc.abstractmethod
    def angles(self) -> np.ndarray:
        """(n,) bool: the coordinates in which the system is 2 pi periodic."""

    @abc.abstractmethod
    def forces(self, q: np.ndarray) -> np.ndarray:
        """Generalized forces F(q; p) (n,), without the damping."""

    @abc.abstractmethod
    def mass(self) -> np.ndarray:
        """Diagonal of M (n,), > 0."""

    @abc.abstractmethod
    def damping(self) -> np.ndarray:
        """Diagonal of C (n,): >= 0 for a passive system (a negative one feeds energy)."""

    # -- what the base class gives --------------------------------------------------------

    @property
    def size(self) -> int:
        """n, the number of coordinates."""
        return len(self.coordinates)

    @property
    def parameters(self) -> dict[str, float]:
        """The named parameters and their values (a copy)."""
        return dict(self._parameters)

    def parameter(self, name: str) -> float:
        """The value of parameter ``name``."""
        self._check_name(name)
        return self._parameters[name]

    def with_parameters(self, **values: float) -> System:
        """A copy with some parameters changed."""
        for name in values:
            self._check_name(name)
        clone = object.__new__(type(self))
        clone.__dict__.update(self.__dict__)
        merged = dict(self._parameters)
        merged.update(values)
        System.__init__(clone, merged)
        return clone

    def _check_name(self, name: str) -> None:
        if name not in self._parameters:
            known = ", ".join(self._parameters) or "none"
            raise SystemDefinitionError(f"{self.name} has no parameter {name!r}; its parameters are: {known}")

    def check_state(self, q: np.ndarray, what: str = "q") -> np.ndarray:
        """``q`` as a finite float array of shape (n,), or a clear error."""
        q = np.asarray(q, dtype=float)
        if q.shape != (self.size,):
            raise SystemDefinitionError(f"{what} must have shape ({self.size},) for {self.name}, got {q.shape}")
        if not np.all(np.isfinite(q)):
            raise SystemDefinitionError(f"{what} must be finite, got a non-finite entry at index {int(np.flatnonzero(~np.isfinite(q))[0])}")
        return q

    def energy(self, q: np.ndarray) -> float | None:
        """Potential energy E(q) with F = -dE/dq, or None for a system without one."""
        return None

    def force_jacobian(self, q: np.ndarray) -> sp.csr_matrix:
        """dF/dq (n, n), by central differences unless a subclass gives it exactly."""
        self._warn_approximate()
        q = np.asarray(q, dtype=float)
        columns = []
        for i in range(self.size):
            step = FD_STEP * max(1.0, abs(q[i]))
            plus, minus = q.copy(), q.copy()
            plus[i] += step
            minus[i] -= step
            columns.append((self.forces(plus) - self.forces(minus)) / (2 * step))
        return sp.csr_matrix(np.column_stack(columns))

    def parameter_forces(self, q: np.ndarray, name: str) -> np.ndarray:
        """dF/dp for parameter ``name`` (n,), by central differences unless a subclass gives it exactly."""
        self._warn_approximate()
        value = self.parameter(name)
        step = FD_STEP * max(1.0, abs(value))
        plus = self.with_parameters(**{name: value + step}).forces(q)
        minus = self.with_parameters(**{name: value - step}).forces(q)
        return (plus - minus) / (2 * step)

    def parameter_mass_damping(self, name: str) -> tuple[np.ndarray, np.ndarray]:
        """d(1/M)/dp and d(C/M)/dp (n,) each, for the flow's parameter derivative."""
        value = self.parameter(name)
        step = FD_STEP * max(1.0, abs(value))
        plus, minus = self.with_parameters(**{name: value + step}), self.with_parameters(**{name: value - step})
        d_inverse = (1 / plus.mass() - 1 / minus.mass()) / (2 * step)
        d_rate = (plus.damping() / plus.mass() - minus.damping() / minus.mass()) / (2 * step)
        return d_inverse, d_rate

    def vector_field(self, y: np.ndarray) -> np.ndarray:
        """The first-order field f(y) of (S), y = (q, q') (2n,)."""
        n = self.size
        q, v = y[:n], y[n:]
        return np.concatenate([v, (self.forces(q) - self.damping() * v) / self.mass()])

    def flow_kernels(self):
        """Compiled kernels of the flow of (S) and its variational equations, or None.

        A compiled system returns :class:`FlowKernels`. The base class returns None: the
        flow is then integrated by SciPy from :meth:`vector_field` and the Jacobians.
        """
        return None

    def _warn_approximate(self) -> None:
        # Once per system (its copies by with_parameters share the flag), not once per evaluation.
        if not self.__dict__.get("_warned_approximate"):
            self._warned_approximate = True
            warnings.warn(
                f"{self.name} ({type(self).__name__}) gives no Jacobian: finite differences stand in (about 1e-9 accurate, "
                "n force evaluations each); write the system as a LatticeSystem or override force_jacobian for exact ones",
                ApproximateJacobianWarning,
                stacklevel=3,
            )

    def describe(self) -> dict:
        """Name, coordinates and parameters, for the attributes of result files and JSON."""
        return {"system": self.name, "coordinates": list(self.coordinates), "parameters": self.parameters}
