"""Philox4x32-10 known answers, Python/Numba identity, and the uniform/normal transforms."""

from __future__ import annotations

import math

import numba
import numpy as np
import pytest

from stochpend.numerics import rng
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


# -- the multiply of a Philox round ------------------------------------------------------------
def test_mulhilo_is_the_exact_product_in_python_and_numba():
    """rng.mulhilo (the CPU's and Python's definition; the CUDA backend's mul.wide.u32 returns
    the same halves by construction) splits the exact 64-bit product of two 32-bit words."""
    words = np.random.default_rng(3).integers(0, 2**32, size=(200, 2), dtype=np.uint64)
    words = np.vstack([words, [[0, 0], [2**32 - 1, 2**32 - 1], [0xD2511F53, 2**32 - 1]]]).astype(np.uint64)
    jit = numba.njit(rng.mulhilo)
    for a, b in words:
        exact = int(a) * int(b)
        want = (exact >> 32, exact & 0xFFFFFFFF)
        assert tuple(int(v) for v in rng.mulhilo(a, b)) == want
        assert tuple(int(v) for v in jit(a, b)) == want


# -- float32 normals ---------------------------------------------------------------------------
def test_uniform_f32_is_in_the_half_open_unit_interval():
    assert rng.uniform_f32(U(0)) == np.float32(2.0**-33)
    assert rng.uniform_f32(U(2**32 - 1)) == np.float32(1.0)  # rounds up to 1: log(1) = 0, finite
    assert rng.uniform_f32(U(2**31)) == np.float32(0.5 + 2.0**-33)
    for a in (U(0), U(1), U(2**24), U(2**32 - 129), U(2**32 - 1)):
        u = rng.uniform_f32(a)
        assert isinstance(u, np.float32) and 0.0 < u <= 1.0 and math.isfinite(math.log(u))


def _f32_normals():
    from stochpend.numerics.mathlib import LIBM

    return rng.normals_with(LIBM, np.float32)


def test_float32_normals_are_float32_in_numba_and_finite_at_the_extremes():
    normals = numba.njit(_f32_normals())
    z = normals(U(1), U(2), U(3), U(4))
    assert normals.nopython_signatures[0].return_type == numba.types.UniTuple(numba.types.float32, 2)
    assert all(isinstance(v, float) for v in z)
    # the largest radius the float32 uniforms allow: sqrt(-2 log 2**-33) = 6.76
    r_max = math.sqrt(-2.0 * math.log(float(rng.uniform_f32(U(0)))))
    assert 6.7 < r_max < 6.8


def test_float32_normals_follow_the_float64_pair():
    """Words 0 and 2 carry the high bits of the float64 pair's uniforms, so the float32 pair is
    the float64 pair to float32 round-off (paths of the two precisions stay close)."""
    normals32 = numba.njit(_f32_normals())
    normals64 = numba.njit(rng.draw_normals)
    worst = 0.0
    for i in range(2000):
        z32 = normals32(U(11), U(0), U(i), U(7))
        z64 = normals64(U(11), U(0), U(i), U(7))
        for a, b in zip(z32, z64, strict=True):
            worst = max(worst, abs(a - b) / max(1.0, abs(b)))
    assert worst < 1e-5, worst


def _moments_f32(n, key0):
    normals = _f32_normals()

    @numba.njit
    def moments(n, key0):
        s1 = s2 = s3 = s4 = c12 = 0.0
        beyond3 = 0
        for i in range(n):
            a32, b32 = normals(key0, np.uint64(0), np.uint64(i), np.uint64(3))
            a = np.float64(a32)
            b = np.float64(b32)
            s1 += a + b
            s2 += a * a + b * b
            s3 += a**3 + b**3
            s4 += a**4 + b**4
            c12 += a * b
            beyond3 += (abs(a) > 3.0) + (abs(b) > 3.0)
        m = 2.0 * n
        return s1 / m, s2 / m, s3 / m, s4 / m, c12 / n, beyond3 / m

    return moments(n, key0)


def test_float32_normals_have_standard_gaussian_moments_and_tails():
    n = 500_000
    m1, m2, m3, m4, c12, tail = _moments_f32(n, np.uint64(13))
    m = 2 * n
    p3 = math.erfc(3.0 / math.sqrt(2.0))  # P(|z| > 3) = 2.7e-3
    checks = {"mean": (m1, 0.0, 1.0), "E z^2": (m2, 1.0, 2.0), "E z^3": (m3, 0.0, 15.0),
              "E z^4": (m4, 3.0, 96.0), "E z1 z2": (c12, 0.0, 1.0 * m / n),
              "P(|z| > 3)": (tail, p3, p3 * (1.0 - p3))}
    for name, (value, exact, var) in checks.items():
        z = (value - exact) / math.sqrt(var / m)
        assert abs(z) < Z_TOL, f"{name} = {value:.6g}, exact {exact:.6g}: {z:+.2f} standard errors"


def test_the_seed_becomes_a_key_in_one_place():
    """Issue 33, item 6: only rng.run_keys turns a seed into Philox keys (drivers read
    config.keys); the keys are the seed's words and the channel's mixed words, as before."""
    import ast
    from pathlib import Path

    from stochpend.model.settings import SimulationConfig

    src = Path(rng.__file__).parents[1]  # the package root
    callers = set()
    for path in src.rglob("*.py"):
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            if isinstance(node, ast.Call):
                name = getattr(node.func, "attr", getattr(node.func, "id", None))
                if name in ("seed_to_key", "additive_key", "run_keys"):
                    callers.add((path.relative_to(src).as_posix(), name))
    # model/settings.py (SimulationConfig.keys, what the drivers read); initial.py, integrator.py
    # and reduced.py take any object with a seed (tests pass namespaces), so they ask run_keys itself
    assert callers == {("numerics/rng.py", "seed_to_key"), ("numerics/rng.py", "additive_key"),
                       ("model/settings.py", "run_keys"), ("model/initial.py", "run_keys"),
                       ("engine/integrator.py", "run_keys"), ("runs/reduced.py", "run_keys")}, callers
    seed = 2**40 + 77
    keys = SimulationConfig.build(seed=seed).keys
    assert keys.main == (np.uint64(seed & 0xFFFFFFFF), np.uint64(seed >> 32))
    assert keys.additive == (np.uint64((seed & 0xFFFFFFFF) ^ rng.ADDITIVE_KEY_MIX[0]),
                             np.uint64((seed >> 32) ^ rng.ADDITIVE_KEY_MIX[1]))
