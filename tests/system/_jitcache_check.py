"""Drive the CPU kernels of one or two Specs in a fresh process (used by test_jitcache.py).

Usage: ``python _jitcache_check.py OUT.npy NOISE [NOISE...]``: runs the fixed-step kernels of
each noise in turn (the pendulum, 40 paths to t = 0.5) and saves the final angles of the last
one. With NUMBA_CACHE_DIR shared between calls, the last noise's kernels may come from the
on-disk cache written by another process.
"""

from __future__ import annotations

import sys

import numpy as np


def final_angles(noise: str) -> np.ndarray:
    from tests._kernels import Paths, kernels

    kern = kernels(noise, adaptive=False)
    p = Paths(40).init(kern, 7, D=1.0, tau=1.0, W=2.0)
    while True:
        _, unfinished = p.advance(kern, 0.5, 10**6, 7, D=1.0, tau=1.0, W=2.0, omega2=1.0, h_max=0.01)
        if unfinished == 0:
            return p.x


if __name__ == "__main__":
    for noise in sys.argv[2:]:
        x = final_angles(noise)
    np.save(sys.argv[1], x)
