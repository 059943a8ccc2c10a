"""The report's answer to the paper's open problem: its numbers against the discrete chain solved here, its figure against its data."""

from __future__ import annotations

import json

import numpy as np

from conftest import random_geometries
from cosserat_chain.analysis.continuum import convergence
from cosserat_chain.analysis.which_continuum import DEFAULT_N
from cosserat_chain.report import reproduce
from test_report import QUICK


def test_the_report_states_the_orders_of_both_continua_from_its_own_data(tmp_path):
    params = random_geometries(1, seed=7)[0]
    result = reproduce(tmp_path, params=params, settings=QUICK, stages=["which_continuum"])
    (section,) = result.sections
    assert section.error is None, section.error
    data = json.loads((tmp_path / "data" / "which_continuum.json").read_text())
    beam = data["timoshenko"]
    n = np.array(beam["N"])
    assert list(n) == list(DEFAULT_N)
    # the discrete compliances are the package's exact clamped solve (Section 3's comparison), chain by chain
    table = convergence(params, n)
    np.testing.assert_allclose(beam["discrete"], table.discrete, rtol=1e-9)
    # eq. (11) is the paper's continuum of the same table
    np.testing.assert_allclose(beam["paper"], table.continuum, rtol=1e-12)
    # the measured orders over the longest chains: 2 for the beam, 1 for eq. (11)
    t_err, p_err = np.abs(beam["timoshenko_error"]), np.abs(beam["paper_error"])
    assert np.log(t_err[-2] / t_err[-1]) / np.log(n[-1] / n[-2]) > 1.8
    assert 0.8 < np.log(p_err[-2] / p_err[-1]) / np.log(n[-1] / n[-2]) < 1.2
    text = " ".join(section.paragraphs)
    assert f"{beam['timoshenko_error'][-1]:+.1e}" in text and f"{beam['paper_error'][-1]:+.1e}" in text
    assert (tmp_path / "figures" / "which_continuum.png").stat().st_size > 10_000
    html = (tmp_path / "index.html").read_text()
    assert "Which continuum?" in html and "figures/which_continuum.svg" in html
