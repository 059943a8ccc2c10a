"""Every command over a corpus of careless and hostile inputs (issue 15).

Each case runs one command line in process and asserts what a user is owed:
no traceback, exit code 2 (bad input), a message that
names the option, field, value or path, nothing computed before a bad output path
is refused, and nothing replaced or lost (every file of the workspace is compared
before and after). A failure message starts with its class, TRACEBACK, SILENT
(accepted), UNCLEAR (no name in the message), LOSS (a file changed or vanished)
or COMPUTED (work done before the refusal), so that a run of this module counts them.
"""

from __future__ import annotations

import hashlib
import json
import math
import os
import signal
import stat
from dataclasses import dataclass
from pathlib import Path

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from typer.testing import CliRunner

from cosserat_chain.cli import app

runner = CliRunner()

#: Where each command does its work: patched to fail, so that a refusal after computing is caught.
COMPUTE = {
    "simulate": "cosserat_chain.experiments.simulation.simulate",
    "sweep": "cosserat_chain.experiments.sweep.relaxation_sweep",
    "critical": "cosserat_chain.experiments.critical.critical_point",
    "rotate": "cosserat_chain.experiments.localization.localization_run",
    "orbit": "cosserat_chain.experiments.orbits.periodic_orbit",
    "study": "cosserat_chain.study_runner.run_study",
    "draw": "cosserat_chain.experiments.simulation.simulate",
    "animate": "cosserat_chain.experiments.simulation.simulate",
    "waves": "cosserat_chain.analysis.dispersion.wave_summary",
    "reproduce": "cosserat_chain.report.reproduce",
    "theory": "cosserat_chain.analysis.continuum.convergence",
    "export": "cosserat_chain.exports.export",
    "models": "cosserat_chain.models.base.available_models",
    "diagram": "cosserat_chain.experiments.diagram.state_diagram",
    "states": "cosserat_chain.experiments.coexisting.states_at",
    "breathers": "cosserat_chain.experiments.breathers.roto_breather_family",
}

SPEC = """\
models = ["linear"]
quantities = ["compliance"]
[parameters]
a = [0.1, 0.2]
"""


@dataclass
class Case:
    """One command line, ``{name}`` replaced by the workspace's files, and what it must give."""

    id: str
    argv: list[str]
    names: tuple[str, ...] = ()
    #: the command must be refused before it computes anything
    early: bool = True


def _case(id: str, argv: str, *names: str, early=True) -> Case:
    return Case(id, argv.split(), names=names, early=early)


FAST = "--model linear --t-end 1"
CASES = [
    # 1. outputs must not destroy what is there
    _case("out-fifo", f"simulate {FAST} --out {{fifo}}", "{fifo}", "not a regular file"),
    _case("out-device", f"simulate {FAST} --out {{device}}", "{device}", "not a regular file"),
    _case("out-is-config", f"simulate {FAST} --config {{config}} --out {{config}}", "--out", "--config"),
    _case("draw-out-is-run", "draw {run_png} --out {run_png}", "--out", "RUN"),
    _case("study-out-is-spec", "study {spec} --out {spec}", "--out", "SPEC"),
    _case("rotate-checkpoint-is-out", "rotate --moment 0.3 --turns 1 --out {new_nc} --checkpoint {new_nc}", "--checkpoint", "--out"),
    _case(
        "rotate-checkpoint-is-config", "rotate --moment 0.3 --turns 1 --config {config} --checkpoint {config}", "--checkpoint", "--config"
    ),
    _case("reproduce-out-is-file", "reproduce --turns 1 --out {afile}", "{afile}", "not a folder"),
    # 2. output paths checked before computing
    _case("simulate-out-dir", f"simulate {FAST} --out {{adir}}", "{adir}", "folder"),
    _case("simulate-out-under-file", f"simulate {FAST} --out {{afile}}/x.nc", "{afile}", "not a folder"),
    _case("simulate-out-unwritable", f"simulate {FAST} --out /proc/x.nc", "/proc"),
    _case("simulate-out-missing-unwritable", f"simulate {FAST} --out /proc/none/x.nc", "/proc/none"),
    _case("sweep-out-dir", "sweep --model linear --m-max 0.01 --steps 1 --out {adir}", "{adir}", "folder"),
    _case("sweep-plot-format", "sweep --model linear --m-max 0.01 --steps 1 --plot {tmp}/fig.xyz", ".xyz", "--plot"),
    _case("sweep-plot-unwritable", "sweep --model linear --m-max 0.01 --steps 1 --plot /proc/fig.png", "/proc"),
    _case("critical-out-under-file", "critical --model linear --out {afile}/x.nc", "{afile}"),
    _case("critical-plot-format", "critical --model linear --plot {tmp}/fig.xyz", ".xyz", "--plot"),
    _case("critical-plot-no-suffix", "critical --model linear --plot {tmp}/fig", "--plot"),
    _case("rotate-out-unwritable", "rotate --moment 0.3 --turns 1 --out /proc/x.nc", "/proc"),
    _case("rotate-out-dir", "rotate --moment 0.3 --turns 1 --out {adir}", "{adir}", "folder"),
    _case("orbit-out-dir", "orbit --moment 0.3 --out {adir}", "{adir}", "folder"),
    _case("orbit-plot-format", "orbit --moment 0.3 --down-to 0.25 --plot {tmp}/fig.xyz", ".xyz", "--plot"),
    _case("study-out-dir", "study {spec} --out {adir}", "{adir}", "folder"),
    _case("study-plot-format", "study {spec} --plot {tmp}/fig.xyz", ".xyz", "--plot"),
    _case("draw-out-unwritable", "draw --t-end 1 --out /proc/x.png", "/proc"),
    _case("draw-out-under-file", "draw --t-end 1 --out {afile}/x.png", "{afile}"),
    _case("animate-out-unwritable", "animate --t-end 1 --out /proc/x.gif", "/proc"),
    _case("waves-plot-unwritable", "waves --plot /proc/x.png", "/proc"),
    _case("reproduce-out-unwritable", "reproduce --turns 1 --out /proc/paper", "/proc"),
    _case("simulate-out-empty", f"simulate {FAST}", "--out"),
    # 5. checkpoints
    _case("rotate-checkpoint-exists", "rotate --moment 0.3 --turns 1 --checkpoint {garbage_nc}", "{garbage_nc}", "--resume", "--force"),
    _case(
        "rotate-resume-garbage",
        "rotate --moment 0.3 --turns 1 --checkpoint {garbage_nc} --resume",
        "{garbage_nc}",
        "checkpoint",
        early=False,
    ),
    _case("rotate-resume-dir", "rotate --moment 0.3 --turns 1 --checkpoint {adir} --resume", "{adir}"),
    # 6. parameters and arguments
    _case("config-string-number", "simulate --t-end 1 --config {config_string}", "E1", "'2'"),
    _case("config-boolean", "simulate --t-end 1 --config {config_bool}", "gamma_u", "True"),
    _case("config-huge-stiffness", "simulate --t-end 1 --config {config_stiff}", "1e+300", early=False),
    _case("config-huge-N", "simulate --t-end 1 --config {config_huge_n}", "memory", "N", early=False),
    _case("critical-huge-N", "critical --model nonlinear --config {config_huge_n}", "memory", "N=1000000000", early=False),
    _case("sweep-huge-N", "sweep --model linear --m-max 0.1 --steps 1 --config {config_huge_n}", "memory", "N=1000000000", early=False),
    _case("rotate-huge-N", "rotate --moment 0.3 --turns 1 --config {config_huge_n}", "memory", "N=1000000000", early=False),
    _case("orbit-huge-N", "orbit --moment 0.3 --config {config_huge_n}", "memory", "N=1000000000", early=False),
    _case("theory-errata-huge-N", "theory --n-list 3 --config {config_huge_n}", "memory", "N = 1000000000", early=False),
    _case("config-dev-zero", "simulate --t-end 1 --config /dev/zero", "/dev/zero", "not a regular file"),
    _case("config-dir", "simulate --t-end 1 --config {adir}", "{adir}"),
    _case("config-missing", "simulate --t-end 1 --config {tmp}/none.toml", "none.toml"),
    _case("config-binary", "simulate --t-end 1 --config {binary}", "TOML"),
    _case("theory-huge-n", "theory --n-list 100000000", "memory", "100000000", early=False),
    _case("simulate-load-garbage", f"simulate {FAST} --load phi0.1", "--load", "ROW:PARTICLE=VALUE"),
    _case("simulate-load-held", f"simulate {FAST} --load u:3=0.1", "particle 3", "clamped"),
    _case("simulate-x0-dev-zero", f"simulate {FAST} --x0 /dev/zero", "/dev/zero", "not a NetCDF file"),
    _case("simulate-x0-not-a-run", f"simulate {FAST} --x0 {{binary}}", "--x0"),
    _case("simulate-x0-is-out", f"simulate {FAST} --x0 {{run_png}} --out {{run_png}}", "--out", "--x0"),
    _case("simulate-at-without-x0", f"simulate {FAST} --at 3", "--at", "--x0"),
    _case("diagram-out-dir", "diagram --vary E2 --values 1 --out {adir}", "--out", "{adir}"),
    _case("diagram-plot-format", "diagram --vary E2 --values 1 --plot {tmp}/d.bmp", "--plot", ".bmp"),
    _case("diagram-values-garbage", "diagram --vary E2 --values 1,,x", "--values"),
    _case("diagram-vary-unknown", "diagram --vary E3 --values 1", "E3", "field must be one of"),
    _case("diagram-values-nan", "diagram --vary E2 --values nan", "finite"),
    _case("states-moment-nan", "states --moment nan", "--moment", "finite"),
    _case("states-random-starts-negative", "states --moment 0.22 --random-starts -1", "--random-starts", "-1"),
    _case("states-turns-zero", "states --moment 0.22 --turns 0", "--turns"),
    _case("states-particle-outside", "states --moment 0.22 --particle 9", "--particle", "9", early=False),
    _case("states-config-missing", "states --moment 0.22 --config {tmp}/none.toml", "none.toml"),
    _case("simulate-checkpoint-exists", f"simulate {FAST} --checkpoint {{garbage_nc}}", "{garbage_nc}", "--resume", "--force"),
    _case("simulate-resume-and-force", f"simulate {FAST} --out {{new_nc}} --resume --force", "--resume", "--force"),
    _case("simulate-checkpoint-is-config", f"simulate {FAST} --config {{config}} --checkpoint {{config}}", "--checkpoint", "--config"),
    _case("simulate-frames-0", f"simulate {FAST} --frames 0", "--frames"),
    _case("simulate-frames-negative", f"simulate {FAST} --frames -5", "--frames"),
    _case("simulate-frames-huge", f"simulate {FAST} --frames 1000000000000", "--frames", early=False),
    _case("simulate-threads-0", f"simulate {FAST} --threads 0", "--threads"),
    _case("simulate-threads-negative", f"simulate {FAST} --threads -3", "--threads"),
    _case("simulate-ramp-negative", f"simulate {FAST} --ramp -1", "--ramp"),
    _case("simulate-ramp-nan", f"simulate {FAST} --ramp nan", "--ramp"),
    _case("simulate-t-end-negative", "simulate --t-end -1", "--t-end"),
    _case("simulate-t-end-nan", "simulate --t-end nan", "--t-end"),
    _case("simulate-t-end-inf", "simulate --t-end inf", "--t-end"),
    _case("simulate-moment-nan", f"simulate {FAST} --moment nan", "--moment"),
    _case("simulate-moment-inf", f"simulate {FAST} --moment inf", "--moment"),
    _case("simulate-dt-zero", f"simulate {FAST} --dt 0", "--dt"),
    _case("simulate-dt-negative", f"simulate {FAST} --dt -0.01", "--dt"),
    _case("simulate-dt-nan", f"simulate {FAST} --dt nan", "--dt"),
    _case("simulate-particle-out", f"simulate {FAST} --particle 99", "99"),
    _case("animate-fps-0", "animate {run} --out {tmp}/a.gif --fps 0", "--fps"),
    _case("animate-fps-nan", "animate {run} --out {tmp}/a.gif --fps nan", "--fps"),
    _case("animate-frames-0", "animate {run} --out {tmp}/a.gif --frames 0", "--frames"),
    _case("animate-window-empty", "animate {run} --out {tmp}/a.gif --t-start 5 --t-stop 1", "--t-start"),
    _case("sweep-m-max-nan", "sweep --model linear --m-max nan --steps 2", "--m-max"),
    _case("sweep-m-max-negative", "sweep --model linear --m-max -1 --steps 2", "--m-max"),
    _case("sweep-steps-0", "sweep --model linear --m-max 0.1 --steps 0", "--steps"),
    _case("sweep-dm-0", "sweep --model linear --m-max 0.1 --dm 0", "--dm"),
    _case("sweep-t-max-0", "sweep --model linear --m-max 0.1 --steps 2 --t-max 0", "--t-max"),
    _case("rotate-turns-0", "rotate --moment 0.3 --turns 0", "--turns"),
    _case("rotate-t-max-negative", "rotate --moment 0.3 --t-max -1", "--t-max"),
    _case("rotate-moment-nan", "rotate --moment nan", "--moment"),
    _case("rotate-checkpoint-every-negative", "rotate --moment 0.3 --out {new_nc} --checkpoint-every -1", "--checkpoint-every"),
    _case("orbit-turns-0", "orbit --moment 0.3 --turns 0", "--turns"),
    _case("orbit-moment-nan", "orbit --moment nan", "--moment"),
    _case("orbit-period-max-negative", "orbit --moment 0.3 --down-to 0.2 --period-max -1", "--period-max"),
    _case("orbit-down-to-nan", "orbit --moment 0.3 --down-to nan", "--down-to"),
    _case("breathers-omega-nan", "breathers --omega nan", "--omega"),
    _case("breathers-steps-1", "breathers --omega 6 --to 5 --steps 1", "--steps"),
    _case("breathers-out-dir", "breathers --omega 6 --out {adir}", "{adir}", "folder"),
    _case("breathers-plot-format", "breathers --omega 6 --plot {tmp}/fig.xyz", ".xyz", "--plot"),
    _case("study-workers-0", "study {spec} --workers 0", "--workers"),
    _case("study-chunk-0", "study {spec} --chunk 0", "--chunk"),
    _case("study-n-fraction", "study {spec_n_fraction}", "N", "2.5"),
    _case("study-load-nan", "study {spec_load_nan}", "loads"),
    _case("study-range-inf", "study {spec_range_inf}", "stop"),
    _case("study-missing", "study {tmp}/none.toml", "none.toml"),
    _case("study-scheduler-unreachable", "study {spec} --scheduler tcp://127.0.0.1:9", "127.0.0.1:9", early=False),
    _case("reproduce-turns-0", "reproduce --turns 0 --out {tmp}/paper", "--turns"),
    _case("draw-times-text", "draw {run} --out {tmp}/x.png --times abc", "--times", "abc"),
    _case("draw-times-nan", "draw {run} --out {tmp}/x.png --times nan", "--times"),
    _case("theory-n-list-text", "theory --n-list 3,x", "--n-list"),
    _case("theory-n-list-zero", "theory --n-list 0", "--n-list"),
    _case("export-out-suffix", "export {run} --to vtk --out {tmp}/run.vtu", "'.vtu'", ".pvd"),
    _case("export-out-is-run", "export {run} --to csv --out {run}", "'.nc'"),
    _case("export-out-unwritable", "export {run} --to csv --out /proc/run.csv", "/proc"),
    _case("export-format-unknown", "export {run} --to stl --out {tmp}/run.stl", "--to"),
    _case("export-missing", "export {tmp}/none.nc --to csv --out {tmp}/x.csv", "none.nc"),
    _case("export-critical-output", "export {critical_nc} --to csv --out {tmp}/x.csv", "critical"),
    _case("models-unknown-option", "models --bogus", "--bogus"),
    # 7. files from elsewhere
    _case("draw-rotate-output", "draw {rotate_nc} --out {tmp}/x.png", "rotate", early=False),
    _case("draw-critical-output", "draw {critical_nc} --out {tmp}/x.png", "critical", early=False),
    _case("animate-critical-output", "animate {critical_nc} --out {tmp}/x.gif", "critical", early=False),
    _case("draw-config", "draw {config} --out {tmp}/x.png", "{config}", early=False),
    _case("draw-missing", "draw {tmp}/none.nc --out {tmp}/x.png", "none.nc"),
]


def _workspace(tmp: Path, made: dict[str, Path]) -> dict[str, str]:
    """The files the cases refer to, made afresh in ``tmp`` (the costly ones copied from ``made``)."""
    names: dict[str, str] = {"tmp": str(tmp)}

    def put(name: str, text: str | bytes, filename: str) -> None:
        path = tmp / filename
        path.write_bytes(text if isinstance(text, bytes) else text.encode())
        names[name] = str(path)

    put("config", "E1 = 1.0\nN = 3\n", "chain.toml")
    put("config_string", 'E1 = "2"\n', "string.toml")
    put("config_bool", "gamma_u = true\n", "bool.toml")
    put("config_stiff", "E1 = 1e300\n", "stiff.toml")
    put("config_huge_n", "N = 1000000000\n", "huge.toml")
    put("binary", bytes(range(256)) * 4, "binary.toml")
    put("afile", "not a folder\n", "afile")
    put("garbage_nc", "garbage\n", "garbage.nc")
    put("spec", SPEC, "spec.toml")
    put("spec_n_fraction", SPEC.replace("a = [0.1, 0.2]", "N = [2.5, 3]"), "n_fraction.toml")
    put("spec_load_nan", 'models = ["sine"]\nquantities = ["mean_angular_velocity"]\nloads = [nan]\n[parameters]\na = [0.1]\n', "nan.toml")
    put("spec_range_inf", SPEC.replace("a = [0.1, 0.2]", "E2 = { start = 0.1, stop = inf, num = 3 }"), "inf.toml")
    (tmp / "adir").mkdir()
    names["adir"] = str(tmp / "adir")
    os.mkfifo(tmp / "fifo.nc")
    names["fifo"] = str(tmp / "fifo.nc")
    device = tmp / "device.nc"
    if os.geteuid() == 0:
        os.mknod(device, stat.S_IFCHR | 0o666, os.makedev(1, 3))  # a /dev/null of our own
    else:  # pragma: no cover - the CI runs as root; elsewhere a second FIFO stands in
        os.mkfifo(device)
    names["device"] = str(device)
    names["new_nc"] = str(tmp / "new.nc")
    for name, source in made.items():
        path = tmp / source.name
        path.write_bytes(source.read_bytes())
        names[name] = str(path)
    return names


def _snapshot(tmp: Path) -> dict[str, object]:
    """What every entry of the workspace is: a digest for a file, its kind otherwise."""
    out: dict[str, object] = {}
    for path in sorted(tmp.rglob("*")):
        mode = path.lstat().st_mode
        if stat.S_ISREG(mode):
            out[str(path)] = hashlib.sha256(path.read_bytes()).hexdigest()
        else:
            out[str(path)] = stat.S_IFMT(mode)
    return out


@pytest.fixture(scope="module")
def made(tmp_path_factory) -> dict[str, Path]:
    """Outputs of real runs, made once: a simulation, a rotation and a critical point."""
    where = tmp_path_factory.mktemp("made")
    paths = {"run": where / "run.nc", "rotate_nc": where / "rotate.nc", "critical_nc": where / "critical.nc"}
    for argv in (
        ["simulate", "--model", "linear", "--t-end", "5", "--frames", "11", "--out", str(paths["run"])],
        ["rotate", "--model", "sine", "--moment", "0.3", "--turns", "1", "--out", str(paths["rotate_nc"])],
        ["critical", "--model", "linear", "--out", str(paths["critical_nc"])],
    ):
        result = runner.invoke(app, argv)
        assert result.exit_code == 0, result.output
    (where / "rotate.checkpoint.nc").unlink(missing_ok=True)
    paths["run_png"] = where / "run.png"
    paths["run_png"].write_bytes(paths["run"].read_bytes())
    return paths


#: Seconds a case may take: a command that hangs (reading /dev/zero, waiting on a FIFO) fails as HUNG.
DEADLINE = 120


class _Hung(Exception):
    pass


def _invoke_with_deadline(argv: list[str]):
    def alarm(signum, frame):
        raise _Hung(f"HUNG: {' '.join(argv)} did not return within {DEADLINE} s")

    previous = signal.signal(signal.SIGALRM, alarm)
    signal.alarm(DEADLINE)
    try:
        result = runner.invoke(app, argv)
    finally:
        signal.alarm(0)
        signal.signal(signal.SIGALRM, previous)
    if isinstance(result.exception, _Hung):
        pytest.fail(str(result.exception))
    return result


@pytest.mark.parametrize("case", CASES, ids=[c.id for c in CASES])
def test_hostile_input_is_refused_clearly_and_loses_nothing(case: Case, made, tmp_path, monkeypatch):
    names = _workspace(tmp_path, made)
    argv = [arg.format(**names) for arg in case.argv]
    if case.id == "simulate-out-empty":
        argv += ["--out", ""]
    if case.id == "study-scheduler-unreachable":
        import cosserat_chain.study_runner as study_runner

        # A refused port is retried for half the timeout: 1 s tells the same as the default 5.
        monkeypatch.setattr(study_runner, "CONNECT_TIMEOUT", 2.0)
    if case.early:
        command = argv[0]

        def computed(*args, **kwargs):
            raise AssertionError(f"COMPUTED: {command} started computing before refusing its input")

        monkeypatch.setattr(COMPUTE[command], computed)
    before = _snapshot(tmp_path)
    result = _invoke_with_deadline(argv)
    if isinstance(result.exception, AssertionError) and "COMPUTED" in str(result.exception):
        pytest.fail(str(result.exception))
    if result.exception is not None and not isinstance(result.exception, SystemExit):
        pytest.fail(f"TRACEBACK: {type(result.exception).__name__}: {result.exception}")
    if result.exit_code != 2:
        pytest.fail(f"SILENT: exit code {result.exit_code} (expected 2, bad input); output: {result.output[-400:]}")
    missing = [name.format(**names) for name in case.names if name.format(**names) not in result.output]
    assert not missing, f"UNCLEAR: the message does not name {missing}: {result.output[-600:]}"
    assert "Traceback" not in result.output, f"TRACEBACK in the output: {result.output[-600:]}"
    after = _snapshot(tmp_path)
    changed = [path for path, digest in before.items() if after.get(path) != digest]
    assert not changed, f"LOSS: {changed} changed or vanished"
    created = [path for path in after if path not in before]
    assert not created, f"LOSS: a refused command left {created}"


def test_corpus_names_every_command_it_guards():
    """The corpus covers every command that computes (a command added without cases fails here)."""
    commands = {info.name or info.callback.__name__ for info in app.registered_commands}
    assert commands <= set(COMPUTE), commands - set(COMPUTE)
    assert {case.argv[0] for case in CASES} == set(COMPUTE)


def test_a_run_beyond_its_accuracy_is_flagged_not_reported_completed():
    """At ten times the default step (still inside the stability limit) the energy balance and the rotation per step are off."""
    from cosserat_chain import ChainParams
    from cosserat_chain.numerics.dynamics import default_time_step

    dt = default_time_step(ChainParams(), "nonlinear")
    argv = ["simulate", "--model", "nonlinear", "--moment", "0.3", "--t-end", "200", "--frames", "51", "--json"]
    good = runner.invoke(app, [*argv, "--dt", f"{dt!r}"])
    assert good.exit_code == 0, good.output
    coarse = runner.invoke(app, [*argv, "--dt", f"{10 * dt!r}"])
    assert coarse.exit_code == 5, coarse.output
    summary = json.loads(coarse.stdout)
    # M / gamma_phi = 3 rad per unit time: 0.62 rad per step of 10 dt; the remedy names the step that follows it.
    assert summary["status"] == "inaccurate" and f"dt <= {0.5 / 3:.3g}" in summary["message"]
    accurate = json.loads(good.stdout)["accuracy"]
    assert accurate["balance_relative"] < 1e-3 < summary["accuracy"]["balance_relative"]
    assert summary["accuracy"]["rotation_per_step"] > 0.5 > accurate["rotation_per_step"]
    # A load no step of this size can follow: the remedy named is the load, with the step it would need.
    spun = runner.invoke(app, ["simulate", "--model", "sine", "--moment", "1000", "--t-end", "20", "--json"])
    assert spun.exit_code == 5
    message = json.loads(spun.stdout)["message"]
    assert "M / gamma_phi = 1e+04 rad per unit time" in message and "dt <= 5e-05" in message


def test_parameters_are_numbers_and_numpy_scalars_are_accepted():
    import numpy as np
    from pydantic import ValidationError

    from cosserat_chain import ChainParams

    chain = ChainParams(m=np.int64(2), a=np.float32(0.25), N=np.int64(4))
    assert chain.j == pytest.approx(2 * (0.25**2 + 0.2**2) / 3) and type(chain.N) is int and type(chain.m) is float
    for field, value in (("E1", "2"), ("E2", True), ("h", [1.0]), ("N", 3.0)):
        with pytest.raises(ValidationError, match=field):
            ChainParams(**{field: value})


def _toml_value(value) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, float):
        return {"nan": "nan", "inf": "inf", "-inf": "-inf"}.get(repr(value), repr(value))
    if isinstance(value, str):
        return json.dumps(value, ensure_ascii=False)
    if isinstance(value, list):
        return "[" + ", ".join(map(_toml_value, value)) + "]"
    return str(value)


#: Values of every type. Magnitudes stay where a run is short, or is refused at once: a mass of
#: 1e-28 (kg taken for the model's units) asks, rightly, for 10^15 steps, which run for years.
_VALUES = st.one_of(
    st.floats(1e-3, 1e3),
    st.floats(-1e3, 0.0),
    st.integers(-10, 40),
    st.sampled_from([math.nan, math.inf, -math.inf, 10**12, 1e300, 1e-300, -1e300]),
    st.booleans(),
    st.text(max_size=5),
    st.lists(st.floats(0, 2), max_size=2),
)
_KEYS = st.sampled_from(["E1", "E2", "h", "a", "b", "m", "j", "gamma_u", "gamma_v", "gamma_phi", "N", "gama_phi"])


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(config=st.dictionaries(_KEYS, _VALUES, max_size=4))
def test_any_config_gives_a_run_or_a_clear_refusal(config, tmp_path):
    """Random TOML configs of every type: a run (0, or 5 when flagged inaccurate) or exit 2 naming a key, never a traceback."""
    path = tmp_path / "random.toml"
    path.write_text("".join(f"{key} = {_toml_value(value)}\n" for key, value in config.items()))
    result = _invoke_with_deadline(["simulate", "--model", "linear", "--t-end", "1", "--frames", "3", "--config", str(path)])
    assert result.exception is None or isinstance(result.exception, SystemExit), f"TRACEBACK: {result.exception!r} for {config}"
    assert result.exit_code in (0, 2, 3, 5), result.output
    if result.exit_code == 2:
        assert any(key in result.output for key in config) or "memory" in result.output, f"UNCLEAR: {result.output} for {config}"
