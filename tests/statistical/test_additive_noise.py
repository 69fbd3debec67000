"""The generic additive noise channel (issue 23): ``additive_noise`` = any registered noise.

    dOmega/dt = ... + xi_a(t),   xi_a: the named noise, intensity additive_D (S(0) = D_a),
                                 correlation time additive_tau, its own draws (rng.additive_key)

References, each tested exactly or in standard errors (|z| < 4, relative standard error <= 1 %):
* the damped harmonic oscillator driven by additive HARMONIC noise is a linear system
  (x, Omega, xi_a, eta_a): its stationary <Omega^2>, <E> solve a Lyapunov equation
  (theory.family.harmonic_harmonic_additive_variances); the scheme's own exact moment map (read
  off the kernel's step and the noise's exact update) tends to it as h^2, and the kernel's
  ensemble matches it;
* the same oscillator driven by additive DICHOTOMOUS noise: second moments of a linear system
  depend on the noise's correlation function only, which is the OU one with the same D_a,
  tau_a, so the law is theory.family.harmonic_ou_additive_variances (an exact law for a
  non-Gaussian noise, with the steps cut at the channel's flips);
* a user's noise with a parameter of its own (``gain``, defined here: an OU noise of intensity
  gain^2 D) runs on the channel through the API (its law) and the command line (``--plugin``,
  the API's numbers bit for bit); it has ``draw_keyed``, so the SIMD lanes run it and give the
  one-path loop's numbers, the bias pairs included; the harmonic and dichotomous channels go one
  path at a time;
* the CUDA simulator gives the CPU's numbers; a checkpointed run resumes to the straight run's
  numbers; the channel's start is a function of (seed, path) and independent of xi's;
* additive_noise unset, "white" and "ou" are today's kernels, bit for bit; bad settings are
  refused in one line (the command line exits 2 without a traceback).
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest
from numba.extending import register_jitable
from scipy.linalg import solve_discrete_lyapunov

import stochpend
from stochpend import noises
from stochpend.engine import integrator
from stochpend.model import dynamics, initial
from stochpend.model.parameters import Parameter
from stochpend.noises import harmonic as harmonic_noise
from stochpend.noises import ou
from stochpend.noises.base import Noise, NoiseKernel
from stochpend.numerics import rng
from stochpend.theory import family
from tests._checkpoints import StopAfter
from tests._lanes import assert_lanes_equal_one_path

Z = 4.0
ROOT = Path(__file__).resolve().parents[2]


# -- a user's noise, defined here ------------------------------------------------------------------
def _build_gain_ou(real, mathlib) -> NoiseKernel:
    """The OU noise with intensity gain^2 D: its record (D, tau, gain), OU's device functions
    (its draw_keyed too, so the SIMD lanes can run it)."""
    base = ou.build(real, mathlib)
    base_init = base.init
    base_coefficients = base.coefficients

    @register_jitable
    def init(key0, key1, path, p, xi0, stationary):
        g = p[2]
        return base_init(key0, key1, path, (p[0] * g * g, p[1]), xi0, stationary)

    @register_jitable(inline="always")
    def coefficients(h, p):
        g = p[2]
        return base_coefficients(h, (p[0] * g * g, p[1]))

    return NoiseKernel(init, base.load_aux, coefficients, base.scratch0, base.draw, base.update,
                       base.next_event, base.at_event, base.draw_keyed)


GAIN_OU = Noise(name="gain-ou", build=_build_gain_ou, description="OU noise of intensity gain^2 D (tests)",
                colored=True, parameters=("D", "tau", Parameter("gain", 1.0, "amplitude factor", low=0.0)))


@pytest.fixture
def gain_ou():
    noises.register(GAIN_OU)
    try:
        yield GAIN_OU
    finally:
        noises.unregister(GAIN_OU.name)


def _rel_ok(ds, name, want):
    value, se = ds[name].values, ds[f"{name}_stderr"].values
    z = (value - want) / se
    print(f"{name}: value {value}, theory {want}, z {z}, relative stderr {se / abs(want)}")
    assert np.all(np.abs(z) < Z), (name, value, want, z)
    assert np.all(se / abs(want) <= 0.01), (name, se / abs(want))
    return z


# -- the harmonic channel's exact law ----------------------------------------------------------------
def _harmonic_stationary(h, gamma, D_a, tau, omega=1.0):
    """The scheme's stationary covariance of (x, Omega, xi_a, eta_a): z' = A z + N w, w three
    standard normals, from the kernel's own step (linear in x, Omega and the integral I of xi_a,
    its ``za``) and the harmonic noise's exact update (noises.harmonic.step_coefficients)."""
    spec = integrator.spec("white", "harmonic", "force", adaptive=False,
                           terms=frozenset({"damping", "additive_noise"}), additive="harmonic")
    step = integrator.build(spec).family_step
    d = dynamics.record(SimpleNamespace(dyn_params=dynamics.resolve(
        {"gamma": gamma, "additive_D": D_a, "additive_tau": tau})))

    def apply(x, Omega, I):
        return np.array(step(x, Omega, h, omega * omega, 0.0, (0.0,), 0.0, h, I, d))

    B0 = np.column_stack([apply(1.0, 0.0, 0.0), apply(0.0, 1.0, 0.0)])
    b = apply(0.0, 0.0, 1.0)
    p11, p12, p21, p22, p31, p32, l11, l21, l22, l31, l32, l33 = harmonic_noise.step_coefficients(
        h, D_a, tau, 2.0 / tau)
    A = np.zeros((4, 4))
    A[:2, :2] = B0
    A[:2, 2] = b * p31
    A[:2, 3] = b * p32
    A[2, 2:] = p11, p12
    A[3, 2:] = p21, p22
    N = np.zeros((4, 3))
    N[:2, 0] = b * l31
    N[:2, 1] = b * l32
    N[:2, 2] = b * l33
    N[2, 0] = l11
    N[3, 0] = l21
    N[3, 1] = l22
    return solve_discrete_lyapunov(A, N @ N.T)


def _harmonic_theory(gamma, D_a, tau, omega=1.0):
    v = family.harmonic_harmonic_additive_variances(D_a=D_a, tau=tau, gamma=gamma, omega=omega)
    return np.array([[v.mean_x2, v.mean_xOmega, v.mean_x_xi], [v.mean_xOmega, v.mean_Omega2, v.mean_Omega_xi],
                     [v.mean_x_xi, v.mean_Omega_xi, v.mean_xi2]])


def test_the_lyapunov_law_is_the_spectral_integral():
    """<Omega^2> = (1/2pi) int S(nu) nu^2 |chi(nu)|^2 dnu, <x^2> likewise without nu^2."""
    from scipy.integrate import quad

    D_a, tau, gamma, omega = 0.4, 0.5, 0.7, 1.3
    W = 2.0 / tau
    v = family.harmonic_harmonic_additive_variances(D_a=D_a, tau=tau, gamma=gamma, omega=omega)

    def S(nu):
        return D_a * W**4 / ((W * W - nu * nu) ** 2 + (W * W * tau * nu) ** 2)

    def chi2(nu):
        return 1.0 / ((omega * omega - nu * nu) ** 2 + (gamma * nu) ** 2)

    Omega2 = quad(lambda nu: S(nu) * nu * nu * chi2(nu), -np.inf, np.inf)[0] / (2 * np.pi)
    x2 = quad(lambda nu: S(nu) * chi2(nu), -np.inf, np.inf)[0] / (2 * np.pi)
    assert v.mean_Omega2 == pytest.approx(Omega2, rel=1e-9)
    assert v.mean_x2 == pytest.approx(x2, rel=1e-9)
    assert v.mean_xi2 == pytest.approx(D_a / (2 * tau), rel=1e-12)
    with pytest.raises(ValueError, match="omega_noise"):
        family.harmonic_harmonic_additive_variances(D_a=D_a, tau=tau, gamma=gamma, omega=omega, omega_noise=-1.0)


def test_the_schemes_harmonic_law_tends_to_the_theory_as_h_squared():
    gamma, D_a, tau = 0.7, 0.8, 0.5
    exact = _harmonic_theory(gamma, D_a, tau)
    hs = [0.1, 0.05, 0.025, 0.0125]
    errors = [np.max(np.abs(_harmonic_stationary(h, gamma, D_a, tau)[:3, :3] - exact)) for h in hs]
    slopes = np.diff(np.log(errors)) / np.diff(np.log(hs))
    assert np.all(np.abs(slopes - 2.0) < 0.2), (errors, slopes)
    # xi_a's own law is exact at every h (the harmonic noise's exact update)
    assert _harmonic_stationary(0.1, gamma, D_a, tau)[2, 2] == pytest.approx(D_a / (2 * tau), rel=1e-10)


LAW = dict(potential="harmonic", noise="white", D=0.0, omega=1.0, t_max=20.0, times=(20.0,), theta0=0.0,
           Omega0=0.0, step_c=0.0, bias_paths=0)


def test_the_damped_oscillator_reaches_its_harmonic_noise_law():
    gamma, D_a, tau, h = 1.0, 1.0, 0.5, 0.02
    v = family.harmonic_harmonic_additive_variances(D_a=D_a, tau=tau, gamma=gamma, omega=1.0)
    scheme = _harmonic_stationary(h, gamma, D_a, tau)  # its step bias, far below the errors
    assert abs(scheme[1, 1] / v.mean_Omega2 - 1) < 1e-3 and abs(scheme[0, 0] / v.mean_x2 - 1) < 1e-3
    ds = stochpend.simulate(**LAW, paths=25_000, seed=41, h_max=h, gamma=gamma, additive_noise="harmonic",
                            additive_D=D_a, additive_tau=tau)
    assert ds.attrs["additive_noise"] == "harmonic"
    _rel_ok(ds, "mean_Omega2", v.mean_Omega2)
    _rel_ok(ds, "mean_E", 0.5 * (v.mean_Omega2 + v.mean_x2))


def test_the_damped_oscillator_driven_by_dichotomous_noise_has_the_ou_second_moments():
    gamma, D_a, tau, h = 1.0, 1.0, 0.5, 0.02
    v = family.harmonic_ou_additive_variances(D_a=D_a, tau=tau, gamma=gamma, omega=1.0)
    ds = stochpend.simulate(**LAW, paths=25_000, seed=43, h_max=h, gamma=gamma, additive_noise="dichotomous",
                            additive_D=D_a, additive_tau=tau)
    _rel_ok(ds, "mean_Omega2", v.mean_Omega2)
    _rel_ok(ds, "mean_E", family.harmonic_ou_additive_mean_E(D_a=D_a, tau=tau, gamma=gamma, omega=1.0))


def test_a_users_noise_with_its_own_parameter_runs_on_the_channel(gain_ou):
    """gain-ou with gain g is the OU noise of intensity g^2 D_a: the OU-driven law at g^2 D_a."""
    gamma, D_a, tau, g, h = 1.0, 0.5, 0.5, 1.5, 0.02
    v = family.harmonic_ou_additive_variances(D_a=g * g * D_a, tau=tau, gamma=gamma, omega=1.0)
    ds = stochpend.simulate(**LAW, paths=25_000, seed=47, h_max=h, gamma=gamma, additive_noise="gain-ou",
                            additive_D=D_a, additive_tau=tau, additive_gain=g)
    assert ds.attrs["dynamics_parameters"] == "additive_D=0.5, additive_gain=1.5, additive_tau=0.5, gamma=1"
    _rel_ok(ds, "mean_Omega2", v.mean_Omega2)


# -- drivers, backends, checkpoints ---------------------------------------------------------------
PENDULUM = dict(noise="ou", D=1.0, tau=1.0, omega=1.0, paths=600, t_max=6.0, n_times=3, seed=9, gamma=0.4,
                additive_D=0.3, additive_tau=0.4, torque=0.2, drive_amplitude=0.3, drive_frequency=1.3,
                parametric_amplitude=0.2, parametric_frequency=2.0)


def _config(run, **extra):
    from stochpend.model.settings import SimulationConfig

    own = {k: v for k, v in run.items() if k in dynamics.names() or (k.startswith("additive_") and k != "additive_noise")}
    return SimulationConfig.build(**{k: v for k, v in run.items() if k not in own}, **extra, noise_params=own)


@pytest.mark.parametrize("step", [dict(), dict(step_c=0.0, h_max=0.02)])
def test_the_lanes_give_the_one_path_numbers(step, gain_ou, monkeypatch):
    """A channel noise with draw_keyed and no events (the user's gain-ou) runs in the SIMD lanes
    (the runs' and the pairs'), which agree with the one-path loops of the same fast-math KernelSpec
    (a run with an accumulator goes one path at a time)."""
    from stochpend.engine import cpu

    run = {**PENDULUM, "additive_noise": "gain-ou", "additive_gain": 0.8}
    config = _config(run, **step)
    spec = cpu.spec_for(config)
    assert "additive_noise" in spec.terms and spec.additive is GAIN_OU and integrator.lanes_supported(spec)
    assert_lanes_equal_one_path({**run, **step}, config, monkeypatch)


@pytest.mark.parametrize("name", ["harmonic", "dichotomous"])
def test_a_channel_without_keyed_draws_or_with_events_runs_one_path_at_a_time(name):
    from stochpend.engine import cpu

    config = _config({**PENDULUM, "additive_noise": name})
    fast = integrator.KernelSpec.of(config, fast_math=True)
    assert not integrator.lanes_supported(fast)
    spec = cpu.spec_for(config)
    assert not spec.fast_math and spec.additive is noises.get(name)


def test_the_channels_start_is_keyed_by_seed_and_path_and_independent_of_xi():
    n = 20_000
    config = _config({**PENDULUM, "paths": n, "additive_noise": "harmonic"})
    xa, aux = initial.additive_states(config, 0, n)
    var = 0.3 / (2 * 0.4)
    assert abs(np.mean(xa * xa) / var - 1) < Z * np.std(xa * xa) / var / np.sqrt(n)
    assert np.array_equal(initial.additive_states(config, 7, 10)[1], aux[7:17])  # a function of (seed, path)
    # xi(0) of the same paths (the main OU noise's start, under the seed's own key)
    xi = np.array([rng.draw_normals(*rng.seed_to_key(config.seed), np.uint64(i), np.uint64(rng.N_INIT_XI))[0]
                   for i in range(n)])
    assert abs(np.corrcoef(xi, xa)[0, 1]) < Z / np.sqrt(n)
    assert rng.additive_key(config.seed) != rng.seed_to_key(config.seed)


@pytest.mark.parametrize("name", ["harmonic", "dichotomous"])
def test_a_checkpointed_run_resumes_to_the_same_numbers(name, tmp_path):
    from stochpend.runs import checkpoint as ck
    from stochpend.runs.simulate import run

    config = _config(dict(noise="ou", D=1.0, tau=1.0, omega=1.0, paths=300, t_max=10.0, n_times=4, seed=4,
                          gamma=0.3, additive_D=0.2, additive_tau=0.7), additive_noise=name)
    ref = run(config, chunk_paths=90, bias_paths=64)
    path = tmp_path / "run.ckpt"
    with pytest.raises(KeyboardInterrupt):
        ck.run_checkpointed(config, checkpoint_path=path, every_s=None, chunk_paths=90, bias_paths=64,
                            checkpointer=StopAfter(path, None, config=config, n=5, chunk_paths=90))
    saved = ck.read(path)
    assert saved.config.additive_noise == name
    assert saved.state.aux_a.shape == saved.state.xi_a.shape == saved.state.x.shape
    assert np.any(saved.state.aux_a != 0.0)
    done = ck.resume(path)
    assert done.attrs["additive_noise"] == name
    for v in ref.data_vars:
        assert np.array_equal(done[v].values, ref[v].values, equal_nan=True), v


def test_unset_is_the_white_channel_or_the_channels_ou_bit_for_bit():
    """Issue 33, item 5: additive_tau > 0 alone is the channel's "ou" (one mechanism for every
    coloured noise, the same kernel), additive_tau = 0 alone the white channel."""
    from stochpend.engine import cpu
    from stochpend.model.settings import SimulationConfig

    spec = cpu.spec_for(SimulationConfig.build(noise="white", D=0.5, noise_params=dict(additive_D=0.3, additive_tau=0.6)))
    assert "additive_noise" in spec.terms and spec.additive is not None and spec.additive.name == "ou"
    base = dict(noise="ou", D=1.0, tau=1.0, omega=1.0, paths=300, t_max=4.0, n_times=2, seed=11, bias_paths=32,
                gamma=0.5, additive_D=0.3)
    for tau_a, name in ((0.0, "white"), (0.6, "ou")):
        plain = stochpend.simulate(**base, additive_tau=tau_a)
        named = stochpend.simulate(**base, additive_tau=tau_a, additive_noise=name)
        assert "additive_noise" not in plain.attrs and named.attrs["additive_noise"] == name
        for v in plain.data_vars:
            assert np.array_equal(plain[v].values, named[v].values, equal_nan=True), (name, v)


@pytest.mark.parametrize(("kwargs", "match"), [
    (dict(additive_noise="nope"), r"additive_noise='nope' is not accepted: one of white, ou, dichotomous, harmonic"),
    (dict(additive_noise="harmonic"), r"additive_tau=0.0 is not accepted: additive_noise='harmonic' is colored"),
    (dict(additive_noise="white", additive_tau=0.5), r"additive_tau=0.5 is not accepted: additive_noise='white'"),
    (dict(additive_noise="ou"), r"additive_tau=0.0 is not accepted: additive_noise='ou' needs"),
    (dict(additive_noise="dichotomous", additive_tau=0.5, additive_omega_noise=2.0),
     r"additive_omega_noise=2.0 is not accepted: additive_omega_noise applies to additive_noise='harmonic'"),
    (dict(additive_noise="harmonic", additive_tau=0.5, additive_omega_noise=-1.0), r"additive_omega_noise=-1.0"),
])
def test_bad_settings_are_refused_in_one_line(kwargs, match):
    with pytest.raises(ValueError, match=match) as info:
        stochpend.simulate(noise="white", D=0.5, paths=100, t_max=1.0, n_times=2, additive_D=0.3, **kwargs)
    assert "\n" not in str(info.value)


def test_a_users_parameter_out_of_range_is_refused_naming_the_channels_name(gain_ou):
    with pytest.raises(ValueError, match=r"^additive_gain=-1.0 is not accepted: a finite number in \[0"):
        stochpend.simulate(noise="white", D=0.5, paths=100, t_max=1.0, n_times=2, additive_D=0.3, additive_tau=0.5,
                           additive_noise="gain-ou", additive_gain=-1.0)


def _env(**extra):
    return {**os.environ, "PYTHONPATH": os.pathsep.join([str(ROOT / "src"), str(ROOT), os.environ.get("PYTHONPATH", "")]),
            **extra}


@pytest.mark.slow  # three processes, one compiling the user's kernel: about 20 s
def test_the_command_line_runs_a_users_noise_on_the_channel(gain_ou, tmp_path):
    """--plugin loads the user's noise (a module that registers the one defined here),
    --additive-noise selects it, --param sets its own parameter: the API's numbers bit for bit,
    and ``show`` names it; a bad name exits 2 in one line without a traceback."""
    (tmp_path / "gain_plugin.py").write_text(
        "from stochpend import noises\nfrom tests.statistical.test_additive_noise import GAIN_OU\n"
        "noises.register(GAIN_OU)\n")
    env = _env(PYTHONPATH=os.pathsep.join([str(tmp_path), str(ROOT / "src"), str(ROOT)]))
    run = dict(noise="white", D=0.0, omega=1.0, paths=200, t_max=3.0, n_times=2, seed=5, gamma=0.5, additive_D=0.4,
               additive_tau=0.3, additive_gain=1.2)
    api = stochpend.simulate(**run, additive_noise="gain-ou", bias_paths=0)
    out = tmp_path / "r.nc"
    args = ["simulate", "--plugin", "gain_plugin", "--noise", "white", "--D", "0", "--paths", "200", "--t-max", "3",
            "--n-times", "2", "--seed", "5", "--bias-paths", "0", "--additive-noise", "gain-ou", "-q", "--out", str(out)]
    for k in ("gamma", "additive_D", "additive_tau", "additive_gain"):
        args += ["--param", f"{k}={run[k]}"]
    done = subprocess.run([sys.executable, "-m", "stochpend", *args], cwd=tmp_path, env=env, capture_output=True,
                          text=True, timeout=600)
    assert done.returncode == 0, done.stderr[-3000:]
    import xarray as xr

    cli = xr.load_dataset(out)
    assert cli.attrs["additive_noise"] == "gain-ou"
    for v in ("mean_E", "mean_Omega2"):
        assert np.array_equal(cli[v].values, api[v].values), v
    shown = subprocess.run([sys.executable, "-m", "stochpend", "show", str(out)], cwd=tmp_path, env=env,
                           capture_output=True, text=True, timeout=300)
    assert shown.returncode == 0 and "gain-ou" in shown.stdout, shown.stderr
    bad = subprocess.run([sys.executable, "-m", "stochpend", "simulate", "--noise", "white", "--paths", "10",
                          "--t-max", "1", "--additive-noise", "gain-ou", "--param", "additive_D=0.3"],
                         cwd=tmp_path, env=env, capture_output=True, text=True, timeout=300)
    assert bad.returncode == 2 and "'gain-ou' is not accepted" in bad.stderr, bad.stderr
    assert len(bad.stderr.strip().splitlines()) == 1, bad.stderr
    assert "Traceback" not in bad.stderr


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
out = {}
for name in ("harmonic", "dichotomous"):
    terms = dict(gamma=0.7, additive_D=0.3, additive_tau=0.4, torque=0.2, parametric_amplitude=0.4)
    for backend, precision in (("cpu", "float64"), ("cuda", "float64"), ("cuda", "float32")):
        ds = stochpend.simulate(**kw, **terms, additive_noise=name, backend=backend, precision=precision,
                                bias_paths=16 if precision == "float64" else 0)
        names = ("mean_E", "mean_Omega2") + (("mean_E_bias",) if precision == "float64" else ())
        out[name + backend + precision] = {v: ds[v].values.tolist() for v in names}
# a checkpointed CUDA run of the harmonic channel, interrupted and resumed, against the straight one
terms = dict(gamma=0.7, additive_D=0.3, additive_tau=0.4)
config = SimulationConfig.build(**kw, noise_params=terms, additive_noise="harmonic")
ref = stochpend.simulate(**kw, **terms, additive_noise="harmonic", backend="cuda", chunk_paths=20, bias_paths=0)


path = Path(tempfile.mkdtemp()) / "run.ckpt"
with pytest.raises(KeyboardInterrupt):
    ck.run_checkpointed(config, checkpoint_path=path, every_s=None, chunk_paths=20, bias_paths=0, backend="cuda",
                        checkpointer=StopAfter(path, None, config=config, chunk_paths=20, n=3))
saved = ck.read(path).state
assert saved.aux_a.shape == saved.xi_a.shape == saved.x.shape
done = ck.resume(path)
out["resumed_equal"] = all(np.array_equal(done[v].values, ref[v].values, equal_nan=True) for v in ref.data_vars)
print(json.dumps(out))
"""


@pytest.mark.gpu
def test_the_cuda_simulator_gives_the_cpu_numbers_and_resumes_exactly():
    """Numba's CUDA simulator: float64 = the CPU to 1e-12 (bias included), float32 to its
    round-off; a CUDA checkpoint (xi_a, aux_a on the device, copied back) resumes bit for bit."""
    env = {**os.environ, "NUMBA_ENABLE_CUDASIM": "1",
           "PYTHONPATH": os.pathsep.join([str(Path(stochpend.__file__).resolve().parents[1]), str(ROOT),
                                          os.environ.get("PYTHONPATH", "")])}
    done = subprocess.run([sys.executable, "-c", _CUDASIM], env=env, capture_output=True, text=True, timeout=900)
    assert done.returncode == 0, done.stderr[-3000:]
    r = json.loads(done.stdout.strip().splitlines()[-1])
    assert r["resumed_equal"]
    for name in ("harmonic", "dichotomous"):
        for v, cpu in r[name + "cpufloat64"].items():
            assert np.allclose(r[name + "cudafloat64"][v], cpu, rtol=1e-12, atol=1e-15), (name, v)
            if v in r[name + "cudafloat32"]:
                assert np.allclose(r[name + "cudafloat32"][v], cpu, rtol=1e-5), (name, v)


def test_a_sweep_takes_the_channels_noise_and_parameters_as_keys(gain_ou):
    base = {"noise": "white", "D": 0.5, "omega": 1.0, "paths": 100, "t_max": 2.0, "n_times": 2, "seed": 6,
            "gamma": 0.5, "additive_D": 0.2, "additive_tau": 0.5, "additive_noise": "gain-ou"}
    ds = stochpend.sweep.sweep({"base": base, "grid": {"additive_gain": [0.5, 2.0]}}, scheduler="sync", bias_paths=0)
    for g in (0.5, 2.0):
        alone = stochpend.simulate(**base, additive_gain=g, bias_paths=0)
        assert np.array_equal(ds.sel(additive_gain=g).mean_E.values, alone.mean_E.values), g
