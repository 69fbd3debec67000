"""The benchmark's references compute what stochpend computes (benchmarks/, issue 5).

Tiny workload: 50 paths (not a multiple of the C reference's 16-path blocks, so its padding
lanes are exercised), OU noise D = tau = omega = 1, fixed step 0.01 to t = 0.5 (50 steps),
same seed. Tolerances:

* NumPy with Philox and the C reference built in "exact" mode (no -ffast-math, no FMA
  contraction) draw the same Philox numbers and do the same IEEE operations in the same order
  as stochpend, so the final states are equal; <E^2> is compared to 1e-12 relative, which
  leaves room only for the order of the final summation (stochpend sums per batch) and for an
  ulp of difference between NumPy's SIMD log/sin/cos and glibc's on other builds.
* The C reference with the benchmark's flags (-O3 -march=native -ffast-math: FMA contraction,
  reciprocal division, libmvec log/sin/cos within 4 ulp) differs by a few ulps per step; over
  50 steps the difference grows by the dynamics' mild stretching, measured here about 1e-15
  absolute in the states. <E^2> is compared to 1e-10 relative and the states to 1e-10 absolute.
* NumPy with its own generator (PCG64) gives other numbers, the same law: <E^2> agrees within
  4 combined standard errors (2000 paths for that one).
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[2]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

from benchmarks import c_ref, numpy_ref  # noqa: E402
from stochpend.runs.simulate import simulate  # noqa: E402
from tests._kernels import Paths, kernels  # noqa: E402

PATHS, T, H, SEED = 50, 0.5, 0.01, 7
D = TAU = OMEGA = 1.0


def _stochpend_states(paths=PATHS, t_max=T, seed=SEED):
    kern = kernels("ou", adaptive=False)  # the C library's math, one path at a time
    p = Paths(paths).init(kern, seed, D=D, tau=TAU)
    while True:
        _, unfinished = p.advance(kern, t_max, 10**6, seed, D=D, tau=TAU, omega2=OMEGA**2, h_max=H)
        if unfinished == 0:
            return p.x, p.Omega, p.xi, int(p.k[0])


def _stochpend_E2(paths=PATHS, t_max=T, seed=SEED):
    ds = simulate("ou", D=D, tau=TAU, omega=OMEGA, paths=paths, t_max=t_max, times=[t_max],
                  seed=seed, step_c=0.0, h_max=H, n_batches=min(paths, 100))
    return float(ds["mean_E2"].values[-1]), float(ds["mean_E2_stderr"].values[-1])


def test_numpy_philox_reference_matches_stochpend():
    x, Om, xi, steps = _stochpend_states()
    r = numpy_ref.simulate(PATHS, T, H, D=D, tau=TAU, omega=OMEGA, seed=SEED, rng="philox")
    assert r.steps == steps
    np.testing.assert_allclose(r.theta, x, rtol=0, atol=1e-12)
    np.testing.assert_allclose(r.Omega, Om, rtol=0, atol=1e-12)
    np.testing.assert_allclose(r.xi, xi, rtol=0, atol=1e-12)
    E2 = float(np.mean(r.energy(OMEGA) ** 2))
    assert E2 == pytest.approx(_stochpend_E2()[0], rel=1e-12)


def test_numpy_own_generator_agrees_statistically():
    paths = 2000
    m_sp, se_sp = _stochpend_E2(paths=paths)
    r = numpy_ref.simulate(paths, T, H, D=D, tau=TAU, omega=OMEGA, seed=SEED, rng="numpy")
    E2 = r.energy(OMEGA) ** 2
    m_np, se_np = float(np.mean(E2)), float(np.std(E2, ddof=1) / np.sqrt(paths))
    assert abs(m_np - m_sp) < 4.0 * np.hypot(se_np, se_sp)


needs_gcc = pytest.mark.skipif(c_ref.compiler() is None, reason="gcc not found: no C reference")


@needs_gcc
@pytest.mark.parametrize("variant", ["scalar", "simd"])
def test_c_reference_exact_build_is_bit_identical(variant):
    x, Om, xi, steps = _stochpend_states()
    r = c_ref.run(PATHS, T, H, D=D, tau=TAU, omega=OMEGA, seed=SEED, variant=variant, flavour="exact")
    assert r.steps == steps
    np.testing.assert_array_equal(r.x, x)
    np.testing.assert_array_equal(r.Omega, Om)
    np.testing.assert_array_equal(r.xi, xi)
    E2 = float(np.mean(r.energy(OMEGA) ** 2))
    assert E2 == pytest.approx(_stochpend_E2()[0], rel=1e-12)


@needs_gcc
@pytest.mark.parametrize("variant", ["scalar", "simd"])
def test_c_reference_fast_math_build_agrees_to_roundoff(variant):
    x, Om, xi, steps = _stochpend_states()
    r = c_ref.run(PATHS, T, H, D=D, tau=TAU, omega=OMEGA, seed=SEED, variant=variant, flavour="fast")
    assert r.steps == steps
    np.testing.assert_allclose(r.x, x, rtol=0, atol=1e-10)
    np.testing.assert_allclose(r.Omega, Om, rtol=0, atol=1e-10)
    np.testing.assert_allclose(r.xi, xi, rtol=0, atol=1e-10)
    E2 = float(np.mean(r.energy(OMEGA) ** 2))
    assert E2 == pytest.approx(_stochpend_E2()[0], rel=1e-10)


ADAPTIVE_TIMES = (0.3, 1.0, 2.5)


def _stochpend_adaptive(spec, D):
    """Paths 0..PATHS-1 through ADAPTIVE_TIMES with the default step control (h_max = 0.05,
    c = 0.1), the calls split every 37 steps as the runner splits them."""
    kern = kernels("ou", fast_math=spec == "fast")
    p = Paths(PATHS).init(kern, SEED, D=D, tau=TAU)
    for t_target in ADAPTIVE_TIMES:
        while p.advance(kern, t_target, 37, SEED, D=D, tau=TAU, omega2=OMEGA**2, h_max=0.05,
                        step_c=0.1)[1]:
            pass
    return p


@needs_gcc
@pytest.mark.parametrize("D", [1.0, 30.0])
def test_c_reference_adaptive_scheme_is_stochpends(D):
    """The adaptive C reference takes stochpend's steps: built "exact", one path at a time, it
    is stochpend's C-library kernel bit for bit (step rule, landing, clock, coefficients,
    escapes); its SIMD lanes (branch-free coefficients) take the same steps as stochpend's
    lanes, their states equal to round-off (glibc's log/sin/cos against fastmath's, 1e-12)."""
    libm = _stochpend_adaptive("libm", D)
    fast = _stochpend_adaptive("fast", D)
    assert libm.k.min() < libm.k.max()  # the paths took their own steps
    r = c_ref.run_adaptive(PATHS, ADAPTIVE_TIMES, D=D, tau=TAU, omega=OMEGA, seed=SEED,
                           variant="scalar", flavour="exact")
    np.testing.assert_array_equal(r.path_steps, libm.k.astype(np.int64))
    for got, want in ((r.x, libm.x), (r.Omega, libm.Omega), (r.xi, libm.xi)):
        np.testing.assert_array_equal(got, want)
    for flavour in ("exact", "fast"):
        r = c_ref.run_adaptive(PATHS, ADAPTIVE_TIMES, D=D, tau=TAU, omega=OMEGA, seed=SEED,
                               variant="simd", flavour=flavour)
        np.testing.assert_array_equal(r.path_steps, fast.k.astype(np.int64))
        for got, want in ((r.x, fast.x), (r.Omega, fast.Omega), (r.xi, fast.xi)):
            np.testing.assert_allclose(got, want, rtol=0, atol=1e-12)


def test_loading_the_fast_math_reference_keeps_denormals():
    """Linking with -ffast-math would switch on flush-to-zero for the whole test process."""
    if c_ref.compiler() is None:
        pytest.skip("gcc not found: the C reference cannot be built")
    c_ref.build("fast")
    assert np.spacing(0.0) > 0.0, "denormals are flushed to zero after loading the C reference"
