"""Compiling is reported apart from the run (issue 20): ``compile_time_s`` beside
``wall_time_s``, a one-line note on stderr only when a kernel is not in Numba's cache, and the
expected compile time in the estimates of a run whose kernels are not cached."""

from __future__ import annotations

import json
import os
import re
import subprocess
import sys
from pathlib import Path

import numpy as np

import stochpend

SRC = str(Path(stochpend.__file__).resolve().parent.parent)

#: A tiny run in a fresh process: the expected compile time before it, its attrs and stderr.
_SCRIPT = """
import json, sys
import stochpend
from stochpend.numerics import _calibration
from stochpend.runs import resources
from stochpend.model.settings import SimulationConfig
# The estimate scales with the load average (_calibration.slowdown), read anew for the note and
# for 'before': held at 0 so that both are the same number on a busy CI (it moved ~10 s -> ~11 s).
_calibration.current_load = lambda: 0.0
kw = dict(noise="ou", paths=64, t_max=1.0, n_times=2, seed=1)
config = SimulationConfig.build(**kw)
before = resources.compile_seconds(config, pairs=False)
ds = stochpend.simulate(**kw, bias_paths=0)
after = resources.compile_seconds(config, pairs=False)
a = ds.attrs
# The built-in accumulator and observable (their code is the package's): cached on disk too.
tracked = stochpend.simulate(**kw, bias_paths=0, observables=("displacement", "log_energy"))
print(json.dumps({"tracked_compile": float(tracked.attrs["compile_time_s"]),
                  "before": before, "after": after, "compile": float(a["compile_time_s"]),
                  "wall": float(a["wall_time_s"]), "sim": float(a["simulation_wall_time_s"]),
                  "rate": float(a["path_steps_per_s"]), "steps": int(a["path_steps"])}))
"""


def _run(cache_dir: Path) -> tuple[dict, str]:
    env = {**os.environ, "NUMBA_CACHE_DIR": str(cache_dir),
           "PYTHONPATH": os.pathsep.join([SRC, os.environ.get("PYTHONPATH", "")])}
    done = subprocess.run([sys.executable, "-c", _SCRIPT], env=env, capture_output=True,
                          text=True, timeout=300)
    assert done.returncode == 0, done.stderr
    return json.loads(done.stdout.strip().splitlines()[-1]), done.stderr


def test_a_cold_cache_compiles_once_with_a_note_and_reports_it_apart(tmp_path):
    """An empty kernel cache (a fresh NUMBA_CACHE_DIR): the run says once, before compiling,
    which kernels compile and for about how long, and stores the compile time apart: the wall
    time and the rate are the run's own. The same run again (cached kernels): no note, no
    compile time, no expected compile time; also for a run with the built-in accumulator and
    observable (displacement, log_energy)."""
    cold, err = _run(tmp_path)
    notes = [line for line in err.splitlines() if line.startswith("compiling kernels for ")]
    assert notes[0] == ("compiling kernels for pendulum/force/ou/float64/adaptive/fast (first use: "
                        f"~{cold['before']:.2g} s, cached after)"), err
    # The tracked run compiles its own two kernels, and says so with their expected time.
    assert len(notes) == 2 and re.fullmatch(r"compiling kernels for \S+ \(first use: ~[0-9.]+ s, cached after\)",
                                            notes[1]), err
    assert cold["before"] > 0 and cold["after"] == 0
    assert cold["compile"] > 0.5  # seconds of Numba compiling, at least
    assert 0 < cold["wall"] < cold["compile"]  # a few ms of work, compiling left out
    assert cold["sim"] <= cold["wall"]
    assert np.isclose(cold["rate"], cold["steps"] / cold["wall"])

    assert cold["tracked_compile"] > 0.5  # the one-path loop with tracking, the accumulate kernel
    warm, err = _run(tmp_path)
    assert "compiling kernels" not in err, err
    assert warm["before"] == 0 and warm["compile"] == 0.0
    assert warm["tracked_compile"] == 0.0  # a run with built-in accumulators compiles once, ever
    assert warm["steps"] == cold["steps"]


def test_compile_clock_times_compiles_and_notes_the_first_only():
    """A compile inside the clock is timed and announced once, before it runs; a function
    already compiled (what a cached kernel is) adds neither time nor a note."""
    import numba

    from stochpend.numerics._jitcache import CompileClock

    @numba.njit
    def first(x):
        return x + 1

    @numba.njit
    def second(x):
        return first(x) * 2  # nested: counted inside its caller's interval

    notes = []
    with CompileClock(lambda: notes.append(first.signatures[:])) as clock:
        assert second(1) == 4
        after_compile = clock.seconds
        assert second(2) == 6
    assert notes == [[]]  # called once, before ``first`` was compiled
    assert after_compile > 0
    assert clock.seconds == after_compile
    first(1.5)  # outside the clock: not counted
    assert clock.seconds == after_compile


def test_a_run_reports_compile_time_apart_from_its_wall_time():
    ds = stochpend.simulate(noise="ou", paths=64, t_max=1.0, n_times=2, seed=1, bias_paths=0)
    assert ds.attrs["compile_time_s"] >= 0.0
    assert 0.0 < ds.attrs["simulation_wall_time_s"] <= ds.attrs["wall_time_s"]


def test_the_estimate_line_counts_the_compile_time():
    from stochpend.model.settings import SimulationConfig
    from stochpend.runs import resources

    config = SimulationConfig.build(noise="ou", paths=64, t_max=1.0, n_times=2, seed=1)
    est = resources.estimate(config)
    assert est.compile_seconds == 0 and "compiling" not in est.describe()
    cold = resources.Estimate(**{**est.__dict__, "compile_seconds": 12.0})
    assert cold.total_seconds == est.seconds + 12.0
    assert "plus ~12 s compiling kernels (first use, cached after)" in cold.describe()
    # Every kernel a run calls is counted once, in kinds resources.COMPILE_S knows.
    from stochpend.engine import cpu

    kinds = set(cpu.compiled_kernels(cpu.spec_for(config), pairs=True))
    other = SimulationConfig.build(noise="dichotomous", paths=64, t_max=1.0, n_times=2, seed=1)
    kinds |= set(cpu.compiled_kernels(cpu.spec_for(other), pairs=True))
    assert kinds == set(resources.COMPILE_S)
    counted: set = set()
    first = resources.compile_seconds(config, counted=counted)
    assert resources.compile_seconds(config, counted=counted) == 0.0  # counted already
    assert first <= sum(resources.COMPILE_S.values())


#: A cold run of the demo's KernelSpec in a fresh process, with the compile helper (or, with
#: ``fail``, a helper that exits at once): per kernel, Numba's cache hits and misses in this
#: process, and every data variable of the result.
_HELPER_SCRIPT = """
import json, sys
import numpy as np
import stochpend
from stochpend.runs import _compile_helper
from stochpend.engine import cpu
from stochpend.model.settings import SimulationConfig
if sys.argv[1] == "fail":
    _compile_helper.COMMAND = (sys.executable, "-c", "import sys; sys.exit(3)")
kw = dict(noise="ou", paths=256, t_max=5.0, n_times=3, seed=3)
ds = stochpend.simulate(**kw, bias_paths=64)
kernels = cpu.compiled_kernels(cpu.spec_for(SimulationConfig.build(**kw)))
stats = {kind: [sum(k.stats.cache_hits.values()), sum(k.stats.cache_misses.values())]
         for kind, k in kernels.items()}
np.savez(sys.argv[2], **{name: ds[name].values for name in ds.data_vars})
print(json.dumps({"stats": stats, "compile": float(ds.attrs["compile_time_s"])}))
"""


def _helper_run(tmp_path: Path, mode: str) -> tuple[dict, dict]:
    cache = tmp_path / f"cache-{mode}"
    out = tmp_path / f"{mode}.npz"
    env = {**os.environ, "NUMBA_CACHE_DIR": str(cache),
           "PYTHONPATH": os.pathsep.join([SRC, os.environ.get("PYTHONPATH", "")])}
    env.pop("STOCHPEND_COMPILE_HELPER", None)
    done = subprocess.run([sys.executable, "-c", _HELPER_SCRIPT, mode, str(out)], env=env,
                          capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, done.stderr
    with np.load(out) as arrays:
        data = {name: arrays[name] for name in arrays.files}
    return json.loads(done.stdout.strip().splitlines()[-1]), data


def test_the_compile_helper_compiles_the_pair_kernel_and_changes_no_number(tmp_path):
    """A cold run on 2+ CPUs has its bias-pair kernel compiled by a helper process meanwhile:
    this process loads it from the cache (a hit, no miss), and every number, the bias estimate
    included, equals that of a run whose helper failed, which compiled the kernel itself."""
    if (os.cpu_count() or 1) < 2:
        import pytest

        pytest.skip("the helper runs on machines with two or more CPUs only")
    helped, helped_data = _helper_run(tmp_path, "help")
    failed, failed_data = _helper_run(tmp_path, "fail")
    pairs = next(kind for kind in helped["stats"] if kind.startswith("pairs"))
    assert helped["stats"][pairs] == [1, 0], helped
    assert failed["stats"][pairs] == [0, 1], failed
    assert failed["stats"]["advance"] == [0, 1] and helped["stats"]["advance"] == [0, 1]
    assert helped["compile"] > 0 and failed["compile"] > 0
    assert helped_data.keys() == failed_data.keys() and any(k.startswith("bias") for k in helped_data)
    for name, value in helped_data.items():
        np.testing.assert_array_equal(value, failed_data[name], err_msg=name)
