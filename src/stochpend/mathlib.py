"""The transcendental functions a kernel is compiled with: the C library's, or fastmath's.

An integrator is specialised for one :class:`MathLib` at compile time (``integrator.Spec``):

* :data:`LIBM`: ``math.log``/``math.sin``/``math.cos`` (the C library, correctly rounded or
  < 1 ulp); every kernel uses it except the one below;
* :data:`FAST`: the branch-free fdlibm versions of :mod:`stochpend.fastmath`, which LLVM can
  vectorize; the CPU lock-step (SIMD) driver uses them, so its numbers differ from LIBM's by
  at most an ulp per call (tests/unit/test_fastmath.py).

The functions are ``register_jitable``, so a kernel inlines them and Python can call them.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

from numba.extending import register_jitable

from stochpend import fastmath


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


@dataclass(frozen=True)
class MathLib:
    """``log`` (of a positive normal number), ``sin``, ``cos`` and ``sincos`` (-> (sin, cos))."""

    name: str
    log: Callable[[float], float]
    sin: Callable[[float], float]
    cos: Callable[[float], float]
    sincos: Callable[[float], tuple[float, float]]


LIBM = MathLib("libm", _log, _sin, _cos, _sincos)
FAST = MathLib("fast", fastmath.log_pos, fastmath.sin, fastmath.cos, fastmath.sincos)
