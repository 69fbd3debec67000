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
    assert host_attrs["cpu_target"].endswith("(host)")
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
