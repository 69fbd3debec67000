"""The models, written once: plain scalar functions of floats, compiled by Numba for every target.

The oscillator is

    dx/dt = Omega,    dOmega/dt = -omega**2 U'(x) - xi(t) G(x)

with the paper's pendulum as the default: x = theta, U(theta) = -cos(theta), G = U' = sin
(Eqs. `dynOmega`, `dyntheta`). The noise xi is either white, <xi(t) xi(t')> = D delta(t - t')
(`defbruitblanc`), or Ornstein-Uhlenbeck with correlation time tau, <xi xi'> = D/(2 tau)
exp(-|t - t'|/tau) (`eqOU`, `correlationOU`). The energy is E = Omega**2/2 + omega**2 U(x)
(`defenergie`).

Because the noise multiplies a function of x alone and enters only the Omega equation, the
Ito and Stratonovich readings of the white-noise system coincide (the drift correction
(1/2) b . grad b vanishes: b = (0, -G(x)) has no component along Omega's gradient of itself).

Every function takes and returns scalars; integer codes select the potential and the coupling
so that a single compiled kernel serves every model (and can be cached on disk).
"""

from __future__ import annotations

import math

from numba.extending import register_jitable

#: Potential codes. PENDULUM: U = -cos x. HARMONIC: U = x**2/2. POWER: U = x**(2n)/(2n).
PENDULUM = 0
HARMONIC = 1
POWER = 2
POTENTIALS = {"pendulum": PENDULUM, "harmonic": HARMONIC, "power": POWER}

#: Coupling codes: the noise multiplies the force U'(x) (the paper's pendulum) or x itself
#: (the random-frequency oscillator of the follow-up papers).
COUPLING_FORCE = 0
COUPLING_POSITION = 1
COUPLINGS = {"force": COUPLING_FORCE, "position": COUPLING_POSITION}


@register_jitable
def potential(x, potential_code, power_n):
    """U(x), dimensionless; the energy is Omega**2/2 + omega**2 U(x) (Eq. `defenergie`)."""
    if potential_code == PENDULUM:
        return -math.cos(x)
    if potential_code == HARMONIC:
        return 0.5 * x * x
    return x ** (2 * power_n) / (2 * power_n)


@register_jitable
def force_shape(x, potential_code, power_n):
    """U'(x): the deterministic force is -omega**2 U'(x)."""
    if potential_code == PENDULUM:
        return math.sin(x)
    if potential_code == HARMONIC:
        return x
    return x ** (2 * power_n - 1)


@register_jitable
def curvature(x, potential_code, power_n):
    """|U''(x)|, bounded by 1 for the pendulum; sets the local oscillation frequency."""
    if potential_code == PENDULUM:
        return 1.0
    if potential_code == HARMONIC:
        return 1.0
    return (2 * power_n - 1) * x ** (2 * power_n - 2)


@register_jitable
def noise_shape(x, potential_code, power_n, coupling_code):
    """G(x), the function of x that the noise multiplies in dOmega/dt (Eq. `dynOmega`: sin x)."""
    if coupling_code == COUPLING_POSITION:
        return x
    return force_shape(x, potential_code, power_n)


@register_jitable
def energy(x, Omega, omega2, potential_code, power_n):
    """E = Omega**2/2 + omega**2 U(x) (Eq. `defenergie`)."""
    return 0.5 * Omega * Omega + omega2 * potential(x, potential_code, power_n)


@register_jitable
def wrap_angle(x, potential_code):
    """Reduce the pendulum angle to [-pi, pi); other coordinates pass through unchanged."""
    if potential_code == PENDULUM:
        return x - 2.0 * math.pi * math.floor((x + math.pi) / (2.0 * math.pi))
    return x
