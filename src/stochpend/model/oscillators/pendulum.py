"""The paper's pendulum: U(theta) = -cos theta, G = sin theta, theta kept in [-pi, pi).

The step control follows the instantaneous speed |Omega|, and |U''| <= 1 bounds the curvature
(the validated rule of docs/numerics.md).
"""

from __future__ import annotations

import math

from stochpend.model.oscillators.base import Oscillator, OscillatorKernel
from stochpend.numerics._jitable import register_jitable


def build(real, mathlib) -> OscillatorKernel:
    sin = mathlib.sin
    cos = mathlib.cos
    floor = mathlib.floor
    one = real(1.0)
    pi = real(math.pi)
    two_pi = real(2.0 * math.pi)

    @register_jitable
    def potential(x, q):
        return -cos(x)

    @register_jitable
    def force(x, q):
        return sin(x)

    @register_jitable
    def noise_shape(x, q):
        return sin(x)

    @register_jitable
    def step_scales(x, Omega, omega2, q):
        return abs(Omega), one

    @register_jitable
    def wrap(x):
        return x - two_pi * real(floor((x + pi) / two_pi))

    return OscillatorKernel(potential, force, noise_shape, step_scales, wrap)


PENDULUM = Oscillator(
    name="pendulum",
    build=build,
    description="pendulum, U = -cos(theta)",
    periodic=True,
    energy_floor=lambda q: -1.0,
    builtin=True,
)
