"""Plain NumPy of stochpend's fixed-step OU scheme, vectorized over paths, as a user would write it.

One step of length h (schemes.py): the exact OU update of (xi, integral of xi over the step)
from two standard normals, then the drift-kick-drift (position Stormer-Verlet) step with the
angle wrapped to [-pi, pi). The time bookkeeping is stochpend's: the last step lands exactly on
t_max (a step ending within 1e-6 h of it is stretched), t += h with Kahan compensation.

Two sources of normals:

* ``rng="numpy"`` (the benchmark): NumPy's own ``default_rng(seed)`` (PCG64, ziggurat
  normals), what a NumPy user would use. Statistically equivalent to stochpend, not the same
  numbers.
* ``rng="philox"``: Philox4x32-10 vectorized in NumPy with stochpend's counter convention
  (rng.py), so each path gets exactly stochpend's numbers and the final states agree to
  round-off (NumPy's SIMD log/sin/cos differ from glibc's by an ulp or so). Slow (ten rounds of
  uint64 array arithmetic per step); used by the smoke test.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass

import numpy as np

_M0 = np.uint64(0xD2511F53)
_M1 = np.uint64(0xCD9E8D57)
_W0 = 0x9E3779B9
_W1 = 0xBB67AE85
_MASK = np.uint64(0xFFFFFFFF)
_S32 = np.uint64(32)


def philox4x32_10(c0, c1, c2, c3, k0: int, k1: int):
    """Philox4x32-10 on uint64 arrays holding 32-bit words; scalar key (Python ints)."""
    for r in range(10):
        kk0 = np.uint64((k0 + r * _W0) & 0xFFFFFFFF)
        kk1 = np.uint64((k1 + r * _W1) & 0xFFFFFFFF)
        p0 = _M0 * c0
        p1 = _M1 * c2
        c0, c1, c2, c3 = (p1 >> _S32) ^ c1 ^ kk0, p1 & _MASK, (p0 >> _S32) ^ c3 ^ kk1, p0 & _MASK
    return c0, c1, c2, c3


def _uniform_open(a, b):
    """rng.uniform_open on arrays: (k + 1/2) / 2**52, k the high 26 bits of a and of b."""
    k = (a >> np.uint64(6)).astype(np.float64) * 67108864.0 + (b >> np.uint64(6)).astype(np.float64)
    return (k + 0.5) * (1.0 / 4503599627370496.0)


class PhiloxNormals:
    """stochpend's Philox streams for paths 0..n-1: draw n gives two normals (or uniforms)."""

    def __init__(self, seed: int, paths: int):
        self.k0 = seed & 0xFFFFFFFF
        self.k1 = (seed >> 32) & 0xFFFFFFFF
        p = np.arange(paths, dtype=np.uint64)
        self.c2 = p & _MASK
        self.c3 = p >> _S32
        self.ones = np.ones(paths, dtype=np.uint64)

    def words(self, n: int):
        c0 = self.ones * np.uint64(n & 0xFFFFFFFF)
        c1 = self.ones * np.uint64(n >> 32)
        return philox4x32_10(c0, c1, self.c2, self.c3, self.k0, self.k1)

    def uniforms(self, n: int):
        r0, r1, r2, r3 = self.words(n)
        return _uniform_open(r0, r1), _uniform_open(r2, r3)

    def normals(self, n: int):
        u1, u2 = self.uniforms(n)
        r = np.sqrt(-2.0 * np.log(u1))
        phase = 2.0 * math.pi * u2
        return r * np.cos(phase), r * np.sin(phase)


_TANH_SERIES = (
    1.0 / 12.0, -1.0 / 120.0, 17.0 / 20160.0, -31.0 / 362880.0, 691.0 / 79833600.0,
    -5461.0 / 6227020800.0, 929569.0 / 10461394944000.0, -3202291.0 / 355687428096000.0,
    221930581.0 / 243290200817664000.0, -4722116521.0 / 51090942171709440000.0,
    56963745931.0 / 6082827467972935680000.0, -14717667114151.0 / 15511210043330985984000000.0,
)


def ou_coefficients(h: float, D: float, tau: float):
    """The exact OU update over a step h (schemes.ou_step_coefficients, in plain Python)."""
    x = h / tau
    b = -math.expm1(-x)
    a = 1.0 - b
    s_xi = math.sqrt(D * b * (2.0 - b) / (2.0 * tau))
    c_I = 0.5 * D * b * b / s_xi
    if x < 0.6:  # x - 2 tanh(x/2) by its Taylor series, free of cancellation
        x2 = x * x
        acc = 0.0
        for c in reversed(_TANH_SERIES):
            acc = acc * x2 + c
        r = acc * x * x2
    else:
        r = x - 2.0 * math.tanh(0.5 * x)
    s_I = math.sqrt(D * tau * r)
    return a, s_xi, tau * b, c_I, s_I


@dataclass
class Result:
    theta: np.ndarray
    Omega: np.ndarray
    xi: np.ndarray
    steps: int
    seconds: float

    def energy(self, omega: float) -> np.ndarray:
        return 0.5 * self.Omega**2 - omega**2 * np.cos(self.theta)


def simulate(paths: int, t_max: float, h: float, *, D: float = 1.0, tau: float = 1.0,
             omega: float = 1.0, seed: int = 0, rng: str = "numpy") -> Result:
    """Fixed-step ensemble from uniform theta0, Omega0 = 0 and stationary xi0 to t_max."""
    t0 = time.perf_counter()
    if rng == "philox":
        streams = PhiloxNormals(seed, paths)
        u, _ = streams.uniforms(0)
        theta = 2.0 * math.pi * u - math.pi
        z, _ = streams.normals(1)

        def normals(k):
            return streams.normals(k + 2)
    elif rng == "numpy":
        gen = np.random.default_rng(seed)
        theta = gen.uniform(-math.pi, math.pi, paths)
        z = gen.standard_normal(paths)

        def normals(k):
            zz = gen.standard_normal((2, paths))
            return zz[0], zz[1]
    else:
        raise ValueError(f"rng={rng!r} is not accepted: 'numpy' or 'philox'")
    xi = math.sqrt(D / (2.0 * tau)) * z
    Omega = np.zeros(paths)
    omega2 = omega * omega

    t = 0.0
    t_comp = 0.0
    k = 0
    h_cached = None
    while True:
        step = h
        last = t + step * (1.0 + 1e-6) >= t_max  # a step ending within 1e-6 h of t_max lands on it
        if last:
            step = t_max - t
        if step != h_cached:
            a, s_xi, m_I, c_I, s_I = ou_coefficients(step, D, tau)
            h_cached = step
        z1, z2 = normals(k)
        noise_integral = m_I * xi + c_I * z1 + s_I * z2
        xi = a * xi + s_xi * z1
        theta_half = theta + 0.5 * step * Omega
        s = np.sin(theta_half)
        Omega = Omega - (omega2 * step * s + noise_integral * s)
        theta = theta_half + 0.5 * step * Omega
        theta = theta - 2.0 * math.pi * np.floor((theta + math.pi) / (2.0 * math.pi))
        k += 1
        if last:
            break
        y = step - t_comp  # Kahan-compensated t += h, as stochpend
        t_new = t + y
        t_comp = (t_new - t) - y
        t = t_new
    return Result(theta, Omega, xi, k, time.perf_counter() - t0)
