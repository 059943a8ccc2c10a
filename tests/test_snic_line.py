"""The SNIC point's line, one printer for ``diagram`` and ``diagram --system``.

Both commands print where the homoclinic end meets the static fold with
:func:`cosserat_chain.cli.common.snic_line`; checked here on each of its three forms (solved,
extrapolated, not located), and through each command's own printing with a stand-in diagram.
"""

from __future__ import annotations

from types import SimpleNamespace

import pytest
from typer.testing import CliRunner

from cosserat_chain.cli import app
from cosserat_chain.cli.common import snic_line
from cosserat_chain.cli.systems import _echo_diagram
from cosserat_chain.experiments import diagram as chain_diagram

SOLVED = {
    "between": [0.128, 0.14],
    "method": "solved",
    "value": 0.13323601631862,
    "accuracy": 1.2e-10,
    "moment": 0.46769230769,
    "drive": 1.0,
}
EXTRAPOLATED = {"between": [1.1, 1.25], "method": "extrapolated", "value": 1.19391, "from": [1.1, 1.15], "reason": "the solve failed"}
NOT_LOCATED = {"between": [1.1, 1.25], "method": "not_located", "value": None, "drive": None, "reason": "no homoclinic row"}


def test_each_form_of_the_snic_line():
    assert snic_line(SOLVED, "gamma_phi", "M_c", "M_c", SOLVED["moment"]) == (
        "the homoclinic end meets M_c (a SNIC from there on) between gamma_phi = 0.128 and 0.14: "
        "gamma_phi = 0.1332360163186 +- 1e-10 (solved by the augmented system, M_c = 0.4676923077 there)"
    )
    assert snic_line(EXTRAPOLATED, "eps", "the fold", "I", None) == (
        "the homoclinic end meets the fold (a SNIC from there on) between eps = 1.1 and 1.25: "
        "eps = 1.19391, extrapolated from eps = 1.1, 1.15 (the solve failed)"
    )
    assert snic_line(NOT_LOCATED, "eps", "the fold", "I", None).endswith(
        "between eps = 1.1 and 1.25: eps = not located (no homoclinic row)"
    )


@pytest.mark.parametrize("point", [SOLVED, NOT_LOCATED])
def test_the_system_diagram_prints_the_shared_line(point, capsys):
    result = SimpleNamespace(system=SimpleNamespace(name="pen"), vary="eps", drive="I", rows=[], snic_point=point, codim2_between=None)
    _echo_diagram(result)
    assert snic_line(point, "eps", "the fold", "I", point.get("drive")) in capsys.readouterr().out.splitlines()


@pytest.mark.parametrize("point", [SOLVED, EXTRAPOLATED])
def test_the_chain_diagram_prints_the_shared_line(point, monkeypatch):
    stand_in = SimpleNamespace(rows=[], snic_point=point, codim2_between=None, independent=False, vary="gamma_phi", to_dataset=lambda: None)
    monkeypatch.setattr(chain_diagram, "state_diagram", lambda *args, **kwargs: stand_in)
    result = CliRunner().invoke(app, ["diagram", "--model", "sine", "--vary", "gamma_phi", "--values", "0.128,0.14"])
    assert result.exit_code == 0, result.output
    assert snic_line(point, "gamma_phi", "M_c", "M_c", point.get("moment")) in result.stdout.splitlines()
