"""Statics that answer with the state a slowly loaded chain reaches, or say why not (issue 45, items 1, 2, 3 and 6)."""

from __future__ import annotations

import functools
import json
import math
import pickle

import numpy as np
import pytest

from conftest import random_geometries
from cosserat_chain import ChainParams, moment_load
from cosserat_chain.analysis.continuum import discrete_static
from cosserat_chain.experiments.critical import critical_point
from cosserat_chain.numerics.continuation import compliance, continue_in_moment
from cosserat_chain.numerics.newton import BranchEndError, Equilibrium, solve_equilibrium

#: Agreement of two solves of one static state, relative to the state's size.
STATE_RTOL = 1e-8


def _stable_point_of_branch(params: ChainParams, model: str) -> tuple[float, np.ndarray]:
    """A point of the continuation's stable branch from rest at 0.8 of its largest moment: (M, x)."""
    branch = continue_in_moment(params, model, max_folds=1, max_points=400)
    stable = np.flatnonzero(branch.stable)
    i = stable[np.argmin(np.abs(branch.moment[stable] - 0.8 * branch.moment[stable].max()))]
    return float(branch.moment[i]), branch.x[i]


@pytest.mark.parametrize("model", ["nonlinear", "sine"])
@pytest.mark.parametrize("n, seed", [(10, 3), (30, 4), (100, 5)])
def test_solve_equilibrium_lands_on_the_continuations_branch_from_rest(n, seed, model):
    params = ChainParams(**{**random_geometries(1, seed=seed)[0].model_dump(), "N": n})
    moment, expected = _stable_point_of_branch(params, model)
    x = solve_equilibrium(params, model, moment_load(moment))
    assert np.max(np.abs(x - expected)) <= STATE_RTOL * max(1.0, np.max(np.abs(expected)))
    assert x.from_rest and x.index == 0 and x.stable


def test_solve_equilibrium_at_n_1000_lands_on_the_branch_from_rest():
    params = ChainParams(**{**random_geometries(1, seed=7)[0].model_dump(), "N": 1000})
    moment, expected = _stable_point_of_branch(params, "nonlinear")
    x = solve_equilibrium(params, "nonlinear", moment_load(moment))
    assert np.max(np.abs(x - expected)) <= STATE_RTOL * max(1.0, np.max(np.abs(expected)))
    assert x.index == 0


def test_the_issues_chain_of_30_is_not_wound():
    """Newton from rest with full steps returned phi_0 = 90.9 rad with 35 negative eigenvalues here."""
    x = solve_equilibrium(ChainParams(N=30), "nonlinear", moment_load(0.1))
    assert x[2, 30] == pytest.approx(0.951, abs=5e-4)
    assert x.index == 0 and x.stable and x.from_rest


def test_sine_state_from_rest_is_the_linear_solve_through_the_sines():
    """Eq. (2) is linear in (u, v, sin phi): the branch from rest is (u, v, sin phi) = M K^-1 e of the linear K."""
    params = ChainParams(N=20, E2=0.7)
    linear = solve_equilibrium(params, "linear", moment_load(1.0))
    moment = 0.6 / np.max(np.abs(linear[2]))  # every particle below pi/2
    x = solve_equilibrium(params, "sine", moment_load(moment))
    assert np.allclose(np.sin(x[2]), moment * linear[2], rtol=0, atol=1e-12)
    assert np.allclose(x[:2], moment * linear[:2], rtol=0, atol=1e-11)


def test_a_load_beyond_the_fold_is_refused_at_the_fold():
    params = ChainParams()
    fold = continue_in_moment(params, "nonlinear", max_folds=1).folds[0]
    with pytest.raises(BranchEndError, match="branch from rest") as caught:
        solve_equilibrium(params, "nonlinear", moment_load(2 * fold.moment))
    assert 2 * fold.moment * caught.value.load_factor == pytest.approx(fold.moment, rel=1e-4)


def test_a_given_start_may_give_an_unstable_state_and_says_so():
    params = ChainParams()
    branch = continue_in_moment(params, "nonlinear", phi0_stop=4.0)
    i = int(np.flatnonzero(~branch.stable)[0]) + 1  # past the fold: an unstable state
    x = solve_equilibrium(params, "nonlinear", moment_load(branch.moment[i]), x0=branch.x[i])
    assert not x.from_rest and x.index == 1 and not x.stable
    assert np.allclose(x, branch.x[i], atol=1e-9)


def test_equilibrium_is_an_array_whose_derived_arrays_are_plain():
    x = solve_equilibrium(ChainParams(), "nonlinear", moment_load(0.05))
    assert isinstance(x, Equilibrium) and x.shape == (3, 7)
    assert type(x + 0.0) is np.ndarray
    assert type(pickle.loads(pickle.dumps(x))) is np.ndarray
    assert x.dynamic is None  # a conservative model: K's verdict is the dynamics'
    with pytest.raises(AttributeError, match="copy or slice"):
        _ = x.copy().stable
    assert math.isfinite(x.stability.critical_eigenvalue)


# ---------------------------------------------------------------- the cantilever's branch point beyond one turn
@functools.lru_cache
def _bond_branch_point(params: ChainParams) -> tuple[float, float]:
    """(M, theta) where one bond of the nonlinear model under a pure moment loses its transverse stiffness.

    Independent of the package's kernels: the bond's energy written out with SymPy. In the bond's
    bisector frame the particles sit at (-+s/2, -+w/2) turned by -+theta/2; under a pure moment the
    force vanishes (dW/ds = 0 at w = 0, the state symmetric about the bisector) and the branch point
    is where the antisymmetric (transverse) stiffness d2W/dw2 vanishes; M = dW/dtheta there.
    """
    sy = pytest.importorskip("sympy")
    import scipy.optimize as so

    a, b, h, E1, E2 = params.a, params.b, params.h, params.E1, params.E2
    gap, d = h - 2 * a, math.hypot(h - 2 * a, 2 * b)
    s, w, t = sy.symbols("s w t", real=True)

    def corner(c, angle):
        return sy.Matrix([c[0] * sy.cos(angle) - c[1] * sy.sin(angle), c[0] * sy.sin(angle) + c[1] * sy.cos(angle)])

    left, right = sy.Matrix([-s / 2, -w / 2]), sy.Matrix([s / 2, w / 2])
    links = [((a, b), (-a, b), E1, gap), ((a, -b), (-a, -b), E1, gap), ((a, b), (-a, -b), E2, d), ((a, -b), (-a, b), E2, d)]
    energy = 0
    for c0, c1, stiffness, rest in links:
        link = right + corner(c1, t / 2) - left - corner(c0, -t / 2)
        energy += stiffness * (sy.sqrt(link.dot(link)) - rest) ** 2 / 2
    force = sy.lambdify((s, t), sy.diff(energy, s).subs(w, 0))
    transverse = sy.lambdify((s, t), sy.diff(energy, w, 2).subs(w, 0))
    moment = sy.lambdify((s, t), sy.diff(energy, t).subs(w, 0))
    root = so.fsolve(lambda z: [force(*z), transverse(*z)], [h, 1.4], xtol=1e-12)
    assert abs(force(*root)) < 1e-12 and abs(transverse(*root)) < 1e-12
    return float(moment(*root)), float(root[1])


# N = 5, the shortest chain stable beyond one turn, in the quick suite; N = 6, the same claim once more, with the slow tests.
@pytest.mark.parametrize("n", [1, 2, 5, pytest.param(6, marks=pytest.mark.slow)])
def test_cantilever_ends_at_the_branch_point_of_one_bond_for_every_n(n):
    """Every clamped-side bond carries the pure moment: the branch point is at one bond's moment, phi_0 = N theta.

    N >= 5 stay stable beyond one turn: before, critical stopped at phi_0 = 2 pi with no M_c and branch_complete.
    """
    params = ChainParams(N=n, right_end="free")
    moment, theta = _bond_branch_point(ChainParams())  # the paper's bond: the ends do not enter
    result = critical_point(params, "nonlinear")
    assert result.onset == "branch_point" and result.end == "branch_point" and result.complete
    assert result.critical_moment == pytest.approx(moment, rel=2e-8)
    assert result.phi0_at_onset == pytest.approx(n * theta, rel=2e-8)


def test_a_branch_still_stable_at_the_budget_is_not_complete():
    result = critical_point(ChainParams(N=8, right_end="free"), "nonlinear", turns=1)
    assert result.end == "budget" and not result.complete and result.critical_moment is None
    with pytest.raises(ValueError, match="turns"):
        critical_point(ChainParams(), "nonlinear", turns=0.5)


# ---------------------------------------------------------------- a particle other than the loaded one turns first
WEAK_PIN = dict(N=1, h=1.0, a=0.45, b=0.1, E1=0.5, E2=1.5, right_end="pinned")


def test_a_pinned_end_that_turns_first_names_itself_and_stops_the_trace():
    """Before: 208 folds, the point budget spent (exit 3), a spurious snap-through."""
    params = ChainParams(**WEAK_PIN)
    result = critical_point(params, "sine")
    angles = solve_equilibrium(params, "linear", moment_load(1.0))[2]  # eq. (2): sin phi = M c
    assert np.argmax(np.abs(angles)) == 2 * params.N  # the pinned end has the largest compliance
    assert result.onset_particle == params.N and result.end == "fold" and result.complete
    assert result.critical_moment == pytest.approx(1.0 / np.max(np.abs(angles)), rel=1e-13)
    assert result.critical_moment < 1.0 / result.compliance  # M_c is not 1 / the loaded particle's compliance here
    assert result.branch.stop == "wound" and f"particle {params.N}" in result.branch.message
    assert len(result.branch.folds) <= 4 and not result.as_dict()["snap_through"]


def test_the_sine_fold_is_the_closed_form_on_random_chains():
    for params in random_geometries(3, seed=11):
        result = critical_point(params, "sine")
        angles = solve_equilibrium(params, "linear", moment_load(1.0))[2]
        assert result.critical_moment == pytest.approx(1.0 / np.max(np.abs(angles)), rel=1e-12)
        assert result.fold.discrepancy < 1e-9 and result.accurate


def test_critical_and_the_linear_solve_give_one_compliance():
    params = ChainParams(N=200)
    expected = discrete_static(params)[2, params.N]
    for model in ("nonlinear", "sine", "linear"):
        assert compliance(params, model) == expected


def test_an_unstable_sine_state_takes_the_dynamics_verdict():
    params = ChainParams()
    branch = continue_in_moment(params, "sine", phi0_stop=3.0)
    i = int(np.flatnonzero(~branch.stable)[0]) + 1  # past the fold: a particle beyond pi/2
    x = solve_equilibrium(params, "sine", moment_load(branch.moment[i]), x0=branch.x[i])
    assert x.index == 1 and x.dynamic is not None and not x.dynamic.stable and not x.stable


# ---------------------------------------------------------------- one compliance, and eq. (2)'s M_c, at N = 10^4
@pytest.mark.slow
def test_critical_and_theory_give_the_exact_compliance_at_n_10000():
    """Before: critical's compliance (the nonlinear Hessian's) 4.2e-8 off the exact one, theory's 6.9e-11."""
    from cosserat_chain.analysis.timoshenko import clamped_central_compliance

    params = ChainParams(N=10**4)
    exact = clamped_central_compliance(params, nodal=True)
    value = compliance(params, "nonlinear")
    assert value == discrete_static(params)[2, params.N]
    assert abs(value / exact - 1) < 1e-9


@pytest.mark.slow
def test_the_sine_critical_moment_at_n_10000_is_accurate():
    """Before: flagged inaccurate (exit 5), the traced folds 3.6e-6 from 1 / compliance."""
    params = ChainParams(N=10**4)
    result = critical_point(params, "sine")
    assert result.accurate and result.complete and result.confirmation == "closed form"
    assert result.critical_moment == pytest.approx(1.0 / result.compliance, rel=1e-14)
    assert result.onset_particle == 0 and result.phi0_at_onset == pytest.approx(math.pi / 2, rel=1e-15)


def test_critical_command_names_the_turning_particle_and_exits_3_at_the_budget(tmp_path):
    from typer.testing import CliRunner

    from cosserat_chain.cli import app

    runner = CliRunner()
    pin = tmp_path / "pin.toml"
    pin.write_text("".join(f"{k} = {v!r}\n".replace("'", '"') for k, v in WEAK_PIN.items()))
    result = runner.invoke(app, ["critical", "--model", "sine", "--config", str(pin), "--json"])
    assert result.exit_code == 0, result.output
    summary = json.loads(result.stdout)["models"]["sine"]
    assert summary["onset_particle"] == 1 and summary["end"] == "fold" and not summary["snap_through"]
    assert summary["branch"]["stop"] == "wound" and "particle 1" in summary["branch"]["message"]
    cantilever = tmp_path / "cantilever.toml"
    cantilever.write_text('N = 8\nright_end = "free"\n')
    result = runner.invoke(app, ["critical", "--model", "nonlinear", "--config", str(cantilever), "--turns", "1"])
    assert result.exit_code == 3 and "still stable after 1 turns" in result.output and "--turns" in result.output
    result = runner.invoke(app, ["critical", "--turns", "0.5"])
    assert result.exit_code == 2 and "--turns" in result.output
