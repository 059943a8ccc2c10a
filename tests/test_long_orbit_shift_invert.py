"""Leading Floquet multipliers of long orbits where they crowd near 1: shift-invert on the formed monodromy (numerics.long_orbits,
linalg.eigen.largest_and_nearest), against LAPACK's eigenvalues of the same matrix."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.linalg as sla

from cosserat_chain import ChainParams, memory
from cosserat_chain.linalg.eigen import largest_and_nearest
from cosserat_chain.models import get_model
from cosserat_chain.numerics import long_orbits
from cosserat_chain.numerics.long_orbits import Monodromy, leading_multipliers
from cosserat_chain.numerics.periodic import _System, _to_y, find_periodic_orbit, initial_guess

#: The crowd: 1 - CROWD_SCALE k^4, k = 1 ... CROWD (a long chain's soft bending modes, 1e-9 to 1e-5 below 1).
CROWD, CROWD_SCALE = 10, 1e-9
#: LAPACK's own eigenvalues of these matrices carry a few 1e-15 (the round-off of |M| times their condition).
LAPACK_ROUND_OFF = 1e-13


def _crowded_monodromy(size: int = 300, seed: int = 1) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A non-normal matrix with the trivial multiplier 1 (eigenvector: the returned flow), a crowd of real multipliers within
    1e-5 below it, a ring of complex pairs at |mu| 0.92-0.94 (the damped modes) and the rest below 0.5; and its eigenvalues."""
    rng = np.random.default_rng(seed)
    known = [1.0] + [1.0 - CROWD_SCALE * k**4 for k in range(1, CROWD + 1)]
    diagonal = np.zeros((size, size))
    diagonal[np.arange(len(known)), np.arange(len(known))] = known
    j = len(known)
    while j + 2 <= size - 20:
        angle, radius = rng.uniform(0.1, 3.0), 0.939 * (1 - 0.02 * rng.random())
        diagonal[j : j + 2, j : j + 2] = radius * np.array([[np.cos(angle), -np.sin(angle)], [np.sin(angle), np.cos(angle)]])
        j += 2
    diagonal[np.arange(j, size), np.arange(j, size)] = 0.5 * rng.random(size - j)
    basis = np.eye(size) + 0.3 * rng.standard_normal((size, size)) / np.sqrt(size)
    return basis @ diagonal @ np.linalg.inv(basis), basis[:, 0], sla.eigvals(diagonal)


def _nearest(reference: np.ndarray, values: np.ndarray) -> np.ndarray:
    return np.array([np.min(np.abs(reference - mu)) for mu in values])


def test_shift_invert_finds_the_crowded_leading_multipliers_lapack_finds_within_their_stated_errors(monkeypatch):
    # Largest-modulus ARPACK cannot separate the crowd from the ring within its restarts, and the Arnoldi fallback's Ritz
    # values were off by up to 1e-3 (residuals 1e-2): shift-invert just above 1 resolves each to its residual.
    matrix, flow, _ = _crowded_monodromy()
    exact = sla.eigvals(matrix)
    monkeypatch.setattr(long_orbits, "ALL_MULTIPLIERS_UP_TO", 100)
    with pytest.warns(UserWarning, match="is not excluded"):
        values, errors = leading_multipliers(matrix, flow)
    assert values.size == long_orbits.MULTIPLIERS + 1
    assert np.all(_nearest(exact, values) <= errors + LAPACK_ROUND_OFF)
    assert np.all(errors < 1e-8)
    leading = exact[np.argsort(-np.abs(exact))][: CROWD + 1]  # the trivial one and the crowd
    assert np.max(_nearest(values, leading)) < 1e-10
    trivial = np.argmin(np.abs(values - 1.0))
    assert abs(values[trivial] - 1.0) <= errors[trivial] + LAPACK_ROUND_OFF


def test_where_the_lu_factors_do_not_fit_the_fallback_says_so_and_flags_its_unconverged_multipliers(monkeypatch):
    matrix, flow, _ = _crowded_monodromy()
    monkeypatch.setattr(long_orbits, "ALL_MULTIPLIERS_UP_TO", 100)
    monkeypatch.setattr(memory, "available", lambda: 1000)
    with pytest.warns(UserWarning) as record:
        values, errors = leading_multipliers(matrix, flow)
    messages = [str(warning.message) for warning in record]
    assert any("not enough memory: the LU factors of M" in message for message in messages)
    # The Arnoldi fallback's Ritz values, each with its residual: those above UNCONVERGED are counted in the warning.
    trivial = np.argmin(np.abs(values - 1.0))
    loose = np.delete(errors > long_orbits.UNCONVERGED * np.maximum(1.0, np.abs(values)), trivial)
    assert np.any(loose)
    assert any(f"{np.count_nonzero(loose)} of {values.size - 1} nontrivial Floquet multipliers did not converge" in m for m in messages)


def test_largest_and_nearest_finds_both_sets_of_a_known_spectrum_once_each():
    # A normal matrix: eigenvalue errors are bounded by the residuals, and the two runs' common values appear once.
    rng = np.random.default_rng(2)
    known = np.concatenate([[2.0, 1.5], 1.0 - 1e-8 * np.arange(1, 7) ** 2, rng.uniform(-0.9, 0.9, 92)])
    rotation = np.linalg.qr(rng.standard_normal((100, 100)))[0]
    matrix = rotation @ np.diag(known) @ rotation.T
    shift = 1.0 + 1e-9
    solve = sla.lu_factor(matrix - shift * np.eye(100))
    values, vectors, converged = largest_and_nearest(
        lambda z: matrix @ z, lambda z: sla.lu_solve(solve, z), 100, shift, 4, tol=1e-12, restarts=200
    )  # fmt: skip
    assert converged == (4, 4)
    nearest = known[np.argsort(np.abs(known - shift))][:4]
    assert values.size == 6  # 2, 1.5 and the four nearest the shift, which the largest-modulus run shares two of
    assert np.max(_nearest(values, np.concatenate([[2.0, 1.5], nearest]))) < 1e-12
    assert np.allclose(np.linalg.norm(vectors, axis=0), 1.0)
    assert np.all(np.diff(np.abs(values)) <= 1e-15)  # by decreasing modulus


def test_shift_invert_on_an_orbits_monodromy_equals_all_its_eigenvalues(monkeypatch):
    # The short orbit of a 31-particle sine chain (default fields, M = 0.5): its soft multipliers 4e-5, 6e-4, 1e-3 below 1,
    # the shift-invert's through the LU factors of M - s I and the Schur complement of the deflation (no deflated copy of M).
    params = ChainParams(N=30)
    orbit = find_periodic_orbit(params, "sine", 0.5, guess=initial_guess(params, "sine", 0.5), method="blocks")
    system = _System(params, get_model("sine"), 0.5, 0)
    start = _to_y(params, orbit.x, orbit.v)
    matrix = Monodromy(system, start, orbit.period, 1e-11, 1e-11).matrix()
    dense, dense_errors = leading_multipliers(matrix, system.velocity(start))
    monkeypatch.setattr(long_orbits, "ALL_MULTIPLIERS_UP_TO", 100)
    values, errors = leading_multipliers(matrix, system.velocity(start))
    assert values.size == long_orbits.MULTIPLIERS + 1
    assert np.all(_nearest(dense, values) <= errors + LAPACK_ROUND_OFF)
    assert np.max(_nearest(values, dense[:8])) < 1e-11
    assert errors[0] == pytest.approx(dense_errors[0], abs=1e-13) and abs(values[0] - 1.0) <= errors[0]
