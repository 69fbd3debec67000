"""White noise: <xi(t) xi(t')> = D delta(t - t') (Eq. `defbruitblanc`).

Its integral over a step h is exactly N(0, D h). Step k uses one normal of the pair of Philox
draw ``N_FIRST_STEP + k // 2`` (the first for even k, the second for odd k), so two steps cost
one draw; the pair is carried from one step to the next in the loop's scratch.
"""

from __future__ import annotations

import math

import numpy as np

from stochpend.model.noises.base import Noise, NoiseKernel, at_no_event, no_event
from stochpend.numerics import rng
from stochpend.numerics._jitable import register_jitable
from stochpend.numerics.fastmath import select

_U64 = np.uint64
_NO_DRAW = np.uint64(0xFFFFFFFFFFFFFFFF)


def build(real, mathlib) -> NoiseKernel:
    normals = rng.normals_with(mathlib, real)
    normals_keyed = rng.normals_keyed_with(mathlib)
    zero = real(0.0)

    @register_jitable
    def init(key0, key1, path, p, xi0, stationary):
        return 0.0, 0.0

    @register_jitable
    def load_aux(a):
        return real(a)

    @register_jitable
    def coefficients(h, p):
        D = real(p[0])
        return math.sqrt(D * h)

    @register_jitable
    def scratch0():
        return _NO_DRAW, zero, zero

    @register_jitable
    def draw(key0, key1, path, k, S):
        d = _U64(rng.N_FIRST_STEP) + (k >> _U64(1))
        pair, z_even, z_odd = S
        if d != pair:
            z_even, z_odd = normals(key0, key1, path, d)
            pair = d
        z = z_even if (k & _U64(1)) == 0 else z_odd
        return (real(z),), (pair, z_even, z_odd)

    @register_jitable(inline="always")
    def draw_keyed(rk0, rk1, c2, c3, k):
        # Both normals of the pair every step (a lane keeps no pair from step to step).
        z_even, z_odd = normals_keyed(rk0, rk1, c2, c3, _U64(rng.N_FIRST_STEP) + (k >> _U64(1)))
        z = select((k & _U64(1)) != 0, z_odd, z_even)
        return (real(z),)

    @register_jitable
    def update(xi, aux, C, z):
        return C * z[0], xi, aux

    return NoiseKernel(init, load_aux, coefficients, scratch0, draw, update, no_event, at_no_event,
                       None if mathlib.name == "libm" else draw_keyed)


WHITE = Noise(
    name="white",
    build=build,
    description="white noise, <xi(t) xi(t')> = D delta(t - t') (defbruitblanc)",
    colored=False,
    builtin=True,
    parameters=("D",),
    variance=lambda D, tau=None, W=None: math.inf,
    correlation=None,
    spectral_density=lambda nu, D, tau=None, W=None: D + 0.0 * np.asarray(nu, dtype=float),
)
