"""Drive the CPU kernels of a KernelSpec on raw arrays (for tests that look below the runner)."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np

from stochpend.engine import cpu, integrator
from stochpend.numerics import rng


def kernels(noise="ou", potential="pendulum", coupling="force", *, adaptive=True, fast_math=False):
    """``cpu.kernels`` of the KernelSpec with these names; the lock-step driver when ``fast_math``."""
    return cpu.kernels(integrator.spec(noise, potential, coupling, adaptive=adaptive,
                                       fast_math=fast_math))


def record(kern, D=1.0, tau=1.0, W=0.0):
    """The noise record of ``kern``'s KernelSpec (``Noise.record``) for these D, tau and W; without a
    KernelSpec, the triple (D, tau, W)."""
    spec = getattr(kern, "spec", None)
    if spec is None:
        return (float(D), float(tau), float(W))
    return spec.noise.record(SimpleNamespace(D=D, tau=tau, omega_noise=W))


class Paths:
    """The state arrays of n paths: x, Omega, xi, xi_aux, t, t_comp, k, status."""

    def __init__(self, n: int):
        self.x, self.Omega, self.xi, self.xi_aux, self.t, self.t_comp = (np.zeros(n) for _ in range(6))
        self.k = np.zeros(n, dtype=np.uint64)
        self.status = np.zeros(n, dtype=np.uint8)

    def arrays(self):
        return (self.x, self.Omega, self.xi, self.xi_aux, self.t, self.t_comp, self.k, self.status)

    def init(self, kern, seed, *, path0=0, theta0=None, Omega0=0.0, xi0=None, D=1.0, tau=1.0, W=0.0):
        key0, key1 = rng.seed_to_key(seed)
        kern.init(self.arrays(), key0, key1, path0, 0.0 if theta0 is None else theta0,
                  theta0 is None, Omega0, 0.0 if xi0 is None else xi0, xi0 is None,
                  record(kern, D, tau, W))
        return self

    def advance(self, kern, t_target, max_steps, seed, *, path0=0, D=1.0, tau=1.0, W=0.0,
                omega2=1.0, n=2, h_max=0.05, step_c=0.0):
        key0, key1 = rng.seed_to_key(seed)
        # n: the power family's n, or the oscillator's whole record q (Oscillator.record)
        q = tuple(float(v) for v in n) if isinstance(n, tuple) else (float(n),)
        run = (float(omega2), q, float(h_max), float(step_c))
        return kern.advance(self.arrays(), t_target, max_steps, key0, key1, path0,
                            record(kern, D, tau, W), run)
