"""The x**(2n) oscillators: U(x) = x**(2n)/(2n), G = x**(2n-1), n = ``power_n`` >= 1.

Step control as for the harmonic oscillator (:mod:`.harmonic`): speed and |U''| at the orbit's
extremes, A**(2n)/(2n) = U(x) + Omega**2/(2 omega**2).
"""

from __future__ import annotations

import math

from stochpend.model.oscillators.base import Oscillator, OscillatorKernel
from stochpend.numerics._jitable import register_jitable


def build(real, mathlib) -> OscillatorKernel:
    zero = real(0.0)
    half = real(0.5)
    two = real(2.0)

    # q = (power_n,), an integer in the record (Oscillator.record): x ** (2 * n) stays an integer
    # power (repeated multiplication), never pow(x, float); int() of it costs nothing.
    @register_jitable
    def potential(x, q):
        n = int(q[0])
        return real(x ** (2 * n) / (2 * n))

    @register_jitable
    def force(x, q):
        n = int(q[0])
        return real(x ** (2 * n - 1))

    @register_jitable
    def noise_shape(x, q):
        n = int(q[0])
        return real(x ** (2 * n - 1))

    @register_jitable
    def step_scales(x, Omega, omega2, q):
        n = int(q[0])
        if omega2 > zero:
            u_max = potential(x, q) + half * Omega * Omega / omega2
            speed = math.sqrt(two * omega2 * u_max)
            return speed, real((2 * n - 1) * (2 * n * u_max) ** ((n - 1) / n))
        return abs(Omega), real((2 * n - 1) * x ** (2 * n - 2))

    @register_jitable
    def wrap(x):
        return x

    return OscillatorKernel(potential, force, noise_shape, step_scales, wrap)


POWER = Oscillator(
    name="power",
    build=build,
    description="x^(2n) oscillator, U = x^(2n)/(2n)",
    builtin=True,
    parameters=("power_n",),
)
