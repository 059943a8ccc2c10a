"""Parameter studies on a real Dask LocalCluster: cells equal the single-run API, chunks equal single cells, resume, failures, bad specs."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from typer.testing import CliRunner

from cosserat_chain import ChainParams
from cosserat_chain.analysis.dispersion import wave_summary
from cosserat_chain.cli import app
from cosserat_chain.experiments.study import cell_time_step, spec_from_mapping
from cosserat_chain.experiments.sweep import relaxation_sweep
from cosserat_chain.io import read_dataset, write_dataset
from cosserat_chain.loads import Loads, PointLoad, Schedule
from cosserat_chain.numerics.continuation import compliance, locate_fold
from cosserat_chain.numerics.relaxation import relax
from cosserat_chain.study_runner import chunk_cells, default_chunk_size, run_study

SPEC = {
    "parameters": {"a": [0.15, 0.2], "E2": {"start": 0.5, "stop": 2.0, "num": 2, "scale": "log"}},
    "models": ["nonlinear", "sine", "linear"],
    "quantities": ["M_c", "phi0_at_fold", "compliance", "onset_load", "band_gap"],
    "sweep": {"m_max": 0.4, "dm": 0.05},
}

#: Relaxation quantities only, on cells that share one time step (a and gamma_phi barely
#: move the highest frequency): a chunk of them runs in one compiled loop.
RELAXING = {
    "parameters": {"a": [0.15, 0.2], "gamma_phi": [0.1, 0.3]},
    "models": ["sine", "nonlinear"],
    "quantities": ["onset_load", "stop_load", "mean_angular_velocity"],
    "loads": [0.2, 0.35],
    "sweep": {"m_max": 0.4, "dm": 0.1, "t_max": 2000.0},
}


@pytest.fixture(scope="module")
def one_cell_per_task(dask_cluster, tmp_path_factory):
    """The RELAXING study computed with one cell per task."""
    run = run_study(
        spec_from_mapping(RELAXING), out=tmp_path_factory.mktemp("single") / "study.nc", scheduler=dask_cluster.scheduler_address, chunk=1
    )
    assert run.completed and run.computed == 8 and run.failed == 0
    return run.dataset


def assert_same_cells(ds, expected):
    for name in ("onset_load", "stop_load", "mean_angular_velocity", "done", "error"):
        np.testing.assert_array_equal(ds[name].values, expected[name].values, err_msg=name)


def test_every_cell_equals_the_single_run_api(dask_cluster, tmp_path):
    spec = spec_from_mapping(SPEC)
    run = run_study(spec, out=tmp_path / "study.nc", scheduler=dask_cluster.scheduler_address)
    assert run.completed and run.computed == 12 and run.failed == 0
    ds = read_dataset(tmp_path / "study.nc")
    assert list(ds.M_c.dims) == ["a", "E2", "model"]
    np.testing.assert_allclose(ds.E2.values, [0.5, 2.0])
    for a in (0.15, 0.2):
        for e2 in (0.5, 2.0):
            params = ChainParams(a=a, E2=e2)
            gap = wave_summary(params).gap
            for model in ("nonlinear", "sine", "linear"):
                cell = ds.sel(a=a, E2=e2, model=model)
                fold = locate_fold(params, model)
                if fold is None:
                    assert math.isnan(float(cell.M_c)) and math.isnan(float(cell.onset_load))
                else:
                    assert float(cell.M_c) == fold.moment and float(cell.phi0_at_fold) == fold.phi0
                    dt = cell_time_step(params, model, spec)
                    assert (
                        float(cell.onset_load) == relaxation_sweep(params, model, m_max=0.4, dm=0.05, stop_at_onset=True, dt=dt).onset_load
                    )
                assert float(cell.compliance) == compliance(params, model)
                assert float(cell.band_gap) == (0.0 if gap is None else gap[1] - gap[0])
                assert int(cell.done) == 1 and str(cell.error.values) == ""


def test_chunks_of_cells_equal_one_cell_per_task_and_single_runs(dask_cluster, tmp_path, one_cell_per_task):
    spec = spec_from_mapping(RELAXING)
    params = [ChainParams(**fields) for _, _, fields in spec.cells()]
    assert len({cell_time_step(p, "sine", spec) for p in params}) == 1  # one shared loop per chunk
    run = run_study(spec, out=tmp_path / "study.nc", scheduler=dask_cluster.scheduler_address, chunk=6)
    assert run.completed and run.computed == 8 and run.failed == 0
    assert_same_cells(read_dataset(tmp_path / "study.nc"), one_cell_per_task)
    cell = run.dataset.sel(a=0.15, gamma_phi=0.3, model="nonlinear")
    chain = ChainParams(a=0.15, gamma_phi=0.3)
    dt = cell_time_step(chain, "nonlinear", spec)
    sweep = relaxation_sweep(chain, "nonlinear", m_max=0.4, dm=0.1, down=True, stop_at_onset=True, t_max=2000.0, dt=dt)
    assert (float(cell.onset_load), float(cell.stop_load)) == (sweep.onset_load, sweep.stop_load)
    for load, rate in zip(RELAXING["loads"], cell.mean_angular_velocity.values):
        assert rate == relax(chain, "nonlinear", load, t_max=2000.0, dt=dt).angular_velocity[chain.N]


@pytest.mark.parametrize("stop", [KeyboardInterrupt, RuntimeError])
def test_a_study_stopped_after_a_chunk_resumes_without_recomputing_it(dask_cluster, tmp_path, one_cell_per_task, stop):
    spec = spec_from_mapping(RELAXING)
    out = tmp_path / "study.nc"

    def stop_after_a_chunk(done, total):
        if done > 0:
            raise stop

    if stop is KeyboardInterrupt:
        first = run_study(spec, out=out, scheduler=dask_cluster.scheduler_address, chunk=2, progress=stop_after_a_chunk)
        assert not first.completed and first.computed == 2
    else:
        with pytest.raises(RuntimeError):
            run_study(spec, out=out, scheduler=dask_cluster.scheduler_address, chunk=2, progress=stop_after_a_chunk)
    assert int(read_dataset(out).done.sum()) == 2
    second = run_study(spec, out=out, scheduler=dask_cluster.scheduler_address, chunk=4)
    assert second.completed and second.skipped == 2 and second.computed == 8 - 2
    assert_same_cells(second.dataset, one_cell_per_task)
    again = run_study(spec, out=out, scheduler=dask_cluster.scheduler_address)
    assert again.computed == 0 and again.skipped == 8


def test_chunks_share_n_and_model_and_keep_the_workers_busy():
    spec = spec_from_mapping(
        {"parameters": {"N": [3, 4], "a": [0.1, 0.15, 0.2]}, "models": ["sine", "linear"], "quantities": ["compliance"]}
    )
    cells = spec.cells()
    chunks = chunk_cells(cells, 2)
    assert sorted(cell for chunk in chunks for cell in chunk) == sorted(cells)
    for chunk in chunks:
        assert len(chunk) <= 2 and len({(fields["N"], model) for _, model, fields in chunk}) == 1
        assert chunk == sorted(chunk)  # spec order: neighbours along the innermost field
    assert [len(chunk) for chunk in chunks] == [2, 1] * 4
    assert (default_chunk_size(12, 2), default_chunk_size(2000, 2), default_chunk_size(10**5, 2), default_chunk_size(3, 8)) == (
        2,
        250,
        256,
        1,
    )


def test_a_failing_cell_in_a_chunk_is_recorded_and_the_others_complete(dask_cluster, tmp_path):
    # dt = 0.05 is stable for E1 = 1 and 2 but beyond the stability limit for E1 = 1000: that cell's
    # relaxation refuses to run, so the chunk's batch raises and its cells are computed one by one.
    spec = spec_from_mapping(
        {
            "parameters": {"E1": [1.0, 1000.0, 2.0]},
            "models": ["sine"],
            "quantities": ["onset_load", "compliance"],
            "sweep": {"m_max": 0.3, "dm": 0.1, "dt": 0.05},
        }
    )
    run = run_study(spec, out=tmp_path / "study.nc", scheduler=dask_cluster.scheduler_address, chunk=3)
    assert run.completed and run.computed == 3 and run.failed == 1
    ds = run.dataset
    assert "stability limit" in str(ds.error.sel(E1=1000.0, model="sine").values)
    for e1 in (1.0, 2.0):
        assert str(ds.error.sel(E1=e1, model="sine").values) == ""
        single = relaxation_sweep(ChainParams(E1=e1), "sine", m_max=0.3, dm=0.1, dt=0.05, stop_at_onset=True)
        np.testing.assert_equal(float(ds.onset_load.sel(E1=e1, model="sine")), math.nan if single.onset_load is None else single.onset_load)
        assert float(ds.compliance.sel(E1=e1, model="sine")) == compliance(ChainParams(E1=e1), "sine")


def test_a_different_spec_does_not_resume_from_the_same_file(dask_cluster, tmp_path):
    out = tmp_path / "study.nc"
    run_study(spec_from_mapping({**SPEC, "quantities": ["compliance"]}), out=out, scheduler=dask_cluster.scheduler_address)
    with pytest.raises(ValueError, match="different study spec"):
        run_study(spec_from_mapping({**SPEC, "quantities": ["band_gap"]}), out=out, scheduler=dask_cluster.scheduler_address)
    earlier = read_dataset(out)
    earlier.attrs["time_step_rule"] = "default step of each cell"
    write_dataset(earlier, out)
    with pytest.raises(ValueError, match="another time-step rule"):
        run_study(spec_from_mapping({**SPEC, "quantities": ["compliance"]}), out=out, scheduler=dask_cluster.scheduler_address)


@pytest.mark.parametrize(
    ("change", "match"),
    [
        ({"parameters": {"aa": [0.1]}}, r"unknown parameter\(s\) \['aa'\]"),
        ({"colour": "red"}, "colour"),
        ({"models": ["cubic"]}, r"unknown model\(s\) \['cubic'\]"),
        ({"quantities": ["speed"]}, "quantities.0"),
        ({"quantities": ["mean_angular_velocity"]}, "needs loads"),
        ({"parameters": {"a": [0.2, 0.6]}}, r"cell a=0.6.*a must satisfy 0 < a < h/2"),
        (
            {
                "parameters": {
                    "a": {"start": 0.1, "stop": 0.2, "num": 2, "scale": "log"},
                    "E2": {"start": 0.0, "stop": 1.0, "num": 2, "scale": "log"},
                }
            },
            "log range needs start > 0",
        ),
        ({"fixed": {"a": 0.1}}, "both swept"),
        (
            {"loads": [{"row": "phi", "particle": 1, "value": 0.1}]},
            "quantities M_c, phi0_at_fold, compliance take no extra loads",
        ),
        (
            {"quantities": ["onset_load"], "loads": [{"row": "v", "particle": -3, "value": 0.01}]},
            "load on v of particle -3: the left end is clamped and holds v fixed",
        ),
        (
            {"quantities": ["onset_load"], "loads": [{"row": "phi", "particle": 1, "kind": "ramp", "value": 0.1, "duration": 5.0}]},
            r"loads\[0\] \(kind 'ramp'\) changes in time",
        ),
        ({"quantities": ["onset_load"], "loads": [{"row": "w", "particle": 1, "value": 0.1}]}, r"loads\[0\]\.row must be one of"),
    ],
)
def test_bad_specs_are_reported_before_anything_runs(change, match):
    with pytest.raises(ValueError, match=match):
        spec_from_mapping({**SPEC, **change})


#: Relaxation quantities under an extra constant moment on particle 1 besides the stepped one on particle 0.
LOADED = {
    "parameters": {"a": [0.15, 0.2]},
    "models": ["sine"],
    "quantities": ["onset_load", "stop_load", "mean_angular_velocity"],
    "loads": [0.2, {"row": "phi", "particle": 1, "value": 0.1}],
    "sweep": {"m_max": 0.4, "dm": 0.05, "t_max": 2000.0},
}


def test_a_cell_under_extra_loads_equals_the_single_runs_under_the_same_loads(dask_cluster, tmp_path):
    spec = spec_from_mapping(LOADED)
    assert spec.loads == [0.2]  # the number stays a moment of mean_angular_velocity, the table is an extra load
    extra = Loads([PointLoad("phi", 1, Schedule.constant(0.1))])
    assert spec.extra() == extra
    # chunk=2: both cells in one batch on a worker, which receives the loads in the spec's JSON.
    run = run_study(spec, out=tmp_path / "study.nc", scheduler=dask_cluster.scheduler_address, chunk=2)
    assert run.completed and run.computed == 2 and run.failed == 0
    ds = read_dataset(tmp_path / "study.nc")
    assert json.loads(ds.attrs["loads_json"]) == extra.to_list()
    assert spec_from_mapping(json.loads(ds.attrs["study_spec_json"])).extra() == extra
    moved = False
    for a in (0.15, 0.2):
        chain = ChainParams(a=a)
        cell = ds.sel(a=a, model="sine")
        dt = cell_time_step(chain, "sine", spec)
        options = {"m_max": 0.4, "dm": 0.05, "down": True, "stop_at_onset": True, "t_max": 2000.0, "dt": dt}
        sweep = relaxation_sweep(chain, "sine", **options, loads=extra)
        assert (float(cell.onset_load), float(cell.stop_load)) == (sweep.onset_load, sweep.stop_load)
        rate = relax(chain, "sine", 0.2, t_max=2000.0, dt=dt, loads=extra).angular_velocity[chain.N]
        assert float(cell.mean_angular_velocity.sel(load=0.2)) == rate
        unloaded = relaxation_sweep(chain, "sine", **options)
        moved |= unloaded.onset_load != sweep.onset_load
    assert moved  # the extra moment brings the onset forward: a study that dropped it would fail above


def test_study_cli_takes_load_tables_and_load_options(dask_cluster, tmp_path):
    spec_file = tmp_path / "loaded.toml"
    spec_file.write_text(
        'models = ["sine"]\nquantities = ["onset_load"]\n[parameters]\na = [0.2]\n[sweep]\nm_max = 0.4\ndm = 0.05\nt_max = 2000.0\n'
        '[[loads]]\nrow = "phi"\nparticle = 1\nvalue = 0.05\n'
    )
    address = dask_cluster.scheduler_address
    result = CliRunner().invoke(app, ["study", str(spec_file), "--load", "phi:-1=0.05", "--scheduler", address, "--json"])
    assert result.exit_code == 0, result.output
    data = json.loads(result.stdout)
    extra = Loads([PointLoad("phi", 1, Schedule.constant(0.05)), PointLoad("phi", -1, Schedule.constant(0.05))])
    assert data["extra_loads"] == extra.to_list()
    chain = ChainParams(a=0.2)
    dt = cell_time_step(chain, "sine", spec_from_mapping({"parameters": {"a": [0.2]}, "models": ["sine"], "quantities": ["onset_load"]}))
    sweep = relaxation_sweep(chain, "sine", m_max=0.4, dm=0.05, stop_at_onset=True, t_max=2000.0, dt=dt, loads=extra)
    assert data["results"][0]["onset_load"] == sweep.onset_load
    statics = tmp_path / "statics.toml"
    statics.write_text('quantities = ["M_c", "onset_load"]\n[parameters]\na = [0.2]\n')
    result = CliRunner().invoke(app, ["study", str(statics), "--load", "phi:1=0.05"])
    assert result.exit_code == 2 and "quantity M_c takes no extra loads" in result.output
    result = CliRunner().invoke(app, ["study", str(spec_file), "--load", "u:3=0.05"])
    assert result.exit_code == 2 and "load on u of particle 3" in result.output
    result = CliRunner().invoke(app, ["study", str(spec_file), "--load", "phi=0.05"])
    assert result.exit_code == 2 and "ROW:PARTICLE=VALUE" in result.output


def test_study_maps_show_each_quantity_and_the_regime_per_load():
    from cosserat_chain.experiments.study import empty_results, store_cell
    from cosserat_chain.plots.study import study_figure

    spec = spec_from_mapping(
        {
            "parameters": {"a": [0.1, 0.2], "b": [0.2, 0.3]},
            "models": ["sine"],
            "quantities": ["M_c", "mean_angular_velocity"],
            "loads": [0.3],
        }
    )
    ds = empty_results(spec)
    for (i, j), rate in zip([(0, 0), (0, 1), (1, 0), (1, 1)], [0.0, 1.5, float("nan"), 2.0]):
        store_cell(ds, spec, (i, j), "sine", {"M_c": 0.1 * (i + 2 * j + 1), "mean_angular_velocity": [rate]})
    fig = study_figure(ds)
    panels = {ax.get_title(): ax for ax in fig.axes if ax.get_title()}
    assert set(panels) == {"M_c (sine)", "regime at M=0.3 (sine)"}
    m_c = panels["M_c (sine)"].collections[0].get_array()
    np.testing.assert_allclose(np.asarray(m_c).reshape(2, 2), ds.M_c.sel(model="sine").values.T)  # rows: b, columns: a
    regime = np.ma.filled(panels["regime at M=0.3 (sine)"].collections[0].get_array(), np.nan).reshape(2, 2).T
    np.testing.assert_array_equal(regime, [[0.0, 1.0], [np.nan, 1.0]])


# Last of the file: the shared cluster's users (dask_cluster) run one after the other, not with this one's cluster between.
def test_study_cli_with_an_embedded_cluster(tmp_path):
    spec_file = tmp_path / "spec.toml"
    spec_file.write_text('models = ["sine"]\nquantities = ["M_c", "compliance"]\n[parameters]\nb = [0.2, 0.3]\n')
    out, plot = tmp_path / "study.nc", tmp_path / "lines.png"
    result = CliRunner().invoke(
        app, ["study", str(spec_file), "--out", str(out), "--workers", "1", "--chunk", "2", "--json", "--plot", str(plot)]
    )
    assert result.exit_code == 0, result.output
    data = json.loads(result.stdout)
    assert data["computed"] == 2 and data["failed"] == 0
    for cell in data["results"]:
        params = ChainParams(b=cell["params"]["b"])
        assert cell["M_c"] == pytest.approx(locate_fold(params, "sine").moment, rel=1e-12)
    assert plot.stat().st_size > 5_000
    bad = tmp_path / "bad.toml"
    bad.write_text('quantities = ["M_c"]\n[parameters]\na = [0.7]\n')
    result = CliRunner().invoke(app, ["study", str(bad)])
    assert result.exit_code == 2 and "a=0.7" in result.output
    result = CliRunner().invoke(app, ["study", str(spec_file), "--chunk", "0"])
    assert result.exit_code == 2 and "Invalid value for '--chunk'" in result.output
