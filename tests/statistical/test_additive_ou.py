"""The additive Ornstein-Uhlenbeck channel (issue 23): ``additive_tau`` tau_a > 0.

    dOmega/dt = ... + xi_a(t),  <xi_a(t) xi_a(s)> = D_a/(2 tau_a) exp(-|t - s|/tau_a)

References, each tested exactly or in standard errors:
* the scheme is linear for the damped harmonic oscillator, so its exact moment map on (x,
  Omega, xi_a) gives its stationary covariance without sampling: it tends to
  theory.family.harmonic_ou_additive_variances as h^2 (weak order 2), and as tau_a -> 0 to the
  white channel's scheme;
* the kernel against that law (4e4 paths, |z| < 4, relative standard error <= 1 %);
* the free particle without damping or force: Omega(t) - Omega(0) is the exact integral of the
  stationary xi_a, variance D_a [t - tau_a (1 - e^{-t/tau_a})] whatever h (this checks the
  stationary start and the exact integral together), and xi_a(0) itself has variance
  D_a/(2 tau_a);
* the SIMD lanes give the one-path loop's numbers, the bias pairs included; a checkpointed run
  resumes to the straight run's numbers (CPU, and CUDA in Numba's simulator); the CUDA
  simulator gives the CPU's numbers.
"""

from __future__ import annotations

import math
import subprocess
import sys
from types import SimpleNamespace

import numpy as np
import pytest
from scipy.linalg import solve_discrete_lyapunov

import stochpend
from stochpend.engine import integrator
from stochpend.model import dynamics, initial
from stochpend.noises.ou import step_coefficients
from stochpend.theory import family
from tests._checkpoints import StopAfter
from tests._lanes import assert_lanes_equal_one_path

Z = 4.0


def _record(**values):
    return dynamics.record(SimpleNamespace(dyn_params=dynamics.resolve(values)))


def _step(terms):
    additive = "ou" if "additive_noise" in terms else None  # the channel of the OU noise
    return integrator.build(integrator.spec("white", "harmonic", "force", adaptive=False,
                                            terms=frozenset(terms), additive=additive)).family_step


def _ou_stationary(h, gamma, D_a, tau, omega=1.0):
    """The scheme's stationary covariance of (x, Omega, xi_a): z' = A z + N w, w two standard
    normals, read off the kernel's own step function (linear in x, Omega and the integral I of
    xi_a, which the kernel takes as its ``za``) and the OU noise's exact update."""
    d = _record(gamma=gamma, additive_D=D_a, additive_tau=tau)
    step = _step({"damping", "additive_noise"})

    def apply(x, Omega, I):
        return np.array(step(x, Omega, h, omega * omega, 0.0, (0.0,), 0.0, h, I, d))

    B0 = np.column_stack([apply(1.0, 0.0, 0.0), apply(0.0, 1.0, 0.0)])
    b = apply(0.0, 0.0, 1.0)
    a, s_xi, m_I, c_I, s_I = step_coefficients(h, (D_a, tau))
    A = np.zeros((3, 3))
    A[:2, :2] = B0
    A[:2, 2] = b * m_I
    A[2, 2] = a
    N = np.zeros((3, 2))
    N[:2, 0] = b * c_I
    N[:2, 1] = b * s_I
    N[2, 0] = s_xi
    return solve_discrete_lyapunov(A, N @ N.T)


def _theory(gamma, D_a, tau, omega=1.0):
    v = family.harmonic_ou_additive_variances(D_a=D_a, tau=tau, gamma=gamma, omega=omega)
    return np.array([[v.mean_x2, v.mean_xOmega, v.mean_x_xi],
                     [v.mean_xOmega, v.mean_Omega2, v.mean_Omega_xi],
                     [v.mean_x_xi, v.mean_Omega_xi, v.mean_xi2]])


def test_the_schemes_stationary_law_tends_to_the_theory_as_h_squared():
    gamma, D_a, tau = 0.7, 0.8, 0.5
    exact = _theory(gamma, D_a, tau)
    hs = [0.2, 0.1, 0.05, 0.025]
    errors = [np.max(np.abs(_ou_stationary(h, gamma, D_a, tau) - exact)) for h in hs]
    slopes = np.diff(np.log(errors)) / np.diff(np.log(hs))
    assert np.all(np.abs(slopes - 2.0) < 0.2), (errors, slopes)
    # xi_a's own law is exact at every h (its update is the OU's exact one)
    assert _ou_stationary(0.2, gamma, D_a, tau)[2, 2] == pytest.approx(D_a / (2 * tau), rel=1e-12)


def test_a_short_correlation_time_gives_the_white_channels_scheme():
    """tau_a -> 0 at fixed h: xi_a's integral over a step becomes a white increment of variance
    D_a h, which enters the kick (half before, half after the damping's flow), where the white
    channel adds its exact O-flow normal in the middle. Both enter Omega_{n+1} alone (and x_{n+1}
    by h/2 times that), so the limit is the white scheme with its noise variance scaled by r =
    (1 + e)^2 h / 4 / ((1 - e^2) / (2 gamma)) = 1 + (gamma h)^2/12 + ..., e = exp(-gamma h): the
    same stationary law up to the schemes' O(h^2). The gap to that limit falls as tau_a."""
    gamma, D_a, h = 0.7, 0.8, 0.1
    d = _record(gamma=gamma, additive_D=D_a)
    step = _step({"damping", "additive"})
    B0 = np.column_stack([np.array(step(1.0, 0.0, h, 1.0, 0.0, (0.0,), 0.0, h, 0.0, d)),
                          np.array(step(0.0, 1.0, h, 1.0, 0.0, (0.0,), 0.0, h, 0.0, d))])
    a = np.array(step(0.0, 0.0, h, 1.0, 0.0, (0.0,), 0.0, h, 1.0, d))
    white = solve_discrete_lyapunov(B0, np.outer(a, a))
    e = math.exp(-gamma * h)
    r = (1 + e) ** 2 * h / 4 / ((1 - e * e) / (2 * gamma))
    assert abs(r - 1 - (gamma * h) ** 2 / 12) < 1e-6
    gaps = [np.max(np.abs(_ou_stationary(h, gamma, D_a, tau)[:2, :2] - r * white)) / white[1, 1]
            for tau in (1e-3, 1e-4, 1e-5)]
    assert gaps[-1] < 1e-4, gaps
    assert gaps[0] / gaps[1] > 5 and gaps[1] / gaps[2] > 5, gaps


def _rel_ok(ds, name, want):
    value, se = ds[name].values, ds[f"{name}_stderr"].values
    z = (value - want) / se
    assert np.all(np.abs(z) < Z), (name, value, want, z)
    assert np.all(se / abs(want) <= 0.01), (name, se / abs(want))
    return z


def test_the_damped_harmonic_oscillator_reaches_its_ou_driven_law():
    gamma, D_a, tau, h = 1.0, 1.0, 0.5, 0.02
    v = family.harmonic_ou_additive_variances(D_a=D_a, tau=tau, gamma=gamma, omega=1.0)
    E = family.harmonic_ou_additive_mean_E(D_a=D_a, tau=tau, gamma=gamma, omega=1.0)
    scheme = _ou_stationary(h, gamma, D_a, tau)  # its step bias, far below the errors
    assert abs(scheme[1, 1] / v.mean_Omega2 - 1) < 1e-3 and abs(scheme[0, 0] / v.mean_x2 - 1) < 1e-3
    ds = stochpend.simulate(potential="harmonic", noise="white", D=0.0, omega=1.0, paths=40_000, t_max=30.0,
                            times=(15.0, 30.0), seed=23, theta0=0.0, Omega0=0.0, h_max=h, step_c=0.0, gamma=gamma,
                            additive_D=D_a, additive_tau=tau, bias_paths=0)
    _rel_ok(ds, "mean_Omega2", v.mean_Omega2)
    _rel_ok(ds, "mean_E", E)


def test_a_short_correlation_time_reaches_the_boltzmann_law():
    gamma, D_a, tau = 0.5, 0.6, 1e-3
    T = family.temperature(D_a=D_a, gamma=gamma)
    ds = stochpend.simulate(potential="harmonic", noise="white", D=0.0, omega=1.0, paths=40_000, t_max=30.0,
                            times=(30.0,), seed=29, gamma=gamma, additive_D=D_a, additive_tau=tau,
                            initial_temperature=T, bias_paths=0)
    _rel_ok(ds, "mean_Omega2", T)
    _rel_ok(ds, "mean_E", family.boltzmann_harmonic_mean_E(D_a=D_a, gamma=gamma, omega=1.0))


def test_the_free_velocity_is_the_exact_integral_of_the_stationary_noise():
    """omega = gamma = 0, D = 0: Omega(t) = int_0^t xi_a, var = D_a [t - tau (1 - e^{-t/tau})]
    for a stationary xi_a (from xi_a(0) = 0 it would be D_a [t - 2 tau (1 - e^{-t/tau}) +
    tau (1 - e^{-2t/tau})/2], smaller by a factor ~2 at t = tau/2). Exact at any h."""
    D_a, tau = 0.8, 2.0
    ds = stochpend.simulate(noise="white", D=0.0, omega=0.0, paths=40_000, t_max=8.0, times=(1.0, 8.0), seed=31,
                            Omega0=0.0, additive_D=D_a, additive_tau=tau, h_max=0.1, step_c=0.0, bias_paths=0)
    t = ds.time.values
    _rel_ok(ds, "mean_Omega2", D_a * (t - tau * (1 - np.exp(-t / tau))))
    from_zero = D_a * (t - 2 * tau * (1 - np.exp(-t / tau)) + tau * (1 - np.exp(-2 * t / tau)) / 2)
    assert abs(float(ds.mean_Omega2[0]) - from_zero[0]) > 10 * float(ds.mean_Omega2_stderr[0])


def test_the_noise_starts_in_its_stationary_law():
    D_a, tau, n = 0.8, 0.25, 100_000
    config = SimpleNamespace(seed=5, dyn_params=dynamics.resolve({"additive_D": D_a, "additive_tau": tau}))
    assert dynamics.additive_arrays(config) == ("xi_a", "aux_a")  # the generic channel's "ou"
    xi = initial.additive_states(config, 0, n)[0]
    var = D_a / (2 * tau)
    z = (np.mean(xi * xi) - var) / (np.std(xi * xi) / math.sqrt(n))
    assert abs(z) < Z, z
    assert abs(np.mean(xi)) < Z * math.sqrt(var / n)
    assert np.array_equal(initial.additive_states(config, 7, 10)[0], xi[7:17])  # a function of (seed, path)
    white = SimpleNamespace(seed=5, dyn_params=dynamics.resolve({"additive_D": D_a}))
    assert initial.additive_states(white, 0, 4) == ()


FAMILY_RUN = dict(noise="ou", D=1.0, tau=1.0, omega=1.0, paths=600, t_max=6.0, n_times=3, seed=9, gamma=0.4,
                  additive_D=0.3, additive_tau=0.4, torque=0.2, drive_amplitude=0.3, drive_frequency=1.3,
                  parametric_amplitude=0.2, parametric_frequency=2.0)


@pytest.mark.parametrize("step", [dict(), dict(step_c=0.0, h_max=0.02)])
def test_the_lanes_give_the_one_path_numbers(step, monkeypatch):
    """The SIMD lane machines (the runs' and the pairs') against the one-path loops of the same
    fast-math KernelSpec (a run with an accumulator goes one path at a time)."""
    from stochpend.engine import cpu
    from stochpend.model.settings import SimulationConfig

    config = SimulationConfig.build(**{k: v for k, v in FAMILY_RUN.items() if k not in dynamics.names()}, **step,
                                    noise_params={k: v for k, v in FAMILY_RUN.items() if k in dynamics.names()})
    spec = cpu.spec_for(config)
    assert "additive_noise" in spec.terms and integrator.lanes_supported(spec)
    assert_lanes_equal_one_path({**FAMILY_RUN, **step}, config, monkeypatch)


def test_the_pairs_bias_is_small_and_the_coarse_member_is_a_run_path():
    """The bias pairs share xi_a as they share xi: well coupled (decorrelation << 1), and the
    bias at h = 0.1 is within a few errors of the moment map's exact bias of the scheme."""
    gamma, D_a, tau, h = 1.0, 1.0, 0.5, 0.1
    ds = stochpend.simulate(potential="harmonic", noise="white", D=0.0, omega=1.0, paths=200, t_max=30.0,
                            times=(30.0,), seed=37, h_max=h, step_c=0.0, gamma=gamma, additive_D=D_a,
                            additive_tau=tau, bias_paths=4000)
    assert float(ds.bias_pair_decorrelation[-1]) < 0.2
    exact = _theory(gamma, D_a, tau)[1, 1]
    coarse, fine = _ou_stationary(h, gamma, D_a, tau)[1, 1], _ou_stationary(h / 2, gamma, D_a, tau)[1, 1]
    assert abs(coarse - fine - (coarse - exact) * 3 / 4) < 0.1 * abs(coarse - exact)  # h^2 ratio
    z = (float(ds.mean_Omega2_bias[-1]) - (coarse - exact)) / float(ds.mean_Omega2_bias_stderr[-1])
    assert abs(z) < Z, (float(ds.mean_Omega2_bias[-1]), coarse - exact, z)


def test_a_checkpointed_run_resumes_to_the_same_numbers(tmp_path):
    from stochpend.model.settings import SimulationConfig
    from stochpend.runs import checkpoint as ck
    from stochpend.runs.simulate import run

    config = SimulationConfig.build(noise="ou", D=1.0, tau=1.0, omega=1.0, paths=300, t_max=10.0, n_times=4, seed=4,
                                    noise_params={"gamma": 0.3, "additive_D": 0.2, "additive_tau": 0.7})
    ref = run(config, chunk_paths=90, bias_paths=64)

    path = tmp_path / "run.ckpt"
    with pytest.raises(KeyboardInterrupt):
        ck.run_checkpointed(config, checkpoint_path=path, every_s=None, chunk_paths=90, bias_paths=64,
                            checkpointer=StopAfter(path, None, config=config, n=5, chunk_paths=90))
    saved = ck.read(path)
    assert saved.state.xi_a is not None and saved.state.xi_a.shape == saved.state.x.shape
    assert np.any(saved.state.xi_a != 0.0)
    done = ck.resume(path)
    assert done.attrs["dynamics_parameters"] == "additive_D=0.2, additive_tau=0.7, gamma=0.3"
    for name in ref.data_vars:
        assert np.array_equal(done[name].values, ref[name].values, equal_nan=True), name


_CUDASIM = """
import json, tempfile
from pathlib import Path
import numpy as np
import pytest
import stochpend
from stochpend.runs import checkpoint as ck
from stochpend.model.settings import SimulationConfig
from tests._checkpoints import StopAfter

kw = dict(noise="ou", D=0.5, tau=0.8, omega=1.0, paths=48, t_max=1.0, times=[0.5, 1.0], seed=3, n_batches=4)
terms = dict(gamma=0.7, additive_D=0.3, additive_tau=0.4, torque=0.2, drive_amplitude=0.5, drive_frequency=1.5,
             parametric_amplitude=0.4, initial_temperature=0.3)
out = {}
for backend, precision in (("cpu", "float64"), ("cuda", "float64"), ("cuda", "float32")):
    ds = stochpend.simulate(**kw, **terms, backend=backend, precision=precision,
                            bias_paths=16 if precision == "float64" else 0)
    names = ("mean_E", "mean_Omega2") + (("mean_E_bias",) if precision == "float64" else ())
    out[backend + precision] = {v: ds[v].values.tolist() for v in names}
# a checkpointed CUDA run, interrupted and resumed, against the straight one
config = SimulationConfig.build(**kw, noise_params=terms)
ref = stochpend.simulate(**kw, **terms, backend="cuda", chunk_paths=20, bias_paths=0)


path = Path(tempfile.mkdtemp()) / "run.ckpt"
with pytest.raises(KeyboardInterrupt):
    ck.run_checkpointed(config, checkpoint_path=path, every_s=None, chunk_paths=20, bias_paths=0, backend="cuda",
                        checkpointer=StopAfter(path, None, config=config, chunk_paths=20, n=3))
assert ck.read(path).state.xi_a.shape == ck.read(path).state.x.shape
done = ck.resume(path)
out["resumed_equal"] = all(np.array_equal(done[v].values, ref[v].values, equal_nan=True) for v in ref.data_vars)
print(json.dumps(out))
"""


@pytest.mark.gpu
def test_the_cuda_simulator_gives_the_cpu_numbers_and_resumes_exactly():
    """Numba's CUDA simulator: float64 = the CPU to 1e-12 (bias included), float32 to its
    round-off; a CUDA checkpoint (xi_a on the device, copied back) resumes bit for bit."""
    import json
    import os
    from pathlib import Path

    env = {**os.environ, "NUMBA_ENABLE_CUDASIM": "1",
           "PYTHONPATH": os.pathsep.join([str(Path(stochpend.__file__).resolve().parents[1]),
                                          str(Path(__file__).resolve().parents[2]),  # tests._checkpoints
                                          os.environ.get("PYTHONPATH", "")])}
    done = subprocess.run([sys.executable, "-c", _CUDASIM], env=env, capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, done.stderr[-3000:]
    r = json.loads(done.stdout.strip().splitlines()[-1])
    assert r["resumed_equal"]
    for name, cpu in r["cpufloat64"].items():
        assert np.allclose(r["cudafloat64"][name], cpu, rtol=1e-12, atol=1e-15), name
        if name in r["cudafloat32"]:
            assert np.allclose(r["cudafloat32"][name], cpu, rtol=1e-5), name


def test_a_bad_correlation_time_is_refused_in_one_line():
    with pytest.raises(ValueError, match=r"additive_tau=-1.0 is not accepted") as info:
        stochpend.simulate(noise="white", D=0.5, paths=100, t_max=1.0, n_times=2, additive_D=0.3, additive_tau=-1.0)
    assert "\n" not in str(info.value)
    done = subprocess.run([sys.executable, "-m", "stochpend", "simulate", "--noise", "white", "--D", "0.5",
                           "--paths", "10", "--t-max", "1", "--param", "additive_D=0.3", "--param",
                           "additive_tau=-1"], capture_output=True, text=True, timeout=300)
    assert done.returncode == 2, done.stderr
    assert "additive_tau" in done.stderr and "Traceback" not in done.stderr


def test_a_correlation_time_without_the_noise_is_todays_kernel():
    """additive_tau alone (additive_D = 0) switches no term on: the paper's kernel, bit for bit."""
    run = dict(noise="ou", D=1.0, tau=1.0, omega=1.0, paths=300, t_max=4.0, n_times=2, seed=11, bias_paths=32)
    plain = stochpend.simulate(**run)
    with_tau = stochpend.simulate(**run, additive_tau=0.5)
    assert with_tau.attrs["dynamics_parameters"] == "additive_tau=0.5"
    for name in plain.data_vars:
        assert np.array_equal(plain[name].values, with_tau[name].values, equal_nan=True), name


def test_a_sweep_over_the_correlation_time_gives_each_runs_numbers():
    base = {"noise": "white", "D": 0.5, "omega": 1.0, "paths": 200, "t_max": 4.0, "n_times": 2, "seed": 6,
            "gamma": 0.5, "additive_D": 0.2}
    ds = stochpend.sweep.sweep({"base": base, "grid": {"additive_tau": [0.0, 0.5]}}, scheduler="sync", bias_paths=0)
    for tau in (0.0, 0.5):
        alone = stochpend.simulate(**base, additive_tau=tau, bias_paths=0)
        assert np.array_equal(ds.sel(additive_tau=tau).mean_E.values, alone.mean_E.values), tau
