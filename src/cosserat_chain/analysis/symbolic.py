"""SymPy derivation of the linear chain from the geometry of model (i), and the paper's errata as data.

Contract
--------
:func:`derivation` linearises the potential (1) of the four links of one bond
(geometry of :mod:`cosserat_chain.geometry`) for general a, b, h, E1, E2 and
returns the linear energy per bond, its Hessian, the equations of motion of a
particle of the infinite chain and their coefficients (those of eqs. (2)-(3),
with D1 and D2 of Section 3). :func:`compare_with_paper` sets every printed
coefficient, definition and closed form of Sections 2-3 against the derivation,
and :func:`errata` turns the disagreements into a list of :class:`Erratum`, with
consequences evaluated for a given chain. ``docs/errata.md`` is this list.

Importing the module is cheap: SymPy is imported and the derivation done on the
first call, and cached.

Notation: g = h - 2a is the rest length of a horizontal link and d the rest length
of a diagonal, d^2 = g^2 + 4 b^2. A particle k of the infinite chain has the
neighbours k-1 (suffix ``m``) and k+1 (suffix ``p``).
"""

from __future__ import annotations

import functools
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..memory import FLOAT, require
from ..params import ChainParams
from ..state import n_free, per_dof, require_clamped
from .continuum import central_rotation, discrete_static, printed_D1

#: Names of the coefficients of eqs. (2)-(3) in the order of
#: ``models.linear.cosserat_coefficients``: F_u = k_u D2u, F_v = k_v (D2v - arm/2 (phi_p - phi_m)),
#: F_phi = bend D2phi + couple ((v_p - v_m)/(2h) - phi), with bend = 2 b^2 D1, couple = 2 b^2 D2.
COEFFICIENTS = ("k_u", "k_v", "arm", "bend", "couple")


@dataclass(frozen=True)
class Derivation:
    """The linear chain derived from model (i); every field a SymPy object.

    Attributes
    ----------
    symbols : dict
        ``E1, E2, h, a, b, d, g, m, j`` and the degrees of freedom of particles
        k-1, k, k+1 (``u_m, v_m, phi_m, u, v, phi, u_p, v_p, phi_p``).
    elongations : tuple of 4 expressions
        Linearised elongation dL of the links top, bottom, diagonal 1, diagonal 2
        of the bond (k, k+1), in (u, v, phi, u_p, v_p, phi_p).
    bond_energy : Expr
        Linear energy per bond, sum of E/2 dL^2 over the four links.
    bond_hessian : Matrix, shape (6, 6)
        Its Hessian over (u, v, phi, u_p, v_p, phi_p).
    forces : tuple of 3 expressions
        (F_u, F_v, F_phi) on particle k: minus the gradient of the energy of the two
        bonds that particle k takes part in.
    coefficients : dict
        The entries of :data:`COEFFICIENTS`, plus ``D1`` and ``D2``, simplified.
    """

    symbols: dict[str, Any]
    elongations: tuple[Any, ...]
    bond_energy: Any
    bond_hessian: Any
    forces: tuple[Any, Any, Any]
    coefficients: dict[str, Any]


@dataclass(frozen=True)
class Check:
    """One printed form of the paper set against the derivation.

    Attributes
    ----------
    key : str
        Identifier, e.g. ``"eq3.couple"``.
    where : str
        Place in the paper.
    quantity : str
        What is compared.
    printed, derived : Expr or str
        The two forms.
    agrees : bool
        Whether they are equal for every geometry (decided by SymPy).
    """

    key: str
    where: str
    quantity: str
    printed: Any
    derived: Any
    agrees: bool


@dataclass(frozen=True)
class Erratum:
    """A place where the printed paper disagrees with its own geometry.

    Attributes
    ----------
    number : int
        Number in ``docs/errata.md``.
    where, printed, derived, consequence : str
    found_by : str
        ``"sympy"`` for errata that :func:`compare_with_paper` detects, ``"computed"``
        for a consequence found numerically (the printed D1's discrete chain), ``"reading"``
        for slips in the text that no derivation can detect.
    checks : tuple of str
        Keys of the failing :class:`Check` entries behind the erratum.
    """

    number: int
    where: str
    printed: str
    derived: str
    consequence: str
    found_by: str
    checks: tuple[str, ...] = ()

    def as_dict(self) -> dict[str, Any]:
        return {
            "number": self.number,
            "where": self.where,
            "printed": self.printed,
            "derived": self.derived,
            "consequence": self.consequence,
            "found_by": self.found_by,
            "checks": list(self.checks),
        }


# --------------------------------------------------------------------------- derivation
@functools.cache
def _symbols() -> dict[str, Any]:
    import sympy as sp

    names = dict(zip(("E1", "E2", "h", "b", "d", "g", "m", "j"), sp.symbols("E1 E2 h b d g m j", positive=True)))
    names["a"] = sp.Symbol("a", positive=True)
    for suffix in ("_m", "", "_p"):
        for row in ("u", "v", "phi"):
            names[row + suffix] = sp.Symbol(row + suffix, real=True)
    return names


def _rest_length_subs() -> dict[Any, Any]:
    """g = h - 2a, for display in the paper's symbols."""
    s = _symbols()
    return {s["g"]: s["h"] - 2 * s["a"]}


def _eliminate_d(expr: Any) -> Any:
    """Replace d by sqrt(g^2 + 4 b^2) and cancel: a canonical form for deciding equality."""
    import sympy as sp

    s = _symbols()
    return sp.cancel(sp.sympify(expr).subs(s["d"], sp.sqrt(s["g"] ** 2 + 4 * s["b"] ** 2)))


def _equal(first: Any, second: Any) -> bool:
    import sympy as sp

    return _eliminate_d(sp.sympify(first) - sp.sympify(second)) == 0


def _tidy(expr: Any) -> Any:
    """Shortest form of a coefficient linear in E1, E2, using d^2 = g^2 + 4 b^2 where it helps."""
    import sympy as sp

    s = _symbols()
    expr = sp.expand(expr)
    out = sp.Integer(0)
    for stiffness in (s["E1"], s["E2"]):
        part = sp.expand(expr.coeff(stiffness))
        candidates = [sp.factor(part), sp.factor(sp.expand(part).subs(s["g"] ** 2, s["d"] ** 2 - 4 * s["b"] ** 2))]
        out += stiffness * min(candidates, key=sp.count_ops)
    return out


def _corner(q: tuple[Any, Any, Any], centre_x: Any, corner: tuple[Any, Any]) -> Any:
    import sympy as sp

    u, v, phi = q
    cx, cy = corner
    return sp.Matrix([centre_x + u + cx * sp.cos(phi) - cy * sp.sin(phi), v + cx * sp.sin(phi) + cy * sp.cos(phi)])


def _link_table() -> tuple[tuple[tuple[Any, Any], tuple[Any, Any], Any], ...]:
    """Corner on particle k, corner on particle k+1, stiffness: the table of :mod:`cosserat_chain.geometry`."""
    s = _symbols()
    a, b = (s["h"] - s["g"]) / 2, s["b"]
    return (
        ((a, b), (-a, b), s["E1"]),
        ((a, -b), (-a, -b), s["E1"]),
        ((a, b), (-a, -b), s["E2"]),
        ((a, -b), (-a, b), s["E2"]),
    )


def _extract(forces: tuple[Any, Any, Any]) -> tuple[dict[str, Any], Any]:
    """Coefficients of a particle's equations in the form of eqs. (2)-(3), and what the form misses.

    Returns the :data:`COEFFICIENTS` read off the neighbour terms and the
    difference between ``forces`` and the eq. (3) form rebuilt from them (zero
    when the equations have that form).
    """
    import sympy as sp

    s = _symbols()
    f_u, f_v, f_phi = (sp.expand(f) for f in forces)
    h = s["h"]
    k_u = f_u.coeff(s["u_p"])
    k_v = f_v.coeff(s["v_p"])
    arm = sp.cancel(-2 * f_v.coeff(s["phi_p"]) / k_v)
    bend = f_phi.coeff(s["phi_p"])
    couple = 2 * h * f_phi.coeff(s["v_p"])
    rebuilt = _eq3_form(k_u, k_v, arm, bend, couple, angle=lambda x: x)
    remainder = tuple(sp.expand(f - r) for f, r in zip((f_u, f_v, f_phi), rebuilt))
    return {"k_u": k_u, "k_v": k_v, "arm": arm, "bend": bend, "couple": couple}, remainder


def _eq3_form(k_u: Any, k_v: Any, arm: Any, bend: Any, couple: Any, angle: Callable[[Any], Any]) -> tuple[Any, Any, Any]:
    """(F_u, F_v, F_phi) of eqs. (2)-(3) with the given coefficients; ``angle`` is phi -> phi or sin phi."""
    s = _symbols()
    h = s["h"]
    pm, p0, pp = (angle(s[n]) for n in ("phi_m", "phi", "phi_p"))
    f_u = k_u * (s["u_p"] - 2 * s["u"] + s["u_m"])
    f_v = k_v * (s["v_p"] - 2 * s["v"] + s["v_m"] - arm / 2 * (pp - pm))
    f_phi = bend * (pp - 2 * p0 + pm) + couple * ((s["v_p"] - s["v_m"]) / (2 * h) - p0)
    return f_u, f_v, f_phi


@functools.cache
def derivation() -> Derivation:
    """Linearise model (i) on the geometry of Fig. 1 (cached; a second or two on first call).

    Each link of stiffness E and rest length L0 stores E (L - L0)^2 / 2 (eq. 1). At
    rest L = L0, so the second-order expansion is E/2 (grad L . dq)^2: only the
    first derivatives of the link lengths at rest are needed, dL/dq = D0 . dD/dq / L0
    for the link vector D between the two corners (D0, L0 at rest).
    """
    import sympy as sp

    s = _symbols()
    left = (s["u"], s["v"], s["phi"])
    right = (s["u_p"], s["v_p"], s["phi_p"])
    dofs = left + right
    rest = dict.fromkeys(dofs, 0)
    elongations = []
    energy = sp.Integer(0)
    for corner_left, corner_right, stiffness in _link_table():
        link = _corner(right, s["h"], corner_right) - _corner(left, 0, corner_left)
        at_rest = link.subs(rest)
        squared = sp.expand(at_rest.dot(at_rest))
        # Rest lengths: g for the horizontal links, d = sqrt(g^2 + 4 b^2) for the diagonals.
        rest_length = {s["g"] ** 2: s["g"], s["g"] ** 2 + 4 * s["b"] ** 2: s["d"]}[squared]
        gradient = [sp.expand(at_rest.dot(sp.diff(link, q).subs(rest))) / rest_length for q in dofs]
        elongation = sum(c * q for c, q in zip(gradient, dofs))
        elongations.append(elongation)
        energy += stiffness / 2 * elongation**2
    hessian = sp.hessian(energy, dofs).applyfunc(_tidy)
    # Particle k is the right end of bond (k-1, k) and the left end of bond (k, k+1).
    previous = {q: q_prev for q, q_prev in zip(dofs, (s["u_m"], s["v_m"], s["phi_m"]) + left)}
    both = energy + energy.subs(previous, simultaneous=True)
    forces = tuple(sp.expand(-sp.diff(both, q)) for q in left)
    coefficients, remainder = _extract(forces)
    if any(r != 0 for r in remainder):
        raise ArithmeticError(f"the derived equations are not of the form of eq. (3): remainder {remainder}")
    coefficients = {name: _tidy(value) if name != "arm" else value for name, value in coefficients.items()}
    coefficients["D1"] = _tidy(coefficients["bend"] / (2 * s["b"] ** 2))
    coefficients["D2"] = _tidy(coefficients["couple"] / (2 * s["b"] ** 2))
    return Derivation(
        symbols=s,
        elongations=tuple(elongations),
        bond_energy=sp.expand(energy),
        bond_hessian=hessian,
        forces=forces,
        coefficients=coefficients,
    )


def _numeric(expr: Any, params: ChainParams) -> float:
    s = _symbols()
    values = {
        s["E1"]: params.E1,
        s["E2"]: params.E2,
        s["h"]: params.h,
        s["b"]: params.b,
        s["d"]: params.d,
        s["g"]: params.gap,
    }
    return float(expr.subs(values))


@functools.cache
def _lambdified(name: str) -> Callable[..., Any]:
    import sympy as sp

    s = _symbols()
    args = [s[n] for n in ("E1", "E2", "h", "b", "d", "g")]
    expr = derivation().bond_hessian if name == "bond_hessian" else derivation().coefficients[name]
    return sp.lambdify(args, expr, modules="numpy")


def derived_coefficients(params: ChainParams) -> dict[str, float]:
    """The derived coefficients (:data:`COEFFICIENTS`, D1, D2) evaluated for a chain."""
    args = (params.E1, params.E2, params.h, params.b, params.d, params.gap)
    return {name: float(_lambdified(name)(*args)) for name in (*COEFFICIENTS, "D1", "D2")}


def derived_bond_hessian(params: ChainParams) -> np.ndarray:
    """The derived Hessian (6, 6) of the linear bond energy over (u_k, v_k, phi_k, u_k+1, v_k+1, phi_k+1)."""
    return np.array(_lambdified("bond_hessian")(params.E1, params.E2, params.h, params.b, params.d, params.gap), dtype=float)


# --------------------------------------------------------------------------- the printed paper
def _printed_equations(which: str) -> tuple[Any, Any, Any]:
    """(F_u, F_v, F_phi) of eq. (2) or eq. (3) as printed, loads and viscosity left out."""
    import sympy as sp

    s = _symbols()
    E1, E2, h, b, d, g = (s[n] for n in ("E1", "E2", "h", "b", "d", "g"))
    coupling = 4 * h**2 / d**2 * E2 if which == "2" else h**2 / d**2 * E2
    return _eq3_form(
        k_u=2 * h**2 * (E1 + g**2 / d**2 * E2) / h**2,
        k_v=8 * b**2 / d**2 * h**2 * E2 / h**2,
        arm=h,
        bend=2 * b**2 * h**2 * (E1 - h**2 / d**2 * E2) / h**2,
        couple=2 * b**2 * coupling,
        angle=sp.sin if which == "2" else (lambda x: x),
    )


def _linearised(forces: tuple[Any, Any, Any]) -> tuple[Any, ...]:
    """Eq. (2) is linear in sin(phi); its linearisation at phi = 0 replaces sin(phi) by phi."""
    import sympy as sp

    s = _symbols()
    subs = {sp.sin(s[n]): s[n] for n in ("phi_m", "phi", "phi_p")}
    return tuple(f.subs(subs) for f in forces)


def _section3_checks() -> list[Check]:
    """Eqs. (7), (11), phi(0), (12) and the reduced solution, with D1, D2 as free symbols."""
    import sympy as sp

    h, L, b, M, x, D1, D2 = sp.symbols("h L b M x D1 D2", positive=True)
    C = sp.symbols("C1:5")
    v = C[0] * x**3 / 6 + C[1] * x**2 / 2 + C[2] * x + C[3]
    phi = C[0] * h**2 * D1 / D2 + C[0] * x**2 / 2 + C[1] * x + C[2]
    checks = []
    # (7) solves (6).
    field = (sp.cancel(sp.diff(v, x, 2) - sp.diff(phi, x)), sp.cancel(h**2 * D1 * sp.diff(phi, x, 2) + D2 * (sp.diff(v, x) - phi)))
    checks.append(Check("eq7", "Section 3.1, eq. (7)", "residual of eq. (6) for the general solution (7)", 0, field, field == (0, 0)))

    def at(f: Any, point: Any) -> Any:
        return f.subs(x, point)

    conditions = [
        at(v, 0),
        at(v, L),
        at(phi, L),
        2 * b**2 * (2 * h**2 * D1 * (at(phi, h) - at(phi, 0)) / h**2 + D2 * (at(v, h) / h - at(phi, 0))) + M,
    ]
    constants = sp.solve(conditions, C, dict=True)[0]
    v_solved, phi_solved = sp.factor(v.subs(constants)), sp.factor(phi.subs(constants))
    den = h * (24 * h**2 * D1**2 + (8 * L**2 + 6 * h**2) * D1 * D2 + L * (2 * L - h) * D2**2)
    v_printed = M * x * (L - x) * (6 * h**2 * D1 + L * (L - x) * D2) / (2 * b**2 * den)
    phi_printed = M * (L - x) * (12 * h**2 * D1 + L * (L - 3 * x) * D2) / (2 * b**2 * den)
    phi0_printed = M * L * (12 * h**2 * D1 + L**2 * D2) / (2 * b**2 * den)
    checks.append(
        Check(
            "eq11.v",
            "Section 3.1, eq. (11)",
            "v(x) solving (7) with (8) and (10)",
            v_printed,
            v_solved,
            sp.cancel(v_printed - v_solved) == 0,
        )
    )
    checks.append(
        Check(
            "eq11.phi",
            "Section 3.1, eq. (11)",
            "phi(x) solving (7) with (8) and (10)",
            phi_printed,
            phi_solved,
            sp.cancel(phi_printed - phi_solved) == 0,
        )
    )
    phi0 = sp.factor(phi_solved.subs(x, 0))
    checks.append(
        Check("phi0", "Section 3.1, phi(0)", "rotation of the loaded particle", phi0_printed, phi0, sp.cancel(phi0_printed - phi0) == 0)
    )
    # Residue of the discrete eq. (5) at an interior site x = k h of the sampled solution.

    def shifted(f: Any, dx: Any) -> Any:
        return f.subs(x, x + dx)

    residue = sp.cancel(
        h**2 * D1 * (shifted(phi_printed, h) - 2 * phi_printed + shifted(phi_printed, -h)) / h**2
        + D2 * ((shifted(v_printed, h) - shifted(v_printed, -h)) / (2 * h) - phi_printed)
    )
    eps = h / L
    residue_printed = M * D2**2 * eps / (2 * b**2 * (24 * eps**2 * D1**2 + (8 + 6 * eps**2) * D1 * D2 + (2 - eps) * D2**2))
    checks.append(
        Check(
            "eq12",
            "Section 3.1, eq. (12)",
            "residue of eq. (5), eps = h/L",
            residue_printed,
            residue,
            sp.cancel(residue - residue_printed) == 0,
        )
    )
    four = sp.cancel(shifted(v_printed, h) - 2 * v_printed + shifted(v_printed, -h)) / h**2 - sp.cancel(
        shifted(phi_printed, h) - shifted(phi_printed, -h)
    ) / (2 * h)
    checks.append(Check("eq4", "Section 3.1, after eq. (12)", "residue of eq. (4)", 0, sp.cancel(four), sp.cancel(four) == 0))
    reduced_v = M * x * (L - x) ** 2 / (2 * b**2 * h * (2 * L - h) * D2)
    reduced_phi = M * (L - x) * (L - 3 * x) / (2 * b**2 * h * (2 * L - h) * D2)
    agrees = sp.cancel(v_printed.subs(D1, 0) - reduced_v) == 0 and sp.cancel(phi_printed.subs(D1, 0) - reduced_phi) == 0
    checks.append(
        Check(
            "reduced",
            "Section 3.2",
            "reduced solution against (11) at D1 = 0",
            (reduced_v, reduced_phi),
            (v_printed.subs(D1, 0), phi_printed.subs(D1, 0)),
            agrees,
        )
    )
    return checks


@functools.cache
def compare_with_paper() -> tuple[Check, ...]:
    """Every printed form of Sections 2-3 against the derivation (cached).

    Returns
    -------
    tuple of Check
        Those of :func:`errata_checks`, then the algebra of Section 3 (eqs. (7),
        (11), phi(0), (12), the reduced solution), which no erratum reads.
    """
    return (*errata_checks(), *_section3_checks())


@functools.cache
def errata_checks() -> tuple[Check, ...]:
    """The printed forms of Sections 2-3 that :func:`errata` reads, against the derivation (cached).

    Returns
    -------
    tuple of Check
        Coefficients of eqs. (2) and (3), the definitions of D1 and D2 and the
        reduced-model condition of Section 3, the linearised link energy of
        Section 2, the kinetic energy and whether eq. (2) derives from a potential:
        the first checks of :func:`compare_with_paper`, the same objects.
    """
    import sympy as sp

    derived = derivation()
    s = derived.symbols
    E1, E2, h, d = (s[n] for n in ("E1", "E2", "h", "d"))
    coefficients = derived.coefficients
    labels = {
        "k_u": "longitudinal stiffness (u equation)",
        "k_v": "transverse stiffness (v equation)",
        "arm": "lever arm h of phi in the v equation",
        "bend": "bending coefficient 2 b^2 D1 (phi equation)",
        "couple": "coupling 2 b^2 D2, coefficient of ((v_k+1 - v_k-1)/(2h) - phi_k) in the phi equation",
    }
    checks = []
    for which, forces in (("2", _linearised(_printed_equations("2"))), ("3", _printed_equations("3"))):
        printed, _ = _extract(forces)
        for name in COEFFICIENTS:
            value = sp.cancel(printed[name])
            checks.append(
                Check(f"eq{which}.{name}", f"eq. ({which})", labels[name], value, coefficients[name], _equal(value, coefficients[name]))
            )
    printed_D1_expr = E1 - 2 * h**2 / d**2 * E2
    printed_D2_expr = 4 * h**2 / d**2 * E2
    checks.append(
        Check(
            "section3.D1",
            "Section 3.1, after eq. (5)",
            "D1",
            printed_D1_expr,
            coefficients["D1"],
            _equal(printed_D1_expr, coefficients["D1"]),
        )
    )
    checks.append(
        Check(
            "section3.D2",
            "Section 3.1, after eq. (5)",
            "D2",
            printed_D2_expr,
            coefficients["D2"],
            _equal(printed_D2_expr, coefficients["D2"]),
        )
    )
    reduced_printed = 2 * h**2 / d**2 * E2
    # D1 is linear in E1: the reduced model's E1 is its one root.
    _, reduced_derived = sp.solve_linear(coefficients["D1"], symbols=[E1])
    checks.append(
        Check(
            "section3.reduced_E1",
            "Section 3.2",
            "E1 of the reduced model (D1 = 0)",
            reduced_printed,
            reduced_derived,
            _equal(reduced_printed, reduced_derived),
        )
    )
    checks.append(_link_energy_check(derived))
    checks.append(_kinetic_energy_check())
    checks.append(_potential_check(derived))
    return tuple(checks)


def _link_energy_check(derived: Derivation) -> Check:
    """Section 2's linearised link energy E/2 [du cos(gamma) + dv sin(gamma) + r0 (...) phi0 - r1 (...) phi1]^2."""
    import sympy as sp

    s = derived.symbols
    h = s["h"]
    printed = []
    for corner_left, corner_right, _ in _link_table():
        dx = h + corner_right[0] - corner_left[0]
        dy = corner_right[1] - corner_left[1]
        length = sp.sqrt(dx**2 + dy**2)
        cos_g, sin_g = dx / length, dy / length
        # r cos(alpha), r sin(alpha) are the corner's body-frame coordinates.
        arm_left = cos_g * corner_left[1] - sin_g * corner_left[0]
        arm_right = cos_g * corner_right[1] - sin_g * corner_right[0]
        printed.append((s["u_p"] - s["u"]) * cos_g + (s["v_p"] - s["v"]) * sin_g + arm_left * s["phi"] - arm_right * s["phi_p"])
    agrees = all(_equal(p, e) for p, e in zip(printed, derived.elongations))
    return Check(
        "section2.link_energy",
        "Section 2, linearised link energy",
        "elongation dL of each of the four links",
        tuple(printed),
        derived.elongations,
        agrees,
    )


def _kinetic_energy_check() -> Check:
    """Inertia terms d/dt dK/dq' of Lagrange's equations for the printed and the squared kinetic energy."""
    import sympy as sp

    t = sp.Symbol("t")
    s = _symbols()
    q = [sp.Function(n)(t) for n in ("u", "v", "phi")]
    rates = [sp.diff(x, t) for x in q]
    printed = s["m"] / 2 * (rates[0] + rates[1]) + s["j"] / 2 * rates[2]
    squared = s["m"] / 2 * (rates[0] ** 2 + rates[1] ** 2) + s["j"] / 2 * rates[2] ** 2

    def inertia(energy: Any) -> tuple[Any, ...]:
        return tuple(sp.diff(sp.diff(energy, r), t) for r in rates)

    needed = (s["m"] * sp.diff(q[0], t, 2), s["m"] * sp.diff(q[1], t, 2), s["j"] * sp.diff(q[2], t, 2))
    derived_ok = inertia(squared) == needed
    return Check(
        "section2.kinetic",
        "Section 2, kinetic energy",
        "inertia terms of Lagrange's equations (eqs. (2)-(3) need m u'', m v'', j phi'')",
        {"K": printed, "inertia": inertia(printed)},
        {"K": squared, "inertia": inertia(squared)},
        derived_ok and inertia(printed) == needed,
    )


def _potential_check(derived: Derivation) -> Check:
    """Eq. (2) derives from a potential only if dF_v,k/dphi_k+1 = dF_phi,k+1/dv_k."""
    import sympy as sp

    s = derived.symbols
    f_v = _printed_equations("2")[1]
    # F_phi of particle k+1 depends on v_k through its left neighbour: shift the printed phi equation by one site.
    f_phi_next = _printed_equations("2")[2].subs({s["v_m"]: s["v"]}, simultaneous=True)
    curl = sp.cancel(sp.diff(f_v, s["phi_p"]) - sp.diff(f_phi_next, s["v"]))
    curl = sp.factor(curl.subs(_k_v_subs()))
    return Check(
        "eq2.potential",
        "eq. (2), presented as a linearisation of model (i)",
        "dF_v,k/dphi_k+1 - dF_phi,k+1/dv_k (zero for forces with a potential)",
        0,
        curl,
        curl == 0,
    )


def _k_v_subs() -> dict[Any, Any]:
    """8 b^2 / d^2 E2 = k_v: lets the curl of eq. (2) read k_v h (1 - cos phi) / 2."""
    import sympy as sp

    s = _symbols()
    return {s["E2"]: sp.Symbol("k_v") * s["d"] ** 2 / (8 * s["b"] ** 2)}


# --------------------------------------------------------------------------- errata with consequences
def printed_eq3_stiffness(params: ChainParams):
    """Sparse matrix -dF/dq of eq. (3) as printed (coupling without the factor 4) over the free DOFs.

    Ordering as in :mod:`cosserat_chain.state`; block tridiagonal (CSR). Not
    symmetric: it is the operator the printed equations would integrate.
    """
    import scipy.sparse as sparse
    import sympy as sp

    # The paper's chain: its errata are about the clamped chain's operator.
    require_clamped(params, "the printed operator of eq. (3)")
    s = _symbols()
    forces = _printed_equations("3")
    neighbours = [[s[r + sfx] for r in ("u", "v", "phi")] for sfx in ("_m", "", "_p")]
    blocks = [np.array([[-_numeric(sp.diff(f, q), params) for q in qs] for f in forces]) for qs in neighbours]
    n = params.n_particles - 2
    # Block row i holds blocks[0] at block column i-1, blocks[1] at i and blocks[2] at i+1.
    return sum(sparse.kron(sparse.eye(n, k=offset), block) for offset, block in zip((-1, 0, 1), blocks)).tocsr()


def _fmt(expr: Any) -> str:
    import sympy as sp

    return sp.sstr(sp.sympify(expr).subs(_rest_length_subs()))


def errata(params: ChainParams | None = None) -> tuple[Erratum, ...]:
    """The errata of ``docs/errata.md``, with consequences evaluated for ``params``.

    Parameters
    ----------
    params : ChainParams, optional
        Chain for the numbers in the consequences; default the paper's (Section 4).

    Returns
    -------
    tuple of Erratum
        Numbers 1-4 are found by :func:`errata_checks` (each lists its failing
        checks; Section 3's algebra, the rest of :func:`compare_with_paper`, is
        no erratum's); 5 and 6 are slips in the text.
    """
    from ..linalg import lowest_real_eigenvalue, smallest_eigenvalue
    from ..models.linear import stiffness_matrix

    params = ChainParams() if params is None else params
    # The printed operator, its eigenvalues and the derived one's bands: tens of arrays of the chain's size.
    require(60 * FLOAT * n_free(params), f"the errata's operators for N = {params.N}", "evaluate the errata on a shorter chain")
    checks = {c.key: c for c in errata_checks()}
    failing = {key for key, c in checks.items() if not c.agrees}

    # 1: the printed eq. (3) as an operator.
    import scipy.sparse as sparse

    printed_K = printed_eq3_stiffness(params)
    inverse_mass = 1.0 / per_dof(params, params.inertia)
    lowest = lowest_real_eigenvalue(sparse.diags(inverse_mass) @ printed_K)
    # O(N) (LAPACK's banded eigensolver is O(N^2): benchmarks/TIMINGS.md).
    derived_lowest, derived_resolution = smallest_eigenvalue(stiffness_matrix(params))
    asymmetry = float(abs(printed_K - printed_K.T).max())
    # A long chain's softest eigenvalue (N^-4) falls below its round-off: its digits are then noise.
    derived = (
        f"{derived_lowest:+.3g}" if abs(derived_lowest) > derived_resolution else f"within its round-off ({derived_resolution:.1g}) of zero"
    )
    if params.E2 == 0:
        operator = "Without diagonal links (E2 = 0) the coupling vanishes and the misprint has no effect on this chain."
    else:
        if lowest.real < 0:
            stability = (
                f"M^-1 K has the eigenvalue {lowest.real:.3g}: the chain at rest is unstable, its displacements grow "
                f"like exp({np.sqrt(-lowest.real):.3g} t) without damping"
            )
        else:
            stability = f"the lowest eigenvalue of M^-1 K is {lowest.real:.3g}, so this chain happens to stay stable"
        operator = (
            f"The printed stiffness matrix is not symmetric (max |K - K^T| = {asymmetry:.3g}), so no energy exists; for "
            f"this chain (N = {params.N}) {stability}. With the factor 4 the smallest eigenvalue of K is {derived}."
        )
    one = Erratum(
        1,
        "eq. (3), phi equation",
        f"coupling {_fmt(checks['eq3.couple'].printed)} (i.e. (h^2/d^2) E2 inside 2 b^2 [...])",
        f"coupling {_fmt(checks['eq3.couple'].derived)} (4 (h^2/d^2) E2, as printed in eq. (2))",
        operator,
        "sympy",
        tuple(sorted(k for k in failing if k.startswith("eq3."))),
    )

    # 2: Section 3's D1.
    d1_printed = printed_D1(params)
    if params.E2 > 0:
        discrete = float(discrete_static(params)[2, params.N])
        try:
            printed_compliance = f"{central_rotation(params, D1=d1_printed):.4g}"
        except ValueError:
            printed_compliance = "undefined (the denominator of (11) vanishes)"
        compliance = (
            f"With the derived D1 the continuum compliance phi(0)/M of (11) is {central_rotation(params):.4g} against the "
            f"discrete {discrete:.4g}; with the printed D1 it is {printed_compliance}. "
        )
    else:
        compliance = "Without diagonal links (E2 = 0) there is no coupling and Section 3 does not apply. "
    two = Erratum(
        2,
        "Section 3.1, definition after eq. (5), and Section 3.2",
        f"D1 = {_fmt(checks['section3.D1'].printed)}; reduced model at E1 = {_fmt(checks['section3.reduced_E1'].printed)}",
        f"D1 = {_fmt(checks['section3.D1'].derived)}, the bending coefficient of eqs. (2)-(3); reduced model at E1 = {_fmt(checks['section3.reduced_E1'].derived)}",
        f"For this chain D1 = {params.D1:.4g}, not {d1_printed:.4g}. {compliance}"
        "The large-N limit of (11) has the sign of 4 D1 + D2, which is 4 E1 > 0 with the derived D1 but 4 E1 - 4 (h/d)^2 E2 with "
        "the printed one: for E2 > (d/h)^2 E1 the printed theory turns the loaded particle against the moment.",
        "sympy",
        tuple(sorted(k for k in failing if k.startswith("section3."))),
    )
    kinetic = checks["section2.kinetic"]
    three = Erratum(
        3,
        "Section 2, kinetic energy",
        f"K = {_fmt(kinetic.printed['K'])}".replace("Derivative(u(t), t)", "u'")
        .replace("Derivative(v(t), t)", "v'")
        .replace("Derivative(phi(t), t)", "phi'"),
        "K = m*(u'**2 + v'**2)/2 + j*phi'**2/2",
        "The printed form is linear in the velocities: Lagrange's equations get no inertia terms (d/dt dK/du' = 0), so it "
        "cannot give eqs. (2)-(3); it is not an energy. The package's energy budget uses the squares.",
        "sympy",
        ("section2.kinetic",) if "section2.kinetic" in failing else (),
    )
    curl = checks["eq2.potential"].derived
    four = Erratum(
        4,
        'eq. (2), introduced as obtained "by linearizing these equations" of model (i)',
        "eq. (2) presented as a linearisation of the nonlinear model, which has a potential",
        f"eq. (2) is the linear model with phi replaced by sin(phi): dF_v,k/dphi_k+1 - dF_phi,k+1/dv_k = {_fmt(curl)}",
        "The Jacobian K diag(1, 1, cos phi) is not symmetric away from phi = 0, so eq. (2) is not the gradient of any "
        "potential: the sine model has no energy and no energy balance (the package reports its potential as NaN), "
        "and its statics and stability need the non-symmetric Jacobian.",
        "sympy",
        ("eq2.potential",) if "eq2.potential" in failing else (),
    )
    five = Erratum(
        5,
        "Section 4, discussion of Fig. 3",
        '"In the nonlinear model (3) all degrees of freedom are coupled"',
        "the nonlinear model is (1); in (3) u decouples",
        "Reference slip; the tests check that u decouples in (2) and (3) and not in (1).",
        "reading",
    )
    six = Erratum(
        6,
        "Section 2, linearised link energy",
        "... - r1(cos gamma sin alpha1 - sin gamma cos alpha1) phi1)]^2",
        "one closing parenthesis too many; otherwise the printed elongation equals the derived one for all four links",
        "Typographical.",
        "reading",
    )
    # 7: the discrete chain of eqs. (4)-(5) with the printed D1. D1 multiplies the phi
    # Laplacian 2 b^2 (phi_k+1 - 2 phi_k + phi_k-1) of eq. (5): the derived chain's stiffness
    # with that term changed by (printed - derived) D1.
    shift = d1_printed - params.D1
    n = params.n_particles
    phi = 3 * np.arange(n - 2) + 2  # the phi rows of the free degrees of freedom (state.pack order)
    bending = sparse.csr_matrix((n_free(params), n_free(params)))
    if n > 3:
        bending = sparse.coo_matrix(
            (np.concatenate([np.full(n - 2, 2.0), np.full(2 * (n - 3), -1.0)]) * 2 * params.b**2,
             (np.concatenate([phi, phi[:-1], phi[1:]]), np.concatenate([phi, phi[1:], phi[:-1]]))),
            shape=bending.shape,
        ).tocsr()  # fmt: skip
    else:
        bending = sparse.coo_matrix(([4 * params.b**2], ([phi[0]], [phi[0]])), shape=bending.shape).tocsr()
    with_printed = lowest_real_eigenvalue(sparse.diags(inverse_mass) @ (stiffness_matrix(params) + shift * bending)).real
    if params.E2 == 0:
        printed_chain = "Without diagonal links (E2 = 0) the printed and the derived D1 agree."
    elif with_printed < 0:
        printed_chain = (
            f"For this chain (N = {params.N}) M^-1 K of that chain has the eigenvalue {with_printed:.3g}: the discrete chain "
            "of Section 3 is itself unstable at rest, not only its continuum limit wrong."
        )
    else:
        printed_chain = (
            f"For this chain (N = {params.N}) the lowest eigenvalue of M^-1 K of that chain is {with_printed:.3g}: it stays stable."
        )
    seven = Erratum(
        7,
        "Section 3.1, eqs. (4)-(5) with the printed D1",
        f"the discrete steady-state equations (4)-(5) with D1 = {_fmt(checks['section3.D1'].printed)}",
        f"D1 = {_fmt(checks['section3.D1'].derived)}: with it eqs. (4)-(5) are the v, phi part of eq. (3) at rest",
        printed_chain,
        "computed",
    )
    eight = Erratum(
        8,
        "Section 4, the relaxation protocol",
        '"At each step we solved the set of dynamic equations (1-3)"',
        "(1) is the potential of a link, not an equation of motion: the dynamic equations are model (1)'s equations of "
        "motion (not printed), (2) and (3)",
        "Reference slip.",
        "reading",
    )
    nine = Erratum(
        9,
        "Abstract, last sentences",
        '"... the model containing nonlinear sine-dependence of the angle of rotation is observed. It is not described by the '
        'linear model (iii)."',
        'the sentence "It is not described by the linear model (iii)." appears twice; the second time after a sentence '
        "whose end is missing",
        "Editorial: the abstract repeats itself.",
        "reading",
    )
    ten = Erratum(
        10,
        "Section 3.1, after eq. (12)",
        '"The boundary conditions v_0 = 0, v_N = 0, phi_N = 0 of the discrete model (9) are automatically satisfied"',
        "(9) is the equation of the central particle; the conditions are the symmetry v_0 = 0 and the clamped end "
        "v_N = phi_N = 0, the discrete form of (8)",
        "Reference slip.",
        "reading",
    )
    return (one, two, three, four, five, six, seven, eight, nine, ten)


# --------------------------------------------------------------------------- the Timoshenko beam
@dataclass(frozen=True)
class TimoshenkoDerivation:
    """The chain's Timoshenko beam derived from the linear bond energy (:mod:`cosserat_chain.analysis.timoshenko`).

    Attributes
    ----------
    density : Expr
        The bond energy over h in the bond's strains ``epsilon`` = du/h, ``kappa`` = dphi/h and
        ``gamma`` = dv/h - (phi_k + phi_k+1)/2, exactly: EI/2 kappa^2 + GA/2 gamma^2 + EA/2 epsilon^2.
    strain_corrections : tuple of 3 Expr
        Those strains of smooth fields sampled at the bond's ends, less the beam's strains
        u_x, phi_x, v_x - phi at its centre: O(h^2) each (h^2 u_xxx/24, h^2 phi_xxx/24,
        h^2 (v_xxx/24 - phi_xx/8)).
    stiffness : dict
        ``EI``, ``GA``, ``EA`` read off ``density`` (in E1, E2, h, b, d, g).
    claimed : dict
        The same three as stated in the module: 2 E1 b^2 h, k_v h, k_u h; each equal to the derived one.
    bond_shear : Expr
        The shear strain dv/h - (phi_k + phi_k+1)/2 of one bond of the exact beam (shear
        compliance ``c``, bending stiffness ``EI``, shear force ``Q``), which is
        Q (c + h^2/(12 EI)).
    bond_moment_is_midpoint : bool
        Whether the bond's EI dphi/h is the beam's bending moment at the bond's centre.
    paper_bending : bool
        Whether 2 b^2 D1 = EI/h - GA h/4, with the derived D1: the paper's coefficient is the
        beam's bending less a quarter of its shear moved from the bond's centre to the particle.
    central_compliance : Expr
        phi(0)/M of the clamped-clamped beam of length 2L under a moment at its centre, solved
        from its general solution (symbols ``L``, ``EI``, ``c``).
    error_coefficients : dict
        Leading relative error of the loaded particle's compliance against the chain (the
        beam with c = 1/GA - h^2/(12 EI), exact at the particles): ``"timoshenko"``, the
        coefficient of 1/N^2 (3/4), and ``"paper"``, that of 1/N for eq. (11) (in D1, D2, E1).
    """

    density: Any
    strain_corrections: tuple[Any, ...]
    stiffness: dict[str, Any]
    claimed: dict[str, Any]
    bond_shear: Any
    bond_moment_is_midpoint: bool
    paper_bending: bool
    central_compliance: Any
    error_coefficients: dict[str, Any]

    @property
    def agrees(self) -> bool:
        """Whether every claim holds: EI, GA, EA, the bond's shear and moment, and the paper's D1."""
        return all(_equal(self.stiffness[k], self.claimed[k]) for k in self.stiffness) and self.bond_moment_is_midpoint and self.paper_bending


@functools.cache
def timoshenko_derivation() -> TimoshenkoDerivation:
    """Derive the chain's Timoshenko beam with SymPy (cached; a few seconds on first call).

    The bond energy of :func:`derivation`, written in the bond's three strains, is exactly h
    times a Timoshenko density (no strain coupled to another); smooth fields sampled at the
    bond's ends have those strains to O(h^2) (Taylor series about the bond's centre), so the
    beam is the chain's long-wave limit, with errors O(h^2) where eq. (6), whose shear is
    taken at the particle, keeps an O(h) one.
    """
    import sympy as sp

    derived = derivation()
    s = derived.symbols
    E1, h, b = (s[n] for n in ("E1", "h", "b"))
    # Step 1, exact: the bond energy in the bond's strains du/h, dphi/h, dv/h - (phi_k + phi_k+1)/2.
    axial, bending, shear = sp.symbols("epsilon kappa gamma", real=True)
    strains = {
        s["u_p"]: s["u"] + h * axial,
        s["phi_p"]: s["phi"] + h * bending,
        s["v_p"]: s["v"] + h * (shear + s["phi"] + h * bending / 2),
    }
    density = sp.expand(derived.bond_energy.subs(strains, simultaneous=True) / h)
    stiffness = {
        "EI": _tidy(2 * density.coeff(bending, 2)),
        "GA": _tidy(2 * density.coeff(shear, 2)),
        "EA": _tidy(2 * density.coeff(axial, 2)),
    }
    leftover = density - sum(stiffness[k] / 2 * e**2 for k, e in (("EI", bending), ("GA", shear), ("EA", axial)))
    if _eliminate_d(leftover) != 0:
        raise ArithmeticError(f"the bond energy is not a sum of squares of its three strains: {density}")
    # Step 2: smooth fields about the bond's centre give those strains to O(h^2).
    x = sp.Symbol("x", real=True)
    u_f, v_f, phi_f = (sp.Function(name)(x) for name in ("u", "v", "phi"))

    def ends(f: Any) -> tuple[Any, Any]:
        series = [sp.diff(f, x, n) * (h / 2) ** n / sp.factorial(n) for n in range(4)]
        return sum((-1) ** n * t for n, t in enumerate(series)), sum(series)

    (u0, u1), (v0, v1), (p0, p1) = ends(u_f), ends(v_f), ends(phi_f)
    bond_strains = ((u1 - u0) / h, (p1 - p0) / h, (v1 - v0) / h - (p0 + p1) / 2)
    centre = (sp.diff(u_f, x), sp.diff(phi_f, x), sp.diff(v_f, x) - phi_f)
    corrections = tuple(sp.expand(bs - c) for bs, c in zip(bond_strains, centre))
    if any(sp.expand(corr.subs(h, 0)) != 0 or sp.expand(sp.diff(corr, h).subs(h, 0)) != 0 for corr in corrections):
        raise ArithmeticError(f"the bond's strains differ from the beam's at O(h): {corrections}")
    coefficients = derived.coefficients
    claimed = {"EI": 2 * E1 * b**2 * h, "GA": coefficients["k_v"] * h, "EA": coefficients["k_u"] * h}
    paper_bending = _equal(2 * b**2 * coefficients["D1"], stiffness["EI"] / h - stiffness["GA"] * h / 4)

    # One bond of the exact beam: Q constant, m = EI phi_x linear, v_x = phi + c Q.
    EI, c, Q, m0, phi0, v0, L, M = sp.symbols("EI c Q m0 phi0 v0 L M", real=True)
    phi = phi0 + (m0 * x - Q * x**2 / 2) / EI
    v = v0 + sp.integrate(phi + c * Q, (x, 0, x))
    bond_shear = sp.factor(sp.expand((v.subs(x, h) - v0) / h - (phi0 + phi.subs(x, h)) / 2))
    midpoint = sp.expand(EI * (phi.subs(x, h) - phi0) / h - (m0 - Q * h / 2)) == 0

    # The clamped-clamped beam under a central moment, from its general solution on each half.
    C = sp.symbols("C1:9")

    def general(k: int) -> tuple[Any, Any]:
        c1, c2, c3, c4 = C[4 * k : 4 * k + 4]
        return c1 * x**3 / 6 + c2 * x**2 / 2 + c3 * x + c4, c1 * x**2 / 2 + c2 * x + c3 + c * EI * c1

    (v_left, phi_left), (v_right, phi_right) = general(0), general(1)

    def moment(f: Any) -> Any:
        return EI * sp.diff(f, x)

    def force(f: Any) -> Any:
        return -sp.diff(moment(f), x)

    conditions = [
        v_left.subs(x, -L),
        phi_left.subs(x, -L),
        v_right.subs(x, L),
        phi_right.subs(x, L),
        (v_right - v_left).subs(x, 0),
        (phi_right - phi_left).subs(x, 0),
        (moment(phi_right) - moment(phi_left)).subs(x, 0) + M,
        (force(phi_right) - force(phi_left)).subs(x, 0),
    ]
    solved = sp.solve(conditions, C, dict=True)[0]
    central = sp.factor(phi_right.subs(solved).subs(x, 0) / M)

    # Leading errors in 1/N against the chain, the beam with c* = 1/GA - h^2/(12 EI) (L = N h).
    n_inv, GA, D1, D2 = sp.symbols("n_inv GA D1 D2", positive=True)
    chain = central.subs(c, 1 / GA - h**2 / (12 * EI)).subs(L, h / n_inv)
    beam = central.subs(c, 1 / GA).subs(L, h / n_inv)
    timoshenko = sp.limit(sp.cancel((beam - chain) / chain) / n_inv**2, n_inv, 0)
    Lh = h / n_inv
    den = h * (24 * h**2 * D1**2 + (8 * Lh**2 + 6 * h**2) * D1 * D2 + Lh * (2 * Lh - h) * D2**2)
    paper = Lh * (12 * h**2 * D1 + Lh**2 * D2) / (2 * b**2 * den)
    # In the paper's variables: EI = 2 b^2 h E1 = 2 b^2 h (D1 + D2/4), GA = 2 b^2 D2 / h.
    in_d = {EI: 2 * b**2 * h * (D1 + D2 / 4), GA: 2 * b**2 * D2 / h}
    paper_error = sp.factor(sp.limit(sp.cancel((paper - chain.subs(in_d)) / chain.subs(in_d)) / n_inv, n_inv, 0))
    return TimoshenkoDerivation(
        density=density,
        strain_corrections=corrections,
        stiffness=stiffness,
        claimed={k: _tidy(v) for k, v in claimed.items()},
        bond_shear=bond_shear,
        bond_moment_is_midpoint=midpoint,
        paper_bending=paper_bending,
        central_compliance=central,
        error_coefficients={"timoshenko": timoshenko, "paper": paper_error},
    )
