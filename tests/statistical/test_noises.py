"""The dichotomous and harmonic noises as the kernel evolves them: normalization, correlation
function and spectrum against their exact values (docs/models.md).

The oscillator is held at rest (harmonic potential, x = Omega = 0: neither the force nor the
noise can move it), so the kernel's ``xi`` is a free sample of the noise at the output times.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
import scipy.linalg

from stochpend.engine import integrator
from stochpend.noises import harmonic
from stochpend.numerics import rng
from tests._kernels import Paths, kernels
from tests.conftest import SEED, Z_TOL

N_PATHS = 20_000
DT = 0.1
N_GRID = 128


def sample_noise(noise, D, tau, omega_noise, h_max=0.05, step_c=0.0):
    """xi at t = DT, 2 DT, ..., N_GRID DT for N_PATHS stationary paths: shape (N_GRID, N_PATHS)."""
    kern = kernels(noise, "harmonic", adaptive=step_c > 0)
    p = Paths(N_PATHS).init(kern, SEED, theta0=0.0, D=D, tau=tau, W=omega_noise)
    p.x[:] = 0.0
    out = np.empty((N_GRID, N_PATHS))
    for j in range(N_GRID):
        p.advance(kern, (j + 1) * DT, 10**9, SEED, D=D, tau=tau, W=omega_noise, h_max=h_max,
                  step_c=step_c)
        out[j] = p.xi
    assert np.all(p.status == 0) and np.all(p.x == 0.0) and np.all(p.Omega == 0.0)
    return out


def harmonic_correlation(lag, D, tau, W):
    """<xi(t + lag) xi(t)> of the stationary harmonic noise: [exp(A lag) Sigma]_11 with
    A = [[0, 1], [-W**2, -W**2 tau]] and Sigma = diag(D/(2 tau), W**2 D/(2 tau))."""
    A = np.array([[0.0, 1.0], [-(W**2), -(W**2) * tau]])
    var = D / (2 * tau)
    sigma = np.diag([var, W**2 * var])
    return np.array([(scipy.linalg.expm(A * abs(s)) @ sigma)[0, 0] for s in np.atleast_1d(lag)])


def ou_correlation(lag, D, tau):
    return D / (2 * tau) * np.exp(-np.abs(lag) / tau)


def check_correlation(samples, correlation):
    """<xi(t0) xi(t0 + lag)> at several lags against the exact correlation, in SEs."""
    i0 = 20
    for lag in (0, 1, 3, 10, 30):
        prod = samples[i0] * samples[i0 + lag]
        exact = correlation(lag * DT)
        se = prod.std(ddof=1) / math.sqrt(prod.size)
        if np.ptp(prod) == 0.0:  # xi**2 = a**2 exactly for the telegraph noise
            assert np.allclose(prod, exact, rtol=1e-14, atol=0.0)
            continue
        z = (prod.mean() - exact) / se
        assert abs(z) < Z_TOL, (lag, z)
    return samples[i0] * samples[i0]


def check_spectrum(samples, correlation):
    """Periodogram of the sampled paths at several frequencies against its exact expectation
    (DT**2 / T) sum_{n,m} C((n - m) DT) cos(nu (n - m) DT); returns the relative SE reached."""
    T = N_GRID * DT
    lags = np.arange(-(N_GRID - 1), N_GRID)
    weights = N_GRID - np.abs(lags)
    c = correlation(lags * DT)
    times = DT * np.arange(N_GRID)
    rel_se = []
    for nu in (0.0, 0.5, 1.3, 3.0, 7.0):
        f = (np.exp(1j * nu * times)[:, None] * samples).sum(axis=0) * DT
        periodogram = np.abs(f) ** 2 / T
        exact = DT**2 / T * np.sum(weights * c * np.cos(nu * lags * DT))
        se = periodogram.std(ddof=1) / math.sqrt(periodogram.size)
        z = (periodogram.mean() - exact) / se
        assert abs(z) < Z_TOL, (nu, z, periodogram.mean(), exact)
        rel_se.append(se / exact)
    return max(rel_se)


def test_dichotomous_noise_values_correlation_and_spectrum():
    D, tau = 1.3, 0.4
    a = math.sqrt(D / (2 * tau))
    samples = sample_noise("dichotomous", D, tau, 0.0)
    # Two values only, +-a, equally likely.
    assert np.all(np.abs(samples) == a)
    frac = np.mean(samples[50] > 0)
    assert abs(frac - 0.5) / math.sqrt(0.25 / N_PATHS) < Z_TOL
    check_correlation(samples, lambda s: ou_correlation(s, D, tau))
    rel = check_spectrum(samples, lambda s: ou_correlation(s, D, tau))
    # Teeth: the test resolves the spectrum to ~1 %, so a flip rate off by 10 % would fail.
    assert rel < 0.02


def test_dichotomous_noise_does_not_depend_on_the_step_in_law():
    """The flips cut the steps, so a step of 0.5 (longer than the mean time between flips,
    2 tau = 0.6) samples the same telegraph process."""
    D, tau = 1.0, 0.3
    samples = sample_noise("dichotomous", D, tau, 0.0, h_max=0.5)
    check_correlation(samples, lambda s: ou_correlation(s, D, tau))


@pytest.mark.parametrize("W", [None, 1.0, 6.0], ids=["critical", "underdamped", "overdamped"])
def test_harmonic_noise_correlation_and_spectrum(W):
    D, tau = 0.8, 0.5
    W = 2.0 / tau if W is None else W
    samples = sample_noise("harmonic", D, tau, W)
    corr = lambda s: harmonic_correlation(s, D, tau, W)  # noqa: E731
    sq = check_correlation(samples, corr)
    # The variance is D/(2 tau), the OU noise's, whatever W.
    assert abs(sq.mean() - D / (2 * tau)) / (sq.std(ddof=1) / math.sqrt(sq.size)) < Z_TOL
    rel = check_spectrum(samples, corr)
    assert rel < 0.02


def test_harmonic_noise_does_not_depend_on_the_step_in_law():
    """The update is exact, so a step of 0.5 and one of 0.01 sample the same process (here:
    same correlation function, checked against the exact one, with a step 50 times larger)."""
    D, tau, W = 1.0, 1.0, 1.5
    samples = sample_noise("harmonic", D, tau, W, h_max=0.5)
    check_correlation(samples, lambda s: harmonic_correlation(s, D, tau, W))


def _exact_harmonic_update(h, D, tau, W):
    """(Phi, Q) of the harmonic-noise state (xi, xi', integral) over h, by adaptive quadrature
    of exp(A u) b b^T exp(A^T u): an independent reference for ``harmonic_step_coefficients``."""
    import warnings

    from scipy.integrate import IntegrationWarning, quad

    g = W * W * tau
    A = np.array([[0.0, 1.0, 0.0], [-W * W, -g, 0.0], [1.0, 0.0, 0.0]])
    b = np.array([0.0, W * W * math.sqrt(D), 0.0])
    Q = np.zeros((3, 3))
    with warnings.catch_warnings():  # quad warns that it cannot reach 1e-12 where round-off
        warnings.simplefilter("ignore", IntegrationWarning)  # limits it; the test checks 1e-11
        for i in range(3):
            for j in range(i, 3):
                f = lambda u, i=i, j=j: (scipy.linalg.expm(A * u) @ b)[i] * (scipy.linalg.expm(A * u) @ b)[j]  # noqa: E731
                Q[i, j] = Q[j, i] = quad(f, 0.0, h, epsabs=0.0, epsrel=1e-12, limit=200)[0]
    return scipy.linalg.expm(A * h), Q


@pytest.mark.parametrize("h, D, tau, W", [(1e-4, 1.0, 1.0, 2.0), (0.05, 1.0, 1.0, 2.0),
                                          (0.7, 2.0, 0.5, 1.0), (3.0, 0.5, 0.3, 5.0)])
def test_harmonic_step_coefficients_are_exact(h, D, tau, W):
    """Propagator and covariance agree with quadrature to round-off, even at h = 1e-4 where
    var xi ~ h**3 and var I ~ h**5 (a Van Loan block exponential loses 5 digits there)."""
    c = harmonic.step_coefficients(h, D, tau, W)
    Phi, Q = _exact_harmonic_update(h, D, tau, W)
    P = np.array([[c[0], c[1]], [c[2], c[3]], [c[4], c[5]]])
    assert np.max(np.abs(P - Phi[:, :2])) < 1e-13 * np.max(np.abs(Phi[:, :2]))
    L = np.array([[c[6], 0, 0], [c[7], c[8], 0], [c[9], c[10], c[11]]])
    scale = np.sqrt(np.outer(np.diag(Q), np.diag(Q)))
    assert np.max(np.abs(L @ L.T - Q) / scale) < 1e-11


def test_stationary_initial_noise_laws():
    key0, key1 = rng.seed_to_key(SEED)
    D, tau, W = 1.0, 0.5, 3.0
    init_harmonic = integrator.build(integrator.spec("harmonic")).init_path
    init_dichotomous = integrator.build(integrator.spec("dichotomous")).init_path
    draws = np.array([init_harmonic(key0, key1, np.uint64(p), 0.0, False, 0.0, 0.0, True,
                                    (D, tau, W))[2:] for p in range(2000)])
    var = D / (2 * tau)
    for col, v in ((0, var), (1, W * W * var)):
        s = draws[:, col] ** 2
        assert abs(s.mean() - v) / (s.std(ddof=1) / math.sqrt(s.size)) < Z_TOL
    # Dichotomous: the first flip is exponential with mean 2 tau.
    waits = np.array([init_dichotomous(key0, key1, np.uint64(p), 0.0, False, 0.0, 0.0, True,
                                       (D, tau))[3] for p in range(2000)])
    assert abs(waits.mean() - 2 * tau) / (waits.std(ddof=1) / math.sqrt(waits.size)) < Z_TOL


@pytest.mark.parametrize("noise", ["dichotomous", "harmonic"])
def test_new_noises_do_not_depend_on_chunks_threads_or_kernel_call_splits(noise):
    """The extra noise state (flip time, xi') travels with the path: chunking, thread count
    and the kernel's step budget per call change no number."""
    import importlib

    import stochpend

    sim = importlib.import_module("stochpend.engine.cpu")  # where the per-call budget lives

    kw = dict(noise=noise, D=1.0, tau=0.5, paths=300, t_max=200.0, n_times=5, seed=SEED,
              n_batches=6)
    ref = stochpend.simulate(**kw)
    other = stochpend.simulate(**kw, chunk_paths=100, threads=1)
    saved = sim.WORK_PER_CALL
    sim.WORK_PER_CALL = 1  # every call stops after 1000 steps: segments split into many calls
    try:
        split = stochpend.simulate(**kw)
    finally:
        sim.WORK_PER_CALL = saved
    for ds in (other, split):
        for name in ("mean_E", "mean_E4", "E_hist", "batch_sum_E"):
            np.testing.assert_array_equal(ref[name].values, ds[name].values, err_msg=name)
