"""benchmarks/gpu_check.py (``make gpu-check``) without a GPU: its refusal, its argument errors,
its report from fake measurements, and its oracle step on a toy case in the CUDA simulator."""

from __future__ import annotations

import importlib.util
import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
SCRIPT = ROOT / "benchmarks" / "gpu_check.py"


def _module():
    if "gpu_check" in sys.modules:
        return sys.modules["gpu_check"]
    spec = importlib.util.spec_from_file_location("gpu_check", SCRIPT)
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    sys.modules["gpu_check"] = module  # its dataclasses look their module up there
    spec.loader.exec_module(module)
    return module


def _run(*args: str, simulator: bool = False) -> subprocess.CompletedProcess:
    env = {**os.environ, "PYTHONPATH": os.pathsep.join((str(ROOT / "src"), str(ROOT / "tests" / "_simulator_site")))}
    env.pop("NUMBA_ENABLE_CUDASIM", None)
    if simulator:
        env["NUMBA_ENABLE_CUDASIM"] = "1"
    return subprocess.run([sys.executable, str(SCRIPT), *args], env=env, capture_output=True, text=True,
                          timeout=600, cwd=ROOT)


def test_without_a_gpu_it_refuses_in_one_line(tmp_path):
    out = tmp_path / "report.md"
    res = _run("--out", str(out))
    if res.returncode != 2 and "no usable GPU" not in res.stderr:  # a machine with a GPU
        pytest.skip("a GPU is here: the refusal cannot be seen")
    assert res.returncode == 2
    assert res.stderr.startswith("gpu_check: no usable GPU:") and res.stderr.count("\n") == 1, res.stderr
    assert "Traceback" not in res.stderr and not out.exists()
    res = _run("--out", str(out), simulator=True)  # the simulator measures nothing: refused too
    assert res.returncode == 2 and "no usable GPU" in res.stderr and res.stderr.count("\n") == 1


@pytest.mark.parametrize("args, parameter", [(("--only", "bogus"), "--only"), (("--out",), "--out"),
                                             (("--quick=3",), "--quick")])
def test_bad_arguments_get_one_line_naming_the_parameter(args, parameter):
    res = _run(*args)
    assert res.returncode == 2
    assert res.stderr.count("\n") == 1 and parameter in res.stderr and "Traceback" not in res.stderr, res.stderr


def test_the_report_holds_the_device_the_versions_and_every_figure(monkeypatch, tmp_path):
    gc = _module()
    from stochpend.engine import cuda as gpu

    def fake_oracle(args):
        return True, ["| precision | z |", "|---|---:|", "| float64 | +0.123 |"]

    def fake_bench(args):
        return False, ["| float32 | fixed | 1e+06 | 0.456 | 2.190e+09 |"]

    def broken(args):
        raise RuntimeError("out of device memory\nsecond line")

    monkeypatch.setattr(gpu, "availability", lambda: (True, "Fake GPU 9000 (compute capability 9.0)"))
    monkeypatch.setattr(gpu, "_simulator_enabled", lambda: False)
    monkeypatch.setattr(gc, "STEP_FUNCTIONS", {"device-tests": lambda args: (None, ["1 skipped"]),
                                               "bench": fake_bench, "oracle": fake_oracle,
                                               "family": broken, "reproduce": fake_oracle})
    out = tmp_path / "sub" / "report.md"
    assert gc.main(["--out", str(out), "--only", "device-tests", "bench", "oracle", "family"]) == 1
    text = out.read_text()
    assert "Device: Fake GPU 9000 (compute capability 9.0)" in text
    assert re.search(r"^Versions: Python [\d.]+, numpy [\d.]+, numba [\d.]+", text, re.M)
    for name, status in (("device-tests", "skipped"), ("bench", "failed"), ("oracle", "passed"), ("family", "failed")):
        assert re.search(rf"^\| {name} \| {status} \| \d+\.\d \|$", text, re.M), (name, text)
        assert f"## {name}: {status}" in text
    assert "reproduce" not in text  # not asked for
    assert "| float64 | +0.123 |" in text and "| float32 | fixed | 1e+06 | 0.456 | 2.190e+09 |" in text
    assert "raised RuntimeError: out of device memory second line" in text
    # all passed (or skipped): exit 0
    assert gc.main(["--out", str(out), "--only", "device-tests", "oracle"]) == 0


def test_the_oracle_step_runs_in_the_simulator_on_a_toy_case(tmp_path):
    out = tmp_path / "report.md"
    res = _run("--allow-simulator", "--only", "oracle", "--out", str(out), simulator=True)
    assert res.returncode in (0, 1), res.stderr
    text = out.read_text()
    assert "Device: Numba CUDA simulator" in text
    rows = re.findall(r"^\| (float64|float32) \| (1|4) \| (mean_sin2theta|mean_Omega2) \| (\S+) \| (\S+) \| (\S+) \| (\S+) \|$",
                      text, re.M)
    assert len(rows) == 8, text
    gc = _module()
    for _precision, t, name, value, want, se, z in rows:
        # the reference column is the scheme's moment map, computed here again
        from types import SimpleNamespace

        from stochpend.model import dynamics

        d = dynamics.record(SimpleNamespace(dyn_params=dynamics.resolve({"gamma": 0.7, "additive_D": 0.3})))
        moments = gc.scheme_moments(0.1, round(float(t) / 0.1), 0.5, d)
        expected = moments[0] if name == "mean_sin2theta" else moments[2]
        assert float(want) == pytest.approx(expected, rel=1e-5)
        assert float(z) == pytest.approx((float(value) - float(want)) / float(se), abs=0.02)
    status = "passed" if all(abs(float(r[-1])) < gc.Z for r in rows) else "failed"
    assert f"| oracle | {status} |" in text and res.returncode == (0 if status == "passed" else 1)
