"""The joint (x, Omega) histogram's cell of one path, shared by the CPU and CUDA kernels.

Uniform bins of ``[lo, hi)`` along each axis (``stochpend.model.settings.joint_grid``), with an outside
row and column on either side: the cells are numbered ``ix * (nO + 2) + iO``, ``ix`` in
``0 .. nx + 1`` (0: below the range, nx + 1: at or above it), likewise ``iO``. A periodic
oscillator's angle is reduced to [-pi, pi) first, so it is never outside. The same float64
operations on both backends, so the same state gives the same cell.
"""

from __future__ import annotations

import math

from numba.extending import register_jitable

__all__ = ["axis_bin", "angle_bin", "cell"]

_TWO_PI = 2.0 * math.pi


@register_jitable
def axis_bin(v, lo, hi, n):  # pragma: no cover - compiled
    """0 below ``lo``, ``n + 1`` at or above ``hi``, else 1 + the uniform bin of v."""
    if v < lo:
        return 0
    if v >= hi:
        return n + 1
    k = int(math.floor((v - lo) * (n / (hi - lo))))
    return 1 + min(k, n - 1)


@register_jitable
def angle_bin(x, n):  # pragma: no cover - compiled
    """1 + the bin of the angle x reduced to [-pi, pi), n uniform bins."""
    u = x + math.pi
    w = u - _TWO_PI * math.floor(u / _TWO_PI)  # in [0, 2 pi], up to rounding
    k = int(math.floor(w * (n / _TWO_PI)))
    return 1 + max(0, min(k, n - 1))


@register_jitable
def cell(x, Omega, periodic, x_lo, x_hi, nx, O_lo, O_hi, nO):  # pragma: no cover - compiled
    """The cell of (x, Omega) (see the module docstring)."""
    ix = angle_bin(x, nx) if periodic else axis_bin(x, x_lo, x_hi, nx)
    return ix * (nO + 2) + axis_bin(Omega, O_lo, O_hi, nO)
