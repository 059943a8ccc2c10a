"""Host bands and localized modes of a finite chain (issue 41): a graded chain's impurity mode is no band edge.

:func:`~cosserat_chain.analysis.localized_modes.classify_modes` tells a finite chain's extended modes
from its localized ones by their participation at two lengths; the roto-breathers' bands are the
extended ones, and a localized mode is a resonance only where it overlaps the rotors."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
import sympy as sp
from scipy.optimize import brentq

from cosserat_chain.analysis.dispersion import BRANCHES, wave_summary
from cosserat_chain.analysis.localized_modes import classify_modes, lengthened
from cosserat_chain.experiments.breathers import (
    CORE_SHARE,
    band_edges,
    core_modes,
    harmonics_in_bands,
    resonances,
    roto_breather_family,
)
from cosserat_chain.models.linear import bloch_stiffness, cosserat_coefficients
from cosserat_chain.params import ChainParams


def centred(n: int, **defect) -> ChainParams:
    """A chain of 2n + 1 particles, uniform but for factors given about its centre: {name: factors of particles (or bonds) -k..k}."""
    fields = {}
    for name, factors in defect.items():
        bonds = name.startswith("E")
        count = 2 * n if bonds else 2 * n + 1
        pad = (count - len(factors)) // 2
        fields[name] = (1.0,) * pad + tuple(factors) + (1.0,) * pad
    return ChainParams(N=n, **fields)


def test_a_uniform_chain_has_no_localized_mode_and_its_host_bands_converge_to_the_dispersions():
    """Clamped ends: every mode is extended; the longitudinal band is the clamped chain's closed form
    2 sqrt(k_u / m) sin(k pi / (4N)), k = 1 and 2N - 1 (2N - 1 free particles), and every other edge meets the infinite
    chain's like 1 / N^2 (the optical bottom and the tops have zero group velocity, the transverse
    acoustic bottom is omega ~ q^2)."""
    infinite = wave_summary(ChainParams(N=10)).bands
    errors = []
    for n in (10, 20, 40):
        params = ChainParams(N=n)
        classes = classify_modes(params)
        assert classes.localized == ()
        k_u = cosserat_coefficients(params)[0]
        closed = [2 * math.sqrt(k_u / params.m) * math.sin(k * math.pi / (4 * n)) for k in (1, 2 * n - 1)]
        assert classes.host_bands["longitudinal"] == pytest.approx(closed, rel=1e-12)
        errors.append([abs(classes.host_bands[b][e] - infinite[b][e]) for b in BRANCHES for e in (0, 1)][2:])
    orders = np.log2(np.array(errors[:-1]) / np.array(errors[1:]))
    assert np.all(np.abs(orders[-1] - 2.0) < 0.1), orders
    assert np.max(errors[-1]) < 1.1e-3


def test_the_lengthened_chain_repeats_each_ends_particle_and_bond():
    params = ChainParams(N=2, m_factors=(2.0, 1.0, 1.0, 1.0, 3.0), E1_factors=(0.5, 1.0, 1.0, 4.0))
    longer = lengthened(params)
    assert longer.N == 4
    assert longer.m_factors == (2.0, 2.0, 2.0, 1.0, 1.0, 1.0, 3.0, 3.0, 3.0)
    assert longer.E1_factors == (0.5, 0.5, 0.5, 1.0, 1.0, 4.0, 4.0, 4.0)
    ring = ChainParams(N=1, periodic=True, E1_factors=(0.5, 1.0, 2.0))
    assert lengthened(ring).E1_factors == (0.5, 0.5, 1.0, 1.0, 2.0)  # the closing bond stays last


def light_mass_mode() -> tuple[sp.Expr, sp.Expr]:
    """The light mass m' on the monatomic chain m u_n'' = k (u_{n+1} - 2 u_n + u_{n-1}): (omega^2, z) of
    u_n = (-1)^n z^|n| u_0, solved by SymPy from the equation at n != 0 and at the impurity."""
    z, w2, k, m, mp = sp.symbols("z omega2 k m mp", positive=True)
    far = sp.Eq(m * w2, k * (2 + z + 1 / z))  # -m w2 u_n = k (-z - 2 - 1/z) u_n
    centre = sp.Eq(mp * w2, 2 * k * (1 + z))  # -m' w2 u_0 = k (-2 z - 2) u_0
    (solution,) = [s for s in sp.solve([far, centre], [z, w2], dict=True) if s[z] != -1]
    return solution[w2], solution[z], (k, m, mp)


@pytest.mark.parametrize("light", [0.5, 0.25])
def test_a_light_mass_gives_the_closed_form_defect_mode_and_localization_length(light):
    w2, z, (k, m, mp) = light_mass_mode()
    epsilon = sp.Symbol("epsilon")
    # The textbook form: omega_d^2 = omega_max^2 / (1 - epsilon^2), m' = m (1 - epsilon), omega_max^2 = 4 k / m.
    assert sp.simplify(w2.subs(mp, m * (1 - epsilon)) - 4 * k / m / (1 - epsilon**2)) == 0
    params = centred(20, m_factors=(light,))
    values = {k: cosserat_coefficients(params)[0], m: params.m, mp: light * params.m}
    frequency, ratio = math.sqrt(float(w2.subs(values))), float(z.subs(values))
    assert ratio == pytest.approx(light / (2 - light), rel=1e-15)
    (mode,) = [mode for mode in classify_modes(params).localized if mode.branch == "longitudinal"]
    assert mode.particle == 0
    assert mode.frequency == pytest.approx(frequency, rel=1e-12)
    assert mode.localization_length == pytest.approx(-1 / math.log(ratio), rel=1e-6)
    # P = (sum w)^2 / sum w^2 with w_0 = m', w_n = m z^(2 |n|): the same at both lengths.
    total, squares = light + 2 * ratio**2 / (1 - ratio**2), light**2 + 2 * ratio**4 / (1 - ratio**4)
    assert mode.participation == pytest.approx(total**2 / squares, rel=1e-10)
    assert mode.participation_longer == pytest.approx(mode.participation, rel=1e-10)
    assert mode.frequency > classify_modes(params).host_bands["longitudinal"][1]


def test_a_heavy_mass_holds_no_longitudinal_mode():
    """A heavier mass on a monatomic chain binds no mode (z = m' / (2 m - m') would exceed 1)."""
    params = centred(10, m_factors=(2.0,))
    assert not [mode for mode in classify_modes(params).localized if mode.branch == "longitudinal"]


def test_pinned_ends_hold_end_modes_in_the_gap_that_a_centre_rotor_does_not_meet():
    params = ChainParams(N=10, left_end="pinned", right_end="pinned", j_factors=(1.0,) * 10 + (1.5,) + (1.0,) * 10)
    classes = classify_modes(params)
    ends = [mode for mode in classes.localized if abs(mode.particle) == 10]
    # The mirror-symmetric chain's two end modes are its even and odd pair, split by 5e-7 in omega: each holds
    # both ends alike (which of the two is its peak is round-off).
    assert len(ends) == 2
    for mode in ends:
        assert mode.shares[0] == pytest.approx(mode.shares[-1], rel=1e-6) and mode.shares[0] > 0.4
    top, bottom = classes.host_bands["transverse_acoustic"][1], classes.host_bands["rotational_optical"][0]
    for mode in ends:
        assert top < mode.frequency < bottom and mode.branch == "rotational_optical"
        assert mode.participation_longer < 1.01 * mode.participation < 2 * mode.participation_longer
    shares = [(mode.particle, share) for mode, share in core_modes(params, (0,))]
    assert [share < 1e-4 for particle, share in shares if particle != 0] == [True, True]
    assert [share > 0.5 for particle, share in shares if particle == 0] == [True]
    found = {r.edge_frequency for r in resonances(params, 0.1, 10.0) if r.edge == "localized"}
    assert found == {mode.frequency for mode in classes.localized if mode.particle == 0}


#: A soft bond left of the centre, a heavy rotor (3 j) at it and a light particle (m / 2) right of it.
GRADED = {"E1_factors": (0.5, 1.0), "m_factors": (1.0, 1.0, 0.5), "j_factors": (1.0, 3.0, 1.0)}


def test_a_graded_chains_classification_is_the_same_at_two_lengths():
    """One localized mode per branch (the light particle's longitudinal and transverse ones, the heavy
    rotor's optical one in the gap), the same at N = 8 and 16; the host bands approach the uniform
    host's infinite bands, where the whole spectrum's optical bottom would stay at the rotor's 2.34."""
    a, b = classify_modes(centred(8, **GRADED)), classify_modes(centred(16, **GRADED))
    assert [m.branch for m in a.localized] == ["transverse_acoustic", "rotational_optical", "longitudinal"]
    for p, q in zip(a.localized, b.localized, strict=True):
        assert (p.branch, p.particle) == (q.branch, q.particle) and p.particle in (0, 1)
        assert p.frequency == pytest.approx(q.frequency, rel=1e-3)
        assert p.participation == pytest.approx(q.participation, rel=0.05)
        assert p.participation_longer < a.growth_threshold * p.participation
    assert a.localized[1].frequency < 0.7 * b.host_bands["rotational_optical"][0]
    infinite = wave_summary(ChainParams()).bands
    for name in BRANCHES:
        assert b.host_bands[name][1] == pytest.approx(infinite[name][1], abs=0.03)
    assert b.host_bands["rotational_optical"][0] == pytest.approx(infinite["rotational_optical"][0], abs=0.03)


def test_a_heavy_rotors_mode_is_a_resonance_where_the_rotor_turns_and_none_five_particles_away():
    """The heavy rotor (j x 4) has a mode at 2.1433 in the gap below the host's optical band (3.52):
    its harmonics resonate for a rotor on it (share 0.97) and not for one 5 particles away (7e-4);
    a harmonic in the gap between the mode and the band is in no band."""
    params = centred(10, j_factors=(4.0,))
    (mode,) = classify_modes(params).localized
    assert mode.frequency == pytest.approx(2.1433, abs=1e-4) and mode.branch == "rotational_optical"
    assert band_edges(params)["rotational_optical"][0] > 3.5 > mode.frequency
    (on,), (away,) = core_modes(params, (0,)), core_modes(params, (5,))
    assert on[1] > 0.9 and away[1] < CORE_SHARE / 10
    near = [r for r in resonances(params, 0.3, 3.0) if r.edge == "localized"]
    assert [r.omega for r in near] == pytest.approx([mode.frequency / n for n in range(6, 0, -1)], rel=1e-15)
    assert not [r for r in resonances(params, 0.3, 3.0, rotors=(5,)) if r.edge == "localized"]
    assert (1, "rotational_optical") not in harmonics_in_bands(params, 3.0)
    assert (1, "rotational_optical") in harmonics_in_bands(params, 4.0)


def test_a_graded_familys_json_and_netcdf_give_the_host_bands_and_the_localized_modes():
    params = centred(3, j_factors=(4.0,)).replace(gamma_u=0.0, gamma_v=0.0, gamma_phi=0.0)
    family = roto_breather_family(params, "sine", [5.0], locate=False)
    summary = json.loads(json.dumps(family.as_dict()))
    (mode,) = summary["localized_modes"]
    assert mode["particle"] == 0 and mode["resonant"] and mode["core_share"] > 0.9
    assert summary["host_bands"]["rotational_optical"][0] > mode["frequency"]
    assert summary["host_bands"] == {name: list(edge) for name, edge in band_edges(params).items()}
    attrs = family.to_dataset().attrs
    assert json.loads(attrs["localized_modes_json"]) == summary["localized_modes"]
    assert json.loads(attrs["host_bands_json"]) == summary["host_bands"]


def test_the_command_names_the_localized_mode(tmp_path):
    from typer.testing import CliRunner

    from cosserat_chain.cli import app

    config = tmp_path / "heavy.toml"
    config.write_text("N = 3\ngamma_u = 0\ngamma_v = 0\ngamma_phi = 0\nj_factors = [1, 1, 1, 4, 1, 1, 1]\n")
    out = CliRunner().invoke(app, ["breathers", "--config", str(config), "--omega", "5"])
    assert out.exit_code == 0, out.output
    (line,) = [line for line in out.output.splitlines() if line.startswith("localized mode:")]
    assert line.startswith("localized mode: omega = 2.14") and "(rotational_optical) at particle 0" in line
    assert line.endswith(": a resonance")


def test_a_graded_atlas_gives_each_values_localized_modes_with_its_rotors_share():
    """The heavy rotor's mode moves with the field E2 (its bonds' couple stiffness) and keeps its core share."""
    from cosserat_chain.experiments.breather_atlas import breather_atlas

    params = centred(3, j_factors=(4.0,)).replace(gamma_u=0.0, gamma_v=0.0, gamma_phi=0.0)
    atlas = breather_atlas(params, "sine", [5.0], "E2", [params.E2, 1.5 * params.E2])
    summary = json.loads(json.dumps(atlas.as_dict()))
    assert json.loads(atlas.to_dataset().attrs["localized_modes_json"]) == summary["localized_modes"]
    (low,), (high,) = summary["localized_modes"]
    assert low["frequency"] == pytest.approx(classify_modes(params).localized[0].frequency, rel=1e-15)
    assert high["frequency"] > low["frequency"] and low["resonant"] and high["resonant"]


def host_green(host: ChainParams, omega: float, dof: int, n_q: int = 1024) -> float:
    """G_dd(omega) at one particle of the infinite host: the mean over q of (B(q) - omega^2 M)^-1 (trapezoid, periodic)."""
    q = 2 * np.pi * np.arange(n_q) / n_q
    return float(np.mean(np.linalg.inv(bloch_stiffness(host, q) - omega**2 * np.diag(host.inertia))[:, dof, dof]).real)


@pytest.mark.parametrize(
    "field, factor, dof, branch, bracket",
    [
        ("j_factors", 4.0, 2, "rotational_optical", ("transverse_acoustic", 1, "rotational_optical", 0)),
        ("j_factors", 0.25, 2, "rotational_optical", ("rotational_optical", 1, None, 50.0)),
        ("m_factors", 0.5, 1, "transverse_acoustic", ("transverse_acoustic", 1, "rotational_optical", 0)),
    ],
)
def test_an_inertia_defects_transverse_mode_is_the_lifshitz_root_of_the_hosts_green_function(field, factor, dof, branch, bracket):
    """A defect dM on one degree of freedom d of particle 0 holds a mode where 1 = omega^2 dM G_dd(omega), G the
    infinite host's Green's function from its Bloch stiffness (independent of the finite chain's eigen solver):
    the heavy rotor's in the gap, the light rotor's above the optical band, the light mass's transverse one."""
    host = ChainParams(N=30)
    bands = wave_summary(host).bands
    low = bands[bracket[0]][bracket[1]] + 1e-9
    high = bands[bracket[2]][bracket[3]] - 1e-9 if bracket[2] else bracket[3]
    grid = np.linspace(low, high, 200)
    excess = (factor - 1.0) * host.inertia[dof]
    residual = np.array([1.0 - w**2 * excess * host_green(host, w, dof) for w in grid])
    crossings = np.flatnonzero(np.sign(residual[:-1]) != np.sign(residual[1:]))
    assert crossings.size == 1  # one bound state of this branch
    i = crossings[0]
    lifshitz = brentq(lambda w: 1.0 - w**2 * excess * host_green(host, w, dof), grid[i], grid[i + 1], xtol=1e-15)
    (mode,) = [m for m in classify_modes(centred(30, **{field: (factor,)})).localized if m.branch == branch]
    assert mode.particle == 0
    assert mode.frequency == pytest.approx(lifshitz, rel=1e-9)
