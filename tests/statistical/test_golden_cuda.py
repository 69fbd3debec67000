"""Bit-for-bit guard of the CUDA backend, in Numba's CUDA simulator: the statistics of eight tiny
runs (every built-in noise, the quartic with position coupling, the harmonic oscillator, a
fixed step in float64 and float32), stored in tests/golden/cudasim.npz by
tests/golden/make_golden_cuda.py, must come out identical (on the machines of
tests/statistical/test_golden.py: x86-64 with AVX2, FMA and glibc; ``make test-baseline`` runs it
with numpy held to AVX2 too).

The simulator needs NUMBA_ENABLE_CUDASIM=1 before Numba is imported, while this process runs the
real CPU Numba, so the generator script runs here in a subprocess (as test_cuda_sim.py does).
Regenerate only for a change that is meant to alter numbers, and say so in its commit."""

from __future__ import annotations

import os
import sys
from pathlib import Path

import numpy as np
import pytest

from tests import _background
from tests._machine import golden_machine

pytestmark = [pytest.mark.gpu,
              pytest.mark.skipif(golden_machine() is not None, reason=f"the golden bits are x86-64's with AVX2, "
                                 f"FMA and glibc; {golden_machine()}: the statistical tests check its numbers")]

GOLDEN_DIR = Path(__file__).resolve().parents[1] / "golden"
GOLDEN = GOLDEN_DIR / "cudasim.npz"
SCRIPT = GOLDEN_DIR / "make_golden_cuda.py"


def _load(path: Path) -> dict[str, np.ndarray]:
    with np.load(path) as data:
        return {key: data[key] for key in data.files}


GOLDEN_ARRAYS = _load(GOLDEN)
NAMES = sorted({key.split("/", 1)[0] for key in GOLDEN_ARRAYS})


def background_run(folder: Path) -> _background.Command:
    """The generator script in the CUDA simulator (about 20 s), started with the session
    (tests/_background.py)."""
    return _background.Command([sys.executable, str(SCRIPT), str(folder / "now.npz")],
                               env={**os.environ, "NUMBA_ENABLE_CUDASIM": "1"})


@pytest.fixture(scope="module")
def simulated() -> dict[str, np.ndarray]:
    """The generator script run at this commit in the CUDA simulator."""
    run = _background.start(__name__, background_run)
    proc = run.wait(timeout=600)
    if proc.returncode != 0:
        pytest.fail(f"CUDA simulator run failed:\n{proc.stdout}\n{proc.stderr[-5000:]}")
    return _load(run.folder / "now.npz")


def test_fixture_covers_what_it_claims():
    """Guards the fixture: eight cases, one of them float32, each with its statistics."""
    assert len(NAMES) == 8, NAMES
    assert '"float32"' in str(GOLDEN_ARRAYS["fixed_step_f32/case"])
    # float32 really ran: its numbers differ from the same run's in float64.
    assert not np.array_equal(GOLDEN_ARRAYS["fixed_step_f32/mean_E"], GOLDEN_ARRAYS["fixed_step/mean_E"])


@pytest.mark.parametrize("name", NAMES)
def test_cuda_simulator_statistics_are_bit_identical_to_golden(simulated, name):
    expected = {key: value for key, value in GOLDEN_ARRAYS.items() if key.startswith(name + "/")}
    assert len(expected) > 20, name
    # The case's parameters first: an edited case must fail, not be compared with other numbers.
    assert str(simulated[f"{name}/case"]) == str(expected[f"{name}/case"]), name
    for key, values in expected.items():
        assert key in simulated, key
        assert np.array_equal(simulated[key], values, equal_nan=values.dtype.kind == "f"), key
