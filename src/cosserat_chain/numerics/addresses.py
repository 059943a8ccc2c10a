"""Compiled functions handed to compiled code by their addresses: Numba's dispatcher then skips their look-up.

Contract
--------
The package's compiled loops (:mod:`.dop853`'s integrator, :mod:`.engine`'s advance) take their
right-hand sides and force kernels as first-class function arguments. Called from Python with a
compiled function (a Numba dispatcher) in such an argument, Numba looks up that function's
compiled overload and its address at every call. :func:`entry` finds the address once and hands
it over through Numba's wrapper-address protocol: the same compiled code runs, through the same
address, with no look-up; results are bitwise the same.
"""

from __future__ import annotations

from numba import types
from numba.core.typing.typeof import typeof_impl
from numba.experimental.function_type import _get_wrapper_address


class _Entry(types.WrapperAddressProtocol):
    """A compiled function handed to compiled code as a first-class function by its address, found once.

    Numba's dispatcher looks up the compiled overload and its address of every function argument at
    every call (:func:`entry`); this object gives the address it was made with.
    """

    def __init__(self, function, kind: types.FunctionType) -> None:
        self.function, self.kind = function, kind
        self.address = _get_wrapper_address(function, kind.signature)

    def __wrapper_address__(self) -> int:
        return self.address

    def signature(self):
        return self.kind.signature


@typeof_impl.register(_Entry)
def _typeof_entry(value: _Entry, context) -> types.FunctionType:
    """The Numba type of an :class:`_Entry` argument: the type it was made with, not one built anew at every call.

    Numba's own rule for wrapper-address objects builds a fresh ``FunctionType`` from the signature
    each time the dispatcher types the argument; the type is the same, so the compiled code chosen is
    the same.
    """
    return value.kind


_ENTRIES: dict = {}


def entry(function, kind: types.FunctionType):
    """``function`` (a compiled function) as a first-class function argument of type ``kind`` that compiled code
    enters with no look-up: the same compiled code, called through the same address, as ``function`` itself.

    A function Numba cannot address so (a plain Python function) is returned as it is.
    """
    if isinstance(function, _Entry):
        return function
    key = (function, kind)
    found = _ENTRIES.get(key)
    if found is None:
        try:
            found = _Entry(function, kind)
        except (TypeError, ValueError, NotImplementedError, AttributeError):
            found = function
        _ENTRIES[key] = found
    return found
