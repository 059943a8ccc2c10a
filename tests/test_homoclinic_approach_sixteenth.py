"""Branches of rotating orbits that approach a homoclinic end, where the period grows at an all but fixed moment.

The N = 1 sine chain (the damped driven pendulum with its two translations) at the default fields: its one-turn orbit
followed down from M = 0.5 ends at the homoclinic orbit of the saddle, M_h = 0.42900339512 (bisection on the saddle's
unstable manifold: 0.4290033951198778 to ...797). Its u oscillator is linear and decoupled in the sine model, so two
multipliers of every orbit are exp((-gamma_u / 2m +- i omega) T), of modulus exp(-gamma_u T / 2m) exactly, and nothing
else is larger: the pendulum's own are exp(-gamma_phi T / j) and smaller.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from cosserat_chain import ChainParams
from cosserat_chain.numerics import collocation, kit
from cosserat_chain.numerics.periodic import continue_orbit, find_periodic_orbit

#: The homoclinic end of the N = 1 sine chain at the default fields (the module docstring's bisection).
M_HOMOCLINIC = 0.42900339512


class _Asymptote:
    """R(x, lambda) = lambda - 1 + exp(-x): a branch whose parameter stops moving (d lambda / dx = exp(-x)), as M does
    towards a homoclinic end."""

    tol = 1e-14
    parameter_name = "lambda"

    def evaluate(self, w, jacobian):
        residual = np.array([w[1] - 1.0 + math.exp(-w[0])])
        return kit.Evaluation(residual, np.array([[-math.exp(-w[0]), 1.0]]) if jacobian else None)

    def point(self, w, evaluation, iterations):
        return w.copy()

    def accept(self, previous, candidate):
        return True

    def tests(self, point):
        return {}

    def stop(self, point):
        return None

    def confirm(self, kind, point):
        return True


def test_a_restart_along_its_tangent_is_corrected_on_the_tangents_hyperplane():
    # lambda slightly above its asymptote: held fixed (the start without a tangent) it has no solution at all; a restart
    # along the branch's tangent (all but x) lands on the branch at the same x.
    w0 = np.array([30.0, 1.0 + 1e-12])
    with pytest.raises(kit.StartError):
        kit.continuation(_Asymptote(), w0, step=0.5, min_step=1e-6, max_step=1.0, max_points=3)
    traced = kit.continuation(_Asymptote(), w0, step=0.5, min_step=1e-6, max_step=1.0, max_points=4, tangent0=np.array([1.0, 1e-13]))
    first = traced.points[0]
    assert first[0] == pytest.approx(30.0, abs=1e-9) and first[1] == pytest.approx(1.0 - math.exp(-30.0), abs=1e-15)
    # ... and goes on the way the tangent points, x growing, every point on the branch.
    xs = np.array([p[0] for p in traced.points])
    assert len(traced.points) == 4 and np.all(np.diff(xs) > 0)
    assert all(abs(p[1] - 1.0 + math.exp(-p[0])) <= 1e-14 for p in traced.points)


def test_collocation_follows_the_orbit_past_its_remeshings_to_the_homoclinic_end():
    # Each remeshing restarts the driver from an interpolated orbit: with M held fixed that correction diverged once the
    # period grew (T = 16 here), and the branch stopped as "the start is not on the branch".
    start = collocation.find_collocation_orbit(ChainParams(N=1), "sine", 0.5)
    branch = collocation.continue_collocation(start, moment_min=0.4, period_max=100.0)
    assert branch.end == "infinite_period" and branch.orbits[-1].period > 100.0
    assert branch.orbits[-1].moment == pytest.approx(M_HOMOCLINIC, abs=1e-10)
    # M falls all the way (to the mesh's noise in M at the longest periods, 2e-10 on 40 intervals).
    assert np.all(np.diff([o.moment for o in branch.orbits]) < 1e-9)
    # On 40 intervals the multipliers of the longest orbits are not resolved (the trivial one far off 1, some other
    # above 1): the branch does not claim a loss of stability from them.
    reported = branch.orbit_branch()
    assert not all(reported.stable) and max(o.trivial_multiplier_error for o in branch.orbits) > 0.1
    assert reported.stability_lost_at is None


def test_shooting_towards_the_homoclinic_end_keeps_true_multipliers_and_ends_where_its_accuracy_does():
    params = ChainParams(N=1)
    branch = continue_orbit(find_periodic_orbit(params, "sine", 0.5), moment_min=0.4)
    # Before: the corrector's evaluations with and without the variational equations disagreed beyond the closure and
    # 400 orbits crawled to T = 6.85; once past, the monodromy's multiplier along the flow drifted to 2.03 and, past the
    # damped pair, read as a real multiplier through +1: a false fold of cycles at T = 10.3.
    assert branch.end == "infinite_period" and "accuracy is exhausted" in branch.message, branch.message
    assert len(branch.orbits) < 300 and max(branch.period) > 10.0
    assert 0 < branch.orbits[-1].moment - M_HOMOCLINIC < 1e-6
    assert np.all(np.diff(branch.moment) < 0)
    assert branch.stability_lost_at is None and all(branch.stable)
    for orbit in branch.orbits:
        u_modulus = math.exp(-params.gamma_u * orbit.period / (2 * params.m))
        moduli = np.abs(orbit.nontrivial_multipliers)
        assert np.sum(np.isclose(moduli, u_modulus, rtol=1e-6)) >= 2, (orbit.period, np.sort(moduli)[-3:])
        assert moduli.max() <= u_modulus * (1 + 1e-6)
        # The trivial multiplier is 1 until the saddle's growth swamps it (like exp(lambda_u T)) ...
        if orbit.period < 6.0:
            assert abs(orbit.trivial_multiplier - 1) < 1e-5
    # ... and off by more than 0.5 it ends the branch.
    assert abs(branch.orbits[-1].trivial_multiplier - 1) > 0.5 > abs(branch.orbits[-2].trivial_multiplier - 1)
