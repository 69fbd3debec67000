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


# -- the noises -------------------------------------------------------------------------------
#: Noise codes (the index in ``params.NOISES``).
NOISE_WHITE = 0
NOISE_OU = 1
NOISE_DICHOTOMOUS = 2
NOISE_HARMONIC = 3


@register_jitable
def dichotomous_amplitude(D, tau):
    """a = sqrt(D/(2 tau)): the telegraph noise +-a flipping at rate 1/(2 tau) then has the OU
    correlation <xi(t) xi(0)> = a**2 exp(-|t|/tau) = D/(2 tau) exp(-|t|/tau) (Eq. `correlationOU`)."""
    return math.sqrt(D / (2.0 * tau))


@register_jitable
def dichotomous_waiting_time(u, tau):
    """Time to the next flip from a uniform u in (0, 1): exponential with rate 1/(2 tau)."""
    return -2.0 * tau * math.log(u)


@register_jitable
def _mm3(a, b):
    """Product of two 3x3 matrices stored row-major in 9-tuples."""
    a0, a1, a2, a3, a4, a5, a6, a7, a8 = a
    b0, b1, b2, b3, b4, b5, b6, b7, b8 = b
    return (a0 * b0 + a1 * b3 + a2 * b6, a0 * b1 + a1 * b4 + a2 * b7, a0 * b2 + a1 * b5 + a2 * b8,
            a3 * b0 + a4 * b3 + a5 * b6, a3 * b1 + a4 * b4 + a5 * b7, a3 * b2 + a4 * b5 + a5 * b8,
            a6 * b0 + a7 * b3 + a8 * b6, a6 * b1 + a7 * b4 + a8 * b7, a6 * b2 + a7 * b5 + a8 * b8)


@register_jitable
def _mt3(a):
    """Transpose of a 3x3 matrix stored row-major in a 9-tuple."""
    a0, a1, a2, a3, a4, a5, a6, a7, a8 = a
    return (a0, a3, a6, a1, a4, a7, a2, a5, a8)


@register_jitable
def _madd3(a, b, c):
    """a + c b for 3x3 matrices in 9-tuples."""
    return (a[0] + c * b[0], a[1] + c * b[1], a[2] + c * b[2], a[3] + c * b[3], a[4] + c * b[4],
            a[5] + c * b[5], a[6] + c * b[6], a[7] + c * b[7], a[8] + c * b[8])


@register_jitable
def _mscale3(a, c):
    """c a for a 3x3 matrix in a 9-tuple."""
    return (c * a[0], c * a[1], c * a[2], c * a[3], c * a[4], c * a[5], c * a[6], c * a[7],
            c * a[8])


#: Terms of the Taylor series of the harmonic-noise propagator at the reduced step (norm of
#: s A at most 1/2): the first term left out is below 2**-17 / 17! ~ 2e-20 relative.
_HARMONIC_TAYLOR_TERMS = 17


@register_jitable
def harmonic_step_coefficients(h, D, tau, omega_noise):
    """Exact update over a step h of the harmonic noise and of its integral (Eq. in docs/numerics.md).

    The noise obeys xi'' + gamma xi' + W**2 xi = W**2 sqrt(D) zeta(t) (zeta: unit white noise),
    W = ``omega_noise``, gamma = W**2 tau, so that its spectrum D W**4 / ((W**2 - nu**2)**2 +
    gamma**2 nu**2) equals D at nu = 0 (like the OU noise) and falls as nu**-4. The vector
    X = (xi, eta = xi', I = integral of xi since the start of the step) is linear,
    dX = A X dt + b dW with A = [[0, 1, 0], [-W**2, -gamma, 0], [1, 0, 0]], b = (0, W**2 sqrt(D), 0),
    so X(h) = Phi X(0) + L z exactly, Phi = exp(A h), L L^T = Q = int_0^h exp(A u) b b^T exp(A^T u) du,
    z three independent standard normals.

    Phi and Q are computed by scaling and squaring: their Taylor series at s = h / 2**m (norm of
    s A at most 1/2), then m doublings Q <- Q + Phi Q Phi^T, Phi <- Phi Phi, which add
    positive-definite terms only, so the small entries (var xi ~ h**3, var I ~ h**5) keep their
    relative accuracy at any h.

    Returns ``(p11, p12, p21, p22, p31, p32, l11, l21, l22, l31, l32, l33)``: xi' = p11 xi +
    p12 eta + l11 z1, eta' = p21 xi + p22 eta + l21 z1 + l22 z2, I = p31 xi + p32 eta + l31 z1 +
    l32 z2 + l33 z3.
    """
    W2 = omega_noise * omega_noise
    gamma = W2 * tau
    norm = 1.0 + W2 + gamma  # bounds the infinity norm of A
    m = 0
    s = h
    while s * norm > 0.5:
        s *= 0.5
        m += 1
    sA = (0.0, s, 0.0, -W2 * s, -gamma * s, 0.0, s, 0.0, 0.0)
    sAT = _mt3(sA)
    phi = (1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0)
    term = phi
    # P_1 = b b^T s; P_{k+1} = (sA P_k + P_k sA^T) / (k + 1); Q(s) = sum of P_k.
    sigma2 = W2 * W2 * D
    P = (0.0, 0.0, 0.0, 0.0, sigma2 * s, 0.0, 0.0, 0.0, 0.0)
    Q = P
    for k in range(1, _HARMONIC_TAYLOR_TERMS + 1):
        term = _mscale3(_mm3(term, sA), 1.0 / k)  # (sA)**k / k!
        phi = _madd3(phi, term, 1.0)
        P = _mscale3(_madd3(_mm3(sA, P), _mm3(P, sAT), 1.0), 1.0 / (k + 1))
        Q = _madd3(Q, P, 1.0)
    for _ in range(m):
        Q = _madd3(Q, _mm3(_mm3(phi, Q), _mt3(phi)), 1.0)
        phi = _mm3(phi, phi)
    q11 = Q[0]
    q21 = Q[3]
    q22 = Q[4]
    q31 = Q[6]
    q32 = Q[7]
    q33 = Q[8]
    l11 = math.sqrt(q11) if q11 > 0.0 else 0.0
    l21 = q21 / l11 if l11 > 0.0 else 0.0
    r22 = q22 - l21 * l21
    l22 = math.sqrt(r22) if r22 > 0.0 else 0.0
    l31 = q31 / l11 if l11 > 0.0 else 0.0
    l32 = (q32 - l31 * l21) / l22 if l22 > 0.0 else 0.0
    r33 = q33 - l31 * l31 - l32 * l32
    l33 = math.sqrt(r33) if r33 > 0.0 else 0.0
    return phi[0], phi[1], phi[3], phi[4], phi[6], phi[7], l11, l21, l22, l31, l32, l33


#: Placeholder coefficients before the first harmonic-noise step (never used for a step).
HARMONIC_NO_COEFFICIENTS = (0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0)


@register_jitable
def harmonic_noise_step(xi, eta, z1, z2, z3, c):
    """One exact step of the harmonic noise: ``c`` from :func:`harmonic_step_coefficients`,
    z1..z3 independent standard normals. Returns (integral of xi over the step, xi', eta')."""
    p11, p12, p21, p22, p31, p32, l11, l21, l22, l31, l32, l33 = c
    integral = p31 * xi + p32 * eta + l31 * z1 + l32 * z2 + l33 * z3
    return (integral, p11 * xi + p12 * eta + l11 * z1,
            p21 * xi + p22 * eta + l21 * z1 + l22 * z2)


@register_jitable
def landing_or_flip(t, h, t_target, next_flip, dichotomous):
    """The step from time t towards the output time ``t_target`` (:func:`landing_step`), cut at
    the dichotomous noise's next flip when that comes first or at the same time.

    Returns ``(h, last, flip, t_land)``: ``last`` the step lands on ``t_target``, ``flip`` it
    lands on the flip, ``t_land`` the time it lands on when either holds (for
    :func:`advance_clock`).
    """
    if dichotomous and next_flip <= t_target:
        h, flip = landing_step(t, h, next_flip)
        return h, flip and next_flip == t_target, flip, next_flip
    h, last = landing_step(t, h, t_target)
    return h, last, False, t_target


@register_jitable
def dichotomous_flip(xi, next_flip, u, tau):
    """The telegraph noise at its flip: (-xi, time of the next flip), from a uniform u."""
    return -xi, next_flip + dichotomous_waiting_time(u, tau)


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
def step_size(Omega, xi, x, h_max, c_angle, omega2, potential_code, power_n, coupling_code):
    """Per-path step h = min(h_max, c/v, c/sqrt(k)), v a speed and k a stiffness.

    The first bound resolves the motion (x moves by at most c per step), the second the
    oscillation (c radians of phase per step): k = |omega**2 + xi| |U''| when the noise
    multiplies the force, |omega**2 U'' + xi| when it multiplies x (the linearized force in
    each case; |U''| is bounded by 1 for the pendulum).

    Pendulum (and user models): v = |Omega| and U'' at x, the instantaneous values. Harmonic
    and power potentials: v and U'' at the extremes of the current orbit (v = sqrt(Omega**2 +
    2 omega**2 U(x)), U'' at the amplitude A, A**(2n)/(2n) = U(x) + Omega**2/(2 omega**2)),
    which are constant along a deterministic orbit. An oscillator's speed runs from 0 to its
    maximum twice a period, and a step that follows it makes Stormer-Verlet lose its
    symplecticity: the energy then drifts secularly (measured: the quartic with OU noise on x
    heated to 2.6 times the converged <E> at t = 10**4). A step set by the orbit varies only as
    the noise changes the energy. Both bounds use only the state at the start of the step, so
    the choice does not look into the future of the noise. ``c_angle <= 0``: fixed step h_max.
    """
    h = h_max
    if c_angle > 0.0:
        if potential_code != physics.PENDULUM and omega2 > 0.0:
            u_max = physics.potential(x, potential_code, power_n) + 0.5 * Omega * Omega / omega2
            speed = math.sqrt(2.0 * omega2 * u_max)
            if potential_code == physics.POWER:
                curv = (2 * power_n - 1) * (2 * power_n * u_max) ** ((power_n - 1) / power_n)
            else:
                curv = 1.0
        else:
            speed = abs(Omega)
            curv = physics.curvature(x, potential_code, power_n)
        if speed * h > c_angle:
            h = c_angle / speed
        if coupling_code == physics.COUPLING_POSITION:
            stiff = abs(omega2 * curv + xi)
        else:
            stiff = abs(omega2 + xi) * curv
        if stiff * h * h > c_angle * c_angle:
            h = c_angle / math.sqrt(stiff)
    return h


#: A path whose step control asks for a step below this fraction of h_max has escaped: it is
#: running away (|Omega| or its frequency beyond 1e9 c/h_max, e.g. a finite-time blow-up that
#: the shrinking steps would otherwise follow forever). It is frozen and counted with the
#: non-finite paths, never averaged.
ESCAPE_STEP_FRACTION = 1e-9


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
                  noise_code, omega_noise):
    """(x, Omega, xi, xi_aux) of a path at t = 0. ``path`` is the global path index (uint64).

    x is uniform on [-pi, pi) from draw ``N_INIT_THETA`` (or ``theta0``); Omega is Omega0. The
    noise starts in its stationary law from draw ``N_INIT_XI`` unless ``stationary_xi0`` is
    false:

    * white: xi = 0 (unused);
    * OU: xi ~ N(0, D/(2 tau)) (or ``xi0``);
    * dichotomous: xi = +a or -a with probability 1/2 (or a with the sign of ``xi0``), and
      ``xi_aux`` = the time of the first switch, exponential with rate 1/(2 tau) (memoryless:
      the stationary law of the time to the next switch);
    * harmonic: (xi, xi_aux = dxi/dt) ~ N(0, D/(2 tau)) x N(0, W**2 D/(2 tau)) independent,
      W = ``omega_noise`` (or ``(xi0, 0)``).
    """
    if uniform_theta0:
        u, _ = rng.draw_uniforms(key0, key1, path, np.uint64(rng.N_INIT_THETA))
        x = 2.0 * math.pi * u - math.pi
    else:
        x = theta0
    xi = 0.0
    xi_aux = 0.0
    if noise_code == NOISE_OU:
        if stationary_xi0:
            z, _ = rng.draw_normals(key0, key1, path, np.uint64(rng.N_INIT_XI))
            xi = math.sqrt(D / (2.0 * tau)) * z
        else:
            xi = xi0
    elif noise_code == NOISE_DICHOTOMOUS:
        a = dichotomous_amplitude(D, tau)
        u_sign, u_wait = rng.draw_uniforms(key0, key1, path, np.uint64(rng.N_INIT_XI))
        if stationary_xi0:
            xi = a if u_sign < 0.5 else -a
        else:
            xi = a if xi0 > 0.0 else -a
        xi_aux = dichotomous_waiting_time(u_wait, tau)
    elif noise_code == NOISE_HARMONIC:
        if stationary_xi0:
            z1, z2 = rng.draw_normals(key0, key1, path, np.uint64(rng.N_INIT_XI))
            s = math.sqrt(D / (2.0 * tau))
            xi = s * z1
            xi_aux = omega_noise * s * z2
        else:
            xi = xi0
    return x, Omega0, xi, xi_aux
