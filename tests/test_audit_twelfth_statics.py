"""Twelfth audit, statics: M_c where the stable branch from rest ends at a branch point past which a crossing branch is stable.

An audit's symmetric clamped chain (N = 2) has a supercritical pitchfork at M = 1.42447: the branch from rest turns
unstable there, but the chain, loaded slowly, goes on at rest along the crossing (asymmetric) branch, back onto the
symmetric one at its second branch point, up to the fold at M = 2.60411 (a ramped run rests at 2.55, rotates at 2.66).
``critical`` reported the branch point as M_c, 45 % low. The auditor's own minimisation of the corner-spring energy
(the angle held, the other degrees of freedom by Newton) put the crossing branch's maximum at 2.604111 (phi_0 1.414).
"""

import math

import pytest

from cosserat_chain import ChainParams
from cosserat_chain.experiments.critical import critical_point
from cosserat_chain.numerics.relaxation import relax
from cosserat_chain.status import Status

PITCHFORK = ChainParams(
    a=0.44438395337992437, b=0.608385502700794, h=1.4673205056421992, E1=1.2228457546383051, E2=1.6538244045219441, N=2
)
#: A clamped-free chain (N = 1, graded) whose crossing branch past its branch point at M = 0.39951 turns unstable at a
#: branch point of its own before any maximum (ramped runs rest at 0.515, rotate at 0.5205).
NESTED = ChainParams(
    a=0.28220643936837014, b=0.43144255542415944, h=1.1094958815215095, E1=0.6993894966193828, E2=2.467898821401867, N=1,
    right_end="free", E1_factors=(1.703546241701795, 0.7869858890858004), E2_factors=(0.6223289260452691, 1.7828404614306053),
)  # fmt: skip


@pytest.fixture(scope="module")
def pitchfork():
    return critical_point(PITCHFORK, "nonlinear", dynamics=False)


def test_crossing_branch_carries_past_the_branch_point(pitchfork):
    r = pitchfork
    assert r.branch_point is not None and math.isclose(r.branch_point.moment, 1.4244670747, rel_tol=1e-8)
    assert r.onset == "crossing_fold" and r.accurate and not r.crossing_unresolved
    # The auditor's independent value (rotation-controlled minimisation of the exact corner-spring energy, 0.002 rad grid).
    assert math.isclose(r.critical_moment, 2.604111, rel_tol=2e-6)
    assert r.as_dict()["crossing"] == {"moment": r.critical_moment, "phi0": r.phi0_at_onset}


def test_relaxations_around_the_crossing_fold(pitchfork):
    r = pitchfork
    # Just above the branch point the chain rests (the old M_c): it is not the onset of rotation.
    above = relax(PITCHFORK, "nonlinear", 1.01 * r.branch_point.moment, x0=r.branch_point.x)
    assert above.status == Status.STATIC
    below = relax(PITCHFORK, "nonlinear", 0.99 * r.critical_moment, x0=r.crossing.x)
    assert below.status == Status.STATIC
    beyond = relax(PITCHFORK, "nonlinear", 1.01 * r.critical_moment, x0=r.crossing.x)
    assert beyond.status == Status.ROTATING


def test_unresolved_crossing_is_flagged():
    r = critical_point(NESTED, "nonlinear", dynamics=False)
    assert r.onset == "branch_point" and r.crossing is None
    assert r.crossing_unresolved and not r.accurate
    assert r.as_dict()["crossing_unresolved"] is True


def test_files_meet_cf_1_8_which_they_declare(tmp_path):
    """Every file declares "CF-1.8 CF-1.10"; CF-1.8 has no 64-bit integers, and a run's ``particle`` and ``phi_winding``
    were int64 (compliance-checker cf:1.8: "the datatype is int64"). They are written as int32 where they fit."""
    pytest.importorskip("compliance_checker", reason="compliance-checker is not installed (pip install -e .[test])")
    import json

    import numpy as np
    import xarray as xr
    from compliance_checker.runner import CheckSuite, ComplianceChecker
    from typer.testing import CliRunner

    from cosserat_chain.cli import app
    from cosserat_chain.io import read_dataset

    out = tmp_path / "run.nc"
    result = CliRunner().invoke(app, ["simulate", "--moment", "0.3", "--t-end", "20", "--frames", "5", "--out", str(out)])
    assert result.exit_code == 0, result.output
    with xr.open_dataset(out, engine="h5netcdf") as ds:
        assert ds["particle"].dtype == np.int32
        assert not [name for name, variable in ds.variables.items() if variable.dtype == np.int64]
    assert read_dataset(out)["particle"].values.tolist() == list(range(-3, 4))
    CheckSuite.load_all_available_checkers()
    report = tmp_path / "report.json"
    ComplianceChecker.run_checker(str(out), ["cf:1.8"], 0, "normal", output_filename=str(report), output_format="json")
    errors = [m for r in json.loads(report.read_text())["cf:1.8"]["high_priorities"] for m in r["msgs"]]
    assert errors == []
