"""The report's roto-breather section: its tables equal the Python API's families, its figure and data are written."""

from __future__ import annotations

import json

import pytest

from cosserat_chain.experiments.breathers import roto_breather_family
from cosserat_chain.params import ChainParams
from cosserat_chain.report.breathers import NONLINEAR_OMEGAS, REPORT_N, SINE_OMEGAS


def test_the_roto_breather_section_shows_the_families_of_the_python_api(quick_report_and_figures):
    """The session's quick report (conftest.py; the section reads neither the sweeps nor the runs its settings
    shorten: its chain and frequencies are fixed) wrote the section, its data and its figure. Each family is continued from
    its first frequency to the next: the API's first orbits of it (to the first unstable one), recomputed here, are the
    table's first rows."""
    result, figures = quick_report_and_figures
    out = result.out
    (section,) = [s for s in result.sections if s.title.startswith("Roto-breathers")]
    assert not section.error
    data = json.loads((out / "data" / "roto_breathers.json").read_text())
    params = ChainParams(N=REPORT_N, gamma_u=0.0, gamma_v=0.0, gamma_phi=0.0)
    for model, omegas, first in (("sine", SINE_OMEGAS, 6), ("nonlinear", NONLINEAR_OMEGAS, 2)):
        assert data[model]["omega"] == pytest.approx(list(omegas), rel=1e-14)
        family = roto_breather_family(params, model, list(omegas[:first])).as_dict()
        assert data[model]["max_multiplier"][:first] == pytest.approx(family["max_multiplier"], rel=1e-8)
        assert data[model]["stable"][:first] == family["stable"]
    # Stable above the infinite chain's combination edge w_TA + w_RO (6.373), unstable well below it.
    sine = dict(zip(data["sine"]["omega"], data["sine"]["stable"]))
    assert data["combination_edge"] == pytest.approx(1.5689290811 + 4.8038446142, rel=1e-9)
    assert all(sine[o] for o in sine if o > data["combination_edge"]) and not any(sine[o] for o in sine if o < 5.9)
    text = (out / "report.md").read_text()
    assert "Roto-breathers" in text and (out / "figures" / "roto_breathers_sine.png").stat().st_size > 0
    assert "roto_breathers_sine" in figures
