"""``cosserat-chain critical --json`` on the paper's chain, every model, in a fresh interpreter: it computes each model's
verdict and loads no data, plot or symbolic library (issue 44, item 3: a --json run pays for what it computes only).

The run is :func:`fresh_cli.fresh_run`'s, shared with test_cli_startup.py's; ``sys.modules`` at exit tells what it loaded.
"""

from __future__ import annotations

import json

from fresh_cli import fresh_run

#: Libraries a --json run of a computing command has no use for: files (xarray, pandas, Dask, the NetCDF engine), plots,
#: and the symbolic derivation (SymPy and its mpmath).
NOT_FOR_JSON = ("xarray", "pandas", "dask", "distributed", "h5netcdf", "netCDF4", "matplotlib", "sympy", "mpmath")


def test_critical_json_of_every_model_loads_no_data_plot_or_symbolic_library():
    done, probe = fresh_run("critical", "--json")
    assert done.returncode == 0, done.stderr
    # the three built-in models were computed, so their kernels were loaded: the check below is not vacuous
    assert set(json.loads(done.stdout)["models"]) == {"nonlinear", "sine", "linear"}
    assert {"numba", "cosserat_chain.models.nonlinear", "cosserat_chain.experiments.critical"} <= set(probe["modules"])
    loaded = {name for name in probe["modules"] if name.split(".")[0] in NOT_FOR_JSON}
    assert loaded == set(), sorted(loaded)
