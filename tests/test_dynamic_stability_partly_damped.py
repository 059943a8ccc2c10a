"""The damped dynamics' verdict on chains with an undamped degree of freedom (gamma_u, gamma_v or gamma_phi zero).

The sparse path counts unstable eigenvalues by the argument principle with steps that rely on every degree of
freedom being damped; with one undamped, eigenvalues sit on the imaginary axis next to the counting line, and the
count came out wrong (negative, or 30 where the dense eigenvalues give 6). A conservative model takes K's negative
count there too (the theorem holds for damping >= 0); eq. (2) is solved densely, and refused beyond the dense limit.
"""

from __future__ import annotations

import numpy as np
import pytest

from cosserat_chain.numerics.stability import PARTLY_DAMPED_DENSE_LIMIT, dynamic_stability
from cosserat_chain.params import ChainParams
from cosserat_chain.state import zero_held

CASES = [
    ("nonlinear", (0.0, 0.1, 0.0), ("pinned", "free"), 1),
    ("nonlinear", (1.0, 1.0, 0.0), ("clamped", "pinned"), 2),
    ("nonlinear", (0.0, 0.0, 0.0), ("clamped", "clamped"), 3),
    ("sine", (0.1, 0.0, 0.0), ("clamped", "clamped"), 4),
    ("sine", (1.0, 0.1, 0.0), ("pinned", "free"), 5),
    ("sine", (0.0, 0.0, 0.0), ("clamped", "free"), 6),
]


def _state(params: ChainParams, seed: int) -> np.ndarray:
    rng = np.random.default_rng(seed)
    k = 2 * params.N + 1
    x = np.zeros((3, k))
    x[0], x[1], x[2] = rng.normal(0, 0.05, k), rng.normal(0, 0.05, k), rng.normal(0, 1.0, k)
    return zero_held(params, x)


@pytest.mark.parametrize(("model", "damping", "ends", "seed"), CASES)
def test_a_partly_damped_chain_has_the_dense_count_on_the_sparse_path(model, damping, ends, seed):
    rng = np.random.default_rng(100 + seed)
    params = ChainParams(
        N=40, a=rng.uniform(0.2, 0.45), b=rng.uniform(0.2, 0.6), E1=rng.uniform(0.5, 3), E2=rng.uniform(0.5, 3),
        gamma_u=damping[0], gamma_v=damping[1], gamma_phi=damping[2], left_end=ends[0], right_end=ends[1],
    )  # fmt: skip
    x = _state(params, seed)
    dense = dynamic_stability(params, model, x, method="dense")
    sparse = dynamic_stability(params, model, x, method="sparse")
    assert sparse.unstable_eigenvalues == dense.unstable_eigenvalues
    assert (sparse.unstable_real, sparse.unstable_pairs) == (dense.unstable_real, dense.unstable_pairs)
    if model == "nonlinear":  # the theorem, undamped degrees of freedom included
        assert dense.unstable_eigenvalues == dense.stiffness_index
        assert sparse.method == "sparse"


def test_a_partly_damped_sine_chain_beyond_the_dense_limit_is_refused_naming_the_undamped_fields():
    params = ChainParams(N=700, gamma_u=0.0, gamma_phi=0.0)
    assert 2 * 3 * (2 * params.N - 1) > PARTLY_DAMPED_DENSE_LIMIT
    with pytest.raises(ValueError, match=r"gamma_u, gamma_phi = 0.*above 4000"):
        dynamic_stability(params, "sine", np.zeros((3, 2 * params.N + 1)))
