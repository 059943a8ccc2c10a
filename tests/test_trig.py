"""The inline sincos used by the compiled kernels is as accurate as libm and has no branch."""

from __future__ import annotations

import math

import numpy as np

from cosserat_chain.models.trig import sincos


def test_sincos_matches_libm_to_one_ulp_over_many_turns():
    rng = np.random.default_rng(0)
    angles = np.concatenate(
        [np.linspace(-7, 7, 20001), rng.uniform(-1e4, 1e4, 20000), rng.uniform(-1e6, 1e6, 2000), [0.0, -0.0, 1e-300, math.pi / 2, 3e7]]
    )
    for angle in angles:
        s, c = sincos(angle)
        assert abs(s - math.sin(angle)) <= 2.3e-16 and abs(c - math.cos(angle)) <= 2.3e-16


def test_sincos_of_a_non_finite_angle_is_not_finite():
    # The engine's runaway test then stops the run (no branch for it in the hot loop).
    for bad in (math.nan, math.inf, -math.inf):
        s, c = sincos(bad)
        assert not math.isfinite(s) and not math.isfinite(c)
