"""The diagram's SNIC point (issue 40): solved by the augmented system, the extrapolation only a labelled fallback.

Where a homoclinic row and a SNIC row are neighbours, ``state_diagram`` solves the codimension-two point between
them (:func:`~cosserat_chain.numerics.homoclinic.chain_snic_point`); the one-particle sine chain is the damped
pendulum, whose point alpha* = gamma_phi / sqrt(j M_c) = 1.1930459188 is known independently
(tests/test_homoclinic.py). Where the solve fails the row pair keeps the extrapolation, saying it is one and why.
"""

from __future__ import annotations

import json

import numpy as np
import pytest
from typer.testing import CliRunner

from cosserat_chain import ChainParams
from cosserat_chain.cli import app
from cosserat_chain.experiments.diagram import DiagramRow, StateDiagram, _solve_snic
from cosserat_chain.models.base import get_model
from cosserat_chain.numerics.continuation import locate_fold

#: The damped pendulum's codimension-two point, alpha* (tests/test_homoclinic.py's independent shooting).
ALPHA_STAR = 1.1930459188


def pendulum_scale() -> tuple[ChainParams, float]:
    """The one-particle chain and sqrt(j M_c), which turns gamma_phi into the pendulum's alpha."""
    params = ChainParams(N=1)
    return params, float(np.sqrt(params.j * locate_fold(params, "sine").moment))


@pytest.mark.slow
def test_the_diagrams_snic_point_is_the_augmented_systems_to_its_accuracy(tmp_path):
    """Two rows, alpha = 1.146 (homoclinic end) and 1.254 (SNIC): the point between them is chain_snic_point's and the pendulum's."""
    from cosserat_chain.numerics.homoclinic import chain_snic_point

    params, scale = pendulum_scale()
    (tmp_path / "N1.toml").write_text("N = 1\n")
    command = ["diagram", "--model", "sine", "--vary", "gamma_phi", "--values", "0.128,0.14", "--config", str(tmp_path / "N1.toml")]
    result = CliRunner().invoke(app, [*command, "--json"])
    assert result.exit_code == 0, result.output
    found = json.loads(result.stdout)
    assert [row["end"] for row in found["rows"]] == ["homoclinic", "snic"]
    point = found["snic_point"]
    assert point["method"] == "solved" and point["between"] == [0.128, 0.14] and "reason" not in point
    reference = chain_snic_point(params.replace(gamma_phi=0.128), "sine", name="gamma_phi", bracket=(0.128, 0.14))
    assert abs(point["value"] - reference.value) <= max(point["accuracy"], reference.accuracy)
    assert abs(point["value"] / scale - ALPHA_STAR) <= max(point["accuracy"] / scale, 1e-9)
    assert point["moment"] == pytest.approx(found["rows"][0]["static_fold"], rel=1e-12)


def _rows(scale: float, alphas: list[float], ends: list[str]) -> list[DiagramRow]:
    """Rows of the one-particle chain with made-up edges: a homoclinic end closing like (alpha_0 - alpha)^2."""

    def stops(alpha: float, end: str) -> float:
        return 1.0 - (1.35 - alpha) ** 2 / 16 if end == "homoclinic" else 1.0

    return [DiagramRow(a * scale, 1.0, 1.0, stops(a, end), end, end == "homoclinic") for a, end in zip(alphas, ends)]


@pytest.mark.parametrize(
    "ends, method",
    [(["homoclinic", "homoclinic", "snic"], "extrapolated"), (["snic", "homoclinic", "snic"], "not_located")],
)
def test_where_the_solve_fails_the_point_is_the_labelled_extrapolation_with_the_reason(ends, method):
    """Rows all above alpha* (the saddle's manifold falls back at both ends): the augmented system has no point to find,
    so the diagram keeps the extrapolation from two homoclinic rows, labelled, or says it is not located without them."""
    params, scale = pendulum_scale()
    diagram = StateDiagram(params, "sine", "gamma_phi", 3, _rows(scale, [1.25, 1.3, 1.4], ends))
    _solve_snic(diagram, params, get_model("sine"), 0)
    assert diagram.solved_snic is None and "falls back at both ends" in diagram.snic_failure
    point = diagram.snic_point
    assert point["method"] == method and point["accuracy"] is None
    assert point["reason"].startswith("the augmented system did not solve it") and "falls back" in point["reason"]
    assert point["between"] == ([1.3 * scale, 1.4 * scale] if method == "extrapolated" else [1.25 * scale, 1.3 * scale])
    if method == "extrapolated":
        assert point["value"] / scale == pytest.approx(1.35, rel=1e-12)  # where the made-up gap closes
    else:
        assert point["value"] is None
    assert json.loads(json.dumps(diagram.as_dict()))["snic_point"] == point


def test_rows_without_a_homoclinic_row_next_to_a_snic_have_no_point_and_nothing_is_solved():
    params, scale = pendulum_scale()
    diagram = StateDiagram(params, "sine", "gamma_phi", 3, _rows(scale, [1.3, 1.4], ["snic", "snic"]))
    _solve_snic(diagram, params, get_model("sine"), 0)
    assert diagram.snic_point is None and diagram.solved_snic is None and diagram.snic_failure == ""
