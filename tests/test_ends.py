"""Ends other than clamped: pinned and free ends and the ring (``ChainParams.left_end``, ``right_end``, ``periodic``).

Each test checks what a wrong implementation of the ends would fail: the rigid
motions a free chain keeps (zero modes, invariance of the energy, conservation of
momentum and angular momentum), a ring's modes against the infinite chain's
dispersion, the degrees of freedom a pinned end holds, the point symmetry of the
response to a central moment, and the engine's copies of one run (batch, threads,
the adaptive reference) against each other.
"""

from __future__ import annotations

import numpy as np
import pytest

from conftest import ROUND_OFF, random_geometries, random_state
from cosserat_chain import ChainParams, moment_load
from cosserat_chain.analysis.dispersion import finite_modes
from cosserat_chain.loads import Loads, PointLoad, Schedule
from cosserat_chain.models import LINEAR, NONLINEAR, SINE
from cosserat_chain.models.linear import bloch_stiffness
from cosserat_chain.models.nonlinear import chain_energy
from cosserat_chain.numerics.adaptive import integrate_adaptive
from cosserat_chain.numerics.batch import integrate_batch
from cosserat_chain.numerics.dynamics import integrate
from cosserat_chain.numerics.newton import solve_equilibrium
from cosserat_chain.state import fixed_mask, free_index, n_free, pack
from static_onsets import nonlinear_critical

ALL = [NONLINEAR, SINE, LINEAR]
ENDS = {
    "free": {"left_end": "free", "right_end": "free"},
    "pinned": {"left_end": "pinned", "right_end": "pinned"},
    "clamped-free": {"left_end": "clamped", "right_end": "free"},
    "pinned-free": {"left_end": "pinned", "right_end": "free"},
    "ring": {"periodic": True},
}
GEOMETRIES = random_geometries(4, seed=14)


def chains(kind: str) -> list[ChainParams]:
    """The paper's chain and random admissible geometries of several lengths, with the given ends."""
    return [ChainParams(**ENDS[kind])] + [g.replace(N=n, **ENDS[kind]) for g, n in zip(GEOMETRIES, (1, 2, 5, 9))]


def rigid_motions(params: ChainParams) -> np.ndarray:
    """Translations along u and v and the linearised rigid rotation (v = theta X, phi = theta), packed, (n_free, 3)."""
    X = params.h * np.arange(-params.N, params.N + 1, dtype=float)
    motions = np.zeros((3, 3, params.n_particles))
    motions[0, 0] = 1.0
    motions[1, 1] = 1.0
    motions[2, 1] = X
    motions[2, 2] = 1.0
    return np.stack([pack(params, m) for m in motions], axis=1)


# --------------------------------------------------------------------------- parameters
def test_ends_are_validated_with_the_field_value_and_the_choices():
    with pytest.raises(ValueError, match=r"left_end must be one of 'clamped', 'pinned', 'free', got 'hinged'"):
        ChainParams(left_end="hinged")
    with pytest.raises(ValueError, match="periodic=True .* has no ends"):
        ChainParams(periodic=True, right_end="free")
    with pytest.raises(ValueError, match="periodic"):
        ChainParams(periodic="yes")
    p = ChainParams(left_end="pinned", right_end="free")
    assert p.replace(N=5).ends == ("pinned", "free")
    assert ChainParams(**p.model_dump()) == p  # the ends travel with the parameters (TOML, NetCDF, JSON)
    assert (ChainParams().rigid_modes, p.rigid_modes, ChainParams(periodic=True).rigid_modes) == (0, 1, 2)
    ring = ChainParams(N=2, periodic=True)
    assert ring.ends == ("ring", "ring") and ChainParams(**ring.model_dump()) == ring
    with pytest.raises(ValueError, match="'ring' only with periodic = true"):
        ChainParams(left_end="ring")


def test_the_fixed_degrees_of_freedom_of_each_end():
    p = ChainParams(N=2, left_end="pinned", right_end="clamped")
    mask = fixed_mask(p)
    assert mask[:, 0].tolist() == [True, True, False] and mask[:, -1].all() and not mask[:, 1:-1].any()
    assert n_free(p) == 3 * 3 + 1
    assert n_free(ChainParams(N=2, periodic=True)) == n_free(ChainParams(N=2, left_end="free", right_end="free")) == 15
    # The default keeps the paper's ordering: (u, v, phi) of particles -N+1 .. N-1.
    np.testing.assert_array_equal(free_index(ChainParams(N=2)), np.arange(3, 12))


def test_a_load_on_a_held_degree_of_freedom_is_refused_and_a_free_one_is_taken():
    p = ChainParams(N=3, left_end="pinned", right_end="free")
    with pytest.raises(ValueError, match="load on u of particle -3: the left end is pinned and holds u fixed"):
        Loads([PointLoad("u", -3, Schedule.constant(0.1))]).validate(p)
    Loads([PointLoad("phi", -3, Schedule.constant(0.1)), PointLoad("v", 3, Schedule.constant(0.1))]).validate(p)
    with pytest.raises(ValueError, match="the right end is clamped"):
        moment_load(0.1, 3).validate(ChainParams(N=3))


def test_a_state_that_moves_a_held_degree_of_freedom_is_refused():
    p = ChainParams(N=2, left_end="pinned")
    x = np.zeros((3, p.n_particles))
    x[2, 0] = 0.3  # phi of a pinned end is free
    NONLINEAR.forces(p, x)
    x[1, 0] = 0.1
    with pytest.raises(ValueError, match=r"x\[v\] of particle -2 is 0.1, but its end is pinned"):
        NONLINEAR.forces(p, x)


# --------------------------------------------------------------------------- rigid motions
@pytest.mark.parametrize("model", [NONLINEAR, LINEAR], ids=lambda m: m.name)
@pytest.mark.parametrize("params", chains("free"), ids=lambda p: f"N{p.N}")
def test_a_free_chain_at_rest_has_exactly_three_zero_modes_its_rigid_motions(model, params):
    K = model.stiffness(params, np.zeros((3, params.n_particles))).toarray()
    scale = np.abs(K).max()
    np.testing.assert_allclose(K @ rigid_motions(params), 0.0, atol=1e-12 * scale)
    eigenvalues = np.linalg.eigvalsh(K)
    assert np.sum(np.abs(eigenvalues) < 1e-10 * scale) == 3
    assert eigenvalues[3] > 1e-8 * scale


@pytest.mark.parametrize("params", chains("pinned-free"), ids=lambda p: f"N{p.N}")
def test_a_pinned_free_chain_keeps_only_the_rotation_about_its_pin(params):
    modes = finite_modes(params, "nonlinear")
    omega2 = np.sort(modes.omega2.real)
    assert abs(omega2[0]) < 1e-10 * omega2[-1] < omega2[1]
    # The zero mode turns the chain about the pinned particle -N: v = theta (X + N h), phi = theta.
    shape = modes.shapes[np.argmin(np.abs(modes.omega2))]
    X = params.h * np.arange(params.n_particles)
    np.testing.assert_allclose(shape[1] / shape[2], X, atol=1e-8 * X[-1])
    np.testing.assert_allclose(shape[0], 0.0, atol=1e-8 * np.abs(shape).max())


@pytest.mark.parametrize("params", chains("free")[1:], ids=lambda p: f"N{p.N}")
def test_the_nonlinear_energy_and_forces_are_invariant_under_finite_rigid_motions(params):
    x = random_state(params, 0.3, seed=params.N)
    X = params.h * np.arange(-params.N, params.N + 1) + x[0]
    Y = x[1]
    theta, shift = 2.3, np.array([0.7, -1.9])
    c, s = np.cos(theta), np.sin(theta)
    moved = np.stack([c * X - s * Y + shift[0] - params.h * np.arange(-params.N, params.N + 1), s * X + c * Y + shift[1], x[2] + theta])
    energy = chain_energy(params, x)
    assert energy > 0
    np.testing.assert_allclose(chain_energy(params, moved), energy, rtol=1e-12)
    # The internal forces balance: no net force, no net moment about the origin.
    for state, centre_x in ((x, X), (moved, c * X - s * Y + shift[0])):
        f = NONLINEAR.forces(params, state)
        centre_y = state[1]
        assert abs(f[0].sum()) < 1e-12 * np.abs(f).max() and abs(f[1].sum()) < 1e-12 * np.abs(f).max()
        torque = np.sum(centre_x * f[1] - centre_y * f[0] + f[2])
        assert abs(torque) < 1e-11 * np.abs(f).max() * params.N * params.h


@pytest.mark.parametrize("model", ALL, ids=lambda m: m.name)
def test_a_free_undamped_chain_conserves_its_momentum_in_the_dynamics(model):
    params = GEOMETRIES[1].replace(N=6, gamma_u=0.0, gamma_v=0.0, gamma_phi=0.0, left_end="free", right_end="free")
    x0 = random_state(params, 0.05, seed=3)
    v0 = random_state(params, 0.05, seed=4)
    run = integrate(params, model, Loads(), t_end=40.0, x0=x0, v0=v0, n_frames=41)
    assert run.ok
    momentum = params.m * run.v[:, :2].sum(axis=-1)
    np.testing.assert_allclose(momentum, np.broadcast_to(momentum[0], momentum.shape), rtol=0, atol=1e-12)
    if model is NONLINEAR:
        # Angular momentum about the origin, sum m (X v_y - Y v_x) + j phi': the potential (1) is
        # invariant under rigid rotations, and velocity Verlet keeps such a momentum map.
        X = params.h * np.arange(-params.N, params.N + 1) + run.x[:, 0]
        L = params.m * np.sum(X * run.v[:, 1] - run.x[:, 1] * run.v[:, 0], axis=-1) + params.j * run.v[:, 2].sum(axis=-1)
        np.testing.assert_allclose(L, np.full_like(L, L[0]), rtol=0, atol=1e-11)


# --------------------------------------------------------------------------- the ring
@pytest.mark.parametrize("params", chains("ring"), ids=lambda p: f"N{p.N}")
def test_a_ring_has_the_infinite_chains_frequencies_at_its_wavenumbers(params):
    n = params.n_particles
    q = 2 * np.pi * np.arange(n) / n
    scale = 1.0 / np.sqrt(np.array(params.inertia))
    bloch = bloch_stiffness(params, q) * scale[:, None] * scale[None, :]
    expected = np.sort(np.linalg.eigvalsh(bloch).ravel())
    for model in ALL:
        got = np.sort(finite_modes(params, model).omega2.real)
        np.testing.assert_allclose(got, expected, atol=1e-10 * expected.max())
    assert np.sum(np.abs(expected) < 1e-10 * expected.max()) == 2  # the two translations


def test_a_ring_is_invariant_under_a_shift_of_its_particles():
    params = GEOMETRIES[2].replace(N=4, periodic=True)
    x = random_state(params, 0.4, seed=8)
    for model in ALL:
        f = model.compiled_forces(params, x)
        np.testing.assert_allclose(model.compiled_forces(params, np.roll(x, 3, axis=1)), np.roll(f, 3, axis=1), atol=1e-13)


# --------------------------------------------------------------------------- pinned ends
@pytest.mark.parametrize("model", ALL, ids=lambda m: m.name)
def test_pinned_ends_hold_u_and_v_and_let_phi_turn_with_a_point_symmetric_response(model):
    params = GEOMETRIES[0].replace(N=4, left_end="pinned", right_end="pinned")
    run = integrate(params, model, moment_load(0.02), t_end=60.0, n_frames=31)
    assert run.ok
    assert np.all(run.x[:, :2, [0, -1]] == 0.0) and np.all(run.v[:, :2, [0, -1]] == 0.0)
    assert np.abs(run.x[-1, 2, [0, -1]]).min() > 1e-4  # the pinned ends turn
    # A central moment on a chain with like ends: turning the plane by pi (x -> -x, y -> -y)
    # maps the problem onto itself, so u and v are odd in the particle and phi even.
    final = run.x[-1]
    np.testing.assert_allclose(final[:2], -final[:2, ::-1], atol=1e-12)
    np.testing.assert_allclose(final[2], final[2, ::-1], atol=1e-12)
    static = solve_equilibrium(params, model, moment_load(0.02))
    np.testing.assert_allclose(static[:2], -static[:2, ::-1], atol=1e-12)
    np.testing.assert_allclose(static[2], static[2, ::-1], atol=1e-12)


@pytest.mark.parametrize("kind", ["pinned", "clamped-free"])
def test_the_static_state_balances_the_forces_and_the_damped_run_comes_to_it(kind):
    params = GEOMETRIES[3].replace(N=3, **ENDS[kind])
    loads = moment_load(0.03, 1)
    static = solve_equilibrium(params, "nonlinear", loads)
    residual = NONLINEAR.forces(params, static)
    residual[2, params.N + 1] += 0.03
    assert np.abs(residual).max() < 1e-12
    run = integrate(params, "nonlinear", loads, t_end=3000.0, n_frames=3)
    np.testing.assert_allclose(run.x[-1], static, atol=1e-7)


def test_a_cantilevers_stable_branch_ends_at_a_branch_point_where_the_rotation_starts():
    """Paper's geometry, right end free, nonlinear model: K turns singular (three eigenvalues at
    once) at M = 0.08198 while M still rises; the chain rotates just above it, below the fold."""
    from cosserat_chain.numerics.relaxation import relax
    from cosserat_chain.numerics.stability import static_stability

    params = ChainParams(**ENDS["clamped-free"])
    result = nonlinear_critical(params)
    point = result.branch_point
    assert result.onset == "branch_point" and result.critical_moment == point.moment
    assert point.index_before == 0 and point.index_after > 0
    assert point.moment < result.fold.moment - 1e-3  # the fold lies higher, on the unstable part
    # K is singular there: its smallest eigenvalue vanishes. Three vanish at once, so the
    # bordered Jacobian is singular too and the state is known only to about sqrt(eps) along
    # its kernel: the eigenvalue at the located point is that noise (4e-10 or 1.4e-9 as the
    # inverse iteration's sums round), where a point off by the traced steps' scale has 1e-3.
    assert abs(static_stability(params, "nonlinear", point.x).critical_eigenvalue) < 1e-8
    # ... and M is still rising through it, the traced points on both sides stable and unstable.
    i = point.after_point
    assert result.branch.moment[i] < point.moment < result.branch.moment[i + 2]
    assert result.branch.stable[i] and not result.branch.stable[i + 1]
    # The protocol: at rest just below, rotating just above (below the fold's moment).
    below = solve_equilibrium(params, "nonlinear", moment_load(0.99 * point.moment), x0=result.branch.x[i])
    step = relax(params, "nonlinear", 0.998 * point.moment, x0=below)
    assert step.status.value == "static" and abs(step.x[2, params.N] - point.phi0) < 0.1
    assert relax(params, "nonlinear", 1.002 * point.moment, x0=step.x).status.value == "rotating"
    as_json = result.as_dict()
    assert as_json["M_c"] == point.moment and as_json["onset"] == "branch_point" and not as_json["snap_through"]
    assert as_json["largest_fold"]["moment"] == result.fold.moment and len(as_json["branch_points"]) == 1


@pytest.mark.parametrize(
    "params", [ChainParams(**ENDS["clamped-free"])] + [g.replace(N=n, **ENDS["clamped-free"]) for g, n in zip(GEOMETRIES, (1, 3))]
)
def test_a_cantilevers_sine_fold_is_the_reciprocal_of_its_compliance(params):
    """The sine model's fold is 1 / (rotation compliance); the cantilever's branch passes a fold
    at which the corrector converges only linearly (it failed there before)."""
    from cosserat_chain.experiments.critical import critical_point

    result = critical_point(params, "sine")
    assert result.onset == "fold" and result.complete
    assert result.critical_moment * result.compliance == pytest.approx(1.0, rel=1e-10)
    assert [fold.maximum for fold in result.branch.folds][:2] == [True, False]


# Chain 7 (its branch points all solved for, as chain 4's) with the slow tests; chains 3 and 4 (solved) and 5 (bracketed) quick.
@pytest.mark.parametrize(
    ("index", "kind"), [(3, "clamped-free"), (4, "clamped-free"), pytest.param(7, "clamped-free", marks=pytest.mark.slow), (5, "pinned")]
)
def test_branch_points_where_the_corrector_stalls_are_bracketed_not_fatal(index, kind):
    """Random chains whose branch-point search stalled next to a singular K (NewtonError before):
    the branch completes, each branch point solved for or bracketed within a short arclength,
    and a solved one has a vanishing smallest eigenvalue."""
    from cosserat_chain.experiments.critical import critical_point
    from cosserat_chain.numerics.stability import static_stability

    params = random_geometries(10)[index].replace(**ENDS[kind])
    result = critical_point(params, "nonlinear")
    assert result.complete and result.branch.branch_points
    for point in result.branch.branch_points:
        assert point.located or 0.0 < point.bracket <= 1e-3
        if point.located and point.index_before == 0:
            eigenvalue = static_stability(params, "nonlinear", point.x).critical_eigenvalue
            assert abs(eigenvalue) < 1e-8 * max(1.0, params.E1, params.E2)


def test_statics_refuse_a_chain_that_can_move_rigidly():
    for kind in ("free", "pinned-free", "ring"):
        with pytest.raises(ValueError, match="can move rigidly .* the statics need a clamped end or two pinned ones"):
            solve_equilibrium(chains(kind)[0], "linear", moment_load(0.01))


# --------------------------------------------------------------------------- one engine, many copies
@pytest.mark.parametrize("kind", ["free", "pinned-free", "ring"])
@pytest.mark.parametrize("model", ALL, ids=lambda m: m.name)
def test_batch_members_equal_single_runs(model, kind):
    params = GEOMETRIES[1].replace(N=3, **ENDS[kind])
    moments = [0.01, 0.05, 0.2]
    x0 = np.stack([random_state(params, 0.05, seed=s) for s in range(3)])
    batch = integrate_batch([params] * 3, model, moments, t_end=30.0, x0=x0, n_records=3)
    for b, moment in enumerate(moments):
        single = integrate(params, model, moment_load(moment), t_end=30.0, x0=x0[b], n_frames=2)
        # As for clamped chains (test_batch.py): equal forces to the last bit, but the batch's
        # and the chain's kick-drift loops are compiled apart and may round differently.
        np.testing.assert_allclose(batch.x[b], single.x[-1], rtol=0, atol=ROUND_OFF)
        np.testing.assert_allclose(batch.v[b], single.v[-1], rtol=0, atol=ROUND_OFF)


@pytest.mark.parametrize("kind", ["free", "pinned-free"])
def test_two_threads_equal_one_bit_for_bit_with_free_and_pinned_ends(kind):
    params = ChainParams(N=2000, **ENDS[kind])
    x0 = random_state(params, 0.02, seed=5)
    runs = [integrate(params, "nonlinear", moment_load(0.05, -params.N), t_end=2.0, x0=x0, n_frames=3, threads=t) for t in (1, 2)]
    np.testing.assert_array_equal(runs[0].x, runs[1].x)
    np.testing.assert_allclose(runs[0].dissipated, runs[1].dissipated, rtol=1e-13)  # summed block by block


@pytest.mark.parametrize("kind", ["free", "pinned", "ring"])
def test_verlet_converges_to_the_adaptive_reference_at_second_order(kind):
    params = GEOMETRIES[2].replace(N=3, **ENDS[kind])
    loads = moment_load(0.05, 1)
    x0 = random_state(params, 0.1, seed=9)
    reference = integrate_adaptive(params, "nonlinear", loads, t_end=5.0, x0=x0, n_frames=2)
    errors = []
    for dt in (0.02, 0.01):
        run = integrate(params, "nonlinear", loads, t_end=5.0, dt=dt, x0=x0, n_frames=2)
        errors.append(np.abs(run.x[-1] - reference.x[-1]).max())
    assert 3.5 < errors[0] / errors[1] < 4.5
    assert np.all(reference.x[:, fixed_mask(params)] == 0.0)
