"""User systems: the pen demo against SciPy, lattices from formulas against hand-written ones and closed forms,
the paper's chain through the same interface against the package's own chain machinery."""

from __future__ import annotations

import math
import warnings
from pathlib import Path

import numpy as np
import pytest
from scipy.integrate import solve_ivp
from scipy.optimize import fsolve

from conftest import SYSTEMS_CACHE
from cosserat_chain.numerics import equilibria, shooting
from cosserat_chain.params import ChainParams
from cosserat_chain.systems import (
    ApproximateJacobianWarning,
    LatticeSystem,
    System,
    SystemDefinitionError,
    frenkel_kontorova,
    josephson_array,
    load_system,
    pen,
    takeno_peyrard,
)
from cosserat_chain.systems.chain import ChainSystem


@pytest.fixture(autouse=True)
def _cache(monkeypatch):
    """The compiled systems go to the tests' cache folder, not the user's."""
    monkeypatch.setenv("COSSERAT_CHAIN_CACHE", str(SYSTEMS_CACHE))


# -- the pen demo against an independent SciPy shooting --------------------------------------------------

GAMMA, EPS = 0.175, 0.1


def _pen_field(t, z, current):
    p1, p2, v1, v2 = z[:4]
    out = [v1, v2, -EPS * v1 - math.sin(p1) + current + GAMMA * (p2 - p1), -EPS * v2 - math.sin(p2) + current + GAMMA * (p1 - p2)]
    if len(z) > 4:
        jac = np.array([[0, 0, 1, 0], [0, 0, 0, 1], [-math.cos(p1) - GAMMA, GAMMA, -EPS, 0], [GAMMA, -math.cos(p2) - GAMMA, 0, -EPS]])
        out += list((jac @ z[4:].reshape(4, 4)).ravel())
    return out


def _scipy_in_phase_orbit(current: float):
    """(phi_2, v_1, v_2, T) at the section phi_1 = 0 of the in-phase rotation, by fsolve on SciPy's DOP853."""

    def closure(u):
        p2, v1, v2, period = u
        end = solve_ivp(_pen_field, (0, period), [0, p2, v1, v2], method="DOP853", rtol=1e-13, atol=1e-13, args=(current,)).y[:, -1]
        return [end[0] - 2 * math.pi, end[1] - p2 - 2 * math.pi, end[2] - v1, end[3] - v2]

    rate = current / EPS
    return fsolve(closure, [0.0, rate, rate, 2 * math.pi / rate], xtol=1e-13)


def _scipy_multipliers(current: float, u) -> np.ndarray:
    p2, v1, v2, period = u
    start = [0, p2, v1, v2, *np.eye(4).ravel()]
    end = solve_ivp(_pen_field, (0, period), start, method="DOP853", rtol=1e-13, atol=1e-13, args=(current,)).y[:, -1]
    return np.linalg.eigvals(end[4:].reshape(4, 4))


def test_pen_in_phase_rotation_period_at_I_04_equals_scipy_shooting(pen_in_phase_orbit):
    reference = _scipy_in_phase_orbit(0.4)
    assert pen_in_phase_orbit.period == pytest.approx(reference[3], abs=1e-9)
    assert pen_in_phase_orbit.closure <= shooting.CLOSURE_TOL
    # In phase: the two pendula move together, and the Floquet multipliers are SciPy's.
    assert pen_in_phase_orbit.q0[0] - pen_in_phase_orbit.q0[1] == pytest.approx(0.0, abs=1e-9)
    mine = np.sort(np.abs(pen_in_phase_orbit.multipliers))
    theirs = np.sort(np.abs(_scipy_multipliers(0.4, reference)))
    np.testing.assert_allclose(mine, theirs, atol=1e-8)


def test_pen_period_doubling_in_I_equals_scipy(pen_in_phase_branch):
    assert pen_in_phase_branch.end == "period_doubling"
    located = [e for e in pen_in_phase_branch.events if e.kind == "period_doubling"][0]

    def test(current):
        return float(np.real(np.prod(_scipy_multipliers(current, _scipy_in_phase_orbit(current)) + 1.0)))

    # SciPy's test function changes sign within 1e-9 of the located doubling: its root, the reference, lies there.
    below, above = (test(located.parameter + side * 1e-9) for side in (-1, 1))
    assert below * above < 0
    # A multiplier sits at -1 there, and the orbit was stable above and is unstable below.
    assert np.min(np.abs(located.point.multipliers + 1)) < 1e-6
    assert pen_in_phase_branch.orbits[0].stable and not pen_in_phase_branch.orbits[-1].stable


def test_pen_period_against_I_equals_scipy(pen_in_phase_branch):
    for orbit in pen_in_phase_branch.orbits[1::12]:
        current = orbit.parameter("I")
        assert orbit.period == pytest.approx(_scipy_in_phase_orbit(current)[3], abs=1e-9), current


# -- lattices from formulas ------------------------------------------------------------------------------


class HandWritten(System):
    """A two-dof lattice written by hand in NumPy (forces only: the base class's finite differences stand in)."""

    name = "hand-written"

    def __init__(self, sites, boundary, **parameters):
        super().__init__(parameters)
        self.sites, self.boundary = sites, boundary

    @property
    def coordinates(self):
        return tuple(f"{d}_{i}" for i in range(self.sites) for d in ("u", "phi"))

    @property
    def angles(self):
        return np.tile([False, True], self.sites)

    def _bonds(self):
        n = self.sites
        if self.boundary == "free":
            return [(i, i + 1) for i in range(n - 1)]
        if self.boundary == "periodic":
            return [(i, (i + 1) % n) for i in range(n)]
        return [(-1, 0)] + [(i, i + 1) for i in range(n - 1)] + [(n - 1, -1)]

    def forces(self, q):
        p = self.parameters
        u, phi = q[0::2], q[1::2]
        f = np.zeros_like(q)
        f[0::2] += -p["k0"] * u - p["c"] * u**3
        f[1::2] += -p["w"] * np.sin(phi) + p["T"]
        for left, right in self._bonds():
            ul, pl = (u[left], phi[left]) if left >= 0 else (0.0, 0.0)
            ur, pr = (u[right], phi[right]) if right >= 0 else (0.0, 0.0)
            # E_b = k/2 (ur - ul)^2 + g (1 - cos(pr - pl)) + e ul sin(pr)
            fl = (p["k"] * (ur - ul) - p["e"] * math.sin(pr), p["g"] * math.sin(pr - pl))
            fr = (-p["k"] * (ur - ul), -p["g"] * math.sin(pr - pl) - p["e"] * ul * math.cos(pr))
            if left >= 0:
                f[2 * left] += fl[0]
                f[2 * left + 1] += fl[1]
            if right >= 0:
                f[2 * right] += fr[0]
                f[2 * right + 1] += fr[1]
        return f

    def mass(self):
        return np.tile([self.parameters["m"], 1.0], self.sites)

    def damping(self):
        return np.tile([0.0, self.parameters["gamma"]], self.sites)


def _formula_twin(sites, boundary, parameters):
    return LatticeSystem(
        sites=sites,
        dofs=("u", "phi"),
        site_energy="k0*u**2/2 + c*u**4/4 + w*(1 - cos(phi))",
        bond_energy="k/2*(u_r - u_l)**2 + g*(1 - cos(phi_r - phi_l)) + e*u_l*sin(phi_r)",
        site_force={"phi": "T"},
        mass={"u": "m", "phi": 1},
        damping={"u": 0, "phi": "gamma"},
        boundary=boundary,
        parameters=parameters,
    )


@pytest.mark.parametrize("boundary", ["free", "periodic", "fixed"])
@pytest.mark.parametrize("sites", [1, 3, 8])
def test_a_lattice_from_formulas_equals_a_hand_written_one_and_its_jacobians_equal_finite_differences(sites, boundary):
    if boundary == "periodic" and sites < 3:
        pytest.skip("a ring needs three sites")
    rng = np.random.default_rng(sites * 7 + len(boundary))
    parameters = {name: float(rng.uniform(0.3, 2.0)) for name in ("k0", "c", "w", "T", "k", "g", "e", "m", "gamma")}
    formulas = _formula_twin(sites, boundary, parameters)
    hand = HandWritten(sites, boundary, **parameters)
    q = rng.normal(size=2 * sites)
    assert formulas.coordinates == hand.coordinates
    np.testing.assert_allclose(formulas.forces(q), hand.forces(q), rtol=1e-13, atol=1e-13)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ApproximateJacobianWarning)
        fd_jacobian = hand.force_jacobian(q).toarray()
        for name in parameters:
            if name in ("m", "gamma"):
                continue
            np.testing.assert_allclose(formulas.parameter_forces(q, name), hand.parameter_forces(q, name), atol=1e-8)
    np.testing.assert_allclose(formulas.force_jacobian(q).toarray(), fd_jacobian, atol=1e-8)
    np.testing.assert_allclose(formulas.mass(), hand.mass())
    np.testing.assert_allclose(formulas.damping(), hand.damping())
    # A site torque makes it non-conservative: no energy. Without it, -dE/dq = F.
    assert formulas.energy(q) is None
    conservative = LatticeSystem(
        sites=sites,
        dofs=("u", "phi"),
        site_energy="k0*u**2/2 + c*u**4/4 + w*(1 - cos(phi))",
        bond_energy="k/2*(u_r - u_l)**2 + g*(1 - cos(phi_r - phi_l)) + e*u_l*sin(phi_r)",
        boundary=boundary,
        parameters={k: v for k, v in parameters.items() if k not in ("T", "m", "gamma")},
    )
    step = 1e-6
    gradient = [(conservative.energy(q + step * e) - conservative.energy(q - step * e)) / (2 * step) for e in np.eye(2 * sites)]
    np.testing.assert_allclose(-np.array(gradient), conservative.forces(q), atol=1e-8)
    jac = conservative.force_jacobian(q).toarray()
    np.testing.assert_allclose(jac, jac.T, atol=1e-13)


def test_a_plain_numpy_system_runs_through_the_same_orbit_machinery_with_a_warning():
    """The SciPy fallback flow and finite-difference Jacobians give the compiled system's orbit."""
    parameters = {"k0": 1.0, "c": 0.5, "w": 1.0, "T": 1.5, "k": 0.4, "g": 0.3, "e": 0.2, "m": 1.3, "gamma": 0.5}
    compiled = _formula_twin(1, "fixed", parameters)
    hand = HandWritten(1, "fixed", **parameters)
    guess = shooting.settled_guess(compiled, np.zeros(2 * 1 * 2), coordinate="phi_0", transient=100.0, window=50.0, samples=1000)
    mine = shooting.find_orbit(compiled, guess, turns={"phi_0": 1})
    with pytest.warns(ApproximateJacobianWarning):
        theirs = shooting.find_orbit(hand, guess, turns={"phi_0": 1}, tol=1e-8)
    assert theirs.period == pytest.approx(mine.period, abs=1e-7)


def test_linear_bands_of_the_builtin_lattices_equal_their_closed_forms():
    n = 12
    wave = np.sin(np.pi * np.arange(n) / n) ** 2
    cases = [
        (takeno_peyrard(n, C=0.7, boundary="periodic"), np.zeros(n), 1 + 4 * 0.7 * wave),
        (frenkel_kontorova(n, C=1.9, V=0.6, boundary="periodic"), np.zeros(n), 0.6 + 4 * 1.9 * wave),
        (josephson_array(n, I=0.3, kappa=2.5, boundary="periodic"), np.full(n, math.asin(0.3)), math.sqrt(1 - 0.09) + 4 * 2.5 * wave),
    ]
    for system, rest, band in cases:
        assert np.max(np.abs(system.forces(rest))) < 1e-14
        squared = np.linalg.eigvalsh(-system.force_jacobian(rest).toarray())
        np.testing.assert_allclose(np.sort(squared), np.sort(band), atol=1e-12, err_msg=system.name)


# Frenkel-Kontorova in the quick suite, Takeno-Peyrard (the same convergence with another coupling) with the slow tests.
@pytest.mark.parametrize("make", [pytest.param(takeno_peyrard, marks=pytest.mark.slow), frenkel_kontorova])
def test_static_kinks_converge_to_the_sine_gordon_kink_at_first_order_in_1_over_C(make):
    """Energy 8 sqrt(C) and profile 4 arctan exp(i / sqrt(C)) of the continuum kink, errors O(1/C)."""
    errors = []
    for coupling in (4.0, 16.0, 64.0):
        n = int(30 * math.sqrt(coupling)) | 1
        system = make(n, C=coupling)
        position = np.arange(n) - (n - 1) / 2 + 0.5
        continuum = 4 * np.arctan(np.exp(position / math.sqrt(coupling)))
        kink = equilibria.find_equilibrium(system, continuum)
        assert kink.q[-1] - kink.q[0] == pytest.approx(2 * math.pi, abs=1e-5)
        assert np.max(np.abs(kink.q - continuum)) < 2.0 / coupling
        errors.append(system.energy(kink.q) / (8 * math.sqrt(coupling)) - 1)
    ratios = [errors[0] / errors[1], errors[1] / errors[2]]
    assert all(3.5 < r < 5.0 for r in ratios), (errors, ratios)


def test_the_uniform_state_of_a_josephson_array_folds_at_I_1():
    """With free ends the uniform state has no coupling force: sin phi = I, a fold at I = 1."""
    system = josephson_array(5, I=0.0, kappa=0.8)
    start = equilibria.find_equilibrium(system, np.zeros(5))
    assert start.stable
    branch = equilibria.continue_equilibria(start, "I", direction=1.0, step=0.05, max_step=0.1)
    assert branch.end == "fold"
    assert branch.folds()[0] == pytest.approx(1.0, abs=1e-9)
    assert all(point.stable for point in branch.points[:-1])


def test_a_circulatory_force_loses_stability_at_the_closed_form_hopf_point():
    """M q'' = -K q + P [[0, 1], [-1, 0]] q - c q': flutter where P^2 = ((k1 - k2)/2)^2 + c^2 (k1 + k2)/2."""
    k1, k2, c = 1.0, 1.6, 0.2
    system = LatticeSystem(
        sites=1,
        dofs=("x", "y"),
        site_energy="k1*x**2/2 + k2*y**2/2",
        site_force={"x": "P*y", "y": "-P*x"},
        damping="c",
        parameters={"k1": k1, "k2": k2, "c": c, "P": 0.0},
    )
    start = equilibria.find_equilibrium(system, np.zeros(2))
    branch = equilibria.continue_equilibria(start, "P", step=0.05, max_step=0.1, stop_at=("hopf",))
    assert branch.end == "hopf"
    hopf = [e for e in branch.events if e.kind == "hopf"][0]
    assert hopf.parameter == pytest.approx(math.sqrt(((k1 - k2) / 2) ** 2 + c**2 * (k1 + k2) / 2), abs=1e-9)
    assert branch.points[0].stable and not branch.points[-1].stable


def test_the_chain_through_the_system_interface_equals_the_chain_machinery():
    """The paper's sine chain (N = 1) as a ChainSystem: the generic orbit and fold equal find_periodic_orbit's and
    continue_in_moment's."""
    from cosserat_chain.numerics.continuation import continue_in_moment
    from cosserat_chain.numerics.periodic import _to_y, find_periodic_orbit

    params = ChainParams(N=1)
    system = ChainSystem(params, "sine", M=1.0)
    assert system.coordinates == ("u_0", "v_0", "phi_0")
    reference = find_periodic_orbit(params, "sine", 1.0)
    guess = (_to_y(params, reference.x, reference.v) + 1e-4, reference.period * 1.001)
    orbit = shooting.find_orbit(system, guess, turns={"phi_0": 1})
    assert orbit.period == pytest.approx(reference.period, abs=1e-9)
    np.testing.assert_allclose(np.sort(np.abs(orbit.multipliers)), np.sort(np.abs(reference.multipliers)), atol=1e-7)
    start = equilibria.find_equilibrium(system.with_parameters(M=0.1), np.zeros(3))
    branch = equilibria.continue_equilibria(start, "M")
    assert branch.folds()[0] == pytest.approx(continue_in_moment(params, "sine").folds[0].moment, abs=1e-10)


def test_bad_systems_are_refused_with_messages_that_name_the_field():
    with pytest.raises(SystemDefinitionError, match="site_energy uses unknown names \\['K'\\]"):
        LatticeSystem(sites=3, site_energy="K*(1 - cos(phi))")
    with pytest.raises(SystemDefinitionError, match="sites must be an integer >= 1"):
        LatticeSystem(sites=0)
    with pytest.raises(SystemDefinitionError, match="at least 3 sites"):
        LatticeSystem(sites=2, boundary="periodic")
    with pytest.raises(SystemDefinitionError, match="boundary must be one of"):
        LatticeSystem(sites=2, boundary="open")
    with pytest.raises(SystemDefinitionError, match="has no parameter 'J'"):
        pen().with_parameters(J=1.0)
    with pytest.raises(SystemDefinitionError, match="mass of every degree of freedom must be > 0"):
        pen().with_parameters().__class__(sites=2, mass="-m", parameters={"m": 1.0}).mass()
    with pytest.raises(SystemDefinitionError, match="shape \\(2,\\)"):
        pen().forces(np.zeros(3))
    with pytest.raises(ValueError, match="only angles can turn"):
        shooting.turns_vector(frenkel_kontorova(3).__class__(sites=1, dofs=("u",), angles=()), {"u_0": 1})
    with pytest.raises(SystemDefinitionError, match="built-in"):
        load_system("nonsense")
    with pytest.raises(SystemDefinitionError, match="check the \\[system\\] parameters"):
        load_system("pen", {"current": 0.3})


def test_systems_load_by_name_module_or_file(tmp_path):
    assert load_system("pen", {"I": 0.3}).parameter("I") == 0.3
    assert load_system("cosserat_chain.systems.takeno_peyrard:takeno_peyrard", {"sites": 4}).size == 4
    user = tmp_path / "mine.py"
    user.write_text(
        "from cosserat_chain.systems import LatticeSystem\n"
        "def rotors(sites=3, K=1.0):\n"
        "    return LatticeSystem(sites=sites, site_energy='K*(1 - cos(phi))', parameters={'K': K}, name='rotors')\n"
    )
    system = load_system(f"{user}:rotors", {"sites": 5, "K": 2.0})
    assert system.name == "rotors" and system.size == 5
    np.testing.assert_allclose(system.forces(np.full(5, 0.5)), -2.0 * np.sin(0.5))


def test_in_phase_pen_orbits_equal_the_sine_chain_N1_in_pendulum_units(pen_in_phase_orbit):
    """With clamped neighbours the loaded particle of the N = 1 sine chain (eq. (2)) is one pendulum,
    j phi'' + gamma_phi phi' + K sin phi = M with K = 4 b^2 (E1 + h^2 E2 / d^2): in the time sqrt(j / K) it is
    the in-phase pen orbit at I = M / K, eps = gamma_phi / sqrt(j K). The chain's own shooting agrees."""
    from cosserat_chain.numerics.periodic import find_periodic_orbit
    from cosserat_chain.state import zeros

    params = ChainParams(N=1, a=0.17, b=0.23, E1=1.3, E2=0.8)
    d2 = (params.h - 2 * params.a) ** 2 + 4 * params.b**2
    stiffness = 4 * params.b**2 * (params.E1 + params.h**2 * params.E2 / d2)
    params = params.replace(gamma_phi=0.1 * math.sqrt(params.j * stiffness))
    unit = math.sqrt(params.j / stiffness)
    x, v = zeros(params), zeros(params)
    v[2, 1] = pen_in_phase_orbit.v0[0] / unit
    chain = find_periodic_orbit(params, "sine", 0.4 * stiffness, guess=(x, v, pen_in_phase_orbit.period * unit))
    assert chain.period / unit == pytest.approx(pen_in_phase_orbit.period, abs=1e-9)


def test_a_takeno_peyrard_rotobreather_from_the_anti_continuum_limit_is_an_orbit_of_the_undamped_chain():
    """Conservative orbits by the unfolding: at C = 0 one rotor turns with the closed-form energy of the
    rotating pendulum of that period; continued in C its orbits close under the undamped flow itself."""
    from scipy.integrate import quad

    n, energy = 7, 3.0
    period = 2 * quad(lambda p: 1 / math.sqrt(2 * (energy - 1 + math.cos(p))), 0, math.pi, epsabs=1e-13, epsrel=1e-13)[0]
    system = takeno_peyrard(n, C=0.0)
    y0 = np.zeros(2 * n)
    y0[n + 3] = math.sqrt(2 * energy)
    orbit = shooting.find_orbit(system, (y0 + 1e-3, period), turns={"phi_3": 1}, unfold="gamma")
    assert abs(orbit.unfolding) < 1e-10
    assert orbit.period == period
    rotor = 0.5 * orbit.v0[3] ** 2 + 1 - math.cos(orbit.q0[3])
    assert rotor == pytest.approx(energy, abs=1e-9)
    assert np.max(np.abs(np.abs(orbit.nontrivial_multipliers) - 1)) < 1e-6
    family = shooting.continue_orbits(orbit, "C", direction=1, limits=(0.0, 0.15), stop_at=(), step=0.02, max_step=0.05)
    assert family.end == "parameter_limit" and family.values[-2] > 0.1
    shift = np.zeros(2 * n)
    shift[3] = 2 * math.pi
    for member in family.orbits[1::3]:
        undamped = member.system.with_parameters(gamma=0.0)
        end = shooting.flow(undamped, member.y0, member.period, variations=False)[0]
        assert np.max(np.abs(end - member.y0 - shift)) < 1e-8
        assert abs(member.unfolding) < 1e-10
    with pytest.raises(ValueError, match="needs an orbit found with unfold"):
        shooting.continue_orbits(shooting.find_orbit(pen(), (np.array([0, 0, 4.2, 4.2]), 1.57), turns={"phi_0": 1, "phi_1": 1}), "period")


def test_a_runaway_flow_fails_within_its_step_budget_instead_of_grinding():
    """A Newton trial into a blow-up (a strong negative damping) is refused by the flow's budget of steps per time."""
    from cosserat_chain.numerics.kit import EvaluationFailed

    runaway = josephson_array(3, I=0.0, alpha=-50.0)
    with pytest.raises(EvaluationFailed, match="failed"):
        shooting.flow(runaway, np.array([0.1, 0.0, -0.1, 1.0, 0.0, 0.0]), 50.0, variations=False)
    ring = josephson_array(5, kappa=0.3).with_boundary("periodic")
    assert ring.boundary == "periodic" and ring.force_jacobian(np.zeros(5)).nnz == 15
    with pytest.raises(SystemDefinitionError, match="boundary must be one of"):
        ring.with_boundary("open")


def test_the_index_of_a_long_josephson_array_is_the_closed_form_count_of_its_soft_modes():
    """Past the dense limit the index is the inertia of -J: at the uniform state phi = pi - arcsin I of a free
    array, -J = -sqrt(1 - I^2) + kappa L, so the index counts the modes with 4 kappa sin^2(pi k / 2n) < sqrt(1 - I^2)."""
    n, current, kappa = 700, 0.5, 1.0
    assert n > equilibria.DENSE_LIMIT
    system = josephson_array(n, I=current, kappa=kappa)
    top = equilibria.find_equilibrium(system, np.full(n, math.pi - math.asin(current)))
    k = np.arange(n)
    assert top.index == int(np.sum(4 * kappa * np.sin(np.pi * k / (2 * n)) ** 2 < math.sqrt(1 - current**2)))
    assert top.index > 100 and not top.stable
    bottom = equilibria.find_equilibrium(system, np.full(n, math.asin(current)))
    assert bottom.index == 0 and bottom.stable
    ring = equilibria.find_equilibrium(system.with_boundary("periodic"), np.full(n, math.asin(current)))
    assert ring.stable is None and ring.index is None  # a ring's corners: not banded, not claimed


def test_generated_code_is_never_imported_from_a_folder_others_may_write(tmp_path, monkeypatch):
    """The compiled system's source is imported: a cache folder writable by others is refused (it would let
    anyone plant code), and the message says what to do. In a private folder the module is imported from there (its
    kernels, compiled at first use, compute what every other system test checks: no call here compiles them afresh)."""
    import os

    from cosserat_chain.systems import lattice

    shared = tmp_path / "shared"
    (shared / "systems").mkdir(parents=True)
    os.chmod(shared / "systems", 0o777)
    monkeypatch.setenv("COSSERAT_CHAIN_CACHE", str(shared))
    monkeypatch.setattr(lattice.tempfile, "gettempdir", lambda: str(shared))
    os.makedirs(shared / f"cosserat-chain-{os.getuid()}" / "systems", exist_ok=True)
    os.chmod(shared / f"cosserat-chain-{os.getuid()}" / "systems", 0o777)
    with pytest.raises(SystemDefinitionError, match="private writable cache directory"):
        LatticeSystem(sites=2, site_energy="w*(1 - cos(phi)) + 0.123456789*phi**2", parameters={"w": 1.0})
    own = tmp_path / "own"
    monkeypatch.setenv("COSSERAT_CHAIN_CACHE", str(own))
    system = LatticeSystem(sites=2, site_energy="w*(1 - cos(phi)) + 0.123456789*phi**2", parameters={"w": 1.0})
    assert oct(os.stat(own / "systems").st_mode & 0o777) == "0o700"
    module = Path(system._spec.kernels.__file__)
    assert module.parent == own / "systems" and "0.123456789" in module.read_text()


def test_an_orbits_trajectory_in_one_integration_closes_after_a_period_and_equals_the_flow(pen_in_phase_orbit):
    times = pen_in_phase_orbit.period * np.array([0.25, 0.5, 1.0])
    path = pen_in_phase_orbit.trajectory(times)
    shift = np.array([2 * math.pi, 2 * math.pi, 0.0, 0.0])
    assert np.max(np.abs(path[-1] - pen_in_phase_orbit.y0 - shift)) < 1e-8
    alone = shooting.flow(pen_in_phase_orbit.system, pen_in_phase_orbit.y0, times[0], variations=False)[0]
    np.testing.assert_allclose(path[0], alone, atol=1e-9)


def test_a_frenkel_kontorova_sliding_state_has_auto07ps_tori_and_fold_of_cycles():
    # Three particles with free ends pulled apart by springs of rest length a0 (no symmetry reduces the sliding state),
    # every particle one period a turn, followed down in F from 0.9. AUTO-07p 0.9.2 on the same equations
    # (benchmarks/auto07p_user_systems.py, NTST = 200, NCOL = 4; NTST = 100 moves the first by 1e-11) labels TR at
    # F = 0.64394622614 and 0.57916770498 and LP at 0.51128461338.
    system = frenkel_kontorova(3, C=0.61, gamma=0.29, a0=1.3, F=0.9)
    guess = shooting.settled_guess(system, np.r_[np.zeros(3), np.full(3, 0.9 / 0.29)], coordinate=0)
    orbit = shooting.find_orbit(system, guess, turns={name: 1 for name in system.coordinates})
    branch = shooting.continue_orbits(orbit, "F", limits=(0.5, 1.0))
    located = {kind: [e.parameter for e in branch.events if e.kind == kind] for kind in ("torus", "fold")}
    np.testing.assert_allclose(located["torus"], [0.64394622614, 0.57916770498], atol=1e-9)
    np.testing.assert_allclose(located["fold"], [0.51128461338], atol=1e-9)
    assert branch.end == "fold"
    # Stable above the first torus point, unstable between the two, stable again down to the fold.
    (fold,) = [e for e in branch.events if e.kind == "fold"]
    upper = branch.orbits[: fold.index]  # the orbits before the fold (after it: the unstable side)
    between = [o.stable for o in upper if 0.5802 < o.parameter("F") < 0.6429]
    outside = [o.stable for o in upper if not 0.5782 < o.parameter("F") < 0.6449]
    assert between and not any(between) and outside and all(outside)
