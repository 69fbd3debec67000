"""Calibration of simulate(target_error=...) (issue 35, "Calibrated"): over 100 seeds of cases
with exact answers, the reported total error (statistical half-width + bias bound, 95 %)
covers the true error |estimate - exact| in at least 90 % of runs, and the reported cost is
the path-steps spent.

Cases (stochpend.theory.family, the damped family with additive white noise D_a, started in
its Boltzmann law exp(-E/T), T = D_a/(2 gamma), so that the exact law is stationary):
* the pendulum: <E> = T/2 - omega^2 I1/I0(omega^2/T), <E^2> = 3T^2/4 - omega^2 T I1/I0 +
  omega^4 (1/2 + I2/(2 I0)) (Omega ~ N(0, T) independent of the von Mises angle);
* the harmonic oscillator: E/T ~ Exp(1), <E> = T, <E^2> = 2 T^2. Its scheme's stationary
  <Omega^2> is T/(1 - h^2 omega^2/4) (test_family_dynamics): at h_max = 1 level 0 alone is
  biased by T/6, 17 % of <E>, so the telescope and the bias bound carry the result.
* the random-frequency oscillator x'' + gamma x' + (omega^2 + xi) x = 0, xi white (parametric
  noise, no additive one), from (x, Omega) = (1, 0): its second moments close (Ito =
  Stratonovich here), d/dt (<x^2>, <x Omega>, <Omega^2>) = M (...) with M
  family.random_frequency_moment_matrix, so <E>(t) = expm(M t) exactly; <E> only (<E^2> needs the
  fourth moments). At h_max = 0.5 level 0 alone is about 7 % high.
* the paper's skewness S and flatness F of the same two Boltzmann laws (functions of means,
  errors by the jackknife): E/T ~ Exp(1) gives S = 6/2^(3/2), F = 6 for the harmonic oscillator;
  the pendulum's from its exact energy moments (family.boltzmann_pendulum_energy_moment).
Each takes a few minutes on two cores (make test-slow).
"""

from __future__ import annotations

import pytest

import stochpend
from stochpend.theory import family

SEEDS = 100
EPS = 0.01
COVERAGE = 0.90
GAMMA, D_A, OMEGA = 0.5, 0.4, 1.0
T = family.temperature(D_a=D_A, gamma=GAMMA)


def _exact(potential: str) -> dict[str, float]:
    if potential == "harmonic":
        return {"mean_E": T, "mean_E2": 2.0 * T * T}
    c = family.boltzmann_pendulum_mean_cos(D_a=D_A, gamma=GAMMA, omega=OMEGA)
    c2 = family.boltzmann_pendulum_mean_cos2(D_a=D_A, gamma=GAMMA, omega=OMEGA)
    return {"mean_E": family.boltzmann_pendulum_mean_E(D_a=D_A, gamma=GAMMA, omega=OMEGA),
            "mean_E2": 0.75 * T * T - OMEGA**2 * T * c + OMEGA**4 * c2}


def _random_frequency_mean_E(D: float, gamma: float, omega: float, t: float) -> float:
    import numpy as np
    from scipy.linalg import expm

    m = expm(family.random_frequency_moment_matrix(D=D, gamma=gamma, omega=omega) * t) @ np.array([1.0, 0.0, 0.0])
    return 0.5 * float(m[2]) + 0.5 * omega**2 * float(m[0])


@pytest.mark.slow
def test_the_total_error_covers_the_random_frequency_oscillators_closed_moments():
    D, gamma, t = 0.5, 0.5, 2.0
    exact = _random_frequency_mean_E(D, gamma, OMEGA, t)
    covered = level0_off = 0
    for seed in range(SEEDS):
        ds = stochpend.simulate(noise="white", D=D, omega=OMEGA, potential="harmonic", theta0=1.0, Omega0=0.0,
                                t_max=t, times=(t,), h_max=0.5, gamma=gamma, seed=seed, target_error=EPS,
                                target_statistics=("mean_E",))
        assert ds.attrs["path_steps"] == int(ds["level_path_steps"].sum()) + ds.attrs["target_route_path_steps"]
        covered += abs(float(ds["mean_E"][0]) - exact) <= float(ds["mean_E_total_error"][0])
        level0_off += abs(float(ds["mean_E_level_mean"][0, 0]) - exact) > EPS * exact
    assert covered >= COVERAGE * SEEDS, covered
    assert level0_off == SEEDS  # the telescope and the bias bound carry the result


@pytest.mark.slow
@pytest.mark.parametrize("potential", ["pendulum", "harmonic"])
def test_the_reported_total_error_covers_the_true_error(potential):
    exact = _exact(potential)
    covered = {name: 0 for name in exact}
    level0_off = 0
    for seed in range(SEEDS):
        ds = stochpend.simulate(noise="white", D=0.0, omega=OMEGA, potential=potential, t_max=2.0, times=(2.0,),
                                h_max=1.0, seed=seed, gamma=GAMMA, additive_D=D_A, initial_temperature=T,
                                target_error=EPS)
        assert ds.attrs["path_steps"] == int(ds["level_path_steps"].sum()) + ds.attrs["target_route_path_steps"]
        for name, want in exact.items():
            covered[name] += abs(float(ds[name][0]) - want) <= float(ds[f"{name}_total_error"][0])
        level0_off += abs(float(ds["mean_E_level_mean"][0, 0]) - exact["mean_E"]) > EPS * abs(exact["mean_E"])
    for name, n in covered.items():
        assert n >= COVERAGE * SEEDS, (potential, name, n)
    if potential == "harmonic":  # the bias is the point: level 0 alone misses the target
        assert level0_off == SEEDS


def _exact_skewness_flatness(potential: str) -> dict[str, float]:
    """The paper's S = <E^3>/<E^2>^(3/2) and F = <E^4>/<E^2>^2 of the Boltzmann law: E/T ~ Exp(1)
    for the harmonic oscillator (<E^n> = n! T^n), the pendulum's from its energy moments."""
    if potential == "harmonic":
        return {"skewness": 6.0 / 2.0**1.5, "flatness": 6.0}
    m2, m3, m4 = (family.boltzmann_pendulum_energy_moment(n, D_a=D_A, gamma=GAMMA, omega=OMEGA) for n in (2, 3, 4))
    return {"skewness": m3 / m2**1.5, "flatness": m4 / m2**2}


@pytest.mark.slow
@pytest.mark.parametrize("potential", ["pendulum", "harmonic"])
def test_the_total_error_of_skewness_and_flatness_covers_the_true_error(potential):
    """The nonlinear statistics as targets (functions of means, jackknife errors), the same two
    Boltzmann cases as the means'."""
    exact = _exact_skewness_flatness(potential)
    covered = {name: 0 for name in exact}
    for seed in range(SEEDS):
        ds = stochpend.simulate(noise="white", D=0.0, omega=OMEGA, potential=potential, t_max=2.0, times=(2.0,),
                                h_max=1.0, seed=seed, gamma=GAMMA, additive_D=D_A, initial_temperature=T,
                                target_error=EPS, target_statistics=tuple(exact))
        assert ds.attrs["path_steps"] == int(ds["level_path_steps"].sum()) + ds.attrs["target_route_path_steps"]
        for name, want in exact.items():
            covered[name] += abs(float(ds[name][0]) - want) <= float(ds[f"{name}_total_error"][0])
    for name, n in covered.items():
        assert n >= COVERAGE * SEEDS, (potential, name, n)


@pytest.mark.slow
@pytest.mark.parametrize("potential", ["pendulum", "harmonic"])
def test_the_total_error_of_a_time_average_and_a_running_sum_covers_the_true_error(potential):
    """Per-path accumulators as targets (each coupled member tracks its own steps): in the
    stationary Boltzmann law the time average of E over [0, t] has the exact mean <E>, and the
    running integral of E the mean <E> t, at every t."""
    from stochpend.model import observables as obs

    mean_E = _exact(potential)["mean_E"]
    t = 2.0
    import math

    if potential == "harmonic":  # E as the run's table has it (stochpend.model.oscillators)
        def average(x, Omega, xi, t):
            return 0.5 * Omega * Omega + 0.5 * x * x

        def integral(x0, O0, xi0, x1, O1, xi1, t0, t1):
            return 0.25 * (t1 - t0) * (O0 * O0 + x0 * x0 + O1 * O1 + x1 * x1)
    else:
        def average(x, Omega, xi, t):
            return 0.5 * Omega * Omega - math.cos(x)

        def integral(x0, O0, xi0, x1, O1, xi1, t0, t1):
            return 0.5 * (t1 - t0) * (0.5 * O0 * O0 - math.cos(x0) + 0.5 * O1 * O1 - math.cos(x1))
    exact = {"mean_cal_E_avg": mean_E, "mean_cal_E_int": mean_E * t}
    registry = dict(obs._REGISTRY)
    covered = {name: 0 for name in exact}
    try:
        obs.register(obs.TimeAverage("cal_E_avg", average, window=(0.0, t)))
        obs.register(obs.RunningSum("cal_E_int", integral))
        for seed in range(SEEDS):
            ds = stochpend.simulate(noise="white", D=0.0, omega=OMEGA, potential=potential, t_max=t, times=(t,),
                                    h_max=1.0, seed=seed, gamma=GAMMA, additive_D=D_A, initial_temperature=T,
                                    observables=("cal_E_avg", "cal_E_int"), target_error=EPS,
                                    target_statistics=tuple(exact))
            assert ds.attrs["path_steps"] == int(ds["level_path_steps"].sum()) + ds.attrs["target_route_path_steps"]
            for name, want in exact.items():
                covered[name] += abs(float(ds[name][0]) - want) <= float(ds[f"{name}_total_error"][0])
    finally:
        obs._REGISTRY.clear()
        obs._REGISTRY.update(registry)
    for name, n in covered.items():
        assert n >= COVERAGE * SEEDS, (potential, name, n)


@pytest.mark.slow
def test_the_total_error_of_the_displacements_variance_covers_the_true_error():
    """A running sum's variance and effective diffusion (functions of its two columns' means):
    the displacement of the damped harmonic oscillator in its Boltzmann law, whose variance is
    2 T (1 - C(t)) / omega^2 with C the stationary position autocorrelation."""
    import math

    import numpy as np

    t = 2.0
    w1 = math.sqrt(OMEGA**2 - GAMMA**2 / 4)
    C = math.exp(-GAMMA * t / 2) * (math.cos(w1 * t) + GAMMA / (2 * w1) * math.sin(w1 * t))
    var = 2 * T / OMEGA**2 * (1 - C)
    exact = {"var_displacement": var, "diffusion_displacement": var / (2 * t)}
    covered = {name: 0 for name in exact}
    for seed in range(SEEDS):
        ds = stochpend.simulate(noise="white", D=0.0, omega=OMEGA, potential="harmonic", t_max=t, times=(t,),
                                h_max=1.0, seed=seed, gamma=GAMMA, additive_D=D_A, initial_temperature=T,
                                observables=("displacement",), target_error=EPS, target_statistics=tuple(exact))
        for name, want in exact.items():
            covered[name] += abs(float(ds[name][0]) - want) <= float(ds[f"{name}_total_error"][0])
        kurt = ds["var_displacement_level_kurtosis"].values  # level 0 has no difference
        assert np.isnan(kurt[0]).all() and (kurt[1:] >= 1.0).all(), kurt
    for name, n in covered.items():
        assert n >= COVERAGE * SEEDS, (name, n)
