"""A run of few frames is advanced in pieces of bounded work, with the same bits as in one call.

``integrate`` cut its run into chunks of whole strides, so with few frames one compiled call
ran a whole stride and Ctrl-C waited for it. A chunk is now advanced in pieces of at most
``CHUNK_WORK`` particle force evaluations, left open between them: the final state, every
frame and the energy sums equal those of the run in one call, bit for bit; a Ctrl-C between
two pieces goes back to the chunk's start, the last stored frame.
"""

from __future__ import annotations

import numpy as np
import pytest

from cosserat_chain import ChainParams
from cosserat_chain.loads import moment_load
from cosserat_chain.numerics import dynamics
from cosserat_chain.numerics.engine import Lanes
from cosserat_chain.status import Status

PARAMS = ChainParams(N=3)
#: 2400 steps in two strides of 1200 (three frames).
RUN = {"t_end": 24.0, "dt": 0.01, "n_frames": 3}


def _run(method: str, model: str = "nonlinear", **options):
    return dynamics.integrate(PARAMS, model, moment_load(0.3), method=method, **RUN, **options)


@pytest.fixture
def calls(monkeypatch):
    """The lengths of the compiled loop's calls."""
    lengths: list[int] = []
    advance = Lanes.advance

    def counted(self, n_steps, *args, **kwargs):
        lengths.append(n_steps)
        return advance(self, n_steps, *args, **kwargs)

    monkeypatch.setattr(Lanes, "advance", counted)
    return lengths


@pytest.mark.parametrize(("method", "model"), [("verlet", "nonlinear"), ("yoshida4", "sine")])
def test_a_stride_in_pieces_has_the_bits_of_the_stride_in_one_call(monkeypatch, calls, method, model):
    whole = _run(method, model)
    assert calls == [2400]  # the default work per chunk holds the whole run
    calls.clear()
    evaluations = dynamics.get_method(method).force_evaluations
    monkeypatch.setattr(dynamics, "CHUNK_WORK", 7 * evaluations * 500)  # 500 steps of the 7 particles a piece
    pieces = _run(method, model)
    assert calls == [500, 500, 200] * 2
    assert pieces.status == whole.status == Status.COMPLETED and pieces.steps == whole.steps == 2400
    for name in ("time", "x", "v", "load_work", "dissipated", "winding"):
        np.testing.assert_array_equal(getattr(pieces, name), getattr(whole, name), err_msg=name)
    assert np.abs(whole.x[-1, 2]).max() > 0.1  # the load turned the chain: the comparison is not of rest states


def test_ctrl_c_between_pieces_returns_to_the_chunks_start(monkeypatch, calls):
    whole = _run("verlet")
    calls.clear()
    monkeypatch.setattr(dynamics, "CHUNK_WORK", 7 * 500)
    advance = Lanes.advance

    def interrupted(self, n_steps, *args, **kwargs):
        if len(calls) == 4:  # the second piece of the second stride
            raise KeyboardInterrupt
        return advance(self, n_steps, *args, **kwargs)

    monkeypatch.setattr(Lanes, "advance", interrupted)
    stopped = _run("verlet")
    assert stopped.status == Status.INTERRUPTED and "after 1200 of 2400 steps" in stopped.message
    assert len(stopped.time) == 2
    np.testing.assert_array_equal(stopped.x, whole.x[:2])
    np.testing.assert_array_equal(stopped.v, whole.v[:2])


def test_a_blow_up_found_pieces_later_is_placed_at_its_first_bad_step(monkeypatch, calls):
    # dt = 0.54 is past the stability limit: the first bad state comes at step 143, in the second piece, and is
    # seen at the check at that piece's end (every call ends with one); the chunk run again from its start places it.
    run = {"t_end": 3000 * 0.54, "dt": 0.54, "n_frames": 3, "check_stability": False}
    whole = dynamics.integrate(PARAMS, "nonlinear", moment_load(0.3), **run)
    calls.clear()
    monkeypatch.setattr(dynamics, "CHUNK_WORK", 7 * 100)
    pieces = dynamics.integrate(PARAMS, "nonlinear", moment_load(0.3), **run)
    assert calls == [100] * 2 + [200]  # two pieces, then the chunk run again over their 200 steps, to the first bad one
    assert pieces.status == whole.status == Status.BLEW_UP and pieces.steps == whole.steps == 143
    assert pieces.message == whole.message
    for name in ("time", "x", "v"):
        np.testing.assert_array_equal(getattr(pieces, name), getattr(whole, name), err_msg=name)
