"""Lattice systems from formulas: per-site and per-bond energies (or forces) compiled to exact kernels.

Contract
--------
A :class:`LatticeSystem` is a one-dimensional lattice of ``sites`` identical sites, each
with the same degrees of freedom (``dofs``, e.g. ``("phi",)`` for rotators or ``("u",
"v", "phi")`` for the paper's particles), coupled to nearest neighbours:

    E(q) = sum_i site_energy(q_i) + sum_bonds bond_energy(q_l, q_r),
    F(q) = -dE/dq + sum_i site_force(q_i),                              (L)

with the equations of motion (S) of :mod:`cosserat_chain.systems.base`,
M q'' = F(q) - C q'. Formulas are SymPy expressions or strings in the site's degrees
of freedom (``phi``), the bond's (``phi_l``, ``phi_r``: the left and the right site) and
the named parameters. ``site_force`` holds the non-conservative parts (a constant torque
written as a force keeps the energy periodic; the sine-Cosserat model (2) is such a force).

From these formulas SymPy derives the forces, their exact Jacobian dF/dq and dF/dp for
every parameter; they are printed as Python, compiled by Numba with ``cache=True`` in a
file named by their hash (under the user cache directory, or ``$COSSERAT_CHAIN_CACHE``),
so a system is compiled once per machine. The compiled kernels are O(sites): forces,
the Jacobian's triplets (banded for open ends), the energy, and the DOP853 right-hand
side of the flow with its variational equations, which applies the Jacobian bond by bond.

Ends (``boundary``): ``"free"`` (sites - 1 bonds), ``"periodic"`` (a ring, sites bonds, at
least 3 sites) or ``"fixed"`` (a bond from each end to a phantom site held at q = 0).
"""

from __future__ import annotations

import hashlib
import importlib.util
import io
import keyword
import os
import stat
import sys
import tempfile
import tokenize
from collections.abc import Mapping, Sequence
from pathlib import Path

import numpy as np
import scipy.sparse as sp

from ..memory import FLOAT, MemoryEstimateError, require
from .base import FlowKernels, System, SystemDefinitionError

BOUNDARIES = ("free", "periodic", "fixed")


def _sympy():
    import sympy

    return sympy


def _cache_dir() -> Path:
    root = os.environ.get("COSSERAT_CHAIN_CACHE")
    if root:
        return Path(root) / "systems"
    base = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
    return Path(base) / "cosserat-chain" / "systems"


#: Bytes a coordinate holds at the least: its name (a short str and its pointer), a force and two state entries.
COORDINATE_BYTES = 80 + 3 * FLOAT


def _require_memory(sites: int, dofs: int) -> None:
    """Refuse, before compiling anything, a lattice whose coordinates and Jacobian do not fit in the free memory.

    Raises
    ------
    SystemDefinitionError
        Naming ``sites`` and the memory it needs (see :func:`cosserat_chain.memory.require`).
    """
    jacobian = (2 * sites + 1) * 4 * dofs * dofs * 3 * FLOAT  # the triplets force_jacobian fills
    try:
        require(
            sites * dofs * COORDINATE_BYTES + jacobian,
            f"a lattice of sites={sites} x {dofs} dofs (its coordinates and Jacobian)",
            "fewer sites",
        )
    except MemoryEstimateError as error:
        raise SystemDefinitionError(str(error)) from None


class LatticeSystem(System):
    """A lattice of rotators or particles posed by formulas (eq. (L)); see the module docstring.

    Parameters
    ----------
    sites : int
        Number of sites, >= 1 (>= 3 for a ring).
    dofs : sequence of str
        Degrees of freedom of a site, e.g. ``("phi",)``.
    angles : sequence of str
        Those of ``dofs`` in which the system is 2 pi periodic (default: all named ``phi*``, ``theta*``, ``φ*``, ``ϕ*`` or ``θ*``).
    site_energy, bond_energy : str or sympy.Expr
        Energy of a site in its ``dofs``, of a bond in ``<dof>_l`` and ``<dof>_r``.
    site_force : mapping dof -> str or sympy.Expr, optional
        Non-conservative generalized force on each site's degree of freedom.
    mass, damping : number, str, or mapping dof -> number or str
        Diagonal inertia (> 0) and viscous damping per degree of freedom, in the parameters.
    boundary : {"free", "periodic", "fixed"}
    parameters : mapping name -> float
        Every parameter the formulas use, with its value.
    name : str
    """

    def __init__(
        self,
        *,
        sites: int,
        dofs: Sequence[str] = ("phi",),
        angles: Sequence[str] | None = None,
        site_energy="0",
        bond_energy="0",
        site_force: Mapping[str, object] | None = None,
        mass=1.0,
        damping=0.0,
        boundary: str = "free",
        parameters: Mapping[str, float] | None = None,
        name: str = "lattice",
    ):
        super().__init__(parameters or {})
        if not (isinstance(sites, int | np.integer) and not isinstance(sites, bool) and sites >= 1):
            raise SystemDefinitionError(f"sites must be an integer >= 1, got {sites!r}")
        if boundary not in BOUNDARIES:
            raise SystemDefinitionError(f"boundary must be one of {', '.join(BOUNDARIES)}, got {boundary!r}")
        if boundary == "periodic" and sites < 3:
            raise SystemDefinitionError(f"a periodic lattice (a ring) needs at least 3 sites, got sites={sites}")
        dofs = tuple(dofs)
        if not dofs or len(set(dofs)) != len(dofs) or not all(isinstance(d, str) and d.isidentifier() for d in dofs):
            raise SystemDefinitionError(f"dofs must be distinct identifiers, got {dofs!r}")
        reserved = sorted(n for n in (*dofs, *self._parameters) if keyword.iskeyword(n))
        if reserved:
            raise SystemDefinitionError(
                f"names {reserved} are Python keywords, which a formula cannot use: rename them (e.g. 'lam' for 'lambda')"
            )
        clash = set(dofs) & set(self._parameters)
        if clash:
            raise SystemDefinitionError(f"names used both as a degree of freedom and a parameter: {sorted(clash)}")
        if angles is None:
            angles = tuple(d for d in dofs if d.startswith(("phi", "theta", "φ", "ϕ", "θ")))
        unknown = [a for a in angles if a not in dofs]
        if unknown:
            raise SystemDefinitionError(f"angles must be among dofs {dofs}, got {unknown}")
        _require_memory(int(sites), len(dofs))
        self.name = name
        self.sites = int(sites)
        self.dofs = dofs
        self.angle_dofs = tuple(angles)
        self.boundary = boundary
        self._spec = _Spec.build(dofs, tuple(self._parameters), site_energy, bond_energy, site_force or {}, mass, damping)
        self.mass()  # a mass <= 0 is refused here, naming it, not at the first flow

    # -- the System interface ---------------------------------------------------------------

    @property
    def coordinates(self) -> tuple[str, ...]:
        return tuple(f"{d}_{i}" for i in range(self.sites) for d in self.dofs)

    @property
    def angles(self) -> np.ndarray:
        return np.tile([d in self.angle_dofs for d in self.dofs], self.sites)

    @property
    def _boundary_code(self) -> int:
        return BOUNDARIES.index(self.boundary)

    @property
    def _coef(self) -> np.ndarray:
        return np.array([self._parameters[p] for p in self._spec.parameters], dtype=float)

    def forces(self, q: np.ndarray) -> np.ndarray:
        q = self.check_state(q)
        out = np.zeros(self.size)
        self._spec.kernels.forces(q, self._coef, self.sites, self._boundary_code, out)
        return out

    def force_jacobian(self, q: np.ndarray) -> sp.csr_matrix:
        q = self.check_state(q)
        nd = len(self.dofs)
        capacity = (self.sites + self.sites + 1) * 4 * nd * nd
        rows = np.empty(capacity, dtype=np.int64)
        cols = np.empty(capacity, dtype=np.int64)
        vals = np.empty(capacity)
        count = self._spec.kernels.jacobian(q, self._coef, self.sites, self._boundary_code, rows, cols, vals)
        return sp.csr_matrix((vals[:count], (rows[:count], cols[:count])), shape=(self.size, self.size))

    def parameter_forces(self, q: np.ndarray, name: str) -> np.ndarray:
        self._check_name(name)
        q = self.check_state(q)
        out = np.zeros((self.size, max(1, len(self._spec.parameters))))
        self._spec.kernels.parameter_forces(q, self._coef, self.sites, self._boundary_code, out)
        return out[:, self._spec.parameters.index(name)].copy()

    def energy(self, q: np.ndarray) -> float | None:
        if not self._spec.conservative:
            return None
        q = self.check_state(q)
        return float(self._spec.kernels.energy(q, self._coef, self.sites, self._boundary_code))

    def mass(self) -> np.ndarray:
        values = self._spec.per_dof(self._spec.mass, self._parameters)
        if np.any(values <= 0):
            raise SystemDefinitionError(f"the mass of every degree of freedom must be > 0, got {dict(zip(self.dofs, values, strict=True))}")
        return np.tile(values, self.sites)

    def damping(self) -> np.ndarray:
        # Any sign: a negative damping feeds energy (an active element), and the unfolding of a
        # conservative orbit (numerics.shooting) passes through zero.
        return np.tile(self._spec.per_dof(self._spec.damping, self._parameters), self.sites)

    def parameter_mass_damping(self, name: str) -> tuple[np.ndarray, np.ndarray]:
        self._check_name(name)
        d_inverse, d_rate = self._spec.mass_damping_derivatives(name, self._parameters)
        return np.tile(d_inverse, self.sites), np.tile(d_rate, self.sites)

    def flow_kernels(self) -> FlowKernels:
        index = {p: i for i, p in enumerate(self._spec.parameters)}
        kernels = self._spec.kernels
        # Compiled on the first flow only (statics never need it); DOP853 takes it as a typed first-class function.
        if not kernels.rhs.signatures:
            kernels.rhs.compile(kernels.RHS_SIGNATURE.args)
        return FlowKernels(kernels.rhs, self._coef, (self.sites, self._boundary_code), index)

    def with_sites(self, sites: int) -> LatticeSystem:
        """The same lattice with another number of sites."""
        clone = self.with_parameters()
        if not (isinstance(sites, int | np.integer) and sites >= (3 if self.boundary == "periodic" else 1)):
            raise SystemDefinitionError(f"sites must be an integer >= {3 if self.boundary == 'periodic' else 1}, got {sites!r}")
        clone.sites = int(sites)
        return clone

    def with_boundary(self, boundary: str) -> LatticeSystem:
        """The same lattice with other ends (``"free"``, ``"periodic"``, ``"fixed"``): e.g. the ring whose
        Bloch waves give the bands of a finite lattice."""
        if boundary not in BOUNDARIES:
            raise SystemDefinitionError(f"boundary must be one of {', '.join(BOUNDARIES)}, got {boundary!r}")
        if boundary == "periodic" and self.sites < 3:
            raise SystemDefinitionError(f"a periodic lattice (a ring) needs at least 3 sites, got sites={self.sites}")
        clone = self.with_parameters()
        clone.boundary = boundary
        return clone

    def describe(self) -> dict:
        out = super().describe()
        out.update(
            sites=self.sites,
            dofs=list(self.dofs),
            boundary=self.boundary,
            site_energy=str(self._spec.site_energy),
            bond_energy=str(self._spec.bond_energy),
            site_force={d: str(e) for d, e in zip(self.dofs, self._spec.site_force, strict=True)},
        )
        return out


class _Spec:
    """The parsed formulas of a lattice and its compiled kernels (shared by every copy of the system)."""

    @classmethod
    def build(cls, dofs, parameters, site_energy, bond_energy, site_force, mass, damping) -> _Spec:
        spec = cls()
        sympy = _sympy()
        spec.dofs, spec.parameters = dofs, parameters
        spec._functions = {}
        spec.q = [sympy.Symbol(d, real=True) for d in dofs]
        spec.ql = [sympy.Symbol(f"{d}_l", real=True) for d in dofs]
        spec.qr = [sympy.Symbol(f"{d}_r", real=True) for d in dofs]
        spec.p = [sympy.Symbol(p, real=True) for p in parameters]
        site_names = {s.name: s for s in spec.q + spec.p}
        bond_names = {s.name: s for s in spec.ql + spec.qr + spec.p}
        param_names = {s.name: s for s in spec.p}
        spec.site_energy = _parse(site_energy, site_names, "site_energy")
        spec.bond_energy = _parse(bond_energy, bond_names, "bond_energy")
        unknown = set(site_force) - set(dofs)
        if unknown:
            raise SystemDefinitionError(f"site_force names unknown degrees of freedom {sorted(unknown)}; the dofs are {dofs}")
        spec.site_force = [_parse(site_force.get(d, 0), site_names, f"site_force[{d!r}]") for d in dofs]
        spec.conservative = all(f == 0 for f in spec.site_force)
        spec.mass = [_parse(_per(mass, d), param_names, f"mass[{d!r}]") for d in dofs]
        spec.damping = [_parse(_per(damping, d), param_names, f"damping[{d!r}]") for d in dofs]
        spec.kernels = _compile(spec)
        return spec

    def per_dof(self, expressions, values: Mapping[str, float]) -> np.ndarray:
        """``expressions`` (the mass or the damping, one per dof) at the parameters ``values``."""
        return np.array(self._numeric(tuple(expressions))(*(values[p] for p in self.parameters)), dtype=float)

    def mass_damping_derivatives(self, name: str, values: Mapping[str, float]) -> tuple[np.ndarray, np.ndarray]:
        symbol = self.p[self.parameters.index(name)]
        d_inverse = tuple((1 / m).diff(symbol) for m in self.mass)
        d_rate = tuple((c / m).diff(symbol) for c, m in zip(self.damping, self.mass, strict=True))
        return self.per_dof(d_inverse, values), self.per_dof(d_rate, values)

    def _numeric(self, expressions: tuple):
        # Each flow reads the mass, the damping and their derivatives: lambdified once, since SymPy's
        # subs took half the time of a short orbit's flow.
        function = self._functions.get(expressions)
        if function is None:
            function = self._functions[expressions] = _sympy().lambdify(self.p, list(expressions), "math")
        return function


def _per(value, dof: str):
    if isinstance(value, Mapping):
        if dof not in value:
            raise SystemDefinitionError(f"no value for degree of freedom {dof!r} in {dict(value)!r}")
        return value[dof]
    return value


def _parse(expression, names: Mapping[str, object], field: str):
    sympy = _sympy()
    try:
        if isinstance(expression, str):
            # A bare name that is not declared is a symbol (so refused below, by name), not SymPy's constant or
            # function of that name: E would be Euler's number, I the imaginary unit, gamma or zeta a function.
            bare = {n: sympy.Symbol(n) for n in _bare_names(expression) if n not in names and n != "pi"}
            expr = sympy.sympify(expression, locals={**bare, **names})
        else:
            expr = sympy.sympify(expression)
    except (sympy.SympifyError, SyntaxError, TypeError) as error:
        raise SystemDefinitionError(f"{field}: cannot read {expression!r} as a formula ({error})") from None
    if expr.has(sympy.I, sympy.zoo, sympy.nan, sympy.oo, -sympy.oo):
        raise SystemDefinitionError(f"{field}: {expression!r} is not a real finite formula (it holds sqrt(-1) or a division by zero)")
    # Symbols of the same name but other assumptions (a user's plain sympy.Symbol("phi")) are the same variable.
    expr = expr.subs({s: names[s.name] for s in expr.free_symbols if s.name in names})
    unknown = sorted(s.name for s in expr.free_symbols if s.name not in names)
    if unknown:
        raise SystemDefinitionError(f"{field} uses unknown names {unknown}; it may use: {', '.join(names) or 'nothing'}")
    return expr


def _bare_names(text: str) -> set[str]:
    """The names in ``text`` not called as functions (empty where it does not tokenize: SymPy then says why)."""
    try:
        tokens = [t for t in tokenize.generate_tokens(io.StringIO(text).readline) if t.string.strip()]
    except (tokenize.TokenError, SyntaxError):
        return set()
    following = [t.string for t in tokens[1:]] + [""]
    return {
        t.string
        for t, nxt in zip(tokens, following, strict=True)
        if t.type == tokenize.NAME and nxt != "(" and not keyword.iskeyword(t.string)
    }


def _block(lines: list[str], targets: list[tuple[str, object]], indent: str, prefix: str) -> None:
    """Straight-line code assigning each target its expression, common subexpressions shared."""
    sympy = _sympy()
    if not targets:
        return
    replacements, reduced = sympy.cse([e for _, e in targets], symbols=sympy.numbered_symbols(prefix))
    for symbol, value in replacements:
        lines.append(f"{indent}{symbol} = {sympy.pycode(value)}")
    for (target, _), value in zip(targets, reduced, strict=True):
        lines.append(f"{indent}{target} = {sympy.pycode(value)}")


def _source(spec: _Spec) -> str:
    sympy = _sympy()
    nd, npar = len(spec.dofs), len(spec.parameters)
    # The generated code names every variable q_<dof> and p_<parameter>, so that no user's name
    # (a parameter called k, f or math) can shadow the kernels' own arguments and modules.
    rename = {s: sympy.Symbol(f"q_{s.name}", real=True) for s in spec.q + spec.ql + spec.qr}
    rename.update({s: sympy.Symbol(f"p_{s.name}", real=True) for s in spec.p})
    q, ql, qr, params = ([rename[s] for s in group] for group in (spec.q, spec.ql, spec.qr, spec.p))
    site_energy, bond_energy = spec.site_energy.xreplace(rename), spec.bond_energy.xreplace(rename)
    site_force = [f.xreplace(rename) for f in spec.site_force]
    site_f = [-sympy.diff(site_energy, s) + f for s, f in zip(q, site_force, strict=True)]
    bond_q = ql + qr
    bond_f = [-sympy.diff(bond_energy, s) for s in bond_q]
    read_p = [f"    {p} = coef[{i}]" for i, p in enumerate(params)]

    def function(name: str, args: str, variables, forces, local) -> list[str]:
        lines = ["", "@njit(cache=True, nogil=True, error_model='numpy')", f"def {name}({args}):", *read_p]
        lines += [f"    {v} = {src}" for v, src in variables]
        _block(lines, [(f"f[{i}]", e) for i, e in enumerate(forces)], "    ", "a")
        lines.append("    if mode >= 1:")
        _block(lines, [(f"k[{i}, {j}]", sympy.diff(e, s)) for i, e in enumerate(forces) for j, s in enumerate(local)], "        ", "b")
        lines.append("        pass")
        lines.append("    if mode >= 2:")
        _block(lines, [(f"dp[{i}, {j}]", sympy.diff(e, s)) for i, e in enumerate(forces) for j, s in enumerate(params)], "        ", "c")
        lines.append("        pass")
        return lines

    def energy(name: str, args: str, variables, expr) -> list[str]:
        lines = ["", "@njit(cache=True, nogil=True, error_model='numpy')", f"def {name}({args}):", *read_p]
        lines += [f"    {v} = {src}" for v, src in variables]
        _block(lines, [("e", expr)], "    ", "a")
        lines.append("    return e")
        return lines

    site_vars = [(s.name, f"x[{i}]") for i, s in enumerate(q)]
    bond_vars = [(s.name, f"xl[{i}]") for i, s in enumerate(ql)] + [(s.name, f"xr[{i}]") for i, s in enumerate(qr)]
    lines = [f"# Generated by cosserat_chain.systems.lattice for dofs {spec.dofs}, parameters {spec.parameters}.", _HEADER]
    lines.append(f"ND = {nd}\nNP = {max(npar, 1)}")
    lines += function("site_terms", "x, coef, f, k, dp, mode", site_vars, site_f, q)
    lines += function("bond_terms", "xl, xr, coef, f, k, dp, mode", bond_vars, bond_f, bond_q)
    lines += energy("site_energy", "x, coef", site_vars, site_energy)
    lines += energy("bond_energy", "xl, xr, coef", bond_vars, bond_energy)
    lines.append(_TEMPLATE)
    return "\n".join(lines) + "\n"


_HEADER = """import math

import numpy as np
from numba import njit, types

from cosserat_chain.models.base import END_KERNEL_TYPE, FORCE_KERNEL_TYPE

RHS_SIGNATURE = types.void(
    FORCE_KERNEL_TYPE, END_KERNEL_TYPE, types.float64, types.float64[::1], types.float64[::1],
    types.float64[::1], types.int64[::1], types.float64[::1],
)
"""

# The loops every lattice shares; boundary 0 free, 1 periodic, 2 fixed (phantom sites at q = 0).
_TEMPLATE = """

@njit(cache=True, nogil=True)
def bonds(nsites, boundary):
    if boundary == 0:
        return nsites - 1
    if boundary == 1:
        return nsites
    return nsites + 1


@njit(cache=True, nogil=True)
def bond_ends(b, nsites, boundary):
    if boundary == 0:
        return b, b + 1
    if boundary == 1:
        return b, (b + 1) % nsites
    return b - 1, (b if b < nsites else -1)


@njit(cache=True, nogil=True)
def gather(q, site, x):
    for d in range(ND):
        x[d] = q[site * ND + d] if site >= 0 else 0.0


@njit(cache=True, nogil=True)
def bond_scratch():
    # A bond's two sites, forces, Jacobian block, parameter derivatives and coordinates.
    return (
        np.empty(ND),
        np.empty(ND),
        np.empty(2 * ND),
        np.zeros((2 * ND, 2 * ND)),
        np.zeros((2 * ND, NP)),
        np.empty(2 * ND, dtype=np.int64),
    )


@njit(cache=True, nogil=True, error_model="numpy")
def bond_at(q, b, nsites, boundary, coef, xl, xr, fb, kb, dpb, index, mode):
    # Bond b's terms, and index[a] the coordinate of its local entry a (-1 on a phantom site).
    left, right = bond_ends(b, nsites, boundary)
    gather(q, left, xl)
    gather(q, right, xr)
    bond_terms(xl, xr, coef, fb, kb, dpb, mode)
    for d in range(ND):
        index[d] = left * ND + d if left >= 0 else -1
        index[ND + d] = right * ND + d if right >= 0 else -1


@njit(cache=True, nogil=True, error_model="numpy")
def accumulate(q, coef, nsites, boundary, out, jq, ncols, cols_q, cols_off, dpar, mode):
    # Forces into out; with mode >= 1 also J @ columns (jq (n, ncols) += dF/dq cols_q), with
    # mode >= 2 dF/dp into dpar (n, NP). cols_q holds the q-rows of the variational columns at
    # row stride ncols from offset cols_off.
    x = np.empty(ND)
    f = np.empty(ND)
    k = np.zeros((ND, ND))
    dp = np.zeros((ND, NP))
    for i in range(nsites):
        gather(q, i, x)
        site_terms(x, coef, f, k, dp, mode)
        for d in range(ND):
            out[i * ND + d] += f[d]
        if mode >= 1:
            for d in range(ND):
                for e in range(ND):
                    kde = k[d, e]
                    src = cols_off + (i * ND + e) * ncols
                    for c in range(ncols):
                        jq[i * ND + d, c] += kde * cols_q[src + c]
        if mode >= 2:
            for d in range(ND):
                for j in range(NP):
                    dpar[i * ND + d, j] += dp[d, j]
    xl, xr, fb, kb, dpb, index = bond_scratch()
    for b in range(bonds(nsites, boundary)):
        bond_at(q, b, nsites, boundary, coef, xl, xr, fb, kb, dpb, index, mode)
        for a in range(2 * ND):
            r = index[a]
            if r < 0:
                continue
            out[r] += fb[a]
            if mode >= 1:
                for e in range(2 * ND):
                    s = index[e]
                    if s < 0:
                        continue
                    kae = kb[a, e]
                    src = cols_off + s * ncols
                    for c in range(ncols):
                        jq[r, c] += kae * cols_q[src + c]
            if mode >= 2:
                for j in range(NP):
                    dpar[r, j] += dpb[a, j]


@njit(cache=True, nogil=True, error_model="numpy")
def forces(q, coef, nsites, boundary, out):
    jq = np.zeros((1, 1))
    dpar = np.zeros((1, 1))
    accumulate(q, coef, nsites, boundary, out, jq, 0, q, 0, dpar, 0)


@njit(cache=True, nogil=True, error_model="numpy")
def parameter_forces(q, coef, nsites, boundary, dpar):
    out = np.zeros(q.size)
    jq = np.zeros((1, 1))
    accumulate(q, coef, nsites, boundary, out, jq, 0, q, 0, dpar, 2)


@njit(cache=True, nogil=True, error_model="numpy")
def jacobian(q, coef, nsites, boundary, rows, cols, vals):
    x = np.empty(ND)
    f = np.empty(ND)
    k = np.zeros((ND, ND))
    dp = np.zeros((ND, NP))
    count = 0
    for i in range(nsites):
        gather(q, i, x)
        site_terms(x, coef, f, k, dp, 1)
        for d in range(ND):
            for e in range(ND):
                rows[count] = i * ND + d
                cols[count] = i * ND + e
                vals[count] = k[d, e]
                count += 1
    xl, xr, fb, kb, dpb, index = bond_scratch()
    for b in range(bonds(nsites, boundary)):
        bond_at(q, b, nsites, boundary, coef, xl, xr, fb, kb, dpb, index, 1)
        for a in range(2 * ND):
            for e in range(2 * ND):
                if index[a] >= 0 and index[e] >= 0:
                    rows[count] = index[a]
                    cols[count] = index[e]
                    vals[count] = kb[a, e]
                    count += 1
    return count


@njit(cache=True, nogil=True, error_model="numpy")
def energy(q, coef, nsites, boundary):
    x = np.empty(ND)
    total = 0.0
    for i in range(nsites):
        gather(q, i, x)
        total += site_energy(x, coef)
    xl = np.empty(ND)
    xr = np.empty(ND)
    for b in range(bonds(nsites, boundary)):
        left, right = bond_ends(b, nsites, boundary)
        gather(q, left, xl)
        gather(q, right, xr)
        total += bond_energy(xl, xr, coef)
    return total


@njit(cache=True, nogil=True, error_model="numpy")
def rhs(force, end_force, t, y, coef, rpar, ipar, dy):
    # y = (q, v, columns (2n, ncols) row-major); rpar = (1/M, C/M, d(1/M)/dp, d(C/M)/dp);
    # ipar = (nsites, boundary, ncols, k): the last column is dy/dp_k when k >= 0.
    nsites = ipar[0]
    boundary = ipar[1]
    ncols = ipar[2]
    k = ipar[3]
    n = nsites * ND
    q = y[:n]
    f = np.zeros(n)
    jq = np.zeros((n, max(ncols, 1)))
    dpar = np.zeros((n, NP))
    mode = 0 if ncols == 0 else (2 if k >= 0 else 1)
    accumulate(q, coef, nsites, boundary, f, jq, ncols, y, 2 * n, dpar, mode)
    for i in range(n):
        dy[i] = y[n + i]
        dy[n + i] = rpar[i] * f[i] - rpar[n + i] * y[n + i]
    if ncols == 0:
        return
    base = 2 * n
    for r in range(n):
        for c in range(ncols):
            dy[base + r * ncols + c] = y[base + (n + r) * ncols + c]
            dy[base + (n + r) * ncols + c] = rpar[r] * jq[r, c] - rpar[n + r] * y[base + (n + r) * ncols + c]
    if k >= 0:
        c = ncols - 1
        for r in range(n):
            dy[base + (n + r) * ncols + c] += rpar[r] * dpar[r, k] + rpar[2 * n + r] * f[r] - rpar[3 * n + r] * y[n + r]
"""


_LOADED: dict[str, object] = {}


def _private(directory: Path) -> bool:
    """Whether ``directory`` is a real folder of this user that nobody else may write: the code in it is imported."""
    info = directory.lstat()
    return stat.S_ISDIR(info.st_mode) and info.st_uid == os.getuid() and not info.st_mode & (stat.S_IWGRP | stat.S_IWOTH)


def _compile(spec: _Spec):
    """The compiled kernels of ``spec``: its generated module, written once under the cache directory."""
    source = _source(spec)
    digest = hashlib.sha256(source.encode()).hexdigest()[:20]
    if digest in _LOADED:
        return _LOADED[digest]
    name = f"cosserat_chain_lattice_{digest}"
    path = None
    for directory in (_cache_dir(), Path(tempfile.gettempdir()) / f"cosserat-chain-{os.getuid()}" / "systems"):
        try:
            directory.mkdir(parents=True, exist_ok=True, mode=0o700)
            if not _private(directory):
                continue
            target = directory / f"{name}.py"
            if not target.is_file() or target.is_symlink() or target.read_text() != source:
                handle, temporary = tempfile.mkstemp(dir=directory, suffix=".tmp")
                with os.fdopen(handle, "w") as stream:
                    stream.write(source)
                os.replace(temporary, target)
            path = target
            break
        except OSError:
            continue
    if path is None:
        raise SystemDefinitionError(
            "no private writable cache directory for the compiled system (the generated code is imported from it, so it must "
            "belong to you and be writable by nobody else); set COSSERAT_CHAIN_CACHE to one"
        )
    module_spec = importlib.util.spec_from_file_location(name, path)
    module = importlib.util.module_from_spec(module_spec)
    sys.modules[name] = module
    module_spec.loader.exec_module(module)
    _LOADED[digest] = module
    return module
