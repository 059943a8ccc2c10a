/*
 * Reference C loop for the throughput benchmark (benchmark code only, not part of
 * the package): damped velocity Verlet on the nonlinear springs model, the same
 * scheme and arithmetic as cosserat_chain.numerics.integrators.advance with
 * method "verlet", one thread, a constant moment on one column.
 *
 *   x, v, f : (3, n) row-major (rows u, v, phi); f must hold forces + load at x on entry
 *             and holds them at the final x on return; columns 0 and n-1 are clamped.
 *   coef    : [a, b, h, E1, E2, h - 2a, d]  (NonlinearModel.coefficients)
 *   table   : (2, 3, 3) from substep_table([1.0], dt, inertia, damping);
 *             row 0 the Verlet sub-step, row 1 the empty sub-step;
 *             table[s][0][r] = exp(-gamma_r h/(2 m_r)), [s][1][r] = h/(2 m_r), [s][2][r] = h.
 *   load_col, moment : a constant moment on x[2][load_col].
 *   prepare() fills f at the initial state, as integrate() does before its first step.
 *
 * Like the package it accumulates the load work and the dissipated energy and
 * checks for a runaway state every 1024 steps; run_acc() returns them.
 *
 * Build: gcc -O3 -march=native -shared -fPIC -o libverlet.so verlet_nonlinear.c -lm
 * (the benchmark's reference: libm sin/cos). With -DPOLY_SINCOS it uses the
 * package's inline sincos polynomial instead (an optional, stronger reference).
 * gcc fuses a * b + c into one multiply-add wherever it can (GNU C defaults to
 * -ffp-contract=fast); the package's force kernels do the same (numba fastmath
 * "contract"), its kick-drift does not, so results agree to round-off, not bit for bit.
 */
#include <math.h>

#define EMPTY 1
#define CHECK_EVERY 1024

#ifdef POLY_SINCOS
/* The package's inline sincos (models/trig.py): (angle, 1) below 2^-27, Cephes
 * polynomials after a three-part reduction by pi/2; libm beyond |angle| >= 1e6. */
static inline void sin_cos(double angle, double *s_out, double *c_out)
{
    if (fabs(angle) < 0x1p-27) {
        *s_out = angle + 0.0;
        *c_out = 1.0;
        return;
    }
    if (!(fabs(angle) < 1.0e6)) {
        *s_out = sin(angle);
        *c_out = cos(angle);
        return;
    }
    double n = floor(angle * 0.636619772367581343076 + 0.5);
    double r = ((angle - n * 1.57079632673412561417e00) - n * 6.07710050630396597660e-11) - n * 2.02226624879595063154e-21;
    double z = r * r;
    double s = r + r * z * (((((1.58962301576546568060e-10 * z + -2.50507477628578072866e-8) * z + 2.75573136213857245213e-6) * z
                              + -1.98412698295895385996e-4) * z + 8.33333333332211858878e-3) * z + -1.66666666666666307295e-1);
    double c = 1.0 - 0.5 * z + z * z * (((((-1.13585365213876817300e-11 * z + 2.08757008419747316778e-9) * z + -2.75573141792967388112e-7) * z
                                          + 2.48015872888517045348e-5) * z + -1.38888888888730564116e-3) * z + 4.16666666666665929218e-2);
    switch ((long)n & 3) {
    case 0: *s_out = s; *c_out = c; break;
    case 1: *s_out = c; *c_out = -s; break;
    case 2: *s_out = -s; *c_out = -c; break;
    default: *s_out = -c; *c_out = s; break;
    }
}
#else
/* libm sin and cos (gcc merges them into one sincos call). */
static inline void sin_cos(double angle, double *s_out, double *c_out)
{
    *s_out = sin(angle);
    *c_out = cos(angle);
}
#endif

static double last_acc[2];
static int last_status;

/* Force (fx, fy) and moment m0 on the left particle of a bond, m1 on the right one
 * (which receives -fx, -fy); a line-by-line copy of models/nonlinear.py::_bond. */
static inline void bond(const double *coef, double c0, double s0, double c1, double s1,
                        double du, double dv, double *fx, double *fy, double *m0, double *m1)
{
    const double a = coef[0], b = coef[1], h = coef[2], E1 = coef[3], E2 = coef[4];
    const double rest1 = coef[5], rest2 = coef[6];
    double ax = a * c0 - b * s0;
    double ay = a * s0 + b * c0;
    double bx = a * c0 + b * s0;
    double by = a * s0 - b * c0;
    double cx = -a * c1 - b * s1;
    double cy = -a * s1 + b * c1;
    double dx = -a * c1 + b * s1;
    double dy = -a * s1 - b * c1;
    double ex = h + du;
    double ey = dv;
    double lx, ly, t;
    lx = ex + cx - ax;
    ly = ey + cy - ay;
    t = E1 * (1.0 - rest1 / sqrt(lx * lx + ly * ly));
    double top_x = t * lx, top_y = t * ly;
    lx = ex + dx - bx;
    ly = ey + dy - by;
    t = E1 * (1.0 - rest1 / sqrt(lx * lx + ly * ly));
    double bot_x = t * lx, bot_y = t * ly;
    lx = ex + dx - ax;
    ly = ey + dy - ay;
    t = E2 * (1.0 - rest2 / sqrt(lx * lx + ly * ly));
    double ad_x = t * lx, ad_y = t * ly;
    lx = ex + cx - bx;
    ly = ey + cy - by;
    t = E2 * (1.0 - rest2 / sqrt(lx * lx + ly * ly));
    double bc_x = t * lx, bc_y = t * ly;
    *fx = top_x + bot_x + ad_x + bc_x;
    *fy = top_y + bot_y + ad_y + bc_y;
    *m0 = ax * (top_y + ad_y) - ay * (top_x + ad_x) + bx * (bot_y + bc_y) - by * (bot_x + bc_x);
    *m1 = -(cx * (top_y + bc_y) - cy * (top_x + bc_x) + dx * (bot_y + ad_y) - dy * (bot_x + ad_x));
}

/* Forces on columns start..stop-1, one pass with the right half of the previous
 * bond carried in registers (models/nonlinear.py::nonlinear_forces_kernel). */
static void forces(const double *restrict x, const double *coef, double *restrict out,
                   int n, int start, int stop)
{
    const double *u = x, *v = x + n, *phi = x + 2 * n;
    double *ou = out, *ov = out + n, *om = out + 2 * n;
    double s0, c0, s1, c1;
    sin_cos(phi[start - 1], &s0, &c0);
    sin_cos(phi[start], &s1, &c1);
    double fx, fy, m0, m1;
    bond(coef, c0, s0, c1, s1, u[start] - u[start - 1], v[start] - v[start - 1], &fx, &fy, &m0, &m1);
    double carry_u = -fx, carry_v = -fy, carry_m = m1;
    c0 = c1;
    s0 = s1;
    for (int k = start; k < stop; k++) {
        sin_cos(phi[k + 1], &s1, &c1);
        bond(coef, c0, s0, c1, s1, u[k + 1] - u[k], v[k + 1] - v[k], &fx, &fy, &m0, &m1);
        ou[k] = carry_u + fx;
        ov[k] = carry_v + fy;
        om[k] = carry_m + m0;
        carry_u = -fx;
        carry_v = -fy;
        carry_m = m1;
        c0 = c1;
        s0 = s1;
    }
}

/* End sub-step `close` and begin sub-step `open` (integrators.py::_close_and_open);
 * returns the kinetic energy removed by the two damping flows. */
static double close_and_open(double *restrict x, double *restrict v, const double *restrict f,
                             const double *mass, const double *table, int close, int open,
                             int n, int start, int stop)
{
    double dissipated = 0.0;
    for (int r = 0; r < 3; r++) {
        const double e_close = table[close * 9 + 0 * 3 + r];
        const double kick_close = table[close * 9 + 1 * 3 + r];
        const double e_open = table[open * 9 + 0 * 3 + r];
        const double kick_open = table[open * 9 + 1 * 3 + r];
        const double drift = table[open * 9 + 2 * 3 + r];
        double before_close = 0.0, before_open = 0.0;
        double *restrict xr = x + r * n;
        double *restrict vr = v + r * n;
        const double *restrict fr = f + r * n;
        for (int k = start; k < stop; k++) {
            double w = vr[k] + kick_close * fr[k];
            before_close += w * w;
            w *= e_close;
            before_open += w * w;
            w = e_open * w + kick_open * fr[k];
            vr[k] = w;
            xr[k] += drift * w;
        }
        dissipated += 0.5 * mass[r] * (before_close * (1.0 - e_close * e_close)
                                       + before_open * (1.0 - e_open * e_open));
    }
    return dissipated;
}

static int runaway(const double *x, const double *v, int n, double max_displacement)
{
    for (int r = 0; r < 3; r++)
        for (int k = 0; k < n; k++) {
            double xv = x[r * n + k], vv = v[r * n + k];
            if (!(isfinite(xv) && isfinite(vv))) return 1;
            if (r < 2 && fabs(xv) > max_displacement) return 1;
        }
    return 0;
}

/* n_steps steps of damped velocity Verlet from the state at the start of a step
 * (velocities at the step boundary), ending with the last step closed. */
void run(double *x, double *v, double *f, int n, const double *coef, const double *table,
         int n_steps, int load_col, double moment)
{
    /* Inertia m_r = h / (2 * kick_r) of the Verlet sub-step (table[0][1][r] = h / (2 m_r)). */
    double mass[3];
    for (int r = 0; r < 3; r++) mass[r] = table[0 * 9 + 2 * 3 + r] / (2.0 * table[0 * 9 + 1 * 3 + r]);
    const double max_displacement = 100.0 * (n - 1) * coef[2];
    double work = 0.0, dissipated = 0.0;
    int pending = EMPTY;
    last_status = 0;
    for (int k = 0; k < n_steps; k++) {
        double q_old = x[2 * n + load_col];
        dissipated += close_and_open(x, v, f, mass, table, pending, 0, n, 1, n - 1);
        forces(x, coef, f, n, 1, n - 1);
        f[2 * n + load_col] += moment;
        work += moment * (x[2 * n + load_col] - q_old);
        pending = 0;
        int last = k == n_steps - 1;
        if (last) {
            dissipated += close_and_open(x, v, f, mass, table, pending, EMPTY, n, 1, n - 1);
            pending = EMPTY;
        }
        if (((k + 1) % CHECK_EVERY == 0 || last) && runaway(x, v, n, max_displacement)) {
            if (pending != EMPTY)
                dissipated += close_and_open(x, v, f, mass, table, pending, EMPTY, n, 1, n - 1);
            last_status = 1;
            break;
        }
    }
    last_acc[0] = work;
    last_acc[1] = dissipated;
}

/* Forces plus the moment at x (what the package computes before its first step). */
void prepare(const double *x, double *f, int n, const double *coef, int load_col, double moment)
{
    forces(x, coef, f, n, 1, n - 1);
    f[2 * n + load_col] += moment;
}

/* (load work, dissipated energy) of the last run; returns its status (1 = blew up). */
int run_acc(double *acc)
{
    acc[0] = last_acc[0];
    acc[1] = last_acc[1];
    return last_status;
}
