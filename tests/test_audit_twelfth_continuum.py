"""Outside audit of the continuum theory (H12audD): independent derivations against the package.

Each check rebuilds its reference from the corner geometry of Fig. 1 without the package's
formulas: the bond's linearised elongations (unit vector of each link times the relative motion
of its two corners), the boundary-value problem (7), (8), (10) solved as a linear system of its
own, the Bloch matrix of the independently assembled bond Hessian, and the held bond's exact
four-link potential. Random admissible geometries (0 < a < h/2), not the paper's.
"""

from __future__ import annotations

import numpy as np
import pytest

from cosserat_chain import ChainParams
from cosserat_chain.analysis import continuum
from cosserat_chain.analysis.dispersion import dispersion
from cosserat_chain.analysis.rotation_front import bond_potential, quasi_continuum
from cosserat_chain.models.base import get_model
from cosserat_chain.models.linear import stiffness_matrix


def _geometries(count: int, seed: int) -> list[dict[str, float]]:
    rng = np.random.default_rng(seed)
    out = []
    for _ in range(count):
        h = rng.uniform(0.5, 2.0)
        out.append(
            dict(h=h, a=rng.uniform(0.03, 0.47) * h, b=rng.uniform(0.05, 1.0) * h, E1=rng.uniform(0.2, 3.0), E2=rng.uniform(0.01, 3.0))
        )
    return out


def _links(g: dict[str, float]) -> list[tuple[float, tuple[float, float], tuple[float, float]]]:
    """(stiffness, corner on the left particle, corner on the right one), offsets from the centres."""
    a, b = g["a"], g["b"]
    return [(g["E1"], (a, b), (-a, b)), (g["E1"], (a, -b), (-a, -b)), (g["E2"], (a, b), (-a, -b)), (g["E2"], (a, -b), (-a, b))]


def _bond_hessian(g: dict[str, float]) -> np.ndarray:
    """Hessian (6 x 6, (u0, v0, phi0, u1, v1, phi1)) of sum E/2 dL^2, dL the linearised elongation."""
    H = np.zeros((6, 6))
    for stiffness, (x0, y0), (x1, y1) in _links(g):
        e = np.array([g["h"] + x1 - x0, y1 - y0])
        e /= np.hypot(*e)
        # a corner r turned by phi moves by phi (-r_y, r_x)
        row = np.array([-e[0], -e[1], -(e @ [-y0, x0]), e[0], e[1], e @ [-y1, x1]])
        H += stiffness * np.outer(row, row)
    return H


def _chain_stiffness(g: dict[str, float], N: int) -> np.ndarray:
    n = 2 * N + 1
    K = np.zeros((3 * n, 3 * n))
    H = _bond_hessian(g)
    for k in range(n - 1):
        K[3 * k : 3 * k + 6, 3 * k : 3 * k + 6] += H
    free = np.arange(3, 3 * n - 3)
    return K[np.ix_(free, free)]


@pytest.mark.parametrize("g", _geometries(6, 1201))
def test_coefficients_and_stiffness_are_the_corner_links_linearised(g):
    """k_u, k_v, D1, D2 and the assembled K of models (iii), (ii) and (i) at rest equal the corner links' Hessian."""
    params = ChainParams(**g, N=4)
    H = _bond_hessian(g)
    two_b2 = 2 * g["b"] ** 2
    c = (H[2, 2] + H[2, 5]) / (2 * two_b2)  # the bond's phi block is 2 b^2 [[E1 + c, c - E1], [c - E1, E1 + c]]
    assert params.k_u == pytest.approx(H[0, 0], rel=1e-13)
    assert params.k_v == pytest.approx(H[1, 1], rel=1e-13)
    assert H[1, 2] == pytest.approx(params.k_v * g["h"] / 2, rel=1e-13)
    assert params.D1 == pytest.approx(-H[2, 5] / two_b2, rel=1e-12, abs=1e-13)
    assert params.D2 == pytest.approx(4 * c, rel=1e-12)
    K = _chain_stiffness(g, 4)
    x = np.zeros((3, 9))
    for name in ("linear", "sine", "nonlinear"):
        assert np.abs(get_model(name).stiffness(params, x).toarray() - K).max() <= 1e-13 * np.abs(K).max()
    assert np.abs(stiffness_matrix(params).toarray() - K).max() <= 1e-13 * np.abs(K).max()


@pytest.mark.parametrize("g", _geometries(4, 1202))
def test_dispersion_is_the_bloch_spectrum_of_the_corner_links(g):
    params = ChainParams(**g, m=1.3)
    H = _bond_hessian(g)
    scale = np.diag(1 / np.sqrt([params.m, params.m, params.j]))
    q = np.linspace(0.0, np.pi, 41)
    mine = []
    for qq in q:
        D = H[:3, :3] + H[3:, 3:] + H[:3, 3:] * np.exp(1j * qq) + H[3:, :3] * np.exp(-1j * qq)
        mine.append(np.sqrt(np.maximum(np.linalg.eigvalsh(scale @ D @ scale), 0.0)))
    theirs = np.sort(dispersion(params, q).omega, axis=0)
    assert np.abs(theirs - np.array(mine).T).max() <= 1e-10 * np.max(mine)


def _own_central_rotation(g: dict[str, float], N: int, D1: float, D2: float) -> float:
    """phi(0) from (7) with (8) and (10) as a 4 x 4 linear system (M = 1)."""
    h, b, L = g["h"], g["b"], N * g["h"]
    k = h * h * D1 / D2

    def v(x):
        return np.array([x**3 / 6, x**2 / 2, x, 1.0])

    def phi(x):
        return np.array([x**2 / 2 + k, x, 1.0, 0.0])

    rows = np.array([v(0), v(L), phi(L), 2 * b * b * (2 * D1 * (phi(h) - phi(0)) + D2 * (v(h) / h - phi(0)))])
    return float(phi(0) @ np.linalg.solve(rows, [0, 0, 0, -1.0]))


@pytest.mark.parametrize("g", _geometries(4, 1203))
def test_continuum_compliance_solves_its_boundary_value_problem_and_converges_like_1_over_N(g):
    params = ChainParams(**g)
    d2 = (g["h"] - 2 * g["a"]) ** 2 + 4 * g["b"] ** 2
    D1, D2 = g["E1"] - g["h"] ** 2 / d2 * g["E2"], 4 * g["h"] ** 2 / d2 * g["E2"]
    for N in (2, 7, 40):
        assert continuum.central_rotation(params.replace(N=N)) == pytest.approx(_own_central_rotation(g, N, D1, D2), rel=1e-9)
    # The discrete compliance: the independently assembled K at N = 5 and 20, where it equals the
    # shifted Timoshenko beam's L (1 + P) / (8 EI (1 + P/4)), P = 12 EI c / L^2, c = 1/GA - h^2/(12 EI)
    # (docs/which-continuum.md, derived there); that closed form then at N = 2000 and 4000.
    EI, GA = 2 * g["E1"] * g["b"] ** 2 * g["h"], 8 * g["b"] ** 2 / d2 * g["E2"] * g["h"]

    def beam(N):
        L = N * g["h"]
        P = 12 * EI * (1 / GA - g["h"] ** 2 / (12 * EI)) / L**2
        return L * (1 + P) / (8 * EI * (1 + P / 4))

    for N in (5, 20):
        K = _chain_stiffness(g, N)
        load = np.zeros(K.shape[0])
        load[3 * N - 1] = 1.0
        assert np.linalg.solve(K, load)[3 * N - 1] == pytest.approx(beam(N), rel=1e-11)
    errors = [(continuum.central_rotation(params.replace(N=N)) - beam(N)) / beam(N) for N in (2000, 4000)]
    assert np.log2(errors[0] / errors[1]) == pytest.approx(1.0, abs=0.05)
    # leading term +D2 / (2 (4 D1 + D2) N), its next order removed by Richardson extrapolation
    assert 2 * 4000 * errors[1] - 2000 * errors[0] == pytest.approx(D2 / (2 * (4 * D1 + D2)), rel=2e-3)


def test_central_rotation_for_three_particles_where_the_denominator_of_11_vanishes():
    """N = 1: the conditions fix phi(0) = M / (2 b^2 (2 D1 + D2)), the chain's value, for every geometry.

    At E1 = 2/3 (h/d)^2 E2 (here exactly: D1 = -1/2, D2 = 6) the denominator of (11) and its
    numerator both vanish; the formula evaluated as a ratio gave 1.333 for 1.6 (and lost digits
    nearby), and the profile, which the conditions leave undetermined, came out as 1e15.
    """
    for E1 in (1.0, 1.0 + 1e-12, 1.0 + 1e-9):
        params = ChainParams(h=1.0, a=0.25, b=0.25, E1=E1, E2=0.75, N=1)
        discrete = continuum.discrete_static(params)[2, 1]
        assert continuum.central_rotation(params) == pytest.approx(discrete, rel=1e-13)
        assert continuum.convergence(params, [1]).relative_error[0] < 1e-12
    with pytest.raises(ValueError, match="singular"):
        continuum.solution(ChainParams(h=1.0, a=0.25, b=0.25, E1=1.0, E2=0.75, N=1), 0.5)


@pytest.mark.parametrize("g", [dict(h=1.0, a=0.08, b=0.7, E1=1.0, E2=0.005), dict(h=1.3, a=0.1, b=0.9, E1=1.5, E2=0.01)])
def test_held_bond_potential_and_quasi_continuum_front(g):
    """V from the four links' exact lengths; W = V(p, p), kappa = d^2/dd^2 V(p - d/2, p + d/2); front energy int sqrt(2 W kappa)."""
    params = ChainParams(**g)
    phi0, phi1 = np.meshgrid(np.linspace(0, 2 * np.pi, 37), np.linspace(0, 2 * np.pi, 29))

    def V(p0, p1):
        total = 0.0
        for stiffness, (x0, y0), (x1, y1) in _links(g):
            X0, Y0 = x0 * np.cos(p0) - y0 * np.sin(p0), x0 * np.sin(p0) + y0 * np.cos(p0)
            X1, Y1 = g["h"] + x1 * np.cos(p1) - y1 * np.sin(p1), x1 * np.sin(p1) + y1 * np.cos(p1)
            rest = np.hypot(g["h"] + x1 - x0, y1 - y0)
            total = total + 0.5 * stiffness * (np.hypot(X1 - X0, Y1 - Y0) - rest) ** 2
        return total

    assert np.abs(bond_potential(params, phi0, phi1) - V(phi0, phi1)).max() < 1e-13
    p, s = np.linspace(0, 2 * np.pi, 4001), 1e-4
    W = V(p, p)
    kappa = (V(p - s, p + s) - 2 * W + V(p + s, p - s)) / (2 * s) ** 2
    qc = quasi_continuum(params)
    assert qc.front_energy == pytest.approx(np.trapezoid(np.sqrt(2 * W * kappa), p), rel=1e-4)
    assert qc.width == pytest.approx(2 * np.pi / np.max(np.sqrt(2 * W / kappa)), rel=1e-3)


def test_eq2_is_not_model_i_linearised_in_the_displacements():
    """At u = v = 0 a linearisation in u, v keeps model (i)'s exact torque; eq. (2)'s differs beyond small angles.

    One particle of the paper's chain turned by pi/2, its neighbours at rest: model (i) (its forces, and
    -dV/dphi of the four links' exact lengths) gives the torque -0.258, eq. (2) -4 b^2 (E1 + (h/d)^2 E2)
    = -0.468; they agree to O(phi^2) only (ratio 0.9999 at 0.01 rad).
    """
    params = ChainParams(N=3)
    g = dict(h=1.0, a=0.2, b=0.2, E1=1.0, E2=1.0)
    x = np.zeros((3, 7))
    for angle, ratio in ((0.01, 1.0), (np.pi / 2, 0.5517)):
        x[2, 3] = angle
        nonlinear = get_model("nonlinear").forces(params, x)[2, 3]
        sine = get_model("sine").forces(params, x)[2, 3]
        assert sine == pytest.approx(-4 * g["b"] ** 2 * (g["E1"] + params.h**2 / params.d**2 * params.E2) * np.sin(angle), rel=1e-12)
        step = 1e-6

        def held(p):
            return bond_potential(params, 0.0, p) + bond_potential(params, p, 0.0)

        assert nonlinear == pytest.approx(-(held(angle + step) - held(angle - step)) / (2 * step), rel=1e-7)
        assert nonlinear / sine == pytest.approx(ratio, abs=2e-4)
