"""The harmonic oscillator: U(x) = x**2/2, G = x.

The step control uses the speed and curvature at the extremes of the current orbit (constant
along a deterministic orbit), so the step changes only as the noise changes the energy: a step
that follows the instantaneous speed, which vanishes twice a period, breaks the symplecticity
of Stormer-Verlet and heats the oscillator secularly (docs/scaling.md, section 12).
"""

from __future__ import annotations

import math

from numba.extending import register_jitable

from stochpend.oscillators.base import Oscillator, OscillatorKernel


def build(real, mathlib) -> OscillatorKernel:
    zero = real(0.0)
    half = real(0.5)
    one = real(1.0)
    two = real(2.0)

    @register_jitable
    def potential(x, q):
        return half * x * x

    @register_jitable
    def force(x, q):
        return x

    @register_jitable
    def noise_shape(x, q):
        return x

    @register_jitable
    def step_scales(x, Omega, omega2, q):
        if omega2 > zero:
            u_max = potential(x, q) + half * Omega * Omega / omega2
            return math.sqrt(two * omega2 * u_max), one
        return abs(Omega), one

    @register_jitable
    def wrap(x):
        return x

    return OscillatorKernel(potential, force, noise_shape, step_scales, wrap)


HARMONIC = Oscillator(
    name="harmonic",
    build=build,
    description="harmonic oscillator, U = x^2/2",
    builtin=True,
)
