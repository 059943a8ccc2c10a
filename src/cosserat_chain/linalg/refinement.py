"""Linear solves of a long chain to more digits than its condition number leaves a double-precision solve.

Contract
--------
:func:`refined_solve` solves A x = b for a sparse A by SuperLU in double precision and
then refines x with residuals in extended precision (``numpy.longdouble``; mixed-precision
iterative refinement, Wilkinson): each step solves A dx = b - A x with the same factor and
adds dx, with x and the residual carried in extended precision.

Why: a clamped chain's stiffness has its softest eigenvalue at N^-4 (the bending mode), so
its condition number is about 4e16 at N = 10^4, beyond 1/eps. Two double-precision
factorisations of K (SuperLU, LAPACK's banded Cholesky) then disagree in the third digit of
the compliance phi_0 / M (15434.5 and 15377.4 for the paper's chain at N = 10^4). Refined,
both give 15625.0001 to 1e-9 after about 12 steps (each an O(N) solve with the factor and
an O(N) residual). What remains is the problem's own: K's entries are rounded to
double, and the three models' K at rest (equal in exact arithmetic, assembled each its own
way) give compliances that differ by 2e-10 at N = 1000 and 4e-8 at N = 10^4.

The refined solution's error is then set by the residual's precision: about cond(A) times
the extended type's eps (1.1e-19 on x86-64) at worst, instead of cond(A) times double's
(tested on the integer biharmonic system of condition 1.6e15: 4e-7 against 3e-4). Where
the extended type is no wider than double (some platforms), or the steps stop shrinking,
the result says how far it got: :attr:`Refined.uncertainty` holds the size of the last
corrections, per component, never a precision it did not reach.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

#: Most refinement steps (the paper's chain at N = 10^4 settles in about 12).
MAX_STEPS = 40
#: Steps without a new smallest correction after which the refinement has settled.
PATIENCE = 4


@dataclass(frozen=True)
class Refined:
    """A refined solution.

    Attributes
    ----------
    x : ndarray
        The solution, rounded to double precision.
    uncertainty : ndarray
        Per component, the largest of the last :data:`PATIENCE` corrections (the first
        solve excluded): the refinement's own estimate of each component's error, since the
        corrections stop shrinking at the residual's round-off.
    steps : int
        Solves with the factor (the first one and the refinement steps).
    """

    x: np.ndarray
    uncertainty: np.ndarray
    steps: int

    @property
    def error(self) -> float:
        """max uncertainty / max |x|: the solution's estimated relative error as a whole."""
        scale = float(np.abs(self.x).max()) if self.x.size else 0.0
        return float(self.uncertainty.max()) / scale if scale > 0 else 0.0

    def relative_error(self, index: int) -> float:
        """Estimated relative error of component ``index`` (inf where it is zero and uncertain)."""
        value, spread = abs(float(self.x[index])), float(self.uncertainty[index])
        return spread / value if value > 0 else (0.0 if spread == 0 else np.inf)


def refined_solve(matrix: sp.spmatrix, rhs: np.ndarray, solve: Callable[[np.ndarray], np.ndarray] | None = None) -> Refined:
    """Solve ``matrix`` x = ``rhs`` to the precision of residuals in extended precision (module docstring).

    ``solve``: the double-precision solve with a factor of ``matrix`` that the steps use
    (default SuperLU's); another factorisation's (LAPACK's banded Cholesky) gives an
    independent check of the refined result.

    Raises
    ------
    ValueError
        If the matrix is singular (the factor or a correction is not finite).
    """
    csr = sp.csr_matrix(matrix)
    if solve is None:
        import scipy.sparse.linalg as spla  # here, not at import: small chains' statics never use it

        try:
            solve = spla.splu(csr.tocsc()).solve
        except RuntimeError as err:  # SuperLU: "Factor is exactly singular"
            raise ValueError(f"the matrix is singular: {err}") from None
    data = csr.data.astype(np.longdouble)
    starts = csr.indptr[:-1]
    empty = csr.indptr[1:] == starts  # reduceat would copy the next row's first product into an empty row
    target = np.asarray(rhs, dtype=np.longdouble)
    x = np.zeros(csr.shape[0], dtype=np.longdouble)
    residual = target.copy()
    corrections: list[np.ndarray] = []
    best, since_best = np.inf, 0
    for step in range(1, MAX_STEPS + 2):
        correction = solve(np.asarray(residual, dtype=float))
        if not np.all(np.isfinite(correction)):
            raise ValueError("the matrix is singular: a correction is not finite")
        x += correction
        products = data * x[csr.indices]
        applied = np.add.reduceat(products, starts) if products.size else np.zeros_like(x)
        applied[empty] = 0.0
        residual = target - applied
        if step == 1:
            continue  # the solve itself, not a correction
        corrections.append(np.abs(correction))
        size = float(corrections[-1].max()) if correction.size else 0.0
        if size < best:
            best, since_best = size, 0
        else:
            since_best += 1
        if size == 0.0 or since_best >= PATIENCE:
            break
    uncertainty = np.max(corrections[-PATIENCE:], axis=0) if corrections else np.zeros(csr.shape[0])
    return Refined(np.asarray(x, dtype=float), uncertainty, step)
