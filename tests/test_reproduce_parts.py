"""Parts of ``reproduce`` made cheaper keep their results (issue 44 item 1).

The report's figures are saved with the layout engine removed once it has laid them out (no second draw
before printing): the PNG is the one the layout engine's placeholder gave, byte for byte. The periodic
orbits' state-only right-hand side is compiled apart from the one with force differences: the same bits. The errata
read only the SymPy checks they report, not Section 3's algebra: the same errata.
"""

from __future__ import annotations

import io

import numpy as np
import pytest

from cosserat_chain.analysis import symbolic
from cosserat_chain.models.base import get_model
from cosserat_chain.numerics import dop853
from cosserat_chain.numerics.periodic import _bond_rhs, _rhs, _state_rhs, _System
from cosserat_chain.params import ChainParams
from cosserat_chain.report import ReproduceSettings
from cosserat_chain.report.stages import FIGURE_DPI, _Stage


def _figure():
    from matplotlib.figure import Figure

    figure = Figure(figsize=(10.0, 4.0), layout="constrained")
    left, right = figure.subplots(1, 2)
    x = np.linspace(0.0, 3.0, 50)
    left.plot(x, np.sin(x), label="$\\sin x$")
    left.legend()
    right.semilogy(x, np.exp(x))
    right.set_title("a title that the layout must make room for")
    figure.supxlabel("x")
    return figure


def test_a_report_figure_is_the_png_the_placeholder_engine_gave(tmp_path):
    """The old way: laid out, the engine set to "none" (a placeholder, with which savefig draws once more first)."""
    figure = _figure()
    figure.set_dpi(FIGURE_DPI)
    figure.get_layout_engine().execute(figure)
    figure.set_layout_engine("none")
    assert figure.get_layout_engine() is not None
    before = io.BytesIO()
    figure.savefig(before, format="png", dpi=FIGURE_DPI)

    stage = _Stage(tmp_path, ChainParams(), ReproduceSettings())
    again = _figure()
    assert stage.figure(again, "test") == "test"
    assert again.get_layout_engine() is None
    assert (tmp_path / "figures" / "test.png").read_bytes() == before.getvalue()
    assert {"figures/test.png", "figures/test.svg"} <= stage.written


@pytest.mark.parametrize("model", ["sine", "nonlinear", "linear"])
@pytest.mark.parametrize("ends", ["clamped", "free"])
def test_the_state_only_right_hand_side_is_rhs_without_columns_bit_for_bit(model, ends):
    params = ChainParams(N=4, right_end=ends)
    system = _System(params, get_model(model), 0.13, 0)
    rhs, kernel, end_kernel, coef, rpar, ipar = system.parameters(0)
    assert rhs is _state_rhs
    assert system.parameters(2 * system.nf + 1)[0] is _bond_rhs  # every built-in model has a bond kernel
    y = 0.3 * np.random.default_rng(7).standard_normal(2 * system.nf)
    # Through the integrator, which takes both by their addresses (a direct call with the kernels would compile
    # other versions of them): every step the same, so every right-hand side the same.
    times = np.array([0.0, 2.0])
    runs = [dop853.solve(f, kernel, coef, rpar, ipar, y, times, rtol=1e-9, atol=1e-9, end_force=end_kernel) for f in (_state_rhs, _rhs)]
    assert runs[0].steps == runs[1].steps
    np.testing.assert_array_equal(runs[0].y.view(np.int64), runs[1].y.view(np.int64))


def test_the_errata_read_only_their_checks_and_miss_no_failing_one(monkeypatch):
    full = symbolic.compare_with_paper()
    read = symbolic.errata_checks()
    # The same checks, the same objects, then Section 3's algebra, of which none fails (no erratum is left out).
    assert full[: len(read)] == read and all(a is b for a, b in zip(full, read))
    assert {c.key for c in full[len(read) :]} == {"eq7", "eq11.v", "eq11.phi", "phi0", "eq12", "eq4", "reduced"}
    assert all(c.agrees for c in full[len(read) :])
    # The reduced model's E1 (D1 = 0) by the linear solve is sympy.solve's root, the same expression.
    sp = pytest.importorskip("sympy")
    (reduced,) = [c for c in read if c.key == "section3.reduced_E1"]
    coefficients, symbols = symbolic.derivation().coefficients, symbolic.derivation().symbols
    assert sp.srepr(reduced.derived) == sp.srepr(sp.solve(sp.Eq(coefficients["D1"], 0), symbols["E1"])[0])
    expected = symbolic.errata(ChainParams())

    def refused():
        raise AssertionError("errata computed Section 3's algebra")

    monkeypatch.setattr(symbolic, "compare_with_paper", refused)
    monkeypatch.setattr(symbolic, "_section3_checks", refused)
    assert symbolic.errata(ChainParams()) == expected
    assert {key for e in expected for key in e.checks} == {c.key for c in full if not c.agrees}
