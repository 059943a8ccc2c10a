"""The nonlinear model's critical points that several test modules read, computed once a session.

``critical_point(chain, "nonlinear")`` with its defaults was traced again by each test that reads it: the chain with two
maxima and a minimum between them (``TWO_MAXIMA``: ``tests/test_statics.py``, ``tests/test_fold_confirmation.py``,
``tests/test_critical_scaling.py``), the paper's cantilever (its stable branch ends at a branch point:
``tests/test_ends.py``, ``tests/test_diagram.py``, ``tests/test_diagram_rows.py``) and the paper's chain. The result is a
deterministic function of the chain, and no test changes it; a test that patches the package before it asks (another
confirmation margin, fewer states kept) still calls ``critical_point`` itself.
"""

from __future__ import annotations

import functools

from cosserat_chain import ChainParams
from cosserat_chain.experiments.critical import CriticalResult, critical_point

#: The chain whose branch has two maxima and a minimum between them: it snaps through at the first maximum.
TWO_MAXIMA = ChainParams(N=10, a=0.3, b=0.1, E1=2.0, E2=0.3)


@functools.cache
def nonlinear_critical(chain: ChainParams) -> CriticalResult:
    """``critical_point(chain, "nonlinear")`` with the package's defaults, once a session per chain."""
    return critical_point(chain, "nonlinear")
