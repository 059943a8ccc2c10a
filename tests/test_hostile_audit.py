"""Hostile inputs found by the audit of every command (issue HX): each gave a traceback or a wrong message.

Each case runs the command in process and checks the exit code, that no exception escaped
and that the message names the option or field, the value and what is allowed; those that
must be refused before any work patch the computation to fail.
"""

from __future__ import annotations

import pytest
from typer.testing import CliRunner

from cosserat_chain.cli import app

runner = CliRunner()


def _never(*args, **kwargs):
    raise AssertionError("computed before the refusal")


def _invoke(argv: list[str]):
    result = runner.invoke(app, argv)
    assert result.exception is None or isinstance(result.exception, SystemExit), repr(result.exception)
    return result, result.output + getattr(result, "stderr", "")


@pytest.fixture
def config(tmp_path):
    def write(text: str):
        path = tmp_path / "chain.toml"
        path.write_text(text)
        return str(path)

    return write


def test_states_refuses_a_negative_seed_before_computing(monkeypatch):
    monkeypatch.setattr("cosserat_chain.experiments.coexisting.states_at", _never)
    result, text = _invoke(["states", "--moment", "0.22", "--seed", "-1"])
    assert result.exit_code == 2
    assert "--seed" in text and "-1" in text and ">= 0" in text


def test_states_refuses_a_chain_that_moves_rigidly_naming_the_config(monkeypatch, config):
    monkeypatch.setattr("cosserat_chain.experiments.coexisting.states_at", _never)
    result, text = _invoke(["states", "--moment", "0.22", "--config", config("periodic = true\n")])
    assert result.exit_code == 2
    assert "--config" in text and "rigidly" in text


def test_states_failing_inside_its_computation_exits_3_without_blaming_the_particle(monkeypatch):
    """A NaN met by the continuation (E1 = 1e-100 gives one) is the run's failure, not bad input."""

    def nan_state(*args, **kwargs):
        raise ValueError("x[u] of particle -2 is nan; values must be finite")

    monkeypatch.setattr("cosserat_chain.experiments.coexisting.states_at", nan_state)
    result, text = _invoke(["states", "--moment", "0.22", "--turns", "1", "--random-starts", "0"])
    assert result.exit_code == 3
    assert "--particle" not in text and "the computation failed: x[u] of particle -2 is nan" in text


def test_sweep_of_a_stiff_chain_is_refused_by_its_work_not_an_overflow(monkeypatch, config):
    """E1 = 1e100 makes the default step 3e-52: the relaxation's chunk count overflowed a C long."""
    monkeypatch.setattr("cosserat_chain.experiments.sweep.relaxation_sweep", _never)
    result, text = _invoke(["sweep", "--model", "nonlinear", "--m-max", "0.05", "--steps", "1", "--config", config("E1 = 1e100\n")])
    assert result.exit_code == 2
    assert "particle-steps" in text and "dt=2.89e-52" in text and "E1" in text


@pytest.mark.parametrize(
    ("text", "named"),
    [("E2 = 0\n", ["E2 = 0", "E2 > 0"]), ("E1 = 1e-100\n", ["singular", "E1=1e-100"]), ("b = 1e-100\n", ["singular", "b=1e-100"])],
)
def test_critical_on_a_chain_without_stiffness_at_rest_names_its_fields(config, text, named):
    """Admissible fields whose K at rest is singular: the continuation's message named a fold (or max_step = inf)."""
    result, out = _invoke(["critical", "--model", "linear", "--config", config(text)])
    assert result.exit_code == 2
    assert all(name in out for name in named), out
    assert "a fold" not in out and "max_step" not in out


def test_critical_failing_on_a_regular_chain_exits_3_with_its_message(monkeypatch):
    def fails(*args, **kwargs):
        raise ValueError("x[u] of particle 1 is nan; values must be finite")

    monkeypatch.setattr("cosserat_chain.experiments.critical.critical_point", fails)
    result, out = _invoke(["critical", "--model", "linear"])
    assert result.exit_code == 3
    assert "the computation failed: x[u] of particle 1 is nan" in out


def test_critical_refuses_a_ring_naming_the_config_before_computing(monkeypatch, config):
    monkeypatch.setattr("cosserat_chain.experiments.critical.critical_point", _never)
    result, out = _invoke(["critical", "--model", "linear", "--config", config("periodic = true\n")])
    assert result.exit_code == 2
    assert "--config" in out and "rigidly" in out


@pytest.mark.parametrize(
    ("argv", "named"),
    [
        (["--vary", "a", "--values", "0.1,0.6"], ["--values", "a = 0.6", "h/2"]),
        (["--vary", "E2", "--values", "-1"], ["--values", "E2 = -1.0", ">= 0"]),
        (["--vary", "m", "--values", "0"], ["--values", "m = 0.0", "> 0"]),
        (["--vary", "E2", "--range", "1:2:1000000000"], ["--range", "1000000000", "10,000"]),
    ],
)
def test_diagram_refuses_values_that_make_no_chain_before_computing(monkeypatch, argv, named):
    """The chain's validation error came out raw (pydantic's text and link) after the diagram began; 10^9 values ran."""
    monkeypatch.setattr("cosserat_chain.experiments.diagram.state_diagram", _never)
    result, out = _invoke(["diagram", *argv])
    assert result.exit_code == 2
    assert all(name in out for name in named), out
    assert "pydantic" not in out


def test_a_default_inertia_out_of_range_is_refused_naming_j(config):
    """h = 1e100, a = b = 1e99 are each in range, but their default j = 6.7e197 is not: later copies of the chain failed."""
    result, out = _invoke(["waves", "--config", config("h = 1e100\na = 1e99\nb = 1e99\n")])
    assert result.exit_code == 2
    assert "j, left out, defaults to m (a^2 + b^2) / 3 = 6.666666666666666e+197" in out and "give j" in out


def test_theory_refuses_a_graded_chain_naming_the_config(monkeypatch, config):
    monkeypatch.setattr("cosserat_chain.analysis.timoshenko.convergence", _never)
    result, out = _invoke(["theory", "--n-list", "3", "--config", config("E1_factors = [1, 2, 3, 4, 5, 6]\n")])
    assert result.exit_code == 2
    assert "--config" in out and "E1_factors" in out


def test_theory_on_a_chain_singular_at_rest_names_its_fields(config):
    """The discrete chain's solve said only "the matrix is singular: Factor is exactly singular"."""
    result, out = _invoke(["theory", "--n-list", "2", "--config", config("E1 = 1e-100\n")])
    assert result.exit_code == 2
    assert "singular" in out and "E1=1e-100" in out and "Factor" not in out


def test_diagram_whose_run_blows_up_exits_3_with_its_message(monkeypatch):
    """gamma_phi = 1e100 made the orbit's settling run blow up: IntegrationError escaped as a traceback."""
    from cosserat_chain.numerics.dynamics import IntegrationError

    def blows_up(*args, **kwargs):
        raise IntegrationError("the run blew up at t=21.3: v of particle -2 became non-finite", None)

    monkeypatch.setattr("cosserat_chain.experiments.diagram.state_diagram", blows_up)
    result, out = _invoke(["diagram", "--vary", "E2", "--values", "1"])
    assert result.exit_code == 3
    assert "the diagram could not be computed: the run blew up at t=21.3" in out


def test_draw_names_times_outside_the_run(tmp_path):
    run = tmp_path / "run.nc"
    made, _ = _invoke(["simulate", "--model", "linear", "--t-end", "1", "--frames", "3", "--out", str(run)])
    assert made.exit_code == 0
    result, out = _invoke(["draw", str(run), "--out", str(tmp_path / "x.png"), "--times", "0,100"])
    assert result.exit_code == 2
    assert "--times '0,100'" in out and "100" in out and "0 <= t <= 1" in out


def test_states_interrupted_exits_130_with_a_message(monkeypatch):
    """Ctrl-C in a long run (integrate's IntegrationError, status interrupted) exited 3, as if the run blew up."""
    from types import SimpleNamespace

    from cosserat_chain.numerics.dynamics import IntegrationError
    from cosserat_chain.status import Status

    def interrupted(*args, **kwargs):
        raise IntegrationError("interrupted at t=12 after 600 of 240000 steps", SimpleNamespace(status=Status.INTERRUPTED))

    monkeypatch.setattr("cosserat_chain.experiments.coexisting.states_at", interrupted)
    result, out = _invoke(["states", "--moment", "0.22", "--turns", "1"])
    assert result.exit_code == 130
    assert "interrupted at t=12" in out and "none is kept" in out


@pytest.mark.parametrize(
    ("argv", "target"),
    [
        (["states", "--moment", "0.22", "--turns", "1"], "cosserat_chain.experiments.coexisting.states_at"),
        (["diagram", "--vary", "E2", "--values", "1"], "cosserat_chain.experiments.diagram.state_diagram"),
    ],
)
def test_ctrl_c_in_python_code_exits_130_saying_what_is_kept(monkeypatch, argv, target):
    """Typer turned the KeyboardInterrupt into a silent exit 130."""

    def ctrl_c(*args, **kwargs):
        raise KeyboardInterrupt

    monkeypatch.setattr(target, ctrl_c)
    result, out = _invoke(argv)
    assert result.exit_code == 130
    assert "interrupted" in out and "none is kept" in out


def test_study_refuses_a_grid_beyond_its_cell_limit_before_building_it(monkeypatch, tmp_path):
    """num = 10^9 built the grid's 10^9 values for minutes before anything ran."""
    monkeypatch.setattr("cosserat_chain.experiments.study.spec_from_mapping", _never)
    spec = tmp_path / "spec.toml"
    spec.write_text('models = ["linear", "sine"]\nquantities = ["compliance"]\n[parameters]\nE2 = { start = 0.1, stop = 1, num = 1000000000 }\n')
    result, out = _invoke(["study", str(spec)])
    assert result.exit_code == 2
    assert "2e+09 cells" in out and "E2 1000000000" in out and "1,000,000" in out


def test_diagram_with_empty_values_quotes_what_was_given(monkeypatch):
    monkeypatch.setattr("cosserat_chain.experiments.diagram.state_diagram", _never)
    result, out = _invoke(["diagram", "--vary", "E2", "--values", ""])
    assert result.exit_code == 2
    assert "got ''" in out and "None" not in out
