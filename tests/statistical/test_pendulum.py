"""The stochastic pendulum against exact statements, and the OU noise against its exact law."""

from __future__ import annotations

import math

import numpy as np
import pytest

import stochpend
from stochpend.noises import ou
from tests._kernels import Paths, kernels
from tests.conftest import SEED, Z_TOL


def test_white_noise_mean_energy_grows_as_Dt_over_4():
    """Eq. moyblanc/eq:scalEblanc: <E>/(D t/4) -> 1 (omega = 0, where no trapped phase biases it)."""
    D, t = 1.0, 100.0
    ds = stochpend.simulate(noise="white", D=D, omega=0.0, paths=8000, t_max=t, times=[t], seed=SEED)
    row = ds.isel(time=-1)
    z = (float(row.mean_E) - D * t / 4) / float(row.mean_E_stderr)
    assert abs(z) < Z_TOL, f"<E> = {float(row.mean_E):.3f} vs Dt/4 = {D * t / 4}: z = {z:+.2f}"
    # a broken factor (Dt/2 or Dt/8) would be tens of standard errors away
    assert float(row.mean_E_stderr) < 0.05 * D * t / 4


@pytest.mark.parametrize("omega", [0.0, 1.0])
def test_white_noise_energy_identity_on_the_ensemble(omega):
    """Exact: dE = -Omega sin(theta) o dW, i.e. (Ito) d<E>/dt = (D/2) <sin^2 theta>.

    Integrated: <E>(t) - <E>(0) = (D/2) int_0^t <sin^2 theta> ds. Both sides are measured on the
    same ensemble; their difference is the mean of a martingale (bounded by the SE of <E>) plus
    the trapezoid error of the time integral (bounded by the curvature of <sin^2>, tiny here).
    """
    D, t_max = 2.0, 20.0
    times = np.linspace(0.0, t_max, 201)
    ds = stochpend.simulate(noise="white", D=D, omega=omega, paths=40_000, t_max=t_max, times=times,
                            seed=SEED + 1)
    s2 = ds.mean_sin2theta.values
    integral = 0.5 * D * np.concatenate([[0.0], np.cumsum(0.5 * (s2[1:] + s2[:-1]) * np.diff(times))])
    lhs = ds.mean_E.values - ds.mean_E.values[0]
    se = ds.mean_E_stderr.values
    z = (lhs[1:] - integral[1:]) / se[1:]
    assert np.max(np.abs(z)) < Z_TOL, f"identity violated: max |z| = {np.max(np.abs(z)):.2f}"
    # the identity has teeth: a 5 % error in the noise amplitude is caught
    z_wrong = (lhs[-1] - 1.05 * integral[-1]) / se[-1]
    assert abs(z_wrong) > Z_TOL


def test_ou_process_mean_variance_and_autocorrelation():
    """The OU noise as the kernel evolves it: exact mean, variance, and correlation at lags h, 5h."""
    D, tau, h, xi0, n = 1.5, 0.7, 0.3, 2.0, 200_000
    kern = kernels("ou", "harmonic", adaptive=False)
    p = Paths(n)  # x = 0, Omega = 0 and harmonic: the oscillator stays at rest, xi evolves freely
    p.xi[:] = xi0
    xi, t = p.xi, p.t

    def run(t_stop):
        p.advance(kern, t_stop, 10**9, SEED, D=D, tau=tau, omega2=0.0, h_max=h)

    t1 = 2.0 * h
    run(t1)
    mean_exact = xi0 * math.exp(-t1 / tau)
    var_exact = D / (2 * tau) * (1 - math.exp(-2 * t1 / tau))
    z_mean = (xi.mean() - mean_exact) / math.sqrt(var_exact / n)
    z_var = (xi.var() - var_exact) / (var_exact * math.sqrt(2.0 / n))
    assert abs(z_mean) < Z_TOL, f"OU mean {xi.mean():.5f} vs {mean_exact:.5f}: z = {z_mean:+.2f}"
    assert abs(z_var) < Z_TOL, f"OU variance {xi.var():.5f} vs {var_exact:.5f}: z = {z_var:+.2f}"
    # autocovariance at lags h and 5h: Cov(xi(t1), xi(t1 + L)) = exp(-L/tau) Var(xi(t1))
    start = xi.copy()
    for lag_steps in (1, 4):  # cumulative: lags h and 5h
        run(t[0] + lag_steps * h)
        lag = t[0] - t1
        cov = np.mean((start - start.mean()) * (xi - xi.mean()))
        cov_exact = math.exp(-lag / tau) * var_exact
        var_end = D / (2 * tau) * (1 - math.exp(-2 * t[0] / tau))
        se = math.sqrt((var_exact * var_end + cov_exact**2) / n)
        z = (cov - cov_exact) / se
        assert abs(z) < Z_TOL, f"lag {lag:.2f}: cov {cov:.5f} vs {cov_exact:.5f}: z = {z:+.2f}"


def test_ou_noise_integral_composes_exactly():
    """Composition: one exact step of 8h and eight exact steps of h give the same (xi, int xi) law.

    The sampled pair's joint Gaussian law is checked through the kick it gives a free particle:
    harmonic potential with omega = 0, x = 1 fixed... instead we accumulate the noise integral
    directly from the coefficient formula, drawing normals from Philox.
    """
    D, tau, h, n = 1.0, 0.5, 0.2, 200_000
    rs = np.random.default_rng(SEED)
    xi0 = rs.normal(0.0, math.sqrt(D / (2 * tau)), n)
    # one step of 8h
    a, s_xi, m_I, c_I, s_I = ou.step_coefficients(8 * h, (D, tau))
    z1, z2 = rs.normal(size=n), rs.normal(size=n)
    I_big = m_I * xi0 + c_I * z1 + s_I * z2
    xi_big = a * xi0 + s_xi * z1
    # eight steps of h
    a, s_xi, m_I, c_I, s_I = ou.step_coefficients(h, (D, tau))
    xi, I_small = xi0.copy(), np.zeros(n)
    for _ in range(8):
        z1, z2 = rs.normal(size=n), rs.normal(size=n)
        I_small += m_I * xi + c_I * z1 + s_I * z2
        xi = a * xi + s_xi * z1
    for name, u, v in (("var I", I_big**2, I_small**2), ("cov(I, xi')", I_big * xi_big, I_small * xi),
                       ("cov(I, xi0)", I_big * xi0, I_small * xi0)):
        se = math.sqrt(u.var() / n + v.var() / n)
        z = (u.mean() - v.mean()) / se
        assert abs(z) < Z_TOL, f"{name}: {u.mean():.5f} (one step) vs {v.mean():.5f} (eight): z = {z:+.2f}"


def test_results_do_not_depend_on_threads_or_chunks():
    for noise in ("ou", "white"):
        kw = dict(noise=noise, D=1.0, tau=0.5, omega=1.0, paths=1000, t_max=10.0, n_times=5, seed=SEED)
        a = stochpend.simulate(**kw, threads=2)
        b = stochpend.simulate(**kw, threads=1, chunk_paths=70)
        c = stochpend.simulate(**kw, chunk_paths=400)
        for v in a.data_vars:
            assert np.array_equal(a[v].values, b[v].values, equal_nan=True), f"{noise}: {v} differs (threads/chunks)"
            assert np.array_equal(a[v].values, c[v].values, equal_nan=True), f"{noise}: {v} differs (chunks)"
        d = stochpend.simulate(**{**kw, "seed": SEED + 1})
        assert not np.array_equal(a.mean_E.values, d.mean_E.values), "the seed has no effect"


def test_nonfinite_paths_are_counted_and_excluded():
    """Quartic potential with a step far too large: large-amplitude paths blow up, others don't."""
    ds = stochpend.simulate(noise="white", D=0.0, omega=1.0, paths=400, t_max=20.0, n_times=3,
                            potential="power", power_n=2, h_max=1.0, step_c=0.0, seed=SEED)
    bad = ds.nonfinite_paths.values
    good = ds.n_finite_paths.values
    assert bad[-1] > 0 and good[-1] > 0, (bad, good)
    assert np.all(bad + good == 400)
    assert np.all(np.diff(bad) >= 0), "a path came back from non-finite"
    for v in ("mean_E", "mean_E2", "mean_Omega2", "skewness", "flatness"):
        assert np.all(np.isfinite(ds[v].values)), f"{v} averaged in a non-finite path"
    assert int(ds.E_hist.sum(dim="E_bin")[-1] + ds.E_hist_overflow[-1] + ds.E_hist_underflow[-1]) == good[-1]


def test_histogram_counts_every_finite_path():
    ds = stochpend.simulate(noise="ou", D=1.0, tau=1.0, omega=1.0, paths=3000, t_max=50.0, n_times=4, seed=SEED)
    total = ds.E_hist.sum(dim="E_bin") + ds.E_hist_overflow + ds.E_hist_underflow
    assert np.all(total.values == 3000)
    assert int(ds.E_hist_underflow.sum()) == 0  # E >= -omega^2 always
    edges = ds.E_bin_edges.values
    assert np.all(np.diff(edges, axis=1) > 0)
    # the binned mean agrees with the exact mean within the bin resolution
    mids = 0.5 * (edges[:, 1:] + edges[:, :-1])
    binned = (ds.E_hist.values * mids).sum(axis=1) / ds.E_hist.values.sum(axis=1)
    width = np.diff(edges, axis=1).max(axis=1)
    assert np.all(np.abs(binned - ds.mean_E.values) < width)


def test_results_do_not_depend_on_kernel_call_budget():
    """Segments longer than one kernel call's step budget are split; the clock must not notice."""
    import importlib

    sim_mod = importlib.import_module("stochpend.engine.cpu")
    # 200 time units are > 4000 steps a path: several calls of the minimum 1000-step budget
    kw = dict(noise="ou", D=1.0, tau=0.5, omega=1.0, paths=64, t_max=200.0, times=[200.0], seed=SEED)
    a = stochpend.simulate(**kw)
    saved = sim_mod.WORK_PER_CALL
    try:
        sim_mod.WORK_PER_CALL = 1  # every call takes the minimum budget: many calls per segment
        b = stochpend.simulate(**kw)
    finally:
        sim_mod.WORK_PER_CALL = saved
    for v in a.data_vars:
        assert np.array_equal(a[v].values, b[v].values, equal_nan=True), f"{v} depends on the call budget"
