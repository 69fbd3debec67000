"""Ornstein-Uhlenbeck noise: <xi(t) xi(t')> = D/(2 tau) exp(-|t - t'|/tau) (Eqs. `eqOU`,
`correlationOU`), started in its stationary law N(0, D/(2 tau)).

The step is exact whatever h/tau: given xi_n and two independent standard normals z1, z2,

    xi_{n+1} = a xi_n + s_xi z1
    I_n      = m_I xi_n + c_I z1 + s_I z2

reproduce the joint Gaussian law of (xi_{n+1}, integral of xi over the step) (NOTES.md; Fox et
al. 1988, Gillespie 1996): means (a xi_n, tau (1 - a) xi_n), variances D (1 - a**2)/(2 tau) and
D [h - 2 tau (1 - a) + tau (1 - a**2)/2], covariance D (1 - a)**2 / 2, with a = exp(-h/tau).
The conditional variance of I given xi_{n+1} simplifies to D tau (x - 2 tanh(x/2)), x = h/tau,
which :func:`x_minus_2tanh_half` evaluates without cancellation. Step k uses both normals of
Philox draw ``N_FIRST_STEP + k``. With the fast math of the CPU's SIMD kernels the
coefficients are :func:`branch_free_coefficients` (a few ulps from the C library's).
"""

from __future__ import annotations

import math

import numpy as np

from stochpend.model.noises.base import Noise, NoiseKernel, at_no_event, no_event, no_scratch
from stochpend.numerics import rng
from stochpend.numerics._jitable import register_jitable
from stochpend.numerics.fastmath import select

_U64 = np.uint64

# Taylor coefficients of x - 2 tanh(x/2) = x**3/12 - x**5/120 + 17 x**7/20160 - ...
# (successive coefficients shrink by about 1/pi**2; below x = 0.6 the 12 terms kept leave a
# relative truncation error < 1e-17).
TANH_SERIES = (
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
)
SERIES_BELOW = 0.6


def step_functions(real):
    """``(x_minus_2tanh_half, coefficients)`` computed in ``real`` arithmetic."""
    zero = real(0.0)
    half = real(0.5)
    one = real(1.0)
    two = real(2.0)
    below = real(SERIES_BELOW)
    series = tuple(real(c) for c in TANH_SERIES)
    n_series = len(series)

    @register_jitable
    def x_minus_2tanh_half(x):
        """x - 2 tanh(x/2) for x >= 0: the series below 0.6 (round-off accurate); above it the
        direct difference, whose relative error is at most about 12 eps / x**2 (< 1e-14)."""
        if x < below:
            x2 = x * x
            acc = zero
            for i in range(n_series - 1, -1, -1):
                acc = acc * x2 + series[i]
            return acc * x * x2
        return x - two * math.tanh(half * x)

    @register_jitable
    def coefficients(h, p):
        """``(a, s_xi, m_I, c_I, s_I)`` of the exact update over a step h (module docstring);
        ``p = (D, tau)``."""
        D = real(p[0])
        tau = real(p[1])
        x = h / tau
        b = -math.expm1(-x)  # 1 - a, exact for small x
        a = one - b
        var_xi = D * b * (two - b) / (two * tau)
        s_xi = math.sqrt(var_xi)
        cov = half * D * b * b
        c_I = cov / s_xi if s_xi > zero else zero
        s_I = math.sqrt(D * tau * x_minus_2tanh_half(x))
        return a, s_xi, tau * b, c_I, s_I

    return x_minus_2tanh_half, coefficients


#: The float64 functions, callable from Python (tests, the reduced dynamics).
x_minus_2tanh_half, step_coefficients = step_functions(np.float64)


def branch_free_coefficients(real, mathlib):
    """:func:`step_functions`'s ``coefficients`` with no branch and no C-library call, so that
    a loop over SIMD lanes, each with its own h, vectorizes (the fast-math kernels).

    The same formulas, with ``mathlib.expm1`` for 1 - a and tanh(x/2) = b/(2 - b) (b = 1 - a)
    in the direct form of x - 2 tanh(x/2) for x >= 0.6; both branches are evaluated and one
    selected; invariant factors (1/tau, D/(2 tau)) grouped so that the compiler computes them
    once per loop. They differ from the C library's by a few ulps
    (tests/unit/test_fastmath.py).
    """
    expm1 = mathlib.expm1
    zero = real(0.0)
    half = real(0.5)
    one = real(1.0)
    two = real(2.0)
    below = real(SERIES_BELOW)
    c0, c1, c2, c3, c4, c5, c6, c7, c8, c9, c10, c11 = (real(c) for c in TANH_SERIES)

    @register_jitable(inline="always")
    def coefficients(h, p):
        D = real(p[0])
        tau = real(p[1])
        x = h * (one / tau)
        b = -expm1(-x)
        a = one - b
        s_xi = math.sqrt((D / (two * tau)) * (b * (two - b)))
        cov = (half * D) * (b * b)
        c_I = select(s_xi > zero, cov / s_xi, zero)
        x2 = x * x
        acc = c11
        acc = acc * x2 + c10
        acc = acc * x2 + c9
        acc = acc * x2 + c8
        acc = acc * x2 + c7
        acc = acc * x2 + c6
        acc = acc * x2 + c5
        acc = acc * x2 + c4
        acc = acc * x2 + c3
        acc = acc * x2 + c2
        acc = acc * x2 + c1
        acc = acc * x2 + c0
        series = acc * x * x2
        direct = x - two * b / (two - b)
        f = select(x < below, series, direct)
        s_I = math.sqrt((D * tau) * f)
        return a, s_xi, tau * b, c_I, s_I

    return coefficients


def build(real, mathlib) -> NoiseKernel:
    normals = rng.normals_with(mathlib, real)
    normals_keyed = rng.normals_keyed_with(mathlib)
    lanes = mathlib.name != "libm"
    if lanes:
        coefficients = branch_free_coefficients(real, mathlib)
    else:
        _, coefficients = step_functions(real)

    @register_jitable
    def init(key0, key1, path, p, xi0, stationary):
        if stationary:
            D = p[0]
            tau = p[1]
            z, _ = rng.draw_normals(key0, key1, path, np.uint64(rng.N_INIT_XI))
            return math.sqrt(D / (2.0 * tau)) * z, 0.0
        return xi0, 0.0

    @register_jitable
    def load_aux(a):
        return real(a)

    @register_jitable
    def draw(key0, key1, path, k, S):
        z1, z2 = normals(key0, key1, path, _U64(rng.N_FIRST_STEP) + k)
        return (real(z1), real(z2)), S

    @register_jitable(inline="always")
    def draw_keyed(rk0, rk1, c2, c3, k):
        z1, z2 = normals_keyed(rk0, rk1, c2, c3, _U64(rng.N_FIRST_STEP) + k)
        return (real(z1), real(z2))

    @register_jitable
    def update(xi, aux, C, z):
        a, s_xi, m_I, c_I, s_I = C
        z1, z2 = z
        return m_I * xi + c_I * z1 + s_I * z2, a * xi + s_xi * z1, aux

    return NoiseKernel(init, load_aux, coefficients, no_scratch, draw, update, no_event, at_no_event,
                       draw_keyed if lanes else None)


def _correlation(t, D, tau, W=None):
    return D / (2.0 * tau) * np.exp(-np.abs(np.asarray(t, dtype=float)) / tau)


def _spectral_density(nu, D, tau, W=None):
    nu = np.asarray(nu, dtype=float)
    return D / (1.0 + (nu * tau) ** 2)


OU = Noise(
    name="ou",
    build=build,
    description="Ornstein-Uhlenbeck noise, <xi xi'> = D/(2 tau) exp(-|t - t'|/tau) (eqOU)",
    colored=True,
    pair_draws=True,
    builtin=True,
    parameters=("D", "tau"),
    variance=lambda D, tau, W=None: D / (2.0 * tau),
    correlation=_correlation,
    spectral_density=_spectral_density,
)
