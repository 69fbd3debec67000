"""A SIMD fixed-step CPU kernel: blocks of paths advanced in lockstep, vectorized by LLVM.

``advance_paths`` is a drop-in for :func:`stochpend._backends.cpu.advance_paths` (same
arguments, same effect on the state arrays, same return value). For the case it is made for
-- fixed step (``step_c <= 0``), OU noise, pendulum, noise on the force -- it runs
``_advance_blocks``; anything else goes to the scalar kernel unchanged.

``_advance_blocks`` takes ``BLOCK`` consecutive paths at a time (threads over blocks). With a
fixed step every path of a block is at the same time ``t`` and step count ``k``, so the time
bookkeeping (the scalar kernel's landing rule and Kahan-compensated ``t += h``, whose
compensation term ``t_comp`` is path state), the last step
and the OU coefficients (``expm1``/``tanh``, only when h changes) are per block, and each step is a few loops over the block's lanes with no branches
and no calls, which LLVM vectorizes:

1. Philox4x32-10 of draw ``k + 2`` for each lane (``rng.philox_round`` written out ten times;
   32x32 -> 64-bit multiplies on uint64), the two uniforms (``rng.uniform_open``),
   ``r = sqrt(-2 log u1)`` (``fastmath.log_pos``) and the phase ``2 pi u2``;
2. ``fastmath.sincos`` of the phase, the exact OU update, the drift-kick-drift step with
   ``fastmath.sin`` in the kick and the angle wrap with ``floor``.

The random numbers are stochpend's, bit for bit, and the arithmetic is the scalar kernel's in
the same order; only log/sin/cos differ from the C library's, by at most an ulp
(tests/unit/test_fastmath.py), so the results agree with ``cpu.advance_paths`` to round-off.
Because the pendulum amplifies round-off differences slowly, a difference of about 1e-15 after
one step grows over a long run (documented in docs/performance.md with the measured maximum).

A block whose paths are not in lockstep (a path frozen as non-finite, paths at different times
after a resumed checkpoint), and the rest of a block where a path turned non-finite, go one path
at a time through ``_advance_one``: the scalar kernel's bookkeeping with the lanes' arithmetic
(fastmath included), so every path's numbers are a function of (seed, path) alone, whatever its
block, chunk or thread, as with the scalar kernel.
"""

from __future__ import annotations

import math

import numba
import numpy as np
from numba import prange
from numba.extending import register_jitable

from stochpend import fastmath, physics, rng, schemes
from stochpend._backends import cpu
from stochpend._jitcache import drop_stale_cache

drop_stale_cache(__file__)

#: Paths per lockstep block (a multiple of the 8 float64 lanes of AVX-512).
BLOCK = 64

_U64 = np.uint64
_MASK32 = np.uint64(0xFFFFFFFF)
_SHIFT32 = np.uint64(32)
_W0 = np.uint64(0x9E3779B9)
_W1 = np.uint64(0xBB67AE85)
_TWO_PI = 2.0 * math.pi


@register_jitable
def round_keys(key0, key1):
    """The ten Philox round keys (two uint64 arrays of length 10)."""
    rk0 = np.empty(10, dtype=np.uint64)
    rk1 = np.empty(10, dtype=np.uint64)
    a0 = key0
    a1 = key1
    for r in range(10):
        rk0[r] = a0
        rk1[r] = a1
        a0 = (a0 + _W0) & _MASK32
        a1 = (a1 + _W1) & _MASK32
    return rk0, rk1


def advance_paths(x, Omega, xi, t, k, status, t_target, max_steps, noise_code, D, tau, omega2,
                  h_max, step_c, potential_code, power_n, coupling_code, key0, key1, path0,
                  t_comp, xi_aux, omega_noise):
    """Drop-in for ``cpu.advance_paths``; the SIMD kernel for fixed-step OU pendulum runs."""
    if (step_c <= 0.0 and noise_code == cpu.OU and potential_code == physics.PENDULUM
            and coupling_code == physics.COUPLING_FORCE and tau > 0.0):
        return _advance_blocks(x, Omega, xi, t, k, status, t_target, max_steps, D, tau, omega2,
                               h_max, key0, key1, path0, t_comp)
    return cpu.advance_paths(x, Omega, xi, t, k, status, t_target, max_steps, noise_code, D, tau,
                             omega2, h_max, step_c, potential_code, power_n, coupling_code, key0,
                             key1, path0, t_comp, xi_aux, omega_noise)


@numba.njit(cache=True, error_model="numpy")
def _advance_one(i, x, Omega, xi, t, k, status, t_target, max_steps, D, tau, omega2, h_max, key0,
                 key1, path0, t_comp):  # pragma: no cover - compiled
    """Path i alone, with exactly the lockstep lanes' arithmetic (fastmath log/sin/cos), so a
    path's numbers never depend on which block it shares; the bookkeeping of the scalar
    kernel. Returns (steps, unfinished)."""
    if status[i] != 0 or t[i] >= t_target:
        return 0, 0
    path = _U64(path0 + i)
    xs = x[i]
    Om = Omega[i]
    xn = xi[i]
    tt = t[i]
    kk = k[i]
    h_cached = -1.0
    a = 0.0
    s_xi = 0.0
    m_I = 0.0
    c_I = 0.0
    s_I = 0.0
    n = 0
    tc = t_comp[i]
    bad = False
    while n < max_steps:
        h, last = schemes.landing_step(tt, h_max, t_target)
        c0, c1, c2, c3 = rng.draw_words(key0, key1, path, _U64(rng.N_FIRST_STEP) + kk)
        u1 = rng.uniform_open(c0, c1)
        u2 = rng.uniform_open(c2, c3)
        r = math.sqrt(-2.0 * fastmath.log_pos(u1))
        sn, cs = fastmath.sincos(_TWO_PI * u2)
        z1 = r * cs
        z2 = r * sn
        if h != h_cached:
            a, s_xi, m_I, c_I, s_I = schemes.ou_step_coefficients(h, D, tau)
            h_cached = h
        noise_integral = m_I * xn + c_I * z1 + s_I * z2
        xn = a * xn + s_xi * z1
        half_h = 0.5 * h
        x_half = xs + half_h * Om
        g = fastmath.sin(x_half)
        kick = omega2 * h * g
        kick += noise_integral * g
        Om = Om - kick
        x_new = x_half + half_h * Om
        xs = x_new - _TWO_PI * math.floor((x_new + math.pi) / _TWO_PI)
        kk += _U64(1)
        n += 1
        tt, tc = schemes.advance_clock(tt, tc, h, last, t_target)
        if not (math.isfinite(xs) and math.isfinite(Om) and math.isfinite(xn)):
            bad = True
            break
        if last:
            break
    x[i] = xs
    Omega[i] = Om
    xi[i] = xn
    t[i] = tt
    t_comp[i] = tc
    k[i] = kk
    if bad:
        status[i] = 1
    return n, (1 if (not bad and tt < t_target) else 0)


@numba.njit(parallel=True, cache=True, error_model="numpy")
def _advance_blocks(x, Omega, xi, t, k, status, t_target, max_steps, D, tau, omega2, h_max, key0,
                    key1, path0, t_comp):  # pragma: no cover - compiled
    """Fixed-step OU pendulum, BLOCK paths in lockstep; see the module docstring."""
    n_paths = x.shape[0]
    n_blocks = (n_paths + BLOCK - 1) // BLOCK
    rk0, rk1 = round_keys(key0, key1)  # the same for every path
    steps_taken = 0
    unfinished = 0
    for b in prange(n_blocks):
        i0 = b * BLOCK
        m = min(BLOCK, n_paths - i0)
        t0 = t[i0]
        k0 = k[i0]
        tc0 = t_comp[i0]
        lockstep = True
        for l in range(m):
            if (status[i0 + l] != 0 or t[i0 + l] != t0 or k[i0 + l] != k0
                    or t_comp[i0 + l] != tc0):
                lockstep = False
        if not lockstep or t0 >= t_target:
            for l in range(m):
                s, u = _advance_one(i0 + l, x, Omega, xi, t, k, status, t_target, max_steps, D,
                                    tau, omega2, h_max, key0, key1, path0, t_comp)
                steps_taken += s
                unfinished += u
            continue
        bx = np.empty(BLOCK)
        bO = np.empty(BLOCK)
        bxi = np.empty(BLOCK)
        br = np.empty(BLOCK)
        bph = np.empty(BLOCK)
        bc2 = np.empty(BLOCK, dtype=np.uint64)
        bc3 = np.empty(BLOCK, dtype=np.uint64)
        for l in range(BLOCK):
            src = i0 + l if l < m else i0  # padding lanes repeat the first path, never stored
            bx[l] = x[src]
            bO[l] = Omega[src]
            bxi[l] = xi[src]
            p = _U64(path0 + src)
            bc2[l] = p & _MASK32
            bc3[l] = p >> _SHIFT32
        tt = t0
        kk = k0
        h_cached = -1.0
        ca = 0.0
        s_xi = 0.0
        m_I = 0.0
        c_I = 0.0
        s_I = 0.0
        n = 0
        tc = tc0
        bad = False
        while n < max_steps:
            h, last = schemes.landing_step(tt, h_max, t_target)
            if h != h_cached:
                ca, s_xi, m_I, c_I, s_I = schemes.ou_step_coefficients(h, D, tau)
                h_cached = h
            draw = _U64(rng.N_FIRST_STEP) + kk
            d0 = draw & _MASK32
            d1 = draw >> _SHIFT32
            half_h = 0.5 * h
            kick_h = omega2 * h
            # 1. Philox, uniforms, Box-Muller radius and phase.
            for l in range(BLOCK):
                # Philox4x32-10, the rounds written out: a loop or a helper function left to
                # LLVM's inliner keeps the lane loop from vectorizing.
                c0 = d0
                c1 = d1
                c2 = bc2[l]
                c3 = bc3[l]
                c0, c1, c2, c3 = rng.philox_round(c0, c1, c2, c3, rk0[0], rk1[0])
                c0, c1, c2, c3 = rng.philox_round(c0, c1, c2, c3, rk0[1], rk1[1])
                c0, c1, c2, c3 = rng.philox_round(c0, c1, c2, c3, rk0[2], rk1[2])
                c0, c1, c2, c3 = rng.philox_round(c0, c1, c2, c3, rk0[3], rk1[3])
                c0, c1, c2, c3 = rng.philox_round(c0, c1, c2, c3, rk0[4], rk1[4])
                c0, c1, c2, c3 = rng.philox_round(c0, c1, c2, c3, rk0[5], rk1[5])
                c0, c1, c2, c3 = rng.philox_round(c0, c1, c2, c3, rk0[6], rk1[6])
                c0, c1, c2, c3 = rng.philox_round(c0, c1, c2, c3, rk0[7], rk1[7])
                c0, c1, c2, c3 = rng.philox_round(c0, c1, c2, c3, rk0[8], rk1[8])
                c0, c1, c2, c3 = rng.philox_round(c0, c1, c2, c3, rk0[9], rk1[9])
                u1 = rng.uniform_open(c0, c1)
                u2 = rng.uniform_open(c2, c3)
                br[l] = math.sqrt(-2.0 * fastmath.log_pos(u1))
                bph[l] = _TWO_PI * u2
            # 2. Normals, exact OU update, drift-kick-drift, wrap.
            for l in range(BLOCK):
                sn, cs = fastmath.sincos(bph[l])
                z1 = br[l] * cs
                z2 = br[l] * sn
                xn = bxi[l]
                noise_integral = m_I * xn + c_I * z1 + s_I * z2
                bxi[l] = ca * xn + s_xi * z1
                Om = bO[l]
                x_half = bx[l] + half_h * Om
                g = fastmath.sin(x_half)
                kick = kick_h * g
                kick += noise_integral * g
                Om = Om - kick
                bO[l] = Om
                x_new = x_half + half_h * Om
                bx[l] = x_new - _TWO_PI * math.floor((x_new + math.pi) / _TWO_PI)
            kk += _U64(1)
            n += 1
            tt, tc = schemes.advance_clock(tt, tc, h, last, t_target)
            finite = True
            for l in range(BLOCK):
                v = bx[l] + bO[l] + bxi[l]
                if not math.isfinite(v):
                    finite = False
            if not finite:
                bad = True
                break
            if last:
                break
        for l in range(m):
            x[i0 + l] = bx[l]
            Omega[i0 + l] = bO[l]
            xi[i0 + l] = bxi[l]
            t[i0 + l] = tt
            t_comp[i0 + l] = tc
            k[i0 + l] = kk
        steps_taken += n * m
        if bad:
            # The scalar kernel stops a path at its first non-finite state: freeze those lanes,
            # and let the others go on one by one (the same numbers, scalar code).
            for l in range(m):
                if not (math.isfinite(bx[l]) and math.isfinite(bO[l]) and math.isfinite(bxi[l])):
                    status[i0 + l] = 1
            for l in range(m):
                s, u = _advance_one(i0 + l, x, Omega, xi, t, k, status, t_target, max_steps - n, D,
                                    tau, omega2, h_max, key0, key1, path0, t_comp)
                steps_taken += s
                unfinished += u
        elif tt < t_target:
            unfinished += m
    return steps_taken, unfinished
