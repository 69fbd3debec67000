"""When a run's pair kernel is left to the compile helper (stochpend.runs._compile_helper.wanted):
only where it can save time, never where it cannot run or is turned off."""

from __future__ import annotations

from stochpend.engine import cpu
from stochpend.model.settings import SimulationConfig
from stochpend.numerics._jitcache import in_cache
from stochpend.runs import _compile_helper


def test_the_helper_is_wanted_only_for_a_cold_cpu_run_with_pairs(monkeypatch):
    config = SimulationConfig.build(noise="ou", paths=64, t_max=1.0, n_times=2, seed=1)
    monkeypatch.setattr(_compile_helper.os, "cpu_count", lambda: 2)
    assert not _compile_helper.wanted(config, backend="cuda", pairs=True)
    assert not _compile_helper.wanted(config, backend="cpu", pairs=False)
    monkeypatch.setenv(_compile_helper.ENV, "0")
    assert not _compile_helper.wanted(config, backend="cpu", pairs=True)
    monkeypatch.delenv(_compile_helper.ENV)
    monkeypatch.setattr(_compile_helper.os, "cpu_count", lambda: 1)
    assert not _compile_helper.wanted(config, backend="cpu", pairs=True)
    monkeypatch.setattr(_compile_helper.os, "cpu_count", lambda: 2)
    # Wanted exactly when neither the pair kernel nor all of the run's own kernels are cached.
    kernels = cpu.compiled_kernels(cpu.spec_for(config), pairs=True)
    pairs_cached = all(in_cache(k) for kind, k in kernels.items() if kind.startswith("pairs"))
    own_cached = all(in_cache(k) for kind, k in kernels.items() if not kind.startswith("pairs"))
    assert _compile_helper.wanted(config, backend="cpu", pairs=True) == (not pairs_cached and not own_cached)
    import stochpend.numerics._jitcache as jitcache

    monkeypatch.setattr(jitcache, "in_cache", lambda k: False)
    assert _compile_helper.wanted(config, backend="cpu", pairs=True)  # a cold cache: wanted
    monkeypatch.setattr(jitcache, "in_cache", lambda k: True)
    assert not _compile_helper.wanted(config, backend="cpu", pairs=True)  # all cached: nothing to gain


def test_a_started_helper_gets_the_configuration_and_is_waited_for_or_stopped(monkeypatch, tmp_path):
    """The launch itself (the suite runs with the helper off: tests/conftest.py): the helper gets
    the pickled configuration on stdin, :meth:`Helper.wait` returns the seconds it waited,
    :meth:`Helper.stop` ends one still running, and a helper that cannot start is None."""
    import pickle
    import sys

    config = SimulationConfig.build(noise="ou", paths=64, t_max=1.0, n_times=2, seed=1)
    monkeypatch.setattr(_compile_helper, "wanted", lambda *a, **k: True)
    got = tmp_path / "config.pkl"
    monkeypatch.setattr(_compile_helper, "COMMAND", (sys.executable, "-c", "import sys, pathlib; "
                        f"pathlib.Path({str(got)!r}).write_bytes(sys.stdin.buffer.read())"))
    helper = _compile_helper.start(config, backend="cpu", bias_paths=64)
    assert helper is not None
    assert helper.wait() >= 0.0
    assert pickle.loads(got.read_bytes()) == config  # no user observables here: the same object
    monkeypatch.setattr(_compile_helper, "COMMAND", (sys.executable, "-c", "import time; time.sleep(60)"))
    slow = _compile_helper.start(config, backend="cpu", bias_paths=64)
    assert slow is not None
    slow.stop()
    assert slow._process.poll() is not None
    monkeypatch.setattr(_compile_helper, "COMMAND", (str(tmp_path / "no-such-program"),))
    assert _compile_helper.start(config, backend="cpu", bias_paths=64) is None


def test_a_run_waits_for_its_helper_counts_the_wait_as_compiling_and_keeps_its_numbers(monkeypatch):
    """A run with a helper (here one that only sleeps) waits for it before its bias estimate,
    counts the wait in ``compile_time_s``, and has the numbers of a run without one."""
    import sys

    import numpy as np

    import stochpend

    kw = dict(noise="ou", paths=64, t_max=1.0, n_times=2, seed=1, bias_paths=16)
    plain = stochpend.simulate(**kw)
    monkeypatch.setattr(_compile_helper, "wanted", lambda *a, **k: True)
    monkeypatch.setattr(_compile_helper, "COMMAND", (sys.executable, "-c",
                                                     "import sys, time; sys.stdin.buffer.read(); time.sleep(0.5)"))
    helped = stochpend.simulate(**kw)
    assert helped.attrs["compile_time_s"] >= 0.3
    assert set(helped.data_vars) == set(plain.data_vars)
    for name in plain.data_vars:
        assert np.array_equal(helped[name].values, plain[name].values, equal_nan=True), name
