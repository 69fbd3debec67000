"""The instruction set the CPU kernels are compiled for: this machine's own, or a fixed baseline.

Numba compiles every kernel for the host's CPU (its name and features: vector width, FMA, ...).
The kernels are written so that their numbers do not depend on it: no fast-math flags (so no
reassociation and no fused multiply-add contraction; LLVM must keep IEEE semantics), the
transcendental functions are the C library's or :mod:`stochpend.numerics.fastmath`'s branch-free ones,
and every sum runs in a fixed order (docs/development.md, "What is bit-identical, and where").
A machine with AVX-512 and one with AVX2 only then give the same bits, which the golden tests
check with the kernels compiled both ways (``make test-baseline``).

For a guarantee that does not rest on that reasoning (a heterogeneous cluster, two laptops), the
kernels can be compiled for one fixed target on every machine: :data:`BASELINE_NAME`
(x86-64-v3: AVX2, FMA, BMI2, the level of every x86-64 server and laptop since 2013-2015),
chosen by ``STOCHPEND_CPU_TARGET=baseline`` in the environment (set before Python starts: Dask
workers and child processes inherit it), ``stochpend --cpu-target baseline`` or
:func:`select` before the first kernel of the process compiles. Numba's cache keeps the two
targets' kernels apart (its index is keyed by the CPU name and features).

Every result names the target its kernels were compiled for (the ``cpu_target`` attribute,
:func:`describe`).
"""

from __future__ import annotations

import os
import platform
import sys

#: The environment variable that chooses the target: ``host`` (default) or ``baseline``.
ENV = "STOCHPEND_CPU_TARGET"
TARGETS = ("host", "baseline")

#: LLVM's name for the x86-64-v3 micro-architecture level, and its features written out (Numba
#: needs both: with a name alone it would add the host's features).
BASELINE_NAME = "x86-64-v3"
BASELINE_FEATURES = ",".join(
    "+" + f for f in ("64bit", "avx", "avx2", "bmi", "bmi2", "cmov", "crc32", "cx16", "cx8", "f16c", "fma", "fxsr",
                      "lzcnt", "mmx", "movbe", "popcnt", "sahf", "sse", "sse2", "sse3", "sse4.1", "sse4.2", "ssse3",
                      "xsave"))
#: What the host must have to run baseline code (else: SIGILL, so it is refused first).
_BASELINE_NEEDS = ("avx", "avx2", "fma", "bmi", "bmi2", "f16c", "lzcnt", "movbe")


def _accepted() -> str:
    return f"{ENV} must be one of {', '.join(TARGETS)} (baseline: {BASELINE_NAME}, x86-64 with AVX2 and FMA)"


def requested() -> str:
    """The target the environment asks for (``host`` when unset); ValueError for another word."""
    value = os.environ.get(ENV, "").strip().lower() or "host"
    if value not in TARGETS:
        raise ValueError(f"{ENV}={os.environ.get(ENV)!r} is not accepted: {_accepted()}")
    return value


def _compiled() -> bool:
    """Whether Numba has made its CPU code generator in this process (its target is then fixed)."""
    numba = sys.modules.get("numba")
    if numba is None:
        return False
    from numba.core import registry

    return "_toplevel_target_context" in vars(registry.cpu_target)


def _host_supports_baseline() -> str | None:
    """None if this machine runs x86-64-v3 code, else why not."""
    if platform.machine().lower() not in ("x86_64", "amd64"):
        return f"this machine is {platform.machine()}, the baseline is for x86-64"
    import llvmlite.binding as ll

    features = ll.get_host_cpu_features()
    missing = [f for f in _BASELINE_NEEDS if not features.get(f, False)]
    if missing:
        return f"this CPU lacks {', '.join(missing)}"
    return None


def select(target: str) -> None:
    """Compile this process's CPU kernels (and its children's) for ``target``.

    ``"baseline"``: :data:`BASELINE_NAME` on every machine; ``"host"``: this machine's own CPU
    (Numba's default). Must come before the process compiles or loads its first Numba kernel;
    afterwards only the target already in use is accepted. ValueError (one line) otherwise.
    """
    if target not in TARGETS:
        raise ValueError(f"cpu_target={target!r} is not accepted: one of {', '.join(TARGETS)}")
    if target == "baseline":
        why = _host_supports_baseline()
        if why is not None:
            raise ValueError(f"cpu_target='baseline' is not accepted: {why}")
        name, features = BASELINE_NAME, BASELINE_FEATURES
    else:
        name, features = None, None
    if _compiled():
        if current_name() != (name or _host_name()):
            raise ValueError(
                f"cpu_target={target!r} is not accepted: this process has compiled its kernels for "
                f"{current_name()} already; set {ENV}={target} before starting Python")
        os.environ[ENV] = target
        return
    os.environ[ENV] = target  # children (Dask workers, the CLI's subprocesses) inherit it
    for var, value in (("NUMBA_CPU_NAME", name), ("NUMBA_CPU_FEATURES", features)):
        if value is None:
            os.environ.pop(var, None)
        else:
            os.environ[var] = value
    numba = sys.modules.get("numba")
    if numba is not None:  # Numba read the environment at import: set its config directly
        numba.config.CPU_NAME = name
        numba.config.CPU_FEATURES = features


def apply_environment() -> None:
    """Apply :data:`ENV` if it asks for the baseline (called before any kernel is compiled)."""
    if requested() == "baseline":
        select("baseline")


def _host_name() -> str:
    import llvmlite.binding as ll

    return str(ll.get_host_cpu_name())


def current_name() -> str:
    """The CPU name Numba compiles for in this process (LLVM's name, e.g. ``znver4``)."""
    import numba

    return str(numba.config.CPU_NAME or _host_name())


def describe() -> str:
    """What a result's ``cpu_target`` attribute says: the CPU name the kernels were compiled for
    and why, e.g. ``"znver4 (host)"`` or ``"x86-64-v3 (baseline)"``."""
    import numba

    name = current_name()
    if name == BASELINE_NAME and numba.config.CPU_FEATURES == BASELINE_FEATURES:
        return f"{name} (baseline)"
    if numba.config.CPU_NAME:
        return f"{name} (NUMBA_CPU_NAME, features {numba.config.CPU_FEATURES or 'host'})"
    return f"{name} (host)"


def planned() -> str:
    """:func:`describe` without importing Numba or LLVM (``stochpend info`` starts fast): what
    this process's kernels will be compiled for, from the environment; the host by its model
    name (LLVM's name of it appears in a result's ``cpu_target``)."""
    try:
        target = requested()
    except ValueError as exc:
        return f"unknown ({exc})"
    if target == "baseline":
        return f"{BASELINE_NAME} (baseline)"
    name = os.environ.get("NUMBA_CPU_NAME")
    if name:
        return f"{name} (NUMBA_CPU_NAME, features {os.environ.get('NUMBA_CPU_FEATURES') or 'host'})"
    return f"this machine's CPU (host: {_model_name()})"


def _model_name() -> str:
    try:
        with open("/proc/cpuinfo", encoding="utf-8", errors="replace") as f:
            for line in f:
                if line.startswith("model name"):
                    return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or platform.machine()
