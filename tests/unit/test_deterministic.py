"""D = 0: the scheme is symplectic Stormer-Verlet; energy bounded, exact libration period."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.special import ellipk

import stochpend
from tests._kernels import Paths, kernels


def _one_path(theta0: float, Omega0: float, t_end: float, h: float, max_steps: int = 10**9):
    p = Paths(1)
    p.x[0], p.Omega[0] = theta0, Omega0
    p.advance(kernels("ou", adaptive=False), t_end, max_steps, 0, D=0.0, h_max=h)
    return float(p.x[0]), float(p.Omega[0]), int(p.k[0])


@pytest.mark.parametrize("theta_max", [0.3, 1.5, 2.8])
def test_libration_period_is_4K_over_omega(theta_max):
    """After one exact period 4K(k)/omega, k = sin(theta_max/2), the pendulum is back at rest."""
    period = 4.0 * ellipk(math.sin(theta_max / 2.0) ** 2)  # scipy's ellipk takes m = k^2
    h = 1e-3
    x, O, _ = _one_path(theta_max, 0.0, period, h)
    # Verlet's phase error over one period is O(h^2 T): ~1e-6 here
    assert x == pytest.approx(theta_max, abs=2e-5), f"theta(T) = {x}, expected {theta_max}"
    assert abs(O) < 2e-5, f"Omega(T) = {O}, expected 0"
    x_half, O_half, _ = _one_path(theta_max, 0.0, period / 2.0, h)
    assert x_half == pytest.approx(-theta_max, abs=2e-5)
    # a wrong period (by 1 %) would be caught
    x_off, _, _ = _one_path(theta_max, 0.0, 1.01 * period, h)
    assert abs(x_off - theta_max) > 1e-4


def test_energy_error_bounded_without_drift_over_ten_million_steps():
    """D = 0, h = 0.05: 10^7 steps of a swinging and of a rotating pendulum. (No bias estimate:
    its default two pairs, each a path at h and one at h/2, were 6e7 more steps than the run's
    2e7, and nothing here reads it.)"""
    times = np.linspace(0.0, 5e5, 401)
    ds = stochpend.simulate(noise="ou", D=0.0, tau=1.0, omega=1.0, paths=2, t_max=5e5, times=times,
                            theta0=2.0, Omega0=0.5, h_max=0.05, step_c=0.0, n_batches=2, bias_paths=0)
    assert ds.attrs["path_steps"] == 2 * 10_000_000
    E = ds.mean_E.values
    err = E - E[0]
    assert np.max(np.abs(err)) < 2e-3 * abs(E[0]) + 2e-3, f"energy error up to {np.max(np.abs(err))}"
    # no drift: the error in the last tenth is no larger than in the first tenth (+ round-off)
    first, last = np.abs(err[1:41]).max(), np.abs(err[-40:]).max()
    assert last < 1.5 * first + 1e-9, f"energy error grew from {first:.3e} to {last:.3e}"
    assert abs(np.mean(err[-40:]) - np.mean(err[1:41])) < 1e-6 + 0.1 * first
