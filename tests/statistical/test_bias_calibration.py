"""Calibration of what the bias estimate says (stochpend.bias.assess, issue "bias you can trust").

A warning is a statistical claim, so its rates are measured, not assumed:

* false alarms: over many independent runs (seeds) of cases whose true bias is far below the
  standard error, the fraction of runs with *any* significant (statistic, time) -- what the CLI
  warns about -- is at most the stated family-wise level, 5 %;
* detection: a case with a real bias of 3-5 standard errors at 10^4 paths (the truth measured
  here by brute-force refinement) is flagged in at least 90 % of runs;
* coverage: where the truth is exact (the harmonic oscillator with white noise, whose scheme and
  limit moments are closed linear maps), value - bias is within 4 combined errors of the exact
  value at every output time;
* the horizon: the pairs of OU D = tau = omega = 1 stay coupled at least up to t = 20
  (docs/numerics.md), and the estimate certifies the bias there early on.

Rates are printed (``pytest -s``) and recorded in docs/numerics.md. The full calibration is in the
slow suite; the default suite runs a small version that still fails on the previous rule
(any |b| > 2 sigma_b and |b| > SE warned: most runs of the README's command did).
"""

from __future__ import annotations

import math

import numpy as np
import pytest

import stochpend
from stochpend import bias
from tests.conftest import SEED, Z_TOL
from tests.statistical.test_weak_order import OMEGA as OMEGA_H
from tests.statistical.test_weak_order import X0 as X0_H
from tests.statistical.test_weak_order import D as D_H
from tests.statistical.test_weak_order import exact_second_moments

#: Cases whose true bias at the default step control is far below the standard error of a
#: small run (docs/numerics.md: below 0.1 standard error of a 10^5-path run everywhere).
QUIET_CASES = {
    "ou tau=1 omega=1": dict(noise="ou", D=1.0, tau=1.0, omega=1.0, t_max=50.0, n_times=16),
    "white omega=1": dict(noise="white", D=1.0, omega=1.0, t_max=20.0, n_times=12),
    "ou tau=0.1 omega=0": dict(noise="ou", D=1.0, tau=0.1, omega=0.0, t_max=20.0, n_times=12),
}

#: A real bias: the pendulum with weak OU noise from a fixed angle at a coarse fixed step;
#: <E>(2) is off by about 4.5 standard errors of a 10^4-path run (measured below).
BIASED = dict(noise="ou", D=0.1, tau=1.0, omega=1.0, theta0=2.0, h_max=0.25, step_c=0.0,
              times=(1.0, 2.0, 4.0, 8.0), t_max=8.0)


def _alarmed(ds) -> bool:
    verdicts = bias.assess_dataset(ds)
    return any(np.any(v == bias.SIGNIFICANT) for v in verdicts.verdict.values())


def _rate(k: int, n: int) -> str:
    p = k / n
    return f"{k}/{n} = {100 * p:.1f} % +- {100 * math.sqrt(max(p * (1 - p), 1.0 / n) / n):.1f} %"


def _false_alarms(case: dict, runs: int, paths: int) -> int:
    return sum(_alarmed(stochpend.simulate(paths=paths, seed=SEED + s, **case))
               for s in range(runs))


def test_few_false_alarms_on_quiet_runs():
    """40 small runs of the OU case: the old rule warned in most of them; at 5 % family-wise
    at most 2 may (P(more than 2 | rate 5 %) = 0.32; the measured rate is far below 5 %)."""
    k = _false_alarms(QUIET_CASES["ou tau=1 omega=1"], 40, 2000)
    print(f"false alarms, ou tau=1 omega=1, 2000 paths: {_rate(k, 40)}")
    assert k <= 2


@pytest.mark.slow
@pytest.mark.parametrize("name", list(QUIET_CASES))
def test_false_alarm_rate_is_at_most_five_percent(name):
    """200 seeds per case at 2000 and at 10^4 paths: the fraction of runs with any significant
    entry is at most 5 %."""
    for paths in (2000, 10_000):
        runs = 200
        k = _false_alarms(QUIET_CASES[name], runs, paths)
        print(f"false alarms, {name}, {paths} paths: {_rate(k, runs)}")
        assert k <= 0.05 * runs


def _true_bias_of_mean_E_at_2() -> tuple[float, float]:
    """(bias, its error) of <E>(2) at BIASED's step, by brute force: the run at h and at h/8
    (2*10^5 paths each, independent seeds), Richardson-scaled by 64/63."""
    coarse = stochpend.simulate(paths=200_000, seed=SEED, bias_paths=0, **BIASED)
    fine = stochpend.simulate(paths=200_000, seed=SEED + 1, bias_paths=0,
                              **{**BIASED, "h_max": BIASED["h_max"] / 8})
    j = 1
    d = float(coarse.mean_E[j] - fine.mean_E[j]) * 64 / 63
    e = math.hypot(float(coarse.mean_E_stderr[j]), float(fine.mean_E_stderr[j])) * 64 / 63
    return d, e


@pytest.mark.parametrize("runs", [pytest.param(20, id="20-runs"),
                                  pytest.param(100, id="100-runs", marks=pytest.mark.slow)])
def test_real_bias_of_a_few_standard_errors_is_detected(runs):
    """BIASED at 10^4 paths, default pairs: the truth, measured by refinement, is 3-5 standard
    errors; the warning flags <E> in at least 90 % of the runs, with the right sign."""
    truth, truth_se = _true_bias_of_mean_E_at_2()
    flagged = 0
    ratios = []
    for s in range(runs):
        ds = stochpend.simulate(paths=10_000, seed=SEED + 100 + s, **BIASED)
        se = float(ds.mean_E_stderr[1])
        ratios.append(truth / se)
        v = bias.assess_dataset(ds).verdict["mean_E"]
        if v[1] == bias.SIGNIFICANT and np.sign(ds.mean_E_bias[1]) == np.sign(truth):
            flagged += 1
    r = float(np.median(ratios))
    print(f"true bias of <E>(2): {truth:.5f} +- {truth_se:.5f} = {r:.2f} standard errors; "
          f"flagged {_rate(flagged, runs)}")
    assert 3.0 <= r <= 5.0 and abs(truth) > 4 * truth_se
    assert flagged >= 0.9 * runs


@pytest.mark.parametrize("h", [0.2, 0.1])
def test_value_minus_bias_covers_the_exact_limit(h):
    """The harmonic oscillator with white noise (noise on the force), fixed step h, start
    (X0, 0): <x^2>, <Omega^2> and <E> have exact limits (test_weak_order). At every output time
    value - bias is within 4 combined errors of them, while at h = 0.2 the raw value is not
    (the bias is resolved and large): the correction is real, and its error bar honest."""
    times = (0.5, 1.0, 2.0, 3.0, 4.0)
    ds = stochpend.simulate(noise="white", D=D_H, omega=OMEGA_H, potential="harmonic",
                            theta0=X0_H, Omega0=0.0, h_max=h, step_c=0.0, paths=100_000,
                            t_max=4.0, times=times, seed=SEED, bias_paths=25_000)
    worst_raw = 0.0
    for j, t in enumerate(times):
        x2, _, O2 = exact_second_moments(t)
        exact = {"mean_sin2theta": x2, "mean_Omega2": O2, "mean_E": 0.5 * O2 + 0.5 * OMEGA_H**2 * x2}
        for name, want in exact.items():
            value, se = float(ds[name][j]), float(ds[f"{name}_stderr"][j])
            b, b_se = float(ds[f"{name}_bias"][j]), float(ds[f"{name}_bias_stderr"][j])
            z = (value - b - want) / math.hypot(se, b_se)
            assert abs(z) < Z_TOL, f"h={h} t={t} {name}: {value - b:.5f} vs exact {want:.5f} (z={z:+.1f})"
            worst_raw = max(worst_raw, abs(value - want) / se)
    if h == 0.2:
        assert worst_raw > 1.5 * Z_TOL, worst_raw


def test_pairs_stay_coupled_past_twenty_correlation_times():
    """OU D = tau = omega = 1 (t_c = 1), 10^4 paths: the pairs decorrelate (sqrt(1 - r) > 1/2)
    no earlier than t = 20 (docs/numerics.md measured 'from t ~ 20' with the one-path pairs), and
    every entry is resolved up to t >= 5."""
    for seed in (SEED, SEED + 1):
        ds = stochpend.simulate(noise="ou", D=1.0, tau=1.0, omega=1.0, paths=10_000, t_max=200.0,
                                n_times=24, seed=seed)
        verdicts = bias.assess_dataset(ds)
        print(f"seed {seed}: resolved up to t = {verdicts.certified_until:.3g}, "
              f"pairs decorrelate from t = {verdicts.horizon:.3g}")
        assert verdicts.horizon >= 20.0
        assert verdicts.certified_until >= 5.0
        assert ds.attrs["bias_horizon"] == verdicts.horizon


@pytest.mark.slow
@pytest.mark.parametrize("seed", [1, 2, 3])
def test_readme_command_prints_no_bias_warning(seed):
    """The README's command (10^4 paths to t = 1000, 40 times) with seeds 1, 2, 3: no warning
    (the old rule printed three for seed 1)."""
    from stochpend.cli import bias_warnings, shown_rows

    ds = stochpend.simulate(noise="ou", D=1.0, tau=1.0, omega=1.0, paths=10_000, t_max=1000.0,
                            n_times=40, seed=seed)
    assert bias_warnings(ds, shown_rows(ds)) == []
