"""Micro-benchmarks: the cost of each operation of a path-step (docs/performance.md).

    python -m benchmarks.micro          # prints a Markdown table

Each operation is applied to 2**20 independent inputs in the range a path-step uses, in a Numba
loop, best of 5 by the process's CPU time (robust to other processes sharing the machine); ns
per evaluation, one thread. "scalar" loops sum the results and call what stochpend's scalar kernel calls (glibc through LLVM
intrinsics; the llvmlite wheels have no vector math library, so these loops stay scalar);
"SIMD" loops call the branch-free ``stochpend.numerics.fastmath`` versions and store each result, so
that LLVM vectorizes them (a floating-point sum would not vectorize without fastmath).
"""

from __future__ import annotations

import math
import time

import numba
import numpy as np

from stochpend.noises import ou
from stochpend.numerics import fastmath, rng

N = 1 << 20
_U64 = np.uint64


@numba.njit(cache=True)
def _libm(op, xs):
    acc = 0.0
    for i in range(xs.shape[0]):
        v = xs[i]
        if op == 0:
            acc += math.log(v)
        elif op == 1:
            acc += math.sqrt(v)
        elif op == 2:
            acc += math.sin(v)
        elif op == 3:
            acc += math.cos(v)
        elif op == 4:
            acc += math.floor(v)
        elif op == 5:
            acc += v / 6.283185307179586
        elif op == 6:
            acc += math.expm1(-v)
        elif op == 7:
            acc += math.tanh(v)
        elif op == 8:
            acc += v * 1.0000001 + 0.5
    return acc


# One function per op for the vectorizable loops: a branch on `op` inside would block SIMD.
@numba.njit(cache=True, error_model="numpy")
def _fm_log(xs, out):
    for i in range(xs.shape[0]):
        out[i] = fastmath.log_pos(xs[i])


@numba.njit(cache=True, error_model="numpy")
def _fm_sin(xs, out):
    for i in range(xs.shape[0]):
        out[i] = fastmath.sin(xs[i])


@numba.njit(cache=True, error_model="numpy")
def _fm_sincos(xs, out):
    for i in range(xs.shape[0]):
        s, c = fastmath.sincos(xs[i])
        out[i] = s + c


@numba.njit(cache=True, error_model="numpy")
def _vec_sqrt(xs, out):
    for i in range(xs.shape[0]):
        out[i] = math.sqrt(xs[i])


@numba.njit(cache=True, error_model="numpy")
def _vec_floor_div(xs, out):
    for i in range(xs.shape[0]):
        out[i] = math.floor((xs[i] + 3.141592653589793) / 6.283185307179586)


@numba.njit(cache=True)
def _philox_scalar(n):
    acc = _U64(0)
    k0 = _U64(12345)
    k1 = _U64(678)
    for i in range(n):
        r0, r1, r2, r3 = rng.draw_words(k0, k1, _U64(i), _U64(7))
        acc ^= r0 ^ r1 ^ r2 ^ r3
    return acc


@numba.njit(cache=True, error_model="numpy")
def _philox_vec(n_blocks, bc2, bc3, buf):
    # The lock-step driver's form: rounds written out, a fixed-size block of lanes per loop.
    rk0, rk1 = rng.round_keys(_U64(12345), _U64(678))
    for b in range(n_blocks):
        for l in range(bc2.shape[0]):
            c0 = _U64(7)
            c1 = _U64(b)
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
            buf[l] = float(c0 ^ c1 ^ c2 ^ c3)
    return buf[0]


@numba.njit(cache=True)
def _normals_scalar(n):
    acc = 0.0
    k0 = _U64(12345)
    k1 = _U64(678)
    for i in range(n):
        z1, z2 = rng.draw_normals(k0, k1, _U64(i), _U64(7))
        acc += z1 + z2
    return acc


@numba.njit(cache=True)
def _ou_coefficients(n):
    acc = 0.0
    for i in range(n):
        a, s_xi, m_I, c_I, s_I = ou.step_coefficients(0.01 + 1e-9 * i, (1.0, 1.0))
        acc += a + s_xi + m_I + c_I + s_I
    return acc


def _best(fn, *args, repeat=5):
    fn(*args)
    best = math.inf
    for _ in range(repeat):
        t0 = time.process_time()
        fn(*args)
        best = min(best, time.process_time() - t0)
    return best


def run() -> list[tuple[str, str, float, str]]:
    """(operation, implementation, ns per evaluation, note) rows, one thread."""
    g = np.random.default_rng(0)
    u = (g.integers(0, 2**53, N) + 0.5) * 2.0**-53  # the Box-Muller uniforms
    phase = 2.0 * math.pi * g.random(N)
    angle = g.uniform(-math.pi - 0.2, math.pi + 0.2, N)
    small = g.uniform(0.0, 0.1, N)
    out = np.empty(N)
    prev = numba.get_num_threads()
    numba.set_num_threads(1)
    rows = []
    try:
        per = 1e9 / N
        rows.append(("Philox4x32-10 (10 rounds, 4 words)", "scalar Numba (rng.draw_words)",
                     _best(_philox_scalar, N) * per, "1 per path-step"))
        rows.append(("Philox4x32-10 (10 rounds, 4 words)", "SIMD Numba (lock-step driver form, 64-lane blocks)",
                     _best(_philox_vec, N // 64, np.arange(64, dtype=np.uint64), np.zeros(64, np.uint64),
                           np.empty(64)) * per, "1 per path-step"))
        rows.append(("log", "glibc (scalar)", _best(_libm, 0, u) * per, "1 per path-step (Box-Muller)"))
        rows.append(("log", "fastmath.log_pos (SIMD)", _best(_fm_log, u, out) * per, ""))
        rows.append(("sqrt", "glibc/LLVM (scalar loop)", _best(_libm, 1, u) * per,
                     "1 per path-step (Box-Muller)"))
        rows.append(("sqrt", "vsqrtpd (SIMD)", _best(_vec_sqrt, u, out) * per, ""))
        rows.append(("sin", "glibc (scalar)", _best(_libm, 2, phase) * per,
                     "2 per path-step (Box-Muller, kick)"))
        rows.append(("cos", "glibc (scalar)", _best(_libm, 3, phase) * per, "1 per path-step (Box-Muller)"))
        rows.append(("sin", "fastmath.sin (SIMD)", _best(_fm_sin, angle, out) * per, ""))
        rows.append(("sin and cos", "fastmath.sincos (SIMD)", _best(_fm_sincos, phase, out) * per, ""))
        rows.append(("floor", "LLVM (scalar loop)", _best(_libm, 4, angle) * per, "1 per path-step (wrap)"))
        rows.append(("division", "scalar loop", _best(_libm, 5, angle) * per, "1 per path-step (wrap)"))
        rows.append(("floor((x + pi) / 2pi)", "SIMD loop", _best(_vec_floor_div, angle, out) * per, ""))
        rows.append(("multiply-add", "scalar loop (sum chain)", _best(_libm, 8, angle) * per,
                     "about 15 per path-step"))
        rows.append(("expm1", "glibc (scalar)", _best(_libm, 6, small) * per, "only when h changes"))
        rows.append(("tanh", "glibc (scalar)", _best(_libm, 7, small) * per, "only when h changes"))
        rows.append(("OU coefficients (expm1, tanh, 2 sqrt, div)", "scalar",
                     _best(_ou_coefficients, N // 8) * 8 * per, "only when h changes"))
        rows.append(("two normals (Philox + Box-Muller)", "scalar Numba (rng.draw_normals)",
                     _best(_normals_scalar, N) * per, "1 per path-step"))
    finally:
        numba.set_num_threads(prev)
    return rows


def table(rows) -> str:
    lines = ["| operation | implementation | ns per evaluation (1 thread) | per path-step |",
             "|---|---|---|---|"]
    for op, impl, ns, note in rows:
        lines.append(f"| {op} | {impl} | {ns:.2f} | {note} |")
    return "\n".join(lines)


if __name__ == "__main__":
    print(table(run()))
