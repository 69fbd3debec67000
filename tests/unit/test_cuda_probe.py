"""The CUDA stack self-test: a GPU whose CUDA stack cannot compile a kernel is 'unusable'.

numba-cuda 0.30.4 with numpy 2.5 imports, finds the driver and the GPU, and fails at the first
kernel compile ("module 'numpy' has no attribute 'row_stack'"). Here the device check is made
to say yes and the probe's compile step to fail that way; in Numba's CUDA simulator (a
subprocess) the real probe compiles and runs its kernel.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

import stochpend
from stochpend import cli
from stochpend.engine import cuda as gpu
from stochpend.engine import cuda_probe
from stochpend.runs.simulate import cuda_status, resolve_backend

ROW_STACK = "module 'numpy' has no attribute 'row_stack'"
GPU = "NVIDIA Fake (compute capability 9.0)"


@pytest.fixture
def broken_stack(monkeypatch):
    """A GPU that the driver sees, and a CUDA stack that cannot compile; counts compiles."""
    calls = []

    def compile_fails():
        calls.append(1)
        raise AttributeError(ROW_STACK)

    monkeypatch.setattr(gpu, "availability", lambda: (True, GPU))
    monkeypatch.setattr(gpu, "_simulator_enabled", lambda: False)
    monkeypatch.setattr(cli, "_no_cuda_driver", lambda: None)  # info's quick look: a driver is there
    monkeypatch.setattr(cuda_probe, "_compile_and_launch", compile_fails)
    cuda_probe.probe.cache_clear()
    yield calls
    cuda_probe.probe.cache_clear()


def _normalised(text: str) -> str:
    """Rich table text as one line: box characters and wrapping removed."""
    return " ".join(text.replace("│", " ").split())


def test_broken_stack_is_unusable_and_compiled_once(broken_stack):
    reason = f"{GPU}: a test kernel fails to compile or run (AttributeError: {ROW_STACK})"
    assert cuda_status() == (False, reason, True)
    assert cuda_status("auto") == (False, reason, True)
    with pytest.raises(ValueError) as info:
        resolve_backend("cuda")
    assert str(info.value) == (f"backend='cuda' is not accepted: {reason}; install a numba-cuda that works "
                               "with this numpy (pip install 'stochpend[cuda]' pins one), or use backend='cpu'")
    assert len(broken_stack) == 1, "the probe must compile once per process"


def test_auto_falls_back_to_the_cpu_with_one_line(broken_stack):
    notes = []
    assert resolve_backend("auto", note=notes.append) == "cpu"
    assert notes == [f"backend='auto' runs on the CPU: the CUDA stack is unusable ({GPU}: a test kernel "
                     f"fails to compile or run (AttributeError: {ROW_STACK}))"]
    with pytest.warns(RuntimeWarning, match="the CUDA stack is unusable") as record:
        ds = stochpend.simulate(paths=10, t_max=0.5, n_times=1, backend="auto", bias_paths=0)
    assert len(record) == 1 and "\n" not in str(record[0].message)
    assert ds.attrs["backend"] == "cpu"


def test_info_says_unusable(broken_stack):
    result = CliRunner().invoke(cli.app, ["info"])
    assert result.exit_code == 0, result.output
    assert (f"backend cuda unusable: {GPU}: a test kernel fails to compile or run (AttributeError: "
            f"{ROW_STACK})") in _normalised(result.output)


def test_cli_auto_notes_the_fallback_in_one_line(broken_stack, tmp_path):
    result = CliRunner().invoke(cli.app, ["simulate", "--paths", "10", "--t-max", "0.5", "--n-times", "1",
                                          "--bias-paths", "0", "--backend", "auto", "--quiet"])
    assert result.exit_code == 0, result.output
    lines = [ln for ln in result.output.splitlines() if ln.strip()]
    assert lines == [f"note: backend='auto' runs on the CPU: the CUDA stack is unusable ({GPU}: a test kernel "
                     f"fails to compile or run (AttributeError: {ROW_STACK}))"]
    result = CliRunner().invoke(cli.app, ["simulate", "--paths", "10", "--t-max", "0.5", "--backend", "cuda"])
    assert result.exit_code == 2
    assert len([ln for ln in result.output.splitlines() if ln.strip()]) == 1
    assert ROW_STACK in result.output and "Traceback" not in result.output


def test_a_kernel_that_writes_wrong_numbers_is_unusable(monkeypatch):
    monkeypatch.setattr(cuda_probe, "_compile_and_launch", lambda: np.zeros(4))
    cuda_probe.probe.cache_clear()
    try:
        ok, why = cuda_probe.probe()
    finally:
        cuda_probe.probe.cache_clear()
    assert not ok and why == "a test kernel ran but wrote [0.0, 0.0, 0.0, 0.0] instead of [1.0, 3.0, 5.0, 7.0]"


def test_no_gpu_is_not_probed(monkeypatch):
    """Without a driver or a GPU nothing is compiled, and info keeps saying 'not usable'."""
    monkeypatch.setattr(gpu, "availability", lambda: (False, "the CUDA driver reports no GPU"))
    monkeypatch.setattr(cuda_probe, "probe", lambda: pytest.fail("probed without a GPU"))
    monkeypatch.setattr(cli, "_no_cuda_driver", lambda: None)  # info's quick look: a driver is there
    assert cuda_status() == (False, "the CUDA driver reports no GPU", False)
    assert resolve_backend("auto") == "cpu"  # no note: nothing is broken
    result = CliRunner().invoke(cli.app, ["info"])
    assert "backend cuda not usable: the CUDA driver reports no GPU" in _normalised(result.output)


@pytest.mark.gpu
def test_real_probe_in_the_simulator():
    """The real probe kernel compiles and runs (Numba's CUDA simulator, in its own process)."""
    code = ("import json; from stochpend.engine import cuda_probe; from stochpend.runs.simulate import cuda_status;"
            "print(json.dumps([cuda_probe.probe(), cuda_status(), cuda_status('auto'), cuda_probe._compile_and_launch().tolist()]))")
    src = Path(stochpend.__file__).resolve().parents[1]
    env = {**os.environ, "NUMBA_ENABLE_CUDASIM": "1",
           "PYTHONPATH": os.pathsep.join([str(src), *filter(None, [os.environ.get("PYTHONPATH")])])}
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env, timeout=120)
    assert r.returncode == 0, r.stderr
    probe, status, auto, values = json.loads(r.stdout)
    assert probe == [True, "a test kernel compiled and ran"]
    assert status[0] is True and "simulator" in status[1] and status[2] is False
    assert auto[0] is False and auto[2] is False  # auto never picks the simulator, and says nothing
    assert values == [1.0, 3.0, 5.0, 7.0]


def test_info_without_a_driver_imports_no_numba(monkeypatch):
    """Where no NVIDIA device node exists, info says so without Numba's CUDA check (which needs
    Numba imported, seconds): the check is not called."""
    monkeypatch.setattr(cli, "_no_cuda_driver", lambda: "no NVIDIA driver on this machine (no /dev/nvidiactl)")
    monkeypatch.setattr(gpu, "availability", lambda: pytest.fail("Numba's CUDA check was called"))
    result = CliRunner().invoke(cli.app, ["info"])
    assert result.exit_code == 0, result.output
    assert "backend cuda not usable: no NVIDIA driver on this machine (no /dev/nvidiactl)" in _normalised(result.output)
