"""The dense matrix of banded rows (values from each row's first column on), the form RootFactor and MixedFactor take."""

from __future__ import annotations

import numpy as np

from cosserat_chain.linalg.root import ROW_WIDTH


def dense_rows(values: np.ndarray, starts: np.ndarray, n: int) -> np.ndarray:
    """Row i holds ``values[i]`` from column ``starts[i]`` on, cut at the n-th column."""
    a = np.zeros((len(starts), n))
    for i, (row, first) in enumerate(zip(values, starts)):
        width = min(ROW_WIDTH, n - first)
        a[i, first : first + width] = row[:width]
    return a
