"""Two-site breathers and roto-breathers at small coupling against the effective-Hamiltonian (averaging) theory;
Takeno and Peyrard's rotating mode at any coupling (its own section below).

Published statement reproduced: V. Koukouloyannis and P. G. Kevrekidis, "On the stability of multibreathers
in Klein-Gordon chains", Nonlinearity 22, 2269 (2009), arXiv:0902.3990 (its abstract; the body was not
reachable from this project, so no equation or theorem number is cited; the chain's equation is written as in
D. Pelinovsky and A. Sakovich, arXiv:1111.2557, eq. (1)): in a Klein-Gordon chain

    H = sum_n [ x_n'^2 / 2 + V(x_n) + (eps / 2) (x_{n+1} - x_n)^2 ]

with a soft on-site potential (dOmega/dE < 0) and eps > 0 only two-site breathers with the excited sites
out of phase may be stable, with eps < 0 only in-phase ones; hard potentials reverse it; the exponents are
O(sqrt(eps)), estimated by MacKay's effective Hamiltonian. Here V = 1 - cos x (soft) and V = x^2 / 2 + x^4 / 4
(hard), and the package's Newton and Floquet multipliers (:func:`~cosserat_chain.numerics.shooting.find_orbit` on a user
:class:`~cosserat_chain.systems.lattice.LatticeSystem`) are held against it, sign and size.

The size is derived here (the paper's own formula was not read), from first principles, as follows. Near
the anti-continuum limit the two excited sites are oscillators h(I_1), h(I_2) in action-angle variables
(I_i, theta_i); averaged over the fast motion the bond between them is eps W(psi), psi = theta_1 - theta_2,
W(psi) = < b(x(theta), x(theta - psi)) >_theta (b the bond energy, x(theta) the lone orbit at the common
frequency Omega). H_eff = h(I_1) + h(I_2) + eps W(psi) linearized at a critical point psi_0 of W (0 or pi by
the reversibility) has, besides the double zero of the common phase, the pair

    sigma^2 = -2 eps h''(I) W''(psi_0),        h'' = dOmega/dI = Omega dOmega/dE,           (P)

(the 2 from both sites' actions: (I_1 - I_2)' = -2 eps W'(psi)), the Floquet multipliers exp(+-sigma T):
real (unstable) for sigma^2 > 0, on the circle for sigma^2 < 0. For a linear bond W''(0) = -W''(pi) =
<x'^2> / Omega^2 = I / Omega (x(theta + pi) = -x(theta) for an even V), so sigma^2 = -+ 2 eps I dOmega/dE in
phase / out of phase; Omega(E) and I(E) are closed forms in complete elliptic integrals (SymPy below, checked
against SciPy's quadrature of the period).

The same averaging holds for rotations (the theory is stated for oscillators in general periodic orbits
of a one-degree-of-freedom system: MacKay and Sepulchre's effective Hamiltonian needs only the action-angle
variables, which a rotation has; a counter-rotating partner is the mirror (x, p) -> (-x, -p), symplectic, of
a co-rotating one). Applied here to the Takeno-Peyrard lattice (bond C (1 - cos(phi_r - phi_l))): the pair
turning together in phase and out of phase, against each other in phase and out of phase. This application
is ours, not published; W'' comes from an FFT of the lone pendulum's rotation run by SciPy, independent of
the package's shooting.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
import sympy as sp
from scipy.integrate import quad, solve_ivp
from scipy.optimize import brentq
from scipy.special import ellipe, ellipk

from cosserat_chain.experiments.system_breathers import roto_breather_family
from cosserat_chain.numerics.shooting import find_orbit
from cosserat_chain.systems import takeno_peyrard
from cosserat_chain.systems.lattice import LatticeSystem

SITES, A, B = 10, 4, 5  # the excited pair: sites 4 and 5 of 10, free ends
SAMPLES = 256  # of the lone orbit, for W(psi)
COUPLINGS = (0.000625, 0.00125, 0.0025, 0.005, 0.01)

# -- the single oscillator: closed forms (SymPy) and the lone orbit (SciPy) ------------------------------------

_A = sp.symbols("A", positive=True)
#: The three oscillators, each in a parameter A: (force, Omega(A), E(A), I(A) or None, range of A). The pendulum
#: p^2 / 2 + 1 - cos x librating (A = E < 2, m = E / 2) or turning (A = E > 2, m = 2 / E), and the hard Duffing
#: oscillator p^2 / 2 + x^2 / 2 + x^4 / 4 of amplitude A (m = A^2 / (2 (1 + A^2))).
KINDS = {
    "libration": (
        math.sin, sp.pi / (2 * sp.elliptic_k(_A / 2)), _A,
        8 / sp.pi * (sp.elliptic_e(_A / 2) - (1 - _A / 2) * sp.elliptic_k(_A / 2)), (1e-12, 2 - 1e-14),
    ),
    "rotation": (
        math.sin, sp.pi * sp.sqrt(2 * _A) / (2 * sp.elliptic_k(2 / _A)), _A,
        2 * sp.sqrt(2 * _A) * sp.elliptic_e(2 / _A) / sp.pi, (2 + 1e-14, 1e4),
    ),
    "duffing": (
        lambda x: x + x**3, sp.pi * sp.sqrt(1 + _A**2) / (2 * sp.elliptic_k(_A**2 / (2 * (1 + _A**2)))),
        _A**2 / 2 + _A**4 / 4, None, (1e-8, 1e3),
    ),
}  # fmt: skip


def _numeric(expr):
    return sp.lambdify(_A, expr, modules="mpmath")


def parameter(omega: float, kind: str) -> float:
    """A of the orbit of frequency omega (for the pendulum its energy), from SciPy's K."""
    if kind == "libration":
        return brentq(lambda e: 4 * ellipk(e / 2) - 2 * math.pi / omega, 1e-12, 2 - 1e-14, xtol=1e-15, rtol=1e-15)
    if kind == "rotation":
        return brentq(lambda e: 4 * ellipk(2 / e) / math.sqrt(2 * e) - 2 * math.pi / omega, 2 + 1e-14, 1e4, xtol=1e-15, rtol=1e-15)
    period = lambda a: 4 * ellipk(a * a / (2 * (1 + a * a))) / math.sqrt(1 + a * a)  # noqa: E731
    return brentq(lambda a: period(a) - 2 * math.pi / omega, 1e-8, 1e3, xtol=1e-15, rtol=1e-15)


def energy(omega: float, kind: str) -> float:
    return float(_numeric(KINDS[kind][2])(parameter(omega, kind)))


def frequency_slope(omega: float, kind: str) -> float:
    """dOmega/dE from SymPy's derivatives of the closed forms."""
    _, freq, en, _, _ = KINDS[kind]
    return float(_numeric(sp.diff(freq, _A) / sp.diff(en, _A))(parameter(omega, kind)))


def action(omega: float, kind: str) -> float:
    return float(_numeric(KINDS[kind][3])(parameter(omega, kind)))


def lone_orbit(omega: float, kind: str) -> np.ndarray:
    """(x, x') of the lone oscillator at SAMPLES equal steps of one period, from x' = 0 (libration) or x = 0 (rotation)."""
    force, period = KINDS[kind][0], 2 * math.pi / omega
    e = energy(omega, kind)
    if kind == "rotation":
        start = [0.0, math.sqrt(2 * e)]
    else:
        start = [math.acos(1 - e) if kind == "libration" else parameter(omega, kind), 0.0]
    t = np.arange(SAMPLES) * period / SAMPLES
    run = solve_ivp(lambda _, y: [y[1], -force(y[0])], (0, period), start, method="DOP853", rtol=1e-13, atol=1e-13, t_eval=t)
    return run.y


def phase_curvature(x: np.ndarray, bond, psi0: float) -> float:
    """W''(psi0) of W(psi) = < bond(x(theta), x(theta - psi)) >: W at every shift of the samples, differentiated by FFT."""
    w = np.array([np.mean(bond(x, np.roll(x, j))) for j in range(SAMPLES)])
    c = np.fft.rfft(w) / SAMPLES
    n = np.arange(c.size)
    weight = np.where((n == 0) | (n == SAMPLES // 2), 1.0, 2.0)
    return float(np.sum(-(n**2) * weight * np.real(c * np.exp(1j * n * psi0))))


def predicted_square(eps: float, omega: float, kind: str, curvature: float) -> float:
    """sigma^2 of (P)."""
    return -2 * eps * omega * frequency_slope(omega, kind) * curvature


# -- the package's orbits --------------------------------------------------------------------------------------


SITE_ENERGY = {"libration": "1 - cos(x)", "duffing": "x**2/2 + x**4/4"}
FREQUENCY = {"libration": 0.8, "duffing": 1.2, "rotation": 1.3}  # 3 Omega above the band / Omega above it (both V even)


def klein_gordon(kind: str, eps: float) -> LatticeSystem:
    return LatticeSystem(
        sites=SITES, dofs=("x",), site_energy=SITE_ENERGY[kind], bond_energy="C*(x_r - x_l)**2/2", damping="gamma",
        parameters={"C": eps, "gamma": 0.0}, name=f"klein_gordon_{kind}",
    )  # fmt: skip


def anti_continuum(omega: float, kind: str, psi0: float, counter: bool) -> np.ndarray:
    """Site A at theta = 0, site B at theta = -psi0 (0 or pi; mirrored with ``counter``), the others at rest."""
    e = energy(omega, kind)
    if kind == "rotation":
        states = {0.0: (0.0, math.sqrt(2 * e)), math.pi: (-math.pi, math.sqrt(2 * (e - 2)))}
    else:
        amplitude = math.acos(1 - e) if kind == "libration" else parameter(omega, kind)
        states = {0.0: (amplitude, 0.0), math.pi: (-amplitude, 0.0)}
    y0 = np.zeros(2 * SITES)
    y0[A], y0[SITES + A] = states[0.0]
    sign = -1.0 if counter else 1.0
    y0[B], y0[SITES + B] = (sign * s for s in states[psi0])
    return y0


def pair_orbits(kind: str, psi0: float, counter: bool, couplings) -> list:
    """Newton at each coupling in turn, from the anti-continuum state and then from the last orbit."""
    omega, rotation = FREQUENCY[kind], kind == "rotation"
    y0, turns = anti_continuum(omega, kind, psi0, counter), ({A: 1, B: -1 if counter else 1} if rotation else None)
    orbits = []
    for eps in couplings:
        system = takeno_peyrard(SITES, C=eps) if rotation else klein_gordon(kind, eps)
        orbit = find_orbit(system, (y0, 2 * math.pi / omega), turns=turns, unfold="gamma")
        orbits.append(orbit)
        y0 = orbit.y0
    return orbits


def measured_exponent(orbit) -> tuple[float, bool]:
    """sigma T of the nontrivial pair nearest +1 and whether it is real (off the circle): |log mu| and the sector."""
    mu = orbit.nontrivial_multipliers
    pair = mu[np.argsort(np.abs(np.log(mu)))[:2]]
    assert abs(pair[0] * pair[1] - 1) < 1e-7  # a symplectic pair mu, 1 / mu (real) or mu, conj(mu) (on the circle)
    real = bool(np.all(np.abs(pair.imag) < 1e-9))
    return float(np.max(np.abs(np.log(pair).real if real else np.log(pair).imag))), real


CASES = {
    # name: (kind, psi0, counter, coupling sign)
    "Klein-Gordon soft V, in phase, eps > 0": ("libration", 0.0, False, 1.0),
    "Klein-Gordon soft V, out of phase, eps > 0": ("libration", math.pi, False, 1.0),
    "Klein-Gordon soft V, in phase, eps < 0": ("libration", 0.0, False, -1.0),
    "Klein-Gordon soft V, out of phase, eps < 0": ("libration", math.pi, False, -1.0),
    "Klein-Gordon hard V, in phase, eps > 0": ("duffing", 0.0, False, 1.0),
    "Klein-Gordon hard V, out of phase, eps > 0": ("duffing", math.pi, False, 1.0),
    "rotors together, in phase": ("rotation", 0.0, False, 1.0),
    "rotors together, out of phase": ("rotation", math.pi, False, 1.0),
    "rotors against each other, in phase": ("rotation", 0.0, True, 1.0),
    "rotors against each other, out of phase": ("rotation", math.pi, True, 1.0),
}


def bond_of(kind: str, counter: bool):
    if kind != "rotation":
        return lambda a, b: (a - b) ** 2 / 2
    sign = -1.0 if counter else 1.0  # the mirrored partner: phi_B = -Phi
    return lambda a, b: 1 - np.cos(a - sign * b)


def comparison(name: str, couplings=COUPLINGS) -> list[tuple[float, float, float, bool, bool]]:
    """(eps, measured sigma T, predicted sigma T, measured real, predicted real) at each coupling."""
    kind, psi0, counter, sign = CASES[name]
    omega = FREQUENCY[kind]
    curvature = phase_curvature(lone_orbit(omega, kind)[0], bond_of(kind, counter), psi0)
    epss = [sign * c for c in couplings]
    rows = []
    for eps, orbit in zip(epss, pair_orbits(kind, psi0, counter, epss), strict=True):
        square = predicted_square(eps, omega, kind, curvature)
        measured, real = measured_exponent(orbit)
        rows.append((eps, measured, math.sqrt(abs(square)) * orbit.period, real, square > 0))
    return rows


# -- tests -----------------------------------------------------------------------------------------------------


def test_effective_hamiltonian_pair_is_sigma_squared_minus_2_eps_h2_w2():
    """(P) from H_eff = h(I_1) + h(I_2) + eps W(theta_1 - theta_2) linearized at a critical point of W (SymPy)."""
    i1, i2, t1, t2, eps, h2, w2, lam = sp.symbols("I1 I2 theta1 theta2 epsilon h2 w2 lambda")
    psi = t1 - t2
    h = sp.Function("h")
    hamiltonian = h(i1) + h(i2) + eps * w2 * psi**2 / 2  # W near psi0, up to a constant
    z = [t1, t2, i1, i2]
    field = [sp.diff(hamiltonian, i1), sp.diff(hamiltonian, i2), -sp.diff(hamiltonian, t1), -sp.diff(hamiltonian, t2)]
    jac = sp.Matrix(field).jacobian(z).subs({sp.Derivative(h(i1), (i1, 2)): h2, sp.Derivative(h(i2), (i2, 2)): h2})
    poly = sp.factor(jac.charpoly(lam).as_expr())
    assert sp.simplify(poly - lam**2 * (lam**2 + 2 * eps * h2 * w2)) == 0


@pytest.mark.parametrize("kind", list(KINDS))
def test_single_oscillator_closed_forms_against_scipy(kind):
    """Omega and I (SymPy's elliptic integrals) against SciPy: the period, dOmega/dE, dI/dE = 1 / Omega, <x'^2> = Omega I."""
    omega = FREQUENCY[kind]
    force, freq, en, act, _ = KINDS[kind]
    a = parameter(omega, kind)
    assert float(_numeric(freq)(a)) == pytest.approx(omega, rel=1e-13)
    # SymPy's dOmega/dE against the period by quadrature (SciPy) and central differences in the energy
    x, v = lone_orbit(omega, kind)
    e, step = energy(omega, kind), 1e-5

    def quadrature_frequency(level: float) -> float:
        """2 pi / T(E), T by quadrature (x = amp sin u on a libration: no singular end)."""
        if kind == "rotation":
            return 2 * math.pi / quad(lambda p: 1 / math.sqrt(2 * (level - 1 + math.cos(p))), 0, 2 * math.pi, epsabs=1e-14, epsrel=1e-13)[0]
        if kind == "libration":
            amp = math.acos(1 - level)
            quarter = quad(lambda u: amp * math.cos(u) / math.sqrt(2 * (math.cos(amp * math.sin(u)) - math.cos(amp))), 0, math.pi / 2,
                           epsabs=1e-14, epsrel=1e-13)[0]  # fmt: skip
        else:
            square = math.sqrt(1 + 4 * level) - 1  # A^2 of E = A^2 / 2 + A^4 / 4
            quarter = quad(lambda u: 1 / math.sqrt(1 + square * (1 + math.sin(u) ** 2) / 2), 0, math.pi / 2, epsabs=1e-14, epsrel=1e-13)[0]
        return 2 * math.pi / (4 * quarter)

    slope = (quadrature_frequency(e + step) - quadrature_frequency(e - step)) / (2 * step)
    assert frequency_slope(omega, kind) == pytest.approx(slope, rel=1e-6)
    assert frequency_slope(omega, kind) * (1 if kind == "libration" else -1) < 0  # soft libration; hard Duffing, rotation
    if act is None:
        return
    assert float(_numeric(sp.diff(act, _A) / sp.diff(en, _A))(a)) * omega == pytest.approx(1, rel=1e-12)
    assert float(np.mean(v**2)) == pytest.approx(omega * action(omega, kind), rel=1e-10)
    m = 2 / e if kind == "rotation" else e / 2  # and the action against SciPy's E and K directly
    direct = 2 * math.sqrt(2 * e) * ellipe(m) / math.pi if kind == "rotation" else 8 / math.pi * (ellipe(m) - (1 - m) * ellipk(m))
    assert action(omega, kind) == pytest.approx(direct, rel=1e-13)
    if kind == "libration":  # the FFT curvature of a linear bond against its closed form +-I / Omega
        bond = bond_of(kind, False)
        assert phase_curvature(x, bond, 0.0) == pytest.approx(action(omega, kind) / omega, rel=1e-9)
        assert phase_curvature(x, bond, math.pi) == pytest.approx(-action(omega, kind) / omega, rel=1e-9)


@pytest.mark.parametrize("name", list(CASES))
def test_two_site_exponents_converge_to_the_averaged_prediction(name):
    """Stable or not as (P) says (for Klein-Gordon: as Koukouloyannis & Kevrekidis state), sigma T to within 10 eps."""
    rows = comparison(name, COUPLINGS[:3])
    errors = []
    for _, measured, predicted, real, predicted_real in rows:
        assert real == predicted_real
        errors.append(measured / predicted - 1)
    # the error O(eps): at most 10 eps (the largest coefficient, the Klein-Gordon pair out of phase, is 7), and shrinking
    # with eps (for the co-rotating pair out of phase the O(eps) coefficient is small, -0.005, and the error
    # near eps = 0 is the multipliers' own, 3e-6)
    assert all(abs(e) < 10 * abs(eps) for e, (eps, *_) in zip(errors, rows, strict=True))
    assert abs(errors[0]) < abs(errors[2])


@pytest.mark.parametrize("counter", [False, True])
def test_package_family_start_is_the_in_phase_pair(counter):
    """roto_breather_family with a partner starts at psi = 0: its pair is the in-phase one computed above."""
    eps = COUPLINGS[1]
    orbit = roto_breather_family(takeno_peyrard(SITES, C=eps), FREQUENCY["rotation"], rotor=A, partner=B, counter=counter).orbits[0]
    name = "rotors against each other, in phase" if counter else "rotors together, in phase"
    _, measured, _, real, _ = comparison(name, [eps])[0]
    assert measured_exponent(orbit) == (pytest.approx(measured, rel=1e-7), real)


# -- Takeno and Peyrard: the rotating mode at any coupling, intrinsically discrete ---------------------------------
#
# Published statements: S. Takeno and M. Peyrard, "A new type of topological localized mode: the rotating mode",
# conference abstract (http://www.macs.hw.ac.uk/~chris/sca/TAKPEY.html; the authors' paper on the lattice is
# "Nonlinear modes in coupled rotator models", Physica D 92, 140 (1996), not reachable here, so no equation is
# cited): in a lattice whose on-site and coupling potentials are both periodic (the package's ``takeno_peyrard``,
# H = sum [phi_i'^2 / 2 + 1 - cos phi_i + C (1 - cos(phi_{i+1} - phi_i))]) "an exact solution is likely to exist",
# and the rotating modes "exist for any value of the coupling, strong or weak" and are "intrinsically discrete".
# Checked here: Newton finds the rotating mode (one rotor turning, the rest oscillating) over five decades of C at
# Omega = RATIO * omega_max, omega_max = sqrt(1 + 4 C) the top of the band, so that no harmonic of Omega meets the
# band; "intrinsically discrete" as a number (derived here): in the tail, where the motion is linear, the amplitude
# c_n of the k-th harmonic at site n obeys (1 - k^2 Omega^2) c_n = C (c_{n+1} - 2 c_n + c_{n-1}), so
#
#     c_{n+1} / c_n = -exp(-kappa_k),    cosh kappa_k = (k^2 Omega^2 - 1) / (2 C) - 1,                (T)
#
# (the forces are odd in the angles, so the nonlinearity feeds the k-th harmonic from the others only through products
# of three or more amplitudes, whose tails fall faster: the first two harmonics follow (T) from three sites on). At Omega = RATIO * omega_max, cosh kappa_1 tends to
# 2 RATIO^2 - 1 as C grows: the decay length 1 / kappa_1 stays
# below a site at every coupling, while a continuum object (the static kink, 4 arctan exp(n / sqrt(C))) widens as
# sqrt(C), 31.6 sites at C = 1000.

TP_SITES, TP_RATIO = 21, 1.5
TP_COUPLINGS = (0.01, 0.1, 1.0, 10.0, 100.0, 1000.0)


def tail_rate(omega: float, coupling: float, harmonic: int = 1) -> float:
    """exp(-kappa_k) of (T)."""
    return math.exp(-math.acosh(((harmonic * omega) ** 2 - 1) / (2 * coupling) - 1))


def harmonic_amplitudes(orbit, harmonic: int = 1) -> np.ndarray:
    """The complex amplitude of a harmonic of each angle (its winding k Omega t removed), by FFT."""
    t = np.arange(SAMPLES) * orbit.period / SAMPLES
    sites = orbit.system.size
    phi = orbit.trajectory(t)[:, :sites] - np.outer(t, orbit.turns * 2 * math.pi / orbit.period)
    return np.fft.rfft(phi, axis=0)[harmonic] / SAMPLES


@pytest.fixture(scope="module")
def rotating_modes():
    """The one-site rotating mode of the Takeno-Peyrard lattice at each coupling (Newton from the anti-continuum limit)."""
    return {
        c: roto_breather_family(takeno_peyrard(TP_SITES, C=c), TP_RATIO * math.sqrt(1 + 4 * c), locate=False).orbits[0]
        for c in TP_COUPLINGS
    }


def test_rotating_mode_exists_from_weak_to_strong_coupling(rotating_modes):
    """Takeno & Peyrard: the rotating mode exists for any coupling; Newton closes it to round-off, C = 0.01 to 1000."""
    centre = TP_SITES // 2
    for c, orbit in rotating_modes.items():
        assert orbit.closure < 1e-8, c
        assert orbit.turns[centre] == 1 and np.count_nonzero(orbit.turns) == 1  # one rotor turns once a period
        states = orbit.trajectory(np.linspace(0, orbit.period, 65))
        others = np.delete(states[:, :TP_SITES], centre, axis=1)
        assert np.max(np.abs(others)) < 0.5, c  # the rest oscillate about phi = 0, far from turning over
        assert orbit.period == pytest.approx(2 * math.pi / (TP_RATIO * math.sqrt(1 + 4 * c)), rel=1e-12)


def test_rotating_mode_is_intrinsically_discrete(rotating_modes):
    """Each of the tail's first two harmonics decays by -exp(-kappa_k) per site, (T); 1 / kappa_1 stays under a site."""
    centre = TP_SITES // 2
    for c, orbit in rotating_modes.items():
        omega = 2 * math.pi / orbit.period
        for k in (1, 2):
            amp = harmonic_amplitudes(orbit, k)
            expected = -tail_rate(omega, c, k)
            near, far = amp[centre + 2] / amp[centre + 1], amp[centre + 4] / amp[centre + 3]
            assert abs(far.imag) < 1e-6 * abs(far)  # real and negative: the neighbours move against each other
            assert far.real == pytest.approx(expected, rel=2e-4), (c, k)
            assert abs(far.real / expected - 1) < abs(near.real / expected - 1)  # the core is nonlinear, the tail linear
            assert amp[centre - 3] / amp[centre - 2] == pytest.approx(amp[centre + 3] / amp[centre + 2], rel=1e-6)  # mirror
    strong = 2 * TP_RATIO**2 - 1  # cosh kappa_1 at C -> infinity
    amp = harmonic_amplitudes(rotating_modes[1000.0])
    rate = abs(amp[centre + 4] / amp[centre + 3])
    assert rate == pytest.approx(math.exp(-math.acosh(strong)), rel=3e-3)
    assert 1 / math.acosh(strong) < 1 < math.sqrt(1000.0)  # decay length 0.52 site against the kink's width 31.6


def table() -> str:
    """The docs' table (docs/roto-breathers-literature.md): ``python tests/test_rotobreather_literature.py``."""
    lines = ["| case | eps | sigma T (Newton, Floquet) | sigma T (P) | ratio | fitted order of ratio - 1 |", "|---|---|---|---|---|---|"]
    for name in CASES:
        rows = comparison(name)
        errors = np.array([abs(m / p - 1) for _, m, p, _, _ in rows])
        order = np.polyfit(np.log(COUPLINGS), np.log(errors), 1)[0]
        for j, (eps, measured, predicted, real, _) in enumerate(rows):
            kind = "real" if real else "angle"
            lines.append(
                f"| {name if j == 0 else ''} | {eps:+g} | {measured:.6f} ({kind}) | {predicted:.6f} | {measured / predicted:.6f} "
                f"| {f'{order:.2f}' if j == 0 else ''} |"
            )
    return "\n".join(lines)


if __name__ == "__main__":
    print(table())
