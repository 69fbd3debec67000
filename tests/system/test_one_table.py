"""Statistics declared once (issue 22): a new moment is one line of ``stochpend/model/observables.py``.

The test copies the package, appends one line to its table -- the mean of Omega**6 -- and runs
the copy in fresh processes with a fresh kernel cache: on the CPU (the SIMD-lane run, the
Dataset, the bias estimate's coupled pairs) and in Numba's CUDA simulator. In each, the new
column of the per-batch sums must equal the sum of Omega**6 over the finite paths of the state
the run ended in (recomputed here with numpy), and ⟨Ω⁶⟩ must come out as a variable with its
standard error and bias estimate. Nothing else of the package is edited: the diff is checked
to be that one line.
"""

from __future__ import annotations

import difflib
import json
import math
import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

import stochpend

HELPER = Path(__file__).with_name("_one_entry_check.py")
LINE = 'mean("Omega6", "Omega2 * Omega4", "⟨Ω⁶⟩", "<Omega^6>")\n'
ANCHOR = "#: The summed values, in column order"


@pytest.fixture(scope="module")
def package_with_omega6(tmp_path_factory) -> Path:
    root = tmp_path_factory.mktemp("one_entry")
    source = Path(stochpend.__file__).resolve().parent
    shutil.copytree(source, root / "stochpend", ignore=shutil.ignore_patterns("__pycache__"))
    table = root / "stochpend" / "model" / "observables.py"
    before = table.read_text().splitlines(keepends=True)
    at = next(i for i, line in enumerate(before) if line.startswith(ANCHOR))
    after = before[:at] + [LINE, "\n"] + before[at:]
    table.write_text("".join(after))
    added = [d for d in difflib.unified_diff(before, after, n=0) if d.startswith("+") and not d.startswith("+++")]
    assert [a for a in added if a.strip() != "+"] == ["+" + LINE]
    return root


def _run(root: Path, backend: str) -> dict:
    env = {k: v for k, v in os.environ.items() if not k.startswith("NUMBA_")}
    env["PYTHONPATH"] = str(root) + os.pathsep + str(Path(__file__).resolve().parents[2])
    env["NUMBA_CACHE_DIR"] = str(root / "numba-cache")
    if backend == "cuda":
        env["NUMBA_ENABLE_CUDASIM"] = "1"
    done = subprocess.run([sys.executable, str(HELPER), backend], env=env, capture_output=True, text=True,
                          timeout=600)
    assert done.returncode == 0, done.stderr[-3000:]
    result = json.loads(done.stdout.strip().splitlines()[-1])
    assert Path(result["package"]).resolve().is_relative_to(root), result["package"]
    return result


def _same_sum(got: float, expected: float) -> None:
    # The kernels add path by path in path order, numpy pairwise: equal to rounding.
    assert math.isclose(got, expected, rel_tol=1e-12), (got, expected)


@pytest.mark.parametrize("backend", ["cpu", "cuda"])
def test_one_line_of_the_table_adds_a_statistic_on_every_backend(package_with_omega6, backend):
    r = _run(package_with_omega6, backend)
    assert r["count"] == r["finite_paths"] > 0
    _same_sum(r["sum_Omega6"], r["state_sum_Omega6"])
    _same_sum(r["sum_Omega4"], r["state_sum_Omega4"])  # the columns before it did not move
    assert r["sum_Omega6"] != r["sum_Omega4"]
    if backend == "cpu":
        assert r["variables"] == ["mean_Omega6", "mean_Omega6_bias", "mean_Omega6_bias_stderr",
                                  "mean_Omega6_bias_verdict", "mean_Omega6_stderr"]
        assert r["long_name"] == "⟨Ω⁶⟩"
        for value, se, bias_se, m4 in zip(r["mean_Omega6"], r["mean_Omega6_stderr"],
                                          r["mean_Omega6_bias_stderr"], r["mean_Omega4"], strict=True):
            assert value > 0 and 0 < se < value and bias_se > 0
            assert value >= m4**1.5 * (1 - 1e-12)  # Jensen: <Omega^6> >= <Omega^4>^(3/2)
