"""Changes of stability located in the roto-breather atlases, and two pairs crossing between the same two members (issue 41).

The case with known answers: a rotor and two Mathieu oscillators on one site,

    E = phi'^2 / 2 + x'^2 / 2 + y'^2 / 2 + (w0^2 + C cos phi) x^2 / 2 + (w1^2 + C cos phi) y^2 / 2.

x = y = 0 is invariant and on it phi = Omega t exactly; x and y decouple, each obeying Mathieu's equation
(test_breather_pitchfork): each has an instability tongue at +1 near Omega = w, between the Omegas where
4 w^2 / Omega^2 = a_2(2 C / Omega^2) and b_2(2 C / Omega^2), which SciPy gives to round-off. With w0 = 1, w1 = 1.01
and C = 0.3 the tongues overlap: [0.98127, 1.00371] and [0.99182, 1.01360]. A member in the overlap has two real
pairs off the circle at +1; a member above both tongues has none: the parity of the pairs through +1 (pair_test) is
the same at both, so two crossings between them cancel there, and a stable/unstable flag sees one change, not two.
"""

from __future__ import annotations

import functools
import json

import numpy as np
import pytest
import xarray as xr
from scipy.optimize import brentq
from scipy.special import mathieu_a, mathieu_b
from typer.testing import CliRunner

from conftest import SYSTEMS_CACHE
from cosserat_chain.cli import app
from cosserat_chain.experiments import system_breathers as sb
from cosserat_chain.experiments.breather_atlas import AtlasChange, check_locate_tol
from cosserat_chain.experiments.system_breather_atlas import system_breather_atlas
from cosserat_chain.numerics.breather_arclength import collisions_between, instability_counts, pair_test
from mathieu_rotor_system import REFERENCE, rotor_two_mathieu

runner = CliRunner()
C, W0, W1 = 0.3, 1.0, 1.01
#: Above both tongues, in their overlap, below both.
OMEGAS = [1.03, 0.998, 0.96]


@pytest.fixture(autouse=True)
def _cache(monkeypatch):
    """The compiled systems go to the tests' cache folder (compiled once, not every session), not the user's."""
    monkeypatch.setenv("COSSERAT_CHAIN_CACHE", str(SYSTEMS_CACHE))


def edge(w: float, characteristic) -> float:
    """The Omega near w with 4 w^2 / Omega^2 = a_2(2 C / Omega^2) (or b_2)."""
    return brentq(lambda o: 4 * w**2 / o**2 - characteristic(2, 2 * C / o**2), 0.95 * w, 1.05 * w, xtol=1e-15)


#: The four edges in the order the atlas meets them going down in Omega: y's and x's upper edges, then their lower ones.
EDGES = [edge(W1, mathieu_b), edge(W0, mathieu_b), edge(W1, mathieu_a), edge(W0, mathieu_a)]


@pytest.fixture(scope="module")
def atlas():
    found = system_breather_atlas(rotor_two_mathieu(), OMEGAS, "C", [C])
    found.locate_changes(1e-9)
    return found


def test_the_edges_overlap_as_the_case_needs():
    upper_y, upper_x, lower_y, lower_x = EDGES
    assert OMEGAS[2] < lower_x < lower_y < OMEGAS[1] < upper_x < upper_y < OMEGAS[0]


def test_instability_counts_count_pairs_and_quartets():
    """One member of a real pair lies outside the circle, two of a quartet; a pair on the circle is not counted; the pair just
    off +1 whose imaginary part is the eigenvalue solver's round-off counts as real."""
    on = np.exp(1j * np.array([0.4, -0.4]))
    real_plus = np.array([1.3, 1 / 1.3])
    real_minus = np.array([-2.0, -0.5])
    quartet = 1.1 * np.exp(1j * np.array([2.0, -2.0]))
    quartet = np.concatenate([quartet, 1 / quartet])
    assert instability_counts(on) == (0, 0, 0)
    assert instability_counts(np.concatenate([on, real_plus, real_plus, real_minus, quartet])) == (2, 1, 1)
    assert instability_counts(np.array([1 + 1e-4 + 1e-12j, 1 / (1 + 1e-4) - 1e-12j])) == (1, 0, 0)
    assert collisions_between((0, 0, 0), (2, 1, 1)) == 4 and collisions_between((1, 0, 0), (1, 0, 0)) == 0


def test_two_pairs_through_plus_one_cancel_in_the_old_tests_and_are_counted_in_the_new(atlas):
    above, overlap, below = (p.orbit for p in atlas.points[0])
    assert above.stable and below.stable and not overlap.stable
    assert sb._counts(above) == sb._counts(below) == (0, 0, 0) and sb._counts(overlap) == (2, 0, 0)

    class Plain:  # the orbit's multipliers as pair_test reads a chain's orbit
        def __init__(self, orbit):
            self.multipliers = orbit.nontrivial_multipliers

    # The parity of the pairs through +1 is the same at both members, and the flags differ once: one change where there are two.
    assert pair_test(Plain(above)) == pair_test(Plain(overlap))
    assert collisions_between(sb._counts(above), sb._counts(overlap)) == 2


def test_the_atlas_locates_all_four_edges_at_the_mathieu_values(atlas):
    """Between each pair of neighbours two changes (the second inside an unstable stretch), each at SciPy's edge
    within its accuracy, kind +1, by the discriminant."""
    changes = atlas.changes
    assert [c.between for c in changes] == [(0, 1), (0, 1), (1, 2), (1, 2)]
    for located, exact in zip(changes, EDGES, strict=True):
        assert isinstance(located, AtlasChange) and located.placed_by == "discriminant"
        assert located.change.kind == "+1" and located.value == C
        assert abs(located.change.omega - exact) <= located.accuracy < 1e-8
    assert atlas.settings["locate"] == {"tol": 1e-9, "every": False, "along": ["omega", "C"], "not_one_family": []}


def test_the_atlas_changes_are_the_familys(atlas):
    """The family from 1.03 down to 0.96 (the kit's driver, its members far finer than the atlas's) locates the same four
    changes: each within the sum of the two accuracies of the atlas's."""
    family = sb.roto_breather_family(rotor_two_mathieu(), OMEGAS[0], to=OMEGAS[-1])
    assert len(family.changes) == 4
    for ours, theirs in zip(atlas.changes, family.changes, strict=True):
        assert ours.change.kind == theirs.kind
        assert abs(ours.change.omega - theirs.omega) <= ours.accuracy + theirs.accuracy


def test_a_looser_tolerance_costs_fewer_solves_and_reports_an_accuracy_that_holds():
    """At 1e-4 the bisection and the secant stop sooner; the accuracy reported grows with the secant's last step, and the
    edges still lie within it."""
    found = system_breather_atlas(rotor_two_mathieu(), OMEGAS, "C", [C])
    found.locate_changes(1e-4)
    assert len(found.changes) == 4
    for located, exact in zip(found.changes, EDGES, strict=True):
        assert abs(located.change.omega - exact) <= located.accuracy <= 1e-4 + 1e-8


def test_the_dataset_and_the_json_carry_the_changes(atlas, tmp_path):
    path = tmp_path / "atlas.nc"
    atlas.to_dataset("rotor_two_mathieu").to_netcdf(path)
    with xr.open_dataset(path) as ds:
        assert ds.sizes["change"] == 4
        for j, located in enumerate(atlas.changes):
            assert float(ds["change_omega"][j]) == located.change.omega
            assert float(ds["change_accuracy"][j]) == located.accuracy
            assert float(ds["change_value"][j]) == C and int(ds["change_between"][j]) == located.between[0]
        assert ds["change_kind"].attrs["flag_meanings"].split()[int(ds["change_kind"][0])] == "plus_one"
        assert ds["change_placed_by"].attrs["flag_meanings"].split()[int(ds["change_placed_by"][0])] == "discriminant"
        for name in ds.data_vars:
            if str(name).startswith("change_"):
                assert ds[name].attrs["units"] and ds[name].attrs["long_name"]
        assert json.loads(ds.attrs["settings_json"])["locate"] == {
            "tol": 1e-9,
            "every": False,
            "along": ["omega", "C"],
            "not_one_family": [],
        }
    summary = atlas.as_dict()["stability_changes"]
    assert [c["omega"] for c in summary] == [c.change.omega for c in atlas.changes]
    assert all(c["placed_by"] == "discriminant" and c["kind"] == "+1" for c in summary)


def test_the_cli_json_and_plot_carry_the_located_changes(tmp_path):
    args = ["breathers", "--system", REFERENCE, "--omega", "1.03", "--to", "0.96", "--steps", "3", "--atlas", "C=0.3"]
    # np.linspace(1.03, 0.96, 3) puts the middle member at 0.995, in the overlap too.
    result = runner.invoke(app, [*args, "--json", "--locate-tol", "1e-9", "--plot", str(tmp_path / "map.png")])
    assert result.exit_code == 0, result.output
    changes = json.loads(result.stdout)["stability_changes"]
    assert len(changes) == 4
    for located, exact in zip(changes, EDGES, strict=True):
        assert abs(located["omega"] - exact) <= located["accuracy"]
    assert (tmp_path / "map.png").stat().st_size > 0
    off = runner.invoke(app, [*args, "--json", "--no-locate"])
    assert off.exit_code == 0 and json.loads(off.stdout)["stability_changes"] is None


@pytest.mark.parametrize("tol", ["0", "-1e-6", "0.5", "nan"])
def test_a_bad_tolerance_exits_2_naming_the_option(tol):
    result = runner.invoke(app, ["breathers", "--system", "takeno_peyrard", "--set", "sites=3", "--omega", "1.3", "--atlas", "C=0.05",
                                 "--locate-tol", tol])  # fmt: skip
    assert result.exit_code == 2 and "--locate-tol" in result.output, result.output


@pytest.mark.parametrize("extra", [["--locate-tol", "1e-6"], ["--locate-every"]])
def test_locate_options_without_an_atlas_exit_2(extra):
    result = runner.invoke(app, ["breathers", "--omega", "6", *extra])
    assert result.exit_code == 2 and extra[0] in result.output and "--atlas" in result.output


def test_locate_every_with_no_locate_exits_2():
    result = runner.invoke(app, ["breathers", "--omega", "6", "--atlas", "b=0.2", "--no-locate", "--locate-every"])
    assert result.exit_code == 2 and "--no-locate" in result.output


@pytest.mark.slow
def test_every_locates_the_pairs_leaving_an_unstable_stretch_too():
    """The sine chain, N = 6, at Omega = 6.6, 6.4, 6.2, 6.0: stable, stable, unstable, unstable. By default only the loss
    between 6.4 and 6.2 is located; with ``every`` also the quartet that leaves between 6.2 and 6.0 (two quartets at
    N = 10, the same path), as the family's located changes over the same members (each within the two accuracies)."""
    from cosserat_chain import ChainParams
    from cosserat_chain.experiments.breather_atlas import breather_atlas
    from cosserat_chain.experiments.breathers import located_changes

    chain = ChainParams(N=6, gamma_u=0.0, gamma_v=0.0, gamma_phi=0.0)
    found = breather_atlas(chain, "sine", [6.6, 6.4, 6.2, 6.0], "b", [chain.b])
    assert found.grid("stable").tolist() == [[1, 1, 0, 0]]
    found.locate_changes()
    (loss,) = found.changes
    assert loss.between == (1, 2) and loss.change.kind == "complex"
    found.locate_changes(every=True)
    assert [c.between for c in found.changes] == [(1, 2), (2, 3)]
    assert found.settings["locate"] == {"tol": 1e-6, "every": True, "along": ["omega", "b"], "not_one_family": []}
    family = located_changes([p.orbit for p in found.points[0]], found.bands)
    assert len(family) == 2
    for ours, theirs in zip(found.changes, family, strict=True):
        assert ours.change.kind == theirs.kind == "complex"
        assert abs(ours.change.omega - theirs.omega) <= ours.accuracy + theirs.accuracy


def test_check_locate_tol_names_the_field():
    for bad in (0.0, -1.0, float("nan"), 0.02, True, "1e-6"):
        with pytest.raises(ValueError, match="locate_tol must be an accuracy in Omega"):
            check_locate_tol(bad)
    assert check_locate_tol(1e-6) == 1e-6


def test_a_looser_tolerance_solves_fewer_orbits(monkeypatch):
    """The bisection and the secant stop sooner at 1e-4 than at 1e-9: fewer orbits solved between the same members."""
    from cosserat_chain.experiments import system_breather_atlas as module

    found = system_breather_atlas(rotor_two_mathieu(), OMEGAS, "C", [C])
    calls = []

    def counted(*args):
        calls.append(args[-1])
        return sb._at(*args)

    monkeypatch.setattr(module, "_at", counted)
    solves = {}
    for tol in (1e-9, 1e-4):
        calls.clear()
        found.locate_changes(tol)
        solves[tol] = len(calls)
    assert solves[1e-4] < solves[1e-9]


@functools.cache
def chain_family():
    """The sine chain's (N = 2, undamped) family over Omega = 6.2 ... 4.8 with its changes located: the independent
    reference of the chain's atlas and of its command, computed once."""
    from cosserat_chain import ChainParams
    from cosserat_chain.experiments.breathers import roto_breather_family

    return roto_breather_family(ChainParams(N=2, gamma_u=0.0, gamma_v=0.0, gamma_phi=0.0), "sine", [6.2, 6.0, 5.8, 5.2, 5.0, 4.8])


def test_the_chains_atlas_locates_the_chains_family_changes():
    """The sine chain with N = 2 (test_breather_chain_changes): its atlas over the family's frequencies, at the
    chain's own b, locates at the default tolerance the family's three changes (two Krein collisions, one at +1),
    each within the sum of the two accuracies, and its NetCDF carries them."""
    from cosserat_chain import ChainParams
    from cosserat_chain.experiments.breather_atlas import LOCATE_TOL, breather_atlas

    chain = ChainParams(N=2, gamma_u=0.0, gamma_v=0.0, gamma_phi=0.0)
    omegas = [6.2, 6.0, 5.8, 5.2, 5.0, 4.8]
    family = chain_family()
    found = breather_atlas(chain, "sine", omegas, "b", [chain.b])
    found.locate_changes()
    assert [c.change.kind for c in found.changes] == [c.kind for c in family.changes] == ["complex", "complex", "+1"]
    for ours, theirs in zip(found.changes, family.changes, strict=True):
        assert ours.placed_by == "discriminant" and ours.accuracy <= LOCATE_TOL + 1e-9
        assert abs(ours.change.omega - theirs.omega) <= ours.accuracy + theirs.accuracy
    ds = found.to_dataset()
    assert ds["change_omega"].values.tolist() == [c.change.omega for c in found.changes]
    assert ds["change_omega"].attrs["units"] == "rad s-1"
    # The map marks each change on its row.
    import matplotlib

    matplotlib.use("Agg")
    from cosserat_chain.plots.breathers import breather_atlas_figure

    ax = breather_atlas_figure(found).axes[0]
    handles, labels = ax.get_legend_handles_labels()
    marks = handles[labels.index("stability changes (located)")].lines[0]
    assert marks.get_xdata().tolist() == [c.change.omega for c in found.changes]
    assert marks.get_ydata().tolist() == [chain.b] * 3


def test_the_chain_cli_json_and_netcdf_carry_the_located_changes(tmp_path):
    """``breathers --atlas`` of the chain (sine, N = 2, Omega 6.2 down to 4.8 in 8 steps): --json lists the three changes the
    family locates between the same frequencies (on its own six members), within the two accuracies, and --out carries
    the same numbers."""
    config = tmp_path / "chain.toml"
    config.write_text("N = 2\n")
    out = tmp_path / "atlas.nc"
    args = ["breathers", "--model", "sine", "--omega", "6.2", "--to", "4.8", "--steps", "8", "--atlas", "b=0.2", "--config", str(config)]
    result = runner.invoke(app, [*args, "--json", "--out", str(out)])
    assert result.exit_code == 0, result.output
    changes = json.loads(result.stdout)["stability_changes"]
    family = chain_family()
    assert [c["kind"] for c in changes] == [c.kind for c in family.changes] == ["complex", "complex", "+1"]
    for ours, theirs in zip(changes, family.changes, strict=True):
        assert abs(ours["omega"] - theirs.omega) <= ours["accuracy"] + theirs.accuracy
    with xr.open_dataset(out) as ds:
        assert ds["change_omega"].values.tolist() == [c["omega"] for c in changes]
        assert ds["change_accuracy"].values.tolist() == [c["accuracy"] for c in changes]
        assert ds["change_accuracy"].attrs["units"] == "rad s-1"


@pytest.mark.slow
def test_a_krein_collision_on_a_dense_circle_is_located_where_the_quartet_leaves():
    """The sine chain, N = 25, between Omega = 6.4 and 6.2: a quartet leaves the circle between 6.3640402 (off it by 1.5e-5
    in modulus, solved at rtol 1e-13) and 6.3640407 (on it to 1e-12). The atlas's first located change lies there, and
    is the family's within the two accuracies (a bisection cut short on the circle's many multipliers picked another
    pair, whose discriminant's zero lay 5e-7 away)."""
    from cosserat_chain import ChainParams
    from cosserat_chain.experiments.breather_atlas import breather_atlas
    from cosserat_chain.experiments.breathers import located_changes

    chain = ChainParams(N=25, gamma_u=0.0, gamma_v=0.0, gamma_phi=0.0)
    found = breather_atlas(chain, "sine", [6.6, 6.4, 6.2], "b", [chain.b])
    found.locate_changes()
    first = found.changes[0]
    assert first.change.kind == "complex" and 6.3640402 < first.change.omega < 6.3640407
    (theirs, *_) = located_changes([p.orbit for p in found.points[0][1:]], found.bands)
    assert abs(first.change.omega - theirs.omega) <= first.accuracy + theirs.accuracy
