"""The step control of the linear oscillator is amplitude-free (issue 35, item 4).

x'' = -(omega**2 + xi) x is linear: (x, Omega) -> s (x, Omega) maps solutions onto solutions, so
the step may resolve only the local frequency sqrt(|omega**2 + xi|), never the amplitude. With
parametric white noise the energy grows like e^(2 lambda t) (lambda the top Lyapunov exponent,
exact by the Rice/Riccati quadrature, stochpend.theory.family.random_frequency_lyapunov); a step
bounded by c/|Omega| shrank as e^(-lambda t) and the run never finished. The reference here is
that exact law: <ln E>(t) grows with slope 2 lambda.
"""

from __future__ import annotations

import numpy as np
import pytest

from stochpend import observables
from stochpend.engine import runner
from stochpend.model.settings import SimulationConfig
from stochpend.theory.family import random_frequency_lyapunov


def _slope_of_log_energy(paths: int, t1: float, t2: float, seed: int) -> tuple[float, float, int]:
    """(slope of <ln E> between t1 and t2, its delete-one-batch jackknife error, path-steps).

    The slope's error comes from the per-batch sums of ln E at both times, so the correlation of
    a path's ln E at t1 and t2 (it is the same path) is accounted for."""
    config = SimulationConfig.build(potential="harmonic", noise="white", D=1.0, omega=1.0, paths=paths,
                                    t_max=t2, times=[t1, t2], seed=seed, observables=("log_energy",))
    sums, path_steps = runner.run_batches(config, 0, config.n_batches)
    c = observables.N_SUMS  # log_energy's columns: the sum of ln(E - E_min) and its count
    S, N = sums.sums[..., c], sums.sums[..., c + 1]  # (batch, time)

    def slope(S: np.ndarray, N: np.ndarray) -> float:
        y = S.sum(axis=0) / N.sum(axis=0)
        return float((y[1] - y[0]) / (t2 - t1))

    full = slope(S, N)
    B = S.shape[0]
    keep = ~np.eye(B, dtype=bool)
    leave_one = np.array([slope(S[keep[b]], N[keep[b]]) for b in range(B)])
    se = float(np.sqrt((B - 1) / B * np.sum((leave_one - leave_one.mean()) ** 2)))
    return full, se, int(path_steps)


def test_linear_oscillator_step_is_amplitude_free_and_growth_is_the_lyapunov_law():
    """4000 paths to t = 100 (about 1e7 path-steps): every step is h_max (c/omega = 0.1 >
    h_max = 0.05 and white noise has no xi in the state), whatever the amplitude, which grows
    by e^(0.22 t) ~ 4e9 in energy; and <ln E> grows at 2 lambda within 4 standard errors."""
    # First a probe a broken control fails in seconds instead of running for hours: to t = 40
    # the energy grows by e^9, and a step following the amplitude would take ~20 times as many.
    _, _, probe_steps = _slope_of_log_energy(200, 20.0, 40.0, seed=20)
    assert probe_steps == 200 * round(40.0 / 0.05)
    slope, se, path_steps = _slope_of_log_energy(4000, 25.0, 100.0, seed=21)
    assert path_steps == 4000 * round(100.0 / 0.05)
    two_lambda = 2.0 * random_frequency_lyapunov(D=1.0, gamma=0.0, omega=1.0)
    assert 0 < se < 0.01 * two_lambda
    assert abs(slope - two_lambda) < 4 * se, (slope, se, two_lambda)


@pytest.mark.slow
def test_linear_oscillator_lyapunov_law_at_the_issues_size():
    """Issue 35's case: 20 000 paths to t = 200, slope over t = 25 .. 200 within 3 sigma."""
    slope, se, path_steps = _slope_of_log_energy(20_000, 25.0, 200.0, seed=22)
    assert path_steps == 20_000 * round(200.0 / 0.05)
    two_lambda = 2.0 * random_frequency_lyapunov(D=1.0, gamma=0.0, omega=1.0)
    assert abs(slope - two_lambda) < 3 * se, (slope, se, two_lambda)
