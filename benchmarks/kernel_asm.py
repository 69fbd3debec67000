"""The x86 assembly of every CPU kernel a set of small runs compiles, one digest per kernel.

A restructuring that promises "the same kernels" (issue 33: the step written once) shows it
here: the same digests before and after mean the same machine code, so the same numbers and
the same speed, whatever a busy machine's benchmark would say. Names are normalised first:
the code digest stochpend puts in every closure's and cache index's name
(:mod:`stochpend.numerics._jitcache`) and Numba's per-process counters change with any edit.

Usage: ``python benchmarks/kernel_asm.py OUT.json`` (in a fresh ``NUMBA_CACHE_DIR`` or not:
the assembly is read from the compiled library either way), then compare two files with
``python benchmarks/kernel_asm.py --compare A.json B.json`` (exit 1 on any difference).
"""

from __future__ import annotations

import gc
import hashlib
import json
import os
import re
import sys
import tempfile

#: Small runs whose kernels cover the drivers: SIMD lanes (fast math) with pairs, the one-path
#: driver (C library), events (dichotomous), the x^(2n) oscillator with position coupling, the
#: family terms and an additive OU noise (on the additive channel), a fixed step.
RUNS = [
    dict(noise="ou", D=1.0, tau=1.0, omega=1.0),
    dict(noise="white", D=1.0, omega=1.0),
    dict(noise="dichotomous", D=1.0, tau=1.0, omega=1.0),
    dict(noise="harmonic", D=1.0, tau=1.0, omega_noise=1.5, omega=1.0),
    dict(potential="power", power_n=2, coupling="position", noise="ou", D=1.0, tau=1.0, omega=1.0),
    dict(potential="harmonic", noise="white", D=1.0, omega=1.0),
    dict(noise="ou", D=1.0, tau=1.0, omega=1.0, step_c=0.0, h_max=0.01),
    dict(noise="white", D=0.0, omega=1.0, gamma=0.5, additive_D=0.4, additive_tau=1.0),
]

_TAG = re.compile(r"_[0-9a-f]{16}")
_COUNTER = re.compile(r"\$\d+")
#: Numba's ABI tag of a mangled name carries a per-process function counter ("B2v17").
_ABI_COUNTER = re.compile(r"B\d+v\d+")


def _normalised(asm: str) -> str:
    asm = _TAG.sub("_TAG", asm)
    asm = _ABI_COUNTER.sub("Bv", asm)
    return _COUNTER.sub("$N", asm)


def digests() -> dict[str, str]:
    """``{kernel qualname | signature: sha256 of its normalised assembly}`` of every compiled
    CPU dispatcher after the runs (functions of one name and signature, e.g. two Specs'
    closures, are hashed together, their texts sorted)."""
    # Numba keeps no assembly for a kernel loaded from its cache (a kernel another dispatcher of
    # this very process saved counts): every kernel compiles afresh and nothing is saved.
    os.environ["NUMBA_CACHE_DIR"] = tempfile.mkdtemp(prefix="kernel-asm-")
    from numba.core import caching
    from numba.core.registry import CPUDispatcher

    caching.Cache.load_overload = lambda self, *args, **kwargs: None  # type: ignore[method-assign]
    caching.Cache.save_overload = lambda self, *args, **kwargs: None  # type: ignore[method-assign]
    import stochpend

    for kwargs in RUNS:
        stochpend.simulate(**kwargs, paths=64, t_max=2.0, n_times=2, seed=1, bias_paths=32)
    texts: dict[str, list[str]] = {}
    for obj in gc.get_objects():
        if isinstance(obj, CPUDispatcher) and obj.py_func.__module__.startswith("stochpend"):
            for sig, asm in obj.inspect_asm().items():
                if not asm:
                    raise RuntimeError(f"no assembly for {obj.py_func.__qualname__} (loaded from a cache?)")
                name = _TAG.sub("", f"{obj.py_func.__module__}.{obj.py_func.__qualname__}|{sig}")
                texts.setdefault(name, []).append(_normalised(asm))
    # One digest per compiled function, sorted: a kernel of one KernelSpec that changed shows as one
    # differing entry, not as a change of every kernel sharing its name and signature.
    return {name: ",".join(sorted(hashlib.sha256(x.encode()).hexdigest()[:16] for x in t))
            for name, t in sorted(texts.items())}


def main(argv: list[str]) -> int:
    if argv[:1] == ["--compare"] and len(argv) == 3:
        a, b = (json.load(open(p)) for p in argv[1:])
        differ = sorted(k for k in a.keys() | b.keys() if a.get(k) != b.get(k))
        print(f"{len(a)} and {len(b)} kernel names; {len(differ)} differ")
        for k in differ:
            x, y = set(a.get(k, "").split(",")) - {""}, set(b.get(k, "").split(",")) - {""}
            print(f"  {len(x - y)} of {len(x)} functions vs {len(y - x)} of {len(y)} differ: {k}")
        return 1 if differ else 0
    if len(argv) != 1:
        print("usage: kernel_asm.py OUT.json | --compare A.json B.json", file=sys.stderr)
        return 2
    result = digests()
    with open(argv[0], "w") as f:
        json.dump(result, f, indent=1)
    print(f"{len(result)} kernels -> {argv[0]}", file=sys.stderr)
    return 0


if __name__ == "__main__":
    raise SystemExit(main(sys.argv[1:]))
