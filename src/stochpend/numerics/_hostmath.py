"""Host-side arithmetic whose bits do not depend on the machine's vector extensions.

numpy chooses its loops for ``exp``, ``log``, ``power``, ``expm1``, ``arctan2`` ... by the CPU
it runs on (an AVX-512 machine gets vector code derived from Intel's SVML, an AVX2 one the C
library's functions), and those loops differ in the last bit: ``np.geomspace(0.05, 50, 6)`` and
``x ** 1.5`` are not the same numbers on two x86-64 machines. A number that feeds a run (the
output times, the Boltzmann start of the x^(2n) oscillators, a statistic made from the sums)
is computed instead from operations IEEE 754 rounds exactly (+, -, *, /, sqrt) or from the C
library's functions one value at a time (Python's :mod:`math`, as the kernels call them), which
every x86-64 machine with FMA computes alike (docs/development.md, "What is bit-identical").
"""

from __future__ import annotations

import math

import numpy as np


def geomspace(start: float, stop: float, num: int) -> np.ndarray:
    """``num`` numbers from ``start`` to ``stop`` (both > 0, both kept exactly) evenly spaced in
    log10, as ``np.geomspace``: 10 ** linspace(log10(start), log10(stop), num) with the C
    library's log10 and pow. Shape (num,), float64."""
    exponents = np.linspace(math.log10(start), math.log10(stop), num)
    grid = np.array([10.0 ** float(e) for e in exponents], dtype=np.float64)
    grid[0] = start
    grid[-1] = stop
    return grid
