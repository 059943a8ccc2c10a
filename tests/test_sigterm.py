"""SIGTERM (a batch scheduler's stop) ends a command as Ctrl-C does: the checkpoint and the frames so far are kept."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time

import pytest

from cosserat_chain.cli import app
from cosserat_chain.cli import simulate as simulate_command
from cosserat_chain.io import read_dataset
from cosserat_chain.numerics import dynamics


def test_sigterm_during_a_command_takes_its_ctrl_c_path_and_the_handler_is_given_back(tmp_path, monkeypatch, capsys):
    if signal.getsignal(signal.SIGTERM) is not signal.SIG_DFL:
        pytest.skip("the test runner handles SIGTERM itself")
    monkeypatch.setattr(dynamics, "CHUNK_WORK", 7 * 200)  # chunks of a few hundred steps of the seven-particle chain
    calls = []

    def progress(done, total):
        calls.append(done)
        if len(calls) == 2:
            os.kill(os.getpid(), signal.SIGTERM)

    monkeypatch.setattr(simulate_command, "bar_callback", lambda bar: progress)
    out, checkpoint = tmp_path / "run.nc", tmp_path / "run.checkpoint.nc"
    with pytest.raises(SystemExit) as stopped:
        app(["simulate", "--t-end", "30", "--dt", "0.0173", "--frames", "41", "--out", str(out), "--checkpoint-every", "0"])
    assert stopped.value.code == 130, capsys.readouterr()
    assert signal.getsignal(signal.SIGTERM) is signal.SIG_DFL
    assert "resume" in capsys.readouterr().err
    assert (
        read_dataset(out).attrs["status"] == "interrupted"
        and 0 < read_dataset(checkpoint).attrs["steps"] < read_dataset(checkpoint).attrs["n_steps"]
    )


@pytest.mark.slow
def test_a_run_stopped_by_sigterm_keeps_its_checkpoint_and_says_it_was_interrupted(tmp_path):
    out, checkpoint = tmp_path / "run.nc", tmp_path / "run.checkpoint.nc"
    command = [sys.executable, "-m", "cosserat_chain.cli", "simulate", "--model", "sine", "--moment", "0.3", "--t-end", "1e7"]
    command += ["--frames", "10001", "--out", str(out), "--checkpoint-every", "0"]
    env = {**os.environ, "OMP_NUM_THREADS": "1", "OPENBLAS_NUM_THREADS": "1"}
    run = subprocess.Popen(command, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env)
    try:
        # The first checkpoint is the start's; the signal comes once a chunk of steps (10^8 particle-steps) is kept.
        deadline, done = time.monotonic() + 300, 0
        while not done and run.poll() is None and time.monotonic() < deadline:
            time.sleep(0.1)
            if checkpoint.exists():
                done = int(read_dataset(checkpoint).attrs["steps"])
        assert done, run.communicate(timeout=5)
        run.send_signal(signal.SIGTERM)
        stdout, stderr = run.communicate(timeout=120)
    finally:
        run.kill()
    assert run.returncode == 130, stderr
    assert "resume" in stderr and "Traceback" not in stderr
    assert read_dataset(out).attrs["status"] == "interrupted"
    assert read_dataset(checkpoint).attrs["steps"] >= done
