"""Numba's performance warnings never reach a user of the CUDA backend (issue 34, item 2).

NVIDIA's numba-cuda raises its own ``numba.cuda.core.errors.NumbaPerformanceWarning``, which is
not numba's ``numba.core.errors.NumbaPerformanceWarning`` nor a subclass of it: silencing only
numba's let every small launch (the availability probe's four threads, a small ensemble, the
statistics kernel's one block per batch) print Numba's advice. The backend silences both around
its launches and says in its own words when a chunk is too small to fill the GPU. No GPU needed.
"""

from __future__ import annotations

import importlib.util
import types
import warnings

import numba.core.errors
import pytest

from stochpend.engine import cuda as gpu
from tests import conftest


def _classes() -> list[type[Warning]]:
    classes = [numba.core.errors.NumbaPerformanceWarning]
    if importlib.util.find_spec("numba_cuda") is not None:
        from numba.cuda.core.errors import NumbaPerformanceWarning

        classes.append(NumbaPerformanceWarning)
    return classes


def test_both_numba_performance_warning_classes_are_silenced_where_importable():
    assert set(_classes()) <= set(gpu.PERFORMANCE_WARNINGS)
    for category in gpu.PERFORMANCE_WARNINGS:
        with warnings.catch_warnings():
            warnings.simplefilter("error")
            with gpu._quiet():
                warnings.warn(category("Grid size 1 will likely result in GPU under-utilization"), stacklevel=1)
            # outside the backend's launches the filter is as it was
            with pytest.raises(category):
                warnings.warn(category("outside"), stacklevel=1)


def test_a_chunk_too_small_for_the_gpu_is_said_in_stochpends_words():
    sms, tpb = 132, 128
    enough = 2 * sms * tpb  # two blocks per multiprocessor
    assert gpu.fill_note(enough, sms, tpb) is None
    assert gpu.fill_note(10 * enough, sms, tpb) is None
    note = gpu.fill_note(enough - tpb, sms, tpb)  # one block short
    assert note is not None and "\n" not in note
    assert f"{enough - tpb} paths" in note and f"{sms} multiprocessors" in note and f"{enough} paths" in note
    assert "Numba" not in note and "occupancy" not in note
    small = gpu.fill_note(1, sms, tpb)
    assert small is not None and "1 blocks" in small
    # no multiprocessor count (the simulator, an unreadable device): nothing to say
    assert gpu.fill_note(1, 0, tpb) is None


def test_the_suite_ignores_numba_cudas_own_class_only_where_it_is_installed(monkeypatch):
    added: list[tuple[str, str]] = []
    config = types.SimpleNamespace(addinivalue_line=lambda name, line: added.append((name, line)))
    monkeypatch.setattr(importlib.util, "find_spec", lambda name: object() if name == "numba_cuda" else None)
    conftest.pytest_configure(config)  # type: ignore[arg-type]
    assert added == [("filterwarnings", "ignore::numba.cuda.core.errors.NumbaPerformanceWarning")]
    added.clear()
    monkeypatch.setattr(importlib.util, "find_spec", lambda name: None)
    conftest.pytest_configure(config)  # type: ignore[arg-type]
    assert added == []


_SIMULATED_RUN = r"""
import json, sys, warnings
import stochpend
from stochpend.engine import cuda as gpu
gpu._multiprocessors = lambda: int(sys.argv[1])  # the simulator has no SM count: a GPU's
with warnings.catch_warnings(record=True) as caught:
    warnings.simplefilter("always")
    for category in gpu.PERFORMANCE_WARNINGS:
        warnings.simplefilter("error", category)  # Numba's own advice must not reach the user
    stochpend.simulate(noise="ou", D=1.0, tau=1.0, omega=1.0, paths=64, n_batches=2, t_max=0.05,
                       n_times=2, seed=1, bias_paths=0, backend="cuda")
print(json.dumps([str(w.message) for w in caught if w.category.__name__ == "StochpendWarning"]))
"""


@pytest.mark.parametrize("sms", [132, 0])
def test_a_run_on_too_few_blocks_says_so_once(sms):
    """In the CUDA simulator, with the SM count of a 132-SM GPU: 64 paths are one block, one
    note (and none without an SM count)."""
    import json
    import os
    import subprocess
    import sys
    from pathlib import Path

    root = Path(__file__).resolve().parents[2]
    env = {**os.environ, "NUMBA_ENABLE_CUDASIM": "1",
           "PYTHONPATH": os.pathsep.join((str(root / "src"), str(root / "tests" / "_simulator_site")))}
    res = subprocess.run([sys.executable, "-c", _SIMULATED_RUN, str(sms)], env=env, capture_output=True,
                         text=True, timeout=600)
    assert res.returncode == 0, res.stderr
    notes = json.loads(res.stdout.strip().splitlines()[-1])
    if sms == 0:
        assert notes == []
    else:
        tpb = 32  # the simulator's block (cuda.THREADS_PER_BLOCK under NUMBA_ENABLE_CUDASIM)
        assert notes == [gpu.fill_note(64, sms, tpb)], notes
