"""CPU kernels: Numba, parallel over paths, cached on disk.

The kernels only orchestrate: the physics, the integrator step and the random numbers are the
shared scalar functions of ``physics``, ``schemes`` and ``rng``. They trust their inputs
(validated in ``params``), allocate nothing inside the path loops and call no Python.

Each path's state lives in arrays of length n_paths: position ``x`` (the angle theta for the
pendulum), ``Omega``, the noise ``xi``, its auxiliary variable ``xi_aux`` (harmonic noise: its
derivative; dichotomous noise: the time of the next flip), the time ``t``, the number of steps
taken ``k`` and a ``status`` (0: finite, 1: went non-finite and frozen). The random numbers of
step k of global path p are Philox draw N_FIRST_STEP + k (OU: both normals; dichotomous: a
uniform for the next waiting time, on a step that ends on a flip), N_FIRST_STEP + k // 2
(white: one normal of the pair, alternately) or N_FIRST_STEP + 2k and 2k + 1 (harmonic: three
normals), so they depend on (seed, p, k) only.
"""

from __future__ import annotations

import math

import numba
import numpy as np
from numba import prange

from stochpend import physics, rng, schemes
from stochpend._jitcache import drop_stale_cache

drop_stale_cache(__file__)

WHITE = schemes.NOISE_WHITE
OU = schemes.NOISE_OU
DICHOTOMOUS = schemes.NOISE_DICHOTOMOUS
HARMONIC = schemes.NOISE_HARMONIC

#: Columns of the per-batch sums.
S_COUNT, S_E1, S_E2, S_E3, S_E4, S_OMEGA2, S_OMEGA4, S_G2, S_NONFINITE = range(9)
N_SUMS = 9

_U64 = np.uint64


@numba.njit(parallel=True, cache=True)
def init_paths(x, Omega, xi, t, k, status, key0, key1, path0, theta0, uniform_theta0, Omega0, xi0,
               stationary_xi0, D, tau, noise_code, t_comp, xi_aux,
               omega_noise):  # pragma: no cover - compiled
    """Initial conditions of paths path0 .. path0 + len(x) - 1 (draws 0 and 1)."""
    for i in prange(x.shape[0]):
        x[i], Omega[i], xi[i], xi_aux[i] = schemes.initial_state(
            key0, key1, _U64(path0 + i), theta0, uniform_theta0, Omega0, xi0, stationary_xi0, D,
            tau, noise_code, omega_noise)
        t[i] = 0.0
        t_comp[i] = 0.0
        k[i] = 0
        status[i] = 0


@numba.njit(parallel=True, cache=True)
def advance_paths(x, Omega, xi, t, k, status, t_target, max_steps, noise_code, D, tau, omega2,
                  h_max, step_c, potential_code, power_n, coupling_code, key0, key1,
                  path0, t_comp, xi_aux, omega_noise):  # pragma: no cover - compiled
    """Advance every unfinished path towards ``t_target``, at most ``max_steps`` steps each.

    The last step of a path is shortened to land exactly on ``t_target``; with dichotomous
    noise a step is also cut at each flip (the dynamics between flips is deterministic, with the
    constant noise folded into the kick). A path whose state
    becomes non-finite gets status 1 and is never advanced again. The clock is a Kahan sum whose
    compensation term ``t_comp`` is part of the path's state (zeroed on landing), so the result
    does not depend on how a segment is split into calls.

    Returns ``(steps_taken, paths_unfinished)``.
    """
    n_paths = x.shape[0]
    steps_taken = 0
    unfinished = 0
    for i in prange(n_paths):
        if status[i] != 0 or t[i] >= t_target:
            continue
        path = _U64(path0 + i)
        xs = x[i]
        Om = Omega[i]
        xn = xi[i]
        xa = xi_aux[i]
        tt = t[i]
        kk = k[i]
        # Noise coefficients are cached while the step is unchanged (h = h_max most of the time).
        h_cached = -1.0
        a = 0.0
        s_xi = 0.0
        m_I = 0.0
        c_I = 0.0
        s_I = 0.0
        hc = schemes.HARMONIC_NO_COEFFICIENTS
        pair_draw = _U64(0xFFFFFFFFFFFFFFFF)
        z_even = 0.0
        z_odd = 0.0
        tc = t_comp[i]
        n = 0
        bad = False
        while n < max_steps:
            h = schemes.step_size(Om, xn, xs, h_max, step_c, omega2, potential_code, power_n,
                                  coupling_code)
            if h < schemes.ESCAPE_STEP_FRACTION * h_max:
                bad = True  # running away (see ESCAPE_STEP_FRACTION)
                break
            h, last, flip, t_land = schemes.landing_or_flip(tt, h, t_target, xa,
                                                            noise_code == DICHOTOMOUS)
            if noise_code == OU:
                z1, z2 = rng.draw_normals(key0, key1, path, _U64(rng.N_FIRST_STEP) + kk)
                if h != h_cached:
                    a, s_xi, m_I, c_I, s_I = schemes.ou_step_coefficients(h, D, tau)
                    h_cached = h
                noise_integral = m_I * xn + c_I * z1 + s_I * z2
                xn = a * xn + s_xi * z1
            elif noise_code == WHITE:
                d = _U64(rng.N_FIRST_STEP) + (kk >> _U64(1))
                if d != pair_draw:
                    z_even, z_odd = rng.draw_normals(key0, key1, path, d)
                    pair_draw = d
                z = z_even if (kk & _U64(1)) == 0 else z_odd
                noise_integral = math.sqrt(D * h) * z
            elif noise_code == DICHOTOMOUS:
                noise_integral = xn * h
            else:
                d = _U64(rng.N_FIRST_STEP) + (kk << _U64(1))
                z1, z2 = rng.draw_normals(key0, key1, path, d)
                z3, _ = rng.draw_normals(key0, key1, path, d + _U64(1))
                if h != h_cached:
                    hc = schemes.harmonic_step_coefficients(h, D, tau, omega_noise)
                    h_cached = h
                noise_integral, xn, xa = schemes.harmonic_noise_step(xn, xa, z1, z2, z3, hc)
            xs, Om = schemes.verlet_step(xs, Om, h, omega2, noise_integral, potential_code,
                                         power_n, coupling_code)
            if flip:
                u, _ = rng.draw_uniforms(key0, key1, path, _U64(rng.N_FIRST_STEP) + kk)
                xn, xa = schemes.dichotomous_flip(xn, xa, u, tau)
            kk += _U64(1)
            n += 1
            tt, tc = schemes.advance_clock(tt, tc, h, flip or last, t_land)
            if not (math.isfinite(xs) and math.isfinite(Om) and math.isfinite(xn)
                    and math.isfinite(xa)):
                bad = True
                break
            if last:
                break
        x[i] = xs
        Omega[i] = Om
        xi[i] = xn
        xi_aux[i] = xa
        t[i] = tt
        t_comp[i] = tc
        k[i] = kk
        if bad:
            status[i] = 1
        steps_taken += n
        if not bad and tt < t_target:
            unfinished += 1
    return steps_taken, unfinished


@numba.njit(parallel=True, cache=True)
def accumulate_batches(x, Omega, status, omega2, potential_code, power_n, coupling_code,
                       batch_size, edges, sums, hist):  # pragma: no cover - compiled
    """Per-batch power sums of E and Omega, and the energy histogram, at one output time.

    A path whose E**4, Omega**4 or G(x) is not finite is marked non-finite here (status 1).

    Paths ``[b * batch_size, (b + 1) * batch_size)`` of this chunk form batch b; each batch is
    summed sequentially in path order, so the sums do not depend on the thread count.

    ``sums``: (n_batches, N_SUMS) float64, overwritten. ``hist``: (n_batches, n_bins + 2)
    int64, overwritten; column 0 counts E below ``edges[0]``, the last column E at or above
    ``edges[-1]``.
    """
    n_paths = x.shape[0]
    n_edges = edges.shape[0]
    for b in prange(sums.shape[0]):
        for c in range(sums.shape[1]):
            sums[b, c] = 0.0
        for c in range(hist.shape[1]):
            hist[b, c] = 0
        start = b * batch_size
        stop = min(start + batch_size, n_paths)
        for i in range(start, stop):
            if status[i] != 0:
                sums[b, S_NONFINITE] += 1.0
                continue
            E = physics.energy(x[i], Omega[i], omega2, potential_code, power_n)
            E2 = E * E
            O2 = Omega[i] * Omega[i]
            g = physics.noise_shape(x[i], potential_code, power_n, coupling_code)
            if not (math.isfinite(E2 * E2) and math.isfinite(O2 * O2) and math.isfinite(g)):
                # The state is finite but its moments overflow: the path has escaped. It is
                # frozen as non-finite, so it stays excluded at every later time too.
                status[i] = 1
                sums[b, S_NONFINITE] += 1.0
                continue
            sums[b, S_COUNT] += 1.0
            sums[b, S_E1] += E
            sums[b, S_E2] += E2
            sums[b, S_E3] += E2 * E
            sums[b, S_E4] += E2 * E2
            sums[b, S_OMEGA2] += O2
            sums[b, S_OMEGA4] += O2 * O2
            sums[b, S_G2] += g * g
            if E < edges[0]:
                hist[b, 0] += 1
            elif E >= edges[n_edges - 1]:
                hist[b, n_edges] += 1
            else:
                hist[b, np.searchsorted(edges, E, side="right")] += 1
