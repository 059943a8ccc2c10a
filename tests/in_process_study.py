"""A study's cells computed by a Dask cluster of threads in the test process, for tests whose claim is about the
study's files, not its cluster.

The embedded cluster of ``study_runner`` starts worker processes, each importing the package again; the tests
of the cluster itself (test_study.py, test_study_cluster.py) keep it. A test that only needs a study to run
(to write a file that is then damaged, or to fill a full disk) takes this one.
"""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager

import pytest

import cosserat_chain.study_runner as study_runner


@contextmanager
def _threads_client(scheduler, workers, dashboard) -> Iterator[tuple[object, int]]:
    from dask.distributed import Client, LocalCluster

    with LocalCluster(n_workers=1, threads_per_worker=1, processes=False, dashboard_address=None) as cluster:
        with Client(cluster, set_as_default=False) as client:
            yield client, 1


@pytest.fixture
def study_in_process(monkeypatch):
    """``study_runner``'s embedded cluster replaced by one worker thread in this process."""
    monkeypatch.setattr(study_runner, "_client", _threads_client)
