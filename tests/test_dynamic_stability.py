"""Dynamic stability of static states from the damped first-order system, and Hopf points (issue 45, item 4).

Checked against a theorem (conservative K with positive damping: the unstable count is K's
negative count), against LAPACK's dense eigenvalues, against the determinant's parity, and
at the sine model's Hopf points by the eigenvalues on either side and the branch's symmetry.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from cosserat_chain.numerics.continuation import continue_in_moment
from cosserat_chain.numerics.hopf import crossing_part, hopf_points
from cosserat_chain.numerics.newton import solve_rotation_controlled
from cosserat_chain.numerics.stability import dynamic_stability
from cosserat_chain.params import ChainParams
from cosserat_chain.state import zeros

#: Paper's geometry at N = 2: the sine model's Hopf points (phi_0, M), located once by this package
#: and checked here by the eigenvalues on either side.
HOPF_PHI0 = (1.6575078516528, 2.4380368033649)


@pytest.fixture(scope="module")
def sine_branch():
    params = ChainParams(N=2)
    return params, continue_in_moment(params, "sine", phi0_stop=2 * math.pi)


@pytest.fixture(scope="module")
def hopf(sine_branch):
    params, branch = sine_branch
    return hopf_points(params, "sine", branch)


@pytest.mark.parametrize("gammas", [(0.1, 0.1, 0.1), (0.02, 0.5, 0.003)])
def test_conservative_models_unstable_count_equals_the_stiffness_index(gammas):
    # With positive damping and symmetric K, x is stable iff K > 0, and the damped dynamics
    # has exactly as many unstable eigenvalues as K has negative ones (all real).
    params = ChainParams(N=3, gamma_u=gammas[0], gamma_v=gammas[1], gamma_phi=gammas[2])
    branch = continue_in_moment(params, "nonlinear", phi0_stop=2 * math.pi)
    indices = set()
    for x in branch.x[::4]:
        s = dynamic_stability(params, "nonlinear", x)
        assert s.unstable_eigenvalues == s.stiffness_index and s.unstable_pairs == 0
        assert s.stable == (s.stiffness_index == 0)
        indices.add(s.stiffness_index)
    assert indices == {0, 1}  # both kinds of state were met
    linear = dynamic_stability(params, "linear", branch.x[len(branch.x) // 2])
    assert linear.stable and linear.stiffness_index == 0 and linear.unstable_eigenvalues == 0


def test_sine_unstable_branch_has_more_unstable_eigenvalues_than_stiffness_index(sine_branch):
    params, _ = sine_branch
    x, _ = solve_rotation_controlled(params, "sine", 2.0, tol=1e-13)
    s = dynamic_stability(params, "sine", x)
    assert (s.stiffness_index, s.unstable_eigenvalues, s.unstable_real, s.unstable_pairs) == (1, 3, 1, 1)
    assert not s.stable and s.describe() == "unstable eigenvalues: 3 (1 real, 1 complex pair; stiffness index 1)"


def test_sine_hopf_points_at_n2_are_located_and_mirror_each_other(hopf):
    assert len(hopf) == 4 and all(h.located for h in hopf)
    assert [h.unstable_before for h in hopf] == [1, 3, 1, 3] and [h.unstable_after for h in hopf] == [3, 1, 3, 1]
    assert all(h.stiffness_index == 1 for h in hopf)
    np.testing.assert_allclose([h.phi0 for h in hopf[:2]], HOPF_PHI0, atol=1e-9)
    # phi -> 2 pi - phi, M -> -M maps eq. (2)'s branch to itself (cos phi is even about pi).
    for first, mirror in zip(hopf[:2], hopf[::-1][:2]):
        assert first.phi0 + mirror.phi0 == pytest.approx(2 * math.pi, abs=1e-9)
        assert first.moment == pytest.approx(-mirror.moment, abs=1e-10)
        assert first.frequency == pytest.approx(mirror.frequency, rel=1e-8)


def test_the_crossing_pair_is_on_the_axis_at_a_hopf_point_and_off_it_either_side(sine_branch, hopf):
    params, _ = sine_branch
    for h in hopf[:2]:
        at = dynamic_stability(params, "sine", h.x)
        real, frequency = crossing_part(at)
        assert abs(real) < 1e-9 and frequency == pytest.approx(h.frequency)
        counts = []
        for offset in (-1e-3, 1e-3):
            x, _ = solve_rotation_controlled(params, "sine", h.phi0 + offset, x0=h.x, moment0=h.moment, tol=1e-13)
            counts.append(dynamic_stability(params, "sine", x).unstable_eigenvalues)
        assert counts == [h.unstable_before, h.unstable_after]


def test_sparse_path_equals_dense_eigenvalues_at_small_n(sine_branch):
    params, branch = sine_branch
    for x in branch.x[::5]:
        dense = dynamic_stability(params, "sine", x, method="dense")
        sparse = dynamic_stability(params, "sine", x, method="sparse")
        assert (sparse.method, dense.method) == ("sparse", "dense")
        assert sparse.unstable_eigenvalues == dense.unstable_eigenvalues
        assert sparse.unstable_pairs == dense.unstable_pairs and sparse.stiffness_index == dense.stiffness_index
        # The eigenvalues the sparse path lists (nearest the axis) are eigenvalues of the dense one.
        for z in sparse.rightmost:
            assert np.min(np.abs(np.array(dense.rightmost + _all(params, x)) - z)) < 1e-8 * max(1.0, abs(z))


def _all(params, x):
    return tuple(dynamic_stability(params, "sine", x, method="dense", rightmost=200).rightmost)


@pytest.mark.parametrize("model", ["sine", "nonlinear"])
def test_sparse_count_matches_dense_on_a_longer_chain(model):
    params = ChainParams(N=12, a=0.3, b=0.12)
    branch = continue_in_moment(params, model, phi0_stop=3.5)
    for x in branch.x[:: max(1, len(branch.x) // 6)]:
        dense = dynamic_stability(params, model, x, method="dense")
        sparse = dynamic_stability(params, model, x, method="sparse")
        assert sparse.unstable_eigenvalues == dense.unstable_eigenvalues
        # det(A) = det(K~) (A's eigenvalues come in conjugate pairs): the parity of the
        # unstable count is that of K's negative count.
        assert (sparse.unstable_eigenvalues - sparse.stiffness_index) % 2 == 0


@pytest.mark.parametrize("gamma", [0.1, 0.0])
@pytest.mark.parametrize("method", ["dense", "sparse"])
def test_a_free_chain_at_rest_is_dynamically_stable_its_rigid_modes_neutral(method, gamma):
    # Undamped, a rigid mode is a Jordan block at zero (a drift), whose computed eigenvalues
    # scatter by sqrt(eps): neutral, not unstable.
    params = ChainParams(N=8, left_end="free", right_end="free", gamma_u=gamma, gamma_v=gamma, gamma_phi=gamma)
    for model in ("linear", "sine", "nonlinear"):
        s = dynamic_stability(params, model, zeros(params), method=method)
        assert s.stable and s.stiffness_index == 0 and s.unstable_eigenvalues == 0


def test_bad_input_names_the_argument():
    params = ChainParams(N=2)
    with pytest.raises(ValueError, match="method must be one of auto, dense, sparse, got 'lapack'"):
        dynamic_stability(params, "sine", zeros(params), method="lapack")
    with pytest.raises(ValueError, match="rightmost must be an integer >= 1"):
        dynamic_stability(params, "sine", zeros(params), rightmost=0)
    with pytest.raises(ValueError, match="shape"):
        dynamic_stability(params, "sine", np.zeros((3, 4)))


def test_states_reports_the_stiffness_index_and_the_unstable_eigenvalues_each_by_its_name():
    from cosserat_chain.experiments.coexisting import _static_states
    from cosserat_chain.models.base import get_model

    params = ChainParams(N=2)
    static, hopf = _static_states(params, get_model("sine"), 0.25, 0)
    saddle = max(static, key=lambda s: s.phi0).as_dict()
    assert 1.658 < saddle["phi0"] < 2.438  # between the two Hopf points of positive M
    assert saddle["stiffness_index"] == 1 and saddle["unstable_eigenvalues"] == 3 and saddle["unstable_pairs"] == 1
    assert saddle["stable"] is saddle["dynamically_stable"] is False and "index" not in saddle
    assert len(hopf) == 4


@pytest.mark.parametrize("model", ["sine", "nonlinear"])
def test_argument_principle_counts_with_and_without_the_rest_reference_and_with_uneven_damping(model):
    import scipy.sparse as sp

    from cosserat_chain.linalg.pencil import unstable_count
    from cosserat_chain.models.base import get_model
    from cosserat_chain.state import pack, per_dof

    params = ChainParams(N=6, gamma_u=0.02, gamma_v=0.5, gamma_phi=0.003)
    root = sp.diags(1.0 / np.sqrt(pack(params, params.particle_inertia)))
    rate = per_dof(params, params.damping) / pack(params, params.particle_inertia)
    rest = root @ get_model(model).stiffness(params, zeros(params)) @ root
    for phi0 in (0.5, 2.0, 3.0):
        x, _ = solve_rotation_controlled(params, model, phi0, tol=1e-13)
        dense = dynamic_stability(params, model, x, method="dense")
        scaled = sp.csr_matrix(root @ get_model(model).stiffness(params, x) @ root)
        assert unstable_count(scaled, rate, dense.tolerance) == dense.unstable_eigenvalues
        assert unstable_count(scaled, rate, dense.tolerance, sp.csr_matrix(rest)) == dense.unstable_eigenvalues


def _pair_run(params, x, moment, pair):
    """The growth over one period 2 pi / omega of a damped run from x nudged along the eigenvector of ``pair``."""
    import scipy.linalg as la

    from cosserat_chain.loads import moment_load
    from cosserat_chain.models.base import get_model
    from cosserat_chain.numerics.dynamics import integrate
    from cosserat_chain.state import pack, per_dof, unpack

    model = get_model("sine")
    stiffness = model.stiffness(params, x).toarray()
    mass = pack(params, params.particle_inertia)
    n = mass.size
    a = np.zeros((2 * n, 2 * n))
    a[:n, n:] = np.diag(1.0 / mass)
    a[n:, :n] = -stiffness
    a[n:, n:] = -np.diag(per_dof(params, params.damping) / mass)
    values, vectors = la.eig(a)
    k = int(np.argmin(np.abs(values - pair)))
    vector = 1e-6 * vectors[:, k] / np.max(np.abs(vectors[:n, k]))
    period = 2 * math.pi / abs(pair.imag)
    run = integrate(params, model, moment_load(moment, 0), t_end=period, dt=period / 4000, method="yoshida4", n_frames=2,
                    x0=x + unpack(params, vector[:n].real), v0=unpack(params, vector[n:].real / mass))  # fmt: skip
    return np.linalg.norm(pack(params, run.x[-1]) - pack(params, x)) / np.linalg.norm(vector[:n].real), period


def test_a_damped_run_along_the_crossing_pair_neither_grows_nor_decays_at_the_hopf_point(sine_branch, hopf):
    # An independent check by the package's integrator: nudged along the pair's eigenvector, the
    # chain comes back to the same deviation after one period at the Hopf point, and grows by
    # exp(Re lambda T) between the Hopf points (the real unstable mode is not excited in one period).
    params, _ = sine_branch
    h = hopf[0]
    growth, _ = _pair_run(params, h.x, h.moment, complex(0.0, h.frequency))
    assert growth == pytest.approx(1.0, abs=1e-4)
    x, moment = solve_rotation_controlled(params, "sine", 2.0, tol=1e-14)
    real, frequency = crossing_part(dynamic_stability(params, "sine", x))
    growth, period = _pair_run(params, x, moment, complex(real, frequency))
    assert real > 0.02 and growth == pytest.approx(math.exp(real * period), rel=3e-3)
