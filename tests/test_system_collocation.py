"""Orbits of user systems by orthogonal collocation (numerics/system_collocation.py; issue 40, item 2).

The quick tests: a uniformly rotating driven damped rotor (no potential) whose orbit, period 2 pi alpha / I and
multipliers {1, exp(-alpha T)} are known in closed form, also along a continuation in I; the fields' Jacobian and
parameter column against finite differences of the fields; AUTO-07p's ``pen`` pair at I = 0.4 against single
shooting; clear errors. The slow tests: three unequal Josephson junctions against shooting, and their snake towards a
saddle-focus homoclinic loop through AUTO-07p's folds of cycles (benchmarks/auto07p_jj3_snake.py).
"""

import json
import math
from pathlib import Path

import numpy as np
import pytest
import scipy.sparse as sp

from cosserat_chain.numerics.collocation_core import CollocationError
from cosserat_chain.numerics.shooting import second_multiplier_at_one
from cosserat_chain.numerics.system_collocation import SystemFields, continue_collocation_orbits, find_collocation_orbit
from cosserat_chain.systems.base import System, SystemDefinitionError
from three_junctions import jj3

#: Agreement of two independent methods (collocation, shooting) on the same orbit.
AGREE = 1e-8
AUTO_SNAKE = Path(__file__).resolve().parents[1] / "benchmarks" / "results" / "auto07p_jj3_snake.json"
#: AUTO-07p's printed digits (11) on its folds and period doublings.
AUTO_DIGITS = 1e-9


class _Rotor(System):
    """phi'' + alpha phi' = I: the rotation phi' = I / alpha, period 2 pi alpha / I, multipliers 1 and exp(-alpha T)."""

    coordinates = ("phi_0",)
    angles = np.array([True])

    def forces(self, q):
        return np.full(1, self.parameter("I"))

    def force_jacobian(self, q):
        return sp.csr_matrix((1, 1))

    def parameter_forces(self, q, name):
        return np.full(1, 1.0 if name == "I" else 0.0)

    def mass(self):
        return np.ones(1)

    def damping(self):
        return np.full(1, self.parameter("alpha"))


def rotor(I=0.3, alpha=0.5):  # noqa: E741
    return _Rotor({"I": I, "alpha": alpha})


class _Chain3(System):
    """Three pendula in a row, F_i = I - w sin(phi_i) + k (phi_{i+1} - 2 phi_i + phi_{i-1}) (free ends), C = 0.2 + 0.1 w,
    with its Jacobian and parameter derivatives written out."""

    coordinates = ("phi_0", "phi_1", "phi_2")
    angles = np.array([True, True, True])
    _lap = np.array([[-1.0, 1.0, 0.0], [1.0, -2.0, 1.0], [0.0, 1.0, -1.0]])

    def forces(self, q):
        p = self.parameters
        return p["I"] - p["w"] * np.sin(q) + p["k"] * (self._lap @ q)

    def force_jacobian(self, q):
        p = self.parameters
        return sp.csr_matrix(np.diag(-p["w"] * np.cos(q)) + p["k"] * self._lap)

    def parameter_forces(self, q, name):
        return {"I": np.ones(3), "w": -np.sin(q), "k": self._lap @ q}[name]

    def mass(self):
        return np.ones(3)

    def damping(self):
        return np.full(3, 0.2 + 0.1 * self.parameter("w"))


def test_uniform_rotation_period_and_multipliers_are_exact():
    system = rotor()
    # A wrong start (speed 0.4 instead of 0.6, period 10 instead of 2 pi 0.5 / 0.3) converges to the exact orbit.
    orbit = find_collocation_orbit(system, (np.array([0.0, 0.4]), 10.0), turns={"phi_0": 1}, ntst=20)
    period = 2 * math.pi * 0.5 / 0.3
    assert orbit.period == pytest.approx(period, rel=1e-12)
    assert np.allclose(orbit.profile[:, 1], 0.6, atol=1e-12)
    assert orbit.trivial_multiplier_error < 1e-12
    assert orbit.nontrivial_multipliers[0] == pytest.approx(math.exp(-0.5 * period), rel=1e-10)


def test_continuation_in_the_drive_follows_the_exact_period():
    start = find_collocation_orbit(rotor(), (np.array([0.0, 0.6]), 2 * math.pi * 0.5 / 0.3), turns={"phi_0": 1}, ntst=8)
    branch = continue_collocation_orbits(start, "I", direction=1.0, limits=(0.2, 0.6), max_points=8)
    drives = branch.moment
    assert drives[-1] > 0.35
    # Each point's period is the exact one at its own I: the parameter's column of the Jacobian is right.
    assert np.allclose(branch.period, 2 * math.pi * 0.5 / drives, rtol=1e-10)
    assert all(o.system.parameter("I") == o.moment for o in branch.orbits)


def test_fields_jacobian_and_parameter_column_against_finite_differences():
    system = _Chain3({"I": 0.4, "k": 0.7, "w": 1.3})
    fields = SystemFields(system, "w")
    points = np.random.default_rng(1).standard_normal((4, 6))
    value = 1.3
    f, pattern = fields.jacobian(points, value)
    assert np.allclose(f, fields.values(points, value))
    dense = fields.dense(pattern)
    step = 1e-6
    for i in range(6):
        e = np.zeros(6)
        e[i] = step
        column = (fields.values(points + e, value) - fields.values(points - e, value)) / (2 * step)
        assert np.allclose(dense[:, :, i], column, atol=1e-8)
    # The parameter enters the forces and the damping (C = 0.2 + 0.1 w).
    column = (fields.values(points, value + step) - fields.values(points, value - step)) / (2 * step)
    assert np.allclose(fields.parameter_derivative(points, value), column, atol=1e-8)


def test_compiled_fields_against_finite_differences(pen_in_phase_orbit):
    # pen's compiled right-hand side with coloured seeds: the two pendula's Jacobian (coupled, so two colours) and dF/dI.
    fields = SystemFields(pen_in_phase_orbit.system, "gamma")
    points = np.random.default_rng(2).standard_normal((3, 4))
    value = 0.175
    f, pattern = fields.jacobian(points, value)
    assert np.allclose(f, fields.values(points, value), rtol=1e-14, atol=1e-14)
    dense, step = fields.dense(pattern), 1e-6
    for i in range(4):
        e = np.zeros(4)
        e[i] = step
        assert np.allclose(dense[:, :, i], (fields.values(points + e, value) - fields.values(points - e, value)) / (2 * step), atol=1e-8)
    column = (fields.values(points, value + step) - fields.values(points, value - step)) / (2 * step)
    assert np.allclose(fields.parameter_derivative(points, value), column, atol=1e-8)
    assert np.any(column != 0.0)


def test_pen_in_phase_orbit_equals_shooting(pen_in_phase_orbit):
    shooting = pen_in_phase_orbit
    orbit = find_collocation_orbit(shooting.system, shooting, ntst=20)
    assert orbit.period == pytest.approx(shooting.period, abs=AGREE)
    assert orbit.trivial_multiplier_error < AGREE
    ours, theirs = np.sort_complex(orbit.multipliers), np.sort_complex(shooting.multipliers)
    assert np.max(np.abs(ours - theirs)) < AGREE
    # The profile starts at the shooting's y0 up to a phase: the shooting's start lies on it.
    tau = np.linspace(0.0, 1.0, 2001)
    assert np.min(np.linalg.norm(orbit.states(tau) - shooting.y0, axis=1)) < 1e-2


class _PlainPair(System):
    """Two pendula in plain NumPy (finite-difference Jacobians), the coupling written to depend on ``c``."""

    coordinates = ("a", "b")
    angles = np.array([True, True])

    def forces(self, q):
        c = self.parameter("c")
        return self.parameter("I") - np.sin(q) + c * (q[::-1] - q)

    def mass(self):
        return np.ones(2)

    def damping(self):
        return np.full(2, 0.3)


class _HiddenCoupling(_PlainPair):
    """Its Jacobian shows the coupling only beyond phi_a = 3.2, where no random state in (-pi, pi) lies: an entry outside the pattern."""

    def force_jacobian(self, q):
        c = self.parameter("c") if q[0] > 3.2 else 0.0
        return sp.csr_matrix(np.diag(-np.cos(q)) + c * np.array([[-1.0, 1.0], [1.0, -1.0]]))


def test_a_plain_numpy_system_is_solved_and_a_hidden_entry_refused():
    system = _PlainPair({"I": 1.2, "c": 0.1})
    with pytest.warns(UserWarning, match="finite differences"):
        orbit = find_collocation_orbit(system, (np.array([0.0, 0.0, 4.0, 4.0]), 1.6), turns={"a": 1, "b": 1}, ntst=16)
    # In phase, the coupling is idle: one damped driven pendulum; Liouville: the product of the multipliers is exp(-0.6 T).
    assert np.allclose(orbit.profile[:, 0], orbit.profile[:, 1], atol=1e-9)
    assert np.prod(np.abs(orbit.multipliers)) == pytest.approx(math.exp(-0.6 * orbit.period), rel=1e-6)
    hidden = _HiddenCoupling({"I": 1.2, "c": 0.1})
    with pytest.raises(CollocationError, match=r"outside the pattern"):
        find_collocation_orbit(hidden, (np.array([0.0, 0.0, 4.0, 4.0]), 1.6), turns={"a": 1, "b": 1}, ntst=16)


def test_bad_input_is_refused_with_its_name():
    start = find_collocation_orbit(rotor(), (np.array([0.0, 0.6]), 10.0), turns={"phi_0": 1}, ntst=4)
    with pytest.raises(SystemDefinitionError, match="no parameter 'J'"):
        continue_collocation_orbits(start, "J")
    with pytest.raises(ValueError, match="ncol"):
        find_collocation_orbit(rotor(), start, ncol=9)
    with pytest.raises(ValueError, match="period"):
        find_collocation_orbit(rotor(), (np.array([0.0, 0.6]), -1.0), turns={"phi_0": 1})


def junction_rotation(system):
    from cosserat_chain.numerics.shooting import find_orbit, settled_guess

    drift = system.parameter("I") / system.parameter("alpha")
    guess = settled_guess(system, np.concatenate([np.zeros(3), np.full(3, drift)]), coordinate=0)
    return find_orbit(system, guess, turns=dict.fromkeys(system.coordinates, 1))


@pytest.mark.slow
def test_junction_orbit_equals_shooting():
    shooting = junction_rotation(jj3(I=0.8))
    orbit = find_collocation_orbit(shooting.system, shooting, ntst=40)
    assert orbit.period == pytest.approx(shooting.period, abs=AGREE)
    assert orbit.trivial_multiplier_error < AGREE
    assert np.max(np.abs(np.sort_complex(orbit.multipliers) - np.sort_complex(shooting.multipliers))) < AGREE


@pytest.mark.slow
def test_junction_snake_through_auto07p_folds_and_period_doublings():
    # AUTO-07p's folds where its two meshes (NTST = 100, 200) agree to their printed digits: the first eight. Single
    # shooting reaches three (its monodromy's trivial multiplier is lost at T = 32.4); collocation on 200 intervals
    # locates and confirms all eight, to period 53.6, each by a double multiplier at +1 (split by the discretisation).
    auto = json.loads(AUTO_SNAKE.read_text())
    coarse, fine = (auto[f"ntst{n}"]["folds"] for n in (100, 200))
    agreed = [b["I"] for a, b in zip(coarse, fine, strict=False) if abs(a["I"] - b["I"]) < 1e-10]
    assert len(agreed) >= 8
    shooting = junction_rotation(jj3())
    start = find_collocation_orbit(shooting.system, shooting, ntst=200)
    branch = continue_collocation_orbits(start, "I", through_folds=True, period_max=56.0, max_points=2000)
    folds = [e for e in branch.events if e["kind"] == "fold"]
    assert len(folds) == 8 and all(e["located"] for e in folds)
    assert np.allclose([e["moment"] for e in folds], agreed[:8], rtol=0.0, atol=AUTO_DIGITS)
    for event in folds:
        assert second_multiplier_at_one(event["orbit"].multipliers)
    # Between the folds the trivial multiplier is 1 to 1e-5 (at a fold the double one splits like the root of the error).
    assert min(o.trivial_multiplier_error for o in branch.orbits if o.period > 45.0) < 1e-5
    # AUTO-07p's five period doublings before the first fold (its only PD labels), in the same order.
    doublings = [e["moment"] for e in branch.events if e["kind"] == "period_doubling"]
    assert np.allclose(doublings[:5], [0.93171808563, 0.67728400426, 0.54097375857, 0.53370515518, 0.53147837059], atol=AUTO_DIGITS)
