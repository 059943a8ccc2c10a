"""The package against independent computations on randomized admissible chains (an outsider's audit).

Every reference here is written from the paper alone, not from the package: the nonlinear forces
from eq. (1) on the exact corner geometry (the springs of ``geometry``'s table, summed link by link
with the chain rule), the linear model (3) as the sum of E g g^T over the links with g = dL/dq at
rest (the linearisation of eq. (1) the paper describes), the sine model (2) as that linear force at
(u, v, sin phi), and SciPy's root finders, DOP853 and NumPy's eigenvalues on those forces. The
cases are drawn with fixed seeds over the validated ranges of :class:`ChainParams`: random
geometry, stiffnesses, inertia and damping, N in {1, 2, 3, 5, 8, 13}, every end condition and the
ring, graded chains, the reduced chain D1 = 0, and the built-in user systems.
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy.integrate import solve_ivp
from scipy.optimize import root

from cosserat_chain import ChainParams, dispersion, get_model, locate_fold, moment_load, periodic_orbit, simulate, solve_equilibrium

MODELS = ("nonlinear", "sine", "linear")
OPEN_ENDS = (("clamped", "clamped"), ("pinned", "pinned"), ("clamped", "free"), ("pinned", "free"), ("free", "free"))
HELD = {"clamped": (0, 1, 2), "pinned": (0, 1), "free": (), "ring": ()}


# -- the independent chain -------------------------------------------------------------------------


def _links(p):
    """(left corner, right corner, stiffness of this bond's kind 1 or 2, rest length) of the four links of a bond."""
    a, b, gap = p.a, p.b, p.h - 2 * p.a
    d = np.hypot(gap, 2 * b)
    return (((a, b), (-a, b), 1, gap), ((a, -b), (-a, -b), 1, gap), ((a, b), (-a, -b), 2, d), ((a, -b), (-a, b), 2, d))


def _bonds(p):
    """(left particle, right particle, shift of the right one's rest position, E1, E2) of every bond (a ring's last)."""
    n = 2 * p.N + 1
    pairs = [(k, k + 1, 0.0) for k in range(n - 1)] + ([(n - 1, 0, n * p.h)] if p.periodic else [])
    e1 = np.ones(len(pairs)) if p.E1_factors is None else np.asarray(p.E1_factors)
    e2 = np.ones(len(pairs)) if p.E2_factors is None else np.asarray(p.E2_factors)
    return [(i, j, s, p.E1 * e1[k], p.E2 * e2[k]) for k, (i, j, s) in enumerate(pairs)]


def _held(p):
    mask = np.zeros((3, 2 * p.N + 1), bool)
    mask[list(HELD[p.left_end]), 0] = True
    mask[list(HELD[p.right_end]), -1] = True
    return mask


def _free(p):
    """Free degrees of freedom as positions in x.T.ravel() (particle by particle)."""
    return np.flatnonzero(~_held(p).T.ravel())


def nonlinear_forces(p, x):
    """-dP/dq of eq. (1) summed over the links, zero where the ends hold the chain."""
    rest = p.h * np.arange(-p.N, p.N + 1)
    u, v, phi = x
    out = np.zeros_like(x)
    for i, j, shift, e1, e2 in _bonds(p):
        for left, right, kind, length0 in _links(p):
            ci, si, cj, sj = np.cos(phi[i]), np.sin(phi[i]), np.cos(phi[j]), np.sin(phi[j])
            rxi, ryi = left[0] * ci - left[1] * si, left[0] * si + left[1] * ci
            rxj, ryj = right[0] * cj - right[1] * sj, right[0] * sj + right[1] * cj
            dx = rest[j] + shift + u[j] + rxj - rest[i] - u[i] - rxi
            dy = v[j] + ryj - v[i] - ryi
            length = np.hypot(dx, dy)
            tension = (e1 if kind == 1 else e2) * (length - length0)
            fx, fy = tension * dx / length, tension * dy / length
            out[:, i] += (fx, fy, rxi * fy - ryi * fx)
            out[:, j] -= (fx, fy, rxj * fy - ryj * fx)
    out[_held(p)] = 0.0
    return out


def bond_stiffness(p, e1, e2):
    """The 6 x 6 stiffness of one bond of eq. (3) over (u, v, phi) of its left, then right particle: sum of E g g^T
    over its links, g = dL/dq at rest."""
    K = np.zeros((6, 6))
    for left, right, kind, _ in _links(p):
        dx, dy = p.h + right[0] - left[0], right[1] - left[1]
        ex, ey = np.array([dx, dy]) / np.hypot(dx, dy)
        g = np.array([-ex, -ey, left[1] * ex - left[0] * ey, ex, ey, right[0] * ey - right[1] * ex])
        K += (e1 if kind == 1 else e2) * np.outer(g, g)
    return K


def linear_stiffness(p):
    """K of eq. (3) over all 3 (2N+1) degrees of freedom (particle by particle), assembled bond by bond."""
    n = 2 * p.N + 1
    K = np.zeros((3 * n, 3 * n))
    for i, j, _, e1, e2 in _bonds(p):
        index = np.r_[3 * i : 3 * i + 3, 3 * j : 3 * j + 3]
        K[np.ix_(index, index)] += bond_stiffness(p, e1, e2)
    return K


def linear_forces(p, x):
    out = -(linear_stiffness(p) @ x.T.ravel()).reshape(-1, 3).T
    out[_held(p)] = 0.0
    return out


def sine_forces(p, x):
    return linear_forces(p, np.vstack([x[:2], np.sin(x[2:])]))


FORCES = {"nonlinear": nonlinear_forces, "sine": sine_forces, "linear": linear_forces}


def _state(p, q):
    x = np.zeros(3 * (2 * p.N + 1))
    x[_free(p)] = q
    return x.reshape(-1, 3).T


def _residual(p, model, moment, column):
    """The free rows of F(q) + M e_phi(column), as a function of the free degrees of freedom."""

    def residual(q):
        f = FORCES[model](p, _state(p, q))
        f[2, column] += moment
        return f.T.ravel()[_free(p)]

    return residual


def _mass_and_damping(p):
    n = 2 * p.N + 1
    m = p.m * (np.ones(n) if p.m_factors is None else np.asarray(p.m_factors))
    j = p.j * (np.ones(n) if p.j_factors is None else np.asarray(p.j_factors))
    return np.stack([m, m, j]).T.ravel()[_free(p)], np.tile([p.gamma_u, p.gamma_v, p.gamma_phi], n)[_free(p)]


def _moment_turning_by(p, particle, angle):
    """The moment on ``particle`` that turns the linear chain's most turned particle by ``angle`` (K^-1 e of eq. (3))."""
    free = _free(p)
    load = np.zeros(3 * (2 * p.N + 1))
    load[3 * (particle + p.N) + 2] = 1.0
    response = np.linalg.solve(linear_stiffness(p)[np.ix_(free, free)], load[free])
    return angle / np.abs(_state(p, response)[2]).max()


def _central_jacobian(fun, z, step=1e-6):
    columns = []
    for c in range(z.size):
        e = np.zeros(z.size)
        e[c] = step
        columns.append((fun(z + e) - fun(z - e)) / (2 * step))
    return np.array(columns).T


def draw(rng, N, ends=("clamped", "clamped"), graded=False, reduced=False):
    """A random admissible chain: 0.05 h < a < 0.42 h, 0.05 h < b < 0.5 h, stiffnesses, inertia and damping of order 1."""
    h = rng.uniform(0.7, 1.5)
    a, b = rng.uniform(0.05, 0.42) * h, rng.uniform(0.05, 0.5) * h
    E1 = rng.uniform(0.5, 2.0)
    E2 = E1 * ((h - 2 * a) ** 2 + 4 * b * b) / h**2 if reduced else rng.uniform(0.2, 2.0)
    fields = dict(h=h, a=a, b=b, E1=E1, E2=E2, m=rng.uniform(0.5, 2.0), j=rng.uniform(0.02, 0.3), N=N)
    fields.update(zip(("gamma_u", "gamma_v", "gamma_phi"), rng.uniform(0.05, 0.3, 3)))
    if ends == "ring":
        fields["periodic"] = True
    else:
        fields["left_end"], fields["right_end"] = ends
    if graded:
        bonds = 2 * N + (ends == "ring")
        fields.update({name: tuple(rng.uniform(0.5, 1.5, bonds)) for name in ("E1_factors", "E2_factors")})
        fields.update({name: tuple(rng.uniform(0.5, 1.5, 2 * N + 1)) for name in ("m_factors", "j_factors")})
    return ChainParams(**fields)


# -- forces and stiffness ----------------------------------------------------------------------------


@pytest.mark.parametrize("N", [1, 2, 3, 5, 8, 13])
def test_forces_of_every_model_agree_with_the_paper_on_random_chains(N):
    rng = np.random.default_rng(100 + N)
    for ends in (*OPEN_ENDS, "ring"):
        for graded in (False, True):
            p = draw(rng, N, ends, graded)
            x = rng.normal(0.0, 0.3, (3, 2 * N + 1)) * [[1], [1], [5]]
            x[_held(p)] = 0.0
            for model in MODELS:
                expected = FORCES[model](p, x)
                assert np.abs(get_model(model).forces(p, x) - expected).max() <= 1e-12 * max(1.0, np.abs(expected).max()), (model, ends)


@pytest.mark.parametrize("model", MODELS)
def test_stiffness_is_minus_the_derivative_of_the_independent_forces(model):
    rng = np.random.default_rng(7)
    for N, ends in ((1, ("pinned", "pinned")), (2, ("clamped", "free")), (3, "ring"), (5, ("clamped", "clamped"))):
        p = draw(rng, N, ends, graded=bool(N % 2), reduced=N == 2)
        x = rng.normal(0.0, 0.2, (3, 2 * N + 1))
        x[_held(p)] = 0.0
        jacobian = _central_jacobian(_residual(p, model, 0.0, 0), x.T.ravel()[_free(p)])
        K = get_model(model).stiffness(p, x).toarray()
        assert np.abs(K + jacobian).max() <= 1e-7 * np.abs(jacobian).max()


# -- statics -----------------------------------------------------------------------------------------


@pytest.mark.parametrize("model", MODELS)
@pytest.mark.parametrize("reduced", [False, True], ids=["full", "D1=0"])
def test_equilibrium_agrees_with_scipy_root_on_the_independent_forces(model, reduced):
    rng = np.random.default_rng(11 + 2 * MODELS.index(model) + reduced)
    for N, ends in ((1, ("clamped", "clamped")), (2, ("pinned", "pinned")), (3, ("clamped", "free")), (5, ("pinned", "clamped"))):
        p = draw(rng, N, ends, graded=N > 2, reduced=reduced)
        assert not reduced or abs(p.D1) < 1e-12
        particle = int(rng.integers(-N + 1, N))
        moment = _moment_turning_by(p, particle, rng.uniform(0.02, 0.08))
        reference = root(_residual(p, model, moment, particle + N), np.zeros(_free(p).size), tol=1e-14).x
        x = np.asarray(solve_equilibrium(p, model, moment_load(moment, particle)))
        assert np.abs(x.T.ravel()[_free(p)] - reference).max() <= 1e-8 * np.abs(reference).max()


def _first_fold(p, model, step=0.04, length=8.0):
    """The first maximum of M along the static branch from rest: pseudo-arclength in (q, M) with
    finite-difference Jacobians, then Newton on the extended system (F + M e = 0, J w = 0, w.w = 1)."""
    column, free = p.N, _free(p)

    def g(z):
        return _residual(p, model, z[-1], column)(z[:-1])

    z, tangent = np.zeros(free.size + 1), np.eye(free.size + 1)[-1]
    previous = z
    for _ in range(int(length / step)):
        tangent_new = np.linalg.svd(_central_jacobian(g, z))[2][-1]
        tangent = tangent_new * np.sign(tangent_new @ tangent)
        start = z

        def arclength(w, start=start, tangent=tangent):
            return np.append(g(w), (w - start) @ tangent - step)

        previous, z = z, root(arclength, z + step * tangent, tol=1e-13).x
        if z[-1] < previous[-1]:
            break
    else:
        return None
    n = free.size
    w0 = np.linalg.svd(_central_jacobian(lambda q: g(np.append(q, previous[-1])), previous[:-1]))[2][-1]

    def extended(y):
        q, moment, w = y[:n], y[n], y[n + 1 :]
        jacobian = _central_jacobian(lambda s: g(np.append(s, moment)), q)
        return np.concatenate([g(np.append(q, moment)), jacobian @ w, [w @ w - 1.0]])

    solution = root(extended, np.concatenate([previous, w0]), tol=1e-12)
    return solution.x[n], _state(p, solution.x[:n])[2, column]


@pytest.mark.parametrize(
    ("model", "N"),
    [
        ("nonlinear", 1),
        pytest.param("sine", 1, marks=pytest.mark.slow),
        *(pytest.param(m, 2, marks=pytest.mark.slow) for m in ("sine", "nonlinear")),
    ],
)
def test_first_fold_agrees_with_an_independent_arclength_and_extended_system(model, N):
    rng = np.random.default_rng(31 + N + 5 * (model == "sine"))
    for ends in (("clamped", "clamped"), ("pinned", "clamped")):
        p = draw(rng, N, ends, graded=True)
        moment, phi0 = _first_fold(p, model, step=0.04 / N**2)  # fine enough not to step over a small first fold
        fold = locate_fold(p, model)
        assert fold.moment == pytest.approx(moment, rel=1e-7)
        assert fold.phi0 == pytest.approx(phi0, abs=1e-4)


# -- dynamics ----------------------------------------------------------------------------------------


def _reference_run(p, model, moment, particle, times):
    """DOP853 (rtol 1e-11) on the independent forces, with the load's work and the dissipation as two more unknowns."""
    mass, damping = _mass_and_damping(p)
    free, n = _free(p), _free(p).size
    phi_row = list(free).index(3 * (particle + p.N) + 2)

    def rhs(_, y):
        f = _residual(p, model, moment, particle + p.N)(y[:n])
        w = y[n : 2 * n]
        return np.concatenate([w, (f - damping * w) / mass, [moment * w[phi_row], damping @ (w * w)]])

    solution = solve_ivp(rhs, (0.0, times[-1]), np.zeros(2 * n + 2), method="DOP853", rtol=1e-11, atol=1e-13, t_eval=times)
    states = np.array([_state(p, y[:n]) for y in solution.y.T])
    kinetic = 0.5 * (mass * solution.y[n : 2 * n].T ** 2).sum(axis=1)
    return states, kinetic, solution.y[-2], solution.y[-1]


CASES = [
    (1, ("clamped", "clamped"), "nonlinear"),
    (2, ("pinned", "free"), "sine"),
    (3, "ring", "linear"),
    (2, ("clamped", "free"), "nonlinear"),
]


@pytest.mark.parametrize(("N", "ends", "model"), CASES)
def test_simulate_agrees_with_solve_ivp_and_balances_energy(N, ends, model):
    rng = np.random.default_rng(41 + N)
    p = draw(rng, N, ends, graded=True)
    particle = 0 if ends != ("pinned", "free") else N
    moment = rng.uniform(0.2, 1.0) * p.b**2
    loads = moment_load(moment, particle)
    reference = simulate(p, model, loads, t_end=6.0, reference=True, rtol=1e-11, n_frames=4)
    fixed = simulate(p, model, loads, t_end=6.0, method="yoshida4", n_frames=4)
    for run, rtol in ((reference, 1e-8), (fixed, 1e-4)):
        states, kinetic, work, dissipated = _reference_run(p, model, moment, particle, run.time.values)
        computed = np.stack([run.u.values, run.v.values, run.phi.values], axis=1)
        assert np.abs(computed - states).max() <= rtol * np.abs(states).max()
        assert run.load_work.values == pytest.approx(work, rel=rtol, abs=1e-14)
        assert run.dissipated.values == pytest.approx(dissipated, rel=rtol, abs=1e-14)
        assert run.kinetic.values[1:] == pytest.approx(kinetic[1:], rel=10 * rtol)


def test_yoshida4_error_falls_as_the_fourth_power_of_the_step():
    rng = np.random.default_rng(43)
    p = draw(rng, 2, ("clamped", "clamped"), graded=True)
    moment = 0.5 * p.b**2
    dt = 0.5 * get_model("nonlinear").max_frequency(p) ** -1
    times = np.array([0.0, 240 * dt])
    states = _reference_run(p, "nonlinear", moment, 0, times)[0][-1]
    errors = []
    for step in (dt, dt / 2):
        run = simulate(p, "nonlinear", moment_load(moment), t_end=times[-1], dt=step, method="yoshida4", n_frames=2)
        errors.append(np.abs(np.stack([run.u.values[-1], run.v.values[-1], run.phi.values[-1]]) - states).max())
    assert 2**3.5 < errors[0] / errors[1] < 2**4.5


# -- rotating orbits ---------------------------------------------------------------------------------


def _shooting(p, model, moment, x0, v0, period):
    """Independent shooting: y(T) = y(0) + 2 pi e_phi0 with phi_0(0) held, and the monodromy by central differences."""
    mass, damping = _mass_and_damping(p)
    free, n = _free(p), _free(p).size
    row = list(free).index(3 * p.N + 2)

    def rhs(_, y):
        return np.concatenate([y[n:], (_residual(p, model, moment, p.N)(y[:n]) - damping * y[n:]) / mass])

    def flow(y, t):
        return solve_ivp(rhs, (0.0, t), y, method="DOP853", rtol=1e-12, atol=1e-13).y[:, -1]

    gain = np.zeros(2 * n)
    gain[row] = 2 * np.pi
    y0 = np.concatenate([x0.T.ravel()[free], v0.T.ravel()[free]])

    def closure(z):
        y = np.insert(z[:-1], row, y0[row])
        return flow(y, z[-1]) - y - gain

    z = root(closure, np.append(np.delete(y0, row), period), tol=1e-12).x
    y, period = np.insert(z[:-1], row, y0[row]), z[-1]
    monodromy = _central_jacobian(lambda s: flow(s, period), y)
    return period, np.linalg.eigvals(monodromy)


@pytest.mark.slow
@pytest.mark.parametrize("N", [1, 2])
@pytest.mark.parametrize("model", ["sine", "nonlinear"])
def test_rotating_orbit_period_and_multipliers_agree_with_independent_shooting(model, N):
    rng = np.random.default_rng(51 + N)
    p = draw(rng, N, ("pinned", "clamped"), graded=True)
    moment = 1.3 * locate_fold(p, model).moment
    orbit = periodic_orbit(p, model, moment).orbit
    period, multipliers = _shooting(p, model, moment, np.asarray(orbit.x), np.asarray(orbit.v), orbit.period)
    assert orbit.period == pytest.approx(period, rel=1e-9)
    assert max(np.abs(multipliers - mu).min() for mu in np.asarray(orbit.multipliers)) < 1e-6


def _running_orbit_case(rng, kind, sites, boundary):
    """A drawn Josephson array or Takeno-Peyrard lattice, its independent forces and the package's running orbit."""
    from cosserat_chain.numerics.shooting import find_orbit, settled_guess
    from cosserat_chain.systems.josephson import josephson_array
    from cosserat_chain.systems.takeno_peyrard import takeno_peyrard

    drive, coupling, damping = rng.uniform(1.2, 2.0), rng.uniform(0.2, 1.5), rng.uniform(0.1, 0.5)
    if kind == "josephson":
        system = josephson_array(sites, I=drive, kappa=coupling, alpha=damping, boundary=boundary)
    else:
        system = takeno_peyrard(sites, C=coupling, T=drive, gamma=damping, boundary=boundary)
    pairs = [(b, (b + 1) % sites) for b in range(sites if boundary == "periodic" else sites - 1)]

    def forces(q):
        f = drive - np.sin(q)
        for left, right in pairs:
            pull = coupling * (q[right] - q[left] if kind == "josephson" else np.sin(q[right] - q[left]))
            f[left] += pull
            f[right] -= pull
        return f

    def flow(y, t):
        def rhs(_, s):
            return np.concatenate([s[sites:], forces(s[:sites]) - damping * s[sites:]])

        return solve_ivp(rhs, (0.0, t), y, method="DOP853", rtol=1e-12, atol=1e-13).y[:, -1]

    guess = settled_guess(
        system, np.concatenate([rng.normal(0.0, 0.1, sites), np.zeros(sites)]), coordinate=0, transient=100.0, window=60.0
    )
    return system, forces, flow, find_orbit(system, guess, turns={c: 1 for c in system.coordinates})


@pytest.mark.parametrize(("kind", "sites", "boundary"), [("josephson", 2, "free"), ("takeno_peyrard", 3, "periodic")])
def test_user_systems_running_orbits_agree_with_independent_shooting(kind, sites, boundary):
    rng = np.random.default_rng(61 + sites)
    system, forces, flow, orbit = _running_orbit_case(rng, kind, sites, boundary)
    q = rng.normal(0.0, 2.0, sites)
    assert np.asarray(system.forces(q)) == pytest.approx(forces(q), abs=1e-13)
    y0 = np.asarray(orbit.y0)
    gain = np.concatenate([2 * np.pi * np.ones(sites), np.zeros(sites)])

    def closure(z):
        y = np.insert(z[:-1], 0, y0[0])
        return flow(y, z[-1]) - y - gain

    z = root(closure, np.append(y0[1:], orbit.period), tol=1e-12).x
    y, period = np.insert(z[:-1], 0, y0[0]), z[-1]
    multipliers = np.linalg.eigvals(_central_jacobian(lambda s: flow(s, period), y))
    assert orbit.period == pytest.approx(period, rel=1e-9)
    assert max(np.abs(multipliers - mu).min() for mu in np.asarray(orbit.multipliers)) < 1e-6


# -- dispersion --------------------------------------------------------------------------------------


def test_dispersion_bands_are_the_eigenvalues_of_the_independent_bloch_matrix():
    rng = np.random.default_rng(71)
    for case in range(12):
        p = draw(rng, 1, reduced=case % 4 == 0)
        K = bond_stiffness(p, p.E1, p.E2)
        A, B, C = K[:3, :3], K[:3, 3:], K[3:, 3:]
        q = rng.uniform(0.0, np.pi, 5)
        scale = np.diag(np.array([p.m, p.m, p.j]) ** -0.5)
        expected = np.array([np.linalg.eigvalsh(scale @ (A + C + B * np.exp(1j * k) + B.T * np.exp(-1j * k)) @ scale) for k in q]).T
        computed = np.sort(dispersion(p, q).omega2, axis=0)
        assert np.abs(computed - expected).max() <= 1e-12 * expected.max()


# -- hostile inputs found by the audit ---------------------------------------------------------------


@pytest.mark.parametrize("model", ["sine", "linear"])
def test_equilibrium_of_a_chain_without_transverse_stiffness_is_refused_by_name(model):
    # E2 = 0 is admissible (k_v = 0), but K of eqs. (2)-(3) is then singular: a raw LinAlgError or a NaN state before.
    with pytest.raises(ValueError, match=r"singular for this chain \(E2=0\.0"):
        solve_equilibrium(ChainParams(N=2, E2=0.0), model, moment_load(0.01))


def test_waves_refuses_a_graded_chain_naming_its_factors(tmp_path):
    from typer.testing import CliRunner

    from cosserat_chain.cli import app

    config = tmp_path / "graded.toml"
    config.write_text("N = 1\nE1_factors = [1.0, 2.0]\n")
    result = CliRunner().invoke(app, ["waves", "--json", "--config", str(config)])
    assert result.exit_code == 2 and "E1_factors" in result.output and "Traceback" not in result.output


def test_reproduce_refuses_a_chain_no_memory_holds_before_any_stage(tmp_path):
    from typer.testing import CliRunner

    from cosserat_chain.cli import app

    config = tmp_path / "long.toml"
    config.write_text("N = 100000000000\n")
    result = CliRunner().invoke(app, ["reproduce", "--out", str(tmp_path / "report"), "--json", "--config", str(config)])
    assert result.exit_code == 2 and "N=100000000000" in result.output and "Traceback" not in result.output
    assert not (tmp_path / "report" / "summary.json").exists()
