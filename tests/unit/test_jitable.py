"""stochpend.numerics._jitable: the kernels' functions are registered with Numba whichever of Numba and
the package is imported first, and importing the package's pieces imports no Numba (issue 36)."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

import stochpend

SRC = str(Path(stochpend.__file__).resolve().parents[1])

# A jitted function that calls register_jitable functions of rng, mathlib, fastmath (its overloads
# and intrinsics too) and a noise module, then prints what it computed and what Python computes.
CALLS = """
log = mathlib.LIBM.log
@numba.njit
def f(x):
    return fastmath.sin(x) + fastmath.floor(x) + log(x) + no_event(0.0, 0.0)
print(f(1.25) == fastmath.sin(1.25) + 1.0 + math.log(1.25) + math.inf)
"""


def _run(code: str) -> subprocess.CompletedProcess:
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(filter(None, [SRC, os.environ.get("PYTHONPATH")]))}
    env.pop("NUMBA_DISABLE_JIT", None)
    return subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, timeout=300)


@pytest.mark.parametrize("numba_first", [False, True])
def test_registered_whichever_is_imported_first(numba_first):
    imports = ("import math, sys\n" + ("import numba\n" if numba_first else "")
               + "from stochpend import noises, oscillators\nfrom stochpend.numerics import fastmath, mathlib, rng\n"
               "from stochpend.noises.base import no_event\n"
               "print('numba' in sys.modules)\n" + ("" if numba_first else "import numba\n"))
    done = _run(imports + CALLS)
    assert done.returncode == 0, done.stderr[-3000:]
    assert done.stdout.split() == [str(numba_first), "True"]


def test_the_import_hook_is_gone_after_numba_is_imported():
    done = _run("import sys; from stochpend import noises; from stochpend.numerics._jitable import _NumbaWatcher as W\n"
                "print(any(isinstance(f, W) for f in sys.meta_path))\n"
                "import numba\nprint(any(isinstance(f, W) for f in sys.meta_path))")
    assert done.returncode == 0, done.stderr[-3000:]
    assert done.stdout.split() == ["True", "False"]
