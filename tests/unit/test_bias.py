"""The discretisation-bias estimate (stochpend.bias) and accuracy="auto".

The reference is exact: for the harmonic oscillator with white noise on the force the scheme is
linear, so its second moments after n fixed steps follow an exact moment map
(tests/statistical/test_weak_order.py). The estimator's expectation is then known without
sampling, 4/3 (M_h - M_{h/2}), and the true bias M_h - exact too.
"""

from __future__ import annotations

import math
import types

import numpy as np
import pytest
from typer.testing import CliRunner

import stochpend
from stochpend import bias
from stochpend.cli import app
from stochpend.engine import integrator
from stochpend.model.settings import SimulationConfig
from tests.conftest import SEED, Z_TOL
from tests.statistical.test_weak_order import OMEGA, X0, D, exact_second_moments, scheme_second_moments

H = 0.2
TIMES = (1.0, 2.0, 4.0)


def _harmonic(paths: int, **kw) -> SimulationConfig:
    return SimulationConfig.build(noise="white", D=D, omega=OMEGA, paths=paths, t_max=4.0,
                                  times=TIMES, seed=SEED, theta0=X0, Omega0=0.0,
                                  potential="harmonic", h_max=H, step_c=0.0, **kw)


def test_estimate_has_the_exact_expectation_of_the_richardson_difference():
    """<x^2> and <Omega^2> bias estimates vs 4/3 (M_h - M_{h/2}) of the exact moment maps:
    |z| < 4 wherever that bias is resolved (> 5 standard errors: most entries). A pair whose
    coarse kick used one half-step integral, or whose fine member took full steps, or a wrong
    Richardson factor, is off by many standard errors."""
    est = bias.estimate(_harmonic(20_000), 20_000)
    checked = 0
    for name, col in (("mean_sin2theta", 0), ("mean_Omega2", 2)):
        b, se = est.bias[name]
        c, c_se = est.coarse[name]
        for j, t in enumerate(TIMES):
            n = round(t / H)
            m_h = scheme_second_moments(H, n)[col]
            want = bias.RICHARDSON * (m_h - scheme_second_moments(H / 2, 2 * n)[col])
            # the coarse member has the law of an ordinary path of the run
            zc = (c[j] - m_h) / c_se[j]
            assert abs(zc) < Z_TOL, f"t={t}: coarse {name} {c[j]:.5f}, scheme map {m_h:.5f} (z={zc:+.1f})"
            if abs(want) < 5 * se[j]:
                continue
            checked += 1
            z = (b[j] - want) / se[j]
            assert abs(z) < Z_TOL, f"t={t}: {name} bias {b[j]:.6f} +- {se[j]:.1e}, expected {want:.6f} (z={z:+.1f})"
    assert checked >= 4


def test_richardson_expectation_is_the_true_bias_to_leading_order():
    """No sampling: 4/3 (M_h - M_{h/2}) is within 6 % of M_h - exact at h = 0.2 (every second
    moment at t = 4) and the gap shrinks with h (the next term of the weak error)."""
    gaps = []
    for h in (H, H / 2):
        n = round(4.0 / h)
        true = scheme_second_moments(h, n) - exact_second_moments(4.0)
        est = bias.RICHARDSON * (scheme_second_moments(h, n) - scheme_second_moments(h / 2, 2 * n))
        gaps.append(np.max(np.abs(est - true) / np.abs(true)))
    assert gaps[0] < 0.06, gaps
    assert gaps[1] < 0.6 * gaps[0], gaps


@pytest.mark.parametrize("step_c", [0.0, 0.1])
def test_pairs_without_noise_are_the_run_at_h_and_at_h_over_2(step_c):
    """D = 0, fixed start: the coarse member is advance_path's path bit for bit (fixed and
    adaptive steps), and with a fixed step the fine member is the path run at h_max/2: the
    pair adds nothing to the scheme but the shared noise."""
    from stochpend.numerics import rng
    from tests._kernels import Paths, kernels

    n, seed, theta0, Omega0 = 8, SEED, 2.5, np.linspace(-1.0, 3.0, 8)
    key0, key1 = rng.seed_to_key(seed)
    spec = integrator.spec("ou", adaptive=step_c > 0)
    from stochpend.engine import cpu

    init, advance = cpu.init_kernel(spec), cpu.pair_advance_kernel(spec)
    pair = [np.zeros(n) for _ in range(8)]
    k = np.zeros(n, dtype=np.uint64)
    status = np.zeros(n, dtype=np.uint8)
    x, Om, xf, Of, xi, xa, t, tc = pair
    init((x, Om, xi, xa, t, tc, k, status), key0, key1, np.uint64(0), theta0, False, 0.0,
         0.0, False, (0.0, 1.0))
    xf[:] = x
    Om[:] = Omega0
    Of[:] = Omega0
    advance((x, Om, xf, Of, xi, xa, t, tc, k, status), 3.0, 10**6, key0, key1, np.uint64(0),
            (0.0, 1.0), (1.0, (2.0,), 0.1, step_c))
    kern = kernels("ou", adaptive=step_c > 0)
    for h, (xs, Os) in ((0.1, (x, Om)), (0.05, (xf, Of))):
        if h == 0.05 and step_c > 0:
            continue
        p = Paths(n).init(kern, seed, theta0=theta0, xi0=0.0, D=0.0)
        p.Omega[:] = Omega0
        p.advance(kern, 3.0, 10**6, seed, D=0.0, h_max=h, step_c=step_c)
        if h == 0.1:
            assert np.array_equal(xs, p.x) and np.array_equal(Os, p.Omega)
        else:  # the same steps up to the last one's rounding (a clock of 0.1s vs of 0.05s)
            assert np.allclose(xs, p.x, rtol=0, atol=1e-12) and np.allclose(Os, p.Omega, rtol=0, atol=1e-12)
            assert not np.array_equal(xs, x)  # and not the coarse member
    assert np.all(t == 3.0) and not np.any(status)


def test_estimate_does_not_depend_on_chunks_or_threads():
    import numba

    cfg = SimulationConfig.build(noise="ou", paths=500, t_max=20.0, n_times=4, seed=SEED)
    a = bias.estimate(cfg, 300)
    b = bias.estimate(cfg, 300, chunk_pairs=40)
    previous = numba.get_num_threads()
    numba.set_num_threads(1)
    try:
        c = bias.estimate(cfg, 300)
    finally:
        numba.set_num_threads(previous)
    for name in a.bias:
        for other in (b, c):
            assert np.array_equal(a.bias[name][0], other.bias[name][0], equal_nan=True)
            assert np.array_equal(a.bias[name][1], other.bias[name][1], equal_nan=True)
    assert a.path_steps == b.path_steps == c.path_steps


def test_simulate_reports_bias_variables_and_attrs():
    ds = stochpend.simulate(noise="ou", paths=2000, t_max=10.0, n_times=3, seed=SEED)
    for name in bias.CONTROLLED:
        assert f"{name}_bias" in ds and f"{name}_bias_stderr" in ds
        assert ds[f"{name}_bias"].dims == ("time",)
    assert ds.attrs["bias_paths"] == bias.default_bias_paths(2000) == bias.MIN_PAIRS
    assert bias.default_bias_paths(96_000) == 2000  # a 48th of a larger run
    assert ds.attrs["accuracy"] == "fixed"
    assert 0 < ds.attrs["bias_path_steps"] < ds.attrs["path_steps"]
    none = stochpend.simulate(noise="ou", paths=2000, t_max=10.0, n_times=3, seed=SEED, bias_paths=0)
    assert "mean_E_bias" not in none
    # the run's own numbers do not depend on the estimate
    assert np.array_equal(ds.mean_E.values, none.mean_E.values)


def test_auto_refines_a_coarse_step_and_accepts_a_loose_tolerance():
    kw = dict(noise="ou", paths=4000, t_max=20.0, times=(5.0, 20.0), seed=SEED, h_max=0.4,
              step_c=0.8, bias_paths=512)
    ds = stochpend.simulate(accuracy="auto", **kw)
    level = ds.attrs["accuracy_level"]
    assert level >= 1
    assert ds.attrs["h_max"] == pytest.approx(0.4 / 2**level)
    assert ds.attrs["step_c"] == pytest.approx(0.8 / 2**level)
    assert ds.attrs["accuracy_pilot_h_max"] == 0.4
    # the reported bias is the pilot's, scaled to the chosen level
    pilot = bias.estimate(SimulationConfig.build(**{k: v for k, v in kw.items() if k != "bias_paths"}),
                          ds.attrs["bias_paths"])
    assert np.allclose(ds.mean_E_bias.values, pilot.bias["mean_E"][0] * 0.25**level)
    loose = stochpend.simulate(rtol=0.9, **kw)
    assert loose.attrs["accuracy"] == "auto"
    assert loose.attrs["accuracy_level"] < level


@pytest.mark.parametrize(
    ("args", "needle"),
    [
        (["--accuracy", "best"], "--accuracy 'best' is not accepted: one of fixed, auto"),
        (["--rtol", "2"], "--rtol 2.0 is not accepted: a number in (0, 1)"),
        (["--rtol", "nan"], "--rtol nan is not accepted"),
        (["--bias-paths", "1"], "--bias-paths 1 is not accepted: an integer >= 2"),
    ],
)
def test_cli_refuses_bad_accuracy_options(args, needle, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    result = CliRunner().invoke(app, ["simulate", "--paths", "100", "--t-max", "1", *args])
    assert result.exit_code == 2, result.output
    assert needle in " ".join(result.output.split())
    assert "Traceback" not in result.output
    assert list(tmp_path.iterdir()) == []


def test_cli_checkpoints_an_auto_run_with_its_bias_paths(tmp_path, monkeypatch):
    """--accuracy auto and --bias-paths with --checkpoint: the run stochpend.simulate makes."""
    monkeypatch.chdir(tmp_path)
    kw = dict(noise="ou", paths=1000, t_max=10.0, times=(5.0, 10.0), seed=3, h_max=0.4, step_c=0.8)
    result = CliRunner().invoke(app, ["simulate", "--paths", "1000", "--t-max", "10", "--times", "5,10",
                                      "--seed", "3", "--h-max", "0.4", "--step-c", "0.8", "--accuracy", "auto",
                                      "--bias-paths", "256", "--checkpoint", "ck", "--out", "o.nc", "--quiet"])
    assert result.exit_code == 0, result.output
    from stochpend import io

    ds = io.open_results(tmp_path / "o.nc")
    ref = stochpend.simulate(accuracy="auto", bias_paths=256, **kw)
    assert ds.attrs["accuracy"] == "auto" and ds.attrs["accuracy_level"] == ref.attrs["accuracy_level"] >= 1
    for name in ref.data_vars:
        assert np.array_equal(ds[name].values, ref[name].values, equal_nan=True), name
    assert not (tmp_path / "ck").exists()


def test_cli_warns_when_the_bias_exceeds_the_standard_error():
    # the linear harmonic oscillator at a coarse fixed step: an exact bias of <E> of 0.008 at
    # t = 2 (test_estimate_has_the_exact_expectation_of_the_richardson_difference), 4.5
    # standard errors at 80 000 paths, and 10 000 pairs resolve it (error 0.001)
    result = CliRunner().invoke(app, ["simulate", "--potential", "harmonic", "--noise", "white",
                                      "--D", "0.5", "--theta0", "1", "--h-max", "0.2", "--step-c",
                                      "0", "--paths", "80000", "--t-max", "4", "--times", "2,4",
                                      "--seed", "2", "--bias-paths", "10000"])
    assert result.exit_code == 0, result.output
    text = " ".join(result.output.split())
    assert "bias <E>" in text
    assert "<E> at t=2: discretisation bias" in text
    assert "family-wise level over" in text and "rerun with --accuracy auto" in text


def test_spec_pair_function_exists_for_every_noise():
    for noise in ("white", "ou", "dichotomous", "harmonic"):
        assert callable(integrator.build(integrator.spec(noise)).advance_pair)


def test_each_spec_has_its_own_cache_index():
    """Numba's index file is shared by every overload of one function; two processes adding
    different Specs to it at once can leave one KernelSpec's key pointing at another's code. Each
    KernelSpec's kernels therefore get their own index file (stochpend.numerics._jitcache.own_index)."""
    from stochpend.engine import cpu

    paths = set()
    for noise in ("ou", "dichotomous"):
        for adaptive in (True, False):
            spec = integrator.spec(noise, adaptive=adaptive)
            for kern in (cpu.advance_kernel(spec), cpu.pair_advance_kernel(spec)):
                kern = kern.kernel  # the Numba dispatcher under the threads' wrapper
                paths.add(kern._cache._cache_file._index_path)
    assert len(paths) == 8


@pytest.mark.parametrize(("noise", "adaptive"), [("ou", True), ("white", True), ("ou", False)])
def test_pairs_in_simd_lanes_are_the_one_pair_kernel_bit_for_bit(noise, adaptive):
    """The pairs run in SIMD lanes with the run's fast math (integrator.build_pair_lanes): the
    same numbers as advance_pair of that KernelSpec one pair at a time, however the calls are cut
    (max_steps) and whatever the thread count; a lane that swapped its draws, shared a
    neighbour's counter or dropped a half step differs at once."""
    import numba

    from stochpend.engine import cpu
    from stochpend.numerics import rng

    spec = integrator.spec(noise, adaptive=adaptive, fast_math=True)
    assert integrator.lanes_supported(spec)
    n = 300
    key0, key1 = rng.seed_to_key(SEED)
    path0 = np.uint64(bias.BIAS_PATH0)
    out = []
    for advance, threads in ((cpu.pair_advance_kernel(spec), 2), (cpu.pair_advance_kernel(spec), 1),
                             (cpu._pair_path_kernel(spec), 2)):
        previous = numba.get_num_threads()
        numba.set_num_threads(min(threads, previous))
        try:
            x, Om, xf, Of, xi, xa, t, tc = (np.empty(n) for _ in range(8))
            k = np.empty(n, dtype=np.uint64)
            status = np.empty(n, dtype=np.uint8)
            p = spec.noise.record(types.SimpleNamespace(D=1.0, tau=1.0, omega_noise=None))
            cpu.init_kernel(spec)((x, Om, xi, xa, t, tc, k, status), key0, key1, path0, 0.0, True,
                                  0.0, 0.0, True, p)
            xf[:] = x
            Of[:] = Om
            draws = 0
            for t_target in (0.7, 3.0, 8.0):
                while True:
                    d, unfinished = advance((x, Om, xf, Of, xi, xa, t, tc, k, status), t_target, 37,
                                            key0, key1, path0, p,
                                            (1.0, (2.0,), 0.05, 0.1 if adaptive else 0.0))
                    draws += d
                    if unfinished == 0:
                        break
        finally:
            numba.set_num_threads(previous)
        out.append((x, Om, xf, Of, xi, k, status, draws))
    for other in out[1:]:
        for a, b in zip(out[0], other, strict=True):
            assert np.array_equal(a, b)
    x, Om, xf, Of = out[0][:4]
    assert not np.array_equal(x, xf)  # the members differ: a coupled pair, not one path twice
    assert np.median(np.abs(Om - Of)) < 0.1 * np.std(Om)  # ... and most stay close
    assert out[0][-1] == 2 * int(np.sum(out[0][5])) // 2 and np.all(t == 8.0)


def test_auto_does_not_buy_levels_for_times_beyond_the_horizon():
    """OU tau = omega = 1 at the default controls: accurate early, and from t ~ 60 on the pairs
    have decorrelated. auto chooses level 0 from the early times and reports the horizon; the
    same pilot asked about every time would have bought 4 levels (256 times the work) of noise."""
    import dataclasses

    kw = dict(noise="ou", D=1.0, tau=1.0, omega=1.0, paths=4000, t_max=200.0,
              times=(2.0, 5.0, 100.0, 200.0), seed=3)
    choice = bias.choose_level(SimulationConfig.build(**kw), bias.default_bias_paths(4000))
    assert choice.level == 0 and choice.horizon == 100.0
    blind = dataclasses.replace(choice.pilot, decorrelation=None)
    assert bias._needed_level(blind, 4000, None)[0] >= 2
    result = CliRunner().invoke(app, ["simulate", "--accuracy", "auto", "--paths", "4000",
                                      "--t-max", "200", "--times", "2,5,100,200", "--seed", "3"])
    assert result.exit_code == 0, result.output
    text = " ".join(result.output.split())
    assert "accuracy auto chose the step from the times before t = 100" in text
    assert "not certified" in text and "independent ensembles of" in text


def test_verdicts_follow_the_interval_rule():
    """assess on hand-made numbers: the three verdicts, the family size and width, how far the
    entries are resolved and the horizon."""
    times = np.array([1.0, 2.0, 3.0, 4.0])
    b = np.array([0.001, 5.0, 0.3, 0.0])
    b_se = np.array([0.001, 0.1, 0.3, np.nan])
    se = np.ones(4)
    a = bias.assess(times, {"mean_E": (b, b_se)}, {"mean_E": se}, 32,
                    decorrelation=np.array([0.01, 0.2, 0.6, 0.9]))
    assert a.n_tests == 3
    assert a.width == pytest.approx(bias.interval_width(3, 32))
    assert 2.4 < a.width < 3.2  # Bonferroni at 5 % over 3 tests, t with 31 degrees of freedom
    assert list(a.verdict["mean_E"]) == [bias.CERTIFIED_SMALL, bias.SIGNIFICANT,
                                         bias.INCONCLUSIVE, bias.INCONCLUSIVE]
    assert a.certified_until == 2.0 and a.horizon == 3.0
    # more tests, wider intervals: 5.0 +- w 0.1 stays significant, 1.3 +- w 0.1 does not at w > 3
    many = bias.assess(np.arange(400.0), {"mean_E": (np.full(400, 1.3), np.full(400, 0.1))},
                       {"mean_E": np.ones(400)}, 32)
    assert many.width > 4.0 and not np.any(many.verdict["mean_E"] == bias.SIGNIFICANT)


def test_interval_width_is_students_t_quantile_to_the_last_bit():
    """interval_width takes Student's t quantile from scipy.special (scipy.stats costs ~0.6 s
    to import): the same number as scipy.stats.t.isf, bit for bit, over the range used."""
    from scipy.stats import t as student

    for n_tests in (1, 3, 108, 360, 4000):
        for batches in (2, 3, 8, 32, 1000):
            expected = float(student.isf(bias.FAMILY_ALPHA / (2.0 * n_tests), batches - 1))
            assert bias.interval_width(n_tests, batches) == expected
    assert bias.interval_width(0, 32) == math.inf and bias.interval_width(5, 1) == math.inf


def test_the_footer_says_where_a_time_that_is_not_a_shown_row_lies(monkeypatch):
    """Walk-through N4: the footer said 'resolved ... up to t = 11.94' under a table of 12 of 40
    times without that row; a time the table shows is cited as it is."""
    times = np.array([0.1, 1.0, 2.0, 11.94, 20.0, 49.24, 100.0])
    assessment = bias.Assessment(times, {}, 3.0, 10, 11.94, 49.24)
    monkeypatch.setattr(bias, "assess_dataset", lambda ds: assessment)
    ds = types.SimpleNamespace(attrs={"paths": 0})
    line = bias.summary_line(ds, shown=[0, 2, 4, 6])
    assert "up to t = 11.94 (between the rows t = 2 and 20)" in line
    assert "decorrelate from t = 49.24 (between the rows t = 20 and 100)" in line
    line = bias.summary_line(ds, shown=[0, 3, 5, 6])
    assert "up to t = 11.94, inconclusive" in line and "from t = 49.24, beyond" in line
    assert "between" not in bias.summary_line(ds)  # without rows: the times alone
