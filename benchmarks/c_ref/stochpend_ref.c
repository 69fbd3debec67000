/*
 * C reference of stochpend's OU scheme, fixed step and adaptive step (the default; see the
 * second half of this file): the practical floor for the benchmark.
 *
 * It reproduces, number for number, what stochpend's CPU kernels (init_paths + advance_paths
 * in src/stochpend/engine/cpu.py) do for the pendulum with OU noise at a fixed step:
 *
 *   - the same Philox4x32-10 stream: key = (seed mod 2^32, seed >> 32),
 *     counter = (n mod 2^32, n >> 32, path mod 2^32, path >> 32); draw 0 gives theta0,
 *     draw 1 the stationary xi0, draw k + 2 the two normals of step k (rng.py);
 *   - the same uniform on (0, 1) (rng.uniform_open, 52 bits) and the same Box-Muller transform;
 *   - the same exact OU update (schemes.ou_step_coefficients), recomputed only when h changes;
 *   - the same drift-kick-drift step (schemes.verlet_step) and angle wrap (physics.wrap_angle);
 *   - the same time bookkeeping: the last step lands exactly on t_target (a step ending within
 *     1e-6 h of it is stretched), t += h with Kahan compensation.
 *
 * Two loop orders, same numbers:
 *   sp_run_scalar: one path at a time, all its steps (what the Numba kernel does), OpenMP over
 *                  paths;
 *   sp_run_simd:   blocks of SP_BLOCK paths advanced in lockstep, the lane loop marked
 *                  `omp simd`, so that gcc vectorizes Philox (32x32->64 multiplies) and, under
 *                  -ffast-math, calls glibc's libmvec for log/sin/cos. OpenMP over blocks.
 *
 * Compiled by benchmarks/c_ref/__init__.py either with the benchmark flags
 * (-O3 -march=native -ffast-math -fopenmp: FMA contraction, libmvec, reciprocal division, so the
 * numbers agree with stochpend to round-off per step, not bit for bit) or in "exact" mode
 * (-O3 -march=native -fopenmp -ffp-contract=off -fno-fast-math: scalar glibc libm, IEEE
 * arithmetic in the same order as Numba's, so the numbers are bit-identical).
 */
#include <math.h>
#include <stdint.h>
#include <omp.h>

#define SP_BLOCK 16

static const double SP_PI = 3.141592653589793;
static const double SP_TWO_PI = 6.283185307179586;

/* ---- Philox4x32-10 ------------------------------------------------------------------------ */
/* Scalars only (no arrays) and fully unrolled rounds, so that gcc can vectorize across paths. */
static inline void philox4x32_10(uint32_t *c0, uint32_t *c1, uint32_t *c2, uint32_t *c3,
                                 uint32_t k0, uint32_t k1)
{
    uint32_t a0 = *c0, a1 = *c1, a2 = *c2, a3 = *c3;
#pragma GCC unroll 10
    for (int r = 0; r < 10; ++r) {
        uint64_t p0 = (uint64_t)0xD2511F53u * (uint64_t)a0;
        uint64_t p1 = (uint64_t)0xCD9E8D57u * (uint64_t)a2;
        uint32_t n0 = (uint32_t)(p1 >> 32) ^ a1 ^ k0;
        uint32_t n2 = (uint32_t)(p0 >> 32) ^ a3 ^ k1;
        a0 = n0; a1 = (uint32_t)p1; a2 = n2; a3 = (uint32_t)p0;
        k0 += 0x9E3779B9u;
        k1 += 0xBB67AE85u;
    }
    *c0 = a0; *c1 = a1; *c2 = a2; *c3 = a3;
}

/* rng.uniform_open: (k + 1/2) / 2^52, k the high 26 bits of a and of b. */
static inline double uniform_open(uint32_t a, uint32_t b)
{
    double k = (double)(a >> 6) * 67108864.0 + (double)(b >> 6);
    return (k + 0.5) * (1.0 / 4503599627370496.0);
}

static inline void draw_words(uint32_t out[4], uint32_t k0, uint32_t k1, uint64_t path, uint64_t n)
{
    uint32_t c0 = (uint32_t)n, c1 = (uint32_t)(n >> 32), c2 = (uint32_t)path, c3 = (uint32_t)(path >> 32);
    philox4x32_10(&c0, &c1, &c2, &c3, k0, k1);
    out[0] = c0; out[1] = c1; out[2] = c2; out[3] = c3;
}

/* ---- exact OU coefficients (schemes.ou_step_coefficients) ------------------------------- */
/* schemes.x_minus_2tanh_half: the Taylor series below 0.6 (Horner, 12 terms), else direct. */
static const double TANH_SERIES[12] = {
    1.0 / 12.0,
    -1.0 / 120.0,
    17.0 / 20160.0,
    -31.0 / 362880.0,
    691.0 / 79833600.0,
    -5461.0 / 6227020800.0,
    929569.0 / 10461394944000.0,
    -3202291.0 / 355687428096000.0,
    221930581.0 / 243290200817664000.0,
    -4722116521.0 / 51090942171709440000.0,
    56963745931.0 / 6082827467972935680000.0,
    -14717667114151.0 / 15511210043330985984000000.0,
};

static double x_minus_2tanh_half(double x)
{
    if (x < 0.6) {
        double x2 = x * x;
        double acc = 0.0;
        for (int i = 11; i >= 0; --i) acc = acc * x2 + TANH_SERIES[i];
        return acc * x * x2;
    }
    return x - 2.0 * tanh(0.5 * x);
}

typedef struct { double a, s_xi, m_I, c_I, s_I; } ou_coef;

static ou_coef ou_step_coefficients(double h, double D, double tau)
{
    ou_coef c;
    double x = h / tau;
    double b = -expm1(-x);
    c.a = 1.0 - b;
    double var_xi = D * b * (2.0 - b) / (2.0 * tau);
    c.s_xi = sqrt(var_xi);
    double cov = 0.5 * D * b * b;
    c.c_I = c.s_xi > 0.0 ? cov / c.s_xi : 0.0;
    c.s_I = sqrt(D * tau * x_minus_2tanh_half(x));
    c.m_I = tau * b;
    return c;
}

/* ---- one path-step: OU noise, Box-Muller, drift-kick-drift, wrap ------------------------- */
#define SP_STEP(xs, Om, xn, path, kk)                                                          \
    do {                                                                                        \
        uint64_t n_ = (kk) + 2u;                                                                \
        uint32_t w0_ = (uint32_t)n_, w1_ = (uint32_t)(n_ >> 32);                                \
        uint32_t w2_ = (uint32_t)(path), w3_ = (uint32_t)((uint64_t)(path) >> 32);              \
        philox4x32_10(&w0_, &w1_, &w2_, &w3_, k0, k1);                                          \
        double u1_ = uniform_open(w0_, w1_);                                                    \
        double u2_ = uniform_open(w2_, w3_);                                                    \
        double r_ = sqrt(-2.0 * log(u1_));                                                      \
        double ph_ = SP_TWO_PI * u2_;                                                           \
        double z1_ = r_ * cos(ph_);                                                             \
        double z2_ = r_ * sin(ph_);                                                             \
        double I_ = cf.m_I * (xn) + cf.c_I * z1_ + cf.s_I * z2_;                                \
        (xn) = cf.a * (xn) + cf.s_xi * z1_;                                                     \
        double xh_ = (xs) + 0.5 * h * (Om);                                                     \
        double s_ = sin(xh_);                                                                   \
        double kick_ = omega2 * h * s_;                                                         \
        kick_ += I_ * s_;                                                                       \
        (Om) = (Om) - kick_;                                                                    \
        double xw_ = xh_ + 0.5 * h * (Om);                                                      \
        (xs) = xw_ - SP_TWO_PI * floor((xw_ + SP_PI) / SP_TWO_PI);                              \
    } while (0)

/* Time bookkeeping of cpu.advance_paths: the landing rule (a step ending within 1e-6 h of
   t_target is stretched to it) and Kahan-compensated t += h. Compiled without -ffast-math,
   which would simplify the compensation away. */
__attribute__((optimize("no-fast-math"), noinline))
static int sp_land(double tt, double h, double t_target)
{
    return tt + h * (1.0 + 1e-6) >= t_target;
}

__attribute__((optimize("no-fast-math"), noinline))
static void sp_advance_time(double *tt, double *comp, double h)
{
    double y = h - *comp;
    double t_new = *tt + y;
    *comp = (t_new - *tt) - y;
    *tt = t_new;
}

/* Initial conditions of stochpend (uniform theta0, Omega0 = 0, stationary xi0). */
static inline void init_path(double *x, double *Om, double *xi, uint32_t k0, uint32_t k1,
                             uint64_t path, double D, double tau)
{
    uint32_t w[4];
    draw_words(w, k0, k1, path, 0u);
    *x = 2.0 * SP_PI * uniform_open(w[0], w[1]) - SP_PI;
    *Om = 0.0;
    draw_words(w, k0, k1, path, 1u);
    double u1 = uniform_open(w[0], w[1]);
    double u2 = uniform_open(w[2], w[3]);
    double z = sqrt(-2.0 * log(u1)) * cos(SP_TWO_PI * u2);
    *xi = sqrt(D / (2.0 * tau)) * z;
}

/*
 * Both entry points: paths path0 .. path0 + n - 1, from t = 0 to t_target with step h_max
 * (the last step shortened to land on t_target); the final states go to x, Om, xi.
 * Returns the number of steps of each path.
 */
long sp_run_scalar(long n, uint64_t path0, uint64_t seed, double D, double tau, double omega2,
                   double h_max, double t_target, int threads, double *x, double *Om, double *xi)
{
    const uint32_t k0 = (uint32_t)seed, k1 = (uint32_t)(seed >> 32);
    long steps_out = 0;
    if (threads > 0) omp_set_num_threads(threads);
#pragma omp parallel for schedule(static) reduction(max : steps_out)
    for (long i = 0; i < n; ++i) {
        uint64_t path = path0 + (uint64_t)i;
        double xs, Om_, xn;
        init_path(&xs, &Om_, &xn, k0, k1, path, D, tau);
        double tt = 0.0, t_comp = 0.0, h_cached = -1.0;
        ou_coef cf = {0, 0, 0, 0, 0};
        uint64_t kk = 0;
        for (;;) {
            double h = h_max;
            int last = 0;
            if (sp_land(tt, h, t_target)) { h = t_target - tt; last = 1; }
            if (h != h_cached) { cf = ou_step_coefficients(h, D, tau); h_cached = h; }
            SP_STEP(xs, Om_, xn, path, kk);
            kk += 1;
            if (last) tt = t_target; else sp_advance_time(&tt, &t_comp, h);
            if (last) break;
        }
        x[i] = xs; Om[i] = Om_; xi[i] = xn;
        if ((long)kk > steps_out) steps_out = (long)kk;
    }
    return steps_out;
}

long sp_run_simd(long n, uint64_t path0, uint64_t seed, double D, double tau, double omega2,
                 double h_max, double t_target, int threads, double *x, double *Om, double *xi)
{
    const uint32_t k0 = (uint32_t)seed, k1 = (uint32_t)(seed >> 32);
    long n_blocks = (n + SP_BLOCK - 1) / SP_BLOCK;
    long steps_out = 0;
    if (threads > 0) omp_set_num_threads(threads);
#pragma omp parallel for schedule(static) reduction(max : steps_out)
    for (long b = 0; b < n_blocks; ++b) {
        long i0 = b * SP_BLOCK;
        int m = (int)((n - i0) < SP_BLOCK ? (n - i0) : SP_BLOCK);
        double bx[SP_BLOCK], bO[SP_BLOCK], bxi[SP_BLOCK];
        uint32_t bp0[SP_BLOCK], bp1[SP_BLOCK];
        for (int l = 0; l < SP_BLOCK; ++l) {
            /* Padding lanes repeat the block's first path; they are not stored. */
            uint64_t path = path0 + (uint64_t)(i0 + (l < m ? l : 0));
            bp0[l] = (uint32_t)path;
            bp1[l] = (uint32_t)(path >> 32);
            init_path(&bx[l], &bO[l], &bxi[l], k0, k1, path, D, tau);
        }
        double tt = 0.0, t_comp = 0.0, h_cached = -1.0;
        ou_coef cf = {0, 0, 0, 0, 0};
        uint64_t kk = 0;
        for (;;) {
            double h = h_max;
            int last = 0;
            if (sp_land(tt, h, t_target)) { h = t_target - tt; last = 1; }
            if (h != h_cached) { cf = ou_step_coefficients(h, D, tau); h_cached = h; }
            /* Loop fission: the normals' cos and sin in separate lane loops, so that gcc
               does not fuse them into sincos (which has no vector variant it can call). */
            double br[SP_BLOCK], bph[SP_BLOCK], bc[SP_BLOCK], bs[SP_BLOCK];
            const uint64_t nn = kk + 2u;
#pragma omp simd
            for (int l = 0; l < SP_BLOCK; ++l) {
                uint32_t w0 = (uint32_t)nn, w1 = (uint32_t)(nn >> 32);
                uint32_t w2 = bp0[l], w3 = bp1[l];
                philox4x32_10(&w0, &w1, &w2, &w3, k0, k1);
                double u1 = uniform_open(w0, w1);
                double u2 = uniform_open(w2, w3);
                br[l] = sqrt(-2.0 * log(u1));
                bph[l] = SP_TWO_PI * u2;
            }
#pragma omp simd
            for (int l = 0; l < SP_BLOCK; ++l) bc[l] = cos(bph[l]);
#pragma omp simd
            for (int l = 0; l < SP_BLOCK; ++l) bs[l] = sin(bph[l]);
#pragma omp simd
            for (int l = 0; l < SP_BLOCK; ++l) {
                double z1 = br[l] * bc[l];
                double z2 = br[l] * bs[l];
                double xn = bxi[l];
                double I = cf.m_I * xn + cf.c_I * z1 + cf.s_I * z2;
                bxi[l] = cf.a * xn + cf.s_xi * z1;
                double Om_ = bO[l];
                double xh = bx[l] + 0.5 * h * Om_;
                double s_ = sin(xh);
                double kick = omega2 * h * s_;
                kick += I * s_;
                Om_ = Om_ - kick;
                bO[l] = Om_;
                double xw = xh + 0.5 * h * Om_;
                bx[l] = xw - SP_TWO_PI * floor((xw + SP_PI) / SP_TWO_PI);
            }
            kk += 1;
            if (last) tt = t_target; else sp_advance_time(&tt, &t_comp, h);
            if (last) break;
        }
        for (int l = 0; l < m; ++l) { x[i0 + l] = bx[l]; Om[i0 + l] = bO[l]; xi[i0 + l] = bxi[l]; }
        if ((long)kk > steps_out) steps_out = (long)kk;
    }
    return steps_out;
}

/* ==========================================================================================
 * The adaptive scheme: stochpend's default (integrator.step_size, landing_step, advance_clock).
 *
 * Every path goes from t = 0 through the output times times[0] < ... < times[n_times-1] with
 * its own step h = min(h_max, c/|Omega|, c/sqrt(|omega2 + xi|)) (the pendulum: |U''| <= 1),
 * the last step before each output time shortened to land on it (stretched when it would stop
 * within 1e-6 h of it), t summed with Kahan compensation (reset on landing), the OU
 * coefficients recomputed whenever h changes. A step below 1e-9 h_max freezes the path
 * (escape); so does a non-finite state. Each path's final state and step count are stored.
 *
 *   sp_run_adaptive_scalar: one path at a time (OpenMP over paths), the C library's expm1 and
 *       tanh for the coefficients (noises.ou.step_coefficients): compiled "exact" it is
 *       stochpend's one-path kernel with the C library's math, bit for bit (the smoke test);
 *   sp_run_adaptive_simd: SP_LANES lanes per thread, each carrying one path with its own
 *       time, step, coefficients and Philox counter, advanced together by one branch-free
 *       `omp simd` loop and refilled with the next path when theirs is done (the design of
 *       stochpend's lane machine, integrator.build_lanes); coefficients by the branch-free
 *       formulas of noises.ou.branch_free_coefficients (the polynomial expm1 of
 *       fastmath.expm1), log/sin/cos from libmvec under -ffast-math.
 * ========================================================================================== */
#define SP_LANES 16

static inline double sp_kahan_comp(double t_new, double tt, double y)
{
#if defined(__FAST_MATH__) && defined(__GNUC__) && __GNUC__ >= 12
    return __builtin_assoc_barrier(t_new - tt) - y;
#else
    return (t_new - tt) - y;
#endif
}

static inline double sp_step_size(double Om, double xn, double h_max, double c, double omega2)
{
    double h = h_max;
    double speed = fabs(Om);
    if (speed * h > c) h = c / speed;
    double stiff = fabs(omega2 + xn);
    if (stiff * h * h > c * c) h = c / sqrt(stiff);
    return h;
}

/* fastmath.expm1: x = k ln2 + r, expm1(r) by its Taylor polynomial (degree 13). The int <->
   double conversions go through the mantissa of 1.5 * 2^52, as in fastmath. */
static inline double sp_bits_f(int64_t i) { double d; __builtin_memcpy(&d, &i, 8); return d; }
static inline int64_t sp_bits_i(double d) { int64_t i; __builtin_memcpy(&i, &d, 8); return i; }

static inline double sp_expm1_poly(double x)
{
    x = x < -700.0 ? -700.0 : x;
    double fk = floor(x * 1.44269504088896338700e+00 + 0.5);
    double r = (x - fk * 6.93147180369123816490e-01) - fk * 1.90821492927058770002e-10;
    double q = 1.0 / 6227020800.0;
    q = q * r + 1.0 / 479001600.0;
    q = q * r + 1.0 / 39916800.0;
    q = q * r + 1.0 / 3628800.0;
    q = q * r + 1.0 / 362880.0;
    q = q * r + 1.0 / 40320.0;
    q = q * r + 1.0 / 5040.0;
    q = q * r + 1.0 / 720.0;
    q = q * r + 1.0 / 120.0;
    q = q * r + 1.0 / 24.0;
    q = q * r + 1.0 / 6.0;
    q = q * r + 0.5;
    double p = r + (r * r) * q;
    int64_t k = sp_bits_i(fk + 6755399441055744.0) - 0x4338000000000000LL;
    double two_k = sp_bits_f((k + 1023) << 52);
    return two_k * p + (two_k - 1.0);
}

static inline ou_coef ou_coefficients_branch_free(double h, double D, double tau)
{
    ou_coef cf;
    double x = h * (1.0 / tau);
    double b = -sp_expm1_poly(-x);
    cf.a = 1.0 - b;
    cf.s_xi = sqrt((D / (2.0 * tau)) * (b * (2.0 - b)));
    double cov = (0.5 * D) * (b * b);
    cf.c_I = cf.s_xi > 0.0 ? cov / cf.s_xi : 0.0;
    double x2 = x * x;
    double acc = TANH_SERIES[11];
    for (int i = 10; i >= 0; --i) acc = acc * x2 + TANH_SERIES[i];
    double series = acc * x * x2;
    double direct = x - 2.0 * b / (2.0 - b);
    cf.s_I = sqrt((D * tau) * (x < 0.6 ? series : direct));
    cf.m_I = tau * b;
    return cf;
}

long sp_run_adaptive_scalar(long n, uint64_t path0, uint64_t seed, double D, double tau,
                            double omega2, double h_max, double step_c, int n_times,
                            const double *times, int threads, double *x, double *Om,
                            double *xi, long *steps)
{
    const uint32_t k0 = (uint32_t)seed, k1 = (uint32_t)(seed >> 32);
    long total = 0;
    if (threads > 0) omp_set_num_threads(threads);
#pragma omp parallel for schedule(static) reduction(+ : total)
    for (long i = 0; i < n; ++i) {
        uint64_t path = path0 + (uint64_t)i;
        double xs, Om_, xn;
        init_path(&xs, &Om_, &xn, k0, k1, path, D, tau);
        double tt = 0.0, t_comp = 0.0, h_cached = h_max;
        ou_coef cf = ou_step_coefficients(h_max, D, tau);
        uint64_t kk = 0;
        int bad = 0;
        for (int j = 0; j < n_times && !bad; ++j) {
            double t_target = times[j];
            while (tt < t_target) {
                double h = sp_step_size(Om_, xn, h_max, step_c, omega2);
                if (h < 1e-9 * h_max) { bad = 1; break; }
                int last = 0;
                if (sp_land(tt, h, t_target)) { h = t_target - tt; last = 1; }
                if (h != h_cached) { cf = ou_step_coefficients(h, D, tau); h_cached = h; }
                SP_STEP(xs, Om_, xn, path, kk);
                kk += 1;
                if (last) { tt = t_target; t_comp = 0.0; } else sp_advance_time(&tt, &t_comp, h);
                if (!(isfinite(xs) && isfinite(Om_) && isfinite(xn))) { bad = 1; break; }
                if (last) break;
            }
        }
        x[i] = xs; Om[i] = Om_; xi[i] = xn; steps[i] = (long)kk;
        total += (long)kk;
    }
    return total;
}

long sp_run_adaptive_simd(long n, uint64_t path0, uint64_t seed, double D, double tau,
                          double omega2, double h_max, double step_c, int n_times,
                          const double *times, int threads, double *x, double *Om,
                          double *xi, long *steps)
{
    const uint32_t k0 = (uint32_t)seed, k1 = (uint32_t)(seed >> 32);
    long total = 0;
    if (threads > 0) omp_set_num_threads(threads);
#pragma omp parallel reduction(+ : total)
    {
        int nt = omp_get_num_threads(), tid = omp_get_thread_num();
        long lo = n * tid / nt, hi = n * (tid + 1) / nt, next = lo;
        /* Lane state; an idle lane (act = 0) computes on harmless numbers, never stored. */
        double bx[SP_LANES], bO[SP_LANES], bxi[SP_LANES], bt[SP_LANES], btc[SP_LANES],
            btarget[SP_LANES];
        uint64_t bk[SP_LANES];
        uint32_t bp0[SP_LANES], bp1[SP_LANES];
        long bi[SP_LANES];
        int bj[SP_LANES], bact[SP_LANES], bland[SP_LANES], bbad[SP_LANES];
        int n_active = 0;
        for (int l = 0; l < SP_LANES; ++l) {
            bx[l] = bO[l] = bxi[l] = bt[l] = btc[l] = 0.0;
            btarget[l] = 0.0; bk[l] = 0; bp0[l] = bp1[l] = 0; bi[l] = -1; bj[l] = 0;
            bact[l] = bland[l] = bbad[l] = 0;
            if (next < hi) {
                uint64_t path = path0 + (uint64_t)next;
                init_path(&bx[l], &bO[l], &bxi[l], k0, k1, path, D, tau);
                bp0[l] = (uint32_t)path; bp1[l] = (uint32_t)(path >> 32);
                bi[l] = next++; btarget[l] = times[0]; bact[l] = 1; ++n_active;
            }
        }
        while (n_active > 0) {
            /* Loop fission as in sp_run_simd: the normals' cos and sin in their own lane
               loops, so that gcc does not fuse them into sincos (no vector variant). */
            double br[SP_LANES], bph[SP_LANES], bc[SP_LANES], bs[SP_LANES];
#pragma omp simd
            for (int l = 0; l < SP_LANES; ++l) {
                uint64_t nn = bk[l] + 2u;
                uint32_t w0 = (uint32_t)nn, w1 = (uint32_t)(nn >> 32), w2 = bp0[l], w3 = bp1[l];
                philox4x32_10(&w0, &w1, &w2, &w3, k0, k1);
                br[l] = sqrt(-2.0 * log(uniform_open(w0, w1)));
                bph[l] = SP_TWO_PI * uniform_open(w2, w3);
            }
#pragma omp simd
            for (int l = 0; l < SP_LANES; ++l) bc[l] = cos(bph[l]);
#pragma omp simd
            for (int l = 0; l < SP_LANES; ++l) bs[l] = sin(bph[l]);
            int n_done = 0;
#pragma omp simd reduction(+ : n_done)
            for (int l = 0; l < SP_LANES; ++l) {
                double xs = bx[l], Om_ = bO[l], xn = bxi[l], tt = bt[l], tc = btc[l];
                double t_target = btarget[l];
                uint64_t kk = bk[l];
                int act = bact[l];
                double h = sp_step_size(Om_, xn, h_max, step_c, omega2);
                int esc = h < 1e-9 * h_max;
                int last = tt + h * (1.0 + 1e-6) >= t_target;
                h = last ? t_target - tt : h;
                ou_coef cf = ou_coefficients_branch_free(h, D, tau);
                double z1 = br[l] * bc[l], z2 = br[l] * bs[l];
                double I = cf.m_I * xn + cf.c_I * z1 + cf.s_I * z2;
                double xn_new = cf.a * xn + cf.s_xi * z1;
                double xh = xs + 0.5 * h * Om_;
                double s_ = sin(xh);
                double kick = omega2 * h * s_;
                kick += I * s_;
                double Om_new = Om_ - kick;
                double xw = xh + 0.5 * h * Om_new;
                double xs_new = xw - SP_TWO_PI * floor((xw + SP_PI) / SP_TWO_PI);
                double y = h - tc;
                double t_sum = tt + y;
                double tc_new = sp_kahan_comp(t_sum, tt, y);
                int finite = isfinite(xs_new) & isfinite(Om_new) & isfinite(xn_new);
                int go = act & !esc;
                bx[l] = go ? xs_new : xs;
                bO[l] = go ? Om_new : Om_;
                bxi[l] = go ? xn_new : xn;
                bt[l] = go ? (last ? t_target : t_sum) : tt;
                btc[l] = go ? (last ? 0.0 : tc_new) : tc;
                bk[l] = go ? kk + 1u : kk;
                int bad = act & (esc | (go & !finite));
                int land = go & last & finite;
                bbad[l] = bad;
                bland[l] = land;
                n_done += bad | land;
            }
            if (n_done == 0) continue;
            for (int l = 0; l < SP_LANES; ++l) {
                if (!(bbad[l] | bland[l])) continue;
                bland[l] = 0;
                if (!bbad[l] && ++bj[l] < n_times) { btarget[l] = times[bj[l]]; continue; }
                long i = bi[l];
                x[i] = bx[l]; Om[i] = bO[l]; xi[i] = bxi[l]; steps[i] = (long)bk[l];
                total += (long)bk[l];
                bbad[l] = 0; bact[l] = 0; bi[l] = -1; --n_active;
                if (next < hi) {
                    uint64_t path = path0 + (uint64_t)next;
                    init_path(&bx[l], &bO[l], &bxi[l], k0, k1, path, D, tau);
                    bt[l] = 0.0; btc[l] = 0.0; bk[l] = 0; bj[l] = 0; btarget[l] = times[0];
                    bp0[l] = (uint32_t)path; bp1[l] = (uint32_t)(path >> 32);
                    bi[l] = next++; bact[l] = 1; ++n_active;
                }
            }
        }
    }
    return total;
}

/* Micro-benchmark helpers for docs/performance.md: n evaluations of one operation. */
double sp_micro(int op, long n)
{
    double acc = 0.0;
    uint32_t w[4] = {1, 2, 3, 4};
    double v = 0.3;
    for (long i = 0; i < n; ++i) {
        switch (op) {
        case 0: w[0] += (uint32_t)i; philox4x32_10(&w[0], &w[1], &w[2], &w[3], 7u, 9u); acc += w[1]; break;
        case 1: acc += log(v + 1e-9 * (double)i); break;
        case 2: acc += sqrt(v + 1e-9 * (double)i); break;
        case 3: acc += sin(v + 1e-9 * (double)i); break;
        case 4: acc += cos(v + 1e-9 * (double)i); break;
        case 5: acc += floor(v + 1e-9 * (double)i); break;
        default: break;
        }
    }
    return acc + w[0];
}

int sp_max_threads(void) { return omp_get_max_threads(); }
