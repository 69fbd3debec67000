r"""The reduced (averaged) dynamics of Mallick & Marcq (2004) as ensembles.

``simulate_reduced(order, ...)`` returns an ``xarray.Dataset`` in the format of
:func:`stochpend.simulate` (same variable names, jackknife errors, histogram), for the
effective energy equations obtained by averaging over the fast angle:

``"zeroth"`` -- Eq. `average0`
    dOmega/dt = 0 and xi an OU process: the energy stays at ``E0`` (no random number is used;
    xi does not enter E).
``"first"`` -- Eqs. `average1`, `OUaverage1`
    dE_1 = sigma dW with sigma**2 = D/(2 tau**2) (eta_1 of amplitude D divided by sqrt(2) tau),
    on the half line E >= 0 by instantaneous reflection: ``E_t = |E0 + sigma W_t|``. Sampled
    EXACTLY at the output times from independent Gaussian increments of the free process
    (xi is independent of E_1 and is not simulated). From E0 = 0 the law is `PDFav1`.
``"second"`` -- Eqs. `average2`, `ZOU`
    dE_2 = -(omega**2 xi + xi**2)/(4 tau E_2) dt + sigma dW_2, xi the OU process of `ZOU`.
    The drift is singular at E_2 = 0; the process is integrated in ``X = E_2**2`` (below).
``"asymptotic"`` -- Eq. `average2eta`
    dE = -D/(8 tau**2 E) dt + sigma dW: a Bessel process of dimension 1/2 (drift
    -sigma**2/(4E)), reflected at 0. Sampled EXACTLY: ``X = E**2`` is a squared Bessel process
    of dimension delta = 1/2 run at the clock sigma**2 t, whose transition law is a scaled
    non-central chi-square. From E0 = 0 the law is exactly `eq:pdfEcolor`.

Squared Bessel transitions
--------------------------
With ``dX = delta sigma**2 dt + 2 sigma sqrt(X) dW`` (Ito: for X = E**2 and
dE = (delta - 1) sigma**2/(2E) dt + sigma dW), over a time ``h`` and with ``s = sigma**2 h``:

* ``delta >= 0`` (reflected at 0 for 0 < delta < 2, absorbed for delta = 0):
  ``X_h = s chi'^2_delta(X_0/s) = 2 s Gamma(delta/2 + N)``, ``N ~ Poisson(X_0/(2 s))``;
* ``delta < 0`` (the drift pushes through 0; held at 0 by the Skorokhod reflection, i.e. the
  process absorbed at 0): with ``a = X_0/(2 s)`` and ``mu = 1 - delta/2``, draw
  ``G ~ Gamma(mu)``; if ``G >= a`` the process has hit 0 (``T_0 = X_0/(2 sigma**2 G)``) and
  ``X_h = 0``; otherwise ``X_h = 2 s Gamma(K + 1)``, ``K ~ Poisson(a - G)``. This is exact:
  integrating over G gives ``P(K = k, T_0 > h) = e^{-a} a^{k+mu}/Gamma(k + mu + 1)``, the
  series of the killed density ``(1/2s)(y/x)^{nu/2} e^{-(x+y)/2s} I_mu(sqrt(xy)/s)``,
  ``nu = delta/2 - 1``.

Second order: the treatment of E_2 = 0
--------------------------------------
In ``X = E_2**2`` the equation `average2` becomes
``dX = [sigma**2 - (omega**2 xi + xi**2)/(2 tau)] dt + 2 sigma sqrt(X) dW_2``: the drift is
no longer singular. Its value fluctuates with xi; its mean, sigma**2 - <xi**2>/(2 tau) =
sigma**2/2, is that of the dimension-1/2 process of `average2eta`. Where the instantaneous
drift is negative the process would cross 0; it is kept at X >= 0 by the Skorokhod
(minimal) reflection, i.e. held at 0 until the drift turns positive. Each step of length h
freezes the drift at its step average
``b = sigma**2 - (omega**2 I + J)/(2 tau h)``, with ``I`` the exact integral of xi over the
step (drawn jointly with xi_{n+1}, :func:`stochpend.noises.ou.step_coefficients`) and
``J = h (xi_n**2 + xi_{n+1}**2)/2`` (trapezoid; unbiased for stationary xi); the X step is
then the exact squared-Bessel transition of dimension ``delta = b/sigma**2`` above. The
error is the freezing of the drift within a step (O(h/tau)); E_2 never goes through 0 and no
step is singular. A path whose state becomes non-finite (or whose rejection sampler exceeds
its cap) gets status 1, is never advanced again and is counted in ``nonfinite_paths``, never
averaged.

Random numbers
--------------
Philox4x32-10 with key = seed (as the pendulum), counter ``(n, global path index)``. The
reduced dynamics use a DIFFERENT stream of the same key: every draw index has bit 62 set
(the pendulum uses n = 0, 1, 2 + step < 2**62)::

    n = 2**62 + code * 2**56 + block * 2**24 + m

``code`` = 1 (first), 2 (second), 3 (asymptotic), 4 (sampler tests); ``block`` = j + 1 for the
transition to output time j (first, asymptotic) or k + 1 for global step k (second; block 0
holds the initial xi); ``m`` numbers the draws inside a block (the rejection samplers take
successive m, at most 2**20 tries each). So every number depends on (seed, path, order,
time index or step) only: results do not depend on threads or chunks.

Energy statistics
-----------------
The Dataset has the variables of :func:`stochpend.simulate`. The reduced models have no
angle: ``mean_Omega2`` and ``mean_Omega4`` hold <2E> and <4E**2> (Omega**2 = 2E, exact for
omega = 0 and the theta-average at leading order for E >> omega**2), ``mean_sin2theta`` and
its error are NaN.
"""

from __future__ import annotations

import math
import platform
import time as _time
import warnings
from dataclasses import asdict, dataclass
from typing import Any

import numba
import numpy as np
import xarray as xr
from numba import prange
from numba.extending import register_jitable

from stochpend._version import __version__
from stochpend.model.noises import ou as _ou
from stochpend.model.observables import (
    N_SUMS,
    S_COUNT,
    S_NONFINITE,
    SUMS,
    TABLE_KEY,
    reduced_values_source,
)
from stochpend.model.power_sums import EnsembleSums
from stochpend.model.settings import DEFAULT_HIST_BINS, DEFAULT_N_BATCHES, SimulationConfig
from stochpend.numerics import _cputarget, rng
from stochpend.numerics._jitcache import own_index
from stochpend.text._docs import documented

__all__ = [
    "ORDERS",
    "ReducedConfig",
    "besq_step",
    "gamma_sample",
    "ncx2_sample",
    "poisson_sample",
    "sample_reduced",
    "simulate_reduced",
    "draw_samples",
]

ORDERS = ("zeroth", "first", "second", "asymptotic")
EQUATIONS = {
    "zeroth": "average0",
    "first": "average1, OUaverage1 (law PDFav1)",
    "second": "average2, ZOU (LangeffZ)",
    "asymptotic": "average2eta (law eq:pdfEcolor)",
}
CODE_FIRST = 1
CODE_SECOND = 2
CODE_ASYMPTOTIC = 3
CODE_TEST = 4

#: Second-order step, as a fraction of tau, when ``h_max`` is not given.
DEFAULT_H_OVER_TAU = 0.05
#: Paths advanced together (bounded memory).
DEFAULT_CHUNK_PATHS = 1 << 18
#: Largest number of tries of one rejection sampler (never reached in practice).
MAX_TRIES = 1 << 20

_U64 = np.uint64
_TAG = np.uint64(1 << 62)
_CODE_SHIFT = np.uint64(56)
_BLOCK_SHIFT = np.uint64(24)
_TWO_POW_M32 = 1.0 / 4294967296.0
_TWO_PI = 2.0 * math.pi
_HALF_LOG_TWO_PI = 0.5 * math.log(2.0 * math.pi)
_ONE_THIRD = 1.0 / 3.0

# how the state is turned into E by the accumulator
_AS_IS, _ABS, _SQRT = 0, 1, 2


# ---------------------------------------------------------------------------------------------
# Scalar samplers (register_jitable: compiled into the kernels, callable from Python)
# ---------------------------------------------------------------------------------------------


@register_jitable
def draw_base(code, block):
    """First draw index of ``block`` of the stream ``code`` (see the module docstring)."""
    return _TAG + (_U64(code) << _CODE_SHIFT) + (_U64(block) << _BLOCK_SHIFT)


@register_jitable
def normal_uniform(key0, key1, path, n):
    """A standard normal and an independent uniform on (0, 1) from ONE Philox draw.

    The normal is the cosine branch of Box-Muller with a 52-bit radius uniform (words 0, 1)
    and a 32-bit phase (word 2); the uniform is word 3, ``(r3 + 1/2)/2**32``.
    """
    r0, r1, r2, r3 = rng.draw_words(key0, key1, path, n)
    u1 = rng.uniform_open(r0, r1)
    phase = (float(r2) + 0.5) * _TWO_POW_M32
    u = (float(r3) + 0.5) * _TWO_POW_M32
    return math.sqrt(-2.0 * math.log(u1)) * math.cos(_TWO_PI * phase), u


@register_jitable
def gamma_sample(alpha, key0, key1, path, n):
    """Gamma(alpha, 1) by Marsaglia & Tsang (2000); returns ``(value, next draw index)``.

    ``alpha <= 0`` gives 0 (the point mass of shape 0). For ``alpha < 1`` the boost
    ``Gamma(alpha) = Gamma(alpha + 1) U**(1/alpha)`` uses one uniform (draw ``n``). Each try
    uses one draw (:func:`normal_uniform`); tries take successive draw indices, so the value is
    a function of ``(key, path, n)``. NaN after ``MAX_TRIES`` tries (never in practice).
    """
    if alpha <= 0.0:
        return 0.0, n
    log_boost = 0.0
    if alpha < 1.0:
        ub, _ = rng.draw_uniforms(key0, key1, path, n)
        n += _U64(1)
        log_boost = math.log(ub) / alpha
        alpha += 1.0
    d = alpha - _ONE_THIRD
    c = 1.0 / math.sqrt(9.0 * d)
    for _ in range(MAX_TRIES):
        z, u = normal_uniform(key0, key1, path, n)
        n += _U64(1)
        v = 1.0 + c * z
        if v <= 0.0:
            continue
        v = v * v * v
        z2 = z * z
        if u < 1.0 - 0.0331 * z2 * z2 or math.log(u) < 0.5 * z2 + d - d * v + d * math.log(v):
            return d * v * math.exp(log_boost), n
    return math.nan, n


@register_jitable
def _stirlerr(k):
    """log(k!) - [(k + 1/2) log k - k + log(2 pi)/2], for k >= 10 (error < 1e-12)."""
    r = 1.0 / k
    r2 = r * r
    return r * (1.0 / 12.0 - r2 * (1.0 / 360.0 - r2 * (1.0 / 1260.0 - r2 / 1680.0)))


@register_jitable
def log_poisson_pmf(k, lam):
    """log P(N = k) for N ~ Poisson(lam), without cancellation for large lam and k."""
    if k < 10.0:
        return -lam + k * math.log(lam) - math.lgamma(k + 1.0)
    r = (lam - k) / k
    if abs(r) < 0.5:  # near the mode: k log(lam/k) + k - lam = k (log1p(r) - r), no cancellation
        main = k * (math.log1p(r) - r)
    else:
        main = k * math.log(lam / k) + (k - lam)
    return main - 0.5 * math.log(k) - _HALF_LOG_TWO_PI - _stirlerr(k)


@register_jitable
def poisson_sample(lam, key0, key1, path, n):
    """Poisson(lam) as a float; returns ``(value, next draw index)``.

    ``lam < 10``: inversion by sequential search (one uniform). ``lam >= 10``: the transformed
    rejection PTRS of Hormann (1993), two uniforms (one draw) per try, with the log-pmf
    evaluated without cancellation (:func:`log_poisson_pmf`), so any finite lam works.
    """
    if not lam > 0.0:
        return 0.0, n
    if lam < 10.0:
        u, _ = rng.draw_uniforms(key0, key1, path, n)
        n += _U64(1)
        k = 0.0
        p = math.exp(-lam)
        cdf = p
        while u > cdf:
            k += 1.0
            p *= lam / k
            if p <= 1e-18 * cdf and k > lam:  # round-off: u beyond the computable cdf
                break
            cdf += p
        return k, n
    slam = math.sqrt(lam)
    b = 0.931 + 2.53 * slam
    a = -0.059 + 0.02483 * b
    log_invalpha = math.log(1.1239 + 1.1328 / (b - 3.4))
    vr = 0.9277 - 3.6224 / (b - 2.0)
    for _ in range(MAX_TRIES):
        u, v = rng.draw_uniforms(key0, key1, path, n)
        n += _U64(1)
        u -= 0.5
        us = 0.5 - abs(u)
        k = np.floor((2.0 * a / us + b) * u + lam + 0.43)
        if us >= 0.07 and v <= vr:
            return k, n
        if k < 0.0 or (us < 0.013 and v > us):
            continue
        if math.log(v) + log_invalpha - math.log(a / (us * us) + b) <= log_poisson_pmf(k, lam):
            return k, n
    return math.nan, n


@register_jitable
def ncx2_sample(df, nc, key0, key1, path, n):
    """Non-central chi-square (df >= 0, nc >= 0): ``2 Gamma(df/2 + N)``, N ~ Poisson(nc/2)."""
    N, n = poisson_sample(0.5 * nc, key0, key1, path, n)
    g, n = gamma_sample(0.5 * df + N, key0, key1, path, n)
    return 2.0 * g, n


@register_jitable
def besq_step(x, delta, s, key0, key1, path, n):
    """Exact step of ``dX = delta sigma**2 dt + 2 sigma sqrt(X) dW`` over h, ``s = sigma**2 h``.

    ``delta >= 0``: reflected (absorbed for delta = 0) squared Bessel process,
    ``X_h = s chi'^2_delta(x/s)``. ``delta < 0``: absorbed at 0 (held there by the Skorokhod
    reflection): ``G ~ Gamma(1 - delta/2)``; ``X_h = 0`` if ``G >= x/(2s)``, else
    ``2 s Gamma(K + 1)`` with ``K ~ Poisson(x/(2s) - G)``. Returns ``(X_h, next draw index)``.
    """
    a = 0.5 * x / s
    if delta >= 0.0:
        N, n = poisson_sample(a, key0, key1, path, n)
        g, n = gamma_sample(0.5 * delta + N, key0, key1, path, n)
        return 2.0 * s * g, n
    if not a > 0.0:
        return 0.0, n
    G, n = gamma_sample(1.0 - 0.5 * delta, key0, key1, path, n)
    if G >= a:
        return 0.0, n
    K, n = poisson_sample(a - G, key0, key1, path, n)
    g, n = gamma_sample(K + 1.0, key0, key1, path, n)
    return 2.0 * s * g, n


# ---------------------------------------------------------------------------------------------
# Kernels
# ---------------------------------------------------------------------------------------------


@numba.njit(parallel=True, cache=True)
@own_index("reduced")
def _advance_first(Y, status, sd, key0, key1, path0, block):  # pragma: no cover - compiled
    """Free Wiener process Y += sd z (E = |Y| is the reflected one); one draw per transition."""
    for i in prange(Y.shape[0]):
        if status[i] != 0:
            continue
        z, _ = rng.draw_normals(key0, key1, _U64(path0 + i), draw_base(CODE_FIRST, block))
        y = Y[i] + sd * z
        if math.isfinite(y):
            Y[i] = y
        else:
            status[i] = 1


@numba.njit(parallel=True, cache=True)
@own_index("reduced")
def _advance_besq(X, status, delta, s, code, key0, key1, path0, block):  # pragma: no cover
    """Exact squared-Bessel transition of every path over one output interval."""
    for i in prange(X.shape[0]):
        if status[i] != 0:
            continue
        x, _ = besq_step(X[i], delta, s, key0, key1, _U64(path0 + i), draw_base(code, block))
        if math.isfinite(x):
            X[i] = x
        else:
            status[i] = 1


@numba.njit(parallel=True, cache=True)
@own_index("reduced")
def _init_xi(xi, key0, key1, path0, stationary, xi0, sd_stationary):  # pragma: no cover
    """Initial OU noise of the second-order model (block 0 of its stream)."""
    for i in prange(xi.shape[0]):
        if stationary:
            z, _ = rng.draw_normals(key0, key1, _U64(path0 + i), draw_base(CODE_SECOND, 0))
            xi[i] = sd_stationary * z
        else:
            xi[i] = xi0


@numba.njit(parallel=True, cache=True)
@own_index("reduced")
def _advance_second(X, xi, status, n_steps, h, k0, sigma2, tau, omega2, a, s_xi, m_I, c_I, s_I,
                    key0, key1, path0):  # pragma: no cover - compiled
    """``n_steps`` steps of length h of the second-order model in X = E_2**2 (module doc).

    Step k (global index k0 + q) uses block k + 1: draw 0 is the OU pair (xi_{n+1}, I), the
    squared-Bessel samplers take draws 1, 2, ... of the block.
    """
    inv = 1.0 / (2.0 * tau * h)
    s = sigma2 * h
    for i in prange(X.shape[0]):
        if status[i] != 0:
            continue
        path = _U64(path0 + i)
        x = X[i]
        xn = xi[i]
        bad = False
        for q in range(n_steps):
            base = draw_base(CODE_SECOND, k0 + q + 1)
            z1, z2 = rng.draw_normals(key0, key1, path, base)
            integral = m_I * xn + c_I * z1 + s_I * z2
            xn1 = a * xn + s_xi * z1
            b = sigma2 - (omega2 * integral + 0.5 * h * (xn * xn + xn1 * xn1)) * inv
            x, _ = besq_step(x, b / sigma2, s, key0, key1, path, base + _U64(1))
            xn = xn1
            if not (math.isfinite(x) and math.isfinite(xn)):
                bad = True
                break
        X[i] = x
        xi[i] = xn
        if bad:
            status[i] = 1


def _reduced_values():
    """``reduced_values(E)``: the summed values of a path of the averaged dynamics, generated
    from the statistics table (:func:`stochpend.observables.reduced_values_source`)."""
    namespace: dict = {}
    exec(compile(reduced_values_source(), f"<stochpend.observables {TABLE_KEY}>", "exec"), namespace)
    function = namespace["reduced_values"]
    function.__module__ = __name__
    return numba.njit(function)


_values = _reduced_values()
_N_VALUES = len(SUMS)


@numba.njit(parallel=True, cache=True)
@own_index(f"reduced/{TABLE_KEY}")
def _accumulate(state, status, transform, batch_size, edges, sums, hist):  # pragma: no cover
    """Per-batch power sums of E (and Omega**2 = 2E) and the E histogram at one output time.

    Each batch is summed sequentially in path order (results do not depend on threads), as in
    :func:`stochpend.engine.cpu.accumulate_batches`; same columns and histogram layout.
    """
    n_paths = state.shape[0]
    n_edges = edges.shape[0]
    for b in prange(sums.shape[0]):
        for c in range(sums.shape[1]):
            sums[b, c] = 0.0
        for c in range(hist.shape[1]):
            hist[b, c] = 0
        start = b * batch_size
        stop = min(start + batch_size, n_paths)
        for i in range(start, stop):
            v = state[i]
            if transform == _ABS:
                E = abs(v)
            elif transform == _SQRT:
                E = math.sqrt(v)
            else:
                E = v
            if status[i] != 0 or not math.isfinite(E):
                sums[b, S_NONFINITE] += 1.0
                continue
            values = _values(E)
            sums[b, S_COUNT] += 1.0
            for c in range(_N_VALUES):
                sums[b, 1 + c] += values[c]
            if E < edges[0]:
                hist[b, 0] += 1
            elif E >= edges[n_edges - 1]:
                hist[b, n_edges] += 1
            else:
                hist[b, np.searchsorted(edges, E, side="right")] += 1


@numba.njit(parallel=True, cache=True)
@own_index("reduced")
def _sampler_draws(kind, p1, p2, p3, count, key0, key1):  # pragma: no cover - compiled
    """``count`` independent draws of a sampler (paths 0..count-1, stream CODE_TEST)."""
    out = np.empty(count)
    for i in prange(count):
        path = _U64(i)
        n = draw_base(CODE_TEST, 0)
        if kind == 0:
            v, _ = gamma_sample(p1, key0, key1, path, n)
        elif kind == 1:
            v, _ = poisson_sample(p1, key0, key1, path, n)
        elif kind == 2:
            v, _ = ncx2_sample(p1, p2, key0, key1, path, n)
        else:
            v, _ = besq_step(p1, p2, p3, key0, key1, path, n)
        out[i] = v
    return out


def draw_samples(kind: str, *params: float, count: int, seed: int = 0) -> np.ndarray:
    """Independent draws of one scalar sampler, for tests.

    ``kind``: ``"gamma"`` (alpha), ``"poisson"`` (lam), ``"ncx2"`` (df, nc) or ``"besq"``
    (x, delta, s: one :func:`besq_step`).
    """
    kinds = ("gamma", "poisson", "ncx2", "besq")
    if kind not in kinds:
        raise ValueError(f"kind={kind!r} is not accepted: one of {', '.join(kinds)}")
    p = [float(v) for v in params] + [0.0] * (3 - len(params))
    key0, key1 = rng.run_keys(seed).main
    return _sampler_draws(kinds.index(kind), p[0], p[1], p[2], int(count), key0, key1)


# ---------------------------------------------------------------------------------------------
# Configuration and driver
# ---------------------------------------------------------------------------------------------


def _fail(name: str, value: Any, accepted: str) -> None:
    raise ValueError(f"{name}={value!r} is not accepted: {accepted}")


@dataclass(frozen=True)
class ReducedConfig:
    """A validated reduced-dynamics run (build with :meth:`build`)."""

    order: str
    D: float
    tau: float
    omega: float
    paths: int
    t_max: float
    times: tuple[float, ...]
    seed: int
    E0: float
    xi0: float | None  # None: stationary
    h_max: float
    hist_bins: int
    hist_E_max: tuple[float, ...]
    n_batches: int

    @property
    def batch_size(self) -> int:
        return -(-self.paths // self.n_batches)

    @property
    def sigma2(self) -> float:
        """Diffusion coefficient of E: sigma**2 = D/(2 tau**2)."""
        return self.D / (2.0 * self.tau**2)

    def steps(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Second order: per output interval, the number of steps, their length, first index."""
        t = np.asarray(self.times)
        dt = np.diff(np.concatenate([[0.0], t]))
        n = np.where(dt > 0, np.ceil(dt / self.h_max * (1.0 - 1e-12)), 0).astype(np.int64)
        n = np.where(dt > 0, np.maximum(n, 1), 0)
        h = np.where(n > 0, dt / np.maximum(n, 1), 0.0)
        k0 = np.concatenate([[0], np.cumsum(n)[:-1]]).astype(np.int64)
        return n, h, k0

    def to_attrs(self) -> dict[str, Any]:
        d = asdict(self)
        d.pop("times")
        d.pop("hist_E_max")
        d["xi0"] = "stationary" if self.xi0 is None else self.xi0
        return d

    @classmethod
    def build(
        cls,
        order: str,
        *,
        D: float,
        tau: float,
        omega: float = 1.0,
        paths: int = 10_000,
        t_max: float = 1000.0,
        times: Any = None,
        n_times: int = 40,
        seed: int = 0,
        E0: float = 0.0,
        xi0: float | str = "stationary",
        h_max: float | None = None,
        hist_bins: int = DEFAULT_HIST_BINS,
        hist_E_max: Any = None,
        n_batches: int = DEFAULT_N_BATCHES,
    ) -> ReducedConfig:
        """Validate every argument (one-line ValueError naming the parameter)."""
        if not isinstance(order, str) or order not in ORDERS:
            _fail("order", order, f"one of {', '.join(ORDERS)}")
        # the parameters shared with the simulator are checked by its validator
        base = SimulationConfig.build(
            noise="ou", D=D, tau=tau, omega=omega, paths=paths, t_max=t_max, times=times,
            n_times=n_times, seed=seed, xi0=xi0, hist_bins=hist_bins, n_batches=n_batches,
            hist_E_max=1.0,
        )
        if base.D <= 0:
            _fail("D", D, "D must be a finite number > 0 (the noise amplitude of the reduced dynamics)")
        try:
            E0_v = float(E0)
        except (TypeError, ValueError):
            E0_v = math.nan
        if isinstance(E0, bool) or not math.isfinite(E0_v) or E0_v < 0:
            _fail("E0", E0, "E0 must be a finite number >= 0 (the initial energy; E >= 0 in the reduced dynamics)")
        assert base.tau is not None
        if h_max is None:
            h = DEFAULT_H_OVER_TAU * base.tau
        else:
            try:
                h = float(h_max)
            except (TypeError, ValueError):
                h = math.nan
            if isinstance(h_max, bool) or not math.isfinite(h) or h <= 0:
                _fail("h_max", h_max, "h_max must be a finite number > 0 (the second-order time step)")
        grid = np.asarray(base.times)
        if hist_E_max is None:
            e_max = default_hist_E_max(grid, D=base.D, tau=base.tau, omega=base.omega, E0=E0_v)
        else:
            try:
                e_max = np.broadcast_to(np.asarray(hist_E_max, dtype=np.float64), grid.shape).copy()
            except (TypeError, ValueError):
                _fail("hist_E_max", hist_E_max, "hist_E_max must be a number > 0 or one per output time")
            if not np.all(np.isfinite(e_max)) or np.any(e_max <= 0):
                _fail("hist_E_max", hist_E_max, "hist_E_max must be finite and > 0")
        cfg = cls(
            order=order, D=base.D, tau=base.tau, omega=base.omega, paths=base.paths,
            t_max=base.t_max, times=base.times, seed=base.seed, E0=E0_v, xi0=base.xi0, h_max=h,
            hist_bins=base.hist_bins, hist_E_max=tuple(float(v) for v in e_max),
            n_batches=base.n_batches,
        )
        if order == "second":
            n, _, _ = cfg.steps()
            if int(n.sum()) >= 2**32 - 1:
                _fail("h_max", h_max, f"h_max must give fewer than 2**32 steps up to t_max={base.t_max}")
        return cfg


def default_hist_E_max(times: np.ndarray, *, D: float, tau: float, omega: float, E0: float) -> np.ndarray:
    """Upper histogram edge: far in the tail of the reduced laws (scale (D t/tau**2)**(1/2),
    plus the early omega**2 xi contribution of the second order, (omega**4 D t/tau**2)**(1/4))."""
    t = np.asarray(times, dtype=np.float64)
    # (D t)^(1/4) as two square roots: the same bits on every machine (stochpend.numerics._hostmath)
    scale = np.sqrt(D * t) / tau + omega * np.sqrt(np.sqrt(D * t)) / math.sqrt(tau)
    return E0 + 1.0 + 12.0 * scale


def hist_edges(config: ReducedConfig) -> np.ndarray:
    """Bin edges, shape (n_times, hist_bins + 1), uniform in sqrt(E) on [0, hist_E_max]."""
    u = np.linspace(0.0, 1.0, config.hist_bins + 1) ** 2
    return np.asarray(config.hist_E_max)[:, None] * u[None, :]


def _run_chunk(config: ReducedConfig, p0: int, n: int, sums: np.ndarray | None,
               hist: np.ndarray | None, edges: np.ndarray) -> tuple[np.ndarray, np.ndarray, int]:
    """Paths p0 .. p0 + n - 1: advance through every output time, accumulating the sums of
    their batches into ``sums[:, j]`` and ``hist[j]`` (when given). Returns the final state
    (as E), the status and the number of path-steps."""
    key0, key1 = rng.run_keys(config.seed).main
    times = np.asarray(config.times)
    bs = config.batch_size
    nb = -(-n // bs)
    status = np.zeros(n, dtype=np.uint8)
    xi = np.zeros(0)
    order = config.order
    if order == "zeroth":
        state = np.full(n, config.E0)
        transform = _AS_IS
    elif order == "first":
        state = np.full(n, config.E0)
        transform = _ABS
    else:
        state = np.full(n, config.E0**2)
        transform = _SQRT
    if order == "second":
        xi = np.empty(n)
        _init_xi(xi, key0, key1, p0, config.xi0 is None, 0.0 if config.xi0 is None else config.xi0,
                 math.sqrt(config.D / (2.0 * config.tau)))
        n_steps, h_steps, k0_steps = config.steps()
    batch_sums = np.empty((nb, N_SUMS))
    batch_hist = np.empty((nb, config.hist_bins + 2), dtype=np.int64)
    sigma2 = config.sigma2
    path_steps = 0
    t_prev = 0.0
    for j, t in enumerate(times):
        dt = float(t) - t_prev
        t_prev = float(t)
        if dt > 0:
            if order == "first":
                _advance_first(state, status, math.sqrt(sigma2 * dt), key0, key1, p0, j + 1)
                path_steps += n
            elif order == "asymptotic":
                _advance_besq(state, status, 0.5, sigma2 * dt, CODE_ASYMPTOTIC, key0, key1, p0, j + 1)
                path_steps += n
            elif order == "second":
                h = float(h_steps[j])
                a, s_xi, m_I, c_I, s_I = _ou.step_coefficients(h, (config.D, config.tau))
                _advance_second(state, xi, status, int(n_steps[j]), h, int(k0_steps[j]), sigma2,
                                config.tau, config.omega**2, a, s_xi, m_I, c_I, s_I, key0, key1, p0)
                path_steps += n * int(n_steps[j])
        if sums is not None and hist is not None:
            _accumulate(state, status, transform, bs, edges[j], batch_sums, batch_hist)
            sums[:, j, :] = batch_sums
            hist[j] += batch_hist.sum(axis=0)
    if transform == _ABS:
        E = np.abs(state)
    elif transform == _SQRT:
        E = np.sqrt(state)
    else:
        E = state.copy()
    E[status != 0] = np.nan
    return E, status, path_steps


def _with_threads(threads: int | None):
    if threads is not None and (isinstance(threads, bool) or not isinstance(threads, int) or threads < 1
                                or threads > numba.config.NUMBA_NUM_THREADS):
        raise ValueError(
            f"threads={threads!r} is not accepted: an integer in [1, {numba.config.NUMBA_NUM_THREADS}]"
        )
    return threads


def _chunk_batches(config: ReducedConfig, chunk_paths: int | None) -> int:
    if chunk_paths is not None and (isinstance(chunk_paths, bool) or not isinstance(chunk_paths, int)
                                    or chunk_paths < 1):
        raise ValueError(f"chunk_paths={chunk_paths!r} is not accepted: an integer >= 1")
    return max(1, (chunk_paths or DEFAULT_CHUNK_PATHS) // config.batch_size)


@documented  # help() shows the signature's defaults and the paper's equation numbers
def simulate_reduced(
    order: str,
    *,
    D: float,
    tau: float,
    omega: float = 1.0,
    paths: int = 10_000,
    t_max: float = 1000.0,
    times: Any = None,
    n_times: int = 40,
    seed: int = 0,
    E0: float = 0.0,
    xi0: float | str = "stationary",
    h_max: float | None = None,
    hist_bins: int = DEFAULT_HIST_BINS,
    hist_E_max: Any = None,
    n_batches: int = DEFAULT_N_BATCHES,
    threads: int | None = None,
    chunk_paths: int | None = None,
    max_path_steps: float | None = None,
) -> xr.Dataset:
    r"""Ensemble of the reduced (averaged) energy dynamics; Dataset as :func:`stochpend.simulate`.

    It runs its own loop, outside :mod:`stochpend.runs.lifecycle`, and has no bias estimate: reduced
    is exempt where its orders are sampled exactly; its weak-order-1 order would need the
    estimator's factor for that order (2, not 4/3) and coupled draws it does not have.

    Parameters
    ----------
    order : {"zeroth", "first", "second", "asymptotic"}
        Eq. `average0`; Eqs. `average1`/`OUaverage1` (exact reflected Wiener process);
        Eqs. `average2`/`ZOU` (time-stepped in X = E_2**2, module docstring); Eq.
        `average2eta` (exact squared-Bessel transitions).
    D : float
        OU noise amplitude, > 0 (E diffuses with sigma**2 = D/(2 tau**2)).
    tau : float
        OU correlation time, > 0.
    omega : float
        Pendulum frequency, >= 0 (enters the second order only).
    paths : int
        Number of realizations.
    t_max : float
        Final time, > 0.
    times : array_like, optional
        Output times in [0, t_max], strictly increasing; default ``n_times`` log-spaced times
        from t_max/1000 to t_max (as the simulator).
    n_times : int
        Number of default output times.
    seed : int
        Seed in [0, 2**64). The reduced dynamics use their own Philox stream (draw indices
        >= 2**62), independent of the pendulum's numbers for the same seed.
    E0 : float
        Initial energy, >= 0.
    xi0 : float or "stationary"
        Initial OU noise of the second order; default drawn from N(0, D/(2 tau)).
    h_max : float, optional
        Second-order step (<= h_max, equal steps landing on the output times); default
        0.05 tau. Ignored by the other orders (exact).
    hist_bins, hist_E_max, n_batches
        Histogram bins (uniform in sqrt(E) on [0, hist_E_max]), upper edge (default far in
        the tail), jackknife batches.
    threads, chunk_paths : int, optional
        CPU threads and paths held in memory at once; results do not depend on them.
    max_path_steps : float, optional
        Refuse, before any work, a run needing more than this many path-steps (paths x the
        steps of its order); default :data:`stochpend.runs.resources.DEFAULT_MAX_PATH_STEPS`,
        ``math.inf``: no limit (the command line's ``--max-path-steps``).

    Returns
    -------
    xarray.Dataset
        The variables of :func:`stochpend.simulate`; ``mean_Omega2``/``mean_Omega4`` are
        <2E>/<4E**2>, ``mean_sin2theta`` is NaN (no angle). Attributes: every parameter, the
        order and its equations, the random-number layout, versions, wall time.

    Raises
    ------
    ValueError
        A parameter outside its accepted range (one line naming it).
    """
    config = ReducedConfig.build(
        order, D=D, tau=tau, omega=omega, paths=paths, t_max=t_max, times=times, n_times=n_times,
        seed=seed, E0=E0, xi0=xi0, h_max=h_max, hist_bins=hist_bins, hist_E_max=hist_E_max,
        n_batches=n_batches,
    )
    threads = _with_threads(threads)
    chunk_batches = _chunk_batches(config, chunk_paths)
    from stochpend.runs import resources

    est = resources.check_reduced(config, chunk_paths=chunk_paths, max_path_steps=max_path_steps, threads=threads)
    previous = numba.get_num_threads()
    if threads is not None:
        numba.set_num_threads(threads)
    from stochpend.numerics import _calibration
    from stochpend.numerics._jitcache import CompileClock

    load = _calibration.current_load()  # the rate is stored as on an idle machine (later estimates)
    clock = CompileClock().__enter__()  # a first run's compiling is not its rate
    started = _time.perf_counter()
    n_times_ = len(config.times)
    edges = hist_edges(config)
    acc = EnsembleSums.empty(config.n_batches, n_times_, config.hist_bins)
    path_steps = 0
    try:
        bs = config.batch_size
        for b0 in range(0, config.n_batches, chunk_batches):
            b1 = min(b0 + chunk_batches, config.n_batches)
            p0 = b0 * bs
            n = min(b1 * bs, config.paths) - p0
            sums = np.zeros((b1 - b0, n_times_, N_SUMS))
            hist = np.zeros((n_times_, config.hist_bins + 2), dtype=np.int64)
            _, _, steps = _run_chunk(config, p0, n, sums, hist, edges)
            path_steps += steps
            acc.add_batches(b0, sums, hist)
    finally:
        numba.set_num_threads(previous)
        clock.__exit__(None, None, None)
    wall = _time.perf_counter() - started
    _calibration.record_rate(f"reduced-{config.order}", est.min_path_steps, wall - clock.seconds, threads or previous,
                             load=load)
    attrs = _provenance(config, threads=threads or previous, wall_time_s=wall, path_steps=path_steps)
    with warnings.catch_warnings():
        # zeroth order from E0 = 0: S and F are 0/0 = NaN in every batch (not an error)
        warnings.filterwarnings("ignore", message="Mean of empty slice", category=RuntimeWarning)
        ds = acc.to_dataset(np.asarray(config.times), edges, attrs)
    for undefined in (f"mean_{s.name}" for s in SUMS if s.reduced is None):  # a function of the angle
        ds[undefined] = ("time", np.full(n_times_, np.nan), {"long_name": "not defined: the reduced dynamics have no angle"})
        ds[f"{undefined}_stderr"] = ("time", np.full(n_times_, np.nan), {"long_name": "not defined"})
    ds["mean_Omega2"].attrs["long_name"] = "<2E>: Omega**2 = 2E (exact for omega = 0; theta-average for E >> omega**2)"
    ds["mean_Omega4"].attrs["long_name"] = "<4E**2>: Omega**4 = 4E**2 (exact for omega = 0; leading order for E >> omega**2)"
    return ds


def sample_reduced(
    order: str,
    *,
    D: float,
    tau: float,
    omega: float = 1.0,
    paths: int = 10_000,
    t_max: float = 1000.0,
    times: Any = None,
    n_times: int = 40,
    seed: int = 0,
    E0: float = 0.0,
    xi0: float | str = "stationary",
    h_max: float | None = None,
    threads: int | None = None,
    max_path_steps: float | None = None,
) -> np.ndarray:
    """Per-path energies at ``t_max`` (shape ``(paths,)``; NaN for non-finite paths).

    The same numbers as the last output time of :func:`simulate_reduced` with the same
    arguments (the second order and the chain of transitions depend on the output times).
    """
    config = ReducedConfig.build(
        order, D=D, tau=tau, omega=omega, paths=paths, t_max=t_max, times=times, n_times=n_times,
        seed=seed, E0=E0, xi0=xi0, h_max=h_max,
    )
    threads = _with_threads(threads)
    from stochpend.runs import resources

    resources.check_reduced(config, chunk_paths=DEFAULT_CHUNK_PATHS, max_path_steps=max_path_steps,
                            threads=threads, keep_energies=True)
    previous = numba.get_num_threads()
    if threads is not None:
        numba.set_num_threads(threads)
    try:
        out = np.empty(config.paths)
        step = DEFAULT_CHUNK_PATHS
        for p0 in range(0, config.paths, step):
            n = min(step, config.paths - p0)
            out[p0:p0 + n], _, _ = _run_chunk(config, p0, n, None, None, hist_edges(config))
    finally:
        numba.set_num_threads(previous)
    return out


def _provenance(config: ReducedConfig, *, threads: int, wall_time_s: float, path_steps: int) -> dict[str, Any]:
    attrs: dict[str, Any] = {"title": f"stochpend reduced dynamics, {config.order} order"}
    attrs.update(config.to_attrs())
    attrs.update(
        {
            "noise": "ou",
            "equations": EQUATIONS[config.order],
            "sigma2": config.sigma2,
            "method": {
                "zeroth": "E = E0 (no randomness)",
                "first": "exact: E = |E0 + sigma W| sampled from independent Gaussian increments",
                "second": "X = E_2**2, drift frozen per step at its step average (exact OU integral, "
                          "trapezoid for xi**2), exact squared-Bessel transition; Skorokhod reflection at 0",
                "asymptotic": "exact: X = E**2 squared Bessel (delta = 1/2), non-central chi-square transitions",
            }[config.order],
            "omega_columns": "mean_Omega2 = <2E>, mean_Omega4 = <4E^2>; mean_sin2theta undefined (NaN)",
            "rng": "Philox4x32-10, key = seed, counter = (draw, global path index); "
                   "draw = 2^62 + code 2^56 + block 2^24 + m (code 1 first, 2 second, 3 asymptotic)",
            "threads": threads,
            "wall_time_s": wall_time_s,
            "path_steps": path_steps,
            "stochpend_version": __version__,
            "numba_version": numba.__version__,
            "cpu_target": _cputarget.describe(),
            "numpy_version": np.__version__,
            "python_version": platform.python_version(),
            "created": _time.strftime("%Y-%m-%dT%H:%M:%SZ", _time.gmtime()),
            "reference": "K. Mallick and P. Marcq, On the stochastic pendulum with Ornstein-Uhlenbeck noise (2004)",
        }
    )
    return {k: (int(v) if isinstance(v, bool) else v) for k, v in attrs.items()}
