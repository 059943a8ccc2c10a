"""Changes of stability located along an atlas's field (its geometry, a coupling) at a fixed Omega (issue 41).

The one locate mechanism (:func:`~cosserat_chain.experiments.system_breathers.locate_stability_changes`) on
:func:`~cosserat_chain.experiments.system_breathers.parameter_axis`: bisection and secant in the field's value.
Checked against

* closed forms: a rotor and two Mathieu oscillators on one site (test_breather_atlas_changes), each of whose
  instability tongues at +1 has its edge where 4 w^2 / Omega^2 = a_2(2 C / Omega^2): at Omega = 0.97 the coupling C
  of each edge is a root SciPy gives to round-off;
* the Floquet multipliers themselves: near a collision the pair's split goes as the square root of the distance,
  so (ln |mu|)^2 on the unstable side and the squared distance of the colliding pair on the stable side are linear
  in the field, and each fit's zero is the collision, found from the atlas's own solve without the discriminant;
* the other axis: the Omega-axis locate on the row at the located value finds the same collision at the column's Omega;
* the bands at the located value: a loss at +1 just above the band of Takeno-Peyrard names the band's top there,
  sqrt(1 + 4 C), not at the grid's values.
"""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
import xarray as xr
from scipy.optimize import brentq
from scipy.special import mathieu_a
from typer.testing import CliRunner

from conftest import SYSTEMS_CACHE
from cosserat_chain import ChainParams
from cosserat_chain.cli import app
from cosserat_chain.experiments import system_breathers as sb
from cosserat_chain.experiments.breather_atlas import breather_atlas, check_along, traced_families
from cosserat_chain.experiments.breathers import _Member, _solvers
from cosserat_chain.experiments.system_breather_atlas import SystemBreatherAtlas, system_breather_atlas
from cosserat_chain.systems import takeno_peyrard
from mathieu_rotor_system import REFERENCE, rotor_two_mathieu

runner = CliRunner()
W0, W1, OMEGA = 1.0, 1.01, 0.97
#: The couplings of the Mathieu atlas: below both tongues' edges at OMEGA, between them, above both.
COUPLINGS = [0.2, 0.4, 0.6]
#: The sine chain with N = 2: at Omega = 5.8 a quartet leaves the circle between b = 0.16 and 0.2.
CHAIN = ChainParams(N=2, gamma_u=0.0, gamma_v=0.0, gamma_phi=0.0)
#: Takeno-Peyrard, 7 sites: the one-site family loses stability at +1 along C between 0.05 and 0.07 at Omega = 1.15.
TP_OMEGAS, TP_COUPLINGS = [1.2, 1.15], [0.05, 0.07]


@pytest.fixture(autouse=True)
def _cache(monkeypatch):
    """The compiled systems go to the tests' cache folder (compiled once, not every session), not the user's."""
    monkeypatch.setenv("COSSERAT_CHAIN_CACHE", str(SYSTEMS_CACHE))


def edge_coupling(w: float) -> float:
    """The C at which OMEGA is the lower edge of the tongue near w: 4 w^2 / OMEGA^2 = a_2(2 C / OMEGA^2)."""
    return brentq(lambda c: 4 * w**2 / OMEGA**2 - mathieu_a(2, 2 * c / OMEGA**2), 0.25, 0.55, xtol=1e-15)


@pytest.fixture(scope="module")
def mathieu():
    found = system_breather_atlas(rotor_two_mathieu(), [OMEGA], "C", COUPLINGS)
    found.locate_changes(1e-9, every=True)
    return found


@pytest.fixture(scope="module")
def chain():
    found = breather_atlas(CHAIN, "sine", [5.8], "b", [0.16, 0.2])
    found.locate_changes(1e-9)
    return found


@pytest.fixture(scope="module")
def peyrard():
    found = system_breather_atlas(takeno_peyrard(7, C=0.05), TP_OMEGAS, "C", TP_COUPLINGS)
    found.locate_changes(1e-9)
    return found


def zero_of_square_law(field: np.ndarray, measure: np.ndarray) -> float:
    """Where the line through (field, measure^2) crosses zero: a pair split as the square root of the distance."""
    slope, intercept = np.polyfit(field, measure**2, 1)
    return -intercept / slope


def test_the_mathieu_edges_are_located_along_the_coupling_at_scipys_values(mathieu):
    """Between 0.2 (stable) and 0.4 (x's tongue entered) the loss; with ``every`` also y's tongue between 0.4 and 0.6,
    both at +1, each at SciPy's edge within its accuracy, which is below 1e-9 + the secant's; none along Omega (one column)."""
    assert mathieu.grid("stable").ravel().tolist() == [1, 0, 0]
    assert mathieu.settings["locate"] == {"tol": 1e-9, "every": True, "along": ["omega", "C"], "not_one_family": []}
    located = mathieu.changes
    assert [(c.axis, c.between, c.column, c.omega) for c in located] == [("C", (0, 1), 0, OMEGA), ("C", (1, 2), 0, OMEGA)]
    for change, w in zip(located, (W0, W1), strict=True):
        assert change.placed_by == "discriminant" and change.change.kind == "+1"
        assert abs(change.value - edge_coupling(w)) <= change.accuracy < 1e-8
        assert change.change.stable_omega < change.value < change.change.unstable_omega  # the coupling's bracket
    default = system_breather_atlas(rotor_two_mathieu(), [OMEGA], "C", COUPLINGS)
    default.locate_changes(1e-9)
    assert [c.value for c in default.changes] == [located[0].value]


def test_at_the_located_coupling_the_pair_leaves_the_unit_circle_at_plus_one(mathieu):
    """The atlas's own solve at C_c -+ d (d = 1e-6 .. 4e-6): below, every multiplier on the circle and the pair near +1 at
    angles +-theta; above, the pair real, mu and 1 / mu. theta^2 and (ln mu)^2 are linear in C, and both lines' zeros are
    the located C_c to 1e-9 (the square-root law of a collision at +1, measured from the moduli and angles alone)."""
    change = mathieu.changes[0]
    start = mathieu.points[0][0].orbit
    k = np.array([1.0, 0.0, 0.0])
    steps = np.array([1e-6, 2e-6, 4e-6])
    angle, modulus = [], []
    for d in steps:
        below = sb._at(mathieu.system_at(change.value - d), k, "gamma", start.y0, start.period).nontrivial_multipliers
        above = sb._at(mathieu.system_at(change.value + d), k, "gamma", start.y0, start.period).nontrivial_multipliers
        assert np.max(np.abs(below)) - 1 < 1e-9 < 1e-5 < np.max(np.abs(above)) - 1
        angle.append(np.min(np.abs(np.angle(below))))
        modulus.append(math.log(np.max(np.abs(above))))
    assert abs(zero_of_square_law(change.value - steps, np.array(angle)) - change.value) < 1e-9
    assert abs(zero_of_square_law(change.value + steps, np.array(modulus)) - change.value) < 1e-9


def test_a_chain_geometry_change_is_a_krein_collision_where_the_scan_puts_it(chain):
    """The sine chain's change along b at Omega = 5.8: a quartet (complex), placed by the discriminant to < 1e-9. The atlas's
    own solve at b_c -+ d: below, the two colliding multipliers on the circle closer as sqrt(b_c - b); above, a quartet off
    it by ~ sqrt(b - b_c); both square laws vanish at b_c to 1e-8."""
    (change,) = chain.changes
    assert change.axis == "b" and change.omega == 5.8 and change.change.kind == "complex" and change.placed_by == "discriminant"
    assert change.accuracy < 1e-9 and 0.16 < change.value < 0.2
    start = chain.points[0][0].orbit
    solve, _ = _solvers(start, "b")
    steps = np.array([1e-6, 2e-6, 4e-6])
    split, modulus = [], []
    for d in steps:
        below = solve(_Member(start).y0, change.value - d).orbit.nontrivial_multipliers
        above = solve(_Member(start).y0, change.value + d).orbit.nontrivial_multipliers
        assert np.max(np.abs(below)) - 1 < 1e-9 < 1e-4 < np.max(np.abs(above)) - 1
        upper = below[below.imag > 0]
        split.append(np.min(np.abs(upper[:, None] - upper[None, :]) + np.eye(upper.size)))
        modulus.append(math.log(np.max(np.abs(above))))
    assert abs(zero_of_square_law(change.value - steps, np.array(split)) - change.value) < 1e-8
    assert abs(zero_of_square_law(change.value + steps, np.array(modulus)) - change.value) < 1e-8


def test_the_chain_change_is_the_one_the_omega_axis_locates_on_the_row_through_it(chain):
    """The row at the located b, across Omega = 5.81 .. 5.79: its one change along Omega lies at 5.8, within its accuracy
    plus the field's accuracy times |dOmega/db| (about 10 here; 50 allowed)."""
    (change,) = chain.changes
    row = breather_atlas(CHAIN, "sine", [5.81, 5.79], "b", [change.value])
    row.locate_changes(1e-9, along="omega")
    (across,) = row.changes
    assert across.axis == "omega" and across.change.kind == "complex"
    assert abs(across.omega - 5.8) <= across.accuracy + 50 * change.accuracy


def test_takeno_peyrard_loses_stability_along_its_coupling_at_its_bands_top_there(peyrard):
    """Along C at Omega = 1.15 the loss at +1 (the family's energy extremum, above the band's top): the resonance named is
    the first harmonic at the top of the band at the located C, sqrt(1 + 4 C_c), not at the grid's; along Omega at C = 0.07
    the same curve's other side. The row through C_c locates it at Omega = 1.15 again, within the two accuracies."""
    along_omega, along_c = peyrard.changes
    assert (along_omega.axis, along_omega.value, along_omega.between) == ("omega", 0.07, (0, 1))
    assert (along_c.axis, along_c.omega, along_c.between, along_c.column) == ("C", 1.15, (0, 1), 1)
    assert along_c.change.kind == "+1" and along_c.placed_by == "discriminant" and along_c.accuracy < 1e-8
    assert 0.05 < along_c.value < 0.07
    resonance = along_c.change.resonance
    assert (resonance.harmonic, resonance.edge) == (1.0, "top")
    assert resonance.omega == pytest.approx(math.sqrt(1 + 4 * along_c.value), rel=1e-12)
    row = system_breather_atlas(takeno_peyrard(7, C=0.05), [1.16, 1.14], "C", [along_c.value])
    row.locate_changes(1e-9, along="omega")
    (across,) = row.changes
    # dOmega/dC along the curve is about 2 here (the curve's two points above): 10 allowed.
    assert across.change.kind == "+1" and abs(across.omega - 1.15) <= across.accuracy + 10 * along_c.accuracy


def test_neighbours_of_two_families_are_not_located_between(peyrard):
    """A row holding the two-site (out-of-phase) breather instead of the one-site one: the atlas's continuation does not
    join them and Newton from the one-site orbit at the other value lands on the one-site family, so the pair is left
    unlocated and listed; along Omega nothing changes."""
    two = system_breather_atlas(takeno_peyrard(7, C=0.05), TP_OMEGAS[:1], "C", [0.07], partner=4, counter=True)
    assert two.points[0][0].source == "anti_continuum" and not two.points[0][0].orbit.stable
    mixed = SystemBreatherAtlas(
        peyrard.system, "C", np.array(TP_COUPLINGS), np.array(TP_OMEGAS[:1]), [[peyrard.points[0][0]], [two.points[0][0]]],
        peyrard.rotors, {"unfold": "gamma"},
    )  # fmt: skip
    assert traced_families(mixed.points).tolist() == [[0], [1]]
    mixed.locate_changes(1e-6)
    assert mixed.changes == [] and mixed.settings["locate"]["not_one_family"] == [{"axis": "C", "row": 0, "column": 0}]


def test_traced_families_follow_the_sources():
    """Labels shared along continuations (omega: from the left, field: from below), split by a fresh start or a gap."""

    class Point:
        def __init__(self, source):
            self.source, self.orbit = source, None if source == "none" else object()

    grid = [["anti_continuum", "omega", "omega"], ["field", "anti_continuum", "omega"], ["anti_continuum", "none", "field"]]
    labels = traced_families([[Point(s) for s in row] for row in grid])
    assert labels[0, 0] == labels[0, 2] == labels[1, 0] and labels[1, 1] == labels[1, 2] == labels[2, 2]
    assert labels[1, 1] != labels[0, 0] and labels[2, 0] not in (labels[0, 0], labels[1, 1]) and labels[2, 1] == -1


def test_the_dataset_json_and_map_carry_the_field_changes(chain, tmp_path):
    from cosserat_chain.io import netcdf_image

    path = tmp_path / "atlas.nc"
    path.write_bytes(netcdf_image(chain.to_dataset()))
    (change,) = chain.changes
    with xr.open_dataset(path) as ds:
        assert ds["change_axis"].attrs["flag_meanings"].split()[int(ds["change_axis"][0])] == "b"
        assert float(ds["change_value"][0]) == change.value and float(ds["change_omega"][0]) == 5.8
        assert float(ds["change_value_accuracy"][0]) == change.accuracy and np.isnan(ds["change_accuracy"][0])
        assert float(ds["change_stable_value"][0]) == change.change.stable_omega and np.isnan(ds["change_stable_omega"][0])
        assert int(ds["change_between"][0]) == 0 and int(ds["change_at"][0]) == 0
        assert ds["change_value_accuracy"].attrs["units"] == ds["change_value"].attrs["units"] != ds["change_accuracy"].attrs["units"]
    (record,) = chain.as_dict()["stability_changes"]
    assert record["axis"] == "b" and record["omega"] == 5.8 and record["value"] == change.value
    assert record["accuracy"] == change.accuracy and record["stable_value"] < record["value"] < record["unstable_value"]
    assert not any("omega" in key for key in record if key != "omega")
    import matplotlib

    matplotlib.use("Agg")
    from cosserat_chain.plots.breathers import breather_atlas_figure

    ax = breather_atlas_figure(chain).axes[0]
    handles, labels = ax.get_legend_handles_labels()
    marks = handles[labels.index("stability changes along b (located)")].lines[0]
    assert marks.get_xdata().tolist() == [5.8] and marks.get_ydata().tolist() == [change.value]
    assert "stability changes (located)" not in labels


def test_check_along_names_the_axes():
    assert check_along(None, "b") == ("omega", "b") and check_along(["b", "omega"], "b") == ("omega", "b")
    assert check_along("b", "b") == ("b",)
    for bad in ("a", [], ["omega", "C"]):
        with pytest.raises(ValueError, match=r"along must name one or both of the atlas's axes omega, b"):
            check_along(bad, "b")


def test_the_system_cli_locates_along_the_coupling_into_json_and_netcdf(tmp_path):
    out = tmp_path / "atlas.nc"
    args = ["breathers", "--system", REFERENCE, "--omega", str(OMEGA), "--atlas", "C=0.2,0.4,0.6", "--locate-tol", "1e-9"]
    result = runner.invoke(app, [*args, "--locate-along", "C", "--locate-every", "--json", "--out", str(out)])
    assert result.exit_code == 0, result.output
    changes = json.loads(result.stdout)["stability_changes"]
    assert [c["axis"] for c in changes] == ["C", "C"]
    for located, w in zip(changes, (W0, W1), strict=True):
        assert located["omega"] == OMEGA and abs(located["value"] - edge_coupling(w)) <= located["accuracy"] < 1e-8
    with xr.open_dataset(out) as ds:
        assert ds["change_value"].values.tolist() == [c["value"] for c in changes]
        assert ds["change_value_accuracy"].values.tolist() == [c["accuracy"] for c in changes]
        assert json.loads(ds.attrs["settings_json"])["locate"]["along"] == ["C"]
    text = runner.invoke(app, args)
    assert text.exit_code == 0 and "located along omega and C" in text.output and "Omega = 0.97: C = 0.37995359" in text.output
    omega_only = runner.invoke(app, [*args, "--locate-along", "omega", "--json"])
    assert omega_only.exit_code == 0 and json.loads(omega_only.stdout)["stability_changes"] == []


def test_the_chain_cli_locates_along_b(tmp_path):
    config = tmp_path / "chain.toml"
    config.write_text("N = 2\n")
    args = ["breathers", "--model", "sine", "--omega", "5.8", "--atlas", "b=0.16,0.2", "--config", str(config), "--json"]
    result = runner.invoke(app, [*args, "--locate-along", "omega,b"])
    assert result.exit_code == 0, result.output
    (record,) = json.loads(result.stdout)["stability_changes"]
    assert record["axis"] == "b" and record["kind"] == "complex" and 0.19 < record["value"] < 0.1902
    assert record["accuracy"] <= 1e-6


@pytest.mark.parametrize(
    ("extra", "message"),
    [
        (["--locate-along", "E1"], "--locate-along must name omega, b or both as omega,b"),
        (["--locate-along", ""], "--locate-along must name omega, b"),
        (["--locate-along", "omega,b,h"], "--locate-along must name omega, b"),
        (["--locate-along", "b", "--no-locate"], "leave out --no-locate"),
    ],
)
def test_bad_locate_along_exits_2_naming_the_option(extra, message):
    result = runner.invoke(app, ["breathers", "--model", "sine", "--omega", "6", "--atlas", "b=0.2", *extra])
    assert result.exit_code == 2 and message in result.output, result.output


def test_locate_along_without_an_atlas_or_on_a_system_names_what_is_wrong():
    alone = runner.invoke(app, ["breathers", "--omega", "6", "--locate-along", "omega"])
    assert alone.exit_code == 2 and "--locate-along" in alone.output and "--atlas" in alone.output
    system = runner.invoke(app, ["breathers", "--system", "takeno_peyrard", "--set", "sites=3", "--omega", "1.3", "--atlas", "C=0.05",
                                 "--locate-along", "b"])  # fmt: skip
    assert system.exit_code == 2 and "--locate-along must name omega, C or both as omega,C" in system.output


@pytest.mark.slow
def test_every_chain_geometry_change_is_where_the_row_through_it_locates_it():
    """The sine chain, N = 2, over Omega 6.2 .. 4.8 and b = 0.16, 0.2, 0.24: each change along b placed by the discriminant
    is found again along Omega on the row at its b (Omega +- 0.01 about its column), of its kind, at its column's Omega
    within the row's accuracy plus 50 times its own."""
    found = breather_atlas(CHAIN, "sine", [6.2, 6.0, 5.8, 5.2, 5.0, 4.8], "b", [0.16, 0.2, 0.24])
    found.locate_changes()
    along_b = [c for c in found.changes if c.axis == "b" and c.placed_by == "discriminant"]
    assert len(along_b) >= 4 and found.settings["locate"]["not_one_family"] == []
    for change in along_b:
        row = breather_atlas(CHAIN, "sine", [change.omega + 0.01, change.omega - 0.01], "b", [change.value])
        row.locate_changes(along="omega")
        across = min(row.changes, key=lambda c: abs(c.omega - change.omega))
        assert across.change.kind == change.change.kind
        assert abs(across.omega - change.omega) <= across.accuracy + 50 * change.accuracy
