"""Codimension-two points of cycles on systems built to have them at known parameters (issue 40 item 4):
``numerics.cycle_curve``'s fold-torus (AUTO-07p's LTR, Kuznetsov's fold-Neimark-Sacker), the 1:1, 1:3 and 1:4
resonances on a torus curve, and the cusp of a user system's fold-of-cycles curve.

Each system is a rotor phi'' = 1 - phi' (its rotation phi' = 1, period 2 pi) beside a normal form at rest: the
normal form does not feel the rotor, so the orbit's Floquet multipliers are 1, exp(-2 pi) (the rotor) and
exp(2 pi lambda) over the normal form's eigenvalues lambda at its rest point, all in closed form, and so is every
codimension-two point.
"""

from __future__ import annotations

import cmath
import json
import math
from types import SimpleNamespace

import numpy as np
import pytest
import scipy.sparse as sp

from cosserat_chain.numerics import shooting
from cosserat_chain.numerics.cycle_curve import (
    AUTO_LABELS,
    CODIM2,
    _codim2_tests,
    _FoldArc,
    _genuine,
    _SystemAugmented,
    continue_cycle_end,
)
from cosserat_chain.systems import System

PERIOD = 2 * math.pi
#: The fold-torus system's numbers: stiffness k0 and damping c of its circulatory pair, the fold's a and s there.
K0, C, A_LTR, S_LTR = 1.44, 0.2, 0.1, 0.24


class _Beside(System):
    """A rotor (coordinate ``phi``, unit mass and damping, unit torque) beside a normal form in parameters a, s."""

    def __init__(self, a: float, s: float):
        super().__init__({"a": a, "s": s})

    def mass(self) -> np.ndarray:
        return np.ones(self.size)


class FoldTorus(_Beside):
    """x'' = a - 0.1 - 0.5 (s - 0.24) - xi^2 - x' (xi = x - 0.5; its rest points fold at xi = 0) beside a pair
    y'' = -(k0 + xi) y + s J y - c y' (J the rotation by -pi/2: a circulatory force, on the circle where
    s = c sqrt(k0 + xi), lambda = +-i sqrt(k0 + xi)). Fold curve a = 0.1 + 0.5 (s - 0.24); torus curve
    xi = (s / c)^2 - k0, a = 0.1 + 0.5 (s - 0.24) + xi^2; fold-torus where both meet, (s, a) = (0.24, 0.1)."""

    name = "fold_torus"
    coordinates = ("phi", "x", "y1", "y2")
    angles = np.array([True, False, False, False])

    def damping(self) -> np.ndarray:
        return np.array([1.0, 1.0, C, C])

    def forces(self, q: np.ndarray) -> np.ndarray:
        a, s = self.parameter("a"), self.parameter("s")
        xi, y1, y2 = q[1] - 0.5, q[2], q[3]
        k = K0 + xi
        return np.array([1.0, a - A_LTR - 0.5 * (s - S_LTR) - xi**2, -k * y1 + s * y2, -k * y2 - s * y1])

    def force_jacobian(self, q: np.ndarray) -> sp.csr_matrix:
        s, xi, y1, y2 = self.parameter("s"), q[1] - 0.5, q[2], q[3]
        k = K0 + xi
        return sp.csr_matrix(np.array([[0, 0, 0, 0], [0, -2 * xi, 0, 0], [0, -y1, -k, s], [0, -y2, -s, -k]], dtype=float))

    def parameter_forces(self, q: np.ndarray, name: str) -> np.ndarray:
        return np.array([0.0, 1.0, 0.0, 0.0]) if name == "a" else np.array([0.0, -0.5, q[3], -q[2]])


class Resonant(_Beside):
    """y'' = -(s - 0.3) y - (a - 0.05 - 0.5 (s - 0.3)) y': a torus where the damping vanishes, a = 0.05 + 0.5 (s - 0.3),
    its pair exp(+-2 pi i sqrt(s - 0.3)) at the angle 2 pi sqrt(s - 0.3): 1:3 resonance at s = 0.3 + 1/9, 1:4 at
    0.3 + 1/16; at s = 0.3 the pair meets +1 as a Jordan block (y'' = 0) and turns real: the 1:1 resonance."""

    name = "resonant"
    coordinates = ("phi", "y")
    angles = np.array([True, False])

    def damping(self) -> np.ndarray:
        return np.array([1.0, self.parameter("a") - 0.05 - 0.5 * (self.parameter("s") - 0.3)])

    def forces(self, q: np.ndarray) -> np.ndarray:
        return np.array([1.0, -(self.parameter("s") - 0.3) * q[1]])

    def force_jacobian(self, q: np.ndarray) -> sp.csr_matrix:
        return sp.csr_matrix(np.array([[0.0, 0.0], [0.0, 0.3 - self.parameter("s")]]))

    def parameter_forces(self, q: np.ndarray, name: str) -> np.ndarray:
        return np.zeros(2) if name == "a" else np.array([0.0, -q[1]])

    def parameter_mass_damping(self, name: str) -> tuple[np.ndarray, np.ndarray]:
        return np.zeros(2), np.array([0.0, 1.0 if name == "a" else -0.5])


class Cusp(_Beside):
    """x'' = (a - 0.3) + (s - 0.2) xi - xi^3 - x' (xi = x - 0.5), the rotor's torque 1 + 0.2 xi (the period
    2 pi / (1 + 0.2 xi) changes along the curve). Fold curve s = 0.2 + 3 xi^2, a = 0.3 - 2 xi^3: it turns back in s
    at the cusp (s, a) = (0.2, 0.3), its two folds xi = +-sqrt((s - 0.2) / 3) meeting there."""

    name = "cusp"
    coordinates = ("phi", "x")
    angles = np.array([True, False])

    def damping(self) -> np.ndarray:
        return np.ones(2)

    def forces(self, q: np.ndarray) -> np.ndarray:
        a, s, xi = self.parameter("a"), self.parameter("s"), q[1] - 0.5
        return np.array([1.0 + 0.2 * xi, a - 0.3 + (s - 0.2) * xi - xi**3])

    def force_jacobian(self, q: np.ndarray) -> sp.csr_matrix:
        xi = q[1] - 0.5
        return sp.csr_matrix(np.array([[0.0, 0.2], [0.0, self.parameter("s") - 0.2 - 3 * xi**2]]))

    def parameter_forces(self, q: np.ndarray, name: str) -> np.ndarray:
        return np.array([0.0, 1.0]) if name == "a" else np.array([0.0, q[1] - 0.5])


def orbit_at(system: System, x: float) -> shooting.Orbit:
    """The rotation with the normal form at rest at x (its other coordinates zero)."""
    y0 = np.zeros(2 * system.size)
    y0[1], y0[system.size] = x, 1.0
    return shooting.find_orbit(system, (y0, PERIOD), turns={"phi": 1})


def pair_multiplier(s: float, xi: float) -> complex:
    """The fold-torus system's critical multiplier in closed form: exp(2 pi lambda), lambda^2 + c lambda + k + i s = 0
    (u = y1 + i y2), the root of the larger real part."""
    root = cmath.sqrt(C**2 - 4 * (K0 + xi + 1j * s))
    return cmath.exp(PERIOD * max((-C + root) / 2, (-C - root) / 2, key=lambda z: z.real))


def fake(*mu) -> SimpleNamespace:
    """An orbit with the trivial multiplier 1 and ``mu``."""
    every = np.array([1.0, *mu], dtype=complex)
    return SimpleNamespace(multipliers=every, nontrivial_multipliers=every[1:])


def test_the_fold_torus_test_functions_change_sign_where_their_multiplier_crosses_and_refuse_a_neutral_saddle():
    assert AUTO_LABELS["fold_torus"] == "LTR" and AUTO_LABELS["fold_flip"] == "LPD"
    assert "fold_torus" in CODIM2["fold_of_cycles"] and "fold_torus" in CODIM2["torus"]
    # On a fold curve (a second multiplier at +1): a complex pair through the circle, +-(|mu|^2 - 1) (the sign of the
    # product of all mu_i mu_j - 1: here (0.3 (-0.2) - 1) < 0 turns it).
    inside, outside = (fake(1.0, r * np.exp(1j), r * np.exp(-1j), 0.3, -0.2) for r in (0.99, 1.01))
    f_in, f_out = (_codim2_tests("fold_of_cycles", o, None)["fold_torus"] for o in (inside, outside))
    assert f_in == pytest.approx(1.0 - 0.99**2, rel=1e-12) and f_out == pytest.approx(1.0 - 1.01**2, rel=1e-12)
    # A neutral saddle (a real pair with product 1: 2.5 x 0.4) changes the sign too, and is refused where located.
    saddle = [fake(1.0, 2.5, 0.4 + d, 0.1 + 0.2j, 0.1 - 0.2j) for d in (-1e-3, 1e-3)]
    assert np.prod([_codim2_tests("fold_of_cycles", o, None)["fold_torus"] for o in saddle]) < 0
    assert not _genuine("fold_of_cycles", "fold_torus", fake(1.0, 2.5, 0.4, 0.1 + 0.2j, 0.1 - 0.2j), None)
    assert _genuine("fold_of_cycles", "fold_torus", fake(1.0, np.exp(1j), np.exp(-1j), 0.3), None)
    # On a torus curve: a second real multiplier through +1, also where it moves far between two points (the sum of
    # the two nearest +1 would keep its sign: 0.9 and then 3.4 is no nearer +1 than the rotor's 0.002).
    pair = complex(np.exp(1.2j))
    sides = [_codim2_tests("torus", fake(pair, pair.conjugate(), mu, 0.002), pair)["fold_torus"] for mu in (0.9, 3.4)]
    assert abs(sides[0]) == pytest.approx(0.1, rel=1e-9) and sides[0] * sides[1] < 0
    assert _genuine("torus", "fold_torus", fake(pair, pair.conjugate(), 1.0 + 1e-6, 0.002), pair)
    assert not _genuine("torus", "fold_torus", fake(pair, pair.conjugate(), 1.0 + 0.1j, 1.0 - 0.1j), pair)


def fold_torus_fold_curve():
    """The fold-torus system's fold of cycles followed in s from 0.2 to 0.27 (its end in a)."""
    start = orbit_at(FoldTorus(a=A_LTR + 0.5 * (0.2 - S_LTR) + 1e-4, s=0.2), 0.51)
    return continue_cycle_end(start, "fold_of_cycles", "s", [0.2, 0.23, 0.25, 0.27], parameter="a")


def test_a_fold_torus_on_a_fold_curve_is_where_the_circulatory_pair_reaches_the_circle():
    curve = fold_torus_fold_curve()
    assert curve.complete
    # The curve itself, a = 0.1 + 0.5 (s - 0.24), and its multipliers: a second one at +1 and the pair in closed form.
    assert np.allclose(curve.moment, A_LTR + 0.5 * (curve.values - S_LTR), atol=1e-9, rtol=0)
    for s, orbit in zip(curve.values, curve.orbits):
        exact = pair_multiplier(s, 0.0)
        assert np.min(np.abs(orbit.multipliers - exact)) < 1e-8
        assert abs(_codim2_tests("fold_of_cycles", orbit, None)["fold_torus"]) == pytest.approx(abs(abs(exact) ** 2 - 1.0), abs=1e-8)
    (point,) = curve.points
    assert (point.kind, point.label, point.name) == ("fold_torus", "LTR", "fold-torus")
    # Where s = c sqrt(k0): the closed form to 1e-8 (a test function with another zero fails this).
    assert point.value == pytest.approx(S_LTR, abs=1e-8) and point.moment == pytest.approx(A_LTR, abs=1e-8)
    assert abs(point.value - S_LTR) <= point.uncertainty + 1e-10 and point.uncertainty < 1e-8
    mu = point.orbit.multipliers
    on_circle = mu[np.argmin(np.abs(mu - pair_multiplier(S_LTR, 0.0)))]
    assert abs(abs(on_circle) - 1.0) < 1e-8 and abs(np.angle(on_circle)) == pytest.approx(2 * math.pi * 1.2 - 2 * math.pi, abs=1e-8)
    assert point.angle == pytest.approx(abs(np.angle(on_circle)), abs=1e-12)
    assert np.sort(np.abs(mu - 1.0))[1] < 1e-3  # still a fold of cycles: a second multiplier at +1
    assert json.loads(json.dumps(curve.as_dict()))["codim2"][0]["label"] == "LTR"


def test_a_fold_torus_on_a_torus_curve_is_where_the_rest_point_folds():
    """The torus curve from s = 0.241 to 0.239 passes xi = 0, where the x-mode's multiplier crosses +1: the same
    point, from the other augmented system (|mu|^2 = 1 on the pair instead of the bordered shooting Jacobian)."""
    xi = (0.241 / C) ** 2 - K0
    start = orbit_at(FoldTorus(a=A_LTR + 0.5 * (0.241 - S_LTR) + xi**2 + 1e-5, s=0.241), 0.5 + xi)
    curve = continue_cycle_end(start, "torus", "s", [0.241, 0.239], parameter="a")
    assert curve.complete
    xis = (curve.values / C) ** 2 - K0
    assert np.allclose(curve.moment, A_LTR + 0.5 * (curve.values - S_LTR) + xis**2, atol=1e-9, rtol=0)
    (point,) = curve.points
    assert (point.kind, point.label) == ("fold_torus", "LTR")
    assert point.value == pytest.approx(S_LTR, abs=1e-8) and point.moment == pytest.approx(A_LTR, abs=1e-8)
    assert point.angle == pytest.approx(2 * math.pi * 1.2 - 2 * math.pi, abs=1e-8)
    assert np.sort(np.abs(point.orbit.multipliers - 1.0))[1] < 1e-6  # the x-mode's multiplier at +1


def test_a_torus_curve_passes_the_1_to_3_and_1_to_4_resonances_and_ends_at_the_1_to_1():
    s0 = 0.42
    start = orbit_at(Resonant(a=0.05 + 0.5 * (s0 - 0.3) + 1e-3, s=s0), 0.0)
    curve = continue_cycle_end(start, "torus", "s", [s0, 0.4, 0.35, 0.31, 0.29], parameter="a")
    assert not curve.complete and "1:1 resonance (R1)" in curve.message
    assert np.allclose(curve.moment, 0.05 + 0.5 * (curve.values - 0.3), atol=1e-9, rtol=0)
    exact = {"resonance_1_3": 0.3 + 1 / 9, "resonance_1_4": 0.3 + 1 / 16, "resonance_1_1": 0.3}
    assert [p.kind for p in curve.points] == list(exact) and [p.label for p in curve.points] == ["R3", "R4", "R1"]
    for point in curve.points:
        assert point.value == pytest.approx(exact[point.kind], abs=1e-8)
        assert point.moment == pytest.approx(0.05 + 0.5 * (exact[point.kind] - 0.3), abs=1e-8)
        assert abs(point.value - exact[point.kind]) <= point.uncertainty + 1e-10
    assert curve.points[-1].angle == pytest.approx(0.0, abs=1e-4)  # the pair at +1 (a Jordan block: sqrt of round-off)


def cusp_curve(values):
    xi = math.sqrt((values[0] - 0.2) / 3)
    start = orbit_at(Cusp(a=0.3 - 2 * xi**3 + 1e-4, s=values[0]), 0.5 + xi)
    return continue_cycle_end(start, "fold_of_cycles", "s", values, parameter="a")


@pytest.mark.slow
def test_a_system_s_fold_curve_turns_back_at_its_cusp():
    """Followed from s = 0.3 towards 0.15, the fold curve stops short of 0.2 on natural steps; pseudo-arclength
    through the turn locates the cusp at the closed form's (0.2, 0.3), with the two folds on either side."""
    curve = cusp_curve([0.3, 0.15])
    assert not curve.complete and "cusp (CP)" in curve.message and "turns back in s" in curve.message
    point = curve.points[-1]
    assert (point.kind, point.label) == ("cusp", "CP")
    assert point.value == pytest.approx(0.2, abs=1e-8) and point.moment == pytest.approx(0.3, abs=1e-8)
    assert abs(point.value - 0.2) <= point.uncertainty < 1e-8
    assert abs(point.test) < 1e-6 and abs(point.tangent_moment) < 1e-6
    # The two branches: folds of the closed-form curve a = 0.3 - 2 xi^3 at s = 0.2 + 3 xi^2, xi of either sign.
    for (value, _), moment in zip(point.branches, point.branch_moments):
        xi = math.sqrt(max(value - 0.2, 0.0) / 3)
        assert min(abs(moment - (0.3 - 2 * xi**3)), abs(moment - (0.3 + 2 * xi**3))) < 1e-8
    assert json.loads(json.dumps(curve.as_dict()))["codim2"][-1]["branches"][0]["moment"] == point.branch_moments[0]


def test_the_fold_curve_s_tangent_on_a_system_is_the_closed_form_s_on_either_side_of_the_cusp():
    """The pseudo-arclength's tangent (what the cusp search watches, its s-component changing sign at the cusp) at
    two folds xi = +-0.05 of the cusp system: (dx, da, ds) along (1, -6 xi^2, 6 xi), to the differences' 1e-6."""
    start = cusp_curve([0.23]).orbits[0]
    for xi in (0.05, -0.05):
        value = 0.2 + 3 * xi**2
        augmented = _SystemAugmented("fold_of_cycles", start, 1e-10, 1e-11, 1e-12, field_name="s", parameter="a")
        z = augmented.pack(start)
        z[1], z[-1] = 0.5 + xi, 0.3 - 2 * xi**3  # the fold's x and a: Newton from there
        z_fold = augmented.solve(augmented.at(value), z)[0]
        assert z_fold[1] == pytest.approx(0.5 + xi, abs=1e-9) and z_fold[-1] == pytest.approx(0.3 - 2 * xi**3, abs=1e-9)
        t = _FoldArc(augmented).tangent(np.append(z_fold, value), None)
        # (phi, x, phi', x', log T, a, s): phi kept on the phase plane, phi' = 1 + 0.2 xi, T = 2 pi / (1 + 0.2 xi).
        exact = np.array([0.0, 1.0, 0.2, 0.0, -0.2 / (1 + 0.2 * xi), -6 * xi**2, 6 * xi])
        assert np.allclose(t * math.copysign(1.0, t[1]), exact / np.linalg.norm(exact), atol=1e-5)
