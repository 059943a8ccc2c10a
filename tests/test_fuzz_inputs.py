"""Fuzzing of the inputs (issue 46, item 8): config tables of every type and corrupted result files.

Hypothesis draws ``[[loads]]`` and ``[disorder]`` tables with values of every TOML type,
and result files damaged as a disk, a transfer or a hand would damage them (bytes flipped,
the file cut short, variables removed, attributes edited). What every case is owed: a
result or a ``ValueError`` naming what is wrong (exit 2 on the command line, 3 where an
output could not be written), never another exception, and no file but the output changed.
"""

from __future__ import annotations

import hashlib
import json
import math

import pytest
import xarray as xr
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from typer.testing import CliRunner

from cosserat_chain import ChainParams
from cosserat_chain.cli import app
from cosserat_chain.experiments.simulation import simulate
from cosserat_chain.inputs import check_run
from cosserat_chain.io import load_config, read_dataset, run_frame, write_dataset
from cosserat_chain.loads import moment_load

runner = CliRunner()


def _quick_and_slow(quick: int, more: int, **strategies):
    """Two tests of one property drawn from ``strategies``: ``quick`` examples in the quick suite and ``more`` in the
    slow one, for the properties whose examples each run a command or a simulation."""

    def tests(body):
        def drawn(count):
            return settings(max_examples=count, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])(
                given(**strategies)(body)
            )

        return drawn(quick), pytest.mark.slow(drawn(more))

    return tests


#: TOML values of every type, at every scale.
_VALUES = st.recursive(
    st.one_of(
        st.none(),
        st.booleans(),
        st.integers(-(10**12), 10**12),
        st.floats(allow_nan=True, allow_infinity=True),
        st.text(max_size=6),
        st.sampled_from(["phi", "u", "v", "E1", "step", "ramp", "staircase", "harmonic", "knots", "constant"]),
    ),
    lambda inner: st.one_of(st.lists(inner, max_size=3), st.dictionaries(st.text(max_size=4), inner, max_size=2)),
    max_leaves=6,
)
_LOAD_KEYS = st.sampled_from(
    ["row", "particle", "kind", "value", "at", "before", "duration", "start", "increment", "hold", "n_steps", "amplitude", "frequency",
     "phase", "offset", "times", "values", "bogus"]
)  # fmt: skip
_LOAD_TABLE = st.dictionaries(_LOAD_KEYS, _VALUES, max_size=6)
_DISORDER = st.one_of(_VALUES, st.dictionaries(st.sampled_from(["seed", "spread", "fields", "bogus"]), _VALUES, max_size=3))


def _toml(value) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, float):
        return "nan" if math.isnan(value) else ("inf" if value > 0 else "-inf") if math.isinf(value) else repr(value)
    if isinstance(value, str):
        return json.dumps(value)
    if isinstance(value, list):
        return "[" + ", ".join(_toml(v) for v in value if v is not None) + "]"
    if isinstance(value, dict):
        return "{" + ", ".join(f"{json.dumps(k)} = {_toml(v)}" for k, v in value.items() if v is not None) + "}"
    return str(value)


def _config(loads: list[dict], disorder) -> str:
    lines = ["N = 3"]
    if disorder is not None:
        lines.append(f"disorder = {_toml(disorder)}")
    lines.append(f"loads = {_toml(loads)}")
    return "\n".join(lines) + "\n"


@settings(max_examples=100, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(loads=st.lists(_LOAD_TABLE, max_size=3), disorder=_DISORDER)
def test_any_loads_and_disorder_tables_give_a_chain_or_a_named_refusal(loads, disorder, tmp_path):
    path = tmp_path / "fuzz.toml"
    path.write_text(_config(loads, disorder))
    try:
        params, got = load_config(path)
    except ValueError as err:
        assert "fuzz.toml" in str(err) or "loads" in str(err) or "disorder" in str(err), str(err)
        return
    assert isinstance(params, ChainParams) and len(got) <= len(loads)


@settings(max_examples=15, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(loads=st.lists(_LOAD_TABLE, max_size=2), disorder=_DISORDER)
def test_simulate_given_any_config_tables_runs_or_exits_2(loads, disorder, tmp_path):
    """The command line over the same tables: a run (0, or 3/5 for a load the step cannot follow) or exit 2 naming the file."""
    path = tmp_path / "fuzz.toml"
    path.write_text(_config(loads, disorder))
    out = tmp_path / "out.nc"
    argv = ["simulate", "--model", "linear", "--t-end", "0.5", "--frames", "2", "--config", str(path), "--out", str(out)]
    result = runner.invoke(app, argv)
    assert result.exception is None or isinstance(result.exception, SystemExit), f"TRACEBACK: {result.exception!r}"
    assert result.exit_code in (0, 2, 3, 5), result.output
    if result.exit_code == 2:
        assert "fuzz.toml" in result.output or "loads" in result.output or "disorder" in result.output, result.output
    assert {p.name for p in tmp_path.iterdir()} <= {"fuzz.toml", "out.nc"}


@pytest.fixture(scope="module")
def run_bytes(tmp_path_factory) -> bytes:
    """A short run with its velocities, as ``simulate --out`` writes it."""
    path = tmp_path_factory.mktemp("fuzz") / "run.nc"
    write_dataset(simulate(ChainParams(), "linear", moment_load(0.1), t_end=1.0, n_frames=3), path)
    return path.read_bytes()


@pytest.fixture(scope="module")
def run_dataset(run_bytes, tmp_path_factory) -> xr.Dataset:
    """The run of :func:`run_bytes`, read back."""
    path = tmp_path_factory.mktemp("fuzz") / "run.nc"
    path.write_bytes(run_bytes)
    return read_dataset(path)


def _read_as_input(path, ds=None) -> str:
    """What a command reading ``path`` (or the Dataset ``ds`` read from it) as a run gets: "ok" or the refusal.

    Any other exception escapes and fails the test.
    """
    try:
        ds = read_dataset(path) if ds is None else ds
        check_run(ds, repr(str(path)), velocities=True)
        run_frame(ds)
    except ValueError as err:
        assert str(path.name) in str(err) or "dataset" in str(err), str(err)
        return "refused"
    return "ok"


def _run_with_flipped_bytes_or_cut_short(run_bytes, flips, cut, tmp_path):
    """A run with bytes flipped or its end cut off is read or refused (each example reads a file, in a forked probe)."""
    data = bytearray(run_bytes)
    for where, mask in flips:
        data[int(where * len(data))] ^= mask
    path = tmp_path / "damaged.nc"
    path.write_bytes(bytes(data[: max(1, int(cut * len(data)))] if cut < 0.9 else data))
    _read_as_input(path)


test_a_run_with_flipped_bytes_or_cut_short_is_read_or_refused, test_more_runs_with_flipped_bytes_or_cut_short = _quick_and_slow(
    20,
    60,
    flips=st.lists(st.tuples(st.floats(0, 1, exclude_max=True), st.integers(1, 255)), min_size=1, max_size=8),
    cut=st.floats(0, 1),
)(_run_with_flipped_bytes_or_cut_short)


def _without(ds, name):
    out = ds.copy()
    out.attrs.pop(name, None)
    return out


_EDITS = {
    "drop": lambda ds, name: ds.drop_vars(name),
    "nan": lambda ds, name: ds.assign({name: ds[name] * math.nan}) if ds[name].dtype.kind == "f" else ds,
    "first-frame": lambda ds, name: ds.isel(time=slice(0, 1)),
    "no-frame": lambda ds, name: ds.isel(time=slice(0, 0)),
    "attr": lambda ds, name: ds.assign_attrs({name: "[]"}),
    "attr-drop": _without,
}


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(
    edits=st.lists(
        st.tuples(
            st.sampled_from(sorted(_EDITS)),
            st.sampled_from(["u", "v", "phi", "u_dot", "v_dot", "phi_dot", "time", "particle", "kinetic", "params_json", "loads_json"]),
        ),
        min_size=1,
        max_size=3,
    )
)
def test_a_run_with_variables_or_attributes_edited_is_read_or_refused(run_dataset, edits, tmp_path):
    ds = run_dataset.copy(deep=True)
    for edit, name in edits:
        if name in ds.variables or edit in ("attr", "attr-drop"):
            try:
                ds = _EDITS[edit](ds, name)
            except ValueError:  # xarray refuses to drop an index this way: not a file anyone could write
                continue
    # In memory: the file's round trip is the flipped-bytes test's; here the schema meets every edit.
    outcome = _read_as_input(tmp_path / "edited.nc", ds)
    intact = all(edit in ("attr", "attr-drop") and name not in ("params_json", "loads_json") for edit, name in edits)
    assert outcome == "ok" or not intact


def _digests(folder) -> dict[str, str]:
    return {str(p): hashlib.sha256(p.read_bytes()).hexdigest() for p in sorted(folder.rglob("*")) if p.is_file()}


def _commands_given_a_damaged_run(run_bytes, damage, command, tmp_path):
    """The command line over damaged runs: no traceback, exit 2 (or 0 for a damage the reader does not see), the input untouched."""
    folder = tmp_path / "work"
    folder.mkdir(exist_ok=True)
    for stale in folder.iterdir():
        stale.unlink()
    run = folder / "run.nc"
    kind, value = damage
    if kind == "drop":
        source = folder / "source.nc"
        source.write_bytes(run_bytes)
        read_dataset(source).drop_vars(value).to_netcdf(run, engine="h5netcdf")
        source.unlink()
    else:
        data = bytearray(run_bytes)
        if kind == "cut":
            data = data[: int(value * len(data))]
        else:
            data[int(value * len(data))] ^= 0xFF
        run.write_bytes(bytes(data))
    out = folder / {"export": "out.csv", "x0": "out.nc", "draw": "out.png"}[command]
    argv = {
        "export": ["export", str(run), "--to", "csv", "--out", str(out)],
        "x0": ["simulate", "--model", "linear", "--t-end", "2", "--frames", "3", "--x0", str(run), "--out", str(out)],
        "draw": ["draw", str(run), "--out", str(out)],
    }[command]
    before = _digests(folder)
    result = runner.invoke(app, argv)
    assert result.exception is None or isinstance(result.exception, SystemExit), f"TRACEBACK: {result.exception!r}"
    assert result.exit_code in (0, 2, 3), result.output
    if result.exit_code != 0:
        assert "run.nc" in result.output, result.output
    after = _digests(folder)
    assert {path: digest for path, digest in after.items() if path != str(out)} == before


test_commands_given_a_damaged_run_exit_2_or_3_and_change_nothing_else, test_commands_given_more_damaged_runs = _quick_and_slow(
    4,
    12,
    damage=st.one_of(
        st.tuples(st.just("cut"), st.floats(0, 0.95)),
        st.tuples(st.just("flip"), st.floats(0, 1, exclude_max=True)),
        st.tuples(st.just("drop"), st.sampled_from(["u", "phi_dot", "time"])),
    ),
    command=st.sampled_from(["export", "x0", "draw"]),
)(_commands_given_a_damaged_run)


@pytest.fixture(scope="module")
def checkpoint_bytes(tmp_path_factory) -> bytes:
    """The checkpoint of a finished short simulation."""
    path = tmp_path_factory.mktemp("fuzz") / "run.checkpoint.nc"
    simulate(ChainParams(), "linear", moment_load(0.1), t_end=1.0, n_frames=5, checkpoint=path, checkpoint_every=0.0)
    return path.read_bytes()


@pytest.mark.filterwarnings("ignore::UserWarning")
def _damaged_or_resealed_checkpoint(checkpoint_bytes, damage, value, tmp_path):
    """A checkpoint cut, flipped, or edited and sealed again: the resumed run is the run asked for, or a ValueError."""
    from cosserat_chain.experiments.checkpoint import seal
    from cosserat_chain.experiments.simulation import _STATE_ATTRIBUTES, CHECKPOINT_EXPERIMENT, CHECKPOINT_FORMAT

    path = tmp_path / "run.checkpoint.nc"
    kind, what = damage
    data = bytearray(checkpoint_bytes)
    if kind == "cut":
        path.write_bytes(bytes(data[: int(what * len(data))]))
    elif kind == "flip":
        data[int(what * len(data))] ^= 0xFF
        path.write_bytes(bytes(data))
    else:
        path.write_bytes(checkpoint_bytes)
        ds = read_dataset(path)
        ds = ds.drop_vars(what) if kind == "drop" else ds.assign_attrs({what: value})
        seal(ds, CHECKPOINT_EXPERIMENT, CHECKPOINT_FORMAT, _STATE_ATTRIBUTES).to_netcdf(path, engine="h5netcdf")
    try:
        # No checkpoint written on the way: a chunk of one step (chunk_steps = 1) would write one a step.
        ds = simulate(
            ChainParams(), "linear", moment_load(0.1), t_end=1.0, n_frames=5, checkpoint=path, checkpoint_every=3600.0, resume=True
        )
    except ValueError:  # exit 2, the message naming what differs (checked case by case in test_inputs_schema)
        return
    assert ds.sizes["time"] == 5 and float(ds.time[-1]) == 1.0


test_a_damaged_or_resealed_checkpoint_resumes_or_is_refused, test_more_damaged_or_resealed_checkpoints = _quick_and_slow(
    8,
    30,
    damage=st.one_of(
        st.tuples(st.just("cut"), st.floats(0, 0.99)),
        st.tuples(st.just("flip"), st.floats(0, 1, exclude_max=True)),
        st.tuples(st.just("drop"), st.sampled_from(["phi", "final_phi_dot", "frame_step", "final_load_work", "split_sums", "time"])),
        st.tuples(st.just("count"), st.sampled_from(["steps", "n_steps", "stride_steps", "chunk_steps"])),
    ),
    value=st.one_of(st.integers(-10, 10**6), st.floats(allow_nan=True), st.text(max_size=3)),
)(_damaged_or_resealed_checkpoint)
