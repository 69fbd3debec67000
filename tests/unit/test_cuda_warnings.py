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

from stochpend._backends import cuda as gpu
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
