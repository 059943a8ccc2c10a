"""Band storage of the statics' matrices: its round trips, its refusals, and the models' banded stiffness."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp

from conftest import random_geometries, random_state
from cosserat_chain import ChainParams
from cosserat_chain.linalg import BANDWIDTH, BandMatrix
from cosserat_chain.models.base import BOND_SUMS, assemble_bond_blocks, assemble_bond_sums, get_model
from cosserat_chain.models.nonlinear import _hessian
from cosserat_chain.state import n_free, pack, unpack


def _random_band(n: int, seed: int) -> sp.csr_matrix:
    rng = np.random.default_rng(seed)
    offsets = [k for k in range(-BANDWIDTH, BANDWIDTH + 1) if abs(k) < n]
    return sp.diags([rng.standard_normal(n - abs(k)) for k in offsets], offsets, shape=(n, n), format="csr")


@pytest.mark.parametrize("n", [1, 2, 6, 11, 40])
def test_a_banded_matrix_round_trips_through_band_storage_and_keeps_its_norm_and_storage_layout(n):
    matrix = _random_band(n, seed=n)
    band = BandMatrix.from_sparse(matrix)
    dense = matrix.toarray()
    assert band.shape == (n, n) and band.data.shape == (n + 2 * BANDWIDTH, 2 * BANDWIDTH + 1)
    assert np.array_equal(band.toarray(), dense) and np.array_equal(band.tocsr().toarray(), dense)
    assert np.array_equal(BandMatrix.from_sparse(dense).data, band.data)  # dense input, same storage
    assert band.infinity_norm == pytest.approx(np.abs(dense).sum(axis=1).max(), rel=1e-15)
    # The padding is zero; row B + i holds M[i, i + d] at column B + d.
    assert not band.data[:BANDWIDTH].any() and not band.data[n + BANDWIDTH :].any()
    for i in range(n):
        for d in range(-BANDWIDTH, BANDWIDTH + 1):
            assert band.data[BANDWIDTH + i, BANDWIDTH + d] == (dense[i, i + d] if 0 <= i + d < n else 0.0)


def test_a_matrix_wider_than_the_band_and_malformed_storage_are_refused_by_name():
    n = 20
    wide = sp.diags([np.ones(n), np.full(n - BANDWIDTH - 2, 0.5)], [0, -BANDWIDTH - 2], format="csr")
    with pytest.raises(ValueError, match=f"half-bandwidth {BANDWIDTH + 2}, more than the chain's {BANDWIDTH}"):
        BandMatrix.from_sparse(wide)
    with pytest.raises(ValueError, match=r"band data must have shape \(n \+ 10, 11\), got \(12, 7\)"):
        BandMatrix(np.zeros((12, 7)))


def _ends(N: int) -> list[ChainParams]:
    return [
        ChainParams(N=N),
        ChainParams(N=N, left_end="pinned", right_end="pinned"),
        ChainParams(N=N, left_end="clamped", right_end="free"),
        ChainParams(N=N, left_end="free", right_end="pinned"),
    ]


@pytest.mark.parametrize("params", [*_ends(1), *_ends(3), *_ends(30), *random_geometries(4, seed=11)], ids=repr)
def test_the_banded_stiffness_equals_the_sparse_one_bit_for_bit_at_random_states(params):
    x = random_state(params, 0.3, seed=params.N)
    for name in ("nonlinear", "sine", "linear"):
        model = get_model(name)
        band = model.stiffness_band(params, x)
        assert isinstance(band, BandMatrix) and band.shape == (n_free(params),) * 2
        assert np.array_equal(band.toarray(), model.stiffness(params, x).toarray()), name


@pytest.mark.parametrize("params", [*_ends(1), *_ends(3), *_ends(30), *random_geometries(4, seed=12)], ids=repr)
def test_the_sine_models_banded_similar_equals_its_sparse_product_bit_for_bit_and_has_the_stiffness_eigenvalues(params):
    """U C U^T assembled in the band is SciPy's product to the bit (padding zero), and similar to K C."""
    x = random_state(params, 2.0, seed=params.N)  # angles beyond pi / 2: C has negative entries
    model = get_model("sine")
    band = model.symmetric_similar_band(params, x)
    if params.rigid_modes:
        assert band is None and model.symmetric_similar(params, x) is None
        return
    reference = BandMatrix.from_sparse(model.symmetric_similar(params, x)).data
    assert np.array_equal(band.data, reference)
    if params.N <= 3:
        similar = np.sort(np.linalg.eigvalsh(band.toarray()))
        direct = np.sort(np.linalg.eigvals(model.stiffness(params, x).toarray()).real)
        assert np.allclose(similar, direct, rtol=1e-9, atol=1e-9 * np.abs(direct).max())


@pytest.mark.parametrize("params", [*_ends(3), *random_geometries(2, seed=13)], ids=repr)
@pytest.mark.parametrize("name", ["nonlinear", "linear"])
def test_a_conservative_models_banded_similar_is_its_stiffness_band_bit_for_bit(params, name):
    x = random_state(params, 0.5, seed=params.N)
    model = get_model(name)
    assert np.array_equal(model.symmetric_similar_band(params, x).data, BandMatrix.from_sparse(model.symmetric_similar(params, x)).data)


def test_a_ring_has_no_banded_similar():
    ring = ChainParams(N=3, periodic=True)
    rest = np.zeros((3, ring.n_particles))
    assert get_model("sine").symmetric_similar_band(ring, rest) is None
    with pytest.raises(ValueError, match="not banded"):  # the Hessian's corner blocks
        get_model("nonlinear").symmetric_similar_band(ring, rest)


def test_bond_sums_assemble_what_their_six_by_six_blocks_assemble():
    # Each bond's block from its ten sums by the rule of BOND_SUMS (translations +-S, their
    # couplings to a rotation signed by the particle, the rotations alone), assembled by
    # the independent block path: the same matrix, banded or CSR, on every kind of end.
    rng = np.random.default_rng(5)
    for params in (*_ends(4), ChainParams(N=4, periodic=True)):
        n_bonds = params.n_bonds
        sums = rng.standard_normal((len(BOND_SUMS), n_bonds))
        s = dict(zip(BOND_SUMS, sums))
        blocks = np.zeros((n_bonds, 6, 6))
        S = np.array([[s["uu"], s["uv"]], [s["uv"], s["vv"]]]).transpose(2, 0, 1)
        for i, si in ((0, -1.0), (3, 1.0)):
            for j, sj in ((0, -1.0), (3, 1.0)):
                blocks[:, i : i + 2, j : j + 2] = si * sj * S
            for a, row in ((0, "u"), (1, "v")):
                for rotation, phi in ((2, "phi0"), (5, "phi1")):
                    blocks[:, i + a, rotation] = blocks[:, rotation, i + a] = si * s[f"{row}_{phi}"]
        blocks[:, 2, 2], blocks[:, 5, 5] = s["phi0_phi0"], s["phi1_phi1"]
        blocks[:, 2, 5] = blocks[:, 5, 2] = s["phi0_phi1"]
        expected = assemble_bond_blocks(blocks, params).toarray()
        assert np.allclose(assemble_bond_sums(sums, params).toarray(), expected, rtol=0, atol=1e-14)
        if params.periodic:
            with pytest.raises(ValueError, match="a ring's matrices are not banded"):
                assemble_bond_sums(sums, params, band=True)
        else:
            assert np.array_equal(assemble_bond_sums(sums, params, band=True).toarray(), assemble_bond_sums(sums, params).toarray())


def test_the_nonlinear_hessian_sums_are_the_second_differences_of_the_energy():
    # An independent check of the compiled sums: the stiffness from them against central
    # differences of the forces, on a random geometry far from rest.
    model = get_model("nonlinear")
    params = ChainParams(**{**random_geometries(1, seed=21)[0].model_dump(), "N": 6})
    x = random_state(params, 0.4, seed=2)
    assert _hessian(params, x).shape == (len(BOND_SUMS), params.n_bonds)
    k = model.stiffness_band(params, x).toarray()
    q, step = pack(params, x), 1e-6
    columns = []
    for i in range(q.size):
        e = np.zeros(q.size)
        e[i] = step
        plus, minus = model.forces(params, unpack(params, q + e)), model.forces(params, unpack(params, q - e))
        columns.append(-(pack(params, plus) - pack(params, minus)) / (2 * step))
    assert np.allclose(k, np.array(columns).T, rtol=0, atol=1e-7 * np.abs(k).max())


def _dense_lu_without_pivoting(a: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The textbook Doolittle elimination (unit lower L, upper U) of a dense matrix, as a reference."""
    n = a.shape[0]
    lower, upper = np.eye(n), a.astype(float).copy()
    for j in range(n):
        for i in range(j + 1, n):
            lower[i, j] = upper[i, j] / upper[j, j]
            upper[i, j:] -= lower[i, j] * upper[j, j:]
    return lower, upper


@pytest.mark.parametrize("n", [1, 2, 5, 6, 11, 40])
def test_the_band_lu_is_the_dense_elimination_of_minus_k_and_its_pivots_count_the_negative_eigenvalues(n):
    # The row-by-row elimination has a branch for the first B rows and one for the rest;
    # n = 1 ... 40 covers both and their seam. A symmetric matrix with a shifted diagonal
    # is indefinite: its pivots' signs are its inertia (Sylvester), which the continuation
    # takes for the index instead of a factor of its own.
    from cosserat_chain.linalg import BorderedFactor

    rng = np.random.default_rng(n)
    for shift in (0.0, 1.5, 4.0):
        upper = sp.triu(_random_band(n, seed=10 * n + int(shift)))
        symmetric = (upper + upper.T + sp.eye(n) * (6.0 - 2 * shift)).tocsr()
        factor = BorderedFactor(BandMatrix.from_sparse(symmetric), dof=n - 1)
        lower, up = _dense_lu_without_pivoting(-symmetric.toarray())
        band = factor._band
        for i in range(n):
            for j in range(max(0, i - BANDWIDTH), min(n, i + BANDWIDTH + 1)):
                expected = lower[i, j] if j < i else up[i, j]
                assert band[i, BANDWIDTH + j - i] == pytest.approx(expected, rel=1e-12, abs=1e-12)
        assert np.allclose(factor._inverse, 1.0 / np.diag(up), rtol=1e-12)
        assert factor.negative_eigenvalues == np.count_nonzero(np.linalg.eigvalsh(symmetric.toarray()) < 0)
        # A system solved with the factor, refined, is solved to round-off.
        row, rhs = rng.standard_normal(n + 1), rng.standard_normal(n + 1)
        dense = np.zeros((n + 1, n + 1))
        dense[:n, :n], dense[n - 1, n], dense[n] = -symmetric.toarray(), 1.0, row
        assert np.allclose(factor.solve(row, rhs), np.linalg.solve(dense, rhs), rtol=1e-9, atol=1e-9)


@pytest.mark.parametrize("params", [ChainParams(N=1), ChainParams(N=4, right_end="free"), *random_geometries(3, seed=21)], ids=str)
def test_the_tangent_factors_inertia_is_the_dense_index_of_the_stiffness_at_random_states(params):
    from cosserat_chain.linalg import BorderedFactor
    from cosserat_chain.numerics.newton import moment_dof
    from cosserat_chain.numerics.stability import static_stability

    model = get_model("nonlinear")
    for seed, scale in enumerate((0.05, 0.5, 2.0)):
        x = random_state(params, scale, seed)
        k = model.stiffness_band(params, x)
        counted = BorderedFactor(k, moment_dof(params, 0)).negative_eigenvalues
        dense = static_stability(params, model, x, dense=True)
        assert counted == dense.index
        # Given to the banded stability, the count is its index (and changes nothing else).
        given = static_stability(params, model, x, similar=k, index=counted)
        assert given == static_stability(params, model, x, similar=k)
    assert BorderedFactor(sp.eye(12, format="csr") + sp.eye(12, k=7, format="csr"), 0).negative_eigenvalues is None
