"""Initial conditions drawn from the Boltzmann law, P(x, Omega) ∝ exp(-E/T) (issue 23).

``initial_temperature=T`` (a parameter of :data:`stochpend.model.dynamics.FAMILY`: the API keyword,
``--param initial_temperature=T``, a sweep key) starts every path from the Boltzmann law of the
run's oscillator at temperature T, E = Omega^2/2 + omega^2 U(x), instead of ``theta0`` and
``Omega0``: Omega ~ N(0, T), and x

* for a periodic oscillator (the pendulum), by rejection from the uniform law on [-pi, pi):
  accept x with probability exp(-omega^2 (U(x) - min U)/T) (the acceptance rate is about
  sqrt(T/(2 pi omega^2)) at low T; exact whatever T);
* for the harmonic oscillator, x ~ N(0, T/omega^2) exactly;
* for the x**(2n) oscillators (``potential="power"``), exactly by inversion: with m = 2n,
  y = omega^2 |x|^m/(m T) has the Gamma(1/m, 1) law, so |x| = (m T y/omega^2)^(1/m) with
  y = P^-1(1/m, u) (the inverse regularized incomplete gamma function of a uniform u) and the
  sign from a second uniform.

Other oscillators (users' own) are refused in one line (their x has no bounded proposal here).
The numbers are Philox draws of their own (``rng.N_BOLTZMANN``: Omega from draw N_BOLTZMANN, x
from draws N_BOLTZMANN + 1 + j for attempt j; the power oscillators use draw N_BOLTZMANN + 1's
two uniforms), a function of (seed, path) alone, computed on the host in
float64 for every backend and for the bias estimate's pairs, so a run's paths start at the same
numbers wherever they run. With the damping and the additive noise on, T = D_a/(2 gamma) starts
the ensemble in its own stationary law (docs/family.md).
"""

from __future__ import annotations

import functools
import math
from typing import Any

import numba
import numpy as np

from stochpend.model import dynamics
from stochpend.numerics import rng
from stochpend.numerics._jitcache import own_index
from stochpend.numerics.mathlib import LIBM

__all__ = ["MAX_ATTEMPTS", "additive_states", "boltzmann", "check", "temperature"]

#: Rejection attempts per path before the path is given up as non-finite (NaN): at the lowest
#: acceptance rate a run can ask for (check), the chance of reaching it is below 1e-300.
MAX_ATTEMPTS = 100_000


def temperature(config: Any) -> float:
    """The run's ``initial_temperature`` (0: theta0 and Omega0 as given)."""
    return float(dynamics.value(getattr(config, "dyn_params", ()), "initial_temperature"))


def check(oscillator: Any, omega: float, T: float) -> None:
    """One-line ValueError where the Boltzmann law cannot be drawn: an oscillator other than a
    periodic one or the harmonic one, omega = 0 (no bound state), or a temperature so low that
    rejection would take more than about 1e4 attempts a path."""
    if T <= 0.0:
        return
    if not (oscillator.periodic or oscillator.name in ("harmonic", "power")):
        raise ValueError(f"initial_temperature={T!r} is not accepted for potential={oscillator.name!r}: the "
                         "Boltzmann law is drawn for the periodic oscillators, the harmonic one and the "
                         "x^(2n) ones")
    if omega <= 0.0:
        raise ValueError(f"initial_temperature={T!r} is not accepted with omega={omega!r}: at omega = 0 there "
                         "is no Boltzmann law in x (give omega > 0)")
    if oscillator.periodic and math.sqrt(T / (2 * math.pi * omega * omega)) < 1e-4:
        raise ValueError(f"initial_temperature={T!r} is not accepted: below about 6e-8 omega^2 the rejection "
                         "sampler would take more than 1e4 attempts a path")


@functools.cache
def _kernel(oscillator: Any):
    potential = oscillator.kernel(np.float64, LIBM).potential
    PERIODIC = oscillator.periodic
    POWER = oscillator.name == "power"
    two_pi = 2.0 * math.pi
    first = np.uint64(rng.N_BOLTZMANN)
    max_attempts = MAX_ATTEMPTS

    @numba.njit(nogil=True)
    def draw(x, Omega, key0, key1, path0, T, omega2, q, floor):  # pragma: no cover - compiled
        sigma = math.sqrt(T)
        for i in range(x.shape[0]):
            path = np.uint64(path0 + np.uint64(i))
            z, z2 = rng.draw_normals(key0, key1, path, first)
            Omega[i] = sigma * z
            if POWER:  # two uniforms, turned into x on the host (boltzmann): exact
                u, v = rng.draw_uniforms(key0, key1, path, first + np.uint64(1))
                x[i] = u if v < 0.5 else -u
                continue
            if not PERIODIC:  # the harmonic oscillator: exact
                x[i] = math.sqrt(T / omega2) * z2
                continue
            x[i] = math.nan
            for j in range(max_attempts):
                u, v = rng.draw_uniforms(key0, key1, path, first + np.uint64(1 + j))
                xi = two_pi * u - math.pi
                if v < math.exp(-omega2 * (potential(xi, q) - floor) / T):
                    x[i] = xi
                    break

    return draw


def boltzmann(config: Any, path0: int, n: int) -> tuple[np.ndarray, np.ndarray]:
    """(x, Omega) of global paths path0 .. path0 + n - 1 (path0 a uint64-sized integer: the bias
    pairs' start at 2**63) drawn from the Boltzmann law at the run's ``initial_temperature``."""
    from stochpend.model import oscillators

    oscillator = oscillators.get(config.potential)
    assert oscillator is not None, config.potential  # validated when the config was built
    T = temperature(config)
    q = oscillator.record(config)
    x = np.empty(n)
    Omega = np.empty(n)
    key0, key1 = rng.run_keys(config.seed).main
    omega2 = float(config.omega) ** 2
    _kernel(oscillator)(x, Omega, key0, key1, np.uint64(path0), T, omega2, q, float(oscillator.energy_floor(q)))
    if oscillator.name == "power":  # x holds +-u: |x| = (m T y/omega^2)^(1/m), y = P^-1(1/m, u)
        from scipy.special import gammaincinv

        m = 2 * int(q[0])
        y = gammaincinv(1.0 / m, np.abs(x))
        x = np.copysign(_root(m * T * y / omega2, 1.0 / m), x)
    return x, Omega


@numba.njit(nogil=True, cache=True)
@own_index("boltzmann-root")  # the code digest in its cache index, as every cached kernel
def _root(values, power):  # pragma: no cover - compiled
    """values ** power elementwise with the C library's pow, as the kernels call it: numpy's
    power loop differs in the last bit between AVX-512 and AVX2 machines (stochpend.numerics._hostmath)."""
    out = np.empty_like(values)
    for i in range(values.shape[0]):
        out[i] = values[i] ** power
    return out


@functools.cache
def _channel_init(noise: Any):
    """The generic additive channel's start for ``noise``: its own ``init`` (float64, the C
    library's math) over a range of paths, stationary, under the channel's key."""
    noise_init = noise.kernel(np.float64, LIBM).init

    @numba.njit(nogil=True)
    def draw(xa, aux, key0, key1, path0, p):  # pragma: no cover - compiled
        for i in range(xa.shape[0]):
            xa[i], aux[i] = noise_init(key0, key1, np.uint64(path0 + np.uint64(i)), p, 0.0, True)

    return draw


def additive_states(config: Any, path0: int, n: int) -> tuple[np.ndarray, ...]:
    """The additive channel's per-path arrays at t = 0 for global paths path0 .. path0 + n - 1,
    in the order of :func:`stochpend.model.dynamics.additive_arrays`: ``(xi_a, aux_a)`` for the
    channel of a coloured noise (``additive_tau`` > 0 or ``additive_noise``): its noise's
    stationary start (``init``), drawn under the channel's Philox key
    (:func:`stochpend.numerics.rng.additive_key`), on the host in float64 for every backend and for the
    bias pairs; ``()`` for any other run. Each array (n,) float64."""
    if not dynamics.additive_arrays(config):
        return ()
    noise = dynamics.channel(config)
    xa = np.zeros(n)
    aux = np.zeros(n)
    key0, key1 = rng.run_keys(config.seed).additive
    _channel_init(noise)(xa, aux, key0, key1, np.uint64(path0), dynamics.channel_record(config))
    return xa, aux
