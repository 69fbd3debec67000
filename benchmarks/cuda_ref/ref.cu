/*
 * Hand-written CUDA C reference of stochpend's scheme, the GPU floor for benchmarks/gpu_bench.py.
 *
 * One thread per path, the state in registers, nothing stored per path: the pendulum with OU
 * noise on the force (dOmega/dt = -(omega^2 + xi) sin theta), stochpend's numbers:
 *
 *   - Philox4x32-10 keyed like stochpend.numerics.rng: key = (seed mod 2^32, seed >> 32), counter =
 *     (n mod 2^32, n >> 32, path mod 2^32, path >> 32); draw 0 gives theta0, draw 1 xi0, draw
 *     k + 2 the two normals of step k. On the device the round uses __umulhi and a 32-bit
 *     product (cuRAND's philox4x32_10);
 *   - float64 normals: Box-Muller on two 52-bit uniforms (rng.uniform_open); float32 normals:
 *     Box-Muller in float32 on (0, 1] uniforms of words 0 and 2 (rng.uniform_f32);
 *   - initial conditions in float64, rounded to the precision (integrator.init_path);
 *   - the exact OU step (noises/ou.py: a, s_xi, m_I, c_I, s_I from x = h/tau, with the series of
 *     x - 2 tanh(x/2) below 0.6), recomputed whenever h changes;
 *   - the drift-kick-drift step and the angle wrap of integrator.verlet/oscillators/pendulum.py;
 *   - fixed step: h = h_max, n_steps steps; adaptive: h = min(h_max, c/|Omega|,
 *     c/sqrt|omega^2 + xi|) from the state at the start of the step, the last step landing on
 *     t_max (a step ending within 1e-6 h of it is stretched), t += h in float64 (no Kahan
 *     compensation, no output times, no escape test, no finiteness test: stochpend's extra work);
 *   - at the end E = Omega^2/2 - omega^2 cos theta (float64); E and E^2 summed per warp
 *     (shuffles), one atomicAdd per warp; the steps taken likewise.
 *
 * Kernels (extern "C", so the names are known): ref_f64_fixed, ref_f64_adaptive, ref_f32_fixed,
 * ref_f32_adaptive, all with the arguments of REF_ARGS. Compiled by gpu_bench.py with NVRTC (or
 * nvcc) for the GPU. Without __CUDACC__ the same file compiles as C++ for the host (g++), which
 * the benchmark's offline check uses to compare Philox, the normals and the step with stochpend's.
 */
#ifdef __CUDACC__
#define SP_HD __host__ __device__ __forceinline__
#else
#include <math.h>
#define SP_HD static inline
#endif

typedef unsigned int u32;
typedef unsigned long long u64;

#define SP_PI 3.141592653589793
#define SP_TWO_PI 6.283185307179586
#define N_FIRST_STEP 2ull
#define LANDING_SLACK 1e-6

/* ---- Philox4x32-10 ------------------------------------------------------------------------- */
SP_HD void mulhilo(u32 m, u32 a, u32 *hi, u32 *lo)
{
#ifdef __CUDA_ARCH__
    *hi = __umulhi(m, a);
    *lo = m * a;
#else
    u64 p = (u64)m * (u64)a;
    *hi = (u32)(p >> 32);
    *lo = (u32)p;
#endif
}

SP_HD void philox4x32_10(u32 c[4], u32 k0, u32 k1)
{
#pragma unroll
    for (int r = 0; r < 10; ++r) {
        u32 hi0, lo0, hi1, lo1;
        mulhilo(0xD2511F53u, c[0], &hi0, &lo0);
        mulhilo(0xCD9E8D57u, c[2], &hi1, &lo1);
        u32 n0 = hi1 ^ c[1] ^ k0;
        u32 n2 = hi0 ^ c[3] ^ k1;
        c[0] = n0; c[1] = lo1; c[2] = n2; c[3] = lo0;
        k0 += 0x9E3779B9u;
        k1 += 0xBB67AE85u;
    }
}

SP_HD void draw_words(u32 k0, u32 k1, u64 path, u64 n, u32 w[4])
{
    w[0] = (u32)n; w[1] = (u32)(n >> 32); w[2] = (u32)path; w[3] = (u32)(path >> 32);
    philox4x32_10(w, k0, k1);
}

/* rng.uniform_open: (k + 1/2) / 2^52, k the high 26 bits of a and of b. */
SP_HD double uniform_open(u32 a, u32 b)
{
    double k = (double)(a >> 6) * 67108864.0 + (double)(b >> 6);
    return (k + 0.5) * (1.0 / 4503599627370496.0);
}

/* rng.uniform_f32: a 2^-32 + 2^-33 in float32, on (0, 1]. */
SP_HD float uniform_f32(u32 a)
{
    return (float)a * 2.3283064365386963e-10f + 1.1641532182693481e-10f;
}

SP_HD void normals_f64(u32 k0, u32 k1, u64 path, u64 n, double *z1, double *z2)
{
    u32 w[4];
    draw_words(k0, k1, path, n, w);
    double r = sqrt(-2.0 * log(uniform_open(w[0], w[1])));
    double phase = SP_TWO_PI * uniform_open(w[2], w[3]);
    *z1 = r * cos(phase);
    *z2 = r * sin(phase);
}

SP_HD void normals_f32(u32 k0, u32 k1, u64 path, u64 n, float *z1, float *z2)
{
    u32 w[4];
    draw_words(k0, k1, path, n, w);
    float r = sqrtf(-2.0f * logf(uniform_f32(w[0])));
    float s, c;
#ifdef __CUDA_ARCH__
    sincosf((float)SP_TWO_PI * uniform_f32(w[2]), &s, &c);
#else
    float phase = (float)SP_TWO_PI * uniform_f32(w[2]);
    s = sinf(phase);
    c = cosf(phase);
#endif
    *z1 = r * c;
    *z2 = r * s;
}

SP_HD void normals(u32 k0, u32 k1, u64 path, u64 n, double *z1, double *z2) { normals_f64(k0, k1, path, n, z1, z2); }
SP_HD void normals(u32 k0, u32 k1, u64 path, u64 n, float *z1, float *z2) { normals_f32(k0, k1, path, n, z1, z2); }

/* ---- the step, in the precision T ------------------------------------------------------------ */
SP_HD double t_sqrt(double x) { return sqrt(x); }
SP_HD float t_sqrt(float x) { return sqrtf(x); }
SP_HD double t_sin(double x) { return sin(x); }
SP_HD float t_sin(float x) { return sinf(x); }
SP_HD double t_expm1(double x) { return expm1(x); }
SP_HD float t_expm1(float x) { return expm1f(x); }
SP_HD double t_tanh(double x) { return tanh(x); }
SP_HD float t_tanh(float x) { return tanhf(x); }
SP_HD double t_floor(double x) { return floor(x); }
SP_HD float t_floor(float x) { return floorf(x); }

/* x - 2 tanh(x/2): the series of noises/ou.py below 0.6, else the difference. */
template <typename T> SP_HD T x_minus_2tanh_half(T x)
{
    const T c[12] = {
        (T)(1.0 / 12.0), (T)(-1.0 / 120.0), (T)(17.0 / 20160.0), (T)(-31.0 / 362880.0),
        (T)(691.0 / 79833600.0), (T)(-5461.0 / 6227020800.0), (T)(929569.0 / 10461394944000.0),
        (T)(-3202291.0 / 355687428096000.0), (T)(221930581.0 / 243290200817664000.0),
        (T)(-4722116521.0 / 51090942171709440000.0),
        (T)(56963745931.0 / 6082827467972935680000.0),
        (T)(-14717667114151.0 / 15511210043330985984000000.0)};
    if (x < (T)0.6) {
        T x2 = x * x, acc = (T)0;
#pragma unroll
        for (int i = 11; i >= 0; --i) acc = acc * x2 + c[i];
        return acc * x * x2;
    }
    return x - (T)2 * t_tanh((T)0.5 * x);
}

template <typename T> struct OUCoefficients { T a, s_xi, m_I, c_I, s_I; };

template <typename T> SP_HD OUCoefficients<T> ou_coefficients(T h, T D, T tau)
{
    OUCoefficients<T> C;
    T x = h / tau;
    T b = -t_expm1(-x);
    C.a = (T)1 - b;
    C.s_xi = t_sqrt(D * b * ((T)2 - b) / ((T)2 * tau));
    T cov = (T)0.5 * D * b * b;
    C.c_I = C.s_xi > (T)0 ? cov / C.s_xi : (T)0;
    C.s_I = t_sqrt(D * tau * x_minus_2tanh_half(x));
    C.m_I = tau * b;
    return C;
}

/* One step of length h: the noise's exact update and drift-kick-drift (integrator.verlet). */
template <typename T>
SP_HD void step(T *x, T *Omega, T *xi, T h, T omega2, const OUCoefficients<T> &C, T z1, T z2)
{
    T I = C.m_I * *xi + C.c_I * z1 + C.s_I * z2;
    *xi = C.a * *xi + C.s_xi * z1;
    T x_half = *x + (T)0.5 * h * *Omega;
    T s = t_sin(x_half);
    T kick = omega2 * h * s;
    kick += I * s;
    *Omega = *Omega - kick;
    T x_new = x_half + (T)0.5 * h * *Omega;
    const T pi = (T)SP_PI, two_pi = (T)SP_TWO_PI;
    *x = x_new - two_pi * t_floor((x_new + pi) / two_pi);
}

/* integrator.init_path for the OU pendulum: theta0 uniform, Omega0 = 0, stationary xi0. */
SP_HD void init_path(u32 k0, u32 k1, u64 path, double D, double tau, double *x, double *xi)
{
    u32 w[4];
    draw_words(k0, k1, path, 0ull, w);
    *x = SP_TWO_PI * uniform_open(w[0], w[1]) - SP_PI;
    double z1, z2;
    normals_f64(k0, k1, path, 1ull, &z1, &z2);
    *xi = sqrt(D / (2.0 * tau)) * z1;
}

#ifdef __CUDACC__
/* ---- the kernels ------------------------------------------------------------------------------ */
template <typename T, bool ADAPTIVE>
__device__ void run_path(u64 n_paths, u64 path0, u32 k0, u32 k1, double D, double tau,
                         double omega2, double h_max, double step_c, double t_max, u64 n_steps,
                         double *sums, u64 *steps_out)
{
    u64 i = (u64)blockIdx.x * blockDim.x + threadIdx.x;
    double E = 0.0, E2 = 0.0;
    u64 steps = 0;
    if (i < n_paths) {
        u64 path = path0 + i;
        double x0, xi0;
        init_path(k0, k1, path, D, tau, &x0, &xi0);
        T x = (T)x0, Omega = (T)0, xi = (T)xi0;
        const T D_r = (T)D, tau_r = (T)tau, omega2_r = (T)omega2, h_max_r = (T)h_max, c_r = (T)step_c;
        OUCoefficients<T> C = ou_coefficients(h_max_r, D_r, tau_r);
        if (!ADAPTIVE) {
            for (u64 k = 0; k < n_steps; ++k) {
                T z1, z2;
                normals(k0, k1, path, N_FIRST_STEP + k, &z1, &z2);
                step(&x, &Omega, &xi, h_max_r, omega2_r, C, z1, z2);
            }
            steps = n_steps;
        } else {
            double t = 0.0;
            T h_cached = h_max_r;
            bool last = false;
            while (!last) {
                T h = h_max_r;
                T speed = fabs(Omega);
                if (speed * h > c_r) h = c_r / speed;
                T stiff = fabs(omega2_r + xi);
                if (stiff * h * h > c_r * c_r) h = c_r / t_sqrt(stiff);
                double h_clock = (h == h_max_r) ? h_max : (double)h;
                if (t + h_clock * (1.0 + LANDING_SLACK) >= t_max) {
                    h_clock = t_max - t;
                    last = true;
                }
                h = (T)h_clock;
                if (h != h_cached) {
                    C = ou_coefficients(h, D_r, tau_r);
                    h_cached = h;
                }
                T z1, z2;
                normals(k0, k1, path, N_FIRST_STEP + steps, &z1, &z2);
                step(&x, &Omega, &xi, h, omega2_r, C, z1, z2);
                t = last ? t_max : t + h_clock;
                ++steps;
            }
        }
        double Om = (double)Omega;
        E = 0.5 * Om * Om - omega2 * cos((double)x);
        E2 = E * E;
    }
    for (int offset = 16; offset > 0; offset >>= 1) {
        E += __shfl_down_sync(0xffffffffu, E, offset);
        E2 += __shfl_down_sync(0xffffffffu, E2, offset);
        steps += __shfl_down_sync(0xffffffffu, steps, offset);
    }
    if ((threadIdx.x & 31) == 0) {
        atomicAdd(&sums[0], E);
        atomicAdd(&sums[1], E2);
        atomicAdd(steps_out, steps);
    }
}

#define REF_ARGS u64 n_paths, u64 path0, u32 k0, u32 k1, double D, double tau, double omega2, \
                 double h_max, double step_c, double t_max, u64 n_steps, double *sums, u64 *steps
#define REF_CALL n_paths, path0, k0, k1, D, tau, omega2, h_max, step_c, t_max, n_steps, sums, steps

extern "C" __global__ void ref_f64_fixed(REF_ARGS) { run_path<double, false>(REF_CALL); }
extern "C" __global__ void ref_f64_adaptive(REF_ARGS) { run_path<double, true>(REF_CALL); }
extern "C" __global__ void ref_f32_fixed(REF_ARGS) { run_path<float, false>(REF_CALL); }
extern "C" __global__ void ref_f32_adaptive(REF_ARGS) { run_path<float, true>(REF_CALL); }
#endif
