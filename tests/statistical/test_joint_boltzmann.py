"""The joint (x, Omega) histogram of the damped pendulum with additive white noise (gamma > 0,
D_a > 0, no parametric noise) against its stationary law, Boltzmann at T = D_a / (2 gamma):
P(x, Omega) = exp(-Omega^2 / 2T) / sqrt(2 pi T) * exp(omega^2 cos x / T) / (2 pi I0(omega^2/T)).

Each bin's exact probability is the product of the Gaussian's integral over the Omega bin
(erf) and the von Mises law's over the x bin (quadrature); the histogram's bin probabilities
are compared with it bin by bin (z with the run's own standard errors, |z| < 4) and as a whole
(Pearson's chi-square over the bins and the outside cell, against its degrees of freedom).
The parameters are test_family_dynamics.py's (its <Omega^2> and <E> tests hold there at this
step control)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy import integrate, special, stats

import stochpend
from stochpend.theory import family

Z = 4.0
GAMMA, D_A, OMEGA = 0.5, 0.4, 1.0


def _boltzmann_cells(x_edges: np.ndarray, O_edges: np.ndarray, T: float) -> np.ndarray:
    """Exact probabilities of the bins (nx, nO) under the Boltzmann law at T."""
    k = OMEGA**2 / T
    norm = 2.0 * math.pi * special.i0(k)
    px = np.array([integrate.quad(lambda x: math.exp(k * math.cos(x)), a, b, epsabs=0, epsrel=1e-12)[0]
                   for a, b in zip(x_edges[:-1], x_edges[1:], strict=True)]) / norm
    cdf = 0.5 * (1.0 + special.erf(O_edges / math.sqrt(2.0 * T)))
    pO = np.diff(cdf)
    return px[:, None] * pO[None, :]


def _z(ds, j: int, p: np.ndarray) -> np.ndarray:
    """Each bin's density against ``p / area`` in its standard errors, over the bins where
    Boltzmann expects at least 10 paths (an empty bin has no error of its own)."""
    area = np.diff(ds.x_bin_edges.values[j])[:, None] * np.diff(ds.Omega_bin_edges.values[j])[None, :]
    n = float(ds.n_finite_paths.values[j])
    populated = n * p >= 10.0
    assert populated.sum() >= 0.4 * p.size, populated.sum()
    return (ds.joint_density.values[j] - p / area)[populated] / ds.joint_density_stderr.values[j][populated]


def _compare(ds, j: int) -> tuple[float, int, float, float]:
    """(chi-square, degrees of freedom, its p-value, max |z|) of output time j."""
    T = family.temperature(D_a=D_A, gamma=GAMMA)
    x_edges, O_edges = ds.x_bin_edges.values[j], ds.Omega_bin_edges.values[j]
    p = _boltzmann_cells(x_edges, O_edges, T)
    counts = ds.joint_hist.values[j].astype(np.float64)
    n = float(ds.n_finite_paths.values[j])
    z = _z(ds, j, p)
    expected = np.append(n * p.ravel(), n * (1.0 - p.sum()))
    observed = np.append(counts.ravel(), float(ds.joint_hist_outside.values[j]))
    chi2 = float(((observed - expected) ** 2 / expected).sum())
    dof = observed.size - 1
    return chi2, dof, float(stats.chi2.sf(chi2, dof)), float(np.max(np.abs(z)))


@pytest.fixture(scope="module")
def relaxing():
    """test_family_dynamics.py's run: 40 000 paths from rest at uniform angles; t = 4 (not
    relaxed yet: the energy relaxes like exp(-gamma t)), 20 and 40."""
    return stochpend.simulate(noise="white", D=0.0, omega=OMEGA, paths=40_000, t_max=40.0, times=(4.0, 20.0, 40.0),
                              seed=3, gamma=GAMMA, additive_D=D_A, bias_paths=0, joint_bins=(12, 8),
                              joint_Omega_max=1.6)


@pytest.mark.parametrize("j", [1, 2])
def test_the_damped_pendulum_relaxes_to_the_boltzmann_joint_law(relaxing, j):
    chi2, dof, pvalue, zmax = _compare(relaxing, j)
    assert zmax < Z, zmax
    assert pvalue > 1e-4, (chi2, dof, pvalue)
    # the Omega range is +-2.5 thermal standard deviations: about 1.2% of the paths outside
    assert 0.005 * 40_000 < int(relaxing.joint_hist_outside[j]) < 0.02 * 40_000


def test_the_check_sees_an_ensemble_not_yet_relaxed_and_a_wrong_temperature(relaxing):
    """The comparison can fail: at t = 4 the ensemble is still hotter than Boltzmann, and the
    relaxed histogram is far from Boltzmann at 0.8 T."""
    chi2, dof, pvalue, zmax = _compare(relaxing, 0)
    assert pvalue < 1e-6 and zmax > Z, (chi2, dof, pvalue, zmax)
    T = family.temperature(D_a=D_A, gamma=GAMMA)
    p = _boltzmann_cells(relaxing.x_bin_edges.values[-1], relaxing.Omega_bin_edges.values[-1], 0.8 * T)
    assert float(np.max(np.abs(_z(relaxing, -1, p)))) > Z
