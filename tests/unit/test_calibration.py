"""Estimates calibrated by what the machine measured (issue 36, item 2): the arithmetic, with fake
measurements and fake loads; no wall time is measured or compared here."""

from __future__ import annotations

import json
import os

import pytest

from stochpend.numerics import _calibration as cal
from stochpend.runs import resources


@pytest.fixture
def file(tmp_path):
    return tmp_path / "cache" / cal.FILE_NAME


def test_slowdown_is_the_oversubscription_of_the_cores():
    assert cal.slowdown(1, load=0.0, n_cores=2) == 1.0
    assert cal.slowdown(2, load=0.0, n_cores=2) == 1.0
    assert cal.slowdown(2, load=4.0, n_cores=2) == 3.0  # 6 runnable threads on 2 cores
    assert cal.slowdown(1, load=6.0, n_cores=2) == 3.5
    assert cal.slowdown(1, load=float("nan"), n_cores=2) == 1.0  # unknown load: as idle


def test_unmeasured_machine_uses_the_builtin_figures(file):
    assert cal.compile_scale(file) == 1.0
    assert cal.rate("cpu", 1e7, 2, load=0.0, n_cores=2, file=file) == (2e7, False)
    # ... slowed by the load of now
    assert cal.rate("cpu", 1e7, 2, load=2.0, n_cores=2, file=file) == (1e7, False)


def test_a_compile_measured_under_load_predicts_the_idle_and_the_loaded_machine(file):
    # built-in figures said 6 s; it took 42 s while 6 other threads shared the 2 cores (x3.5)
    cal.record_compile(42.0, 6.0, load=6.0, n_cores=2, file=file)
    assert cal.compile_scale(file) == pytest.approx(2.0)  # 12 s on the idle machine
    # the same kernels again under the same load: 42 s predicted, the measured figure
    assert 6.0 * cal.compile_scale(file) * cal.slowdown(1, load=6.0, n_cores=2) == pytest.approx(42.0)


def test_the_median_of_the_recent_samples(file):
    for measured in (10.0, 11.0, 100.0):  # one outlier
        cal.record_compile(measured, 5.0, load=0.0, n_cores=2, file=file)
    assert cal.compile_scale(file) == pytest.approx(2.2)
    for _ in range(cal.KEEP):
        cal.record_compile(5.0, 5.0, load=0.0, n_cores=2, file=file)
    assert cal.compile_scale(file) == 1.0  # only the last KEEP samples count
    assert len(cal.read(file)["compile"]) == cal.KEEP


def test_rates_are_stored_per_thread_as_on_an_idle_machine(file):
    # 1e8 lower-bound steps in 10 s on 2 threads, with load 2 on 2 cores (x2): 1e7/s per thread idle
    cal.record_rate("cpu", 1e8, 10.0, 2, load=2.0, n_cores=2, file=file)
    assert cal.rate("cpu", 1.4e7, 2, load=0.0, n_cores=2, file=file) == (pytest.approx(2e7), True)
    assert cal.rate("cpu", 1.4e7, 1, load=0.0, n_cores=2, file=file) == (pytest.approx(1e7), True)
    # predicted under the load it was measured at: the measured rate itself
    assert cal.rate("cpu", 1.4e7, 2, load=2.0, n_cores=2, file=file)[0] == pytest.approx(1e7)
    # kinds are apart
    assert cal.rate("bfpe", 2e7, 1, load=0.0, n_cores=2, file=file) == (2e7, False)


def test_short_or_broken_samples_are_not_stored(file):
    cal.record_compile(0.1, 5.0, load=0.0, file=file)  # below MIN_SECONDS: noise
    cal.record_rate("cpu", 1e6, 1.0, 2, load=0.0, file=file)  # below MIN_RATE_SECONDS: fixed costs
    cal.record_rate("cpu", float("inf"), 5.0, 2, load=0.0, file=file)
    cal.record_compile(float("nan"), 5.0, load=0.0, file=file)
    assert not file.exists() or cal.read(file) in ({}, {"compile": [], "rate": {}})


def test_a_damaged_or_foreign_file_is_ignored_and_rewritten(file):
    file.parent.mkdir(parents=True)
    file.write_text("{not json")
    assert cal.read(file) == {} and cal.compile_scale(file) == 1.0
    cal.record_compile(10.0, 5.0, load=0.0, n_cores=2, file=file)
    assert cal.compile_scale(file) == pytest.approx(2.0)
    data = json.loads(file.read_text())
    data["hosts"][cal._host()]["compile"] = ["x", -1, None, 4.0]  # hand-edited nonsense
    file.write_text(json.dumps(data))
    assert cal.compile_scale(file) == 4.0
    # another host's samples are not this one's
    data["hosts"] = {"elsewhere": {"compile": [9.0]}}
    file.write_text(json.dumps(data))
    assert cal.compile_scale(file) == 1.0


def test_written_atomically_and_nothing_left_behind(file):
    cal.record_rate("cpu", 1e8, 10.0, 2, load=0.0, n_cores=2, file=file)
    assert [p.name for p in file.parent.iterdir()] == [cal.FILE_NAME]


def test_an_unwritable_directory_is_no_error(tmp_path):
    target = tmp_path / "ro"
    target.mkdir()
    os.chmod(target, 0o500)
    try:
        cal.record_compile(10.0, 5.0, load=0.0, file=target / cal.FILE_NAME)  # no exception
    finally:
        os.chmod(target, 0o700)


def test_the_file_sits_with_numbas_cache(monkeypatch, tmp_path):
    monkeypatch.setenv("NUMBA_CACHE_DIR", str(tmp_path))
    assert cal.path() == tmp_path / cal.FILE_NAME
    monkeypatch.delenv("NUMBA_CACHE_DIR")
    assert cal.path().parent.name == "__pycache__"


def test_the_estimates_use_the_calibration(monkeypatch, tmp_path):
    """resources' rate and compile seconds come from the file: the estimate a user reads."""
    monkeypatch.setenv("NUMBA_CACHE_DIR", str(tmp_path))
    monkeypatch.setattr(cal, "current_load", lambda: 0.0)
    monkeypatch.setattr(cal, "cores", lambda: 2)
    from stochpend.model.settings import SimulationConfig

    config = SimulationConfig.build(paths=100_000, t_max=1000.0, n_times=4)  # seconds of work: a sample
    before = resources.estimate(config, threads=2)
    assert before.rate == pytest.approx(2 * resources.CPU_PATH_STEPS_PER_S_PER_CORE)
    assert "measured here" not in before.describe()
    cal.record_rate(resources.kernel_kind(config), before.min_path_steps, before.seconds * 4, 2, load=0.0,
                    n_cores=2)  # 4x slower
    after = resources.estimate(config, threads=2)
    assert after.seconds == pytest.approx(4 * before.seconds)
    assert "(rate measured here)" in after.describe()
    # compile seconds: the built-in figures times the measured scale and the load now
    from stochpend.numerics import _jitcache

    monkeypatch.setattr(_jitcache, "in_cache", lambda kernel: False)  # a cold kernel cache
    builtin = resources.compile_seconds(config, calibrated=False)
    assert builtin == sum(resources.COMPILE_S[k] for k in ("init", "advance", "accumulate", "pairs"))
    cal.record_compile(3 * builtin, builtin, load=0.0, n_cores=2)
    assert resources.compile_seconds(config) == pytest.approx(3 * builtin)
    monkeypatch.setattr(cal, "current_load", lambda: 3.0)  # (3 + 1) / 2: twice as long
    assert resources.compile_seconds(config) == pytest.approx(6 * builtin)


def test_bfpe_announces_a_long_solve_at_the_measured_rate(monkeypatch, tmp_path):
    """bfpe printed no estimate (issue 36): a solve expected beyond LONG_RUN_S says so first."""
    from stochpend.theory import bfpe

    monkeypatch.setenv("NUMBA_CACHE_DIR", str(tmp_path))
    monkeypatch.setattr(cal, "current_load", lambda: 0.0)
    lines: list[str] = []
    bfpe.solve_bfpe(D=1.0, tau=1.0, t_max=10.0, n_times=3, n_cells=50, log=lines.append)
    assert lines == []  # short at the built-in rate
    work = 50 * 10_000.0  # a measured rate this slow makes the same solve "long"
    cal.record_rate("bfpe", work, 1000.0, 1, load=0.0)
    bfpe.solve_bfpe(D=1.0, tau=1.0, t_max=10.0, n_times=3, n_cells=50, log=lines.append)
    assert len(lines) == 1 and lines[0].startswith("estimate: about ") and "cell-steps" in lines[0]


def test_a_long_sweep_has_an_estimate_line(monkeypatch, tmp_path):
    from stochpend.cli._scale import sweep_estimate
    from stochpend.sweep import load_spec

    monkeypatch.setenv("NUMBA_CACHE_DIR", str(tmp_path))
    monkeypatch.setattr(cal, "current_load", lambda: 0.0)
    spec = tmp_path / "s.toml"
    spec.write_text('[base]\nnoise = "ou"\npaths = 1000\nt_max = 10\nn_times = 2\n[grid]\nomega = [0, 1]\n')
    plan = load_spec(spec)
    assert sweep_estimate(plan, pairs=False) is None  # 4e5 path-steps: short
    cal.record_rate(resources.kernel_kind(plan.configs[0]), 1e5, 10.0, cal.cores(), load=0.0)  # 1e4 path-steps/s
    line = sweep_estimate(plan, pairs=False)
    assert line is not None and line.startswith("2 parameter sets, at least 4e+05 path-steps")
    assert "rate measured here" in line


def test_a_sweep_of_many_tiny_sets_counts_each_sets_own_cost(monkeypatch, tmp_path):
    """NEW03 (hostile-turn4): 99 999 sets of 2 paths ran for about an hour with no estimate line:
    their 2e5 path-steps are 0.03 s of work, each set's own cost (its tasks, statistics and bias
    estimate) was not counted."""
    from types import SimpleNamespace

    from stochpend.cli._scale import SET_SECONDS, SET_SECONDS_WITH_BIAS, sweep_estimate
    from stochpend.model.settings import SimulationConfig

    monkeypatch.setenv("NUMBA_CACHE_DIR", str(tmp_path))
    monkeypatch.setattr(cal, "current_load", lambda: 0.0)
    monkeypatch.setattr(resources, "compile_seconds", lambda *a, **k: 0.0)  # the sets' cost alone
    config = SimulationConfig.build(paths=2, t_max=0.05, n_times=1)
    few = SimpleNamespace(configs=[config] * 100)
    assert sweep_estimate(few, pairs=True) is None
    many = SimpleNamespace(configs=[config] * 20_000)
    line = sweep_estimate(many, pairs=True)
    assert line is not None and line.startswith("20000 parameter sets, at least 4e+04 path-steps"), line
    assert f"roughly {resources.format_seconds(20_000 * SET_SECONDS_WITH_BIAS)} on " in line, line
    assert line.endswith("and ~3 ms a set"), line
    assert sweep_estimate(many, pairs=False) is not None and 20_000 * SET_SECONDS > resources.LONG_RUN_S


def test_a_kernels_own_rate_never_another_kernels(monkeypatch, tmp_path):
    """A quartic oscillator's runs do far more than the lower bound's work (its energy grows, its
    steps shrink): its samples set its own estimates, never the pendulum's."""
    monkeypatch.setenv("NUMBA_CACHE_DIR", str(tmp_path))
    monkeypatch.setattr(cal, "current_load", lambda: 0.0)
    monkeypatch.setattr(resources, "_cores", lambda threads: 2)
    monkeypatch.setattr(cal, "cores", lambda: 2)
    from stochpend.model.settings import SimulationConfig

    quartic = SimulationConfig.build(paths=100_000, t_max=1000.0, n_times=4, potential="power", power_n=2)
    kind = resources.kernel_kind(quartic)
    assert kind.startswith("cpu ") and "power" in kind
    builtin = 2 * resources.CPU_PATH_STEPS_PER_S_PER_CORE
    assert resources.estimate(quartic).rate == pytest.approx(builtin)
    cal.record_rate(kind, 1e8, 50.0, 2, load=0.0, n_cores=2)  # this kernel: 1e6 a thread
    assert resources.estimate(quartic).rate == pytest.approx(2e6)
    pendulum = SimulationConfig.build(paths=100_000, t_max=1000.0, n_times=4)
    assert resources.estimate(pendulum).rate == pytest.approx(builtin)  # unmeasured: the built-in figure
