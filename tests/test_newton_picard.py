"""Newton-Picard shooting (numerics.newton_picard): the blocks' orbit, the leading multipliers within their residuals."""

from __future__ import annotations

import numpy as np
import pytest

from conftest import random_geometries
from cosserat_chain import ChainParams
from cosserat_chain.numerics import newton_picard
from cosserat_chain.numerics.newton_picard import RHO, check_options, ritz_multipliers
from cosserat_chain.numerics.periodic import find_periodic_orbit, initial_guess

#: The two shootings stop at closure 1e-12 (the blocks' depth below tol 1e-9) with products at 1e-11: their orbits agree to this.
SAME_ORBIT = 1e-9

#: (params, model, moment, guess's moment or None for the settled simulation's): the strongly damped sine and nonlinear
#: chains of benchmarks/bench_long_orbits.py, shortened to N = 6 (the sine chain's multipliers 0.957 and 0.546 above rho,
#: 0.445 just below it; N = 10 and 30 are the slow test's), and a random geometry (whose settled guess closes only to
#: 1e-1, outside Newton-Picard's basin: it starts, as documented, from the orbit at a nearby moment).
CASES = {
    "sine N=6": (ChainParams(N=6, gamma_u=1.0, gamma_v=1.0, gamma_phi=1.0), "sine", 0.3, None),
    "nonlinear N=6": (ChainParams(N=6, gamma_u=1.0, gamma_v=1.0, gamma_phi=1.0), "nonlinear", 0.3, None),
    "random sine N=3": (random_geometries(6, seed=3)[1], "sine", 0.40880890655281255, 0.41),
}


def _shootings(params, model, moment, nearby=None) -> dict:
    if nearby is None:
        guess = initial_guess(params, model, moment)
    else:
        guess = find_periodic_orbit(params, model, nearby, method="blocks")
    return {method: find_periodic_orbit(params, model, moment, guess=guess, method=method) for method in ("picard", "blocks")}


@pytest.fixture(scope="module", params=list(CASES))
def two_shootings(request):
    """The same orbit from the same guess by Newton-Picard and by the blocks (all multipliers)."""
    return _shootings(*CASES[request.param])


def _check_against_blocks(picard, blocks) -> None:
    assert picard.period == pytest.approx(blocks.period, abs=SAME_ORBIT)
    assert np.max(np.abs(picard.x - blocks.x)) < SAME_ORBIT and np.max(np.abs(picard.v - blocks.v)) < SAME_ORBIT
    # Every multiplier above rho, no more and no fewer (the trivial one besides), each one of the blocks' within the two
    # stated errors (the residuals here, the blocks' deflated eigen-residuals).
    assert picard.multiplier_errors.shape == picard.multipliers.shape
    for mu, error in zip(picard.multipliers, picard.multiplier_errors, strict=True):
        nearest = np.argmin(np.abs(blocks.multipliers - mu))
        assert abs(blocks.multipliers[nearest] - mu) <= error + blocks.multiplier_errors[nearest]
    assert np.count_nonzero(np.abs(blocks.multipliers) > RHO + 1e-6) <= picard.multipliers.size
    assert np.all(np.abs(picard.multipliers) > RHO) and picard.multipliers.size <= np.count_nonzero(np.abs(blocks.multipliers) > RHO - 1e-6)
    # The trivial one equals 1 within its error |(M - I) f| / |f|, which is small.
    assert abs(picard.trivial_multiplier - 1.0) <= picard.trivial_multiplier_error < 1e-9
    assert picard.stable == blocks.stable


def test_newton_picard_finds_the_blocks_orbit_and_their_multipliers_above_rho(two_shootings):
    _check_against_blocks(two_shootings["picard"], two_shootings["blocks"])


@pytest.mark.slow
@pytest.mark.parametrize(("n", "model"), [(10, "sine"), (10, "nonlinear"), (30, "sine")])
def test_newton_picard_on_longer_chains(n, model):
    # At N = 30, 19 multipliers above rho = 0.5 among 354, the largest nontrivial 0.99993 (a soft mode Newton must carry).
    _check_against_blocks(**_shootings(ChainParams(N=n, gamma_u=1.0, gamma_v=1.0, gamma_phi=1.0), model, 0.3))


class _Matrix:
    """A Monodromy stand-in: products with a known matrix."""

    def __init__(self, matrix: np.ndarray):
        self.matrix = matrix
        self.size = matrix.shape[0]

    def apply(self, columns: np.ndarray) -> np.ndarray:
        return self.matrix @ columns


def test_subspace_iteration_gives_the_multipliers_above_rho_of_a_non_normal_matrix_with_their_residuals():
    rng = np.random.default_rng(7)
    size = 60
    # The flow's 1, a real one near 1, a complex pair and a real one just above rho, the rest below rho / 2.
    known = np.concatenate([[1.0, 0.97, 0.6], 0.8 * np.exp([0.4j, -0.4j]), 0.25 * rng.uniform(-1, 1, size - 5)])
    basis = (np.eye(size) + 0.3 * rng.standard_normal((size, size))).astype(complex)
    basis[:, 3], basis[:, 4] = basis[:, 3].real + 1j * basis[:, 4].real, basis[:, 3].real - 1j * basis[:, 4].real
    matrix = np.real(basis @ np.diag(known) @ np.linalg.inv(basis))
    values, errors, _ = ritz_multipliers(_Matrix(matrix), basis[:, 0].real, rho=0.5, guard=4)
    above = known[np.abs(known) > 0.5]
    assert values.size == above.size
    assert np.max([np.min(np.abs(above - mu)) for mu in values]) < 1e-9
    assert values[0] == pytest.approx(1.0, abs=1e-12) and errors[0] < 1e-12
    # Each residual is what it says: |M x - mu x| of the Ritz vector, small; all certified above rho.
    assert np.all(errors < 1e-9) and np.all(np.abs(values) - errors > 0.5)


@pytest.mark.parametrize(
    ("rho", "guard", "match"),
    [
        (1.0, 8, r"rho must be a number in \(0, 1\)"),
        (0.0, 8, r"rho must be a number in \(0, 1\)"),
        (float("nan"), 8, r"rho must be a number in \(0, 1\)"),
        (0.5, 0, r"guard must be an integer in \[1, 112\]"),
        (0.5, 2.5, r"guard must be an integer in \[1, 112\]"),
    ],
)
def test_bad_rho_or_guard_is_refused_with_what_is_allowed(rho, guard, match):
    with pytest.raises(ValueError, match=match):
        check_options(rho, guard, 114)


def test_find_periodic_orbit_refuses_a_bad_module_rho(monkeypatch):
    params = ChainParams(N=3, gamma_u=1.0, gamma_v=1.0, gamma_phi=1.0)
    guess = initial_guess(params, "sine", 0.3)
    monkeypatch.setattr(newton_picard, "RHO", 1.5)
    with pytest.raises(ValueError, match=r"rho must be a number in \(0, 1\).*got 1.5"):
        find_periodic_orbit(params, "sine", 0.3, guess=guess, method="picard")
    with pytest.raises(ValueError, match="segments applies to the dense and blocks shooting only"):
        find_periodic_orbit(params, "sine", 0.3, guess=guess, method="picard", segments=4)


def test_find_periodic_orbit_takes_rho_and_guard_and_refuses_them_for_other_methods():
    # The strongly damped N = 3 chain: one nontrivial multiplier (0.4992) between rho = 0.2 and the default 0.5.
    params = ChainParams(N=3, gamma_u=1.0, gamma_v=1.0, gamma_phi=1.0)
    guess = initial_guess(params, "sine", 0.3)
    blocks = find_periodic_orbit(params, "sine", 0.3, guess=guess, method="blocks")
    between = blocks.multipliers[
        (np.abs(blocks.multipliers) > 0.2) & (np.abs(blocks.multipliers) < RHO) & (np.abs(blocks.multipliers - 1) > 1e-6)
    ]
    assert between.size == 1
    default = find_periodic_orbit(params, "sine", 0.3, guess=guess, method="picard")
    lower = find_periodic_orbit(params, "sine", 0.3, guess=guess, method="picard", rho=0.2, guard=4)
    assert np.all(np.abs(default.multipliers - between[0]) > 1e-3)
    nearest = np.argmin(np.abs(lower.multipliers - between[0]))
    assert abs(lower.multipliers[nearest] - between[0]) <= lower.multiplier_errors[nearest] + 1e-9
    assert lower.period == pytest.approx(blocks.period, abs=SAME_ORBIT)
    with pytest.raises(ValueError, match=r"rho and guard apply to method='picard' only, got method='blocks'"):
        find_periodic_orbit(params, "sine", 0.3, guess=guess, method="blocks", rho=0.2)
    with pytest.raises(ValueError, match=r"guard must be an integer in \[1, 28\].*got 0"):
        find_periodic_orbit(params, "sine", 0.3, guess=guess, method="picard", guard=0)


@pytest.mark.slow
def test_a_longer_settle_puts_the_guess_where_newton_picard_steps_in_full():
    # The settled run stops where two turns take the same time to 1e-3 while its period still drifts (docs/periodic-orbits.md,
    # why N = 500 stalled): continued by 100 more calls, the guess's period is 30x nearer the orbit's and Newton-Picard
    # converges from it to the same orbit in fewer iterations.
    params = ChainParams(N=20, gamma_u=1.0, gamma_v=1.0, gamma_phi=1.0)
    settled = initial_guess(params, "sine", 0.3)
    longer = settled
    for _ in range(100):
        longer = initial_guess(params, "sine", 0.3, x0=longer[0], v0=longer[1])
    from_settled = find_periodic_orbit(params, "sine", 0.3, guess=settled, method="picard")
    from_longer = find_periodic_orbit(params, "sine", 0.3, guess=longer, method="picard")
    assert abs(longer[2] - from_settled.period) < abs(settled[2] - from_settled.period) / 30
    assert from_longer.period == pytest.approx(from_settled.period, abs=SAME_ORBIT)
    assert np.max(np.abs(from_longer.x - from_settled.x)) < SAME_ORBIT
    assert from_longer.iterations < from_settled.iterations


def test_trust_region_step_is_newtons_within_reach_and_the_best_step_of_that_length_beyond():
    # A nearly singular direction (a soft multiplier within 1e-8 of 1) makes the Newton step long: within the reach the
    # step is Newton's; beyond it, the Levenberg-Marquardt step of the reach's length, whose linear residual is below that
    # of Newton's step cut to the same length (the halving that keeps its direction) and of random steps of that length.
    rng = np.random.default_rng(3)
    matrix = rng.standard_normal((6, 6)) @ np.diag([1.0, 0.8, 0.5, 0.3, 0.1, 1e-8]) @ rng.standard_normal((6, 6))
    right = rng.standard_normal(6)
    newton_step = np.linalg.solve(matrix, right)
    same = newton_picard._trust_region_step(matrix, right, lambda x: x, 2 * np.linalg.norm(newton_step))
    assert np.allclose(same, newton_step, rtol=1e-5, atol=0)  # two solves of a system of condition 1e9
    reach = 1.0
    assert np.linalg.norm(newton_step) > 1e3 * reach
    step = newton_picard._trust_region_step(matrix, right, lambda x: x, reach)
    assert np.linalg.norm(step) == pytest.approx(reach, rel=1e-5)
    residual = np.linalg.norm(matrix @ step - right)
    assert residual < np.linalg.norm(matrix @ (newton_step * reach / np.linalg.norm(newton_step)) - right)
    for trial in rng.standard_normal((200, 6)):
        assert residual <= np.linalg.norm(matrix @ (trial * reach / np.linalg.norm(trial)) - right) + 1e-12


def test_newton_picards_default_start_is_the_settled_guess_continued_nearer_the_orbit(monkeypatch):
    """Without a guess, method="picard" continues the settled simulation by PICARD_SETTLE further settled runs (the
    period still drifts where two turns agree to SETTLE_RTOL); the other methods start from the first settled run."""
    from cosserat_chain.numerics import periodic

    starts = []
    settled = periodic._settled_guess

    def counted(*args, **kwargs):
        starts.append("rest" if kwargs["x0"] is None else "continued")
        return settled(*args, **kwargs)

    monkeypatch.setattr(periodic, "_settled_guess", counted)
    monkeypatch.setattr(periodic, "PICARD_SETTLE", 4)
    params, model, moment = ChainParams(N=10, gamma_u=1.0, gamma_v=1.0, gamma_phi=1.0), "sine", 0.3
    orbit = find_periodic_orbit(params, model, moment, method="picard")
    assert starts == ["rest"] + ["continued"] * 4
    first = continued = initial_guess(params, model, moment)
    for _ in range(4):
        continued = initial_guess(params, model, moment, x0=continued[0], v0=continued[1])
    assert abs(continued[2] - orbit.period) < 0.5 * abs(first[2] - orbit.period)
    starts.clear()
    find_periodic_orbit(ChainParams(N=1), model, 1.5, method="dense")
    assert starts == ["rest"]
