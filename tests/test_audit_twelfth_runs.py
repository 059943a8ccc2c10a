"""Outside audit of long runs and roto-breathers against independent code (H12audC).

The references here are written from the model's definition alone (four links per bond of
stiffness E1, E1, E2, E2 between the rectangles' corners, eq. (1); the sine model as the
linearisation at rest evaluated at (u, v, sin phi), eq. (2)) and integrated by SciPy's DOP853.
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from cosserat_chain import ChainParams, moment_load
from cosserat_chain.experiments.breathers import roto_breather_family
from cosserat_chain.experiments.simulation import simulate
from cosserat_chain.models import get_model
from cosserat_chain.status import Status


def _links(p: ChainParams):
    a, b = p.a, p.b
    corners = [((a, b), (-a, b), p.E1), ((a, -b), (-a, -b), p.E1), ((a, b), (-a, -b), p.E2), ((a, -b), (-a, b), p.E2)]
    return [(left, right, stiff, np.hypot(p.h + right[0] - left[0], right[1] - left[1])) for left, right, stiff in corners]


def _forces(p: ChainParams, q: np.ndarray) -> np.ndarray:
    """Forces and moments on the free particles of a clamped chain, q (3, 2N-1), from the links' tensions."""
    full = np.zeros((3, 2 * p.N + 1))
    full[:, 1:-1] = q
    u, v, phi = full
    c, s = np.cos(phi), np.sin(phi)
    out = np.zeros_like(full)
    for (lx0, ly0), (rx0, ry0), stiff, rest in _links(p):
        lx, ly = c[:-1] * lx0 - s[:-1] * ly0, s[:-1] * lx0 + c[:-1] * ly0
        rx, ry = c[1:] * rx0 - s[1:] * ry0, s[1:] * rx0 + c[1:] * ry0
        dx, dy = p.h + u[1:] - u[:-1] + rx - lx, v[1:] - v[:-1] + ry - ly
        t = stiff * (1.0 - rest / np.hypot(dx, dy))
        tx, ty = t * dx, t * dy
        out[0, :-1] += tx
        out[1, :-1] += ty
        out[2, :-1] += lx * ty - ly * tx
        out[0, 1:] -= tx
        out[1, 1:] -= ty
        out[2, 1:] -= rx * ty - ry * tx
    return out[:, 1:-1]


def _rhs(p: ChainParams, moment: float):
    n = 2 * p.N - 1
    inertia = np.repeat([p.m, p.m, p.j], n)
    damping = np.repeat([p.gamma_u, p.gamma_v, p.gamma_phi], n)
    load = np.zeros(3 * n)
    load[2 * n + n // 2] = moment

    def rhs(t, y):
        q, w = y[: 3 * n], y[3 * n :]
        return np.concatenate([w, (_forces(p, q.reshape(3, n)).ravel() + load - damping * w) / inertia])

    return rhs


def test_light_particle_run_is_flagged_not_completed():
    """A light particle (j = 1e-5) relaxes its spin within a default step: the run drifts 2.4 times too fast.

    The energy balance stays closed (the split scheme keeps it), so only the damping per step
    shows it; DOP853 gives phi_0(2) = 7.8335 where the default step gives 18.9.
    """
    ds = simulate(ChainParams(N=3, j=1e-5), "nonlinear", moment_load(0.5), t_end=2.0, n_frames=2)
    assert ds.attrs["balance_relative"] < 1e-3  # the balance cannot see it
    assert ds.attrs["status"] == Status.INACCURATE
    assert "damping" in ds.attrs["message"]


@pytest.mark.slow
def test_light_particle_default_step_is_wrong_and_a_step_that_passes_the_check_converges():
    """The flagged run above against DOP853 (the default step 2.4 times too fast), and a step within the check."""
    params = ChainParams(N=3, j=1e-5)
    ds = simulate(params, "nonlinear", moment_load(0.5), t_end=2.0, n_frames=2)
    sol = solve_ivp(_rhs(params, 0.5), (0.0, 2.0), np.zeros(30), method="DOP853", rtol=1e-10, atol=1e-10)
    assert abs(ds.phi.values[-1, 3] - sol.y[12, -1]) > 1.0
    fine = simulate(params, "nonlinear", moment_load(0.5), t_end=2.0, dt=4e-6, n_frames=2)
    assert fine.attrs["status"] == Status.COMPLETED
    assert abs(fine.phi.values[-1, 3] - sol.y[12, -1]) < 5e-3


def test_paper_chain_default_step_not_flagged_by_damping():
    ds = simulate(ChainParams(), "nonlinear", moment_load(0.25), t_end=20.0, n_frames=2)
    assert ds.attrs["status"] == Status.COMPLETED
    assert 0.07 < ds.attrs["damping_per_step"] < 0.09  # 0.1 * 0.0208 / 0.0267


def test_short_run_against_independent_dop853():
    """N = 10, b > a, other stiffnesses: the package's default-step run against an independent reference at t = 5,
    and its kinetic energy and load work recomputed from its own frames."""
    rng = np.random.default_rng(3)
    params = ChainParams(N=10, E1=rng.uniform(0.5, 2), E2=rng.uniform(0.3, 2), a=0.17, b=0.31, gamma_u=0.05, gamma_v=0.05, gamma_phi=0.05)
    ds = simulate(params, "nonlinear", moment_load(0.6), t_end=5.0, n_frames=2)
    sol = solve_ivp(_rhs(params, 0.6), (0.0, 5.0), np.zeros(6 * 19), method="DOP853", rtol=1e-11, atol=1e-12)
    mine = sol.y[: 3 * 19, -1].reshape(3, 19)
    package = np.stack([ds[row].values[-1, 1:-1] for row in ("u", "v", "phi")])
    assert np.abs(mine - package).max() < 5e-3
    q = package
    translation = sum((ds[row].values[-1, 1:-1] ** 2).sum() for row in ("u_dot", "v_dot"))
    kinetic = 0.5 * params.m * translation + 0.5 * params.j * (ds.phi_dot.values[-1, 1:-1] ** 2).sum()
    assert ds.kinetic.values[-1] == pytest.approx(kinetic, rel=1e-12)
    assert ds.load_work.values[-1] == pytest.approx(0.6 * q[2, 9], rel=1e-12)


@pytest.mark.parametrize("periods", [10, pytest.param(50, marks=pytest.mark.slow)])
def test_breather_orbit_against_independent_integration(periods):
    """An undamped nonlinear family member (N = 2, b > a) closes under an independent DOP853 run for 10 periods (50 in
    the slow case): a period 1e-8 short already misses by 7e-8 a period, 7e-7 after ten."""
    params = ChainParams(N=2, a=0.15, b=0.3, gamma_u=0, gamma_v=0, gamma_phi=0)
    orbit = roto_breather_family(params, "nonlinear", [10.0], locate=False).family.orbits[0]
    n = 3
    y0 = np.concatenate([orbit.x[:, 1:-1].ravel(), orbit.v[:, 1:-1].ravel()])
    shift = np.zeros(6 * n)
    shift[2 * n + 1] = 2 * np.pi * orbit.turns
    y, worst = y0.copy(), 0.0
    for _ in range(periods):
        y = solve_ivp(_rhs(params, 0.0), (0.0, orbit.period), y, method="DOP853", rtol=1e-12, atol=1e-12).y[:, -1] - shift
        worst = max(worst, np.abs(y - y0).max())
    assert worst < 1e-7
    q, w = y[: 3 * n], y[3 * n :]
    full = np.zeros((3, 5))
    full[:, 1:-1] = q.reshape(3, n)
    energy = get_model("nonlinear").energy(params, full) + 0.5 * np.sum(np.repeat([params.m, params.m, params.j], n) * w * w)
    assert energy == pytest.approx(orbit.energy, abs=1e-9)


def test_light_particle_localization_run_is_flagged():
    """`rotate` on the same light particle made its 3 turns by t = 1.99, where DOP853 turns 7.83 rad by t = 2."""
    from cosserat_chain.experiments.localization import localization_run

    result = localization_run(ChainParams(N=3, j=1e-5), "nonlinear", 0.5, turns=3, t_max=10.0)
    assert result.status == Status.INACCURATE
    assert "damping" in result.message
