"""A rotation that ends at a loop homoclinic to a saddle-focus (issue 40, items 1 and 3): the shooting continuation
follows it through its folds of cycles, and the end is solved, not fitted.

Three Josephson junctions in a row with unequal critical currents (one site, three phases; the audit's system) at
alpha = 0.45: the one-turn rotation continued down in I snakes into a homoclinic end at a saddle with two real unstable
eigenvalues and a complex leading stable pair. AUTO-07p's values (NTST = 200, benchmarks/auto07p_user_systems.py's
setup; /tmp runs of the audit, written down here): folds of cycles at I = 0.53142260384 (T = 16.9357), 0.53193913189
(T = 22.0902), 0.53175119894 (T = 27.3060), ...; the period reaches 150 at I = 0.53179413051.
"""

import json

import numpy as np
import pytest
from typer.testing import CliRunner

from cosserat_chain.cli import app
from cosserat_chain.numerics.homoclinic import solve_branch_end
from cosserat_chain.numerics.shooting import (
    SEGMENTED_FROM,
    continue_orbits,
    find_orbit,
    orbit_multipliers,
    second_multiplier_at_one,
    settled_guess,
)
from three_junctions import REFERENCE, jj3

AUTO_FOLDS = (0.53142260384, 0.53193913189, 0.53175119894)
AUTO_END = 0.53179413051


def rotation(system):
    drift = system.parameter("I") / system.parameter("alpha")
    guess = settled_guess(system, np.concatenate([np.zeros(3), np.full(3, drift)]), coordinate=0)
    return find_orbit(system, guess, turns={c: 1 for c in system.coordinates})


def test_double_multiplier_split_by_errors():
    # A Jordan block at +1 perturbed by e splits into 1 +- sqrt(e) (real or a complex pair): still a second multiplier
    # at +1. A second multiplier at 1.05 beside an exact trivial one, or far from it, is not.
    for e in (1e-12, 1e-3, -1e-3, 0.03, -0.03):
        block = np.linalg.eigvals(np.array([[1.0, 1.0], [e, 1.0]]))
        assert second_multiplier_at_one(np.concatenate([block, [250.0, 1e-5]]))
    assert not second_multiplier_at_one(np.array([1.0, 1.05, 250.0, 1e-5]))
    assert not second_multiplier_at_one(np.array([1.0, 3.95, -2.5e5, 1e-5]))
    assert not second_multiplier_at_one(np.array([0.9, 0.2, -2.5e5]))


@pytest.mark.slow
def test_segmented_multipliers_agree_and_keep_liouville(monkeypatch):
    # The periodic Schur form of the segments against the formed monodromy's eigenvalues on an orbit where both are
    # accurate, and the product of all multipliers against Liouville's exp(-3 alpha T) (unit masses, damping alpha).
    import cosserat_chain.numerics.shooting as shooting

    orbit = rotation(jj3(I=0.8))
    formed = np.sort_complex(np.linalg.eigvals(orbit.monodromy))
    monkeypatch.setattr(shooting, "SEGMENTED_FROM", 0.0)
    segmented = np.sort_complex(orbit_multipliers(orbit.system, orbit.y0, orbit.period, orbit.monodromy))
    big = np.abs(formed) > 1e-3
    assert np.allclose(segmented[big], formed[big], rtol=1e-7, atol=1e-9)
    assert np.prod(np.abs(segmented)) == pytest.approx(np.exp(-3 * 0.45 * orbit.period), rel=1e-6)
    assert SEGMENTED_FROM > 1.0


@pytest.mark.slow
def test_snake_through_folds_to_a_solved_end():
    branch = continue_orbits(rotation(jj3()), "I", period_max=150.0, stop_at=(), max_points=3000)
    folds = [e for e in branch.events if e.kind == "fold" and e.located]
    assert len(folds) >= 3
    for event, auto in zip(folds, AUTO_FOLDS):
        assert event.parameter == pytest.approx(auto, abs=1e-9)
    # The branch goes past its third fold before the shooting's accuracy runs out, and says why it stops.
    assert max(branch.periods) > 30.0
    assert "exhausted" in branch.message or "period_max" in branch.message
    end = solve_branch_end(branch)
    assert end is not None and branch.end_method == "solved"
    assert branch.as_dict()["end_method"] == "solved"
    assert end.accuracy < 1e-7
    assert abs(end.value - AUTO_END) <= end.accuracy + 1e-9
    # The saddle: two real unstable eigenvalues, the leading stable ones a complex pair (a saddle-focus).
    eig = end.rest.eigenvalues
    assert np.sum(eig.real > 0) == 2 and np.all(np.abs(eig[eig.real > 0].imag) < 1e-9)
    lead = eig[eig.real < 0][np.argmax(eig[eig.real < 0].real)]
    assert abs(lead.imag) > 0.1


@pytest.mark.slow
def test_cli_through_folds_names_each_fold_and_the_end():
    base = ["orbit", "--system", REFERENCE, "--vary", "I", "--down-to", "0.5", "--period-max", "150", "--json"]
    result = CliRunner().invoke(app, [*base, "--through-folds"])
    assert result.exit_code == 0, result.output
    branch = json.loads(result.stdout)["branch"]
    folds = [e["value"] for e in branch["events"] if e["kind"] == "fold"]
    assert np.allclose(folds[:3], AUTO_FOLDS, atol=1e-9)
    assert branch["end_method"] == "solved"
    assert abs(branch["end_value"] - AUTO_END) <= branch["end_uncertainty"] + 1e-9
    # Without the option the branch stops at its first fold, as before.
    plain = CliRunner().invoke(app, base)
    assert plain.exit_code == 0, plain.output
    first = json.loads(plain.stdout)["branch"]
    assert first["end"] == "fold" and first["values"][-1] >= AUTO_FOLDS[0] - 1e-9


def test_through_folds_needs_vary():
    result = CliRunner().invoke(app, ["orbit", "--system", "pen", "--through-folds"])
    assert result.exit_code == 2
    assert "--through-folds" in result.output and "--vary" in result.output
