"""numerics.addresses: a compiled function handed over by its address runs the same code as the dispatcher."""

import numpy as np
import pytest

from cosserat_chain.models.base import END_KERNEL_TYPE, FORCE_KERNEL_TYPE, get_model
from cosserat_chain.numerics import dop853
from cosserat_chain.numerics.addresses import _Entry, entry
from cosserat_chain.numerics.periodic import _System
from cosserat_chain.params import ChainParams


def _parts(model: str, ncols: int = 0):
    system = _System(ChainParams(), get_model(model), 0.21, 0)
    return system, system.parameters(ncols)


def test_entry_is_found_once_and_kept():
    _, (rhs, kernel, ends, *_) = _parts("sine")
    first = entry(kernel, FORCE_KERNEL_TYPE)
    assert isinstance(first, _Entry)
    assert entry(kernel, FORCE_KERNEL_TYPE) is first
    assert entry(first, FORCE_KERNEL_TYPE) is first
    assert first.signature() == FORCE_KERNEL_TYPE.signature
    assert entry(ends, END_KERNEL_TYPE).address > 0


def test_a_plain_python_function_is_returned_as_it_is():
    def plain(*args):
        return None

    assert entry(plain, FORCE_KERNEL_TYPE) is plain


@pytest.mark.parametrize("model", ["sine", "nonlinear"])
def test_dop853_by_address_is_bitwise_the_dispatchers_run(model):
    """The integrator entered through the addresses and through the dispatchers themselves (the compiled
    loop called directly) gives the same numbers to the last bit, monodromy columns included."""
    system, (rhs, kernel, ends, coef, rpar, ipar) = _parts(model, ncols=3)
    size = 2 * system.nf
    rng = np.random.default_rng(4)
    y0 = np.concatenate([0.05 * rng.standard_normal(size), rng.standard_normal(size * 3)])
    times = np.array([0.0, 1.5, 3.0])
    by_address = dop853.solve(rhs, kernel, coef, rpar, ipar, y0, times, rtol=1e-10, atol=1e-10, end_force=ends)
    out = np.empty((times.size, y0.size))
    out[0] = y0
    code, frames, steps, evaluations, t = dop853._solve(rhs, kernel, ends, coef, rpar, ipar, times, 1e-10, 1e-10, 100000, out)
    assert by_address.success and code == 0
    assert by_address.steps == steps
    np.testing.assert_array_equal(by_address.y, out)


def test_rhs_by_address_matches_the_dispatcher():
    system, (rhs, kernel, ends, coef, rpar, ipar) = _parts("nonlinear")
    y = 0.1 * np.random.default_rng(1).standard_normal(2 * system.nf)
    direct = np.empty_like(y)
    rhs(kernel, ends, 0.0, y, coef, rpar, ipar, direct)
    np.testing.assert_array_equal(system.rhs(0)(0.0, y), direct)


def test_a_kernel_compiled_at_first_use_is_compiled_for_the_kernel_signature_only():
    """A kernel with no signature at import (the graded and unused end kernels: cold start, issue 44) is compiled by
    :func:`entry` for the kernel type's signature, once, and runs the same code as a call of the dispatcher."""
    from numba import njit

    from cosserat_chain.models.base import FORCE_SIGNATURE

    @njit(cache=False)
    def lazy(x, coef, out, start, stop):  # pragma: no cover - compiled
        for k in range(start, stop):
            out[0, k] = coef[0] * (x[0, k - 1] - 2.0 * x[0, k] + x[0, k + 1])

    assert lazy.signatures == []
    handed = entry(lazy, FORCE_KERNEL_TYPE)
    assert isinstance(handed, _Entry) and handed.address > 0
    assert lazy.signatures == [FORCE_SIGNATURE.args]
    x = np.random.default_rng(3).standard_normal((3, 9))
    out = np.zeros((3, 9))
    lazy(x, np.array([2.5]), out, 1, 8)
    assert lazy.signatures == [FORCE_SIGNATURE.args]  # the call found the same overload
    np.testing.assert_array_equal(out[0, 1:8], 2.5 * (x[0, :7] - 2.0 * x[0, 1:8] + x[0, 2:]))


@pytest.mark.parametrize("model", ["nonlinear", "sine", "linear"])
def test_the_graded_kernels_compile_at_first_use_to_the_force_signature(model):
    from cosserat_chain.models.base import FORCE_SIGNATURE

    kernel = type(get_model(model)).graded_kernel
    entry(kernel, FORCE_KERNEL_TYPE)
    assert kernel.signatures == [FORCE_SIGNATURE.args]


@pytest.mark.parametrize("model", ["nonlinear", "sine", "linear"])
def test_the_batch_kernels_compile_at_first_use_to_the_batch_signature(model):
    """The batch kernels have no signature at import (a single chain's run never calls one: cold start, issue 44); a
    batch's run compiles the kernel type's signature only, which the engine's call from Python finds too."""
    from cosserat_chain import ChainParams
    from cosserat_chain.models.base import BATCH_FORCE_SIGNATURE
    from cosserat_chain.numerics.batch import integrate_batch

    kernel = type(get_model(model)).batch_kernel
    run = integrate_batch([ChainParams(N=2), ChainParams(N=2, gamma_phi=0.3)], model, [0.4, 0.8], t_end=2.0)
    assert np.isfinite(run.x).all()
    assert kernel.signatures == [BATCH_FORCE_SIGNATURE.args]


def test_the_engine_hands_a_single_chain_stubs_for_the_batch_slots_and_a_batch_one_for_the_chain_slot():
    """The compiled loop calls the chain kernel for one chain and the batch kernel and sub-step for a batch: the slot
    it does not call holds a stub, so that the run compiles no kernel it does not use; both runs stay exact."""
    from cosserat_chain import ChainParams, moment_load
    from cosserat_chain.models.base import no_batch_forces, no_chain_forces
    from cosserat_chain.numerics import engine
    from cosserat_chain.numerics.batch import integrate_batch
    from cosserat_chain.numerics.dynamics import integrate

    handed = []
    original = engine.advance

    def spy(kernels, *rest):
        handed.append(tuple(getattr(k, "function", k) for k in kernels))
        return original(kernels, *rest)

    members = [ChainParams(N=2), ChainParams(N=2, gamma_phi=0.3)]
    kind = type(get_model("sine"))
    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(engine, "advance", spy)
        single = integrate(members[1], "sine", moment_load(0.8), t_end=2.0, n_frames=3)
        ends = get_model("sine").chain_kernels(members[1])[1]  # the default chain is clamped: the stub no_ends
        assert handed[-1] == (kind.force_kernel, ends, no_batch_forces, engine._no_batch_step)
        batch = integrate_batch(members, "sine", [0.4, 0.8], t_end=2.0)
        assert handed[-1] == (no_chain_forces, ends, kind.batch_kernel, engine._batch_substep)
    # The batch's member equals its single run (the batch test's tolerance: another loop, the same scheme).
    np.testing.assert_allclose(batch.x[1], single.x[-1], rtol=0, atol=1e-12)


def test_an_entry_is_typed_as_numbas_own_rule_types_it():
    """The registered ``typeof`` gives the type the entry was made with, equal to (and interned as) the type Numba's
    rule for wrapper-address objects builds from its signature, so the dispatcher picks the same compiled code."""
    from numba import typeof, types
    from numba.experimental.function_type import typeof_function_type

    _, (rhs, kernel, ends, *_) = _parts("nonlinear")
    for function, kind in ((kernel, FORCE_KERNEL_TYPE), (ends, END_KERNEL_TYPE)):
        handed = entry(function, kind)
        assert typeof(handed) is kind
        assert typeof_function_type(handed, None) == kind
        assert typeof((handed, handed)) == types.UniTuple(kind, 2)
