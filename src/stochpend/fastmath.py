"""Branch-free log, sin and cos in plain float64 arithmetic, so that LLVM can vectorize them.

Numba lowers ``math.log``/``math.sin``/``math.cos`` to calls into the C library, and the
llvmlite wheels carry no vector math library (SVML), so a loop that calls them stays scalar.
These versions are the FreeBSD msun (fdlibm) algorithms with their branches replaced by
selects: the same polynomials and the same error bounds (< 1 ulp), so they agree with glibc's
correctly rounded or < 1 ulp results to within an ulp. Measured maximum errors against
``math.log``/``math.sin``/``math.cos`` are asserted in tests/unit/test_fastmath.py.

Valid inputs (no special cases are handled, by design):

* :func:`log_pos`: finite, positive, normal x (the Box-Muller uniforms of ``rng.uniform_open``
  lie in [2**-53, 1 - 2**-53]);
* :func:`sincos`, :func:`sin`: finite ``|x| < 2**19 * pi/2`` (about 8e5); the reduction uses
  pi/2 to 119 bits (fdlibm's ``pio2_1 + pio2_2 + pio2_2t``), exact enough in this range.

The functions are ``register_jitable``: compiled into the calling kernel and inlined, callable
from Python too (as the tests do).
"""

from __future__ import annotations

import math

from numba import types
from numba.extending import intrinsic, register_jitable


# -- bit casts --------------------------------------------------------------------------------
@intrinsic
def f64_as_i64(typingctx, x):
    """The IEEE-754 bits of a float64 as an int64 (no conversion)."""
    if not isinstance(x, types.Float) or x.bitwidth != 64:
        return None

    def codegen(context, builder, signature, args):
        return builder.bitcast(args[0], context.get_value_type(types.int64))

    return types.int64(types.float64), codegen


@intrinsic
def i64_as_f64(typingctx, x):
    """The float64 whose IEEE-754 bits are the int64 x (no conversion)."""
    if not isinstance(x, types.Integer) or x.bitwidth != 64:
        return None

    def codegen(context, builder, signature, args):
        return builder.bitcast(args[0], context.get_value_type(types.float64))

    return types.float64(x), codegen


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
    dk = float(k)
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
    fn = math.floor(x * _INVPIO2 + 0.5)
    n = int(fn)
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
