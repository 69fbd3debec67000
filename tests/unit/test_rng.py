"""Philox4x32-10 known answers, Python/Numba identity, and the uniform/normal transforms."""

from __future__ import annotations

import math

import numba
import numpy as np
import pytest

from stochpend import rng
from tests.conftest import Z_TOL

U = np.uint64

# Random123 kat_vectors, "philox4x32 10": counter[4] key[2] -> output[4].
KAT = [
    ("00000000 00000000 00000000 00000000", "00000000 00000000", "6627e8d5 e169c58d bc57ac4c 9b00dbd8"),
    ("ffffffff ffffffff ffffffff ffffffff", "ffffffff ffffffff", "408f276d 41c83b0e a20bc7c6 6d5451fd"),
    ("243f6a88 85a308d3 13198a2e 03707344", "a4093822 299f31d0", "d16cfe09 94fdcceb 5001e420 24126ea1"),
]


def _words(text: str) -> list[np.uint64]:
    return [U(int(w, 16)) for w in text.split()]


@pytest.mark.parametrize("ctr,key,expected", KAT)
def test_philox_known_answers_python_and_numba(ctr, key, expected):
    want = [int(w, 16) for w in expected.split()]
    got_py = [int(w) for w in rng.philox4x32_10(*_words(ctr), *_words(key))]
    got_jit = [int(w) for w in numba.njit(rng.philox4x32_10)(*_words(ctr), *_words(key))]
    assert got_py == want, f"pure-Python Philox gives {got_py}, Random123 says {want}"
    assert got_jit == want, f"Numba-compiled Philox gives {got_jit}, Random123 says {want}"


def test_uniform_open_interval_extremes():
    assert rng.uniform_open(U(0), U(0)) == 2.0**-53
    assert rng.uniform_open(U(0), U(0)) > 0.0
    top = rng.uniform_open(U(0xFFFFFFFF), U(0xFFFFFFFF))
    assert top == 1.0 - 2.0**-53 and top < 1.0


def test_draws_depend_on_seed_path_and_counter():
    base = rng.draw_normals(U(1), U(0), U(5), U(7))
    assert rng.draw_normals(U(1), U(0), U(5), U(7)) == base
    assert rng.draw_normals(U(2), U(0), U(5), U(7)) != base
    assert rng.draw_normals(U(1), U(0), U(6), U(7)) != base
    assert rng.draw_normals(U(1), U(0), U(5), U(8)) != base
    # high words of path and counter are used too
    assert rng.draw_normals(U(1), U(0), U(5 + 2**32), U(7)) != base
    assert rng.draw_normals(U(1), U(0), U(5), U(7 + 2**32)) != base


@numba.njit
def _normal_moments(n, key0):
    s1 = s2 = s3 = s4 = c12 = 0.0
    for i in range(n):
        a, b = rng.draw_normals(key0, np.uint64(0), np.uint64(i), np.uint64(3))
        s1 += a + b
        s2 += a * a + b * b
        s3 += a**3 + b**3
        s4 += a**4 + b**4
        c12 += a * b
    m = 2.0 * n
    return s1 / m, s2 / m, s3 / m, s4 / m, c12 / n


def test_normals_have_standard_gaussian_moments():
    n = 500_000
    m1, m2, m3, m4, c12 = _normal_moments(n, np.uint64(11))
    m = 2 * n
    # standard errors of the sample moments of N(0, 1): sqrt(Var(z^k)/m)
    checks = {"mean": (m1, 0.0, 1.0), "E z^2": (m2, 1.0, 2.0), "E z^3": (m3, 0.0, 15.0),
              "E z^4": (m4, 3.0, 96.0), "E z1 z2": (c12, 0.0, 1.0 * m / n)}
    for name, (value, exact, var) in checks.items():
        z = (value - exact) / math.sqrt(var / m)
        assert abs(z) < Z_TOL, f"{name} = {value:.6f}, exact {exact}: {z:+.2f} standard errors"
