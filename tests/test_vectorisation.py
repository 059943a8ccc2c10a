"""The hot loops compile to packed SIMD instructions (a branch or a strict-order sum in a loop body would keep them scalar).

Numba disables ``inspect_asm`` for cached functions, so each kernel is compiled
here afresh from its Python source with the options it is compiled with.
"""

from __future__ import annotations

import re

import numpy as np
import pytest
from numba import njit

from cosserat_chain.models import available_models, get_model
from cosserat_chain.models.base import BATCH_FORCE_SIGNATURE, FORCE_SIGNATURE, KERNEL_OPTIONS
from cosserat_chain.numerics import engine

#: A packed double-precision instruction on 256- or 512-bit registers.
PACKED = re.compile(r"\bv\w+pd\s+[^\n]*%[yz]mm")


_ASM: dict[tuple, str] = {}


def _fresh_asm(py_func, signature, options) -> str:
    """The assembly of ``py_func`` compiled afresh for ``signature`` with ``options``, once a session: the nonlinear
    force kernel's is read by two tests."""
    key = (py_func, str(signature), repr(sorted(options.items())))
    if key not in _ASM:
        fresh = njit(signature, **{**options, "cache": False})(py_func)
        _ASM[key] = fresh.inspect_asm(fresh.signatures[0])
    return _ASM[key]


def packed_instructions(dispatcher, signature, options) -> int:
    return len(PACKED.findall(_fresh_asm(dispatcher.py_func, signature, options)))


def nonlinear_quick(names) -> list:
    """The models, each but the nonlinear one (the kernels' hardest case: square roots and divisions) marked slow: each
    case compiles a kernel afresh, which is what this file's time is."""
    return [name if name == "nonlinear" else pytest.param(name, marks=pytest.mark.slow) for name in names]


def force_kernel_cases() -> list:
    """(kind, model) of every force kernel, each compiled afresh (this file's cost): the nonlinear row kernel quick, as
    in ``nonlinear_quick``; of the batch kernels the linear one quick (its loop over the members, innermost, is every
    model's, and it compiles quickest) and the nonlinear one slow, whose square roots and divisions the quick row case
    finds packed; the others slow."""
    quick = {"force_kernel": "nonlinear", "batch_kernel": "linear"}
    return [
        pytest.param(kind, name, id=f"{kind}-{name}", marks=() if name == quick[kind] else pytest.mark.slow)
        for kind in quick
        for name in available_models()
    ]


@pytest.mark.parametrize(("kind", "name"), force_kernel_cases())
def test_every_force_kernel_vectorises(name, kind):
    kernel = getattr(type(get_model(name)), kind)
    signature = FORCE_SIGNATURE if kind == "force_kernel" else BATCH_FORCE_SIGNATURE
    # Each of the three models does at least a dozen packed operations per column.
    assert packed_instructions(kernel, signature, KERNEL_OPTIONS) >= 12


def test_the_nonlinear_kernels_take_square_roots_and_divisions_four_lanes_at_a_time():
    kernel = type(get_model("nonlinear")).force_kernel
    asm = _fresh_asm(kernel.py_func, FORCE_SIGNATURE, KERNEL_OPTIONS)
    assert re.search(r"vsqrtpd\s+[^\n]*%[yz]mm", asm) and re.search(r"vdivpd\s+[^\n]*%[yz]mm", asm)


@pytest.mark.parametrize("name", nonlinear_quick(available_models()))
def test_every_bond_kernel_vectorises(name):
    """The bonds' forces and exact Jacobian (the periodic orbits' variational equations) are computed across bonds in SIMD lanes."""
    kernel = type(get_model(name)).bond_kernel
    fresh = njit(FORCE_SIGNATURE, **{**KERNEL_OPTIONS, "cache": False})(kernel.py_func)
    asm = fresh.inspect_asm(fresh.signatures[0])
    assert len(PACKED.findall(asm)) >= 40  # at least one packed store of every row
    if name == "nonlinear":
        assert re.search(r"vsqrtpd\s+[^\n]*%[yz]mm", asm) and re.search(r"vdivpd\s+[^\n]*%[yz]mm", asm)


def test_the_kick_drift_vectorises_with_its_energy_sums():
    options = {**engine._KICK_OPTIONS, "cache": False}
    row = njit(**options)(engine._kick_drift_row.py_func)
    batch = njit(**options)(engine._kick_drift_batch.py_func)

    rows = np.zeros((3, 64))
    row(rows, rows.copy(), rows.copy(), 0, 1, 63, 1.0, 0.0, 0.0, 1.0, 0.0, 1.0)
    # A batch of 8 members of 8 columns, flat (3, 8 x 8), with its (S+1, S+1, 6, 3, B) factors.
    batch(rows, rows.copy(), rows.copy(), np.ones((2, 2, 6, 3, 8)), 0, 1, np.zeros(8), np.zeros(8), 1, 7)
    for fresh in (row, batch):
        assert len(PACKED.findall(fresh.inspect_asm(fresh.signatures[0]))) >= 4


@pytest.mark.parametrize("name", nonlinear_quick(available_models()))
def test_every_graded_kernel_vectorises(name):
    """The per-bond coefficients (a graded chain, issue 14) keep the interior loop packed."""
    kernel = type(get_model(name)).graded_kernel
    assert packed_instructions(kernel, FORCE_SIGNATURE, KERNEL_OPTIONS) >= 12


def test_the_per_column_kick_drift_of_graded_inertia_vectorises():
    options = {**engine._KICK_OPTIONS, "cache": False}
    columns = njit(**options)(engine._kick_drift_columns.py_func)
    rows = np.zeros((3, 64))
    pairs = np.ones((2, 2, 6, 3, 64))
    columns(rows, rows.copy(), rows.copy(), pairs, 0, 1, 1, 63, 1.0)
    assert len(PACKED.findall(columns.inspect_asm(columns.signatures[0]))) >= 4


def test_the_nonlinear_hessian_sums_take_square_roots_and_divisions_several_bonds_at_a_time():
    # models/nonlinear.py::_hessian_sums is written for SIMD across bonds (the statics'
    # assembly: 0.13 -> 0.02 ms at N = 1000); an aliasing or wrap-around check it could not
    # prove would leave the loop scalar.
    from cosserat_chain import ChainParams
    from cosserat_chain.models import nonlinear

    fresh = njit(nogil=True, error_model="numpy", cache=False)(nonlinear._hessian_sums.py_func)
    params = ChainParams(N=40)
    x = np.zeros((3, params.n_particles))
    fresh(x, params.h, *nonlinear._link_tables(params), np.empty((10, params.n_bonds)))
    asm = fresh.inspect_asm(fresh.signatures[0])
    assert re.search(r"vsqrtpd\s+[^\n]*%[yz]mm", asm) and re.search(r"vdivpd\s+[^\n]*%[yz]mm", asm)
    assert len(PACKED.findall(asm)) >= 40
