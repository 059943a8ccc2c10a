"""Homoclinic ends of unequal pendulum pairs, solved (issue 40 item 3; numerics/homoclinic.py ``homoclinic_from_orbit``).

Two damped driven pendula of different lengths, masses and dampings, coupled by a torsion spring (or a sine bond):

    phi_a'' + a phi_a' + sin(phi_a) = I + k (phi_b - phi_a),
    mu phi_b'' + a r phi_b' + w sin(phi_b) = I - k (phi_b - phi_a).

Their in-phase rotation, followed down in I, ends at a loop homoclinic to the saddle with BOTH pendula up (two real
unstable eigenvalues), not to the static branch's saddle past the fold (one pendulum up, one unstable eigenvalue):
following that one, ``diagram --system`` lost the saddle and reported the fit of the period's growth with the searched
bracket (15.9) as its uncertainty. The references are AUTO-07p's (NTST = 100 and 200, NCOL = 4, the rotation continued
down in I until its period passes 150, where AUTO's I is the homoclinic end to its 11 printed digits, equal for both
meshes): the pair of the twelfth audit and two random pairs (seeds 1 and 2 of ``numpy.random.default_rng``: k, a, mu, w, r drawn
uniformly from [0.1, 0.5], [0.08, 0.2], [0.6, 2], [0.7, 1.5], [0.7, 1.5], a sine bond for seed 1).
"""

from __future__ import annotations

import math
from types import SimpleNamespace

import numpy as np
import pytest

from conftest import SYSTEMS_CACHE
from cosserat_chain.experiments import system_diagram as module
from cosserat_chain.experiments.system_diagram import system_diagram
from cosserat_chain.numerics.homoclinic import HomoclinicError, homoclinic_from_orbit
from cosserat_chain.numerics.shooting import find_orbit, flow
from cosserat_chain.systems import LatticeSystem

#: The accuracy the issue asks of the lower edge of the loop.
ASKED = 1e-8
#: AUTO-07p's homoclinic end of the audit's pair (11 digits, NTST = 100 and 200 alike).
AUDIT_END = 0.19625240437
TURNS = {"phia_0": 1, "phib_0": 1}


@pytest.fixture(autouse=True)
def _cache(monkeypatch):
    """The compiled systems go to the tests' cache folder, not the user's."""
    monkeypatch.setenv("COSSERAT_CHAIN_CACHE", str(SYSTEMS_CACHE))


def unequal_pair(*, I=0.0, k=0.3, a=0.15, mu=1.7, w=1.3, r=1.2, coupling="harmonic"):  # noqa: E741 - the drive's name
    """The pair above as one site with two angles (the defaults: the twelfth audit's pair)."""
    bond = "k/2*(phib - phia)**2" if coupling == "harmonic" else "k*(1 - cos(phib - phia))"
    return LatticeSystem(
        sites=1, dofs=("phia", "phib"), angles=("phia", "phib"),
        site_energy=f"(1 - cos(phia)) + w*(1 - cos(phib)) - I*(phia + phib) + {bond}",
        mass={"phia": 1.0, "phib": "mu"}, damping={"phia": "a", "phib": "a*r"},
        parameters={"I": I, "k": k, "a": a, "mu": mu, "w": w, "r": r}, name=f"unequal_pair_{coupling}",
    )  # fmt: skip


def test_the_loop_of_a_long_period_orbit_is_solved_through_the_saddle_it_lingers_at():
    """From the audit's orbit of period 20 (1.1e-6 above the end), the loop is solved to the asked accuracy, AUTO-07p's
    value within it, through the saddle with both pendula up (two real unstable eigenvalues), which is not the static
    branch's saddle past the fold (one pendulum up: one unstable eigenvalue)."""
    current = 0.19625347517247732
    system = unequal_pair(I=current)
    # The continuation's last orbit (Newton on it from these digits stalls at a residual of 7e-9: the loop is that near).
    y0 = np.array([4.461599650031927, 4.73942602312344, 1.4107314150964145, 1.2426390390178979])
    orbit = SimpleNamespace(system=system, y0=y0, period=20.12041962519776)
    closure = flow(system, y0, orbit.period, variations=False)[0] - y0 - np.array([2 * math.pi, 2 * math.pi, 0.0, 0.0])
    assert np.max(np.abs(closure)) < 1e-6
    end = homoclinic_from_orbit(orbit, turns=TURNS, parameter="I")
    assert end.accuracy <= ASKED and abs(end.value - AUDIT_END) <= max(end.accuracy, 1e-11)
    assert np.sum(end.rest.eigenvalues.real > 0) == 2 and end.rest.others.shape[1] == 1
    # Both pendula up: each angle between pi/2 and pi (mod 2 pi), where its own restoring torque falls with the angle.
    up = np.mod(end.rest.q, 2 * math.pi)
    assert np.all((math.pi / 2 < up) & (up < math.pi))
    # The loop: it leaves the saddle and comes back to it shifted by 2 pi in both angles.
    path = end.trajectory(np.linspace(0.0, end.time, 400))
    assert np.linalg.norm(path[-1] - end.rest.y - end.shift) == pytest.approx(end.eps, rel=1e-4)


def test_an_orbit_far_from_its_loop_is_refused_with_a_message():
    system = unequal_pair(I=1.3)
    orbit = find_orbit(system, (np.array([0.0, 0.0, 8.0, 7.0]), 0.8), turns=TURNS)
    with pytest.raises(HomoclinicError, match="near the orbit.s slowest point|not close enough to its homoclinic loop"):
        homoclinic_from_orbit(orbit, turns=TURNS, parameter="I")
    with pytest.raises(ValueError, match="value must be a finite number"):
        homoclinic_from_orbit(orbit, turns=TURNS, parameter="I", value=math.nan)


@pytest.mark.parametrize(
    ("parameters", "auto"),
    [
        pytest.param({}, AUDIT_END, id="audit"),
        pytest.param(
            {"k": 0.305, "a": 0.194, "mu": 0.802, "w": 1.459, "r": 0.949, "coupling": "sine"},
            0.27968300176,
            id="seed1",
            marks=pytest.mark.slow,
        ),
        pytest.param(
            {"k": 0.205, "a": 0.116, "mu": 1.74, "w": 0.774, "r": 1.18},
            0.13311167554,
            id="seed2",
            marks=pytest.mark.slow,
        ),
    ],
)
def test_the_diagrams_end_of_an_unequal_pair_is_solved_to_auto07p(parameters, auto):
    """``diagram --system``'s row: the end solved (not fitted) to the asked accuracy, AUTO-07p's value within it. Seeds 1
    and 2's branches end where the monodromy loses the trivial multiplier (||M|| ~ 1e9), their last orbits 0.004 and
    0.002 from the saddle; seed 2's loop is solved from an earlier orbit (``branch_end_orbits``: its two longest ones a
    unit of time apart miss a rung of the ladder)."""
    pair = unequal_pair(**parameters)
    (row,) = system_diagram(pair, "a", [pair.parameter("a")], "I").rows
    assert (row.end, row.method) == ("homoclinic", "solved"), row.message
    assert row.accuracy <= ASKED and abs(row.stops - auto) <= max(row.accuracy, 1e-11)
    assert row.homoclinic["unstable_directions"] == 2 and row.open is True


def test_a_fit_that_remains_carries_its_own_uncertainty_and_says_fitted(monkeypatch):
    """Where neither solve finds the loop, the row keeps the fit of the period's growth: ``stops_method`` fitted, its
    uncertainty the fit's own (the continuation's), in the JSON and the NetCDF, and the message says it is a fit."""

    def refuse(*args, **kwargs):
        raise HomoclinicError("no loop here")

    monkeypatch.setattr(module, "homoclinic_from_orbit", refuse)
    monkeypatch.setattr(module, "homoclinic_end", refuse)
    fits = []
    continued = module.continue_orbits

    def spy(*args, **kwargs):
        fits.append(continued(*args, **kwargs))
        return fits[-1]

    monkeypatch.setattr(module, "continue_orbits", spy)
    pair = LatticeSystem(sites=1, site_energy="1 - cos(phi) - I*phi", damping="alpha", parameters={"I": 0.0, "alpha": 0.3}, name="pendulum")
    diagram = system_diagram(pair, "alpha", [0.3], "I")
    (row,) = diagram.rows
    (branch,) = fits
    assert (row.end, row.method) == ("homoclinic", "fitted")
    assert row.stops == branch.end_value and row.accuracy == branch.end_uncertainty > 0
    assert "no loop here" in row.reason and "fitted (the fit's own uncertainty)" in row.message
    (entry,) = diagram.as_dict()["rows"]
    assert (entry["stops_method"], entry["stops_uncertainty"]) == ("fitted", branch.end_uncertainty)
    ds = diagram.to_dataset()
    assert ds["stops_uncertainty"].values[0] == branch.end_uncertainty and ds["stops_method"].values[0] == "fitted"


def test_orbit_down_to_says_its_end_is_a_fit_in_the_json_and_the_file(tmp_path):
    """``orbit --system --vary``: a period that diverges gives the end fitted from its growth, labelled ``fitted`` with the
    fit's own uncertainty in the JSON branch and the NetCDF attributes (the pendulum's retrapping current within it)."""
    import json

    import xarray as xr
    from typer.testing import CliRunner

    from cosserat_chain.cli import app

    out = tmp_path / "orbit.nc"
    args = ["orbit", "--system", "josephson_array", "--set", "sites=1", "--set", "alpha=0.3", "--set", "I=0.8"]
    result = CliRunner().invoke(app, [*args, "--vary", "I", "--period-max", "60", "--json", "--out", str(out)])
    assert result.exit_code == 0, result.output
    branch = json.loads(result.stdout)["branch"]
    assert branch["end_method"] == "fitted" and branch["end_uncertainty"] > 0
    with xr.open_dataset(out) as ds:
        assert ds.attrs["branch_end_method"] == "fitted"
        assert (ds.attrs["branch_end_value"], ds.attrs["branch_end_uncertainty"]) == (branch["end_value"], branch["end_uncertainty"])
    # The pendulum's retrapping current at alpha = 0.3 (the solved loop, 1e-10).
    pendulum = LatticeSystem(
        sites=1, site_energy="1 - cos(phi) - I*phi", damping="alpha", parameters={"I": 0.5, "alpha": 0.3}, name="pendulum"
    )
    from cosserat_chain.numerics.homoclinic import homoclinic_end

    end = homoclinic_end(pendulum, np.array([math.pi - math.asin(0.5)]), turns={"phi_0": 1}, bracket=(0.2, 0.5), parameter="I")
    assert abs(branch["end_value"] - end.value) <= branch["end_uncertainty"]
