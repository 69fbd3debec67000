"""A test-only noise with parameters of its own, defined in this one file: the sum of two
independent Ornstein-Uhlenbeck processes,

    xi = xi_1 + xi_2,   <xi_i(t) xi_i(t')> = D_i/(2 tau_i) exp(-|t - t'|/tau_i),
    D_1 = weight D,  D_2 = (1 - weight) D,

so that its spectral density at zero is D, as for every built-in noise, and its stationary
variance is weight D/(2 tau1) + (1 - weight) D/(2 tau2). It declares three parameters the
package has never heard of -- ``tau1``, ``tau2`` and ``weight`` -- with their defaults, ranges
and meanings; the kernels receive them in its record ``(D, tau1, tau2, weight)``. Each
component steps exactly with the OU update of ``stochpend.noises.ou`` (two normals each: draws
``N_FIRST_STEP + 2k`` and ``+ 2k + 1``). ``xi`` is the sum, ``aux`` the second component.

Registering it (importing this module: ``--plugin tests.unit._two_ou`` on the command line)
makes ``noise="two-ou"`` work everywhere with no file of stochpend changed
(tests/unit/test_declared_parameters.py).
"""

from __future__ import annotations

import math

import numpy as np
from numba.extending import register_jitable

from stochpend import noises
from stochpend.model.parameters import Parameter
from stochpend.noises import ou
from stochpend.noises.base import Noise, NoiseKernel, at_no_event, no_event, no_scratch
from stochpend.numerics import rng

NAME = "two-ou"
_U64 = np.uint64


def build(real, mathlib) -> NoiseKernel:
    normals = rng.normals_with(mathlib, real)
    _, ou_coefficients = ou.step_functions(real)
    one = real(1.0)

    @register_jitable
    def init(key0, key1, path, p, xi0, stationary):
        D, tau1, tau2, weight = p
        if stationary:
            z1, z2 = rng.draw_normals(key0, key1, path, np.uint64(rng.N_INIT_XI))
            xi1 = math.sqrt(weight * D / (2.0 * tau1)) * z1
            xi2 = math.sqrt((1.0 - weight) * D / (2.0 * tau2)) * z2
            return xi1 + xi2, xi2
        return xi0, (1.0 - weight) * xi0

    @register_jitable
    def load_aux(a):
        return real(a)

    @register_jitable
    def coefficients(h, p):
        D, tau1, tau2, weight = real(p[0]), real(p[1]), real(p[2]), real(p[3])
        return ou_coefficients(h, (weight * D, tau1)), ou_coefficients(h, ((one - weight) * D, tau2))

    @register_jitable
    def draw(key0, key1, path, k, S):
        d = _U64(rng.N_FIRST_STEP) + (k << _U64(1))
        z1, z2 = normals(key0, key1, path, d)
        z3, z4 = normals(key0, key1, path, d + _U64(1))
        return (real(z1), real(z2), real(z3), real(z4)), S

    @register_jitable
    def update(xi, aux, C, z):
        (a1, s1, m1, c1, t1), (a2, s2, m2, c2, t2) = C
        z1, z2, z3, z4 = z
        xi1 = xi - aux
        xi2 = aux
        integral = (m1 * xi1 + c1 * z1 + t1 * z2) + (m2 * xi2 + c2 * z3 + t2 * z4)
        new1 = a1 * xi1 + s1 * z1
        new2 = a2 * xi2 + s2 * z3
        return integral, new1 + new2, new2

    return NoiseKernel(init, load_aux, coefficients, no_scratch, draw, update, no_event, at_no_event)


def variance(D: float, tau1: float, tau2: float, weight: float) -> float:
    """The stationary variance <xi^2>."""
    return weight * D / (2.0 * tau1) + (1.0 - weight) * D / (2.0 * tau2)


TWO_OU = Noise(
    name=NAME,
    build=build,
    description="xi_1 + xi_2, two independent OU noises of correlation times tau1, tau2 "
                "sharing S(0) = D by weight (test only)",
    colored=False,
    parameters=(
        "D",
        Parameter("tau1", 1.0, "correlation time of the first component", low=0.0, low_open=True),
        Parameter("tau2", 10.0, "correlation time of the second component", low=0.0, low_open=True),
        Parameter("weight", 0.5, "share of S(0) = D carried by the first component", low=0.0, high=1.0),
    ),
)


def register() -> Noise:
    return noises.register(TWO_OU) if noises.get(NAME) is None else noises.get(NAME)  # type: ignore[return-value]


register()
