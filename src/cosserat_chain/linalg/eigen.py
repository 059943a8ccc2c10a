"""Extreme eigenvalues of a chain's symmetric band matrices, in O(n) a factor, certified by their inertia.

Contract
--------
:func:`smallest_eigenvalue` (and :func:`smallest_band_eigenvalue`, on the storage, with a
guess and a warm start) finds the smallest eigenvalue of a symmetric matrix within the band
(:mod:`.band`) by inverse iteration with banded LDL^T factors, certified by their inertia
(Sylvester's law: the negative pivots of a factor of M - s I count the eigenvalues below s);
bisection on that count is the fallback. Where the lowest eigenvalues crowd (the edge of a
band of a long chain's spectrum) Krylov methods slow down with n and this does not; LAPACK's
banded eigensolver is O(n^2) (benchmarks/TIMINGS.md). :func:`eigenvalue_resolution` is the
round-off of the result.

:func:`largest_eigenvalue_bound` brackets the largest eigenvalue of a symmetric banded
matrix of any bandwidth by bisection with LAPACK's banded Cholesky.
:func:`band_eigenpairs` is every eigenpair of a symmetric band matrix of any bandwidth w,
without a dense matrix: the eigenvalues by LAPACK's band reduction (O(n^2 + n w^2)), each
eigenvector by inverse iteration with a band LU (O(n w^2) each, O(n^2 w^2) in all), where
LAPACK's own eigenvectors (the band reduction's rotations accumulated) cost O(n^3).
:func:`lowest_real_eigenvalue` is the eigenvalue of smallest real part of any sparse matrix,
through its symmetric similar (:func:`diagonal_similar_symmetric`) where a diagonal
similarity gives one.

:func:`largest_and_nearest` is the eigenvalues of largest modulus of a general operator and
those nearest a shift (shift-invert), by ARPACK, merged: the Floquet multipliers of long
orbits, where they crowd near 1 (collocation, long-orbit shooting).
"""

from __future__ import annotations

import math
from functools import lru_cache

import numpy as np
import scipy.sparse as sp
from numba import njit
from scipy.linalg import LinAlgError, cholesky_banded, eig_banded
from scipy.linalg.lapack import dgbtrf, dgbtrs

from .band import BANDWIDTH, BandMatrix, band_storage, ldlt, upper_bands
from .norms import euclidean_norm, infinity_norm

#: Relative width (to the Gershgorin radius) at which the bisection for the smallest eigenvalue stops.
BISECTION_RTOL = 1e-14
#: Inverse-iteration steps with one factor before the shift moves (each an O(n w) solve).
INVERSE_STEPS = 12


def smallest_eigenvalue(matrix: sp.spmatrix | BandMatrix) -> tuple[float, float]:
    """The smallest eigenvalue of a symmetric matrix within the band (:mod:`.band`), and its round-off, O(n) a factor.

    Inverse iteration certified by the inertia of banded LDL^T factors, with bisection
    on that count as the fallback (:func:`smallest_band_eigenvalue`): where the lowest
    eigenvalues crowd (the edge of a band of a long chain's spectrum), Krylov methods
    slow down with n and this does not.

    Raises
    ------
    ValueError
        If the matrix is wider than the band.
    """
    band = band_storage(matrix)
    resolution = eigenvalue_resolution(matrix)
    value, _ = smallest_band_eigenvalue(band, resolution / BISECTION_RTOL)
    return value, resolution


def eigenvalue_resolution(matrix) -> float:
    """BISECTION_RTOL times the Gershgorin radius of ``matrix`` (sparse, banded or dense)."""
    if sp.issparse(matrix) or isinstance(matrix, BandMatrix):
        return BISECTION_RTOL * infinity_norm(matrix)
    return BISECTION_RTOL * float(abs(matrix).sum(axis=1).max()) if matrix.shape[0] else 0.0


@njit(cache=True, nogil=True)
def _inverse_step(factor, inverse, shift, vector, work):  # pragma: no cover - compiled
    """One step of inverse iteration, ``vector`` <- (L D L^T)^-1 vector normalised; returns its Rayleigh quotient.

    With A = L D L^T = M - shift I and y = A^-1 x, the quotient of y is
    shift + x^T y / y^T y: no cancellation, unlike y^T M y, whose round-off (n eps |M|)
    exceeds a long chain's critical eigenvalue. ``work``: as long as the factor has rows.
    Each substitution carries the last B unknowns solved in registers
    (B = :data:`~.band.BANDWIDTH` = 5) and subtracts the term of the one
    solved last at the end: only one multiply-add a row waits for it, and nothing waits on
    a store and its reload (benchmarks/TIMINGS.md). The back substitution
    forms x^T y and y^T y as it goes, in four partial sums each.
    """
    n = vector.size
    w1 = w2 = w3 = w4 = w5 = 0.0
    for i in range(n):  # L y = b, then D^-1
        r = i + BANDWIDTH
        total = vector[i] - factor[r, 5] * w5
        total -= factor[r, 4] * w4
        total -= factor[r, 3] * w3
        total -= factor[r, 2] * w2
        total -= factor[r, 1] * w1
        work[r] = total * inverse[r]
        w5, w4, w3, w2, w1 = w4, w3, w2, w1, total
    w1 = w2 = w3 = w4 = w5 = 0.0
    cross = np.zeros(4)
    square = np.zeros(4)
    for i in range(n - 1, -1, -1):  # L^T z = y
        r = i + BANDWIDTH
        total = work[r] - factor[r + 5, 5] * w5
        total -= factor[r + 4, 4] * w4
        total -= factor[r + 3, 3] * w3
        total -= factor[r + 2, 2] * w2
        total -= factor[r + 1, 1] * w1
        cross[i % 4] += vector[i] * total
        square[i % 4] += total * total
        vector[i] = total
        w5, w4, w3, w2, w1 = w4, w3, w2, w1, total
    size = (square[0] + square[1]) + (square[2] + square[3])
    quotient = shift + ((cross[0] + cross[1]) + (cross[2] + cross[3])) / size
    vector /= math.sqrt(size)
    return quotient


@njit(cache=True, nogil=True)
def _smallest_eigenvalue_compiled(band, low, high, tolerance, guess, vector):  # pragma: no cover - compiled
    """The smallest eigenvalue of ``band`` in [low, high] to ``tolerance``: inverse iteration certified by the inertia.

    Below the smallest eigenvalue lambda_min, M - shift I is positive definite: its
    LDL^T is stable and inverse iteration with it converges to the lowest eigenvector
    at the rate (lambda_1 - shift) / (lambda_2 - shift), each step a cheap banded solve
    with the same factor. The Rayleigh quotient rho is an upper bound of lambda_min, and
    no eigenvalue below rho - tolerance (a count of zero) certifies it. The first shift
    is just below ``guess``; while eigenvalues lie below the shift it moves down by
    growing distances (a chain's critical eigenvalue is small: a few factors settle it),
    then to the middle of the bracket, so the result is never worse than bisection
    (about 50 factors).

    Returns the eigenvalue and a lower bound of it: ``low`` is the Gershgorin bound or
    a shift whose factor has no negative pivot.
    """
    factor = np.zeros((band.shape[0], BANDWIDTH + 1))
    inverse = np.zeros(band.shape[0])
    work = np.zeros(band.shape[0])
    distance = max(0.05 * abs(guess), tolerance)
    shift = guess - distance if low < guess - distance < high else 0.5 * (low + high)
    width = high - low
    below_found = False
    while high - low > tolerance:
        if ldlt(band, shift, factor, inverse) > 0:
            high = shift
        else:
            low = shift
            below_found = True
            previous, decrease = math.inf, math.inf
            for _ in range(INVERSE_STEPS):
                quotient = _inverse_step(factor, inverse, shift, vector, work)
                high = min(high, quotient)
                # Converged, or converging too slowly for this shift (a closer one is cheaper).
                if previous - quotient <= tolerance or previous - quotient > 0.5 * decrease:
                    break
                previous, decrease = quotient, previous - quotient
            if high - low > tolerance:
                if ldlt(band, high - tolerance, factor, inverse) == 0:
                    return high, max(low, high - tolerance)
                high -= tolerance
        distance = max(4.0 * distance, 1e-6 * width)
        shift = 0.5 * (low + high) if below_found else max(0.5 * (low + high), high - distance)
    return 0.5 * (low + high), low


@lru_cache(maxsize=8)
def _start_vector(n: int) -> np.ndarray:
    """The fixed start vector of inverse iteration, drawn once a size, not once a point (benchmarks/TIMINGS.md)."""
    vector = np.random.default_rng(0).standard_normal(n)
    vector.flags.writeable = False
    return vector


def smallest_band_eigenvalue(
    band: np.ndarray, radius: float, guess: float | None = None, start: np.ndarray | None = None
) -> tuple[float, float]:
    """Smallest eigenvalue to round-off of the matrix's scale, O(n) a round (:func:`_smallest_eigenvalue_compiled`),
    and a lower bound of it certified by a factor without negative pivots (-``radius`` if none was).

    ``start``: see :func:`~cosserat_chain.numerics.stability.static_stability` (overwritten with the last iterate)."""
    n = band.shape[0] - 2 * BANDWIDTH  # the rows of the chain (the storage is padded)
    low, high = -radius, float(band[BANDWIDTH : n + BANDWIDTH, BANDWIDTH].min())  # Gershgorin, and lambda_min <= min diagonal
    # A fixed generic start vector: deterministic, and with a component along any
    # mode (all ones would miss an antisymmetric lowest mode and leave it to the bisection).
    # A given start that is not a usable vector (zero, or not finite after a factor
    # with a nudged zero pivot) is reset to it.
    if start is None:
        vector = _start_vector(n).copy()  # the compiled search overwrites it
    else:
        if start.shape != (n,):
            raise ValueError(f"start has shape {start.shape}, expected ({n},)")
        vector = start
        if not 0.0 < euclidean_norm(vector) < math.inf:
            vector[:] = _start_vector(n)
    tolerance = max(BISECTION_RTOL * radius, 1e-300)
    try:
        value, bound = _smallest_eigenvalue_compiled(band, low, high, tolerance, 0.0 if guess is None else float(guess), vector)
    except ZeroDivisionError:
        # A pivot of exactly zero in every nudge: entries so far from O(1) that the shifts vanish against them.
        sizes = np.abs(band[np.nonzero(band)])
        raise FloatingPointError(
            "the smallest eigenvalue of the stiffness matrix cannot be searched in double precision: its entries span "
            f"{sizes.min():.3g} to {sizes.max():.3g} (a chain far from unit scale: give its lengths, stiffnesses and "
            "inertia in units where they are of order one)"
        ) from None
    return float(value), float(bound)


def largest_eigenvalue_bound(matrix: sp.spmatrix, rtol: float) -> float:
    """An upper bound of the largest eigenvalue of a symmetric sparse banded matrix, within ``rtol`` times its Gershgorin bound.

    Bisection between its largest diagonal entry and the Gershgorin bound (the largest
    absolute row sum): sigma I - M is positive definite exactly when sigma > lambda_max,
    which a banded Cholesky factorisation (LAPACK's) tells, O(n w^2) a step with no dense
    matrix; the upper end of the final bracket is returned.
    """
    gershgorin = float(abs(matrix).sum(axis=1).max())
    negative = upper_bands(-matrix)
    bandwidth = negative.shape[0] - 1
    low, high = float(matrix.diagonal().max()), gershgorin
    while high - low > rtol * gershgorin:
        middle = 0.5 * (low + high)
        shifted = negative.copy()
        shifted[bandwidth] += middle
        try:
            cholesky_banded(shifted, check_finite=False)
        except LinAlgError:
            low = middle
        else:
            high = middle
    return high


#: Inverse-iteration steps of :func:`band_eigenpairs` for each eigenvalue, from a fixed start, with one LU of M - lambda I:
#: each divides the other eigenvectors' components by |lambda_j - lambda| / (round-off of lambda), >= 1e-9 / 1e-14 outside a cluster.
PAIR_STEPS = 3
#: Eigenvalues of :func:`band_eigenpairs` within this times the Gershgorin radius of the last one are a cluster:
#: each eigenvector is orthogonalised against the cluster's earlier ones (inverse iteration alone cannot split them).
#: Small: a long chain's flat band edges chain a wider threshold's clusters over hundreds of modes (O(n^3) again).
CLUSTER_RTOL = 1e-9


def band_eigenpairs(bands: np.ndarray, deflate: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Every eigenpair of a symmetric band matrix M, less a null space it is given, without a dense matrix.

    The eigenvalues are LAPACK's (``scipy.linalg.eig_banded``, band reduction to tridiagonal
    form without its rotations: O(n^2 + n w^2)). Each eigenvector is found by :data:`PAIR_STEPS`
    steps of inverse iteration with one band LU of M - lambda I (LAPACK's xGBTRF, partial
    pivoting), O(n w^2); LAPACK's own eigenvectors accumulate the reduction's rotations in a
    dense n x n matrix, O(n^3). Within a cluster (:data:`CLUSTER_RTOL`) each vector is
    orthogonalised against the cluster's earlier ones at every step, as LAPACK's xSTEIN does.

    Parameters
    ----------
    bands : ndarray, shape (w + 1, n)
        M in LAPACK's upper band storage (:func:`~.band.upper_bands`).
    deflate : ndarray, shape (n, r), optional
        Orthonormal columns spanning part of M's null space (a chain's rigid motions): their r
        eigenvalues (those nearest zero) are left out, and every eigenvector is kept orthogonal
        to them.

    Returns
    -------
    values : ndarray, shape (n - r,)
        Ascending.
    vectors : ndarray, shape (n, n - r)
        Orthonormal columns, orthogonal to ``deflate``.
    """
    width, n = bands.shape[0] - 1, bands.shape[1]
    deflate = np.zeros((n, 0)) if deflate is None else deflate
    values = eig_banded(bands, eigvals_only=True, check_finite=False)
    if deflate.shape[1]:
        values = np.sort(np.delete(values, np.argsort(np.abs(values), kind="stable")[: deflate.shape[1]]))
    # LAPACK's general band storage of M for its LU: rows [0, w) for the fill-in, then M[i, j] at 2w + i - j.
    general = np.zeros((3 * width + 1, n), order="F")
    general[width : 2 * width + 1] = bands
    for d in range(1, width + 1):
        general[2 * width + d, : n - d] = bands[width - d, d:]
    radius = float(np.max(np.sum(np.abs(general), axis=0), initial=0.0))
    start = _start_vector(n)
    vectors = np.empty((n, values.size))
    first = 0  # of the cluster
    for i, value in enumerate(values):
        if i and value - values[i - 1] > CLUSTER_RTOL * radius:
            first = i
        shift = value
        while True:
            shifted = general.copy(order="F")
            shifted[2 * width] -= shift
            factor, pivots, info = dgbtrf(shifted, width, width, overwrite_ab=1)
            if info == 0:
                break
            # An exactly zero pivot: the shift is the eigenvalue to the last bit; a nudge by its round-off.
            shift += np.finfo(float).eps * max(radius, abs(shift), np.finfo(float).tiny)
        vector = np.array(start)
        for _ in range(PAIR_STEPS):
            vector = dgbtrs(factor, width, width, vector, pivots)[0]
            vector -= deflate @ (deflate.T @ vector)
            cluster = vectors[:, first:i]
            vector -= cluster @ (cluster.T @ vector)
            vector /= np.linalg.norm(vector)
        vectors[:, i] = vector
    return values, vectors


#: Size up to which :func:`lowest_real_eigenvalue` computes the whole spectrum densely.
DENSE_SPECTRUM_LIMIT = 600


def diagonal_similar_symmetric(matrix: sp.spmatrix) -> sp.csc_matrix | None:
    """D A D^-1, symmetric, for a diagonal D > 0, or None where no such D exists.

    A similarity with a diagonal D makes A symmetric iff every pair of entries has
    a_ji / a_ij = d_i^2 / d_j^2 > 0 and these ratios are consistent round every cycle of
    its graph. The printed eq. (3) times M^-1 is such a matrix (its phi rows couple to v
    with a quarter of what the v rows couple to phi), and its symmetric similar has the
    same, real, spectrum. log d^2 is built along a breadth-first tree of each connected
    component, and the result is checked entry by entry (None if it is not symmetric).
    The result is CSC, symmetrised (the mean of it and its transpose).
    """
    from scipy.sparse import csgraph  # here, not at import: small chains' statics never use it

    a = sp.csr_matrix(matrix, dtype=float)
    a.eliminate_zeros()
    pattern = (a != 0).astype(np.int8)
    if pattern.nnz != (pattern + pattern.T).nnz:
        return None  # a one-sided entry: no diagonal similarity makes it symmetric
    n_components, labels = csgraph.connected_components(pattern, directed=False)
    log_d2 = np.zeros(a.shape[0])
    for component in range(n_components):
        root = int(np.flatnonzero(labels == component)[0])
        order, parent = csgraph.breadth_first_order(pattern, root, directed=False)
        children = order[1:]
        # d_k^2 / d_parent^2 = a_parent,k / a_k,parent
        forward = np.asarray(a[parent[children], children]).ravel()
        backward = np.asarray(a[children, parent[children]]).ravel()
        if np.any(forward * backward <= 0):
            return None
        step = np.log(forward / backward)
        for k, w in zip(children, step):
            log_d2[k] = log_d2[parent[k]] + w
    d = np.exp(0.5 * log_d2)
    similar = sp.diags(d) @ a @ sp.diags(1.0 / d)
    scale = float(abs(similar).max())
    if abs(similar - similar.T).max() > 1e-12 * scale:
        return None
    return (0.5 * (similar + similar.T)).tocsc()


def lowest_real_eigenvalue(matrix: sp.spmatrix) -> complex:
    """The eigenvalue of a sparse matrix with the smallest real part.

    Dense up to :data:`DENSE_SPECTRUM_LIMIT`. Beyond, where a diagonal similarity makes the
    matrix symmetric (:func:`diagonal_similar_symmetric`; the printed eq. (3) is such a
    matrix), the banded smallest eigenvalue of the symmetric similar
    (:func:`smallest_eigenvalue`: LDL^T inertia, O(N) a factor); otherwise ARPACK's eigenvalue nearest the Gershgorin lower bound of the
    real parts (shift-invert), which is the leftmost one unless a complex pair lies as
    near. The printed operator's lowest eigenvalue is the edge of a band of its spectrum
    (-5.3077 at N = 1000 and 2000): Krylov iterations slow down with N, ARPACK's and
    Lanczos's on the symmetric similar alike (benchmarks/TIMINGS.md).
    """
    if matrix.shape[0] <= DENSE_SPECTRUM_LIMIT:
        eigenvalues = np.linalg.eigvals(matrix.toarray())
        return complex(eigenvalues[np.argmin(eigenvalues.real)])
    shift = -float(abs(matrix).sum(axis=1).max()) - 1.0
    symmetric = diagonal_similar_symmetric(matrix)
    if symmetric is not None:
        try:
            return complex(smallest_eigenvalue(symmetric)[0])
        except ValueError:  # wider than the band
            pass
    import scipy.sparse.linalg as spla  # here, not at import: small chains' statics never use it

    # A wide Krylov space: the eigenvalues near the shift are clustered, and 40 vectors
    # converge in fewer restarts than ARPACK's default of 20 (benchmarks/TIMINGS.md).
    # The fixed start: ARPACK's own is random, and the eigenvalue's last digits would change from run to run.
    start = np.array(_start_vector(matrix.shape[0]))
    return complex(
        spla.eigs(matrix.tocsc(), k=1, sigma=shift, which="LM", ncv=min(matrix.shape[0] - 1, 40), v0=start, return_eigenvectors=False)[0]
    )


#: Arnoldi vectors at least of :func:`largest_and_nearest`'s ARPACK runs (and 2 count + 1): crowded leading eigenvalues
#: converge in fewer restarts in a wide Krylov space.
NEAREST_KRYLOV = 40
#: A pair of one of :func:`largest_and_nearest`'s runs (:func:`merge_eigenpairs`' sets) is the other's where the two lie within this times
#: max(1, |value|) and their unit eigenvectors' overlap |v^H w| exceeds :data:`SAME_DIRECTION`.
SAME_EIGENVALUE = 1e-6
SAME_DIRECTION = 0.99


def largest_and_nearest(product, inverse, size: int, shift: float, count: int, *, tol: float, restarts: int):
    """The ``count`` eigenvalues of largest modulus of an operator A and the ``count`` nearest ``shift``, merged.

    ARPACK runs twice: on the products z -> A z (largest modulus) and on z -> (A - shift)^-1 z
    (largest modulus nu, the eigenvalues shift + 1 / nu nearest the shift: shift-invert). Where
    eigenvalues crowd (a long chain's soft Floquet multipliers just below 1), the first run
    converges slowly or not at all within ``restarts``, the second fast where the shift lies
    within the crowd's width of it; each keeps the pairs that converged. A pair found by both
    is kept once (:func:`merge_eigenpairs`).

    Parameters
    ----------
    product, inverse : callable
        z (size,) or (size, p) -> A z and -> (A - shift)^-1 z, real.
    size : int
        The operator's size (>= 4).
    shift : float
        Where the second set is sought.
    count : int
        Eigenvalues sought by each run.
    tol, restarts : float, int
        ARPACK's relative tolerance and most implicit restarts.

    Returns
    -------
    values : ndarray complex
        The merged eigenvalues, by decreasing modulus.
    vectors : ndarray (size, len(values)) complex
        Their unit eigenvectors.
    converged : tuple of int
        How many each run converged on (largest modulus, nearest the shift), each at most ``count``.
    """
    import scipy.sparse.linalg as spla  # here, not at import: small chains' statics never use it

    k = min(count, size - 2)
    krylov = min(size - 1, max(2 * k + 1, NEAREST_KRYLOV))
    found, vectors, converged = [], [], []
    for apply, convert in ((product, lambda nu: nu), (inverse, lambda nu: shift + 1.0 / nu)):
        operator = spla.LinearOperator((size, size), matvec=apply, matmat=apply, dtype=float)
        try:
            nu, v = spla.eigs(operator, k=k, which="LM", ncv=krylov, tol=tol, maxiter=restarts, v0=np.array(_start_vector(size)))
        except spla.ArpackNoConvergence as err:
            nu, v = err.eigenvalues, err.eigenvectors
        found.append(convert(nu))
        vectors.append(v)
        converged.append(int(nu.size))
    values, v = merge_eigenpairs(product, (found[0], vectors[0]), (found[1], vectors[1]))
    return values, v, (converged[0], converged[1])


def merge_eigenpairs(product, first: tuple[np.ndarray, np.ndarray], second: tuple[np.ndarray, np.ndarray]):
    """Two sets of eigenpairs (values, vectors) of the operator ``product`` merged, by decreasing modulus (unit vectors).

    A pair of one set is the other's where the values lie within :data:`SAME_EIGENVALUE` times
    max(1, |value|) and the unit vectors' overlap exceeds :data:`SAME_DIRECTION`; of the two the
    one with the smaller residual |A v - lambda v| is kept. A set's own pairs are never merged,
    however close their values (a crowd's).
    """
    (a, va), (b, vb) = [(np.asarray(values), v / np.linalg.norm(v, axis=0)) for values, v in (first, second)]
    residual_a, residual_b = [np.linalg.norm(np.asarray(product(v)) - v * values, axis=0) for values, v in ((a, va), (b, vb))]
    keep_a, keep_b = np.ones(a.size, dtype=bool), np.ones(b.size, dtype=bool)
    for i in range(a.size):
        for j in np.flatnonzero(keep_b):
            if abs(a[i] - b[j]) <= SAME_EIGENVALUE * max(1.0, abs(b[j])) and abs(np.vdot(va[:, i], vb[:, j])) > SAME_DIRECTION:
                keep_a[i] = residual_a[i] < residual_b[j]
                keep_b[j] = not keep_a[i]
                break
    values = np.concatenate([a[keep_a], b[keep_b]])
    vectors = np.concatenate([va[:, keep_a], vb[:, keep_b]], axis=1)
    order = np.argsort(-np.abs(values), kind="stable")
    return values[order], vectors[:, order]
