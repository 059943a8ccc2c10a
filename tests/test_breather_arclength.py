"""Roto-breather families by pseudo-arclength in Omega (numerics.breather_arclength): through folds, on the kit's driver."""

from __future__ import annotations

import dataclasses
import json
import math

import numpy as np
import pytest
import xarray as xr
from typer.testing import CliRunner

from cosserat_chain.cli import app
from cosserat_chain.experiments.breathers import damped_to_undamped, roto_breather_family
from cosserat_chain.loads import moment_load
from cosserat_chain.numerics.breather_arclength import HamiltonianFrequencyProblem, continue_hamiltonian_arclength
from cosserat_chain.numerics.dynamics import integrate
from cosserat_chain.numerics.kit import BranchEnd
from cosserat_chain.numerics.periodic import continue_in_frequency, find_periodic_orbit
from cosserat_chain.params import ChainParams
from cosserat_chain.state import ROW_INDEX

PHI = ROW_INDEX["phi"]
runner = CliRunner()


def undamped(**fields) -> ChainParams:
    return ChainParams(gamma_u=0.0, gamma_v=0.0, gamma_phi=0.0, **fields)


def closes_by_a_direct_run(o) -> float:
    """max |x(T) - x(0) - 2 pi k e_phi|, |v(T) - v(0)| of an independent Yoshida-4 run over one period."""
    run = integrate(
        o.params, o.model, moment_load(0.0, o.particle), t_end=o.period, dt=o.period / 4000, x0=o.x, v0=o.v,
        method="yoshida4", n_frames=2,
    )  # fmt: skip
    shift = np.zeros_like(o.x)
    shift[PHI] = 2 * math.pi * o.particle_turns
    return max(float(np.max(np.abs(run.x[-1] - o.x - shift))), float(np.max(np.abs(run.v[-1] - o.v))))


def test_without_a_fold_the_arclength_family_is_the_natural_step_family_at_the_same_frequencies():
    family = roto_breather_family(undamped(N=1), "sine", [6.0, 5.4], arclength=True, max_points=6)
    arc = family.family
    assert arc.folds == [] and len(arc.orbits) == 6
    omegas = arc.omega
    assert np.all(np.diff(omegas) < 0)  # towards omegas[-1]
    natural = continue_in_frequency(arc.orbits[0], omegas)
    assert natural.complete
    for a, b in zip(arc.orbits, natural.orbits):
        assert b.omega == pytest.approx(a.omega, rel=1e-14)
        assert np.max(np.abs(a.x - b.x)) < 1e-9 and np.max(np.abs(a.v - b.v)) < 1e-9
        assert abs(a.unfolding) < 1e-10
    assert family.as_dict()["events"] == []


def test_the_trace_stops_where_omega_leaves_the_range():
    family = roto_breather_family(undamped(N=1), "sine", [6.0, 5.9], arclength=True, max_points=50)
    arc = family.family
    assert arc.end == BranchEnd.PARAMETER_LIMIT and arc.complete
    assert arc.omega[-1] < 5.9 <= arc.omega[-2]


def test_bad_ranges_are_refused_naming_the_field():
    start = roto_breather_family(undamped(N=1), "sine", [6.0]).family.orbits[0]
    with pytest.raises(ValueError, match="omega_min"):
        continue_hamiltonian_arclength(start, -1.0, 7.0)
    with pytest.raises(ValueError, match=r"start's Omega"):
        continue_hamiltonian_arclength(start, 6.5, 7.0)
    with pytest.raises(ValueError, match="direction"):
        continue_hamiltonian_arclength(start, 5.0, 7.0, direction=0.5)
    with pytest.raises(ValueError, match="different frequencies"):
        roto_breather_family(undamped(N=1), "sine", [6.0, 6.0], arclength=True)


@pytest.fixture(scope="module")
def folded():
    """The in-band undamped family the paper's nonlinear rotation (N = 3, gamma = 0.1, M = 0.30) lands on, traced up in Omega."""
    damped = find_periodic_orbit(ChainParams(gamma_u=0.1, gamma_v=0.1, gamma_phi=0.1), "nonlinear", 0.30)
    landed = damped_to_undamped(damped).landed
    return landed, continue_hamiltonian_arclength(landed, 1.2, 1.45, max_points=40)


@pytest.mark.slow
def test_the_in_band_family_passes_its_fold_in_omega_where_the_fixed_frequency_problem_is_singular(folded):
    landed, arc = folded
    assert landed.omega == pytest.approx(1.3485410, abs=1e-6)
    assert len(arc.folds) == 1
    fold = arc.folds[0]
    # Omega turns back there, the energy goes on rising through it.
    omegas, energies = arc.omega, arc.energy
    assert np.all(omegas[: fold.index] < fold.parameter) and np.all(omegas[fold.index :] < fold.parameter)
    assert np.all(np.diff(omegas[: fold.index]) > 0) and np.all(np.diff(omegas[fold.index + 1 :]) < 0)
    assert np.all(np.diff(energies) > 0)
    assert energies[fold.index - 1] < fold.point.energy < energies[fold.index]
    assert fold.point.omega == pytest.approx(fold.parameter, rel=1e-14)
    # The energy-frequency curve's turn: a parabola Omega(E) through the orbits around the fold peaks there.
    near = slice(fold.index - 2, fold.index + 2)
    a, b, c = np.polyfit(energies[near], omegas[near], 2)
    assert -b / (2 * a) == pytest.approx(fold.point.energy, abs=2e-3)
    assert c - b * b / (4 * a) == pytest.approx(fold.parameter, abs=1e-5)
    # The fixed-frequency Newton Jacobian (find_hamiltonian_orbit's) is singular at the fold, regular beside it.
    problem = HamiltonianFrequencyProblem(landed, 1.2, 1.45)
    assert problem.fixed_frequency_singular_value(fold.point) < 1e-12
    assert problem.fixed_frequency_singular_value(arc.orbits[fold.index + 3]) > 1e-5
    assert problem.fixed_frequency_singular_value(arc.orbits[fold.index - 4]) > 1e-5

    # The Jordan block of the Hamiltonian pair at +1 (coupled by dT/dE) changes sign there: the pair, split by the
    # integration error, is real on the rising side and complex on the falling one.
    def pair(o):
        return o.multipliers[np.argsort(np.abs(o.multipliers - 1.0))[:2]]

    for o in arc.orbits[fold.index - 3 : fold.index]:
        assert np.all(np.abs(pair(o) - 1.0) < 1e-3) and np.all(pair(o).imag == 0.0)
    for o in arc.orbits[fold.index : fold.index + 3]:
        assert np.all(np.abs(pair(o) - 1.0) < 1e-3) and np.all(np.abs(pair(o).imag) > 1e-7)
    # Both sides, and the fold itself, close under an independent integration.
    for o in (arc.orbits[fold.index - 1], fold.point, arc.orbits[fold.index + 1], arc.orbits[-1]):
        assert abs(o.unfolding) < 1e-10
        assert closes_by_a_direct_run(o) < 1e-7


@pytest.mark.slow
def test_two_orbits_of_the_folded_family_share_a_frequency(folded):
    """Past the fold the family holds a second orbit at a frequency already traced: another energy, both closed."""
    _, arc = folded
    fold = arc.folds[0]
    omega = float(arc.omega[-1])
    below = [o for o in arc.orbits[: fold.index] if o.omega < omega]
    assert below, "the trace came back below a frequency of the rising side"
    natural = continue_in_frequency(below[-1], [below[-1].omega, omega])
    assert natural.complete
    low, high = natural.orbits[-1], arc.orbits[-1]
    assert low.omega == pytest.approx(high.omega, rel=1e-14)
    assert high.energy - low.energy > 0.05
    assert np.max(np.abs(high.x - low.x)) > 1e-2


@pytest.mark.slow
def test_the_pitchfork_before_the_fold_is_a_branch_point_where_a_multiplier_pair_meets_plus_one(folded):
    _, arc = folded
    points = [e for e in arc.events if e.kind == "branch_point"]
    assert len(points) == 1
    bp = points[0]
    assert bp.parameter < arc.folds[0].parameter
    before, after = arc.orbits[bp.index - 1], arc.orbits[bp.index]

    # Beside the branch point a nontrivial pair goes from the unit circle (complex) to the real axis.
    def nearest_pair(o):
        others = o.nontrivial_multipliers
        return others[np.argsort(np.abs(others - 1.0))[:2]]

    assert np.all(np.abs(np.abs(nearest_pair(before)) - 1.0) < 1e-6) and np.all(np.abs(nearest_pair(before).imag) > 1e-3)
    assert np.all(np.abs(nearest_pair(after).imag) < 1e-9) and np.max(np.abs(nearest_pair(after))) > 1.0 + 1e-3
    assert np.min(np.abs(nearest_pair(bp.point) - 1.0)) < 1e-2


def test_cli_arclength_json_and_refusal(tmp_path):
    config = tmp_path / "chain.toml"
    config.write_text("N = 1\n")
    out = tmp_path / "family.nc"
    args = ["breathers", "--omega", "6", "--to", "5.9", "--arclength", "--config", str(config), "--json", "--out", str(out)]
    result = runner.invoke(app, args)
    assert result.exit_code == 0, result.output
    summary = json.loads(result.output.splitlines()[-1])
    with xr.open_dataset(out) as ds:
        assert json.loads(ds.attrs["events_json"]) == [] and np.allclose(ds["omega"].values, summary["omega"], rtol=1e-14)
    assert summary["events"] == [] and summary["complete"]
    assert summary["omega"][0] == pytest.approx(6.0) and summary["omega"][-1] < 5.9 <= summary["omega"][-2]
    refused = runner.invoke(app, ["breathers", "--omega", "6", "--arclength", "--config", str(config)])
    assert refused.exit_code == 2 and "--arclength" in refused.output and "Traceback" not in refused.output


def test_a_family_in_a_field_at_fixed_omega_is_the_natural_step_family_at_the_same_values():
    """The sine chain N = 1 at Omega = 6, in E2 and in a (which carries the inertia j of its rectangle with it)."""
    from cosserat_chain.experiments.breather_atlas import chain_at
    from cosserat_chain.numerics.breather_arclength import continue_hamiltonian_field
    from cosserat_chain.numerics.periodic import find_hamiltonian_orbit

    params = undamped(N=1)
    start = roto_breather_family(params, "sine", [6.0]).family.orbits[0]
    for name, high in (("E2", 1.2), ("a", 0.24)):
        arc = continue_hamiltonian_field(start, name, lambda value, name=name: chain_at(params, name, value), 0.0, high, max_points=5)
        values = arc.values
        assert arc.parameter == name and values[0] == getattr(params, name) and np.all(np.diff(values) > 0) and arc.events == []
        for o in arc.orbits[1:]:
            assert o.omega == pytest.approx(6.0, rel=1e-14) and abs(o.unfolding) < 1e-10
            # Newton at that value from the start's state: the same orbit.
            natural = find_hamiltonian_orbit(o.params, "sine", 6.0, (start.x, start.v), turns=1, particle=0)
            assert np.max(np.abs(natural.x - o.x)) < 1e-8 and np.max(np.abs(natural.v - o.v)) < 1e-8
        if name == "a":
            assert arc.orbits[-1].params.j == pytest.approx(params.m * (values[-1] ** 2 + params.b**2) / 3.0, rel=1e-12)
    with pytest.raises(ValueError, match="field_name"):
        continue_hamiltonian_field(start, "model", lambda value: params, 0.0, 1.0)
    with pytest.raises(ValueError, match="must lie in"):
        continue_hamiltonian_field(start, "E2", lambda value: params, 1.5, 2.0)
    with pytest.raises(ValueError, match="arclength=True"):
        roto_breather_family(params, "sine", [6.0], along=("E2", 1.1))
    with pytest.raises(ValueError, match="one of a, b, h, E1, E2"):
        roto_breather_family(params, "sine", [6.0], arclength=True, along=("m", 1.1))


def test_cli_along_a_field_json_and_refusals(tmp_path):
    config = tmp_path / "chain.toml"
    config.write_text("N = 1\n")
    out = tmp_path / "family.nc"
    args = ["breathers", "--omega", "6", "--arclength", "--config", str(config)]
    result = runner.invoke(app, [*args, "--along", "E2=1.05", "--json", "--out", str(out)])
    assert result.exit_code == 0, result.output
    summary = json.loads(result.output.splitlines()[-1])
    assert summary["parameter"] == "E2" and summary["values"][0] == 1.0 and summary["values"][-1] > 1.05 > summary["values"][-2]
    assert np.allclose(summary["omega"], 6.0, rtol=1e-14) and summary["events"] == []
    with xr.open_dataset(out) as ds:
        assert json.loads(ds.attrs["settings_json"])["along"] == ["E2", 1.05]
    for extra, message in (
        (["--along", "m=2"], "FIELD one of a, b, h, E1, E2"),
        (["--along", "E2=x"], "VALUE must be a number"),
        (["--along", "E2=1"], "other than its 1.0"),
        (["--along", "E2=1.1", "--to", "5"], "give one of them"),
    ):
        refused = runner.invoke(app, [*args, *extra])
        assert refused.exit_code == 2 and message in refused.output, (extra, refused.output)


@pytest.mark.slow
def test_the_in_band_family_folds_in_e2_at_fixed_omega_where_the_family_in_omega_at_that_e2_folds(folded):
    """dT/dE = 0 on the surface of orbits over (Omega, E2): a fold in E2 at a fixed Omega is a fold in Omega at that E2."""
    from cosserat_chain.experiments.breather_atlas import chain_at
    from cosserat_chain.numerics.breather_arclength import continue_hamiltonian_field
    from cosserat_chain.numerics.periodic import find_hamiltonian_orbit

    landed, arc = folded
    start = arc.orbits[arc.folds[0].index - 2]  # below the fold in Omega, on its rising side
    params = start.params
    in_e2 = continue_hamiltonian_field(start, "E2", lambda value: chain_at(params, "E2", value), 0.9, 1.1, direction=-1.0, max_points=9)
    (fold,) = in_e2.folds
    (diagnostic,) = [d for e, d in zip(in_e2.events, in_e2.diagnostics, strict=True) if e.kind == "fold"]
    # The fixed-(Omega, E2) Newton system is singular there. (The pair at +1 stays split complex on both sides here:
    # its split follows the integration error's sign as well, so only the singular value marks the fold.)
    assert diagnostic["singular_value"] < 1e-10 and diagnostic["split_before"] == diagnostic["split_after"] == "complex"
    e2 = fold.parameter
    assert 0.998 < e2 < 0.9995 and fold.point.omega == pytest.approx(start.omega, rel=1e-14)
    problem = HamiltonianFrequencyProblem(fold.point, 1.2, 1.45)
    assert problem.fixed_frequency_singular_value(fold.point) < 1e-10
    # The family in Omega at that E2, from an orbit 0.002 below: it folds at the fixed frequency, at the same energy.
    below = find_hamiltonian_orbit(fold.point.params, "nonlinear", start.omega - 0.002, fold.point, turns=1, particle=0)
    in_omega = continue_hamiltonian_arclength(below, 1.3, 1.45, max_points=12)
    other = in_omega.folds[0]
    assert other.parameter == pytest.approx(start.omega, abs=1e-8)
    assert other.point.energy == pytest.approx(fold.point.energy, abs=1e-7)


def point_reflection_asymmetry(x: np.ndarray, v: np.ndarray) -> float:
    """max |S(x, v) - (x, v)| for the chain turned by pi in its plane: particle i -> -i, (u, v, phi) -> (-u, -v, phi)."""
    sign = np.array([-1.0, -1.0, 1.0])[:, None]
    return float(max(np.max(np.abs(sign * x[:, ::-1] - x)), np.max(np.abs(sign * v[:, ::-1] - v))))


@pytest.mark.slow
def test_the_branch_off_the_pitchfork_before_the_fold_breaks_the_point_symmetry_the_family_keeps(folded):
    from cosserat_chain.numerics.breather_arclength import follow_branches

    landed, arc = folded
    problem = HamiltonianFrequencyProblem(landed, 1.2, 1.45)
    follow_branches(arc, problem, max_points=8)
    (branch,) = [b for b in arc.branches if b is not None]
    # The kit's bisection of a sign stopped short; relocated on the chord a pair sits at +1 to 1e-11 in Omega.
    assert branch.point.omega == pytest.approx(1.3763283, abs=1e-6) and branch.accuracy < 1e-9
    assert max(point_reflection_asymmetry(o.x, o.v) for o in arc.orbits) < 1e-10
    orbits = branch.orbits
    assert len(orbits) == 8, branch.message
    grows = [point_reflection_asymmetry(o.x, o.v) for o in orbits]
    assert 1e-3 < grows[0] and grows[-1] > 0.1 and np.all(np.diff(grows) > 0)
    last = orbits[-1]
    assert abs(last.unfolding) < 1e-10 and closes_by_a_direct_run(last) < 1e-7
    # Its image under the point reflection is another orbit of the same frequency (the pitchfork's other half).
    sign = np.array([-1.0, -1.0, 1.0])[:, None]
    image = dataclasses.replace(last, x=sign * last.x[:, ::-1], v=sign * last.v[:, ::-1])
    assert closes_by_a_direct_run(image) < 1e-7
    assert max(np.max(np.abs(image.x - last.x)), np.max(np.abs(image.v - last.v))) > 0.1
