"""Per-path accumulators (issue 22, item 3): a time average over a window, a first-passage
time and a running sum, carried in each path's state through the integrator's step loop and
reduced over the ensemble at every output time.

References they must meet: a running sum of the noise's integral has the exact variance of the
integral of a stationary OU process; a first-passage time and a time average of a deterministic
harmonic oscillator have closed forms, met to the scheme's second order (the error falls
4-fold when the step halves); the displacement of a rotating pendulum is its wrapped angle plus
whole turns. Adding accumulators moves no other number of a run (bit for bit), a checkpointed
run resumes to the same numbers, and the CUDA simulator gives the CPU's.
"""

from __future__ import annotations

import json
import math
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import stochpend
from stochpend.model.settings import SimulationConfig
from stochpend.observables import FirstPassage, Observable, RunningSum, TimeAverage, register, unregister
from stochpend.runs import checkpoint as ck
from stochpend.runs.simulate import run
from tests._checkpoints import StopAfter

RUN = dict(noise="ou", D=1.0, tau=1.0, omega=1.0, paths=2000, t_max=10.0, n_times=4, seed=11)
NAMES = ("Om2_avg", "t_avg", "t_late", "xi_int", "escape", "at_t", "x_now", "minus_x", "x2_avg", "xi_avg",
         "first_flip")


@pytest.fixture(autouse=True)
def accumulators():
    register(TimeAverage("Om2_avg", lambda x, Omega, xi, t: Omega * Omega, window=(0.0, 10.0)))
    register(TimeAverage("t_avg", lambda x, Omega, xi, t: t, window=(0.0, 10.0)))
    register(TimeAverage("t_late", lambda x, Omega, xi, t: t, window=(1.0, 4.0)))
    register(RunningSum("xi_int", lambda x0, O0, xi0, x1, O1, xi1, t0, t1: 0.5 * (t1 - t0) * (xi0 + xi1)))
    register(FirstPassage("escape", lambda x, Omega, xi, t: 0.5 * Omega * Omega - math.cos(x), threshold=1.5))
    register(FirstPassage("at_t", lambda x, Omega, xi, t: t, threshold=3.3))
    register(Observable("x_now", lambda x, Omega, xi, t: x))
    register(FirstPassage("minus_x", lambda x, Omega, xi, t: -x, threshold=0.5))
    register(TimeAverage("x2_avg", lambda x, Omega, xi, t: x * x, window=(0.0, 2.0 * math.pi)))
    register(TimeAverage("xi_avg", lambda x, Omega, xi, t: xi, window=(0.0, 4.0)))
    register(FirstPassage("first_flip", lambda x, Omega, xi, t: -xi, threshold=0.0))
    yield
    for name in NAMES:
        unregister(name)


def test_accumulators_move_no_other_number_and_report_their_statistics():
    plain = stochpend.simulate(**RUN, bias_paths=128)
    ds = stochpend.simulate(**RUN, bias_paths=128, observables=("Om2_avg", "escape", "displacement"))
    for name in plain.data_vars:
        if not name.endswith("_bias_verdict"):  # the family of simultaneous tests is the same size
            assert np.array_equal(plain[name].values, ds[name].values, equal_nan=True), name
    for name in ("mean_Om2_avg", "mean_escape", "passed_escape", "mean_displacement", "var_displacement"):
        assert np.all(np.isfinite(ds[f"{name}_stderr"].values[-1])), name
        # Not estimated: the coupled pairs do not carry accumulators (a first passage's step
        # error is not O(h^2) anyway). NaN, never a 0 that reads as "no bias".
        assert np.all(np.isnan(ds[f"{name}_bias"].values)), name
    # <(1/t) int_0^t Omega^2> lies between the ensemble's <Omega^2> at the first and last times.
    assert ds.mean_Omega2.values[0] < ds.mean_Om2_avg.values[-1] < ds.mean_Omega2.values[-1]
    passed = ds.passed_escape.values
    assert np.all(np.diff(passed) >= 0) and 0 < passed[-1] < 1  # censored: some have not passed
    assert np.isnan(ds.mean_escape.values[0]) and passed[0] == 0  # none passed yet: undefined, not 0


def test_time_averages_are_exact_for_a_linear_function_and_respect_their_window():
    ds = stochpend.simulate(**{**RUN, "paths": 200}, times=(0.5, 1.0, 2.5, 4.0, 7.0, 10.0), bias_paths=0,
                            observables=("t_avg", "t_late"))
    t = ds.time.values
    # The trapezoidal rule integrates t exactly: the average over [0, t] is t/2.
    assert np.allclose(ds.mean_t_avg.values, t / 2, rtol=1e-12, atol=0)
    late = ds.mean_t_late.values
    assert np.all(np.isnan(late[t <= 1.0]))  # before its window opens: undefined
    inside = (t > 1.0) & (t <= 4.0)
    assert np.allclose(late[inside], (1.0 + t[inside]) / 2, rtol=1e-12, atol=0)
    assert np.allclose(late[t > 4.0], 2.5, rtol=1e-12, atol=0)  # closed at 4: frozen


def test_the_running_integral_of_ou_noise_has_the_exact_variance():
    """Var int_0^T xi dt = 2 s2 tau (T - tau (1 - exp(-T/tau))) for a stationary OU noise of
    variance s2 = D/(2 tau) (the package's convention, checked in test_user_observables)."""
    D, tau = 1.0, 0.5
    ds = stochpend.simulate(noise="ou", D=D, tau=tau, omega=1.0, paths=20000, t_max=4.0, times=(1.0, 4.0),
                            seed=5, bias_paths=0, observables=("xi_int",))
    s2 = D / (2 * tau)
    T = ds.time.values
    exact = 2 * s2 * tau * (T - tau * (1 - np.exp(-T / tau)))
    z = (ds.var_xi_int.values - exact) / ds.var_xi_int_stderr.values
    assert np.all(np.abs(z) < 4), z
    assert np.all(ds.var_xi_int_stderr.values / exact < 0.03)  # resolved to a few percent
    z_mean = ds.mean_xi_int.values / ds.mean_xi_int_stderr.values
    assert np.all(np.abs(z_mean) < 4), z_mean


def _harmonic(h: float, names: tuple[str, ...]):
    return stochpend.simulate(potential="harmonic", noise="white", D=0.0, omega=1.0, paths=16, theta0=1.0,
                              Omega0=0.0, t_max=2 * math.pi, times=(1.0, 2 * math.pi), h_max=h, step_c=0.0,
                              bias_paths=0, observables=names)


def test_a_first_passage_and_a_time_average_converge_at_second_order():
    """x(t) = cos t from x = 1 at rest (D = 0): -x reaches 1/2 first at t* = 2 pi/3, and the
    average of x^2 over one period is 1/2. The time average's error falls 4-fold per halved
    step (the scheme's order). The passage time's is a phase error and an interpolation error of
    varying sign, both O(h^2): it stays below 0.1 h^2 (measured: up to 0.06 h^2), where the end
    time of the crossing step, uninterpolated, would be off by a fraction of h."""
    errors = []
    for h in (0.04, 0.02, 0.01, 0.005):
        ds = _harmonic(h, ("minus_x", "x2_avg"))
        assert ds.passed_minus_x.values.tolist() == [0.0, 1.0]
        passage = abs(ds.mean_minus_x.values[-1] - 2 * math.pi / 3)
        assert passage < 0.1 * h * h, (h, passage)
        errors.append(abs(ds.mean_x2_avg.values[-1] - 0.5))
    ratios = np.array(errors[:-1]) / np.array(errors[1:])
    assert np.all((ratios > 3.6) & (ratios < 4.4)), (errors, ratios)


def test_an_event_noise_is_seen_before_its_jump_so_the_accumulators_are_exact_at_any_step():
    """The dichotomous noise is constant between flips and the step lands on each flip, so the
    trapezoid integrates it exactly and its first flip is found at the flip's time, whatever
    the step: where the accumulators see the noise at each step's end before its jump (its
    left limit; the next step starts after it). From xi0 = +a, E xi(t) = a exp(-t/tau): the
    mean of (1/T) int_0^T xi dt is a tau (1 - exp(-T/tau))/T, and the first flip (where -xi
    reaches 0) is exponential with rate 1/(2 tau), censored at t_end. With the value after the
    jump at a step's end (before the fix) both were off by 9 standard errors at this step."""
    D, tau, T, t_end = 2.0, 1.0, 4.0, 20.0
    a = math.sqrt(D / (2 * tau))
    ds = stochpend.simulate(noise="dichotomous", D=D, tau=tau, omega=1.0, paths=200_000, t_max=t_end,
                            times=(T, t_end), seed=3, h_max=0.2, step_c=0.0, xi0=a, bias_paths=0,
                            observables=("xi_avg", "xi_int", "first_flip"))
    integral = a * tau * (1 - math.exp(-T / tau))
    rate = 1 / (2 * tau)
    first_flip = (1 / rate - (t_end + 1 / rate) * math.exp(-rate * t_end)) / (1 - math.exp(-rate * t_end))
    z = {"xi_avg": (ds.mean_xi_avg.values[0] - integral / T) / ds.mean_xi_avg_stderr.values[0],
         "xi_int": (ds.mean_xi_int.values[0] - integral) / ds.mean_xi_int_stderr.values[0],
         "first_flip": (ds.mean_first_flip.values[1] - first_flip) / ds.mean_first_flip_stderr.values[1]}
    assert all(abs(v) < 4 for v in z.values()), z
    assert ds.mean_xi_avg_stderr.values[0] < 0.01 * integral / T  # resolved to 1 %: the old error was 5 %


def test_a_first_passage_between_output_times_is_censored_until_then():
    ds = stochpend.simulate(**{**RUN, "paths": 100}, times=(1.0, 3.0, 3.3, 5.0), bias_paths=0, observables=("at_t",))
    assert ds.passed_at_t.values.tolist() == [0.0, 0.0, 1.0, 1.0]
    assert np.allclose(ds.mean_at_t.values[2:], 3.3, rtol=1e-12, atol=0)


def test_the_displacement_of_a_rotating_pendulum_is_its_angle_plus_whole_turns():
    # D = 0: every path is the same rotation (E = 4.5 - 1 above the separatrix at 1).
    ds = stochpend.simulate(noise="white", D=0.0, omega=1.0, paths=8, theta0=0.0, Omega0=3.0, t_max=20.0,
                            times=(5.0, 20.0), bias_paths=0, observables=("x_now", "displacement"))
    turns = (ds.mean_displacement.values - ds.mean_x_now.values) / (2 * math.pi)
    assert np.allclose(turns, np.round(turns), rtol=0, atol=1e-9), turns
    assert turns[-1] >= 8  # ~2.6 rad/time over 20: many turns, kept exactly
    assert np.all(ds.var_displacement.values < 1e-20)  # identical paths


def test_a_checkpointed_run_with_accumulators_resumes_to_the_same_numbers(tmp_path):
    config = SimulationConfig.build(**{**RUN, "paths": 300}, observables=("Om2_avg", "escape", "displacement"))
    ref = run(config, chunk_paths=90, bias_paths=0)

    path = tmp_path / "run.ckpt"
    with pytest.raises(KeyboardInterrupt):
        ck.run_checkpointed(config, checkpoint_path=path, every_s=None, chunk_paths=90,
                            checkpointer=StopAfter(path, None, config=config, n=5, chunk_paths=90))
    done = ck.resume(path)
    for name in ref.data_vars:
        assert np.array_equal(done[name].values, ref[name].values, equal_nan=True), name


@pytest.mark.parametrize("make, message", [
    (lambda: TimeAverage("a", lambda x, Omega, xi, t: x, window=(2.0, 1.0)), "0 <= t0 < t1"),
    (lambda: TimeAverage("a", lambda x, Omega, xi, t: x, window="late"), "window='late' is not accepted"),
    (lambda: TimeAverage("E", lambda x, Omega, xi, t: x, window=(0, 1)), "built-in statistic"),
    (lambda: FirstPassage("a", lambda x, Omega, xi, t: x, threshold=math.inf), "threshold=inf is not accepted"),
    (lambda: FirstPassage("a", lambda x, Omega: x, threshold=1.0), "raised TypeError"),
    (lambda: RunningSum("a", lambda x0, O0: 0.0), "increment is not accepted"),
    (lambda: RunningSum("a", lambda *args: 0.0, rates=1), "rates=1 is not accepted: True or False"),
])
def test_an_accumulator_that_cannot_work_is_refused_where_it_is_declared(make, message):
    with pytest.raises(ValueError, match=message) as info:
        make()
    assert "\n" not in str(info.value)


def test_a_window_that_does_not_end_on_an_output_time_is_refused_in_one_line():
    with pytest.raises(ValueError, match=r"the window \(1\.0, 4\.0\) of 't_late' must start and end") as info:
        stochpend.simulate(**RUN, times=(1.0, 5.0, 10.0), observables=("t_late",))
    assert "\n" not in str(info.value)


_CUDASIM = """
import json, math
import numpy as np
import stochpend
from stochpend.observables import FirstPassage, TimeAverage, register
register(TimeAverage("x2_avg", lambda x, Omega, xi, t: x * x, window=(0.0, 1.0)))
register(FirstPassage("far", lambda x, Omega, xi, t: abs(x), threshold=0.6))
out = {}
for backend in ("cpu", "cuda"):
    ds = stochpend.simulate(potential="harmonic", noise="white", D=1.0, omega=1.0, paths=48, t_max=1.0,
                            times=[0.5, 1.0], seed=3, n_batches=4, backend=backend, bias_paths=0,
                            observables=("x2_avg", "far", "displacement", "log_energy"))
    out[backend] = {v: ds[v].values.tolist() for v in ("mean_x2_avg", "mean_far", "passed_far",
                                                        "mean_displacement", "var_displacement", "mean_E",
                                                        "mean_log_energy", "rate_displacement",
                                                        "diffusion_displacement", "fpt_far_quantile",
                                                        "fpt_far_quantile_lower", "fpt_far_quantile_upper",
                                                        "fpt_far_hist", "fpt_far_censored", "fpt_far_passed")}
print(json.dumps(out))
"""


@pytest.mark.gpu
def test_accumulators_in_the_cuda_simulator_give_the_cpu_numbers():
    env = {**os.environ, "NUMBA_ENABLE_CUDASIM": "1",
           "PYTHONPATH": os.pathsep.join([str(Path(stochpend.__file__).resolve().parents[1]),
                                          os.environ.get("PYTHONPATH", "")])}
    done = subprocess.run([sys.executable, "-c", _CUDASIM], env=env, capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, done.stderr[-3000:]
    r = json.loads(done.stdout.strip().splitlines()[-1])
    for name, cpu in r["cpu"].items():
        assert np.allclose(r["cuda"][name], cpu, rtol=1e-12, atol=1e-15, equal_nan=True), name
    assert 0 < r["cpu"]["passed_far"][-1] < 1
    # the law of the passage time from each path's own time (issue 23): the CPU's, censored too
    assert r["cuda"]["fpt_far_hist"] == r["cpu"]["fpt_far_hist"] and r["cpu"]["fpt_far_censored"] > 0
    assert np.isnan(r["cpu"]["fpt_far_quantile"][-1]) and np.isfinite(r["cpu"]["fpt_far_quantile"][0])


def test_the_command_line_reports_an_accumulator_and_show_lists_it(tmp_path):
    from typer.testing import CliRunner

    from stochpend.cli import app

    out = tmp_path / "run.nc"
    runner = CliRunner()
    done = runner.invoke(app, ["simulate", "--paths", "400", "--t-max", "10", "--n-times", "3", "--seed", "2",
                               "--observable", "displacement", "--out", str(out)])
    assert done.exit_code == 0, done.output
    assert "mean_displacement" in done.stdout and "var_displacement" in done.stdout
    shown = runner.invoke(app, ["show", str(out)])
    assert shown.exit_code == 0 and "var_displacement" in shown.stdout
    listed = runner.invoke(app, ["list"])
    assert "--observable" in listed.stdout and "displacement" in listed.stdout
    bad = runner.invoke(app, ["simulate", "--paths", "400", "--observable", "nope"])
    assert bad.exit_code == 2
    assert "'nope' is not a registered observable" in bad.stderr and "Traceback" not in bad.output


def test_log_energy_is_the_mean_log_of_the_energy_above_the_floor_and_leaves_no_path_out():
    """Harmonic oscillator from x = 1 at rest, D = 0: E - E_min = 1/2 for ever (to the scheme's
    modified energy), so <ln e> = ln(1/2); from rest at the bottom (additive noise moves it
    later) e = 0 at t = 0: ln e = -inf is left out of that statistic only."""
    ds = stochpend.simulate(potential="harmonic", noise="white", D=0.0, omega=1.0, paths=8, theta0=1.0, Omega0=0.0,
                            t_max=2.0, times=(1.0, 2.0), h_max=0.001, step_c=0.0, bias_paths=0,
                            observables=("log_energy",))
    assert np.allclose(ds.mean_log_energy.values, math.log(0.5), atol=1e-6)
    assert np.all(ds.n_log_energy.values == 1.0)
    # The pendulum at rest at its bottom, kicked by additive noise from t = 0: every path counted
    # in <E> at every time; e > 0 once the noise has acted.
    ds = stochpend.simulate(noise="white", D=0.0, omega=1.0, paths=200, theta0=0.0, Omega0=0.0, t_max=1.0,
                            times=(0.5, 1.0), gamma=0.5, additive_D=0.2, bias_paths=0, observables=("log_energy",))
    assert np.all(ds.n_finite_paths.values == 200) and np.all(ds.n_log_energy.values == 1.0)
    e = ds.mean_E.values + 1.0  # E_min = -omega^2
    assert np.all(ds.mean_log_energy.values < np.log(e))  # Jensen: <ln e> < ln <e>


@pytest.mark.parametrize("scheduler", ["sync", "local"])
def test_a_sweep_reports_user_observables_and_accumulators_on_every_scheduler(scheduler, monkeypatch):
    """A plugin's observable and time average, and the built-in displacement, in a sweep: each
    set's numbers are its run's alone, also on a two-worker Dask cluster (the workers load the
    plugin the client loaded)."""
    if scheduler == "local":
        pytest.importorskip("distributed")
    from stochpend import plugins

    # Only this test's plugin: the workers load every plugin this process loaded, and another
    # test may have loaded one from its temporary directory, which the workers cannot import.
    monkeypatch.setattr(plugins, "_LOADED", [])
    plugins.load("tests.unit._observables_plugin")
    plugins.load("tests.unit._passage_plugin")
    names = ["Omega2_plugin", "Omega2_avg_plugin", "displacement", "Omega_up"]
    spec = {"base": {"noise": "ou", "D": 1.0, "omega": 1.0, "paths": 200, "times": [2.0, 4.0], "seed": 6,
                     "observables": names},
            "grid": {"tau": [0.5, 2.0]}}
    kwargs = dict(scheduler="local", workers=2) if scheduler == "local" else dict(scheduler="sync")
    ds = stochpend.sweep.sweep(spec, bias_paths=0, **kwargs)
    for tau in (0.5, 2.0):
        alone = stochpend.simulate(noise="ou", D=1.0, tau=tau, omega=1.0, paths=200, times=(2.0, 4.0), seed=6,
                                   bias_paths=0, observables=names)
        got = ds.sel(tau=tau)
        for v in ("mean_Omega2_plugin", "mean_Omega2_avg_plugin", "var_displacement", "mean_E",
                  "diffusion_displacement", "fpt_Omega_up_quantile", "fpt_Omega_up_quantile_upper",
                  "fpt_Omega_up_hist", "fpt_Omega_up_censored"):  # a passage's law: from every path's time
            assert np.array_equal(got[v].values, alone[v].values, equal_nan=True), (tau, v)
        assert np.array_equal(got.mean_Omega2_plugin.values, got.mean_Omega2.values)


def test_a_sweep_whose_sets_ask_for_different_observables_is_refused_in_one_line():
    spec = {"base": {"noise": "ou", "paths": 100, "t_max": 1.0, "n_times": 2},
            "case": [{"seed": 1, "observables": ["displacement"]}, {"seed": 2}]}
    with pytest.raises(ValueError, match="observables is not accepted: it differs between sets") as info:
        stochpend.sweep.load_spec(spec)
    assert "\n" not in str(info.value)
