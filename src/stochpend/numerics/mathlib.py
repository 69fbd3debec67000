"""The transcendental functions a kernel is compiled with: the C library's, or fastmath's.

An integrator is specialised for one :class:`MathLib` at compile time (``integrator.KernelSpec``):

* :data:`LIBM`: ``math.log``/``math.sin``/``math.cos``/``math.expm1`` (the C library,
  correctly rounded or < 1 ulp); the CUDA kernels and the CPU's one-path-at-a-time driver use it;
* :data:`FAST`: the branch-free versions of :mod:`stochpend.numerics.fastmath`, which LLVM can
  vectorize; the CPU's SIMD drivers (lock-step blocks and lanes) use them, so their numbers
  differ from LIBM's by an ulp or two per call (tests/unit/test_fastmath.py).

The functions are ``register_jitable``, so a kernel inlines them and Python can call them.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

from stochpend.numerics import fastmath
from stochpend.numerics._jitable import register_jitable


@register_jitable
def _log(x):
    return math.log(x)


@register_jitable
def _sin(x):
    return math.sin(x)


@register_jitable
def _cos(x):
    return math.cos(x)


@register_jitable
def _sincos(x):
    return math.sin(x), math.cos(x)


@register_jitable
def _expm1(x):
    return math.expm1(x)


@register_jitable
def _floor(x):
    return float(math.floor(x))


@dataclass(frozen=True)
class MathLib:
    """``log`` (of a positive normal number), ``sin``, ``cos``, ``sincos`` (-> (sin, cos)),
    ``expm1`` (of x <= 700) and ``floor`` (a float, equal for both libraries)."""

    name: str
    log: Callable[[float], float]
    sin: Callable[[float], float]
    cos: Callable[[float], float]
    sincos: Callable[[float], tuple[float, float]]
    expm1: Callable[[float], float]
    floor: Callable[[float], float]


LIBM = MathLib("libm", _log, _sin, _cos, _sincos, _expm1, _floor)
FAST = MathLib("fast", fastmath.log_pos, fastmath.sin, fastmath.cos, fastmath.sincos,
               fastmath.expm1, fastmath.floor)
