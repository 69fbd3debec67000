"""The family's terms (issue 23): damping, torque, drives, additive white noise.

References, each tested in standard errors or exactly:
* every term zero is today's kernel, bit for bit;
* the damped harmonic oscillator with multiplicative white noise on the force and additive white
  noise has closed second moments; the scheme, linear in the state, has an exact moment map
  (as in test_weak_order.py), so its weak order is measured without sampling noise: 2;
* with damping and additive noise only, the harmonic oscillator's stationary <x^2> is
  Boltzmann's T/omega^2 exactly for every gamma h (up to gamma h = 2), <Omega^2> =
  T/(1 - h^2 omega^2/4) (Stormer-Verlet's modified energy), independent of gamma;
* the pendulum's Boltzmann law <Omega^2> = T, <E> = T/2 - omega^2 I1/I0(omega^2/T)
  (stochpend.theory.family, independent code), at |z| < 4 with a relative error <= 1 %;
* the free particle with torque (omega = 0): <x(t) - x(0)> and var(x(t) - x(0)) of the
  Ornstein-Uhlenbeck velocity from rest, exactly;
* the damped driven harmonic oscillator: its steady amplitude A / sqrt((omega^2 - nu^2)^2 +
  gamma^2 nu^2), to the scheme's second order.
"""

from __future__ import annotations

import json
import math
import os
import subprocess
import sys
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest
from scipy.linalg import expm, solve_discrete_lyapunov

import stochpend
from stochpend.engine import integrator
from stochpend.model import dynamics
from stochpend.observables import TimeAverage, register, unregister
from stochpend.theory import family
from tests._checkpoints import StopAfter
from tests._lanes import assert_lanes_equal_one_path

Z = 4.0


def _record(**values):
    return dynamics.record(SimpleNamespace(dyn_params=dynamics.resolve(values)))


def _maps(h, d, terms):
    """(B0, B1, a) of one step of the damped harmonic oscillator, noise on the force (G = x):
    z' = (B0 + I B1) z + za a, read off the kernel's own step function."""
    return integrator.linear_step_maps(h, d, terms)


def _scheme_moments(h, n, D, d, terms, x0=1.0):
    B0, B1, a = _maps(h, d, terms)
    M = np.array([[x0 * x0, 0.0], [0.0, 0.0]])
    for _ in range(n):
        M = B0 @ M @ B0.T + D * h * (B1 @ M @ B1.T) + np.outer(a, a)
    return np.array([M[0, 0], M[0, 1], M[1, 1]])


def _exact_moments(t, D, gamma, D_a, x0=1.0):
    """(<x^2>, <x Omega>, <Omega^2>) from the closed moment equations (omega = 1, <xi xi'> =
    D delta on the force, additive <xi_a xi_a'> = D_a delta), start (x0, 0)."""
    A = np.zeros((4, 4))
    A[:3, :3] = [[0.0, 2.0, 0.0], [-1.0, -gamma, 1.0], [D, -2.0, -2.0 * gamma]]
    A[2, 3] = D_a
    return (expm(A * t) @ np.array([x0 * x0, 0.0, 0.0, 1.0]))[:3]


RUN = dict(noise="ou", D=1.0, tau=1.0, omega=1.0, paths=2000, t_max=10.0, n_times=4, seed=11, bias_paths=64)


def test_every_term_zero_is_todays_kernel_bit_for_bit():
    plain = stochpend.simulate(**RUN)
    zero = stochpend.simulate(**RUN, gamma=0.0, torque=0.0, drive_amplitude=0.0, parametric_amplitude=0.0,
                              additive_D=0.0, drive_frequency=2.0)
    assert "dynamics_parameters" not in zero.attrs or zero.attrs["dynamics_parameters"] == "drive_frequency=2"
    for name in plain.data_vars:
        assert np.array_equal(plain[name].values, zero[name].values, equal_nan=True), name


def test_weak_order_two_with_damping_and_both_noise_channels():
    """Exact moment maps, no sampling: the error of <x^2>, <x Omega>, <Omega^2> at t = 4 falls as
    h^2 with damping, the multiplicative white noise and the additive white noise all on."""
    D, gamma, D_a, T = 0.5, 0.7, 0.3, 4.0
    d = _record(gamma=gamma, additive_D=D_a)
    exact = _exact_moments(T, D, gamma, D_a)
    hs = [T / n for n in (20, 40, 80, 160, 320)]
    errors = [np.max(np.abs(_scheme_moments(h, round(T / h), D, d, {"damping", "additive"}) - exact)) for h in hs]
    slopes = np.diff(np.log(errors)) / np.diff(np.log(hs))
    order = np.polyfit(np.log(hs), np.log(errors), 1)[0]
    assert abs(order - 2.0) < 0.2 and np.all(np.abs(slopes - 2.0) < 0.2), (order, slopes)


def test_the_kernel_follows_its_moment_map():
    D, gamma, D_a, h = 0.5, 0.7, 0.3, 0.1
    times = (1.0, 4.0)
    ds = stochpend.simulate(noise="white", D=D, omega=1.0, potential="harmonic", paths=100_000, t_max=4.0,
                            times=times, seed=7, theta0=1.0, Omega0=0.0, h_max=h, step_c=0.0, gamma=gamma,
                            additive_D=D_a, bias_paths=0)
    d = _record(gamma=gamma, additive_D=D_a)
    for i, t in enumerate(times):
        x2, _, O2 = _scheme_moments(h, round(t / h), D, d, {"damping", "additive"})
        for name, want in (("mean_sin2theta", x2), ("mean_Omega2", O2)):
            z = (float(ds[name][i]) - want) / float(ds[f"{name}_stderr"][i])
            assert abs(z) < Z, (t, name, float(ds[name][i]), want, z)


@pytest.mark.parametrize("gamma_h", [0.1, 1.0, 2.0])
def test_the_harmonic_boltzmann_law_holds_for_every_gamma_h(gamma_h):
    """Stationary law of the scheme (discrete Lyapunov equation of its exact map): <x^2> =
    T/omega^2 to round-off, <Omega^2> = T / (1 - h^2 omega^2 / 4), whatever gamma h."""
    h, D_a = 0.2, 0.4
    gamma = gamma_h / h
    T = family.temperature(D_a=D_a, gamma=gamma)
    B0, _, a = _maps(h, _record(gamma=gamma, additive_D=D_a), {"damping", "additive"})
    M = solve_discrete_lyapunov(B0, np.outer(a, a))
    assert M[0, 0] == pytest.approx(T, rel=1e-12)
    assert M[1, 1] == pytest.approx(T / (1 - h * h / 4), rel=1e-12)
    assert abs(M[0, 1]) < 1e-12 * T


def test_the_pendulum_reaches_the_boltzmann_law():
    gamma, D_a, omega = 0.5, 0.4, 1.0
    ds = stochpend.simulate(noise="white", D=0.0, omega=omega, paths=40_000, t_max=40.0, times=(20.0, 40.0),
                            seed=3, gamma=gamma, additive_D=D_a, bias_paths=0)
    refs = {"mean_Omega2": family.boltzmann_mean_Omega2(D_a=D_a, gamma=gamma),
            "mean_E": family.boltzmann_pendulum_mean_E(D_a=D_a, gamma=gamma, omega=omega)}
    for name, want in refs.items():
        value, se = ds[name].values, ds[f"{name}_stderr"].values
        z = (value - want) / se
        assert np.all(np.abs(z) < Z), (name, value, want, z)
        assert np.all(se / abs(want) <= 0.01), (name, se / abs(want))


def test_the_free_particle_with_torque_drifts_and_diffuses_as_its_exact_law():
    """omega = 0: Omega is an OU process from rest, Omega(t) -> F/gamma; x(t) - x(0) has mean
    (F/gamma)(t - (1 - e^{-gamma t})/gamma) and variance (2T/gamma)(t - (3 - 4e^{-gamma t} +
    e^{-2 gamma t})/(2 gamma)), T = D_a/(2 gamma): D_eff = T/gamma."""
    gamma, D_a, F = 1.0, 0.5, 0.3
    T = D_a / (2 * gamma)
    ds = stochpend.simulate(noise="white", D=0.0, omega=0.0, paths=40_000, t_max=20.0, times=(2.0, 20.0), seed=5,
                            Omega0=0.0, gamma=gamma, additive_D=D_a, torque=F, bias_paths=0,
                            observables=("displacement",))
    t = ds.time.values
    e = np.exp(-gamma * t)
    mean = F / gamma * (t - (1 - e) / gamma)
    var = 2 * T / gamma * (t - (3 - 4 * e + e * e) / (2 * gamma))
    z_mean = (ds.mean_displacement.values - mean) / ds.mean_displacement_stderr.values
    z_var = (ds.var_displacement.values - var) / ds.var_displacement_stderr.values
    assert np.all(np.abs(z_mean) < Z) and np.all(np.abs(z_var) < Z), (z_mean, z_var)
    assert family.free_particle_diffusion(D_a=D_a, gamma=gamma) == pytest.approx(T / gamma)


@pytest.fixture
def x2_late():
    register(TimeAverage("x2_late", lambda x, Omega, xi, t: x * x, window=(40.0, 40.0 + math.pi)))
    yield
    unregister("x2_late")


def test_the_damped_driven_oscillator_reaches_its_steady_amplitude(x2_late):
    """D = 0: x'' + gamma x' + x = A cos(nu t); after the transient (e^{-gamma t/2} < 1e-8) the
    time average of x^2 over one period 2 pi/nu is amplitude^2/2. The error falls ~4-fold per
    halved step (the drive's exact integral keeps the scheme's order)."""
    gamma, A, nu = 1.0, 0.8, 2.0
    amp2 = A * A / ((1 - nu * nu) ** 2 + (gamma * nu) ** 2)
    errors = []
    for h in (0.02, 0.01, 0.005):
        ds = stochpend.simulate(potential="harmonic", noise="white", D=0.0, omega=1.0, paths=4, theta0=0.3,
                                Omega0=0.0, t_max=40.0 + math.pi, times=(40.0, 40.0 + math.pi), h_max=h,
                                step_c=0.0, gamma=gamma, drive_amplitude=A, drive_frequency=nu, bias_paths=0,
                                observables=("x2_late",))
        errors.append(abs(float(ds.mean_x2_late[-1]) - amp2 / 2))
    assert errors[-1] < 1e-4 * amp2, errors
    ratios = np.array(errors[:-1]) / np.array(errors[1:])
    assert np.all((ratios > 3.5) & (ratios < 4.5)), (errors, ratios)


def test_a_fixed_point_is_accepted_when_a_term_can_leave_it():
    with pytest.raises(ValueError, match="fixed point"):
        stochpend.simulate(noise="ou", theta0=0.0, Omega0=0.0, paths=10, t_max=1.0, n_times=2)
    ds = stochpend.simulate(noise="ou", theta0=0.0, Omega0=0.0, paths=100, t_max=1.0, n_times=2, gamma=1.0,
                            additive_D=0.5, bias_paths=0)
    assert float(ds.mean_Omega2[-1]) > 0


@pytest.mark.parametrize("kwargs, message", [
    (dict(gamma=-1.0), "gamma=-1.0 is not accepted: a finite number in [0, inf)"),
    (dict(drive_frequency=0.0), "drive_frequency=0.0 is not accepted"),
    (dict(additive_D=math.nan), "additive_D=nan is not accepted"),
])
def test_a_bad_term_is_refused_in_one_line(kwargs, message):
    with pytest.raises(ValueError, match=message.replace("(", r"\(").replace(")", r"\)").replace("[", r"\[")) as info:
        stochpend.simulate(**RUN, **kwargs)
    assert "\n" not in str(info.value)


def test_a_checkpointed_damped_run_resumes_to_the_same_numbers(tmp_path):
    from stochpend.model.settings import SimulationConfig
    from stochpend.runs import checkpoint as ck
    from stochpend.runs.simulate import run

    config = SimulationConfig.build(noise="ou", D=1.0, tau=1.0, omega=1.0, paths=300, t_max=10.0, n_times=4, seed=4,
                                    noise_params={"gamma": 0.3, "additive_D": 0.2, "torque": 0.1})
    ref = run(config, chunk_paths=90, bias_paths=64)

    path = tmp_path / "run.ckpt"
    with pytest.raises(KeyboardInterrupt):
        ck.run_checkpointed(config, checkpoint_path=path, every_s=None, chunk_paths=90, bias_paths=64,
                            checkpointer=StopAfter(path, None, config=config, n=5, chunk_paths=90))
    done = ck.resume(path)
    assert done.attrs["dynamics_parameters"] == "additive_D=0.2, gamma=0.3, torque=0.1"
    for name in ref.data_vars:
        assert np.array_equal(done[name].values, ref[name].values, equal_nan=True), name


_CUDASIM = """
import json
import stochpend
out = {}
for backend in ("cpu", "cuda"):
    ds = stochpend.simulate(noise="white", D=0.5, omega=1.0, paths=48, t_max=1.0, times=[0.5, 1.0], seed=3,
                            n_batches=4, backend=backend, bias_paths=16, gamma=0.7, additive_D=0.3, torque=0.2,
                            drive_amplitude=0.5, drive_frequency=1.5, parametric_amplitude=0.4, initial_temperature=0.3)
    out[backend] = {v: ds[v].values.tolist() for v in ("mean_E", "mean_Omega2", "mean_E_bias")}
print(json.dumps(out))
"""


@pytest.mark.gpu
def test_the_family_in_the_cuda_simulator_gives_the_cpu_numbers():
    env = {**os.environ, "NUMBA_ENABLE_CUDASIM": "1",
           "PYTHONPATH": os.pathsep.join([str(Path(stochpend.__file__).resolve().parents[1]),
                                          os.environ.get("PYTHONPATH", "")])}
    done = subprocess.run([sys.executable, "-c", _CUDASIM], env=env, capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, done.stderr[-3000:]
    r = json.loads(done.stdout.strip().splitlines()[-1])
    for name, cpu in r["cpu"].items():
        assert np.allclose(r["cuda"][name], cpu, rtol=1e-12, atol=1e-15), name


def test_a_sweep_over_the_damping_gives_each_runs_numbers():
    spec = {"base": {"noise": "white", "D": 0.5, "omega": 1.0, "paths": 200, "t_max": 4.0, "n_times": 2, "seed": 6,
                     "additive_D": 0.2},
            "grid": {"gamma": [0.0, 0.5]}}
    ds = stochpend.sweep.sweep(spec, scheduler="sync", bias_paths=0)
    for gamma in (0.0, 0.5):
        alone = stochpend.simulate(noise="white", D=0.5, omega=1.0, paths=200, t_max=4.0, n_times=2, seed=6,
                                   additive_D=0.2, gamma=gamma, bias_paths=0)
        got = ds.sel(gamma=gamma)
        assert np.array_equal(got.mean_E.values, alone.mean_E.values), gamma


FAMILY_RUN = dict(noise="ou", D=1.0, tau=1.0, omega=1.0, paths=600, t_max=6.0, n_times=3, seed=9, gamma=0.4,
                  additive_D=0.3, torque=0.2, drive_amplitude=0.3, drive_frequency=1.3, drive_phase=0.5,
                  parametric_amplitude=0.2, parametric_frequency=2.0)


@pytest.mark.parametrize("step", [dict(), dict(step_c=0.0, h_max=0.02)])
def test_the_lanes_run_the_family_with_the_one_path_numbers(step, monkeypatch):
    """The SIMD lane machines (the runs' and the pairs') against the one-path loops of the same
    fast-math KernelSpec: a run with an accumulator goes one path at a time, and must change no other
    number; the pairs' one-path kernel must give the lanes' bias estimate bit for bit."""
    from stochpend.engine import cpu
    from stochpend.model.settings import SimulationConfig

    config = SimulationConfig.build(**{k: v for k, v in FAMILY_RUN.items()
                                       if k not in dynamics.names()}, **step,
                                    noise_params={k: v for k, v in FAMILY_RUN.items() if k in dynamics.names()})
    assert integrator.lanes_supported(cpu.spec_for(config))
    assert_lanes_equal_one_path({**FAMILY_RUN, **step}, config, monkeypatch, finite_bias=False)


def test_the_typical_growth_of_the_damped_random_frequency_oscillator_is_its_lyapunov_exponent():
    """x'' + gamma x' + (omega^2 + xi) x = 0, white xi: <ln(E - E_min)> grows as 2 lambda t, lambda
    the top Lyapunov exponent (Riccati quadrature, stochpend.theory.family), while <E> grows at
    the larger mean-square rate. The slope between t = 100 and 200, with the two times' errors
    added in quadrature (an upper bound: the two means are positively correlated). Fixed steps:
    the linear oscillator's step control follows its amplitude, which grows exponentially."""
    D, gamma = 1.0, 0.2
    lam = family.random_frequency_lyapunov(D=D, gamma=gamma, omega=1.0)
    ds = stochpend.simulate(potential="harmonic", coupling="position", noise="white", D=D, omega=1.0, paths=8000,
                            t_max=200.0, times=(100.0, 200.0), seed=13, theta0=1.0, Omega0=0.0, gamma=gamma,
                            h_max=0.02, step_c=0.0, bias_paths=0, observables=("log_energy",))
    m, se = ds.mean_log_energy.values, ds.mean_log_energy_stderr.values
    slope = (m[1] - m[0]) / (2 * 100.0)
    z = (slope - lam) / (math.hypot(se[0], se[1]) / 200.0)
    assert abs(z) < Z, (slope, lam, z)
    assert np.all(ds.n_log_energy.values == 1.0)
    mean_rate = family.random_frequency_moment_growth_rate(D=D, gamma=gamma, omega=1.0)
    assert mean_rate > 2 * lam  # the mean grows faster than the typical energy


@pytest.mark.slow
def test_the_pendulum_hops_at_the_kramers_rate():
    """Damped pendulum with additive white noise, gamma = 2 omega, Delta U/T = 5 (Delta U = 2
    omega^2): the spatial-diffusion regime (theory.family.kramers_regime). Hops of 2 pi to either
    side at rate k each give var(x(t) - x(0)) growing as 2 (2 pi)^2 k t; k from the growth between
    t = 2000 and 20000 (errors added in quadrature: an upper bound). Kramers' formula is high by
    about T/(2 Delta U) at this barrier (docs/theory.md, measured against the exact overdamped
    rate): the test asks for |z| < 4 against k_K (1 - T/(2 Delta U)), and for the uncorrected
    formula to be within its stated accuracy plus 4 standard errors. About 4 min on 2 cores."""
    gamma, T = 2.0, 0.4
    D_a = 2 * gamma * T
    assert family.kramers_regime(D_a=D_a, gamma=gamma, omega=1.0).startswith("spatial")
    ds = stochpend.simulate(noise="white", D=0.0, omega=1.0, paths=2000, t_max=20000.0, times=(2000.0, 20000.0),
                            seed=21, gamma=gamma, additive_D=D_a, bias_paths=0, observables=("displacement",))
    v, se, t = ds.var_displacement.values, ds.var_displacement_stderr.values, ds.time.values
    scale = 2 * (t[1] - t[0]) * (2 * math.pi) ** 2
    k, k_se = (v[1] - v[0]) / scale, math.hypot(se[0], se[1]) / scale
    k_K = family.kramers_rate_spatial_diffusion(D_a=D_a, gamma=gamma, omega=1.0)
    accuracy = T / (2 * 2.0)
    z = (k - k_K * (1 - accuracy)) / k_se
    assert abs(z) < Z, (k, k_se, k_K, z)
    assert abs(k / k_K - 1) < accuracy + 4 * k_se / k_K, (k, k_K)


@pytest.mark.parametrize("potential", ["pendulum", "harmonic", "power"])
def test_an_ensemble_started_from_the_boltzmann_law_is_there_and_stays(potential):
    """initial_temperature = T = D_a/(2 gamma): the first output time (t = 0.01) already shows
    the Boltzmann law, and so does every later one (the run starts in its stationary law). The
    x^4 oscillator (power_n = 2) is drawn by inverting its Gamma(1/4) law: ⟨E⟩ = T/2 + T/4."""
    gamma, D_a, omega = 0.5, 0.6, 1.0
    T = D_a / (2 * gamma)
    ds = stochpend.simulate(potential=potential, noise="white", D=0.0, omega=omega, paths=40_000, t_max=10.0,
                            times=(0.01, 2.0, 10.0), seed=17, gamma=gamma, additive_D=D_a, initial_temperature=T,
                            bias_paths=64)
    if potential == "power":
        E = family.boltzmann_power_mean_E(D_a=D_a, gamma=gamma, omega=omega, power_n=2)
    else:
        E = (family.boltzmann_pendulum_mean_E if potential == "pendulum" else family.boltzmann_harmonic_mean_E)(
            D_a=D_a, gamma=gamma, omega=omega)
    for name, want in (("mean_Omega2", T), ("mean_E", E)):
        z = (ds[name].values - want) / ds[f"{name}_stderr"].values
        assert np.all(np.abs(z) < Z), (name, ds[name].values, want, z)
    assert ds.attrs["initial_temperature"] == T and int(ds.nonfinite_paths[-1]) == 0


@pytest.mark.parametrize("power_n", [1, 2, 3])
def test_the_power_oscillators_boltzmann_start_has_the_exact_law_of_x(power_n):
    """The start alone (stochpend.model.initial.boltzmann, what every backend and the bias pairs use):
    <x^2> of U = x^(2n)/(2n) at temperature T against (2nT/omega^2)^(1/n) Gamma(3/2n)/Gamma(1/2n),
    <omega^2 U> against the virial T/(2n), x symmetric, and n = 1 the harmonic law."""
    from stochpend.model import initial
    from stochpend.model.settings import SimulationConfig

    T, omega, n = 0.7, 1.3, 50_000
    config = SimulationConfig.build(potential="power", power_n=power_n, noise="white", D=0.0, omega=omega,
                                    paths=n, t_max=1.0, n_times=2, seed=5,
                                    noise_params={"gamma": 1.0, "additive_D": 2 * T, "initial_temperature": T})
    x, Omega = initial.boltzmann(config, 0, n)
    checks = [(x**2, family.boltzmann_power_mean_x2(D_a=2 * T, gamma=1.0, omega=omega, power_n=power_n)),
              (omega**2 * x ** (2 * power_n) / (2 * power_n), T / (2 * power_n)), (x, 0.0), (Omega**2, T)]
    for values, want in checks:
        z = (values.mean() - want) / (values.std() / math.sqrt(n))
        assert abs(z) < Z, (power_n, values.mean(), want, z)
    again, _ = initial.boltzmann(config, 7, 10)
    assert np.array_equal(again, x[7:17])  # a function of (seed, path) alone


@pytest.mark.parametrize("kwargs, message", [
    (dict(potential="double-well", initial_temperature=0.5), "is not accepted for potential='double-well'"),
    (dict(omega=0.0, initial_temperature=0.5), "with omega=0.0"),
    (dict(initial_temperature=-1.0), "initial_temperature=-1.0 is not accepted"),
])
def test_a_boltzmann_start_that_cannot_be_drawn_is_refused_in_one_line(kwargs, message):
    from tests.unit._user_models import register_all

    register_all()  # a user's oscillator: no bounded proposal for its x
    with pytest.raises(ValueError, match=message.replace("(", r"\(").replace(")", r"\)")) as info:
        stochpend.simulate(noise="white", D=0.5, paths=100, t_max=1.0, n_times=2, **kwargs)
    assert "\n" not in str(info.value)
