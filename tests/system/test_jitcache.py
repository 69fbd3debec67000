"""A kernel loaded from Numba's on-disk cache computes what it computed when it was compiled.

Numba names each compiled function ``<qualname>$<n>``, ``n`` a counter unique in one process
only; a cached kernel refers to the integrator's pieces (``_step_loop.<locals>.advance_path``) by
those names. Without care, process B that compiles another KernelSpec's pieces first gives them the
names the writer process A gave the cached kernel's pieces, and the cached kernel, once
loaded, calls B's functions: other noise, wrong numbers, no error. (Seen in the test suite:
the fixed-step OU kernel computed with the dichotomous noise's step after the bias estimate
of a dichotomous run.) ``stochpend.numerics._jitcache`` names every closure after what decides its code
and the code digest, so one name is one code in every process.

Numba also keys a cached kernel on its own file only: an edit of a function it calls from
another module (``mathlib``, ``rng``, the integrator) would reuse the old machine code. The
digest of the sources that decide the numbers is in every cached kernel's name, whatever the
cache directory.
"""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
import types
from pathlib import Path

import numpy as np

import stochpend

HELPER = Path(__file__).with_name("_jitcache_check.py")
ROOT = Path(__file__).resolve().parents[2]


def _run(cache: Path, out: Path, *noises: str, src: Path | None = None) -> np.ndarray:
    src = src or Path(stochpend.__file__).resolve().parents[1]
    env = {**os.environ, "NUMBA_CACHE_DIR": str(cache),
           "PYTHONPATH": os.pathsep.join([str(src), str(ROOT), *filter(None, [os.environ.get("PYTHONPATH")])])}
    env.pop("NUMBA_ENABLE_CUDASIM", None)
    r = subprocess.run([sys.executable, str(HELPER), str(out), *noises], capture_output=True, text=True,
                       env=env, timeout=600)
    assert r.returncode == 0, r.stderr
    return np.load(out)


def test_a_cached_kernel_never_calls_another_processes_pieces(tmp_path):
    cache = tmp_path / "numba-cache"
    cache.mkdir()
    # A: compiles and caches the OU kernels alone.
    ou_alone = _run(cache, tmp_path / "a.npy", "ou")
    # B: compiles the dichotomous kernels first (the same compile sequence as A, so without the
    # fix its pieces get A's numbers), then loads the OU kernels from A's cache.
    ou_after = _run(cache, tmp_path / "b.npy", "dichotomous", "ou")
    assert any(cache.rglob("*.nbc")), "nothing was cached: the test does not test the cache"
    np.testing.assert_array_equal(ou_after, ou_alone)


def test_an_edited_module_level_function_runs_with_numba_cache_dir_set(tmp_path):
    """The issue's case: with NUMBA_CACHE_DIR set, a run, then a function of another module
    that the kernels call (``mathlib._sin``, the pendulum's force) edited, then the same run:
    the new code runs (the numbers a fresh cache gives), not the cached machine code."""
    src = tmp_path / "src"
    shutil.copytree(Path(stochpend.__file__).resolve().parent, src / "stochpend",
                    ignore=shutil.ignore_patterns("__pycache__"))
    cache = tmp_path / "numba-cache"
    cache.mkdir()
    before = _run(cache, tmp_path / "before.npy", "ou", src=src)
    mathlib = src / "stochpend" / "numerics" / "mathlib.py"
    text = mathlib.read_text()
    old = "def _sin(x):\n    return math.sin(x)\n"
    assert text.count(old) == 1
    mathlib.write_text(text.replace(old, "def _sin(x):\n    return 1.01 * math.sin(x)\n"))
    after = _run(cache, tmp_path / "after.npy", "ou", src=src)
    fresh_cache = tmp_path / "fresh-cache"
    fresh_cache.mkdir()
    fresh = _run(fresh_cache, tmp_path / "fresh.npy", "ou", src=src)
    assert not np.array_equal(fresh, before), "the edited sin changes no number: the test tests nothing"
    np.testing.assert_array_equal(after, fresh, err_msg="the old code's cached kernel ran after the edit")


def _unnamed_closures(functions) -> list[str]:
    """Qualnames of closures reachable from ``functions`` (Numba dispatchers' Python functions,
    closure cells, tuples) that were not named by ``_jitcache``."""
    seen, stack, unnamed = set(), list(functions), []
    while stack:
        obj = stack.pop()
        if id(obj) in seen:
            continue
        seen.add(id(obj))
        if isinstance(obj, (tuple, list)):
            stack.extend(obj)
        elif hasattr(obj, "py_func"):
            stack.append(obj.py_func)
        elif isinstance(obj, types.FunctionType):
            if "<locals>" in obj.__qualname__ and not getattr(obj, "_stochpend_named", False):
                unnamed.append(obj.__qualname__)
            for cell in obj.__closure__ or ():
                try:
                    stack.append(cell.cell_contents)
                except ValueError:
                    pass
    return unnamed


def test_every_closure_of_every_builtin_spec_is_named_where_it_is_made():
    """Each closure is named once, by the builder that makes it, after what decides its code;
    a name given by a kernel's ``own_index`` (whichever kernel is built first) would depend
    on the order of a process's builds, so none may be left to it. Two Specs that differ in
    anything that decides a closure's code never share its name."""
    from stochpend import noises, oscillators
    from stochpend.engine import cpu, integrator
    from stochpend.numerics import _jitcache

    seen_names: dict[str, str] = {}
    for noise in noises.names():
        for potential in oscillators.names():
            for precision in ("float32", "float64"):
                for fast_math in (False, True):
                    spec = integrator.spec(noise, potential, precision=precision, fast_math=fast_math)
                    built = integrator.build(spec)
                    fns = [*built.advance_levels.values(), *built.device_levels.values(), built.advance_lanes,
                           built.init_path, built.path_values]
                    if integrator.lanes_supported(spec):
                        fns += [integrator.build_lanes(spec).advance_range,
                                integrator.build_pair_lanes(spec).advance_range]
                    assert _unnamed_closures(fns) == [], spec.label
                    assert "_" + _jitcache.tag(spec.label) in built.verlet.__qualname__
                    seen_names.setdefault(built.verlet.__qualname__, spec.label)
                    assert seen_names[built.verlet.__qualname__] == spec.label
                    if precision == "float64":
                        kernels = cpu.compiled_kernels(spec).values()
                        assert _unnamed_closures(kernels) == [], spec.label
