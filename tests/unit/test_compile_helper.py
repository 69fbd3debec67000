"""When a run's pair kernel is left to the compile helper (stochpend._compile_helper.wanted):
only where it can save time, never where it cannot run or is turned off."""

from __future__ import annotations

from stochpend import _compile_helper
from stochpend._backends import cpu
from stochpend._jitcache import in_cache
from stochpend.params import SimulationConfig


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
    import stochpend._jitcache as jitcache

    monkeypatch.setattr(jitcache, "in_cache", lambda k: False)
    assert _compile_helper.wanted(config, backend="cpu", pairs=True)  # a cold cache: wanted
    monkeypatch.setattr(jitcache, "in_cache", lambda k: True)
    assert not _compile_helper.wanted(config, backend="cpu", pairs=True)  # all cached: nothing to gain
