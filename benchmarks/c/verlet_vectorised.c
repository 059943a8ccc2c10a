/*
 * Vectorised C reference for the benchmarks (benchmark code only, not part of the
 * package): the package's damped velocity Verlet scheme on the nonlinear springs
 * model, laid out for SIMD, the twin of benchmarks/reference.py.
 *
 * Per step, for every free column and row r (u, v, phi):
 *   damp(h/2) kick(h/2) drift(h) | forces at the new x + the moment | kick(h/2) damp(h/2)
 * with the exact damping flow v <- v exp(-gamma_r h / (2 m_r)); with energy != 0 the
 * work of the moment and the kinetic energy removed by every damping sub-step are
 * summed, as the package does (they never feed back into the state).
 *
 * Layout: structure of arrays. run_single: x, v (3, n) row-major (rows u, v, phi),
 * columns 0 and n-1 clamped. run_batch: x, v (3, n, B), the batch index innermost, so
 * that the SIMD lanes run over the members; coefficients, inertia, sub-step factors
 * and moments per member.
 *   coef    : [a, b, h, E1, E2, h - 2a, d] (NonlinearModel.coefficients); (7, B) for a batch
 *   mass    : (3,) inertia of the rows; (3, B) for a batch
 *   table   : (2, 3, 3) substep_table([1.0], dt, mass, gamma): [s][kind][r], s = 1 the
 *             empty sub-step, kind 0 damping factor, 1 kick h/(2m), 2 drift h;
 *             (2, 3, 3, B) for a batch
 *   acc     : (load work, dissipated energy), added to; (2, B) for a batch
 * Both return 0, or 1 if a value became non-finite or out of range (|u|, |v| beyond
 * max_displacement, |phi| beyond 1e6, where the reduction stops being exact); the test
 * runs every 1024 steps, outside the hot loops.
 *
 * The sin/cos is branch-free: Cody-Waite reduction by pi/2 in three parts and the
 * Cephes minimax polynomials (those of the package's models/trig.py), the quadrant
 * applied by selects that gcc turns into blends. The force is computed in blocks of
 * BLOCK columns: sin/cos of the block, its bonds, then each column as the difference
 * of its two bonds (models/nonlinear.py::_bond line by line), each pass an
 * `omp simd` loop.
 *
 * Build (what benchmarks/bench_throughput.py does, into a temporary directory):
 *   gcc -O3 -march=native -ffast-math -mprefer-vector-width=512 -fopenmp-simd \
 *       -shared -fPIC -o libverlet_vectorised.so verlet_vectorised.c -lm
 */
#include <math.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

#define BLOCK 256
#define CHECK_EVERY 1024
#define ANGLE_LIMIT 1.0e6

#pragma omp declare simd
static inline void sin_cos(double angle, double *s_out, double *c_out)
{
    const double n = floor(angle * 0.636619772367581343076 + 0.5);
    const double r = ((angle - n * 1.57079632673412561417e00) - n * 6.07710050630396597660e-11) - n * 2.02226624879595063154e-21;
    const double z = r * r;
    const double s = r + r * z * (((((1.58962301576546568060e-10 * z + -2.50507477628578072866e-8) * z + 2.75573136213857245213e-6) * z
                                    + -1.98412698295895385996e-4) * z + 8.33333333332211858878e-3) * z + -1.66666666666666307295e-1);
    const double c = 1.0 - 0.5 * z + z * z * (((((-1.13585365213876817300e-11 * z + 2.08757008419747316778e-9) * z + -2.75573141792967388112e-7) * z
                                                + 2.48015872888517045348e-5) * z + -1.38888888888730564116e-3) * z + 4.16666666666665929218e-2);
    const long q = (long)n;
    const int odd = (int)(q & 1);
    const double sign_s = (q & 2) ? -1.0 : 1.0;
    const double sign_c = ((q + 1) & 2) ? -1.0 : 1.0;
    *s_out = sign_s * (odd ? c : s);
    *c_out = sign_c * (odd ? s : c);
}

/* models/nonlinear.py::_bond: (fx, fy) and m0 on the left particle, m1 on the right. */
#pragma omp declare simd
static inline void bond(double a, double b, double h, double E1, double E2, double rest1, double rest2,
                        double c0, double s0, double c1, double s1, double du, double dv,
                        double *fx, double *fy, double *m0, double *m1)
{
    const double ax = a * c0 - b * s0, ay = a * s0 + b * c0;
    const double bx = a * c0 + b * s0, by = a * s0 - b * c0;
    const double cx = -a * c1 - b * s1, cy = -a * s1 + b * c1;
    const double dx = -a * c1 + b * s1, dy = -a * s1 - b * c1;
    const double ex = h + du, ey = dv;
    double lx, ly, t;
    lx = ex + cx - ax;
    ly = ey + cy - ay;
    t = E1 * (1.0 - rest1 / sqrt(lx * lx + ly * ly));
    const double top_x = t * lx, top_y = t * ly;
    lx = ex + dx - bx;
    ly = ey + dy - by;
    t = E1 * (1.0 - rest1 / sqrt(lx * lx + ly * ly));
    const double bot_x = t * lx, bot_y = t * ly;
    lx = ex + dx - ax;
    ly = ey + dy - ay;
    t = E2 * (1.0 - rest2 / sqrt(lx * lx + ly * ly));
    const double ad_x = t * lx, ad_y = t * ly;
    lx = ex + cx - bx;
    ly = ey + cy - by;
    t = E2 * (1.0 - rest2 / sqrt(lx * lx + ly * ly));
    const double bc_x = t * lx, bc_y = t * ly;
    *fx = top_x + bot_x + ad_x + bc_x;
    *fy = top_y + bot_y + ad_y + bc_y;
    *m0 = ax * (top_y + ad_y) - ay * (top_x + ad_x) + bx * (bot_y + bc_y) - by * (bot_x + bc_x);
    *m1 = -(cx * (top_y + bc_y) - cy * (top_x + bc_x) + dx * (bot_y + ad_y) - dy * (bot_x + ad_x));
}

/* ------------------------------------------------------------------ one chain, x[3][n] */
static void forces_single(const double *restrict x, const double *restrict coef, double *restrict f, long n)
{
    const double a = coef[0], b = coef[1], h = coef[2], E1 = coef[3], E2 = coef[4], rest1 = coef[5], rest2 = coef[6];
    double sb[BLOCK + 2], cb[BLOCK + 2], bfx[BLOCK + 1], bfy[BLOCK + 1], bm0[BLOCK + 1], bm1[BLOCK + 1];
    for (long k0 = 1; k0 < n - 1; k0 += BLOCK) {
        const long k1 = k0 + BLOCK < n - 1 ? k0 + BLOCK : n - 1;
        const long m = k1 - k0 + 1; /* bonds k0-1 .. k1-1 */
        const double *restrict uu = x + k0 - 1, *restrict vv = x + n + k0 - 1, *restrict ph = x + 2 * n + k0 - 1;
#pragma omp simd
        for (long i = 0; i < m + 1; i++)
            sin_cos(ph[i], &sb[i], &cb[i]);
#pragma omp simd
        for (long i = 0; i < m; i++) {
            double fx, fy, m0, m1;
            bond(a, b, h, E1, E2, rest1, rest2, cb[i], sb[i], cb[i + 1], sb[i + 1], uu[i + 1] - uu[i], vv[i + 1] - vv[i], &fx, &fy, &m0, &m1);
            bfx[i] = fx;
            bfy[i] = fy;
            bm0[i] = m0;
            bm1[i] = m1;
        }
        double *restrict fu = f + k0, *restrict fv = f + n + k0, *restrict fm = f + 2 * n + k0;
#pragma omp simd
        for (long i = 0; i < m - 1; i++) {
            fu[i] = bfx[i + 1] - bfx[i];
            fv[i] = bfy[i + 1] - bfy[i];
            fm[i] = bm1[i] + bm0[i + 1];
        }
    }
}

/* Close sub-step `close` and open sub-step `open` on the free columns; returns the
 * kinetic energy removed by the two damping flows (0 without energy). */
static double close_open_single(double *restrict x, double *restrict v, const double *restrict f, long n,
                                const double *restrict mass, const double *restrict table, int close, int open, int energy)
{
    double dissipated = 0.0;
    for (int r = 0; r < 3; r++) {
        const double ec = table[close * 9 + r], kc = table[close * 9 + 3 + r];
        const double eo = table[open * 9 + r], ko = table[open * 9 + 3 + r], dr = table[open * 9 + 6 + r];
        double *restrict xr = x + r * n + 1, *restrict vr = v + r * n + 1;
        const double *restrict fr = f + r * n + 1;
        const long m = n - 2;
        if (energy) {
            double bc = 0.0, bo = 0.0;
#pragma omp simd reduction(+ : bc, bo)
            for (long k = 0; k < m; k++) {
                double w = vr[k] + kc * fr[k];
                bc += w * w;
                w *= ec;
                bo += w * w;
                w = eo * w + ko * fr[k];
                vr[k] = w;
                xr[k] += dr * w;
            }
            dissipated += 0.5 * mass[r] * (bc * (1.0 - ec * ec) + bo * (1.0 - eo * eo));
        } else {
#pragma omp simd
            for (long k = 0; k < m; k++) {
                double w = ec * (vr[k] + kc * fr[k]);
                w = eo * w + ko * fr[k];
                vr[k] = w;
                xr[k] += dr * w;
            }
        }
    }
    return dissipated;
}

/* Finiteness from the bits: -ffast-math lets gcc assume that no value is NaN or inf,
 * so isfinite() and comparisons with NaN cannot be trusted here. */
static inline int not_finite(double value)
{
    uint64_t bits;
    memcpy(&bits, &value, sizeof bits);
    return ((bits >> 52) & 0x7ff) == 0x7ff;
}

static int out_of_range(const double *x, const double *v, long rows, long cols, double max_displacement)
{
    int bad = 0;
    for (long r = 0; r < rows; r++) {
        const double limit = r < 2 ? max_displacement : ANGLE_LIMIT;
        for (long k = 0; k < cols; k++)
            bad |= not_finite(x[r * cols + k]) | not_finite(v[r * cols + k]) | (fabs(x[r * cols + k]) > limit);
    }
    return bad;
}

int run_single(double *x, double *v, long n, const double *coef, const double *mass, const double *table,
               long n_steps, long col, double moment, double max_displacement, int energy, double *acc)
{
    double *f = calloc(3 * n, sizeof(double));
    double work = 0.0, dissipated = 0.0;
    int pending = 1, status = 0;
    long to_check = CHECK_EVERY;
    forces_single(x, coef, f, n);
    f[2 * n + col] += moment;
    for (long k = 0; k < n_steps; k++) {
        const double q_old = x[2 * n + col];
        dissipated += close_open_single(x, v, f, n, mass, table, pending, 0, energy);
        forces_single(x, coef, f, n);
        f[2 * n + col] += moment;
        work += moment * (x[2 * n + col] - q_old);
        pending = 0;
        const int last = k == n_steps - 1;
        if (last)
            dissipated += close_open_single(x, v, f, n, mass, table, 0, 1, energy);
        if (--to_check == 0 || last) {
            to_check = CHECK_EVERY;
            if (out_of_range(x, v, 3, n, max_displacement)) {
                status = 1;
                break;
            }
        }
    }
    if (energy) {
        acc[0] += work;
        acc[1] += dissipated;
    }
    free(f);
    return status;
}

/* ------------------------------------------------------------------ a batch, x[3][n][B] */
static void forces_batch(const double *restrict x, const double *restrict coef, double *restrict f, long n, long B,
                         double *restrict sb, double *restrict cb, double *restrict carry)
{
    const double *restrict ca = coef, *restrict cbb = coef + B, *restrict ch = coef + 2 * B, *restrict cE1 = coef + 3 * B;
    const double *restrict cE2 = coef + 4 * B, *restrict cr1 = coef + 5 * B, *restrict cr2 = coef + 6 * B;
    const double *restrict phi = x + 2 * n * B;
    for (long k = 0; k < n; k++) {
#pragma omp simd
        for (long j = 0; j < B; j++)
            sin_cos(phi[k * B + j], &sb[k * B + j], &cb[k * B + j]);
    }
    double *restrict cu = carry, *restrict cv = carry + B, *restrict cm = carry + 2 * B;
    for (long k = 1; k < n; k++) {
        const double *restrict u0 = x + (k - 1) * B, *restrict u1 = x + k * B;
        const double *restrict v0 = x + n * B + (k - 1) * B, *restrict v1 = x + n * B + k * B;
        const double *restrict s0 = sb + (k - 1) * B, *restrict s1 = sb + k * B;
        const double *restrict c0 = cb + (k - 1) * B, *restrict c1 = cb + k * B;
        double *restrict fu = f + (k - 1) * B, *restrict fv = f + n * B + (k - 1) * B, *restrict fm = f + 2 * n * B + (k - 1) * B;
        if (k == 1) {
#pragma omp simd
            for (long j = 0; j < B; j++) {
                double fx, fy, m0, m1;
                bond(ca[j], cbb[j], ch[j], cE1[j], cE2[j], cr1[j], cr2[j], c0[j], s0[j], c1[j], s1[j], u1[j] - u0[j], v1[j] - v0[j], &fx, &fy, &m0, &m1);
                cu[j] = fx;
                cv[j] = fy;
                cm[j] = m1;
            }
        } else {
#pragma omp simd
            for (long j = 0; j < B; j++) {
                double fx, fy, m0, m1;
                bond(ca[j], cbb[j], ch[j], cE1[j], cE2[j], cr1[j], cr2[j], c0[j], s0[j], c1[j], s1[j], u1[j] - u0[j], v1[j] - v0[j], &fx, &fy, &m0, &m1);
                fu[j] = fx - cu[j];
                fv[j] = fy - cv[j];
                fm[j] = cm[j] + m0;
                cu[j] = fx;
                cv[j] = fy;
                cm[j] = m1;
            }
        }
    }
}

static void close_open_batch(double *restrict x, double *restrict v, const double *restrict f, long n, long B,
                             const double *restrict mass, const double *restrict factors, int close, int open, int energy,
                             double *restrict dissipated, double *restrict bc, double *restrict bo)
{
    /* factors[s][kind][r][j] */
    for (int r = 0; r < 3; r++) {
        const double *restrict ec = factors + ((close * 3 + 0) * 3 + r) * B, *restrict kc = factors + ((close * 3 + 1) * 3 + r) * B;
        const double *restrict eo = factors + ((open * 3 + 0) * 3 + r) * B, *restrict ko = factors + ((open * 3 + 1) * 3 + r) * B;
        const double *restrict dr = factors + ((open * 3 + 2) * 3 + r) * B;
        if (energy)
            for (long j = 0; j < B; j++)
                bc[j] = bo[j] = 0.0;
        for (long k = 1; k < n - 1; k++) {
            double *restrict xr = x + (r * n + k) * B, *restrict vr = v + (r * n + k) * B;
            const double *restrict fr = f + (r * n + k) * B;
            if (energy) {
#pragma omp simd
                for (long j = 0; j < B; j++) {
                    double w = vr[j] + kc[j] * fr[j];
                    bc[j] += w * w;
                    w *= ec[j];
                    bo[j] += w * w;
                    w = eo[j] * w + ko[j] * fr[j];
                    vr[j] = w;
                    xr[j] += dr[j] * w;
                }
            } else {
#pragma omp simd
                for (long j = 0; j < B; j++) {
                    double w = ec[j] * (vr[j] + kc[j] * fr[j]);
                    w = eo[j] * w + ko[j] * fr[j];
                    vr[j] = w;
                    xr[j] += dr[j] * w;
                }
            }
        }
        if (energy) {
            const double *restrict m = mass + r * B;
#pragma omp simd
            for (long j = 0; j < B; j++)
                dissipated[j] += 0.5 * m[j] * (bc[j] * (1.0 - ec[j] * ec[j]) + bo[j] * (1.0 - eo[j] * eo[j]));
        }
    }
}

int run_batch(double *x, double *v, long n, long B, const double *coef, const double *mass, const double *factors,
              long n_steps, long col, const double *moments, double max_displacement, int energy, double *acc)
{
    double *f = calloc(3 * n * B, sizeof(double));
    double *sb = malloc(n * B * sizeof(double)), *cb = malloc(n * B * sizeof(double));
    double *carry = malloc(3 * B * sizeof(double)), *q_old = malloc(B * sizeof(double));
    double *bc = malloc(B * sizeof(double)), *bo = malloc(B * sizeof(double));
    double *work = acc, *dissipated = acc + B;
    double *restrict fm = f + (2 * n + col) * B;
    const double *restrict xm = x + (2 * n + col) * B;
    int pending = 1, status = 0;
    long to_check = CHECK_EVERY;
    forces_batch(x, coef, f, n, B, sb, cb, carry);
    for (long j = 0; j < B; j++)
        fm[j] += moments[j];
    for (long k = 0; k < n_steps; k++) {
        for (long j = 0; j < B; j++)
            q_old[j] = xm[j];
        close_open_batch(x, v, f, n, B, mass, factors, pending, 0, energy, dissipated, bc, bo);
        forces_batch(x, coef, f, n, B, sb, cb, carry);
#pragma omp simd
        for (long j = 0; j < B; j++)
            fm[j] += moments[j];
        if (energy) {
#pragma omp simd
            for (long j = 0; j < B; j++)
                work[j] += moments[j] * (xm[j] - q_old[j]);
        }
        pending = 0;
        const int last = k == n_steps - 1;
        if (last)
            close_open_batch(x, v, f, n, B, mass, factors, 0, 1, energy, dissipated, bc, bo);
        if (--to_check == 0 || last) {
            to_check = CHECK_EVERY;
            if (out_of_range(x, v, 3, n * B, max_displacement)) {
                status = 1;
                break;
            }
        }
    }
    free(f);
    free(sb);
    free(cb);
    free(carry);
    free(q_old);
    free(bc);
    free(bo);
    return status;
}
