"""Harmonic noise: xi'' + gamma xi' + W**2 xi = W**2 sqrt(D) zeta(t), gamma = W**2 tau.

zeta is unit white noise and W = ``omega_noise`` (default 2/tau, critical damping). The spectrum
D W**4 / ((W**2 - nu**2)**2 + gamma**2 nu**2) equals D at nu = 0 (like the OU noise), falls as
nu**-4, and the variance is D/(2 tau). The step is exact: (xi, eta = xi', integral of xi) is a
linear Gaussian process, updated by :func:`step_coefficients` (scaling and squaring) and
:func:`noise_step`. ``aux`` holds eta. Step k uses three normals: both of Philox draw
``N_FIRST_STEP + 2k`` and the first of draw ``N_FIRST_STEP + 2k + 1``.
"""

from __future__ import annotations

import math

import numpy as np

from stochpend.model.noises.base import Noise, NoiseKernel, at_no_event, no_event, no_scratch
from stochpend.numerics import rng
from stochpend.numerics._jitable import register_jitable

_U64 = np.uint64


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
def step_coefficients(h, D, tau, omega_noise):
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


@register_jitable
def noise_step(xi, eta, z1, z2, z3, c):
    """One exact step of the harmonic noise: ``c`` from :func:`step_coefficients`,
    z1..z3 independent standard normals. Returns (integral of xi over the step, xi', eta')."""
    p11, p12, p21, p22, p31, p32, l11, l21, l22, l31, l32, l33 = c
    integral = p31 * xi + p32 * eta + l31 * z1 + l32 * z2 + l33 * z3
    return (integral, p11 * xi + p12 * eta + l11 * z1,
            p21 * xi + p22 * eta + l21 * z1 + l22 * z2)


def build(real, mathlib) -> NoiseKernel:
    normals = rng.normals_with(mathlib, real)

    @register_jitable
    def init(key0, key1, path, p, xi0, stationary):
        """(xi, xi') ~ N(0, D/(2 tau)) x N(0, W**2 D/(2 tau)), independent (or (xi0, 0))."""
        if stationary:
            D = p[0]
            tau = p[1]
            W = p[2]
            z1, z2 = rng.draw_normals(key0, key1, path, np.uint64(rng.N_INIT_XI))
            s = math.sqrt(D / (2.0 * tau))
            return s * z1, W * s * z2
        return xi0, 0.0

    @register_jitable
    def load_aux(a):
        return real(a)

    @register_jitable
    def coefficients(h, p):
        # The parameters through real (as before records), then float64: the
        # scaling-and-squaring keeps relative accuracy for var xi ~ h**3.
        D = real(p[0])
        tau = real(p[1])
        W = real(p[2])
        c = step_coefficients(np.float64(h), np.float64(D), np.float64(tau), np.float64(W))
        return (real(c[0]), real(c[1]), real(c[2]), real(c[3]), real(c[4]), real(c[5]),
                real(c[6]), real(c[7]), real(c[8]), real(c[9]), real(c[10]), real(c[11]))

    @register_jitable
    def draw(key0, key1, path, k, S):
        d = _U64(rng.N_FIRST_STEP) + (k << _U64(1))
        z1, z2 = normals(key0, key1, path, d)
        z3, _ = normals(key0, key1, path, d + _U64(1))
        return (real(z1), real(z2), real(z3)), S

    @register_jitable
    def update(xi, aux, C, z):
        z1, z2, z3 = z
        return noise_step(xi, aux, z1, z2, z3, C)

    return NoiseKernel(init, load_aux, coefficients, no_scratch, draw, update, no_event, at_no_event)


def _spectral_density(nu, D, tau, W):
    nu = np.asarray(nu, dtype=float)
    W2 = W * W
    gamma = W2 * tau
    return D * W2 * W2 / ((W2 - nu * nu) ** 2 + gamma * gamma * nu * nu)


HARMONIC = Noise(
    name="harmonic",
    build=build,
    description="harmonic noise xi'' + W^2 tau xi' + W^2 xi = W^2 sqrt(D) zeta (spectrum ~ nu^-4)",
    colored=True,
    uses_omega_noise=True,
    builtin=True,
    parameters=("D", "tau", "omega_noise"),
    default_omega_noise=lambda tau: 2.0 / tau,  # critical damping: gamma = W**2 tau = 2 W
    variance=lambda D, tau, W: D / (2.0 * tau),
    correlation=None,
    spectral_density=_spectral_density,
)
