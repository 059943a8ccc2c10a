"""The shooting's force Jacobian: exact from a model's bond kernel, or by fourth-order
differences exact to round-off, so that DOP853's steps follow the state.

The variational equations read dF/dq from the model's bond kernel
(:func:`cosserat_chain.numerics.periodic._bond_rhs`) or, for a model without one, from
differences of the compiled force kernel (:func:`cosserat_chain.numerics.periodic._rhs`).
The differences' error must be far below the integration tolerance: second-order differences
(error ~1e-9, rough from one evaluation to the next) made DOP853 shrink its steps to resolve
their round-off, 80 times as many as the state alone needs near the nonlinear chain's period
doubling.
"""

from __future__ import annotations

import numpy as np
import pytest

from conftest import random_state
from cosserat_chain import ChainParams
from cosserat_chain.models import get_model
from cosserat_chain.numerics import dop853
from cosserat_chain.numerics.periodic import RTOL, _bond_rhs, _rhs, _System, _to_y, continue_orbit, find_periodic_orbit
from cosserat_chain.state import n_free, pack, per_dof

#: dF/dq against the exact stiffness, relative to its largest entry, at displacements of 0.1
#: (second-order differences of step 1e-6: ~1e-10 to 1e-9).
JACOBIAN_RTOL = 1e-11
#: The monodromy's integration takes at most this many times the state-only integration's steps.
STEP_RATIO = 2.0

CHAINS = {
    "clamped": ChainParams(),
    "cantilever": ChainParams(N=4, right_end="free"),
    "pinned": ChainParams(N=2, left_end="pinned"),
}


def _without_bond_kernel(model):
    """The model with its bond kernel taken away: the variational equations fall back to differences."""
    return type(f"{type(model).__name__}WithoutBonds", (type(model),), {"bond_kernel": None})()


@pytest.mark.parametrize("model", ["nonlinear", "sine", "linear"])
@pytest.mark.parametrize("chain", list(CHAINS))
@pytest.mark.parametrize("exact", [True, False])
def test_the_variational_force_jacobian_equals_the_exact_stiffness_to_round_off(chain, model, exact):
    params, m = CHAINS[chain], get_model(model)
    if not exact:
        m = _without_bond_kernel(m)
    x, v = random_state(params, 0.1, seed=2), random_state(params, 1.0, seed=3)
    system = _System(params, m, 0.2, 0)
    assert system.parameters(1)[0] is (_bond_rhs if exact else _rhs)
    nf = n_free(params)
    y = np.concatenate([pack(params, x), pack(params, v), np.hstack([np.eye(2 * nf), np.zeros((2 * nf, 1))]).ravel()])
    dy = system.rhs(2 * nf + 1)(0.0, y)
    dphi = dy[2 * nf :].reshape(2 * nf, 2 * nf + 1)
    mass = pack(params, params.particle_inertia)
    expected = -m.stiffness(params, x).toarray() / mass[:, None]
    assert np.abs(dphi[nf:, :nf] - expected).max() <= (1e-14 if exact else JACOBIAN_RTOL) * np.abs(expected).max()
    # The velocity block, the damping and the moment's column are the same whichever Jacobian.
    assert np.array_equal(dphi[:nf], np.hstack([np.zeros((nf, nf)), np.eye(nf), np.zeros((nf, 1))]))
    gamma = np.diag(dphi[nf:, nf : 2 * nf])
    assert np.allclose(gamma * mass, -per_dof(params, params.damping), rtol=1e-15)
    assert dphi[nf:, -1] @ mass == pytest.approx(1.0, rel=1e-15)
    # The state's own rate: the forces of either path are the model's to round-off.
    state = _System(params, m, 0.2, 0).rhs(0)(0.0, y[: 2 * nf])
    assert np.abs(dy[: 2 * nf] - state).max() <= 1e-13 * np.abs(state).max()


def test_the_monodromy_near_the_period_doubling_takes_about_the_steps_of_the_state_alone():
    params = ChainParams(gamma_phi=0.2)
    start = find_periodic_orbit(params, "nonlinear", 0.1975)
    # Just above the period doubling at 0.19665 (the first orbit below 0.1968), where the monodromy's entries reach ~5e3.
    orbit = continue_orbit(start, moment_min=0.1968, period_max=100.0).orbits[-1]
    system = _System(params, get_model("nonlinear"), orbit.moment, orbit.particle)
    y0 = _to_y(params, orbit.x, orbit.v)
    size = y0.size
    steps = {}
    for ncols in (0, size + 1):
        rhs, kernel, ends, coef, rpar, ipar = system.parameters(ncols)
        start_state = np.concatenate([y0, np.hstack([np.eye(size), np.zeros((size, 1))]).ravel()]) if ncols else y0
        sol = dop853.solve(rhs, kernel, coef, rpar, ipar, start_state, np.array([0.0, orbit.period]), rtol=RTOL, atol=RTOL, end_force=ends)
        assert sol.success
        steps[ncols] = sol.steps
    assert steps[size + 1] <= STEP_RATIO * steps[0], steps
