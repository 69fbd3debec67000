"""The harmonic oscillator: U(x) = x**2/2, G = x.

The step control resolves the local frequency sqrt(|omega**2 + xi|) alone (U'' = 1), with no
bound from the speed: the equations are linear, so (x, Omega) -> s (x, Omega) maps solutions
onto solutions and nothing in them has a length scale for a step to resolve. A speed bound
c/|Omega| would shrink the step as the amplitude grows like e^(lambda t) (issue 35: white noise,
D = omega = 1, 20 000 paths to t = 200 stood at 5 % after 9 minutes, its ETA growing). The step
is then constant along a deterministic orbit, as Stormer-Verlet's symplecticity asks (a step
that follows the instantaneous speed heats the oscillator secularly, docs/scaling.md, section 12).
"""

from __future__ import annotations

from stochpend.model.oscillators.base import Oscillator, OscillatorKernel
from stochpend.numerics._jitable import register_jitable


def build(real, mathlib) -> OscillatorKernel:
    zero = real(0.0)
    half = real(0.5)
    one = real(1.0)

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
        return zero, one  # no speed to resolve (scale invariance), U'' = 1

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
