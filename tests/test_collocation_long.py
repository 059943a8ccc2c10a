"""Collocation of long chains: the nested-dissection factor (the same Newton steps as minimum degree, fill linear
in N, work independent of the period) and the leading multipliers by Arnoldi (the dense path's where both run, the
shooting's on a chain of 30 particles)."""

from __future__ import annotations

import numpy as np
import pytest

from cosserat_chain import ChainParams
from cosserat_chain.models.base import get_model
from cosserat_chain.numerics import collocation_core, periodic
from cosserat_chain.numerics.collocation import find_collocation_orbit
from cosserat_chain.numerics.collocation_core import _Collocation, _shift, _SparseStep, _trajectory_guess, scheme
from cosserat_chain.numerics.periodic import find_periodic_orbit, initial_guess
from cosserat_chain.state import n_free

MOMENT = 0.5


def _guess(params: ChainParams, model: str = "sine") -> tuple:
    return tuple(initial_guess(params, model, MOMENT))[:3]


def _problem(orbit) -> tuple[_Collocation, np.ndarray, float]:
    """The collocation system at a solved orbit, its field Jacobian values and period."""
    system = periodic._System(orbit.params, get_model(orbit.model), orbit.moment, orbit.particle)
    problem = _Collocation(system, orbit.mesh, orbit.ncol, _shift(system, orbit.particle_turns), orbit.profile, free_moment=False)
    a_values, period = problem.evaluate(problem.pack(orbit.profile, orbit.period), True).data
    return problem, a_values, period


@pytest.fixture(scope="module")
def chain5():
    """The nonlinear chain at N = 5 (its multipliers' moduli distinct, three pairs outside the circle; 2 n_free = 54, of
    which Arnoldi takes twenty, as on a long chain)."""
    params = ChainParams(N=5)
    return find_collocation_orbit(params, "nonlinear", MOMENT, guess=_guess(params, "nonlinear"))


def test_the_dissected_factor_gives_the_minimum_degree_orbit(monkeypatch):
    """The same orbit (period, profile) by Newton on the nested-dissection factor and on SuperLU's minimum degree
    (N = 4: the dissection splits both across the mesh and across the particles)."""
    params = ChainParams(N=4)
    dissected = find_collocation_orbit(params, "nonlinear", MOMENT, guess=_guess(params, "nonlinear"))
    monkeypatch.setattr(_Collocation, "elimination_order", lambda self, bordered: None)
    old = find_collocation_orbit(params, "nonlinear", MOMENT, guess=_guess(params, "nonlinear"))
    assert dissected.period == pytest.approx(old.period, rel=1e-12)
    assert np.max(np.abs(dissected.profile - old.profile)) < 1e-9
    assert dissected.iterations == old.iterations


def test_the_leading_multipliers_are_the_dense_paths(chain5):
    """Arnoldi on the intervals' sparse maps and on the shift-inverted periodic problem: each multiplier one of the
    dense transfer matrices' (periodic Schur) to 1e-10, all those on or outside the unit circle (three pairs and the
    trivial one) found, the trivial one within 1e-10 of 1, each error estimate small. (Within the damped ring of
    nearly equal moduli below the circle the set found need not be the twenty largest.)"""
    problem, a_values, period = _problem(chain5)
    dense = problem.floquet(a_values, period)  # 2 n_free = 54: all multipliers
    assert dense.values.size == problem.n
    leading = problem.leading(a_values, period)
    for value in leading.values:
        assert np.min(np.abs(dense.values - value)) < 1e-10
    outside = dense.values[np.abs(dense.values) > 0.99]
    assert outside.size == 7
    for value in outside:
        assert np.min(np.abs(leading.values - value)) < 1e-10
    assert np.min(np.abs(leading.values - 1.0)) < 1e-10
    assert np.all(leading.errors < 1e-9)
    assert np.all(np.diff(np.abs(leading.values)) <= 1e-15)


def test_above_the_threshold_an_orbit_carries_the_leading_multipliers(monkeypatch):
    """With the threshold below the chain's 2 n_free the orbit gets the leading multipliers (the same ones above 0.99)."""
    params = ChainParams(N=3)
    guess = _guess(params)
    dense = find_collocation_orbit(params, "sine", MOMENT, guess=guess)
    monkeypatch.setattr(collocation_core, "ALL_MULTIPLIERS_UP_TO", 10)
    leading = find_collocation_orbit(params, "sine", MOMENT, guess=guess)
    assert leading.multipliers.size < dense.multipliers.size
    assert leading.period == pytest.approx(dense.period, rel=1e-12)
    for value in dense.multipliers[np.abs(dense.multipliers) > 0.99]:
        assert np.min(np.abs(leading.multipliers - value)) < 1e-10
    assert leading.trivial_multiplier_error < 1e-10 and leading.stable == dense.stable


def _fills(params: ChainParams) -> tuple[int, int]:
    """Entries of L + U of the bordered Newton system (M free, the arclength row) on the guess's profile, factored in
    the nested-dissection order and in SuperLU's minimum degree (the same system, built once)."""
    system = periodic._System(params, get_model("sine"), MOMENT, 0)
    x0, v0, period = _guess(params)
    sch = scheme(collocation_core.NCOL)
    mesh = np.linspace(0.0, 1.0, collocation_core.NTST + 1)
    shift = _shift(system, periodic._loaded_turns(params, 0, 1, MOMENT))
    profile = _trajectory_guess(system, periodic._to_y(params, x0, v0), period, mesh, sch, shift)
    problem = _Collocation(system, mesh, sch.ncol, shift, profile, free_moment=True)
    w = problem.pack(profile, period, MOMENT)
    evaluation = problem.evaluate(w, True)
    t = np.cos(np.arange(w.size, dtype=float))
    fills = []
    for order in (problem.elimination_order(True), None):
        step = _SparseStep((t / np.linalg.norm(t), w), order)
        step(w, evaluation, evaluation.matrix())
        assert step.factorizations == 1
        fills.append(step.fill)
    return fills[0], fills[1]


def test_the_factors_fill_grows_linearly_with_the_chain():
    """nnz(L + U) / N grows by less than 1.3 from N = 10 to 20 in the nested-dissection order (measured 1.25, the
    log N of a dissected grid while the chain is shorter than the mesh is long; 1.21 from N = 20 to 40); SuperLU's
    minimum degree on the same systems by more than 1.35 (measured 1.39, 1.36 from N = 20 to 40: its fill goes like
    N^2 per mesh point)."""
    (dissected_10, minimum_degree_10), (dissected_20, minimum_degree_20) = (np.array(_fills(ChainParams(N=n))) / n for n in (10, 20))
    assert dissected_20 / dissected_10 < 1.3
    assert minimum_degree_20 / minimum_degree_10 > 1.35
    assert dissected_20 < minimum_degree_20


def test_the_work_of_a_solve_does_not_grow_with_the_period(monkeypatch):
    """Two orbits of the nonlinear N = 1 chain towards its SNIC, periods 10x apart (3.8 at M = 0.3, 36 at M = 0.26225,
    each solved from the settled guess on 40 intervals), solved again from themselves on the same number of intervals:
    the same Jacobian entries, factors of the same fill, no more factorisations."""
    short, long = (find_collocation_orbit(ChainParams(N=1), "nonlinear", moment) for moment in (0.3, 0.26225))
    assert long.period > 8.0 * short.period and long.mesh.size == short.mesh.size
    steps: list[_SparseStep] = []
    original = _SparseStep.__init__

    def spy(self, *args, **kwargs):
        original(self, *args, **kwargs)
        steps.append(self)

    monkeypatch.setattr(_SparseStep, "__init__", spy)
    work = []
    for orbit in (short, long):
        steps.clear()
        again = find_collocation_orbit(orbit.params, "nonlinear", orbit.moment, guess=orbit, adapt=0)
        assert again.period == pytest.approx(orbit.period, rel=1e-8)
        work.append((sum(s.factorizations for s in steps), max(s.fill for s in steps)))
    (count_short, fill_short), (count_long, fill_long) = work
    assert count_long <= count_short + 1
    assert abs(fill_long / fill_short - 1.0) < 0.05


@pytest.mark.slow
def test_a_chain_of_30_particles_is_the_block_shootings_orbit():
    """N = 30 (2 n_free = 354, the leading multipliers' path): the period of the shooting's ``blocks`` method to 1e-8,
    its multipliers above 0.99 in modulus (the soft modes' cluster below 1 among them) to 1e-6, the trivial one near 1."""
    params = ChainParams(N=30)
    guess = _guess(params)
    orbit = find_collocation_orbit(params, "sine", MOMENT, guess=guess)
    assert orbit.multipliers.size < 2 * n_free(params)
    shot = find_periodic_orbit(params, "sine", MOMENT, guess=guess, method="blocks", tol=1e-10, rtol=1e-12, atol=1e-12)
    assert orbit.period == pytest.approx(shot.period, rel=1e-8)
    near = shot.multipliers[np.abs(shot.multipliers) > 0.99]
    assert near.size >= 3
    for value in near:
        assert np.min(np.abs(orbit.multipliers - value)) < 1e-6
    assert orbit.trivial_multiplier_error < 1e-9
