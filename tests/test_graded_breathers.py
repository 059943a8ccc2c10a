"""Roto-breathers of graded chains (per-bond and per-particle factors): a heavy rotor, a soft bond beside it.

The families, their Floquet multipliers and lifetimes run on the graded chain as on the uniform one; the
bands the harmonics are held against are the finite graded chain's linear modes
(:func:`~cosserat_chain.experiments.breathers.band_edges`, their extended ones), a graded chain having no Bloch bands."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from scipy.optimize import brentq
from scipy.special import ellipk
from typer.testing import CliRunner

from cosserat_chain.analysis.dispersion import BRANCHES, finite_modes, wave_summary
from cosserat_chain.analysis.localized_modes import classify_modes
from cosserat_chain.cli import app
from cosserat_chain.experiments.breathers import (
    BAND_SOURCES,
    anti_continuum_state,
    band_edges,
    resonances,
    roto_breather_family,
)
from cosserat_chain.loads import moment_load
from cosserat_chain.models.base import get_model
from cosserat_chain.numerics.dynamics import integrate
from cosserat_chain.numerics.periodic import find_hamiltonian_orbit, hamiltonian_energy
from cosserat_chain.params import ChainParams
from cosserat_chain.state import ROW_INDEX, column, dof, zeros

PHI = ROW_INDEX["phi"]
#: The point symmetry of the plane chain turned by pi: u, v -> -u, -v, the angles kept (a rotor keeps its sense).
HALF_TURN = np.array([-1.0, -1.0, 1.0])[:, None]
runner = CliRunner()


def undamped(**fields) -> ChainParams:
    return ChainParams(gamma_u=0.0, gamma_v=0.0, gamma_phi=0.0, **fields)


#: A heavy rotor (3 j) at the centre, a soft bond (E1 / 2) on its left and a heavy particle (2 m) beyond it.
GRADED = {"E1_factors": (1.0, 0.5, 1.0, 1.0), "m_factors": (2.0, 1.0, 1.0, 1.0, 1.0), "j_factors": (1.0, 1.0, 3.0, 1.0, 1.0)}


def mirrored(fields: dict) -> dict:
    """The same chain end to end: bond k <-> bond 2N - 1 - k, particle n <-> -n."""
    return {name: tuple(reversed(factors)) for name, factors in fields.items()}


@pytest.fixture(scope="module")
def graded_orbit():
    """A roto-breather of the graded nonlinear chain, N = 2 (the neighbours move), above every band."""
    return roto_breather_family(undamped(N=2, **GRADED), "nonlinear", [6.5]).family.orbits[0]


def test_factors_all_alike_give_the_uniform_family_bitwise():
    uniform = undamped(N=2, E1=2.0)
    alike = undamped(N=2, E1_factors=(2.0,) * 4, m_factors=(1.0,) * 5, j_factors=(1.0,) * 5)
    assert alike == uniform and not alike.graded  # they fold into the scalars
    a = roto_breather_family(uniform, "sine", [5.0, 5.2])
    b = roto_breather_family(alike, "sine", [5.0, 5.2])
    for p, q in zip(a.family.orbits, b.family.orbits, strict=True):
        assert np.array_equal(p.x, q.x) and np.array_equal(p.v, q.v)
        assert np.array_equal(p.multipliers, q.multipliers)
    assert a.as_dict() == b.as_dict()
    assert a.as_dict()["bands_from"] == BAND_SOURCES[False]


@pytest.mark.parametrize(
    "ends", [{}, {"left_end": "pinned", "right_end": "pinned"}, {"left_end": "free", "right_end": "free"}, {"periodic": True}]
)
def test_the_finite_chains_bands_lie_in_the_infinite_ones_and_split_at_the_gap(ends):
    """The split by the count of free v coordinates puts every acoustic mode below the optical ones,
    for every kind of end (a pinned or free chain's end modes lie in the gap: localized, out of the host bands)."""
    params = ChainParams(N=10, **ends)
    finite, infinite = classify_modes(params).host_bands, wave_summary(params).bands
    for name in BRANCHES:
        assert finite[name][1] <= infinite[name][1] + 1e-12
    assert finite["transverse_acoustic"][1] < finite["rotational_optical"][0]
    frequencies = np.sort(finite_modes(params, "linear").frequencies)
    assert finite["longitudinal"][1] in frequencies and finite["rotational_optical"][0] in frequencies


def test_the_finite_chains_band_edges_converge_to_the_infinite_chains():
    """The clamped chain's modes sample q = k pi / (2N): its bottoms approach the bands' like 1 / N, its tops like 1 / N^2."""
    infinite = wave_summary(ChainParams(N=10)).bands
    errors = []
    for n in (10, 40):
        finite = classify_modes(ChainParams(N=n)).host_bands
        errors.append([abs(finite[name][e] - infinite[name][e]) for name in BRANCHES for e in (0, 1)])
    coarse, fine = np.array(errors)
    assert np.all(fine < coarse / 3.5)
    assert np.max(fine[1::2]) < 2e-3  # the tops


def test_a_graded_chains_resonances_are_its_finite_modes_edges():
    params = undamped(N=10, j_factors=(1.0,) * 10 + (4.0,) + (1.0,) * 10, E1_factors=(1.0,) * 9 + (0.5, 0.5) + (1.0,) * 9)
    edges = band_edges(params)
    assert edges == classify_modes(params).host_bands
    top = edges["transverse_acoustic"][1]
    found = [r for r in resonances(params, 0.1, 10.0) if r.band == "transverse_acoustic" and r.edge == "top"]
    assert [r.omega for r in found] == pytest.approx([top / n for n in range(6, 0, -1)], rel=1e-15)
    with pytest.raises(ValueError, match="graded"):  # the infinite chain's summary stays refused
        wave_summary(params)


def pendulum_rate_at_bottom(c: float, inertia: float, omega: float) -> float:
    """phi' at phi = 0 of the pendulum J phi'' = -c sin phi turning at mean rate omega: 2 w0 / k with 2 k K(k) / w0 = 2 pi / omega."""
    w0 = math.sqrt(c / inertia)
    k = brentq(lambda k: 2 * k * ellipk(k * k) / w0 - 2 * math.pi / omega, 1e-12, 1 - 1e-15, xtol=1e-15)
    return 2 * w0 / k


def test_a_heavy_rotors_anti_continuum_limit_is_the_pendulum_with_its_own_inertia():
    """N = 1, clamped: the centre turns alone between neighbours held at rest, J = 4 j."""
    params = undamped(N=1, j_factors=(1.0, 4.0, 1.0))
    c = get_model("linear").stiffness(undamped(N=1), zeros(params)).toarray()[2, 2]  # the uniform chain's on-site pendulum
    omega = 6.0
    exact = pendulum_rate_at_bottom(c, 4.0 * params.j, omega)
    assert exact < 0.9 * pendulum_rate_at_bottom(c, params.j, omega)  # the heavy rotor turns otherwise
    x, v, _ = anti_continuum_state(params, "sine", omega)
    assert v[PHI, 1] == pytest.approx(exact, rel=1e-10)
    orbit = find_hamiltonian_orbit(params, "sine", omega, (x, v))
    assert orbit.v[PHI, 1] == pytest.approx(exact, rel=1e-9) and abs(orbit.unfolding) < 1e-10
    # With the soft bond beside it (and the neighbours moving, N = 2) the start is the pendulum of its two bonds.
    soft = undamped(N=2, E1_factors=(1.0, 0.5, 0.5, 1.0), j_factors=(1.0, 1.0, 4.0, 1.0, 1.0))
    c_soft = get_model("linear").stiffness(soft, zeros(soft)).toarray()[dof(soft, "phi", 0), dof(soft, "phi", 0)]
    assert c_soft < 0.99 * c  # the soft bonds soften the pendulum
    rate = anti_continuum_state(soft, "sine", omega)[1][PHI, column(soft, 0)]
    assert rate == pytest.approx(pendulum_rate_at_bottom(c_soft, 4.0 * soft.j, omega), rel=1e-10)


def test_energy_is_conserved_along_a_graded_orbit(graded_orbit):
    o = graded_orbit
    xs, vs = o.trajectory(o.period * np.arange(1, 41) / 40)
    energies = np.array([hamiltonian_energy(o.params, "nonlinear", x, v) for x, v in zip(xs, vs, strict=True)])
    assert np.max(np.abs(energies - o.energy)) < 1e-9 * abs(o.energy)
    assert np.max(np.abs(xs[:, :, [0, 1, 3, 4]])) > 1e-3  # the neighbours do oscillate


def test_a_graded_orbit_returns_to_itself_in_a_direct_run_with_symplectic_multipliers(graded_orbit):
    o = graded_orbit
    run = integrate(
        o.params, "nonlinear", moment_load(0.0, 0), t_end=o.period, dt=o.period / 4000, x0=o.x, v0=o.v, method="yoshida4", n_frames=2
    )
    shift = np.zeros_like(o.x)
    shift[PHI, o.params.N] = 2 * math.pi
    assert np.max(np.abs(run.x[-1] - o.x - shift)) < 1e-7 and np.max(np.abs(run.v[-1] - o.v)) < 1e-6
    mu = o.multipliers
    assert np.prod(mu).real == pytest.approx(1.0, abs=1e-7)  # Liouville
    assert max(np.min(np.abs(mu - m)) for m in 1.0 / mu) < 1e-5  # mu and 1 / mu together
    assert max(np.min(np.abs(mu - m)) for m in np.conj(mu)) < 1e-12  # and their conjugates
    assert sorted(np.abs(mu - 1.0))[1] < 1e-4  # the Hamiltonian pair at +1


@pytest.mark.parametrize("particle", [0, -1])
def test_a_graded_chain_mirrored_end_to_end_gives_the_mirrored_breather(particle):
    a = roto_breather_family(undamped(N=2, **GRADED), "nonlinear", [6.5], particle=particle).family.orbits[0]
    b = roto_breather_family(undamped(N=2, **mirrored(GRADED)), "nonlinear", [6.5], particle=-particle).family.orbits[0]
    assert np.max(np.abs(a.x - HALF_TURN * a.x[:, ::-1])) > 1e-3  # the graded chain is not symmetric itself
    assert np.max(np.abs(b.x - HALF_TURN * a.x[:, ::-1])) < 1e-8
    assert np.max(np.abs(b.v - HALF_TURN * a.v[:, ::-1])) < 1e-7
    assert b.period == a.period and b.energy == pytest.approx(a.energy, rel=1e-12)
    assert np.sort(np.abs(b.multipliers)) == pytest.approx(np.sort(np.abs(a.multipliers)), abs=1e-7)


def test_cli_runs_a_graded_family_with_the_finite_chains_bands(tmp_path):
    config = tmp_path / "graded.toml"
    config.write_text("N = 5\nj_factors = [1, 1, 1, 1, 1, 3, 1, 1, 1, 1, 1]\nE1_factors = [1, 1, 1, 1, 0.5, 1, 1, 1, 1, 1]\n")
    out = runner.invoke(app, ["breathers", "--config", str(config), "--omega", "5", "--lifetimes", "5", "--json"])
    assert out.exit_code == 0, out.output
    summary = json.loads(out.output)
    assert summary["bands_from"] == BAND_SOURCES[True] and summary["complete"]
    assert summary["params"]["j_factors"][5] == 3.0 and summary["closure"][0] < 1e-8
    assert len(summary["lifetimes"]) == 1  # the direct run from the perturbed orbit, on the graded kernels
