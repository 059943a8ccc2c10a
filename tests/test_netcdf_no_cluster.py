"""io.netcdf_image: a NetCDF file is made without importing Dask's ``distributed``, with the same contents as with it."""

import subprocess
import sys
import textwrap

import numpy as np
import xarray as xr

from cosserat_chain import io

SCRIPT = textwrap.dedent(
    """
    import sys
    import numpy as np, xarray as xr
    from cosserat_chain import io
    data = xr.Dataset({"a": (("x",), np.arange(4.0))}, coords={"x": np.arange(4.0)})
    io.netcdf_image(data)
    written_without = "distributed" not in sys.modules
    import distributed  # not left blocked after the write
    print(written_without, distributed.Client.__name__)
    """
)


def test_a_write_in_a_fresh_process_leaves_distributed_unimported_and_importable():
    done = subprocess.run([sys.executable, "-c", SCRIPT], capture_output=True, text=True, check=True)
    assert done.stdout.split() == ["True", "Client"]


def _dataset() -> xr.Dataset:
    rng = np.random.default_rng(7)
    data = xr.Dataset(
        {"force": (("time", "particle"), rng.standard_normal((6, 3)), {"units": "N", "note": "a"})},
        coords={"time": np.linspace(0.0, 1.0, 6), "particle": np.arange(3), "model": "nonlinear"},
        attrs={"converged": True, "title": "x"},
    )
    return data


def _read(image: memoryview) -> xr.Dataset:
    from io import BytesIO

    return xr.open_dataset(BytesIO(bytes(image)), engine="h5netcdf").load()


def test_the_file_is_the_same_as_the_one_written_with_distributed_imported(monkeypatch):
    """The branch where ``distributed`` is imported (xarray then asks it for a client) and the one where it is hidden
    give files with the same variables, values, attributes and encodings (but the time of writing in ``history``)."""
    import distributed  # noqa: F401  (the first branch: imported, so not hidden)

    with_it = _read(io.netcdf_image(_dataset()))
    monkeypatch.delitem(sys.modules, "distributed")
    without = _read(io.netcdf_image(_dataset()))
    assert "distributed" not in sys.modules
    assert with_it.attrs.pop("history")[:4] == without.attrs.pop("history")[:4]
    xr.testing.assert_identical(with_it, without)
    for name in with_it.variables:
        first, second = ({k: str(v) for k, v in data[name].encoding.items() if k != "source"} for data in (with_it, without))
        assert first == second
