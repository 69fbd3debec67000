"""Branch-free log, sin, cos and expm1 in plain float64 arithmetic, so that LLVM can vectorize them.

Numba lowers ``math.log``/``math.sin``/``math.cos``/``math.expm1`` to calls into the C library,
and the llvmlite wheels carry no vector math library (SVML), so a loop that calls them stays
scalar. ``log``, ``sin`` and ``cos`` are the FreeBSD msun (fdlibm) algorithms with their
branches replaced by selects: the same polynomials and the same error bounds (< 1 ulp), so they
agree with glibc's correctly rounded or < 1 ulp results to within an ulp. ``expm1`` is a
Cody-Waite reduction and a degree-13 Taylor polynomial (at most 2 ulps from glibc's). Measured
maximum errors against the C library are asserted in tests/unit/test_fastmath.py.

With AVX2 alone (no AVX-512) there is no vector conversion between int64 and float64, and
Numba's ``math.floor`` returns an int64: :func:`floor`, :func:`int_to_float` and
:func:`float_to_int` do these exactly without conversion instructions (bit casts and the
1.5 * 2**52 trick), so that nothing in a lane loop falls back to one lane at a time.

Valid inputs (no special cases are handled, by design):

* :func:`log_pos`: finite, positive, normal x (the Box-Muller uniforms of ``rng.uniform_open``
  lie in [2**-53, 1 - 2**-53]);
* :func:`sincos`, :func:`sin`: finite ``|x| < 2**19 * pi/2`` (about 8e5); the reduction uses
  pi/2 to 119 bits (fdlibm's ``pio2_1 + pio2_2 + pio2_2t``), exact enough in this range;
* :func:`expm1`: x <= 700 (-1 below -700).

The functions are ``register_jitable`` (or ``overload``-ed Python functions): compiled into the
calling kernel and inlined, callable from Python too (as the tests do).
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from stochpend.numerics._jitable import register_jitable, when_numba


# -- bit casts, floor, exact integer conversions --------------------------------------------------
# Each is a plain Python function (so that the functions below stay callable from Python, as
# the tests call them) with an LLVM implementation for compiled code (``overload``).
def f64_as_i64(x):
    """The IEEE-754 bits of a float64 as an int64 (no conversion)."""
    return int(np.float64(x).view(np.int64))


def i64_as_f64(x):
    """The float64 whose IEEE-754 bits are the int64 x (no conversion)."""
    return float(np.int64(x).view(np.float64))


def floor(x):
    """floor(x) as a float64 (``math.floor`` gives an int64 in Numba, and the conversions
    do not vectorize without AVX-512)."""
    return float(math.floor(x))


def _register_overloads() -> None:
    """The LLVM implementations of the three functions above (``intrinsic`` and ``overload``),
    registered when Numba is first imported (:func:`stochpend.numerics._jitable.when_numba`), so that
    importing this module imports no Numba."""
    global _f64_as_i64, _i64_as_f64, _floor
    from numba import types
    from numba.extending import intrinsic, overload

    @intrinsic
    def _f64_as_i64(typingctx, x):
        if not isinstance(x, types.Float) or x.bitwidth != 64:
            return None

        def codegen(context, builder, signature, args):
            return builder.bitcast(args[0], context.get_value_type(types.int64))

        return types.int64(types.float64), codegen

    @intrinsic
    def _i64_as_f64(typingctx, x):
        if not isinstance(x, types.Integer) or x.bitwidth != 64:
            return None

        def codegen(context, builder, signature, args):
            return builder.bitcast(args[0], context.get_value_type(types.float64))

        return types.float64(x), codegen

    @intrinsic
    def _floor(typingctx, x):
        if not isinstance(x, types.Float) or x.bitwidth != 64:
            return None

        def codegen(context, builder, signature, args):
            fn = builder.module.declare_intrinsic("llvm.floor", [args[0].type])
            return builder.call(fn, args)

        return types.float64(types.float64), codegen

    @overload(f64_as_i64)
    def _ol_f64_as_i64(x):
        return lambda x: _f64_as_i64(x)

    @overload(i64_as_f64)
    def _ol_i64_as_f64(x):
        return lambda x: _i64_as_f64(x)

    @overload(floor)
    def _ol_floor(x):
        return lambda x: _floor(x)


_f64_as_i64: Any = None
_i64_as_f64: Any = None
_floor: Any = None
when_numba(_register_overloads)


@register_jitable
def select(condition, a, b):
    """``a if condition else b``, as a call: functions that Numba inlines into its IR
    (``inline="always"``) keep no conditional expression of their own, whose merged variables
    Numba's IR inliner mishandles; LLVM inlines this and makes it a select."""
    if condition:
        return a
    return b


# AVX2 has no vector conversion between int64 and float64 (AVX-512DQ has), so LLVM would do
# these one lane at a time. Adding 1.5 * 2**52 puts an integer |k| < 2**51 in the low bits of
# the mantissa, exactly.
_MAGIC = 6755399441055744.0  # 1.5 * 2**52
_MAGIC_BITS = 0x4338000000000000


@register_jitable
def int_to_float(k):
    """float(k) for an int64 |k| < 2**51 (exact), vectorizable."""
    return i64_as_f64(k + _MAGIC_BITS) - _MAGIC


@register_jitable
def float_to_int(f):
    """int(f) for an integral float64 |f| < 2**51 (exact), vectorizable."""
    return f64_as_i64(f + _MAGIC) - _MAGIC_BITS


# -- log (FreeBSD e_log.c) ----------------------------------------------------------------------
_LN2_HI = 6.93147180369123816490e-01
_LN2_LO = 1.90821492927058770002e-10
_LG1 = 6.666666666666735130e-01
_LG2 = 3.999999999940941908e-01
_LG3 = 2.857142874366239149e-01
_LG4 = 2.222219843214978396e-01
_LG5 = 1.818357216161805012e-01
_LG6 = 1.531383769920937332e-01
_LG7 = 1.479819860511658591e-01


@register_jitable
def log_pos(x):
    """Natural log of a finite, positive, normal float64, < 1 ulp (fdlibm), branch-free."""
    bits = f64_as_i64(x)
    hx = bits >> 32
    k = (hx >> 20) - 1023
    hx = hx & 0x000FFFFF
    i = (hx + 0x95F64) & 0x100000
    # x scaled by a power of two into [sqrt(2)/2, sqrt(2)).
    m = i64_as_f64((((hx | (i ^ 0x3FF00000)) << 32)) | (bits & 0xFFFFFFFF))
    k = k + (i >> 20)
    f = m - 1.0
    s = f / (2.0 + f)
    dk = int_to_float(k)
    z = s * s
    w = z * z
    t1 = w * (_LG2 + w * (_LG4 + w * _LG6))
    t2 = z * (_LG1 + w * (_LG3 + w * (_LG5 + w * _LG7)))
    R = t2 + t1
    hfsq = 0.5 * f * f
    big = dk * _LN2_HI - ((hfsq - (s * (hfsq + R) + dk * _LN2_LO)) - f)
    small = dk * _LN2_HI - ((s * (f - R) - dk * _LN2_LO) - f)
    sel = ((hx - 0x6147A) | (0x6B851 - hx)) > 0
    return big if sel else small


# -- sin, cos (FreeBSD k_sin.c, k_cos.c, e_rem_pio2.c) -----------------------------------------
_S1 = -1.66666666666666324348e-01
_S2 = 8.33333333332248946124e-03
_S3 = -1.98412698298579493134e-04
_S4 = 2.75573137070700676789e-06
_S5 = -2.50507602534068634195e-08
_S6 = 1.58969099521155010221e-10
_C1 = 4.16666666666666019037e-02
_C2 = -1.38888888888741095749e-03
_C3 = 2.48015872894767294178e-05
_C4 = -2.75573143513906633035e-07
_C5 = 2.08757232129817482790e-09
_C6 = -1.13596475577881948265e-11
_INVPIO2 = 6.36619772367581382433e-01
_PIO2_1 = 1.57079632673412561417e+00  # first 33 bits of pi/2
_PIO2_2 = 6.07710050630396597660e-11  # next 33 bits
_PIO2_2T = 2.02226624879595063154e-21  # pi/2 - (pio2_1 + pio2_2)


@register_jitable
def _kernel_sin(x, y):
    """sin(x + y) for |x + y| <= pi/4, y the tail of the reduced argument."""
    z = x * x
    w = z * z
    r = _S2 + z * (_S3 + z * _S4) + z * w * (_S5 + z * _S6)
    v = z * x
    return x - ((z * (0.5 * y - v * r) - y) - v * _S1)


@register_jitable
def _kernel_cos(x, y):
    """cos(x + y) for |x + y| <= pi/4."""
    z = x * x
    w = z * z
    r = z * (_C1 + z * (_C2 + z * _C3)) + w * w * (_C4 + z * (_C5 + z * _C6))
    hz = 0.5 * z
    w = 1.0 - hz
    return w + (((1.0 - w) - hz) + (z * r - x * y))


@register_jitable
def sincos(x):
    """(sin x, cos x), each < 1 ulp, branch-free, for finite |x| < 2**19 pi/2."""
    fn = floor(x * _INVPIO2 + 0.5)
    n = float_to_int(fn)
    # Cody-Waite reduction x - fn pi/2 = y0 + y1, pi/2 to 119 bits (fdlibm's second pass).
    t = x - fn * _PIO2_1
    w = fn * _PIO2_2
    r = t - w
    w = fn * _PIO2_2T - ((t - r) - w)
    y0 = r - w
    y1 = (r - y0) - w
    s = _kernel_sin(y0, y1)
    c = _kernel_cos(y0, y1)
    q = n & 3
    swap = (q & 1) != 0
    sin_x = c if swap else s
    cos_x = s if swap else c
    sin_x = -sin_x if (q & 2) != 0 else sin_x
    cos_x = -cos_x if ((q + 1) & 2) != 0 else cos_x
    return sin_x, cos_x


@register_jitable
def sin(x):
    """sin x, < 1 ulp, branch-free, for finite |x| < 2**19 pi/2."""
    return sincos(x)[0]


@register_jitable
def cos(x):
    """cos x, < 1 ulp, branch-free, for finite |x| < 2**19 pi/2."""
    return sincos(x)[1]


# -- expm1 (exp(x) - 1 by argument reduction and a Taylor polynomial) ---------------------------
_INVLN2 = 1.44269504088896338700e+00
_LN2_HI_EXP = 6.93147180369123816490e-01  # fdlibm's ln2_hi: k * ln2_hi exact for |k| < 2**11
_LN2_LO_EXP = 1.90821492927058770002e-10
# 1/j! for j = 2..13: the Taylor series of expm1(r) = r + r**2 q(r), |r| <= ln2/2, whose first
# term left out, r**14/14!, is below 1e-17 relative.
_EXPM1_TAYLOR = tuple(1.0 / math.factorial(j) for j in range(2, 14))
_EXPM1_LOWEST = -700.0


@register_jitable
def expm1(x):
    """exp(x) - 1 for finite x <= 700 (-1 below -700), a few ulps at most, branch-free.

    x = k ln2 + r with |r| <= ln2/2 (Cody-Waite, ln2 in two parts); expm1(r) = r + r**2 q(r) by
    its Taylor polynomial (degree 13), then expm1(x) = 2**k expm1(r) + (2**k - 1), exact
    arithmetic for k = 0 (|x| <= ln2/2, where the relative accuracy of a small argument matters).
    Measured error against ``math.expm1`` in tests/unit/test_fastmath.py.
    """
    x = max(x, _EXPM1_LOWEST)
    fk = floor(x * _INVLN2 + 0.5)
    hi = x - fk * _LN2_HI_EXP
    lo = fk * _LN2_LO_EXP
    r = hi - lo
    q = _EXPM1_TAYLOR[11]
    q = q * r + _EXPM1_TAYLOR[10]
    q = q * r + _EXPM1_TAYLOR[9]
    q = q * r + _EXPM1_TAYLOR[8]
    q = q * r + _EXPM1_TAYLOR[7]
    q = q * r + _EXPM1_TAYLOR[6]
    q = q * r + _EXPM1_TAYLOR[5]
    q = q * r + _EXPM1_TAYLOR[4]
    q = q * r + _EXPM1_TAYLOR[3]
    q = q * r + _EXPM1_TAYLOR[2]
    q = q * r + _EXPM1_TAYLOR[1]
    q = q * r + _EXPM1_TAYLOR[0]
    p = r + (r * r) * q
    two_k = i64_as_f64((float_to_int(fk) + 1023) << 52)
    return two_k * p + (two_k - 1.0)
