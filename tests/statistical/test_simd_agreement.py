"""The default CPU path (SIMD, fast math) against the C library's one-path kernel, in law.

Since the lane machine, the default runs (the pendulum with the noise on the force, OU or
white noise, adaptive steps) use the branch-free log/sin/cos/expm1 of ``stochpend.numerics.fastmath``
and the branch-free OU coefficients: each step differs from the C library's by an ulp or so,
and the chaotic dynamics amplify that, so paths end apart while the ensembles must agree. Two
independent ensembles (different seeds) of 10**5 paths per case, one per kernel: <E> and <E**2>
at three output times, |z| < Z_TOL with the combined standard error, over noises x omega x tau.
"""

from __future__ import annotations

import numpy as np
import pytest

from stochpend.engine import cpu
from stochpend.model.settings import SimulationConfig
from tests._kernels import Paths, kernels
from tests.conftest import SEED, Z_TOL

pytestmark = pytest.mark.slow

PATHS = 100_000
TIMES = (1.0, 5.0, 20.0)
D = 1.0
# (noise, tau): the series (h/tau < 0.6) and the direct form (h_max/tau = 1) of the OU
# coefficients, slow noise, and white noise.
NOISES = [("ou", 0.05), ("ou", 1.0), ("ou", 10.0), ("white", 0.0)]


def _moments(noise, tau, omega, fast_math, seed):
    kern = kernels(noise, fast_math=fast_math)
    p = Paths(PATHS).init(kern, seed, D=D, tau=tau)
    out = []
    for t_target in TIMES:
        while p.advance(kern, t_target, 10**9, seed, D=D, tau=tau, omega2=omega**2,
                        h_max=0.05, step_c=0.1)[1]:
            pass
        assert np.all(p.status == 0)
        E = 0.5 * p.Omega**2 - omega**2 * np.cos(p.x)
        out.append([(np.mean(v), np.std(v, ddof=1) / np.sqrt(PATHS)) for v in (E, E * E)])
    return np.array(out)  # (time, statistic, (mean, se))


@pytest.mark.parametrize("noise,tau", NOISES)
@pytest.mark.parametrize("omega", [0.0, 1.0])
def test_simd_default_agrees_with_the_c_library_kernel(noise, tau, omega):
    config = SimulationConfig.build(noise=noise, D=D, omega=omega,
                                    **({"tau": tau} if tau else {}))
    assert cpu.spec_for(config).fast_math  # the case is the default SIMD path
    new = _moments(noise, tau, omega, True, SEED)
    old = _moments(noise, tau, omega, False, SEED + 1)
    z = (new[..., 0] - old[..., 0]) / np.hypot(new[..., 1], old[..., 1])
    print(f"\n{noise} tau={tau} omega={omega}: z(<E>) = {np.round(z[:, 0], 2)}, "
          f"z(<E^2>) = {np.round(z[:, 1], 2)}, relative s.e. of <E^2> at t = {TIMES[-1]}: "
          f"{new[-1, 1, 1] / new[-1, 1, 0]:.4f}")
    assert np.max(np.abs(z)) < Z_TOL, z
