"""The study's cluster: it listens on 127.0.0.1 only, a silent or foreign scheduler cannot hang it, and a study or sweep
that produced nothing says so with its exit code (issue 48)."""

from __future__ import annotations

import json
import socket
import threading
from collections.abc import Iterator
from contextlib import contextmanager

import psutil
import pytest
from typer.testing import CliRunner

import cosserat_chain.study_runner as study_runner
from cosserat_chain.cli import app
from cosserat_chain.experiments.study import spec_from_mapping

runner = CliRunner()

#: Two cheap cells (a static compliance each), computed one per task so that the progress
#: callback runs while the cluster is up.
CHEAP = {"models": ["sine"], "quantities": ["compliance"], "parameters": {"a": [0.1, 0.2]}}
#: Two cells whose relaxation refuses its time step (beyond the stability limit of E1 = 1000 and 2000).
FAILING = {"parameters": {"E1": [1000.0, 2000.0]}, "models": ["sine"], "quantities": ["onset_load"], "sweep": {"m_max": 0.3, "dm": 0.1, "dt": 0.05}}
LOOPBACK = {"127.0.0.1", "::1"}


def _listening(process: psutil.Process) -> list[tuple[int, str, int]]:
    """(pid, ip, port) of every listening internet socket of ``process`` and its descendants."""
    found = []
    for proc in [process, *process.children(recursive=True)]:
        try:
            connections = proc.net_connections(kind="inet")
        except psutil.Error:  # a child that ended meanwhile
            continue
        found += [(proc.pid, c.laddr.ip, c.laddr.port) for c in connections if c.status == psutil.CONN_LISTEN]
    return found


# First of the file: the shared cluster (conftest.py) closes after its last user, not idle through the tests below.
def test_a_study_whose_every_cell_failed_exits_3_and_a_partial_one_says_how_many(dask_cluster, tmp_path):
    spec = tmp_path / "failing.toml"
    spec.write_text(
        'models = ["sine"]\nquantities = ["onset_load"]\n[parameters]\nE1 = [1000.0, 2000.0]\n[sweep]\nm_max = 0.3\ndm = 0.1\ndt = 0.05\n'
    )
    result = runner.invoke(app, ["study", str(spec), "--scheduler", dask_cluster.scheduler_address, "--json"])
    assert result.exit_code == 3, result.output
    assert json.loads(result.stdout.splitlines()[0])["failed"] == 2
    assert "no cell succeeded" in result.stderr and "2 of 2 cells failed" in result.stderr and "stability limit" in result.stderr
    spec.write_text(spec.read_text().replace("E1 = [1000.0, 2000.0]", "E1 = [1.0, 1000.0]"))
    result = runner.invoke(app, ["study", str(spec), "--scheduler", dask_cluster.scheduler_address])
    assert result.exit_code == 0, result.output
    assert "1 of 2 cells failed" in result.stderr


# With the dashboard the cluster opens every listener it opens without one, and the dashboard's: the quick case.
@pytest.mark.parametrize("dashboard", [pytest.param(False, marks=pytest.mark.slow), True], ids=["no-dashboard", "dashboard"])
def test_the_embedded_cluster_listens_on_loopback_only(dashboard):
    sockets: list[tuple[int, str, int]] = []
    addresses: list[str] = []

    def look(done, total):
        if done:  # a chunk arrived: the cluster is up
            sockets.extend(_listening(psutil.Process()))

    # One worker: a second one is a process of the same kind, listening as the first (and importing the package again).
    run = study_runner.run_study(
        spec_from_mapping(CHEAP), workers=1, chunk=1, progress=look, dashboard=addresses.append if dashboard else None
    )
    assert run.completed and run.computed == 2
    # the scheduler's process and the worker's: several listeners, every one on loopback
    assert len({pid for pid, _, _ in sockets}) >= 2, sockets
    assert {ip for _, ip, _ in sockets} <= LOOPBACK, sockets
    if dashboard:
        assert len(addresses) == 1 and addresses[0].startswith("http://127.0.0.1:")
        port = int(addresses[0].split(":")[2].split("/")[0])
        assert port in {p for _, _, p in sockets}
    else:
        assert not addresses


@contextmanager
def _fake_scheduler(behaviour: str) -> Iterator[str]:
    """A TCP server on 127.0.0.1 that accepts connections and then stays silent, or answers bytes that are not Dask's."""
    server = socket.socket()
    server.bind(("127.0.0.1", 0))
    server.listen(8)
    kept = []

    def serve():
        while True:
            try:
                conn, _ = server.accept()
            except OSError:
                return
            kept.append(conn)
            if behaviour == "garbage":
                conn.sendall(b"HTTP/1.1 200 OK\r\nContent-Length: 5\r\n\r\nhello" * 8)

    threading.Thread(target=serve, daemon=True).start()
    try:
        yield f"tcp://127.0.0.1:{server.getsockname()[1]}"
    finally:
        server.close()
        for conn in kept:
            conn.close()


def _free_port() -> int:
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        return probe.getsockname()[1]


@pytest.mark.parametrize("behaviour", ["silent", "garbage", "refused"])
def test_a_scheduler_that_does_not_answer_as_dask_fails_within_the_timeout(behaviour, monkeypatch):
    monkeypatch.setattr(study_runner, "CONNECT_TIMEOUT", 2.0)
    outcome: list[BaseException | None] = []

    def attempt(address):
        try:
            study_runner.run_study(spec_from_mapping(CHEAP), scheduler=address)
            outcome.append(None)
        except BaseException as err:
            outcome.append(err)

    if behaviour == "refused":
        context = _nothing_listens()
    else:
        context = _fake_scheduler(behaviour)
    with context as address:
        worker = threading.Thread(target=attempt, args=(address,), daemon=True)
        worker.start()
        # a hang, not a slow refusal, is what this bounds: the timeout is 2 s
        worker.join(60)
    assert not worker.is_alive(), f"run_study still waits on a {behaviour} scheduler after 60 s"
    assert isinstance(outcome[0], study_runner.ClusterError), outcome
    assert address in str(outcome[0])
    expected = {"silent": "within 2 s", "garbage": "not as a Dask scheduler", "refused": "cannot reach"}[behaviour]
    assert expected in str(outcome[0])


@contextmanager
def _nothing_listens() -> Iterator[str]:
    yield f"tcp://127.0.0.1:{_free_port()}"


def test_the_cli_refuses_a_silent_scheduler_with_exit_2(tmp_path, monkeypatch):
    monkeypatch.setattr(study_runner, "CONNECT_TIMEOUT", 1.0)
    spec = tmp_path / "spec.toml"
    spec.write_text('models = ["sine"]\nquantities = ["compliance"]\n[parameters]\na = [0.1]\n')
    out = tmp_path / "study.nc"
    with _fake_scheduler("silent") as address:
        result = runner.invoke(app, ["study", str(spec), "--scheduler", address, "--out", str(out)])
    assert result.exit_code == 2, result.output
    assert "no Dask scheduler answered" in result.output and address in result.output
    assert not out.exists()


def test_a_sweep_with_no_converged_step_exits_3_and_a_partial_one_warns():
    # t_max far below the relaxation time: no step can settle
    result = runner.invoke(app, ["sweep", "--model", "sine", "--m-max", "0.3", "--steps", "3", "--t-max", "0.5", "--json"])
    assert result.exit_code == 3, result.output
    assert json.loads(result.stdout.splitlines()[0])["models"]["sine"]["status"] == ["not_converged"] * 3
    assert "no load step converged" in result.stderr
    # at t_max = 150 the step at M = 0.26 rotates steadily while the one at 0.13 is still ringing down
    result = runner.invoke(app, ["sweep", "--model", "sine", "--m-max", "0.26", "--steps", "2", "--t-max", "150", "--json"])
    assert result.exit_code == 0, result.output
    assert json.loads(result.stdout.splitlines()[0])["models"]["sine"]["status"] == ["not_converged", "rotating"]
    assert "1 of 2 load steps neither came to rest nor rotated steadily" in result.stderr
