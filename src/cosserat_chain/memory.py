"""Memory estimates checked before large allocations.

Contract
--------
A computation whose arrays grow with the chain (frames x particles x variables, a
branch of states, a dense monodromy matrix) calls :func:`require` with its estimate
before it allocates anything. An estimate beyond the memory this machine has free
raises :class:`MemoryEstimateError` (a ``ValueError``: bad input for the command
line, exit code 2) with the number, what it is made of and what to change, instead of
failing hours later or taking the machine down.
"""

from __future__ import annotations

import psutil

from .errors import CosseratChainError

#: Bytes of one float64.
FLOAT = 8

#: Share of the free memory a single computation may plan to use: the rest is left to
#: temporaries the estimate does not count and to the other programs on the machine.
USABLE = 0.8


class MemoryEstimateError(CosseratChainError, ValueError):
    """A computation would need more memory than this machine has free."""


def available() -> int:
    """Bytes of memory free for a new allocation now (physical memory not in use, caches counted as free)."""
    return int(psutil.virtual_memory().available)


def size_text(nbytes: float) -> str:
    """``nbytes`` in binary units, e.g. ``'2.1 TiB'``."""
    value = float(nbytes)
    for unit in ("B", "KiB", "MiB", "GiB", "TiB", "PiB"):
        if value < 1024 or unit == "PiB":
            return f"{value:.3g} {unit}" if unit != "B" else f"{value:.0f} B"
        value /= 1024
    raise AssertionError("unreachable")


def require(nbytes: float, what: str, hint: str = "") -> None:
    """Refuse a computation whose estimated memory exceeds :data:`USABLE` of the free memory.

    Parameters
    ----------
    nbytes : float
        Estimated bytes of the computation's arrays.
    what : str
        What the estimate is made of, e.g. ``"201 frames x 3 rows x 2000000001 particles (N=1000000000) x 2 arrays"``.
    hint : str
        What to change to make it fit (fewer frames, a shorter chain).

    Raises
    ------
    MemoryEstimateError
    """
    free = available()
    if nbytes > USABLE * free:
        raise MemoryEstimateError(
            f"not enough memory: {what} needs about {size_text(nbytes)}, and this machine has {size_text(free)} free"
            + (f"; {hint}" if hint else "")
        )
