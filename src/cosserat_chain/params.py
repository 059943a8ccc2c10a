"""Validated parameters of the chain and the coefficients derived from its geometry.

Contract
--------
:class:`ChainParams` holds the paper's symbols (Sections 2 and 4) and nothing else.
Every derived quantity (diagonal length ``d``, the coefficients of eqs. (2)-(3),
``D1`` and ``D2`` of Section 3) is a property computed from the geometry of the
nonlinear model (i), never read from the printed equations: the printed
coefficients disagree with each other (see ``docs/errata.md``).

Linearising the four links of one bond (two horizontal ones of stiffness E1 and
rest length h - 2a, two crossed diagonals of stiffness E2 and rest length d)
gives the bond energy

    P_bond = k_u/2 du^2 + E1 b^2 dphi^2 + k_v/2 (dv - h (phi_k + phi_k+1)/2)^2

with du = u_k+1 - u_k etc., k_u = 2 (E1 + (h - 2a)^2 / d^2 E2) and
k_v = 8 b^2 / d^2 E2. Its equations of motion are eq. (3) with the coupling
term 4 (h^2/d^2) E2 of eq. (2), i.e. with bending coefficient
D1 = E1 - (h^2/d^2) E2 and coupling D2 = 4 (h^2/d^2) E2.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from pydantic import BaseModel, ConfigDict, Field, StrictBool, StrictInt, field_validator, model_validator

#: Default viscous coefficient of every degree of freedom (the paper gives none). With
#: the paper's geometry it damps the rotational modes (omega ~ 3-5, j ~ 0.027) at about
#: 40 % of critical and the translational ones lightly, so static states are reached in
#: tens to hundreds of time units, and a particle driven by M spins at most at M / 0.1.
DEFAULT_DAMPING = 0.1


#: What an end particle may be: ``"clamped"`` (u = v = phi = 0), ``"pinned"`` (u = v = 0,
#: phi free: a hinge) or ``"free"`` (no condition).
END_KINDS = ("clamped", "pinned", "free")
#: The ends of a ring (``periodic=True``), set by the ring itself: it has none.
RING = "ring"
#: Degrees of freedom (rows u, v, phi) each kind of end holds fixed.
FIXED_ROWS = {"clamped": (0, 1, 2), "pinned": (0, 1), "free": (), RING: ()}


#: Magnitudes a field may take: the model is dimensionless, and its coefficients multiply and
#: square the fields (d^2 = (h - 2a)^2 + 4 b^2, E h^2 / d^2), which overflow or vanish far outside.
MAX_MAGNITUDE = 1e100
MIN_MAGNITUDE = 1e-100


#: Per-bond factors of the link stiffnesses and per-particle factors of the inertia (a graded
#: or disordered chain); None is the uniform chain.
BOND_FACTORS = ("E1_factors", "E2_factors")
PARTICLE_FACTORS = ("m_factors", "j_factors")
#: Fields that are not numbers (checked by their own validators).
_NOT_NUMBERS = ("N", "left_end", "right_end", "periodic", *BOND_FACTORS, *PARTICLE_FACTORS)


class ChainParams(BaseModel):
    """Parameters of a chain of 2N+1 rectangular particles (paper, Section 2 and Fig. 1).

    Each attribute is also a keyword of the constructor: ``ChainParams(N=10, E2=0.5)``.

    Attributes
    ----------
    E1 : float
        Stiffness of each of the two horizontal links of a bond (top-top and
        bottom-bottom), > 0. Default 1 (Section 4).
    E2 : float
        Stiffness of each of the two crossed diagonal links, >= 0. Default 1
        (Section 4: E2 = E1).
    h : float
        Distance between neighbouring particle centres, > 0. Default 1.
    a, b : float
        Half-width (along the chain) and half-height of a particle, 0 < a < h/2
        (neighbours must not touch) and b > 0. Default 0.2 (Section 4: a = b = 0.2 h).
    m : float
        Mass of a particle, > 0. Default 1 (the paper is dimensionless and gives none).
    j : float, optional
        Moment of inertia, > 0. Default m (a^2 + b^2) / 3, a uniform rectangle 2a x 2b.
    gamma_u, gamma_v, gamma_phi : float
        Viscous coefficients of eqs. (2)-(3), >= 0. Default ``DEFAULT_DAMPING`` = 0.1
        each, a medium that resists every motion alike; the paper gives no value.
    N : int
        Half the number of particles: particles are indexed -N..N. N = 3 is the
        paper's chain of seven particles (the ends +-N among them, clamped).
    left_end, right_end : {"clamped", "pinned", "free"}
        Condition on particle -N and on particle N: ``"clamped"`` (default, the
        paper's: u = v = phi = 0), ``"pinned"`` (u = v = 0, phi free) or ``"free"``.
    periodic : bool
        A ring: particle N is bonded to particle -N as to a neighbour h further on
        (the infinite chain with period (2N+1) h). Every particle is then free;
        ``left_end`` and ``right_end`` must be left out (they become ``"ring"``).
        Default False.
    E1_factors, E2_factors : tuple of float, optional
        A graded or disordered chain: bond k (joining particles k - N and k - N + 1,
        a ring's closing bond last) has links of stiffness E1 E1_factors[k] and
        E2 E2_factors[k]; one factor per bond (:attr:`n_bonds`: 2N, or 2N+1 for a
        ring), each > 0 (E2's >= 0). Default None: every bond alike.
    m_factors, j_factors : tuple of float, optional
        Particle k - N has mass m m_factors[k] and moment of inertia j j_factors[k];
        2N+1 factors each, > 0. Default None: every particle alike.
        (:func:`disordered` draws them from a seed.) Factors all alike are folded into
        the scalar they multiply (``E1_factors`` all 2 is ``E1`` doubled), so that such a
        chain is the uniform chain itself.

    Notes
    -----
    Every value must be a number (an int, a float or a NumPy scalar; not a string or a
    boolean), finite, and 0 or between :data:`MIN_MAGNITUDE` and :data:`MAX_MAGNITUDE` in
    magnitude. An invalid value raises ``pydantic.ValidationError`` (a ``ValueError``)
    naming the field, the value and what is allowed.
    """

    model_config = ConfigDict(extra="forbid", frozen=True, allow_inf_nan=False)

    E1: float = Field(1.0, description="stiffness of a horizontal link (> 0)")
    E2: float = Field(1.0, description="stiffness of a diagonal link (>= 0)")
    h: float = Field(1.0, description="distance between particle centres (> 0)")
    a: float = Field(0.2, description="half-width of a particle (0 < a < h/2)")
    b: float = Field(0.2, description="half-height of a particle (> 0)")
    m: float = Field(1.0, description="mass of a particle (> 0)")
    j: float = Field(None, description="moment of inertia (> 0); default m (a^2 + b^2) / 3")  # type: ignore[assignment]
    gamma_u: float = Field(DEFAULT_DAMPING, description="viscosity of u (>= 0)")
    gamma_v: float = Field(DEFAULT_DAMPING, description="viscosity of v (>= 0)")
    gamma_phi: float = Field(DEFAULT_DAMPING, description="viscosity of phi (>= 0)")
    N: StrictInt = Field(3, description="particles -N..N (>= 1)")
    left_end: str = Field("clamped", description="particle -N: clamped, pinned or free")
    right_end: str = Field("clamped", description="particle N: clamped, pinned or free")
    periodic: StrictBool = Field(False, description="a ring: particle N bonded to particle -N")
    E1_factors: tuple[float, ...] | None = Field(None, description="per-bond factors of E1 (n_bonds values > 0)")
    E2_factors: tuple[float, ...] | None = Field(None, description="per-bond factors of E2 (n_bonds values >= 0)")
    m_factors: tuple[float, ...] | None = Field(None, description="per-particle factors of m (2N+1 values > 0)")
    j_factors: tuple[float, ...] | None = Field(None, description="per-particle factors of j (2N+1 values > 0)")

    @model_validator(mode="before")
    @classmethod
    def _numbers_and_inertia(cls, data: Any) -> Any:
        if not isinstance(data, dict):
            return data
        # Strict on types: a NumPy scalar is a number (converted to its Python value, so
        # that j's default and the JSON see plain numbers); a string or a boolean is not,
        # though pydantic's lax mode would read "2" as 2.0 and true as 1.0 (a TOML typo
        # would pass unnoticed). N must be an integer (StrictInt).
        data = {key: value.item() if isinstance(value, np.generic) else value for key, value in data.items()}
        for key, value in data.items():
            if key not in cls.model_fields or key in _NOT_NUMBERS or value is None:
                continue
            if isinstance(value, bool) or not isinstance(value, (int, float)):
                raise ValueError(f"{key} must be a number, got {value!r} ({type(value).__name__})")
            if math.isfinite(value) and value != 0 and not MIN_MAGNITUDE <= abs(value) <= MAX_MAGNITUDE:
                raise ValueError(
                    f"{key} must lie between {MIN_MAGNITUDE:g} and {MAX_MAGNITUDE:g} in magnitude (or be 0 where allowed), got {value!r}: "
                    "the model is dimensionless, so scale the chain to numbers of order 1 (squares and products of the "
                    "fields must stay finite)"
                )
        # j defaults to a value that depends on m, a and b; it is resolved and stored
        # so that the resolved parameters describe a run completely.
        if data.get("j") is not None:
            return data
        fields = cls.model_fields
        m, a, b = (data.get(name, fields[name].default) for name in ("m", "a", "b"))
        if all(isinstance(x, (int, float)) and not isinstance(x, bool) for x in (m, a, b)):
            j = m * (a * a + b * b) / 3.0
            if m > 0 and a > 0 and b > 0 and not MIN_MAGNITUDE <= j <= MAX_MAGNITUDE:
                # Fields each in range can still give a default j out of it (or 0, or inf).
                raise ValueError(
                    f"j, left out, defaults to m (a^2 + b^2) / 3 = {j!r} (m={m!r}, a={a!r}, b={b!r}), which must lie between "
                    f"{MIN_MAGNITUDE:g} and {MAX_MAGNITUDE:g}: give j, or scale the chain to numbers of order 1"
                )
            data = {**data, "j": j}
        return data

    @field_validator("E1", "h", "b", "m", "j")
    @classmethod
    def _positive(cls, value: float, info: Any) -> float:
        if not value > 0:
            raise ValueError(f"{info.field_name} must be > 0, got {value!r}")
        return value

    @field_validator("E2", "gamma_u", "gamma_v", "gamma_phi")
    @classmethod
    def _non_negative(cls, value: float, info: Any) -> float:
        if not value >= 0:
            raise ValueError(f"{info.field_name} must be >= 0, got {value!r}")
        return value

    @field_validator("N")
    @classmethod
    def _at_least_one(cls, value: int) -> int:
        if value < 1:
            raise ValueError(f"N must be an integer >= 1 (particles -N..N), got {value!r}")
        return value

    @model_validator(mode="before")
    @classmethod
    def _ends(cls, data: Any) -> Any:
        if not isinstance(data, dict):
            return data
        periodic = data.get("periodic", False)
        ring = periodic is True or (isinstance(periodic, np.bool_) and bool(periodic))
        given = {name: data[name] for name in ("left_end", "right_end") if name in data}
        for name, value in given.items():
            if ring and value != RING:
                raise ValueError(f"periodic=True (a ring) has no ends: leave {name} out, got {name}={value!r}")
            if not ring and value not in END_KINDS:
                extra = " ('ring' only with periodic = true)" if value == RING else ""
                raise ValueError(f"{name} must be one of {', '.join(map(repr, END_KINDS))}, got {value!r}{extra}")
        return {**data, "left_end": RING, "right_end": RING} if ring else data

    @model_validator(mode="before")
    @classmethod
    def _factor_lists(cls, data: Any) -> Any:
        if not isinstance(data, dict):
            return data
        out = dict(data)
        for name in (*BOND_FACTORS, *PARTICLE_FACTORS):
            value = data.get(name)
            if value is None:
                continue
            # A flat sequence only: a nested list (a table of factors) or a set has no bond order.
            if not (isinstance(value, (list, tuple)) or (isinstance(value, np.ndarray) and value.ndim == 1)):
                raise ValueError(
                    f"{name} must be a list of numbers (one per {'bond' if name in BOND_FACTORS else 'particle'}), got {value!r}"
                )
            items = [item.item() if isinstance(item, np.generic) else item for item in value]
            lowest = 0.0 if name == "E2_factors" else None
            for index, item in enumerate(items):
                if isinstance(item, bool) or not isinstance(item, (int, float)) or not math.isfinite(item):
                    raise ValueError(f"{name}[{index}] must be a finite number, got {item!r}")
                if not (item >= 0 if lowest == 0.0 else item > 0) or abs(item) > MAX_MAGNITUDE or 0 < abs(item) < MIN_MAGNITUDE:
                    allowed = ">= 0" if lowest == 0.0 else "> 0"
                    raise ValueError(
                        f"{name}[{index}] must be {allowed} (and between {MIN_MAGNITUDE:g} and {MAX_MAGNITUDE:g}), got {item!r}"
                    )
            out[name] = tuple(float(item) for item in items)
        # Factors all alike are no grading: they fold into the scalar (E1_factors all c is the
        # chain with E1 c), so that such a chain is the uniform one, to the last bit, in every
        # kernel and every result. j's default is resolved from the unscaled m first.
        fields = cls.model_fields
        N, periodic = data.get("N", fields["N"].default), data.get("periodic", False) is True
        if isinstance(N, int) and not isinstance(N, bool) and N >= 1:
            # The lengths first: factors all alike fold away below, and must fit the chain too.
            for name in (*BOND_FACTORS, *PARTICLE_FACTORS):
                count = 2 * N + 1 if name in PARTICLE_FACTORS or periodic else 2 * N
                what = "particles" if name in PARTICLE_FACTORS else "bonds"
                if out.get(name) is not None and len(out[name]) != count:
                    raise ValueError(
                        f"{name} must have one value for each of the chain's {count} {what} (N={N}{', a ring' if periodic else ''}), "
                        f"got {len(out[name])}"
                    )
        for name, scalar in (("E1_factors", "E1"), ("E2_factors", "E2"), ("m_factors", "m"), ("j_factors", "j")):
            factors = out.get(name)
            if factors is None or len(set(factors)) > 1 or not factors:
                continue
            if scalar == "m" and out.get("j") is None:
                m, a, b = (out.get(key, fields[key].default) for key in ("m", "a", "b"))
                out["j"] = m * (a * a + b * b) / 3.0
            base = out.get(scalar)
            if scalar == "j" and base is None:
                m, a, b = (data.get(key, fields[key].default) for key in ("m", "a", "b"))
                base = m * (a * a + b * b) / 3.0
            out[scalar] = (fields[scalar].default if base is None else base) * factors[0]
            out[name] = None
        return out

    @model_validator(mode="after")
    def _particles_do_not_touch(self) -> ChainParams:
        if not 0 < self.a < self.h / 2:
            raise ValueError(
                f"a must satisfy 0 < a < h/2 = {self.h / 2!r} (neighbouring particles would touch or overlap), got a={self.a!r}"
            )
        return self

    # ------------------------------------------------------------------ derived
    @property
    def n_particles(self) -> int:
        """Number of particles 2N+1, end particles included."""
        return 2 * self.N + 1

    @property
    def ends(self) -> tuple[str, str]:
        """Kinds of the two ends (left, right); ``("ring", "ring")`` for a ring, whose particles all move."""
        return (self.left_end, self.right_end)

    @property
    def clamped(self) -> bool:
        """Whether both ends are clamped (the paper's chain; the continuum solutions of Section 3 need it)."""
        return not self.periodic and self.left_end == self.right_end == "clamped"

    @property
    def n_bonds(self) -> int:
        """Number of bonds: 2N between neighbours, one more for a ring (particle N to particle -N)."""
        return self.n_particles if self.periodic else self.n_particles - 1

    @property
    def rigid_modes(self) -> int:
        """Rigid motions the ends leave free, the zero modes of the chain at rest.

        3 for free ends (two translations and the rotation), 1 for a pinned end with a
        free one (the rotation about the pin), 2 for a ring (the translations along and
        across it; a rigid rotation does not repeat round it), 0 when a clamped end or
        two pinned ones hold the chain. The statics need 0.
        """
        if self.periodic:
            return 2
        ends = sorted((self.left_end, self.right_end))
        return {("free", "free"): 3, ("free", "pinned"): 1}.get(tuple(ends), 0)

    def describe_ends(self) -> str:
        """The ends in words, for messages and titles: "clamped ends", "a ring", "left pinned, right free"."""
        if self.periodic:
            return "a ring"
        if self.left_end == self.right_end:
            return f"{self.left_end} ends"
        return f"left {self.left_end}, right {self.right_end}"

    @property
    def gap(self) -> float:
        """Rest length h - 2a of a horizontal link."""
        return self.h - 2.0 * self.a

    @property
    def d(self) -> float:
        """Rest length of a diagonal link, sqrt((h - 2a)^2 + 4 b^2) (Fig. 1)."""
        return math.hypot(self.gap, 2.0 * self.b)

    @property
    def k_u(self) -> float:
        """Longitudinal bond stiffness 2 (E1 + (h-2a)^2/d^2 E2), first line of eqs. (2)-(3)."""
        return 2.0 * (self.E1 + self.gap**2 / self.d**2 * self.E2)

    @property
    def k_v(self) -> float:
        """Transverse bond stiffness 8 b^2/d^2 E2, second line of eqs. (2)-(3)."""
        return 8.0 * self.b**2 / self.d**2 * self.E2

    @property
    def D1(self) -> float:
        """Bending coefficient E1 - (h^2/d^2) E2 of eqs. (2)-(3) (Section 3 misprints it)."""
        return self.E1 - self.h**2 / self.d**2 * self.E2

    @property
    def D2(self) -> float:
        """Coupling coefficient 4 (h^2/d^2) E2 of eq. (2) (eq. (3) misprints it without the 4)."""
        return 4.0 * self.h**2 / self.d**2 * self.E2

    @property
    def moment_scale(self) -> float:
        """E1 h^2, the unit of the dimensionless moment M / (E1 h^2) of Fig. 2 (a link's stiffness times a length squared)."""
        return self.E1 * self.h**2

    @property
    def inertia(self) -> tuple[float, float, float]:
        """Inertia of the rows (u, v, phi): (m, m, j)."""
        return (self.m, self.m, self.j)

    @property
    def graded_stiffness(self) -> bool:
        """Whether the bonds differ (``E1_factors`` or ``E2_factors`` given)."""
        return self.E1_factors is not None or self.E2_factors is not None

    @property
    def graded_inertia(self) -> bool:
        """Whether the particles' inertia differs (``m_factors`` or ``j_factors`` given)."""
        return self.m_factors is not None or self.j_factors is not None

    @property
    def graded(self) -> bool:
        """Whether the chain is graded or disordered in its bonds or its particles."""
        return self.graded_stiffness or self.graded_inertia

    @property
    def bond_stiffness(self) -> tuple[np.ndarray, np.ndarray]:
        """(E1, E2) of every bond, arrays (n_bonds,): the scalars times their factors (the scalars repeated if none)."""
        return tuple(  # type: ignore[return-value]
            np.full(self.n_bonds, value) if factors is None else value * np.asarray(factors)
            for value, factors in ((self.E1, self.E1_factors), (self.E2, self.E2_factors))
        )

    @property
    def particle_inertia(self) -> np.ndarray:
        """Inertia of every degree of freedom, (3, 2N+1): rows m, m, j times the particles' factors."""
        n = self.n_particles
        mass = np.full(n, self.m) if self.m_factors is None else self.m * np.asarray(self.m_factors)
        turn = np.full(n, self.j) if self.j_factors is None else self.j * np.asarray(self.j_factors)
        return np.stack([mass, mass, turn])

    @property
    def damping(self) -> tuple[float, float, float]:
        """Viscous coefficients of the rows (u, v, phi)."""
        return (self.gamma_u, self.gamma_v, self.gamma_phi)

    def replace(self, **changes: Any) -> ChainParams:
        """Return validated parameters with some fields changed.

        j keeps its current value unless changed; pass ``j=None`` to have it
        re-derived from the new m, a and b. Making a chain a ring (``periodic=True``) or
        an open chain again resets the ends that are not given.
        """
        data = {**self.model_dump(), **changes}
        sized = {"N", "periodic"} & set(changes)
        graded = [name for name in (*BOND_FACTORS, *PARTICLE_FACTORS) if data.get(name) is not None and name not in changes]
        if sized and graded and (changes.get("N", self.N), changes.get("periodic", self.periodic)) != (self.N, self.periodic):
            raise ValueError(
                f"changing {' and '.join(sorted(sized))} changes the number of bonds and particles: give {', '.join(graded)} "
                "anew (or None) with it"
            )
        if changes.get("periodic", self.periodic) != self.periodic:
            # Into or out of a ring: the ends not given anew follow (a ring's, or clamped).
            for name in ("left_end", "right_end"):
                if name not in changes:
                    data.pop(name)
        return ChainParams(**data)


#: Fields :func:`disordered` may vary, with the factors they draw.
DISORDER_FIELDS = {"E1": "E1_factors", "E2": "E2_factors", "m": "m_factors", "j": "j_factors"}


def disordered(params: ChainParams, seed: int, spread: float, fields: tuple[str, ...] = ("E1", "E2")) -> ChainParams:
    """``params`` with independent factors 1 + spread U(-1, 1) on every bond's E1, E2 or every particle's m, j.

    Parameters
    ----------
    params : ChainParams
        The uniform chain (its existing factors of the named fields are replaced).
    seed : int
        Seed of NumPy's default generator: the same seed gives the same chain.
    spread : float
        Relative spread, 0 <= spread < 1 (factors stay > 0).
    fields : tuple of str
        Any of "E1", "E2" (per bond) and "m", "j" (per particle), drawn in that order.

    Raises
    ------
    ValueError
        For a spread outside [0, 1), an unknown field or a seed that is not an integer.
    """
    if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or seed < 0:
        raise ValueError(f"seed must be an integer >= 0, got {seed!r}")
    if isinstance(spread, bool) or not isinstance(spread, (int, float)) or not 0.0 <= spread < 1.0:
        raise ValueError(f"spread must be a number with 0 <= spread < 1 (the factors must stay > 0), got {spread!r}")
    unknown = [name for name in fields if name not in DISORDER_FIELDS]
    if unknown or not fields:
        raise ValueError(f"fields must be a non-empty selection of {', '.join(DISORDER_FIELDS)}, got {list(fields)!r}")
    rng = np.random.default_rng(int(seed))
    changes = {}
    for name in DISORDER_FIELDS:
        if name in fields:
            count = params.n_bonds if name in ("E1", "E2") else params.n_particles
            changes[DISORDER_FIELDS[name]] = tuple(1.0 + spread * rng.uniform(-1.0, 1.0, count))
    return params.replace(**changes)
