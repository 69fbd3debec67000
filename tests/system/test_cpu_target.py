"""The instruction set of the CPU kernels (stochpend.numerics._cputarget, issue 37): the result names it,
the x86-64-v3 baseline gives this machine's bits, and a target that cannot hold is one line."""

from __future__ import annotations

import os
import subprocess
import sys

import numpy as np
import pytest
from typer.testing import CliRunner

import stochpend
from stochpend import cli, io
from stochpend.numerics import _cputarget

RUN = ["simulate", "--noise", "ou", "--D", "1", "--tau", "1", "--omega", "1", "--paths", "300", "--t-max", "20",
       "--n-times", "4", "--seed", "5", "--bias-paths", "0", "--quiet"]


def _simulate_in_process(tmp_path, name: str, *target: str) -> tuple[dict[str, np.ndarray], dict]:
    """The CLI in a process of its own (a process compiles for one target only)."""
    out = tmp_path / f"{name}.nc"
    env = {k: v for k, v in os.environ.items() if k not in ("STOCHPEND_CPU_TARGET", "NUMBA_CPU_NAME",
                                                          "NUMBA_CPU_FEATURES")}
    proc = subprocess.run([sys.executable, "-m", "stochpend", *target, *RUN, "--out", str(out)],
                          capture_output=True, text=True, env=env, timeout=600)
    assert proc.returncode == 0, proc.stderr
    ds = io.open_results(out)
    return {"time": ds["time"].values, **{v: ds[v].values for v in ds.data_vars}}, dict(ds.attrs)


@pytest.mark.skipif(_cputarget._host_supports_baseline() is not None, reason="this machine cannot run x86-64-v3 code")
def test_baseline_target_gives_the_same_bits_as_the_host(tmp_path):
    host, host_attrs = _simulate_in_process(tmp_path, "host")
    base, base_attrs = _simulate_in_process(tmp_path, "base", "--cpu-target", "baseline")
    assert base_attrs["cpu_target"] == "x86-64-v3 (baseline)"
    assert host_attrs["cpu_target"].endswith(("(host)", "(host, 512-bit vectors)"))
    assert host.keys() == base.keys() and len(host) > 20
    for name, values in host.items():
        assert np.array_equal(values, base[name], equal_nan=True), name


def test_unknown_cpu_target_is_one_line():
    result = CliRunner().invoke(cli.app, ["--cpu-target", "fastest", *RUN])
    assert result.exit_code == 2
    lines = result.output.strip().splitlines()
    assert lines == ["error: --cpu-target 'fastest' is not accepted: one of host, baseline"], lines


def test_unknown_environment_target_is_refused_before_the_run(monkeypatch):
    monkeypatch.setenv("STOCHPEND_CPU_TARGET", "avx9000")
    with pytest.raises(ValueError, match=r"^STOCHPEND_CPU_TARGET='avx9000' is not accepted: STOCHPEND_CPU_TARGET "
                                         r"must be one of host, baseline"):
        stochpend.simulate(noise="white", D=1.0, omega=1.0, paths=10, t_max=1.0, n_times=1, bias_paths=0)


def test_target_cannot_change_once_kernels_are_compiled(monkeypatch):
    stochpend.simulate(noise="white", D=1.0, omega=1.0, paths=10, t_max=1.0, n_times=1, bias_paths=0)
    monkeypatch.setenv("STOCHPEND_CPU_TARGET", os.environ.get("STOCHPEND_CPU_TARGET", "host"))  # restored after
    other = "host" if _cputarget.describe().endswith("(baseline)") else "baseline"
    if other == "baseline" and _cputarget._host_supports_baseline() is not None:
        pytest.skip("this machine cannot run x86-64-v3 code")
    with pytest.raises(ValueError, match=rf"^cpu_target='{other}' is not accepted: this process has compiled its "
                                         "kernels for .* already; set STOCHPEND_CPU_TARGET"):
        _cputarget.select(other)


def test_the_wide_features_are_the_hosts_own_with_the_256_bit_preference_off():
    assert _cputarget.wide_features({"avx512f": True, "avx2": True}, "+avx2,+avx512f,-amx-tile") == \
        "+avx2,+avx512f,-amx-tile,-prefer-256-bit"
    assert _cputarget.wide_features({"avx512f": False, "avx2": True}, "+avx2,-avx512f") is None
    assert _cputarget.wide_features({"avx2": True}, "+avx2") is None


# The engine first: it makes kernels when imported, before any run's own check of the target.
_PROBE = """
import stochpend.engine.cpu
import numba, numpy as np
import stochpend
ds = stochpend.simulate(noise="white", D=1.0, omega=1.0, paths=64, t_max=0.5, n_times=1, bias_paths=0)
@numba.njit
def axpy(a, x, y):
    for i in range(x.shape[0]):
        y[i] = a * x[i] + y[i]
x = np.ones(1024)
axpy(2.0, x, x.copy())
asm = next(iter(axpy.inspect_asm().values()))
print(ds.attrs["cpu_target"])
print("zmm" if "%zmm" in asm else "ymm" if "%ymm" in asm else "neither")
"""


@pytest.mark.parametrize("user_features", [False, True], ids=["default", "NUMBA_CPU_FEATURES"])
def test_an_avx512_host_steps_512_bits_wide_unless_the_user_says_otherwise(user_features):
    """On a host with AVX-512 a process's kernels use its 512-bit registers, and the result says
    so; NUMBA_CPU_FEATURES set by the user (here to the host's own) is left as it is. A host
    without AVX-512 keeps LLVM's choice and says plain "(host)". In a process of its own, since
    a process's code generator is fixed by its first kernel."""
    import platform

    import llvmlite.binding as ll

    env = {k: v for k, v in os.environ.items() if k not in ("STOCHPEND_CPU_TARGET", "NUMBA_CPU_NAME",
                                                          "NUMBA_CPU_FEATURES")}
    if user_features:
        env["NUMBA_CPU_FEATURES"] = ll.get_host_cpu_features().flatten()
    proc = subprocess.run([sys.executable, "-c", _PROBE], capture_output=True, text=True, env=env, timeout=600)
    assert proc.returncode == 0, proc.stderr
    target, registers = proc.stdout.strip().splitlines()[-2:]
    name = ll.get_host_cpu_name()
    x86 = platform.machine().lower() in ("x86_64", "amd64")
    if x86 and ll.get_host_cpu_features().get("avx512f", False) and not user_features:
        assert target == f"{name} (host, 512-bit vectors)"
        assert registers == "zmm"
    else:
        assert target == f"{name} (host)"
        if x86 and not ll.get_host_cpu_features().get("avx512f", False):
            assert registers != "zmm"
