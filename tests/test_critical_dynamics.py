"""``critical`` reports the damped dynamics' verdict beside K's inertia, and the Hopf points of its branch (issue 45, item 4).

Each check fails on a ``critical`` that reports only K's inertia: the JSON's Hopf points are
those :func:`~cosserat_chain.numerics.hopf.hopf_points` finds on the same branch (the sine
model's unstable branch at N = 2 has four, where K keeps one negative eigenvalue), the verdict
of the branch from rest up to M_c is checked against the eigenvalues themselves, and a file from
``critical --out`` carries the new variables with CF attributes.
"""

from __future__ import annotations

import json

import numpy as np
import pytest
from typer.testing import CliRunner

from cosserat_chain import ChainParams
from cosserat_chain.cli import app
from cosserat_chain.experiments.critical import critical_point
from cosserat_chain.io import read_dataset
from cosserat_chain.numerics.hopf import hopf_points
from cosserat_chain.numerics.stability import DENSE_LIMIT, dynamic_stability
from cosserat_chain.state import n_free

runner = CliRunner()

#: The sine model's Hopf points at N = 2 (paper's geometry) on the first half turn: phi_0 and M.
HOPF_PHI0 = (1.6575078517, 2.4380368034)
HOPF_MOMENT = (0.2894347825, 0.1879511404)


@pytest.fixture(scope="module")
def n2_config(tmp_path_factory):
    path = tmp_path_factory.mktemp("critical_dynamics") / "n2.toml"
    path.write_text("N = 2\n")
    return path


@pytest.fixture(scope="module")
def cli_run(n2_config, tmp_path_factory):
    out = tmp_path_factory.mktemp("critical_dynamics_out") / "critical.nc"
    result = runner.invoke(app, ["critical", "--model", "all", "--config", str(n2_config), "--json", "--out", str(out)])
    assert result.exit_code == 0, result.output
    return json.loads(result.stdout)["models"], out


def test_sine_json_lists_the_hopf_points_the_stability_module_finds(cli_run):
    sine = cli_run[0]["sine"]
    params = ChainParams(N=2)
    direct = hopf_points(params, "sine", critical_point(params, "sine").branch)
    assert sine["dynamics"]["verdict_from"] == "eigenvalues"
    assert sine["dynamics"]["hopf_search"] == "searched"
    listed = sine["hopf_points"]
    assert len(listed) == len(direct) == 4
    for got, want in zip(listed, direct, strict=True):
        assert got["phi0"] == pytest.approx(want.phi0, abs=1e-10)
        assert got["moment"] == pytest.approx(want.moment, abs=1e-10)
        assert got["frequency"] == pytest.approx(want.frequency, rel=1e-8)
        assert got["located"] is True
        # K's inertia is one negative eigenvalue on both sides; the dynamics gain or lose a complex pair.
        assert got["stiffness_index"] == 1 and abs(got["unstable_after"] - got["unstable_before"]) == 2
    np.testing.assert_allclose([h["phi0"] for h in listed[:2]], HOPF_PHI0, atol=1e-9)
    np.testing.assert_allclose([h["moment"] for h in listed[:2]], HOPF_MOMENT, atol=1e-9)
    # The mirror pair at 2 pi - phi_0, M -> -M.
    np.testing.assert_allclose([h["phi0"] for h in listed[2:]], [2 * np.pi - p for p in HOPF_PHI0[::-1]], atol=1e-9)
    np.testing.assert_allclose([h["moment"] for h in listed[2:]], [-m for m in HOPF_MOMENT[::-1]], atol=1e-9)


def test_sine_branch_from_rest_to_m_c_is_dynamically_stable_and_the_unstable_branch_is_told_apart(cli_run):
    sine = cli_run[0]["sine"]
    assert sine["dynamics"]["stable_from_rest_to_onset"] is True
    branch = sine["branch"]
    phi0 = np.array(branch["phi0"])
    rest = phi0 < sine["phi0_at_onset"]
    assert rest.sum() > 5
    assert all(np.array(branch["dynamically_stable"])[rest]) and all(np.array(branch["unstable_eigenvalues"])[rest] == 0)
    # Between the Hopf points K has one negative eigenvalue and the dynamics three unstable eigenvalues.
    between = (phi0 > HOPF_PHI0[0] + 0.05) & (phi0 < HOPF_PHI0[1] - 0.05)
    assert between.any()
    assert set(np.array(branch["stiffness_index"])[between]) == {1}
    assert set(np.array(branch["unstable_eigenvalues"])[between]) == {3}
    assert set(np.array(branch["unstable_pairs"])[between]) == {1}
    # The old keys stay, and say what they count.
    assert "stiffness index" in sine["index_meaning"]
    assert [f["index_before"] for f in sine["folds"]] == [0, 1]


def test_conservative_models_report_the_verdict_as_k_inertia_by_the_theorem(cli_run, n2_config):
    models = cli_run[0]
    params = ChainParams(N=2)
    for name in ("nonlinear", "linear"):
        d = models[name]["dynamics"]
        assert d["verdict_from"] == "stiffness index" and "K's inertia" in d["note"] and "theorem" in d["note"]
        assert d["stable_from_rest_to_onset"] is True and models[name]["hopf_points"] == []
        assert models[name]["branch"]["unstable_eigenvalues"] is None  # not recomputed
    # The theorem, checked where the nonlinear branch is unstable: the unstable eigenvalues are K's negative ones.
    branch = critical_point(params, "nonlinear").branch
    for x in branch.x[:: max(1, len(branch.x) // 12)]:
        check = dynamic_stability(params, "nonlinear", x, method="dense")
        assert check.unstable_eigenvalues == check.stiffness_index and check.unstable_pairs == 0
    text = runner.invoke(app, ["critical", "--model", "nonlinear", "--config", str(n2_config)])
    assert text.exit_code == 0, text.output
    assert "verdict from stiffness index: the dynamic verdict is K's inertia" in text.stdout
    sine = runner.invoke(app, ["critical", "--model", "sine", "--config", str(n2_config)])
    assert "branch from rest up to M_c: dynamically stable (verdict from eigenvalues" in sine.stdout
    assert "Hopf points of the traced branch: 4: M = 0.2894347825 at phi_0 = 1.657507852 rad" in sine.stdout
    assert "unstable eigenvalues 1 -> 3 (stiffness index 1)" in sine.stdout


def test_critical_file_carries_the_dynamics_with_cf_attributes(cli_run):
    models, out = cli_run
    ds = read_dataset(out)
    names = list(ds.model.values)
    sine = ds.sel(model="sine")
    hopf = np.array(sine["hopf_phi0"].values)
    np.testing.assert_allclose(hopf[np.isfinite(hopf)], [h["phi0"] for h in models["sine"]["hopf_points"]], atol=1e-12)
    np.testing.assert_allclose(sine["hopf_moment"].values[:2], HOPF_MOMENT, atol=1e-9)
    assert ds["hopf_phi0"].attrs["units"] == "rad" and "Hopf point" in ds["hopf_phi0"].attrs["long_name"]
    assert ds["hopf_moment"].attrs["units"] == "1" and "energy" in ds["hopf_moment"].attrs["scale"]
    assert ds["hopf_frequency"].attrs["units"] == "rad" and "time" in ds["hopf_frequency"].attrs["scale"]
    for name in ("dynamically_stable", "unstable_eigenvalues", "unstable_pairs", "stiffness_index", "hopf_located"):
        assert ds[name].attrs["units"] == "1" and ds[name].attrs["long_name"], name
    assert "stiffness index" in ds["stiffness_index"].attrs["long_name"]
    assert "damped dynamics" in ds["unstable_eigenvalues"].attrs["long_name"]
    k = len(models["sine"]["branch"]["moment"])
    np.testing.assert_array_equal(sine["unstable_eigenvalues"].values[:k], models["sine"]["branch"]["unstable_eigenvalues"])
    nonlinear = ds.sel(model="nonlinear")
    k = len(models["nonlinear"]["branch"]["moment"])
    # The theorem's verdict is K's inertia: equal to stable; the eigenvalues were not counted (-1).
    np.testing.assert_array_equal(nonlinear["dynamically_stable"].values[:k], nonlinear["stable"].values[:k])
    assert set(nonlinear["unstable_eigenvalues"].values[:k]) == {-1}
    assert names == ["nonlinear", "sine", "linear"]


def test_sine_beyond_the_dense_limit_takes_the_theorem_and_does_not_search(tmp_path):
    params = ChainParams(N=40)
    assert 2 * n_free(params) > DENSE_LIMIT
    r = critical_point(params, "sine")
    d = r.as_dict()
    assert d["dynamics"]["verdict_from"] == "eq. (2) theorem" and d["dynamics"]["hopf_search"] == "not searched"
    assert d["hopf_points"] is None and d["dynamics"]["stable_from_rest_to_onset"] is True
    # The theorem against the damped dynamics' own eigenvalues (sparse) on the branch from rest, up to just before M_c.
    rest = r.rest_segment
    for i in (rest // 2, rest - 1):
        check = dynamic_stability(params, "sine", r.branch.x[i], method="sparse")
        assert check.stable and check.unstable_eigenvalues == 0, (i, check.describe())
    ds = r.to_dataset()
    assert ds.attrs["hopf_search"] == "not searched" and ds.sizes["hopf"] == 0
    assert set(ds["dynamically_stable"].values[:rest]) == {1} and set(ds["dynamically_stable"].values[rest:]) <= {-1}


def test_dynamics_false_skips_only_what_costs():
    params = ChainParams(N=2)
    sine = critical_point(params, "sine", dynamics=False)
    assert sine.dynamics_from == "not computed" and sine.hopf is None and sine.dynamically_stable_to_onset is None
    assert sine.as_dict()["dynamics"]["hopf_search"] == "not searched"
    assert set(sine.to_dataset()["dynamically_stable"].values) == {-1}
    # The folds are those of the full result; a conservative model keeps its verdict by the theorem.
    assert sine.critical_moment == critical_point(params, "sine").critical_moment
    assert critical_point(params, "nonlinear", dynamics=False).dynamics_from == "stiffness index"


def test_the_eq2_theorem_rests_on_k_sine_equal_to_k_linear_times_diag_cos_phi():
    """K = K_lin diag(1, 1, cos phi) at any state: the identity the "eq. (2) theorem" verdict uses."""
    from cosserat_chain.models.base import get_model
    from cosserat_chain.state import pack, unpack

    params = ChainParams(N=3)
    rng = np.random.default_rng(45)
    x = unpack(params, rng.normal(size=pack(params, np.zeros((3, params.n_particles))).size))
    sine = get_model("sine").stiffness(params, x).toarray()
    linear = get_model("linear").stiffness(params, x).toarray()
    ones = np.ones(params.n_particles)
    scale = pack(params, np.vstack([ones, ones, np.cos(x[2])]))
    np.testing.assert_allclose(sine, linear * scale[None, :], atol=1e-13 * np.abs(sine).max())
