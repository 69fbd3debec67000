"""A test-only noise, defined in this one file: a sinusoidal drive with a random phase.

    xi(t) = a cos(phi_0 + W t),  a = sqrt(D/tau),  phi_0 uniform on [0, 2 pi)

(the parametric drive of the Mathieu equation, with stationary variance a**2/2 = D/(2 tau) and
correlation D/(2 tau) cos(W s)). Its step is exact and needs no random number: the phase
advances by W h and the integral over the step is (a/W)(sin phi' - sin phi). ``aux`` holds the
phase. Nothing in stochpend knows of it: registering it here makes ``noise="phase-drive"``
work on every backend (tests/unit/test_new_noise.py, tests/unit/test_cuda_sim.py).
"""

from __future__ import annotations

import math

import numpy as np
from numba.extending import register_jitable

from stochpend import noises
from stochpend.noises.base import Noise, NoiseKernel, at_no_event, no_event, no_scratch
from stochpend.numerics import rng

NAME = "phase-drive"


def build(real, mathlib) -> NoiseKernel:
    zero = real(0.0)

    @register_jitable
    def init(key0, key1, path, p, xi0, stationary):
        D = p[0]
        tau = p[1]
        u, _ = rng.draw_uniforms(key0, key1, path, np.uint64(rng.N_INIT_XI))
        phase = 2.0 * math.pi * u
        return math.sqrt(D / tau) * math.cos(phase), phase

    @register_jitable
    def load_aux(a):
        return np.float64(a)  # a phase that grows like the time: kept in float64

    @register_jitable
    def coefficients(h, p):
        D = real(p[0])
        tau = real(p[1])
        W = real(p[2])
        a = math.sqrt(np.float64(D) / np.float64(tau))
        return np.float64(W) * np.float64(h), a / np.float64(W), a

    @register_jitable
    def draw(key0, key1, path, k, S):
        return (zero,), S

    @register_jitable
    def update(xi, phase, C, z):
        dphi, a_over_W, a = C
        new = phase + dphi
        return real(a_over_W * (math.sin(new) - math.sin(phase))), real(a * math.cos(new)), new

    return NoiseKernel(init, load_aux, coefficients, no_scratch, draw, update, no_event, at_no_event)


PHASE_DRIVE = Noise(
    name=NAME,
    build=build,
    description="a sqrt(D/tau) cos(phi_0 + W t) drive with a uniform random phase (test only)",
    colored=True,
    uses_omega_noise=True,
    default_omega_noise=lambda tau: 1.0 / tau,
    parameters=("D", "tau", "omega_noise"),
    variance=lambda D, tau, W: D / (2.0 * tau),
    correlation=lambda s, D, tau, W: D / (2.0 * tau) * np.cos(W * np.asarray(s, dtype=float)),
)


def register() -> Noise:
    return noises.register(PHASE_DRIVE) if noises.get(NAME) is None else noises.get(NAME)
