"""The command line's start-up: a run imports only what its command uses, and says the same as the whole application.

``cosserat-chain critical ...`` imports the module of ``critical`` alone (``cli.COMMAND_MODULES``);
``--help``, a wrong name and a test's runner see every command. Each run is a fresh interpreter, where
``sys.modules`` tells what it imported; the whole application it is compared with is this process's.
"""

from __future__ import annotations

import json

import pytest
from typer.testing import CliRunner

import cosserat_chain.cli as cli
from cosserat_chain.cli import app
from fresh_cli import fresh_run

runner = CliRunner()


def test_the_table_of_command_modules_is_what_the_modules_register_in_the_order_of_help():
    registered = app.registered_commands  # every command module imported
    names = [info.name or info.callback.__name__ for info in registered]
    assert names == list(cli.COMMAND_MODULES)
    for info, name in zip(registered, names, strict=True):
        assert info.callback.__module__ == f"cosserat_chain.cli.{cli.COMMAND_MODULES[name]}"


def test_critical_json_imports_its_own_command_module_and_no_data_or_plot_library():
    done, probe = fresh_run("critical", "--model", "sine", "--json")
    assert done.returncode == 0, done.stderr
    command_modules = {f"cosserat_chain.cli.{module}" for module in cli.COMMAND_MODULES.values()}
    assert command_modules & set(probe["modules"]) == {"cosserat_chain.cli.statics"}
    heavy = {"xarray", "pandas", "dask", "distributed", "matplotlib", "h5netcdf", "scipy.optimize", "mpmath", "sympy"}
    assert heavy.isdisjoint(probe["modules"])
    # the same result, bit for bit, as the whole application gives in this process
    assert done.stdout == runner.invoke(app, ["critical", "--model", "sine", "--json"]).stdout
    assert probe["frozen"] > 0  # the objects alive at exit were frozen out of the teardown's collections


def test_a_run_naming_a_command_prints_the_same_help_and_errors_as_the_whole_application():
    """The fresh interpreter's lazy run against the whole application of this process (every command module
    registered), run by the test runner under the command's name at the width Click takes from the fresh run's
    ``COLUMNS=80`` (80 - 2)."""
    assert len(app.registered_commands) == len(cli.COMMAND_MODULES)  # every command module imported
    for args in (["critical", "--help"], ["animate", "--help"], ["critical", "--model", "pendulum"], ["--help"], ["critcal"]):
        done, probe = fresh_run(*args)
        whole = runner.invoke(app, args, prog_name="cosserat-chain", terminal_width=78)
        assert (done.returncode, done.stdout, done.stderr.splitlines()[:-1]) == (whole.exit_code, whole.stdout, whole.stderr.splitlines())
        assert done.stdout or done.stderr.count("\n") > 1, args  # it said something (the probe's line last)
        loaded = {module for module in cli.COMMAND_MODULES.values() if f"cosserat_chain.cli.{module}" in probe["modules"]}
        named = args[0] in cli.COMMAND_MODULES
        assert loaded == ({cli.COMMAND_MODULES[args[0]]} if named else set(cli.COMMAND_MODULES.values())), args


def test_critical_json_on_the_papers_chain_computes_every_verdict_without_scipys_sparse_solvers():
    # The sine model's dynamic verdict at every traced point comes from the band (numerics.stability), the folds
    # and stability from band factors: SuperLU, ARPACK and the graph routines are imported only where used.
    done, probe = fresh_run("critical", "--json")
    assert done.returncode == 0, done.stderr
    assert {"scipy.sparse.linalg", "scipy.sparse.csgraph", "scipy.optimize"}.isdisjoint(probe["modules"])
    sine = json.loads(done.stdout)["models"]["sine"]
    assert sine["dynamics"]["verdict_from"] == "eigenvalues" and len(sine["branch"]["unstable_eigenvalues"]) == len(sine["branch"]["phi0"])
    assert 0 in sine["branch"]["unstable_eigenvalues"] and 1 in sine["branch"]["unstable_eigenvalues"]  # both sides of the fold


@pytest.mark.parametrize("args", [["--version"], ["--help"], ["critical", "--help"]])
def test_help_and_version_import_no_compiled_library(args):
    done, probe = fresh_run(*args)
    assert done.returncode == 0, done.stderr
    assert {"numba", "scipy", "xarray"}.isdisjoint(probe["modules"])


def test_the_written_out_two_pi_of_the_angle_reduction_is_mpmaths():
    """models.trig.TWO_PI_SCALED (a literal, so that reducing a start angle imports no mpmath) is floor(2 pi 2^256)."""
    import mpmath

    from cosserat_chain.models import trig

    with mpmath.workprec(320):
        assert trig.TWO_PI_SCALED == int(mpmath.floor(2 * mpmath.pi * 2**256))
    with mpmath.workprec(640):  # and not a rounding of the working precision
        assert trig.TWO_PI_SCALED == int(mpmath.floor(2 * mpmath.pi * 2**256))
