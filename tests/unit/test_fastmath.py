"""Branch-free log/sin/cos (stochpend.numerics.fastmath) and the CPU's SIMD lock-step driver.

Errors are measured in ulps of the reference result against glibc's ``log``/``sin``/``cos``
(what the scalar kernel calls), over the ranges the kernel uses: the Box-Muller uniforms
of ``rng.uniform_open`` (and, for margin, the finer grid (k + 1/2) 2**-53) for log, the Box-Muller phase [0, 2 pi) and the kick's angle
[-pi - 0.5, pi + 0.5] for sin/cos, plus a wide range |x| <= 1e4 for margin. The fdlibm
algorithms are < 1 ulp from the exact value, glibc's too, so the two may differ by 1 ulp;
measured maximum: 1 ulp on every range (a few percent of the arguments differ at all).
"""

from __future__ import annotations

import math

import numba
import numpy as np
import pytest

from stochpend.engine import cpu, integrator
from stochpend.model.settings import SimulationConfig
from stochpend.numerics import fastmath, rng
from tests._kernels import Paths, kernels

#: The fixed-step OU pendulum, with the C library's math (one path at a time) and with the
#: fast math of the lock-step driver.
SCALAR = kernels("ou", adaptive=False)
FAST = kernels("ou", adaptive=False, fast_math=True)


@numba.njit(cache=True, error_model="numpy")
def _fast(xs, which):
    out = np.empty_like(xs)
    for i in range(xs.shape[0]):
        if which == 0:
            out[i] = fastmath.log_pos(xs[i])
        elif which == 1:
            out[i] = fastmath.sin(xs[i])
        else:
            out[i] = fastmath.cos(xs[i])
    return out


@numba.njit(cache=True)
def _libm(xs, which):
    out = np.empty_like(xs)
    for i in range(xs.shape[0]):
        if which == 0:
            out[i] = math.log(xs[i])
        elif which == 1:
            out[i] = math.sin(xs[i])
        else:
            out[i] = math.cos(xs[i])
    return out


def _max_ulp(a, b):
    return float(np.max(np.abs(a - b) / np.spacing(np.abs(b))))


@numba.njit(cache=True)
def _uniforms(words):
    out = np.empty(words.shape[0])
    for i in range(words.shape[0]):
        out[i] = rng.uniform_open(words[i, 0], words[i, 1])
    return out


def test_log_within_one_ulp_on_the_box_muller_uniforms():
    g = np.random.default_rng(1)
    words = g.integers(0, 2**32, (300_000, 2)).astype(np.uint64)
    edges = np.array([[0, 0], [0, 64], [2**32 - 1, 2**32 - 1], [2**31, 0], [2**31 - 1, 2**32 - 1]],
                     dtype=np.uint64)
    u = _uniforms(np.concatenate([words, edges]))
    assert u.min() > 0.0 and u.max() < 1.0
    k = g.integers(0, 2**53, 300_000)
    fine = (np.concatenate([k, [0, 1, 2**52 - 1, 2**52, 2**53 - 1]]) + 0.5) * 2.0**-53
    u = np.concatenate([u, fine, [0.7071067811865476, 0.5, 0.25]])
    assert _max_ulp(_fast(u, 0), _libm(u, 0)) <= 1.0


@pytest.mark.parametrize("lo, hi", [(0.0, 2 * math.pi), (-math.pi - 0.5, math.pi + 0.5), (-1e4, 1e4)])
@pytest.mark.parametrize("which", [1, 2])
def test_sin_cos_within_one_ulp(lo, hi, which):
    g = np.random.default_rng(2)
    x = g.uniform(lo, hi, 400_000)
    # Multiples of pi/2 and their neighbours: the hardest cases of the reduction.
    q = np.arange(math.floor(lo / (math.pi / 2)), math.ceil(hi / (math.pi / 2)) + 1)[:2000] * (math.pi / 2)
    q = q[(q >= lo) & (q <= hi)]
    x = np.concatenate([x, q, np.nextafter(q, np.inf), np.nextafter(q, -np.inf)])
    a, b = _fast(x, which), _libm(x, which)
    tiny = np.abs(b) < 1e-300
    assert np.all(np.abs(a[tiny] - b[tiny]) < 1e-300)
    assert _max_ulp(a[~tiny], b[~tiny]) <= 1.0


def test_sincos_matches_sin_and_cos():
    x = np.linspace(-10, 10, 1001)
    s = np.array([fastmath.sincos(v)[0] for v in x])
    c = np.array([fastmath.sincos(v)[1] for v in x])
    np.testing.assert_array_equal(s, _fast(x, 1))
    np.testing.assert_array_equal(c, _fast(x, 2))


def _run(kern, paths, t_max, max_steps, seed=5, h=0.01, freeze=None, path0=0):
    p = Paths(paths).init(kern, seed, path0=path0)
    if freeze is not None:
        p.status[freeze] = 1
    calls = []
    while True:
        s, u = p.advance(kern, t_max, max_steps, seed, path0=path0, h_max=h)
        calls.append((s, u))
        if u == 0:
            return p.x, p.Omega, p.xi, p.t, p.k, p.status, calls, p.t_comp


@pytest.mark.parametrize("paths", [200, 64, 7])
def test_fast_kernel_agrees_with_the_scalar_kernel(paths):
    """Same numbers, same bookkeeping; states equal to round-off (1 ulp of log/sin/cos per step).

    200 paths: three full 64-path blocks and a padded one; max_steps = 37 splits the run into
    calls that end mid-way, as simulate() does. Measured difference after 150 steps: < 1e-14.
    """
    a = _run(SCALAR, paths, 1.5, 37)
    b = _run(FAST, paths, 1.5, 37)
    assert a[6] == b[6]  # (steps, unfinished) of every call
    np.testing.assert_array_equal(a[3], b[3])  # t
    np.testing.assert_array_equal(a[4], b[4])  # k
    np.testing.assert_array_equal(a[5], b[5])  # status
    np.testing.assert_array_equal(a[7], b[7])  # the clock's compensation term
    for u, v in zip(a[:3], b[:3], strict=True):
        np.testing.assert_allclose(v, u, rtol=0, atol=1e-13)


def test_fast_kernel_numbers_do_not_depend_on_blocks():
    """A path's numbers are the same in a lockstep block, alone (a frozen neighbour sends its
    block through the one-path code) or in another chunk: bit for bit."""
    ref = _run(FAST, 200, 1.5, 37)
    frozen = _run(FAST, 200, 1.5, 37, freeze=[3, 130])
    keep = np.ones(200, dtype=bool)
    keep[[3, 130]] = False
    for u, v in zip(ref[:5], frozen[:5], strict=True):
        np.testing.assert_array_equal(u[keep], v[keep])
    np.testing.assert_array_equal(frozen[5], ~keep)
    # Paths 0..99 and 100..199 as two chunks (blocks start at path 0 and at path 100).
    lo = _run(FAST, 100, 1.5, 37)
    hi = _run(FAST, 100, 1.5, 37, path0=100)
    for u, v, w in zip(ref[:5], lo[:5], hi[:5], strict=True):
        np.testing.assert_array_equal(u, np.concatenate([v, w]))


def test_simd_drivers_are_used_only_in_their_cases():
    """The runner gives the SIMD drivers (fast math) the pendulum with the noise on the force in
    float64: the fixed-step OU noise to the lock-step blocks, the OU noise with adaptive steps
    and the white noise to the lane machine. The dichotomous and harmonic noises, another
    oscillator or the position coupling run the C library's math one path at a time (their
    numbers unchanged)."""
    fast = cpu.spec_for(SimulationConfig.build(noise="ou", step_c=0.0))
    assert fast.fast_math and integrator.build(fast).lockstep
    assert cpu.advance_kernel(fast) is FAST.advance
    for kwargs in (dict(noise="ou"), dict(noise="white"), dict(noise="white", step_c=0.0)):
        spec = cpu.spec_for(SimulationConfig.build(**kwargs))
        assert spec.fast_math and integrator.lanes_supported(spec), kwargs
        assert cpu.advance_kernel(spec).kernel.__name__ == "advance", kwargs
        assert cpu.advance_kernel(spec) is not cpu.path_kernel(spec)
    for kwargs in (dict(noise="ou", potential="harmonic"), dict(noise="dichotomous"),
                   dict(noise="harmonic"), dict(noise="dichotomous", step_c=0.0),
                   dict(noise="ou", potential="harmonic", coupling="position")):
        config = SimulationConfig.build(**kwargs)
        spec = cpu.spec_for(config)
        assert spec == integrator.KernelSpec.of(config) and not spec.fast_math, kwargs
        assert cpu.advance_kernel(spec) is cpu.path_kernel(spec)


def test_lockstep_driver_gives_the_fast_one_path_numbers():
    """The lock-step lanes and the one-path code of the fast-math KernelSpec are the same numbers,
    bit for bit (the arithmetic is advance_path's, operation for operation)."""
    steps = integrator.build(FAST.spec)
    one_path = cpu.kernels(FAST.spec)  # the lock-step driver
    p = Paths(130).init(one_path, 3)
    q = Paths(130).init(one_path, 3)
    q.status[[0, 64, 128]] = 1  # every block leaves lock step: one path at a time
    p.advance(one_path, 0.7, 10**6, 3, h_max=0.01)
    q.advance(one_path, 0.7, 10**6, 3, h_max=0.01)
    keep = q.status == 0
    for name in ("x", "Omega", "xi", "t", "t_comp", "k"):
        np.testing.assert_array_equal(getattr(p, name)[keep], getattr(q, name)[keep])
    assert steps.lockstep


# -- the pieces of the lane machine --------------------------------------------------------------
@numba.njit(cache=True, error_model="numpy")
def _fast_expm1(xs):
    out = np.empty_like(xs)
    for i in range(xs.shape[0]):
        out[i] = fastmath.expm1(xs[i])
    return out


@numba.njit(cache=True)
def _libm_expm1(xs):
    out = np.empty_like(xs)
    for i in range(xs.shape[0]):
        out[i] = math.expm1(xs[i])
    return out


@pytest.mark.parametrize("lo, hi", [(-0.35, 0.35), (-1e-6, 1e-6), (-40.0, 0.0), (-800.0, -600.0),
                                    (0.0, 10.0)])
def test_expm1_within_two_ulps(lo, hi):
    """fastmath.expm1 (Taylor polynomial after Cody-Waite reduction) against the C library:
    measured at most 2 ulps (the polynomial's rounding near |x| = ln2/2); exact 0 and -1."""
    x = np.random.default_rng(3).uniform(lo, hi, 300_000)
    x = np.concatenate([x, [lo, hi, 0.5 * math.log(2.0), -0.5 * math.log(2.0)]])
    a, b = _fast_expm1(x), _libm_expm1(x)
    nonzero = b != 0.0
    assert np.all(a[~nonzero] == 0.0)
    assert _max_ulp(a[nonzero], b[nonzero]) <= 2.0
    assert _fast_expm1(np.array([0.0, -700.0, -1e300]))[0] == 0.0
    np.testing.assert_array_equal(_fast_expm1(np.array([-700.0, -1e300])), [-1.0, -1.0])


@numba.njit(cache=True, error_model="numpy")
def _conversions(xs, ks):
    out = np.empty((xs.shape[0], 3))
    for i in range(xs.shape[0]):
        out[i, 0] = fastmath.floor(xs[i])
        out[i, 1] = fastmath.int_to_float(ks[i])
        out[i, 2] = fastmath.float_to_int(fastmath.floor(xs[i]))
    return out


def test_floor_and_exact_integer_conversions():
    g = np.random.default_rng(4)
    x = np.concatenate([g.uniform(-1e6, 1e6, 10_000), [-2.5, -2.0, -0.5, -0.0, 0.0, 0.5, 2.0]])
    k = g.integers(-(2**50), 2**50, x.size)
    out = _conversions(x, k)
    np.testing.assert_array_equal(out[:, 0], np.floor(x))
    np.testing.assert_array_equal(out[:, 1], k.astype(np.float64))
    np.testing.assert_array_equal(out[:, 2], np.floor(x))
    assert fastmath.floor(-2.5) == -3.0 and fastmath.float_to_int(-3.0) == -3  # from Python too


@numba.njit(cache=True)
def _uniform_pairs(words):
    out = np.empty((words.shape[0], 2))
    for i in range(words.shape[0]):
        out[i, 0] = rng.uniform_open(words[i, 0], words[i, 1])
        out[i, 1] = rng.uniform_open_bits(words[i, 0], words[i, 1])
    return out


def test_uniform_open_bits_is_uniform_open():
    g = np.random.default_rng(5)
    words = np.concatenate([g.integers(0, 2**32, (100_000, 2)),
                            [[0, 0], [2**32 - 1, 2**32 - 1], [63, 64], [2**31, 0]]]).astype(np.uint64)
    out = _uniform_pairs(words)
    np.testing.assert_array_equal(out[:, 0], out[:, 1])


@pytest.mark.parametrize("h,tau", [(0.05, 1.0), (0.003, 1.0), (1e-7, 1.0), (0.05, 0.0835),
                                   (0.05, 0.08), (0.05, 0.01), (2.0, 0.5), (0.05, 1e-9), (0.01, 50.0)])
def test_branch_free_ou_coefficients_agree_with_the_c_library_ones(h, tau):
    """The fast-math KernelSpec's OU coefficients (expm1 polynomial, tanh(x/2) = b/(2 - b) in the
    direct form, both forms evaluated and one selected) against noises.ou.step_coefficients:
    within 1e-14 relative for every coefficient (h/tau on both sides of the series' 0.6)."""
    from stochpend.noises import ou
    from stochpend.numerics.mathlib import FAST

    coefficients = ou.branch_free_coefficients(np.float64, FAST)

    @numba.njit(error_model="numpy")
    def fast(h, p):  # as the kernels compile it (0/0 selected away, not an error)
        return coefficients(h, p)

    D = 1.7
    for got, want in zip(fast(h, (D, tau)), ou.step_coefficients(h, (D, tau)), strict=True):
        assert got == pytest.approx(want, rel=1e-14, abs=1e-300), (h, tau, got, want)
    zero = fast(h, (0.0, tau))  # D = 0: no noise, and no 0/0
    assert zero[1] == zero[3] == zero[4] == 0.0
