"""The integrator, written once as plain scalar functions (derivation: docs/numerics.md).

One step of length h is a symmetric drift-kick-drift (position Stormer-Verlet) splitting

    x_half      = x_n + (h/2) Omega_n
    Omega_{n+1} = Omega_n - (omega**2 h U'(x_half) + I_n G(x_half))
    x_{n+1}     = x_half + (h/2) Omega_{n+1}

where I_n is the integral of the noise over the step:

* white noise: I_n ~ N(0, D h) exactly;
* OU noise: (xi_{n+1}, I_n) are drawn jointly and exactly given xi_n (Gaussian pair; NOTES.md,
  Fox et al. 1988, Gillespie 1996), so the step is exact for the noise whatever h/tau.

At D = 0 the step is the symplectic, time-reversible Stormer-Verlet map, so the energy error
stays bounded. With noise the scheme has weak order 2 (measured in tests/statistical).
"""

from __future__ import annotations

import math

from numba.extending import register_jitable

import numpy as np

from stochpend import physics, rng

#: Integrator metadata, stored in every result's attrs.
SCHEME = {
    "name": "strang-verlet-exact-noise",
    "description": "position Stormer-Verlet (drift-kick-drift) with the exact noise integral",
    "weak_order": 2,
    "strong_order": 1,
    "interpretation": "stratonovich (= ito for this model)",
}

# Taylor coefficients of x - 2 tanh(x/2) = x**3/12 - x**5/120 + 17 x**7/20160 - ...
# (successive coefficients shrink by about 1/pi**2; below x = 0.6 the 12 terms kept leave a
# relative truncation error < 1e-17).
_TANH_SERIES = (
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
_SERIES_BELOW = 0.6


@register_jitable
def x_minus_2tanh_half(x):
    """x - 2 tanh(x/2) for x >= 0: the series below 0.6 (round-off accurate); above it the
    direct difference, whose relative error is at most about 12 eps / x**2 (< 1e-14)."""
    if x < _SERIES_BELOW:
        x2 = x * x
        acc = 0.0
        for i in range(len(_TANH_SERIES) - 1, -1, -1):
            acc = acc * x2 + _TANH_SERIES[i]
        return acc * x * x2
    return x - 2.0 * math.tanh(0.5 * x)


@register_jitable
def ou_step_coefficients(h, D, tau):
    """Coefficients of the exact OU update over a step h (s), for noise amplitude D, time tau.

    Given xi_n and two independent standard normals z1, z2,

        xi_{n+1} = a xi_n + s_xi z1
        I_n      = m_I xi_n + c_I z1 + s_I z2

    reproduce exactly the joint Gaussian law of (xi_{n+1}, integral of xi over the step):
    means (a xi_n, tau (1 - a) xi_n), variances D (1 - a**2)/(2 tau) and
    D [h - 2 tau (1 - a) + tau (1 - a**2)/2], covariance D (1 - a)**2 / 2, with a = exp(-h/tau).
    The conditional variance of I given xi_{n+1} simplifies to D tau (x - 2 tanh(x/2)),
    x = h/tau, which is evaluated without cancellation.

    Returns ``(a, s_xi, m_I, c_I, s_I)``.
    """
    x = h / tau
    b = -math.expm1(-x)  # 1 - a, exact for small x
    a = 1.0 - b
    var_xi = D * b * (2.0 - b) / (2.0 * tau)
    s_xi = math.sqrt(var_xi)
    cov = 0.5 * D * b * b
    c_I = cov / s_xi if s_xi > 0.0 else 0.0
    s_I = math.sqrt(D * tau * x_minus_2tanh_half(x))
    return a, s_xi, tau * b, c_I, s_I


@register_jitable
def verlet_step(x, Omega, h, omega2, noise_integral, potential_code, power_n, coupling_code):
    """One drift-kick-drift step; the kick uses the noise integral over the whole step.

    ``noise_integral`` is the integral of xi over [t_n, t_n + h]. Returns (x_{n+1}, Omega_{n+1}),
    with a pendulum angle reduced to [-pi, pi).
    """
    x_half = x + 0.5 * h * Omega
    kick = omega2 * h * physics.force_shape(x_half, potential_code, power_n)
    kick += noise_integral * physics.noise_shape(x_half, potential_code, power_n, coupling_code)
    Omega_new = Omega - kick
    x_new = x_half + 0.5 * h * Omega_new
    return physics.wrap_angle(x_new, potential_code), Omega_new


@register_jitable
def step_size(Omega, xi, x, h_max, c_angle, omega2, potential_code, power_n):
    """Per-path step h = min(h_max, c/|Omega|, c/sqrt(|omega**2 + xi| |U''(x)|)).

    The first bound resolves the rotation (the angle moves by at most c per step), the second
    the instantaneous oscillation (c radians of phase per step). Both use only the state at the
    start of the step, so the choice does not look into the future of the noise.
    ``c_angle <= 0`` means a fixed step h_max.
    """
    h = h_max
    if c_angle > 0.0:
        speed = abs(Omega)
        if speed * h > c_angle:
            h = c_angle / speed
        stiff = abs(omega2 + xi) * physics.curvature(x, potential_code, power_n)
        if stiff * h * h > c_angle * c_angle:
            h = c_angle / math.sqrt(stiff)
    return h


#: A step that would stop within this fraction of h before the target is stretched to it.
LANDING_SLACK = 1e-6


@register_jitable
def landing_step(t, h, t_target):
    """The step to take from time t: h, or the rest of the way when it lands on ``t_target``.

    A step that would stop within ``LANDING_SLACK * h`` of the target is stretched to it, so
    that round-off in t never leaves a sliver step. Returns ``(h, last)``.
    """
    if t + h * (1.0 + LANDING_SLACK) >= t_target:
        return t_target - t, True
    return h, False


@register_jitable
def advance_clock(t, t_comp, h, last, t_target):
    """The time after a step of h: exactly ``t_target`` on landing (compensation reset), else a
    Kahan-compensated ``t + h``. ``t_comp`` is part of the path's state. Returns (t, t_comp)."""
    if last:
        return t_target, 0.0
    y = h - t_comp
    t_new = t + y
    return t_new, (t_new - t) - y


@register_jitable
def initial_state(key0, key1, path, theta0, uniform_theta0, Omega0, xi0, stationary_xi0, D, tau,
                  is_ou):
    """(x, Omega, xi) of a path at t = 0: x uniform on [-pi, pi) from draw ``N_INIT_THETA`` (or
    ``theta0``), Omega0, and xi from its stationary law N(0, D/(2 tau)) from draw ``N_INIT_XI``
    (or ``xi0``; 0 for white noise). ``path`` is the global path index (uint64)."""
    if uniform_theta0:
        u, _ = rng.draw_uniforms(key0, key1, path, np.uint64(rng.N_INIT_THETA))
        x = 2.0 * math.pi * u - math.pi
    else:
        x = theta0
    xi = 0.0
    if is_ou:
        if stationary_xi0:
            z, _ = rng.draw_normals(key0, key1, path, np.uint64(rng.N_INIT_XI))
            xi = math.sqrt(D / (2.0 * tau)) * z
        else:
            xi = xi0
    return x, Omega0, xi
