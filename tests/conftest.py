"""Shared fixtures and the tolerances of the test suite (kept in one place)."""

from __future__ import annotations

import gc
import hashlib
import os
from pathlib import Path

# One BLAS thread, set before NumPy loads (the test processes' children inherit it): the suite's
# dense matrices are small, and OpenBLAS's threads spinning on them cost many times the work
# on a loaded 2-core machine without changing a result the tests check.
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
# The Dask clusters of the studies' tests (the shared one below, the commands' embedded ones, worker processes of the
# test's own), which live for minutes of a session and mostly wait: without the statistical profiler that samples every
# worker's threads a hundred times a second, and with the event loops' liveness checks and the system monitor's
# samples less often. Their work and results are the same; dask reads these when it loads, the workers inherit them.
os.environ.setdefault("DASK_DISTRIBUTED__WORKER__PROFILE__ENABLED", "False")
os.environ.setdefault("DASK_DISTRIBUTED__ADMIN__TICK__INTERVAL", "1s")
os.environ.setdefault("DASK_DISTRIBUTED__ADMIN__SYSTEM_MONITOR__INTERVAL", "5s")

import numpy as np  # noqa: E402
import pytest  # noqa: E402
import typer.testing  # noqa: E402

from cosserat_chain import ChainParams  # noqa: E402
from cosserat_chain.state import fixed_mask  # noqa: E402

#: Where the tests keep the systems they compile from formulas (``COSSERAT_CHAIN_CACHE``): in the checkout, ignored by
#: git, and kept between sessions as Numba keeps the package's own kernels, so that a session compiles only the systems
#: it has not met before; a system's file is named by the hash of its generated code, so nothing in it goes stale.
SYSTEMS_CACHE = Path(__file__).resolve().parents[1] / ".pytest_cache" / "cosserat-chain"

#: Round-off level for exact identities between independent implementations.
ROUND_OFF = 1e-12
#: Central finite differences with step FD_STEP are accurate to about FD_STEP^2.
FD_STEP = 1e-6
FD_TOL = 1e-7


def random_geometries(count: int, seed: int = 0) -> list[ChainParams]:
    """Valid random chains: a in (0.05, 0.45) h, b in (0.05, 0.6) h, E2/E1 in (0, 3)."""
    rng = np.random.default_rng(seed)
    out = []
    for _ in range(count):
        h = rng.uniform(0.5, 2.0)
        out.append(
            ChainParams(
                E1=rng.uniform(0.5, 2.0),
                E2=rng.uniform(0.0, 3.0),
                h=h,
                a=rng.uniform(0.05, 0.45) * h,
                b=rng.uniform(0.05, 0.6) * h,
                m=rng.uniform(0.5, 2.0),
                N=int(rng.integers(2, 6)),
            )
        )
    return out


def undamped_energies(orbit, samples: int) -> np.ndarray:
    """A system's orbit's kinetic plus potential energy with its damping off, at ``samples`` times spread evenly over one
    period (samples,): constant along an undamped (Hamiltonian) orbit."""
    system = orbit.system.with_parameters(gamma=0.0)
    n = system.size
    states = orbit.trajectory(orbit.period * np.linspace(0.0, 1.0, samples))
    return np.array([system.energy(y[:n]) + 0.5 * np.sum(system.mass() * y[n:] ** 2) for y in states])


def random_state(params: ChainParams, scale: float, seed: int = 0) -> np.ndarray:
    """A random configuration, zero where the ends hold it; ``scale`` sets |u|, |v| (in h) and |phi|."""
    rng = np.random.default_rng(seed)
    x = np.zeros((3, params.n_particles))
    x[:, 1:-1] = scale * rng.standard_normal((3, params.n_particles - 2))
    ends = scale * rng.standard_normal((3, 2))
    x[:, [0, -1]] = np.where(fixed_mask(params)[:, [0, -1]], 0.0, ends)
    x[:2] *= params.h
    return x


@pytest.fixture(autouse=True)
def _frozen_heap():
    """What the session made before a test (the imported libraries, the shared fixtures' results) is left out of the
    garbage collector's passes while the test runs, and collected as before afterwards: a refused file ends in
    ``gc.collect()`` (``io.read_dataset``), which would otherwise walk every object of the session each time."""
    gc.freeze()
    yield
    gc.unfreeze()


def _command_built_once(app):
    """The Click command of a Typer ``app``, built once a session as the installed command builds it once a process:
    ``CliRunner().invoke`` would build it again at every call (each command's signature and annotations read anew).
    Keyed by the app and its registered commands and groups, so an app changed in between is built again."""
    key = (
        id(app),
        tuple(id(info.callback) for info in app.registered_commands),
        tuple(id(g.typer_instance) for g in app.registered_groups),
    )
    if key not in _COMMANDS:
        _COMMANDS[key] = (app, _build_command(app))
    return _COMMANDS[key][1]


_COMMANDS: dict = {}
_build_command = typer.testing._get_command
typer.testing._get_command = _command_built_once


#: Digests of the NetCDF images ``io.netcdf_image`` made in this session (every file the package writes in the test
#: process, through ``write_dataset`` or the commands' writer).
WRITTEN_IMAGES: set[bytes] = set()
#: Files larger than this are probed without being read for their digest.
_DIGEST_MAX_BYTES = 1 << 26


def _digest(data) -> bytes:
    return hashlib.blake2b(data, digest_size=16).digest()


def _image_remembered(make):
    def netcdf_image(dataset):
        image = make(dataset)
        WRITTEN_IMAGES.add(_digest(image))
        return image

    return netcdf_image


def _probe_unless_written_whole(probe):
    """``io.read_dataset``'s probe, which opens a file's structure in a forked child (the parent's whole memory mapped
    again, the reader's imports touched), skipped for a file whose bytes are an image the package made in this session
    and read by xarray's own ``open_dataset``: h5netcdf wrote it whole, and the probe finds nothing in it. A file damaged,
    cut short, edited or written by another process, and every file a test reads through a reader it replaced, is
    probed as before (test_suite_shortcuts.py)."""

    def probe_structure(path):
        import xarray

        if _xarrays_own(xarray.open_dataset) and os.stat(path).st_size <= _DIGEST_MAX_BYTES:
            try:
                if _digest(Path(path).read_bytes()) in WRITTEN_IMAGES:
                    return None
            except OSError:  # unreadable here: the probe and the reader say so
                pass
        return probe(path)

    return probe_structure


def _xarrays_own(function) -> bool:
    """Whether ``function`` is xarray's, not a test's replacement."""
    return getattr(function, "__module__", "").split(".")[0] == "xarray"


def _shortcut_the_read_probe() -> None:
    import cosserat_chain.cli.common as common
    import cosserat_chain.io as io

    io.netcdf_image = _image_remembered(io.netcdf_image)
    common.netcdf_image = io.netcdf_image
    io._probe_structure = _probe_unless_written_whole(io._probe_structure)


_shortcut_the_read_probe()


#: The running cluster of ``dask_cluster``, and the last test of the session that uses it.
_DASK: dict = {}


@pytest.fixture(scope="session")
def dask_cluster():
    """One local Dask cluster of two worker processes for the studies of test_study.py and test_study_cluster.py whose
    claim is not about the cluster a command starts itself (each start imports the package in its workers again; these
    workers are forked from the test process, its imports and kernels already loaded, where a command's are spawned).
    Started by the first test that asks for it and closed after the last: an idle cluster's heartbeats cost CPU."""
    if "cluster" not in _DASK:
        import dask
        import dask.distributed

        with dask.config.set({"distributed.worker.multiprocessing-method": "fork"}):
            _DASK["cluster"] = dask.distributed.LocalCluster(
                n_workers=2, threads_per_worker=1, processes=True, host="127.0.0.1", dashboard_address=None
            )
    return _DASK["cluster"]


def pytest_collection_finish(session):
    users = [item for item in session.items if "dask_cluster" in getattr(item, "fixturenames", ())]
    _DASK["last"] = users[-1] if users else None


def pytest_runtest_teardown(item, nextitem):
    if item is _DASK.get("last") and "cluster" in _DASK:
        _DASK.pop("cluster").close()


def pytest_sessionfinish(session):
    if "cluster" in _DASK:  # a session stopped before the last user (-x)
        _DASK.pop("cluster").close()


def selected_params(request: pytest.FixtureRequest, argname: str) -> list:
    """The values of the parameter ``argname`` among the tests of the requesting module this session runs, in order: a
    module fixture that computes every case at once (one interpreter for all the docs pages or examples) computes only
    these, so a case marked slow costs nothing in the quick suite. Other modules' parameters of the same name are not
    its cases."""
    values = []
    for item in request.session.items:
        callspec = getattr(item, "callspec", None)
        if getattr(item, "module", None) is not request.module:
            continue
        if callspec is not None and argname in callspec.params and callspec.params[argname] not in values:
            values.append(callspec.params[argname])
    return values


@pytest.fixture
def paper() -> ChainParams:
    """The paper's Section 4 chain (seven particles)."""
    return ChainParams()


@pytest.fixture(scope="session")
def paper_sine_orbit():
    """The paper chain's one-turn rotating state of the sine model at M = 0.22 (default damping), found once a session."""
    from cosserat_chain.numerics.periodic import find_periodic_orbit

    return find_periodic_orbit(ChainParams(), "sine", 0.22)


@pytest.fixture(scope="session")
def paper_sine_branch(paper_sine_orbit):
    """``paper_sine_orbit`` continued down in M to its fold of cycles (``moment_min=0.1``; the dense method, the one
    ``auto`` takes for seven particles), computed once for the tests of test_periodic.py and test_long_orbits.py."""
    from cosserat_chain.numerics.periodic import continue_orbit

    return continue_orbit(paper_sine_orbit, moment_min=0.1)


@pytest.fixture(scope="session")
def pen_in_phase_orbit():
    """AUTO-07p's demo ``pen`` (defaults): its in-phase rotation at I = 0.4, found from a settled run once a session."""
    from cosserat_chain.numerics import shooting
    from cosserat_chain.systems import pen

    with pytest.MonkeyPatch.context() as patch:
        patch.setenv("COSSERAT_CHAIN_CACHE", str(SYSTEMS_CACHE))  # the compiled system kept with the tests' others
        system = pen()
        guess = shooting.settled_guess(system, np.array([0.0, 0.0, 2.0, 2.0]), coordinate="phi_0")
        return shooting.find_orbit(system, guess, turns={"phi_0": 1, "phi_1": 1})


@pytest.fixture(scope="session")
def pen_in_phase_branch(pen_in_phase_orbit):
    """``pen_in_phase_orbit`` followed down in I to its period doubling (``max_points=60``), traced once a session for
    test_systems.py, test_cycle_switching.py, test_cycle_switching_branch_points.py and test_system_cycle_curve.py
    (none of them changes it)."""
    from cosserat_chain.numerics import shooting

    return shooting.continue_orbits(pen_in_phase_orbit, "I", direction=-1, max_points=60, stop_at=("period_doubling",))


def quick_report_settings():
    """The quick report's settings: short sweeps, runs and chain lists; the sine chain's state diagram at two dampings."""
    from cosserat_chain.report import ReproduceSettings

    return ReproduceSettings(
        dm=0.05,
        turns=15,
        n_list=(3, 10, 30),
        long_n_list=(3, 10),
        snapshot_times=(20.0, 21.0),
        animation_frames=10,
        diagram_damping={"sine": (0.2, 0.5), "nonlinear": ()},
    )


@pytest.fixture(scope="session")
def quick_report_and_figures(tmp_path_factory):
    """(report, {stem: Figure}) of one quick report of the paper's chain, computed once for the tests of the report
    and of its figures (each figure as the stage drew it, before saving)."""
    import cosserat_chain.report as report_module

    figures = {}
    keep = report_module._Stage.figure

    def figure(self, fig, stem):
        figures[stem] = fig
        return keep(self, fig, stem)

    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(report_module._Stage, "figure", figure)
        # Every stage in this process, so that the figures of the ones that would run beside the others
        # (report.background, tested on its own) are caught here too.
        patch.setattr(report_module.background, "start", lambda *args, **kwargs: None)
        report = report_module.reproduce(tmp_path_factory.mktemp("report"), settings=quick_report_settings())
    return report, figures
