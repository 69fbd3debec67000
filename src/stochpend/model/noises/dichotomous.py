"""Dichotomous (telegraph) noise: +-a flipping at rate 1/(2 tau), a = sqrt(D/(2 tau)).

Its correlation a**2 exp(-|t|/tau) = D/(2 tau) exp(-|t|/tau) is the OU noise's (Eq.
`correlationOU`), so D and tau mean the same for both. It is simulated exactly: the waiting
times are exponential; the integrator cuts a step at the next flip (an *event*), between flips
the noise is the constant xi, so the step's integral is xi h, and at the flip xi changes sign
and the next flip time is drawn from the uniform of Philox draw ``N_FIRST_STEP + k`` (k the
step that ended on the flip). ``aux`` holds the time of the next flip (float64, like the clock).
"""

from __future__ import annotations

import math

import numpy as np

from stochpend.model.noises.base import Noise, NoiseKernel, no_scratch
from stochpend.numerics import rng
from stochpend.numerics._jitable import register_jitable

_U64 = np.uint64


@register_jitable
def amplitude(D, tau):
    """a = sqrt(D/(2 tau))."""
    return math.sqrt(D / (2.0 * tau))


@register_jitable
def waiting_time(u, tau):
    """Time to the next flip from a uniform u in (0, 1): exponential with rate 1/(2 tau)."""
    return -2.0 * tau * math.log(u)


def build(real, mathlib) -> NoiseKernel:
    zero = real(0.0)

    @register_jitable
    def init(key0, key1, path, p, xi0, stationary):
        """+a or -a with probability 1/2 (or a with the sign of xi0); the first flip after an
        exponential time (memoryless: the stationary law of the time to the next flip)."""
        D = p[0]
        tau = p[1]
        a = amplitude(D, tau)
        u_sign, u_wait = rng.draw_uniforms(key0, key1, path, np.uint64(rng.N_INIT_XI))
        if stationary:
            xi = a if u_sign < 0.5 else -a
        else:
            xi = a if xi0 > 0.0 else -a
        return xi, waiting_time(u_wait, tau)

    @register_jitable
    def load_aux(a):
        return np.float64(a)

    @register_jitable
    def coefficients(h, p):
        return h

    @register_jitable
    def draw(key0, key1, path, k, S):
        return (zero,), S

    @register_jitable
    def update(xi, aux, C, z):
        return xi * C, xi, aux

    @register_jitable
    def next_event(xi, aux):
        return aux

    @register_jitable
    def at_event(xi, aux, key0, key1, path, k, p):
        tau = real(p[1])  # through real, as before records: float32 kernels round tau first
        u, _ = rng.draw_uniforms(key0, key1, path, _U64(rng.N_FIRST_STEP) + k)
        return -xi, aux + waiting_time(u, np.float64(tau))

    return NoiseKernel(init, load_aux, coefficients, no_scratch, draw, update, next_event, at_event)


def _check_xi0(xi0: float) -> None:
    if xi0 == 0.0:
        raise ValueError(f"xi0={xi0!r} is not accepted: dichotomous noise starts at +a or -a: give "
                         "'stationary' or a nonzero number whose sign picks the state")


DICHOTOMOUS = Noise(
    name="dichotomous",
    build=build,
    description="dichotomous noise +-sqrt(D/(2 tau)) flipping at rate 1/(2 tau)",
    colored=True,
    has_events=True,
    builtin=True,
    parameters=("D", "tau"),
    check_xi0=_check_xi0,
    variance=lambda D, tau, W=None: D / (2.0 * tau),
    correlation=lambda t, D, tau, W=None: D / (2.0 * tau) * np.exp(-np.abs(np.asarray(t, dtype=float)) / tau),
    spectral_density=lambda nu, D, tau, W=None: D / (1.0 + (np.asarray(nu, dtype=float) * tau) ** 2),
)
