"""Section 3.2: the reduced Cosserat model (D1 = 0) is arbitrary as a continuum and unique as a chain."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.linalg as la
import scipy.sparse.linalg as spla
import sympy as sp

from conftest import ROUND_OFF, random_geometries
from cosserat_chain import ChainParams
from cosserat_chain.analysis.continuum import (
    reduced_discrete,
    reduced_E1,
    reduced_family,
    reduced_family_rotation,
    reduced_solution,
)
from cosserat_chain.models.linear import stiffness_matrix

x, L, h, b, D2, M, alpha = sp.symbols("x L h b D2 M alpha", positive=True)
#: The paper's reduced solution (Section 3.2), written out again here: the tests do not trust the package's copy.
CUBIC = M * x * (L - x) ** 2 / (2 * b**2 * h * (2 * L - h) * D2)
#: The quartic that meets the four conditions with M = 0 (:func:`reduced_family`'s w).
QUARTIC = x * (L - x) ** 2 * (x + (L - h) ** 2 / (2 * L - h))


def _conditions(v: sp.Expr) -> list[sp.Expr]:
    """Left-hand sides of the reduced equations and the four conditions of Section 3.2 with phi = v_x (eq. 13)."""
    phi = sp.diff(v, x)
    return [
        sp.diff(v, x, 2) - sp.diff(phi, x),
        sp.diff(v, x) - phi,
        v.subs(x, 0),
        2 * b**2 * D2 * (v.subs(x, h) / h - phi.subs(x, 0)) + M,
        v.subs(x, L),
        phi.subs(x, L),
    ]


def test_every_alpha_meets_the_reduced_equations_and_the_four_conditions_and_moves_phi0():
    family = CUBIC + alpha * QUARTIC
    assert [sp.simplify(c) for c in _conditions(family)] == [0] * 6
    slope = sp.diff(sp.diff(family, x).subs(x, 0), alpha)
    assert sp.simplify(slope - L**2 * (L - h) ** 2 / (2 * L - h)) == 0
    # phi(0) depends on alpha for every chain of N >= 2 (L = N h > h); for N = 1 it cannot.
    assert slope.subs({L: 3, h: 1}) == sp.Rational(36, 5) and slope.subs(L, h) == 0


def test_the_quartic_of_the_family_is_the_only_one():
    # A general quartic meeting the four conditions with M = 0: one free direction, w's.
    c = sp.symbols("c0:5")
    v = sum(ci * x**i for i, ci in enumerate(c))
    rows = sp.Matrix([[sp.diff(e, ci) for ci in c] for e in _conditions(v)[2:]]).subs(M, 0)
    (null,) = rows.nullspace()
    expected = sp.Poly(sp.expand(QUARTIC), x).all_coeffs()[::-1]
    ratio = sp.simplify(null[4] / expected[4])
    assert [sp.simplify(n - ratio * e) for n, e in zip(null, expected)] == [0] * 5


def test_adding_x2_L_minus_x_squared_breaks_the_nonlocal_condition_and_leaves_phi0():
    """The quartic alpha x^2 (L - x)^2 vanishes with its slope at both ends but is no member of the family."""
    shifted = CUBIC + alpha * x**2 * (L - x) ** 2
    residues = [sp.simplify(c) for c in _conditions(shifted)]
    assert residues[:3] == [0, 0, 0] and residues[4:] == [0, 0]
    assert sp.simplify(residues[3] - 2 * b**2 * D2 * alpha * h * (L - h) ** 2) == 0
    assert sp.diff(shifted, x).subs(x, 0) == sp.diff(CUBIC, x).subs(x, 0)


@pytest.mark.parametrize("params", [ChainParams(), ChainParams(N=7, a=0.3, b=0.1, E1=2.0, E2=0.3)])
def test_reduced_family_equals_the_symbolic_family(params):
    points = np.linspace(0.0, params.N * params.h, 11)
    values = {L: params.N * params.h, h: params.h, b: params.b, D2: params.D2, M: 0.7}
    for a in (0.0, 0.31, -2.5):
        v_expr = (CUBIC + alpha * QUARTIC).subs(values).subs(alpha, a)
        v, phi = reduced_family(params, points, 0.7, alpha=a)
        np.testing.assert_allclose(v, sp.lambdify(x, v_expr)(points), rtol=1e-12, atol=1e-14)
        np.testing.assert_allclose(phi, sp.lambdify(x, sp.diff(v_expr, x))(points), rtol=1e-12, atol=1e-14)
        assert reduced_family_rotation(params, 0.7, alpha=a) == pytest.approx(phi[0], rel=1e-12)
    np.testing.assert_array_equal(reduced_family(params, points, 0.7), reduced_solution(params, points, 0.7))
    with pytest.raises(ValueError, match="alpha must be finite, got nan"):
        reduced_family(params, points, alpha=float("nan"))


# Random admissible geometries with coupling, each at several lengths.
REDUCED = [p.replace(N=n) for p in random_geometries(6, seed=11) if p.E2 > 0.05 for n in (1, 2, 5, 12)]


@pytest.mark.parametrize("params", REDUCED, ids=lambda p: f"N{p.N}-E2_{p.E2:.2f}")
def test_the_discrete_reduced_chain_is_positive_definite_with_a_unique_static_state(params):
    result = reduced_discrete(params)
    chain = result.params
    assert chain.E1 == pytest.approx(reduced_E1(params)) and abs(chain.D1) <= ROUND_OFF * chain.D2
    stiffness = stiffness_matrix(chain).toarray()
    eigenvalues = np.linalg.eigvalsh(stiffness)
    assert result.positive_definite and eigenvalues[0] > 0
    assert result.lowest_eigenvalue == pytest.approx(eigenvalues[0], rel=1e-8)
    # Unique: the SuperLU solve equals a dense Cholesky solve and the eigen-decomposition's inverse.
    # The free degrees of freedom run particle by particle from -N+1 (state.py): phi_0 is 3 (N - 1) + 2.
    phi0 = 3 * (chain.N - 1) + 2
    load = np.zeros(stiffness.shape[0])
    load[phi0] = 1.0
    dense = la.cho_solve(la.cho_factor(stiffness), load)
    vectors = np.linalg.eigh(stiffness)[1]
    spectral = vectors @ ((vectors.T @ load) / eigenvalues)
    sparse = spla.spsolve(stiffness_matrix(chain).tocsc(), load)
    np.testing.assert_allclose(sparse, dense, rtol=1e-9, atol=1e-12 * np.max(np.abs(dense)))
    np.testing.assert_allclose(spectral, dense, rtol=1e-7, atol=1e-9 * np.max(np.abs(dense)))
    assert result.compliance == pytest.approx(dense[phi0], rel=1e-9)


def test_the_discrete_chain_picks_one_member_of_the_continuum_family(paper):
    """N = 3: the chain's phi_0 / M is 2.822, the paper's cubic gives 2.925; one alpha of the family matches it."""
    result = reduced_discrete(paper)
    assert result.compliance == pytest.approx(2.8223684210526, rel=1e-10)
    assert result.continuum_compliance == pytest.approx(2.925, rel=1e-12)
    matched = reduced_family_rotation(result.params, alpha=result.matching_alpha)
    assert matched == pytest.approx(result.compliance, rel=1e-12)
    assert reduced_discrete(paper.replace(N=1)).matching_alpha is None
    with pytest.raises(ValueError, match="needs E2 > 0"):
        reduced_discrete(paper.replace(E2=0.0))
