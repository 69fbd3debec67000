"""Counter-based random numbers: Philox4x32-10 (Salmon et al., SC'11; Random123).

Every random number of a simulation is a pure function of ``(seed, path, n)``:

* the 64-bit ``seed`` is the Philox key ``(k0, k1) = (seed mod 2**32, seed >> 32)``;
* the counter is ``(n mod 2**32, n >> 32, path mod 2**32, path >> 32)``, where ``path`` is the
  path's *global* index in the ensemble and ``n`` numbers the draws of that path
  (``n = 0`` and ``n = 1`` are the initial conditions, ``n = k + 2`` is step ``k``).

So a path's numbers do not depend on how many threads run, how the ensemble is chunked, on
which backend (CPU, CUDA) or on which cluster worker it runs.

The functions are plain scalar Python on ``numpy.uint64`` values, registered with Numba's
``register_jitable``: Numba compiles them into CPU kernels and CUDA device code alike, and they
stay callable from Python as the test oracle. Every
32-bit word is held in a ``uint64`` and masked, because Numba would turn a mix of signed and
unsigned 64-bit operands into floating point.

The one operation whose best code differs between targets, the 32 x 32 -> 64-bit product of a
Philox round, is :func:`mulhilo`: on the CPU (and in Python) a 64-bit product; the CUDA backend
registers a CUDA-target implementation of the same function, one ``mul.wide.u32`` instruction on
32-bit registers (``stochpend.engine.cuda``). Both return the exact product's two halves, so
every backend draws the same words.

Normals come as a float64 pair (:func:`draw_normals`, Box-Muller on two 52-bit uniforms) or,
for the float32 kernels, as a float32 pair computed in float32 throughout
(:func:`normals_with` with ``real=numpy.float32``): :func:`uniform_f32` of words 0 and 2 of
the same draw, float32 log, sqrt, sin and cos. They follow the float64 pair to float32
round-off (word 0 carries the high bits of the float64 u1, word 2 those of u2).
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from stochpend.numerics import fastmath
from stochpend.numerics._jitable import register_jitable

_MASK32 = np.uint64(0xFFFFFFFF)
_SHIFT32 = np.uint64(32)
_PHILOX_M0 = np.uint64(0xD2511F53)
_PHILOX_M1 = np.uint64(0xCD9E8D57)
_PHILOX_W0 = np.uint64(0x9E3779B9)
_PHILOX_W1 = np.uint64(0xBB67AE85)
_SHIFT6 = np.uint64(6)
_TWO_POW_26 = 67108864.0
_TWO_POW_M52 = 1.0 / 4503599627370496.0
_TWO_PI = 2.0 * math.pi

_F32_TWO_POW_M32 = np.float32(2.0**-32)
_F32_TWO_POW_M33 = np.float32(2.0**-33)
_F32_MINUS_TWO = np.float32(-2.0)
_F32_TWO_PI = np.float32(2.0 * math.pi)

#: The global path index of the first set of coupled levels (the bias estimate's pairs, a
#: multilevel target's levels): set ``i`` is path ``COUPLED_PATH0 + i`` of the run's seed, so
#: its streams are disjoint from the run's paths (0 .. paths - 1) and the same on every backend.
COUPLED_PATH0 = 1 << 63
#: Draw index of the initial angle theta0 (a uniform).
N_INIT_THETA = 0
#: Draw index of the initial noise xi0 (a normal).
N_INIT_XI = 1
#: Draw index of integrator step 0; step k uses N_FIRST_STEP + k.
N_FIRST_STEP = 2
#: Draw index of the additive noise's normal of step k (stochpend.model.dynamics): N_ADDITIVE + k, a
#: range of the counter no other draw reaches (the multiplicative noise's are N_FIRST_STEP + k).
N_ADDITIVE = 1 << 62
#: Draw index of the Boltzmann initial conditions (stochpend.model.initial): Omega from N_BOLTZMANN, x's
#: rejection attempts from N_BOLTZMANN + 1 + j.
N_BOLTZMANN = 1 << 61


@register_jitable
def mulhilo(a, b):
    """``(hi, lo)``: the high and low 32-bit words of the product of two 32-bit words ``a``,
    ``b`` (uint64 < 2**32), as uint64.

    This definition (a 64-bit product) is the CPU's and Python's. The CUDA backend registers a
    CUDA-target implementation (one ``mul.wide.u32``), which Numba prefers when it compiles
    for the GPU; the product is exact in both, so both give the same words.
    """
    p = a * b
    return p >> _SHIFT32, p & _MASK32


@register_jitable
def philox_round(c0, c1, c2, c3, k0, k1):
    """One Philox4x32 round on four 32-bit words held in uint64."""
    hi0, lo0 = mulhilo(_PHILOX_M0, c0)
    hi1, lo1 = mulhilo(_PHILOX_M1, c2)
    return (hi1 ^ c1 ^ k0) & _MASK32, lo1, (hi0 ^ c3 ^ k1) & _MASK32, lo0


@register_jitable
def philox4x32_10(c0, c1, c2, c3, k0, k1):
    """Philox4x32 with 10 rounds: counter ``(c0..c3)``, key ``(k0, k1)``, all uint64 < 2**32.

    Returns the four output words as uint64 values < 2**32. Known-answer tested against the
    Random123 ``kat_vectors``.
    """
    for _ in range(9):
        c0, c1, c2, c3 = philox_round(c0, c1, c2, c3, k0, k1)
        k0 = (k0 + _PHILOX_W0) & _MASK32
        k1 = (k1 + _PHILOX_W1) & _MASK32
    return philox_round(c0, c1, c2, c3, k0, k1)


@register_jitable
def uniform_open(a, b):
    """A float64 uniform on the open interval (0, 1) from two 32-bit words (52 random bits).

    The value is ``(k + 1/2) / 2**52`` with ``k`` the 52-bit integer made of the high 26 bits of
    ``a`` and of ``b``. Every such value is exactly representable, the largest is
    1 - 2**-53 < 1 and the smallest 2**-53 > 0, so ``log(u)`` and ``log(1 - u)`` are finite.
    """
    k = float(a >> _SHIFT6) * _TWO_POW_26 + float(b >> _SHIFT6)
    return (k + 0.5) * _TWO_POW_M52


@register_jitable
def box_muller(u1, u2):
    """Two independent standard normals from two uniforms on (0, 1)."""
    r = math.sqrt(-2.0 * math.log(u1))
    phase = _TWO_PI * u2
    return r * math.cos(phase), r * math.sin(phase)


@register_jitable
def draw_words(key0, key1, path, n):
    """The four Philox words of draw ``n`` of global path ``path`` (both uint64)."""
    return philox4x32_10(
        n & _MASK32, n >> _SHIFT32, path & _MASK32, path >> _SHIFT32, key0, key1
    )


@register_jitable
def draw_normals(key0, key1, path, n):
    """Two independent standard normals for draw ``n`` of global path ``path``."""
    r0, r1, r2, r3 = draw_words(key0, key1, path, n)
    return box_muller(uniform_open(r0, r1), uniform_open(r2, r3))


@register_jitable
def draw_uniforms(key0, key1, path, n):
    """Two independent uniforms on (0, 1) for draw ``n`` of global path ``path``."""
    r0, r1, r2, r3 = draw_words(key0, key1, path, n)
    return uniform_open(r0, r1), uniform_open(r2, r3)


@register_jitable
def uniform_f32(a):
    """A float32 uniform on (0, 1] from one 32-bit word: ``a 2**-32 + 2**-33`` in float32
    (cuRAND's ``curand_uniform``).

    The smallest value is 2**-33, so ``log(u)`` is finite and a Box-Muller radius is at most
    sqrt(66 ln 2) = 6.76; words within 2**7 of 2**32 round to exactly 1 (radius 0).
    """
    return np.float32(a) * _F32_TWO_POW_M32 + _F32_TWO_POW_M33


def normals_with(mathlib, real=np.float64):
    """The normal pair of a draw (``(key0, key1, path, n) -> (z1, z2)``) for kernels of
    precision ``real``, with ``mathlib``'s log and sincos (:mod:`stochpend.numerics.mathlib`).

    float64: :func:`draw_normals` (the C library's functions) or its Box-Muller with
    ``mathlib``'s. float32: Box-Muller in float32 arithmetic on :func:`uniform_f32` of words 0
    and 2 (no float64 operation; the pair is the float64 pair to float32 round-off, except
    where a uniform is within about 2**-32 of 0 or 1).
    """
    if real is np.float32:
        return _normals_f32(mathlib)
    if mathlib.name == "libm":
        return draw_normals
    log = mathlib.log
    sincos = mathlib.sincos

    @register_jitable
    def normals(key0, key1, path, n):
        r0, r1, r2, r3 = draw_words(key0, key1, path, n)
        r = math.sqrt(-2.0 * log(uniform_open(r0, r1)))
        s, c = sincos(_TWO_PI * uniform_open(r2, r3))
        return r * c, r * s

    return normals


def _normals_f32(mathlib):
    log = mathlib.log
    sincos = mathlib.sincos
    f32 = np.float32

    @register_jitable
    def normals_f32(key0, key1, path, n):
        r0, _, r2, _ = draw_words(key0, key1, path, n)
        r = f32(math.sqrt(_F32_MINUS_TWO * f32(log(uniform_f32(r0)))))
        s, c = sincos(_F32_TWO_PI * uniform_f32(r2))
        return r * f32(c), r * f32(s)

    return normals_f32


#: r * W0 and r * W1 for the rounds r = 0..9 (uint64: no mix of signed and unsigned operands).
_W0_MULTIPLES = tuple(np.uint64(r * 0x9E3779B9) for r in range(10))
_W1_MULTIPLES = tuple(np.uint64(r * 0xBB67AE85) for r in range(10))


@register_jitable
def round_keys(key0, key1):
    """The ten Philox round keys, two 10-tuples of uint64 (round r: key + r W mod 2**32, the
    keys :func:`philox4x32_10` steps through): the same for every path of a seed, so a
    lock-step driver computes them once per call."""
    k0 = (key0, (key0 + _W0_MULTIPLES[1]) & _MASK32, (key0 + _W0_MULTIPLES[2]) & _MASK32,
          (key0 + _W0_MULTIPLES[3]) & _MASK32, (key0 + _W0_MULTIPLES[4]) & _MASK32,
          (key0 + _W0_MULTIPLES[5]) & _MASK32, (key0 + _W0_MULTIPLES[6]) & _MASK32,
          (key0 + _W0_MULTIPLES[7]) & _MASK32, (key0 + _W0_MULTIPLES[8]) & _MASK32,
          (key0 + _W0_MULTIPLES[9]) & _MASK32)
    k1 = (key1, (key1 + _W1_MULTIPLES[1]) & _MASK32, (key1 + _W1_MULTIPLES[2]) & _MASK32,
          (key1 + _W1_MULTIPLES[3]) & _MASK32, (key1 + _W1_MULTIPLES[4]) & _MASK32,
          (key1 + _W1_MULTIPLES[5]) & _MASK32, (key1 + _W1_MULTIPLES[6]) & _MASK32,
          (key1 + _W1_MULTIPLES[7]) & _MASK32, (key1 + _W1_MULTIPLES[8]) & _MASK32,
          (key1 + _W1_MULTIPLES[9]) & _MASK32)
    return k0, k1


@register_jitable
def philox4x32_10_keyed(c0, c1, c2, c3, rk0, rk1):
    """:func:`philox4x32_10` with its round keys given (:func:`round_keys`), the ten rounds
    written out: a loop left to LLVM keeps a lane loop around it from vectorizing."""
    c0, c1, c2, c3 = philox_round(c0, c1, c2, c3, rk0[0], rk1[0])
    c0, c1, c2, c3 = philox_round(c0, c1, c2, c3, rk0[1], rk1[1])
    c0, c1, c2, c3 = philox_round(c0, c1, c2, c3, rk0[2], rk1[2])
    c0, c1, c2, c3 = philox_round(c0, c1, c2, c3, rk0[3], rk1[3])
    c0, c1, c2, c3 = philox_round(c0, c1, c2, c3, rk0[4], rk1[4])
    c0, c1, c2, c3 = philox_round(c0, c1, c2, c3, rk0[5], rk1[5])
    c0, c1, c2, c3 = philox_round(c0, c1, c2, c3, rk0[6], rk1[6])
    c0, c1, c2, c3 = philox_round(c0, c1, c2, c3, rk0[7], rk1[7])
    c0, c1, c2, c3 = philox_round(c0, c1, c2, c3, rk0[8], rk1[8])
    return philox_round(c0, c1, c2, c3, rk0[9], rk1[9])


class RunKeys(NamedTuple):
    """The Philox keys of one run, made from its seed by :func:`run_keys` and nowhere else in the
    package (a driver reads ``config.keys``): ``main`` the seed's key words (the multiplicative
    noise, the initial conditions, the white additive noise), ``additive`` the additive channel
    of a coloured noise (:func:`additive_key`). Each a pair of uint64 holding 32-bit words."""

    main: tuple[np.uint64, np.uint64]
    additive: tuple[np.uint64, np.uint64]


def run_keys(seed: int) -> RunKeys:
    """The run's keys (:class:`RunKeys`) for a seed in [0, 2**64)."""
    return RunKeys(seed_to_key(seed), additive_key(seed))


def seed_to_key(seed: int) -> tuple[np.uint64, np.uint64]:
    """Split a seed in [0, 2**64) into the Philox key words."""
    seed = int(seed)
    return np.uint64(seed & 0xFFFFFFFF), np.uint64((seed >> 32) & 0xFFFFFFFF)


#: What :func:`additive_key` mixes into the seed's key words: SHA-256's initial words H2, H3 (the
#: first 32 bits of the fractional parts of sqrt(5) and sqrt(7)), "nothing up my sleeve"
#: constants; any nonzero pair would do.
ADDITIVE_KEY_MIX = (0x3C6EF372, 0xA54FF53A)


def additive_key(seed: int) -> tuple[np.uint64, np.uint64]:
    """The Philox key of the generic additive noise channel (``additive_noise``,
    stochpend.model.dynamics): the seed's key words XOR :data:`ADDITIVE_KEY_MIX`.

    The channel calls its noise's own device functions (init from draw ``N_INIT_XI``, step k
    from ``N_FIRST_STEP + k``, ...) with this key instead of the seed's: a different key is a
    different Philox permutation, so within a run the channel's numbers are independent of
    every draw under the seed's key (the multiplicative noise xi, the initial conditions, the
    white additive channel), and they are still a function of (seed, path, draw) alone.
    (The key differs from the seed's for every seed; it equals the key of the seed
    ``seed ^ mix``, a different run, which does not matter: runs are never mixed.)"""
    k0, k1 = seed_to_key(seed)
    return np.uint64(int(k0) ^ ADDITIVE_KEY_MIX[0]), np.uint64(int(k1) ^ ADDITIVE_KEY_MIX[1])


_BITS_2_POW_52 = np.uint64(0x4330000000000000)


@register_jitable
def uniform_open_bits(a, b):
    """:func:`uniform_open`'s value, bit for bit, from integer operations and one float64
    subtraction: the 52-bit integer k is placed in the mantissa of 2**52 + k (exact), so no
    integer-to-float conversion is needed (AVX2 has none for 64-bit lanes)."""
    k = ((a >> _SHIFT6) << np.uint64(26)) | (b >> _SHIFT6)
    kf = fastmath.i64_as_f64(np.int64(k | _BITS_2_POW_52)) - 4503599627370496.0
    return (kf + 0.5) * _TWO_POW_M52


def normals_keyed_with(mathlib):
    """``normals(rk0, rk1, c2, c3, n)``: the two normals of draw ``n`` (uint64) of the path whose
    counter words are ``(c2, c3)`` (path mod 2**32, path >> 32), from the round keys of
    :func:`round_keys`: :func:`normals_with`'s numbers, bit for bit, written for a loop over
    lanes that LLVM vectorizes (the rounds written out, no branch)."""
    log = mathlib.log
    sincos = mathlib.sincos

    @register_jitable(inline="always")
    def normals(rk0, rk1, c2, c3, n):
        r0, r1, r2, r3 = philox4x32_10_keyed(n & _MASK32, n >> _SHIFT32, c2, c3, rk0, rk1)
        r = math.sqrt(-2.0 * log(uniform_open_bits(r0, r1)))
        s, c = sincos(_TWO_PI * uniform_open_bits(r2, r3))
        return r * c, r * s

    return normals
