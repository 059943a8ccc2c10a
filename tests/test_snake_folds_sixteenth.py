"""Folds 9-13 of the three junctions' snake (tests/three_junctions.jj3 continued down in I from 0.97) against
AUTO-07p's refined runs: ``refined`` in benchmarks/results/auto07p_jj3_snake.json, written by
``python benchmarks/auto07p_jj3_snake.py`` (EPSL = EPSU = 1e-12, EPSS = 1e-6, ITMX = 20, DSMAX = 0.002 on
(NTST, NCOL) = (200, 4), (400, 4), (400, 7), I printed to 15 digits through PVLS; its docstring says why AUTO's default
settings pass some of these folds unlabelled). tests/test_system_collocation.py checks folds 1-8.
"""

import json
from pathlib import Path

import numpy as np
import pytest
from scipy.optimize import fsolve

from cosserat_chain.numerics.shooting import find_orbit, settled_guess
from cosserat_chain.numerics.system_collocation import continue_collocation_orbits, find_collocation_orbit
from three_junctions import jj3

AUTO_SNAKE = Path(__file__).resolve().parents[1] / "benchmarks" / "results" / "auto07p_jj3_snake.json"
#: Folds 9-13 in the order of the branch.
LATE = slice(8, 13)
#: AUTO-07p's three refined meshes agree on folds 1-13 to 2e-13 in I (NCOL = 7 lies 1e-13 below NCOL = 4 throughout).
AUTO_MESHES = 3e-13


def refined_folds() -> dict[str, list[dict]]:
    return {name: run["folds"] for name, run in json.loads(AUTO_SNAKE.read_text())["refined"]["runs"].items()}


def test_auto07p_refined_folds_are_mesh_converged_and_snake_at_the_saddle_focus_rate():
    runs = refined_folds()
    values = np.array([[f["I"] for f in folds[:16]] for folds in runs.values()])
    periods = np.array([f["period"] for f in runs["ntst400_ncol7"][:16]])
    assert values.shape == (3, 16)
    assert np.ptp(values, axis=0).max() < AUTO_MESHES
    # Shil'nikov's snake: the loop's saddle (two unstable eigenvalues, the leading stable pair -rho +- i omega) puts a
    # fold every pi / omega of period, each on the other side of the homoclinic end and exp(pi rho / omega) times
    # closer to it; folds 9-13 lie 4.6e-8 ... 4.1e-10 apart, far above the meshes' spread.
    system = jj3(I=0.53179413051)
    saddle = fsolve(system.forces, [2.9, 1.9, 2.8], xtol=1e-13)
    stiffness = np.asarray(system.force_jacobian(saddle).todense())
    alpha = system.parameter("alpha")
    eigenvalues = np.linalg.eigvals(np.block([[np.zeros((3, 3)), np.eye(3)], [stiffness, -alpha * np.eye(3)]]))
    assert np.sum(eigenvalues.real > 0) == 2
    stable = eigenvalues[eigenvalues.real < 0]
    rho, omega = -stable[np.argmax(stable.real)].real, abs(stable[np.argmax(stable.real)].imag)
    steps = np.diff(values[0])
    assert np.all(steps[:-1] * steps[1:] < 0)
    assert np.allclose(steps[6:-1] / steps[7:], -np.exp(np.pi * rho / omega), rtol=2e-4)
    assert np.allclose(np.diff(periods[6:13]), np.pi / omega, rtol=1e-3)
    assert np.min(np.abs(steps[: LATE.stop])) > 1e3 * AUTO_MESHES


@pytest.mark.slow
def test_collocation_locates_and_confirms_folds_9_to_13_at_auto07p_values():
    # Folds 1-8 on 200 intervals (NCOL = 4), then the orbit solved again with NCOL = 7 and followed to T = 82. The turns
    # are located (the secant on the tangent's I component) at AUTO's I. The located orbits' multipliers do not show
    # the double +1 (|M| ~ 1e14 ... 1e20, and the second multiplier runs from ~1e6 through +1 within the location's
    # error; AUTO's at its LP 9: 1 and 3.87): each fold is confirmed by a real multiplier through +1 between the two
    # orbits of its step, whose trivial multipliers are resolved (before, none of the five was kept).
    system = jj3()
    drift = system.parameter("I") / system.parameter("alpha")
    guess = settled_guess(system, np.concatenate([np.zeros(3), np.full(3, drift)]), coordinate=0)
    start = find_collocation_orbit(system, find_orbit(system, guess, turns=dict.fromkeys(system.coordinates, 1)), ntst=200)
    first = continue_collocation_orbits(start, "I", through_folds=True, period_max=56.0, max_points=2000)
    assert len([e for e in first.events if e["kind"] == "fold"]) == 8
    last = first.orbits[-1]
    orbit = find_collocation_orbit(last.system, last, ntst=200, ncol=7)
    branch = continue_collocation_orbits(orbit, "I", through_folds=True, period_max=82.0, max_points=400)
    folds = [e for e in branch.events if e["kind"] == "fold"]
    auto = refined_folds()["ntst400_ncol7"][LATE]
    assert len(folds) == 5 and all(e["located"] for e in folds)
    assert np.allclose([e["moment"] for e in folds], [f["I"] for f in auto], rtol=0.0, atol=1e-12)
    # The period at a fold is linear in the location's error: AUTO's meshes spread it by up to 1e-3 at fold 13.
    assert np.allclose([e["orbit"].period for e in folds], [f["period"] for f in auto], rtol=0.0, atol=2e-3)
