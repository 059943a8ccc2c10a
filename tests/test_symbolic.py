"""The SymPy derivation from the geometry of model (i), and the errata it finds."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest
import sympy as sp

from conftest import ROUND_OFF, random_geometries
from cosserat_chain import ChainParams
from cosserat_chain.analysis.continuum import printed_D1
from cosserat_chain.analysis.symbolic import (
    COEFFICIENTS,
    compare_with_paper,
    derivation,
    derived_bond_hessian,
    derived_coefficients,
    errata,
    printed_eq3_stiffness,
)
from cosserat_chain.models import LINEAR, NONLINEAR, SINE
from cosserat_chain.models.base import assemble_bond_blocks
from cosserat_chain.models.linear import bond_stiffness_blocks, cosserat_coefficients
from cosserat_chain.state import zeros

ERRATA_PAGE = Path(__file__).resolve().parents[1] / "docs" / "errata.md"


@pytest.mark.parametrize("params", random_geometries(6, seed=2))
def test_numeric_models_use_exactly_the_derived_coefficients(params):
    derived = derived_coefficients(params)
    expected = np.array([derived[name] for name in COEFFICIENTS])
    for model in (LINEAR, SINE):
        np.testing.assert_allclose(model.coefficients(params), expected, rtol=ROUND_OFF, atol=ROUND_OFF)
    np.testing.assert_allclose(cosserat_coefficients(params), expected, rtol=ROUND_OFF, atol=ROUND_OFF)
    assert params.D1 == pytest.approx(derived["D1"], rel=ROUND_OFF, abs=ROUND_OFF)
    assert params.D2 == pytest.approx(derived["D2"], rel=ROUND_OFF, abs=ROUND_OFF)
    np.testing.assert_allclose(bond_stiffness_blocks(params)[0], derived_bond_hessian(params), rtol=ROUND_OFF, atol=ROUND_OFF)


@pytest.mark.parametrize("params", random_geometries(3, seed=5))
def test_derived_bond_energy_is_the_second_order_expansion_of_model_i(params):
    # The derived bond Hessian, assembled over the chain, is the nonlinear model's exact Hessian at rest.
    blocks = np.broadcast_to(derived_bond_hessian(params), (params.n_particles - 1, 6, 6))
    derived = assemble_bond_blocks(np.ascontiguousarray(blocks), params).toarray()
    exact = NONLINEAR.stiffness(params, zeros(params)).toarray()
    np.testing.assert_allclose(derived, exact, rtol=0, atol=1e-10 * np.max(np.abs(exact)))


def test_derived_coefficients_in_closed_form():
    d = derivation()
    s = d.symbols
    E1, E2, h, b, dd, g = (s[n] for n in ("E1", "E2", "h", "b", "d", "g"))
    expected = {
        "k_u": 2 * (E1 + g**2 / dd**2 * E2),
        "k_v": 8 * b**2 / dd**2 * E2,
        "arm": h,
        "D1": E1 - h**2 / dd**2 * E2,
        "D2": 4 * h**2 / dd**2 * E2,
    }
    for name, value in expected.items():
        assert sp.simplify(d.coefficients[name] - value) == 0, name
    # The bond energy per bond: k_u/2 du^2 + E1 b^2 dphi^2 + k_v/2 (dv - h (phi + phi_p)/2)^2.
    du, dv, dphi = s["u_p"] - s["u"], s["v_p"] - s["v"], s["phi_p"] - s["phi"]
    energy = expected["k_u"] / 2 * du**2 + E1 * b**2 * dphi**2 + expected["k_v"] / 2 * (dv - h * (s["phi"] + s["phi_p"]) / 2) ** 2
    difference = (d.bond_energy - energy).subs(dd, sp.sqrt(g**2 + 4 * b**2))
    assert sp.simplify(difference) == 0


def test_comparison_with_the_paper_finds_exactly_the_known_errata():
    failing = {check.key for check in compare_with_paper() if not check.agrees}
    assert failing == {"eq3.couple", "section3.D1", "section3.reduced_E1", "section2.kinetic", "eq2.potential"}
    agreeing = {check.key for check in compare_with_paper() if check.agrees}
    # Eq. (2) is right, Section 3's algebra is right given D1 and D2, the link energy is right.
    assert {f"eq2.{name}" for name in COEFFICIENTS} <= agreeing
    assert {"section3.D2", "section2.link_energy", "eq7", "eq11.v", "eq11.phi", "phi0", "eq12", "eq4", "reduced"} <= agreeing


def test_eq2_is_not_conservative_and_its_curl_vanishes_only_at_phi_zero():
    (check,) = [c for c in compare_with_paper() if c.key == "eq2.potential"]
    phi_p, k_v, h = sp.Symbol("phi_p", real=True), sp.Symbol("k_v"), derivation().symbols["h"]
    assert sp.simplify(check.derived - k_v * h * (1 - sp.cos(phi_p)) / 2) == 0
    assert check.derived.subs(phi_p, 0) == 0


def test_printed_eq3_is_not_symmetric_and_makes_the_paper_chain_unstable(paper):
    printed = printed_eq3_stiffness(paper).toarray()
    derived = LINEAR.stiffness(paper).toarray()
    # The printed operator differs only in the phi equation's coupling term D2 ((v_k+1 - v_k-1)/2h - phi_k), by the factor 4.
    rows, cols = np.nonzero(np.abs(printed - derived) > ROUND_OFF)
    assert set(rows % 3) == {2} and set(cols % 3) == {1, 2}
    np.testing.assert_allclose(printed[2::3, 1::3], derived[2::3, 1::3] / 4, rtol=ROUND_OFF)
    couple = 2 * paper.b**2 * paper.D2
    np.testing.assert_allclose(np.diag(printed - derived)[2::3], -0.75 * couple, rtol=ROUND_OFF)
    assert np.max(np.abs(printed - printed.T)) > 0.1
    inverse_mass = 1.0 / np.tile(paper.inertia, paper.n_particles - 2)
    lowest = np.min(np.linalg.eigvals(inverse_mass[:, None] * printed).real)
    assert lowest == pytest.approx(-4.66, abs=0.01)
    assert np.min(np.linalg.eigvalsh(derived)) > 0


def test_the_errata_of_a_long_chain_use_no_dense_matrix(monkeypatch):
    # N = 1000: 5997 free degrees of freedom (a dense eigendecomposition took 70 s); the
    # printed operator's leftmost eigenvalue by ARPACK equals the dense one at N = 100.
    from cosserat_chain.linalg import eigen

    matrix = printed_eq3_stiffness(ChainParams(N=100))
    dense = np.min(np.linalg.eigvals(matrix.toarray()).real)
    monkeypatch.setattr(eigen, "DENSE_SPECTRUM_LIMIT", 0)
    assert eigen.lowest_real_eigenvalue(matrix).real == pytest.approx(dense, rel=1e-8)
    monkeypatch.undo()
    (one,) = [e for e in errata(ChainParams(N=1000)) if e.number == 1]
    assert "N = 1000" in one.consequence


def test_the_printed_operator_has_a_symmetric_diagonal_similar_with_its_spectrum():
    # M^-1 K of the printed eq. (3) is made symmetric by a diagonal similarity (its phi rows
    # couple to v with a quarter of what the v rows couple to phi), so its spectrum is real
    # and the banded smallest eigenvalue applies; a matrix with a one-sided entry or a
    # ratio of the wrong sign has no such similar and takes ARPACK.
    import scipy.sparse as sparse

    from cosserat_chain.linalg import eigen
    from cosserat_chain.state import per_dof

    for params in (ChainParams(N=30), ChainParams(N=12, a=0.31, b=0.12, E1=1.7, E2=0.4, m=2.0)):
        matrix = sparse.diags(1.0 / per_dof(params, params.inertia)) @ printed_eq3_stiffness(params)
        similar = eigen.diagonal_similar_symmetric(matrix)
        assert similar is not None
        np.testing.assert_allclose(np.linalg.eigvalsh(similar.toarray()), np.sort(np.linalg.eigvals(matrix.toarray()).real), atol=1e-10)
    one_sided = sparse.csr_matrix(np.triu(np.random.default_rng(3).uniform(0.5, 2.0, (40, 40))))
    assert eigen.diagonal_similar_symmetric(one_sided) is None
    # Symmetrisable but wider than the chain's band: the same eigenvalue from ARPACK.
    d = np.random.default_rng(4).uniform(0.5, 2.0, 700)
    base = sparse.random(700, 700, density=0.01, random_state=5)
    symmetric = base + base.T + 10 * sparse.eye(700)
    wide = sparse.csr_matrix(sparse.diags(d) @ symmetric @ sparse.diags(1 / d))
    assert eigen.lowest_real_eigenvalue(wide).real == pytest.approx(np.linalg.eigvalsh(symmetric.toarray()).min(), abs=1e-8)
    opposite = sparse.csr_matrix(np.array([[2.0, 1.0, 0.0], [-1.0, 2.0, 1.0], [0.0, 1.0, 2.0]]))
    assert eigen.diagonal_similar_symmetric(opposite) is None  # a_ij a_ji < 0: complex eigenvalues possible


def test_the_errata_of_a_ten_thousand_particle_pairs_chain_take_banded_eigenvalues():
    # N = 10^4: the printed operator's lowest eigenvalue is the edge of a band of its
    # spectrum, where ARPACK slowed like N^3 (about half an hour here); the banded smallest
    # eigenvalue of its symmetric similar is O(N) a factor. It has converged in N: the same
    # to 1e-6 as at N = 1000. The derived K's softest eigenvalue (N^-4) is below its round-off.
    (one,) = [e for e in errata(ChainParams(N=10000)) if e.number == 1]
    assert "N = 10000" in one.consequence and "-5.31" in one.consequence and "within its round-off" in one.consequence


def test_errata_carry_printed_derived_and_consequence_for_the_given_chain(paper):
    listed = errata(paper)
    assert [e.number for e in listed] == list(range(1, 11))
    assert all(e.printed and e.derived and e.consequence for e in listed)
    assert [e.found_by for e in listed] == ["sympy"] * 4 + ["reading"] * 2 + ["computed"] + ["reading"] * 3
    assert "-4.66" in listed[0].consequence and "exp(2.16 t)" in listed[0].consequence
    assert "-0.9231" in listed[1].consequence and "-2.846" in listed[1].consequence
    # Every SymPy-found erratum names the failing checks behind it, and every failing check has its erratum.
    behind = {key for e in listed for key in e.checks}
    assert behind == {c.key for c in compare_with_paper() if not c.agrees}
    longer = errata(paper.replace(N=5))
    assert "N = 5" in longer[0].consequence


def test_errata_page_lists_the_same_errata():
    page = ERRATA_PAGE.read_text()
    rows = re.findall(r"^\| (\d+) \|", page, flags=re.MULTILINE)
    assert [int(n) for n in rows] == [e.number for e in errata()]
    assert "-4.66" in page and "exp(2.16 t)" in page and "-0.923" in page


def test_errata_for_a_chain_without_diagonals_say_the_misprints_do_not_apply(paper):
    listed = errata(paper.replace(E2=0.0))
    assert "E2 = 0" in listed[0].consequence and "E2 = 0" in listed[1].consequence


def test_the_chain_with_sections_printed_D1_is_unstable_at_rest(paper):
    """Erratum 7, against a dense eigensolve of the same operator built independently (energy Hessian by hand)."""
    from cosserat_chain.models.linear import stiffness_matrix

    for chain in (paper, paper.replace(N=10)):
        n = chain.n_particles
        stiffness = stiffness_matrix(chain).toarray()
        # Section 3's phi equation (5), times 2 b^2, carries h^2 D1 (phi_k+1 - 2 phi_k + phi_k-1) / h^2.
        delta = printed_D1(chain) - chain.D1
        for col in range(1, n - 1):
            i = 3 * (col - 1) + 2
            stiffness[i, i] += delta * 2 * chain.b**2 * 2
            for other in (col - 1, col + 1):
                if 1 <= other <= n - 2:
                    stiffness[i, 3 * (other - 1) + 2] -= delta * 2 * chain.b**2
        lowest = np.linalg.eigvals(stiffness / np.tile(chain.inertia, n - 2)[:, None]).real.min()
        seventh = errata(chain)[6]
        assert lowest < 0 and f"eigenvalue {lowest:.3g}" in seventh.consequence
