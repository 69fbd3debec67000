"""benchmarks/gpu_bench.py without a GPU: its dry run, its offline mode and its refusal.

CI has no GPU, no nvcc and (without the cuda extra) no NVRTC or numba-cuda: ``--compile-only``
must then skip those parts with a printed reason and still run the host check of the CUDA C
reference (Philox known answers, normals and 30 steps against stochpend, built with g++) when
a C++ compiler is there. Where the CUDA tools are installed it compiles the reference and
stochpend's kernels for sm_90 instead.
"""

from __future__ import annotations

import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
SCRIPT = ROOT / "benchmarks" / "gpu_bench.py"


def _run(*args: str, simulator: bool = False) -> subprocess.CompletedProcess:
    env = {**os.environ, "PYTHONPATH": str(ROOT / "src")}
    env.pop("NUMBA_ENABLE_CUDASIM", None)
    if simulator:
        env["NUMBA_ENABLE_CUDASIM"] = "1"
    return subprocess.run([sys.executable, str(SCRIPT), *args], env=env, capture_output=True,
                          text=True, timeout=600)


def test_dry_run_lists_every_case():
    res = _run("--dry-run", "--paths", "1e6", "1e7")
    assert res.returncode == 0, res.stderr
    rows = [line for line in res.stdout.splitlines() if re.match(r"\| float(32|64) \| (fixed|adaptive) \|", line)]
    assert len(rows) == 2 * 2 * 2, res.stdout
    assert "| float64 | fixed | 1e+06 | 3 | 3e+08 |" in res.stdout  # 1e6 paths x 300 steps


def test_compile_only_compiles_or_skips_with_a_reason_and_checks_the_reference_on_the_host():
    res = _run("--compile-only", "--precisions", "float64", "--modes", "fixed")
    out = res.stdout
    assert res.returncode == 0, out + res.stderr
    assert re.search(r"^reference: (compiled for sm_90 with \S+|skipped: .+)$", out, re.M), out
    if "stochpend registers: skipped:" not in out:
        assert re.search(r"^\| float64 \| fixed \| \d+ \(\d+\.\d%\) \|", out, re.M), out
    if shutil.which("g++") or shutil.which("c++"):
        assert "Philox known answers wrong: 0/3" in out and out.rstrip().endswith("pass"), out
    else:
        assert "host check: skipped:" in out, out


def test_without_a_gpu_it_says_so_in_one_line():
    res = _run("--paths", "1e3", "--check-paths", "0")
    if res.returncode == 0:  # a machine with a GPU: nothing to check here
        return
    assert res.returncode == 2
    assert res.stderr.startswith("gpu_bench: no usable GPU:") and res.stderr.count("\n") == 1
    res = _run("--paths", "1e3", "--check-paths", "0", simulator=True)  # the simulator is refused too
    assert res.returncode == 2 and "no usable GPU" in res.stderr
