"""The test suite's own shortcuts keep what they stand for: the read probe skipped only for a file the package wrote
whole in this session (conftest.py), and the scripts and commands run in the test process leave it as it was
(in_process.py)."""

from __future__ import annotations

import os
import signal
import sys

import numpy as np
import pytest
import xarray as xr

import in_process
from cosserat_chain.io import read_dataset, write_dataset
from cosserat_chain.models import base


@pytest.fixture
def forks(monkeypatch) -> list[int]:
    """The forks made while the test runs (the read probe forks a child to open a file's structure)."""
    made = []
    real = os.fork

    def fork():
        pid = real()
        if pid:
            made.append(pid)
        return pid

    monkeypatch.setattr(os, "fork", fork)
    return made


def _dataset() -> xr.Dataset:
    return xr.Dataset({"x": ("i", np.arange(4.0))}, attrs={"what": "test"})


def test_a_file_the_package_wrote_whole_is_read_without_the_probe_and_every_other_with_it(tmp_path, forks):
    path = write_dataset(_dataset(), tmp_path / "whole.nc")
    np.testing.assert_array_equal(read_dataset(path).x, np.arange(4.0))
    assert forks == []
    # The same bytes elsewhere: what the package wrote, whoever copied it.
    copy = tmp_path / "copy.nc"
    copy.write_bytes(path.read_bytes())
    read_dataset(copy)
    assert forks == []
    # One byte of the file changed (its last, under a checksum of HDF5's), or a file xarray wrote itself: probed.
    data = bytearray(path.read_bytes())
    data[-1] ^= 1
    path.write_bytes(bytes(data))
    with pytest.raises(ValueError, match="whole.nc.*checksum"):
        read_dataset(path)
    assert len(forks) == 1
    _dataset().to_netcdf(tmp_path / "xarrays.nc", engine="h5netcdf")
    read_dataset(tmp_path / "xarrays.nc")
    assert len(forks) == 2


def test_a_file_read_through_a_replaced_reader_is_probed(tmp_path, monkeypatch, forks):
    path = write_dataset(_dataset(), tmp_path / "whole.nc")
    real = xr.open_dataset

    def reader(*args, **kwargs):
        return real(*args, **kwargs)

    monkeypatch.setattr(xr, "open_dataset", reader)
    np.testing.assert_array_equal(read_dataset(path).x, np.arange(4.0))
    assert len(forks) == 1


def test_a_cut_file_is_still_refused_by_the_probe_and_the_reader(tmp_path, forks):
    path = write_dataset(_dataset(), tmp_path / "cut.nc")
    path.write_bytes(path.read_bytes()[:1000])
    with pytest.raises(ValueError, match="cut.nc.*not a readable NetCDF file"):
        read_dataset(path)
    assert len(forks) == 1


def test_a_script_run_in_process_leaves_the_process_as_it_was(tmp_path):
    script = tmp_path / "meddles.py"
    script.write_text(
        "import os, signal, sys, warnings\n"
        "import numpy as np\n"
        "from cosserat_chain.models import LinearModel, register_model\n"
        "class Mine(LinearModel):\n    name = 'mine'\n"
        "register_model(Mine())\n"
        "os.chdir('/')\nsys.argv.append('extra')\nsys.path.insert(0, '/nowhere')\n"
        "signal.signal(signal.SIGINT, signal.SIG_IGN)\nwarnings.simplefilter('error')\nnp.seterr(all='raise')\n"
        "sys.stderr = open(os.devnull, 'w')\nprint('done')\nraise SystemExit(4)\n",
        encoding="utf-8",
    )
    before = (os.getcwd(), sys.argv[:], sys.path[:], signal.getsignal(signal.SIGINT), sys.stderr, np.geterr(), dict(base._REGISTRY))
    filters = list(__import__("warnings").filters)
    assert in_process.run_script(script, tmp_path, ("--quick",)) == (4, "done\n", None)
    after = (os.getcwd(), sys.argv, sys.path, signal.getsignal(signal.SIGINT), sys.stderr, np.geterr(), dict(base._REGISTRY))
    assert after == before and list(__import__("warnings").filters) == filters


def test_a_command_run_in_process_gives_its_exit_code_and_its_bar_on_the_terminal(tmp_path):
    assert in_process.run_command(["simulate", "--t-end", "-1"]) == 2
    code, screen = in_process.on_terminal(lambda: in_process.run_command(["simulate", "--t-end", "2"]), tmp_path)
    assert code == 0 and "simulate nonlinear" in screen and "100%" in screen
    code, screen = in_process.on_terminal(lambda: in_process.run_command(["simulate", "--t-end", "2"]) + 1, tmp_path, columns=80)
    assert code == 1
