"""The paper's chain seen through the public system interface: a ChainParams, a model and a moment, bound once.

Contract
--------
:class:`ChainSystem` is the chain of 2N+1 particles (Section 2) under a constant moment M
on one particle, as a :class:`~cosserat_chain.systems.base.System`: its coordinates are
the free degrees of freedom (the held ones of clamped and pinned ends left out, ordering
of :mod:`cosserat_chain.state`), its angles the free phi, its forces the model's (eqs.
(1)-(3)) plus M, its Jacobian the model's exact stiffness (negated), its mass and
damping the particles' (m, j and gamma_u, gamma_v, gamma_phi). Its parameters are ``M``
and the chain's numeric fields (``E1``, ``E2``, ``h``, ``a``, ``b``, ``m``, ``j``,
``gamma_u``, ``gamma_v``, ``gamma_phi``), so any of them can be continued by
:mod:`cosserat_chain.numerics.equilibria` and :mod:`cosserat_chain.numerics.shooting`.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from ..models.base import Model, get_model
from ..params import ChainParams
from ..state import dof, free_index, n_free, pack, per_dof, unpack
from .base import System, SystemDefinitionError

#: The chain's fields that are parameters of the system (the numbers; N and the ends are its shape).
CHAIN_FIELDS = ("E1", "E2", "h", "a", "b", "m", "j", "gamma_u", "gamma_v", "gamma_phi")


class ChainSystem(System):
    """The paper's chain under a moment ``M`` on ``particle`` (module docstring)."""

    def __init__(self, params: ChainParams, model: str | Model, *, M: float = 0.0, particle: int = 0):
        super().__init__({"M": M, **{name: getattr(params, name) for name in CHAIN_FIELDS}})
        self.chain = params
        self.model = get_model(model)
        self.particle = particle
        self.name = f"chain ({self.model.name}, N={params.N})"
        self._load_dof = dof(params, "phi", particle)

    def with_parameters(self, **values: float) -> ChainSystem:
        clone = super().with_parameters(**values)
        fields = {name: value for name, value in values.items() if name in CHAIN_FIELDS}
        if fields:
            try:
                clone.chain = self.chain.replace(**fields)
            except ValueError as error:
                raise SystemDefinitionError(f"{self.name}: {error}") from None
        return clone

    @property
    def coordinates(self) -> tuple[str, ...]:
        rows = ("u", "v", "phi")
        # free_index counts in x.T.ravel(): particle-major, three rows per particle.
        return tuple(f"{rows[i % 3]}_{i // 3 - self.chain.N}" for i in free_index(self.chain))

    @property
    def angles(self) -> np.ndarray:
        return np.array([name.startswith("phi_") for name in self.coordinates])

    def forces(self, q: np.ndarray) -> np.ndarray:
        q = self.check_state(q)
        out = self.model.packed_forces(self.chain, q)
        out[self._load_dof] += self.parameter("M")
        return out

    def force_jacobian(self, q: np.ndarray) -> sp.csr_matrix:
        q = self.check_state(q)
        return -self.model.stiffness(self.chain, unpack(self.chain, q)).tocsr()

    def parameter_forces(self, q: np.ndarray, name: str) -> np.ndarray:
        if name == "M":
            out = np.zeros(self.size)
            out[self._load_dof] = 1.0
            return out
        return super().parameter_forces(q, name)

    def energy(self, q: np.ndarray) -> float | None:
        try:
            elastic = self.model.energy(self.chain, unpack(self.chain, self.check_state(q)))
        except TypeError:
            return None
        return float(elastic - self.parameter("M") * q[self._load_dof])

    def mass(self) -> np.ndarray:
        return pack(self.chain, self.chain.particle_inertia)

    def damping(self) -> np.ndarray:
        return per_dof(self.chain, self.chain.damping)

    @property
    def size(self) -> int:
        return n_free(self.chain)
