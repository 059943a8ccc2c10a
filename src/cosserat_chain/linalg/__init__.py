"""The linear-algebra floor: band storage and factors, bordered solves, norms, eigenvalues, refined solves.

Contract
--------
Plain matrices and vectors in, numbers out: nothing here knows a chain, a model or its
parameters (it imports NumPy, SciPy and Numba only), so the models, the numerics and the
analyses above all share one implementation, and tests check each piece against dense
NumPy/SciPy references directly (``tests/test_linalg.py``).

* :mod:`.band`: :class:`BandMatrix`, the padded storage of half-bandwidth
  :data:`BANDWIDTH` every compiled kernel reads; the band LU of -M (:func:`negated_lu`),
  the LDL^T of M - s I (:func:`ldlt`) and its inertia (:func:`negative_count`); LAPACK's
  upper band storage; the ordered scatters that assemble a matrix from its terms.
* :mod:`.bordered`: the band matrix bordered by e_dof and a dense row, the statics'
  pseudo-arclength and rotation-controlled systems: :class:`BorderedFactor`,
  :func:`bordered_solve`, :func:`sparse_solve`.
* :mod:`.norms`: :func:`infinity_norm`, :func:`dot`, :func:`euclidean_norm`, compiled and
  on the calling thread.
* :mod:`.eigen`: the smallest eigenvalue of a symmetric band matrix by inverse iteration
  certified by inertia, the largest by bisection, the leftmost of any sparse matrix, and every
  eigenpair (:func:`band_eigenpairs`) by inverse iteration with band LU factors.
* :mod:`.pencil`: the damped pencil K + z R + z^2 I: eigenvalues near the axis by
  shift-invert, the count right of it by the argument principle.
* :mod:`.refinement`: solves refined with residuals in extended precision.
* :mod:`.root`: solves with K = A^T A from A's banded rows (Givens QR), which keep a long chain's soft modes.
* :mod:`.general`: dense-or-sparse matrices of any structure (the continuation kit's):
  :func:`solve`, :func:`append_row`, :func:`determinant_sign`.

The compiled kernels are cached on disk (``cache=True``) and keep a fixed order of
operations: the same inputs give the same bits on every run and thread count.
"""

from .band import BANDWIDTH, BandMatrix, band_storage, from_upper_bands, ldlt, negated_lu, negative_count, upper_bands
from .bordered import BorderedFactor, bordered_jacobian, bordered_solve, rotation_controlled_jacobian, sparse_solve
from .eigen import band_eigenpairs, eigenvalue_resolution, largest_eigenvalue_bound, lowest_real_eigenvalue, smallest_eigenvalue
from .mixed import MixedBorderedFactor, MixedFactor, StiffnessRows
from .norms import dot, euclidean_norm, infinity_norm
from .refinement import Refined, refined_solve
from .root import RootFactor

__all__ = [
    "BANDWIDTH",
    "BandMatrix",
    "BorderedFactor",
    "MixedBorderedFactor",
    "MixedFactor",
    "Refined",
    "RootFactor",
    "StiffnessRows",
    "band_eigenpairs",
    "band_storage",
    "bordered_jacobian",
    "bordered_solve",
    "dot",
    "eigenvalue_resolution",
    "euclidean_norm",
    "from_upper_bands",
    "infinity_norm",
    "largest_eigenvalue_bound",
    "ldlt",
    "lowest_real_eigenvalue",
    "negated_lu",
    "negative_count",
    "refined_solve",
    "rotation_controlled_jacobian",
    "smallest_eigenvalue",
    "sparse_solve",
    "upper_bands",
]
