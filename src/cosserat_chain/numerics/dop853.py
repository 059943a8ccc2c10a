"""Dormand-Prince 8(5,3), compiled: the one adaptive integrator of the package (reference runs, periodic orbits).

Contract
--------
:func:`solve` integrates y' = f(t, y) from ``times[0]`` and returns y at every time of
``times``. The right-hand side is a compiled function of the one signature
:data:`RHS_SIGNATURE`,

    rhs(force, end_force, t, y, coef, rpar, ipar, dy) -> None, overwriting every entry of dy with f(t, y),

where ``force`` and ``end_force`` (a model's force and end kernels) and ``coef`` (its coefficients) are passed through
untouched for the chain's forces, and ``rpar`` (float64) and ``ipar`` (int64) are flat vectors
holding whatever else the right-hand side reads, as RPAR and IPAR of Hairer's ``dop853.f``.
Because right-hand sides and kernels are first-class functions, one compiled and cached
integrator serves every right-hand side and every model (a closure would defeat the cache);
:func:`solve` hands them over by their addresses (:func:`~.addresses.entry`), so that a call
costs no look-up of them.

The method is DOP853 of Hairer, Norsett & Wanner (Solving Ordinary Differential Equations I,
2nd ed., Sec. II.10; the coefficients below are those of the public ``dop853.f``, as SciPy
also tabulates them), with the error norm and step control of ``scipy.integrate.DOP853``, so
that a tolerance means what it means there:

* a step h from (t, y) to y1 is accepted when the combined estimate
  err = |h| e5^2 / sqrt((e5^2 + 0.01 e3^2) n), from the 5th- and 3rd-order embedded
  differences (rows :data:`E5`, :data:`E3`) in the sum-of-squares norm over the n components,
  each scaled by atol + rtol max(|y_i|, |y1_i|), is below 1;
* after an accepted step the next one is h min(10, 0.9 err^(-1/8)) (at most h if the step had
  been rejected before), a rejected step is retried with h max(0.2, 0.9 err^(-1/8)); the first
  step is SciPy's (and Hairer's) estimate from f(t0, y0) and one Euler step;
* FSAL: f(t + h, y1) is the first stage of the next step. It is evaluated once the step is
  accepted, as in ``dop853.f``: the error estimate does not need it;
* steps are clipped onto the output times, so the states there are steps of the method (no
  dense output); a step shortened by an output time does not shorten the next one.

A run that cannot finish (more than ``max_steps`` attempted steps, or a step size fallen to
round-off, which is what a blow-up or a non-finite right-hand side leads to) is returned with
its status and the outputs reached, not raised; bad input raises ValueError.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numba import njit, types

from ..models.base import END_KERNEL_TYPE, FORCE_KERNEL_TYPE, no_ends
from ..status import Status
from .addresses import entry

#: Signature of every right-hand side: rhs(force, end_force, t, y, coef, rpar, ipar, dy) -> None.
RHS_SIGNATURE = types.void(
    FORCE_KERNEL_TYPE,
    END_KERNEL_TYPE,
    types.float64,
    types.float64[::1],
    types.float64[::1],
    types.float64[::1],
    types.int64[::1],
    types.float64[::1],
)
#: The first-class function type :func:`solve` takes.
RHS_TYPE = types.FunctionType(RHS_SIGNATURE)

#: Stages of a step (the FSAL evaluation f(t + h, y1) is the next step's first).
N_STAGES = 12
#: Nodes c_i (dop853.f: C2..C12; c_1 = 0, c_12 = 1).
C = np.array(
    [
        0.0,
        0.526001519587677318785587544488e-01,
        0.789002279381515978178381316732e-01,
        0.118350341907227396726757197510,
        0.281649658092772603273242802490,
        0.333333333333333333333333333333,
        0.25,
        0.307692307692307692307692307692,
        0.651282051282051282051282051282,
        0.6,
        0.857142857142857142857142857142,
        1.0,
    ]
)
#: Rows 2..12 of the strictly lower triangular matrix a_ij, zeros written out (dop853.f: A21..A1211).
_A_ROWS = (
    (5.26001519587677318785587544488e-2,),
    (1.97250569845378994544595329183e-2, 5.91751709536136983633785987549e-2),
    (2.95875854768068491816892993775e-2, 0.0, 8.87627564304205475450678981324e-2),
    (2.41365134159266685502369798665e-1, 0.0, -8.84549479328286085344864962717e-1, 9.24834003261792003115737966543e-1),
    (3.7037037037037037037037037037e-2, 0.0, 0.0, 1.70828608729473871279604482173e-1, 1.25467687566822425016691814123e-1),
    (
        3.7109375e-2,
        0.0,
        0.0,
        1.70252211019544039314978060272e-1,
        6.02165389804559606850219397283e-2,
        -1.7578125e-2,
    ),
    (
        3.70920001185047927108779319836e-2,
        0.0,
        0.0,
        1.70383925712239993810214054705e-1,
        1.07262030446373284651809199168e-1,
        -1.53194377486244017527936158236e-2,
        8.27378916381402288758473766002e-3,
    ),
    (
        6.24110958716075717114429577812e-1,
        0.0,
        0.0,
        -3.36089262944694129406857109825,
        -8.68219346841726006818189891453e-1,
        2.75920996994467083049415600797e1,
        2.01540675504778934086186788979e1,
        -4.34898841810699588477366255144e1,
    ),
    (
        4.77662536438264365890433908527e-1,
        0.0,
        0.0,
        -2.48811461997166764192642586468,
        -5.90290826836842996371446475743e-1,
        2.12300514481811942347288949897e1,
        1.52792336328824235832596922938e1,
        -3.32882109689848629194453265587e1,
        -2.03312017085086261358222928593e-2,
    ),
    (
        -9.3714243008598732571704021658e-1,
        0.0,
        0.0,
        5.18637242884406370830023853209,
        1.09143734899672957818500254654,
        -8.14978701074692612513997267357,
        -1.85200656599969598641566180701e1,
        2.27394870993505042818970056734e1,
        2.49360555267965238987089396762,
        -3.0467644718982195003823669022,
    ),
    (
        2.27331014751653820792359768449,
        0.0,
        0.0,
        -1.05344954667372501984066689879e1,
        -2.00087205822486249909675718444,
        -1.79589318631187989172765950534e1,
        2.79488845294199600508499808837e1,
        -2.85899827713502369474065508674,
        -8.87285693353062954433549289258,
        1.23605671757943030647266201528e1,
        6.43392746015763530355970484046e-1,
    ),
)


def _lower_triangular(rows: tuple[tuple[float, ...], ...]) -> np.ndarray:
    """(N_STAGES, N_STAGES) matrix with ``rows[i - 1]`` left-aligned in row i and zeros elsewhere."""
    a = np.zeros((N_STAGES, N_STAGES))
    for i, row in enumerate(rows, start=1):
        a[i, : len(row)] = row
    return a


#: a_ij (N_STAGES, N_STAGES), zero on and above the diagonal.
A = _lower_triangular(_A_ROWS)
#: Weights b_i of the 8th-order solution (dop853.f: B1..B12).
B = np.array(
    [
        5.42937341165687622380535766363e-2,
        0.0,
        0.0,
        0.0,
        0.0,
        4.45031289275240888144113950566,
        1.89151789931450038304281599044,
        -5.8012039600105847814672114227,
        3.1116436695781989440891606237e-1,
        -1.52160949662516078556178806805e-1,
        2.01365400804030348374776537501e-1,
        4.47106157277725905176885569043e-2,
    ]
)
#: Weights of the embedded 3rd-order solution (dop853.f: BHH1..BHH3 at stages 1, 9, 12).
BHH = np.array(
    [0.244094488188976377952755905512, 0, 0, 0, 0, 0, 0, 0, 0.733846688281611857341361741547, 0, 0, 0.220588235294117647058823529412e-1]
)
#: The 3rd-order error row b - bhh.
E3 = B - BHH
#: The 5th-order error row (dop853.f: ER1, ER6..ER12).
E5 = np.array(
    [
        0.1312004499419488073250102996e-1,
        0.0,
        0.0,
        0.0,
        0.0,
        -0.1225156446376204440720569753e1,
        -0.4957589496572501915214079952,
        0.1664377182454986536961530415e1,
        -0.3503288487499736816886487290,
        0.3341791187130174790297318841,
        0.8192320648511571246570742613e-1,
        -0.2235530786388629525884427845e-1,
    ]
)

#: Step control of scipy.integrate.DOP853: safety factor and bounds of the step-size ratio.
SAFETY = 0.9
MIN_FACTOR = 0.2
MAX_FACTOR = 10.0
#: The error estimate is O(h^8): the step ratio is err^(-1/8).
ERROR_EXPONENT = -1.0 / 8.0
#: Default limit on attempted steps (accepted and rejected), as NMAX of dop853.f.
MAX_STEPS = 10_000_000
#: Below 100 machine epsilons the error test would only see round-off (SciPy raises rtol to it).
MIN_RTOL = 100 * np.finfo(float).eps
#: Components a step's stage sums handle at a time (their partial sums a few kB: in the L1 cache).
STRIP = 512

_COMPLETED, _MAX_STEPS, _STEP_TOO_SMALL = 0, 1, 2
_STATUS = {_COMPLETED: Status.COMPLETED, _MAX_STEPS: Status.MAX_STEPS, _STEP_TOO_SMALL: Status.STEP_TOO_SMALL}

_SOLVE_SIGNATURE = types.Tuple((types.int64, types.int64, types.int64, types.int64, types.float64))(
    RHS_TYPE,
    FORCE_KERNEL_TYPE,
    END_KERNEL_TYPE,
    types.float64[::1],
    types.float64[::1],
    types.int64[::1],
    types.float64[::1],
    types.float64,
    types.float64,
    types.int64,
    types.float64[:, ::1],
)


@njit(cache=True, nogil=True, error_model="numpy")
def _rms(v, y, rtol, atol):  # pragma: no cover - compiled
    total = 0.0
    for i in range(v.size):
        total += (v[i] / (atol + abs(y[i]) * rtol)) ** 2
    return math.sqrt(total / v.size)


@njit(cache=True, nogil=True, error_model="numpy")
def _initial_step(rhs, force, end_force, coef, rpar, ipar, t0, y0, f0, interval, rtol, atol, y1, f1):  # pragma: no cover - compiled
    # scipy.integrate._ivp.common.select_initial_step (Hairer's algorithm, Sec. II.4), order 7.
    d0 = _rms(y0, y0, rtol, atol)
    d1 = _rms(f0, y0, rtol, atol)
    h0 = 1e-6 if d0 < 1e-5 or d1 < 1e-5 else 0.01 * d0 / d1
    h0 = min(h0, interval)
    for i in range(y0.size):
        y1[i] = y0[i] + h0 * f0[i]
    rhs(force, end_force, t0 + h0, y1, coef, rpar, ipar, f1)
    for i in range(y0.size):
        f1[i] -= f0[i]
    d2 = _rms(f1, y0, rtol, atol) / h0
    if d1 <= 1e-15 and d2 <= 1e-15:
        h1 = max(1e-6, h0 * 1e-3)
    else:
        h1 = (0.01 / max(d1, d2)) ** (1.0 / 8.0)
    return min(100.0 * h0, h1, interval)


@njit(_SOLVE_SIGNATURE, cache=True, nogil=True, error_model="numpy")
def _solve(rhs, force, end_force, coef, rpar, ipar, times, rtol, atol, max_steps, out):  # pragma: no cover - compiled
    # out[0] holds y0 on entry and out[1:frames] the outputs on return, with
    # (status, frames, accepted steps, right-hand-side evaluations, t reached).
    size = out.shape[1]
    k = np.empty((N_STAGES, size))
    y = out[0].copy()
    stage = np.empty(size)
    y_new = np.empty(size)
    scaled5 = np.empty(size)
    scaled3 = np.empty(size)
    t = times[0]
    rhs(force, end_force, t, y, coef, rpar, ipar, k[0])
    h_abs = _initial_step(rhs, force, end_force, coef, rpar, ipar, t, y, k[0], times[-1] - t, rtol, atol, stage, y_new)
    evaluations = 2
    accepted = 0
    attempts = 0
    frame = 1
    while frame < times.size:
        target = times[frame]
        min_step = 10.0 * (np.nextafter(t, np.inf) - t)
        h_abs = max(h_abs, min_step)
        rejected = False
        while True:
            if h_abs < min_step:
                return _STEP_TOO_SMALL, frame, accepted, evaluations, t
            if attempts >= max_steps:
                return _MAX_STEPS, frame, accepted, evaluations, t
            attempts += 1
            clipped = t + h_abs > target
            t_new = target if clipped else t + h_abs
            h = t_new - t
            # y + h sum_r a_sr k_r, summed over the stages first as SciPy does (rk_step), a strip of
            # STRIP components at a time: the strip's partial sums stay in the L1 cache, so each stage
            # k_r is read once from memory instead of the sum being read and written once per k_r (a
            # state with variational columns outgrows the caches; the same sums in the same order).
            for s in range(1, N_STAGES):
                for low in range(0, size, STRIP):
                    # Unsigned indices: Numba then drops its wrap-around selects, which keep a loop at a
                    # run-time offset scalar (and 0-based views cost as much as the sums on a short state).
                    first = np.uint64(low)
                    width = np.uint64(min(STRIP, size - low))
                    for i in range(width):
                        stage[first + i] = 0.0
                    for r in range(s):
                        a = A[s, r]
                        if a != 0.0:
                            for i in range(width):
                                stage[first + i] += a * k[r, first + i]
                    for i in range(width):
                        stage[first + i] = y[first + i] + h * stage[first + i]
                rhs(force, end_force, t + C[s] * h, stage, coef, rpar, ipar, k[s])
            evaluations += N_STAGES - 1
            for low in range(0, size, STRIP):
                first = np.uint64(low)
                width = np.uint64(min(STRIP, size - low))
                for i in range(width):
                    y_new[first + i] = 0.0
                for r in range(N_STAGES):
                    b = B[r]
                    if b != 0.0:
                        for i in range(width):
                            y_new[first + i] += b * k[r, first + i]
            # The scaled estimates first, in a loop that vectorises, then their squares summed in order
            # (a strict-order sum is a reduction the vectoriser refuses, which kept the whole loop scalar).
            for i in range(size):
                y_new[i] = y[i] + h * y_new[i]
                scale = atol + max(abs(y[i]), abs(y_new[i])) * rtol
                e5 = 0.0
                e3 = 0.0
                for r in range(N_STAGES):
                    e5 += E5[r] * k[r, i]
                    e3 += E3[r] * k[r, i]
                scaled5[i] = e5 / scale
                scaled3[i] = e3 / scale
            err5 = 0.0
            err3 = 0.0
            for i in range(size):
                err5 += scaled5[i] ** 2
                err3 += scaled3[i] ** 2
            if err5 == 0.0 and err3 == 0.0:
                error = 0.0
            else:
                error = h * err5 / math.sqrt((err5 + 0.01 * err3) * size)
            if error < 1.0:
                break
            # A non-finite estimate (an overflow in the right-hand side) is a rejection
            # like a large one, so the step shrinks until it fails as too small.
            shrink = max(MIN_FACTOR, SAFETY * error**ERROR_EXPONENT) if math.isfinite(error) else MIN_FACTOR
            h_abs = h * shrink
            rejected = True
        factor = MAX_FACTOR if error == 0.0 else min(MAX_FACTOR, SAFETY * error**ERROR_EXPONENT)
        if rejected:
            factor = min(1.0, factor)
        # A step shortened to reach an output time says nothing against the longer one proposed.
        h_abs = max(h_abs, h * factor) if clipped else h * factor
        accepted += 1
        t = t_new
        # Loops, not slice assignments, which compile numba's shape-mismatch message.
        for i in range(size):
            y[i] = y_new[i]
        rhs(force, end_force, t, y, coef, rpar, ipar, k[0])
        evaluations += 1
        if t == target:
            for i in range(size):
                out[frame, i] = y[i]
            frame += 1
    return _COMPLETED, frame, accepted, evaluations, t


@dataclass(frozen=True)
class Solution:
    """Result of :func:`solve`.

    Attributes
    ----------
    t : ndarray (m,)
        The output times reached (all of ``times`` when completed).
    y : ndarray (m, n)
        The states there.
    status : {"completed", "max_steps", "step_too_small"}
    message : str
        What happened and, for a failure, what to try.
    reached : float
        The time of the last accepted step (``t[-1]`` when completed).
    steps : int
        Accepted steps.
    evaluations : int
        Right-hand-side evaluations.
    """

    t: np.ndarray
    y: np.ndarray
    status: str
    message: str
    reached: float
    steps: int
    evaluations: int

    @property
    def success(self) -> bool:
        return self.status == Status.COMPLETED


def solve(
    rhs,
    force,
    coef: np.ndarray,
    rpar: np.ndarray,
    ipar: np.ndarray,
    y0: np.ndarray,
    times: np.ndarray,
    *,
    rtol: float,
    atol: float,
    max_steps: int = MAX_STEPS,
    end_force=no_ends,
) -> Solution:
    """Integrate y' = rhs(t, y) by DOP853 from ``times[0]``, with the states at ``times``.

    Parameters
    ----------
    rhs : compiled function of signature :data:`RHS_SIGNATURE`
    force : compiled force kernel (:data:`~cosserat_chain.models.base.FORCE_SIGNATURE`)
        Passed through to ``rhs`` with ``coef``; a right-hand side without a chain ignores it.
    end_force : compiled end kernel (:data:`~cosserat_chain.models.base.END_SIGNATURE`), optional
        Passed through to ``rhs`` likewise (default the clamped chain's no-op).
    coef : ndarray (c,) float64
    rpar : ndarray (p,) float64
    ipar : ndarray (q,) int64
        Whatever else ``rhs`` reads.
    y0 : ndarray (n,)
        State at ``times[0]``; finite.
    times : ndarray (m,)
        Strictly increasing, finite, m >= 2: the start and the output times.
    rtol : float
        Relative tolerance, >= :data:`MIN_RTOL`.
    atol : float
        Absolute tolerance, > 0 (with 0 a component that stays 0, as a clamped end, would make
        the scaled error 0 / 0).
    max_steps : int
        Most attempted steps.

    Returns
    -------
    Solution
        ``y[0]`` is ``y0``; a failed run keeps the outputs it reached.

    Raises
    ------
    ValueError
        For a non-finite y0, bad times or tolerances, or max_steps < 1.
    """
    y0 = np.ascontiguousarray(y0, dtype=float)
    times = np.ascontiguousarray(times, dtype=float)
    if y0.ndim != 1 or y0.size == 0 or not np.all(np.isfinite(y0)):
        bad = np.flatnonzero(~np.isfinite(y0.ravel()))
        where = f"non-finite at index {int(bad[0])} ({y0.ravel()[bad[0]]!r})" if bad.size else f"shape {y0.shape}"
        raise ValueError(f"y0 must be a non-empty 1-d array of finite numbers, got {where}")
    if times.ndim != 1 or times.size < 2 or not np.all(np.isfinite(times)) or not np.all(np.diff(times) > 0):
        raise ValueError(f"times must be at least two finite, strictly increasing numbers, got {times!r}")
    if not (math.isfinite(rtol) and rtol >= MIN_RTOL):
        raise ValueError(f"rtol must be a finite number >= {MIN_RTOL:.3g} (100 machine epsilons), got {rtol!r}")
    if not (math.isfinite(atol) and atol > 0):
        raise ValueError(f"atol must be a finite number > 0, got {atol!r}")
    if not (isinstance(max_steps, int | np.integer) and max_steps >= 1):
        raise ValueError(f"max_steps must be an integer >= 1, got {max_steps!r}")
    out = np.empty((times.size, y0.size))
    out[0] = y0
    coef = np.ascontiguousarray(coef, dtype=float)
    rpar = np.ascontiguousarray(rpar, dtype=float)
    ipar = np.ascontiguousarray(ipar, dtype=np.int64)
    functions = (entry(rhs, _SOLVE_SIGNATURE.args[0]), entry(force, FORCE_KERNEL_TYPE), entry(end_force, END_KERNEL_TYPE))
    code, frames, steps, evaluations, t = _solve(*functions, coef, rpar, ipar, times, float(rtol), float(atol), int(max_steps), out)
    if code == _COMPLETED:
        message = f"reached t={t:.10g} in {steps} steps"
    elif code == _MAX_STEPS:
        message = (
            f"more than max_steps={max_steps} steps before t={times[frames]:.10g} (reached t={t:.10g}): increase max_steps or loosen rtol"
        )
    else:
        message = (
            f"the step size fell to round-off at t={t:.10g}: the solution blows up or turns non-finite there "
            "(check the initial state and the parameters)"
        )
    return Solution(
        t=times[:frames].copy(),
        y=out[:frames],
        status=_STATUS[code],
        message=message,
        reached=float(t),
        steps=steps,
        evaluations=evaluations,
    )
