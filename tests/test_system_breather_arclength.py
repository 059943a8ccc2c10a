"""A user system's roto-breather family by pseudo-arclength (experiments.system_breather_arclength): folds, branch points, branches.

The Takeno-Peyrard lattice of three sites, free ends, the middle one rotating: below the band
(Omega < 1) its one-site family folds in Omega (C = 0.02), and lower down (C = 0.1) a pair of
multipliers passes through +1 while Omega goes on: a branch point, where orbits that break the
lattice's time reversal branch off.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from conftest import SYSTEMS_CACHE, undamped_energies
from cosserat_chain.experiments import system_breather_arclength as sa
from cosserat_chain.experiments import system_breathers as sb
from cosserat_chain.numerics.breather_arclength import pair_test
from cosserat_chain.numerics.shooting import OrbitNotFound, find_orbit, flow
from cosserat_chain.systems import takeno_peyrard

SITES = 3
#: The rotor turns once per period: its angle gains 2 pi.
SHIFT = np.array([0.0, 2 * math.pi, 0.0, 0.0, 0.0, 0.0])


@pytest.fixture(autouse=True)
def _cache(monkeypatch):
    """The compiled systems go to the tests' cache folder (compiled once, not every session), not the user's."""
    monkeypatch.setenv("COSSERAT_CHAIN_CACHE", str(SYSTEMS_CACHE))


@pytest.fixture(scope="module")
def folding():
    """C = 0.02: from the anti-continuum orbit at Omega = 0.9 up in Omega, through its fold near 0.9653, back down to 0.85."""
    start = sb.roto_breather_family(takeno_peyrard(SITES, C=0.02), 0.9).orbits[0]
    return sa.continue_family(start, "omega", (0.85, 0.97), direction=1.0)


@pytest.fixture(scope="module")
def branching():
    """C = 0.1: from Omega = 1.3 down to 0.7, the branch at its branch point near Omega = 0.743 followed for 10 orbits."""
    start = sb.roto_breather_family(takeno_peyrard(SITES, C=0.1), 1.3).orbits[0]
    return sa.continue_family(start, "omega", (0.7, 1.31), direction=-1.0, branches=True, branch_points=10)


def test_the_family_passes_its_fold_in_omega_and_reports_it_with_a_singular_fixed_frequency_newton_system(folding):
    omegas = folding.values
    (fold,) = folding.folds
    top = int(np.argmax(omegas))
    # The trace went up, turned at the fold and came back down below where it started.
    assert 0 < top < len(omegas) - 1 and omegas[-1] < 0.86 and omegas[0] == pytest.approx(0.9)
    assert omegas[top - 1] < fold.value and omegas[top + 1] < fold.value and abs(fold.value - omegas[top]) < 1e-3
    assert fold.value == pytest.approx(0.96531910, abs=1e-7) and fold.accuracy < 1e-6
    # The fixed-frequency Jacobian is singular at the fold, and only there.
    assert fold.singular_value < 1e-12
    assert min(sa.fixed_parameter_singular_value(o, "omega") for o in folding.orbits[::4]) > 1e-5
    # The Hamiltonian pair at +1 (a Jordan block away from the fold) splits complex on one side, real on the other.
    assert {fold.split_before, fold.split_after} == {"complex", "real"}
    before, after = folding.orbits[fold.index - 3], folding.orbits[fold.index + 3]
    assert {sa.pair_split(before), sa.pair_split(after)} == {"complex", "real"}
    # Energy grows through the fold (the family is one curve) and is conserved along each orbit.
    energies = [sa.energy(o) for o in folding.orbits]
    assert np.all(np.diff(energies) > 0)
    for orbit in (fold.orbit, folding.orbits[0], folding.orbits[-1]):
        assert np.ptp(undamped_energies(orbit, 9)) < 1e-9
        assert np.max(np.abs(flow(orbit.system, orbit.y0, orbit.period, variations=False)[0] - orbit.y0 - SHIFT)) < 1e-8


def test_the_fold_lies_between_two_fixed_frequency_traces_from_either_branch(folding):
    """Newton at fixed Omega (natural steps of 1e-4 up from 0.9640): each branch's last orbit lies just below the fold, none above."""
    (fold,) = folding.folds
    step = 1e-4
    lasts = []
    for side in (folding.orbits[: fold.index], folding.orbits[fold.index :]):
        # The member of this side nearest Omega = 0.9640 starts the trace.
        member = min(side, key=lambda o: abs(2 * math.pi / o.period - 0.964))
        orbit, omega = member, 2 * math.pi / member.period
        while True:
            trial = omega + step
            try:
                found = find_orbit(orbit.system, (orbit.y0, 2 * math.pi / trial), turns=orbit.turns, unfold="gamma")
            except OrbitNotFound:
                break
            if np.max(np.abs(found.y0 - orbit.y0)) > 0.05:  # a jump onto the other branch: the trace's own branch is gone
                break
            orbit, omega = found, trial
            assert omega < fold.value + 1e-6
        lasts.append((omega, sa.energy(orbit)))
    (low_omega, low_energy), (high_omega, high_energy) = lasts
    assert fold.value - 2 * step < low_omega <= fold.value and fold.value - 2 * step < high_omega <= fold.value
    # The fold's energy lies between the two traces' last ones.
    assert low_energy < fold.energy < high_energy


def test_a_branch_point_is_a_pair_through_plus_one_while_omega_goes_on(branching):
    (point,) = branching.branch_points
    assert 0.742 < point.value < 0.744 and point.accuracy < 1e-4
    a, b = branching.orbits[point.index - 1], branching.orbits[point.index]
    # Omega keeps decreasing across it (no fold), and one pair goes from real to the unit circle.
    assert 2 * math.pi / a.period > point.value > 2 * math.pi / b.period
    assert pair_test(a) * pair_test(b) < 0
    assert not branching.folds
    assert point.singular_value < 1e-6


def distance_to_trajectory(orbit, y: np.ndarray, samples: int = 1500) -> float:
    """Smallest max-norm distance from the state y to the orbit's states, the angles compared modulo 2 pi."""
    states = orbit.trajectory(orbit.period * np.linspace(0.0, 1.0, samples))
    n = orbit.system.size
    gap = states - y
    gap[:, :n] = np.angle(np.exp(1j * gap[:, :n]))
    return float(np.min(np.max(np.abs(gap), axis=1)))


def distance_to_reversal_fixed_set(orbit, samples: int = 1500) -> float:
    """Smallest over the orbit of max_i dist(q_i, {0, pi} mod 2 pi): 0 for an orbit the time reversal (q, v) -> (-q, v) maps to itself."""
    q = orbit.trajectory(orbit.period * np.linspace(0.0, 1.0, samples))[:, :SITES]
    r = np.mod(q, math.pi)
    return float(np.min(np.max(np.minimum(r, math.pi - r), axis=1)))


def test_the_branch_at_the_branch_point_breaks_the_time_reversal_the_family_keeps(branching):
    (point,) = branching.branch_points
    branch = point.branch
    assert len(branch) == 10, point.branch_message
    # The family's orbits start at rest in every angle: they pass through the reversal's fixed set.
    assert max(np.max(np.abs(o.q0)) for o in branching.orbits) < 1e-6
    # The branch's do not, more so the farther from the branch point; they are orbits of the undamped lattice
    # and leave at Omega = the branch point's.
    distances = [distance_to_reversal_fixed_set(o) for o in branch[::3]]
    assert distances[0] > 1e-4 and distances[-1] > 3e-3 and distances[-1] > 2 * distances[0]
    assert abs(2 * math.pi / branch[0].period - point.value) < 1e-4
    last = branch[-1]
    assert abs(last.unfolding) < 1e-9
    # Its mirror image under the reversal, (-q0, v0), is an orbit too, and a different one (the other half of the pitchfork).
    system = last.system.with_parameters(gamma=0.0)
    mirrored = np.concatenate([-last.q0, last.v0])
    assert np.max(np.abs(flow(system, mirrored, last.period, variations=False)[0] - mirrored - SHIFT)) < 1e-7
    assert distance_to_trajectory(last, mirrored) > 1e-3
    assert np.ptp(undamped_energies(last, 9)) < 1e-9


def test_bad_input_is_refused_with_the_field_named():
    start = sb.roto_breather_family(takeno_peyrard(SITES, C=0.02), 0.9).orbits[0]
    with pytest.raises(ValueError, match="direction"):
        sa.continue_family(start, "omega", (0.85, 0.97), direction=2)
    with pytest.raises(ValueError, match="must lie in the limits"):
        sa.continue_family(start, "omega", (0.95, 0.97))
    with pytest.raises(ValueError, match="low < high"):
        sa.continue_family(start, "omega", (0.97, 0.85))
    with pytest.raises(ValueError, match="K"):
        sa.continue_family(start, "K", (0.0, 1.0))
    with pytest.raises(sb.BreatherError, match="arclength"):
        sb.roto_breather_family(takeno_peyrard(SITES, C=0.02), 0.9, along=("C", 0.1))
    with pytest.raises(sb.BreatherError, match="along: takeno_peyrard has no parameter 'K'"):
        sb.roto_breather_family(takeno_peyrard(SITES, C=0.02), 0.9, arclength=True, along=("K", 0.1))


@pytest.mark.slow
def test_a_fold_in_the_coupling_at_fixed_omega_is_the_fold_in_omega_at_that_coupling():
    """Both are where dT/dE = 0 on the surface of orbits: the C-family at Omega = 0.95 folds at C_f, and the family in Omega at C_f folds at 0.95."""
    start = sb.roto_breather_family(takeno_peyrard(SITES, C=0.02), 0.95).orbits[0]
    in_coupling = sa.continue_family(start, "C", (0.0, 0.06), direction=1.0)
    (fold,) = in_coupling.folds
    assert 0.03 < fold.value < 0.04 and fold.accuracy < 1e-8 and fold.singular_value < 1e-12
    assert np.all(np.array([o.period for o in in_coupling.orbits]) == start.period)
    assert in_coupling.values[-1] < 0.0  # it came back down past the anti-continuum limit on the other branch
    in_omega = sb.roto_breather_family(takeno_peyrard(SITES, C=fold.value), 0.85, to=0.97, arclength=True)
    (other,) = [e for e in in_omega.events if e.kind == "fold"]
    assert other.value == pytest.approx(0.95, abs=1e-9)
    assert other.energy == pytest.approx(fold.energy, abs=1e-9)


def test_the_command_lists_the_events_in_json_and_in_the_file(tmp_path, monkeypatch):
    import json

    import xarray as xr
    from typer.testing import CliRunner

    from cosserat_chain.cli import app

    # The family traced once: the text run, asked with the same arguments, is handed the JSON run's.
    traced, calls, families = sb.roto_breather_family, [], []

    def once(system, omega, *, progress, **options):
        calls.append((system.name, omega, options))
        if not families:
            families.append(traced(system, omega, progress=progress, **options))
        return families[0]

    monkeypatch.setattr(sb, "roto_breather_family", once)
    out = tmp_path / "family.nc"
    args = ["breathers", "--system", "takeno_peyrard", "--set", "sites=3", "--set", "C=0.02", "--omega", "0.95", "--arclength"]
    result = CliRunner().invoke(app, [*args, "--along", "C=0.06", "--json", "--out", str(out)])
    assert result.exit_code == 0, result.output
    summary = json.loads(result.output.strip().splitlines()[-1])
    assert summary["parameter"] == "C" and summary["values"][0] == 0.02 and np.allclose(summary["omega"], 0.95, rtol=1e-14)
    fold = next(e for e in summary["events"] if e["kind"] == "fold")
    assert (
        0.03 < fold["value"] < 0.04
        and fold["singular_value"] < 1e-12
        and {fold["split_before"], fold["split_after"]} == {"real", "complex"}
    )
    with xr.open_dataset(out) as ds:
        assert ds.attrs["parameter"] == "C"
        assert json.loads(ds.attrs["events_json"]) == summary["events"]
    text = CliRunner().invoke(app, [*args, "--along", "C=0.06"])
    assert text.exit_code == 0 and "fold at C = 0.03364" in text.output and "split complex -> real" in text.output
    assert len(calls) == 2 and calls[0] == calls[1]


@pytest.mark.parametrize(
    ("extra", "message"),
    [
        (["--along", "C=0.06"], "give --arclength as well"),
        (["--arclength", "--along", "K=1"], "NAME=VALUE with NAME a parameter of takeno_peyrard"),
        (["--arclength", "--along", "C=x"], "VALUE must be a number"),
        (["--arclength", "--along", "C=0.02"], "differ from C = 0.02"),
        (["--arclength"], "give one of them"),
        (["--arclength", "--to", "1.0", "--along", "C=0.1"], "give one of them"),
    ],
)
def test_the_command_refuses_bad_arclength_options(extra, message):
    from typer.testing import CliRunner

    from cosserat_chain.cli import app

    args = ["breathers", "--system", "takeno_peyrard", "--set", "sites=3", "--set", "C=0.02", "--omega", "0.95"]
    result = CliRunner().invoke(app, [*args, *extra])
    assert result.exit_code == 2 and message in result.output, result.output


@pytest.mark.slow
def test_the_counter_rotating_pair_has_a_branch_point_where_orbits_breaking_its_mirror_symmetry_branch_off():
    """Four sites, rotors 1 and 2 turning against each other (C = 0.1): the family keeps S: q_i -> -q_(3-i); a branch off it does not."""
    system = takeno_peyrard(4, C=0.1)
    start = sb.roto_breather_family(system, 1.5, rotor=1, partner=2, counter=True).orbits[0]
    family = sa.continue_family(start, "omega", (0.7, 1.5), direction=-1.0, branches=True, branch_points=8)

    def asymmetry(y: np.ndarray) -> float:
        q, v = y[:4], y[4:]
        return float(max(np.max(np.abs(q + q[::-1])), np.max(np.abs(v + v[::-1]))))

    assert max(asymmetry(o.y0) for o in family.orbits) < 1e-9
    breaking = [e for e in family.branch_points if e.branch and asymmetry(e.branch[-1].y0) > 1e-2]
    assert len(breaking) == 1
    point = breaking[0]
    assert point.value == pytest.approx(0.7133125, abs=1e-6) and point.accuracy < 1e-6
    branch = point.branch
    grows = [asymmetry(o.y0) for o in branch]
    assert 1e-4 < grows[0] < grows[-1] and np.all(np.diff(grows) > 0)
    # Its image under S is an orbit too, another one: the branch's two halves.
    last = branch[-1]
    undamped = last.system.with_parameters(gamma=0.0)
    image = -np.concatenate([last.q0[::-1], last.v0[::-1]])
    shift = np.concatenate([2 * math.pi * last.turns, np.zeros(4)])
    assert np.max(np.abs(flow(undamped, image, last.period, variations=False)[0] - image - shift)) < 1e-7
    assert distance_to_trajectory(last, image) > 1e-2
